"""The fused time step: contact forces from the neighbour lists, then leapfrog integration.

One thread per sphere gathers every contact of its sphere (partners, planes, mesh triangles), so no
force atomics are needed and the sum order is fixed: results are deterministic on CPU and CUDA and
world k of a batch computes exactly what a solo run computes. Each sphere-sphere pair is evaluated
by both partners in canonical order (lower index as body a), which keeps the two copies of its
history identical and makes the forces exactly equal and opposite.
"""

import warp as wp

from .geometry import FEATURE_FACE, sphere_mass, triangle_closest
from .law_hertz_mindlin import hertz_mindlin
from .law_rolling import ROLLING_EPSD, rolling_resistance
from .params import PairParams

wp.set_module_options({"enable_backward": False})

BLOWUP_NONE = wp.constant(2147483647)
WALL_LANES = wp.constant(256)
"""Partial accumulators per wall: spreads the force atomics of thousands of spheres on one wall."""


@wp.func
def mesh_contact_shadowed(
    mesh: wp.uint64,
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
        q_m, feature_m = triangle_closest(mesh, face_m, x)
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


@wp.func
def wall_contact(
    overlap: float,
    n: wp.vec3,
    v_i: wp.vec3,
    w_i: wp.vec3,
    r_i: float,
    m_i: float,
    p: PairParams,
    spring: wp.vec3,
    roll: wp.vec3,
    dt: float,
):
    """A sphere against a static wall (infinite radius and mass) along unit normal n (sphere -> wall).

    Returns:
        (force on the sphere [N], torque on the sphere [N m], updated spring [m], updated rolling spring [N m]).
    """
    arm = r_i - 0.5 * overlap
    v_rel = v_i + wp.cross(w_i, arm * n)
    f_a, f_n, f_t, xi, k_n = hertz_mindlin(overlap, n, v_rel, spring, r_i, m_i, p, dt)
    m_roll, roll_new = rolling_resistance(p.rolling_model, w_i, n, f_n, r_i, p.mu_r, k_n, 1.4 * m_i * r_i * r_i,
                                          p.rolling_damping, roll, dt)
    return f_a, wp.cross(arm * n, f_t) + m_roll, xi, roll_new


@wp.kernel
def step_spheres(
    # Model:
    sphere_radius: wp.array[float],
    sphere_material: wp.array[int],
    sphere_world: wp.array[int],
    material_density: wp.array2d[float],
    pair_params: wp.array3d[PairParams],
    world_gravity: wp.array[wp.vec3],
    plane_point: wp.array[wp.vec3],
    plane_normal: wp.array[wp.vec3],
    plane_material: wp.array[int],
    plane_world: wp.array[int],
    mesh: wp.uint64,
    triangle_wall: wp.array[int],
    wall_material: wp.array[int],
    wall_world: wp.array[int],
    # Contacts in/out (each thread owns its column):
    neighbor_count: wp.array[int],
    neighbor_index: wp.array2d[int],
    neighbor_spring: wp.array2d[wp.vec3],
    neighbor_roll: wp.array2d[wp.vec3],
    plane_spring: wp.array2d[wp.vec3],
    plane_roll: wp.array2d[wp.vec3],
    mesh_count: wp.array[int],
    mesh_face: wp.array2d[int],
    mesh_spring: wp.array2d[wp.vec3],
    mesh_roll: wp.array2d[wp.vec3],
    build_x: wp.array[wp.vec3],
    # State in:
    x_in: wp.array[wp.vec3],
    v_in: wp.array[wp.vec3],
    w_in: wp.array[wp.vec3],
    # Step:
    dt: float,
    kick: float,
    skin: float,
    velocity_limit: float,
    clock: wp.array[int],
    # Out:
    x_out: wp.array[wp.vec3],
    v_out: wp.array[wp.vec3],
    w_out: wp.array[wp.vec3],
    f_out: wp.array[wp.vec3],
    t_out: wp.array[wp.vec3],
    wall_f_out: wp.array2d[wp.vec3],
    rebuild_out: wp.array[int],
    blowup_out: wp.array[int],
):
    i = wp.tid()
    world = sphere_world[i]
    mat_i = sphere_material[i]
    r_i = sphere_radius[i]
    m_i = sphere_mass(r_i, material_density[world % material_density.shape[0], mat_i])
    inertia_i = 0.4 * m_i * r_i * r_i
    x_i = x_in[i]
    v_i = v_in[i]
    w_i = w_in[i]
    pw = world % pair_params.shape[0]
    mw = world % material_density.shape[0]

    f = wp.vec3(0.0)
    t = wp.vec3(0.0)

    # sphere-sphere
    for k in range(neighbor_count[i]):
        j = neighbor_index[k, i]
        a = wp.min(i, j)
        b = wp.max(i, j)
        r_a = sphere_radius[a]
        r_b = sphere_radius[b]
        d = x_in[b] - x_in[a]
        dist = wp.length(d)
        overlap = r_a + r_b - dist
        if overlap <= 0.0 or dist <= 0.0:
            neighbor_spring[k, i] = wp.vec3(0.0)
            neighbor_roll[k, i] = wp.vec3(0.0)
            continue
        n = d / dist
        mat_a = sphere_material[a]
        mat_b = sphere_material[b]
        m_a = sphere_mass(r_a, material_density[mw, mat_a])
        m_b = sphere_mass(r_b, material_density[mw, mat_b])
        r_star = r_a * r_b / (r_a + r_b)
        m_star = m_a * m_b / (m_a + m_b)
        arm_a = r_a - 0.5 * overlap
        arm_b = r_b - 0.5 * overlap
        w_a = w_in[a]
        w_b = w_in[b]
        v_rel = (v_in[a] + wp.cross(w_a, arm_a * n)) - (v_in[b] - wp.cross(w_b, arm_b * n))
        p = pair_params[pw, mat_a, mat_b]
        f_a, f_n, f_t, xi, k_n = hertz_mindlin(overlap, n, v_rel, neighbor_spring[k, i], r_star, m_star, p, dt)
        neighbor_spring[k, i] = xi
        i_roll = 0.0
        if p.rolling_model == ROLLING_EPSD:
            i_roll = 1.0 / (1.0 / (1.4 * m_a * r_a * r_a) + 1.0 / (1.4 * m_b * r_b * r_b))
        m_roll, roll = rolling_resistance(p.rolling_model, w_a - w_b, n, f_n, r_star, p.mu_r, k_n, i_roll,
                                          p.rolling_damping, neighbor_roll[k, i], dt)
        neighbor_roll[k, i] = roll
        if i == a:
            f += f_a
            t += wp.cross(arm_a * n, f_t) + m_roll
        else:
            f -= f_a
            t += wp.cross(arm_b * n, f_t) - m_roll

    # infinite planes
    for p_id in range(plane_point.shape[0]):
        pl_world = plane_world[p_id]
        if pl_world >= 0 and pl_world != world:
            continue
        n_p = plane_normal[p_id]
        gap = wp.dot(x_i - plane_point[p_id], n_p)
        overlap = r_i - gap
        if overlap <= 0.0:
            plane_spring[p_id, i] = wp.vec3(0.0)
            plane_roll[p_id, i] = wp.vec3(0.0)
            continue
        p = pair_params[pw, mat_i, plane_material[p_id]]
        f_a, t_a, xi, roll = wall_contact(overlap, -n_p, v_i, w_i, r_i, m_i, p, plane_spring[p_id, i],
                                          plane_roll[p_id, i], dt)
        plane_spring[p_id, i] = xi
        plane_roll[p_id, i] = roll
        f += f_a
        t += t_a
        wp.atomic_add(wall_f_out, p_id, i % WALL_LANES, -f_a)

    # static triangle meshes
    plane_total = plane_point.shape[0]
    for k in range(mesh_count[i]):
        face = mesh_face[k, i]
        wall = triangle_wall[face]
        q, feature = triangle_closest(mesh, face, x_i)
        dq = x_i - q
        gap = wp.length(dq)
        overlap = r_i - gap
        skip = overlap <= 0.0 or gap <= 0.0
        if not skip and feature != FEATURE_FACE:
            skip = mesh_contact_shadowed(mesh, x_i, r_i, k, q, feature, wall, i, mesh_count, mesh_face,
                                         triangle_wall)
        if skip:
            mesh_spring[k, i] = wp.vec3(0.0)
            mesh_roll[k, i] = wp.vec3(0.0)
            continue
        p = pair_params[pw, mat_i, wall_material[wall]]
        f_a, t_a, xi, roll = wall_contact(overlap, -dq / gap, v_i, w_i, r_i, m_i, p, mesh_spring[k, i],
                                          mesh_roll[k, i], dt)
        mesh_spring[k, i] = xi
        mesh_roll[k, i] = roll
        f += f_a
        t += t_a
        wp.atomic_add(wall_f_out, plane_total + wall, i % WALL_LANES, -f_a)

    # leapfrog (velocity Verlet): v(t+dt/2) = v(t-dt/2) + dt a(t); the first step kicks by dt/2
    g = world_gravity[world % world_gravity.shape[0]]
    v_new = v_i + kick * (f / m_i + g)
    w_new = w_i + kick * (t / inertia_i)
    x_new = x_i + dt * v_new
    x_out[i] = x_new
    v_out[i] = v_new
    w_out[i] = w_new
    f_out[i] = f
    t_out[i] = t

    speed = wp.length(v_new)
    if not (speed <= velocity_limit) or not wp.isfinite(x_new) or not wp.isfinite(w_new):
        step = clock[0]
        first = blowup_out[1]
        if first == BLOWUP_NONE or first == step:
            wp.atomic_min(blowup_out, 1, step)
            wp.atomic_min(blowup_out, 0, i)
    if wp.length(x_new - build_x[i]) > 0.5 * skin:
        rebuild_out[0] = 1


@wp.kernel
def begin_step(
    # Out:
    wall_f_lanes_out: wp.array2d[wp.vec3],
    clock_out: wp.array[int],
):
    """Zero the partial wall-force accumulators and advance the device step counter (read by step_spheres)."""
    wall, lane = wp.tid()
    wall_f_lanes_out[wall, lane] = wp.vec3(0.0)
    if wall == 0 and lane == 0:
        clock_out[0] = clock_out[0] + 1


@wp.kernel
def sum_wall_forces(
    # In:
    wall_f_lanes: wp.array2d[wp.vec3],
    # Out:
    wall_f_out: wp.array[wp.vec3],
):
    """Sum the partial accumulators of each wall in a fixed order (deterministic)."""
    wall = wp.tid()
    f = wp.vec3(0.0)
    for lane in range(wall_f_lanes.shape[1]):
        f += wall_f_lanes[wall, lane]
    wall_f_out[wall] = f
