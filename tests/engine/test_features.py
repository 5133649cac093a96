"""A scene pays only for what it uses: the step and rebuild kernels are compiled for the features a model has
(kernels/features.py), and the specialised kernels compute exactly what the all-features kernels compute."""

import numpy as np
import pytest

import warpdem as wd
from warpdem.kernels.features import StepFeatures


def _bed(kind: str, device: str = "cpu"):
    """A tiny scene of ``kind``: plain HM spheres on planes; JKR spheres with EPSD rolling friction (``jkr``) or
    without rolling friction (``jkr_plain``); or 8-sphere clumps on a mesh floor with a coated patch."""
    b = wd.ModelBuilder()
    b.add_material(wd.Material("a", density=2500, youngs_modulus=1e7, poisson_ratio=0.3))
    law = {"law": "JKR", "surface_energy": 0.5} if kind in ("jkr", "jkr_plain") else {}
    rolling = {"rolling_friction": 0.1, "rolling_model": "epsd"} if kind == "jkr" else {}
    b.set_default_interaction(restitution=0.5, static_friction=0.5, **law, **rolling)
    rng = np.random.default_rng(3)
    pts = np.array([(i * 0.011, j * 0.011, 0.006 + k * 0.011) for i in range(3) for j in range(3) for k in range(2)])
    pts[:, :2] += rng.uniform(-1e-3, 1e-3, (len(pts), 2))
    if kind == "clumps":
        b.add_wall_mesh(
            [(-0.05, -0.05, 0), (0.1, -0.05, 0), (0.1, 0.1, 0), (-0.05, 0.1, 0)],
            [(0, 1, 2), (0, 2, 3)],
            "a",
            name="floor",
        )
        b.attach_spheres("floor", [(0.011, 0.011, 0.002)], 0.002, "a")
        a = 0.0012
        offsets = [(x, y, z) for x in (-a, a) for y in (-a, a) for z in (-a, a)]
        b.add_clumps(wd.ClumpTemplate.from_spheres("c8", offsets, [0.002] * 8), pts, "a")
    else:
        b.add_plane((0, 0, 0), (0, 0, 1), "a")
        b.add_spheres(pts, 0.005, "a")
    return b.finalize(device)


@pytest.mark.parametrize(
    "kind, expected",
    [
        ("hm", StepFeatures(False, False, False, False, False, False, False, False, False)),
        ("jkr", StepFeatures(False, False, False, False, True, True, True, False, False)),
        ("clumps", StepFeatures(True, True, True, True, False, False, False, False, False)),
    ],
)
def test_features_follow_the_model(kind, expected):
    assert wd.Solver(_bed(kind)).features == expected


@pytest.mark.parametrize(
    "features, slot_bytes",
    [
        (StepFeatures(cohesive_laws=False, rolling=False, rolling_spring=False), 12),
        (StepFeatures(cohesive_laws=False, rolling=True, rolling_spring=False), 12),  # constant-torque rolling
        (StepFeatures(cohesive_laws=False, rolling=True, rolling_spring=True), 28),  # EPSD keeps its spring
        (StepFeatures(cohesive_laws=True, rolling=False, rolling_spring=False), 16),  # JKR/EEPA keep aux
        (StepFeatures(cohesive_laws=True, rolling=True, rolling_spring=True), 28),
    ],
)
def test_history_slot_holds_only_what_the_laws_use(features, slot_bytes):
    s = wd.Solver(_bed("hm"))
    s.features = features
    c = s.contacts()
    assert c.neighbor_history.capacity == slot_bytes * c.neighbor_history.size
    assert c.plane_history.dtype is c.neighbor_history.dtype is features.history_type


def test_contacts_of_another_layout_are_refused():
    """Features changed after the contacts were allocated: a clear error, not a kernel reading the wrong type."""
    m = _bed("hm")
    s = wd.Solver(m)
    c = s.contacts()
    s.features = StepFeatures()
    with pytest.raises(ValueError, match="contacts hold history of type vec3f.*Solver.contacts"):
        s.run(m.state(), c, 2)


def test_body_contact_mass_needs_no_partner_tables():
    opts = wd.SolverOptions(clump_contact_mass="body")
    assert not wd.Solver(_bed("clumps"), opts).features.share_mass


