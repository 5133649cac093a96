"""Hertz-Mindlin with JKR cohesion, as EDEM defines it (help page "Hertz-Mindlin with JKR").

Normal (elastic) force from the contact radius a, gamma = surface energy [J/m^2]:

    delta = a^2/R* - sqrt(4 pi gamma a / E*)
    F_JKR = 4 E* a^3 / (3 R*) - 4 sqrt(pi gamma E*) a^(3/2)          (positive = repulsive)

Convention for gamma: it is the *surface energy* of EDEM's GUI ("Surface Energy", J/m^2) entered as is;
the work of adhesion of the pair is W = 2 gamma (JKR 1971 write F with W: 4E*a^3/(3R) - sqrt(8 pi W E* a^3),
the same curve). Peak attraction F_min = -3 pi gamma R* (= -1.5 pi W R*, classical JKR pull-off) at a
negative overlap; F(delta = 0) = -(8/3) pi gamma R*; EDEM's quoted "pull-out force" 1.5 pi gamma R* is the
force at its radius a_c (see warpdem/engine/analytic.py for all of these in closed form).

Hysteresis (the caller keeps a per-contact "in contact" flag, see ``jkr_in_contact``): on approach the
contact forms at delta = 0 (the force jumps from 0 to -(8/3) pi gamma R*); on separation it persists into
negative overlap (a gap) until delta < delta_c = jkr_break_overlap(...) < 0, EDEM's break overlap
delta(a_c). So the neighbour search must report pairs up to a gap of |delta_c| (skin >= |delta_c|), or
contacts are cut early. The contact then follows the stable branch (a >= a*, d delta/da > 0) and carries
F = -1.833 pi gamma R* when it breaks (a_c itself lies on the unstable branch, just below a*).

Stiffness for damping and the tangential spring: HM's S_n = 2 E* a, S_t = 8 G* a with a the JKR contact
radius (``jkr_stiffness``). EDEM says HM+JKR uses the HM formulas for tangential elasticity and both
dissipation forces; HM's overlap form S = 2E* sqrt(R* delta) is undefined at negative overlap, and a is the
radius it stands for (Hertz: a = sqrt(R* delta), so gamma = 0 gives HM exactly). 8 G* a is Mindlin's
stiffness of a contact of radius a, as used with JKR by Thornton & Yin (1991). Damping is then HM's Tsuji
form c = -2 sqrt(5/6) beta sqrt(S m*).

Normal load for the Coulomb and rolling limits (``jkr_friction_load``): N = F + 3 pi gamma R*
= F_JKR + 2 * (EDEM's pull-out force 1.5 pi gamma R*). EDEM: friction "depends on the positive repulsive
part of the JKR normal force"; F + 3 pi gamma R* >= 0 on the whole curve (F_min = -3 pi gamma R*), is
zero exactly at peak attraction and reduces to F for gamma = 0. (Thornton & Yin 1991 use F + 2 P_c with
P_c = 3 pi gamma R*, i.e. twice this offset; we follow EDEM.)
"""

import warp as wp

from .features import MODULE_OPTIONS

wp.set_module_options(MODULE_OPTIONS)

JKR_NEWTON_STEPS = wp.constant(8)
"""Newton steps on t = sqrt(a/A); float32 relative error of a < 1e-6 for every delta >= delta_c (tested)."""
JKR_T_STAR = wp.constant(0.7937005259840998)
"""sqrt(a*/A) = 2^(-1/3): end of the stable branch (d delta / da = 0)."""
JKR_CBRT_2 = wp.constant(1.2599210498948732)
"""2^(1/3): sqrt(a/A) at zero overlap."""
JKR_D_CRIT = wp.constant(-1.1864293248596174)
"""delta_c R*/A^2 = s_c^2 - 2 sqrt(s_c), s_c^3 = (9/4)(3/2 - sqrt 2): EDEM's break overlap, dimensionless."""
PI = wp.constant(3.141592653589793)


