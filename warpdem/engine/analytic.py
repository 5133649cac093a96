"""Closed-form references (float64) for the cohesive contact laws: JKR and EEPA.

Used by the unit tests of ``kernels/law_jkr.py`` and ``kernels/law_eepa.py`` and by ``warpdem verify``.
Everything here is plain Python / NumPy in float64; nothing launches a kernel.

JKR (EDEM "Hertz-Mindlin with JKR" form; gamma is the *surface energy*, work of adhesion W = 2 gamma):

    delta(a) = a^2/R* - sqrt(4 pi gamma a / E*)
    F(a)     = 4 E* a^3 / (3 R*) - 4 sqrt(pi gamma E*) a^(3/2)        (positive = repulsive)

With the length scale A = (pi gamma R*^2 / E*)^(1/3) and s = a / A both collapse onto one curve:
delta = (A^2/R*) (s^2 - 2 sqrt(s)),  F = pi gamma R* (4 s^3/3 - 4 s^(3/2)).  From that:

    a_0   = (9 pi gamma R*^2 / E*)^(1/3)      F = 0, delta_0 = (A^2/R*)(3^(4/3) - 2*3^(1/3)) > 0
    F(delta = 0)  = -(8/3) pi gamma R*        (s = 2^(2/3)): the jump on first contact
    F_min         = -3 pi gamma R*            (s = (9/4)^(1/3), at a negative overlap)
    a_c (EDEM)    = [9 pi gamma R*^2/(2 E*) (3/4 - 1/sqrt 2)]^(1/3),  F(a_c) = -1.5 pi gamma R* exactly
    delta_c       = delta(a_c) < 0: EDEM's break overlap (the "pull-out" gap)
    a*            = (pi gamma R*^2 / (4 E*))^(1/3): d delta/da = 0, end of the stable branch,
                    delta* = delta(a*) < delta_c, F(a*) = -(5/3) pi gamma R* (Johnson's fixed-grip pull-off)

a_c lies slightly *below* a* (s_c = 0.578 < s* = 0.630), i.e. on the unstable branch of the JKR curve,
so a displacement-driven contact never passes through a_c: it reaches delta_c on the stable branch at a
larger radius and breaks there with F = jkr_break_force() = -1.833 pi gamma R*, not -1.5 pi gamma R*.
"""

from __future__ import annotations

import math

import numpy as np

# ----------------------------------------------------------------------------------------------------
# JKR
# ----------------------------------------------------------------------------------------------------

S_ZERO_OVERLAP = 2.0 ** (2.0 / 3.0)
"""Dimensionless contact radius a/A at zero overlap (s^2 = 2 sqrt(s))."""
S_ZERO_FORCE = 3.0 ** (2.0 / 3.0)
"""Dimensionless contact radius a_0/A at zero force (s^(3/2) = 3)."""
S_MIN_FORCE = 2.25 ** (1.0 / 3.0)
"""Dimensionless contact radius at the force minimum -3 pi gamma R* (s^(3/2) = 3/2)."""
S_CRITICAL = (2.25 * (1.5 - math.sqrt(2.0))) ** (1.0 / 3.0)
"""EDEM's a_c / A: the smaller root of F(s) = -1.5 pi gamma R* (it lies on the unstable branch)."""
S_INSTABILITY = 2.0 ** (-2.0 / 3.0)
"""a*/A where d delta / da = 0 (s^(3/2) = 1/2): the end of the stable branch."""


def _d_of_s(s):
    return s * s - 2.0 * np.sqrt(s)


def jkr_length_scale(r_star: float, e_star: float, gamma: float) -> float:
    """A = (pi gamma R*^2 / E*)^(1/3) [m]: a = s A."""
    return (math.pi * gamma * r_star**2 / e_star) ** (1.0 / 3.0)


def jkr_overlap_scale(r_star: float, e_star: float, gamma: float) -> float:
    """A^2 / R* [m]: delta = (A^2/R*) (s^2 - 2 sqrt s)."""
    return jkr_length_scale(r_star, e_star, gamma) ** 2 / r_star


def jkr_force_scale(r_star: float, gamma: float) -> float:
    """pi gamma R* [N]: F = pi gamma R* (4 s^3/3 - 4 s^(3/2))."""
    return math.pi * gamma * r_star


