"""ModelBuilder: host-side scene description -> a Model on a device."""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import warp as wp

from warpdem.errors import InputError, PhysicsWarning
from warpdem.kernels.params import PairParams

from . import analytic, suspect
from .checks import vec3
from .keys import VARY, OverrideKey
from .materials import INTERACTION_ENUMS, Interaction, InteractionTable, Material, pair_table
from .motion import WallMotion
from .types import ContactLaw, Model

_GRAVITY = OverrideKey("gravity")

GLUED_VOLUME = 1.0e12
"""Body volume [m^3] of a sphere glued to a wall: its mass exceeds any particle's by > 1e10, so a contact's
reduced mass is the particle's to float32 precision, while products of masses stay finite in float32."""


class ModelBuilder:
    """Collects materials, spheres and walls of one world, then replicates and finalises.

    Example::

        b = ModelBuilder()
        b.add_material(Material("glass", density=2500, youngs_modulus=5e7, poisson_ratio=0.25))
        b.set_interaction("glass", "glass", restitution=0.5, static_friction=0.5)
        b.add_plane((0, 0, 0), (0, 0, 1), "glass")
        b.add_sphere((0, 0, 0.01), 0.002, "glass")
        model = b.finalize("cpu")
    """

    def __init__(self, gravity=(0.0, 0.0, -9.81)):
        self.gravity = np.array(vec3("ModelBuilder", "gravity", gravity))
        self.materials: list[Material] = []
        self.interactions = InteractionTable()
        self._x, self._r, self._mat, self._v, self._w = [], [], [], [], []
        self._clump, self._offset, self._body_volume, self._active = [], [], [], []
        self._glued = []  # wall a sphere is glued to, -1 for none
        # clumps: centre, orientation (x, y, z, w), velocity, angular velocity, first sphere, material, template
        self._cx, self._cq, self._cv, self._cw, self._cfirst, self._cmat, self._ctemplate = [], [], [], [], [], [], []
        self._cscale = []
        self._templates = []  # ClumpTemplate objects, index = template id
        self._planes = []  # (point, normal, material, world)
        self._walls = []  # (vertices, triangles, material, world, name, motion)
        self._factories = []
        self.world_count = 1
        self._variations = {}
        self._world_seeds = None
        self._domain = None
        self._stacked: list[ModelBuilder] = []

    # materials -------------------------------------------------------------------------------
    def add_material(self, material: Material) -> int:
        """Add a material; returns its index. Names are unique."""
        if not isinstance(material, Material):
            raise TypeError(f"add_material: expected a Material, got {type(material).__name__}")
        if any(m.name == material.name for m in self.materials):
            raise InputError(f"add_material: a material named {material.name!r} exists already")
        self.materials.append(material)
        return len(self.materials) - 1

    def material_index(self, material) -> int:
        """Index of a material given by name, index or object."""
        if isinstance(material, Material):
            material = material.name
        if isinstance(material, (int, np.integer)):
            if 0 <= int(material) < len(self.materials):
                return int(material)
        else:
            for k, m in enumerate(self.materials):
                if m.name == material:
                    return k
        names = ", ".join(m.name for m in self.materials) or "none yet"
        raise InputError(f"material = {material!r} is not defined; defined materials: {names}")

    def set_interaction(self, a, b, interaction: Interaction | None = None, **kwargs) -> Interaction:
        """Set the contact parameters of materials ``a`` and ``b`` (see :class:`Interaction`)."""
        na = self.materials[self.material_index(a)].name
        nb = self.materials[self.material_index(b)].name
        return self.interactions.set(na, nb, interaction, **kwargs)

    def set_default_interaction(self, interaction: Interaction | None = None, **kwargs) -> None:
        """Interaction used for every pair not set explicitly."""
        self.interactions.default = (
            interaction if interaction is not None else dataclasses.replace(self.interactions.default, **kwargs)
        )

    # bodies and walls ------------------------------------------------------------------------
    def add_sphere(
        self, position, radius: float, material, velocity=(0, 0, 0), angular_velocity=(0, 0, 0), world: int = 0
    ) -> int:
        """Add one sphere: centre [m], radius [m], velocity [m/s], angular velocity [rad/s]; returns its index."""
        return int(self.add_spheres([position], radius, material, [velocity], [angular_velocity], world)[0])

    def add_spheres(
        self, positions, radius, material, velocities=None, angular_velocities=None, world: int = 0
    ) -> np.ndarray:
        """Add spheres; ``positions`` shape (n, 3) [m], ``radius`` scalar or shape (n,) [m]. Returns their indices."""
        x = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        n = x.shape[0]
        r = np.broadcast_to(np.asarray(radius, dtype=np.float64), (n,)).copy()
        if not np.all(np.isfinite(x)):
            raise InputError("add_spheres: positions contain a non-finite value")
        bad = np.flatnonzero(~(np.isfinite(r) & (r > 0)))
        if bad.size:
            raise InputError(
                f"add_spheres: radius = {float(r[bad[0]])!r} (sphere {bad[0]}) is not allowed; expected a radius > 0 m"
            )
        v = np.zeros((n, 3)) if velocities is None else np.asarray(velocities, dtype=np.float64).reshape(n, 3)
        w = (
            np.zeros((n, 3))
            if angular_velocities is None
            else np.asarray(angular_velocities, dtype=np.float64).reshape(n, 3)
        )
        if not (np.all(np.isfinite(v)) and np.all(np.isfinite(w))):
            raise InputError("add_spheres: velocities contain a non-finite value")
        if int(world) != 0:
            raise InputError(
                f"add_spheres: world = {world!r} is not allowed; build world 0 and call replicate(world_count)"
            )
        mat = self.material_index(material)
        start = len(self._r)
        self._x.extend(x)
        self._r.extend(r)
        self._v.extend(v)
        self._w.extend(w)
        self._mat.extend([mat] * n)
        self._clump.extend([-1] * n)
        self._offset.extend(np.zeros((n, 3)))
        self._body_volume.extend(4.0 / 3.0 * np.pi * r**3)
        self._active.extend([1] * n)
        self._glued.extend([-1] * n)
        return np.arange(start, start + n)

    def attach_spheres(self, wall, positions, radius, material) -> np.ndarray:
        """Glue spheres to a mesh wall (a particle-coated surface, as seed 002 glues ore grains to its lifting
        cylinder and base): ``positions`` shape (n, 3) [m] in the wall's own frame, ``radius`` scalar or (n,) [m].
        Glued spheres move with the wall, are infinitely heavy for the particles they touch and pass those
        contact forces to the wall's force and torque. Returns their indices."""
        k = self._wall_index(wall, "attach_spheres")
        idx = self.add_spheres(positions, radius, material)
        for i in idx:
            self._glued[i] = k
            self._offset[i] = np.asarray(self._x[i], dtype=np.float64)
            self._body_volume[i] = GLUED_VOLUME
        # the glued spheres start where the wall's pose at t = 0 puts them (placed by the solver's first step)
        return idx

    def coat_wall(
        self, wall, radius: float, material, spacing: float | None = None, side: float = 1.0, seed: int = 0
    ) -> np.ndarray:
        """Cover a mesh wall with glued spheres of ``radius`` [m], centres ``radius`` off the surface on the side
        of the triangle normals (right-hand winding; ``side = -1`` for the other side), at least ``spacing`` [m]
        apart (default 2 x radius: touching neighbours), by seeded random sequential placement. Returns the
        sphere indices (see :meth:`attach_spheres`)."""
        from scipy.spatial import cKDTree

        k = self._wall_index(wall, "coat_wall")
        if not (np.isfinite(radius) and radius > 0):
            raise InputError(f"coat_wall: radius = {radius!r} is not allowed; expected a radius > 0 m")
        spacing = 2.0 * radius if spacing is None else float(spacing)
        if not (np.isfinite(spacing) and spacing > 0):
            raise InputError(f"coat_wall: spacing = {spacing!r} is not allowed; expected a distance > 0 m")
        if side not in (1, -1, 1.0, -1.0):
            raise InputError(f"coat_wall: side = {side!r} is not allowed; expected 1 or -1")
        verts, tris = self._walls[k][0], self._walls[k][1]
        a, b, c = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
        cross = np.cross(b - a, c - a)
        area = 0.5 * np.linalg.norm(cross, axis=1)
        normal = cross / np.maximum(2.0 * area, 1e-300)[:, None]
        rng = np.random.default_rng(seed)
        # candidates: about 8 per final sphere, uniform over the surface area
        n_cand = int(max(16, 8 * area.sum() / (0.866 * spacing**2)))
        face = rng.choice(len(tris), size=n_cand, p=area / area.sum())
        u, v = rng.random(n_cand), rng.random(n_cand)
        flip = u + v > 1
        u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
        pts = a[face] + u[:, None] * (b - a)[face] + v[:, None] * (c - a)[face] + side * radius * normal[face]
        taken = np.zeros(n_cand, dtype=bool)
        blocked = np.zeros(n_cand, dtype=bool)
        near = cKDTree(pts).query_ball_point(pts, spacing * (1 - 1e-9))
        for i in range(n_cand):
            if not blocked[i]:
                taken[i] = True
                blocked[near[i]] = True
        return self.attach_spheres(k, pts[taken], radius, material)

    def _wall_index(self, wall, where: str) -> int:
        if isinstance(wall, str):
            for k, w in enumerate(self._walls):
                if w[4] == wall:
                    return k
        elif isinstance(wall, (int, np.integer)) and 0 <= int(wall) < len(self._walls):
            return int(wall)
        names = ", ".join(repr(w[4]) for w in self._walls) or "none yet"
        raise InputError(f"{where}: wall = {wall!r} is not a mesh wall; defined walls: {names}")

    def add_clump(
        self, template, position, material, orientation=(0, 0, 0, 1), velocity=(0, 0, 0), angular_velocity=(0, 0, 0)
    ) -> int:
        """Add one rigid clump; returns its index. See :meth:`add_clumps`."""
        return int(self.add_clumps(template, [position], material, [orientation], [velocity], [angular_velocity])[0])

    def add_clumps(
        self,
        template,
        positions,
        material,
        orientations=None,
        velocities=None,
        angular_velocities=None,
        active: bool = True,
        scale=None,
    ) -> np.ndarray:
        """Add rigid multi-sphere clumps of one template.

        Args:
            template: a :class:`warpdem.ClumpTemplate` (offsets in its principal frame, centre of mass at 0).
            positions: centres of mass [m], shape (n, 3).
            material: material of every sphere of the clumps.
            orientations: quaternions (x, y, z, w) body -> world, shape (n, 4); identity when None.
            velocities: [m/s], shape (n, 3); angular_velocities: [rad/s], world frame, shape (n, 3).
            active: False adds them parked (a factory releases them later).
            scale: size factor per clump, shape (n,) or scalar (offsets and radii x s, volume x s^3, inertia x s^5).

        Returns:
            the clump indices, shape (n,).
        """
        for name in ("sphere_offset", "sphere_radius", "volume", "inertia_unit"):
            if not hasattr(template, name):
                raise TypeError(
                    f"add_clumps: template = {template!r} is not allowed; expected a ClumpTemplate (missing {name})"
                )
        x = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        n = len(x)
        q = (
            np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
            if orientations is None
            else np.asarray(orientations, dtype=np.float64).reshape(n, 4)
        )
        v = np.zeros((n, 3)) if velocities is None else np.asarray(velocities, dtype=np.float64).reshape(n, 3)
        w = (
            np.zeros((n, 3))
            if angular_velocities is None
            else np.asarray(angular_velocities, dtype=np.float64).reshape(n, 3)
        )
        for name, arr in (("positions", x), ("orientations", q), ("velocities", v), ("angular_velocities", w)):
            if not np.all(np.isfinite(arr)):
                raise InputError(f"add_clumps: {name} contain a non-finite value")
        s = np.broadcast_to(np.asarray(1.0 if scale is None else scale, dtype=np.float64), (n,)).copy()
        if not np.all(np.isfinite(s) & (s > 0)):
            raise InputError(f"add_clumps: scale = {scale!r} is not allowed; expected factors > 0")
        norms = np.linalg.norm(q, axis=1)
        if np.any(norms < 1e-6):
            raise InputError(
                "add_clumps: orientations contain a zero quaternion; expected unit quaternions (x, y, z, w)"
            )
        q = q / norms[:, None]
        mat = self.material_index(material)
        tid = next((k for k, t in enumerate(self._templates) if t is template), None)
        if tid is None:
            self._templates.append(template)
            tid = len(self._templates) - 1
        offsets = np.asarray(template.sphere_offset, dtype=np.float64).reshape(-1, 3)
        radii = np.asarray(template.sphere_radius, dtype=np.float64).reshape(-1)
        k = len(radii)
        c0 = len(self._cx)
        # arms[i, s]: offset s of clump i rotated into the world (vectorised: a factory may add 10^6 clumps)
        u, qw = q[:, None, :3], q[:, None, 3:4]
        scaled = offsets[None, :, :] * s[:, None, None]
        tmp = 2.0 * np.cross(u, scaled)
        arms = scaled + qw * tmp + np.cross(u, tmp)
        self._cfirst.extend(len(self._r) + k * np.arange(n))
        self._cx.extend(x)
        self._cq.extend(q)
        self._cv.extend(v)
        self._cw.extend(w)
        self._cmat.extend([mat] * n)
        self._ctemplate.extend([tid] * n)
        self._cscale.extend(s)
        self._x.extend((x[:, None, :] + arms).reshape(-1, 3))
        self._r.extend((radii[None, :] * s[:, None]).reshape(-1))
        self._v.extend((v[:, None, :] + np.cross(w[:, None, :], arms)).reshape(-1, 3))
        self._w.extend(np.repeat(w, k, axis=0))
        self._mat.extend([mat] * (n * k))
        self._clump.extend(np.repeat(np.arange(c0, c0 + n), k))
        self._offset.extend(scaled.reshape(-1, 3))
        self._body_volume.extend(np.repeat(float(template.volume) * s**3, k))
        self._active.extend([int(bool(active))] * (n * k))
        self._glued.extend([-1] * (n * k))
        ids = np.arange(c0, c0 + n)
        return np.asarray(ids, dtype=np.int64)

    @property
    def clump_count(self) -> int:
        return len(self._cx)

    # factories ------------------------------------------------------------------------------
    def _existing(self):
        """Centres [m] and bounding radii [m] of every sphere added so far (clump spheres included)."""
        if not self._r:
            return None, None
        active = np.asarray(self._active, dtype=bool)
        return np.asarray(self._x, dtype=np.float64)[active], np.asarray(self._r, dtype=np.float64)[active]

    def fill(
        self,
        region,
        sizes,
        material,
        count: int | None = None,
        mass: float | None = None,
        seed: int = 0,
        template=None,
        velocity=(0.0, 0.0, 0.0),
        max_attempts: int = 10000,
    ) -> np.ndarray:
        """Static factory: fill ``region`` (Box, Cylinder, Cone) with non-overlapping particles now.

        ``sizes`` (FixedSize, TruncatedNormal, LogNormal, SieveTable) gives sphere radii, or for clumps the
        volume-equivalent radius of each scaled ``template``; ``count`` particles, or ``mass`` [kg] within
        one particle (a clump's equivalent radius carries its union volume, so mass targets hold for clumps too).
        Clumps get uniform random orientations. Returns the new sphere (or clump) indices.
        """
        from .factories import fill_region

        density = self.materials[self.material_index(material)].density
        ex_x, ex_r = self._existing()
        ratio = 1.0 if template is None else template.bounding_radius / template.equivalent_radius
        out = fill_region(
            region,
            sizes,
            count=count,
            mass=mass,
            density=density,
            rng_seed=seed,
            existing_x=ex_x,
            existing_r=ex_r,
            max_attempts=max_attempts,
            bounding_ratio=ratio,
            orientations=template is not None,
        )
        x, r = out[0], out[1]
        v = np.tile(np.asarray(velocity, dtype=np.float64), (len(r), 1))
        if template is None:
            return self.add_spheres(x, r, material, velocities=v)
        return self.add_clumps(
            template, x, material, orientations=out[2], velocities=v, scale=r / template.equivalent_radius
        )

    def add_factory(self, factory, material, template=None) -> int:
        """Dynamic factory: preallocate its ``capacity()`` particles, parked and inactive, for the solver's
        :meth:`Solver.advance` to release on the factory's schedule. Returns the factory index."""
        from .factories import DynamicFactory

        if not isinstance(factory, DynamicFactory):
            raise InputError(f"add_factory: factory = {factory!r} is not allowed; expected a DynamicFactory")
        if template is not None:
            need = template.bounding_radius / template.equivalent_radius
            if factory.bounding_ratio < need * (1 - 1e-9):
                raise InputError(
                    f"add_factory: factory.bounding_ratio = {factory.bounding_ratio!r} is not allowed for "
                    f"template {template.name!r}; expected at least its bounding / equivalent radius "
                    f"= {need:.6g}, or released clumps could overlap"
                )
        n = factory.capacity()
        r = np.asarray(factory.radii, dtype=np.float64)
        bound = r if template is None else r * template.bounding_radius / template.equivalent_radius
        # parked far below the scene on a sparse lattice, so that they crowd no hash cell
        spacing = 3.0 * float(bound.max())
        side = int(math.ceil(n ** (1.0 / 3.0)))
        k = np.arange(n)
        park = np.stack([k % side, (k // side) % side, k // (side * side)], axis=1) * spacing
        park = park + np.array([0.0, 0.0, -1.0e3 - len(self._factories) * (side + 2) * spacing])
        if template is None:
            first = self.sphere_count
            self.add_spheres(park, r, material)
            self._active[first : first + n] = [0] * n
            kind = "sphere"
        else:
            first = self.clump_count
            self.add_clumps(
                template,
                park,
                material,
                orientations=factory.quaternions,
                active=False,
                scale=r / template.equivalent_radius,
            )
            kind = "clump"
        self._factories.append(
            {
                "factory": factory,
                "kind": kind,
                "first": first,
                "count": n,
                "material": self.material_index(material),
                "template": template,
            }
        )
        return len(self._factories) - 1

    def add_plane(self, point, normal, material, world: int = -1) -> int:
        """Add an infinite plane through ``point`` [m] whose ``normal`` points to the particle side."""
        p = np.array(vec3("add_plane", "point", point))
        nrm = np.array(vec3("add_plane", "normal", normal))
        length = np.linalg.norm(nrm)
        if length == 0:
            raise InputError("add_plane: normal = (0, 0, 0) is not allowed; expected a non-zero vector")
        self._planes.append((p, nrm / length, self.material_index(material), int(world)))
        return len(self._planes) - 1

    def add_wall_mesh(
        self, vertices, triangles, material, name: str | None = None, world: int = -1, motion: WallMotion | None = None
    ) -> int:
        """Add a rigid triangle-mesh wall: ``vertices`` shape (v, 3) [m], ``triangles`` shape (t, 3) int.

        Triangles are two-sided: a sphere is pushed away from whichever side it touches. ``motion``
        (a :class:`warpdem.WallMotion`, static when None) moves the wall; the vertices are given in the
        wall's own frame, which for the velocity and rotation forms coincides with the world at t = 0.
        """
        if motion is None:
            motion = WallMotion.static()
        if not isinstance(motion, WallMotion):
            raise InputError(f"add_wall_mesh: motion = {motion!r} is not allowed; expected a WallMotion or None")
        verts = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
        tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
        label = name or f"wall{len(self._walls)}"
        if tris.size == 0:
            raise InputError(f"add_wall_mesh {label!r}: triangles is empty; expected at least one triangle")
        if tris.min() < 0 or tris.max() >= len(verts):
            raise InputError(f"add_wall_mesh {label!r}: triangles index {int(tris.max())} outside 0..{len(verts) - 1}")
        if not np.all(np.isfinite(verts)):
            raise InputError(f"add_wall_mesh {label!r}: vertices contain a non-finite value")
        self._walls.append((verts, tris, self.material_index(material), int(world), label, motion))
        return len(self._walls) - 1

    @property
    def sphere_count(self) -> int:
        return len(self._r)

    # batching --------------------------------------------------------------------------------
    def set_domain(self, low, high) -> None:
        """Simulation domain: the box from ``low`` to ``high`` ((x, y, z) [m]), the same in every world. A body
        (clump or free sphere) whose centre leaves it is removed at the next list rebuild and counted in
        ``State.world_removed``. Without a domain nothing is removed."""
        lo, hi = np.array(vec3("set_domain", "low", low)), np.array(vec3("set_domain", "high", high))
        if not np.all(lo < hi):
            raise InputError(
                f"set_domain: low = {tuple(lo.tolist())} and high = {tuple(hi.tolist())} are not "
                "allowed; expected low < high on every axis"
            )
        self._domain = (tuple(float(v) for v in lo), tuple(float(v) for v in hi))

    def replicate(self, world_count: int) -> None:
        """Make ``world_count`` identical copies of the scene, all at the origin (kept apart by world id)."""
        if int(world_count) < 1:
            raise InputError(f"replicate: world_count = {world_count!r} is not allowed; expected an integer >= 1")
        self.world_count = int(world_count)

    def vary(self, target: str, values) -> None:
        """Give a scalar parameter one value per world.

        ``target`` is ``material.NAME.FIELD`` (any of ``MATERIAL_SCALARS``), ``interaction.A.B.FIELD`` (any
        Interaction field: a number, or for ``law`` and ``rolling_model`` a member or its name) or ``gravity``
        (values shape (world_count, 3)); see :mod:`warpdem.engine.keys`. A value None keeps that world's value
        as the scene sets it. Call after :meth:`replicate`.
        """
        vals = list(values)
        if len(vals) != self.world_count:
            raise InputError(f"vary {target!r}: {len(vals)} values given; expected world_count = {self.world_count}")
        key = VARY.parse(target, "vary", "target", defined={"material": [m.name for m in self.materials]})
        if key != _GRAVITY:
            vals = [_world_value(key, target, v) for v in vals]
        self._variations[key] = vals

    def seed_worlds(self, seeds) -> None:
        """Give each world its own placement seed for the dynamic factories (integers >= 0, one per world;
        0 keeps the factory's own stream). The engine is deterministic, so repeats of one design point (centre
        points, replicates) batched as worlds differ only through these seeds. Call after :meth:`replicate`."""
        vals = [int(v) for v in seeds]
        if len(vals) != self.world_count:
            raise InputError(f"seed_worlds: {len(vals)} seeds given; expected world_count = {self.world_count}")
        bad = [v for v in vals if v < 0]
        if bad:
            raise InputError(f"seed_worlds: seed = {bad[0]} is not allowed; expected integers >= 0")
        self._world_seeds = vals

    def _world_tables(self):
        """Materials and interaction tables per world (length 1 when nothing varies)."""
        varied = [key for key in self._variations if key != _GRAVITY]
        count = self.world_count if varied else 1
        mats_w, tables_w = [], []
        for w in range(count):
            mats = list(self.materials)
            table = InteractionTable(self.interactions.default, dict(self.interactions.pairs))
            for key in varied:
                value = self._variations[key][w]
                if value is None:
                    continue
                if key.kind == "material":
                    k = self.material_index(key.names[0])
                    mats[k] = mats[k].with_value(key.field, value)
                else:
                    a, b = key.names
                    table.set(a, b, table.get(a, b), **{key.field: value})
            mats_w.append(mats)
            tables_w.append(table)
        return mats_w, tables_w

    def stack(self, other: ModelBuilder) -> None:
        """Append the worlds of ``other`` (its replicas, variations and world seeds) after this builder's, so that
        scenes that differ in their particles (grain size, shape, count, feed rate) run as one Model: one launch
        instead of one each, which on a GPU costs little more than the largest alone. World k of ``other`` is
        world ``self.world_count + k`` of the Model (after earlier stacks).

        Both must define the same materials, interactions, planes and gravity, and the same walls by name and
        order; a wall that differs between them (a gate placed by the grain size) becomes one wall per world.
        The Model's domain is the union of the domains. The Model steps every world at the shortest step any
        needs (its smallest grain), so a world matches its solo run exactly only when that is its own step.
        Call once both are complete; stacking is not undone.
        """
        if not isinstance(other, ModelBuilder) or other is self or other in self._stacked:
            raise InputError(f"stack: other = {other!r} is not allowed; expected another, complete ModelBuilder")
        what = None
        if [m.name for m in other.materials] != [m.name for m in self.materials] or other.materials != self.materials:
            what = "materials"
        elif other.interactions != self.interactions:
            what = "interactions"
        elif not np.array_equal(other.gravity, self.gravity):
            what = "gravity"
        elif len(other._planes) != len(self._planes) or any(
            not (np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]) and a[2:] == b[2:])
            for a, b in zip(self._planes, other._planes)
        ):
            what = "planes"
        elif [w[4] for w in other._walls] != [w[4] for w in self._walls]:
            what = "wall names"
        elif other._stacked:
            what = "stacked worlds of its own"
        if what is not None:
            raise InputError(f"stack: the other scene has different {what}; expected the same as this one's")
        if self._domain is None or other._domain is None:
            self._domain = None
        else:
            lo = np.minimum(self._domain[0], other._domain[0])
            hi = np.maximum(self._domain[1], other._domain[1])
            self._domain = (tuple(map(float, lo)), tuple(map(float, hi)))
        self._stacked.append(other)

    @staticmethod
    def _same_wall(a, b) -> bool:
        return np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]) and a[2:5] == b[2:5] and a[5] == b[5]

    # finalise --------------------------------------------------------------------------------
    def _warn_start_overlaps(self) -> None:
        """Warn when spheres of different bodies overlap as placed (every world starts from these places; a
        dynamic factory's spheres are placed apart when released)."""
        active = np.asarray(self._active, dtype=bool) & (np.asarray(self._glued) < 0)
        n = len(self._r)
        clump = np.asarray(self._clump, dtype=np.int64)
        body = np.where(clump >= 0, clump, n + np.arange(n))[active]
        x = np.asarray(self._x, dtype=np.float64).reshape(-1, 3)[active]
        r = np.asarray(self._r, dtype=np.float64)[active]
        found = suspect.overlaps(x, r, np.zeros(len(r), dtype=np.int64), body, 1)
        words = suspect.start_overlap_words({k: v[0] for k, v in found.items()})
        if words:
            warnings.warn(words, PhysicsWarning, stacklevel=3)

    def finalize(self, device: str = "cpu", warn_overlaps: bool = True) -> Model:
        """Build the Model on ``device`` ("cpu" or "cuda[:n]"): this builder's worlds, then those of each
        :meth:`stack` ed builder. ``warn_overlaps``: warn when spheres of different bodies overlap as placed
        (:mod:`warpdem.engine.suspect`; a caller that checks the state itself, as the scene runner, passes
        False)."""
        if not self.materials:
            raise InputError("finalize: no material defined; call add_material first")
        groups = [self, *self._stacked]
        for g in groups:
            if g.sphere_count == 0:
                raise InputError("finalize: the scene has no sphere")
        for g in groups if warn_overlaps else ():
            g._warn_start_overlaps()
        device = str(wp.get_device(device))
        W = sum(g.world_count for g in groups)
        world0 = np.cumsum([0] + [g.world_count for g in groups])
        sphere0 = np.cumsum([0] + [g.sphere_count * g.world_count for g in groups])
        clump0 = np.cumsum([0] + [g.clump_count * g.world_count for g in groups])
        template0 = np.cumsum([0] + [len(g._templates) for g in groups])

        # walls: one shared by every world where the scenes agree, else one per world (index per group and world)
        walls, wall_of = [], [[[] for _ in range(g.world_count)] for g in groups]
        for j, wall in enumerate(self._walls):
            if all(self._same_wall(wall, g._walls[j]) for g in groups[1:]):
                for per_world in wall_of:
                    for lst in per_world:
                        lst.append(len(walls))
                walls.append(wall)
                continue
            for gi, g in enumerate(groups):
                verts, tris, mat, own, name, motion = g._walls[j]
                for w in range(g.world_count):
                    if own < 0 or own == w:
                        wall_of[gi][w].append(len(walls))
                        walls.append((verts, tris, mat, int(world0[gi] + w), name, motion))
                    else:
                        wall_of[gi][w].append(-1)

        def per_world(values, dtype, g, width=None):
            a = np.asarray(values, dtype=dtype)
            a = a.reshape(-1, width) if width else a.reshape(-1)
            return np.tile(a, (g.world_count, 1)) if width else np.tile(a, g.world_count)

        def cat(parts, dtype, width=None):
            parts = [p for p in parts if len(p)]
            if parts:
                return np.concatenate(parts).astype(dtype)
            return np.zeros((0, width) if width else 0, dtype=dtype)

        radius, material, world, sphere_clump, sphere_wall, offset, body_volume = [], [], [], [], [], [], []
        starts, ends, cscale, ctpl, cmat, cworld, seeds, factories, templates = [], [], [], [], [], [], [], [], []
        init = {k: [] for k in ("sphere_x", "sphere_v", "sphere_w", "sphere_active")}
        cinit = {k: [] for k in ("clump_x", "clump_q", "clump_v", "clump_w")}
        mats_w, tables_w, gravity_w = [], [], []
        for gi, g in enumerate(groups):
            n, c, Wg = g.sphere_count, g.clump_count, g.world_count
            radius.append(per_world(g._r, np.float32, g))
            material.append(per_world(g._mat, np.int32, g))
            world.append(np.repeat(np.arange(Wg, dtype=np.int32) + world0[gi], n))
            local = np.asarray(g._clump, dtype=np.int64)
            sphere_clump.append(
                np.concatenate([np.where(local >= 0, local + clump0[gi] + w * c, -1) for w in range(Wg)])
            )
            glued = np.asarray(g._glued, dtype=np.int64)
            sphere_wall.append(
                np.concatenate([np.where(glued >= 0, np.asarray(wall_of[gi][w] + [-1])[glued], -1) for w in range(Wg)])
            )
            offset.append(per_world(g._offset, np.float32, g, 3))
            body_volume.append(per_world(g._body_volume, np.float32, g))
            if c:
                cfirst = np.asarray(g._cfirst, dtype=np.int64)
                tpl = np.asarray(g._ctemplate, dtype=np.int64)
                clen = np.array([len(g._templates[t].sphere_radius) for t in tpl], dtype=np.int64)
                starts.append(np.concatenate([cfirst + sphere0[gi] + w * n for w in range(Wg)]))
                ends.append(np.concatenate([cfirst + clen + sphere0[gi] + w * n for w in range(Wg)]))
                cscale.append(per_world(g._cscale, np.float64, g))
                ctpl.append(per_world(tpl + template0[gi], np.int64, g))
                cmat.append(per_world(g._cmat, np.int32, g))
                cworld.append(np.repeat(np.arange(Wg, dtype=np.int32) + world0[gi], c))
                for key, src, width in (("clump_x", g._cx, 3), ("clump_q", g._cq, 4), ("clump_v", g._cv, 3)):
                    cinit[key].append(per_world(src, np.float32, g, width))
                cinit["clump_w"].append(per_world(g._cw, np.float32, g, 3))
            templates += g._templates
            seeds.append(np.asarray(g._world_seeds if g._world_seeds is not None else [0] * Wg, dtype=np.int64))
            for key, src, width in (("sphere_x", g._x, 3), ("sphere_v", g._v, 3), ("sphere_w", g._w, 3)):
                init[key].append(per_world(src, np.float32, g, width))
            init["sphere_active"].append(per_world(g._active, np.int32, g))
            for rec in g._factories:
                # where world w's copy of the factory's particles starts (-1: the world has no such factory)
                first = np.full(W, -1, dtype=np.int64)
                base, size = (sphere0[gi], n) if rec["kind"] == "sphere" else (clump0[gi], c)
                first[world0[gi] : world0[gi] + Wg] = base + np.arange(Wg) * size + rec["first"]
                factories.append({**rec, "world_first": first})
            m_g, t_g = g._world_tables()
            mats_w.append(m_g)
            tables_w.append(t_g)
            grav = g._variations.get(_GRAVITY)
            gravity_w.append(
                np.asarray(grav, dtype=np.float32).reshape(Wg, 3)
                if grav is not None
                else np.tile(g.gravity.astype(np.float32), (Wg, 1))
            )
        radius, material = cat(radius, np.float32), cat(material, np.int32)
        world, sphere_clump = cat(world, np.int32), cat(sphere_clump, np.int32)
        sphere_wall = cat(sphere_wall, np.int32)
        attached = np.flatnonzero(sphere_wall >= 0).astype(np.int32)
        if len(groups) == 1:
            mats_w, tables_w = mats_w[0], tables_w[0]
            gravity = gravity_w[0] if _GRAVITY in self._variations else self.gravity.astype(np.float32).reshape(1, 3)
        else:
            # a table per world once the scenes differ in it (length 1 per group when nothing varies)
            mats_w = [m for g, ms in zip(groups, mats_w) for m in (ms if len(ms) > 1 else ms * g.world_count)]
            tables_w = [t for g, ts in zip(groups, tables_w) for t in (ts if len(ts) > 1 else ts * g.world_count)]
            gravity = np.concatenate(gravity_w).astype(np.float32)
        params = pair_table(mats_w, tables_w)
        density = np.array([[m.density for m in mats] for mats in mats_w], dtype=np.float32)

        pp = wp.empty(params.shape, dtype=PairParams, device=device)
        host = pp.numpy()
        for name in params.dtype.names:
            host[name] = params[name]
        pp.assign(wp.array(host, dtype=PairParams, device="cpu"))

        planes = self._planes
        plane_point = np.array([p[0] for p in planes], dtype=np.float32).reshape(-1, 3)
        plane_normal = np.array([p[1] for p in planes], dtype=np.float32).reshape(-1, 3)
        plane_material = np.array([p[2] for p in planes], dtype=np.int32)
        plane_world = np.array([p[3] for p in planes], dtype=np.int32)

        meshes, face_start, tri_wall, wall_radius = [], [0], [], []
        for k, (v, t, *_rest) in enumerate(walls):
            meshes.append(
                wp.Mesh(
                    points=wp.array(v.astype(np.float32), dtype=wp.vec3, device=device),
                    indices=wp.array(t.astype(np.int32).reshape(-1), dtype=int, device=device),
                )
            )
            face_start.append(face_start[-1] + len(t))
            tri_wall.append(np.full(len(t), k, dtype=np.int32))
            wall_radius.append(float(np.linalg.norm(v, axis=1).max()))
        triangle_wall = np.concatenate(tri_wall) if tri_wall else np.zeros(0, dtype=np.int32)
        wall_material = np.array([w[2] for w in walls], dtype=np.int32)
        wall_world = np.array([w[3] for w in walls], dtype=np.int32)

        C = int(clump0[-1])
        cscale, ctpl = cat(cscale, np.float64), cat(ctpl, np.int64)
        if C:
            tvol = np.array([t.volume for t in templates], dtype=np.float64)
            tinertia = np.array([np.asarray(t.inertia_unit, dtype=np.float64) for t in templates]).reshape(-1, 3)
            cvol = (tvol[ctpl] * cscale**3).astype(np.float32)
            cinertia = (tinertia[ctpl] * cscale[:, None] ** 5).astype(np.float32)
            starts, ends = cat(starts, np.int32), cat(ends, np.int32)
        else:
            cvol, cinertia = np.zeros(0, np.float32), np.zeros((0, 3), np.float32)
            starts = ends = np.zeros(1, dtype=np.int32)

        r_min = float(radius.min())
        used = sorted({k for g in groups for k in g._mat})
        rayleigh = min(mats[k].rayleigh_time(r_min) for mats in mats_w for k in used)
        reach = contact_reach(params, float(radius.max()))

        model = Model(
            device=device,
            world_count=W,
            sphere_count=len(radius),
            material_count=len(self.materials),
            sphere_radius=wp.array(radius, dtype=float, device=device),
            sphere_material=wp.array(material, dtype=int, device=device),
            sphere_world=wp.array(world, dtype=int, device=device),
            material_density=wp.array(density, dtype=float, device=device),
            pair_params=pp,
            world_gravity=wp.array(gravity, dtype=wp.vec3, device=device),
            plane_point=wp.array(plane_point, dtype=wp.vec3, device=device),
            plane_normal=wp.array(plane_normal, dtype=wp.vec3, device=device),
            plane_material=wp.array(plane_material, dtype=int, device=device),
            plane_world=wp.array(plane_world, dtype=int, device=device),
            wall_meshes=meshes,
            wall_mesh=wp.array(np.array([m.id for m in meshes], dtype=np.uint64), dtype=wp.uint64, device=device),
            wall_face_start=wp.array(np.array(face_start, dtype=np.int32), dtype=int, device=device),
            wall_radius=wp.array(np.array(wall_radius, dtype=np.float32), dtype=float, device=device),
            triangle_wall=wp.array(triangle_wall, dtype=int, device=device),
            wall_material=wp.array(wall_material, dtype=int, device=device),
            wall_world=wp.array(wall_world, dtype=int, device=device),
            sphere_clump=wp.array(sphere_clump, dtype=int, device=device),
            sphere_wall=wp.array(sphere_wall, dtype=int, device=device),
            attached_index=wp.array(attached if len(attached) else np.zeros(1, np.int32), dtype=int, device=device),
            attached_count=len(attached),
            sphere_offset=wp.array(cat(offset, np.float32, 3), dtype=wp.vec3, device=device),
            sphere_body_volume=wp.array(cat(body_volume, np.float32), dtype=float, device=device),
            clump_count=C,
            clump_sphere_start=wp.array(starts, dtype=int, device=device),
            clump_sphere_end=wp.array(ends, dtype=int, device=device),
            clump_material=wp.array(cat(cmat, np.int32), dtype=int, device=device),
            clump_world=wp.array(cat(cworld, np.int32), dtype=int, device=device),
            clump_volume=wp.array(cvol, dtype=float, device=device),
            clump_inertia=wp.array(cinertia, dtype=wp.vec3, device=device),
            contact_reach=reach,
            radius_max=float(radius.max()),
            radius_min=r_min,
            rayleigh_time=float(rayleigh),
            materials=list(self.materials),
            interactions=self.interactions,
            wall_names=[w[4] for w in walls],
            wall_motions=[w[5] for w in walls],
            clump_templates=templates,
            clump_template=ctpl,
            clump_scale=cscale,
            factories=factories,
            domain=self._domain,
            world_seed=np.concatenate(seeds),
        )
        model.initial = {
            k: cat(v, np.int32 if k == "sphere_active" else np.float32, None if k == "sphere_active" else 3)
            for k, v in init.items()
        }
        if C:
            model.initial.update({k: cat(v, np.float32, 4 if k == "clump_q" else 3) for k, v in cinit.items()})
        return model


