"""Materials and the pairwise interaction table, validated at construction.

A :class:`Material` carries the bulk properties of one solid (Young's or shear modulus, Poisson's
ratio, density). An :class:`Interaction` carries what belongs to a *pair* of materials, as in EDEM:
coefficient of restitution, static and rolling friction and the rolling model. The
:class:`InteractionTable` maps unordered pairs of material names to interactions and is turned into
dense per-world device arrays by :func:`pair_table`.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from dataclasses import dataclass, field

import numpy as np

from warpdem.errors import InputError
from warpdem.kernels.law_hertz_mindlin import SQRT_5_6, stable_factors
from warpdem.kernels.params import PairParams

from .checks import check, check_number, enum_value, number_fields
from .types import ContactLaw, RollingModel


def elastic_moduli(poisson_ratio: float, youngs_modulus=None, shear_modulus=None) -> tuple[float, float]:
    """(E, G) [Pa] of an isotropic elastic solid from Poisson's ratio nu [-] and one of E and G [Pa]:
    G = E / (2 (1 + nu)), E = 2 G (1 + nu). Given both, G follows from E."""
    nu = float(poisson_ratio)
    if youngs_modulus is None:
        g = float(shear_modulus)
        return 2.0 * g * (1.0 + nu), g
    e = float(youngs_modulus)
    return e, e / (2.0 * (1.0 + nu))


@dataclass(frozen=True)
class Material:
    """Bulk properties of one solid.

    Give either ``youngs_modulus`` or ``shear_modulus`` (or both, if consistent); the other follows
    from G = E / (2 (1 + nu)).

    Attributes:
        name: unique name.
        density: particle (solid) density [kg/m^3], > 0.
        poisson_ratio: Poisson's ratio [-], in (-1, 0.5).
        youngs_modulus: Young's modulus E [Pa], > 0.
        shear_modulus: shear modulus G [Pa], > 0; for nu >= 0 it cannot exceed E/2.
    """

    name: str
    density: float
    poisson_ratio: float
    youngs_modulus: float | None = None
    shear_modulus: float | None = None

    def __post_init__(self):
        where = f"Material {self.name!r}"
        check(isinstance(self.name, str) and self.name != "", where, "name", self.name, "a non-empty string")
        check_number(where, "density", self.density, lambda v: v > 0, "a density > 0 kg/m^3")
        check_number(where, "poisson_ratio", self.poisson_ratio, lambda v: -1.0 < v < 0.5, "a value in (-1, 0.5)")
        if self.youngs_modulus is None and self.shear_modulus is None:
            raise InputError(f"{where}: give youngs_modulus or shear_modulus (neither was given)")
        nu = float(self.poisson_ratio)
        for name in ("youngs_modulus", "shear_modulus"):
            if getattr(self, name) is not None:
                check_number(where, name, getattr(self, name), lambda v: v > 0, "a modulus > 0 Pa")
        if self.youngs_modulus is not None and self.shear_modulus is not None:
            e, g = float(self.youngs_modulus), float(self.shear_modulus)
            if nu >= 0.0:
                check(
                    g <= 0.5 * e * (1 + 1e-9),
                    where,
                    "shear_modulus",
                    g,
                    f"at most E/2 = {0.5 * e:.6g} Pa for a non-negative Poisson's ratio",
                )
            implied = elastic_moduli(nu, youngs_modulus=e)[1]
            check(
                abs(g - implied) <= 0.01 * implied,
                where,
                "shear_modulus",
                g,
                f"E/(2(1+nu)) = {implied:.6g} Pa within 1% (E = {e:.6g} Pa, nu = {nu})",
            )
        elif self.youngs_modulus is None:
            object.__setattr__(self, "youngs_modulus", elastic_moduli(nu, shear_modulus=self.shear_modulus)[0])
        else:
            object.__setattr__(self, "shear_modulus", elastic_moduli(nu, youngs_modulus=self.youngs_modulus)[1])

    def with_value(self, name: str, value: float) -> Material:
        """A copy with the numeric field ``name`` (one of :data:`MATERIAL_SCALARS`) set to ``value``. E and G
        are tied through nu: a new E re-derives G; a new G or a new nu keeps G and re-derives E."""
        changes = {name: value}
        if name == "youngs_modulus":
            changes["shear_modulus"] = None
        elif name in ("shear_modulus", "poisson_ratio"):
            changes["youngs_modulus"] = None
        return dataclasses.replace(self, **changes)

    @property
    def E(self) -> float:  # noqa: N802 - the physics symbol
        return float(self.youngs_modulus)

    @property
    def G(self) -> float:  # noqa: N802
        return float(self.shear_modulus)

    def rayleigh_time(self, radius: float) -> float:
        """Rayleigh wave time step T_R = pi R sqrt(rho/G) / (0.1631 nu + 0.8766) [s] for a sphere of ``radius`` [m]."""
        return math.pi * radius * math.sqrt(self.density / self.G) / (0.1631 * self.poisson_ratio + 0.8766)


_ENUM_ALIASES = {
    "A": "CONSTANT_TORQUE",
    "TYPE_A": "CONSTANT_TORQUE",
    "RVD": "CONSTANT_TORQUE",
    "C": "EPSD",
    "TYPE_C": "EPSD",
    "HM": "HERTZ_MINDLIN",
    "HM_JKR": "JKR",
    "HERTZ_MINDLIN_JKR": "JKR",
    "HERTZ_MINDLIN_WITH_JKR": "JKR",
}
"""EDEM's names of the rolling models and contact laws (upper case, ``_`` for spaces) -> member names."""