def jkr_overlap(a, r_star: float, e_star: float, gamma: float):
    """Overlap delta(a) = a^2/R* - sqrt(4 pi gamma a / E*) [m] for contact radius a [m]."""
    a = np.asarray(a, dtype=float)
    return a * a / r_star - np.sqrt(4.0 * math.pi * gamma * a / e_star)


def jkr_force_of_radius(a, r_star: float, e_star: float, gamma: float):
    """Normal force F(a) = 4 E* a^3 / (3 R*) - 4 sqrt(pi gamma E*) a^(3/2) [N] (positive = repulsive)."""
    a = np.asarray(a, dtype=float)
    return 4.0 * e_star * a**3 / (3.0 * r_star) - 4.0 * math.sqrt(math.pi * gamma * e_star) * a**1.5


def _stable_s(d):
    """Largest root s >= s* of s^2 - 2 sqrt(s) = d (float64 Newton on t = sqrt s, from above)."""
    d = np.atleast_1d(np.asarray(d, dtype=float))
    t = np.maximum(d, 0.0) ** 0.25 + 2.0 ** (1.0 / 3.0)  # g(t0) >= 0: Newton decreases monotonically
    t_star = math.sqrt(S_INSTABILITY)
    for _ in range(60):
        g = t**4 - 2.0 * t - d
        t = np.maximum(t - g / (4.0 * t**3 - 2.0), t_star)
    return t * t


def jkr_contact_radius(overlap, r_star: float, e_star: float, gamma: float):
    """Contact radius a(delta) [m] on the stable branch (a >= a*); valid for delta >= delta* (float64)."""
    ov = np.asarray(overlap, dtype=float)
    if gamma <= 0.0:
        return np.sqrt(r_star * np.maximum(ov, 0.0))
    s = _stable_s(ov / jkr_overlap_scale(r_star, e_star, gamma))
    out = s * jkr_length_scale(r_star, e_star, gamma)
    return out.reshape(ov.shape) if ov.shape else float(out[0])


def jkr_force(overlap, r_star: float, e_star: float, gamma: float):
    """JKR force F(delta) [N] on the stable branch (no break applied; delta >= delta*)."""
    a = jkr_contact_radius(overlap, r_star, e_star, gamma)
    return jkr_force_of_radius(a, r_star, e_star, gamma)


def jkr_zero_force_radius(r_star: float, e_star: float, gamma: float) -> float:
    """a_0 = (9 pi gamma R*^2 / E*)^(1/3) [m]: contact radius at zero force (JKR's equilibrium radius)."""
    return (9.0 * math.pi * gamma * r_star**2 / e_star) ** (1.0 / 3.0)


def jkr_zero_force_overlap(r_star: float, e_star: float, gamma: float) -> float:
    """Overlap at zero force [m] (> 0)."""
    return float(jkr_overlap(jkr_zero_force_radius(r_star, e_star, gamma), r_star, e_star, gamma))


def jkr_force_at_zero_overlap(r_star: float, gamma: float) -> float:
    """F(delta = 0) = -(8/3) pi gamma R* [N]: the force right after first contact."""
    return -8.0 / 3.0 * math.pi * gamma * r_star


def jkr_min_force(r_star: float, gamma: float) -> float:
    """Peak attraction F_min = -3 pi gamma R* = -1.5 pi W R* [N] (classical JKR pull-off, load control)."""
    return -3.0 * math.pi * gamma * r_star


def jkr_min_force_overlap(r_star: float, e_star: float, gamma: float) -> float:
    """Overlap at which F = F_min [m] (< 0)."""
    return jkr_overlap_scale(r_star, e_star, gamma) * float(_d_of_s(S_MIN_FORCE))


def jkr_critical_radius(r_star: float, e_star: float, gamma: float) -> float:
    """EDEM's a_c = [9 pi gamma R*^2 / (2 E*) (3/4 - 1/sqrt 2)]^(1/3) [m]."""
    return (4.5 * math.pi * gamma * r_star**2 / e_star * (0.75 - 1.0 / math.sqrt(2.0))) ** (1.0 / 3.0)


