"""The fused time step: contact forces from the neighbour lists, then leapfrog integration.

One thread per sphere gathers every contact of its sphere (partners, planes, mesh triangles), so no
force atomics are needed and the sum order is fixed: results are deterministic on CPU and CUDA and
world k of a batch computes exactly what a solo run computes. Each sphere-sphere pair is evaluated
by both partners in canonical order (lower index as body a), which keeps the two copies of its
history identical and makes the forces exactly equal and opposite.

Spheres that belong to a clump only gather forces here; :func:`integrate_clumps` then reduces them
to their clump (one thread per clump, fixed order), integrates the rigid body and places the
component spheres. Mesh walls move rigidly: each keeps its triangles in its own frame and a pose
per step (see warpdem/engine/motion.py), so no BVH refit is needed.

Each kernel has its launcher beside it (``launch_<kernel>``), the only code that calls ``wp.launch``: it takes
the engine's Model, State, Control and Contacts (duck-typed and unannotated: the kernels import nothing above
them, not even for type hints) and the solver's :class:`StepBuffers`, so the solver's step reads as a list of
launcher calls.
"""

import functools
from dataclasses import dataclass

import numpy as np
import warp as wp

from .enums import RollingModel, SphereActivity
from .features import MODULE_OPTIONS, StepFeatures
from .geometry import FEATURE_FACE, closest_point_triangle
from .law_contact import contact_force_for
from .law_rolling import rolling_resistance, standard_rolling
from .params import ContactHistory, PairParams, history_load, history_store, slot_bit, slot_live

wp.set_module_options(MODULE_OPTIONS)

BLOWUP_NONE = wp.constant(2147483647)
"""``StepBuffers.blowup`` while no sphere has blown up (the largest int32, so atomic_min records the first)."""
WALL_LANES = wp.constant(256)
"""Partial accumulators per wall: spreads the force atomics of thousands of spheres on one wall."""
CLUMP_LANES = 32
"""Threads per large clump in integrate_clumps on CUDA (a tiled launch; see ``SMALL_CLUMP_SPHERES``)."""
PARTNER_SLOTS = wp.constant(16)
"""Partner bodies a clump's table holds (a power of two): compact clumps touch at most about 14 bodies."""


def partner_tables(clump_count: int, device) -> tuple[wp.array, wp.array]:
    """Empty partner tables of ``PARTNER_SLOTS`` slots per clump: keys (-1: a free slot) and counts, int32."""
    slots = max(clump_count, 1) * PARTNER_SLOTS
    return wp.full(slots, -1, dtype=int, device=device), wp.zeros(slots, dtype=int, device=device)


@dataclass
class StepBuffers:
    """A solver's own device arrays, which the launchers pass to the kernels besides the Model, State,
    Control and Contacts (one set per solver, made by :meth:`zeros`)."""

    clock: wp.array
    """Steps taken on the device, shape (1,), int32 (a blow-up records the step it happened in)."""
    time: wp.array
    """Device time [s]: [0] the start of the step being taken, [1] its end (the time of state_out), shape (2,),
    float64."""
    wall_f_lanes: wp.array
    """Partial force accumulators of each plane, then each mesh wall [N], shape (max(plane_count + wall_count,
    1), WALL_LANES), vec3."""
    wall_t_lanes: wp.array
    """Partial torque accumulators [N m], same shape, vec3."""
    partner_key_next: wp.array
    """Partner tables the step being taken fills (``Contacts.partner_*`` hold the last step's), int32."""
    partner_count_next: wp.array
    """Their counts, int32."""
    blowup: wp.array
    """[0] the lowest sphere flagged in [1] the first step with a blow-up (``BLOWUP_NONE``: none), shape (2,),
    int32."""
    rebuild_count: wp.array
    """Neighbour-list rebuilds made, shape (1,), int32."""
    stiffness_max: wp.array
    """The largest sum of squared stable-step frequencies over one sphere's contacts [1/s^2] since the solver's
    last ``run`` began, shape (1,), float32 (``Solver.step_margin``)."""
    no_rebuild: wp.array
    """A rebuild flag nothing reads (moving the walls to a fresh state's time must not flag one), shape (1,),
    int32."""

    @staticmethod
    def zeros(model) -> "StepBuffers":
        """The buffers of a solver of ``model``, at step 0 with nothing flagged."""
        dev = model.device
        lanes = wp.zeros((max(model.plane_count + model.wall_count, 1), WALL_LANES), dtype=wp.vec3, device=dev)
        key_next, count_next = partner_tables(model.clump_count, dev)
        return StepBuffers(
            clock=wp.zeros(1, dtype=int, device=dev),
            time=wp.zeros(2, dtype=wp.float64, device=dev),
            wall_f_lanes=lanes,
            wall_t_lanes=wp.zeros_like(lanes),
            partner_key_next=key_next,
            partner_count_next=count_next,
            blowup=wp.array([BLOWUP_NONE, BLOWUP_NONE], dtype=int, device=dev),
            rebuild_count=wp.zeros(1, dtype=int, device=dev),
            stiffness_max=wp.zeros(1, dtype=float, device=dev),
            no_rebuild=wp.zeros(1, dtype=int, device=dev),
        )


@wp.func
def wall_triangle_closest(
    wall_mesh: wp.array[wp.uint64],
    wall_face_start: wp.array[int],
    wall_pose: wp.array[wp.transform],
    wall: int,
    face: int,
    x: wp.vec3,
):
    """Closest point (world frame) to x on global triangle ``face`` of moving wall ``wall``, and its feature."""
    pose = wall_pose[wall]
    x_local = wp.transform_point(wp.transform_inverse(pose), x)
    mesh = wall_mesh[wall]
    local = face - wall_face_start[wall]
    a = wp.mesh_get_point(mesh, local * 3 + 0)
    b = wp.mesh_get_point(mesh, local * 3 + 1)
    c = wp.mesh_get_point(mesh, local * 3 + 2)
    q, feature = closest_point_triangle(x_local, a, b, c)
    return wp.transform_point(pose, q), feature


@wp.func
def mesh_contact_shadowed(
    wall_mesh: wp.array[wp.uint64],
    wall_face_start: wp.array[int],
    wall_pose: wp.array[wp.transform],
    x: wp.vec3,
    radius: float,
    k: int,
    q_k: wp.vec3,
    feature_k: int,
    wall_k: int,
    i: int,
    mesh_count: wp.array[int],
    mesh_face: wp.array2d[int],
    triangle_wall: wp.array[int],
):
    """True when the edge/vertex contact k duplicates another contact of the same wall.

    An edge or vertex contact is dropped when its point lies in the tangent plane of a face contact
    (a flat surface split into triangles), or coincides with another contact of a lower rank or index
    (a convex edge or vertex shared by several triangles).
    """
    tol = 1.0e-3 * radius
    for m in range(mesh_count[i]):
        if m == k:
            continue
        face_m = mesh_face[m, i]
        if triangle_wall[face_m] != wall_k:
            continue
        q_m, feature_m = wall_triangle_closest(wall_mesh, wall_face_start, wall_pose, wall_k, face_m, x)
        d_m = wp.length(x - q_m)
        if d_m >= radius or d_m <= 0.0:
            continue
        if feature_m == FEATURE_FACE:
            n_m = (x - q_m) / d_m
            if wp.abs(wp.dot(q_k - q_m, n_m)) < tol:
                return True
        elif wp.length(q_k - q_m) < tol:
            if feature_m < feature_k or (feature_m == feature_k and m < k):
                return True
    return False


