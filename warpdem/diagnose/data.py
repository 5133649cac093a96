"""Measured data of a diagnosis: a TOML file (``warpdem diagnose DATA.toml``) naming the scene, the base model's
free parameters and an experiments table, loaded into frozen, validated dataclasses.

A diagnosis file names a scene (a rig of :mod:`warpdem.scene.rigs`, or a USD stage) and the overrides every
simulation shares, as a study file does (:mod:`warpdem.study.spec`), the base model's free parameters with
their physical ranges, and a CSV table of measured experiments: each experiment one set of conditions, its rows
the replicates of the measured responses. :func:`load_diagnosis` reads both.

Every bad input raises :class:`DiagnoseError` (a :class:`~warpdem.study.spec.StudyError`, so a ``ValueError``)
whose message names the file, the table and key (or the line and column of the CSV), the value and what is
allowed (an unknown key or column comes with a "did you mean").

Schema (``DATA.toml``)::

    [diagnose]
    name = "pellet_pile"            # identifier, [a-z0-9_]+ (required)
    title = "..."                   # free text
    rig = "funnel"                  # one of warpdem.scene.rigs.RIGS, or
    # scene = "../scenes/funnel.usda"     # a stage, relative to the TOML (exactly one of rig / scene)
    smoke = false                   # start from rigs.SMOKE[rig] (rig only)
    seed = 1                        # integer >= 0: seeds the designs, the MCMC and the bootstrap (default 1)
    batch = 0                       # most worlds per launch, >= 0 (0: no cap)

    [fixed]                         # overrides of every simulation: rig parameters or override keys, as a
    particle = "sphere"             # study's [fixed] (a bare dotted key is read the same way as a quoted one)
    "material.grain.shear_modulus" = 1.0e6

    [[parameters]]                  # the base model's free parameters, at least one, in order
    name = "mu_s"                   # [A-Za-z][A-Za-z0-9_]* (required)
    parameter = "interaction.grain.grain.static_friction"   # the numeric override key or numeric rig
                                    # parameter it sets, as a study's factor (required)
    low = 0.2                       # physical range, low < high (required)
    high = 1.0
    label = "particle-particle static friction"
    unit = ""

    [experiments]
    file = "experiments.csv"        # the experiments table, relative to the TOML (required)
    curves = "curves/{id}.csv"      # per-experiment force-displacement curves ({id}: the experiment id),
                                    # relative to the TOML (optional; an experiment without a file has none)

    [noise]
    sim_seeds = 4                   # world seeds of the simulation scatter, integer >= 2 (default 4)

    [calibration]
    points = 0                      # space-filling points per condition, integer >= 0 (default 0: 4 + 4 x
                                    # the number of free parameters)
    confirm_seeds = 3               # world seeds of each confirming simulation, integer >= 1 (default 3)
    mcmc_steps = 2000               # MCMC steps per walker, integer >= 100 (default 2000); the chain is
                                    # doubled until its kept half spans 50 autocorrelation times (at most
                                    # 8 x mcmc_steps)
    alpha = 0.05                    # significance level of every test, in (0, 0.5) (default 0.05)

    [candidates]
    use = ["cohesion", "plasticity"]    # a subset of diagnose.candidates.CANDIDATE_NAMES (default: every
                                        # candidate that applies; [] tries none)
    ranges = { cohesion = [0.0, 0.2] }  # per candidate [low, high], low < high, replacing its default range
    grain_radius = 1.95e-4              # the measured grains' mean radius [m], > 0, when the scene's grains are
                                        # coarse-grained stand-ins for them (optional; the coarse_graining
                                        # candidate needs it)

``[diagnose]``, ``[[parameters]]`` and ``[experiments]`` are required; the other tables are optional. Free
parameters are read by the factor grammar of :mod:`warpdem.study.spec` (``material.NAME.FIELD``, numeric
``interaction.A.B.FIELD``, ``run.FIELD`` or a numeric rig parameter) and may not be set by ``[fixed]``.

The experiments table (CSV, header on line 1; blank lines are skipped, line numbers count them)::

    id,replicate,split,particle_radius,angle_fit_deg,sd_angle_fit_deg
    r2,1,train,0.002,24.1,0.8
    r2,2,train,0.002,25.0,0.8
    r3,1,test,0.003,27.4,

Columns:

``id`` (required)
    names an experiment (one set of conditions); rows with the same id are its replicates. Read as text.
``replicate``
    integer >= 1, unique within an id (default: 1, 2, ... in file order).
``split``
    ``train`` or ``test``, the same for every row of an id; at least one train experiment. Without the column
    every experiment is ``train`` (the pipeline then holds out one condition at a time).
``<response>``
    a metric of :data:`warpdem.study.spec.MEASURES` (at least one): a number, or empty (not measured); each
    response needs at least one value, and the scene must measure it (``warpdem.scene.runner.measured_metrics``:
    e.g. no ``residual_set_ratio`` on a funnel, no ``bulk_density_kg_m3`` on a funnel without ``gate_time``).
``sd_<response>``
    the stated SD of one measurement of ``<response>`` (the same meaning as the scatter of its replicates):
    a number > 0, or empty (not stated).
any other column
    a condition: an override key (the factor grammar: ``material.NAME.FIELD``, numeric ``interaction.A.B.FIELD``,
    ``run.FIELD``; a number) or a rig parameter (a number, or text for a text parameter such as ``particle``,
    true/false for a boolean one). Every row has a value, the same for every row of an id; a condition may not
    set a key that ``[fixed]`` or a free parameter sets.

With no more measured values (training experiments x the responses each has a value of) than free parameters,
a calibration fits any data it can reach, so the diagnosis asks only which models reach them (:mod:`.reach`).

Curves (``[experiments] curves``): for each experiment whose file exists, a CSV with the numeric columns
``displacement_m`` [m] and ``force_n`` [N] (at least two rows) and an optional ``branch`` (``load`` or
``unload``; default ``load``).

With ``check_scene`` (the default) :func:`load_diagnosis` also builds the scene once with ``[fixed]`` and once
more for each set of rig-parameter conditions, applies every experiment's conditions and each free parameter's
``low`` and ``high`` to it, and refuses a response the experiment's scene does not measure: values the rig, the
scene or the contact law refuse are reported by the loader, naming where they came from, not by a simulation.
"""

