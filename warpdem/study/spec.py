"""Study definitions: a TOML file per calibration stage, loaded into frozen, validated dataclasses.

A study names a scene (a rig of :mod:`warpdem.scene.rigs`, or a USD stage), the overrides every run shares,
the factors (each one override key with its low and high actual value), a design of experiments, the
responses to read from each run's metrics, the regression to fit and the verification runs.
:func:`load_study` reads one; :func:`design_table` expands it into runs; :func:`run_overrides` gives
the ``--set`` overrides of one run and :func:`batch_key` what runs must share to run as batched worlds.

Every bad input raises :class:`StudyError` (a ``ValueError``) whose message names the file, the table
and field, the value and what is allowed (an unknown key comes with a "did you mean").

Schema (``studies/*.toml``)::

    [study]
    name = "pellets_pb"             # identifier, [a-z0-9_]+ (required)
    title = "..."                   # free text
    source = "000_9053eeef0bc95e7d.txt"   # seed paper (free text)
    rig = "funnel"                  # one of warpdem.scene.rigs.RIGS, or
    # scene = "../scenes/funnel.usda"     # a stage, relative to the TOML (exactly one of rig / scene)
    smoke = false                   # start from rigs.SMOKE[rig] (rig only)
    seed = 1                        # run-order randomisation seed, integer >= 0 (default 1)
    batch = 0                       # most worlds per launch, >= 0 (0: all runs that share a scene)

    [fixed]                         # overrides of every run: rig parameters or override keys
    particle = "pellet"
    "interaction.grain.grain.restitution" = 0.37   # quoted (a bare dotted key is read the same way)

    [[factors]]                     # one table per factor, in model order
    name = "A"                      # [A-Za-z][A-Za-z0-9_]*, used in model terms (required)
    label = "particle-wall static friction"
    parameter = "interaction.grain.steel.static_friction"   # the override key it sets (required)
    low = 0.38                      # actual value at coded -1 (required)
    high = 0.65                     # actual value at coded +1 (required; low > high: reversed coding)
    unit = ""

    [design]
    kind = "plackett_burman"        # plackett_burman | full_factorial | fractional_factorial |
                                    # box_behnken | central_composite | steepest_ascent | explicit
    runs = 12                       # plackett_burman: 12 or 20 (default: 12 for <= 11 factors, else 20)
    generators = ["E = ABCD"]       # fractional_factorial (required there)
    alpha = 2.0                     # central_composite: > 0, or "rotatable" (default) | "orthogonal" | "face"
    center_points = 0               # two-level kinds (default 0), box_behnken (default 5, 5, 6 for
                                    # 3, 4, 5 factors, as Design-Expert; >= 1), central_composite (default 6)
    replicates = 1                  # whole-design replicates, >= 1
    randomize = true                # run order drawn with [study] seed; false: standard order
    # steepest_ascent: a path of `steps` runs (the start included) from `start` (actual units;
    # default: the factors' centres), either by a fixed actual step per factor
    #   step = {C = 0.02, D = 0.06, E = 0.01}
    # or along the gradient of a first-order model in coded units
    #   coefficients = {C = 1.33, D = 3.32, E = 1.79}, base = "D", base_step = 0.06 (actual units of
    #   the base factor, > 0), descent = false
    # explicit: points = [{C = 0.39, D = 0.45, E = 0.02}, ...] (actual units, every factor in each)

    [[responses]]                   # at least one
    name = "aor_deg"                # [A-Za-z][A-Za-z0-9_]* (required)
    measure = "angle_fit_deg"       # a metric key of warpdem.scene.runner (MEASURES), or a dotted path into
                                    # the metrics (e.g. "phases.load.Body.max_speed_m_s") (required)
    unit = "deg"
    target = 28.27                  # measured value to calibrate to (optional)
    goal = "target"                 # desirability goal for the multi-response optimisation (optional):
                                    # maximize | minimize | target (uses target) | in_range
    low = 20.0                      # the goal's limits (needed with a goal), low < high; a target lies between
    high = 35.0
    weight = 1.0                    # > 0: 1 linear, above 1 stricter near the goal (default 1)
    weight_high = 1.0               # a target's upper side (default: weight)
    importance = 3                  # 1 to 5, in the overall desirability (default 3)
    transform = "ln"                # this response's own transform, in place of [analysis]'s (optional; with
                                    # transform_power and transform_k as there)

    [analysis]
    model = "linear"                # linear | 2fi | quadratic | none | a list of terms ["A", "A*B", "A^2"]
                                    # (default: linear for two-level kinds, quadratic for box_behnken and
                                    # central_composite, none for steepest_ascent and explicit)
    alpha = 0.05                    # significance level, in (0, 1)
    eliminate = false               # hierarchical backward elimination at alpha
    transform = "none"              # fit every response's model to f(y + k): none | sqrt | ln | log10 |
                                    # inverse_sqrt | inverse | power (Design-Expert's); ANOVA, equations and
                                    # diagnostics on that scale, predictions and solutions back-transformed
    transform_power = 0.25          # the exponent of transform = "power" (not 0: that is ln)
    transform_k = 0.0               # a constant added first, so that y + k fits f's domain (default 0)

    [verification]
    replicates = 0                  # verification runs at the chosen optimum, >= 0

Override keys (``[fixed]`` keys and factor parameters) are read by the one grammar of
:mod:`warpdem.engine.keys`, with the scene's fields of :data:`warpdem.scene.stage.OVERRIDES`:
``material.NAME.FIELD`` (density, poisson_ratio, youngs_modulus, shear_modulus),
``interaction.A.B.FIELD`` (any :class:`~warpdem.engine.materials.Interaction` field; a factor only the numeric
ones of ``materials.INTERACTION_SCALARS``), ``run.FIELD``, ``measure.FIELD`` and ``factory.NAME.FIELD``
(``[fixed]`` only), and any other key is a rig parameter (with ``rig``, checked against the rig's
parameters; a factor must name a numeric one). Only ``material.*`` numbers and ``interaction.*`` fields (the
pair's law included) can differ between the batched worlds of one launch (:meth:`warpdem.engine.builder.ModelBuilder.vary`); a factor on
anything else makes each of its levels a launch of its own (:func:`batch_key`).

:func:`load_study` also builds the scene once (the rig from its parameters, or the stage) and applies
``[fixed]`` and each factor's lowest and highest design value to it, so that a material that does not
exist, or a value the contact law refuses (a restitution of 0 at an axial point), is reported by the
loader and not by the run.

The design table (:func:`design_table`): one row per run in run order with ``run`` (1..N),
``std_order`` (1..N in the standard order of the replicated design, replicate-major), ``point_type``
(factorial | axial | centre | path | point), ``replicate`` (0-based), ``world_seed``, one coded column
per factor (named by the factor) and one actual column (``<name>_actual``), and ``point_id``.
A DEM run is deterministic, so a repeated design point (a centre run, a replicate) would repeat its
result exactly and give no pure error: ``world_seed`` is 0 for the first occurrence of a point (in
standard order) and 1, 2, ... for each further occurrence, and the runner seeds the run's random
inputs (particle release) with it. ``point_id`` is a short sha1 of the scene (rig and smoke, or the
stage path as written), the run's overrides (``[fixed]`` and the factor values, rounded to 12
significant digits) and ``world_seed``: the identity of a run, so that a resumed study matches
finished runs by what they are, not by their position.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import hashlib
import json
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pandas as pd

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10 needs the tomli backport
    import tomli as tomllib

from warpdem.engine.checks import did_you_mean, finite_number, is_number, not_allowed
from warpdem.engine.keys import PER_WORLD, KeyGrammar, is_rig_key
from warpdem.engine.materials import INTERACTION_SCALARS
from warpdem.errors import InputError
from warpdem.scene.runner import COMMON_METRICS, MEASURE_METRICS

from . import designs
from .analysis import model_terms
from .designs import Factor
from .goals import GOALS, Goal
from .transforms import TRANSFORMS, Transform

__all__ = [
    "AnalysisSpec",
    "DESIGN_KINDS",
    "DesignSpec",
    "FactorSpec",
    "FrozenMap",
    "MEASURES",
    "ResponseSpec",
    "StudyError",
    "StudySpec",
    "VerificationSpec",
    "batch_key",
    "build_scene",
    "check_factors",
    "check_fixed",
    "check_header",
    "check_override",
    "check_scene_overrides",
    "check_table_keys",
    "design_table",
    "fixed_scene",
    "flatten_keys",
    "load_study",
    "override_grammar",
    "point_key",
    "read_toml",
    "rig_fields",
    "rig_value",
    "run_overrides",
    "spec_error",
    "spec_integer",
    "spec_number",
    "varies_per_world",
]


class StudyError(InputError):
    """A study definition that cannot be used; the message names file, table, field, value and what is
    allowed."""


DESIGN_KINDS = (
    "plackett_burman",
    "full_factorial",
    "fractional_factorial",
    "box_behnken",
    "central_composite",
    "steepest_ascent",
    "explicit",
)
"""Design kinds of ``[design] kind``."""

MEASURES = tuple(dict.fromkeys(k for keys in MEASURE_METRICS.values() for k in keys)) + COMMON_METRICS
"""Scalar metric keys that :func:`warpdem.scene.runner.run_scene` writes per world (``metrics.json``): those of
every measure kind (:data:`warpdem.scene.runner.MEASURE_METRICS`), then the common ones."""

_POINT_TYPE = {"factorial": "factorial", "axial": "axial", "center": "centre"}
_RESERVED = {"run", "std_order", "point_type", "replicate", "world_seed", "point_id", "kind", "run_order"}
_NAME_RE = re.compile(r"^[a-z0-9_]+$")
_FACTOR_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
_DIGITS = 12  # significant digits of actual values in the table and in point ids


# --------------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------------


def _rigs():
    from warpdem.scene import rigs

    return rigs


def spec_error(where: str, key: str, value, expected: str) -> StudyError:
    return StudyError(not_allowed(where, key, value, expected))


def spec_number(where: str, key: str, v) -> float:
    return finite_number(where, key, v, error=StudyError)


def spec_integer(where: str, key: str, v, minimum: int) -> int:
    if not is_number(v) or float(v) != int(v) or int(v) < minimum:
        raise spec_error(where, key, v, f"an integer >= {minimum}")
    return int(v)


def _transform(where: str, kind, power, k) -> Transform:
    """A :class:`transforms.Transform` from a table's ``transform``, ``transform_power`` and ``transform_k``;
    StudyError naming the table, the key and the value otherwise."""
    if not isinstance(kind, str) or kind not in TRANSFORMS:
        raise spec_error(where, "transform", kind, " | ".join(TRANSFORMS) + did_you_mean(str(kind), TRANSFORMS))
    power = None if power is None else spec_number(where, "transform_power", power)
    k = spec_number(where, "transform_k", k)
    try:
        return Transform(kind, power, k)
    except ValueError as e:
        raise StudyError(f"{where}: {e}") from None


def _boolean(where: str, key: str, v) -> bool:
    if not isinstance(v, (bool, np.bool_)):
        raise spec_error(where, key, v, "true or false")
    return bool(v)


def _string(where: str, key: str, v) -> str:
    if not isinstance(v, str):
        raise spec_error(where, key, v, "a string")
    return v


def _round(v: float) -> float:
    """``v`` to 12 significant digits (-0.0 becomes 0.0): actual values free of coding round-off."""
    r = float(f"{float(v):.{_DIGITS}g}")
    return r + 0.0


class FrozenMap(dict):
    """A read-only dict (picklable and hashable, unlike ``types.MappingProxyType``): the mappings of the
    frozen study dataclasses."""

    def _read_only(self, *args, **kwargs):
        raise TypeError("a study's mappings are read-only; build a new spec (dataclasses.replace)")

    __setitem__ = __delitem__ = clear = pop = popitem = setdefault = update = _read_only  # type: ignore
    __ior__ = _read_only  # type: ignore

    def __hash__(self):
        return hash(tuple(sorted((k, _hashable(v)) for k, v in self.items())))

    def __reduce__(self):
        return (type(self), (dict(self),))


def _mapping(where: str, key: str, v, names: Sequence[str], need_all: bool) -> FrozenMap:
    """A read-only {factor name: finite number} table."""
    if not isinstance(v, Mapping):
        raise spec_error(where, key, v, "a table {factor = number, ...}")
    unknown = [k for k in v if k not in names]
    if unknown:
        raise StudyError(
            f"{where}: {key} names factor {unknown[0]!r}, which is not a factor"
            f"{did_you_mean(unknown[0], names)}; factors: {', '.join(names)}"
        )
    if need_all:
        missing = [n for n in names if n not in v]
        if missing:
            raise StudyError(
                f"{where}: {key} = {dict(v)!r} lacks factor(s) {', '.join(missing)}; expected a "
                f"value for every factor ({', '.join(names)})"
            )
    return FrozenMap({k: spec_number(where, f"{key}.{k}", v[k]) for k in names if k in v})


def rig_fields(rig: str | None) -> dict[str, dataclasses.Field]:
    if rig is None:
        return {}
    return {f.name: f for f in dataclasses.fields(_rigs().RIGS[rig])}


@functools.cache
def override_grammar(rig: str | None, factor: bool) -> KeyGrammar:
    """The override keys of a study on ``rig`` (None: rig parameters not checked): the scene's
    (:data:`warpdem.scene.stage.OVERRIDES`) and the rig's parameters; for a ``factor`` only numbers: material
    and numeric interaction fields, run settings and numeric rig parameters."""
    from warpdem.scene.stage import OVERRIDES

    fields = dict(OVERRIDES.fields)
    labels = {}
    if factor:
        fields = {k: fields[k] for k in ("material", "run")} | {"interaction": INTERACTION_SCALARS}
        labels["interaction"] = "a numeric interaction field"
    fields["rig"] = None
    if rig is not None:
        rf = rig_fields(rig)
        words = [k for k, f in rf.items() if isinstance(f.default, (bool, str))]
        fields["rig"] = tuple(k for k in rf if not (factor and k in words))
        labels["rig"] = f"a numeric {rig} parameter" if factor else f"a {rig} parameter"
        if factor and words:
            labels["rig"] += f" ({', '.join(words)} {'is not a number' if len(words) == 1 else 'are not numbers'})"
    return KeyGrammar(fields, labels)


def varies_per_world(key: str) -> bool:
    """True when override ``key`` can differ between the batched worlds of one launch: a numeric
    ``material.NAME.FIELD`` or any ``interaction.A.B.FIELD`` (:meth:`ModelBuilder.vary`)."""
    return PER_WORLD.accepts(key)


# --------------------------------------------------------------------------------------------------
# the parts of a study
# --------------------------------------------------------------------------------------------------


FACTOR_MAGNITUDE = 1e90
"""The largest magnitude of a factor's low or high value: the analysis raises actual values to the third power
(a cubic model's terms), which must stay finite in float64; no DEM parameter comes near it in SI units."""


@dataclass(frozen=True)
class FactorSpec:
    """One factor: the override ``parameter`` it sets, its actual value at coded -1 (``low``) and +1
    (``high``; ``low > high`` is a reversed coding), a ``label`` and ``unit`` for reports."""

    name: str
    parameter: str
    low: float
    high: float
    label: str = ""
    unit: str = ""

    table: ClassVar[str] = "[[factors]]"
    """The TOML table messages name (a subclass read from another file names its own)."""

    def __post_init__(self):
        where = f"{self.table} {self.name!r}"
        if not isinstance(self.name, str) or not _FACTOR_RE.match(self.name):
            raise spec_error(self.table, "name", self.name, "letters, digits and _ starting with a letter (e.g. A, X1)")
        if self.name in _RESERVED or self.name.endswith("_actual"):
            raise spec_error(
                where,
                "name",
                self.name,
                f"a name that is not a design-table column ({', '.join(sorted(_RESERVED))}, *_actual)",
            )
        override_grammar(None, True).parse(self.parameter, where, "parameter", error=StudyError)
        low = spec_number(where, "low", self.low)
        high = spec_number(where, "high", self.high)
        for k, v in (("low", low), ("high", high)):
            if not abs(v) <= FACTOR_MAGNITUDE:
                raise spec_error(
                    f"{where} ({self.parameter})",
                    k,
                    v,
                    f"a magnitude <= {FACTOR_MAGNITUDE:g} (the analysis takes cubes of actual values)",
                )
        if low == high:
            raise StudyError(
                f"{where}: low = {low!r} and high = {high!r} are not allowed; expected two "
                "different values (low > high is a reversed coding)"
            )
        object.__setattr__(self, "low", low)
        object.__setattr__(self, "high", high)
        _string(where, "label", self.label)
        _string(where, "unit", self.unit)

    @property
    def factor(self) -> Factor:
        """The coding of this factor (:class:`warpdem.study.designs.Factor`)."""
        return Factor(self.name, self.low, self.high, self.unit)


_KIND_OPTIONS = {
    "plackett_burman": {"runs", "center_points"},
    "full_factorial": {"center_points"},
    "fractional_factorial": {"generators", "center_points"},
    "box_behnken": {"center_points"},
    "central_composite": {"alpha", "center_points"},
    "steepest_ascent": {"base", "base_step", "steps", "coefficients", "start", "step", "descent"},
    "explicit": {"points"},
}
_OPTIONS = (
    "runs",
    "generators",
    "alpha",
    "center_points",
    "base",
    "base_step",
    "steps",
    "coefficients",
    "start",
    "step",
    "descent",
    "points",
)


@dataclass(frozen=True)
class DesignSpec:
    """The design of experiments (``[design]``); options that do not apply to ``kind`` must stay None.

    Factor-dependent checks (generators naming factors, a coefficient per factor, the number of factors a
    kind holds) are made by :class:`StudySpec`, which knows the factors.
    """

    kind: str
    runs: int | None = None
    generators: tuple[str, ...] | None = None
    alpha: float | str | None = None
    center_points: int | None = None
    replicates: int = 1
    randomize: bool = True
    base: str | None = None
    base_step: float | None = None
    steps: int | None = None
    coefficients: Mapping[str, float] | None = None
    start: Mapping[str, float] | None = None
    step: Mapping[str, float] | None = None
    descent: bool | None = None
    points: tuple[Mapping[str, float], ...] | None = None

    def __post_init__(self):
        w = "[design]"
        if self.kind not in DESIGN_KINDS:
            raise spec_error(
                w, "kind", self.kind, f"one of {', '.join(DESIGN_KINDS)}{did_you_mean(self.kind, DESIGN_KINDS)}"
            )
        for opt in _OPTIONS:
            if getattr(self, opt) is not None and opt not in _KIND_OPTIONS[self.kind]:
                kinds = [k for k, o in _KIND_OPTIONS.items() if opt in o]
                raise StudyError(
                    f"{w}: {opt} = {getattr(self, opt)!r} is not allowed with kind = {self.kind!r}; "
                    f"it applies to {', '.join(kinds)}"
                )
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731
        set_("replicates", spec_integer(w, "replicates", self.replicates, 1))
        set_("randomize", _boolean(w, "randomize", self.randomize))
        if self.runs is not None:
            if not is_number(self.runs) or self.runs not in (12, 20):
                raise spec_error(w, "runs", self.runs, "12 or 20 (Plackett-Burman runs)")
            set_("runs", int(self.runs))
        if self.center_points is not None:
            set_("center_points", spec_integer(w, "center_points", self.center_points, 0))
            if self.kind == "box_behnken" and self.center_points < 1:
                raise spec_error(
                    w,
                    "center_points",
                    self.center_points,
                    "an integer >= 1 (a Box-Behnken design without a centre run cannot fit a quadratic)",
                )
        if self.kind == "fractional_factorial":
            gens = self.generators
            if gens is None:
                raise StudyError(
                    f'{w}: generators is missing; kind = "fractional_factorial" needs a list of '
                    'generator strings, e.g. ["E = ABCD"]'
                )
            if isinstance(gens, str):
                gens = [gens]
            if not gens or not isinstance(gens, (list, tuple)) or not all(isinstance(g, str) for g in gens):
                raise spec_error(w, "generators", self.generators, 'a list of generator strings, e.g. ["E = ABCD"]')
            set_("generators", tuple(gens))
        if self.alpha is not None:
            if isinstance(self.alpha, str):
                if self.alpha.lower() not in ("rotatable", "orthogonal", "face"):
                    raise spec_error(w, "alpha", self.alpha, 'a number > 0, "rotatable", "orthogonal" or "face"')
                set_("alpha", self.alpha.lower())
            elif not is_number(self.alpha) or not (math.isfinite(self.alpha) and self.alpha > 0):
                raise spec_error(w, "alpha", self.alpha, 'a number > 0, "rotatable", "orthogonal" or "face"')
            else:
                set_("alpha", float(self.alpha))
        if self.kind == "steepest_ascent":
            if self.steps is None:
                raise StudyError(f"{w}: steps is missing; expected the number of runs on the path (start included)")
            set_("steps", spec_integer(w, "steps", self.steps, 2))
            by_step = self.step is not None
            by_gradient = any(getattr(self, k) is not None for k in ("coefficients", "base", "base_step"))
            if by_step == by_gradient:
                raise StudyError(
                    f"{w}: a steepest_ascent path needs either step = {{factor = actual step, ...}} "
                    "or coefficients, base and base_step (not both, not neither)"
                )
            if by_gradient:
                for k in ("coefficients", "base", "base_step"):
                    if getattr(self, k) is None:
                        raise StudyError(f"{w}: {k} is missing; a gradient path needs coefficients, base and base_step")
                _string(w, "base", self.base)
                bs = spec_number(w, "base_step", self.base_step)
                if bs <= 0:
                    raise spec_error(w, "base_step", self.base_step, "a step > 0 in the base factor's actual units")
                set_("base_step", bs)
                set_("descent", _boolean(w, "descent", self.descent if self.descent is not None else False))
            elif self.descent is not None:
                raise StudyError(
                    f"{w}: descent = {self.descent!r} is not allowed with step = {{...}}; the sign of "
                    "each step gives the direction"
                )
            for k in ("coefficients", "start", "step"):
                v = getattr(self, k)
                if v is not None:
                    names = list(v) if isinstance(v, Mapping) else []
                    set_(k, _mapping(w, k, v, names, need_all=False))
        if self.kind == "explicit":
            pts = self.points
            if not isinstance(pts, (list, tuple)) or not pts or not all(isinstance(p, Mapping) for p in pts):
                raise spec_error(w, "points", pts, "a non-empty list of tables {factor = actual value, ...}")
            set_("points", tuple(_mapping(w, f"points[{i}]", p, list(p), need_all=False) for i, p in enumerate(pts)))


@dataclass(frozen=True)
class ResponseSpec:
    """A response: the metric ``measure`` read from each run, its ``unit``, an optional ``target``, and an
    optional desirability ``goal`` (:data:`goals.GOALS`; ``target`` uses ``target``) with its limits ``low``,
    ``high``, shape ``weight`` (``weight_high`` above a target) and ``importance`` (1 to 5); optional
    ``transform``, ``transform_power`` and ``transform_k`` in place of ``[analysis]``'s."""

    name: str
    measure: str
    unit: str = ""
    target: float | None = None
    goal: str | None = None
    low: float | None = None
    high: float | None = None
    weight: float = 1.0
    weight_high: float | None = None
    importance: int = 3
    transform: str | None = None
    transform_power: float | None = None
    transform_k: float | None = None

    def __post_init__(self):
        if not isinstance(self.name, str) or not _FACTOR_RE.match(self.name):
            raise spec_error("[[responses]]", "name", self.name, "letters, digits and _ starting with a letter")
        where = f"[[responses]] {self.name!r}"
        m = self.measure
        if not isinstance(m, str) or not m or ("." not in m and m not in MEASURES):
            raise spec_error(
                where,
                "measure",
                m,
                f"a metric key: {', '.join(MEASURES)}{did_you_mean(m, MEASURES)}, or a dotted path into the metrics",
            )
        _string(where, "unit", self.unit)
        if self.transform is not None or self.transform_power is not None or self.transform_k is not None:
            _transform(where, self.transform or "none", self.transform_power, self.transform_k or 0.0)
        if self.target is not None:
            object.__setattr__(self, "target", spec_number(where, "target", self.target))
        if self.goal is None:
            given = [k for k in ("low", "high", "weight_high") if getattr(self, k) is not None]
            if given:
                raise spec_error(
                    where, given[0], getattr(self, given[0]), f"a goal ({' | '.join(GOALS)}) to go with it"
                )
            return
        if self.goal not in GOALS:
            raise spec_error(where, "goal", self.goal, " | ".join(GOALS) + did_you_mean(str(self.goal), GOALS))
        for k in ("low", "high"):
            if getattr(self, k) is None:
                raise spec_error(where, k, None, f"a number: the {self.goal} goal needs both low and high")
            object.__setattr__(self, k, spec_number(where, k, getattr(self, k)))
        try:
            self.desirability_goal()
        except ValueError as e:
            raise StudyError(f"{where}: {str(e).removeprefix('Goal: ')}") from None

    def desirability_goal(self) -> Goal | None:
        """The response's :class:`goals.Goal`, or None without a goal."""
        if self.goal is None:
            return None
        return Goal(
            self.goal,
            float(self.low),
            float(self.high),
            self.target,
            float(self.weight),
            None if self.weight_high is None else float(self.weight_high),
            self.importance,
        )


@dataclass(frozen=True)
class AnalysisSpec:
    """The regression: ``model`` (``linear``, ``2fi``, ``quadratic``, ``none`` or a tuple of terms), the
    significance level ``alpha`` and whether to ``eliminate`` terms (hierarchical backward elimination).
    ``model = None`` takes the design kind's default (see the module docstring). ``transform``
    (:data:`transforms.TRANSFORMS`), with ``transform_power`` (its exponent, for ``power``) and ``transform_k``
    (a constant added first): every response's model is fitted to f(y + k), unless its ``[[responses]]`` entry
    names its own."""

    model: str | tuple[str, ...] | None = None
    alpha: float = 0.05
    eliminate: bool = False
    transform: str = "none"
    transform_power: float | None = None
    transform_k: float = 0.0

    def __post_init__(self):
        w = "[analysis]"
        m = self.model
        if isinstance(m, str):
            if m.lower() not in ("linear", "2fi", "quadratic", "none"):
                raise spec_error(
                    w,
                    "model",
                    m,
                    'linear, 2fi, quadratic, none or a list of terms such as ["A", "A*B", "A^2"]'
                    + did_you_mean(m.lower(), ("linear", "2fi", "quadratic", "none")),
                )
            object.__setattr__(self, "model", m.lower())
        elif m is not None:
            if not isinstance(m, (list, tuple)) or not m or not all(isinstance(t, str) for t in m):
                raise spec_error(
                    w, "model", m, 'linear, 2fi, quadratic, none or a list of terms such as ["A", "A*B", "A^2"]'
                )
            object.__setattr__(self, "model", tuple(m))
        a = spec_number(w, "alpha", self.alpha)
        if not 0 < a < 1:
            raise spec_error(w, "alpha", self.alpha, "a significance level in (0, 1)")
        object.__setattr__(self, "alpha", a)
        object.__setattr__(self, "eliminate", _boolean(w, "eliminate", self.eliminate))
        _transform(w, self.transform, self.transform_power, self.transform_k)

    def transform_for(self, response: ResponseSpec) -> Transform:
        """The transform ``response`` 's model is fitted to: its own, else this table's."""
        if response.transform is not None or response.transform_power is not None or response.transform_k is not None:
            return Transform(response.transform or "none", response.transform_power, response.transform_k or 0.0)
        return Transform(self.transform, self.transform_power, self.transform_k)


@dataclass(frozen=True)
class VerificationSpec:
    """Verification runs at the chosen optimum (``replicates``; 0: none)."""

    replicates: int = 0

    def __post_init__(self):
        object.__setattr__(self, "replicates", spec_integer("[verification]", "replicates", self.replicates, 0))


_DEFAULT_MODEL = {
    "plackett_burman": "linear",
    "full_factorial": "linear",
    "fractional_factorial": "linear",
    "box_behnken": "quadratic",
    "central_composite": "quadratic",
    "steepest_ascent": "none",
    "explicit": "none",
}


def check_header(spec, w: str, doc: str) -> None:
    """Check (and normalise, in place) the scene fields that a study and a diagnosis share in their first table
    ``w``: name, title, rig or scene (relative to the ``doc``, e.g. "study file"), smoke, path, seed and batch."""
    set_ = lambda k, v: object.__setattr__(spec, k, v)  # noqa: E731
    if not isinstance(spec.name, str) or not _NAME_RE.match(spec.name):
        raise spec_error(w, "name", spec.name, "an identifier of lower-case letters, digits and _")
    _string(w, "title", spec.title)
    rigs = _rigs()
    if (spec.rig is None) == (spec.scene is None):
        raise StudyError(
            f"{w}: rig = {spec.rig!r}, scene = {spec.scene!r}: expected exactly one of rig "
            f"({', '.join(rigs.RIGS)}) and scene (a stage path relative to the {doc})"
        )
    if spec.rig is not None and spec.rig not in rigs.RIGS:
        raise spec_error(w, "rig", spec.rig, f"one of {', '.join(rigs.RIGS)}{did_you_mean(spec.rig, rigs.RIGS)}")
    set_("smoke", _boolean(w, "smoke", spec.smoke))
    if spec.path is not None:
        set_("path", Path(spec.path))
    if spec.scene is not None:
        _string(w, "scene", spec.scene)
        if spec.smoke:
            raise StudyError(
                f"{w}: smoke = true is not allowed with scene = {spec.scene!r}; the smoke "
                "overrides belong to a rig (use rig = ...)"
            )
        if not spec.scene_path.is_file():
            raise StudyError(
                f"{w}: scene = {spec.scene!r} is not allowed: {spec.scene_path} does not exist; "
                f"expected a stage path relative to the {doc}"
            )
    set_("seed", spec_integer(w, "seed", spec.seed, 0))
    set_("batch", spec_integer(w, "batch", spec.batch, 0))


def check_fixed(fixed, rig: str | None) -> FrozenMap:
    """``[fixed]``: override keys of ``rig`` (see :func:`override_grammar`), each a string, a boolean or a finite number."""
    if not isinstance(fixed, Mapping):
        raise spec_error("[fixed]", "fixed", fixed, "a table of overrides")
    for k, v in fixed.items():
        override_grammar(rig, False).parse(k, "[fixed]", error=StudyError)
        if not isinstance(v, (str, bool, int, float)) or (is_number(v) and not math.isfinite(v)):
            raise spec_error("[fixed]", k, v, "a string, a boolean or a finite number")
    return FrozenMap(fixed)


def check_factors(factors, rig: str | None, fixed: Mapping, kind: type[FactorSpec], noun: str) -> tuple:
    """The factors (``kind`` instances, at least one) as a tuple, refused when two share a name or a parameter,
    a parameter is not a numeric override key of ``rig`` or ``fixed`` sets it too; ``noun`` is what a message
    calls one ("factor")."""
    table = kind.table
    factors = tuple(factors)
    if not factors or not all(isinstance(f, kind) for f in factors):
        raise StudyError(f"{table}: expected at least one {noun} table (name, parameter, low, high)")
    names = [f.name for f in factors]
    params = [f.parameter for f in factors]
    for i, f in enumerate(factors):
        if f.name in names[:i]:
            raise StudyError(
                f"{table} {f.name!r}: name = {f.name!r} is not allowed; the name is used "
                f"twice, expected unique {noun} names"
            )
        if f.parameter in params[:i]:
            other = names[params.index(f.parameter)]
            raise StudyError(
                f"{table} {f.name!r}: parameter = {f.parameter!r} is not allowed; {noun} "
                f"{other!r} already sets it, expected one {noun} per parameter"
            )
        override_grammar(rig, True).parse(f.parameter, f"{table} {f.name!r}", "parameter", error=StudyError)
        if f.parameter in fixed:
            raise StudyError(
                f"{table} {f.name!r}: parameter = {f.parameter!r} is not allowed; [fixed] sets "
                f"it too, expected a parameter that is either fixed or a {noun}"
            )
    return factors


@dataclass(frozen=True)
class StudySpec:
    """A whole study (one TOML file). ``path`` is the TOML file (scene paths are relative to it);
    ``fixed`` holds the overrides every run shares. Validated at construction, design included."""

    name: str
    factors: tuple[FactorSpec, ...]
    design: DesignSpec
    responses: tuple[ResponseSpec, ...]
    title: str = ""
    source: str = ""
    rig: str | None = None
    scene: str | None = None
    smoke: bool = False
    seed: int = 1
    batch: int = 0
    fixed: Mapping[str, Any] = field(default_factory=dict)
    analysis: AnalysisSpec = field(default_factory=AnalysisSpec)
    verification: VerificationSpec = field(default_factory=VerificationSpec)
    path: Path | None = None

    def __post_init__(self):
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731
        check_header(self, "[study]", "study file")
        _string("[study]", "source", self.source)
        set_("fixed", check_fixed(self.fixed, self.rig))
        set_("factors", check_factors(self.factors, self.rig, self.fixed, FactorSpec, "factor"))

        # responses, analysis, verification
        responses = tuple(self.responses)
        if not responses or not all(isinstance(r, ResponseSpec) for r in responses):
            raise StudyError("[[responses]]: expected at least one response table (name, measure)")
        rn = [r.name for r in responses]
        dup = next((n for i, n in enumerate(rn) if n in rn[:i]), None)
        if dup:
            raise StudyError(f"[[responses]] {dup!r}: name = {dup!r} is not allowed; expected unique response names")
        set_("responses", responses)
        if not isinstance(self.design, DesignSpec):
            raise spec_error("[design]", "design", self.design, "a [design] table")
        if self.analysis.model is None:
            set_("analysis", dataclasses.replace(self.analysis, model=_DEFAULT_MODEL[self.design.kind]))
        self._check_design()
        self._check_model()

    # -- checks that need factors and design together ------------------------------------------------
    def _check_design(self):
        d, names, w = self.design, self.factor_names, "[design]"
        k = len(names)
        if d.kind == "plackett_burman" and d.runs is not None and k > d.runs - 1:
            raise spec_error(
                w,
                "runs",
                d.runs,
                f"more runs than factors: a {d.runs}-run Plackett-Burman design holds at "
                f"most {d.runs - 1} factors, this study has {k}",
            )
        if d.kind == "box_behnken" and k not in (3, 4, 5):
            raise StudyError(f"{w}: kind = 'box_behnken' is not allowed with {k} factors; expected 3, 4 or 5")
        if d.kind == "central_composite" and k < 2:
            raise StudyError(f"{w}: kind = 'central_composite' is not allowed with {k} factor; expected >= 2")
        if d.kind == "steepest_ascent":
            for key in ("coefficients", "step"):
                v = getattr(d, key)
                if v is not None:
                    _mapping(w, key, v, names, need_all=True)
            if d.start is not None:
                _mapping(w, "start", d.start, names, need_all=True)
            if d.base is not None:
                if d.base not in names:
                    raise spec_error(
                        w, "base", d.base, f"a factor name: {', '.join(names)}{did_you_mean(d.base, names)}"
                    )
                if d.coefficients[d.base] == 0:
                    raise spec_error(w, f"coefficients.{d.base}", 0.0, "a non-zero coefficient for the base factor")
            if d.step is not None and all(v == 0 for v in d.step.values()):
                raise spec_error(w, "step", dict(d.step), "at least one non-zero step")
        if d.kind == "explicit":
            for i, p in enumerate(d.points):
                _mapping(w, f"points[{i}]", p, names, need_all=True)
        try:
            _base_design(self)
        except StudyError:
            raise
        except ValueError as e:
            raise StudyError(f"{w}: kind = {d.kind!r} cannot be built for factors {', '.join(names)}: {e}") from None

    def _check_model(self):
        m = self.analysis.model
        if m == "none":
            return
        try:
            terms = model_terms(m if isinstance(m, str) else list(m), self.factor_names)
        except ValueError as e:
            raise spec_error(
                "[analysis]",
                "model",
                m if isinstance(m, str) else list(m),
                f"terms of the factors {', '.join(self.factor_names)}: {e}",
            ) from None
        coded = _base_design(self)[0][self.factor_names].to_numpy(dtype=float)
        cols = [np.ones(len(coded))] + [
            np.prod([coded[:, self.factor_names.index(f)] for f in t], axis=0) for t in terms
        ]
        X = np.column_stack(cols)
        rank = np.linalg.matrix_rank(X)
        if rank < X.shape[1]:
            raise spec_error(
                "[analysis]",
                "model",
                m if isinstance(m, str) else list(m),
                f"a model the {self.design.kind} design can estimate ({X.shape[1]} parameters, but the "
                f"design's distinct points give rank {rank}; aliased terms)",
            )

    # -- properties ----------------------------------------------------------------------------------
    @property
    def factor_names(self) -> list[str]:
        return [f.name for f in self.factors]

    @property
    def levels(self) -> list[Factor]:
        """The factors' codings, in factor order."""
        return [f.factor for f in self.factors]

    @property
    def scene_path(self) -> Path | None:
        """The stage file (``scene`` relative to the study file), or None for a rig study."""
        if self.scene is None:
            return None
        base = self.path.parent if self.path is not None else Path.cwd()
        return (base / self.scene).resolve()

    def factor(self, name: str) -> FactorSpec:
        for f in self.factors:
            if f.name == name:
                return f
        raise KeyError(f"no factor {name!r}; factors: {', '.join(self.factor_names)}")

    @classmethod
    def from_dict(cls, data: Mapping, path: str | Path | None = None) -> StudySpec:
        """Study from parsed TOML ``data``; errors are prefixed with ``path`` (or ``<dict>``)."""
        where = str(path) if path is not None else "<dict>"
        try:
            return _from_dict(data, path)
        except StudyError as e:
            raise StudyError(f"{where}: {e}") from None


# --------------------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------------------

_TABLES = {
    "study": ("name", "title", "source", "rig", "scene", "smoke", "seed", "batch"),
    "fixed": None,
    "factors": ("name", "label", "parameter", "low", "high", "unit"),
    "design": ("kind", "replicates", "randomize") + _OPTIONS,
    "responses": (
        "name",
        "measure",
        "unit",
        "target",
        "goal",
        "low",
        "high",
        "weight",
        "weight_high",
        "importance",
        "transform",
        "transform_power",
        "transform_k",
    ),
    "analysis": ("model", "alpha", "eliminate", "transform", "transform_power", "transform_k"),
    "verification": ("replicates",),
}
_REQUIRED = {
    "study": ("name",),
    "factors": ("name", "parameter", "low", "high"),
    "design": ("kind",),
    "responses": ("name", "measure"),
}


def check_table_keys(table: str, data, label: str, tables=None, required=None, arrays=("factors", "responses")) -> dict:
    """``data`` (TOML table ``table``, called ``label`` in messages) as a dict, refused unless it is a table whose
    keys are all allowed (``tables``, default a study's) and that holds every required key (``required``);
    ``arrays`` are the tables written [[name]]."""
    tables = _TABLES if tables is None else tables
    required = _REQUIRED if required is None else required
    if not isinstance(data, Mapping):
        kind = "[[" + table + "]]" if table in arrays else "[" + table + "]"
        raise StudyError(f"{label}: expected a table ({kind}), got {data!r}")
    allowed = tables[table]
    for k in data:
        if k not in allowed:
            raise StudyError(
                f"{label}: key {k!r} is not allowed{did_you_mean(k, allowed)}; expected one of {', '.join(allowed)}"
            )
    for k in required.get(table, ()):
        if k not in data:
            raise StudyError(f"{label}: {k} is missing; required: {', '.join(required[table])}")
    return dict(data)


def flatten_keys(d: Mapping, prefix: str = "") -> dict:
    """A bare dotted TOML key (interaction.grain.grain.restitution = 0.37) is a nested table: flatten it."""
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping):
            out.update(flatten_keys(v, key + "."))
        else:
            out[key] = v
    return out