@functools.cache
def wall_contact_for(cohesive_laws: bool, rolling: bool, standard: bool):
    """:func:`wall_contact` compiled for a model's laws and rolling models (see kernels/features.py; ``standard``:
    some pair has EDEM's standard rolling friction)."""
    force_law = contact_force_for(cohesive_laws)

    @wp.func(module="unique")
    def wall_contact(
        overlap: float,
        n: wp.vec3,
        v_i: wp.vec3,
        w_i: wp.vec3,
        v_wall: wp.vec3,
        r_i: float,
        m_i: float,
        body_arm: wp.vec3,
        p: PairParams,
        history: ContactHistory,
        dt: float,
    ):
        """A sphere against a wall (infinite radius and mass) along unit normal n (sphere -> wall).

        ``v_wall`` is the wall's velocity at the contact point [m/s]; ``body_arm`` the sphere's centre less its
        body's centre of mass [m] (zero for a free sphere; EDEM's standard rolling friction reads it).

        Returns:
            (active, force on the sphere [N], torque on the sphere [N m], updated history (zero once the contact
            ended), squared stable-step frequency [1/s^2] (0 once the contact ended)).
        """
        arm = r_i - 0.5 * overlap
        v_rel = v_i + wp.cross(w_i, arm * n) - v_wall
        active, f_a, f_n, f_t, h, k_n, k_s = wp.static(force_law)(overlap, n, v_rel, history, r_i, m_i, p, dt)
        if active == 0:
            return int(0), wp.vec3(0.0), wp.vec3(0.0), h, 0.0
        if wp.static(standard):
            if p.rolling_model == RollingModel.STANDARD:
                m_std = standard_rolling(w_i, f_n, wp.length(body_arm + arm * n), p.mu_r)
                return int(1), f_a, wp.cross(arm * n, f_t) + m_std, ContactHistory(h.spring, h.roll * 0.0, h.aux), k_s
        if wp.static(rolling):
            m_roll, roll = rolling_resistance(
                p.rolling_model, w_i, n, f_n, r_i, p.mu_r, k_n, 1.4 * m_i * r_i * r_i, p.rolling_damping, h.roll, dt
            )
            return int(1), f_a, wp.cross(arm * n, f_t) + m_roll, ContactHistory(h.spring, roll, h.aux), k_s
        return int(1), f_a, wp.cross(arm * n, f_t), ContactHistory(h.spring, h.roll * 0.0, h.aux), k_s

    return wall_contact


@wp.func
def body_key(i: int, sphere_clump: wp.array[int], clump_total: int):
    """Key of the body sphere ``i`` belongs to in the partner tables: its clump, or the sphere itself."""
    c = sphere_clump[i]
    if c >= 0:
        return c
    return clump_total + i


@wp.func
def partner_slot(key: int, s: int):
    """Probe ``s`` of ``key`` in a clump's table of PARTNER_SLOTS slots (a power of two)."""
    h = int((wp.uint32(key) * wp.uint32(2654435761)) >> wp.uint32(16))
    return (h + s) & (PARTNER_SLOTS - 1)


@wp.func
def partner_find(keys: wp.array[int], counts: wp.array[int], c: int, key: int):
    """Sub-contacts clump ``c`` had with body ``key`` at the last step (0: none, or its table was full)."""
    for s in range(PARTNER_SLOTS):
        t = c * PARTNER_SLOTS + partner_slot(key, s)
        k = keys[t]
        if k == key:
            return counts[t]
        if k == -1:
            return 0
    return 0


@wp.func
def partner_add(keys: wp.array[int], counts: wp.array[int], c: int, key: int, n: int):
    """Add ``n`` sub-contacts of clump ``c`` with body ``key`` (a full table drops them: that partner then
    damps with the whole mass, right for the single-touch partners that fill a table, such as fine spheres)."""
    for s in range(PARTNER_SLOTS):
        t = c * PARTNER_SLOTS + partner_slot(key, s)
        k = keys[t]
        if k == -1:
            k = wp.atomic_cas(keys, t, -1, key)
            if k == -1:
                k = key
        if k == key:
            wp.atomic_add(counts, t, n)
            return


@wp.func
def partner_tally(keys: wp.array[int], counts: wp.array[int], c: int, run_key: int, run_n: int, key: int):
    """Count one sub-contact of clump ``c`` (-1: none counted) with body ``key``; a run of them with the same
    body (a sphere's sorted list holds each clump's spheres together) is added to the table at once."""
    if c < 0:
        return run_key, run_n
    if key == run_key:
        return run_key, run_n + 1
    if run_n > 0:
        partner_add(keys, counts, c, run_key, run_n)
    return key, 1


@wp.func
def contact_mass(m: float, c: int, key: int, keys: wp.array[int], counts: wp.array[int]):
    """Mass [kg] one contact damps for a sphere of body mass ``m`` in clump ``c`` (-1: a plain sphere) touching
    body ``key``, where clump masses are shared (``StepFeatures.share_mass``): a clump's mass divided by its
    sub-contacts with that body at the last step, since they act in parallel as one touch; a plain sphere's
    contacts keep the whole mass (EDEM's convention)."""
    if c < 0:
        return m
    return m / float(wp.max(partner_find(keys, counts, c, key), 1))


@wp.func
def flag_blowup(blowup_out: wp.array[int], step: int, i: int):
    """Record the first step with a blow-up and the lowest sphere index flagged in it."""
    first = blowup_out[1]
    if first == BLOWUP_NONE or first == step:
        wp.atomic_min(blowup_out, 1, step)
        wp.atomic_min(blowup_out, 0, i)


STEP_BLOCK_DIM = 128
"""Threads per block of the step kernel on CUDA. Measured on an H100 with fast math (kernels/features.py):
128 beat Warp's 256 by 1-6 % on the HM and the 8-sphere clump beds at every register cap tried."""


def step_max_registers(features: StepFeatures) -> int | None:
    """Register cap of the step kernel on CUDA (``__maxnreg__``; None: the compiler's choice) for ``features``.

    A cap trades spills for occupancy, and the kernel issues instructions more than it waits on memory since
    fast math. Measured on an H100 (sphere-steps/s, blocks of 128, the 1 M bench beds), with the stable-step
    tracking (SolverOptions.dt_margin): plain Hertz-Mindlin spheres 3.03e9 at 80 against 2.86e9 uncapped, 2.81e9
    at 96 and 2.51e9 at 128; the cohesive laws' kernel, whose law dispatch needs more registers, JKR 3.20e9 at 96
    against 3.11e9 at 80 and 2.73e9 uncapped, EEPA 2.98e9 at 96 against 2.66e9 uncapped; the 8-sphere clump bed
    (before the tracking) 2.12e9 at 72 against 2.07e9 at 64, 2.09e9 at 80 and 1.47e9 uncapped.
    """
    if features.clumps:
        return 72
    return 96 if features.cohesive_laws else 80


