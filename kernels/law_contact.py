"""The per-pair choice of contact law: one dispatch function used for every contact kind.

The law of a material pair (``PairParams.law``) picks the normal law; the tangential spring
(Mindlin, Coulomb-capped) and the rolling resistance are shared. Each law decides when its contact
exists (cohesive laws keep a contact alive into negative overlap) and what it keeps in the per-contact
scalar history ``ContactHistory.aux``.

Adding a law: its file ``law_*.py`` of pure ``@wp.func``s, a ``ContactLaw`` member (kernels/enums.py), its
branch in :func:`contact_force`, and its fields in ``PairParams`` (kernels/params.py), with any further
history in ``ContactHistory``.
"""

import warp as wp

from .enums import ContactLaw
from .law_eepa import eepa_damping_coefficient, eepa_normal_force, eepa_tangential_stiffness
from .law_hertz_mindlin import SQRT_5_6, hertz_mindlin, mindlin_tangential, stable_rate
from .law_jkr import jkr_contact_radius, jkr_force_of_radius, jkr_friction_load, jkr_in_contact, jkr_stiffness
from .params import ContactHistory, PairParams


@wp.func
def contact_force(
    overlap: float,
    n: wp.vec3,
    v_rel: wp.vec3,
    history: ContactHistory,
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
        history: the contact's history from the last step (zero for a new contact).
        r_star, m_star: effective radius [m] and mass [kg].

    Returns:
        (active (1 while the contact exists, else 0), force on a [N], normal load for the rolling limit [N],
        tangential force on a [N], history with the spring and aux updated (the rolling spring as given;
        all zero once the contact ended), normal stiffness for the rolling spring [N/m], squared stable-step
        frequency [1/s^2] (``stable_rate`` of the law's current tangent stiffnesses; 0 once the contact ended)).
    """
    v_n = wp.dot(v_rel, n)
    if p.law == ContactLaw.JKR:
        # aux: 1 while the pair is in contact (it persists into a gap down to the break overlap)
        if jkr_in_contact(overlap, int(history.aux > 0.5), r_star, p.e_star, p.gamma) == 0:
            return int(0), wp.vec3(0.0), 0.0, wp.vec3(0.0), ContactHistory(), 0.0, 0.0
        a = jkr_contact_radius(overlap, r_star, p.e_star, p.gamma)
        s_n, s_t = jkr_stiffness(a, p.e_star, p.g_star)
        damp = -2.0 * SQRT_5_6 * p.beta
        c_n = damp * wp.sqrt(s_n * m_star)
        c_t = damp * wp.sqrt(s_t * m_star)
        f_n = jkr_force_of_radius(a, r_star, p.e_star, p.gamma) + c_n * v_n
        load = jkr_friction_load(f_n, r_star, p.gamma)
        f_t, xi = mindlin_tangential(history.spring, n, v_rel - v_n * n, s_t, c_t, p.mu_s * load, dt)
        # the rolling spring uses the Hertz secant stiffness of the same contact radius (2/3 S_n); 2 E* a bounds
        # the JKR tangent stiffness on its stable branch (beyond pull-off it is negative: a snap, not a vibration)
        return (
            int(1),
            -f_n * n + f_t,
            load,
            f_t,
            ContactHistory(xi, history.roll, 1.0),
            (2.0 / 3.0) * s_n,
            stable_rate(s_n, s_t, m_star, p),
        )
    if overlap <= 0.0:
        return int(0), wp.vec3(0.0), 0.0, wp.vec3(0.0), ContactHistory(), 0.0, 0.0
    if p.law == ContactLaw.EEPA:
        # aux: the largest overlap of this contact (its plastic overlap follows from it)
        f_hys, d_max, k_damp, load = eepa_normal_force(
            overlap, history.aux, r_star, p.e_star, p.f0, p.eepa_n, p.lambda_p, p.chi, p.gamma
        )
        c_n = eepa_damping_coefficient(k_damp, m_star, p.beta, p.eepa_n)
        f_n = f_hys + c_n * v_n
        k_t = eepa_tangential_stiffness(overlap, r_star, p.e_star, p.g_star, p.eepa_n, p.ks_fac)
        c_t = eepa_damping_coefficient(k_t, m_star, p.beta, p.eepa_n)
        f_t, xi = mindlin_tangential(history.spring, n, v_rel - v_n * n, k_t, c_t, p.mu_s * load, dt)
        # off the virgin branch the contact unloads or reloads along k2 = k1 / (1 - lambda_p); its dashpot, from
        # k1, damps k2 less than the pair's factor assumes, so the rate errs on the stiff side
        k_n = wp.where(overlap < d_max, k_damp / (1.0 - p.lambda_p), k_damp)
        return (
            int(1),
            -f_n * n + f_t,
            load,
            f_t,
            ContactHistory(xi, history.roll, d_max),
            k_damp / p.eepa_n,
            stable_rate(k_n, k_t, m_star, p),
        )
    f_a, f_n, f_t, xi, k_n, k_s = hertz_mindlin(overlap, n, v_rel, history.spring, r_star, m_star, p, dt)
    return int(1), f_a, f_n, f_t, ContactHistory(xi, history.roll, history.aux), k_n, k_s


@wp.func
def contact_force_hertz_mindlin(
    overlap: float,
    n: wp.vec3,
    v_rel: wp.vec3,
    history: ContactHistory,
    r_star: float,
    m_star: float,
    p: PairParams,
    dt: float,
):
    """:func:`contact_force` for a model whose every pair is Hertz-Mindlin (the kernels pick it at compile time,
    see kernels/features.py): the same results without the cohesive laws' branches."""
    if overlap <= 0.0:
        return int(0), wp.vec3(0.0), 0.0, wp.vec3(0.0), ContactHistory(), 0.0, 0.0
    f_a, f_n, f_t, xi, k_n, k_s = hertz_mindlin(overlap, n, v_rel, history.spring, r_star, m_star, p, dt)
    return int(1), f_a, f_n, f_t, ContactHistory(xi, history.roll, history.aux), k_n, k_s


def contact_force_for(cohesive_laws: bool):
    """The contact dispatch a kernel compiled for ``cohesive_laws`` calls (through ``wp.static``)."""
    return contact_force if cohesive_laws else contact_force_hertz_mindlin
