"""The one check of a whole scene, whatever route its values came by (a stage, ``--set``, a study's ``[fixed]`` and
factor values, or a :class:`~warpdem.scene.stage.SceneSpec` made in Python), run before anything is simulated.

The contact laws (:class:`~warpdem.engine.materials.Material`, :class:`~warpdem.engine.materials.Interaction`),
size distributions and regions check their own fields when they are made; this module checks what is left: the
run and measurement settings, the factories' counts and rates, the walls' meshes and keyframes, gravity and the
cross-field rules (phase ends increasing, an output interval sensible against the duration). A refused value
raises :class:`~warpdem.scene.stage.StageError` saying where it came from (``origin`` of its key), the key, the
value and what is allowed.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable

import numpy as np

from warpdem.engine.checks import check, is_finite, is_number, short
from warpdem.engine.solver import CLUMP_CONTACT_MASSES, SolverOptions

from .measure import PILE_GAP
from .stage import MEASURE_KINDS, NS, SceneSpec, StageError, _camel, _region, _sizes

MAX_OUTPUTS = 100_000
"""The most output frames a run may ask for (duration / output_interval): more is a mistyped interval (a frame
every nanosecond would never finish, and its checkpoint grows without end)."""

_SIZE_KEYS = ("radius", "mean", "std", "low", "high", "median", "sigma_log")
"""The fields of a factory's size distribution (``sizes``), each a stage attribute warpdem:factory:sizeFIELD."""

Origin = Callable[[str], str]
"""Where the value of an override-style key (``run.duration``, ``factory.pour.count``, ``wall.lid.rotations``)
came from, for a message: a stage's prim and attribute, ``--set``, a study's ``[fixed]``."""


def stage_origin(path: str) -> Origin:
    """The origin of a scene read from stage ``path``: the prim and the attribute each key is authored on."""

    def origin(key: str) -> str:
        kind, *rest = key.split(".")
        if kind in ("run", "measure"):
            return f"{path}: prim /World, attribute {NS}{kind}:{_camel(rest[0])}"
        if kind == "factory":
            if rest[1] in ("sizes", "region"):
                return f"{path}: prim /World/Factories/{rest[0]}"
            attr = rest[1]
            return f"{path}: prim /World/Factories/{rest[0]}, attribute {NS}factory:{_camel(attr)}"
        if kind == "wall":
            return f"{path}: prim /World/Walls/{rest[0]}"
        if kind == "gravity":
            return f"{path}: the UsdPhysics.Scene's gravity"
        return path

    return origin


def plain_origin(key: str) -> str:
    """The origin of a scene made in Python (the message names the field after it)."""
    return "scene"


def check_scene(spec: SceneSpec, origin: Origin = plain_origin) -> SceneSpec:
    """Refuse a scene that cannot run as asked (see the module docstring); returns ``spec``."""
    _check_run(spec, origin)
    _check_measure(spec, origin)
    for fac in spec.factories:
        _check_factory(spec, fac, origin)
    for wall in spec.walls:
        _check_wall(spec, wall, origin)
    _check(_finite_vector(spec.gravity, 3), origin, "gravity", spec.gravity, "three finite numbers [m/s^2]")
    return spec


def _finite_vector(value, n: int) -> bool:
    """True for ``n`` finite numbers (a sequence or an array of shape (n,))."""
    return _numbers(value) and np.asarray(value).shape == (n,) and bool(np.all(np.isfinite(np.asarray(value, float))))


def _numbers(value) -> bool:
    try:
        a = np.asarray(value)
    except (TypeError, ValueError):
        return False
    return a.dtype.kind in "iuf"


def _check(cond, origin: Origin, key: str, value, allowed: str) -> None:
    check(cond, origin(key), key, value, allowed, StageError)


def _number(origin: Origin, key: str, value, ok: Callable[[float], bool], allowed: str) -> None:
    _check(is_number(value) and is_finite(value) and ok(float(value)), origin, key, value, allowed)


def _integer(origin: Origin, key: str, value, minimum: int) -> None:
    ok = isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)) and value >= minimum
    _check(ok, origin, key, value, f"an integer >= {minimum}")