@functools.cache
def step_spheres_kernel(features: StepFeatures, max_registers: int | None = None):
    """The fused step kernel compiled for ``features`` (one module per set of features; see kernels/features.py),
    with at most ``max_registers`` registers per thread on CUDA."""
    clumps = features.clumps
    share_mass = features.share_mass
    mesh_walls = features.mesh_walls
    coated_walls = features.coated_walls
    cohesive = features.cohesive_laws
    rolling = features.rolling
    standard = features.rolling_standard
    force_law = contact_force_for(cohesive)
    wall_contact = wall_contact_for(cohesive, rolling, standard)
    History = features.history_type

    @wp.kernel(module="unique", module_options=MODULE_OPTIONS, cuda_max_registers=max_registers)
    def step_spheres(
        # Model:
        sphere_radius: wp.array[float],
        sphere_material: wp.array[int],
        sphere_world: wp.array[int],
        sphere_clump: wp.array[int],
        sphere_body_volume: wp.array[float],
        sphere_wall: wp.array[int],
        material_density: wp.array2d[float],
        pair_params: wp.array3d[PairParams],
        world_gravity: wp.array[wp.vec3],
        plane_point: wp.array[wp.vec3],
        plane_normal: wp.array[wp.vec3],
        plane_material: wp.array[int],
        plane_world: wp.array[int],
        wall_mesh: wp.array[wp.uint64],
        wall_face_start: wp.array[int],
        triangle_wall: wp.array[int],
        wall_material: wp.array[int],
        # State in:
        x_in: wp.array[wp.vec3],
        v_in: wp.array[wp.vec3],
        w_in: wp.array[wp.vec3],
        active_in: wp.array[int],
        clump_x: wp.array[wp.vec3],
        wall_pose: wp.array[wp.transform],
        wall_v: wp.array[wp.vec3],
        wall_w: wp.array[wp.vec3],
        clock: wp.array[int],
        # Contacts in:
        neighbor_count: wp.array[int],
        neighbor_index: wp.array2d[int],
        mesh_count: wp.array[int],
        mesh_face: wp.array2d[int],
        build_x: wp.array[wp.vec3],
        partner_key: wp.array[int],
        partner_count: wp.array[int],
        # Options:
        dt: float,
        kick: float,
        skin: float,
        velocity_limit: float,
        impact_speed_min: float,
        # Out (read, then written; each thread owns its column):
        neighbor_history_out: wp.array2d[History],
        plane_history_out: wp.array2d[History],
        mesh_history_out: wp.array2d[History],
        neighbor_live_out: wp.array[wp.uint64],
        plane_live_out: wp.array[wp.uint64],
        # Out:
        stiffness_max_out: wp.array[float],
        x_out: wp.array[wp.vec3],
        v_out: wp.array[wp.vec3],
        w_out: wp.array[wp.vec3],
        f_out: wp.array[wp.vec3],
        t_out: wp.array[wp.vec3],
        wall_f_lanes_out: wp.array2d[wp.vec3],
        wall_t_lanes_out: wp.array2d[wp.vec3],
        face_impact_count_out: wp.array2d[int],
        face_impact_energy_out: wp.array2d[wp.float64],
        face_impact_speed_out: wp.array2d[float],
        partner_key_out: wp.array[int],
        partner_count_out: wp.array[int],
        rebuild_out: wp.array[int],
        blowup_out: wp.array[int],
    ):
        i = wp.tid()
        x_i = x_in[i]
        v_i = v_in[i]
        w_i = w_in[i]
        clump = int(-1)
        if wp.static(clumps):
            clump = sphere_clump[i]
        parked = active_in[i] != SphereActivity.MOVING
        if wp.static(coated_walls):
            parked = parked or sphere_wall[i] >= 0
        if parked:
            # a factory particle not released yet (parked, invisible to the others), a settled world's sphere
            # (held where it came to rest), or a sphere glued to a wall (infinitely heavy; follow_walls places
            # it): none gathers forces
            if clump < 0:
                x_out[i] = x_i
                v_out[i] = v_i
                w_out[i] = w_i
            f_out[i] = wp.vec3(0.0)
            t_out[i] = wp.vec3(0.0)
            return
        world = sphere_world[i]
        mat_i = sphere_material[i]
        r_i = sphere_radius[i]
        mw = world % material_density.shape[0]
        pw = world % pair_params.shape[0]
        # the body's mass (a sphere's, or its whole clump's), and the share of it one contact damps
        m_i = material_density[mw, mat_i] * sphere_body_volume[i]
        clump_total = partner_key.shape[0] // PARTNER_SLOTS
        wall_key0 = clump_total + sphere_radius.shape[0]
        # sub-contacts of this sphere's clump per partner body, for the next step's mass shares
        tally = int(-1)
        if wp.static(share_mass):
            tally = clump
        run_key = int(-1)
        run_n = int(0)

        # the sphere's centre from its body's centre of mass: EDEM's standard rolling friction takes its lever
        # from the body's centre, a clump's for its spheres
        body_arm = wp.vec3(0.0)
        if wp.static(clumps and standard):
            if clump >= 0:
                body_arm = x_i - clump_x[clump]

        f = wp.vec3(0.0)
        t = wp.vec3(0.0)
        # sum of the contacts' squared stable-step frequencies [1/s^2]: a Gershgorin bound on the fastest mode
        # this sphere takes part in (see SolverOptions.dt_margin)
        stiff = float(0.0)

        # sphere-sphere (a slot not live holds a zero history: it is neither read nor rewritten)
        live_in = neighbor_live_out[i]
        live = wp.uint64(0)
        key_i = int(-1)
        if wp.static(share_mass):
            key_i = body_key(i, sphere_clump, clump_total)
        for k in range(neighbor_count[i]):
            was_live = slot_live(live_in, k)
            j = neighbor_index[k, i]
            # the pair in canonical order (a: the lower index), from the partner's loads alone: this sphere's
            # own values are already in registers and equal what a load of them would give
            i_low = i < j
            x_j = x_in[j]
            r_j = sphere_radius[j]
            r_a = wp.where(i_low, r_i, r_j)
            r_b = wp.where(i_low, r_j, r_i)
            d = wp.where(i_low, x_j - x_i, x_i - x_j)
            dist = wp.length(d)
            overlap = r_a + r_b - dist
            # apart and without history: no law acts (a JKR pair keeps aux = 1 while it hangs on in a gap;
            # Hertz-Mindlin keeps aux = 0)
            hanging = False
            if wp.static(cohesive):
                if was_live:
                    hanging = history_load(neighbor_history_out, k, i).aux != 0.0
            if overlap <= 0.0 and not hanging:
                if was_live:
                    history_store(neighbor_history_out, k, i, ContactHistory())
                if wp.static(share_mass):
                    # a contact due within one step counts already, so a clump's mass is shared from its
                    # first step
                    if tally >= 0 and dist > 0.0:
                        v_j = v_in[j]
                        v_ab = wp.where(i_low, v_i - v_j, v_j - v_i)
                        if overlap + dt * wp.dot(v_ab, d / dist) > 0.0:
                            run_key, run_n = partner_tally(
                                partner_key_out,
                                partner_count_out,
                                tally,
                                run_key,
                                run_n,
                                body_key(j, sphere_clump, clump_total),
                            )
                continue
            if dist <= 0.0 or active_in[j] != SphereActivity.MOVING:
                if was_live:
                    history_store(neighbor_history_out, k, i, ContactHistory())
                continue
            n = d / dist
            mat_j = sphere_material[j]
            m_j = material_density[mw, mat_j] * sphere_body_volume[j]
            if wp.static(share_mass):
                key_j = body_key(j, sphere_clump, clump_total)
                mc_i = contact_mass(m_i, clump, key_j, partner_key, partner_count)
                mc_j = contact_mass(m_j, sphere_clump[j], key_i, partner_key, partner_count)
                m_a = wp.where(i_low, mc_i, mc_j)
                m_b = wp.where(i_low, mc_j, mc_i)
            else:
                m_a = wp.where(i_low, m_i, m_j)
                m_b = wp.where(i_low, m_j, m_i)
            mat_a = wp.where(i_low, mat_i, mat_j)
            mat_b = wp.where(i_low, mat_j, mat_i)
            r_star = r_a * r_b / (r_a + r_b)
            m_star = m_a * m_b / (m_a + m_b)
            arm_a = r_a - 0.5 * overlap
            arm_b = r_b - 0.5 * overlap
            v_j = v_in[j]
            w_j = w_in[j]
            w_a = wp.where(i_low, w_i, w_j)
            w_b = wp.where(i_low, w_j, w_i)
            v_rel = (wp.where(i_low, v_i, v_j) + wp.cross(w_a, arm_a * n)) - (
                wp.where(i_low, v_j, v_i) - wp.cross(w_b, arm_b * n)
            )
            p = pair_params[pw, mat_a, mat_b]
            h_last = ContactHistory()
            if was_live:
                h_last = history_load(neighbor_history_out, k, i)
            active, f_a, f_n, f_t, h, k_n, k_s = wp.static(force_law)(overlap, n, v_rel, h_last, r_star, m_star, p, dt)
            if active == 0:
                if was_live:
                    history_store(neighbor_history_out, k, i, h)
                continue
            stiff += k_s
            if wp.static(share_mass):
                run_key, run_n = partner_tally(
                    partner_key_out, partner_count_out, tally, run_key, run_n, body_key(j, sphere_clump, clump_total)
                )
            m_roll = wp.vec3(0.0)
            roll = h.roll * 0.0
            if wp.static(rolling):
                i_roll = 0.0
                if p.rolling_model == RollingModel.EPSD:
                    i_roll = 1.0 / (1.0 / (1.4 * m_a * r_a * r_a) + 1.0 / (1.4 * m_b * r_b * r_b))
                m_roll, roll = rolling_resistance(
                    p.rolling_model, w_a - w_b, n, f_n, r_star, p.mu_r, k_n, i_roll, p.rolling_damping, h.roll, dt
                )
            if wp.static(standard):
                if p.rolling_model == RollingModel.STANDARD:
                    # this sphere's own torque, as the torque on a that the sign below turns into its own
                    lever = wp.length(body_arm + wp.where(i_low, arm_a, -arm_b) * n)
                    m_std = standard_rolling(w_i, f_n, lever, p.mu_r)
                    m_roll = wp.where(i_low, m_std, -m_std)
            history_store(neighbor_history_out, k, i, ContactHistory(h.spring, roll, h.aux))
            live = live | slot_bit(k)
            f_i = f_a
            if i_low:
                t += wp.cross(arm_a * n, f_t) + m_roll
            else:
                f_i = -f_a
                t += wp.cross(arm_b * n, f_t) - m_roll
            f += f_i
            if wp.static(coated_walls):
                glued = sphere_wall[j]
                if glued >= 0:
                    # a particle-coated wall feels the reaction on its glued sphere
                    origin_j = wp.transform_get_translation(wall_pose[glued])
                    c_pt = wp.where(i_low, x_i, x_j) + arm_a * n
                    wp.atomic_add(wall_f_lanes_out, plane_point.shape[0] + glued, i % WALL_LANES, -f_i)
                    wp.atomic_add(
                        wall_t_lanes_out,
                        plane_point.shape[0] + glued,
                        i % WALL_LANES,
                        wp.cross(c_pt - origin_j, -f_i),
                    )

        # infinite planes (static): one the sphere neither touches (no law forms a contact in a gap) nor touched at
        # the last step (a zero history) has nothing to compute, read or write
        plane_live_in = plane_live_out[i]
        plane_live = wp.uint64(0)
        for p_id in range(plane_point.shape[0]):
            pl_world = plane_world[p_id]
            if pl_world >= 0 and pl_world != world:
                continue
            n_p = plane_normal[p_id]
            gap = wp.dot(x_i - plane_point[p_id], n_p)
            key_w = wall_key0 + p_id
            was_live = slot_live(plane_live_in, p_id)
            active = int(0)
            f_a = wp.vec3(0.0)
            t_a = wp.vec3(0.0)
            if was_live or r_i - gap >= 0.0:
                p = pair_params[pw, mat_i, plane_material[p_id]]
                mc_i = m_i
                if wp.static(share_mass):
                    mc_i = contact_mass(m_i, clump, key_w, partner_key, partner_count)
                h_last = ContactHistory()
                if was_live:
                    h_last = history_load(plane_history_out, p_id, i)
                active, f_a, t_a, h, k_s = wp.static(wall_contact)(
                    r_i - gap, -n_p, v_i, w_i, wp.vec3(0.0), r_i, mc_i, body_arm, p, h_last, dt
                )
                stiff += k_s
                if active != 0 or was_live:
                    history_store(plane_history_out, p_id, i, h)
                if active != 0:
                    plane_live = plane_live | slot_bit(p_id)
            if wp.static(share_mass):
                if tally >= 0 and (active != 0 or r_i - gap - dt * wp.dot(v_i, n_p) > 0.0):
                    run_key, run_n = partner_tally(partner_key_out, partner_count_out, tally, run_key, run_n, key_w)
            if active != 0:
                f += f_a
                t += t_a
                q = x_i - gap * n_p
                wp.atomic_add(wall_f_lanes_out, p_id, i % WALL_LANES, -f_a)
                wp.atomic_add(wall_t_lanes_out, p_id, i % WALL_LANES, wp.cross(q - plane_point[p_id], -f_a))

        # triangle-mesh walls (rigid, possibly moving)
        if wp.static(mesh_walls):
            plane_total = plane_point.shape[0]
            for k in range(mesh_count[i]):
                face = mesh_face[k, i]
                wall = triangle_wall[face]
                q, feature = wall_triangle_closest(wall_mesh, wall_face_start, wall_pose, wall, face, x_i)
                dq = x_i - q
                gap = wp.length(dq)
                skip = gap <= 0.0
                if not skip and feature != FEATURE_FACE and gap < r_i:
                    skip = mesh_contact_shadowed(
                        wall_mesh,
                        wall_face_start,
                        wall_pose,
                        x_i,
                        r_i,
                        k,
                        q,
                        feature,
                        wall,
                        i,
                        mesh_count,
                        mesh_face,
                        triangle_wall,
                    )
                if skip:
                    history_store(mesh_history_out, k, i, ContactHistory())
                    continue
                origin = wp.transform_get_translation(wall_pose[wall])
                v_wall = wall_v[wall] + wp.cross(wall_w[wall], q - origin)
                p = pair_params[pw, mat_i, wall_material[wall]]
                key_w = wall_key0 + plane_total + wall
                mc_i = m_i
                if wp.static(share_mass):
                    mc_i = contact_mass(m_i, clump, key_w, partner_key, partner_count)
                active, f_a, t_a, h, k_s = wp.static(wall_contact)(
                    r_i - gap,
                    -dq / gap,
                    v_i,
                    w_i,
                    v_wall,
                    r_i,
                    mc_i,
                    body_arm,
                    p,
                    history_load(mesh_history_out, k, i),
                    dt,
                )
                stiff += k_s
                history_store(mesh_history_out, k, i, h)
                if wp.static(share_mass):
                    if tally >= 0 and (active != 0 or r_i - gap + dt * wp.dot(v_i - v_wall, dq / -gap) > 0.0):
                        run_key, run_n = partner_tally(partner_key_out, partner_count_out, tally, run_key, run_n, key_w)
                if active != 0:
                    f += f_a
                    t += t_a
                    wp.atomic_add(wall_f_lanes_out, plane_total + wall, i % WALL_LANES, -f_a)
                    wp.atomic_add(wall_t_lanes_out, plane_total + wall, i % WALL_LANES, wp.cross(q - origin, -f_a))
                    # an impact is the first step of a touch: leapfrog moved the sphere by dt * v_i since the
                    # last step, so it was clear of the face then iff the overlap is at most the approach this
                    # step
                    approach = wp.dot(v_i - v_wall, dq / -gap)
                    overlap = r_i - gap
                    if overlap > 0.0 and overlap <= approach * dt and approach >= impact_speed_min:
                        fw = world % face_impact_count_out.shape[0]
                        wp.atomic_add(face_impact_count_out, fw, face, 1)
                        wp.atomic_add(face_impact_energy_out, fw, face, wp.float64(0.5 * m_i * approach * approach))
                        wp.atomic_max(face_impact_speed_out, fw, face, approach)

        neighbor_live_out[i] = live
        plane_live_out[i] = plane_live
        f_out[i] = f
        t_out[i] = t
        # a broadcast load spares the atomic once the largest value has settled
        if stiff > stiffness_max_out[0]:
            wp.atomic_max(stiffness_max_out, 0, stiff)
        if wp.static(share_mass):
            if run_n > 0:
                partner_add(partner_key_out, partner_count_out, tally, run_key, run_n)
        if wp.static(clumps):
            if clump >= 0:
                return

        # leapfrog (velocity Verlet): v(t+dt/2) = v(t-dt/2) + dt a(t); the first step kicks by dt/2
        inertia_i = 0.4 * m_i * r_i * r_i
        g = world_gravity[world % world_gravity.shape[0]]
        v_new = v_i + kick * (f / m_i + g)
        w_new = w_i + kick * (t / inertia_i)
        x_new = x_i + dt * v_new
        x_out[i] = x_new
        v_out[i] = v_new
        w_out[i] = w_new

        speed = wp.length(v_new)
        if not (speed <= velocity_limit) or not wp.isfinite(x_new) or not wp.isfinite(w_new):
            flag_blowup(blowup_out, clock[0], i)
        if wp.length(x_new - build_x[i]) > 0.5 * skin:
            rebuild_out[0] = 1

    return step_spheres