def _from_dict(data: Mapping, path) -> StudySpec:
    if not isinstance(data, Mapping):
        raise StudyError(f"expected a TOML document with tables, got {data!r}")
    for t in data:
        if t not in _TABLES:
            raise StudyError(
                f"table [{t}] is not allowed{did_you_mean(t, _TABLES)}; expected "
                + ", ".join(f"[{x}]" for x in _TABLES)
            )
    for t in ("study", "factors", "design", "responses"):
        if t not in data:
            raise StudyError(f"table [{t}] is missing; a study needs [study], [[factors]], [design] and [[responses]]")
    study = check_table_keys("study", data["study"], "[study]")
    fixed = data.get("fixed", {})
    if not isinstance(fixed, Mapping):
        raise StudyError(f"[fixed]: expected a table of overrides, got {fixed!r}")
    fixed = flatten_keys(fixed)
    for t in ("factors", "responses"):
        if not isinstance(data[t], list):
            raise StudyError(f"[{t}]: expected an array of tables, written [[{t}]] (one per {t[:-1]})")
    factors = []
    for i, f in enumerate(data["factors"]):
        label = f"[[factors]] #{i + 1}" + (f" {f['name']!r}" if isinstance(f, Mapping) and "name" in f else "")
        factors.append(FactorSpec(**check_table_keys("factors", f, label)))
    responses = []
    for i, r in enumerate(data["responses"]):
        label = f"[[responses]] #{i + 1}" + (f" {r['name']!r}" if isinstance(r, Mapping) and "name" in r else "")
        responses.append(ResponseSpec(**check_table_keys("responses", r, label)))
    design = DesignSpec(**check_table_keys("design", data["design"], "[design]"))
    analysis = AnalysisSpec(**check_table_keys("analysis", data.get("analysis", {}), "[analysis]"))
    for r in responses:
        # a target the transform cannot take would stop the analysis after every run: refuse it here
        if r.target is not None:
            try:
                analysis.transform_for(r).forward(r.target, "target")
            except ValueError as e:
                raise StudyError(f"[[responses]] {r.name!r}: {e}") from None
    verification = VerificationSpec(**check_table_keys("verification", data.get("verification", {}), "[verification]"))
    return StudySpec(
        factors=tuple(factors),
        design=design,
        responses=tuple(responses),
        fixed=fixed,
        analysis=analysis,
        verification=verification,
        path=Path(path) if path is not None else None,
        **study,
    )


