"""Engine mechanics: the Hertz-Mindlin law against NumPy, history across rebuilds, blow-ups, overflows."""

import math

import numpy as np
import pytest
import warp as wp

import warpdem as wd
from warpdem.kernels.law_hertz_mindlin import hertz_mindlin
from warpdem.kernels.params import PairParams


@wp.kernel
def _hm_kernel(
    overlap: wp.array[float],
    n: wp.array[wp.vec3],
    v: wp.array[wp.vec3],
    s: wp.array[wp.vec3],
    p: PairParams,
    dt: float,
    f_out: wp.array[wp.vec3],
    xi_out: wp.array[wp.vec3],
):
    i = wp.tid()
    f, fn, ft, xi, kn, ks = hertz_mindlin(overlap[i], n[i], v[i], s[i], 0.002, 1e-4, p, dt)
    f_out[i] = f
    xi_out[i] = xi


def _hm_numpy(d, n, v, s, e_star, g_star, beta, mu, r, m, dt):
    sq = math.sqrt(r * d)
    sn, st = 2 * e_star * sq, 8 * g_star * sq
    damp = -2 * math.sqrt(5 / 6) * beta
    vn = v @ n
    fn = 4 / 3 * e_star * sq * d + damp * math.sqrt(sn * m) * vn
    xi = s - (s @ n) * n
    if np.linalg.norm(xi) > 0:
        xi *= np.linalg.norm(s) / np.linalg.norm(xi)
    vt = v - vn * n
    xi = xi + vt * dt
    ft = -st * xi - damp * math.sqrt(st * m) * vt
    lim = mu * max(fn, 0)
    if np.linalg.norm(ft) > lim:
        ft *= lim / np.linalg.norm(ft)
        xi = -(ft + damp * math.sqrt(st * m) * vt) / st
    return -fn * n + ft, xi


