"""The Model / State / Control / Contacts containers, and the enums (defined in ``warpdem.kernels.enums``).

The split follows Newton (and the former ``warp.sim``): the Model is the static description on the
device, a State is one instant of the time-varying quantities, Control holds what moves walls, and
Contacts holds the neighbour lists with their per-contact history. A solver step reads one State and
writes another; nothing in a step synchronises with the host.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
import warp as wp

from warpdem.errors import InputError
from warpdem.kernels.enums import ContactLaw, Overflow, RollingModel, SphereActivity

__all__ = [
    "ContactLaw",
    "Contacts",
    "Control",
    "Model",
    "Overflow",
    "RollingModel",
    "SphereActivity",
    "State",
    "host",
    "DEVICE_FORMS",
    "device_kind",
    "device_names",
    "init_warp",
]


DEVICE_FORMS = "'cpu', 'cuda', 'cuda:N', 'cuda:all', or a comma-separated list of these (e.g. 'cuda:0,cuda:1')"
"""What a device option may say (``--device``; ``device=`` of the study and diagnosis functions)."""


def device_kind(device: str) -> str:
    """The kind of a device name: "cuda" for "cuda" or "cuda:N", else "cpu". A run's results depend on it, not
    on the ordinal (the same kernels on the same kind of GPU give the same numbers)."""
    return "cuda" if str(device).startswith("cuda") else "cpu"


def device_names(device: str, where: str = "device") -> list[str]:
    """The Warp devices named by ``device``: one name ("cpu", "cuda", "cuda:N") or a comma-separated list of
    them, which may repeat a name ("cpu,cpu": two CPU processes); "cuda:all" is every CUDA device.

    Raises:
        InputError: a name that is not a device, naming ``where``, the value and :data:`DEVICE_FORMS`.
        DeviceError: a CUDA device this machine does not have.
    """
    from warpdem.errors import DeviceError

    names = [d.strip() for d in str(device).split(",")]
    out = []
    for d in names:
        if d == "cuda:all":
            out += [f"cuda:{i}" for i in range(_cuda_count(device, where, "'cuda:all' names no device"))]
        elif d in ("cpu", "cuda") or (d.startswith("cuda:") and d[5:].isdigit()):
            out.append(d)
        else:
            raise InputError(f"{where} = {device!r}: {d!r} is not a device; expected {DEVICE_FORMS}")
    for d in out:
        if device_kind(d) == "cuda":
            n = _cuda_count(device, where, f"{d!r} is not there")
            if d != "cuda" and int(d[5:]) >= n:
                raise DeviceError(
                    f"{where} = {device!r}: {d!r} is not there; this machine has {n} CUDA device(s), "
                    f"cuda:0 to cuda:{n - 1}"
                )
    return out


def _cuda_count(device: str, where: str, what: str) -> int:
    from warpdem.errors import DeviceError

    _init_quietly(gpu=False)
    n = wp.get_cuda_device_count()
    if n == 0:
        raise DeviceError(f"{where} = {device!r}: {what}, this machine has no CUDA device; use 'cpu'")
    return n


def _init_quietly(gpu: bool) -> None:
    """``wp.init()``; without a GPU asked for, Warp's native "Could not find or load the NVIDIA CUDA driver" line
    (written straight to file descriptor 2 by its C++ start-up on a machine without a GPU) is kept off the
    terminal; an error at start still raises."""
    import os
    import sys

    if gpu:
        wp.init()
        return
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            wp.init()
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def init_warp(device: str = "cpu") -> None:
    """Initialise Warp for work on ``device`` (any device option, e.g. ``cpu,cpu`` or ``cuda:all``), without its
    banner and module-load lines (the command line and its worker processes print their own), refusing a device
    that is malformed or absent (:func:`device_names`)."""
    wp.config.quiet = True
    if hasattr(wp.config, "log_level"):  # Warp >= 1.19 prints its banner and module loads by log level
        wp.config.log_level = wp.LOG_WARNING
    _init_quietly(gpu="cuda" in str(device))
    device_names(device, "--device")


def host(a: wp.array) -> np.ndarray:
    """``a`` on the host as a NumPy array (on the CPU a view, on CUDA a copy). On CUDA the copy runs on the
    device's current stream and waits for that stream only: Warp's ``array.numpy()`` copies on the legacy
    default stream, which waits for every stream of the device, and would make the launches that
    ``runner.run_together`` runs side by side wait for one another at each read."""
    if not a.device.is_cuda:
        return a.numpy()
    out = wp.empty(a.shape, dtype=a.dtype, device="cpu")
    wp.copy(out, a)
    wp.synchronize_stream(a.device.stream)
    return out.numpy()


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
    wall_meshes: list
    """One ``wp.Mesh`` (BVH) per triangle-mesh wall, vertices in the wall's own frame."""
    wall_mesh: wp.array
    """Mesh ids of ``wall_meshes``, shape (wall_count,), uint64."""
    wall_face_start: wp.array
    """Global index of each wall's first triangle, shape (wall_count + 1,), int32."""
    wall_radius: wp.array
    """Largest distance of a wall vertex from its frame's origin [m], shape (wall_count,), float32."""
    triangle_wall: wp.array
    """Wall index of each triangle (global numbering), shape (triangle_count,), int32."""
    wall_material: wp.array
    """Material of each mesh wall, shape (wall_count,), int32."""
    wall_world: wp.array
    """World of each mesh wall (-1: every world), shape (wall_count,), int32."""
    sphere_clump: wp.array
    """Clump of each sphere (-1: a free sphere), shape (sphere_count,), int32. A clump's spheres are contiguous."""
    sphere_offset: wp.array
    """Centre of each clump sphere in its clump's principal frame [m] (zero for free spheres), shape (sphere_count,), vec3."""
    sphere_body_volume: wp.array
    """Volume of the body a sphere belongs to (itself, or its clump's union) [m^3], shape (sphere_count,), float32.
    A sphere glued to a wall carries ``GLUED_VOLUME``, so that it is, for its partners, infinitely heavy."""
    sphere_wall: wp.array
    """Mesh wall a sphere is glued to (a particle-coated surface; -1: none), shape (sphere_count,), int32. A glued
    sphere's ``sphere_offset`` is its centre in the wall's frame."""
    attached_index: wp.array
    """Indices of the glued spheres, shape (max(attached_count, 1),), int32."""
    attached_count: int
    clump_count: int
    clump_sphere_start: wp.array
    """First sphere of each clump, shape (max(clump_count, 1),), int32."""
    clump_sphere_end: wp.array
    """One past the last sphere of each clump, shape (max(clump_count, 1),), int32."""
    clump_material: wp.array
    """Material of each clump, shape (clump_count,), int32."""
    clump_world: wp.array
    """World of each clump, shape (clump_count,), int32."""
    clump_volume: wp.array
    """Volume of the union of a clump's spheres [m^3], shape (clump_count,), float32."""
    clump_inertia: wp.array
    """Principal moments of inertia per unit density [m^5], shape (clump_count,), vec3."""
    contact_reach: float
    """Longest distance beyond touching at which a contact can still act (cohesive laws) [m]."""
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
    wall_motions: list = field(default_factory=list)
    """Host WallMotion of each mesh wall (the default Control)."""
    clump_templates: list = field(default_factory=list)
    """Host ClumpTemplate objects used by the clumps (index = template id)."""
    clump_template: object = None
    """Host array: template id of each clump, shape (clump_count,)."""
    clump_scale: object = None
    """Host array: scale of each clump relative to its template, shape (clump_count,)."""
    factories: list = field(default_factory=list)
    """Host records of the dynamic factories (see ModelBuilder.add_factory); ``world_first`` (world_count,): where
    each world's copy of the factory's particles starts (sphere or clump index; -1 where a world has none)."""
    world_seed: object = None
    """Host array: placement seed of each world's dynamic factories, shape (world_count,) (0: the factory's
    own stream, the same in every world)."""
    initial: dict = field(default_factory=dict)
    """Host copies of the initial state arrays (sphere_x/v/w, sphere_active, clump_x/q/v/w)."""
    domain: tuple | None = None
    """Simulation domain ((x, y, z) low, (x, y, z) high) [m], the same box in every world: a body whose centre
    leaves it is removed at the next list rebuild (as EDEM deletes particles that leave its domain), so a
    particle that falls off an open plate neither falls for ever, forcing a rebuild every step, nor keeps a
    settled world moving. None: no domain, nothing is removed."""

    @property
    def plane_count(self) -> int:
        return self.plane_point.shape[0]

    @property
    def wall_count(self) -> int:
        return self.wall_material.shape[0]

    def state(self) -> State:
        """A new State holding the initial positions and velocities given to the builder."""
        n, nc, dev = self.sphere_count, max(self.clump_count, 1), self.device

        def initial(name, dtype=wp.vec3, count=n):
            if name in self.initial:
                return wp.array(self.initial[name], dtype=dtype, device=dev)
            return wp.zeros(count, dtype=dtype, device=dev)

        walls = max(self.wall_count, 1)
        surfaces = max(self.wall_count + self.plane_count, 1)
        faces = (self.world_count, max(self.triangle_wall.shape[0], 1))
        identity = np.tile(np.array([0, 0, 0, 0, 0, 0, 1], dtype=np.float32), (walls, 1))
        return State(
            sphere_x=initial("sphere_x"),
            sphere_v=initial("sphere_v"),
            sphere_w=initial("sphere_w"),
            sphere_f=wp.zeros(n, dtype=wp.vec3, device=dev),
            sphere_t=wp.zeros(n, dtype=wp.vec3, device=dev),
            sphere_active=initial("sphere_active", int),
            clump_x=initial("clump_x", wp.vec3, nc),
            clump_q=initial("clump_q", wp.quat, nc),
            clump_v=initial("clump_v", wp.vec3, nc),
            clump_angmom=initial("clump_angmom", wp.vec3, nc),
            clump_w=initial("clump_w", wp.vec3, nc),
            clump_f=wp.zeros(nc, dtype=wp.vec3, device=dev),
            clump_t=wp.zeros(nc, dtype=wp.vec3, device=dev),
            wall_pose=wp.array(identity, dtype=wp.transform, device=dev),
            wall_v=wp.zeros(walls, dtype=wp.vec3, device=dev),
            wall_w=wp.zeros(walls, dtype=wp.vec3, device=dev),
            wall_f=wp.zeros(surfaces, dtype=wp.vec3, device=dev),
            wall_t=wp.zeros(surfaces, dtype=wp.vec3, device=dev),
            wall_impulse=wp.zeros(surfaces, dtype=wp.vec3d, device=dev),
            face_impact_count=wp.zeros(faces, dtype=int, device=dev),
            face_impact_energy=wp.zeros(faces, dtype=wp.float64, device=dev),
            face_impact_speed=wp.zeros(faces, dtype=float, device=dev),
            world_removed=wp.zeros(self.world_count, dtype=int, device=dev),
        )

    def control(self) -> Control:
        """The wall motions given to the builder, on the device (a solver uses it when run without one)."""
        from .motion import MotionTable, WallMotion

        motions = self.wall_motions or [WallMotion.static()]
        return Control.from_table(MotionTable.build(motions), self.device)


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
    sphere_active: wp.array
    """:class:`SphereActivity` of each sphere, shape (sphere_count,), int32: 1 (MOVING) in the simulation, 0
    (PARKED) a factory particle not released yet or a removed body's, 2 (SETTLED) held where its settled world came
    to rest (:meth:`warpdem.engine.solver.Solver.settle_worlds`). Nonzero: present (measured, drawn)."""
    clump_x: wp.array
    """Clump centre of mass [m], shape (max(clump_count, 1),), vec3."""
    clump_q: wp.array
    """Clump orientation (body principal frame -> world), shape (max(clump_count, 1),), quat (x, y, z, w)."""
    clump_v: wp.array
    """Clump velocity [m/s], shape (max(clump_count, 1),), vec3."""
    clump_angmom: wp.array
    """Clump angular momentum about its centre of mass, world frame [kg m^2/s], shape (max(clump_count, 1),), vec3."""
    clump_w: wp.array
    """Clump angular velocity, world frame [rad/s], shape (max(clump_count, 1),), vec3 (written by the solver)."""
    clump_f: wp.array
    """Contact force on each clump in the last step [N], shape (max(clump_count, 1),), vec3."""
    clump_t: wp.array
    """Contact torque about each clump's centre of mass in the last step [N m], shape (max(clump_count, 1),), vec3."""
    wall_pose: wp.array
    """Pose of each mesh wall (its frame -> world) at ``time``, shape (max(wall_count, 1),), transform."""
    wall_v: wp.array
    """Velocity of each wall frame's origin [m/s], shape (max(wall_count, 1),), vec3."""
    wall_w: wp.array
    """Angular velocity of each wall [rad/s], shape (max(wall_count, 1),), vec3."""
    wall_f: wp.array
    """Force exerted by the particles on each plane, then each mesh wall, in the last step [N], shape (max(plane_count + wall_count, 1),), vec3."""
    wall_t: wp.array
    """Torque of those forces about each plane's point / each wall frame's origin [N m], same shape, vec3."""
    wall_impulse: wp.array
    """Force on each surface summed over every step times dt since the state was made [N s], same shape, vec3d
    (float64): the mean force between two reads is the impulse difference over the time between them."""
    face_impact_count: wp.array = None
    """Impacts on each mesh-wall triangle per world since the last :meth:`reset_impacts`, shape
    (world_count, max(triangle_count, 1)), int32 (triangles numbered globally, see ``Model.wall_face_start``).
    An impact is a sphere's first step of touching a face with a normal approach speed of at least
    ``SolverOptions.impact_speed_min``; a clump's spheres count one by one."""
    face_impact_energy: wp.array = None
    """Sum of the normal impact energies 0.5 m u_n^2 (m the body's mass) [J], same shape, float64."""
    face_impact_speed: wp.array = None
    """Largest normal impact speed u_n [m/s], same shape, float32."""
    world_removed: wp.array = None
    """Bodies (clumps or free spheres) removed for leaving ``Model.domain``, per world, shape (world_count,),
    int32. A removed body's spheres are inactive (``sphere_active`` 0) and at rest where they left."""
    time: float = 0.0
    """Simulated time [s] (host-side)."""
    step: int = 0
    """Steps taken (host-side)."""
    half_step: bool = False
    """True once velocities are leapfrog half-step values."""
    released: dict = field(default_factory=dict)
    """Dynamic factory progress (host-side): factory index -> {"count": released so far, "retry": earliest
    time [s] of the next try after a crowded batch}."""

    SHARED_RECORDS: ClassVar[tuple] = ("face_impact_count", "face_impact_energy", "face_impact_speed")
    """Running records a solver's twin states share (every step adds to them)."""
    TWIN_SHARED: ClassVar[tuple] = SHARED_RECORDS + ("world_removed",)
    """Arrays a solver's twin states share: the running records and the removal counts."""

    def reset_impacts(self) -> None:
        """Zero the impact records (e.g. between the loading and the discharge of a tipper)."""
        for name in self.SHARED_RECORDS:
            getattr(self, name).zero_()