def read_toml(path: Path, what: str, error: type[StudyError] = StudyError) -> dict:
    """The parsed TOML file ``path`` (a ``what`` file: "study", "diagnosis"); a missing file or bad TOML raises
    ``error`` naming the file."""
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except FileNotFoundError:
        raise error(f"{path}: no such {what} file") from None
    except IsADirectoryError:
        raise error(f"{path}: is a folder; expected a {what} file (TOML)") from None
    try:
        return tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as e:
        raise error(
            f"{path}: is not UTF-8 text (byte {e.start}); expected a {what} file in TOML, saved as UTF-8"
        ) from None
    except tomllib.TOMLDecodeError as e:
        raise error(f"{path}: not valid TOML: {e}") from None


def load_study(path: str | Path, check_scene: bool = True) -> StudySpec:
    """Read and validate a study file (TOML, schema in the module docstring).

    With ``check_scene`` (default) the scene is also built once (rig or stage) and ``[fixed]`` and each
    factor's extreme design values are applied to it, so that unknown materials, rig parameter values the
    rig refuses and contact parameters the law refuses are reported here. Raises :class:`StudyError`.
    """
    path = Path(path)
    spec = StudySpec.from_dict(read_toml(path, "study", StudyError), path)
    if check_scene:
        try:
            check_scene_overrides(spec)
        except StudyError as e:
            raise StudyError(f"{path}: {e}") from None
    return spec


