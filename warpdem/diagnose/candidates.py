"""The library of candidate model extensions a diagnosis tries.

Each candidate adds ONE parameter to the base model and reduces to the base model at a known ``off`` value:

- ``cohesion``: the grain-grain JKR surface energy gamma [J/m^2] (the pair's law becomes JKR, which is
  Hertz-Mindlin at gamma = 0). Off 0; range up to the gamma whose JKR pull-off force 1.5 pi gamma R* is
  :data:`BOND_MAX` times a mean grain's weight (R* = R/2).
- ``plasticity``: the grain-grain EEPA contact plasticity ratio lambda_p [-] (the pair's law becomes EEPA with
  n = 1.5, no adhesion, no pull-off force, which is Hertz-Mindlin with its Tsuji damping at lambda_p = 0).
  Off 0; range [0, 0.8].
- ``shape``: the rig's ``aspect_ratio`` (a rod of overlapping spheres of the same volume). Off 1; range
  [1, 2.5]. Only for sphere grains of a rig that has the parameter.
- ``size_distribution``: the rig's relative radius SD ``radius_spread`` [-]. Off: the base value; range
  [off, max(0.25, off)] (a truncated normal at +-2 SD keeps radii positive up to 0.5).
- ``rolling_friction``: the grain-grain rolling friction mu_r [-] (the base's rolling model). Off: the base value;
  range [0, max(0.5, 2 off)].
- ``rolling_model``: not a one-parameter extension (type A, type C and EDEM's standard model are three models,
  not one with an off value), so it never joins the library. The reach diagnosis tries it where the mean cannot
  judge it: when the base model reaches the data but scatters more than the measurement (OVERDISPERSED), each
  other rolling model is a :class:`LawSwitch` (:func:`rolling_alternatives`), judged by its runs' scatter.
- ``wall_friction``: the static friction of the grain against the wall the measurement rests on (the funnel's
  and lifting cylinder's base plate, the press's die, the drum's shell), separate from grain-grain friction.
  Off: the base value; range [0.1, 1].
- ``coarse_graining``: the exponent k of the rule that scales the grain-grain surface energy (JKR's or EEPA's)
  with the grain size, gamma -> gamma s^k, where s is the scene's grain radius over the measured grains' (the data file's
  ``[candidates] grain_radius``): the scene's grains are coarse-grained stand-ins, and a surface energy measured or
  calibrated for the real grains is too weak for them (the pull-off force 1.5 pi gamma R* grows as R, the weight
  as R^3). k = 1 keeps the bulk cohesive stress (pull-off force over a grain's cross-section), k = 2 the granular
  Bond number (pull-off force over weight). Off 0 (the surface energy as given); range [0, 2]. Only for a JKR or
  EEPA grain-grain pair whose surface energy is not 0, with the same s for every experiment. Its parameter is not an
  override key: :func:`resolve` turns it into the surface energy it implies, whatever gives the base value (a free
  parameter, a condition, ``[fixed]`` or the scene).
- ``cohesion_strength``: the grain-grain surface energy (JKR's or EEPA's) weakened by a factor 10^x, x the
  candidate's parameter (off 0; range [-1, 0], a factor 0.1-1), whatever gives the surface energy (as for
  coarse-graining, :func:`resolve`). Not a one-change candidate of the library: a cohesion weaker than the data
  file's box is what a free surface energy already covers up to its bound. It is the second part of a two-change
  model the reach diagnosis tries when its base is OVERDISPERSED and no rolling model alone repeats
  (:func:`cohesion_strength`): a pile of grains cohesive past a granular Bond number of a few stands as a tower
  or falls, and scatters with the seed whatever its rolling law, so a law that repeats may need weaker cohesion
  too (seed 001's fix: EDEM's standard rolling friction with the surface energy times 0.2).

A candidate does not apply when its parameter is already a free parameter of the base model, a condition of
the experiments or a ``[fixed]`` key (the user has decided it), or when the scene cannot carry it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field

from warpdem.errors import InputError

CANDIDATE_NAMES = (
    "cohesion",
    "plasticity",
    "shape",
    "size_distribution",
    "rolling_friction",
    "rolling_model",
    "wall_friction",
    "coarse_graining",
    "cohesion_strength",
)
"""Names of the candidate extensions, in the order they are tried and reported."""

CAUSES = {
    "cohesion": "cohesion (JKR surface energy)",
    "plasticity": "plasticity (EEPA contact plasticity ratio)",
    "shape": "particle shape (elongation)",
    "size_distribution": "size distribution (PSD width)",
    "rolling_friction": "rolling resistance (rolling friction)",
    "rolling_model": "rolling-resistance model (type A, C or EDEM standard)",
    "wall_friction": "particle-wall friction",
    "coarse_graining": "coarse-graining (the surface energy not scaled with the grain size)",
    "cohesion_strength": "cohesion too strong for the grains (the surface energy weakened)",
}
"""The cause each candidate stands for, in the report's words."""