def test_hertz_mindlin_matches_numpy():
    """The Warp law equals an independent NumPy transcription (sticking and sliding, random inputs)."""
    rng = np.random.default_rng(3)
    k = 64
    n = rng.normal(size=(k, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    d = rng.uniform(1e-7, 5e-5, k)
    v = rng.normal(scale=0.3, size=(k, 3))
    s = rng.normal(scale=2e-6, size=(k, 3))
    p = PairParams()
    p.e_star, p.g_star, p.mu_s = 1e8, 4e7, 0.4
    p.beta = math.log(0.5) / math.sqrt(math.log(0.5) ** 2 + math.pi**2)
    f = wp.zeros(k, dtype=wp.vec3)
    xi = wp.zeros(k, dtype=wp.vec3)
    wp.launch(
        _hm_kernel,
        dim=k,
        inputs=[
            wp.array(d, dtype=float),
            wp.array(n, dtype=wp.vec3),
            wp.array(v, dtype=wp.vec3),
            wp.array(s, dtype=wp.vec3),
            p,
            1e-5,
        ],
        outputs=[f, xi],
    )
    sliding = 0
    for i in range(k):
        fe, xe = _hm_numpy(d[i], n[i], v[i], s[i], 1e8, 4e7, p.beta, 0.4, 0.002, 1e-4, 1e-5)
        np.testing.assert_allclose(f.numpy()[i], fe, rtol=2e-4, atol=1e-6 * np.linalg.norm(fe))
        np.testing.assert_allclose(xi.numpy()[i], xe, rtol=2e-4, atol=1e-9)
        sliding += np.linalg.norm(fe - (fe @ n[i]) * n[i]) > 0.39999 * abs(fe @ n[i])
    assert 0 < sliding < k, "the sample must exercise both sticking and sliding"


def _resting_pair(skin):
    b = wd.ModelBuilder()
    b.add_material(wd.Material("a", density=2500, youngs_modulus=1e7, poisson_ratio=0.3))
    b.set_interaction("a", "a", restitution=0.5, static_friction=0.8)
    b.add_plane((0, 0, 0), (0, 0, 1), "a")
    # a sphere pressed on another, sheared sideways: the tangential spring must build and persist
    b.add_sphere((0, 0, 0.00499), 0.005, "a")
    b.add_sphere((0.0005, 0, 0.01495), 0.005, "a", velocity=(0.002, 0, 0))
    m = b.finalize("cpu")
    return m, wd.Solver(m, wd.SolverOptions(skin=skin))


def test_history_survives_rebuilds():
    """The tangential spring is carried across rebuilds by sorted-key matching: a tiny skin (a rebuild every
    step) and a large one (no rebuild after the first build) give the same trajectory.

    The lists are rebuilt once a sphere has moved half the skin since the last build. Skin 0.2 um: the sheared
    sphere starts at 2 mm/s, more than 0.1 um per step, and only gathers speed as it rolls off the lower
    sphere's top (an unstable balance), so the lists are rebuilt before each of the 400 steps. Skin 2 mm: no
    sphere moves 1 mm, so the first build is the only one."""
    res = []
    for skin, rebuilds in ((2e-7, 400), (2e-3, 1)):
        m, s = _resting_pair(skin)
        x0 = m.state().sphere_x.numpy()
        st = s.run(m.state(), (c := s.contacts()), 400)
        res.append(st.sphere_x.numpy())
        spring = c.spring()[:, 0]
        assert np.linalg.norm(spring[: c.neighbor_count.numpy()[0]]) > 0, "the pair's spring was never loaded"
        if rebuilds > 1:
            assert 0.002 * s.dt > 0.5 * skin and np.linalg.norm(st.sphere_v.numpy()[1]) > 0.002
        else:
            assert np.linalg.norm(st.sphere_x.numpy() - x0, axis=1).max() < 0.5 * skin
        assert s.rebuild_count == rebuilds
    np.testing.assert_allclose(res[0], res[1], rtol=0, atol=1e-9)


def test_pair_history_identical_on_both_sides():
    """Both partners hold bit-identical copies of the pair's spring (canonical evaluation)."""
    m, s = _resting_pair(1e-3)
    c = s.contacts()
    s.run(m.state(), c, 200)
    cnt, idx, spr = c.neighbor_count.numpy(), c.neighbor_index.numpy(), c.spring()
    k0 = list(idx[: cnt[0], 0]).index(1)
    k1 = list(idx[: cnt[1], 1]).index(0)
    assert np.array_equal(spr[k0, 0], spr[k1, 1]) and np.linalg.norm(spr[k0, 0]) > 0


def test_blowup_names_step_world_and_sphere():
    """A runaway sphere stops the run with an error naming the step, the world and the sphere."""
    b = wd.ModelBuilder(gravity=(0, 0, 0))
    b.add_material(wd.Material("a", density=2500, youngs_modulus=1e7, poisson_ratio=0.3))
    b.add_sphere((0, 0, 0), 0.005, "a")
    b.add_sphere((1, 0, 0), 0.005, "a", velocity=(600, 0, 0))
    b.replicate(2)
    m = b.finalize("cpu")
    s = wd.Solver(m)
    with pytest.raises(wd.SimulationError, match=r"blow-up at step 1: sphere 1 \(world 0\)"):
        s.run(m.state(), s.contacts(), 5)


def _crowded_run(runaway: bool):
    """Three steps of a 3 x 3 x 3 block of touching spheres with 2 candidate slots each (too few), and with
    ``runaway`` a 28th sphere far off at 600 m/s (above the velocity limit)."""
    b = wd.ModelBuilder(gravity=(0, 0, 0))
    b.add_material(wd.Material("a", density=2500, youngs_modulus=1e7, poisson_ratio=0.3))
    pts = [(i * 0.0099, j * 0.0099, k * 0.0099) for i in range(3) for j in range(3) for k in range(3)]
    b.add_spheres(pts, 0.005, "a")
    if runaway:
        b.add_sphere((1, 0, 0), 0.005, "a", velocity=(600, 0, 0))
    m = b.finalize("cpu")
    s = wd.Solver(m, wd.SolverOptions(neighbor_capacity=2))
    s.run(m.state(), s.contacts(), 3)


def test_neighbor_overflow_reported():
    """More candidates than slots is reported, naming the capacity option."""
    with pytest.raises(wd.SimulationError, match="neighbor_capacity = 2"):
        _crowded_run(runaway=False)


def test_blowup_with_overflow_names_both():
    """When a run both blows up and drops contacts, the message gives the blow-up and the overflow."""
    with pytest.raises(wd.SimulationError, match=r"blow-up at step 1: sphere 27 .*neighbor_capacity = 2"):
        _crowded_run(runaway=True)


def test_rebuild_count_follows_the_skin():
    """A lone sphere coasting at v (no gravity) rebuilds its lists each time it has moved half the Verlet
    skin since the last build: with v dt = (skin / 2) / 10.5 that is every 11th step, so 110 steps (builds
    at steps 0, 11, ..., 99) make 10 rebuilds; a sphere at rest builds once; skin_fraction scales the skin."""
    r = 1e-3
    b = wd.ModelBuilder(gravity=(0, 0, 0))
    b.add_material(wd.Material("a", density=2500, youngs_modulus=1e7, poisson_ratio=0.3))
    b.add_sphere((0, 0, 0), r, "a")
    m = b.finalize("cpu")
    probe = wd.Solver(m)
    v = 0.5 * probe.skin / 10.5 / probe.dt
    b = wd.ModelBuilder(gravity=(0, 0, 0))
    b.add_material(wd.Material("a", density=2500, youngs_modulus=1e7, poisson_ratio=0.3))
    b.add_sphere((0, 0, 0), r, "a", velocity=(v, 0, 0))
    m = b.finalize("cpu")
    s = wd.Solver(m)
    s.run(m.state(), s.contacts(), 110)
    assert s.rebuild_count == 10
    still = wd.Solver(probe.model)
    still.run(probe.model.state(), still.contacts(), 110)
    assert still.rebuild_count == 1
    # a skin of 0.6 r instead of 0.4 r: half of it is 15.75 steps of travel, so builds at 0, 16, ..., 96
    wide = wd.Solver(m, wd.SolverOptions(skin_fraction=0.6))
    wide.run(m.state(), wide.contacts(), 110)
    assert wide.skin == pytest.approx(0.6 * r) and wide.rebuild_count == 7


def _raft(r: float = 1e-3):
    """A flat 3 x 3 raft of spheres of radius r [m], 1.6 r apart: nine spheres touch a plane at once."""
    offsets = np.array([(i * 1.6 * r, j * 1.6 * r, 0.0) for i in (-1, 0, 1) for j in (-1, 0, 1)])
    return wd.ClumpTemplate.from_spheres("raft", offsets, np.full(9, r))


def _raft_rebound(e: float, mass: str) -> float:
    """Rebound speed ratio of a flat 3 x 3 raft clump dropped flat onto a plane at 0.5 m/s."""
    r = 1e-3
    b = wd.ModelBuilder(gravity=(0, 0, 0))
    b.add_material(wd.Material("a", density=2000, youngs_modulus=1e7, poisson_ratio=0.3))
    b.set_interaction("a", "a", restitution=e, static_friction=0.5)
    b.add_plane((0, 0, 0), (0, 0, 1), "a")
    b.add_clump(_raft(r), (0, 0, r + 1e-5), "a", velocity=(0, 0, -0.5))
    m = b.finalize("cpu")
    s = wd.Solver(m, wd.SolverOptions(clump_contact_mass=mass))
    state = s.run(m.state(), s.contacts(), int(0.005 / s.dt))
    return float(state.clump_v.numpy()[0, 2]) / 0.5


def test_clump_sub_contacts_share_the_mass():
    """Nine sub-contacts touching at once act in parallel on one body: sharing the clump's mass among them
    (the default) gives the pair's restitution at the default step (a sphere realises it within 1 %; the
    count of contacts lags by at most the step that predicts them); the whole mass per sub-contact
    (EDEM's convention) overdamps the face about threefold, so the raft barely rebounds."""
    assert _raft_rebound(0.45, "shared") == pytest.approx(0.45, rel=0.03)
    assert _raft_rebound(0.45, "body") < 0.1


def test_clump_mass_is_shared_per_partner_body():
    """A raft resting on a plane with a sphere on one of its spheres: the partner table counts nine
    sub-contacts with the plane and one with the sphere, so the sphere's contact damps with the whole raft
    mass and each plane sub-contact with a ninth of it."""
    r = 1e-3
    b = wd.ModelBuilder(gravity=(0, 0, -9.81))
    b.add_material(wd.Material("a", density=2000, youngs_modulus=1e7, poisson_ratio=0.3))
    b.add_plane((0, 0, 0), (0, 0, 1), "a")
    b.add_clump(_raft(r), (0, 0, r - 1e-6), "a")
    b.add_sphere((0, 0, 3 * r - 2e-6), r, "a")
    m = b.finalize("cpu")
    s = wd.Solver(m)
    c = s.contacts()
    s.run(m.state(), c, 3)
    keys, counts = c.partner_key.numpy(), c.partner_count.numpy()
    table = {int(k): int(n) for k, n in zip(keys, counts) if k >= 0}
    plane_key, sphere_key = m.clump_count + m.sphere_count, m.clump_count + 9
    assert table == {plane_key: 9, sphere_key: 1}


def test_same_inputs_same_numbers():
    """Reproducible: the same inputs on CPU give bit-identical results."""
    out = []
    for _ in range(2):
        m, s = _resting_pair(1e-4)
        out.append(s.run(m.state(), s.contacts(), 300).sphere_x.numpy())
    assert np.array_equal(out[0], out[1])


def test_third_law_momentum():
    """Pair forces are exactly equal and opposite: with no gravity and no walls, momentum is conserved."""
    rng = np.random.default_rng(5)
    b = wd.ModelBuilder(gravity=(0, 0, 0))
    b.add_material(wd.Material("a", density=2500, youngs_modulus=1e7, poisson_ratio=0.3))
    b.set_interaction("a", "a", restitution=0.4, static_friction=0.5, rolling_friction=0.1, rolling_model="epsd")
    pts = np.array([(i * 0.0095, j * 0.0095, k * 0.0095) for i in range(3) for j in range(3) for k in range(3)])
    b.add_spheres(pts, 0.005, "a", velocities=rng.normal(scale=0.5, size=pts.shape))
    m = b.finalize("cpu")
    s = wd.Solver(m)
    st = m.state()
    p0 = st.sphere_v.numpy().sum(axis=0)
    st = s.run(st, s.contacts(), 500)
    f = st.sphere_f.numpy()
    assert np.abs(f.sum(axis=0)).max() <= 1e-5 * np.abs(f).max()
    np.testing.assert_allclose(st.sphere_v.numpy().sum(axis=0), p0, atol=1e-5)


def test_wall_forces_carry_the_weight():
    """Static equilibrium: two spheres pushed by tilted gravity into the corner of the floor plane and a
    45-degree mesh ramp come to rest; the forces on plane and ramp sum to their weight m g."""
    g = np.array([1.5, 0.0, -9.7])
    b = wd.ModelBuilder(gravity=g)
    b.add_material(wd.Material("a", density=2500, youngs_modulus=1e7, poisson_ratio=0.3))
    b.set_interaction("a", "a", restitution=0.3, static_friction=0.5, rolling_friction=0.1, rolling_model="epsd")
    b.add_plane((0, 0, 0), (0, 0, 1), "a")
    b.add_wall_mesh([(0.02, -0.05, 0), (0.02, 0.05, 0), (0.07, 0, 0.05)], [(0, 1, 2)], "a", name="ramp")
    r = 0.005
    x0 = 0.02 + r - r * math.sqrt(2)  # touching both the floor and the ramp
    b.add_spheres([(x0 - 5e-4, -0.006, r + 2e-4), (x0 - 5e-4, 0.006, r + 2e-4)], r, "a")
    m = b.finalize("cpu")
    s = wd.Solver(m)
    st = s.run(m.state(), s.contacts(), int(0.5 / s.dt))
    mass = 2 * 2500 * 4 / 3 * math.pi * r**3
    wf = st.wall_f.numpy()
    assert wf.shape == (2, 3)
    assert float(np.abs(st.sphere_v.numpy()).max()) < 1e-3, "the spheres did not come to rest"
    np.testing.assert_allclose(wf.sum(axis=0), mass * g, atol=2e-3 * mass * 9.81)
    # floor friction may share the sideways push (statically indeterminate), but the ramp must take a real part
    assert wf[1][0] > 0.2 * mass * g[0]


def test_bodies_leaving_the_domain_are_removed():
    """A free sphere and a clump fall from rest out of the domain's floor (z = -0.05 m): each is removed at
    the first list rebuild after its free-fall time sqrt(2 h / g), never before it, at most half the skin
    beyond the floor; a clump leaves whole; each world counts its own (world 1 has no gravity, so nothing
    leaves); once both are gone no rebuild is flagged and they stay put."""
    r, g, floor = 0.005, 9.81, -0.05
    b = wd.ModelBuilder()
    b.add_material(wd.Material("a", density=2500, youngs_modulus=1e7, poisson_ratio=0.3))
    b.add_sphere((0, 0, 0), r, "a")
    b.add_clump(wd.ClumpTemplate.from_spheres("pair", [[-r, 0, 0], [r, 0, 0]], [r, r]), (0.1, 0, 0.02), "a")
    b.set_domain((-1, -1, floor), (1, 1, 1))
    b.replicate(2)
    b.vary("gravity", [[0, 0, -g], [0, 0, 0]])
    m = b.finalize("cpu")
    s = wd.Solver(m)
    st, c = m.state(), s.contacts()
    t_sphere, t_clump = math.sqrt(2 * -floor / g), math.sqrt(2 * (0.02 - floor) / g)
    # half a skin at the speed it leaves with: the latest a rebuild can come after the crossing
    lag = 0.5 * s.skin / (g * t_sphere)

    def alive():
        act = st.sphere_active.numpy().reshape(2, 3)
        return act[0, 0], act[0, 1:], act[1]

    st = s.advance(st, c, t_sphere - 2 * s.dt)
    assert alive()[0] == 1 and st.world_removed.numpy().tolist() == [0, 0]
    st = s.advance(st, c, t_clump - st.time - 2 * s.dt)
    sphere, clump, other = alive()
    assert sphere == 0 and clump.tolist() == [1, 1] and st.world_removed.numpy().tolist() == [1, 0]
    z = st.sphere_x.numpy()[0, 2]
    assert floor - 0.5 * s.skin - g * t_clump * s.dt <= z < floor
    st = s.advance(st, c, 2 * lag + 4 * s.dt)
    sphere, clump, other = alive()
    assert clump.tolist() == [0, 0] and other.tolist() == [1, 1, 1]
    assert st.world_removed.numpy().tolist() == [2, 0]
    assert np.all(st.clump_v.numpy()[0] == 0) and np.all(st.sphere_v.numpy()[:3] == 0)
    x_gone, rebuilds = st.sphere_x.numpy()[:3].copy(), s.rebuild_count
    st = s.advance(st, c, 0.05)
    assert s.rebuild_count == rebuilds and np.array_equal(st.sphere_x.numpy()[:3], x_gone)


def test_a_settled_world_is_held_where_it_is():
    """Solver.settle_worlds holds a world (SphereActivity.SETTLED): its free sphere and its clump stay exactly where
    they were, gravity notwithstanding, stay present (nonzero activity) and leave the contact search (no neighbours
    after a rebuild), while the other world falls on, bit-identical to the same model never held, along the
    free-fall parabola z0 - g t^2 / 2 (leapfrog is exact under a constant force)."""
    r, g, z0 = 0.005, 9.81, 1.0
    b = wd.ModelBuilder(gravity=(0, 0, -g))
    b.add_material(wd.Material("a", density=2500, youngs_modulus=1e7, poisson_ratio=0.3))
    # within the search's reach of the clump (its lists hold the pair) but not touching it: free fall
    b.add_sphere((0, 0, z0), r, "a")
    b.add_clump(wd.ClumpTemplate.from_spheres("pair", [[-r, 0, 0], [r, 0, 0]], [r, r]), (0.0, 0.0, z0 + 2.0 * r), "a")
    b.replicate(2)
    m = b.finalize("cpu")

    def run(hold: bool):
        s = wd.Solver(m)
        st, c = m.state(), s.contacts()
        st = s.run(st, c, 100)
        x_held, q_held = st.sphere_x.numpy()[:3].copy(), st.clump_q.numpy()[0].copy()
        if hold:
            s.settle_worlds(st, [0])
        st = s.run(st, c, 200)
        s.rebuild(st, c)
        return s, st, c, x_held, q_held

    s, st, c, x_held, q_held = run(True)
    _, free, _, _, _ = run(False)
    assert st.sphere_active.numpy().tolist() == [wd.SphereActivity.SETTLED] * 3 + [wd.SphereActivity.MOVING] * 3
    assert np.array_equal(st.sphere_x.numpy()[:3], x_held) and np.array_equal(st.clump_q.numpy()[0], q_held)
    assert c.neighbor_count.numpy()[:3].tolist() == [0, 0, 0] and c.neighbor_count.numpy()[3:].sum() > 0
    assert np.array_equal(st.sphere_x.numpy()[3:], free.sphere_x.numpy()[3:])
    t = st.time
    assert st.sphere_x.numpy()[3, 2] == pytest.approx(z0 - 0.5 * g * t**2, abs=1e-6)
    assert t == pytest.approx(300 * s.dt)


def test_domain_is_validated():
    b = wd.ModelBuilder()
    with pytest.raises(
        ValueError,
        match=r"set_domain: low = \(0.0, 0.0, 1.0\) and high = \(1.0, 1.0, 1.0\) "
        r"are not allowed; expected low < high on every axis",
    ):
        b.set_domain((0, 0, 1), (1, 1, 1))
    with pytest.raises(ValueError, match="set_domain: high = .* is not allowed; expected three finite numbers"):
        b.set_domain((0, 0, 0), (1, 1, float("nan")))


def test_contact_law_varies_per_world():
    """The pair's law is a per-world value: one sphere rests on the floor in three worlds, Hertz-Mindlin (the
    scene's law, world 0 keeps it with None), JKR with gamma = 1 J/m^2 and Hertz-Mindlin set by name. Each sinks
    to its own law's equilibrium overlap: Hertz (3 m g / (4 E* sqrt R))^(2/3); JKR where F_JKR(delta) = m g
    (float64 closed form, R* = R on a plane)."""
    from scipy.optimize import brentq

    from warpdem.engine import analytic as an

    rho, e_mod, nu, r, gamma, g = 2500.0, 1e7, 0.3, 0.005, 1.0, 9.81
    b = wd.ModelBuilder(gravity=(0, 0, -g))
    b.add_material(wd.Material("a", density=rho, youngs_modulus=e_mod, poisson_ratio=nu))
    b.set_interaction("a", "a", restitution=0.2, static_friction=0.5)
    b.add_plane((0, 0, 0), (0, 0, 1), "a")
    b.add_sphere((0, 0, r), r, "a")
    b.replicate(3)
    b.vary("interaction.a.a.law", [None, "jkr", wd.ContactLaw.HERTZ_MINDLIN])
    b.vary("interaction.a.a.surface_energy", [None, gamma, None])
    m = b.finalize("cpu")
    s = wd.Solver(m)
    st = s.run(m.state(), s.contacts(), int(0.3 / s.dt))
    overlap = r - st.sphere_x.numpy()[:, 2]
    weight = rho * 4.0 / 3.0 * math.pi * r**3 * g
    e_star = e_mod / (2.0 * (1.0 - nu**2))
    hertz = (3.0 * weight / (4.0 * e_star * math.sqrt(r))) ** (2.0 / 3.0)
    jkr = brentq(lambda d: an.jkr_force(d, r, e_star, gamma) - weight, 0.0, 100 * hertz)
    assert float(np.abs(st.sphere_v.numpy()).max()) < 1e-4, "the spheres did not come to rest"
    # float32 positions of ~5 mm resolve overlaps to ~1e-9 m: 1 % of a ~1e-5 m overlap is far above it
    np.testing.assert_allclose(overlap, [hertz, jkr, hertz], rtol=0.01)
    assert jkr > 1.5 * hertz  # the check separates the laws


def _scene_of(radius, clumps, gate_x, material=None):
    b = wd.ModelBuilder()
    b.add_material(material or wd.Material("glass", density=2500, youngs_modulus=5e7, poisson_ratio=0.25))
    b.add_plane((0, 0, 0), (0, 0, 1), "glass")
    tri = [(0, 1, 2)]
    b.add_wall_mesh([(0, 0, 0.1), (0.1, 0, 0.1), (0, 0.1, 0.1)], tri, "glass", name="roof")
    b.add_wall_mesh([(gate_x, 0, 0.05), (gate_x + 0.1, 0, 0.05), (gate_x, 0.1, 0.05)], tri, "glass", name="gate")
    b.add_spheres([(0.01 * k, 0, 0.02) for k in range(3)], radius, "glass")
    tpl = wd.ClumpTemplate.from_spheres(f"pair{radius}", [(-radius, 0, 0), (radius, 0, 0)], [radius, radius])
    b.add_clumps(tpl, [(0.01 * k, 0.03, 0.02) for k in range(clumps)], "glass")
    return b


def test_stacked_scenes_keep_their_own_particles_and_walls():
    """Two scenes of other grains as one Model (ModelBuilder.stack): world 0-1 are the first scene replicated,
    world 2 the second; every sphere, clump and glued index stays within its world; the wall both share is one
    wall, the one that differs (the gate) one per world; the step is the smallest grain's Rayleigh time."""
    small, large = _scene_of(1e-3, 1, 0.0), _scene_of(2e-3, 2, 0.02)
    small.replicate(2)
    small.seed_worlds([3, 4])
    small.stack(large)
    m = small.finalize("cpu")
    world, radius = m.sphere_world.numpy(), m.sphere_radius.numpy()
    assert m.world_count == 3 and m.sphere_count == 2 * (3 + 2) + (3 + 4) and m.clump_count == 4
    assert np.bincount(world).tolist() == [5, 5, 7]
    assert np.allclose(radius[world < 2], 1e-3) and np.allclose(radius[world == 2], 2e-3)
    starts, ends, cworld = m.clump_sphere_start.numpy(), m.clump_sphere_end.numpy(), m.clump_world.numpy()
    assert cworld.tolist() == [0, 1, 2, 2]
    for c in range(m.clump_count):
        assert (m.sphere_clump.numpy()[starts[c] : ends[c]] == c).all()
        assert (world[starts[c] : ends[c]] == cworld[c]).all()
    assert m.wall_names == ["roof", "gate", "gate", "gate"]
    assert m.wall_world.numpy().tolist() == [-1, 0, 1, 2]
    assert m.world_seed.tolist() == [3, 4, 0]
    assert np.asarray(m.clump_template).tolist() == [0, 0, 1, 1]
    assert m.rayleigh_time == pytest.approx(m.materials[0].rayleigh_time(1e-3))
    assert m.initial["sphere_x"].shape == (m.sphere_count, 3) and m.initial["clump_q"].shape == (4, 4)


def test_stack_refuses_scenes_that_differ_in_more_than_particles():
    """Another material (or a builder stacked twice) cannot share a Model: the error names what differs."""
    a = _scene_of(1e-3, 1, 0.0)
    other = wd.Material("glass", density=2600, youngs_modulus=5e7, poisson_ratio=0.25)
    with pytest.raises(ValueError, match="stack: the other scene has different materials"):
        a.stack(_scene_of(1e-3, 1, 0.0, other))
    b = _scene_of(2e-3, 1, 0.0)
    a.stack(b)
    with pytest.raises(ValueError, match="stack: other = .* is not allowed"):
        a.stack(b)