def build_scene(spec, rig_values: Mapping | None = None):
    """The scene of ``spec`` (a :class:`StudySpec`, or anything with ``rig``, ``smoke``, ``scene_path``): the rig
    built from ``rig_values`` (over its smoke set with ``smoke``), or the stage regenerated with them. Raises what
    the rig or the stage raises (``StageError``, ``ValueError``, ``KeyError``)."""
    rigs = _rigs()
    if spec.rig is not None:
        return rigs.spec(spec.rig, dict(rig_values or {}), spec.smoke)
    return rigs.load(spec.scene_path, dict(rig_values or {}))


def fixed_scene(spec, rig_values: Mapping | None = None):
    """The scene of ``spec`` (see :func:`build_scene`) with its ``fixed`` overrides applied, and the rig
    parameters ``rig_values`` over them (a diagnosis's conditions, which a scene may need to be built at all);
    raise :class:`StudyError` naming the ``[fixed]`` key and value the scene or the contact law refuses."""
    from warpdem.scene.stage import StageError, apply_overrides

    rig_vals = {**{k: v for k, v in spec.fixed.items() if is_rig_key(k)}, **(rig_values or {})}
    try:
        base = build_scene(spec, rig_vals)
    except (StageError, ValueError, KeyError) as e:
        keys = ", ".join(f"{k} = {v!r}" for k, v in rig_vals.items()) or "(no rig parameters)"
        raise StudyError(f"[fixed]: the scene cannot be built from {keys}: {e}") from None
    for k, v in spec.fixed.items():
        if is_rig_key(k):
            continue
        try:
            apply_overrides(base, {k: v}, where="[fixed]")
        except StageError as e:
            raise StudyError(str(e)) from None
        except (ValueError, KeyError, TypeError) as e:
            raise StudyError(f"[fixed]: {k} = {v!r} is not allowed: {e}") from None
    return base


