"""Results writers: USD for usdview / Omniverse, VTK for ParaView, and side-view pictures.

Everything here takes plain NumPy frames (copy the solver state to the host first), so this module
imports neither Warp nor the solver. Units are SI throughout: metres, seconds, joules.

:class:`ResultWriter` writes one time-sampled USD stage (and optionally a VTK series) from frames
whose particle counts change over time, as they do while factories release particles:

* ``/World`` (default prim, Xform) with ``custom double warpdem:time``: the simulation time [s]
  of each frame, time-sampled.
* ``/World/Spheres`` (``UsdGeom.Points``): the loose spheres (those in no clump); ``points``,
  ``widths`` (= 2 r, vertex interpolation), ``ids``, ``velocities`` (when given), ``extent``.
* ``/World/Clumps`` (``UsdGeom.PointInstancer``): one instance per clump; ``positions``,
  ``orientations`` (quath), ``scales`` (s, s, s), ``protoIndices``, ``ids``, ``velocities`` (when
  given), ``extent``. ``protoIndices`` is written at every frame, not once.
* ``/World/Clumps/Prototypes`` (an ``over``, so generic traversals and renderers skip it, as the
  PointInstancer schema documentation recommends) holding ``<shape>`` (Xform) per clump shape, each
  with ``sphere_0000``, ... (``UsdGeom.Sphere``: ``xformOp:translate`` and ``radius``).
* ``/World/Walls/<wall>`` (``UsdGeom.Mesh``): static ``points``, ``faceVertexCounts``,
  ``faceVertexIndices`` in the wall's own frame; time-sampled ``xformOp:translate`` (double3) and
  ``xformOp:orient`` (quatd) from the wall pose; time-sampled primvars ``impactCount`` (int[]) and
  ``impactEnergy`` (float[], J), uniform interpolation (one value per triangle), when given.

Time code convention: time code = frame index (0, 1, 2, ...), whatever the spacing of the
simulation times; ``timeCodesPerSecond`` (and ``framesPerSecond``) is ``frames_per_second`` when
given, else the mean frame rate of the simulation, (frames - 1) / (t_last - t_first), so that
playback runs in simulated real time and USD's velocity extrapolation (velocities in units per
second) agrees with the positions. The exact time of each frame is ``/World.warpdem:time``.

Optional per-frame arrays (velocities, impact primvars, extents of empty frames) are blocked
(``Sdf.ValueBlock``) at frames where they are absent: a held sample of another frame would carry
an array of the wrong length.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from warpdem.engine.checks import fail, is_finite, readonly

__all__ = ["ResultWriter", "ShapeGeometry", "WallGeometry", "expand_clumps", "quat_to_matrix", "side_view_png"]


# -- validation helpers -----------------------------------------------------------------------------------------


def _shape_ok(shape: tuple, want: tuple) -> bool:
    return len(shape) == len(want) and all(w is None or s == w for s, w in zip(shape, want))


def _floats(
    value, where: str, name: str, want: tuple, allowed: str, *, positive: bool = False, unit: str = ""
) -> np.ndarray:
    """``value`` as a float64 array of shape ``want`` (None = any length), finite (and > 0 if ``positive``)."""
    try:
        a = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        fail(where, name, value, allowed)
    if not _shape_ok(a.shape, want):
        fail(where, f"{name}.shape", a.shape, allowed)
    bad = ~np.isfinite(a)
    if positive:
        bad |= ~(a > 0)
    if bad.any():
        what = ("finite values > 0" if positive else "finite values") + (f" in {unit}" if unit else "")
        if a.ndim == 0:
            fail(where, name, a, what)
        i = int(np.flatnonzero(bad.reshape(a.shape[0], -1).any(axis=1))[0])
        fail(where, f"{name}[{i}]", a[i], what)
    return a


def _ints(
    value, where: str, name: str, want: tuple, allowed: str, lo: int | None = None, hi: int | None = None
) -> np.ndarray:
    """``value`` as an int64 array of shape ``want``, entries in [lo, hi) where given."""
    a = np.asarray(value)
    if a.dtype.kind not in "iu" and not (a.size == 0 and a.dtype.kind == "f"):
        fail(where, f"{name}.dtype", a.dtype, f"an integer array, {allowed}")
    a = a.astype(np.int64)
    if not _shape_ok(a.shape, want):
        fail(where, f"{name}.shape", a.shape, allowed)
    bad = np.zeros(a.shape, bool)
    if lo is not None:
        bad |= a < lo
    if hi is not None:
        bad |= a >= hi
    if bad.any():
        rng = f"integers in [{lo}, {hi})" if hi is not None else f"integers >= {lo}"
        if a.ndim == 0:
            fail(where, name, int(a), rng)
        i = int(np.flatnonzero(bad.reshape(a.shape[0], -1).any(axis=1))[0])
        fail(where, f"{name}[{i}]", a[i] if a.ndim > 1 else int(a[i]), rng)
    return a


def _quats(value, where: str, name: str, k: int, allowed: str) -> np.ndarray:
    """Unit quaternions (k, 4) in (x, y, z, w) order; normalised, since float32 state drifts off unit norm."""
    q = _floats(value, where, name, (k, 4), allowed)
    norm = np.linalg.norm(q, axis=1)
    bad = np.flatnonzero(~(norm > 1e-12))
    if bad.size:
        fail(where, f"{name}[{bad[0]}]", q[bad[0]], "a non-zero quaternion (x, y, z, w)")
    return q / norm[:, None]


def _all_or_none(where: str, group: dict) -> bool:
    """Whether the arrays of ``group`` (name -> value or None) are given; refuses a group given in part."""
    given = [k for k, v in group.items() if v is not None]
    if given and len(given) < len(group):
        missing = [k for k in group if k not in given][0]
        fail(
            where,
            missing,
            None,
            f"an array, since {given[0]} is given ({', '.join(group)} are all given or all None)",
        )
    return bool(given)


_IDENT_BAD = re.compile(r"[^A-Za-z0-9_]")


def _identifiers(names: list[str], fallback: str) -> list[str]:
    """Valid, unique USD prim names for ``names`` (Sdf identifiers: [A-Za-z_][A-Za-z0-9_]*)."""
    out: list[str] = []
    taken: set[str] = set()
    for name in names:
        base = _IDENT_BAD.sub("_", name) or fallback
        if base[0].isdigit():
            base = "_" + base
        ident, i = base, 1
        while ident in taken:
            ident, i = f"{base}_{i}", i + 1
        taken.add(ident)
        out.append(ident)
    return out


# -- geometry ---------------------------------------------------------------------------------------------------


def _rows3(value, where: str, name: str, n: str, low: int, what: str) -> np.ndarray:
    """``value`` as a finite float64 array of ``what`` [m], shape (n, 3) with at least ``low`` rows (``n`` is
    the row count's letter in messages)."""
    a = _floats(value, where, name, (None, 3), f"an ({n}, 3) array of {what} in m, {n} >= {low}", unit="m")
    if a.shape[0] < low:
        fail(where, f"{name}.shape", a.shape, f"({n}, 3) with {n} >= {low}")
    return a


@dataclass(frozen=True)
class _NamedGeometry:
    """A named piece of what the writer draws; a subclass's ``_arrays`` validates its array fields, which
    are then stored read-only."""

    name: str

    def __post_init__(self):
        where = f"{type(self).__name__} {self.name!r}"
        if not isinstance(self.name, str) or not self.name:
            fail(where, "name", self.name, "a non-empty string")
        for field_name, a in self._arrays(where).items():
            object.__setattr__(self, field_name, readonly(a))

    def _arrays(self, where: str) -> dict:
        raise NotImplementedError


@dataclass(frozen=True)
class WallGeometry(_NamedGeometry):
    """A triangle mesh wall as the writer draws it.

    Attributes:
        name: the wall's name; the USD prim name is derived from it (invalid characters become ``_``).
        vertices: vertex positions in the wall's own frame [m], shape (V, 3), V >= 3, finite.
        triangles: vertex indices of each triangle, shape (F, 3), F >= 1, integers in [0, V).
    """

    vertices: np.ndarray
    triangles: np.ndarray

    def _arrays(self, where: str) -> dict:
        v = _rows3(self.vertices, where, "vertices", "V", 3, "vertex positions")
        n = len(v)
        t = _ints(self.triangles, where, "triangles", (None, 3), f"an (F, 3) array of vertex indices in [0, {n})", 0, n)
        if t.shape[0] < 1:
            fail(where, "triangles.shape", t.shape, "(F, 3) with F >= 1")
        return {"vertices": v, "triangles": t}

    @property
    def face_count(self) -> int:
        return int(self.triangles.shape[0])


@dataclass(frozen=True)
class ShapeGeometry(_NamedGeometry):
    """One clump template (multi-sphere particle shape) as the writer draws it.

    Attributes:
        name: the shape's name; the prototype prim name is derived from it.
        sphere_offset: sphere centres in the body frame [m], shape (s, 3), s >= 1, finite.
        sphere_radius: sphere radii [m], shape (s,), finite and > 0.
    """

    sphere_offset: np.ndarray
    sphere_radius: np.ndarray

    def _arrays(self, where: str) -> dict:
        c = _rows3(self.sphere_offset, where, "sphere_offset", "s", 1, "offsets")
        r = _floats(
            self.sphere_radius,
            where,
            "sphere_radius",
            (c.shape[0],),
            f"({c.shape[0]},): one radius per row of sphere_offset",
            positive=True,
            unit="m",
        )
        return {"sphere_offset": c, "sphere_radius": r}

    @classmethod
    def from_template(cls, template) -> ShapeGeometry:
        """The geometry of a :class:`warpdem.ClumpTemplate` (anything with ``name``, ``sphere_offset``,
        ``sphere_radius``)."""
        return cls(template.name, template.sphere_offset, template.sphere_radius)

    @property
    def bounding_radius(self) -> float:
        """Radius of the smallest origin-centred ball holding every sphere [m]."""
        return float(np.max(np.linalg.norm(self.sphere_offset, axis=1) + self.sphere_radius))


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (k, 3, 3) of unit quaternions ``q`` (k, 4) in (x, y, z, w) order (Warp's layout)."""
    q = np.asarray(q, dtype=np.float64)
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    r = np.empty((q.shape[0], 3, 3))
    r[:, 0, 0] = 1 - 2 * (y * y + z * z)
    r[:, 0, 1] = 2 * (x * y - z * w)
    r[:, 0, 2] = 2 * (x * z + y * w)
    r[:, 1, 0] = 2 * (x * y + z * w)
    r[:, 1, 1] = 1 - 2 * (x * x + z * z)
    r[:, 1, 2] = 2 * (y * z - x * w)
    r[:, 2, 0] = 2 * (x * z - y * w)
    r[:, 2, 1] = 2 * (y * z + x * w)
    r[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def _check_clumps(where: str, clump_x, clump_q, clump_shape, clump_scale, n_shapes: int):
    """Validated clump arrays: x (k, 3), unit q (k, 4), shape (k,), scale (k,)."""
    x = _floats(clump_x, where, "clump_x", (None, 3), "a (k, 3) array of clump centres in m", unit="m")
    k = x.shape[0]
    q = _quats(clump_q, where, "clump_q", k, f"({k}, 4): one quaternion (x, y, z, w) per row of clump_x")
    s = _ints(clump_shape, where, "clump_shape", (k,), f"({k},): one shape index per row of clump_x", 0, n_shapes)
    if clump_scale is None:
        sc = np.ones(k)
    else:
        sc = _floats(
            clump_scale, where, "clump_scale", (k,), f"({k},): one scale factor per row of clump_x", positive=True
        )
    return x, q, s, sc


def _shape_list(shapes, where: str) -> list:
    try:
        shapes = list(shapes)
    except TypeError:
        fail(where, "shapes", shapes, "a list of ShapeGeometry")
    for i, sh in enumerate(shapes):
        if not (hasattr(sh, "sphere_offset") and hasattr(sh, "sphere_radius")):
            fail(where, f"shapes[{i}]", sh, "a ShapeGeometry (or ClumpTemplate)")
    return shapes


def _expand(x, q, shape, scale, shapes) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`expand_clumps` on validated arrays; also returns each sphere's component index."""
    k = x.shape[0]
    counts_per_shape = np.array([len(sh.sphere_radius) for sh in shapes], dtype=np.int64)
    if k == 0:
        return np.zeros((0, 3)), np.zeros(0), np.zeros(0, np.int64), np.zeros(0, np.int64)
    # One table of all shapes' spheres; each clump reads the slice of its shape.
    table_off = np.concatenate([np.asarray(sh.sphere_offset, dtype=np.float64) for sh in shapes])
    table_r = np.concatenate([np.asarray(sh.sphere_radius, dtype=np.float64) for sh in shapes])
    first = np.concatenate([[0], np.cumsum(counts_per_shape)[:-1]])
    counts = counts_per_shape[shape]
    body = np.repeat(np.arange(k, dtype=np.int64), counts)
    component = np.arange(body.size, dtype=np.int64) - np.repeat(np.cumsum(counts) - counts, counts)
    row = first[shape][body] + component
    rot = quat_to_matrix(q)
    local = table_off[row] * scale[body, None]
    world = x[body] + np.einsum("mij,mj->mi", rot[body], local)
    return world, table_r[row] * scale[body], body, component


def expand_clumps(clump_x, clump_q, clump_shape, clump_scale, shapes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The component spheres of clumps in world coordinates.

    Sphere j of clump i sits at ``clump_x[i] + R(clump_q[i]) (clump_scale[i] * offset_j)`` with radius
    ``clump_scale[i] * radius_j``.

    Args:
        clump_x: clump centres (body-frame origins) [m], shape (k, 3).
        clump_q: orientations body -> world, unit quaternions (x, y, z, w), shape (k, 4).
        clump_shape: index into ``shapes`` of each clump, shape (k,).
        clump_scale: uniform scale factor of each clump [-], shape (k,), > 0; None means 1.
        shapes: the clump shapes (:class:`ShapeGeometry` or :class:`warpdem.ClumpTemplate`).

    Returns:
        sphere_x: world sphere centres [m], shape (m, 3), grouped by clump in input order.
        sphere_r: sphere radii [m], shape (m,).
        body: row index (0 .. k-1) into the clump arrays of each sphere's clump, shape (m,).
    """
    where = "expand_clumps"
    shapes = _shape_list(shapes, where)
    x, q, s, sc = _check_clumps(where, clump_x, clump_q, clump_shape, clump_scale, len(shapes))
    world, r, body, _ = _expand(x, q, s, sc, shapes)
    return world, r, body


# -- the writer -------------------------------------------------------------------------------------------------

_SAND = (0.80, 0.68, 0.45)
_WALL_GREY = (0.6, 0.6, 0.62)


def _schema_attrs(prim, *names: str) -> dict:
    """The schema attributes ``names`` of the UsdGeom ``prim``, each made by its ``Create<Name>Attr``, by name."""
    return {name: getattr(prim, f"Create{name[0].upper()}{name[1:]}Attr")() for name in names}


class ResultWriter:
    """Writes a time-sampled USD stage (and a VTK series for ParaView) frame by frame.

    Usage::

        with ResultWriter("out/run1", walls, shapes) as w:
            for t, frame in frames:
                w.add_frame(t, **frame)
        # or: info = w.close() -> {"usd": path, "vtk_series": path or None, "frames": count}

    Args:
        out_dir: directory for the results; created if missing.
        walls: wall meshes, in the order of ``wall_pose`` rows.
        shapes: clump shapes, indexed by ``clump_shape``.
        usd_name: file name of the stage in ``out_dir``, ending in .usdc, .usd (both binary) or .usda
            (text; larger and slower). An existing file is overwritten.
        vtk: also write ``out_dir/vtk/particles_%05d.vtp``, ``out_dir/vtk/walls_%05d.vtp`` (when there
            are walls) and the collection ``out_dir/result.pvd``. VTK files are always in metres.
        frames_per_second: USD timeCodesPerSecond [1/s]; None: the mean simulated frame rate (see the
            module docstring for the time code convention).
        up_axis: "Z" or "Y": the stage's upAxis, i.e. which axis of the simulation frame points up. No
            coordinates are rotated.
        meters_per_unit: the stage's metersPerUnit [m]; every length written to USD is divided by it
            (0.001 writes millimetres). Energies stay in J.
        flush_every: save the stage (and the .pvd) every this many frames, so a crashed run leaves a
            readable file; 0 saves only at :meth:`close` and :meth:`flush`.
    """

    def __init__(
        self,
        out_dir,
        walls: list[WallGeometry],
        shapes: list[ShapeGeometry],
        *,
        usd_name: str = "result.usdc",
        vtk: bool = True,
        frames_per_second: float | None = None,
        up_axis: str = "Z",
        meters_per_unit: float = 1.0,
        flush_every: int = 20,
    ):
        where = "ResultWriter"
        try:
            walls = list(walls)
        except TypeError:
            fail(where, "walls", walls, "a list of WallGeometry")
        for i, wall in enumerate(walls):
            if not isinstance(wall, WallGeometry):
                fail(where, f"walls[{i}]", wall, "a WallGeometry")
        shapes = _shape_list(shapes, where)
        shapes = [sh if isinstance(sh, ShapeGeometry) else ShapeGeometry.from_template(sh) for sh in shapes]
        if (
            not isinstance(usd_name, str)
            or os.path.basename(usd_name) != usd_name
            or os.path.splitext(usd_name)[1].lower() not in (".usd", ".usdc", ".usda")
        ):
            fail(where, "usd_name", usd_name, "a file name (no directory) ending in .usdc, .usd or .usda")
        if frames_per_second is not None and not (is_finite(frames_per_second) and frames_per_second > 0):
            fail(where, "frames_per_second", frames_per_second, "None or a rate > 0 per second")
        if not isinstance(up_axis, str) or up_axis.upper() not in ("Y", "Z"):
            fail(where, "up_axis", up_axis, '"Z" or "Y"')
        if not (is_finite(meters_per_unit) and meters_per_unit > 0):
            fail(where, "meters_per_unit", meters_per_unit, "a length > 0 m")
        if isinstance(flush_every, bool) or not isinstance(flush_every, (int, np.integer)) or flush_every < 0:
            fail(where, "flush_every", flush_every, "an integer >= 0 (0: save only at close)")

        from pxr import Sdf, Usd, UsdGeom  # here, not at module level: pictures and expand_clumps need no pxr

        self.out_dir = Path(out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.walls = walls
        self.shapes = shapes
        self.usd_path = self.out_dir / usd_name
        self.vtk = bool(vtk)
        self.frames_per_second = None if frames_per_second is None else float(frames_per_second)
        self.flush_every = int(flush_every)
        self._unit = 1.0 / float(meters_per_unit)  # metres -> stage units
        self._times: list[float] = []
        self._authored: set[str] = set()
        self._pvd: list[tuple[float, int, str, str]] = []
        self._result: dict | None = None

        if Sdf.Layer.Find(str(self.usd_path)):
            fail(
                where,
                "usd_name",
                usd_name,
                f"a file not open in this process ({self.usd_path} is; close the "
                "ResultWriter or stage holding it first)",
            )
        stage = Usd.Stage.CreateNew(str(self.usd_path))
        self._stage = stage
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z if up_axis.upper() == "Z" else UsdGeom.Tokens.y)
        UsdGeom.SetStageMetersPerUnit(stage, float(meters_per_unit))
        world = UsdGeom.Xform.Define(stage, "/World")
        stage.SetDefaultPrim(world.GetPrim())
        self._time_attr = world.GetPrim().CreateAttribute("warpdem:time", Sdf.ValueTypeNames.Double, custom=True)
        self._time_attr.SetDocumentation("simulation time of each frame [s]; time code = frame index")

        pts = UsdGeom.Points.Define(stage, "/World/Spheres")
        pts.CreateDisplayColorAttr([_SAND])
        self._pts = pts
        self._pts_attrs = _schema_attrs(pts, "points", "widths", "ids", "velocities", "extent")
        pts.SetWidthsInterpolation(UsdGeom.Tokens.vertex)

        self._build_instancer(stage)
        self._build_walls(stage)

        self.vtk_dir = self.out_dir / "vtk"
        self.pvd_path = self.out_dir / "result.pvd"
        if self.vtk:
            self.vtk_dir.mkdir(exist_ok=True)

    # -- construction -------------------------------------------------------------------------------------

    def _build_instancer(self, stage):
        from pxr import Gf, Sdf, UsdGeom, Vt

        inst = UsdGeom.PointInstancer.Define(stage, "/World/Clumps")
        self._inst = inst
        self._inst_attrs = _schema_attrs(
            inst, "positions", "orientations", "scales", "protoIndices", "ids", "velocities", "extent"
        )
        root = "/World/Clumps/Prototypes"
        self.prototype_paths = [f"{root}/{n}" for n in _identifiers([s.name for s in self.shapes], "shape")]
        u = self._unit
        for path, shape in zip(self.prototype_paths, self.shapes):
            UsdGeom.Xform.Define(stage, path)
            for j, (c, r) in enumerate(zip(shape.sphere_offset, shape.sphere_radius)):
                sph = UsdGeom.Sphere.Define(stage, f"{path}/sphere_{j:04d}")
                sph.AddTranslateOp().Set(Gf.Vec3d(*(c * u)))
                sph.CreateRadiusAttr(float(r * u))
                sph.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(-r * u), Gf.Vec3f(r * u)]))
                sph.CreateDisplayColorAttr([_SAND])
        if not self.shapes:
            stage.DefinePrim(root)
        # An "over" parent keeps the prototypes out of generic traversals, so they are drawn only as
        # instances (the pattern the PointInstancer schema recommends); set after the children, since
        # Define() would turn it back into a "def".
        stage.GetPrimAtPath(root).SetSpecifier(Sdf.SpecifierOver)
        inst.CreatePrototypesRel().SetTargets([Sdf.Path(p) for p in self.prototype_paths])

    def _build_walls(self, stage):
        from pxr import Sdf, UsdGeom, Vt

        UsdGeom.Scope.Define(stage, "/World/Walls")
        self.wall_paths = [f"/World/Walls/{n}" for n in _identifiers([w.name for w in self.walls], "wall")]
        self._wall_ops = []
        self._wall_primvars = []
        u = self._unit
        for path, wall in zip(self.wall_paths, self.walls):
            mesh = UsdGeom.Mesh.Define(stage, path)
            v = np.ascontiguousarray(wall.vertices * u, dtype=np.float32)
            mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(v))
            mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(wall.face_count, 3, np.int32)))
            mesh.CreateFaceVertexIndicesAttr(
                Vt.IntArray.FromNumpy(np.ascontiguousarray(wall.triangles.reshape(-1), dtype=np.int32))
            )
            mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([v.min(axis=0), v.max(axis=0)])))
            # Walls are faceted triangle meshes (often open, like a cone): no subdivision, both sides lit.
            mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
            mesh.CreateDoubleSidedAttr(True)
            mesh.CreateDisplayColorAttr([_WALL_GREY])
            mesh.CreateDisplayOpacityAttr([0.35])
            translate = mesh.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble)
            orient = mesh.AddOrientOp(UsdGeom.XformOp.PrecisionDouble)
            self._wall_ops.append((translate, orient))
            api = UsdGeom.PrimvarsAPI(mesh.GetPrim())
            count = api.CreatePrimvar("impactCount", Sdf.ValueTypeNames.IntArray, UsdGeom.Tokens.uniform)
            energy = api.CreatePrimvar("impactEnergy", Sdf.ValueTypeNames.FloatArray, UsdGeom.Tokens.uniform)
            energy.GetAttr().SetDocumentation("impact energy on each triangle [J], as given to add_frame")
            self._wall_primvars.append((count.GetAttr(), energy.GetAttr()))

    # -- frames -------------------------------------------------------------------------------------------

    @property
    def frame_count(self) -> int:
        return len(self._times)

    def add_frame(
        self,
        time: float,
        *,
        sphere_x=None,
        sphere_r=None,
        sphere_id=None,
        sphere_v=None,
        clump_x=None,
        clump_q=None,
        clump_shape=None,
        clump_scale=None,
        clump_id=None,
        clump_v=None,
        wall_pose=None,
        face_impacts=None,
        face_energy=None,
    ) -> None:
        """Append one frame (its time code is the frame index).

        Counts may change between frames and may be zero. The sphere group (``sphere_x``, ``sphere_r``,
        ``sphere_id``) and the clump group (``clump_x``, ``clump_q``, ``clump_shape``, ``clump_id``) are
        each all given or all None (None: no such particles in this frame).

        Args:
            time: simulation time [s], greater than the previous frame's.
            sphere_x: loose sphere centres (in no clump) [m], shape (n, 3).
            sphere_r: their radii [m], shape (n,), > 0.
            sphere_id: their persistent ids, shape (n,), integers.
            sphere_v: their velocities [m/s], shape (n, 3), or None.
            clump_x: clump centres (body-frame origins) [m], shape (k, 3).
            clump_q: clump orientations body -> world, quaternions (x, y, z, w), shape (k, 4), non-zero
                (normalised here).
            clump_shape: index into ``shapes`` of each clump, shape (k,).
            clump_scale: uniform scale of each clump [-], shape (k,), > 0; None means 1.
            clump_id: persistent clump ids, shape (k,), integers.
            clump_v: clump centre velocities [m/s], shape (k, 3), or None.
            wall_pose: pose of each wall, rows [px, py, pz, qx, qy, qz, qw] ([m], unit quaternion), shape
                (W, 7): world = R(q) vertex + p. None: every wall at identity.
            face_impacts: per wall, impact count per triangle, a list of W arrays of shape (F_w,), ints >= 0;
                or None.
            face_energy: per wall, impact energy per triangle [J], a list of W arrays of shape (F_w,),
                finite; or None.
        """
        if self._result is not None:
            raise RuntimeError(f"ResultWriter.add_frame: the writer of {self.usd_path} is closed")
        # every input is checked (and converted) before anything is written, so a bad frame leaves no trace
        where = "ResultWriter.add_frame"
        if not is_finite(time):
            fail(where, "time", time, "a finite time in s")
        time = float(time)
        if self._times and not time > self._times[-1]:
            fail(where, "time", time, f"a time > {self._times[-1]!r} s (the previous frame's)")

        if _all_or_none(where, {"sphere_x": sphere_x, "sphere_r": sphere_r, "sphere_id": sphere_id}):
            sx = _floats(sphere_x, where, "sphere_x", (None, 3), "an (n, 3) array of sphere centres in m", unit="m")
            n = sx.shape[0]
            sr = _floats(
                sphere_r,
                where,
                "sphere_r",
                (n,),
                f"({n},): one radius per row of sphere_x (shape {sx.shape})",
                positive=True,
                unit="m",
            )
            sid = _ints(sphere_id, where, "sphere_id", (n,), f"({n},): one id per row of sphere_x (shape {sx.shape})")
        else:
            n = 0
            sx, sr, sid = np.zeros((0, 3)), np.zeros(0), np.zeros(0, np.int64)
        sv = None
        if sphere_v is not None:
            sv = _floats(
                sphere_v, where, "sphere_v", (n, 3), f"({n}, 3): one velocity in m/s per loose sphere, or None"
            )

        if _all_or_none(
            where, {"clump_x": clump_x, "clump_q": clump_q, "clump_shape": clump_shape, "clump_id": clump_id}
        ):
            cx, cq, cs, cscale = _check_clumps(where, clump_x, clump_q, clump_shape, clump_scale, len(self.shapes))
            k = cx.shape[0]
            cid = _ints(clump_id, where, "clump_id", (k,), f"({k},): one id per row of clump_x (shape {cx.shape})")
        else:
            if clump_scale is not None and np.size(clump_scale) != 0:
                fail(where, "clump_scale", clump_scale, "None when clump_x is None")
            k = 0
            cx, cq, cs = np.zeros((0, 3)), np.zeros((0, 4)), np.zeros(0, np.int64)
            cscale, cid = np.zeros(0), np.zeros(0, np.int64)
        cv = None
        if clump_v is not None:
            cv = _floats(clump_v, where, "clump_v", (k, 3), f"({k}, 3): one velocity in m/s per clump, or None")

        w = len(self.walls)
        if wall_pose is None:
            pose = np.tile([0.0, 0, 0, 0, 0, 0, 1], (w, 1))
        else:
            pose = _floats(
                wall_pose,
                where,
                "wall_pose",
                (w, 7),
                f"({w}, 7): one row [px, py, pz, qx, qy, qz, qw] per wall, or None",
            )
            pose[:, 3:] = _quats(pose[:, 3:], where, "wall_pose[:, 3:]", w, "unit quaternions (x, y, z, w)")
        impacts = self._per_face(where, "face_impacts", face_impacts, integer=True)
        energy = self._per_face(where, "face_energy", face_energy, integer=False)
        f = dict(
            time=time,
            sx=sx,
            sr=sr,
            sid=sid,
            sv=sv,
            cx=cx,
            cq=cq,
            cs=cs,
            cscale=cscale,
            cid=cid,
            cv=cv,
            pose=pose,
            impacts=impacts,
            energy=energy,
        )
        frame = len(self._times)
        self._write_usd(frame, f)
        if self.vtk:
            self._write_vtk(frame, f)
        self._times.append(f["time"])
        if self.flush_every and len(self._times) % self.flush_every == 0:
            self.flush()

    def _per_face(self, where: str, name: str, value, integer: bool):
        if value is None:
            return None
        w = len(self.walls)
        if isinstance(value, np.ndarray) and value.dtype != object:
            value = list(value) if value.ndim == 2 else [value]
        if not isinstance(value, (list, tuple)) or len(value) != w:
            fail(where, name, value, f"None or a list of {w} arrays, one per wall")
        out = []
        for i, (a, wall) in enumerate(zip(value, self.walls)):
            fw = wall.face_count
            allowed = f"({fw},): one value per triangle of wall {wall.name!r}"
            if integer:
                out.append(_ints(a, where, f"{name}[{i}]", (fw,), allowed, lo=0))
            else:
                out.append(_floats(a, where, f"{name}[{i}]", (fw,), allowed + " in J"))
        return out

    # -- USD ----------------------------------------------------------------------------------------------

    def _set_optional(self, attr, value, frame: int):
        """Time-sample ``value`` (None: absent) so that no frame shows another frame's array."""
        from pxr import Sdf

        key = str(attr.GetPath())
        if value is None:
            if key in self._authored:
                attr.Set(Sdf.ValueBlock(), frame)
            return
        if key not in self._authored:
            # USD holds the first sample for earlier times; block them instead.
            for earlier in range(frame):
                attr.Set(Sdf.ValueBlock(), earlier)
            self._authored.add(key)
        attr.Set(value, frame)

    def _write_usd(self, frame: int, f: dict):
        from pxr import Gf, Vt

        u = self._unit
        self._time_attr.Set(f["time"], frame)

        def vec3f(a):
            return Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(a * u, dtype=np.float32).reshape(-1, 3))

        def extent(lo, hi):
            return Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(np.stack([lo, hi]) * u, dtype=np.float32))

        sx, sr = f["sx"], f["sr"]
        a = self._pts_attrs
        a["points"].Set(vec3f(sx), frame)
        a["widths"].Set(Vt.FloatArray.FromNumpy(np.ascontiguousarray(2.0 * sr * u, dtype=np.float32)), frame)
        a["ids"].Set(Vt.Int64Array.FromNumpy(np.ascontiguousarray(f["sid"])), frame)
        self._set_optional(a["velocities"], None if f["sv"] is None else vec3f(f["sv"]), frame)
        ext = None
        if sx.shape[0]:
            ext = extent((sx - sr[:, None]).min(axis=0), (sx + sr[:, None]).max(axis=0))
        self._set_optional(a["extent"], ext, frame)

        cx, cq, cs, cscale = f["cx"], f["cq"], f["cs"], f["cscale"]
        k = cx.shape[0]
        a = self._inst_attrs
        a["positions"].Set(vec3f(cx), frame)
        # GfQuath stores (imaginary, real) in memory, so an (x, y, z, w) row is already its layout; read
        # back, GetReal() is w and GetImaginary() is (x, y, z).
        a["orientations"].Set(Vt.QuathArray.FromNumpy(np.ascontiguousarray(cq, dtype=np.float16).reshape(-1, 4)), frame)
        a["scales"].Set(
            Vt.Vec3fArray.FromNumpy(
                np.ascontiguousarray(np.repeat(cscale[:, None], 3, axis=1), dtype=np.float32).reshape(-1, 3)
            ),
            frame,
        )
        a["protoIndices"].Set(Vt.IntArray.FromNumpy(np.ascontiguousarray(cs, dtype=np.int32)), frame)
        a["ids"].Set(Vt.Int64Array.FromNumpy(np.ascontiguousarray(f["cid"])), frame)
        self._set_optional(a["velocities"], None if f["cv"] is None else vec3f(f["cv"]), frame)
        ext = None
        if k:
            reach = np.array([sh.bounding_radius for sh in self.shapes])[cs] * cscale
            ext = extent((cx - reach[:, None]).min(axis=0), (cx + reach[:, None]).max(axis=0))
        self._set_optional(a["extent"], ext, frame)

        for i, ((translate, orient), (count_attr, energy_attr)) in enumerate(zip(self._wall_ops, self._wall_primvars)):
            p = f["pose"][i]
            translate.Set(Gf.Vec3d(*(p[:3] * u)), frame)
            orient.Set(Gf.Quatd(float(p[6]), Gf.Vec3d(*p[3:6])), frame)
            cnt = None if f["impacts"] is None else Vt.IntArray.FromNumpy(f["impacts"][i].astype(np.int32))
            en = None if f["energy"] is None else Vt.FloatArray.FromNumpy(f["energy"][i].astype(np.float32))
            self._set_optional(count_attr, cnt, frame)
            self._set_optional(energy_attr, en, frame)

    def _update_time_metadata(self):
        n = len(self._times)
        if self.frames_per_second is not None:
            fps = self.frames_per_second
        elif n >= 2 and self._times[-1] > self._times[0]:
            fps = (n - 1) / (self._times[-1] - self._times[0])
        else:
            fps = 24.0  # USD's own default, for a single frame
        self._stage.SetStartTimeCode(0)
        self._stage.SetEndTimeCode(max(n - 1, 0))
        self._stage.SetTimeCodesPerSecond(fps)
        self._stage.SetFramesPerSecond(fps)

    # -- VTK ----------------------------------------------------------------------------------------------

    def _write_vtk(self, frame: int, f: dict):
        import pyvista as pv

        ex, er, body, comp = _expand(f["cx"], f["cq"], f["cs"], f["cscale"], self.shapes)
        n = f["sx"].shape[0]
        pts = np.concatenate([f["sx"], ex]).astype(np.float32)
        sv = f["sv"] if f["sv"] is not None else np.full((n, 3), np.nan)
        cv = f["cv"][body] if f["cv"] is not None else np.full((body.size, 3), np.nan)
        vel = np.concatenate([sv, cv]).astype(np.float32)
        cloud = pv.PolyData(pts) if len(pts) else pv.PolyData()
        if len(pts):
            # pyvista refuses empty arrays: a frame before any particle is released is an empty file
            cloud.point_data["radius"] = np.concatenate([f["sr"], er]).astype(np.float32)
            cloud.point_data["id"] = np.concatenate([f["sid"], f["cid"][body]])
            cloud.point_data["body"] = np.concatenate([np.full(n, -1, np.int64), f["cid"][body]])
            cloud.point_data["shape"] = np.concatenate([np.full(n, -1, np.int32), f["cs"][body].astype(np.int32)])
            cloud.point_data["component"] = np.concatenate([np.full(n, -1, np.int32), comp.astype(np.int32)])
            # Clump spheres get their clump's centre velocity (angular velocity is not passed in); NaN = not given.
            cloud.point_data["velocity"] = vel
            cloud.point_data["speed"] = np.linalg.norm(vel, axis=1)
        name = f"particles_{frame:05d}.vtp"
        cloud.save(str(self.vtk_dir / name))
        self._pvd.append((f["time"], 0, f"vtk/{name}", "particles"))

        if not self.walls:
            return
        verts, faces, wall_of, counts, energy = [], [], [], [], []
        base = 0
        rot = quat_to_matrix(f["pose"][:, 3:])
        for i, wall in enumerate(self.walls):
            verts.append(wall.vertices @ rot[i].T + f["pose"][i, :3])
            faces.append(wall.triangles + base)
            base += wall.vertices.shape[0]
            fw = wall.face_count
            wall_of.append(np.full(fw, i, np.int32))
            # -1 / NaN mark "not recorded", distinct from a recorded zero.
            counts.append(f["impacts"][i] if f["impacts"] is not None else np.full(fw, -1, np.int64))
            energy.append(f["energy"][i] if f["energy"] is not None else np.full(fw, np.nan))
        mesh = pv.PolyData.from_regular_faces(np.concatenate(verts), np.concatenate(faces))
        mesh.cell_data["wall"] = np.concatenate(wall_of)
        mesh.cell_data["impactCount"] = np.concatenate(counts)
        mesh.cell_data["impactEnergy"] = np.concatenate(energy)
        mesh.field_data["wall_names"] = np.array([w.name for w in self.walls])
        name = f"walls_{frame:05d}.vtp"
        mesh.save(str(self.vtk_dir / name))
        self._pvd.append((f["time"], 1, f"vtk/{name}", "walls"))

    def _write_pvd(self):
        lines = [
            '<?xml version="1.0"?>',
            '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
            "  <Collection>",
        ]
        for time, part, file, name in self._pvd:
            lines.append(
                f'    <DataSet timestep="{time!r}" group="" part="{part}" name={quoteattr(name)} '
                f"file={quoteattr(file)}/>"
            )
        lines += ["  </Collection>", "</VTKFile>", ""]
        # Written to a side file and renamed, so a crash mid-write never leaves a truncated collection.
        tmp = self.pvd_path.with_suffix(".pvd.tmp")
        tmp.write_text("\n".join(lines))
        os.replace(tmp, self.pvd_path)

    # -- saving -------------------------------------------------------------------------------------------

    def flush(self) -> None:
        """Save the stage (and the .pvd collection) as it stands, so a crash later keeps what is written."""
        if self._result is not None:
            return
        self._update_time_metadata()
        self._stage.Save()
        if self.vtk:
            self._write_pvd()

    def close(self) -> dict:
        """Save and release the stage; further calls return the same summary.

        Returns:
            {"usd": path of the stage, "vtk_series": path of the .pvd or None, "frames": frame count}
        """
        if self._result is None:
            self.flush()
            # Dropping every handle unloads the layer, so the next Usd.Stage.Open reads the file.
            self._stage = None
            self._pts = self._inst = None
            self._pts_attrs = self._inst_attrs = {}
            self._wall_ops, self._wall_primvars, self._time_attr = [], [], None
            self._result = {
                "usd": str(self.usd_path),
                "vtk_series": str(self.pvd_path) if self.vtk else None,
                "frames": len(self._times),
            }
        return dict(self._result)

    def __enter__(self) -> ResultWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# -- pictures ---------------------------------------------------------------------------------------------------

# axis -> (horizontal, vertical, sign): screen right x screen up points at the viewer, so no picture is
# mirrored; "sign" is the viewer's side of the depth axis.
_VIEWS = {"x": (1, 2, +1.0), "y": (0, 2, -1.0), "z": (0, 1, +1.0)}


def _outline_edges(
    v: np.ndarray, tri: np.ndarray, h: int, vax: int, feature_cos: float = math.cos(math.radians(30.0))
) -> np.ndarray:
    """Edges (e, 2) worth drawing in a projection onto axes (h, vax): boundary, non-manifold, silhouette
    and sharp edges.

    Interior edges of a smooth surface (a finely tessellated cylinder) would hide the picture under
    a mesh of lines; only where the projected surface folds over (silhouette) or creases do lines
    help. Both tests ignore triangle winding, which wall meshes do not always keep consistent.
    """
    n = np.cross(v[tri[:, 1]] - v[tri[:, 0]], v[tri[:, 2]] - v[tri[:, 0]])
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = n / np.linalg.norm(n, axis=1)[:, None]
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    third = np.concatenate([tri[:, 2], tri[:, 0], tri[:, 1]])
    face_of = np.tile(np.arange(tri.shape[0]), 3)
    e.sort(axis=1)
    uniq, inv, counts = np.unique(e, axis=0, return_inverse=True, return_counts=True)
    order = np.argsort(inv.reshape(-1), kind="stable")
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    i1, i2 = order[start], order[np.minimum(start + 1, order.size - 1)]
    draw = counts != 2
    two = counts == 2
    p = v[:, [h, vax]]
    a, b = p[uniq[:, 0]], p[uniq[:, 1]]

    def side(c):
        return np.sign((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))

    # Both triangles on the same side of the projected edge: the surface folds back there.
    s1, s2 = side(p[third[i1]]), side(p[third[i2]])
    fold = (s1 == s2) & (s1 != 0)
    with np.errstate(invalid="ignore"):
        sharp = np.abs(np.einsum("ij,ij->i", unit[face_of[i1]], unit[face_of[i2]])) < feature_cos
    draw[two] |= fold[two] | sharp[two]
    return uniq[draw]


PNG_COLOURS = 256
"""Colours of the palette every picture is written with (:func:`palette_png`)."""


def palette_png(data: bytes) -> bytes:
    """The PNG ``data`` as a :data:`PNG_COLOURS`-colour palette PNG where that is smaller (about four times for
    plots and pile renders, with no visible change: they hold few colours), else ``data`` unchanged. The seed
    records keep hundreds of pictures in the repository, which travels to a GPU machine under a size limit."""
    import io

    from PIL import Image

    with Image.open(io.BytesIO(data)) as im:
        im.load()
        if im.mode == "P":
            return data
        rgba = im.convert("RGBA")
        # an opaque picture (matplotlib's, on its white page) needs no transparency in its palette
        src = rgba.convert("RGB") if rgba.getchannel("A").getextrema() == (255, 255) else rgba
        buf = io.BytesIO()
        src.quantize(PNG_COLOURS, method=Image.Quantize.FASTOCTREE).save(buf, "PNG", optimize=True)
    return buf.getvalue() if buf.tell() < len(data) else data


def save_figure(fig, path, **savefig) -> str:
    """Save the matplotlib figure ``fig`` to ``path`` (``savefig``: matplotlib's keywords, ``dpi``,
    ``bbox_inches``, ...): a ``.png`` as :func:`palette_png` gives it, any other suffix as matplotlib writes it.
    Returns ``str(path)``."""
    if Path(path).suffix.lower() != ".png":
        fig.savefig(path, **savefig)
        return str(path)
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", **savefig)
    Path(path).write_bytes(palette_png(buf.getvalue()))
    return str(path)


def side_view_png(
    path,
    sphere_x,
    sphere_r,
    walls_world=None,
    axis: str = "y",
    title: str | None = None,
    colour_by=None,
    *,
    figsize: tuple[float, float] = (8.0, 6.0),
    dpi: int = 150,
    colour_label: str | None = None,
    lines=None,
    frame=None,
) -> str:
    """Orthographic side view of a sphere pile, saved as a PNG (the seeds' photo of the pile).

    Every sphere is a filled disc of its true radius, drawn back to front so nearer spheres cover
    farther ones and shaded darker with depth; walls are drawn as light grey outlines (boundary,
    silhouette and sharp edges of their triangles) behind the spheres. Axes are in mm, equal aspect.
    Looking along ``axis``: "y" shows x right, z up, seen from -y; "x" shows y right, z up, seen from
    +x; "z" shows x right, y up, seen from +z (none is mirrored).

    Args:
        path: PNG file to write.
        sphere_x: sphere centres in world coordinates [m], shape (n, 3); n may be 0.
        sphere_r: radii [m], shape (n,), > 0.
        walls_world: wall meshes already in world coordinates, a list of (vertices (V, 3) [m],
            triangles (F, 3)), or None.
        axis: viewing axis, "x", "y" or "z".
        title: figure title, or None.
        colour_by: a value per sphere (shape (n,)) coloured with viridis plus a colour bar, or None
            for one sand colour; depth shading applies either way.
        figsize: figure size [inch]. dpi: resolution [pixels per inch].
        colour_label: colour bar label when ``colour_by`` is given.
        lines: segments drawn over the spheres (a measurement's fitted lines), each ((h0, v0), (h1, v1), label)
            [m] in the view's horizontal and vertical coordinates, the label written at the first end; or None.
        frame: ((h_min, v_min), (h_max, v_max)) [m], the part of the scene to show (e.g. a dump body, when the
            walls span the whole site); None frames the walls and spheres.

    Returns:
        ``str(path)``.
    """
    where = "side_view_png"
    if axis not in _VIEWS:
        fail(where, "axis", axis, '"x", "y" or "z"')
    x = _floats(sphere_x, where, "sphere_x", (None, 3), "an (n, 3) array of sphere centres in m")
    n = x.shape[0]
    r = _floats(
        sphere_r, where, "sphere_r", (n,), f"({n},): one radius per row of sphere_x (shape {x.shape})", positive=True
    )
    values = None
    if colour_by is not None:
        values = _floats(colour_by, where, "colour_by", (n,), f"({n},): one value per sphere, or None")
    walls = []
    if walls_world is not None:
        if not isinstance(walls_world, (list, tuple)):
            fail(where, "walls_world", walls_world, "None or a list of (vertices (V, 3), triangles (F, 3))")
        for i, item in enumerate(walls_world):
            if not isinstance(item, (list, tuple)) or len(item) != 2:
                fail(where, f"walls_world[{i}]", item, "a pair (vertices (V, 3), triangles (F, 3))")
            v = _floats(item[0], where, f"walls_world[{i}][0]", (None, 3), "a (V, 3) array of vertices in m")
            t = _ints(
                item[1],
                where,
                f"walls_world[{i}][1]",
                (None, 3),
                f"an (F, 3) array of vertex indices in [0, {len(v)})",
                0,
                len(v),
            )
            walls.append((v, t))
    if not isinstance(dpi, (int, np.integer)) or isinstance(dpi, bool) or not 10 <= dpi <= 2000:
        fail(where, "dpi", dpi, "an integer in [10, 2000]")
    if frame is not None:
        f = np.asarray(frame, dtype=float) if np.shape(frame) == (2, 2) else None
        if f is None or not np.all(np.isfinite(f)) or not np.all(f[1] > f[0]):
            fail(where, "frame", frame, "None or ((h_min, v_min), (h_max, v_max)) in m, finite, min < max")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import EllipseCollection, LineCollection

    h, vax, sign = _VIEWS[axis]
    d = {"x": 0, "y": 1, "z": 2}[axis]
    names = "xyz"
    mm = 1000.0
    fig, ax = plt.subplots(figsize=figsize, dpi=dpi)
    try:
        lo = np.full(2, np.inf)
        hi = np.full(2, -np.inf)
        for v, t in walls:
            edges = _outline_edges(v, t, h, vax)
            seg = v[edges][:, :, [h, vax]] * mm
            ax.add_collection(LineCollection(seg, colors="0.75", linewidths=0.8, zorder=1))
            lo = np.minimum(lo, v[:, [h, vax]].min(axis=0) * mm)
            hi = np.maximum(hi, v[:, [h, vax]].max(axis=0) * mm)
        if n:
            near = sign * x[:, d]
            order = np.argsort(near, kind="stable")  # farthest first: later discs cover earlier ones
            span = near.max() - near.min()
            shade = 0.55 + 0.45 * ((near - near.min()) / span if span > 0 else np.ones(n))
            if values is not None:
                vmin, vmax = float(values.min()), float(values.max())
                norm = matplotlib.colors.Normalize(vmin, vmax if vmax > vmin else vmin + 1.0)
                cmap = matplotlib.colormaps["viridis"]
                base = cmap(norm(values))[:, :3]
                shade = 0.65 + 0.35 * (shade - 0.55) / 0.45  # milder, so the colour scale stays readable
            else:
                base = np.tile(_SAND, (n, 1))
            face = np.clip(base * shade[:, None], 0, 1)
            rgba = np.concatenate([face, np.ones((n, 1))], axis=1)[order]
            centres = x[order][:, [h, vax]] * mm
            diam = 2.0 * r[order] * mm
            # An outline helps separate touching discs, but at 1e5 spheres it would be all you see.
            lw = 0.3 if n <= 20000 else 0.0
            discs = EllipseCollection(
                diam,
                diam,
                np.zeros(n),
                units="xy",
                offsets=centres,
                offset_transform=ax.transData,
                facecolors=rgba,
                edgecolors=np.clip(rgba * [0.6, 0.6, 0.6, 1], 0, 1),
                linewidths=lw,
                zorder=2,
            )
            ax.add_collection(discs)
            lo = np.minimum(lo, (x[:, [h, vax]] - r[:, None]).min(axis=0) * mm)
            hi = np.maximum(hi, (x[:, [h, vax]] + r[:, None]).max(axis=0) * mm)
            if values is not None:
                sm = matplotlib.cm.ScalarMappable(norm=norm, cmap=cmap)
                fig.colorbar(sm, ax=ax, label=colour_label or "", shrink=0.8)
        for a, b, label in lines or ():
            seg = np.array([a, b], dtype=float) * mm
            ax.plot(seg[:, 0], seg[:, 1], color="tab:red", linewidth=1.6, zorder=3)
            if label:
                ax.annotate(
                    label,
                    seg[0],
                    color="tab:red",
                    fontsize=9,
                    ha="center",
                    va="bottom",
                    zorder=4,
                    xytext=(0, 6),
                    textcoords="offset points",
                )
        if frame is not None:
            lo, hi = np.asarray(frame[0], dtype=float) * mm, np.asarray(frame[1], dtype=float) * mm
        if not np.all(np.isfinite(lo)):
            lo, hi = np.array([-1.0, -1.0]), np.array([1.0, 1.0])
        pad = 0.03 * max(float(np.max(hi - lo)), 1e-6)
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
        ax.set_aspect("equal")
        ax.set_xlabel(f"{names[h]} [mm]")
        ax.set_ylabel(f"{names[vax]} [mm]")
        if title:
            ax.set_title(title)
        save_figure(fig, path, dpi=dpi, bbox_inches="tight")
    finally:
        plt.close(fig)
    return str(path)