def damping_factor(restitution: float) -> float:
    """Damping factor beta = ln e / sqrt(ln^2 e + pi^2) [-] of a coefficient of restitution e (0 for e = 1)."""
    le = math.log(restitution)
    return le / math.sqrt(le * le + math.pi * math.pi)


def _param(default, pair: str, ok=None, allowed: str = "", to_pair=None):
    """A contact parameter: its default, the PairParams field it fills (``warpdem.kernels.params``; through
    ``to_pair`` when that field holds a function of the value) and, for a number, the test ``ok(value)`` a
    value must pass and the words for what passes. Everything else follows from the Interaction fields: their
    checks, the per-world scalars, the stage attributes, the override keys; a new parameter needs only its
    field here and its PairParams field."""
    return field(default=default, metadata={"pair": pair, "ok": ok, "allowed": allowed, "to_pair": to_pair})


@dataclass(frozen=True)
class Interaction:
    """Contact parameters of a pair of materials (EDEM's "interaction").

    Attributes:
        restitution: coefficient of restitution e [-], in (0, 1].
        static_friction: Coulomb friction coefficient mu_s [-], >= 0.
        rolling_friction: rolling friction coefficient mu_r [-], >= 0 (torque = mu_r R* F_n; STANDARD: mu_r R_i F_n).
        rolling_model: RollingModel (or its name): NONE, CONSTANT_TORQUE (type A, EDEM's RVD), EPSD (type C)
            or STANDARD (EDEM's standard rolling friction: each body's own lever from its centre of mass).
        rolling_damping: EPSD dashpot ratio eta_r [-], >= 0 (0.3 as Ai et al. 2011).
        law: ContactLaw of the pair: HERTZ_MINDLIN, JKR or EEPA.
        surface_energy: gamma [J/m^2], >= 0 (JKR; EEPA's f_min = -1.5 pi gamma R*). EDEM's "Surface Energy"
            entered as is; the work of adhesion is W = 2 gamma.
        pull_off_force: EEPA constant pull-off force f0 [N], <= 0 (EDEM "Constant Pull-Off Force").
        slope_exponent: EEPA loading/unloading exponent n [-], in [1, 2] (1.5: Hertz-like).
        plasticity_ratio: EEPA contact plasticity ratio lambda_p [-], in [0, 1) (0: elastic).
        tensile_exponent: EEPA adhesive branch exponent chi [-], in (0, 3].
        tangential_stiffness_multiplier: EEPA k_t factor [-], > 0.
    """

    restitution: float = _param(
        0.5, "beta", lambda v: 0.0 < v <= 1.0, "a coefficient of restitution in (0, 1]", to_pair=damping_factor
    )
    static_friction: float = _param(0.5, "mu_s", lambda v: v >= 0.0, "a friction coefficient >= 0")
    rolling_friction: float = _param(0.0, "mu_r", lambda v: v >= 0.0, "a rolling friction coefficient >= 0")
    rolling_model: RollingModel = _param(RollingModel.CONSTANT_TORQUE, "rolling_model")
    rolling_damping: float = _param(0.3, "rolling_damping", lambda v: v >= 0.0, "a damping ratio >= 0")
    law: ContactLaw = _param(ContactLaw.HERTZ_MINDLIN, "law")
    surface_energy: float = _param(0.0, "gamma", lambda v: v >= 0.0, "a surface energy >= 0 J/m^2")
    pull_off_force: float = _param(0.0, "f0", lambda v: v <= 0.0, "a constant pull-off force <= 0 N (attractive)")
    slope_exponent: float = _param(1.5, "eepa_n", lambda v: 1.0 <= v <= 2.0, "an exponent in [1, 2]")
    plasticity_ratio: float = _param(0.5, "lambda_p", lambda v: 0.0 <= v < 1.0, "a ratio in [0, 1)")
    tensile_exponent: float = _param(1.5, "chi", lambda v: 0.0 < v <= 3.0, "an exponent in (0, 3]")
    tangential_stiffness_multiplier: float = _param(1.0, "ks_fac", lambda v: v > 0.0, "a factor > 0")

    def __post_init__(self):
        where = "Interaction"
        for f in dataclasses.fields(self):
            if f.name not in INTERACTION_ENUMS:
                check_number(where, f.name, getattr(self, f.name), f.metadata["ok"], f.metadata["allowed"])
        for name, cls in INTERACTION_ENUMS.items():
            object.__setattr__(self, name, enum_value(cls, where, name, getattr(self, name), _ENUM_ALIASES))
        check(self.law != ContactLaw.NONE, where, "law", self.law, "a contact law other than NONE")

    def pair_fields(self) -> dict:
        """The PairParams fields this interaction fills, by PairParams name (enums as their integers)."""
        out = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            out[f.metadata["pair"]] = f.metadata["to_pair"](v) if f.metadata["to_pair"] else v
        return {k: int(v) if isinstance(v, enum.Enum) else v for k, v in out.items()}

    @property
    def dashpot_factor(self) -> float:
        """damp [-] of the pair's dashpots c = damp sqrt(S m*): -2 sqrt(5/6) beta (Tsuji, as Hertz-Mindlin, JKR
        and non-linear EEPA apply it), -2 beta for linear EEPA (n = 1; law_eepa.eepa_damping_coefficient)."""
        linear = self.law == ContactLaw.EEPA and self.slope_exponent == 1.0
        return -2.0 * self.beta * (1.0 if linear else float(SQRT_5_6))

    @property
    def beta(self) -> float:
        """Damping factor beta = ln e / sqrt(ln^2 e + pi^2) (0 for e = 1) of this pair's restitution."""
        return damping_factor(self.restitution)


