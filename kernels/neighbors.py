"""Neighbour search with a Verlet skin and history carried across rebuilds by sorted-key matching.

Sphere candidates come from a hashed cell grid, keyed by cell and world (the world keeps overlapping worlds apart,
so every world sits at the origin), built as a counting sort of the active spheres into the hash buckets: count
the spheres of each bucket, scan the counts into bucket starts, then scatter each sphere into a slot of its
bucket with a packed copy of what the walk reads (centre and radius; index, world and clump). The walk then
streams each bucket's slots instead of chasing a linked list and gathering every candidate from random
addresses. The scan is plain tiled kernels and the sort takes atomic adds, not CUB, so that a rebuild can sit in a
conditional node of a CUDA graph (Warp's ``HashGrid`` sorts with CUB, which a conditional node cannot hold); the
order within a bucket does not matter because each sphere's candidates are sorted. Triangle candidates come from
the mesh BVH.
Each sphere's new candidate list is sorted by partner (or face) index and merged with the sphere's previous
sorted list: every new entry inherits the history of its key, moved in place (no second history array).

A rebuild: clear_cells, count_cells, sum_cell_tiles, scan_cell_tile_sums, scan_cells, sort_spheres,
build_contacts, commit_contacts. Each kernel has its launcher beside it (``launch_<kernel>``), as in step.py.
"""

import functools
import math
from typing import Any

import warp as wp

from .enums import Overflow, SphereActivity
from .features import MODULE_OPTIONS, StepFeatures
from .geometry import closest_point_triangle
from .params import ContactHistory, history_store, slot_bit, slot_live

wp.set_module_options(MODULE_OPTIONS)

CELLS_PER_REACH = 1.0
"""Neighbour cells per longest reach (2 r_max + skin + cohesive reach). The candidate lists do not depend on it
(the walk keeps exactly the spheres within reach); it trades the buckets walked (2 to 3 per axis at 1, 4 to 5 at
2) against the foreign spheres read in each. With the sorted grid a bucket's spheres stream from contiguous
slots, so fewer, fuller cells win: on an H100 a rebuild took 1.46 ms at 1 against 2.17 ms at 2 (settled 1 M HM
bed), 1.9 against 4.1 ms (1.6 M spheres in 8-sphere clumps), and 10 % less for seed 000's polydisperse pellets
(0.6-1.7 mm sub-spheres, 1 and 17 worlds)."""
BUCKETS_PER_SPHERE = 2
"""Hash buckets per sphere, before rounding up to a power of two (so 2 to 4; at least 1024 buckets). In a packed
bed a cell (a reach, about a diameter, wide) holds about one sphere, and a sphere walks 8 to 27 cells; at 2 to 4
buckets per sphere a walked bucket holds few spheres of other cells or worlds (each a 16-byte read that fails the
distance test). A bucket costs 4 bytes and 8 bytes of scan traffic; the count, scan and sort take a few per cent
of a rebuild."""
CELL_TILE = 256
"""Buckets per tile of the bucket scan, and the CUDA block size of its tiled launches (Warp's default block size,
so the module builds once per device)."""
SUM_TILE = 4 * CELL_TILE
"""Tile sums scanned per round of the one-block scan of the tile sums (B / (CELL_TILE * SUM_TILE) rounds: 8 for a
million spheres)."""
LIST_ARRAYS = ("neighbor_count", "neighbor_index", "mesh_count", "mesh_face")
"""The Contacts arrays a rebuild writes into ``Contacts.scratch``, then commits (the histories move in place)."""