@dataclass
class Control:
    """What moves the mesh walls: their prescribed motion as constant-twist segments (warpdem/engine/motion.py).

    Segment ``s`` of wall ``k`` is row ``segment_start[k] + s``; the rows of a wall cover [0, inf).
    """

    segment_start: wp.array
    """First segment of each wall, shape (wall_count + 1,), int32."""
    segment_t0: wp.array
    """Segment start [s], shape (segment_count,), float64."""
    segment_t1: wp.array
    """Segment end [s] (1e30: open), shape (segment_count,), float64."""
    segment_v: wp.array
    """Translation velocity [m/s], shape (segment_count,), vec3."""
    segment_w: wp.array
    """Angular velocity [rad/s], shape (segment_count,), vec3."""
    segment_pivot: wp.array
    """Point on the rotation axis at the segment's start [m], shape (segment_count,), vec3."""
    segment_pose: wp.array
    """Wall pose at the segment's start, shape (segment_count,), transform."""

    @staticmethod
    def _columns(table) -> dict:
        """The table's columns as host arrays of the device arrays' types (one row at least)."""
        pose = np.concatenate([table.pose_translation, table.pose_rotation], axis=1).astype(np.float32)
        if len(pose) == 0:
            pose = np.array([[0, 0, 0, 0, 0, 0, 1]], dtype=np.float32)

        def vec(a):
            a = np.asarray(a, dtype=np.float32).reshape(-1, 3)
            return a if len(a) else np.zeros((1, 3), np.float32)

        def f64(a):
            return np.asarray(a, dtype=np.float64) if len(a) else np.zeros(1)

        return {
            "segment_start": np.asarray(table.start, dtype=np.int32),
            "segment_t0": f64(table.t0),
            "segment_t1": f64(table.t1),
            "segment_v": vec(table.velocity),
            "segment_w": vec(table.angular_velocity),
            "segment_pivot": vec(table.pivot),
            "segment_pose": pose,
        }

    @staticmethod
    def from_table(table, device) -> Control:
        dtypes = {
            "segment_start": int,
            "segment_t0": wp.float64,
            "segment_t1": wp.float64,
            "segment_pose": wp.transform,
        }
        return Control(
            **{k: wp.array(v, dtype=dtypes.get(k, wp.vec3), device=device) for k, v in Control._columns(table).items()}
        )

    def assign(self, table) -> None:
        """Replace the motion with ``table``'s in place (the same arrays, so a captured CUDA graph follows it).

        Raises:
            ValueError: when ``table`` has other segment counts per wall than this Control.
        """
        cols = Control._columns(table)
        if not np.array_equal(cols["segment_start"], self.segment_start.numpy()):
            raise InputError(
                f"Control.assign: segments per wall {np.diff(cols['segment_start']).tolist()} are not allowed; "
                f"expected this Control's {np.diff(self.segment_start.numpy()).tolist()}"
            )
        for k, v in cols.items():
            getattr(self, k).assign(v)


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
    neighbor_history: wp.array
    """History of the pair (canonical order), shape (neighbor_capacity, sphere_count), of the slot type
    ``StepFeatures.history_type`` picks for the model: ``ContactHistory`` (kernels/params.py: tangential spring
    [m], rolling spring torque [N m], the law's scalar) or the part of it the model's laws use (see
    :meth:`spring`)."""
    plane_history: wp.array
    """History per sphere and plane, shape (max(plane_count, 1), sphere_count), the same type."""
    mesh_count: wp.array
    """Candidate triangles per sphere, shape (sphere_count,), int32."""
    mesh_face: wp.array
    """Candidate triangle index, shape (mesh_capacity, sphere_count), int32, ascending per sphere."""
    mesh_history: wp.array
    """History per sphere and triangle, shape (mesh_capacity, sphere_count), the same type."""
    neighbor_live: wp.array
    """Live mask of each sphere's first 64 neighbour slots, shape (sphere_count,), uint64: bit k set when slot k's
    contact was active at the last step (kernels/params.py, ``slot_live``); a clear bit's slot holds a zero
    history, which the step neither reads nor rewrites."""
    plane_live: wp.array
    """The same mask over the planes (bit p: plane p; planes past 64 always count as live)."""
    wall_build_pose: wp.array
    """Wall poses at the last rebuild, shape (max(wall_count, 1),), transform."""
    build_x: wp.array
    """Sphere centres at the last rebuild [m], shape (sphere_count,), vec3."""
    rebuild: wp.array
    """1 when a rebuild is due, shape (1,), int32."""
    overflow: wp.array
    """Overflow bits (see :class:`Overflow`) since the last check, shape (1,), int32."""
    partner_key: wp.array
    """Per clump, the bodies its spheres touched at the last step (contacts due within one step included), a
    small hash table of ``PARTNER_SLOTS`` slots per clump: key = clump index, ``clump_count`` + sphere index for a
    plain sphere, then planes and mesh walls; -1 empty. Shape (max(clump_count, 1) * PARTNER_SLOTS,), int32."""
    partner_count: wp.array
    """Sub-sphere contacts with each body of ``partner_key``: the next step divides the clump's mass by it in that
    body's contacts (``SolverOptions.clump_contact_mass``). Same shape, int32."""
    scratch: dict = field(default_factory=dict)
    """Second buffers of the candidate lists (counts and keys), written by a rebuild and copied back; the
    histories move in place (kernels/neighbors.py, carry_history)."""
    cells: dict = field(default_factory=dict)
    """The cell grid of the last rebuild, the active spheres counting-sorted into B hash buckets of (cell, world)
    (B a power of two): ``start`` (shape (B + 1,), int32: bucket b holds slots ``start[b] .. start[b + 1]``),
    ``tile_sum`` (shape (B / 256,), int32: the scan's per-tile totals), and per slot ``slot_xr`` (shape
    (sphere_count,), vec4: centre [m] and radius [m]) and ``slot_sphere`` (shape (sphere_count,), vec3i: sphere,
    world and clump). See kernels/neighbors.py, ``cell_grid``."""

    def spring(self, kind: str = "neighbor") -> np.ndarray:
        """Tangential springs [m] of the ``kind`` ("neighbor", "plane" or "mesh") history slots, whichever layout
        they are stored in: a host array of shape (slots, sphere_count, 3)."""
        slots = getattr(self, f"{kind}_history").numpy()
        return slots["spring"] if slots.dtype.names else slots[..., :3]
