"""Cohesive contact laws (JKR, EEPA) in Warp against the float64 closed forms of warpdem.engine.analytic.

Displacement-controlled: a tiny kernel drives one contact along a prescribed overlap path through the step's
law dispatch ``contact_force`` (one thread walks the path and carries the contact's history, as the step
kernel does from step to step); other kernels evaluate the laws' functions point by point.
"""

import math

import numpy as np
import pytest
import warp as wp

from warpdem.engine import analytic as an
from warpdem.kernels.enums import ContactLaw
from warpdem.kernels.law_contact import contact_force
from warpdem.kernels.law_eepa import eepa_damping_coefficient, eepa_tangential_stiffness
from warpdem.kernels.law_jkr import (
    jkr_break_overlap,
    jkr_contact_radius,
    jkr_force_of_radius,
    jkr_friction_load,
    jkr_normal_force,
    jkr_stiffness,
)
from warpdem.kernels.params import ContactHistory, PairParams

wp.set_module_options({"enable_backward": False})

# the JKR example of verification-ecosystem 1.4: E* = 10 MPa, R* = 0.5 mm, gamma = 0.1 J/m^2
E_STAR, R_STAR, GAMMA = 1.0e7, 5.0e-4, 0.1
PGR = math.pi * GAMMA * R_STAR
_trapz = getattr(np, "trapezoid", None) or np.trapz  # NumPy < 2 has only trapz


@wp.kernel
def _jkr_kernel(
    overlap: wp.array[float],
    r_star: float,
    e_star: float,
    gamma: float,
    a_out: wp.array[float],
    f_out: wp.array[float],
    load_out: wp.array[float],
    break_out: wp.array[float],
):
    i = wp.tid()
    a_out[i] = jkr_contact_radius(overlap[i], r_star, e_star, gamma)
    f = jkr_normal_force(overlap[i], r_star, e_star, gamma)
    f_out[i] = f
    load_out[i] = jkr_friction_load(f, r_star, gamma)
    break_out[i] = jkr_break_overlap(r_star, e_star, gamma)


@wp.kernel
def _jkr_radius_force_kernel(a: wp.array[float], r_star: float, e_star: float, gamma: float, f_out: wp.array[float]):
    i = wp.tid()
    f_out[i] = jkr_force_of_radius(a[i], r_star, e_star, gamma)


@wp.kernel
def _jkr_stiffness_kernel(
    a: wp.array[float], e_star: float, g_star: float, sn_out: wp.array[float], st_out: wp.array[float]
):
    i = wp.tid()
    sn, st = jkr_stiffness(a[i], e_star, g_star)
    sn_out[i] = sn
    st_out[i] = st


@wp.kernel
def _path_kernel(
    overlap: wp.array[float],
    p: PairParams,
    r_star: float,
    active_out: wp.array[int],
    f_out: wp.array[float],
    aux_out: wp.array[float],
    k_out: wp.array[float],
    load_out: wp.array[float],
):
    # at rest (no dashpot, no tangential spring): the force on a is the law's normal force along -n
    n = wp.vec3(0.0, 0.0, 1.0)
    h = ContactHistory()
    for i in range(overlap.shape[0]):
        active, f_a, load, f_t, h_new, k_n, k_s = contact_force(overlap[i], n, wp.vec3(0.0), h, r_star, 1.0, p, 1.0e-6)
        h = h_new
        active_out[i] = active
        f_out[i] = -wp.dot(f_a, n)
        aux_out[i] = h.aux
        k_out[i] = k_n
        load_out[i] = load


@wp.kernel
def _eepa_aux_kernel(
    k: wp.array[float],
    overlap: wp.array[float],
    m_star: float,
    beta: float,
    n: float,
    r_star: float,
    e_star: float,
    g_star: float,
    ks_fac: float,
    c_out: wp.array[float],
    kt_out: wp.array[float],
):
    i = wp.tid()
    c_out[i] = eepa_damping_coefficient(k[i], m_star, beta, n)
    kt_out[i] = eepa_tangential_stiffness(overlap[i], r_star, e_star, g_star, n, ks_fac)


def _jkr(overlap, r_star=R_STAR, e_star=E_STAR, gamma=GAMMA):
    k = len(overlap)
    outs = [wp.zeros(k, dtype=float, device="cpu") for _ in range(4)]
    wp.launch(
        _jkr_kernel,
        dim=k,
        inputs=[wp.array(np.asarray(overlap, np.float32), dtype=float, device="cpu"), r_star, e_star, gamma],
        outputs=outs,
        device="cpu",
    )
    return [o.numpy().astype(float) for o in outs]


