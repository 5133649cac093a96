"""Design of experiments and response-surface statistics for DEM calibration.

``designs``  classical designs (Plackett–Burman, 2^k and 2^(k-p) factorials with alias structure,
             Box–Behnken, central composite), run order, coded/actual conversion, steepest ascent.
``analysis`` Design-Expert style OLS fits: ANOVA with lack of fit, R^2 / adj / pred R^2, adequate
             precision, backward elimination, effects (Pareto data), solving for a target.
``audit``    recomputes the seed papers' published statistics from their own run tables.
``spec``     study files (``studies/*.toml``): loading, validation, the design table of runs.
``report``   report.md, Design-Expert ANOVA tables, Pareto and contour plots of a finished study.
``execute``  runs a study as batched worlds, one result file per finished point, resumable; analysis and
             verification runs at the chosen optimum (needs the engine: Warp).

May import: ``warpdem.scene`` and ``warpdem.engine`` (``spec`` reads override keys with the engine's one
grammar, so importing this package imports Warp), numpy, scipy, pandas, statsmodels (and matplotlib, inside
the plotting functions). Never imports ``warpdem.cli``.
"""

from .analysis import (
    ModelFit,
    TargetSolution,
    backward_eliminate,
    effects_table,
    fit_model,
    lenth_pse,
    model_terms,
    parse_term,
    response_range,
    solve_target,
    term_label,
)
from .designs import (
    AliasStructure,
    Factor,
    alias_structure,
    box_behnken,
    ccd_alpha,
    central_composite,
    design_counts,
    factor_names,
    fractional_factorial,
    full_factorial,
    plackett_burman,
    randomize,
    steepest_path,
    to_actual,
    to_coded,
)
from .report import anova_frame, format_anova, write_report
from .spec import StudyError, StudySpec, batch_key, design_table, load_study, run_overrides, varies_per_world

__all__ = [
    "StudyError",
    "StudySpec",
    "anova_frame",
    "batch_key",
    "design_table",
    "format_anova",
    "load_study",
    "run_overrides",
    "varies_per_world",
    "write_report",
    "AliasStructure",
    "Factor",
    "ModelFit",
    "TargetSolution",
    "alias_structure",
    "backward_eliminate",
    "box_behnken",
    "ccd_alpha",
    "central_composite",
    "design_counts",
    "effects_table",
    "factor_names",
    "fit_model",
    "fractional_factorial",
    "full_factorial",
    "lenth_pse",
    "model_terms",
    "parse_term",
    "plackett_burman",
    "randomize",
    "response_range",
    "solve_target",
    "steepest_path",
    "term_label",
    "to_actual",
    "to_coded",
]