def jkr_force_at_critical_radius(r_star: float, gamma: float) -> float:
    """F(a_c) = -1.5 pi gamma R* [N] exactly: EDEM's quoted "pull-out force" (its sign convention: attraction)."""
    return -1.5 * math.pi * gamma * r_star


def jkr_break_overlap(r_star: float, e_star: float, gamma: float) -> float:
    """EDEM's break overlap delta_c = delta(a_c) [m] (< 0): the contact ends when delta < delta_c."""
    if gamma <= 0.0:
        return 0.0
    return float(jkr_overlap(jkr_critical_radius(r_star, e_star, gamma), r_star, e_star, gamma))


def jkr_instability_overlap(r_star: float, e_star: float, gamma: float) -> float:
    """delta* = delta(a*) [m]: the lowest overlap of the stable branch (just below delta_c)."""
    return jkr_overlap_scale(r_star, e_star, gamma) * float(_d_of_s(S_INSTABILITY))


def jkr_break_force(r_star: float, e_star: float, gamma: float) -> float:
    """Force on the stable branch at delta_c [N]: what a displacement-driven contact carries as it breaks."""
    return float(jkr_force(jkr_break_overlap(r_star, e_star, gamma), r_star, e_star, gamma))


def jkr_adhesion_work(r_star: float, e_star: float, gamma: float) -> float:
    """Energy lost by an elastic JKR contact in one approach / separation cycle [J].

    On approach the force is zero until delta = 0; on separation the contact follows the JKR curve
    down to delta_c. Loading and unloading for delta >= 0 are the same curve, so the loss is
    W = -int_{delta_c}^{0} F d delta.  In s: F d delta = pi gamma A^2 (8 s^4/3 - 28 s^(5/2)/3 + 4 s) ds,
    whose antiderivative is G(s) = 8 s^5/15 - 8 s^(7/2)/3 + 2 s^2; W = -pi gamma A^2 (G(s_0) - G(s_b)),
    s_0 = 2^(2/3) (delta = 0) and s_b the stable root at delta_c.
    """
    if gamma <= 0.0:
        return 0.0

    def g(s):
        return 8.0 * s**5 / 15.0 - 8.0 * s**3.5 / 3.0 + 2.0 * s * s

    d_c = float(_d_of_s(S_CRITICAL))
    s_b = float(_stable_s(d_c)[0])
    a = jkr_length_scale(r_star, e_star, gamma)
    return -math.pi * gamma * a * a * (g(S_ZERO_OVERLAP) - g(s_b))


def jkr_critical_speed(m: float, r_star: float, e_star: float, gamma: float, restitution: float) -> float:
    """Critical sticking speed [m/s] of a sphere (mass m) hitting a flat wall head-on, JKR + damping.

    Energy balance. Assumptions: (1) for delta >= 0 the JKR curve is conservative and the dashpot
    removes the same fraction (1 - e^2) of the impact energy as in a Hertz collision, so the sphere
    comes back to delta = 0 with e^2 m v^2 / 2; (2) damping in the short tensile tail (delta_c < delta < 0)
    is neglected; (3) the wall is rigid and immobile (m* = m; R* = R). The sphere escapes iff
    e^2 m v^2 / 2 > W with W = jkr_adhesion_work(), so

        v_crit = sqrt(2 W / m) / e.

    For e = 1 this is the elastic sticking speed; with W proportional to gamma^(5/3) R*^(4/3) E*^(-2/3)
    it scales as v ~ (F_c^5 / (E*^2 R* m^3))^(1/6), F_c = 3 pi gamma R* (the Thornton & Ning 1998 scaling).
    """
    w = jkr_adhesion_work(r_star, e_star, gamma)
    return math.sqrt(2.0 * w / m) / restitution


# ----------------------------------------------------------------------------------------------------
# EEPA
# ----------------------------------------------------------------------------------------------------


def eepa_loading_stiffness(e_star: float, r_star: float, n: float) -> float:
    """k1 [N/m^n]: 2 E* R* for n = 1, (4/3) E* sqrt(R*) otherwise (exact Hertz only for n = 1.5)."""
    return 2.0 * e_star * r_star if n == 1.0 else 4.0 / 3.0 * e_star * math.sqrt(r_star)