BOND_MAX = 5.0
"""Largest granular Bond number (JKR pull-off force / a mean grain's weight) of the cohesion candidate's range."""


def bond_surface_energy(bond: float, radius: float, density: float) -> float:
    """The surface energy gamma [J/m^2] whose JKR pull-off force 1.5 pi gamma R* between two equal grains (R* = R/2)
    is ``bond`` times one grain's weight: the granular Bond number of :data:`BOND_MAX`. ``radius`` [m] > 0,
    ``density`` [kg/m^3]."""
    weight = density * 9.81 * 4.0 / 3.0 * math.pi * radius**3
    return bond * weight / (1.5 * math.pi * radius / 2.0)


COARSE_EXPONENT = "coarse_graining.exponent"
"""The coarse_graining candidate's parameter: the exponent k of gamma s^k (not an override key)."""

_COARSE_SHARED = ("coarse_graining.size_ratio", "coarse_graining.surface_energy", "coarse_graining.target")
"""What :func:`resolve` needs beside the exponent, carried in the candidate's ``shared`` overrides: s (the scene's
grain radius over the measured grains'), the scene's own surface energy [J/m^2] (used when no override sets one;
0 when the data file sets it, as a free parameter, condition or [fixed] key) and the surface energy's override
key."""

STRENGTH_EXPONENT = "cohesion_strength.log10_factor"
"""The cohesion_strength candidate's parameter: x of gamma 10^x (not an override key)."""

_STRENGTH_SHARED = ("cohesion_strength.base", "cohesion_strength.surface_energy", "cohesion_strength.target")
"""As :data:`_COARSE_SHARED` for cohesion_strength, its base 10."""

_SCALINGS = {COARSE_EXPONENT: _COARSE_SHARED, STRENGTH_EXPONENT: _STRENGTH_SHARED}
"""The candidates whose parameter scales a surface energy, gamma -> gamma b^x: the parameter x's key and its shared
keys (b, the scene's surface energy, the target override key). Applied in this order."""


def resolve(overrides: Mapping) -> dict:
    """``overrides`` with the scaling candidates' keys (:data:`_SCALINGS`, when present) replaced by the surface
    energy they imply: gamma b^x, gamma the overrides' own value of the target key, else the scene's. Every other
    key is returned as it is."""
    out = dict(overrides)
    for exponent, shared in _SCALINGS.items():
        if exponent not in out:
            continue
        x = float(out.pop(exponent))
        b, gamma, target = (out.pop(key) for key in shared)
        out[target] = float(out.get(target, gamma)) * float(b) ** x
    return out


def varies_per_world(key: str) -> bool:
    """True when a model parameter ``key`` can differ between the batched worlds of one launch: an override key
    that can (:func:`warpdem.study.spec.varies_per_world`) or the coarse-graining exponent (a surface energy)."""
    from warpdem.study.spec import varies_per_world as per_world

    return key in _SCALINGS or per_world(key)


_REST_WALL = {"angle_of_repose": ("Plate", "Base"), "press": ("Die",), "drum": ("Drum",)}
"""The wall each measure kind's grains rest on or slide along (wall_friction)."""


@dataclass(frozen=True)
class Candidate:
    """One extension: its extra parameter ``key`` (an override key or rig parameter), the value ``off`` at which
    the model is the base model, the physical range [``low``, ``high``] (``off`` inside it), the overrides
    ``shared`` every simulation of the extended model needs (e.g. the pair's law), and a ``unit``."""

    name: str
    key: str
    off: float
    low: float
    high: float
    unit: str = ""
    shared: Mapping = field(default_factory=dict)

    def __post_init__(self):
        if self.name not in CANDIDATE_NAMES:
            raise InputError(f"Candidate: name = {self.name!r} is not allowed; expected one of {CANDIDATE_NAMES}")
        if not (self.low < self.high and self.low <= self.off <= self.high):
            raise InputError(
                f"Candidate {self.name!r}: range [{self.low}, {self.high}] with off = {self.off} is not allowed; "
                "expected low < high and off within the range"
            )

    @property
    def cause(self) -> str:
        return CAUSES[self.name]

    @property
    def off_at_edge(self) -> bool:
        """True when the off value is an end of the range (the likelihood-ratio test's boundary case)."""
        return self.off in (self.low, self.high)

    @property
    def test_value(self) -> float:
        """The value the screen moves the candidate to: halfway from off to the far end of its range."""
        far = self.high if self.high - self.off >= self.off - self.low else self.low
        return self.off + 0.5 * (far - self.off)


