"""Hertz-Mindlin (no slip) as EDEM defines it, with Tsuji damping from the coefficient of restitution.

Normal:      F_n = 4/3 E* sqrt(R*) d^(3/2) + 2 sqrt(5/6) |beta| sqrt(S_n m*) v_n,   S_n = 2 E* sqrt(R* d)
Tangential:  F_t = -S_t xi - 2 sqrt(5/6) |beta| sqrt(S_t m*) v_t,                 S_t = 8 G* sqrt(R* d)
             |F_t| <= mu_s max(F_n, 0); on slip the spring xi is rescaled so the limit holds exactly.
beta = ln e / sqrt(ln^2 e + pi^2).

End of contact: the contact lasts while the overlap d > 0 and the damped normal force may turn
attractive near the end (viscous attraction). With that convention the realised restitution of a
binary collision equals the requested e for any impact speed (verification-ecosystem 1.2); cutting
the force at zero instead would raise e_out (0.1 -> 0.25).
"""

import math

import warp as wp

from .params import PairParams

SQRT_5_6 = wp.constant(0.9128709291752769)
TANGENTIAL_MASS_RATIO = wp.constant(3.5)
"""m* / m_t for a tangential spring between solid spheres: the contact point moves by v_t + w x r, so the
tangential mode's effective mass is m_t = 1 / (sum 1/m + r^2/I) = (2/7) m* with I = (2/5) m r^2."""


def stable_factors(damp: float) -> tuple[float, float]:
    """(A, B) [-] of a pair whose dashpots are c = damp sqrt(S m*) (Tsuji: damp = -2 sqrt(5/6) beta): a contact's
    squared stable-step frequency is max(A S_n, B S_t) / m* (:func:`stable_rate`). Host-side, for PairParams.

    Leapfrog with the dashpot on the half-step velocity is stable for S dt^2 / m + 2 c dt / m < 4 (Jury's test on
    the 2 x 2 step matrix): dt < 2 / w_eq with w_eq = (g + sqrt(g^2 + 4 w^2)) / 2, w^2 = S / m, g = c / m. With
    c = damp sqrt(S m*) the ratio z = g / (2 w) is a constant of the pair, so w_eq^2 = w^2 (z + sqrt(z^2 + 1))^2:
    z = damp / 2 for the normal mode (mass m*), z = sqrt(3.5) damp / 2 for the tangential one (mass 2/7 m*,
    ``TANGENTIAL_MASS_RATIO``). Tsuji's dashpot at e = 0.15 raises the normal w_eq 1.6 times, the tangential 2.2.
    """

    def lift(z: float) -> float:
        return (z + math.sqrt(z * z + 1.0)) ** 2

    ratio = float(TANGENTIAL_MASS_RATIO)
    return lift(0.5 * damp), ratio * lift(0.5 * damp * math.sqrt(ratio))


@wp.func
def stable_rate(s_n: float, s_t: float, m_star: float, p: PairParams):
    """A contact's squared stable-step frequency [1/s^2] from its normal and tangential tangent stiffnesses [N/m]:
    the normal mode or the tangential one, whichever limits leapfrog's step more, dashpots included (the pair's
    ``stable_n``, ``stable_t``: :func:`stable_factors`). The solver sums it over a sphere's contacts
    (kernels/step.py): a Gershgorin bound on the fastest mode the sphere takes part in."""
    return wp.max(p.stable_n * s_n, p.stable_t * s_t) / m_star


@wp.func
def mindlin_tangential(
    spring: wp.vec3,
    n: wp.vec3,
    v_t: wp.vec3,
    s_t: float,
    c_t: float,
    f_limit: float,
    dt: float,
):
    """Mindlin no-slip tangential spring-dashpot with a Coulomb cap, shared by every normal law.

    Args:
        spring: tangential spring displacement xi from the last step [m].
        n: unit normal; v_t: tangential relative velocity [m/s].
        s_t: tangential stiffness [N/m]; c_t: tangential damping coefficient [N s/m].
        f_limit: Coulomb limit mu_s * (normal load) [N], >= 0.

    Returns:
        (tangential force on a [N], updated spring [m]).
    """
    # keep the stored spring in the current tangent plane, preserving its length
    xi_len = wp.length(spring)
    xi = spring - wp.dot(spring, n) * n
    xi_proj = wp.length(xi)
    if xi_proj > 0.0:
        xi = xi * (xi_len / xi_proj)
    xi = xi + v_t * dt
    f_t = -s_t * xi - c_t * v_t
    f_t_len = wp.length(f_t)
    if f_t_len > f_limit:
        if f_t_len > 0.0:
            f_t = f_t * (f_limit / f_t_len)
        else:
            f_t = wp.vec3(0.0)
        if s_t > 0.0:
            xi = -(f_t + c_t * v_t) / s_t
    return f_t, xi


@wp.func
def hertz_mindlin(
    overlap: float,
    n: wp.vec3,
    v_rel: wp.vec3,
    spring: wp.vec3,
    r_star: float,
    m_star: float,
    p: PairParams,
    dt: float,
):
    """One Hertz-Mindlin contact, seen from body a.

    Args:
        overlap: d > 0 [m].
        n: unit normal from a towards b.
        v_rel: velocity of a's contact point relative to b's [m/s].
        spring: tangential spring displacement xi from the last step [m].
        r_star, m_star: effective radius [m] and mass [kg].
        p: pair parameters.
        dt: time step [s].

    Returns:
        (force on a [N], normal force F_n [N] (positive = repulsive), tangential force on a [N],
        updated spring [m], secant normal stiffness F_el/d [N/m], squared stable-step frequency [1/s^2]
        (:func:`stable_rate`)).
    """
    sqrt_rd = wp.sqrt(r_star * overlap)
    s_n = 2.0 * p.e_star * sqrt_rd
    s_t = 8.0 * p.g_star * sqrt_rd
    damp = -2.0 * SQRT_5_6 * p.beta
    c_n = damp * wp.sqrt(s_n * m_star)
    c_t = damp * wp.sqrt(s_t * m_star)

    v_n = wp.dot(v_rel, n)
    f_el = (4.0 / 3.0) * p.e_star * sqrt_rd * overlap
    f_n = f_el + c_n * v_n
    f_t, xi = mindlin_tangential(spring, n, v_rel - v_n * n, s_t, c_t, p.mu_s * wp.max(f_n, 0.0), dt)
    return -f_n * n + f_t, f_n, f_t, xi, f_el / overlap, stable_rate(s_n, s_t, m_star, p)
