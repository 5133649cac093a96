"""ModelBuilder: host-side scene description -> a Model on a device."""

from __future__ import annotations

import dataclasses

import numpy as np
import warp as wp

from .materials import Interaction, InteractionTable, Material, pair_table
from .types import Model

from warpdem.kernels.params import PairParams


def _vec3(value, where: str, name: str) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{where}: {name} = {value!r} is not allowed; expected three finite numbers")
    return a


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
        self.gravity = _vec3(gravity, "ModelBuilder", "gravity")
        self.materials: list[Material] = []
        self.interactions = InteractionTable()
        self._x, self._r, self._mat, self._v, self._w, self._world = [], [], [], [], [], []
        self._planes = []  # (point, normal, material, world)
        self._walls = []  # (vertices, triangles, material, world, name)
        self.world_count = 1
        self._variations = {}

    # materials -------------------------------------------------------------------------------
    def add_material(self, material: Material) -> int:
        """Add a material; returns its index. Names are unique."""
        if not isinstance(material, Material):
            raise TypeError(f"add_material: expected a Material, got {type(material).__name__}")
        if any(m.name == material.name for m in self.materials):
            raise ValueError(f"add_material: a material named {material.name!r} exists already")
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
        raise ValueError(f"material = {material!r} is not defined; defined materials: {names}")

    def set_interaction(self, a, b, interaction: Interaction | None = None, **kwargs) -> Interaction:
        """Set the contact parameters of materials ``a`` and ``b`` (see :class:`Interaction`)."""
        na = self.materials[self.material_index(a)].name
        nb = self.materials[self.material_index(b)].name
        return self.interactions.set(na, nb, interaction, **kwargs)

    def set_default_interaction(self, interaction: Interaction | None = None, **kwargs) -> None:
        """Interaction used for every pair not set explicitly."""
        self.interactions.default = interaction if interaction is not None else dataclasses.replace(
            self.interactions.default, **kwargs)

    # bodies and walls ------------------------------------------------------------------------
    def add_sphere(self, position, radius: float, material, velocity=(0, 0, 0), angular_velocity=(0, 0, 0),
                   world: int = 0) -> int:
        """Add one sphere: centre [m], radius [m], velocity [m/s], angular velocity [rad/s]; returns its index."""
        return int(self.add_spheres([position], radius, material, [velocity], [angular_velocity], world)[0])

    def add_spheres(self, positions, radius, material, velocities=None, angular_velocities=None,
                    world: int = 0) -> np.ndarray:
        """Add spheres; ``positions`` shape (n, 3) [m], ``radius`` scalar or shape (n,) [m]. Returns their indices."""
        x = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        n = x.shape[0]
        r = np.broadcast_to(np.asarray(radius, dtype=np.float64), (n,)).copy()
        if not np.all(np.isfinite(x)):
            raise ValueError("add_spheres: positions contain a non-finite value")
        bad = np.flatnonzero(~(np.isfinite(r) & (r > 0)))
        if bad.size:
            raise ValueError(f"add_spheres: radius = {float(r[bad[0]])!r} (sphere {bad[0]}) is not allowed; expected a radius > 0 m")
        v = np.zeros((n, 3)) if velocities is None else np.asarray(velocities, dtype=np.float64).reshape(n, 3)
        w = np.zeros((n, 3)) if angular_velocities is None else np.asarray(angular_velocities, dtype=np.float64).reshape(n, 3)
        if not (np.all(np.isfinite(v)) and np.all(np.isfinite(w))):
            raise ValueError("add_spheres: velocities contain a non-finite value")
        if int(world) != 0:
            raise ValueError(f"add_spheres: world = {world!r} is not allowed; build world 0 and call replicate(world_count)")
        mat = self.material_index(material)
        start = len(self._r)
        self._x.extend(x)
        self._r.extend(r)
        self._v.extend(v)
        self._w.extend(w)
        self._mat.extend([mat] * n)
        return np.arange(start, start + n)

    def add_plane(self, point, normal, material, world: int = -1) -> int:
        """Add an infinite plane through ``point`` [m] whose ``normal`` points to the particle side."""
        p = _vec3(point, "add_plane", "point")
        nrm = _vec3(normal, "add_plane", "normal")
        length = np.linalg.norm(nrm)
        if length == 0:
            raise ValueError("add_plane: normal = (0, 0, 0) is not allowed; expected a non-zero vector")
        self._planes.append((p, nrm / length, self.material_index(material), int(world)))
        return len(self._planes) - 1

    def add_wall_mesh(self, vertices, triangles, material, name: str | None = None, world: int = -1) -> int:
        """Add a static triangle-mesh wall: ``vertices`` shape (v, 3) [m], ``triangles`` shape (t, 3) int.

        Triangles are two-sided: a sphere is pushed away from whichever side it touches.
        """
        verts = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
        tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
        label = name or f"wall{len(self._walls)}"
        if tris.size == 0:
            raise ValueError(f"add_wall_mesh {label!r}: triangles is empty; expected at least one triangle")
        if tris.min() < 0 or tris.max() >= len(verts):
            raise ValueError(f"add_wall_mesh {label!r}: triangles index {int(tris.max())} outside 0..{len(verts) - 1}")
        if not np.all(np.isfinite(verts)):
            raise ValueError(f"add_wall_mesh {label!r}: vertices contain a non-finite value")
        self._walls.append((verts, tris, self.material_index(material), int(world), label))
        return len(self._walls) - 1

    @property
    def sphere_count(self) -> int:
        return len(self._r)

    # batching --------------------------------------------------------------------------------
    def replicate(self, world_count: int) -> None:
        """Make ``world_count`` identical copies of the scene, all at the origin (kept apart by world id)."""
        if int(world_count) < 1:
            raise ValueError(f"replicate: world_count = {world_count!r} is not allowed; expected an integer >= 1")
        self.world_count = int(world_count)

    def vary(self, target: str, values) -> None:
        """Give a scalar parameter one value per world.

        ``target`` is ``material.NAME.FIELD`` (density, youngs_modulus, shear_modulus, poisson_ratio),
        ``interaction.A.B.FIELD`` (restitution, static_friction, rolling_friction, rolling_damping)
        or ``gravity`` (values shape (world_count, 3)). Call after :meth:`replicate`.
        """
        vals = list(values)
        if len(vals) != self.world_count:
            raise ValueError(f"vary {target!r}: {len(vals)} values given; expected world_count = {self.world_count}")
        parts = target.split(".")
        if parts[0] == "material" and len(parts) == 3:
            self.material_index(parts[1])
            if parts[2] not in ("density", "youngs_modulus", "shear_modulus", "poisson_ratio"):
                raise ValueError(f"vary {target!r}: field {parts[2]!r} is not a material scalar")
        elif parts[0] == "interaction" and len(parts) == 4:
            self.material_index(parts[1])
            self.material_index(parts[2])
            if parts[3] not in ("restitution", "static_friction", "rolling_friction", "rolling_damping"):
                raise ValueError(f"vary {target!r}: field {parts[3]!r} is not an interaction scalar")
        elif parts != ["gravity"]:
            raise ValueError(f"vary: target = {target!r} is not allowed; expected material.NAME.FIELD, "
                             "interaction.A.B.FIELD or gravity")
        self._variations[target] = vals

    def _world_tables(self):
        """Materials and interaction tables per world (length 1 when nothing varies)."""
        varied = [t for t in self._variations if t != "gravity"]
        count = self.world_count if varied else 1
        mats_w, tables_w = [], []
        for w in range(count):
            mats = list(self.materials)
            table = InteractionTable(self.interactions.default, dict(self.interactions.pairs))
            for target in varied:
                parts = target.split(".")
                value = float(self._variations[target][w])
                if parts[0] == "material":
                    k = self.material_index(parts[1])
                    m = mats[k]
                    changes = {parts[2]: value}
                    # E and G are tied through nu: varying one re-derives the other
                    if parts[2] == "youngs_modulus":
                        changes["shear_modulus"] = None
                    elif parts[2] == "shear_modulus":
                        changes["youngs_modulus"] = None
                    elif parts[2] == "poisson_ratio":
                        changes["youngs_modulus"] = None
                    mats[k] = dataclasses.replace(m, **changes)
                else:
                    a, b = parts[1], parts[2]
                    table.set(a, b, table.get(a, b), **{parts[3]: value})
            mats_w.append(mats)
            tables_w.append(table)
        return mats_w, tables_w

    # finalise --------------------------------------------------------------------------------
    def finalize(self, device: str = "cpu") -> Model:
        """Build the Model on ``device`` ("cpu" or "cuda[:n]")."""
        if not self.materials:
            raise ValueError("finalize: no material defined; call add_material first")
        if self.sphere_count == 0:
            raise ValueError("finalize: the scene has no sphere")
        device = str(wp.get_device(device))
        W = self.world_count
        n0 = self.sphere_count
        radius = np.tile(np.asarray(self._r, dtype=np.float32), W)
        material = np.tile(np.asarray(self._mat, dtype=np.int32), W)
        world = np.repeat(np.arange(W, dtype=np.int32), n0)

        mats_w, tables_w = self._world_tables()
        params = pair_table(mats_w, tables_w)
        density = np.array([[m.density for m in mats] for mats in mats_w], dtype=np.float32)
        if "gravity" in self._variations:
            gravity = np.asarray(self._variations["gravity"], dtype=np.float32).reshape(W, 3)
        else:
            gravity = self.gravity.astype(np.float32).reshape(1, 3)

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

        mesh = None
        if self._walls:
            verts, tris, tri_wall = [], [], []
            offset = 0
            for k, (v, t, _, _, _) in enumerate(self._walls):
                verts.append(v)
                tris.append(t + offset)
                tri_wall.append(np.full(len(t), k, dtype=np.int32))
                offset += len(v)
            mesh = wp.Mesh(points=wp.array(np.concatenate(verts).astype(np.float32), dtype=wp.vec3, device=device),
                           indices=wp.array(np.concatenate(tris).astype(np.int32).reshape(-1), dtype=int, device=device))
            triangle_wall = np.concatenate(tri_wall)
        else:
            triangle_wall = np.zeros(0, dtype=np.int32)
        wall_material = np.array([w[2] for w in self._walls], dtype=np.int32)
        wall_world = np.array([w[3] for w in self._walls], dtype=np.int32)

        r_min = float(radius.min())
        used = sorted(set(self._mat))
        rayleigh = min(mats[k].rayleigh_time(r_min) for mats in mats_w for k in used)

        model = Model(
            device=device,
            world_count=W,
            sphere_count=n0 * W,
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
            mesh=mesh,
            triangle_wall=wp.array(triangle_wall, dtype=int, device=device),
            wall_material=wp.array(wall_material, dtype=int, device=device),
            wall_world=wp.array(wall_world, dtype=int, device=device),
            radius_max=float(radius.max()),
            radius_min=r_min,
            rayleigh_time=float(rayleigh),
            materials=list(self.materials),
            interactions=self.interactions,
            wall_names=[w[4] for w in self._walls],
        )
        model.initial = {
            "sphere_x": np.tile(np.asarray(self._x, dtype=np.float32), (W, 1)),
            "sphere_v": np.tile(np.asarray(self._v, dtype=np.float32), (W, 1)),
            "sphere_w": np.tile(np.asarray(self._w, dtype=np.float32), (W, 1)),
        }
        return model