from __future__ import annotations

import contextlib
import copy
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

from warpdem.engine.checks import did_you_mean, not_allowed
from warpdem.engine.keys import is_rig_key
from warpdem.study.spec import (
    MEASURES,
    AnalysisSpec,
    DesignSpec,
    FactorSpec,
    FrozenMap,
    ResponseSpec,
    StudyError,
    StudySpec,
    build_scene,
    check_factors,
    check_fixed,
    check_header,
    check_override,
    check_table_keys,
    fixed_scene,
    flatten_keys,
    override_grammar,
    read_toml,
    rig_fields,
    rig_value,
    spec_error,
    spec_integer,
    spec_number,
)

from .candidates import CANDIDATE_NAMES

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["DiagnoseError", "DiagnosisSpec", "Experiments", "ParameterSpec", "load_diagnosis"]


class DiagnoseError(StudyError):
    """A diagnosis file or its data that cannot be used; the message names the file, the table and key (or the
    line and column), the value and what is allowed."""


SPLITS = ("train", "test")
"""Values of the experiments table's ``split`` column."""

CURVE_COLUMNS = ("displacement_m", "force_n", "branch")
"""Columns of a curve file (``branch`` optional)."""

BRANCHES = ("load", "unload")
"""Values of a curve file's ``branch`` column."""

_RESERVED = ("id", "replicate", "split")
_TABLES = {
    "diagnose": ("name", "title", "rig", "scene", "smoke", "seed", "batch"),
    "fixed": None,
    "parameters": ("name", "parameter", "low", "high", "label", "unit"),
    "experiments": ("file", "curves"),
    "noise": ("sim_seeds",),
    "calibration": ("points", "confirm_seeds", "mcmc_steps", "alpha"),
    "candidates": ("use", "ranges", "grain_radius"),
}
_REQUIRED = {
    "diagnose": ("name",),
    "parameters": ("name", "parameter", "low", "high"),
    "experiments": ("file",),
}
_ARRAYS = ("parameters",)
# what a rig parameter sets a measurement up with (runner.METRIC_NEEDS names the MeasureSpec field)
_NEED_HINTS = {("funnel", "packing_time"): "gate_time > 0", ("die_press", "unload_speed"): "unload = true"}
_SCENE_ERRORS = (ValueError, KeyError, TypeError)  # StageError is a ValueError


@contextlib.contextmanager
def _as_diagnose(prefix: str = ""):
    """Raise a :class:`StudyError` of the shared study checks as a :class:`DiagnoseError` (``prefix`` first)."""
    try:
        yield
    except StudyError as e:
        raise DiagnoseError(f"{prefix}{e}") from None


# --------------------------------------------------------------------------------------------------
# the diagnosis file
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ParameterSpec(FactorSpec):
    """A free parameter of the base model: the override ``parameter`` it sets (a study factor's grammar), its
    physical range ``low`` < ``high``, a ``label`` and ``unit`` for reports. A :class:`FactorSpec`, so that the
    study machinery codes it (``factor``: low at -1, high at +1)."""

    table: ClassVar[str] = "[[parameters]]"

    def __post_init__(self):
        lo, hi = _as_number(self.low), _as_number(self.high)
        if lo is not None and hi is not None and lo >= hi:
            raise DiagnoseError(
                f"{self.table} {self.name!r}: low = {self.low!r} and high = {self.high!r} are not allowed; "
                "expected low < high (the parameter's physical range)"
            )
        with _as_diagnose():
            super().__post_init__()


