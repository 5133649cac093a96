"""The time step that follows the stiffest contact (SolverOptions.dt_margin, dt_levels).

The stable-step frequency of a contact is checked against the eigenvalues of leapfrog's own step matrix
(independent of the closed form the kernels use) and against float64 formulas of each law's tangent stiffness;
the solver's margin against two spheres pressed together, whose Hertz stiffness the Rayleigh time does not
cover.
"""

import math

import numpy as np
import pytest
import warp as wp

import warpdem as wd
from warpdem.kernels.enums import ContactLaw
from warpdem.kernels.law_contact import contact_force
from warpdem.kernels.law_hertz_mindlin import stable_factors
from warpdem.kernels.params import ContactHistory, PairParams

wp.set_module_options({"enable_backward": False})

SQRT_5_6 = math.sqrt(5.0 / 6.0)


@wp.kernel
def _rate_path_kernel(overlap: wp.array[float], p: PairParams, r_star: float, m_star: float, rate_out: wp.array[float]):
    # one contact at rest walked along a path of overlaps, carrying its history as the step kernel does
    n = wp.vec3(0.0, 0.0, 1.0)
    h = ContactHistory()
    for i in range(overlap.shape[0]):
        active, f_a, load, f_t, h_new, k_n, k_s = contact_force(overlap[i], n, wp.vec3(0.0), h, r_star, m_star, p, 1e-7)
        h = h_new
        rate_out[i] = k_s


def _leapfrog_radius(w2: float, g: float, dt: float) -> float:
    """Spectral radius of one leapfrog step of x'' = -w2 x - g x' with the dashpot on the half-step velocity:
    (x_n, dt v_{n-1/2}) -> (x_{n+1}, dt v_{n+1/2})."""
    a, b = g * dt, w2 * dt * dt
    step = np.array([[1.0 - b, 1.0 - a], [-b, 1.0 - a]])
    return float(np.max(np.abs(np.linalg.eigvals(step))))


def _mode(s, c, m):
    g = c / m
    return (0.5 * (g + math.sqrt(g * g + 4.0 * s / m))) ** 2


def _beta(e):
    return math.log(e) / math.sqrt(math.log(e) ** 2 + math.pi**2)


@pytest.mark.parametrize("damp", [0.0, 0.4, 0.94, 1.8])
def test_stable_factors_are_the_leapfrog_stability_limit(damp):
    """For dashpots c = damp sqrt(S m*), 2 / sqrt(A S / m*) (normal mode, mass m*) and 2 / sqrt(B S / m*)
    (tangential mode, mass 2/7 m*) are where leapfrog's step matrix turns unstable: spectral radius <= 1 just
    below and > 1 just above, undamped to strongly damped (Tsuji at e = 0.15: damp = 0.94)."""
    m_star, s = 2.0e-6, 3.0e3
    c = damp * math.sqrt(s * m_star)
    for factor, mass in zip(stable_factors(damp), (m_star, m_star / 3.5)):
        dt_crit = 2.0 / math.sqrt(factor * s / m_star)
        assert _leapfrog_radius(s / mass, c / mass, 0.999 * dt_crit) <= 1.0 + 1e-9
        assert _leapfrog_radius(s / mass, c / mass, 1.001 * dt_crit) > 1.0 + 1e-6


def _params(law, e_star, g_star, e, **extra):
    """PairParams as the model builds them (materials.pair_table), for the interaction's law and restitution."""
    inter = wd.Interaction(
        restitution=e, law=law, slope_exponent=extra.get("eepa_n", 1.5), plasticity_ratio=extra.get("lambda_p", 0.5)
    )
    p = PairParams()
    p.law, p.e_star, p.g_star, p.beta, p.mu_s = int(law), e_star, g_star, _beta(e), 0.5
    p.stable_n, p.stable_t = stable_factors(inter.dashpot_factor)
    for k, v in extra.items():
        setattr(p, k, v)
    return p


def _rates(path, p, r_star, m_star):
    out = wp.zeros(len(path), dtype=float, device="cpu")
    wp.launch(
        _rate_path_kernel,
        dim=1,
        inputs=[wp.array(np.asarray(path, np.float32), dtype=float, device="cpu"), p, r_star, m_star],
        outputs=[out],
        device="cpu",
    )
    return out.numpy().astype(float)


E_STAR, G_STAR, R_STAR, M_STAR, E_REST = 1.2e7, 4.0e6, 2.5e-4, 1.0e-7, 0.15


def _hm_rate(s_n, s_t, damp, m_star):
    """The rate of a contact with Tsuji dashpots (damp = 2 sqrt(5/6) |beta|): normal on m*, tangential on 2/7 m*."""
    c_n, c_t = damp * math.sqrt(s_n * m_star), damp * math.sqrt(s_t * m_star)
    return max(_mode(s_n, c_n, m_star), _mode(s_t, c_t, m_star / 3.5))