def _walk(path, law, r_star, **fields):
    """Drive one contact of a pair with ``law`` and PairParams ``fields`` along the overlap ``path`` [m];
    per point: (active, normal force F_n [N], the law's history aux, its stiffness for the rolling spring [N/m],
    normal load for the friction limits [N])."""
    p = PairParams()
    p.law = law
    for name, value in fields.items():
        setattr(p, name, value)
    k = len(path)
    active = wp.zeros(k, dtype=int, device="cpu")
    outs = [wp.zeros(k, dtype=float, device="cpu") for _ in range(4)]
    wp.launch(
        _path_kernel,
        dim=1,
        inputs=[wp.array(np.asarray(path, np.float32), dtype=float, device="cpu"), p, r_star],
        outputs=[active, *outs],
        device="cpu",
    )
    return [active.numpy()] + [o.numpy().astype(float) for o in outs]


def _eepa(path, f0=0.0, n=1.5, lambda_p=0.5, chi=1.5, gamma=5.0, r_star=1e-3, e_star=1e8):
    """(F_hys, delta_max, k_damp, load) along ``path``: EEPA's rolling stiffness is k_damp / n."""
    _, f, d_max, k, load = _walk(
        path, ContactLaw.EEPA, r_star, e_star=e_star, f0=f0, eepa_n=n, lambda_p=lambda_p, chi=chi, gamma=gamma
    )
    return f, d_max, k * n, load


# ------------------------------------------------------------------------------------------- JKR


@pytest.mark.parametrize(
    "e_star,r_star,gamma", [(E_STAR, R_STAR, GAMMA), (7.0e10, 2.0e-3, 0.02), (1.0e6, 5.0e-6, 0.05)]
)
def test_jkr_force_curve_matches_closed_form(e_star, r_star, gamma):
    """JKR (EDEM form) F(delta) at 20 overlaps from delta_c to 20 delta_0 equals the parametric curve
    delta(a), F(a) within 1 % of max(|F|, pi gamma R*), and the float32 Newton contact radius is within
    1e-4 (relative) of the float64 root on the stable branch; three material scales (soft to stiff)."""
    d_c = an.jkr_break_overlap(r_star, e_star, gamma)
    d_0 = an.jkr_zero_force_overlap(r_star, e_star, gamma)
    delta = np.concatenate([np.linspace(d_c * 0.9999, d_0, 12), np.geomspace(1.5 * d_0, 20.0 * d_0, 8)])
    a, f, _, _ = _jkr(delta, r_star, e_star, gamma)
    a_ref = an.jkr_contact_radius(delta, r_star, e_star, gamma)
    f_ref = an.jkr_force_of_radius(a_ref, r_star, e_star, gamma)
    # the reference itself: its (a, delta) pairs satisfy the EDEM relation delta(a)
    assert np.allclose(an.jkr_overlap(a_ref, r_star, e_star, gamma), delta, rtol=1e-9, atol=1e-12 * abs(d_c))
    assert np.max(np.abs(a - a_ref) / a_ref) < 1e-4
    scale = np.maximum(np.abs(f_ref), math.pi * gamma * r_star)
    assert np.max(np.abs(f - f_ref) / scale) < 0.01


def test_jkr_characteristic_values():
    """Verification-ecosystem 1.4 example (E* = 10 MPa, R* = 0.5 mm, gamma = 0.1 J/m^2): closed forms give
    a_0 = 41.35 um, delta(F=0) = +1.140 um, a_c = 11.49 um, delta_c = -0.9376 um, F(a_c) = -0.2356 mN,
    F_min = -0.471 mN, F(delta=0) = -(8/3) pi gamma R*."""
    assert an.jkr_zero_force_radius(R_STAR, E_STAR, GAMMA) == pytest.approx(41.35e-6, rel=1e-3)
    assert an.jkr_zero_force_overlap(R_STAR, E_STAR, GAMMA) == pytest.approx(1.140e-6, rel=1e-3)
    assert an.jkr_critical_radius(R_STAR, E_STAR, GAMMA) == pytest.approx(11.49e-6, rel=1e-3)
    assert an.jkr_break_overlap(R_STAR, E_STAR, GAMMA) == pytest.approx(-0.9376e-6, rel=1e-3)
    a_c = an.jkr_critical_radius(R_STAR, E_STAR, GAMMA)
    assert an.jkr_force_of_radius(a_c, R_STAR, E_STAR, GAMMA) == pytest.approx(-0.2356e-3, rel=1e-3)
    assert an.jkr_force(an.jkr_min_force_overlap(R_STAR, E_STAR, GAMMA), R_STAR, E_STAR, GAMMA) == pytest.approx(
        -0.471e-3, rel=1e-3
    )
    assert an.jkr_force(0.0, R_STAR, E_STAR, GAMMA) == pytest.approx(-8.0 / 3.0 * PGR, rel=1e-9)
    assert an.jkr_force(an.jkr_zero_force_overlap(R_STAR, E_STAR, GAMMA), R_STAR, E_STAR, GAMMA) == pytest.approx(
        0.0, abs=1e-12 * PGR
    )


