"""Enums and the Model / State / Control / Contacts containers.

The split follows Newton (and the former ``warp.sim``): the Model is the static description on the
device, a State is one instant of the time-varying quantities, Control holds what moves walls, and
Contacts holds the neighbour lists with their per-contact history. A solver step reads one State and
writes another; nothing in a step synchronises with the host.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import warp as wp


class RollingModel(enum.IntEnum):
    """Rolling resistance model of a material pair."""

    NONE = 0
    CONSTANT_TORQUE = 1
    """Type A (EDEM "standard rolling friction"): torque -mu_r * R* * F_n along the relative rolling direction."""
    EPSD = 2
    """Type C (elastic-plastic spring-dashpot, Ai et al. 2011): rolling spring capped at mu_r * R* * F_n, plus a dashpot."""


class ContactLaw(enum.IntEnum):
    """Normal contact law of a material pair."""

    NONE = 0
    HERTZ_MINDLIN = 1


class Overflow(enum.IntFlag):
    """Bits of ``Contacts.overflow``: which fixed capacity a rebuild ran out of."""

    NONE = 0
    NEIGHBOR = 1
    MESH = 2


@dataclass
class Model:
    """Static description of W batched worlds on one device. Built by :class:`warpdem.ModelBuilder`.

    Per-world parameters have a leading dimension of 1 (shared by all worlds) or ``world_count``
    and are read in kernels as ``x[world % x.shape[0]]``.
    """

    device: str
    world_count: int
    sphere_count: int
    material_count: int
    sphere_radius: wp.array
    """Sphere radius [m], shape (sphere_count,), float32."""
    sphere_material: wp.array
    """Material index of each sphere, shape (sphere_count,), int32."""
    sphere_world: wp.array
    """World index of each sphere, shape (sphere_count,), int32."""
    material_density: wp.array
    """Density [kg/m^3], shape (1 or world_count, material_count), float32."""
    pair_params: wp.array
    """Derived contact parameters, shape (1 or world_count, material_count, material_count), PairParams."""
    world_gravity: wp.array
    """Gravity [m/s^2], shape (1 or world_count,), vec3."""
    plane_point: wp.array
    """A point on each infinite plane [m], shape (plane_count,), vec3."""
    plane_normal: wp.array
    """Unit normal of each plane, pointing into the particle side, shape (plane_count,), vec3."""
    plane_material: wp.array
    """Material of each plane, shape (plane_count,), int32."""
    plane_world: wp.array
    """World of each plane (-1: every world), shape (plane_count,), int32."""
    mesh: wp.Mesh | None
    """All static triangle walls concatenated into one BVH mesh, or None."""
    triangle_wall: wp.array
    """Wall index of each triangle of ``mesh``, shape (triangle_count,), int32."""
    wall_material: wp.array
    """Material of each mesh wall, shape (wall_count,), int32."""
    wall_world: wp.array
    """World of each mesh wall (-1: every world), shape (wall_count,), int32."""
    radius_max: float
    """Largest sphere radius [m]."""
    radius_min: float
    """Smallest sphere radius [m]."""
    rayleigh_time: float
    """Smallest Rayleigh time over spheres and worlds [s]."""
    materials: list = field(default_factory=list)
    """Host copy of the Material objects, index = material id."""
    interactions: object = None
    """Host copy of the InteractionTable used to derive ``pair_params``."""
    wall_names: list = field(default_factory=list)
    """Names of the mesh walls, index = wall id."""
    initial: dict = field(default_factory=dict)
    """Host copies of the initial sphere_x, sphere_v, sphere_w, shape (sphere_count, 3) each."""

    @property
    def plane_count(self) -> int:
        return self.plane_point.shape[0]

    @property
    def wall_count(self) -> int:
        return self.wall_material.shape[0]

    def state(self) -> "State":
        """A new State holding the initial positions and velocities given to the builder."""
        n, dev = self.sphere_count, self.device

        def initial(name):
            if name in self.initial:
                return wp.array(self.initial[name], dtype=wp.vec3, device=dev)
            return wp.zeros(n, dtype=wp.vec3, device=dev)

        return State(
            sphere_x=initial("sphere_x"),
            sphere_v=initial("sphere_v"),
            sphere_w=initial("sphere_w"),
            sphere_f=wp.zeros(n, dtype=wp.vec3, device=dev),
            sphere_t=wp.zeros(n, dtype=wp.vec3, device=dev),
            wall_f=wp.zeros(max(self.wall_count + self.plane_count, 1), dtype=wp.vec3, device=dev),
        )


@dataclass
class State:
    """One instant of the time-varying quantities.

    Velocities follow the leapfrog convention once a solver has stepped the state: ``sphere_v`` and
    ``sphere_w`` are then the half-step values at ``time - dt/2``. A fresh state holds the full-step
    values at ``time``; the solver's first step applies a half kick so the scheme stays second order
    (velocity Verlet).
    """

    sphere_x: wp.array
    """Sphere centre [m], shape (sphere_count,), vec3."""
    sphere_v: wp.array
    """Sphere velocity [m/s], shape (sphere_count,), vec3."""
    sphere_w: wp.array
    """Sphere angular velocity [rad/s], shape (sphere_count,), vec3."""
    sphere_f: wp.array
    """Contact force on each sphere in the last step [N] (gravity excluded), shape (sphere_count,), vec3."""
    sphere_t: wp.array
    """Contact torque about each sphere's centre in the last step [N m], shape (sphere_count,), vec3."""
    wall_f: wp.array
    """Force exerted by the spheres on each plane, then each mesh wall, in the last step [N], shape (plane_count + wall_count,), vec3."""
    time: float = 0.0
    """Simulated time [s] (host-side)."""
    step: int = 0
    """Steps taken (host-side)."""
    half_step: bool = False
    """True once velocities are leapfrog half-step values."""


