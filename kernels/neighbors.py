"""Neighbour search with a Verlet skin and history carried across rebuilds by sorted-key matching.

Sphere candidates come from a ``wp.HashGrid`` grouped by world (the world id keeps overlapping
worlds apart, so every world sits at the origin). Triangle candidates come from the mesh BVH.
Each sphere's new candidate list is sorted by partner (or face) index and every new entry looks its
key up, by binary search, in the sphere's previous sorted list to inherit the spring history.
"""

import warp as wp

from .geometry import triangle_closest

wp.set_module_options({"enable_backward": False})


@wp.func
def find_sorted(keys: wp.array2d[int], count: int, col: int, key: int):
    """Slot of ``key`` in column ``col`` of ``keys`` (ascending over the first ``count`` slots), or -1."""
    lo = int(0)
    hi = count - 1
    while lo <= hi:
        mid = (lo + hi) // 2
        v = keys[mid, col]
        if v == key:
            return mid
        if v < key:
            lo = mid + 1
        else:
            hi = mid - 1
    return -1


@wp.func
def sort_column(keys: wp.array2d[int], count: int, col: int):
    """Insertion sort of column ``col`` of ``keys`` over its first ``count`` slots (lists are short)."""
    for s in range(1, count):
        key = keys[s, col]
        t = s - 1
        while t >= 0 and keys[t, col] > key:
            keys[t + 1, col] = keys[t, col]
            t -= 1
        keys[t + 1, col] = key


@wp.func
def carry_history(
    old_keys: wp.array2d[int],
    old_count: int,
    old_spring: wp.array2d[wp.vec3],
    old_roll: wp.array2d[wp.vec3],
    new_keys: wp.array2d[int],
    new_count: int,
    new_spring: wp.array2d[wp.vec3],
    new_roll: wp.array2d[wp.vec3],
    col: int,
):
    """Give each new (sorted) entry of column ``col`` the history of the old entry with the same key, else zero."""
    for s in range(new_count):
        slot = find_sorted(old_keys, old_count, col, new_keys[s, col])
        if slot >= 0:
            new_spring[s, col] = old_spring[slot, col]
            new_roll[s, col] = old_roll[slot, col]
        else:
            new_spring[s, col] = wp.vec3(0.0)
            new_roll[s, col] = wp.vec3(0.0)


@wp.kernel
def build_contacts(
    # Model:
    grid: wp.uint64,
    sphere_radius: wp.array[float],
    sphere_world: wp.array[int],
    radius_max: float,
    mesh: wp.uint64,
    has_mesh: int,
    triangle_wall: wp.array[int],
    wall_world: wp.array[int],
    # State in:
    x: wp.array[wp.vec3],
    skin: float,
    # Contacts in (previous lists):
    old_count: wp.array[int],
    old_index: wp.array2d[int],
    old_spring: wp.array2d[wp.vec3],
    old_roll: wp.array2d[wp.vec3],
    old_mesh_count: wp.array[int],
    old_mesh_face: wp.array2d[int],
    old_mesh_spring: wp.array2d[wp.vec3],
    old_mesh_roll: wp.array2d[wp.vec3],
    # Out:
    new_count: wp.array[int],
    new_index: wp.array2d[int],
    new_spring: wp.array2d[wp.vec3],
    new_roll: wp.array2d[wp.vec3],
    new_mesh_count: wp.array[int],
    new_mesh_face: wp.array2d[int],
    new_mesh_spring: wp.array2d[wp.vec3],
    new_mesh_roll: wp.array2d[wp.vec3],
    build_x_out: wp.array[wp.vec3],
    overflow_out: wp.array[int],
):
    i = wp.tid()
    x_i = x[i]
    r_i = sphere_radius[i]
    world = sphere_world[i]
    capacity = new_index.shape[0]

    count = int(0)
    query = wp.hash_grid_query(grid, x_i, r_i + radius_max + skin, world)
    j = int(0)
    while wp.hash_grid_query_next(query, j):
        if j == i:
            continue
        if wp.length(x[j] - x_i) < r_i + sphere_radius[j] + skin:
            if count < capacity:
                new_index[count, i] = j
                count += 1
            else:
                wp.atomic_or(overflow_out, 0, 1)
    sort_column(new_index, count, i)
    carry_history(old_index, old_count[i], old_spring, old_roll, new_index, count, new_spring, new_roll, i)
    new_count[i] = count

    mesh_capacity = new_mesh_face.shape[0]
    mcount = int(0)
    if has_mesh != 0:
        reach = r_i + skin
        lower = x_i - wp.vec3(reach)
        upper = x_i + wp.vec3(reach)
        mq = wp.mesh_query_aabb(mesh, lower, upper)
        face = int(0)
        while wp.mesh_query_aabb_next(mq, face):
            ww = wall_world[triangle_wall[face]]
            if ww >= 0 and ww != world:
                continue
            q, feature = triangle_closest(mesh, face, x_i)
            if wp.length(x_i - q) < reach:
                if mcount < mesh_capacity:
                    new_mesh_face[mcount, i] = face
                    mcount += 1
                else:
                    wp.atomic_or(overflow_out, 0, 2)
        sort_column(new_mesh_face, mcount, i)
        carry_history(old_mesh_face, old_mesh_count[i], old_mesh_spring, old_mesh_roll, new_mesh_face, mcount,
                      new_mesh_spring, new_mesh_roll, i)
    new_mesh_count[i] = mcount
    build_x_out[i] = x_i
