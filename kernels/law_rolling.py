"""Rolling resistance: type A (constant directional torque), type C (EPSD, Ai et al. 2011) and EDEM's standard model.

Types A and C act on the relative rolling velocity w_r = (w_a - w_b) minus its component along the normal
(twisting is not resisted) and use the rolling radius R*, so that the torques on a and b are equal
and opposite. EDEM's standard model (:func:`standard_rolling`) gives each body a torque of its own, from
its own angular velocity and the lever R_i from its centre of mass to the contact point (for a sphere on a
wall, its radius less half the overlap: type A's R* = R to first order).

Type A:  M = -mu_r R* F_n w_r/|w_r|.  At rest it flips sign every step (a known property).
Type C:  spring M_k += -k_r w_r dt, k_r = 2.25 k_n mu_r^2 R*^2 with k_n the secant normal stiffness,
         |M_k| <= mu_r R* F_n; dashpot M_d = -2 eta_r sqrt(I_r k_r) w_r while the spring is not at its
         limit, with 1/I_r = 1/(I_a + m_a r_a^2) + 1/(I_b + m_b r_b^2). Comes to rest.
"""

import warp as wp

from .enums import RollingModel


@wp.func
def standard_rolling(w: wp.vec3, f_n: float, lever: float, mu_r: float):
    """EDEM's standard rolling friction: the torque on one body [N m], -mu_r F_n R_i w/|w|.

    Args:
        w: the body's own angular velocity [rad/s] (a clump's sphere: the clump's).
        f_n: normal force [N] (only its positive part resists rolling).
        lever: R_i, the contact point's distance from the body's centre of mass [m].
        mu_r: rolling friction coefficient [-].
    """
    w_len = wp.length(w)
    if w_len > 0.0:
        return w * (-mu_r * lever * wp.max(f_n, 0.0) / w_len)
    return wp.vec3(0.0)


@wp.func
def rolling_resistance(
    model: int,
    w_rel: wp.vec3,
    n: wp.vec3,
    f_n: float,
    r_star: float,
    mu_r: float,
    k_n: float,
    i_roll: float,
    eta_r: float,
    spring: wp.vec3,
    dt: float,
):
    """Rolling resistance torque on body a.

    Args:
        model: a RollingModel (NONE, CONSTANT_TORQUE: type A, EPSD: type C; STANDARD: zero, see standard_rolling).
        w_rel: angular velocity of a minus that of b [rad/s].
        n: unit contact normal.
        f_n: normal force [N] (only its positive part resists rolling).
        r_star: rolling radius R* [m].
        mu_r: rolling friction coefficient [-].
        k_n: secant normal stiffness [N/m] (EPSD only).
        i_roll: equivalent rotational inertia about the contact point [kg m^2] (EPSD only).
        eta_r: EPSD dashpot ratio [-].
        spring: EPSD spring torque from the last step [N m].
        dt: time step [s].

    Returns:
        (torque on a [N m], updated spring torque [N m]).
    """
    if model == RollingModel.NONE or mu_r == 0.0:
        return wp.vec3(0.0), spring * 0.0
    w_r = w_rel - wp.dot(w_rel, n) * n
    m_max = mu_r * r_star * wp.max(f_n, 0.0)
    if model == RollingModel.CONSTANT_TORQUE:
        w_len = wp.length(w_r)
        if w_len > 0.0:
            return -m_max * (w_r / w_len), wp.vec3(0.0)
        return wp.vec3(0.0), wp.vec3(0.0)
    if model == RollingModel.EPSD:
        k_r = 2.25 * k_n * mu_r * mu_r * r_star * r_star
        m_len = wp.length(spring)
        m_k = spring - wp.dot(spring, n) * n
        m_proj = wp.length(m_k)
        if m_proj > 0.0:
            m_k = m_k * (m_len / m_proj)
        m_k = m_k - k_r * dt * w_r
        m_k_len = wp.length(m_k)
        if m_k_len > m_max:
            # full mobilisation: plastic rolling, the dashpot is off (Ai et al. 2011, f = 0)
            if m_k_len > 0.0:
                m_k = m_k * (m_max / m_k_len)
            return m_k, m_k
        m_d = -2.0 * eta_r * wp.sqrt(i_roll * k_r) * w_r
        return m_k + m_d, m_k
    return wp.vec3(0.0), wp.vec3(0.0)