def test_jkr_peak_attraction_and_force_at_break():
    """Peak attraction of the Warp law over a fine overlap sweep is 3 pi gamma R* (classical JKR pull-off,
    1.5 pi W R*) within 1 %; the law at EDEM's radius a_c gives EDEM's 1.5 pi gamma R* within 1 %; and just
    above delta_c (stable branch) the force is -1.832 pi gamma R* (analytic), within 1 %."""
    d_c = an.jkr_break_overlap(R_STAR, E_STAR, GAMMA)
    delta = np.linspace(d_c * 0.9999, 0.0, 2001)
    _, f, load, _ = _jkr(delta)
    assert -f.min() == pytest.approx(3.0 * PGR, rel=0.01)
    assert load.min() == pytest.approx(0.0, abs=0.01 * PGR)  # F + 3 pi gamma R* >= 0, zero at peak attraction
    assert np.all(load >= 0.0)
    a_c = an.jkr_critical_radius(R_STAR, E_STAR, GAMMA)
    out = wp.zeros(1, dtype=float, device="cpu")
    wp.launch(
        _jkr_radius_force_kernel,
        dim=1,
        inputs=[wp.array([a_c], dtype=float, device="cpu"), R_STAR, E_STAR, GAMMA],
        outputs=[out],
        device="cpu",
    )
    assert out.numpy()[0] == pytest.approx(-1.5 * PGR, rel=0.01)
    assert f[0] == pytest.approx(an.jkr_break_force(R_STAR, E_STAR, GAMMA), rel=0.01)
    assert f[0] / PGR == pytest.approx(-1.832, rel=0.01)


def test_jkr_break_overlap_matches_edem():
    """The law's break overlap delta_c = delta(a_c) matches the closed form within 2 % (anchor: -0.9376 um),
    lies above the end of the stable branch delta* (so a(delta) exists down to it), and no force acts below it."""
    delta = np.array([-2.0e-6, -0.95e-6, -0.93e-6, 0.0])
    _, f, _, brk = _jkr(delta)
    d_c = an.jkr_break_overlap(R_STAR, E_STAR, GAMMA)
    assert brk[0] == pytest.approx(d_c, rel=0.02)
    assert brk[0] == pytest.approx(-0.9376e-6, rel=0.02)
    assert an.jkr_instability_overlap(R_STAR, E_STAR, GAMMA) < d_c
    assert f[0] == 0.0 and f[1] == 0.0 and f[2] < 0.0
    assert f[3] == pytest.approx(-8.0 / 3.0 * PGR, rel=0.01)


def test_jkr_hysteresis_contact_flag():
    """JKR hysteresis: approaching from a gap, no force until delta = 0, then the jump to -(8/3) pi gamma R*;
    separating, the contact persists into negative overlap down to delta_c and then ends."""
    d_c = an.jkr_break_overlap(R_STAR, E_STAR, GAMMA)
    d_0 = an.jkr_zero_force_overlap(R_STAR, E_STAR, GAMMA)
    up = np.linspace(1.5 * d_c, 3.0 * d_0, 400)
    path = np.concatenate([up, up[::-1]]).astype(np.float32)
    flag, f, aux, _, _ = _walk(path, ContactLaw.JKR, R_STAR, e_star=E_STAR, gamma=GAMMA)
    assert np.array_equal(aux, flag)  # the contact keeps its in-contact flag as its history
    approach, leave = slice(0, len(up)), slice(len(up), len(path))
    assert np.all(flag[approach][path[approach] < 0.0] == 0)
    assert np.all(f[approach][path[approach] < 0.0] == 0.0)
    first = np.argmax(flag[approach])
    assert path[first] >= 0.0 and f[first] == pytest.approx(-8.0 / 3.0 * PGR, rel=0.02)
    sep = path[leave]
    assert np.all(flag[leave][sep >= d_c * 0.999] == 1)
    assert np.all(flag[leave][sep < d_c * 1.001] == 0)
    assert np.all(f[leave][(sep < 0.0) & (sep > d_c * 0.999)] < 0.0)