@wp.func
def jkr_length_scale(r_star: float, e_star: float, gamma: float):
    """A = (pi gamma R*^2 / E*)^(1/3) [m]; a = s A, delta = (A^2/R*)(s^2 - 2 sqrt s)."""
    return wp.pow(PI * gamma / e_star, 1.0 / 3.0) * wp.pow(r_star, 2.0 / 3.0)


@wp.func
def jkr_contact_radius(overlap: float, r_star: float, e_star: float, gamma: float):
    """Contact radius a [m] on the stable branch for overlap delta [m] (valid for delta >= delta_c).

    Solves t^4 - 2 t = D (t = sqrt(a/A), D = delta R*/A^2) by Newton from t0 = max(D,0)^(1/4) + 2^(1/3),
    which is above the root: g = t^4 - 2t - D is convex and increasing there, so Newton descends
    monotonically onto the stable root (clamped at t* for safety). gamma = 0 gives Hertz a = sqrt(R* delta).
    """
    if gamma <= 0.0:
        return wp.sqrt(r_star * wp.max(overlap, 0.0))
    length = jkr_length_scale(r_star, e_star, gamma)
    d = overlap * r_star / (length * length)
    t = wp.pow(wp.max(d, 0.0), 0.25) + JKR_CBRT_2
    for _ in range(JKR_NEWTON_STEPS):
        t3 = t * t * t
        t = wp.max(t - (t3 * t - 2.0 * t - d) / (4.0 * t3 - 2.0), JKR_T_STAR)
    return t * t * length


@wp.func
def jkr_force_of_radius(a: float, r_star: float, e_star: float, gamma: float):
    """F = 4 E* a^3 / (3 R*) - 4 sqrt(pi gamma E*) a^(3/2) [N] (positive = repulsive)."""
    return (4.0 / 3.0) * e_star * a * a * a / r_star - 4.0 * wp.sqrt(PI * gamma * e_star) * a * wp.sqrt(a)


@wp.func
def jkr_break_overlap(r_star: float, e_star: float, gamma: float):
    """delta_c [m] (< 0, 0 for gamma = 0): EDEM's break overlap delta(a_c); the contact ends below it."""
    if gamma <= 0.0:
        return 0.0
    length = jkr_length_scale(r_star, e_star, gamma)
    return JKR_D_CRIT * length * length / r_star


@wp.func
def jkr_in_contact(overlap: float, was_in_contact: int, r_star: float, e_star: float, gamma: float):
    """1 if the pair is in JKR contact after this step, else 0 (the caller stores it per contact).

    Forms at delta >= 0; once formed, persists while delta >= delta_c (< 0).
    """
    if overlap >= 0.0:
        return 1
    if was_in_contact != 0 and overlap >= jkr_break_overlap(r_star, e_star, gamma):
        return 1
    return 0


@wp.func
def jkr_normal_force(overlap: float, r_star: float, e_star: float, gamma: float):
    """F_JKR(delta) [N] (positive = repulsive), 0 below delta_c.

    Call it only for pairs that are in contact (``jkr_in_contact``): for delta_c <= delta < 0 a pair that
    has not touched yet feels no force.
    """
    if overlap < jkr_break_overlap(r_star, e_star, gamma):
        return 0.0
    a = jkr_contact_radius(overlap, r_star, e_star, gamma)
    return jkr_force_of_radius(a, r_star, e_star, gamma)


@wp.func
def jkr_stiffness(a: float, e_star: float, g_star: float):
    """(S_n, S_t) = (2 E* a, 8 G* a) [N/m] from the JKR contact radius a: dashpots and tangential spring."""
    return 2.0 * e_star * a, 8.0 * g_star * a


@wp.func
def jkr_friction_load(f_n: float, r_star: float, gamma: float):
    """Normal load for the Coulomb and rolling limits [N]: max(F_n + 3 pi gamma R*, 0) (EDEM: F_JKR + 2 F_pullout)."""
    return wp.max(f_n + 3.0 * PI * gamma * r_star, 0.0)