def _check_run(spec: SceneSpec, origin: Origin) -> None:
    run = spec.run
    _number(origin, "run.duration", run.duration, lambda v: v > 0, "a duration > 0 s")
    _number(
        origin, "run.dt_fraction", run.dt_fraction, lambda v: 0 < v <= 1, "a fraction of the Rayleigh time in (0, 1]"
    )
    _number(origin, "run.settle_energy", run.settle_energy, lambda v: v >= 0, "an energy >= 0 J (0: never settles)")
    _number(origin, "run.settle_after", run.settle_after, lambda v: v >= 0, "a time >= 0 s")
    _number(
        origin,
        "run.output_interval",
        run.output_interval,
        lambda v: v > 0 and run.duration / v <= MAX_OUTPUTS,
        f"an interval > 0 s giving at most {MAX_OUTPUTS:,} outputs over run.duration = {run.duration!r} s "
        f"(>= {run.duration / MAX_OUTPUTS:.3g} s)",
    )
    _number(origin, "run.impact_speed_min", run.impact_speed_min, lambda v: v >= 0, "a speed >= 0 m/s")
    _check(
        run.clump_contact_mass in CLUMP_CONTACT_MASSES,
        origin,
        "run.clump_contact_mass",
        run.clump_contact_mass,
        " or ".join(CLUMP_CONTACT_MASSES),
    )
    _number(origin, "run.skin_fraction", run.skin_fraction, lambda v: v > 0, "a fraction of the smallest radius > 0")
    for f in ("dt_margin", "dt_levels"):
        try:
            SolverOptions(**{f: getattr(run, f)})
        except ValueError as e:
            raise StageError(f"{origin('run.' + f)}: {str(e).split(': ', 1)[-1]}") from None


def _check_measure(spec: SceneSpec, origin: Origin) -> None:
    m = spec.measure
    _check(m.kind in MEASURE_KINDS, origin, "measure.kind", m.kind, ", ".join(MEASURE_KINDS))
    for f, ok, allowed in (
        ("base_height", lambda v: True, "a finite height [m]"),
        ("backstop_height", lambda v: True, "a finite height [m]"),
        (
            "force_limit",
            lambda v: v > 0 if m.kind == "press" else v >= 0,
            "a force > 0 N" if m.kind == "press" else "a force >= 0 N",
        ),
        ("packing_time", lambda v: v >= 0, "a time >= 0 s (0: not measured)"),
        ("packing_radius", lambda v: v > 0 if m.packing_time > 0 else v >= 0, "the container's inner radius > 0 m"),
        ("packing_margin", lambda v: v >= 0, "a margin >= 0 diameters (of a particle)"),
        ("pile_apart", lambda v: v == 0 or v >= PILE_GAP, f"0 (off) or a gap >= {PILE_GAP} (r_i + r_j)"),
        ("pour_radius", lambda v: v >= 0, "a radius >= 0 m (0: not checked)"),
        ("unload_speed", lambda v: v >= 0, "a speed >= 0 m/s (0: no unloading)"),
        ("hold_time", lambda v: v >= 0, "a time >= 0 s"),
        ("first_contact_window", lambda v: v >= 0, "a time >= 0 s (0: not split)"),
        ("drum_radius", lambda v: v > 0 if m.kind == "drum" else v >= 0, "a radius > 0 m"),
        ("average_from", lambda v: v >= 0, "a time >= 0 s"),
    ):
        _number(origin, "measure." + f, getattr(m, f), ok, allowed)
    for f in ("packing_base", "outlet_height"):
        v = getattr(m, f)
        _check(v is None or (is_number(v) and is_finite(v)), origin, "measure." + f, v, "a finite height [m] or unset")
    if m.kind == "drum":
        a = m.drum_axis
        horizontal = _numbers(a) and len(a) == 3 and math.hypot(a[0], a[1]) > 0 and a[2] == 0
        _check(horizontal, origin, "measure.drum_axis", a, "a horizontal direction (x, y, 0), not (0, 0, 0)")
    for f, n in (("center", 2), ("drum_center", 3), ("drum_axis", 3)):
        v = getattr(m, f)
        _check(_finite_vector(v, n), origin, "measure." + f, v, f"{n} finite numbers")
    ends = m.phase_ends
    _check(
        len(ends) == len(m.phase_names),
        origin,
        "measure.phase_ends",
        ends,
        f"one end time per phase ({len(m.phase_names)})",
    )
    ok = all(is_number(t) and is_finite(t) for t in ends) and all(b > a for a, b in zip([0.0, *ends], ends))
    _check(ok, origin, "measure.phase_ends", ends, "finite times > 0 s, each after the one before")
    if m.kind == "press":
        names = [w.name for w in spec.walls]
        _check(m.piston in names, origin, "measure.piston", m.piston, "a wall of the scene: " + ", ".join(names))