def _grain(scene) -> tuple[str, float, float]:
    """(material name, mean radius [m], density [kg/m^3]) of the scene's first factory's grains."""
    fac = scene.factories[0]
    sizes = fac.sizes
    radius = float(sizes.get("radius", sizes.get("mean", sizes.get("median", 0.0))))
    density = next(m.density for m in scene.materials if m.name == fac.material)
    return fac.material, radius, float(density)


def _pair(scene, a: str, b: str):
    from warpdem.engine.materials import Interaction

    for pa, pb, ia in scene.pairs:
        if {pa, pb} == {a, b}:
            return ia
    return Interaction()


def library(
    scene, rig_params: Mapping | None, taken: set[str], grain_radius: float | None = None
) -> tuple[list[Candidate], dict[str, str]]:
    """The candidates that apply to ``scene`` (a SceneSpec built with the base model's overrides) and why the
    others do not. ``rig_params``: the rig's parameter values (None for a stage without a rig), ``taken``: the
    override keys the user has decided (free parameters, conditions, ``[fixed]`` keys), ``grain_radius``: the
    measured grains' mean radius [m] when the scene's grains stand in for them (None: they are the real grains).

    Returns (candidates in :data:`CANDIDATE_NAMES` order, {name: reason it does not apply})."""
    from warpdem.engine.types import ContactLaw

    grain, radius, density = _grain(scene)
    gg = _pair(scene, grain, grain)
    out, skipped = [], {}

    def add(name, key, off, low, high, unit="", shared=None):
        if key in taken:
            skipped[name] = f"{key} is already decided by the data file (a free parameter, condition or [fixed] key)"
            return
        if any(k in taken for k in (shared or {})):
            skipped[name] = f"it changes {', '.join(shared)}, which the data file decides"
            return
        out.append(Candidate(name, key, float(off), float(low), float(high), unit, dict(shared or {})))

    pp = f"interaction.{grain}.{grain}"
    if gg.law == ContactLaw.HERTZ_MINDLIN and radius > 0:
        gamma_max = bond_surface_energy(BOND_MAX, radius, density)
        add("cohesion", f"{pp}.surface_energy", 0.0, 0.0, gamma_max, "J/m^2", {f"{pp}.law": "JKR"})
        add(
            "plasticity",
            f"{pp}.plasticity_ratio",
            0.0,
            0.0,
            0.8,
            "",
            {f"{pp}.law": "EEPA", f"{pp}.slope_exponent": 1.5, f"{pp}.pull_off_force": 0.0},
        )
    else:
        why = f"the grain-grain law is {gg.law.name}, not Hertz-Mindlin"
        skipped["cohesion"] = skipped["plasticity"] = why
    params = dict(rig_params or {})
    shape = scene.shapes[0].kind if scene.shapes else "sphere"
    if "aspect_ratio" not in params:
        skipped["shape"] = "the scene has no aspect_ratio rig parameter"
    elif shape != "sphere" or float(params["aspect_ratio"]) != 1.0:
        skipped["shape"] = "the base grains are not spheres"
    else:
        add("shape", "aspect_ratio", 1.0, 1.0, 2.5)
    if "radius_spread" in params:
        s = float(params["radius_spread"])
        add("size_distribution", "radius_spread", s, s, max(0.25, s))
    else:
        skipped["size_distribution"] = "the scene has no radius_spread rig parameter"
    mu_r = float(gg.rolling_friction)
    add("rolling_friction", f"{pp}.rolling_friction", mu_r, 0.0, max(0.5, 2.0 * mu_r))
    skipped["rolling_model"] = (
        "type A, type C and EDEM's standard model are three models, not one parameter with an off value: the reach "
        "diagnosis tries them by their scatter when the base model is OVERDISPERSED"
    )
    rest = [w for w in scene.walls if w.name in _REST_WALL.get(scene.measure.kind, ())]
    if rest:
        mat = rest[0].material
        mu_w = float(_pair(scene, grain, mat).static_friction)
        add("wall_friction", f"interaction.{grain}.{mat}.static_friction", mu_w, min(0.1, mu_w), max(1.0, mu_w))
    else:
        skipped["wall_friction"] = f"no wall the {scene.measure.kind} measurement rests on"
    gamma, no_gamma = _scalable_surface_energy(gg, f"{pp}.surface_energy", taken)
    if no_gamma:
        skipped["coarse_graining"] = no_gamma
    elif grain_radius is None:
        skipped["coarse_graining"] = (
            "the data file gives no [candidates] grain_radius (the measured grains' mean radius) to scale from"
        )
    elif radius <= 0:
        skipped["coarse_graining"] = "the scene's grains have no mean radius to compare with grain_radius"
    elif math.isclose(radius, grain_radius, rel_tol=1e-9):
        skipped["coarse_graining"] = f"the scene's grains are the measured size ({grain_radius:g} m): nothing to scale"
    else:
        shared = dict(zip(_COARSE_SHARED, (radius / float(grain_radius), gamma, f"{pp}.surface_energy")))
        add("coarse_graining", COARSE_EXPONENT, 0.0, 0.0, 2.0, "", shared)
    skipped["cohesion_strength"] = (
        "a second change only: the reach diagnosis pairs it with each rolling model when the base model is "
        "OVERDISPERSED and no rolling model alone repeats"
    )
    return out, skipped