def launch_step_spheres(
    model,
    contacts,
    state_in,
    state_out,
    buffers: StepBuffers,
    *,
    features: StepFeatures,
    dt: float,
    kick: float,
    skin: float,
    velocity_limit: float,
    impact_speed_min: float,
) -> None:
    """Contact forces on every sphere and the leapfrog step of the free ones, ``state_in`` -> ``state_out``,
    with the kernel compiled for ``features`` (the mass-sharing option is ``features.share_mass``).

    ``kick`` is the velocity step [s] (``dt``, or ``dt / 2`` on a fresh state's first step); the impact records
    are ``state_in``'s (a solver's twin states share them); the partner counts go to ``buffers.partner_*_next``.
    """
    m, c, b = model, contacts, buffers
    wp.launch(
        step_spheres_kernel(features, step_max_registers(features)),
        dim=m.sphere_count,
        block_dim=STEP_BLOCK_DIM,
        inputs=[
            m.sphere_radius,
            m.sphere_material,
            m.sphere_world,
            m.sphere_clump,
            m.sphere_body_volume,
            m.sphere_wall,
            m.material_density,
            m.pair_params,
            m.world_gravity,
            m.plane_point,
            m.plane_normal,
            m.plane_material,
            m.plane_world,
            m.wall_mesh,
            m.wall_face_start,
            m.triangle_wall,
            m.wall_material,
            state_in.sphere_x,
            state_in.sphere_v,
            state_in.sphere_w,
            state_in.sphere_active,
            state_in.clump_x,
            state_in.wall_pose,
            state_in.wall_v,
            state_in.wall_w,
            b.clock,
            c.neighbor_count,
            c.neighbor_index,
            c.mesh_count,
            c.mesh_face,
            c.build_x,
            c.partner_key,
            c.partner_count,
            dt,
            kick,
            skin,
            velocity_limit,
            impact_speed_min,
        ],
        outputs=[
            c.neighbor_history,
            c.plane_history,
            c.mesh_history,
            c.neighbor_live,
            c.plane_live,
            b.stiffness_max,
            state_out.sphere_x,
            state_out.sphere_v,
            state_out.sphere_w,
            state_out.sphere_f,
            state_out.sphere_t,
            b.wall_f_lanes,
            b.wall_t_lanes,
            state_in.face_impact_count,
            state_in.face_impact_energy,
            state_in.face_impact_speed,
            b.partner_key_next,
            b.partner_count_next,
            c.rebuild,
            b.blowup,
        ],
        device=m.device,
    )


