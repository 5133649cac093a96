"""The per-pair choice of contact law: one dispatch function used for every contact kind.

The law of a material pair (``PairParams.law``) picks the normal law; the tangential spring
(Mindlin, Coulomb-capped) and the rolling resistance are shared. Each law decides when its contact
exists (cohesive laws keep a contact alive into negative overlap) and what it keeps in the per-contact
scalar history ``aux``.
"""

import warp as wp

from .law_hertz_mindlin import hertz_mindlin
from .params import PairParams

LAW_HERTZ_MINDLIN = wp.constant(1)


@wp.func
def contact_force(
    overlap: float,
    n: wp.vec3,
    v_rel: wp.vec3,
    spring: wp.vec3,
    aux: float,
    r_star: float,
    m_star: float,
    p: PairParams,
    dt: float,
):
    """One contact seen from body a, for the pair's law.

    Args:
        overlap: r_a + r_b - distance [m] (negative: a gap).
        n: unit normal from a towards b.
        v_rel: velocity of a's contact point relative to b's [m/s].
        spring: tangential spring displacement from the last step [m].
        aux: the law's scalar history from the last step (0 for a new contact).
        r_star, m_star: effective radius [m] and mass [kg].

    Returns:
        (active (1 while the contact exists, else 0 and the caller clears the history), force on a [N],
        normal load for the rolling limit [N], tangential force on a [N], updated spring [m],
        updated aux, normal stiffness for the rolling spring [N/m]).
    """
    if overlap <= 0.0:
        return int(0), wp.vec3(0.0), 0.0, wp.vec3(0.0), wp.vec3(0.0), 0.0, 0.0
    f_a, f_n, f_t, xi, k_n = hertz_mindlin(overlap, n, v_rel, spring, r_star, m_star, p, dt)
    return int(1), f_a, f_n, f_t, xi, aux, k_n