@dataclass(frozen=True, kw_only=True)
class DiagnosisSpec:
    """A whole diagnosis file (schema in the module docstring). ``path`` is the TOML file (the scene, the
    experiments table and the curves are relative to it); ``experiments_file`` and ``curves`` are as written.
    ``candidates`` is None for every candidate that applies; ``candidate_ranges`` maps a candidate name to its
    (low, high); ``grain_radius`` [m] is the measured grains' mean radius (None: the scene's grains are the real
    ones). Validated at construction; the experiments table is read by :func:`load_diagnosis`."""

    name: str
    title: str = ""
    rig: str | None = None
    scene: str | None = None
    smoke: bool = False
    seed: int = 1
    batch: int = 0
    fixed: Mapping[str, Any] = field(default_factory=dict)
    parameters: tuple[ParameterSpec, ...]
    experiments_file: str
    curves: str | None = None
    sim_seeds: int = 4
    points: int = 0
    confirm_seeds: int = 3
    mcmc_steps: int = 2000
    alpha: float = 0.05
    candidates: tuple[str, ...] | None = None
    candidate_ranges: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    grain_radius: float | None = None
    path: Path | None = None

    def __post_init__(self):
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731
        with _as_diagnose():
            check_header(self, "[diagnose]", "diagnosis file")
            set_("fixed", check_fixed(self.fixed, self.rig))
            set_("parameters", check_factors(self.parameters, self.rig, self.fixed, ParameterSpec, "free parameter"))
            w = "[experiments]"
            if not isinstance(self.experiments_file, str) or not self.experiments_file.strip():
                raise spec_error(w, "file", self.experiments_file, "a CSV path relative to the diagnosis file")
            if self.curves is not None and (not isinstance(self.curves, str) or "{id}" not in self.curves):
                raise spec_error(
                    w,
                    "curves",
                    self.curves,
                    'a path with {id} (the experiment id) relative to the diagnosis file, e.g. "curves/{id}.csv"',
                )
            set_("sim_seeds", spec_integer("[noise]", "sim_seeds", self.sim_seeds, 2))
            w = "[calibration]"
            set_("points", spec_integer(w, "points", self.points, 0))
            set_("confirm_seeds", spec_integer(w, "confirm_seeds", self.confirm_seeds, 1))
            set_("mcmc_steps", spec_integer(w, "mcmc_steps", self.mcmc_steps, 100))
            alpha = spec_number(w, "alpha", self.alpha)
            if not 0 < alpha < 0.5:
                raise spec_error(w, "alpha", self.alpha, "a significance level in (0, 0.5)")
            set_("alpha", alpha)
        self._check_candidates()

    def _check_candidates(self):
        w, names = "[candidates]", CANDIDATE_NAMES
        use = self.candidates
        if use is not None:
            if not isinstance(use, (list, tuple)) or not all(isinstance(c, str) for c in use):
                raise DiagnoseError(not_allowed(w, "use", use, f"a list of candidate names: {', '.join(names)}"))
            for i, c in enumerate(use):
                if c not in names:
                    raise DiagnoseError(
                        not_allowed(w, "use", list(use), f"candidate names: {', '.join(names)}")
                        + f"; {c!r} is not a candidate{did_you_mean(c, names)}"
                    )
                if c in use[:i]:
                    raise DiagnoseError(not_allowed(w, "use", list(use), f"each candidate once ({c!r} is twice)"))
            object.__setattr__(self, "candidates", tuple(use))
        ranges = self.candidate_ranges
        if not isinstance(ranges, Mapping):
            raise DiagnoseError(not_allowed(w, "ranges", ranges, "a table {candidate = [low, high], ...}"))
        out = {}
        for c, r in ranges.items():
            if c not in names:
                raise DiagnoseError(
                    f"{w}: ranges names {c!r}, which is not a candidate{did_you_mean(c, names)}; "
                    f"candidates: {', '.join(names)}"
                )
            if use is not None and c not in use:
                raise DiagnoseError(
                    f"{w}: ranges names {c!r}, which use = {list(use)!r} leaves out; expected a range only for a "
                    "candidate that is tried"
                )
            ok = isinstance(r, (list, tuple)) and len(r) == 2
            lo, hi = (_as_number(x) for x in r) if ok else (None, None)
            if lo is None or hi is None:
                raise DiagnoseError(not_allowed(w, f"ranges.{c}", r, "[low, high], two finite numbers"))
            if not lo < hi:
                raise DiagnoseError(not_allowed(w, f"ranges.{c}", list(r), "[low, high] with low < high"))
            out[c] = (lo, hi)
        object.__setattr__(self, "candidate_ranges", FrozenMap(out))
        if self.grain_radius is not None:
            r = _as_number(self.grain_radius)
            if r is None or r <= 0:
                raise DiagnoseError(
                    not_allowed(w, "grain_radius", self.grain_radius, "the measured grains' mean radius in m, > 0")
                )
            object.__setattr__(self, "grain_radius", r)

    # -- properties ----------------------------------------------------------------------------------
    @property
    def parameter_names(self) -> list[str]:
        return [p.name for p in self.parameters]

    @property
    def base(self) -> Path:
        """The folder the file's paths are relative to (the TOML's; the working folder for a spec without one)."""
        return self.path.parent if self.path is not None else Path.cwd()

    @property
    def scene_path(self) -> Path | None:
        """The stage file (``scene`` relative to the diagnosis file), or None for a rig."""
        return None if self.scene is None else (self.base / self.scene).resolve()

    @property
    def experiments_path(self) -> Path:
        """The experiments table (``[experiments] file`` relative to the diagnosis file)."""
        return self.base / self.experiments_file

    def curve_path(self, experiment: str) -> Path | None:
        """The curve file of ``experiment`` (``{id}`` of ``[experiments] curves`` replaced), or None without
        ``curves``; the file need not exist."""
        return None if self.curves is None else self.base / self.curves.replace("{id}", str(experiment))

    @property
    def calibration_points(self) -> int:
        """Space-filling points per condition: ``[calibration] points``, or 4 + 4 x the free parameters for 0."""
        return self.points or 4 + 4 * len(self.parameters)

    def study(self, responses: Sequence[str]) -> StudySpec:
        """An equivalent study: the same scene, ``[fixed]`` and seed, one factor per free parameter (same name,
        low and high), an explicit one-point design at the centre, one response per measure in ``responses``
        (named by it), no regression model. The pipeline sets the design rows' overrides itself and runs them
        with :func:`warpdem.study.execute.run_batch`."""
        if isinstance(responses, str) or not responses:
            raise DiagnoseError(not_allowed("DiagnosisSpec.study", "responses", responses, "a list of measures"))
        factors = tuple(
            FactorSpec(p.name, p.parameter, p.low, p.high, label=p.label, unit=p.unit) for p in self.parameters
        )
        centre = {p.name: 0.5 * (p.low + p.high) for p in self.parameters}
        with _as_diagnose():
            return StudySpec(
                name=self.name,
                title=self.title,
                rig=self.rig,
                scene=self.scene,
                smoke=self.smoke,
                seed=self.seed,
                batch=self.batch,
                fixed=dict(self.fixed),
                factors=factors,
                design=DesignSpec(kind="explicit", points=(centre,)),
                responses=tuple(ResponseSpec(name=r, measure=r) for r in responses),
                analysis=AnalysisSpec(model="none"),
                path=self.path,
            )

    @classmethod
    def from_dict(cls, data: Mapping, path: str | Path | None = None) -> DiagnosisSpec:
        """Diagnosis from parsed TOML ``data``; errors are prefixed with ``path`` (or ``<dict>``)."""
        where = str(path) if path is not None else "<dict>"
        try:
            return _from_dict(data, path)
        except StudyError as e:
            raise DiagnoseError(f"{where}: {e}") from None


