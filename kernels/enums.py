"""The enums of warpdem, defined once: the kernels compare against their members directly (Warp reads an
``IntEnum`` / ``IntFlag`` member in a kernel as an int constant) and ``warpdem.engine.types`` re-exports them.

No kernels here: importing this module compiles nothing.
"""

import enum


class ContactLaw(enum.IntEnum):
    """Normal contact law of a material pair (``PairParams.law``); law_contact.contact_force dispatches on it."""

    NONE = 0
    HERTZ_MINDLIN = 1
    """Hertz-Mindlin (no slip), EDEM's default."""
    JKR = 2
    """Hertz-Mindlin with JKR cohesion (EDEM "Hertz-Mindlin with JKR"), surface energy gamma."""
    EEPA = 3
    """Edinburgh Elasto-Plastic Adhesion (Morrissey 2013; Thakur et al. 2014)."""


class RollingModel(enum.IntEnum):
    """Rolling resistance model of a material pair (``PairParams.rolling_model``)."""

    NONE = 0
    CONSTANT_TORQUE = 1
    """Type A (Ai et al. 2011; EDEM's "RVD rolling friction", LIGGGHTS ``cdt``): torque -mu_r * R* * F_n along the
    relative rolling direction, R* the two spheres' reduced radius."""
    EPSD = 2
    """Type C (elastic-plastic spring-dashpot, Ai et al. 2011): rolling spring capped at mu_r * R* * F_n, plus a dashpot."""
    STANDARD = 3
    """EDEM's "standard rolling friction": on each body its own torque -mu_r * F_n * R_i * w_i/|w_i|, R_i the
    contact point's distance from that body's centre of mass (a clump's, not its sphere's), w_i its own angular
    velocity, twisting included. Between two equal spheres twice type A's torque; on a clump's sphere the lever
    is the clump's."""


class Overflow(enum.IntFlag):
    """Bits of ``Contacts.overflow``: which fixed capacity a rebuild ran out of."""

    NONE = 0
    NEIGHBOR = 1
    MESH = 2


class SphereActivity(enum.IntEnum):
    """What a sphere takes part in (``State.sphere_active``): only a MOVING sphere is stepped and found by the
    contact search."""

    PARKED = 0
    """A factory particle not released yet, or a body removed from the domain: invisible, at rest where it is."""
    MOVING = 1
    """Released: stepped, and in contact with the others."""
    SETTLED = 2
    """Its world has settled (the scene's settle rule, :meth:`warpdem.engine.solver.Solver.settle_worlds`): held
    where it came to rest, neither stepped nor searched (so a launch costs only its worlds still moving), and
    still measured and drawn."""