@wp.func
def body_angular_velocity(q: wp.quat, inertia: wp.vec3, angmom: wp.vec3):
    """World angular velocity R I^-1 R^T L of a body with principal moments ``inertia`` [kg m^2]."""
    lb = wp.quat_rotate_inv(q, angmom)
    return wp.quat_rotate(q, wp.vec3(lb[0] / inertia[0], lb[1] / inertia[1], lb[2] / inertia[2]))


@wp.func
def quat_step(q: wp.quat, w: wp.vec3, h: float):
    """Rotate q by the rotation vector w h (exact for a constant w), renormalised."""
    angle = wp.length(w) * h
    if angle > 0.0:
        q = wp.mul(wp.quat_from_axis_angle(wp.normalize(w), angle), q)
    return wp.normalize(q)


@functools.cache
def integrate_clumps_kernel(tiled: bool):
    """:func:`integrate_clumps` for blocks of lanes per clump (``tiled``), or one thread per clump."""

    @wp.kernel(module="unique", module_options=MODULE_OPTIONS)
    def integrate_clumps(
        # Model:
        clump_sphere_start: wp.array[int],
        clump_sphere_end: wp.array[int],
        clump_material: wp.array[int],
        clump_world: wp.array[int],
        clump_volume: wp.array[float],
        clump_inertia: wp.array[wp.vec3],
        sphere_offset: wp.array[wp.vec3],
        material_density: wp.array2d[float],
        world_gravity: wp.array[wp.vec3],
        # State in (sphere_f and sphere_t: this step's, from step_spheres):
        active_in: wp.array[int],
        sphere_f: wp.array[wp.vec3],
        sphere_t: wp.array[wp.vec3],
        x_in: wp.array[wp.vec3],
        q_in: wp.array[wp.quat],
        v_in: wp.array[wp.vec3],
        angmom_in: wp.array[wp.vec3],
        clock: wp.array[int],
        # Options:
        dt: float,
        kick: float,
        velocity_limit: float,
        lanes: int,
        # Out:
        x_out: wp.array[wp.vec3],
        q_out: wp.array[wp.quat],
        v_out: wp.array[wp.vec3],
        angmom_out: wp.array[wp.vec3],
        w_out: wp.array[wp.vec3],
        f_out: wp.array[wp.vec3],
        t_out: wp.array[wp.vec3],
        blowup_out: wp.array[int],
    ):
        """Reduce component forces to each clump (r x f) and integrate it (:func:`place_clump_spheres` then places
        the components).

        Tiled (large clumps on CUDA), ``lanes`` = ``CLUMP_LANES`` threads per clump: each lane sums every lanes-th
        component in order and a tile reduction adds the lanes in a fixed tree, so the sum is deterministic; a
        clump of 141 spheres does not wait on one thread's serial loop. Every lane integrates the body (the same
        arithmetic, so the same numbers); lane 0 writes it. Otherwise one thread per clump (launched over
        (clump_count, 1), lanes = 1) sums its components in order.

        Leapfrog on momentum and on angular momentum L (world frame, so a torque-free body keeps L
        exactly); the orientation advances by an explicit midpoint rule with L held at its half-step value.
        """
        c, lane = wp.tid()
        first = clump_sphere_start[c]
        last = clump_sphere_end[c]
        x_c = x_in[c]
        q_c = q_in[c]
        if active_in[first] != SphereActivity.MOVING:
            if lane == 0:
                x_out[c] = x_c
                q_out[c] = q_c
                v_out[c] = v_in[c]
                angmom_out[c] = angmom_in[c]
            # parked (not released yet), removed (left the domain) or settled: held where it is
            return
        world = clump_world[c]
        rho = material_density[world % material_density.shape[0], clump_material[c]]
        mass = rho * clump_volume[c]
        inertia = rho * clump_inertia[c]

        f_lane = wp.vec3(0.0)
        t_lane = wp.vec3(0.0)
        for s in range(first + lane, last, lanes):
            fs = sphere_f[s]
            f_lane += fs
            t_lane += sphere_t[s] + wp.cross(wp.quat_rotate(q_c, sphere_offset[s]), fs)
        f = f_lane
        t = t_lane
        if wp.static(tiled):
            f = wp.tile_extract(wp.tile_sum(wp.tile(f_lane, preserve_type=True)), 0)
            t = wp.tile_extract(wp.tile_sum(wp.tile(t_lane, preserve_type=True)), 0)

        g = world_gravity[world % world_gravity.shape[0]]
        v_new = v_in[c] + kick * (f / mass + g)
        angmom = angmom_in[c] + kick * t
        x_new = x_c + dt * v_new
        w_start = body_angular_velocity(q_c, inertia, angmom)
        q_mid = quat_step(q_c, w_start, 0.5 * dt)
        w_mid = body_angular_velocity(q_mid, inertia, angmom)
        q_new = quat_step(q_c, w_mid, dt)

        if lane == 0:
            f_out[c] = f
            t_out[c] = t
            x_out[c] = x_new
            q_out[c] = q_new
            v_out[c] = v_new
            angmom_out[c] = angmom
            w_out[c] = w_mid

        if lane == 0:
            if not (wp.length(v_new) <= velocity_limit) or not wp.isfinite(x_new) or not wp.isfinite(w_mid):
                flag_blowup(blowup_out, clock[0], first)

    return integrate_clumps