def test_jkr_zero_surface_energy_is_hertz():
    """gamma = 0: the JKR law is Hertz, F = 4/3 E* sqrt(R*) delta^1.5, a = sqrt(R* delta), delta_c = 0, and the
    stiffnesses from a are HM's S_n = 2 E* sqrt(R* delta), S_t = 8 G* sqrt(R* delta)."""
    delta = np.geomspace(1e-8, 1e-5, 10)
    a, f, load, brk = _jkr(delta, gamma=0.0)
    assert np.allclose(a, np.sqrt(R_STAR * delta), rtol=1e-5)
    assert np.allclose(f, 4.0 / 3.0 * E_STAR * np.sqrt(R_STAR) * delta**1.5, rtol=1e-5)
    assert np.allclose(load, f, rtol=1e-6)
    assert np.all(brk == 0.0)
    g_star = 4.0e6
    sn, st = wp.zeros(10, dtype=float, device="cpu"), wp.zeros(10, dtype=float, device="cpu")
    wp.launch(
        _jkr_stiffness_kernel,
        dim=10,
        inputs=[wp.array(a.astype(np.float32), dtype=float, device="cpu"), E_STAR, g_star],
        outputs=[sn, st],
        device="cpu",
    )
    assert np.allclose(sn.numpy(), 2.0 * E_STAR * np.sqrt(R_STAR * delta), rtol=1e-5)
    assert np.allclose(st.numpy(), 8.0 * g_star * np.sqrt(R_STAR * delta), rtol=1e-5)


def test_jkr_critical_speed_energy_balance():
    """Sticking speed from the energy balance: the adhesion loss W (closed form) equals -int F d delta over
    [delta_c, 0] by quadrature, and v_crit = sqrt(2 W / m) / e scales as 1/e."""
    d_c = an.jkr_break_overlap(R_STAR, E_STAR, GAMMA)
    x = np.linspace(d_c, 0.0, 100001)
    w_num = -_trapz(an.jkr_force(x, R_STAR, E_STAR, GAMMA), x)
    w = an.jkr_adhesion_work(R_STAR, E_STAR, GAMMA)
    assert w == pytest.approx(w_num, rel=1e-6)
    m = 4.0 / 3.0 * math.pi * R_STAR**3 * 2500.0
    v1 = an.jkr_critical_speed(m, R_STAR, E_STAR, GAMMA, 1.0)
    assert v1 == pytest.approx(math.sqrt(2.0 * w / m))
    assert an.jkr_critical_speed(m, R_STAR, E_STAR, GAMMA, 0.5) == pytest.approx(2.0 * v1)


# ------------------------------------------------------------------------------------------ EEPA

D_MAX = 1.0e-5
R_E, E_E = 1.0e-3, 1.0e8


def _branch_refs(path, dmax_hist, f0=0.0, n=1.5, lambda_p=0.5, chi=1.5, gamma=5.0):
    return np.array([an.eepa_force(d, dm, E_E, R_E, f0, n, lambda_p, chi, gamma) for d, dm in zip(path, dmax_hist)])