INTERACTION_FIELDS = tuple(f.name for f in dataclasses.fields(Interaction))
"""Every Interaction field, in order (the stage's pair attributes and the override keys follow it)."""
INTERACTION_ENUMS = {
    f.name: type(f.default) for f in dataclasses.fields(Interaction) if isinstance(f.default, enum.Enum)
}
"""Interaction fields holding an enum member -> the enum (a token on a stage)."""
INTERACTION_SCALARS = tuple(number_fields(Interaction))
"""The numeric Interaction fields: what :meth:`warpdem.engine.builder.ModelBuilder.vary` can set per world."""
MATERIAL_SCALARS = tuple(number_fields(Material))
"""The numeric Material fields: what an override (and a per-world variation) can set."""


@dataclass
class InteractionTable:
    """Unordered material pair -> Interaction, with a default for pairs not listed."""

    default: Interaction = field(default_factory=Interaction)
    pairs: dict = field(default_factory=dict)

    def set(self, a: str, b: str, interaction: Interaction | None = None, **kwargs) -> Interaction:
        """Set the interaction of materials ``a`` and ``b`` (either order); kwargs build one from the default."""
        if interaction is None:
            interaction = dataclasses.replace(self.default, **kwargs)
        elif kwargs:
            interaction = dataclasses.replace(interaction, **kwargs)
        self.pairs[frozenset((a, b))] = interaction
        return interaction

    def get(self, a: str, b: str) -> Interaction:
        return self.pairs.get(frozenset((a, b)), self.default)


def effective_moduli(ma: Material, mb: Material) -> tuple[float, float]:
    """(E*, G*) of a pair [Pa]: E* = 1/((1-nu_a^2)/E_a + (1-nu_b^2)/E_b), G* = 1/((2-nu_a)/G_a + (2-nu_b)/G_b)."""
    e_star = 1.0 / ((1 - ma.poisson_ratio**2) / ma.E + (1 - mb.poisson_ratio**2) / mb.E)
    g_star = 1.0 / ((2 - ma.poisson_ratio) / ma.G + (2 - mb.poisson_ratio) / mb.G)
    return e_star, g_star


def pair_table(materials_per_world: list[list[Material]], tables_per_world: list[InteractionTable]) -> np.ndarray:
    """Dense PairParams fields, shape (W, M, M), as a NumPy structured array (W = len of the lists, 1 or world_count)."""
    w_count, m_count = len(materials_per_world), len(materials_per_world[0])
    dtype = np.dtype(PairParams.numpy_dtype())
    out = np.zeros((w_count, m_count, m_count), dtype=dtype)
    for w in range(w_count):
        mats, table = materials_per_world[w], tables_per_world[w]
        for a in range(m_count):
            for b in range(m_count):
                e_star, g_star = effective_moduli(mats[a], mats[b])
                inter = table.get(mats[a].name, mats[b].name)
                fields = {"e_star": e_star, "g_star": g_star, **inter.pair_fields()}
                fields["stable_n"], fields["stable_t"] = stable_factors(inter.dashpot_factor)
                out[w, a, b] = tuple(fields[name] for name in dtype.names)
    return out