def check_override(spec, base, key: str, value, where: str = "--set") -> None:
    """Apply override ``key = value`` to a copy of ``base`` (the scene of :func:`fixed_scene`; a rig parameter is
    checked by the rig's parameters over those ``base`` was authored with). Raises what the scene or the contact
    law raises (``StageError``, ``ValueError``, ``KeyError``, ``TypeError``)."""
    from warpdem.scene.stage import apply_overrides

    if is_rig_key(key):
        rig_vals = {k: v for k, v in spec.fixed.items() if is_rig_key(k)}
        _rigs().params(base.rig, {**base.authoring, **rig_vals, key: rig_value(spec, key, value)})
    else:
        apply_overrides(copy.deepcopy(base), {key: value}, where=where)


def check_scene_overrides(spec: StudySpec) -> None:
    """Build the study's scene and apply ``[fixed]`` and every factor's lowest and highest design value
    to it; raise :class:`StudyError` naming the key and value the scene or the contact law refuses, or the run
    that repeats a point of a scene a world seed does not move (:func:`warpdem.scene.stage.world_seeds_move`)."""
    from warpdem.scene.stage import StageError, world_seeds_move

    base = fixed_scene(spec)
    table = design_table(spec)
    if not world_seeds_move(base):
        repeats = table[table["world_seed"] > 0]
        if len(repeats) or spec.verification.replicates > 1:
            what = (
                f"[design]: run {int(repeats['run'].iloc[0])} repeats an earlier point with world seed "
                f"{int(repeats['world_seed'].iloc[0])}"
                if len(repeats)
                else f"[verification]: replicates = {spec.verification.replicates} repeat one point with world seeds"
            )
            fills = ", ".join(repr(f.name) for f in base.factories) or "none"
            raise StudyError(
                f"{what}, but the scene's particles come from static fills only (factories: {fills}), which a world "
                "seed does not move: the repeats would be identical runs. Make them differ through the rig's own "
                "seed (a factor on parameter 'seed' with explicit points) or drop them"
            )
    for f in spec.factors:
        col = table[f"{f.name}_actual"]
        for which, v in (("lowest", float(col.min())), ("highest", float(col.max()))):
            where = f"[[factors]] {f.name!r} at the design's {which} value"
            try:
                check_override(spec, base, f.parameter, v, where)
            except StageError as e:
                raise StudyError(str(e)) from None
            except (ValueError, KeyError, TypeError) as e:
                raise StudyError(
                    f"[[factors]] {f.name!r}: parameter {f.parameter} = {v!r} (the design's {which} "
                    f"value) is not allowed: {e}"
                ) from None