def test_hertz_rate_follows_the_compression():
    """Hertz-Mindlin: S_n = 2 E* sqrt(R* d), S_t = 8 G* sqrt(R* d) with their dashpots; the rate grows as
    sqrt(d), so a contact compressed to a third of R* is 3.2 times stiffer than one at 1 % of it."""
    d = np.array([0.01, 0.1, 1.0 / 3.0]) * R_STAR
    got = _rates(d, _params(ContactLaw.HERTZ_MINDLIN, E_STAR, G_STAR, E_REST), R_STAR, M_STAR)
    damp = -2.0 * SQRT_5_6 * _beta(E_REST)
    want = [_hm_rate(2 * E_STAR * math.sqrt(R_STAR * x), 8 * G_STAR * math.sqrt(R_STAR * x), damp, M_STAR) for x in d]
    np.testing.assert_allclose(got, want, rtol=2e-5)


def test_jkr_rate_uses_the_contact_radius():
    """JKR: the rate of S_n = 2 E* a, S_t = 8 G* a at the contact radius a (the tangent stiffness's bound on its
    stable branch); with adhesion a is larger than Hertz's sqrt(R* d), so the rate is too."""
    gamma = 0.5
    d = np.array([0.05, 0.2]) * R_STAR
    got = _rates(d, _params(ContactLaw.JKR, E_STAR, G_STAR, E_REST, gamma=gamma), R_STAR, M_STAR)
    damp = -2.0 * SQRT_5_6 * _beta(E_REST)
    for x, rate in zip(d, got):
        a = _jkr_radius(x, gamma)
        assert a > math.sqrt(R_STAR * x)
        assert rate == pytest.approx(_hm_rate(2 * E_STAR * a, 8 * G_STAR * a, damp, M_STAR), rel=1e-4)


def _jkr_radius(delta, gamma):
    """Contact radius [m] on JKR's stable branch for overlap ``delta`` [m] (bisection in float64)."""
    lo, hi = (math.pi * gamma * R_STAR**2 / E_STAR) ** (1 / 3), 1e-3
    # delta = a^2 / R* - sqrt(4 pi gamma a / E*) (kernels/law_jkr.py), increasing on the stable branch
    f = lambda a: a * a / R_STAR - math.sqrt(4 * math.pi * gamma * a / E_STAR) - delta  # noqa: E731
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(mid) < 0 else (lo, mid)
    return 0.5 * (lo + hi)


def test_eepa_unloading_rate_uses_k2():
    """EEPA (n = 1.5): loading uses the virgin branch's tangent n k1 d^(n-1); unloading from d_max the steeper
    k2 = k1 / (1 - lambda_p) branch (a small tangential multiplier, so the normal mode limits the step). Its
    dashpot, from k1, damps k2 less than the pair's factor assumes: the rate is then at least the exact limit."""
    lam, n, ks_fac = 0.8, 1.5, 0.2
    d_max = 0.2 * R_STAR
    path = [0.5 * d_max, d_max, 0.9 * d_max]
    p = _params(ContactLaw.EEPA, E_STAR, G_STAR, E_REST, eepa_n=n, lambda_p=lam, chi=1.5, ks_fac=ks_fac)
    got = _rates(path, p, R_STAR, M_STAR)
    k1 = 4.0 / 3.0 * E_STAR * math.sqrt(R_STAR)
    damp = -2.0 * SQRT_5_6 * _beta(E_REST)
    for x, rate, unloading in zip(path, got, (False, False, True)):
        k_load = n * k1 * x ** (n - 1)
        k_n = k_load / (1 - lam) if unloading else k_load
        k_t = ks_fac * 8 * G_STAR * math.sqrt(R_STAR * x)
        c_n, c_t = damp * math.sqrt(k_load * M_STAR), damp * math.sqrt(k_t * M_STAR)
        exact = max(_mode(k_n, c_n, M_STAR), _mode(k_t, c_t, M_STAR / 3.5))
        a, b = stable_factors(damp)
        assert rate == pytest.approx(max(a * k_n, b * k_t) / M_STAR, rel=1e-5)
        if unloading:
            # the factor takes z = damp / 2 where the k1 dashpot on k2 gives z sqrt(1 - lambda_p): the bound
            lift = lambda z: (z + math.sqrt(z * z + 1)) ** 2  # noqa: E731
            bound = exact * lift(damp / 2) / lift(damp / 2 * math.sqrt(1 - lam))
            assert exact * (1 - 1e-5) <= rate <= bound * (1 + 1e-5)
        else:
            assert rate == pytest.approx(exact, rel=1e-5)
    assert got[2] > got[1]