def _as_number(x) -> float | None:
    """``float(x)`` for a finite real number (not a bool), else None."""
    if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
        return None
    return float(x)


def _table(data: Mapping, name: str, label: str) -> dict:
    return check_table_keys(name, data.get(name, {}), label, _TABLES, _REQUIRED, _ARRAYS)


def _from_dict(data: Mapping, path) -> DiagnosisSpec:
    if not isinstance(data, Mapping):
        raise DiagnoseError(f"expected a TOML document with tables, got {data!r}")
    for t in data:
        if t not in _TABLES:
            raise DiagnoseError(
                f"table [{t}] is not allowed{did_you_mean(t, _TABLES)}; expected "
                + ", ".join(f"[[{x}]]" if x in _ARRAYS else f"[{x}]" for x in _TABLES)
            )
    for t in ("diagnose", "parameters", "experiments"):
        if t not in data:
            raise DiagnoseError(
                f"table [{t}] is missing; a diagnosis needs [diagnose], [[parameters]] and [experiments]"
            )
    head = _table(data, "diagnose", "[diagnose]")
    fixed = data.get("fixed", {})
    if not isinstance(fixed, Mapping):
        raise DiagnoseError(f"[fixed]: expected a table of overrides, got {fixed!r}")
    if not isinstance(data["parameters"], list):
        raise DiagnoseError("[parameters]: expected an array of tables, written [[parameters]] (one per parameter)")
    parameters = []
    for i, p in enumerate(data["parameters"]):
        label = f"[[parameters]] #{i + 1}" + (f" {p['name']!r}" if isinstance(p, Mapping) and "name" in p else "")
        parameters.append(ParameterSpec(**check_table_keys("parameters", p, label, _TABLES, _REQUIRED, _ARRAYS)))
    experiments = _table(data, "experiments", "[experiments]")
    candidates = _table(data, "candidates", "[candidates]")
    return DiagnosisSpec(
        **head,
        fixed=flatten_keys(fixed),
        parameters=tuple(parameters),
        experiments_file=experiments["file"],
        curves=experiments.get("curves"),
        **_table(data, "noise", "[noise]"),
        **_table(data, "calibration", "[calibration]"),
        candidates=candidates.get("use"),
        candidate_ranges=candidates.get("ranges", {}),
        grain_radius=candidates.get("grain_radius"),
        path=Path(path) if path is not None else None,
    )


# --------------------------------------------------------------------------------------------------
# the experiments table
# --------------------------------------------------------------------------------------------------