@dataclass
class Control:
    """What moves walls. Static walls only so far: moving walls arrive with prescribed motion."""


@dataclass
class Contacts:
    """Neighbour and wall-contact lists with per-contact history, flat over all worlds.

    Sphere-sphere candidates are kept per sphere in fixed-capacity slots, stored slot-major
    (shape (capacity, sphere_count)) so that neighbouring GPU threads read neighbouring addresses.
    Each sphere lists every candidate, in increasing partner index; the pair's quantities are computed
    in a canonical order (lower index first) by both partners, so the two copies of the history stay
    bit-identical and Newton's third law holds exactly without atomics.
    """

    neighbor_capacity: int
    mesh_capacity: int
    skin: float
    """Verlet skin [m]: candidates are kept out to r_i + r_j + skin; a rebuild follows once any sphere moved skin/2."""
    neighbor_count: wp.array
    """Candidates per sphere, shape (sphere_count,), int32."""
    neighbor_index: wp.array
    """Candidate partner, shape (neighbor_capacity, sphere_count), int32, ascending per sphere."""
    neighbor_spring: wp.array
    """Tangential spring displacement of the pair (canonical order) [m], shape (neighbor_capacity, sphere_count), vec3."""
    neighbor_roll: wp.array
    """Rolling spring torque of the pair (canonical order) [N m], shape (neighbor_capacity, sphere_count), vec3."""
    plane_spring: wp.array
    """Tangential spring per sphere and plane [m], shape (max(plane_count,1), sphere_count), vec3."""
    plane_roll: wp.array
    """Rolling spring torque per sphere and plane [N m], shape (max(plane_count,1), sphere_count), vec3."""
    mesh_count: wp.array
    """Candidate triangles per sphere, shape (sphere_count,), int32."""
    mesh_face: wp.array
    """Candidate triangle index, shape (mesh_capacity, sphere_count), int32, ascending per sphere."""
    mesh_spring: wp.array
    """Tangential spring per sphere and triangle [m], shape (mesh_capacity, sphere_count), vec3."""
    mesh_roll: wp.array
    """Rolling spring torque per sphere and triangle [N m], shape (mesh_capacity, sphere_count), vec3."""
    build_x: wp.array
    """Sphere centres at the last rebuild [m], shape (sphere_count,), vec3."""
    rebuild: wp.array
    """1 when a rebuild is due, shape (1,), int32."""
    overflow: wp.array
    """Overflow bits (see :class:`Overflow`) since the last check, shape (1,), int32."""
    scratch: dict = field(default_factory=dict)
    """Second buffers of the history arrays, written by a rebuild and copied back."""
    grid: object = None
    """The grouped ``wp.HashGrid``."""
