"""Analysis report of a finished design of experiments: Markdown, CSV tables and pictures.

:func:`write_report` takes the run table of a study (one row per finished run, factors in coded
units) and writes, per response, what Design-Expert's analysis screens show: the ANOVA table, fit
statistics, the regression equation in coded and actual units, a Pareto chart of standardized
effects, contour and surface plots of the fitted model and, given a target, the settings that
reach it. The statistics are those of :mod:`warpdem.study.analysis`; this module only chooses the
model, formats and draws.

Conventions, stated once:

* Numbers in the CSV files keep full precision (they are data); ``report.md`` and
  :func:`format_anova` round them for reading. p-values are text everywhere, as Design-Expert
  prints them: four decimals, ``< 0.0001`` below 1e-4, blank where no test exists.
* The design region is the box spanned by the coded factor values of the runs, per factor
  ([-1, 1] for two-level and Box-Behnken designs, [-alpha, alpha] for a central composite design).
  Contour plots and the target search cover it; factors off the plot are held at coded 0.
* A target is a set of settings, not a point: the report lists the sampled family of solutions
  (``optimum_<response>.csv``) and chooses the one nearest the design centre in coded units.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from warpdem.scene.export import save_figure

from .analysis import (
    ModelFit,
    Term,
    _columns,
    alias_lines,
    alias_matrix,
    backward_eliminate,
    box_cox,
    confirmation_interval,
    cube,
    effects_table,
    fit_model,
    fit_summary,
    half_normal,
    influence,
    interaction,
    mean_interval,
    model_terms,
    optimize_desirability,
    outlier_limit,
    perturbation,
    response_extremes,
    solve_target,
    term_label,
)
from .designs import Factor

__all__ = ["ANOVA_COLUMNS", "anova_frame", "format_anova", "format_p", "write_report"]

#: Column names of the ANOVA table, as Design-Expert prints them (plus its significance remark).
ANOVA_COLUMNS = ["Source", "Sum of Squares", "df", "Mean Square", "F-value", "p-value", "Significance"]

_NAMED_MODELS = ("quadratic", "2fi", "linear")
_MODEL_TITLE = {"quadratic": "Quadratic", "2fi": "2FI", "linear": "Linear"}
# optional run-table columns, shown when present
_RUN_EXTRAS = ("replicate", "world_seed", "wall_s")
# solutions sampled on a target contour; about 1 s for three factors
_TARGET_SAMPLES = 100


# --------------------------------------------------------------------------------------------
# Formatting
# --------------------------------------------------------------------------------------------


def format_p(p) -> str:
    """A p-value as Design-Expert prints it: ``< 0.0001``, ``0.0048``; blank when undefined."""
    if p is None or not np.isfinite(p):
        return ""
    return "< 0.0001" if p < 1e-4 else f"{p:.4f}"


def settle(v: float, places: int = 9) -> float:
    """``v`` rounded to ``places`` decimals: a least-squares solve leaves noise of ~1e-15 that differs between BLAS
    builds, and an effect that is a decimal half-way value (6.635 deg from two-decimal data) would then print as 6.63
    on one machine and 6.64 on another."""
    return round(float(v), places)


def _fmt(v, blank: str = "") -> str:
    """A number for reading: two decimals from 1 upwards, four significant digits below."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return blank
    v = float(v)
    if v == 0:
        return "0"
    return f"{v:.2f}" if abs(v) >= 1 else f"{v:.4g}"


def _fmt_g(v, digits: int = 6, blank: str = "") -> str:
    if v is None or not np.isfinite(v):
        return blank
    return f"{float(v):.{digits}g}"


def _json(v):
    """Plain Python value for json.dumps: numpy scalars unwrapped, NaN/inf as None."""
    if isinstance(v, Mapping):
        return {str(k): _json(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_json(x) for x in v]
    if isinstance(v, (np.bool_, bool)):
        return bool(v)
    if isinstance(v, (np.integer, int)):
        return int(v)
    if isinstance(v, (np.floating, float)):
        return float(v) if math.isfinite(v) else None
    return v


def _extra_cell(v) -> str:
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.number)):
        return str(v)
    if isinstance(v, (int, np.integer)):
        return str(int(v))  # seeds are identifiers: never in exponent notation
    return _fmt_g(v, 6, "")


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", str(name)).strip("_") or "response"


def _md_cell(v) -> str:
    return str(v).replace("|", "\\|").replace("\n", " ")