def test_eepa_load_unload_reload_follows_three_branches():
    """EEPA (Thakur et al. 2014 eq. 1) driven 0 -> delta_max -> 0.05 delta_max (through the adhesive branch)
    -> reload -> 1.5 delta_max: every point equals the analytic branch force for the running delta_max within
    1 % of k1 delta_max^n; the path visits virgin loading, unloading, adhesion and the reload back onto the
    virgin branch beyond delta_max."""
    path = np.concatenate(
        [
            np.linspace(0.0, D_MAX, 300)[1:],
            np.linspace(D_MAX, 0.05 * D_MAX, 300),
            np.linspace(0.05 * D_MAX, 1.5 * D_MAX, 450),
        ]
    )
    f, dmax, _, _ = _eepa(path)
    dmax_ref = np.maximum.accumulate(path)
    assert np.allclose(dmax, dmax_ref, rtol=1e-6)
    ref = _branch_refs(path, dmax_ref)
    k1 = an.eepa_loading_stiffness(E_E, R_E, 1.5)
    k2 = an.eepa_unloading_stiffness(k1, 0.5)
    scale = k1 * D_MAX**1.5
    assert np.max(np.abs(f - ref)) / scale < 0.01
    # classify against the three analytic branches
    dpn = 0.5 * dmax_ref**1.5
    k_adh = np.array([an.eepa_adhesion(k2, dm, 0.5, 1.5, 1.5, an.eepa_min_force(R_E, 5.0))[0] for dm in dmax_ref])
    load, unload, adh = k1 * path**1.5, k2 * (path**1.5 - dpn), -k_adh * path**1.5
    on = lambda g: np.abs(f - g) < 1e-4 * scale  # noqa: E731
    assert np.sum(on(load) & (path >= dmax_ref * (1 - 1e-6))) > 400  # virgin (first load + beyond delta_max)
    assert np.sum(on(unload) & ~on(load) & ~on(adh)) > 200  # unloading and reloading line
    assert np.sum(on(adh) & ~on(unload)) > 50  # adhesive branch
    # reload retraces the unloading line up to delta_max, then continues on the virgin branch
    re = slice(599, None)
    below, beyond = path[re] < D_MAX * 0.999, path[re] > D_MAX * 1.001
    assert np.all(on(unload)[re][below & (path[re] > 0.8 * D_MAX)])
    assert np.all(on(load)[re][beyond])


@pytest.mark.parametrize("lambda_p", [0.2, 0.5, 0.8])
def test_eepa_residual_plastic_overlap(lambda_p):
    """Residual plastic overlap: without adhesion (gamma = 0, f0 = 0) the unloading branch from delta_max
    reaches zero force at delta_p = lambda_p^(1/n) delta_max (n = 1.5); found by extrapolating the last two
    driven points before the force rests at zero (grid 1e-3 delta_max, error O(h^2)), within 0.1 %."""
    path = np.concatenate([np.linspace(0.0, D_MAX, 200)[1:], np.linspace(D_MAX, 1e-3 * D_MAX, 1000)])
    f, _, _, _ = _eepa(path, lambda_p=lambda_p, gamma=0.0)
    un_d, un_f = path[199:], f[199:]
    i = np.argmax(un_f <= 0.0)
    assert un_f[i - 1] > 0.0 and un_f[i] == 0.0
    dp = un_d[i - 1] + (un_d[i - 1] - un_d[i - 2]) * un_f[i - 1] / (un_f[i - 2] - un_f[i - 1])
    assert dp == pytest.approx(an.eepa_plastic_overlap(D_MAX, lambda_p, 1.5), rel=1e-3)
    assert dp == pytest.approx(lambda_p ** (1 / 1.5) * D_MAX, rel=1e-3)
    assert np.all(un_f[i:] == 0.0)  # f0 = 0, no adhesion: the force rests at f0 below delta_p


@pytest.mark.parametrize("n,chi,gamma", [(1.5, 1.5, 5.0), (1.0, 1.0, 5.0), (1.5, 1.5, 1e3)])
def test_eepa_dissipated_energy_is_loop_area(n, chi, gamma):
    """Energy dissipated by load to delta_max / unload / adhesion to separation: the trapezoid integral of
    the driven loop (-closed integral of F d delta) equals the closed-form loop area within 2 % (non-linear and
    linear EEPA; the last case has the adhesion depth capped at k2 delta_p^n / 2)."""
    m = 4000
    path = np.concatenate([np.linspace(0.0, D_MAX, m), np.linspace(D_MAX, 0.0, m)[1:]])
    f, _, _, _ = _eepa(path, n=n, chi=chi, gamma=gamma)
    f[-1] = f[-2]  # the contact ends at delta = 0; close the loop with the adhesive branch's limit f0
    w = _trapz(f[:m], path[:m]) + _trapz(f[m - 1 :], path[m - 1 :])
    ref = an.eepa_loop_energy(D_MAX, E_E, R_E, n, 0.5, chi, gamma)
    assert ref > 0.0
    assert w == pytest.approx(ref, rel=0.02)
    k1 = an.eepa_loading_stiffness(E_E, R_E, n)
    k2 = an.eepa_unloading_stiffness(k1, 0.5)
    _, _, f_eff = an.eepa_adhesion(k2, D_MAX, 0.5, n, n, an.eepa_min_force(R_E, gamma))
    assert f.min() == pytest.approx(f_eff, rel=0.01)  # the loop bottoms out at f0 + f_eff