def launch_integrate_clumps(
    model,
    contacts,
    state_in,
    state_out,
    buffers: StepBuffers,
    *,
    features: StepFeatures,
    dt: float,
    kick: float,
    skin: float,
    velocity_limit: float,
) -> None:
    """Reduce the forces :func:`launch_step_spheres` left on the clumps' spheres and step the clumps (tiled with
    ``CLUMP_LANES`` threads per clump on CUDA where ``features.large_clumps``, else one thread per clump), then
    place their spheres (one thread per sphere)."""
    m, c, b = model, contacts, buffers
    tiled = features.large_clumps and wp.get_device(m.device).is_cuda
    lanes = CLUMP_LANES if tiled else 1
    launch = (
        functools.partial(wp.launch_tiled, dim=[m.clump_count], block_dim=lanes)
        if tiled
        else functools.partial(wp.launch, dim=(m.clump_count, 1))
    )
    launch(
        integrate_clumps_kernel(tiled),
        inputs=[
            m.clump_sphere_start,
            m.clump_sphere_end,
            m.clump_material,
            m.clump_world,
            m.clump_volume,
            m.clump_inertia,
            m.sphere_offset,
            m.material_density,
            m.world_gravity,
            state_in.sphere_active,
            state_out.sphere_f,
            state_out.sphere_t,
            state_in.clump_x,
            state_in.clump_q,
            state_in.clump_v,
            state_in.clump_angmom,
            b.clock,
            dt,
            kick,
            velocity_limit,
            lanes,
        ],
        outputs=[
            state_out.clump_x,
            state_out.clump_q,
            state_out.clump_v,
            state_out.clump_angmom,
            state_out.clump_w,
            state_out.clump_f,
            state_out.clump_t,
            b.blowup,
        ],
        device=m.device,
    )
    wp.launch(
        place_clump_spheres,
        dim=m.sphere_count,
        inputs=[
            m.sphere_clump,
            m.clump_sphere_start,
            m.sphere_offset,
            state_in.sphere_active,
            c.build_x,
            state_out.clump_x,
            state_out.clump_q,
            state_out.clump_v,
            state_out.clump_w,
            skin,
        ],
        outputs=[state_out.sphere_x, state_out.sphere_v, state_out.sphere_w, c.rebuild],
        device=m.device,
    )


@wp.kernel
def place_clump_spheres(
    # Model:
    sphere_clump: wp.array[int],
    clump_sphere_start: wp.array[int],
    sphere_offset: wp.array[wp.vec3],
    # State in:
    active_in: wp.array[int],
    # Contacts in:
    build_x: wp.array[wp.vec3],
    # State out (the clumps integrate_clumps just stepped; w: the midpoint angular velocity):
    clump_x: wp.array[wp.vec3],
    clump_q: wp.array[wp.quat],
    clump_v: wp.array[wp.vec3],
    clump_w: wp.array[wp.vec3],
    # Options:
    skin: float,
    # Out:
    sphere_x_out: wp.array[wp.vec3],
    sphere_v_out: wp.array[wp.vec3],
    sphere_w_out: wp.array[wp.vec3],
    rebuild_out: wp.array[int],
):
    """Place each clump's spheres on its new pose, with the rigid body's velocity at their centres; flag a
    rebuild once one has moved half the skin. One thread per sphere, so the reads and writes of the sphere
    arrays are coalesced: a thread per clump walking its spheres strided them across a warp, and an H100 moved
    most of its bytes as excess sectors."""
    s = wp.tid()
    c = sphere_clump[s]
    if c < 0:
        return
    arm = wp.quat_rotate(clump_q[c], sphere_offset[s])
    xs = clump_x[c] + arm
    sphere_x_out[s] = xs
    if active_in[clump_sphere_start[c]] != SphereActivity.MOVING:
        # parked (not released yet), removed (left the domain) or settled: held where it is
        sphere_v_out[s] = clump_v[c]
        sphere_w_out[s] = wp.vec3(0.0)
        return
    w = clump_w[c]
    sphere_v_out[s] = clump_v[c] + wp.cross(w, arm)
    sphere_w_out[s] = w
    if wp.length(xs - build_x[s]) > 0.5 * skin:
        rebuild_out[0] = 1


@wp.kernel
def roll_partners(
    # Out (read, then emptied):
    partner_key_next_out: wp.array[int],
    partner_count_next_out: wp.array[int],
    # Out:
    partner_key_out: wp.array[int],
    partner_count_out: wp.array[int],
):
    """The partner tables just filled become the ones the next step reads; the fill tables are emptied."""
    t = wp.tid()
    partner_key_out[t] = partner_key_next_out[t]
    partner_count_out[t] = partner_count_next_out[t]
    partner_key_next_out[t] = -1
    partner_count_next_out[t] = 0


def launch_roll_partners(model, contacts, buffers: StepBuffers) -> None:
    """Hand the partner tables the step just filled to the next step."""
    b = buffers
    wp.launch(
        roll_partners,
        dim=b.partner_key_next.shape[0],
        outputs=[b.partner_key_next, b.partner_count_next, contacts.partner_key, contacts.partner_count],
        device=model.device,
    )


@wp.kernel
def init_clumps(
    # Model:
    clump_material: wp.array[int],
    clump_world: wp.array[int],
    clump_volume: wp.array[float],
    clump_inertia: wp.array[wp.vec3],
    material_density: wp.array2d[float],
    # State in:
    q: wp.array[wp.quat],
    w: wp.array[wp.vec3],
    # Out:
    angmom_out: wp.array[wp.vec3],
):
    """Angular momentum L = R I R^T w of each clump from its angular velocity (a fresh state gives w)."""
    c = wp.tid()
    world = clump_world[c]
    rho = material_density[world % material_density.shape[0], clump_material[c]]
    inertia = rho * clump_inertia[c]
    wb = wp.quat_rotate_inv(q[c], w[c])
    angmom_out[c] = wp.quat_rotate(q[c], wp.vec3(wb[0] * inertia[0], wb[1] * inertia[1], wb[2] * inertia[2]))


def launch_init_clumps(model, state) -> None:
    """The clumps' angular momenta from their angular velocities (a fresh state holds the latter)."""
    m = model
    wp.launch(
        init_clumps,
        dim=m.clump_count,
        inputs=[
            m.clump_material,
            m.clump_world,
            m.clump_volume,
            m.clump_inertia,
            m.material_density,
            state.clump_q,
            state.clump_w,
        ],
        outputs=[state.clump_angmom],
        device=m.device,
    )


