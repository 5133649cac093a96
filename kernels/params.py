"""The structs of the contact laws: per-pair parameters (derived on the host from the materials and the
interaction table) and per-contact history (carried from step to step and across list rebuilds), with the
functions that load and store a history slot in any of its layouts and those that read a sphere's live-slot
mask."""

import warp as wp


@wp.struct
class PairParams:
    """Contact parameters of one material pair in one world (all SI)."""

    e_star: float
    """Effective Young's modulus E* = 1 / ((1 - nu_a^2)/E_a + (1 - nu_b^2)/E_b) [Pa]."""
    g_star: float
    """Effective shear modulus G* = 1 / ((2 - nu_a)/G_a + (2 - nu_b)/G_b) [Pa]."""
    beta: float
    """Damping factor ln(e) / sqrt(ln(e)^2 + pi^2) (<= 0) [-]."""
    mu_s: float
    """Static (Coulomb) friction coefficient [-]."""
    mu_r: float
    """Rolling friction coefficient [-] (dimensionless, torque = mu_r * R* * F_n)."""
    rolling_model: int
    """A ``RollingModel`` (kernels/enums.py)."""
    rolling_damping: float
    """EPSD viscous damping ratio eta_r [-] (Ai et al. 2011 use 0.3)."""
    law: int
    """A ``ContactLaw`` (kernels/enums.py): the pair's normal law."""
    gamma: float
    """Surface energy gamma [J/m^2] (JKR, and EEPA's f_min = -1.5 pi gamma R*); work of adhesion W = 2 gamma."""
    f0: float
    """EEPA constant pull-off force [N] (<= 0)."""
    eepa_n: float
    """EEPA loading/unloading exponent n [-] (1.5: Hertz-like, 1: linear)."""
    lambda_p: float
    """EEPA contact plasticity ratio [-] in [0, 1)."""
    chi: float
    """EEPA adhesive branch exponent [-]."""
    ks_fac: float
    """EEPA tangential stiffness multiplier [-]."""
    stable_n: float
    """Squared stable-step frequency per unit normal stiffness and inverse mass [-], dashpot included
    (``law_hertz_mindlin.stable_factors``)."""
    stable_t: float
    """The same for the tangential stiffness, on the tangential mode's mass [-]."""


@wp.struct
class ContactHistory:
    """What one contact remembers from the last step, seen from the pair's body a (the lower index of two
    spheres, the sphere against a wall). A zero struct is a new contact; a contact that ends is zeroed.

    A law that needs more history adds its field here, and says in ``StepFeatures.history_type``
    (kernels/features.py) when a model needs it: that property picks what a list slot stores (this struct, or
    the part of it the model's laws use). Kernels read and write slots through :func:`history_load` and
    :func:`history_store`, which take any of those layouts.
    """

    spring: wp.vec3
    """Tangential spring displacement xi [m] (Mindlin), kept in the current tangent plane."""
    roll: wp.vec3
    """Rolling spring torque [N m] (EPSD; zero for the other rolling models)."""
    aux: float
    """The normal law's scalar history: JKR 1 while in contact (also in a gap down to the break overlap);
    EEPA the largest overlap of the contact [m]; Hertz-Mindlin leaves it 0."""


@wp.func
def history_load(slots: wp.array2d[ContactHistory], k: int, i: int):
    """Slot (k, i) of a whole-struct history array."""
    return slots[k, i]


@wp.func
def history_load(slots: wp.array2d[wp.vec3], k: int, i: int):  # noqa: F811 (a Warp overload)
    """Slot (k, i) of a spring-only history array: the rolling spring and ``aux`` read as zero."""
    return ContactHistory(slots[k, i], wp.vec3(0.0), 0.0)


@wp.func
def history_load(slots: wp.array2d[wp.vec4], k: int, i: int):  # noqa: F811
    """Slot (k, i) of a spring-and-scalar history array (x, y, z: the spring; w: ``aux``): the rolling spring
    reads as zero."""
    s = slots[k, i]
    return ContactHistory(wp.vec3(s[0], s[1], s[2]), wp.vec3(0.0), s[3])


@wp.func
def history_store(slots: wp.array2d[ContactHistory], k: int, i: int, h: ContactHistory):
    """Write ``h`` to slot (k, i) of a whole-struct history array."""
    slots[k, i] = h


@wp.func
def history_store(slots: wp.array2d[wp.vec3], k: int, i: int, h: ContactHistory):  # noqa: F811
    """Write ``h``'s spring to slot (k, i) of a spring-only history array (a model of that layout keeps its
    rolling spring and ``aux`` at zero)."""
    slots[k, i] = h.spring


@wp.func
def history_store(slots: wp.array2d[wp.vec4], k: int, i: int, h: ContactHistory):  # noqa: F811
    """Write ``h``'s spring and ``aux`` to slot (k, i) of a spring-and-scalar history array (a model of that
    layout keeps its rolling spring at zero)."""
    slots[k, i] = wp.vec4(h.spring[0], h.spring[1], h.spring[2], h.aux)


LIVE_SLOTS = wp.constant(64)
"""Slots of a sphere's list that its live mask covers (one ``wp.uint64`` per sphere); later slots count as live."""


@wp.func
def slot_live(mask: wp.uint64, k: int):
    """Whether slot ``k`` may hold a nonzero history: its bit of ``mask``, or always past ``LIVE_SLOTS``.

    A slot whose contact was not active at the last step holds a zero history: the live mask lets the step skip
    reading and rewriting those zeros (most candidates of a settled bed, and every plane a sphere is far from).
    """
    return k >= LIVE_SLOTS or ((mask >> wp.uint64(k)) & wp.uint64(1)) != wp.uint64(0)


@wp.func
def slot_bit(k: int):
    """The bit of slot ``k`` in a live mask (none past ``LIVE_SLOTS``)."""
    if k >= LIVE_SLOTS:
        return wp.uint64(0)
    return wp.uint64(1) << wp.uint64(k)