@dataclass
class Experiments:
    """The experiments table of a diagnosis.

    Attributes:
        table: one row per CSV row, in file order: ``line`` (its line in the file), ``id`` (text),
            ``replicate`` (int), ``split`` (train | test), the conditions (numbers as floats, text, booleans),
            the responses (floats, NaN: not measured) and ``sd_<response>`` for every response (floats, NaN: not
            stated).
        conditions: the condition columns (override keys and rig parameters), in file order.
        responses: the response columns (measures), in file order.
        curves: experiment id -> its curve (``displacement_m``, ``force_n``, ``branch``), for the experiments
            that have a curve file.
        source: the CSV file.
        rig: the rig whose parameters the conditions' rig parameters are (None: not known).
    """

    table: pd.DataFrame
    conditions: tuple[str, ...]
    responses: tuple[str, ...]
    curves: dict[str, pd.DataFrame]
    source: Path
    rig: str | None = None

    @property
    def ids(self) -> list[str]:
        """The experiment ids, in order of first appearance."""
        return list(dict.fromkeys(self.table["id"]))

    def ids_of(self, split: str) -> list[str]:
        """The ids of the ``split`` (train | test) experiments, in order of first appearance."""
        if split not in SPLITS:
            raise ValueError(not_allowed("Experiments.ids_of", "split", split, " or ".join(SPLITS)))
        return list(dict.fromkeys(self.table.loc[self.table["split"] == split, "id"]))

    def summary(self) -> pd.DataFrame:
        """One row per experiment (order of first appearance): ``id``, ``split``, the conditions and, for each
        response ``r``: ``r`` (mean of its measured values), ``n_r`` (their count) and ``sd_r`` (the mean stated
        SD, NaN when none is stated)."""
        g = self.table.groupby("id", sort=False)
        out = g[["split", *self.conditions]].first().reset_index()
        for r in self.responses:
            out[r] = g[r].mean().to_numpy()
            out[f"n_{r}"] = g[r].count().to_numpy().astype(int)
            out[f"sd_{r}"] = g[f"sd_{r}"].mean().to_numpy()
        return out

    def replicate_sd(self, response: str) -> tuple[float, int]:
        """(pooled within-experiment SD of ``response``, its degrees of freedom) over every experiment with two or
        more values: sqrt(sum of squared deviations from each experiment's mean / sum (n - 1)); (NaN, 0) when no
        experiment has two values."""
        from .inference import pooled_variance

        self._response(response)
        var, dof = pooled_variance(v.to_numpy(dtype=float) for _, v in self.table.groupby("id", sort=False)[response])
        return math.sqrt(var) if dof else math.nan, dof

    def overrides(self, experiment: str) -> dict:
        """The condition overrides of ``experiment``: override key or rig parameter -> value (a rig parameter in
        its field's type: an integer parameter gets an int)."""
        rows = self.table[self.table["id"] == experiment]
        if rows.empty:
            raise KeyError(f"no experiment {experiment!r}; experiments: {', '.join(self.ids)}")
        row = rows.iloc[0]
        out = {}
        for c in self.conditions:
            v = row[c]
            v = v.item() if hasattr(v, "item") else v
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                v = rig_value(self, c, float(v)) if is_rig_key(c) else float(v)
            out[c] = v
        return out

    def _response(self, response: str) -> None:
        if response not in self.responses:
            raise KeyError(
                f"no response {response!r}{did_you_mean(response, self.responses)}; responses: "
                f"{', '.join(self.responses)}"
            )


def _read_csv(path: Path, what: str) -> list[tuple[int, list[str]]]:
    """The (line, stripped cells) of ``path`` (header first, blank lines dropped), all text."""
    import pandas as pd

    try:
        raw = pd.read_csv(path, header=None, dtype=str, na_filter=False, skip_blank_lines=False, encoding="utf-8-sig")
    except FileNotFoundError:
        raise DiagnoseError(f"{path}: no such {what}") from None
    except pd.errors.EmptyDataError:
        raise DiagnoseError(f"{path}: the {what} is empty; expected a header line and rows") from None
    except (pd.errors.ParserError, UnicodeDecodeError) as e:
        raise DiagnoseError(f"{path}: not a readable CSV {what}: {str(e).strip()}") from None
    rows = []
    for i, cells in enumerate(raw.itertuples(index=False, name=None)):
        cells = [str(c).strip() for c in cells]
        if any(cells):
            rows.append((i + 1, cells))
    if not rows:
        raise DiagnoseError(f"{path}: the {what} is empty; expected a header line and rows")
    header = rows[0][1]
    for j, name in enumerate(header):
        if not name:
            raise DiagnoseError(f"{path}: column {j + 1} of the header (line {rows[0][0]}) has no name")
        if name in header[:j]:
            raise DiagnoseError(f"{path}: column {name!r} is not allowed twice (header, line {rows[0][0]})")
    if len(rows) < 2:
        raise DiagnoseError(f"{path}: the {what} has a header but no rows")
    return rows


def _float(cell: str) -> float | None:
    """The finite number ``cell`` writes, else None."""
    try:
        v = float(cell)
    except ValueError:
        return None
    return v if math.isfinite(v) else None