# --------------------------------------------------------------------------------------------------
# the design table
# --------------------------------------------------------------------------------------------------


def _base_design(spec: StudySpec) -> tuple[pd.DataFrame, pd.DataFrame | None]:
    """(coded design in standard order with a ``point_type`` column, actual values or None).

    Actual values are given (not derived from the coding) for explicit points."""
    d, names = spec.design, spec.factor_names
    k = len(names)
    levels = {f.name: f.factor for f in spec.factors}
    actual = None
    if d.kind == "plackett_burman":
        runs = d.runs or (12 if k <= 11 else 20)
        df = designs.plackett_burman(names, runs, center_points=d.center_points or 0)
    elif d.kind == "full_factorial":
        df = designs.full_factorial(names, center_points=d.center_points or 0)
    elif d.kind == "fractional_factorial":
        df = designs.fractional_factorial(names, list(d.generators), center_points=d.center_points or 0)
    elif d.kind == "box_behnken":
        df = designs.box_behnken(names, d.center_points)
    elif d.kind == "central_composite":
        df = designs.central_composite(
            names,
            alpha=d.alpha if d.alpha is not None else "rotatable",
            center_points=6 if d.center_points is None else d.center_points,
        )
    elif d.kind == "steepest_ascent":
        start = dict(d.start) if d.start is not None else None
        if d.step is not None:
            dx = {n: d.step[n] / levels[n].half_range for n in names}  # coded step per factor
            base = max(names, key=lambda n: abs(dx[n]))
            x0 = {n: float(levels[n].to_coded(start[n])) for n in names} if start else None
            path = designs.steepest_path(dx, base, abs(dx[base]), d.steps - 1, levels, x0, "coded")
        else:
            path = designs.steepest_path(
                dict(d.coefficients), d.base, d.base_step, d.steps - 1, levels, start, "actual", descent=bool(d.descent)
            )
        df = path[names].copy()
        df["kind"] = "path"
    else:  # explicit
        actual = pd.DataFrame([[p[n] for n in names] for p in d.points], columns=names)
        df = pd.DataFrame({n: levels[n].to_coded(actual[n].to_numpy(dtype=float)) for n in names})
        df["kind"] = "point"
    df = df.reset_index(drop=True)
    df["point_type"] = [_POINT_TYPE.get(x, x) for x in df.pop("kind")]
    return df, actual