def _pressed_pair(overlap_fraction: float, **options):
    """Two 1 mm spheres of a soft solid (G = 10 MPa, e = 0.15) at rest, overlapping by ``overlap_fraction`` of
    their radius, no gravity; returns (model, solver, analytic margin at the solver's dt)."""
    r, rho, nu, g_mod = 1.0e-3, 440.0, 0.25, 1.0e7
    b = wd.ModelBuilder(gravity=(0, 0, 0))
    b.add_material(wd.Material("feed", density=rho, poisson_ratio=nu, shear_modulus=g_mod))
    b.set_interaction("feed", "feed", wd.Interaction(restitution=E_REST, static_friction=0.5))
    d = overlap_fraction * r
    b.add_sphere((0.0, 0.0, 0.0), r, "feed")
    b.add_sphere((2 * r - d, 0.0, 0.0), r, "feed")
    model = b.finalize("cpu")
    solver = wd.Solver(model, wd.SolverOptions(**options))
    e_mod = 2 * g_mod * (1 + nu)
    e_star = 1 / (2 * (1 - nu**2) / e_mod)
    g_star = 1 / (2 * (2 - nu) / g_mod)
    r_star, m_star = r / 2, 0.5 * rho * 4 / 3 * math.pi * r**3
    damp = -2.0 * SQRT_5_6 * _beta(E_REST)
    root = math.sqrt(r_star * d)
    rate = _hm_rate(2 * e_star * root, 8 * g_star * root, damp, m_star)
    return model, solver, 0.5 * solver.dt * math.sqrt(rate)


def test_compressed_pair_triggers_the_criterion():
    """Two spheres pressed a fifth of their radius into each other: the margin of the Rayleigh step (20 %) is the
    analytic one and above dt_margin (the Rayleigh time covers an impact, not this contact), so advance halves
    the step until it is below; a light touch (1e-4 of the radius) stays within the margin at the Rayleigh
    step, and dt_levels = 0 keeps the step and only reports."""
    model, solver, want = _pressed_pair(0.2)
    state = solver.run(model.state(), solver.contacts(), 1)
    assert solver.step_margin == pytest.approx(want, rel=1e-4)
    assert want > solver.options.dt_margin
    levels = math.ceil(math.log2(want / solver.options.dt_margin))
    state = solver.advance(state, solver.contacts(), 0.0)
    solver._adapt_dt()
    assert solver.dt_level == levels
    assert solver.dt == pytest.approx(solver.dt_base / 2**levels, rel=1e-12)
    assert solver.step_margin == pytest.approx(want / 2**levels, rel=1e-4)

    model, solver, want = _pressed_pair(1e-4)
    solver.run(model.state(), solver.contacts(), 1)
    # float32 places the spheres 2 mm apart to 2.4e-10 m: the 1e-7 m overlap to 0.24 %, its margin (~ d^1/4) to 0.06 %
    assert solver.step_margin == pytest.approx(want, rel=1e-3) and want < solver.options.dt_margin

    model, solver, want = _pressed_pair(0.2, dt_levels=0)
    state = solver.run(model.state(), solver.contacts(), 1)
    solver.advance(state, solver.contacts(), 10 * solver.dt)
    assert solver.dt == solver.dt_base and solver.step_margin_max >= want * (1 - 1e-4)


def test_step_follows_the_contact_and_returns():
    """Two spheres pressed together fly apart: advance halves the step while they touch and, once the margin
    has fallen (no contact: 0), doubles it back tick by tick to the Rayleigh step, never above; the kick across
    a change of step conserves their momentum (zero total) and the run stays finite."""
    model, solver, want = _pressed_pair(0.2)
    state, contacts = model.state(), solver.contacts()
    levels = []
    for _ in range(40):
        state = solver.advance(state, contacts, 20 * solver.dt_base)
        levels.append(solver.dt_level)
    assert max(levels) >= 1 and levels[-1] == 0
    assert all(lvl >= 0 for lvl in levels)
    v = state.sphere_v.numpy().astype(np.float64)
    assert np.abs(v.sum(axis=0)).max() <= 1e-6 * np.abs(v).max()


def test_dt_state_restores_the_level():
    """A solver restored from dt_state steps at the saved level, with no kick across a change pending."""
    model, solver, _ = _pressed_pair(0.2)
    state = solver.run(model.state(), solver.contacts(), 1)
    solver.advance(state, solver.contacts(), 0.0)
    solver._adapt_dt()
    saved = solver.dt_state()
    _, fresh, _ = _pressed_pair(0.2)
    fresh.restore_dt_state(saved)
    assert (fresh.dt, fresh.dt_level, fresh.step_margin) == (solver.dt, solver.dt_level, solver.step_margin)
    assert fresh._kick_next is None


@pytest.mark.parametrize(
    "field, value",
    [("dt_margin", 0.0), ("dt_margin", 1.5), ("dt_margin", float("nan")), ("dt_levels", -1), ("dt_levels", 2.5)],
)
def test_bad_step_options_are_refused(field, value):
    """Bad step-criterion options name the field, the value and what is allowed."""
    with pytest.raises(ValueError, match=rf"SolverOptions: {field} = .* is not allowed; expected"):
        wd.SolverOptions(**{field: value})