def _md_table(header: Sequence[str], rows: Sequence[Sequence], right: Sequence[bool] | None = None) -> str:
    right = right if right is not None else [False] * len(header)
    lines = [
        "| " + " | ".join(_md_cell(h) for h in header) + " |",
        "|" + "|".join("---:" if r else ":---" for r in right) + "|",
    ]
    lines += ["| " + " | ".join(_md_cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _model_name(fit: ModelFit) -> str:
    """Design-Expert's name of the fitted model: Linear, 2FI, Quadratic, 'Reduced ...', or Custom."""
    if not fit.terms:
        return "Mean"
    order = max(len(t) for t in fit.terms)
    squares = any(len(set(t)) < len(t) for t in fit.terms)
    if order > 2:
        return "Custom"
    base = "quadratic" if squares else ("2fi" if order == 2 else "linear")
    full = model_terms(base, fit.factors)
    if set(fit.terms) == set(full):
        return _MODEL_TITLE[base]
    if set(fit.terms) <= set(full):
        return "Reduced " + _MODEL_TITLE[base]
    return "Custom"


# --------------------------------------------------------------------------------------------
# Tables
# --------------------------------------------------------------------------------------------


def anova_frame(fit: ModelFit, alpha: float = 0.05) -> pd.DataFrame:
    """The ANOVA table in Design-Expert's layout (columns :data:`ANOVA_COLUMNS`).

    Sums of squares, mean squares and F keep full precision (NaN where Design-Expert prints
    nothing); the p-value is text (:func:`format_p`). ``Significance`` remarks on the model
    ("significant" when p < alpha) and on lack of fit ("significant" is bad news there).
    """
    a = fit.anova
    rows = []
    for src, r in a.iterrows():
        remark = ""
        if src in ("Model", "Lack of Fit") and np.isfinite(r["p"]):
            remark = "significant" if r["p"] < alpha else "not significant"
        rows.append(
            [src, float(r["sum_sq"]), int(r["df"]), float(r["mean_sq"]), float(r["F"]), format_p(r["p"]), remark]
        )
    return pd.DataFrame(rows, columns=ANOVA_COLUMNS)


def _anova_text_rows(fit: ModelFit, alpha: float) -> list[list[str]]:
    return [
        [
            r["Source"],
            _fmt(r["Sum of Squares"]),
            str(r["df"]),
            _fmt(r["Mean Square"]),
            _fmt(r["F-value"]),
            r["p-value"],
            r["Significance"],
        ]
        for _, r in anova_frame(fit, alpha).iterrows()
    ]


def format_anova(fit: ModelFit, alpha: float = 0.05) -> str:
    """Fixed-width ANOVA table for a terminal, Design-Expert layout, with its title line."""
    rows = _anova_text_rows(fit, alpha)
    head = ANOVA_COLUMNS[:-1] + [""]
    width = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(head)]
    left = {0, 6}

    def line(cells):
        return "  ".join(c.ljust(w) if i in left else c.rjust(w) for i, (c, w) in enumerate(zip(cells, width))).rstrip()

    title = f"ANOVA for {_model_name(fit)} model, response {fit.response} (Type III partial sums of squares)"
    rule = "-" * len(line(head))
    return "\n".join([title, rule, line(head), rule] + [line(r) for r in rows] + [rule])


def _vif(fit: ModelFit) -> np.ndarray:
    """Variance inflation factor of each term, 1 / (1 - R_j^2) of the term's column regressed on
    the others (intercept included), as Design-Expert prints it; 1 for an orthogonal term."""
    X = _columns(fit.data[fit.factors].to_numpy(float), fit.terms, fit.factors)[:, 1:]
    if X.shape[1] == 0:
        return np.zeros(0)
    Xc = X - X.mean(axis=0)
    g = Xc.T @ Xc
    try:
        return np.diag(np.linalg.inv(g)) * np.diag(g)
    except np.linalg.LinAlgError:
        return np.full(X.shape[1], math.nan)


def _monomial_label(mono: Term, factors: Sequence[str]) -> str:
    return term_label(mono, factors) if mono else "Intercept"


def _coefficients_frame(fit: ModelFit, alpha: float) -> pd.DataFrame:
    """Coded coefficients (estimate, SE, confidence interval, t, p, VIF) and the actual-units
    coefficient of the same monomial; actual-only monomials (from a non-hierarchical model)
    get their own rows."""
    c = fit.coefficients
    df_res = int(fit.anova.loc["Residual", "df"])
    tq = float(stats.t.ppf(1 - alpha / 2, df_res)) if df_res > 0 else math.nan
    ci = f"{100 * (1 - alpha):g}%"
    vif = dict(zip(fit.labels, _vif(fit)))
    actual = {}
    if fit.levels:
        actual = {_monomial_label(m, fit.factors): v for m, v in fit.equation("actual").items()}
    rows = []
    for lab, r in c.iterrows():
        rows.append(
            {
                "Term": lab,
                "Coefficient Estimate": r["coef"],
                "df": 1,
                "Standard Error": r["std_err"],
                f"{ci} CI Low": r["coef"] - tq * r["std_err"],
                f"{ci} CI High": r["coef"] + tq * r["std_err"],
                "t-value": r["t"],
                "p-value": r["p"],
                "VIF": vif.get(lab, math.nan),
                "Actual Coefficient": actual.pop(lab, math.nan),
            }
        )
    for lab, v in actual.items():
        rows.append({"Term": lab, "Actual Coefficient": v})
    return pd.DataFrame(rows)


# --------------------------------------------------------------------------------------------
# Model choice
# --------------------------------------------------------------------------------------------


def _estimable(data: pd.DataFrame, factors: list[str], terms: list[Term]) -> bool:
    """The test fit_model applies: the model matrix has full column rank."""
    X = _columns(data[factors].to_numpy(float), terms, factors)
    return X.shape[0] >= X.shape[1] and np.linalg.matrix_rank(X) == X.shape[1]


def _describe_model(model) -> str:
    if isinstance(model, str):
        return _MODEL_TITLE.get(model.lower(), model)
    return "custom (" + ", ".join(map(str, model)) + ")"


def _choose_terms(data: pd.DataFrame, factors: list[str], model) -> tuple[list[Term], str | None]:
    """Terms of ``model``, or of the largest of quadratic > 2FI > linear that the runs can
    estimate (within the requested terms for a custom model); the second value says why."""
    wanted = model_terms(model, factors)
    if _estimable(data, factors, wanted):
        return wanted, None
    named = isinstance(model, str)
    start = _NAMED_MODELS.index(model.lower()) + 1 if named else 0
    for name in _NAMED_MODELS[start:]:
        cand = model_terms(name, factors)
        if not named:
            cand = [t for t in cand if t in wanted]
        if cand and set(cand) != set(wanted) and _estimable(data, factors, cand):
            return cand, (
                f"the {_describe_model(model)} model is not estimable from these "
                f"{len(data)} runs (aliased terms); fitted the {_MODEL_TITLE[name]} "
                f"model instead"
            )
    # not even all main effects (e.g. failed runs left a factor constant): keep those that fit
    terms: list[Term] = []
    for f in factors:
        if _estimable(data, factors, terms + [(f,)]):
            terms.append((f,))
    kept = ", ".join(t[0] for t in terms) or "none (mean only)"
    which = (
        "the Linear model is"
        if named and model.lower() == "linear"
        else f"neither the {_describe_model(model)} model nor the Linear model is"
    )
    return terms, f"{which} not estimable from these {len(data)} runs; main effects kept: {kept}"


# --------------------------------------------------------------------------------------------
# Pictures
# --------------------------------------------------------------------------------------------


def _figure(three_d: bool = False):
    # A bare Figure renders with Agg and leaves pyplot's global state (and backend) alone.
    from matplotlib.figure import Figure

    fig = Figure(figsize=(5, 4), dpi=100)
    ax = fig.add_subplot(projection="3d") if three_d else fig.add_subplot()
    return fig, ax


def _axis_label(f: Factor, labels: Mapping[str, str]) -> str:
    s = f"{f.name}: {labels[f.name]}" if labels.get(f.name) else f.name
    return s + (f" [{f.unit}]" if f.unit else "")


def _response_label(resp: Mapping) -> str:
    return resp["name"] + (f" [{resp['unit']}]" if resp.get("unit") else "")


def _plot_pareto(path: Path, eff: pd.DataFrame, alpha: float, df_res: int, title: str):
    """Bars: |standardized effect| (t-value, or effect / Lenth PSE when no residual df is left),
    largest first, orange for a positive and blue for a negative effect. Lines: the two-sided
    t limit at ``alpha`` and the Bonferroni limit (alpha / number of terms), Design-Expert's
    pair; with no residual df both are Lenth's margins on the standardized scale (m/3 df)."""
    fig, ax = _figure()
    m = len(eff)
    std = eff["standardized"].to_numpy(float)
    x = np.arange(m)
    ax.bar(x, np.abs(std), color=np.where(std >= 0, "tab:orange", "tab:blue"), edgecolor="black", lw=0.5)
    ax.set_xticks(x, list(eff.index), rotation=90 if m > 8 else 0)
    df = df_res if df_res > 0 else m / 3.0
    if df > 0 and m > 0:
        t_lim = float(stats.t.ppf(1 - alpha / 2, df))
        t_bon = float(stats.t.ppf(1 - alpha / (2 * m), df))
        name = "t limit" if df_res > 0 else "Lenth ME / PSE"
        ax.axhline(t_lim, color="black", lw=1, label=f"{name} ({t_lim:.3g})")
        ax.axhline(t_bon, color="black", lw=1, ls="--", label=f"Bonferroni ({t_bon:.3g})")
        ax.legend(fontsize=7, loc="upper right")
    ax.set_ylabel("|t-value|" if df_res > 0 else "|effect| / Lenth PSE")
    ax.set_xlabel("term (rank order)")
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    save_figure(fig, path)


def _grid(fit: ModelFit, a: str, b: str, region: Mapping[str, tuple[float, float]], n: int = 61):
    """Prediction (in the response's units) on an n x n coded grid over the region of factors a, b (others at 0)."""
    ga = np.linspace(*region[a], n)
    gb = np.linspace(*region[b], n)
    A, B = np.meshgrid(ga, gb)
    pts = pd.DataFrame({f: np.zeros(A.size) for f in fit.factors})
    pts[a], pts[b] = A.ravel(), B.ravel()
    return A, B, fit.predict_response(pts).reshape(A.shape)


def _plot_contour(
    path: Path,
    fit: ModelFit,
    a: Factor,
    b: Factor,
    region,
    labels,
    resp: Mapping,
    runs: pd.DataFrame,
    chosen: pd.Series | None,
    levels=14,
):
    fig, ax = _figure()
    A, B, Z = _grid(fit, a.name, b.name, region)
    XA, XB = a.to_actual(A), b.to_actual(B)
    # one colour scale for all of a response's contour plots (``levels``): a colour means one value in each
    cs = ax.contourf(XA, XB, Z, levels=levels, cmap="viridis", extend="both")
    lines = ax.contour(XA, XB, Z, levels=cs.levels, colors="white", linewidths=0.4)
    ax.clabel(lines, lines.levels[::2], fmt="%.3g", fontsize=6, colors="white")
    fig.colorbar(cs, ax=ax).set_label(_response_label(resp), fontsize=8)
    target = resp.get("target")
    handles = []
    if target is not None and Z.min() <= target <= Z.max():
        ax.contour(XA, XB, Z, levels=[target], colors="red", linewidths=2)
        from matplotlib.lines import Line2D

        handles.append(Line2D([], [], color="red", lw=2, label=f"target {target:g}"))
    # runs are projected onto the plane: a reader sees where the data lie, not only the slice
    ax.scatter(a.to_actual(runs[a.name]), b.to_actual(runs[b.name]), s=14, c="black", zorder=3, clip_on=False)
    others = [f for f in fit.factors if f not in (a.name, b.name)]
    if chosen is not None and all(abs(chosen[f]) < 1e-6 for f in others):
        handles.append(
            ax.scatter(
                [a.to_actual(chosen[a.name])],
                [b.to_actual(chosen[b.name])],
                marker="*",
                s=120,
                c="red",
                edgecolors="white",
                zorder=4,
                label="chosen",
            )
        )
    if handles:
        ax.legend(handles=handles, fontsize=7, loc="best")
    ax.set_xlabel(_axis_label(a, labels), fontsize=8)
    ax.set_ylabel(_axis_label(b, labels), fontsize=8)
    held = ", ".join(others)
    ax.set_title(f"{resp['name']}" + (f" ({held} at centre)" if held else ""), fontsize=9)
    fig.tight_layout()
    save_figure(fig, path)


def _plot_surface(
    path: Path, fit: ModelFit, a: Factor, b: Factor, region, labels, resp: Mapping, runs: pd.DataFrame | None = None
):
    fig, ax = _figure(three_d=True)
    A, B, Z = _grid(fit, a.name, b.name, region, n=41)
    XA, XB = a.to_actual(A), b.to_actual(B)
    ax.plot_surface(XA, XB, Z, cmap="viridis", linewidth=0, antialiased=True, alpha=0.75)
    if runs is not None:
        # the runs at their measured values: above or below the surface by their residual (and, off the plot's
        # plane, by the other factors' effect)
        ax.scatter(
            a.to_actual(runs[a.name]), b.to_actual(runs[b.name]), runs[resp["name"]], c="black", s=10, depthshade=False
        )
    target = resp.get("target")
    if target is not None and Z.min() <= target <= Z.max():
        ax.contour(XA, XB, Z, levels=[target], colors="red", linewidths=2)
    ax.set_xlabel(_axis_label(a, labels), fontsize=7)
    ax.set_ylabel(_axis_label(b, labels), fontsize=7)
    ax.set_zlabel(_response_label(resp), fontsize=7)
    ax.tick_params(labelsize=6)
    others = [f for f in fit.factors if f not in (a.name, b.name)]
    ax.set_title(resp["name"] + (f" ({', '.join(others)} at centre)" if others else ""), fontsize=9)
    ax.zaxis.labelpad = 6
    # the z label sits outside the axes box: a tight box keeps it
    save_figure(fig, path, bbox_inches="tight", pad_inches=0.3)


def _plot_model_graphs(path: Path, fit: ModelFit, eff: pd.DataFrame, two_level: bool, top: list[str], resp) -> list:
    """Design-Expert's model graphs in one picture: the perturbation plot; the interaction plot of the model's
    strongest two-factor interaction (if it has one); the half-normal plot of the terms' effects (two-level
    designs); the cube plot of the three most significant factors (three or more). Returns the panels drawn."""
    from matplotlib.figure import Figure

    ylabel = _response_label(resp)
    # the strongest two-factor interaction (eff is ordered by |standardized effect|)
    pairs = {term_label(t, fit.factors): t for t in fit.terms if len(t) == 2 and t[0] != t[1]}
    inter = next((pairs[lab] for lab in eff.index if lab in pairs), None)
    panels = ["perturbation"] + (["interaction"] if inter else []) + (["half-normal"] if two_level else [])
    panels += ["cube"] if len(top) >= 3 else []
    fig = Figure(figsize=(4.2 * len(panels), 3.8), dpi=100)
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    for ax, kind in zip(axes, panels):
        if kind == "perturbation":
            pert = perturbation(fit)
            for f, g in pert.groupby("factor", sort=False):
                ax.plot(g["deviation"], g["predicted"], label=f)
            ax.set(xlabel="deviation from the centre (coded)", ylabel=ylabel, title="Perturbation")
            ax.legend(fontsize=7)
        elif kind == "interaction":
            a, b = inter
            d = interaction(fit, a, b)
            for level, g in d.groupby("b"):
                ax.plot(g["a"], g["predicted"], marker="", label=f"{b} {'+1' if level > 0 else '-1'}")
            ax.set(xlabel=f"{a} (coded)", ylabel=ylabel, title=f"Interaction {a}*{b}")
            ax.legend(fontsize=7)
        elif kind == "half-normal":
            hn = half_normal(eff["effect"])
            ax.plot(hn["abs_effect"], hn["quantile"], "o", ms=4)
            small = hn.iloc[: max(len(hn) // 2, 1)]
            slope = float(
                np.sum(small["quantile"] * small["abs_effect"]) / max(np.sum(small["abs_effect"] ** 2), 1e-300)
            )
            xs = np.array([0.0, float(hn["abs_effect"].max())])
            ax.plot(xs, slope * xs, "k--", lw=0.8)
            for _, r in hn.tail(min(4, len(hn))).iterrows():
                ax.annotate(
                    r["term"], (r["abs_effect"], r["quantile"]), fontsize=7, xytext=(3, -3), textcoords="offset points"
                )
            ax.set(xlabel="|effect|", ylabel="half-normal quantile", title="Half-normal plot of effects")
        else:
            a, b, c = top[:3]
            cb = cube(fit, [a, b, c])
            # an oblique projection of the cube, each corner labelled with its prediction
            px = cb[a] + 0.45 * cb[c]
            py = cb[b] + 0.35 * cb[c]
            for i in range(8):
                for j in range(i + 1, 8):
                    if int(np.sum(np.abs(cb.iloc[i, :3].to_numpy() - cb.iloc[j, :3].to_numpy()) > 0)) == 1:
                        ax.plot([px[i], px[j]], [py[i], py[j]], color="0.6", lw=0.8)
            for i in range(8):
                ax.annotate(
                    f"{cb['predicted'].iloc[i]:.3g}",
                    (px[i], py[i]),
                    fontsize=7,
                    ha="center",
                    va="center",
                    bbox={"boxstyle": "round", "fc": "white", "ec": "0.5"},
                )
            ax.set(title=f"Cube: {a} right, {b} up, {c} back", xticks=[], yticks=[])
            ax.axis("off")
            ax.set_xlim(-1.5, 1.9)
            ax.set_ylim(-1.5, 1.8)
    fig.suptitle(f"Model graphs: {resp['name']}", fontsize=9)
    fig.tight_layout()
    save_figure(fig, path)
    return panels


def _shared_levels(grids, count: int = 15) -> np.ndarray:
    """Contour levels spanning every grid of one response, so that its contour plots share one colour scale."""
    lo = min(float(np.nanmin(g)) for g in grids)
    hi = max(float(np.nanmax(g)) for g in grids)
    return np.linspace(lo, hi if hi > lo else lo + 1e-12, count)


def _factor_ranking(fit: ModelFit, eff: pd.DataFrame) -> list[str]:
    """Factors of the model, most significant first: a factor scores the largest
    |standardized effect| among the terms that contain it."""
    score: dict[str, float] = {}
    for t in fit.terms:
        s = abs(float(eff.loc[term_label(t, fit.factors), "standardized"]))
        for f in set(t):
            score[f] = max(score.get(f, 0.0), s if np.isfinite(s) else 0.0)
    return sorted(score, key=lambda f: (-score[f], fit.factors.index(f)))


# --------------------------------------------------------------------------------------------
# The report
# --------------------------------------------------------------------------------------------


def _point_type(row: np.ndarray) -> str:
    """Design role of a coded run, with the conventions of :mod:`designs`."""
    nz = np.abs(row) > 1e-9
    if not nz.any():
        return "center"
    if nz.sum() == 1 and len(row) > 1:
        return "axial"
    return "factorial"


def _fit_response(
    data: pd.DataFrame,
    name: str,
    fnames: list[str],
    model,
    alpha: float,
    eliminate: bool,
    levels: dict[str, Factor],
    transform=None,
) -> tuple[ModelFit, str | None]:
    terms, fallback = _choose_terms(data, fnames, model)
    if eliminate:
        fit = backward_eliminate(
            data, name, fnames, terms, alpha, hierarchical=True, levels=levels, transform=transform
        )
    else:
        fit = fit_model(data, name, fnames, terms, levels, transform)
    return fit, fallback


DESIRABILITY_STARTS = 40
"""Seeded starts of the desirability search (besides the design's runs)."""

DESIRABILITY_SHOWN = 10
"""Solutions of the desirability search listed in report.md (desirability.csv has them all)."""


def _desirability_section(out: Path, fits: dict, goals: dict, fmap: dict, labels: dict, region, files, result) -> list:
    """The multi-response optimisation: settings in the design region that maximise the overall desirability
    of the responses with a goal (:func:`analysis.optimize_desirability`), the ten best distinct solutions as a
    table and ``desirability.csv``; ``result["desirability"]`` the best (actual settings, predictions, D)."""
    fnames = list(fmap)
    sols = optimize_desirability(fits, goals, bounds=region, starts=DESIRABILITY_STARTS, seed=0)
    for f in fnames:
        sols[f"{f}_actual"] = fmap[f].to_actual(sols[f].to_numpy())
    sols.to_csv(out / "desirability.csv", index=False)
    files.append("desirability.csv")
    rows = []
    for k, r in sols.head(DESIRABILITY_SHOWN).iterrows():
        rows.append(
            [str(k + 1)]
            + [f"{r[f + '_actual']:.4g}" for f in fnames]
            + [f"{r[n]:.4g} ({r['d_' + n]:.3f})" for n in goals]
            + [f"{r['desirability']:.3f}"]
        )
    goal_text = "; ".join(
        f"{n}: {g.kind}"
        + (f" {g.target:g}" if g.kind == "target" else "")
        + f" in [{g.low:g}, {g.high:g}], weight {g.weight:g}, importance {g.importance}"
        for n, g in goals.items()
    )
    best = sols.iloc[0]
    result["desirability"] = _json(
        {
            "settings": {f: float(best[f + "_actual"]) for f in fnames},
            "predicted": {n: float(best[n]) for n in goals},
            "desirability": float(best["desirability"]),
            "solutions": len(sols),
        }
    )
    return [
        "",
        "## Multi-response optimisation (desirability)",
        "",
        f"Goals (Derringer-Suich; overall D the importance-weighted geometric mean of each d): {goal_text}. "
        f"{len(sols)} distinct solutions from {DESIRABILITY_STARTS} seeded starts and the runs (L-BFGS-B over the "
        f"design region; all in `desirability.csv`), the {DESIRABILITY_SHOWN} best:",
        "",
        _md_table(
            ["#", *(_axis_label(fmap[f], labels) for f in fnames), *(f"{n} (d)" for n in goals), "D"],
            rows,
            [False] + [True] * (len(fnames) + len(goals) + 1),
        ),
    ]


def _alias_section(fit: ModelFit) -> list[str]:
    """Report lines of the alias structure of a two-level design (every run at +/-1 in every factor, or a centre
    point): what each coefficient's estimate also carries of the interactions the model lacks, up to one order
    above the model's highest (at least two-factor, at most three-factor). Empty for other designs."""
    x = fit.data[fit.factors].to_numpy(dtype=float)
    centre = np.all(x == 0.0, axis=1)
    if not fit.terms or not np.all(np.isin(np.abs(x[~centre]), [1.0])):
        return []
    top = max(len(set(t)) for t in fit.terms)
    order = min(max(top + 1, 2), 3)
    lines = alias_lines(alias_matrix(fit, max_order=order))
    where = "-factor interactions" if order == 2 else "- and three-factor interactions"
    head = (
        f"What each estimate also carries of the interactions the model lacks (up to two{where}; the alias "
        "matrix (X1'X1)^-1 X1'X2 of the runs):"
    )
    if all(" = " in ln and ln.split(" = ")[1].count(" ") == 0 for ln in lines):
        return ["", "### Alias structure", "", f"{head} no term is aliased."]
    return ["", "### Alias structure", "", head, "", *[f"- {ln}" for ln in lines]]


def _fit_summary_md(summ: dict, fitted: str) -> list[str]:
    """The fit summary's three tables as Design-Expert prints them, and its suggestion."""
    orders = list(summ["sequential"].index)
    prev = ["Mean"] + orders[:-1]
    md = ["", "### Fit summary", "", "Sequential model sum of squares (type I):", ""]
    rows = []
    for (src, r), before in zip(summ["sequential"].iterrows(), prev):
        label = f"{src} vs {before}"
        if r["aliased"]:
            rows.append([label, "", _fmt_g(r["df"]), "", "", "", "Aliased"])
        else:
            rows.append(
                [
                    label,
                    _fmt_g(r["sum_sq"], 4),
                    _fmt_g(r["df"]),
                    _fmt_g(r["mean_sq"], 4),
                    _fmt_g(r["F"], 4),
                    format_p(r["p"]),
                    "",
                ]
            )
    md.append(_md_table(["Source", "Sum of Squares", "df", "Mean Square", "F-value", "p-value", ""], rows))
    lof = summ["lack_of_fit"]
    if lof.drop(columns="aliased").notna().any().any():
        md += ["", "Lack of fit (against pure error):", ""]
        md.append(
            _md_table(
                ["Source", "Sum of Squares", "df", "Mean Square", "F-value", "p-value", ""],
                [
                    [src, "", "", "", "", "", "Aliased"]
                    if r["aliased"]
                    else [
                        src,
                        _fmt_g(r["sum_sq"], 4),
                        _fmt_g(r["df"]),
                        _fmt_g(r["mean_sq"], 4),
                        _fmt_g(r["F"], 4),
                        format_p(r["p"]),
                        "",
                    ]
                    for src, r in lof.iterrows()
                ],
            )
        )
    md += ["", "Model summary statistics:", ""]
    md.append(
        _md_table(
            ["Source", "Std. Dev.", "R²", "Adjusted R²", "Predicted R²", "PRESS", ""],
            [
                [src, "", "", "", "", "", "Aliased"]
                if r["aliased"]
                else [
                    src,
                    _fmt_g(r["std_dev"], 4),
                    _fmt_g(r["r2"], 4),
                    _fmt_g(r["adj_r2"], 4),
                    _fmt_g(r["pred_r2"], 4),
                    _fmt_g(r["press"], 4),
                    "",
                ]
                for src, r in summ["statistics"].iterrows()
            ],
        )
    )
    sug = summ["suggested"]
    md += [
        "",
        f"**Suggested:** {sug or 'none (no order adds significantly to the mean)'}: the highest order that is not "
        f"aliased, adds significantly to the order below it and shows no significant lack of fit. Fitted below: "
        f"{fitted}.",
    ]
    return md


def diagnostics(fit: ModelFit, runs: Sequence, alpha: float = 0.05) -> dict:
    """Design-Expert's diagnostics of ``fit`` (runs: the run numbers of its rows, in order): the per-run table
    (:func:`analysis.influence`), the Box-Cox result, the runs past each line and one reading per plot.

    Lines: externally studentized residuals beyond the Bonferroni limit (:func:`analysis.outlier_limit`);
    Cook's distance above 4/n; leverage above 2p/n; |DFFITS| above 2 sqrt(p/n). Readings also test the
    residuals' normality (Shapiro-Wilk), a trend with run order (Spearman) and an uneven spread across each
    factor's levels (Brown-Forsythe), each at ``alpha``. ``notes`` holds what the report's notes should repeat."""
    tab = influence(fit)
    n, p = len(tab), int(fit.ols.df_model) + 1
    runs = np.asarray(list(runs))
    lim = outlier_limit(fit, alpha)
    lines = {
        "outlier_limit": lim,
        "cooks_line": 4.0 / n,
        "leverage_line": 2.0 * p / n,
        "dffits_line": 2.0 * math.sqrt(p / n),
    }
    ext = tab["externally_studentized"].to_numpy()
    flagged = {
        "outliers": runs[np.abs(ext) > lim].tolist(),
        "cooks": runs[tab["cooks_distance"].to_numpy() > lines["cooks_line"]].tolist(),
        "leverage": runs[tab["leverage"].to_numpy() > lines["leverage_line"] + 1e-12].tolist(),
        "dffits": runs[np.abs(tab["dffits"].to_numpy()) > lines["dffits_line"]].tolist(),
    }

    def runs_text(k: list) -> str:
        return ", ".join(str(r) for r in k)

    finite = np.isfinite(ext)
    read, notes = [], []
    if not finite.all():
        read.append(
            f"Run(s) {runs_text(runs[~finite].tolist())} have leverage 1 (the model passes through them): their "
            "studentized residuals are not defined and are left out below."
        )
    if finite.sum() >= 3 and np.ptp(ext[finite]) > 0:
        w = stats.shapiro(ext[finite])
        read.append(
            f"Normal plot: residuals {'consistent with' if w.pvalue >= alpha else 'depart from'} a normal "
            f"distribution (Shapiro-Wilk p {format_p(w.pvalue)})."
        )
    else:
        read.append("Normal plot: too few residuals (or all equal) to judge.")
    read.append(
        f"Residuals vs predicted: {'no run' if not flagged['outliers'] else 'run(s) ' + runs_text(flagged['outliers'])}"
        f" beyond the +-{lim:.3g} limit of the externally studentized residuals (Bonferroni at alpha {alpha:g})."
    )
    if finite.sum() >= 3:
        rho = stats.spearmanr(runs[finite], ext[finite])
        trend = rho.pvalue < alpha
        read.append(
            f"Residuals vs run order: {'a trend' if trend else 'no trend'} (Spearman rho {rho.statistic:.2f}, "
            f"p {format_p(rho.pvalue)})" + ("; look for drift in the runs." if trend else ".")
        )
    uneven, judged = [], []
    for f in fit.factors:
        x = fit.data[f].to_numpy(dtype=float)
        groups = [ext[(x == v) & finite] for v in np.unique(x)]
        # two runs sit at the same distance from their median, so a level of two has no spread of its own to
        # compare: Brown-Forsythe would divide by zero and call any difference between levels uneven
        groups = [g for g in groups if len(g) >= 3]
        if len(groups) >= 2 and all(np.ptp(g) > 0 for g in groups):
            judged.append(f)
            if stats.levene(*groups, center="median").pvalue < alpha:
                uneven.append(f)
    if uneven:
        spread = f"uneven spread across the levels of {', '.join(uneven)}"
    elif judged:
        spread = f"even spread across the levels of {', '.join(judged)}"
    else:
        spread = "too few runs per level to judge (at least two levels of three runs each)"
    read.append(f"Residuals vs each factor: {spread} (Brown-Forsythe).")
    read.append(f"Predicted vs actual: R² {fit.stats['r2']:.4f}; points off the line are the residuals above.")
    read.append(
        f"Cook's distance: {'no run' if not flagged['cooks'] else 'run(s) ' + runs_text(flagged['cooks'])} above the "
        f"4/n = {lines['cooks_line']:.3g} line."
    )
    read.append(
        f"Leverage: {'no run' if not flagged['leverage'] else 'run(s) ' + runs_text(flagged['leverage'])} above "
        f"2p/n = {lines['leverage_line']:.3g}."
    )
    read.append(
        f"DFFITS: {'no run' if not flagged['dffits'] else 'run(s) ' + runs_text(flagged['dffits'])} beyond "
        f"+-2 sqrt(p/n) = {lines['dffits_line']:.3g}."
    )
    bc = box_cox(fit, alpha)
    if "error" in bc:
        read.append(f"Box-Cox: not computed: {bc['error']}.")
    else:
        lo, hi = bc["interval"]
        ci = f"[{'< -3' if lo is None else f'{lo:.2f}'}, {'> 3' if hi is None else f'{hi:.2f}'}]"
        y = tab["actual"].to_numpy()
        ratio = f"max/min of the response {y.max() / y.min():.3g}"
        if lo is None and hi is None:
            read.append(
                f"Box-Cox: ln(residual SS) stays inside its confidence limit for every lambda in [-3, 3] ({ratio}): "
                "no transform recommended."
            )
        elif bc["recommended"] == "none":
            read.append(f"Box-Cox: lambda {bc['lambda_hat']:.2f} {ci} holds 1 ({ratio}): no transform recommended.")
        else:
            what = bc["recommended"] if bc["recommended"] != "power" else f"power {bc['lambda_hat']:.2f}"
            read.append(
                f"Box-Cox: lambda {bc['lambda_hat']:.2f} {ci} excludes 1 ({ratio}): recommended transform {what}."
            )
            notes.append(f"Box-Cox recommends the transform {what} (lambda {bc['lambda_hat']:.2f} {ci}).")
    if flagged["outliers"]:
        notes.append(
            f"run(s) {runs_text(flagged['outliers'])} beyond the outlier limit: check them before trusting the model."
        )
    return {
        "table": tab.assign(run=runs),
        "lines": lines,
        "flagged": flagged,
        "box_cox": {k: v for k, v in bc.items() if k not in ("lambdas", "ln_ss")},
        "box_cox_curve": (bc.get("lambdas"), bc.get("ln_ss")),
        "readings": read,
        "notes": notes,
    }


def _plot_diagnostics(out: Path, tag: str, fit: ModelFit, diag: dict, runs, used: pd.DataFrame, fnames, name) -> list:
    """diagnostics_<tag>.png (normal plot, residuals vs predicted and run order, predicted vs actual, Cook's
    distance, leverage, DFFITS, Box-Cox) and residuals_vs_factors_<tag>.png."""
    from matplotlib.figure import Figure

    tab, ln = diag["table"], diag["lines"]
    ext = tab["externally_studentized"].to_numpy()
    runs = np.asarray(list(runs))
    fig = Figure(figsize=(18, 8))
    axes = fig.subplots(2, 4)
    ax = axes[0, 0]
    (osm, osr), _ = stats.probplot(ext[np.isfinite(ext)], dist="norm")
    ax.plot(osr, osm, "o")
    ax.set(xlabel="externally studentized residual", ylabel="normal quantile", title="Normal plot of residuals")
    for ax, x, xl, title in (
        (axes[0, 1], tab["predicted"], "predicted", "Residuals vs predicted"),
        (axes[0, 2], runs, "run number", "Residuals vs run"),
    ):
        ax.plot(x, ext, "o")
        for v in (ln["outlier_limit"], -ln["outlier_limit"]):
            ax.axhline(v, color="r", ls="--")
        ax.axhline(0, color="k", lw=0.5)
        ax.set(xlabel=xl, ylabel="externally studentized residual", title=title)
    ax = axes[0, 3]
    ax.plot(tab["predicted"], tab["actual"], "o")
    lo, hi = (
        float(min(tab["actual"].min(), tab["predicted"].min())),
        float(max(tab["actual"].max(), tab["predicted"].max())),
    )
    ax.plot([lo, hi], [lo, hi], "k-", lw=0.8)
    ax.set(xlabel="predicted", ylabel="actual", title="Predicted vs actual")
    for ax, col, line, title in (
        (axes[1, 0], "cooks_distance", ln["cooks_line"], "Cook's distance (4/n line)"),
        (axes[1, 1], "leverage", ln["leverage_line"], "Leverage (2p/n line)"),
        (axes[1, 2], "dffits", ln["dffits_line"], "DFFITS (+-2 sqrt(p/n))"),
    ):
        ax.vlines(runs, 0, tab[col], lw=2)
        ax.plot(runs, tab[col], "o")
        ax.axhline(line, color="r", ls="--")
        if col == "dffits":
            ax.axhline(-line, color="r", ls="--")
        ax.set(xlabel="run number", ylabel=col.replace("_", " "), title=title)
    ax = axes[1, 3]
    lam, lss = diag["box_cox_curve"]
    bc = diag["box_cox"]
    if lam is not None:
        ax.plot(lam, lss, "-")
        ax.axhline(bc["ln_ss_limit"], color="r", ls="--", label="confidence limit")
        ax.axvline(bc["lambda_hat"], color="g", label=f"best {bc['lambda_hat']:.2f}")
        cur = bc.get("lambda_current", 1.0)
        ax.axvline(cur, color="b", ls=":", label=f"current ({cur:g})")
        # the limit line stays in view; a steep curve is cut 4 above it. An exact fit (residual SS 0) has no
        # finite limit: matplotlib's own limits then
        seen = np.asarray(lss, dtype=float)[np.isfinite(lss)]
        if len(seen) and np.isfinite(bc["ln_ss_limit"]):
            ax.set_ylim(seen.min() - 0.5, max(min(seen.max(), bc["ln_ss_limit"] + 4), bc["ln_ss_limit"] + 0.3))
        ax.legend(fontsize=8)
    else:
        ax.text(0.5, 0.5, bc.get("error", "not computed"), ha="center", va="center", wrap=True, transform=ax.transAxes)
    ax.set(xlabel="lambda", ylabel="ln(residual SS)", title="Box-Cox plot for power transforms")
    fig.suptitle(f"Diagnostics: {name}")
    fig.tight_layout()
    save_figure(fig, out / f"diagnostics_{tag}.png", dpi=90)
    k = len(fnames)
    fig = Figure(figsize=(4.5 * k, 4))
    axes = fig.subplots(1, k, squeeze=False)
    for ax, f in zip(axes[0], fnames):
        ax.plot(used[f].to_numpy(dtype=float), ext, "o")
        for v in (ln["outlier_limit"], -ln["outlier_limit"]):
            ax.axhline(v, color="r", ls="--")
        ax.axhline(0, color="k", lw=0.5)
        ax.set(xlabel=f"{f} (coded)", ylabel="externally studentized residual", title=f"Residuals vs {f}")
    fig.tight_layout()
    save_figure(fig, out / f"residuals_vs_factors_{tag}.png", dpi=90)
    return [f"diagnostics_{tag}.png", f"residuals_vs_factors_{tag}.png"]


def settling_section(out: Path, runs: Sequence[tuple[int, dict]]) -> list[str]:
    """``settling.png`` in ``out`` (each run's kinetic energy per particle [J] against time [s], log scale, its
    threshold dashed) and the report lines that read it; ``runs`` holds (run number, the world's ``settling``
    metric: time_s, kinetic_energy_j, threshold_j). No runs with a series: no picture, no lines."""
    from matplotlib.figure import Figure

    runs = [(k, st) for k, st in runs if st and len(st.get("time_s", []))]
    if not runs:
        return []
    fig = Figure(figsize=(7, 4.5))
    ax = fig.subplots()
    settled = []
    for k, st in runs:
        t, e = np.asarray(st["time_s"], float), np.asarray(st["kinetic_energy_j"], float)
        ax.semilogy(t, np.maximum(e, 1e-300), lw=1, label=f"run {k}")
        thr = float(st.get("threshold_j", 0.0))
        if thr > 0:
            settled.append(bool(len(e) and e[-1] < thr))
    thresholds = sorted({float(st.get("threshold_j", 0.0)) for _, st in runs} - {0.0})
    for thr in thresholds:
        ax.axhline(thr, color="k", ls="--", lw=1)
    ax.set(xlabel="time [s]", ylabel="kinetic energy per particle [J]", title="Settling of each run")
    if len(runs) <= 20:
        ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    save_figure(fig, Path(out) / "settling.png", dpi=90)
    lines = ["", "## Settling", ""]
    if thresholds:
        lines.append(
            f"{sum(settled)} of {len(settled)} runs end below their settle threshold (dashed: "
            + ", ".join(f"{v:.3g} J" for v in thresholds)
            + " per particle); a run above it was still moving when it stopped."
        )
    else:
        lines.append("The scene has no settle threshold: each run ran to its duration.")
    return lines + ["", "![settling of each run](settling.png)", ""]


def write_report(
    out_dir,
    data: pd.DataFrame,
    *,
    title: str,
    factors: list[Factor],
    labels: dict[str, str],
    responses: list[dict],
    model="linear",
    alpha=0.05,
    eliminate=False,
    design_kind: str = "",
    notes: list[str] | None = None,
) -> dict:
    """Analyse every response of a finished design and write the report into ``out_dir``.

    Args:
        out_dir: folder for the report (created when missing).
        data: one row per finished run: the coded factor columns (named by ``Factor.name``), the
            response columns, and optionally ``run``, ``point_type``, ``replicate``,
            ``world_seed``, ``wall_s``. A run whose response is NaN is left out of that
            response's fit and listed as failed.
        title: report title.
        factors: the design's factors with their coding (``low > high`` allowed).
        labels: factor name -> what it is (e.g. ``"restitution, particle-wall"``).
        responses: ``{"name": column, "unit": str, "target": float | None}`` each, optionally ``"goal"`` (a
            :class:`goals.Goal`) and ``"transform"`` (a :class:`transforms.Transform`: the model is fitted to it).
        model: ``"linear"``, ``"2fi"``, ``"quadratic"`` or a list of terms; when the runs cannot
            estimate it, the largest of quadratic > 2FI > linear that they can (said in the notes).
        alpha: significance level (elimination, significance remarks, Pareto limits, CIs).
        eliminate: hierarchical backward elimination of terms with p > alpha.
        design_kind: e.g. ``"Box-Behnken, 3 factors, 5 centre points"``.
        notes: lines appended to the report's notes.

    Writes ``report.md``, and per response ``anova_<r>.csv``, ``coefficients_<r>.csv``,
    ``pareto_<r>.png``, ``contour_<r>_<A>_<B>.png`` (pairs of the two or three most significant
    factors), ``surface_<r>_<A>_<B>.png`` (the most significant pair) and, with a target,
    ``optimum_<r>.csv``.

    Returns:
        ``{response: {"r2", "adj_r2", "pred_r2", "adeq_precision", "model_p", "terms",
        "equation_actual", "chosen", "predicted", "reachable", ...}, "files": [names]}``, JSON-ready
        (NaN as None). ``chosen`` holds actual-unit settings, None without a target or when the
        target is out of reach (then ``closest`` holds the region's extreme nearest it).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fmap = {f.name: f for f in factors}
    fnames = [f.name for f in factors]
    missing = [c for c in fnames + [r["name"] for r in responses] if c not in data.columns]
    if missing:
        raise ValueError(f"data has no column(s) {missing}")
    labels = dict(labels or {})
    data = data.reset_index(drop=True)
    n_runs = len(data)
    run_id = (data["run"] if "run" in data.columns else pd.Series(np.arange(1, n_runs + 1))).tolist()
    coded = data[fnames].to_numpy(float)
    ptype = data["point_type"].astype(str).tolist() if "point_type" in data.columns else [_point_type(r) for r in coded]
    rnames = [r["name"] for r in responses]
    ok = {r: np.isfinite(pd.to_numeric(data[r], errors="coerce").to_numpy(float)) for r in rnames}
    failed_any = ~np.logical_and.reduce([ok[r] for r in rnames]) if rnames else np.zeros(n_runs, bool)
    # the region spanned by the design (failed runs included: the design, not the survivors)
    region = {f: (float(data[f].min()), float(data[f].max())) for f in fnames}
    files: list[str] = []
    result: dict = {}
    auto_notes: list[str] = []

    md: list[str] = [f"# {title}", ""]
    md.append(
        f"**Design:** {design_kind or 'not stated'}; **runs:** {n_runs} "
        f"({int(failed_any.sum())} failed); **factors:** {len(fnames)}; "
        f"**requested model:** {_describe_model(model)}"
        + (f", hierarchical backward elimination at alpha = {alpha:g}" if eliminate else "")
        + "."
    )
    md += ["", "## Factors", ""]
    md.append(
        _md_table(
            ["Factor", "Name", "Unit", "Coded -1", "Coded 0", "Coded +1", "Design range (coded)"],
            [
                [
                    f.name,
                    labels.get(f.name, ""),
                    f.unit,
                    _fmt_g(f.low),
                    _fmt_g(f.centre),
                    _fmt_g(f.high),
                    f"{_fmt_g(region[f.name][0])} .. {_fmt_g(region[f.name][1])}",
                ]
                for f in factors
            ],
            [False, False, False, True, True, True, False],
        )
    )
    if any(f.low > f.high for f in factors):
        md += [
            "",
            "Reversed coding (coded -1 is the higher value) for: "
            + ", ".join(f.name for f in factors if f.low > f.high)
            + ".",
        ]

    # ---- run table
    extras = [c for c in _RUN_EXTRAS if c in data.columns]
    head = (
        ["Run", "Type"]
        + [f"{f} (coded)" for f in fnames]
        + [f"{f} (actual" + (f", {fmap[f].unit})" if fmap[f].unit else ")") for f in fnames]
        + [_response_label(r) for r in responses]
        + extras
    )
    rows = []
    for i in range(n_runs):
        rows.append(
            [run_id[i], ptype[i]]
            + [_fmt_g(v) for v in coded[i]]
            + [_fmt_g(fmap[f].to_actual(coded[i, j])) for j, f in enumerate(fnames)]
            + [_fmt_g(data.at[i, r], 6) if ok[r][i] else "failed" for r in rnames]
            + [_extra_cell(data.at[i, c]) for c in extras]
        )
    md += ["", "## Runs", "", _md_table(head, rows, [True, False] + [True] * (len(head) - 2))]
    if failed_any.any():
        md += [
            "",
            "### Failed runs",
            "",
            "Left out of the fit of the response(s) named; the design region and the run table still include them.",
            "",
        ]
        md.append(
            _md_table(
                ["Run", "Type", "Missing response(s)"],
                [
                    [run_id[i], ptype[i], ", ".join(r for r in rnames if not ok[r][i])]
                    for i in np.flatnonzero(failed_any)
                ],
            )
        )

    fits: dict[str, ModelFit] = {}
    for resp in responses:
        name = resp["name"]
        tag = _safe(name)
        used = data.loc[ok[name], fnames + [name]].astype(float).reset_index(drop=True)
        failed_runs = [run_id[i] for i in np.flatnonzero(~ok[name])]
        md += ["", f"## Response {_response_label(resp)}", ""]
        md.append(
            f"{len(used)} of {n_runs} runs used"
            + (f"; failed runs left out: {', '.join(map(str, failed_runs))}" if failed_runs else "")
            + "."
        )
        if len(used) < 2:
            auto_notes.append(f"{name}: fewer than two finished runs; not analysed.")
            md += ["", "Not analysed: fewer than two finished runs."]
            result[name] = _json(
                {
                    "r2": None,
                    "adj_r2": None,
                    "pred_r2": None,
                    "adeq_precision": None,
                    "model_p": None,
                    "terms": [],
                    "equation_actual": None,
                    "chosen": None,
                    "predicted": None,
                    "reachable": None,
                    "n_used": len(used),
                    "failed_runs": failed_runs,
                }
            )
            continue
        transform = resp.get("transform")
        fit, fallback = _fit_response(used, name, fnames, model, alpha, eliminate, fmap, transform)
        fits[name] = fit
        if fallback:
            auto_notes.append(f"{name}: {fallback}.")
            md += ["", f"**Model fallback:** {fallback}."]
        if fit.transform.kind != "none":
            md += [
                "",
                f"**Transform:** the model is fitted to {fit.transform.label(name)}: its fit summary, ANOVA, "
                "equations and diagnostics are on that scale; predictions, contours, solutions and intervals are "
                f"brought back to {name}'s units (the back-transformed mean, the median where the model scale's "
                "errors are symmetric).",
            ]

        # ---- fit summary: which order the runs support, before the chosen model's ANOVA
        summ = fit_summary(used, name, fnames, alpha, fit.transform)
        md += _fit_summary_md(summ, _model_name(fit))

        # ---- ANOVA
        anova = anova_frame(fit, alpha)
        anova.to_csv(out / f"anova_{tag}.csv", index=False)
        files.append(f"anova_{tag}.csv")
        md += [
            "",
            f"### ANOVA for {_model_name(fit)} model",
            "",
            "Type III (partial) sums of squares; pure error from replicated settings.",
            "",
        ]
        md.append(_md_table(ANOVA_COLUMNS, _anova_text_rows(fit, alpha), [False, True, True, True, True, True, False]))

        # ---- fit statistics
        s = fit.stats
        md += ["", "### Fit statistics", ""]
        md.append(
            _md_table(
                ["Statistic", "Value"],
                [
                    ["Std. Dev.", _fmt_g(s["std_dev"], 4, "n/a")],
                    ["Mean", _fmt_g(s["mean"], 6)],
                    ["C.V. %", _fmt_g(s["cv_pct"], 4, "n/a")],
                    ["R²", _fmt_g(s["r2"], 4, "n/a")],
                    ["Adjusted R²", _fmt_g(s["adj_r2"], 4, "n/a")],
                    ["Predicted R²", _fmt_g(s["pred_r2"], 4, "n/a")],
                    ["Adeq Precision", _fmt_g(s["adeq_precision"], 4, "n/a")],
                    ["PRESS", _fmt_g(s["press"], 4, "n/a")],
                ],
                [False, True],
            )
        )
        if np.isfinite(s["adj_r2"]) and np.isfinite(s["pred_r2"]) and abs(s["adj_r2"] - s["pred_r2"]) > 0.2:
            auto_notes.append(
                f"{name}: predicted R² {s['pred_r2']:.4f} is not within 0.2 of adjusted R² "
                f"{s['adj_r2']:.4f} (Design-Expert's rule of thumb): the model may not "
                f"predict new runs as well as it fits these."
            )
        if np.isfinite(s["adeq_precision"]) and s["adeq_precision"] < 4:
            auto_notes.append(
                f"{name}: adequate precision {s['adeq_precision']:.3g} < 4: weak signal "
                f"against noise; do not navigate the design space with this model."
            )
        if "Lack of Fit" in fit.anova.index and fit.anova.loc["Lack of Fit", "p"] < alpha:
            p_lof = format_p(fit.anova.loc["Lack of Fit", "p"])
            auto_notes.append(
                f"{name}: lack of fit is significant (p {p_lof}): "
                f"the model misses systematic variation that the pure error does not explain."
            )

        # ---- coefficients and equations
        coefs = _coefficients_frame(fit, alpha)
        coefs.to_csv(out / f"coefficients_{tag}.csv", index=False)
        files.append(f"coefficients_{tag}.csv")
        ci = f"{100 * (1 - alpha):g}%"
        md += ["", "### Coefficients in coded units", ""]
        md.append(
            _md_table(
                ["Term", "Estimate", "Std. Error", f"{ci} CI Low", f"{ci} CI High", "p-value", "VIF"],
                [
                    [
                        r["Term"],
                        _fmt_g(r["Coefficient Estimate"], 5),
                        _fmt_g(r["Standard Error"], 4),
                        _fmt_g(r[f"{ci} CI Low"], 5),
                        _fmt_g(r[f"{ci} CI High"], 5),
                        format_p(r["p-value"]),
                        _fmt_g(r["VIF"], 4),
                    ]
                    for _, r in coefs.iterrows()
                    if np.isfinite(r["Coefficient Estimate"])
                ],
                [False] + [True] * 6,
            )
        )
        aliases = _alias_section(fit)
        md += aliases
        eq_coded = fit.equation_string("coded", 6)
        eq_actual = fit.equation_string("actual", 6)
        md += [
            "",
            "### Final equation",
            "",
            "In coded factors (-1 low, +1 high; compare coefficients to rank effects):",
            "",
            "```",
            eq_coded,
            "```",
            "",
            "In actual factors (do not compare coefficients: they depend on the units):",
            "",
            "```",
            eq_actual,
            "```",
            "",
        ]
        md.append(
            "where "
            + "; ".join(
                f"{f.name} = " + (labels.get(f.name) or f.name) + (f" [{f.unit}]" if f.unit else "") for f in factors
            )
            + "."
        )
        if eliminate:
            if fit.elimination:
                md += ["", f"Eliminated (backward, hierarchical, alpha = {alpha:g}), in order:", ""]
                md.append(
                    _md_table(
                        ["Term", "p-value when removed"],
                        [[e["removed"], format_p(e["p"])] for e in fit.elimination],
                        [False, True],
                    )
                )
            else:
                md += ["", f"No term eliminated (every removable term has p <= {alpha:g})."]

        # ---- pictures
        pics: list[str] = []
        if fit.terms:
            eff = effects_table(fit.data, name, fnames, fit.terms)  # on the model scale
            df_res = int(fit.anova.loc["Residual", "df"])
            _plot_pareto(out / f"pareto_{tag}.png", eff, alpha, df_res, f"Pareto chart, {name} ({eff.attrs['method']})")
            pics.append(f"pareto_{tag}.png")
            ranked = _factor_ranking(fit, eff)
            if len(ranked) < 2:  # one active factor: pair it with the next design factor
                spread = [f for f in fnames if f not in ranked and region[f][1] > region[f][0]]
                ranked += spread[: 2 - len(ranked)]
            top = ranked[:3] if len(ranked) >= 3 else ranked[:2]
            # design order on the axes and in file names, whatever the ranking
            pair0 = sorted(top[:2], key=fnames.index)
            top = sorted(top, key=fnames.index)
        else:
            top = []
        sol = None
        target = resp.get("target")
        if target is not None and fit.terms:
            sol = solve_target(fit, float(target), region, n_samples=_TARGET_SAMPLES, seed=0)
        chosen_coded = sol.chosen if (sol is not None and sol.reachable) else None
        if len(top) >= 2:
            pairs = [(a, b) for i, a in enumerate(top) for b in top[i + 1 :]]
            grids = [_grid(fit, a, b, region)[2] for a, b in pairs]
            levels = _shared_levels(grids)
            for a, b in pairs:
                fn = f"contour_{tag}_{_safe(a)}_{_safe(b)}.png"
                _plot_contour(out / fn, fit, fmap[a], fmap[b], region, labels, resp, used, chosen_coded, levels)
                pics.append(fn)
            fn = f"surface_{tag}_{_safe(pair0[0])}_{_safe(pair0[1])}.png"
            _plot_surface(out / fn, fit, fmap[pair0[0]], fmap[pair0[1]], region, labels, resp, used)
            pics.append(fn)
        if fit.terms:
            # a two-level design: every run a corner (all factors +-1) or a centre point
            xs = np.abs(np.round(used[fnames].to_numpy(float), 9))
            two_level = bool(np.all(np.all(xs == 1.0, axis=1) | np.all(xs == 0.0, axis=1)))
            fn = f"model_graphs_{tag}.png"
            panels = _plot_model_graphs(out / fn, fit, eff, two_level, _factor_ranking(fit, eff), resp)
            files.append(fn)
            md += ["", "### Model graphs", ""]
            md.append(
                "Perturbation plot (each factor alone from -1 to +1 coded about the centre)"
                + ("; interaction plot of the strongest two-factor term" if "interaction" in panels else "")
                + ("; half-normal plot of the terms' effects" if "half-normal" in panels else "")
                + ("; cube plot of the three most significant factors" if "cube" in panels else "")
                + f" (predictions in {name}'s units):"
            )
            md += ["", f"![model graphs of {name}]({fn})", ""]
        files += pics
        if pics:
            md += ["", "### Pictures", ""]
            if fit.terms:
                md.append(
                    f"Pareto chart of standardized effects ({eff.attrs['method']}; limits at "
                    f"alpha = {alpha:g}, two-sided, and Bonferroni); orange positive, blue negative:"
                )
                md += ["", f"![Pareto chart of {name}]({pics[0]})", ""]
            if len(pics) > 1:
                md.append(
                    "Fitted model over the design region in actual units; factors off the plot "
                    "at their centre; one colour scale for all of this response's contour plots, lines labelled; "
                    "black dots: runs projected onto the plane (on the surface: at their measured values)"
                    + ("; red line: the target" if target is not None else "")
                    + "."
                )
                md.append("")
                md += [f"![{p[:-4]}]({p})" for p in pics[1:]]

        # ---- diagnostics
        runs_used = [run_id[i] for i in np.flatnonzero(ok[name])]
        diag = diagnostics(fit, runs_used, alpha)
        files += _plot_diagnostics(out, tag, fit, diag, runs_used, used, fnames, name)
        md += ["", "### Diagnostics", ""]
        md += [f"- {line}" for line in diag["readings"]]
        md += ["", f"![diagnostics of {name}](diagnostics_{tag}.png)", ""]
        md += [f"![residuals of {name} against each factor](residuals_vs_factors_{tag}.png)", ""]
        auto_notes += [f"{name}: {n}" for n in diag["notes"]]
        y_used = used[name].to_numpy(dtype=float)
        if fit.terms and np.all(y_used > 0):
            (low, at), _ = response_extremes(fit, region)
            if low < 0:
                where = ", ".join(f"{f} {at[j]:+.2f}" for j, f in enumerate(fnames))
                auto_notes.append(
                    f"{name}: the model predicts {low:.3g} inside the design region (coded {where}) for a response "
                    f"measured between {y_used.min():.3g} and {y_used.max():.3g}: a transform (Box-Cox, in the "
                    "diagnostics) or another model order may fit better."
                )

        # ---- target
        entry = {
            "aliases": [line[2:] for line in aliases if line.startswith("- [")],
            "model": _model_name(fit),
            "model_fallback": fallback,
            "n_used": len(used),
            "failed_runs": failed_runs,
            "eliminated": [e["removed"] for e in fit.elimination],
            "diagnostics": {k: v for k, v in diag.items() if k not in ("table", "box_cox_curve")},
            "suggested_model": summ["suggested"],
            "chosen": None,
            "predicted": None,
            "reachable": None,
        }
        unit = f" {resp['unit']}" if resp.get("unit") else ""
        if target is not None and sol is None:
            # the mean model predicts one value everywhere: the target is either within its interval or out of reach
            mean, lo, hi = mean_interval(fit, alpha)
            inside = bool(lo <= float(target) <= hi)
            md += [
                "",
                "### Target",
                "",
                f"Target {target:g}{unit}: no model terms left, so the model predicts its mean, {mean:.4g}{unit}, at "
                f"every setting of the design region ({100 * (1 - alpha):g} % confidence interval {lo:.4g} .. "
                f"{hi:.4g}{unit}). No settings are chosen.",
                "",
                f"The target lies **{'inside' if inside else 'outside'}** that interval"
                + (
                    ": the region gives it within the runs' scatter, whatever the factors."
                    if inside
                    else f", {abs(float(target) - mean):.3g}{unit} {'above' if target > mean else 'below'} the mean: "
                    "no setting in the design region is predicted to reach it."
                ),
            ]
            if not inside:
                auto_notes.append(
                    f"{name}: target {target:g} is outside the mean model's interval {lo:.4g} .. {hi:.4g}: no factor "
                    "moves the response out of its scatter in the design region; widen the factor ranges or add a "
                    "factor that moves it."
                )
            entry.update(reachable=inside, predicted=mean, mean_interval=[lo, hi])
        if sol is not None:
            fam = sol.family
            opt = pd.DataFrame({f: fam[f"{f}_actual"] for f in fnames})
            for f in fnames:
                opt[f"{f}_coded"] = fam[f]
            opt["predicted"] = fam["predicted"]
            opt["distance_coded"] = fam["distance"]
            opt["on_target"] = sol.reachable
            key = [round(float(sol.chosen[f]), 12) for f in fnames]
            opt["chosen"] = [
                sol.reachable and [round(float(r[f]), 12) for f in fnames] == key for _, r in fam.iterrows()
            ]
            opt.to_csv(out / f"optimum_{tag}.csv", index=False)
            files.append(f"optimum_{tag}.csv")
            settings = {f: float(sol.chosen_actual[f]) for f in fnames}
            pred = float(sol.chosen["predicted"])
            lo, hi = sol.predicted_range
            md += [
                "",
                "### Target",
                "",
                f"Target {target:g}{unit}; over the design region the model predicts {lo:.4g} .. {hi:.4g}{unit}.",
            ]
            table = _md_table(
                ["Factor", "Coded", "Actual"],
                [[_axis_label(fmap[f], labels), f"{sol.chosen[f]:.4f}", f"{settings[f]:.6g}"] for f in fnames],
                [False, True, True],
            )
            if sol.reachable:
                md += [
                    "",
                    f"**Reachable** in the design region. {len(fam)} solutions found on the "
                    f"target contour (`optimum_{tag}.csv`): the target is met on a set of "
                    f"settings, not at one point.",
                    "",
                    f"Chosen by rule: {sol.rule}; distance {sol.chosen['distance']:.4f} coded units from the centre.",
                    "",
                    table,
                    "",
                    f"Predicted {name} at the chosen settings: {pred:.6g}{unit}.",
                ]
                ci = confirmation_interval(fit, {f: float(sol.chosen[f]) for f in fnames}, alpha=alpha)
                # what a confirmation of any number of runs needs (Design-Expert's confirmation node)
                # on the model's scale, with the transform that brings an interval back
                entry["confirmation"] = {
                    k: ci.get("model_scale", ci)["predicted"] if k == "predicted" else ci[k]
                    for k in ("predicted", "mse", "h0", "df")
                } | {
                    "alpha": alpha,
                    "transform": {"kind": fit.transform.kind, "power": fit.transform.power, "k": fit.transform.k},
                }
                entry.update(chosen=settings, predicted=pred, reachable=True)
            else:
                md += [
                    "",
                    "**Not reachable** in the design region: the target lies outside the "
                    "predicted range. No settings are chosen; the closest ones (the region's "
                    "extreme nearest the target) are:",
                    "",
                    table,
                    "",
                    f"Predicted {name} there: {pred:.6g}{unit}.",
                ]
                auto_notes.append(
                    f"{name}: target {target:g} is outside the predicted range "
                    f"{lo:.4g} .. {hi:.4g} of the design region: no settings in it reach "
                    f"the target; widen the factor ranges to look further."
                )
                entry.update(reachable=False, closest={**settings, "predicted": pred})
            entry["n_solutions"] = len(fam) if sol.reachable else 0
            entry["predicted_range"] = [lo, hi]
        entry.update(
            {
                "r2": s["r2"],
                "adj_r2": s["adj_r2"],
                "pred_r2": s["pred_r2"],
                "adeq_precision": s["adeq_precision"],
                "model_p": fit.anova.loc["Model", "p"],
                "terms": fit.labels,
                "equation_coded": eq_coded,
                "equation_actual": eq_actual,
            }
        )
        result[name] = _json(entry)

    goals = {r["name"]: r["goal"] for r in responses if r.get("goal") is not None and r["name"] in fits}
    if goals:
        md += _desirability_section(out, fits, goals, fmap, labels, region, files, result)
    all_notes = auto_notes + list(notes or [])
    md += ["", "## Notes", ""]
    md += [f"- {n}" for n in all_notes] if all_notes else ["None."]
    (out / "report.md").write_text("\n".join(md) + "\n", encoding="utf-8")
    files.insert(0, "report.md")
    result["files"] = files
    return result