def design_table(spec: StudySpec) -> pd.DataFrame:
    """One row per run, in run order (columns in the module docstring)."""
    names = spec.factor_names
    base, given = _base_design(spec)
    n, reps = len(base), spec.design.replicates
    coded = np.vstack([base[names].to_numpy(dtype=float)] * reps)
    if given is not None:
        actual = np.vstack([given[names].to_numpy(dtype=float)] * reps)
    else:
        actual = np.column_stack([f.factor.to_actual(coded[:, j]) for j, f in enumerate(spec.factors)])
    actual = np.vectorize(_round, otypes=[float])(actual)
    coded = np.round(coded, 12) + 0.0
    tab = pd.DataFrame(
        {
            "std_order": np.arange(1, n * reps + 1),
            "point_type": list(base["point_type"]) * reps,
            "replicate": np.repeat(np.arange(reps), n),
        }
    )
    seen: dict[tuple, int] = {}
    seeds = []
    for row in actual:
        key = tuple(row)
        seeds.append(seen.get(key, 0))
        seen[key] = seeds[-1] + 1
    tab["world_seed"] = seeds
    for j, name in enumerate(names):
        tab[name] = coded[:, j]
    for j, name in enumerate(names):
        tab[f"{name}_actual"] = actual[:, j]
    tab["point_id"] = [_point_id(spec, tab.iloc[i]) for i in range(len(tab))]
    if spec.design.randomize:
        tab = designs.randomize(tab, spec.seed).drop(columns="run_order")
    tab = tab.reset_index(drop=True)
    tab.insert(0, "run", np.arange(1, len(tab) + 1))
    return tab