def eepa_unloading_stiffness(k1: float, lambda_p: float) -> float:
    """k2 = k1 / (1 - lambda_p) [N/m^n] (lambda_p = 1 - k1/k2)."""
    return k1 / (1.0 - lambda_p)


def eepa_min_force(r_star: float, gamma: float) -> float:
    """f_min = -1.5 pi gamma R* [N]: depth of the adhesive branch below f0 (JKR force at EDEM's a_c)."""
    return -1.5 * math.pi * gamma * r_star


def eepa_plastic_overlap(overlap_max: float, lambda_p: float, n: float) -> float:
    """delta_p = lambda_p^(1/n) delta_max [m]: where the unloading branch from delta_max meets f0."""
    return lambda_p ** (1.0 / n) * overlap_max


def eepa_adhesion(k2: float, overlap_max: float, lambda_p: float, n: float, chi: float, f_min: float):
    """(k_adh [N/m^chi], delta_min [m], f_eff [N]) of the adhesive branch after loading to delta_max.

    The unloading line f0 + k2 (delta^n - delta_p^n) reaches f0 + f_eff at delta_min^n = delta_p^n + f_eff/k2,
    with f_eff = max(f_min, -k2 delta_p^n / 2) (the cap keeps delta_min > 0); the adhesive branch
    f0 - k_adh delta^chi passes through that point: k_adh = -f_eff / delta_min^chi.
    """
    dpn = lambda_p * overlap_max**n
    f_eff = max(f_min, -0.5 * k2 * dpn)
    if f_eff >= 0.0:
        return 0.0, 0.0, 0.0
    d_min = (dpn + f_eff / k2) ** (1.0 / n)
    return -f_eff / d_min**chi, d_min, f_eff


def eepa_force(
    overlap,
    overlap_max: float,
    e_star: float,
    r_star: float,
    f0: float,
    n: float,
    lambda_p: float,
    chi: float,
    gamma: float,
):
    """EEPA hysteretic force [N] at overlap(s) delta > 0 for a *given* history delta_max (>= delta).

    F = f0 + min(k1 delta^n, max(k2 (delta^n - delta_p^n), -k_adh delta^chi)): the three branches of
    Thakur et al. (2014) eq. 1. Zero for delta <= 0 (contact over).
    """
    d = np.asarray(overlap, dtype=float)
    k1 = eepa_loading_stiffness(e_star, r_star, n)
    k2 = eepa_unloading_stiffness(k1, lambda_p)
    k_adh, _, _ = eepa_adhesion(k2, overlap_max, lambda_p, n, chi, eepa_min_force(r_star, gamma))
    dp = d.clip(min=0.0)
    f = f0 + np.minimum(k1 * dp**n, np.maximum(k2 * (dp**n - lambda_p * overlap_max**n), -k_adh * dp**chi))
    return np.where(d > 0.0, f, 0.0)


def eepa_loop_energy(
    overlap_max: float, e_star: float, r_star: float, n: float, lambda_p: float, chi: float, gamma: float
) -> float:
    """Energy dissipated [J] by one cycle: virgin load 0 -> delta_max, unload through adhesion to delta = 0.

    W_in  = k1 delta_max^(n+1)/(n+1)
    W_out = k2 [(delta_max^(n+1) - delta_min^(n+1))/(n+1) - delta_p^n (delta_max - delta_min)]
            - k_adh delta_min^(chi+1)/(chi+1)
    dissipated = W_in - W_out (f0 cancels: it shifts the whole loop).
    """
    k1 = eepa_loading_stiffness(e_star, r_star, n)
    k2 = eepa_unloading_stiffness(k1, lambda_p)
    k_adh, d_min, _ = eepa_adhesion(k2, overlap_max, lambda_p, n, chi, eepa_min_force(r_star, gamma))
    dpn = lambda_p * overlap_max**n
    if k_adh == 0.0:
        d_min = dpn ** (1.0 / n)  # the unloading line reaches f0 at delta_p; below it the force is f0
    w_in = k1 * overlap_max ** (n + 1.0) / (n + 1.0)
    w_out = k2 * ((overlap_max ** (n + 1.0) - d_min ** (n + 1.0)) / (n + 1.0) - dpn * (overlap_max - d_min))
    w_out -= k_adh * d_min ** (chi + 1.0) / (chi + 1.0)
    return w_in - w_out
