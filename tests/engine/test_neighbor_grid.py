"""The neighbour grid (kernels/neighbors.py): the counting sort into hash buckets and the candidate lists built
from it, against NumPy."""

from types import SimpleNamespace

import numpy as np
import warp as wp

import warpdem as wd
from warpdem.kernels import neighbors as nb

# the band around r_i + r_j + skin + reach where float32 and float64 distances may disagree [relative]
BORDER = 1e-5


def _bed(rng):
    """A polydisperse bed of 300 spheres and 3 clumps in a 6 mm box, replicated into two worlds, with a JKR
    pair so that the lists reach past contact."""
    b = wd.ModelBuilder()
    b.add_material(wd.Material("a", density=2500, youngs_modulus=1e7, poisson_ratio=0.3))
    b.set_interaction("a", "a", law="JKR", surface_energy=0.5)
    radius = np.clip(rng.lognormal(np.log(0.4e-3), 0.5, 300), 0.15e-3, 1.2e-3)
    b.add_spheres(rng.uniform(0.0, 0.006, (300, 3)), radius, "a")
    tmpl = wd.ClumpTemplate("pair", [[-0.4e-3, 0, 0], [0.4e-3, 0, 0]], [0.6e-3, 0.6e-3], 1e-9, [1e-16, 2e-16, 2e-16])
    b.add_clumps(tmpl, rng.uniform(0.001, 0.005, (3, 3)), "a")
    b.replicate(2)
    return b.finalize("cpu")


def _brute_force(x, r, world, clump, active, limit_extra):
    """Every sphere's partners within r_i + r_j + ``limit_extra`` (same world, another clump or none, both
    active), O(n^2) in float64: the sure partners and those within ``BORDER`` of the limit."""
    d = np.linalg.norm(x[:, None, :] - x[None, :, :], axis=2)
    limit = r[:, None] + r[None, :] + limit_extra
    ok = (world[:, None] == world[None, :]) & (active[:, None] != 0) & (active[None, :] != 0)
    ok &= ~((clump[:, None] >= 0) & (clump[:, None] == clump[None, :]))
    np.fill_diagonal(ok, False)
    sure = ok & (d < limit * (1.0 - BORDER))
    border = ok & (np.abs(d - limit) <= limit * BORDER)
    return sure, border


def _check_lists(model, solver, state, contacts):
    """The lists in ``contacts`` are exactly the brute-force candidate sets; returns the candidates listed."""
    x = state.sphere_x.numpy().astype(np.float64)
    r = model.sphere_radius.numpy().astype(np.float64)
    active = state.sphere_active.numpy()
    sure, border = _brute_force(
        x, r, model.sphere_world.numpy(), model.sphere_clump.numpy(), active, solver.skin + model.contact_reach
    )
    assert contacts.overflow.numpy()[0] == 0
    count, index = contacts.neighbor_count.numpy(), contacts.neighbor_index.numpy()
    for i in range(model.sphere_count):
        listed = index[: count[i], i]
        assert np.all(np.diff(listed) > 0), f"sphere {i}: list not strictly ascending"
        want = set(np.flatnonzero(sure[i]))
        maybe = want | set(np.flatnonzero(border[i]))
        assert want <= set(listed) <= maybe, (i, sorted(want ^ set(listed)))
    return int(count.sum())


def test_lists_equal_brute_force_candidates():
    """Each sphere's list holds exactly the spheres within r_i + r_j + skin + cohesive reach of it, O(n^2) in
    NumPy: two worlds with different spheres at nearly the same places (never listed across worlds), clumps
    (never listed with their own spheres), parked spheres (neither listing nor listed), radii 0.15 to 1.2 mm and
    2048 buckets for 612 spheres (many buckets shared by cells and worlds). Then the same rebuild captured as a
    graph under a conditional node, replayed on moved spheres, lists the new sets."""
    rng = np.random.default_rng(17)
    model = _bed(rng)
    assert model.world_count == 2 and model.clump_count == 6 and model.contact_reach > 0
    solver = wd.Solver(model, wd.SolverOptions(neighbor_capacity=64))
    contacts = solver.contacts()
    state = model.state()
    world = model.sphere_world.numpy()
    assert contacts.cells["start"].shape[0] - 1 == 2048

    def scatter(state):
        # world 1: every sphere jittered by up to a radius from its world-0 twin; 40 spheres parked
        x = state.sphere_x.numpy()
        x[world == 1] += rng.uniform(-0.5e-3, 0.5e-3, (int(np.sum(world == 1)), 3))
        state.sphere_x.assign(x)
        active = np.ones(model.sphere_count, np.int32)
        active[rng.choice(model.sphere_count, 40, replace=False)] = 0
        state.sphere_active.assign(active)

    scatter(state)
    solver.rebuild(state, contacts)
    listed = _check_lists(model, solver, state, contacts)
    assert listed > 4 * model.sphere_count, "the bed should give several candidates per sphere"

    # the rebuild as Solver.run replays it: a conditional node of a captured graph, replayed on moved spheres
    contacts.rebuild.fill_(1)
    with wp.ScopedCapture(device=model.device) as cap:
        wp.capture_if(contacts.rebuild, on_true=lambda: solver.rebuild(state, contacts))
    before = solver.rebuild_count
    for _ in range(2):
        x = state.sphere_x.numpy()
        x += rng.uniform(-1e-3, 1e-3, x.shape)
        state.sphere_x.assign(x)
        scatter(state)
        contacts.rebuild.fill_(1)
        wp.capture_launch(cap.graph)
        _check_lists(model, solver, state, contacts)
    assert solver.rebuild_count == before + 2


def test_bucket_scan_matches_numpy():
    """The bucket starts are the exclusive prefix sum of the bucket counts (the tiled scan), here over 2^20
    buckets: 4096 tiles, so the scan of the tile sums takes 4 rounds, each carrying the total of those before
    (the bed above has 8 tiles: one round, partly past the end)."""
    rng = np.random.default_rng(5)
    grid = nb.cell_grid(400_000, "cpu")
    buckets = grid["start"].shape[0] - 1
    assert buckets == 1 << 20 and grid["tile_sum"].shape[0] == 4 * nb.SUM_TILE
    counts = rng.integers(0, 4, buckets).astype(np.int32)
    counts[rng.random(buckets) < 0.5] = 0
    start = np.zeros(buckets + 1, np.int32)
    start[1:] = counts
    grid["start"].assign(start)
    model, contacts = SimpleNamespace(device="cpu"), SimpleNamespace(cells=grid)
    nb.launch_sum_cell_tiles(model, contacts)
    nb.launch_scan_cell_tile_sums(model, contacts)
    nb.launch_scan_cells(model, contacts)
    want = np.concatenate([[0, 0], np.cumsum(counts)[:-1]])
    assert np.array_equal(grid["start"].numpy(), want)