def _condition_kind(col: str, rig: str | None, src: Path, responses: Sequence[str]) -> str:
    """How condition column ``col`` reads its cells: "number", "text", "bool" or "any" (a number when it is one,
    else text: a rig parameter of a rig not known); refused when it is not an override key or rig parameter."""
    if "." in col or col == "gravity":
        override_grammar(rig, True).parse(col, str(src), "column", error=DiagnoseError)
        return "number"
    if rig is None:
        return "any"
    fields = rig_fields(rig)
    if col not in fields:
        known = [*MEASURES, *_RESERVED, *(f"sd_{r}" for r in responses), *fields]
        raise DiagnoseError(
            f"{src}: column {col!r} is not allowed{did_you_mean(col, known)}; expected id, replicate, split, a "
            f"response ({', '.join(MEASURES)}), sd_<response>, an override key "
            f"({override_grammar(rig, True).forms(('material', 'interaction', 'run'))}) or a {rig} parameter "
            f"({', '.join(fields)})"
        )
    d = fields[col].default
    if isinstance(d, bool):
        return "bool"
    return "text" if isinstance(d, str) else "number"


def _classify(header: list[str], spec: DiagnosisSpec, rig: str | None, src: Path) -> tuple[list, list, dict]:
    """(responses, sd columns, {condition: kind}) of the experiments table's ``header``."""
    if "id" not in header:
        raise DiagnoseError(
            f"{src}: column 'id' is missing; expected an id column naming each experiment (rows with the same "
            f"id are its replicates); columns: {', '.join(header)}"
        )
    responses = [c for c in header if c in MEASURES]
    sds, conditions = [], {}
    keys = {p.parameter: p.name for p in spec.parameters}
    for c in header:
        if c in _RESERVED or c in responses:
            continue
        if c.startswith("sd_"):
            r = c[3:]
            if r not in responses:
                why = (
                    f"{r} is not a response column of this file"
                    if r in MEASURES
                    else f"{r!r} is not a measure{did_you_mean(r, MEASURES)}"
                )
                raise DiagnoseError(
                    f"{src}: column {c!r} is not allowed; {why}; expected sd_<response> for a response column "
                    f"({', '.join(responses)})"
                )
            sds.append(c)
            continue
        kind = _condition_kind(c, rig, src, responses)
        if c in keys:
            raise DiagnoseError(
                f"{src}: column {c!r} is not allowed; [[parameters]] {keys[c]!r} sets {c}: a free parameter "
                "cannot also be a condition"
            )
        if c in spec.fixed:
            raise DiagnoseError(
                f"{src}: column {c!r} is not allowed; [fixed] sets {c} = {spec.fixed[c]!r} too: expected a key "
                "that is either fixed or a condition"
            )
        conditions[c] = kind
    if not responses:
        raise DiagnoseError(
            f"{src}: no response column; expected at least one of {', '.join(MEASURES)}; columns: {', '.join(header)}"
        )
    return responses, sds, conditions


def _read_experiments(spec: DiagnosisSpec, rig: str | None) -> Experiments:
    """The experiments table of ``spec``, every cell checked (not yet against the scene)."""
    import numpy as np
    import pandas as pd

    src = spec.experiments_path
    rows = _read_csv(src, "experiments table")
    header = rows[0][1]
    responses, sds, conditions = _classify(header, spec, rig, src)
    col = {c: j for j, c in enumerate(header)}
    data: dict[str, list] = {k: [] for k in ("line", "id", "replicate", "split", *conditions, *responses)}
    data.update({f"sd_{r}": [] for r in responses})
    first: dict[str, dict] = {}  # id -> its first row's line and values
    replicates: dict[str, dict[int, int]] = {}
    for line, cells in rows[1:]:
        at = f"{src}, line {line}"

        def cell(name, _cells=cells):
            return _cells[col[name]]

        eid = cell("id")
        if not eid:
            raise DiagnoseError(not_allowed(at, "id", eid, "an experiment id (text, not empty)"))
        reps = replicates.setdefault(eid, {})
        if "replicate" in col:
            v = _float(cell("replicate"))
            if v is None or v != int(v) or v < 1:
                raise DiagnoseError(not_allowed(at, "replicate", cell("replicate"), "an integer >= 1"))
            rep = int(v)
            if rep in reps:
                raise DiagnoseError(
                    not_allowed(at, "replicate", cell("replicate"), "a replicate unique within its experiment")
                    + f"; line {reps[rep]} is replicate {rep} of experiment {eid!r} too"
                )
        else:
            rep = len(reps) + 1
        reps[rep] = line
        split = cell("split") if "split" in col else "train"
        if split not in SPLITS:
            raise DiagnoseError(not_allowed(at, "split", split, f"train or test{did_you_mean(split, SPLITS)}"))
        values = {"split": split}
        for c, kind in conditions.items():
            values[c] = _condition_value(at, c, cell(c), kind)
        if eid in first:
            for c, v in values.items():
                if v != first[eid][c]:
                    raise DiagnoseError(
                        not_allowed(at, c, cell(c), f"{first[eid][c]!r} as on line {first[eid]['line']}")
                        + f": {'the split' if c == 'split' else 'a condition'} is the same for every row of "
                        f"experiment {eid!r} (rows with the same id are its replicates)"
                    )
        else:
            first[eid] = {"line": line, **values}
        for r in responses:
            text = cell(r)
            v = _float(text) if text else math.nan
            if v is None:
                raise DiagnoseError(not_allowed(at, r, text, "a finite number, or an empty cell (not measured)"))
            data[r].append(v)
            sd = f"sd_{r}"
            text = cell(sd) if sd in col else ""
            v = _float(text) if text else math.nan
            if v is None or v <= 0:
                raise DiagnoseError(
                    not_allowed(at, sd, text, f"the SD of one measurement of {r}, a number > 0, or an empty cell")
                )
            data[sd].append(v)
        data["line"].append(line)
        data["id"].append(eid)
        data["replicate"].append(rep)
        for c, v in values.items():
            data[c].append(v)
    table = pd.DataFrame(data)
    for r in responses:
        if table[r].isna().all():
            raise DiagnoseError(
                f"{src}: column {r!r} has no value; expected at least one measured value (an empty cell is not "
                "measured)"
            )
    if "split" in col and not (table["split"] == "train").any():
        raise DiagnoseError(
            f"{src}: column 'split' has no train experiment; expected at least one (the others are held out)"
        )
    table["replicate"] = table["replicate"].astype(np.int64)
    return Experiments(
        table=table, conditions=tuple(conditions), responses=tuple(responses), curves={}, source=src, rig=rig
    )