def test_eepa_pull_off_force_shifts_loop():
    """The constant pull-off force f0 shifts the whole loop by f0 while in contact (delta > 0) and leaves its
    area unchanged; at delta -> 0+ the force tends to f0; the contact ends (F = 0, history reset) at delta <= 0."""
    path = np.concatenate(
        [np.linspace(0.0, D_MAX, 300)[1:], np.linspace(D_MAX, 0.0, 300)[1:-1], [1e-4 * D_MAX, 0.0, -1e-7]]
    )
    f0 = -0.01
    fa, _, _, _ = _eepa(path, f0=0.0)
    fb, dmax_b, _, _ = _eepa(path, f0=f0)
    inside = path > 0.0
    assert np.allclose(fb[inside] - fa[inside], f0, rtol=0, atol=1e-6 * abs(f0) + 1e-7 * np.abs(fa).max())
    assert fb[inside][-1] == pytest.approx(f0, abs=1e-3 * abs(f0))
    assert np.all(fb[~inside] == 0.0) and np.all(dmax_b[~inside] == 0.0)


def test_eepa_friction_load_and_stiffness():
    """Coulomb load (seed eq. 16) |F_hys + k_adh delta^chi - f0|: k1 delta^n + k_adh delta^chi on virgin loading,
    0 on the adhesive branch; k_damp = n k1 delta^(n-1) = 2 E* sqrt(R* delta) (HM's S_n) for n = 1.5."""
    path = np.concatenate([np.linspace(0.0, D_MAX, 300)[1:], np.linspace(D_MAX, 0.02 * D_MAX, 300)])
    f0 = -0.002
    f, dmax, kd, load = _eepa(path, f0=f0)
    k1 = an.eepa_loading_stiffness(E_E, R_E, 1.5)
    k2 = an.eepa_unloading_stiffness(k1, 0.5)
    k_adh = an.eepa_adhesion(k2, D_MAX, 0.5, 1.5, 1.5, an.eepa_min_force(R_E, 5.0))[0]
    first = slice(0, 299)
    k_adh_first = np.array(
        [an.eepa_adhesion(k2, d, 0.5, 1.5, 1.5, an.eepa_min_force(R_E, 5.0))[0] for d in path[first]]
    )
    assert np.allclose(
        load[first], k1 * path[first] ** 1.5 + k_adh_first * path[first] ** 1.5, rtol=1e-4, atol=1e-6 * k1 * D_MAX**1.5
    )
    on_adh = np.abs(f - (f0 - k_adh * path**1.5)) < 1e-6 * k1 * D_MAX**1.5
    on_adh[first] = False
    assert on_adh.sum() > 20
    assert np.all(load[on_adh] < 1e-4 * k1 * D_MAX**1.5)
    assert np.allclose(kd, 2.0 * E_E * np.sqrt(R_E * path), rtol=1e-5)


def test_eepa_damping_and_tangential_stiffness():
    """Damping: n = 1 gives seed eq. 8, sqrt(4 m* k / (1 + (pi/ln e)^2)); n = 1.5 gives HM's Tsuji coefficient
    2 sqrt(5/6) |beta| sqrt(m* S_n). Tangential stiffness (seed eq. 12): k_sf k1 (n = 1), k_sf 8 G* sqrt(R* delta)."""
    e, m = 0.4, 2e-3
    beta = math.log(e) / math.sqrt(math.log(e) ** 2 + math.pi**2)
    k = np.array([1e4, 1e6], np.float32)
    d = np.array([1e-6, 1e-5], np.float32)
    g_star, ks = 3e7, 0.7
    for n in (1.0, 1.5):
        c = wp.zeros(2, dtype=float, device="cpu")
        kt = wp.zeros(2, dtype=float, device="cpu")
        wp.launch(
            _eepa_aux_kernel,
            dim=2,
            inputs=[
                wp.array(k, dtype=float, device="cpu"),
                wp.array(d, dtype=float, device="cpu"),
                m,
                beta,
                n,
                R_E,
                E_E,
                g_star,
                ks,
            ],
            outputs=[c, kt],
            device="cpu",
        )
        if n == 1.0:
            c_ref = np.sqrt(4.0 * m * k / (1.0 + (math.pi / math.log(e)) ** 2))
            kt_ref = ks * 2.0 * E_E * R_E * np.ones(2)
        else:
            c_ref = 2.0 * math.sqrt(5.0 / 6.0) * abs(beta) * np.sqrt(m * k)
            kt_ref = ks * 8.0 * g_star * np.sqrt(R_E * d)
        assert np.allclose(c.numpy(), c_ref, rtol=1e-5)
        assert np.allclose(kt.numpy(), kt_ref, rtol=1e-5)