@pytest.mark.parametrize("kind", ["hm", "jkr", "jkr_plain", "clumps"])
def test_specialised_kernels_compute_what_the_general_ones_do(kind):
    """Positions, angular velocities and wall impulses after 1,000 steps (several rebuilds; the lower layer lands)
    equal those of the kernels compiled with every feature, to the last bit."""
    runs = []
    for features in (None, StepFeatures()):
        m = _bed(kind)
        s = wd.Solver(m, wd.SolverOptions(dt=2e-5))
        if features is not None:
            s.features = features
        st = s.run(m.state(), s.contacts(), 1000)
        runs.append((st.sphere_x.numpy(), st.sphere_w.numpy(), st.wall_impulse.numpy(), s.rebuild_count))
    assert runs[0][3] >= 2, "the run should rebuild its lists"
    assert np.abs(runs[0][2]).max() > 0.0, "the spheres should have touched a wall"
    for a, b in zip(runs[0][:3], runs[1][:3]):
        assert np.array_equal(a, b)
    assert np.abs(runs[0][0][:, 2] - 0.006).max() > 1e-4, "the spheres should have moved"


@pytest.mark.parametrize("kind", ["hm", "jkr", "jkr_plain"])
def test_live_masks_mark_the_slots_with_history(kind):
    """A neighbour or plane slot whose live bit is clear holds a zero history (the step skips reading it), and the
    bits mark exactly the contacts of the last step (recomputed here from its positions, x - dt v): touching
    partners, and the floor. A JKR pair may also stay live in a gap (it hangs on down to its break overlap)."""
    m = _bed(kind)
    s = wd.Solver(m, wd.SolverOptions(dt=2e-5))
    c = s.contacts()
    st = s.run(m.state(), c, 2000)  # 40 ms: the upper layer lands on the lower
    x = st.sphere_x.numpy().astype(np.float64) - s.dt * st.sphere_v.numpy()
    r = m.sphere_radius.numpy()
    cnt, idx = c.neighbor_count.numpy(), c.neighbor_index.numpy()
    rows = cnt.max()
    live = (c.neighbor_live.numpy()[None, :] >> np.arange(rows, dtype=np.uint64)[:, None]) & np.uint64(1)
    live = live.astype(bool)
    used = np.arange(rows)[:, None] < cnt[None, :]
    assert not np.any(c.spring()[:rows][~live & used]), "a slot without its live bit holds a history"
    assert not np.any(live & ~used), "a live bit past the list"
    cols = np.broadcast_to(np.arange(len(r)), (rows, len(r)))
    j = np.where(used, idx[:rows], 0)
    overlap = r[cols] + r[j] - np.linalg.norm(x[j] - x[cols], axis=-1)
    touching = used & (overlap > 1e-9)
    assert touching.sum() >= 4, "the layers should touch"
    assert np.array_equal(live & (np.abs(overlap) > 1e-9), touching if kind == "hm" else live & (overlap > 1e-9))
    assert np.all(live[touching])
    floor = x[:, 2] < r - 1e-9
    plane_live = (c.plane_live.numpy() & np.uint64(1)).astype(bool)
    assert floor.sum() >= 4 and np.array_equal(plane_live & (np.abs(x[:, 2] - r) > 1e-9), floor)
    assert not np.any(c.spring("plane")[0][~plane_live])


def test_large_clumps_follow_the_templates():
    """Only a clump of more than SMALL_CLUMP_SPHERES spheres (the 141-sphere pellet) takes the tiled integration."""
    from warpdem.kernels.features import SMALL_CLUMP_SPHERES

    b = wd.ModelBuilder()
    b.add_material(wd.Material("a", density=1250, youngs_modulus=4e6, poisson_ratio=0.4))
    b.add_clumps(wd.pellet_template(), [(0, 0, 0.01)], "a")
    assert len(wd.pellet_template().sphere_radius) > SMALL_CLUMP_SPHERES
    assert wd.Solver(b.finalize("cpu")).features.large_clumps
    assert not wd.Solver(_bed("clumps")).features.large_clumps


def test_contacts_refuse_rows_past_int32_strides(monkeypatch):
    """Warp addresses a (slots, sphere_count) list array with int32 strides: a row of one 12-byte spring per
    sphere fits up to 178,956,970 spheres, a 28-byte ContactHistory up to 76,695,844; past that, a clear error
    (a GPU ran into a memory fault at 180 M spheres before this check)."""
    import warp as wp

    import warpdem.engine.solver as solver_module
    from warpdem.kernels.params import ContactHistory

    solver_module.check_row_bytes(178_956_970, wp.vec3)
    with pytest.raises(ValueError, match="178,956,971 is not allowed.*at most 178,956,970 spheres"):
        solver_module.check_row_bytes(178_956_971, wp.vec3)
    with pytest.raises(ValueError, match="28-byte ContactHistory list slots; expected at most 76,695,844"):
        solver_module.check_row_bytes(80_000_000, ContactHistory)
    monkeypatch.setattr(solver_module, "ROW_BYTES_MAX", 100)  # the tiny bed's 18 spheres x 12 bytes pass it
    with pytest.raises(ValueError, match="sphere_count = 18 is not allowed"):
        wd.Solver(_bed("hm")).contacts()