def _condition_value(at: str, c: str, text: str, kind: str):
    if not text:
        raise DiagnoseError(not_allowed(at, c, text, "a value: a condition column sets its key for every experiment"))
    if kind == "bool":
        if text.lower() not in ("true", "false"):
            raise DiagnoseError(not_allowed(at, c, text, "true or false"))
        return text.lower() == "true"
    if kind == "text":
        return text
    v = _float(text)
    if v is None:
        if kind == "any":
            return text
        raise DiagnoseError(not_allowed(at, c, text, "a finite number"))
    return v


def training_values(exps: Experiments) -> int:
    """The measured values a calibration fits: the training experiments x the responses each has a value of.
    No more of them than free parameters: the diagnosis can test only whether the models reach the data
    (:mod:`.reach`)."""
    train = exps.table[exps.table["split"] == "train"]
    return int(train.groupby("id", sort=False)[list(exps.responses)].count().gt(0).to_numpy().sum())


def _check_enough(spec: DiagnosisSpec, exps: Experiments) -> None:
    if training_values(exps) == 0:
        raise DiagnoseError(
            f"{exps.source}: no training experiment has a measured value of {', '.join(exps.responses)}; "
            "expected at least one (a row with split = train and a number in a response column)"
        )


def _read_curves(spec: DiagnosisSpec, exps: Experiments) -> dict:
    import pandas as pd

    out = {}
    for eid in exps.ids:
        path = spec.curve_path(eid)
        if path is None or not path.is_file():
            continue
        rows = _read_csv(path, "curve file")
        header = rows[0][1]
        for c in header:
            if c not in CURVE_COLUMNS:
                raise DiagnoseError(
                    f"{path}: column {c!r} is not allowed{did_you_mean(c, CURVE_COLUMNS)}; expected "
                    f"{', '.join(CURVE_COLUMNS)} (branch optional)"
                )
        for c in CURVE_COLUMNS[:2]:
            if c not in header:
                raise DiagnoseError(f"{path}: column {c!r} is missing; expected {', '.join(CURVE_COLUMNS)}")
        if len(rows) < 3:
            raise DiagnoseError(f"{path}: {len(rows) - 1} row(s) are not allowed; expected a curve of >= 2 points")
        col = {c: j for j, c in enumerate(header)}
        data = {"displacement_m": [], "force_n": [], "branch": []}
        for line, cells in rows[1:]:
            at = f"{path}, line {line}"
            for c in CURVE_COLUMNS[:2]:
                v = _float(cells[col[c]])
                if v is None:
                    raise DiagnoseError(not_allowed(at, c, cells[col[c]], "a finite number"))
                data[c].append(v)
            b = cells[col["branch"]] if "branch" in col else "load"
            if b not in BRANCHES:
                raise DiagnoseError(not_allowed(at, "branch", b, f"load or unload{did_you_mean(b, BRANCHES)}"))
            data["branch"].append(b)
        out[eid] = pd.DataFrame(data)
    return out


# --------------------------------------------------------------------------------------------------
# the scene
# --------------------------------------------------------------------------------------------------


def _check_parameters(spec: DiagnosisSpec, scene, where: str) -> None:
    """Apply each free parameter's low and high to ``scene``; ``where`` prefixes a refusal."""
    for p in spec.parameters:
        for which, v in (("low", p.low), ("high", p.high)):
            try:
                check_override(spec, scene, p.parameter, v, where="")
            except _SCENE_ERRORS as e:
                raise DiagnoseError(
                    f"{where}[[parameters]] {p.name!r}: {which} = {v!r} ({p.parameter} = {v!r}) is not allowed: {e}"
                ) from None