def _check_factory(spec: SceneSpec, fac, origin: Origin) -> None:
    key = f"factory.{fac.name}."
    for f in ("count",):
        if fac.count is not None:
            _integer(origin, key + f, fac.count, 1)
    _integer(origin, key + "seed", fac.seed, 0)
    for f, unit in (("mass", "kg"), ("rate", "particles/s"), ("mass_rate", "kg/s"), ("interval", "s")):
        v = getattr(fac, f)
        if v is not None:
            _number(origin, key + f, v, lambda x: x > 0, f"a value > 0 {unit} or unset")
    _number(origin, key + "start_time", fac.start_time, lambda v: v >= 0, "a time >= 0 s")
    v = fac.initial_velocity
    _check(_finite_vector(v, 3), origin, key + "initial_velocity", v, "three finite numbers [m/s]")
    _check((fac.count is None) != (fac.mass is None), origin, key + "count", fac.count, "exactly one of count or mass")
    if fac.mode == "dynamic":
        _check(
            (fac.rate is None) != (fac.mass_rate is None),
            origin,
            key + "rate",
            fac.rate,
            "exactly one of rate or mass_rate",
        )
    try:
        _sizes(fac.sizes)
    except (ValueError, KeyError, TypeError) as e:
        # the distribution names its field ("TruncatedNormal: mean = ..."): the factory's size_mean
        field = re.search(r": (\w+) = ", str(e))
        at = "size_" + field.group(1) if field and field.group(1) in _SIZE_KEYS else "sizes"
        raise StageError(f"{origin(key + at)}: factory {fac.name!r}: {e}") from None
    try:
        _region(fac.region)
    except (ValueError, KeyError, TypeError) as e:
        raise StageError(f"{origin(key + 'region')}: factory {fac.name!r}: {e}") from None
    names = [m.name for m in spec.materials]
    _check(
        fac.material in names, origin, key + "material", fac.material, "a material of the scene: " + ", ".join(names)
    )
    shapes = [s.name for s in spec.shapes]
    _check(fac.shape in shapes, origin, key + "shape", fac.shape, "a shape of the scene: " + ", ".join(shapes))


def _check_wall(spec: SceneSpec, wall, origin: Origin) -> None:
    key = f"wall.{wall.name}."
    v = np.asarray(wall.vertices, dtype=float) if _numbers(wall.vertices) else None
    ok = v is not None and v.ndim == 2 and v.shape[1] == 3 and len(v) >= 3 and bool(np.all(np.isfinite(v)))
    _check(ok, origin, key + "vertices", wall.vertices, "at least three finite points (V, 3) [m]")
    t = np.asarray(wall.triangles) if _numbers(wall.triangles) else None
    ok = t is not None and t.dtype.kind in "iu" and t.ndim == 2 and t.shape[1] == 3 and len(t) >= 1
    _check(
        ok and t.min() >= 0 and t.max() < len(v),
        origin,
        key + "triangles",
        wall.triangles,
        f"(F >= 1, 3) vertex indices in 0..{len(v) - 1}",
    )
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    size = float(np.ptp(v, axis=0).max())
    flat = np.flatnonzero(area <= 1e-12 * size * size)
    if flat.size:
        raise StageError(
            f"{origin(key + 'triangles')}: wall {wall.name!r}: {flat.size} of {len(t)} triangles have no area "
            f"(the first is face {int(flat[0])}, vertices {t[flat[0]].tolist()}); expected triangles of three "
            "distinct, non-collinear points: remove the degenerate faces"
        )
    names = [m.name for m in spec.materials]
    _check(
        wall.material in names, origin, key + "material", wall.material, "a material of the scene: " + ", ".join(names)
    )
    if wall.times is not None:
        times = np.asarray(wall.times, dtype=float)
        ok = (
            times.ndim == 1
            and len(times) >= 1
            and bool(np.all(np.isfinite(times)))
            and bool(np.all(np.diff(times) > 0))
        )
        _check(ok, origin, key + "times", times, "finite keyframe times [s], each after the one before")
        tr = np.asarray(wall.translations, dtype=float)
        _check(
            tr.shape == (len(times), 3) and bool(np.all(np.isfinite(tr))),
            origin,
            key + "translations",
            tr,
            "one finite (x, y, z) [m] per keyframe",
        )
        q = np.asarray(wall.rotations, dtype=float)
        ok = q.shape == (len(times), 4) and bool(np.all(np.isfinite(q)))
        bad = np.flatnonzero(~(np.abs(np.linalg.norm(q, axis=1) - 1.0) < 1e-6)) if ok else np.arange(len(times))
        if bad.size:
            k = int(bad[0])
            raise StageError(
                f"{origin(key + 'rotations')}: wall {wall.name!r}: the rotation of keyframe {k} (t = "
                f"{short(times[k]) if k < len(times) else '?'} s) = {short(q[k] if ok else q)} is not allowed; "
                "expected a unit quaternion (x, y, z, w), a rigid rotation"
            )
    if wall.coat is not None:
        c = wall.coat
        _number(origin, key + "coat.radius", c.get("radius"), lambda x: x > 0, "a radius > 0 m")
        _check(c.get("side", 1) in (1, -1), origin, key + "coat.side", c.get("side"), "1 or -1")
        s = c.get("spacing")
        _check(
            s is None or (is_number(s) and math.isfinite(s) and s > 0),
            origin,
            key + "coat.spacing",
            s,
            "a spacing > 0 m or unset",
        )
        _check(
            c.get("material") in names,
            origin,
            key + "coat.material",
            c.get("material"),
            "a material of the scene: " + ", ".join(names),
        )