def _canon(v):
    if is_number(v):
        return _round(v)
    return v


def _point_id(spec: StudySpec, row) -> str:
    return point_key(spec, run_overrides(spec, row), int(row["world_seed"]))


def point_key(spec: StudySpec, overrides: Mapping, world_seed: int) -> str:
    """The identity of one simulated world: a short sha1 of the scene (rig and smoke, or the stage path as
    written), its ``overrides`` (numbers to 12 significant digits) and its ``world_seed``."""
    scene = {"rig": spec.rig, "smoke": spec.smoke} if spec.rig is not None else {"scene": spec.scene}
    ov = {k: _canon(v) for k, v in overrides.items()}
    text = json.dumps({"scene": scene, "overrides": ov, "world_seed": int(world_seed)}, sort_keys=True)
    return hashlib.sha1(text.encode()).hexdigest()[:12]


def rig_value(spec: StudySpec, key: str, v: float):
    """A rig parameter value in its field's type (an integer parameter gets an int when v is integral)."""
    rig = spec.rig
    if rig is None:
        return v
    d = rig_fields(rig)[key].default
    if isinstance(d, int) and not isinstance(d, bool) and float(v) == int(v):
        return int(v)
    return v


def run_overrides(spec: StudySpec, row) -> dict:
    """``spec.fixed`` merged with every factor's ``parameter -> actual value`` of design-table ``row``
    (a row of :func:`design_table`, or any mapping with the ``<name>_actual`` values)."""
    out = dict(spec.fixed)
    for f in spec.factors:
        v = float(row[f"{f.name}_actual"])
        out[f.parameter] = rig_value(spec, f.parameter, v) if is_rig_key(f.parameter) else v
    return out


def _hashable(v):
    if isinstance(v, (list, tuple)):
        return tuple(_hashable(x) for x in v)
    if isinstance(v, Mapping):
        return tuple(sorted((k, _hashable(x)) for k, x in v.items()))
    if isinstance(v, (np.floating, np.integer)):
        return v.item()
    return v


def batch_key(spec: StudySpec, overrides: Mapping) -> tuple:
    """The overrides that cannot differ between batched worlds (all but ``material.*`` numbers and
    ``interaction.*`` fields, see :func:`varies_per_world`), as a sorted tuple of (key, value): runs with equal keys can
    share one launch."""
    return tuple(sorted((k, _hashable(v)) for k, v in overrides.items() if not varies_per_world(k)))