@wp.kernel
def move_walls(
    # Control:
    segment_start: wp.array[int],
    segment_t0: wp.array[wp.float64],
    segment_t1: wp.array[wp.float64],
    segment_v: wp.array[wp.vec3],
    segment_w: wp.array[wp.vec3],
    segment_pivot: wp.array[wp.vec3],
    segment_pose: wp.array[wp.transform],
    # Model:
    wall_radius: wp.array[float],
    # State in:
    time: wp.array[wp.float64],
    # Contacts in:
    wall_build_pose: wp.array[wp.transform],
    # Options:
    skin: float,
    slot: int,
    # Out:
    pose_out: wp.array[wp.transform],
    v_out: wp.array[wp.vec3],
    w_out: wp.array[wp.vec3],
    rebuild_out: wp.array[int],
):
    """Pose and velocity of each wall at ``time[slot]`` from its motion segments; flag a rebuild once
    any point of the wall may have moved skin/2 since the lists were built."""
    wall = wp.tid()
    t = time[slot]
    s = segment_start[wall]
    last = segment_start[wall + 1] - 1
    while s < last and t >= segment_t1[s]:
        s += 1
    tau = float(wp.max(t - segment_t0[s], wp.float64(0.0)))
    v = segment_v[s]
    w = segment_w[s]
    pivot = segment_pivot[s] + v * tau
    pose0 = segment_pose[s]
    angle = wp.length(w) * tau
    rot = wp.quat_identity()
    if angle > 0.0:
        rot = wp.quat_from_axis_angle(wp.normalize(w), angle)
    p0 = wp.transform_get_translation(pose0)
    origin = pivot + wp.quat_rotate(rot, p0 - segment_pivot[s])
    pose = wp.transform(origin, wp.normalize(wp.mul(rot, wp.transform_get_rotation(pose0))))
    pose_out[wall] = pose
    v_out[wall] = v + wp.cross(w, origin - pivot)
    w_out[wall] = w

    built = wall_build_pose[wall]
    rel = wp.mul(wp.transform_get_rotation(pose), wp.quat_inverse(wp.transform_get_rotation(built)))
    turn = 2.0 * wp.acos(wp.min(wp.abs(rel[3]), 1.0))
    shift = wp.length(origin - wp.transform_get_translation(built))
    if shift + turn * wall_radius[wall] > 0.5 * skin:
        rebuild_out[0] = 1


def launch_move_walls(
    model,
    control,
    contacts,
    state,
    buffers: StepBuffers,
    *,
    skin: float,
    rebuild: wp.array,
) -> None:
    """The walls' poses and velocities at the device time ``buffers.time[1]`` into ``state``; ``rebuild`` is
    flagged once a wall may have moved half the skin since the lists were built."""
    m, ctl = model, control
    wp.launch(
        move_walls,
        dim=m.wall_count,
        inputs=[
            ctl.segment_start,
            ctl.segment_t0,
            ctl.segment_t1,
            ctl.segment_v,
            ctl.segment_w,
            ctl.segment_pivot,
            ctl.segment_pose,
            m.wall_radius,
            buffers.time,
            contacts.wall_build_pose,
            skin,
            1,
        ],
        outputs=[state.wall_pose, state.wall_v, state.wall_w, rebuild],
        device=m.device,
    )


@wp.kernel
def follow_walls(
    # Model:
    attached_index: wp.array[int],
    sphere_wall: wp.array[int],
    sphere_offset: wp.array[wp.vec3],
    # State in:
    wall_pose: wp.array[wp.transform],
    wall_v: wp.array[wp.vec3],
    wall_w: wp.array[wp.vec3],
    # Contacts in:
    build_x: wp.array[wp.vec3],
    # Options:
    skin: float,
    # Out:
    x_out: wp.array[wp.vec3],
    v_out: wp.array[wp.vec3],
    w_out: wp.array[wp.vec3],
    rebuild_out: wp.array[int],
):
    """Place the spheres glued to walls (a particle-coated surface) at their wall's pose and give them the
    wall's velocity at their centre."""
    k = wp.tid()
    i = attached_index[k]
    wall = sphere_wall[i]
    pose = wall_pose[wall]
    x = wp.transform_point(pose, sphere_offset[i])
    x_out[i] = x
    v_out[i] = wall_v[wall] + wp.cross(wall_w[wall], x - wp.transform_get_translation(pose))
    w_out[i] = wall_w[wall]
    if wp.length(x - build_x[i]) > 0.5 * skin:
        rebuild_out[0] = 1


def launch_follow_walls(model, contacts, state, *, skin: float, rebuild: wp.array) -> None:
    """Place the spheres glued to walls at their walls' poses in ``state``; ``rebuild`` as for the walls."""
    m = model
    wp.launch(
        follow_walls,
        dim=m.attached_count,
        inputs=[
            m.attached_index,
            m.sphere_wall,
            m.sphere_offset,
            state.wall_pose,
            state.wall_v,
            state.wall_w,
            contacts.build_x,
            skin,
        ],
        outputs=[state.sphere_x, state.sphere_v, state.sphere_w, rebuild],
        device=m.device,
    )


@wp.kernel
def begin_step(
    # Options:
    dt: wp.float64,
    # Out (clock and time: read, then advanced):
    wall_f_lanes_out: wp.array2d[wp.vec3],
    wall_t_lanes_out: wp.array2d[wp.vec3],
    clock_out: wp.array[int],
    time_out: wp.array[wp.float64],
):
    """Zero the partial wall accumulators, advance the device step counter and the device time
    (time[0]: this step's start, time[1]: its end)."""
    wall, lane = wp.tid()
    wall_f_lanes_out[wall, lane] = wp.vec3(0.0)
    wall_t_lanes_out[wall, lane] = wp.vec3(0.0)
    if wall == 0 and lane == 0:
        clock_out[0] = clock_out[0] + 1
        t = time_out[1]
        time_out[0] = t
        time_out[1] = t + dt


def launch_begin_step(model, buffers: StepBuffers, dt: float) -> None:
    """Open a step of ``dt`` [s]: zero the wall accumulators, advance the device clock and time."""
    b = buffers
    wp.launch(
        begin_step,
        dim=b.wall_f_lanes.shape,
        inputs=[wp.float64(dt)],
        outputs=[b.wall_f_lanes, b.wall_t_lanes, b.clock, b.time],
        device=model.device,
    )


@wp.kernel
def sum_wall_forces(
    # State in (this step's partial sums):
    wall_f_lanes: wp.array2d[wp.vec3],
    wall_t_lanes: wp.array2d[wp.vec3],
    impulse_in: wp.array[wp.vec3d],
    # Options:
    dt: wp.float64,
    # Out:
    wall_f_out: wp.array[wp.vec3],
    wall_t_out: wp.array[wp.vec3],
    impulse_out: wp.array[wp.vec3d],
):
    """Sum the partial accumulators of each wall (a block per wall: a tree sum in a fixed order, so deterministic);
    accumulate the impulse. One thread per wall walking its lanes waited on 256 dependent loads, tens of
    microseconds a step on a GPU. Every thread of a block writes the same sums (impulse_in and impulse_out are
    the two states' arrays, never one)."""
    wall = wp.tid()
    f = wp.tile_sum(wp.tile_load(wall_f_lanes[wall], shape=WALL_LANES))[0]
    t = wp.tile_sum(wp.tile_load(wall_t_lanes[wall], shape=WALL_LANES))[0]
    wall_f_out[wall] = f
    wall_t_out[wall] = t
    impulse_out[wall] = impulse_in[wall] + wp.vec3d(f) * dt


def launch_sum_wall_forces(model, state_in, state_out, buffers: StepBuffers, dt: float) -> None:
    """Each surface's force and torque of the step into ``state_out``, its impulse summed on from ``state_in``."""
    b = buffers
    wp.launch_tiled(
        sum_wall_forces,
        dim=[model.plane_count + model.wall_count],
        inputs=[b.wall_f_lanes, b.wall_t_lanes, state_in.wall_impulse, wp.float64(dt)],
        outputs=[state_out.wall_f, state_out.wall_t, state_out.wall_impulse],
        block_dim=WALL_LANES,
        device=model.device,
    )