def _scalable_surface_energy(gg, key: str, taken: set[str]) -> tuple[float, str | None]:
    """The grain-grain surface energy [J/m^2] a scaling candidate starts from, carried in its ``shared`` overrides
    (0 when the data file sets ``key``: a free parameter, condition or [fixed] value then reaches every request, and
    may differ between experiments), and None; or (0, why there is none to scale)."""
    from warpdem.engine.types import ContactLaw

    if gg.law not in (ContactLaw.JKR, ContactLaw.EEPA):
        return 0.0, f"the grain-grain law is {gg.law.name}, neither JKR nor EEPA: no surface energy to scale"
    if key in taken:
        return 0.0, None
    if float(gg.surface_energy) == 0.0:
        return 0.0, f"{key} is 0: no cohesion to scale"
    return float(gg.surface_energy), None


STRENGTH_RANGE = (-1.0, 0.0)
"""cohesion_strength's default range of x (the surface energy times 10^x): weaker by up to ten times."""


def cohesion_strength(scene, taken: set[str]) -> tuple[Candidate | None, str | None]:
    """The cohesion_strength candidate of ``scene`` (a SceneSpec built with the base model's overrides; ``taken``:
    the override keys the data file decides) and None, or (None, why it does not apply): the grain-grain law has no
    surface energy, or it is 0 and not the data file's."""
    grain = _grain(scene)[0]
    pp = f"interaction.{grain}.{grain}"
    gamma, why = _scalable_surface_energy(_pair(scene, grain, grain), f"{pp}.surface_energy", taken)
    if why:
        return None, why
    shared = dict(zip(_STRENGTH_SHARED, (10.0, gamma, f"{pp}.surface_energy")))
    lo, hi = STRENGTH_RANGE
    return Candidate("cohesion_strength", STRENGTH_EXPONENT, 0.0, lo, hi, "log10", shared), None


@dataclass(frozen=True)
class LawSwitch:
    """A discrete change of the base model: the grain's rolling-resistance model set to ``model`` (a
    :class:`RollingModel` name, lower case) on every pair of the grain that has rolling friction, through the
    override keys of ``shared``. No parameter is added; the base model's parameters stay free."""

    model: str
    shared: Mapping = field(default_factory=dict)

    @property
    def name(self) -> str:
        """The extended model's name in results and reports: ``rolling_model=<model>``."""
        return f"rolling_model={self.model}"


def rolling_alternatives(scene, taken: set[str]) -> tuple[list[LawSwitch], str | None]:
    """The rolling models the grain of ``scene`` (a SceneSpec built with the base model's overrides) could have
    instead of its own, as :class:`LawSwitch` es over the grain-grain pair and each other pair of the grain with
    rolling friction, and None; or ([], why none applies): the grain-grain pair has no rolling friction (no model
    acts), or the data file decides one of the keys (``taken``: free parameters, conditions, ``[fixed]`` keys)."""
    from warpdem.engine.types import RollingModel

    grain = _grain(scene)[0]
    gg = _pair(scene, grain, grain)
    if float(gg.rolling_friction) == 0.0:
        return [], "the grain-grain rolling friction is 0: no rolling model acts"
    pairs = [(grain, grain)] + [
        (a, b) for a, b, ia in scene.pairs if grain in (a, b) and a != b and float(ia.rolling_friction) > 0.0
    ]
    keys = [f"interaction.{a}.{b}.rolling_model" for a, b in pairs]
    decided = [k for k in keys if k in taken]
    if decided:
        verb = "is" if len(decided) == 1 else "are"
        return [], f"{', '.join(decided)} {verb} decided by the data file (free parameters, conditions or [fixed] keys)"
    base = RollingModel(int(gg.rolling_model))
    models = [m for m in RollingModel if m not in (RollingModel.NONE, base)]
    return [LawSwitch(m.name.lower(), {k: m.name.lower() for k in keys}) for m in models], None


def with_range(c: Candidate, low: float, high: float) -> Candidate:
    """``c`` over the user's range [low, high] (``[candidates] ranges``); the off value must stay inside it."""
    return dataclasses.replace(c, low=float(low), high=float(high))