def cell_grid(sphere_count: int, device) -> dict:
    """An empty cell grid, allocated once (a rebuild allocates nothing), with B a power of two of about
    ``BUCKETS_PER_SPHERE`` buckets per sphere:

    - ``start``: (B + 1,) int32; bucket b holds slots ``start[b] .. start[b + 1]`` once sorted (during a rebuild it
      holds the counts, then the starts, then the ends: ``start[b + 1]`` is bucket b's count, start, then cursor);
    - ``tile_sum``: (B / CELL_TILE,) int32, the spheres of each tile of buckets, then their exclusive scan;
    - ``slot_xr``: (sphere_count,) vec4, centre [m] and radius [m] of the sphere in each slot;
    - ``slot_sphere``: (sphere_count,) vec3i, index, world and clump of the sphere in each slot.

    Bytes per sphere: 4 per bucket (8 to 16) + 16 + 12 = 36 to 44 (the linked lists took 4 per bucket + 4).
    """
    buckets = BUCKETS_PER_SPHERE * max(sphere_count, 1)
    buckets = 1 << max(int(math.log2(4 * CELL_TILE)), int(math.ceil(math.log2(buckets))))
    return {
        "start": wp.zeros(buckets + 1, dtype=int, device=device),
        "tile_sum": wp.zeros(buckets // CELL_TILE, dtype=int, device=device),
        "slot_xr": wp.zeros(sphere_count, dtype=wp.vec4, device=device),
        "slot_sphere": wp.zeros(sphere_count, dtype=wp.vec3i, device=device),
    }


def cell_inverse_size(model, skin: float) -> float:
    """1 / the cell edge [1/m] of a rebuild with Verlet skin ``skin`` [m]."""
    return CELLS_PER_REACH / (2.0 * model.radius_max + skin + model.contact_reach)


@wp.func
def cell_of(x: wp.vec3, inv_cell: float):
    """Integer cell coordinates of the point ``x`` [m] for cells of edge 1 / ``inv_cell``."""
    return wp.vec3i(int(wp.floor(x[0] * inv_cell)), int(wp.floor(x[1] * inv_cell)), int(wp.floor(x[2] * inv_cell)))


@wp.func
def cell_bucket(c: wp.vec3i, world: int, mask: int):
    """Bucket of cell ``c`` in world ``world``, in [0, mask] (mask + 1 a power of two)."""
    h = (wp.uint32(c[0]) * wp.uint32(73856093)) ^ (wp.uint32(c[1]) * wp.uint32(19349663))
    h = h ^ (wp.uint32(c[2]) * wp.uint32(83492791)) ^ (wp.uint32(world) * wp.uint32(2654435761))
    return int(h & wp.uint32(mask))


@wp.kernel
def clear_cells(
    # Out (rebuild_count_out: read, then advanced):
    cell_start_out: wp.array[int],
    rebuild_count_out: wp.array[int],
):
    """Zero every bucket's count and count the rebuild (one thread: no atomic needed)."""
    t = wp.tid()
    cell_start_out[t] = 0
    if t == 0:
        rebuild_count_out[0] = rebuild_count_out[0] + 1


def launch_clear_cells(model, contacts, rebuild_count: wp.array) -> None:
    """Empty the cell grid of ``contacts`` and count a rebuild in ``rebuild_count``."""
    start = contacts.cells["start"]
    wp.launch(clear_cells, dim=start.shape[0], outputs=[start, rebuild_count], device=model.device)


@wp.kernel
def count_cells(
    # Model:
    sphere_world: wp.array[int],
    # State in:
    x: wp.array[wp.vec3],
    active: wp.array[int],
    # Options:
    inv_cell: float,
    # Out (cell_start_out[b + 1]: bucket b's count, advanced):
    cell_start_out: wp.array[int],
):
    """Count the moving spheres of each bucket (parked factory particles and settled worlds stay out)."""
    i = wp.tid()
    if active[i] != SphereActivity.MOVING:
        return
    b = cell_bucket(cell_of(x[i], inv_cell), sphere_world[i], cell_start_out.shape[0] - 2)
    wp.atomic_add(cell_start_out, b + 1, 1)


def launch_count_cells(model, state, contacts, inv_cell: float) -> None:
    """Count the active spheres of ``state`` per bucket of ``contacts``' cell grid (cells of edge 1 / ``inv_cell``)."""
    m = model
    wp.launch(
        count_cells,
        dim=m.sphere_count,
        inputs=[m.sphere_world, state.sphere_x, state.sphere_active, inv_cell],
        outputs=[contacts.cells["start"]],
        device=m.device,
    )


@wp.kernel
def sum_cell_tiles(
    # Contacts in (cell_start[b + 1]: bucket b's count):
    cell_start: wp.array[int],
    # Out:
    tile_sum_out: wp.array[int],
):
    """Spheres in each tile of ``CELL_TILE`` buckets (one block per tile)."""
    k = wp.tid()
    counts = wp.tile_load(cell_start, shape=CELL_TILE, offset=k * CELL_TILE + 1)
    wp.tile_store(tile_sum_out, wp.tile_sum(counts), offset=k)


def launch_sum_cell_tiles(model, contacts) -> None:
    """Sum the bucket counts of ``contacts``' cell grid per tile of buckets."""
    tile_sum = contacts.cells["tile_sum"]
    wp.launch_tiled(
        sum_cell_tiles,
        dim=tile_sum.shape[0],
        inputs=[contacts.cells["start"]],
        outputs=[tile_sum],
        block_dim=CELL_TILE,
        device=model.device,
    )


@wp.kernel
def scan_cell_tile_sums(
    # Out (read, then written):
    tile_sum_out: wp.array[int],
):
    """Exclusive scan of the tile sums in place, by one block, ``SUM_TILE`` sums a round, each round carrying the
    total of those before it."""
    carry = int(0)
    for k in range((tile_sum_out.shape[0] + SUM_TILE - 1) // SUM_TILE):
        sums = wp.tile_load(tile_sum_out, shape=SUM_TILE, offset=k * SUM_TILE)
        inclusive = wp.tile_scan_inclusive(sums)
        ahead = wp.tile_full(SUM_TILE, value=carry, dtype=int)
        wp.tile_store(tile_sum_out, inclusive - sums + ahead, offset=k * SUM_TILE)
        carry += inclusive[SUM_TILE - 1]


def launch_scan_cell_tile_sums(model, contacts) -> None:
    """Turn the tile sums of ``contacts``' cell grid into each tile's first slot."""
    wp.launch_tiled(
        scan_cell_tile_sums,
        dim=1,
        inputs=[],
        outputs=[contacts.cells["tile_sum"]],
        block_dim=CELL_TILE,
        device=model.device,
    )


@wp.kernel
def scan_cells(
    # Contacts in (the first slot of each tile of buckets):
    tile_start: wp.array[int],
    # Out (cell_start_out[b + 1]: bucket b's count, then its first slot):
    cell_start_out: wp.array[int],
):
    """Exclusive scan of the bucket counts within each tile, offset by the tile's first slot (one block per
    tile)."""
    k = wp.tid()
    counts = wp.tile_load(cell_start_out, shape=CELL_TILE, offset=k * CELL_TILE + 1)
    first = wp.tile_full(CELL_TILE, value=tile_start[k], dtype=int)
    wp.tile_store(cell_start_out, wp.tile_scan_exclusive(counts) + first, offset=k * CELL_TILE + 1)


def launch_scan_cells(model, contacts) -> None:
    """Turn the bucket counts of ``contacts``' cell grid into each bucket's first slot."""
    tile_sum = contacts.cells["tile_sum"]
    wp.launch_tiled(
        scan_cells,
        dim=tile_sum.shape[0],
        inputs=[tile_sum],
        outputs=[contacts.cells["start"]],
        block_dim=CELL_TILE,
        device=model.device,
    )


@wp.kernel
def sort_spheres(
    # Model:
    sphere_radius: wp.array[float],
    sphere_world: wp.array[int],
    sphere_clump: wp.array[int],
    # State in:
    x: wp.array[wp.vec3],
    active: wp.array[int],
    # Options:
    inv_cell: float,
    # Out (cell_start_out[b + 1]: bucket b's next free slot, advanced: its end once all are in):
    cell_start_out: wp.array[int],
    slot_xr_out: wp.array[wp.vec4],
    slot_sphere_out: wp.array[wp.vec3i],
):
    """Put each active sphere in a slot of its bucket, with what the walk reads of it (slots of one bucket in any
    order)."""
    i = wp.tid()
    if active[i] != SphereActivity.MOVING:
        return
    x_i = x[i]
    world = sphere_world[i]
    b = cell_bucket(cell_of(x_i, inv_cell), world, cell_start_out.shape[0] - 2)
    s = wp.atomic_add(cell_start_out, b + 1, 1)
    slot_xr_out[s] = wp.vec4(x_i[0], x_i[1], x_i[2], sphere_radius[i])
    slot_sphere_out[s] = wp.vec3i(i, world, sphere_clump[i])


def launch_sort_spheres(model, state, contacts, inv_cell: float) -> None:
    """Sort the active spheres of ``state`` into the counted and scanned buckets of ``contacts``' cell grid."""
    m, g = model, contacts.cells
    wp.launch(
        sort_spheres,
        dim=m.sphere_count,
        inputs=[m.sphere_radius, m.sphere_world, m.sphere_clump, state.sphere_x, state.sphere_active, inv_cell],
        outputs=[g["start"], g["slot_xr"], g["slot_sphere"]],
        device=m.device,
    )


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
    new_keys: wp.array2d[int],
    new_count: int,
    history: wp.array2d(dtype=Any),
    col: int,
    live: wp.uint64,
):
    """Move column ``col`` of ``history`` from the old sorted keys to the new sorted keys, in place: each new
    entry gets the history of the old entry with its key, else zero. Returns the new live mask (kernels/params.py,
    ``slot_live``): each new slot inherits its old slot's bit of ``live``.

    In place, so that the lists need no second history array (``history``: either slot layout, see
    ``StepFeatures.history_type``). Matched entries keep their order, so an entry moving to a lower slot (old
    slot >= new) can only overwrite old slots that entries before it already read: those go in ascending order;
    entries moving up go in descending order for the same reason, and neither kind can overwrite an old slot the
    other still needs. Unmatched entries are zeroed last.
    """
    t = int(0)
    for s in range(new_count):
        key = new_keys[s, col]
        while t < old_count and old_keys[t, col] < key:
            t += 1
        if t < old_count and t > s:
            if old_keys[t, col] == key:
                history[s, col] = history[t, col]
    t = old_count - 1
    for r in range(new_count):
        s = new_count - 1 - r
        key = new_keys[s, col]
        while t >= 0 and old_keys[t, col] > key:
            t -= 1
        if t >= 0 and t < s:
            if old_keys[t, col] == key:
                history[s, col] = history[t, col]
    t = int(0)
    new_live = wp.uint64(0)
    for s in range(new_count):
        key = new_keys[s, col]
        while t < old_count and old_keys[t, col] < key:
            t += 1
        if t >= old_count or old_keys[t, col] != key:
            history_store(history, s, col, ContactHistory())
        elif slot_live(live, t):
            new_live = new_live | slot_bit(s)
    return new_live


@functools.cache
def build_contacts_kernel(features: StepFeatures):
    """The list builder compiled for ``features`` (kernels/features.py): clumps, mesh and coated walls."""
    clumps = features.clumps
    mesh_walls = features.mesh_walls
    coated_walls = features.coated_walls
    History = features.history_type

    @wp.kernel(module="unique", module_options=MODULE_OPTIONS)
    def build_contacts(
        # Model:
        sphere_radius: wp.array[float],
        sphere_world: wp.array[int],
        sphere_clump: wp.array[int],
        sphere_wall: wp.array[int],
        radius_max: float,
        contact_reach: float,
        wall_mesh: wp.array[wp.uint64],
        wall_face_start: wp.array[int],
        wall_world: wp.array[int],
        # State in:
        x: wp.array[wp.vec3],
        active: wp.array[int],
        wall_pose: wp.array[wp.transform],
        # Contacts in (the sorted cell grid and the current lists):
        cell_start: wp.array[int],
        slot_xr: wp.array[wp.vec4],
        slot_sphere: wp.array[wp.vec3i],
        old_count: wp.array[int],
        old_index: wp.array2d[int],
        old_mesh_count: wp.array[int],
        old_mesh_face: wp.array2d[int],
        # Options:
        inv_cell: float,
        skin: float,
        # Out (new_index_out and new_mesh_face_out: written, then sorted in place; the histories: carried over
        # in place from the old lists' keys to the new ones):
        new_count_out: wp.array[int],
        new_index_out: wp.array2d[int],
        new_mesh_count_out: wp.array[int],
        new_mesh_face_out: wp.array2d[int],
        history_out: wp.array2d[History],
        mesh_history_out: wp.array2d[History],
        neighbor_live_out: wp.array[wp.uint64],
        build_x_out: wp.array[wp.vec3],
        overflow_out: wp.array[int],
    ):
        """Candidates within r_i + r_j + skin + contact_reach (the longest cohesive break distance)."""
        i = wp.tid()
        x_i = x[i]
        build_x_out[i] = x_i
        # parked factory particles, settled worlds and spheres glued to a wall take no part as the gathering side
        parked = active[i] != SphereActivity.MOVING
        if wp.static(coated_walls):
            parked = parked or sphere_wall[i] >= 0
        if parked:
            new_count_out[i] = 0
            new_mesh_count_out[i] = 0
            neighbor_live_out[i] = wp.uint64(0)
            return
        r_i = sphere_radius[i]
        world = sphere_world[i]
        clump = int(-1)
        if wp.static(clumps):
            clump = sphere_clump[i]
        capacity = new_index_out.shape[0]

        count = int(0)
        # walk the box of cells that holds the query sphere; cells narrower than the reach make that box hug
        # the sphere (a small sphere walks far fewer spheres than a fixed 27-cell stencil would)
        reach_i = r_i + radius_max + skin + contact_reach
        lo = cell_of(x_i - wp.vec3(reach_i), inv_cell)
        hi = cell_of(x_i + wp.vec3(reach_i), inv_cell)
        mask = cell_start.shape[0] - 2
        for cz in range(lo[2], hi[2] + 1):
            for cy in range(lo[1], hi[1] + 1):
                for cx in range(lo[0], hi[0] + 1):
                    cell = wp.vec3i(cx, cy, cz)
                    bucket = cell_bucket(cell, world, mask)
                    # the bucket's slots are contiguous: centre and radius first, the rest only within reach
                    for s in range(cell_start[bucket], cell_start[bucket + 1]):
                        xr = slot_xr[s]
                        x_j = wp.vec3(xr[0], xr[1], xr[2])
                        if wp.length(x_j - x_i) < r_i + xr[3] + skin + contact_reach:
                            tag = slot_sphere[s]
                            j = tag[0]
                            # a bucket holds other cells and worlds too: take j only in its own cell (never twice)
                            if j != i and tag[1] == world and cell_of(x_j, inv_cell) == cell:
                                own = False
                                if wp.static(clumps):
                                    own = clump >= 0 and tag[2] == clump
                                if not own:
                                    if count < capacity:
                                        new_index_out[count, i] = j
                                        count += 1
                                    else:
                                        wp.atomic_or(overflow_out, 0, Overflow.NEIGHBOR)
        sort_column(new_index_out, count, i)
        neighbor_live_out[i] = carry_history(
            old_index, old_count[i], new_index_out, count, history_out, i, neighbor_live_out[i]
        )
        new_count_out[i] = count

        if wp.static(mesh_walls):
            mesh_capacity = new_mesh_face_out.shape[0]
            mcount = int(0)
            limit = r_i + skin + contact_reach
            for wall in range(wall_mesh.shape[0]):
                ww = wall_world[wall]
                if ww >= 0 and ww != world:
                    continue
                # the wall's triangles live in its own frame: query there (a sphere's box is the same in any frame)
                x_local = wp.transform_point(wp.transform_inverse(wall_pose[wall]), x_i)
                mesh = wall_mesh[wall]
                mq = wp.mesh_query_aabb(mesh, x_local - wp.vec3(limit), x_local + wp.vec3(limit))
                local = int(0)
                while wp.mesh_query_aabb_next(mq, local):
                    a = wp.mesh_get_point(mesh, local * 3 + 0)
                    b = wp.mesh_get_point(mesh, local * 3 + 1)
                    c = wp.mesh_get_point(mesh, local * 3 + 2)
                    q, feature = closest_point_triangle(x_local, a, b, c)
                    if wp.length(x_local - q) < limit:
                        if mcount < mesh_capacity:
                            new_mesh_face_out[mcount, i] = wall_face_start[wall] + local
                            mcount += 1
                        else:
                            wp.atomic_or(overflow_out, 0, Overflow.MESH)
            sort_column(new_mesh_face_out, mcount, i)
            # mesh slots keep no live mask (all live)
            carry_history(
                old_mesh_face, old_mesh_count[i], new_mesh_face_out, mcount, mesh_history_out, i, ~wp.uint64(0)
            )
            new_mesh_count_out[i] = mcount
        else:
            new_mesh_count_out[i] = 0

    return build_contacts


def launch_build_contacts(model, state, contacts, *, features: StepFeatures, inv_cell: float, skin: float) -> None:
    """New candidate lists from the sorted spheres of ``state`` into ``contacts.scratch``; the histories move in
    place to their keys' new slots (see :func:`carry_history`). Records the build positions and any overflow (the
    kernel compiled for ``features``)."""
    m, c, s = model, contacts, contacts.scratch
    wp.launch(
        build_contacts_kernel(features),
        dim=m.sphere_count,
        inputs=[
            m.sphere_radius,
            m.sphere_world,
            m.sphere_clump,
            m.sphere_wall,
            m.radius_max,
            m.contact_reach,
            m.wall_mesh,
            m.wall_face_start,
            m.wall_world,
            state.sphere_x,
            state.sphere_active,
            state.wall_pose,
            c.cells["start"],
            c.cells["slot_xr"],
            c.cells["slot_sphere"],
            c.neighbor_count,
            c.neighbor_index,
            c.mesh_count,
            c.mesh_face,
            inv_cell,
            skin,
        ],
        outputs=[
            s["neighbor_count"],
            s["neighbor_index"],
            s["mesh_count"],
            s["mesh_face"],
            c.neighbor_history,
            c.mesh_history,
            c.neighbor_live,
            c.build_x,
            c.overflow,
        ],
        device=m.device,
    )


@wp.kernel
def commit_contacts(
    # Contacts in (the lists build_contacts just wrote):
    new_count: wp.array[int],
    new_index: wp.array2d[int],
    new_mesh_count: wp.array[int],
    new_mesh_face: wp.array2d[int],
    # Out (the lists the step reads):
    neighbor_count_out: wp.array[int],
    neighbor_index_out: wp.array2d[int],
    mesh_count_out: wp.array[int],
    mesh_face_out: wp.array2d[int],
):
    """Copy each sphere's new keys over its old ones (the histories are already in place), only the slots in
    use: readers never look past a sphere's count, and a full-capacity copy moves several times the bytes
    (capacities of ~60 slots hold ~15 candidates in a dense clump pile)."""
    i = wp.tid()
    n = new_count[i]
    neighbor_count_out[i] = n
    for k in range(n):
        neighbor_index_out[k, i] = new_index[k, i]
    nm = new_mesh_count[i]
    mesh_count_out[i] = nm
    for k in range(nm):
        mesh_face_out[k, i] = new_mesh_face[k, i]


def launch_commit_contacts(model, contacts) -> None:
    """Make the lists :func:`launch_build_contacts` wrote the ones the step reads."""
    wp.launch(
        commit_contacts,
        dim=model.sphere_count,
        inputs=[contacts.scratch[k] for k in LIST_ARRAYS],
        outputs=[getattr(contacts, k) for k in LIST_ARRAYS],
        device=model.device,
    )
