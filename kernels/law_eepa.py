"""Edinburgh Elasto-Plastic Adhesion (EEPA): Morrissey (2013, PhD, Edinburgh); Thakur et al. (2014),
Granular Matter 16:383-400, eq. 1; EDEM's built-in "Edinburgh Elasto-Plastic Adhesion"; PFC ``eepa``.

Hysteretic normal force (delta > 0, positive = repulsive), history delta_max (largest overlap so far):

    F_hys = f0 + k1 delta^n                    if k2 (delta^n - delta_p^n) >= k1 delta^n        virgin loading
          = f0 + k2 (delta^n - delta_p^n)      if k1 delta^n > k2 (...) > -k_adh delta^chi       unloading/reloading
          = f0 - k_adh delta^chi               if -k_adh delta^chi >= k2 (delta^n - delta_p^n)  adhesive branch
          = f0 + min(k1 delta^n, max(k2 (delta^n - delta_p^n), -k_adh delta^chi))         (same thing)

  k1 = (4/3) E* sqrt(R*) for n != 1 (Hertz; dimensionally exact only for n = 1.5), k1 = 2 E* R* for n = 1
       (seed 002 eq. 3, LIGGGHTS ``model edinburgh``);
  k2 = k1 / (1 - lambda_p), lambda_p = 1 - k1/k2 the contact plasticity ratio in [0, 1);
  delta_p^n = (1 - k1/k2) delta_max^n, i.e. delta_p = lambda_p^(1/n) delta_max: the loading and unloading
       branches meet at delta_max, and the unloading branch crosses f0 at delta_p (Exudyn, LIGGGHTS);
  f_min = -1.5 pi gamma R* (gamma = surface energy, JKR force at EDEM's a_c) is the depth of the adhesive
       branch below f0; the adhesive branch passes through the point where the unloading line reaches it:
       delta_min^n = delta_p^n + f_eff/k2, k_adh = -f_eff / delta_min^chi, with f_eff = max(f_min, -k2 delta_p^n/2)
       (the cap keeps delta_min > 0: a lightly loaded contact has little adhesion; LIGGGHTS does the same).
       So k_adh follows from the history and the loop always bottoms out at f0 + f_eff.

Reloading from the unloading branch climbs the same line back to delta_max and continues on the virgin
branch; reloading from the adhesive branch climbs it back to delta_min, then the unloading line. delta_p is
a function of delta_max only (LIGGGHTS instead moves delta_p down while on the adhesive branch).

End of contact: the contact exists while delta > 0 (PFC: active iff gap <= 0; LIGGGHTS clears the history
on separation). At delta -> 0+ the force is f0 (adhesive branch -> f0), so with f0 < 0 the force jumps
between f0 and 0 when the contact forms or ends; the history delta_max is reset to 0 (a new contact is
virgin). No neighbour-search margin is needed beyond contact.

Damping (``eepa_damping_coefficient``): seed eq. 8 / Thakur: beta_n = sqrt(4 m* k / (1 + (pi/ln e)^2))
= -2 beta sqrt(m* k) with beta = ln e / sqrt(ln^2 e + pi^2); it is the linear spring-dashpot rule, exact for
n = 1 with k = k1. For n != 1 we take k = the loading-branch tangent stiffness n k1 delta^(n-1) (= 2 E* sqrt(R*
delta) = HM's S_n for n = 1.5) and HM's Tsuji factor sqrt(5/6), so the elastic limit (lambda_p -> 0, no
adhesion) reproduces EDEM's Hertz-Mindlin damping. ``eepa_normal_force`` returns that k as ``k_damp``.

Tangential (seed eq. 11-16): k_t = k_sf * k1 for n = 1, k_sf * 8 G* sqrt(R* delta) otherwise
(``eepa_tangential_stiffness``; k_sf is EDEM's "tangential stiff multiplier", PFC ``ks_fac``), dashpot as the
normal one with k_t, and the Coulomb limit |F_t| <= mu |F_hys + k_adh delta^chi - f0| (eq. 16: the normal
load is measured from the adhesive branch, so it is zero on that branch).
"""

import warp as wp

from .features import MODULE_OPTIONS

wp.set_module_options(MODULE_OPTIONS)

PI = wp.constant(3.141592653589793)
SQRT_5_6 = wp.constant(0.9128709291752769)


@wp.func
def eepa_loading_stiffness(e_star: float, r_star: float, n: float):
    """k1 [N/m^n]: 2 E* R* for n = 1, (4/3) E* sqrt(R*) otherwise."""
    if n == 1.0:
        return 2.0 * e_star * r_star
    return (4.0 / 3.0) * e_star * wp.sqrt(r_star)