def _world_value(key: OverrideKey, target: str, value):
    """One world's ``value`` of a :meth:`ModelBuilder.vary` ``target`` (parsed as ``key``): None (the scene's
    value), a float, or for an enum Interaction field its member (read by Interaction, which knows the names)."""
    if value is None:
        return None
    try:
        if key.kind == "interaction" and key.field in INTERACTION_ENUMS:
            return getattr(Interaction(**{key.field: value}), key.field)
        return float(value)
    except (TypeError, ValueError) as e:
        raise InputError(f"vary {target!r}: value = {value!r} is not allowed: {e}") from None


def contact_reach(params: np.ndarray, radius_max: float) -> float:
    """Longest gap at which any pair's contact can still act [m]: JKR's |delta_c|, largest for a sphere on a
    wall (R* = radius_max, |delta_c| grows as R*^(1/3)); 0 without JKR."""
    jkr = params[params["law"] == int(ContactLaw.JKR)]
    if len(jkr) == 0:
        return 0.0
    reach = [
        -analytic.jkr_break_overlap(radius_max, float(p["e_star"]), float(p["gamma"])) for p in jkr if p["gamma"] > 0
    ]
    # 5 % margin: float32 rounding of the break test must never find a pair outside the lists
    return 1.05 * max(reach, default=0.0)