@wp.kernel
def place_bodies(
    # Model:
    clump_sphere_start: wp.array[int],
    clump_sphere_end: wp.array[int],
    sphere_offset: wp.array[wp.vec3],
    # Batch in (host-prepared; clump_x, clump_q, clump_v indexed by batch entry):
    sphere_index: wp.array[int],
    sphere_x: wp.array[wp.vec3],
    sphere_v: wp.array[wp.vec3],
    clump_index: wp.array[int],
    clump_x: wp.array[wp.vec3],
    clump_q: wp.array[wp.quat],
    clump_v: wp.array[wp.vec3],
    # Out:
    x_out: wp.array[wp.vec3],
    v_out: wp.array[wp.vec3],
    w_out: wp.array[wp.vec3],
    active_out: wp.array[int],
    clump_x_out: wp.array[wp.vec3],
    clump_q_out: wp.array[wp.quat],
    clump_v_out: wp.array[wp.vec3],
    clump_angmom_out: wp.array[wp.vec3],
    rebuild_out: wp.array[int],
):
    """Release factory particles: entries below len(sphere_index) are free spheres, the rest clumps."""
    k = wp.tid()
    n_s = sphere_index.shape[0]
    if k < n_s:
        i = sphere_index[k]
        x_out[i] = sphere_x[k]
        v_out[i] = sphere_v[k]
        w_out[i] = wp.vec3(0.0)
        active_out[i] = SphereActivity.MOVING
    else:
        c = clump_index[k - n_s]
        clump_x_out[c] = clump_x[k - n_s]
        clump_q_out[c] = clump_q[k - n_s]
        clump_v_out[c] = clump_v[k - n_s]
        clump_angmom_out[c] = wp.vec3(0.0)
        for s in range(clump_sphere_start[c], clump_sphere_end[c]):
            x_out[s] = clump_x[k - n_s] + wp.quat_rotate(clump_q[k - n_s], sphere_offset[s])
            v_out[s] = clump_v[k - n_s]
            w_out[s] = wp.vec3(0.0)
            active_out[s] = SphereActivity.MOVING
    rebuild_out[0] = 1


def launch_place_bodies(
    model,
    contacts,
    state,
    sphere_index,
    sphere_x,
    sphere_v,
    clump_index,
    clump_x,
    clump_q,
    clump_v,
) -> None:
    """Activate parked particles at the given places and flag a rebuild. Host arrays: spheres (n,), (n, 3), (n, 3)
    [m, m/s]; clumps (k,), (k, 3), (k, 4) quaternions (x, y, z, w), (k, 3)."""
    m, dev = model, model.device

    def arr(a, dtype, width=None):
        a = np.asarray(a, dtype=np.float32 if width else np.int32)
        if width:
            a = a.reshape(-1, width)
        if len(a) == 0:
            a = np.zeros((1, width) if width else 1, dtype=a.dtype)
        return wp.array(a, dtype=dtype, device=dev)

    n = len(sphere_index) + len(clump_index)
    if n == 0:
        return
    wp.launch(
        place_bodies,
        dim=n,
        inputs=[
            m.clump_sphere_start,
            m.clump_sphere_end,
            m.sphere_offset,
            # not padded: its length tells the kernel where the clumps begin
            wp.array(np.asarray(sphere_index, dtype=np.int32), dtype=int, device=dev),
            arr(sphere_x, wp.vec3, 3),
            arr(sphere_v, wp.vec3, 3),
            arr(clump_index, int),
            arr(clump_x, wp.vec3, 3),
            arr(clump_q, wp.quat, 4),
            arr(clump_v, wp.vec3, 3),
        ],
        outputs=[
            state.sphere_x,
            state.sphere_v,
            state.sphere_w,
            state.sphere_active,
            state.clump_x,
            state.clump_q,
            state.clump_v,
            state.clump_angmom,
            contacts.rebuild,
        ],
        device=dev,
    )


@wp.kernel
def retire_escaped(
    # Model:
    sphere_clump: wp.array[int],
    sphere_world: wp.array[int],
    sphere_wall: wp.array[int],
    clump_sphere_start: wp.array[int],
    low: wp.vec3,
    high: wp.vec3,
    # State in:
    x_in: wp.array[wp.vec3],
    clump_x_in: wp.array[wp.vec3],
    # Out (active_out and world_removed_out: read, then written):
    active_out: wp.array[int],
    v_out: wp.array[wp.vec3],
    w_out: wp.array[wp.vec3],
    clump_v_out: wp.array[wp.vec3],
    clump_angmom_out: wp.array[wp.vec3],
    clump_w_out: wp.array[wp.vec3],
    world_removed_out: wp.array[int],
):
    """Remove the bodies whose centre is outside the domain box [low, high]: their spheres become inactive
    and at rest (so they neither touch anything nor flag rebuilds); each removed body counts once in its
    world. Every sphere of a clump tests the clump's centre, so a clump leaves whole."""
    i = wp.tid()
    if active_out[i] != SphereActivity.MOVING or sphere_wall[i] >= 0:
        return
    c = sphere_clump[i]
    p = x_in[i]
    if c >= 0:
        p = clump_x_in[c]
    inside = p[0] >= low[0] and p[1] >= low[1] and p[2] >= low[2]
    inside = inside and p[0] <= high[0] and p[1] <= high[1] and p[2] <= high[2]
    if inside:
        return
    active_out[i] = 0
    v_out[i] = wp.vec3(0.0)
    w_out[i] = wp.vec3(0.0)
    if c < 0 or i == clump_sphere_start[c]:
        wp.atomic_add(world_removed_out, sphere_world[i] % world_removed_out.shape[0], 1)
        if c >= 0:
            clump_v_out[c] = wp.vec3(0.0)
            clump_angmom_out[c] = wp.vec3(0.0)
            clump_w_out[c] = wp.vec3(0.0)


def launch_retire_escaped(model, state) -> None:
    """Remove the bodies whose centre left ``model.domain`` (a model without a domain keeps them all)."""
    m = model
    if m.domain is None:
        return
    wp.launch(
        retire_escaped,
        dim=m.sphere_count,
        inputs=[
            m.sphere_clump,
            m.sphere_world,
            m.sphere_wall,
            m.clump_sphere_start,
            wp.vec3(*m.domain[0]),
            wp.vec3(*m.domain[1]),
            state.sphere_x,
            state.clump_x,
        ],
        outputs=[
            state.sphere_active,
            state.sphere_v,
            state.sphere_w,
            state.clump_v,
            state.clump_angmom,
            state.clump_w,
            state.world_removed,
        ],
        device=m.device,
    )


@wp.kernel
def settle_worlds(
    # Model:
    sphere_world: wp.array[int],
    # Options (host-prepared):
    world_settled: wp.array[int],
    # Out (read, then written):
    active_out: wp.array[int],
):
    """Hold the moving spheres of every world flagged in ``world_settled`` where they are (SETTLED)."""
    i = wp.tid()
    if active_out[i] == SphereActivity.MOVING and world_settled[sphere_world[i]] != 0:
        active_out[i] = SphereActivity.SETTLED


def launch_settle_worlds(model, state, worlds) -> None:
    """Hold the spheres of ``worlds`` (host ints) where they are: stepping, the contact search, wall forces and
    removal leave them out from the next step on, and nothing of them moves again. Their clumps' poses and
    velocities stay as they were."""
    m = model
    flags = np.zeros(m.world_count, dtype=np.int32)
    flags[np.asarray(worlds, dtype=np.int64)] = 1
    wp.launch(
        settle_worlds,
        dim=m.sphere_count,
        inputs=[m.sphere_world, wp.array(flags, dtype=int, device=m.device)],
        outputs=[state.sphere_active],
        device=m.device,
    )