@wp.func
def eepa_min_force(r_star: float, gamma: float):
    """f_min = -1.5 pi gamma R* [N] (<= 0): depth of the adhesive branch below f0."""
    return -1.5 * PI * gamma * r_star


@wp.func
def eepa_adhesion_stiffness(k2: float, overlap_max: float, lambda_p: float, n: float, chi: float, f_min: float):
    """k_adh [N/m^chi] of the adhesive branch after loading to delta_max (0 if there is no adhesion).

    f_eff = max(f_min, -k2 delta_p^n / 2), delta_min^n = delta_p^n + f_eff / k2, k_adh = -f_eff / delta_min^chi.
    """
    dpn = lambda_p * wp.pow(wp.max(overlap_max, 0.0), n)
    f_eff = wp.max(f_min, -0.5 * k2 * dpn)
    if f_eff >= 0.0:
        return 0.0
    d_min = wp.pow(dpn + f_eff / k2, 1.0 / n)
    return -f_eff / wp.pow(d_min, chi)


@wp.func
def eepa_friction_load(f_hys: float, overlap: float, k_adh: float, chi: float, f0: float):
    """Normal load for the Coulomb and rolling limits [N]: |F_hys + k_adh delta^chi - f0| (seed eq. 16)."""
    return wp.abs(f_hys + k_adh * wp.pow(wp.max(overlap, 0.0), chi) - f0)


@wp.func
def eepa_normal_force(
    overlap: float,
    overlap_max: float,
    r_star: float,
    e_star: float,
    f0: float,
    n: float,
    lambda_p: float,
    chi: float,
    gamma: float,
):
    """EEPA hysteretic normal force of one contact.

    Args:
        overlap: delta [m] (the contact ends at delta <= 0).
        overlap_max: history delta_max [m] from the last step (0 for a new contact).
        r_star, e_star: effective radius [m] and Young's modulus [Pa].
        f0: constant pull-off force [N] (usually <= 0).
        n: loading/unloading exponent (1.5 non-linear, 1 linear).
        lambda_p: contact plasticity ratio in [0, 1).
        chi: adhesive branch exponent.
        gamma: surface energy [J/m^2] (f_min = -1.5 pi gamma R*).

    Returns:
        (F_hys [N] positive = repulsive, delta_max to store [m] (0 once the contact ended),
        k_damp [N/m] stiffness for the normal dashpot (``eepa_damping_coefficient``),
        normal load for the Coulomb / rolling limits [N] (seed eq. 16)).
    """
    if overlap <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    d_max = wp.max(overlap_max, overlap)
    k1 = eepa_loading_stiffness(e_star, r_star, n)
    k2 = k1 / (1.0 - lambda_p)
    k_adh = eepa_adhesion_stiffness(k2, d_max, lambda_p, n, chi, eepa_min_force(r_star, gamma))
    dn = wp.pow(overlap, n)
    f_load = k1 * dn
    f_unload = k2 * (dn - lambda_p * wp.pow(d_max, n))
    f_adh = -k_adh * wp.pow(overlap, chi)
    f_hys = f0 + wp.min(f_load, wp.max(f_unload, f_adh))
    k_damp = n * k1 * wp.pow(overlap, n - 1.0)
    return f_hys, d_max, k_damp, eepa_friction_load(f_hys, overlap, k_adh, chi, f0)


@wp.func
def eepa_damping_coefficient(k_damp: float, m_star: float, beta: float, n: float):
    """Dashpot coefficient [N s/m] (>= 0) from k_damp [N/m] and beta = ln e / sqrt(ln^2 e + pi^2) (<= 0).

    n = 1: sqrt(4 m* k / (1 + (pi/ln e)^2)) = -2 beta sqrt(m* k) (seed eq. 8 / 15, exact for a linear spring);
    otherwise HM's Tsuji form -2 sqrt(5/6) beta sqrt(m* k).
    """
    c = -2.0 * beta * wp.sqrt(m_star * k_damp)
    if n == 1.0:
        return c
    return SQRT_5_6 * c


@wp.func
def eepa_tangential_stiffness(overlap: float, r_star: float, e_star: float, g_star: float, n: float, ks_fac: float):
    """k_t [N/m] (seed eq. 12): ks_fac * k1 for n = 1, ks_fac * 8 G* sqrt(R* delta) otherwise."""
    if n == 1.0:
        return ks_fac * eepa_loading_stiffness(e_star, r_star, n)
    return ks_fac * 8.0 * g_star * wp.sqrt(r_star * wp.max(overlap, 0.0))