def _first_scene(spec: DiagnosisSpec, exps: Experiments, path: Path):
    """The rig's scene with ``[fixed]`` and the first experiment's rig-parameter conditions (a scene may need
    one to be built at all, as a sphere needs its radius)."""
    first = {k: v for k, v in exps.overrides(exps.ids[0]).items() if is_rig_key(k)}
    where = f"{exps.source}: experiment {exps.ids[0]!r}: " if first else f"{path}: "
    with _as_diagnose(where):
        return fixed_scene(spec, first)


def _check_scene(spec: DiagnosisSpec, exps: Experiments, base) -> None:
    """Build each experiment's scene (``base``, the scene with ``[fixed]``, rebuilt for rig-parameter
    conditions), apply its conditions and the free parameters' ranges, and refuse a response it does not
    measure."""
    from warpdem.scene.runner import MEASURE_METRICS, METRIC_NEEDS, measured_metrics
    from warpdem.scene.stage import apply_overrides

    src = exps.source
    fixed_rig = {k: v for k, v in spec.fixed.items() if is_rig_key(k)}
    fixed_other = {k: v for k, v in spec.fixed.items() if not is_rig_key(k)}
    scenes = {(): base}
    for eid in exps.ids:
        rows = exps.table[exps.table["id"] == eid]
        line = int(rows["line"].iloc[0])
        at = f"{src}, line {line}"
        ov = exps.overrides(eid)
        rig_ov = {k: v for k, v in ov.items() if is_rig_key(k)}
        key = tuple(sorted(rig_ov.items()))
        if key not in scenes:
            try:
                scene = apply_overrides(build_scene(spec, {**fixed_rig, **rig_ov}), fixed_other)
            except _SCENE_ERRORS as e:
                keys = ", ".join(f"{k} = {v!r}" for k, v in rig_ov.items())
                raise DiagnoseError(f"{at}: experiment {eid!r}: the scene cannot be built from {keys}: {e}") from None
            _check_parameters(spec, scene, f"{at}: experiment {eid!r}: in its scene, ")
            scenes[key] = scene
        scene = copy.deepcopy(scenes[key])
        for k, v in ov.items():
            if is_rig_key(k):
                continue
            try:
                apply_overrides(scene, {k: v})
            except _SCENE_ERRORS as e:
                raise DiagnoseError(f"{at}: {k} = {v!r} (experiment {eid!r}) is not allowed: {e}") from None
        m = scene.measure
        have = measured_metrics(m)
        for r in exps.responses:
            got = rows[r].notna().to_numpy()
            if r in have or not got.any():
                continue
            i = int(got.argmax())
            if r in MEASURE_METRICS.get(m.kind, ()):
                need = METRIC_NEEDS[r]
                hint = _NEED_HINTS.get((scene.rig, need))
                why = f"its measurement writes {r} only with measure.{need} set" + (
                    f" (a {scene.rig} sets it with {hint})" if hint else ""
                )
            else:
                why = f"a scene measuring {m.kind} does not write {r}"
            raise DiagnoseError(
                f"{src}, line {int(rows['line'].iloc[i])}: {r} = {float(rows[r].iloc[i])!r} is not allowed; the scene of "
                f"experiment {eid!r} does not measure {r}: {why}; it measures {', '.join(have)}"
            )


# --------------------------------------------------------------------------------------------------
# loading
# --------------------------------------------------------------------------------------------------


def load_diagnosis(path: str | Path, check_scene: bool = True) -> tuple[DiagnosisSpec, Experiments]:
    """Read and validate a diagnosis file and its experiments table (schemas in the module docstring).

    With ``check_scene`` (default) the scene is also built with ``[fixed]`` and each experiment's conditions,
    each free parameter's low and high are applied to it, and each response must be one the experiment's scene
    measures; without it, nothing that needs the scene is checked (a stage's rig parameters are then not known).
    Raises :class:`DiagnoseError`.
    """
    path = Path(path)
    spec = DiagnosisSpec.from_dict(read_toml(path, "diagnosis", DiagnoseError), path)
    src = spec.experiments_path
    if not src.is_file():
        raise DiagnoseError(
            f"{path}: [experiments] file = {spec.experiments_file!r} is not allowed: {src} does not exist; "
            "expected a CSV file relative to the diagnosis file"
        )
    rig, base = spec.rig, None
    if check_scene and rig is None:
        # a stage: its rig (whose parameters may be conditions) is known once it is built
        with _as_diagnose(f"{path}: "):
            base = fixed_scene(spec)
        _check_parameters(spec, base, f"{path}: ")
        if base.rig in _rig_names():
            rig = base.rig
    exps = _read_experiments(spec, rig)
    if check_scene:
        if base is None:
            base = _first_scene(spec, exps, path)
            _check_parameters(spec, base, f"{path}: ")
        _check_scene(spec, exps, base)
    _check_enough(spec, exps)
    exps.curves = _read_curves(spec, exps)
    return spec, exps


def _rig_names():
    from warpdem.scene.rigs import RIGS

    return RIGS
