"""The analysis report of a finished design (warpdem.study.report) on the seed papers' run tables."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from warpdem.study.analysis import backward_eliminate, fit_model
from warpdem.study.designs import Factor, full_factorial
from warpdem.study.report import ANOVA_COLUMNS, format_anova, format_p, write_report

REF = Path(__file__).resolve().parents[2] / "studies" / "reference"
AOR = {"name": "aor_deg", "unit": "deg"}


def _bbd():
    runs = pd.read_csv(REF / "pellets_bbd_runs.csv")
    lv = pd.read_csv(REF / "pellets_bbd_levels.csv")
    # Table 9 prints -1 as the HIGH value: reversed coding
    factors = [Factor(r.factor, r.level_minus1, r.level_plus1) for r in lv.itertuples()]
    labels = {r.factor: f"{r.parameter}, {r.pair}" for r in lv.itertuples()}
    return runs, factors, labels


def _ccd():
    runs = pd.read_csv(REF / "wetfeed_ccd_runs.csv")
    lv = pd.read_csv(REF / "wetfeed_ccd_levels.csv")
    factors = [Factor.from_centre_step(r.factor, r.level_0, r.level_plus1 - r.level_0) for r in lv.itertuples()]
    return runs, factors, {r.factor: r.parameter for r in lv.itertuples()}


def _pb():
    runs = pd.read_csv(REF / "pellets_pb_runs.csv")
    lv = pd.read_csv(REF / "pellets_pb_levels.csv")
    factors = [Factor(r.factor, r.low, r.high) for r in lv.itertuples()]
    return runs, factors, {r.factor: f"{r.parameter}, {r.pair}" for r in lv.itertuples()}


def _aor_report(out: Path, table: tuple, title: str, target: float | None, model: str = "quadratic", **kw) -> dict:
    """write_report of a seed run ``table`` ((runs, factors, labels) as _bbd, _ccd, _pb return it) for the
    angle of repose with ``target`` [deg]; ``kw``: write_report's other options."""
    runs, factors, labels = table
    responses = [{**AOR, "target": target}]
    return write_report(out, runs, title=title, factors=factors, labels=labels, responses=responses, model=model, **kw)


@pytest.fixture(scope="module")
def bbd_report(tmp_path_factory):
    runs, factors, labels = _bbd()
    out = tmp_path_factory.mktemp("bbd")
    kind = "Box-Behnken, 3 factors, 5 centre points"
    res = _aor_report(out, (runs, factors, labels), "Pellets BBD", 28.27, design_kind=kind, notes=["seed 000 Table 10"])
    return out, res, runs, factors


@pytest.fixture(scope="module")
def ccd_report(tmp_path_factory):
    runs, factors, labels = _ccd()
    out = tmp_path_factory.mktemp("ccd")
    kind = "central composite, alpha 2, 9 centre points"
    res = _aor_report(out, (runs, factors, labels), "Wet feed CCD", 54.25, design_kind=kind)
    return out, res, runs, factors


def _anova_csv_matches_fit(path: Path, fit) -> pd.DataFrame:
    csv = pd.read_csv(path, keep_default_na=False, na_values=[""], dtype={"p-value": str})
    assert list(csv.columns) == ANOVA_COLUMNS
    assert list(csv["Source"]) == list(fit.anova.index)
    np.testing.assert_allclose(csv["Sum of Squares"], fit.anova["sum_sq"], rtol=1e-12)
    assert list(csv["df"]) == list(fit.anova["df"])
    np.testing.assert_allclose(csv["F-value"], fit.anova["F"], rtol=1e-12)
    ss = csv.set_index("Source")["Sum of Squares"]
    assert ss["Model"] + ss["Residual"] == pytest.approx(ss["Cor Total"], rel=1e-9)
    if "Lack of Fit" in ss:
        assert ss["Lack of Fit"] + ss["Pure Error"] == pytest.approx(ss["Residual"], rel=1e-9)
    return csv


def test_bbd_report_files_anova_and_target(bbd_report):
    """Seed 000's Box-Behnken (Table 10, reversed coding of Table 9), full quadratic, target
    28.27 deg: every file is written; the ANOVA CSV is fit_model's table (Model + Residual =
    Cor Total, Lack of Fit + Pure Error = Residual, p < 1e-4 printed '< 0.0001'); the chosen
    setting predicts the target to 1e-6 and lies in the design region."""
    out, res, runs, factors = bbd_report
    expected = {
        "report.md",
        "anova_aor_deg.csv",
        "coefficients_aor_deg.csv",
        "pareto_aor_deg.png",
        "contour_aor_deg_C_D.png",
        "contour_aor_deg_C_E.png",
        "contour_aor_deg_D_E.png",
        "surface_aor_deg_C_D.png",
        "optimum_aor_deg.csv",
        "diagnostics_aor_deg.png",
        "residuals_vs_factors_aor_deg.png",
        "model_graphs_aor_deg.png",
    }
    assert set(res["files"]) == expected
    for name in expected:
        assert (out / name).stat().st_size > 0
    json.dumps(res, allow_nan=False)

    fit = fit_model(runs, "aor_deg", ["C", "D", "E"], "quadratic", factors)
    csv = _anova_csv_matches_fit(out / "anova_aor_deg.csv", fit)
    assert {"Lack of Fit", "Pure Error"} <= set(csv["Source"])
    p = csv.set_index("Source")["p-value"]
    assert p["Model"] == "< 0.0001" and p["C"] == "< 0.0001" and p["E"] == "0.0004"
    r = res["aor_deg"]
    assert r["r2"] == pytest.approx(fit.stats["r2"]) and r["pred_r2"] == pytest.approx(fit.stats["pred_r2"])
    assert r["model_p"] == pytest.approx(fit.anova.loc["Model", "p"])
    assert r["terms"] == fit.labels and r["equation_actual"] == fit.equation_string("actual", 6)

    coef = pd.read_csv(out / "coefficients_aor_deg.csv").set_index("Term")
    np.testing.assert_allclose(
        coef.loc[fit.labels, "Coefficient Estimate"], fit.coefficients.loc[fit.labels, "coef"], rtol=1e-12
    )
    assert coef.loc["C^2", "Actual Coefficient"] == pytest.approx(fit.equation("actual")[("C", "C")])
    assert coef.loc["C", "VIF"] == pytest.approx(1.0)

    assert r["reachable"] is True
    fmap = {f.name: f for f in factors}
    chosen = r["chosen"]
    assert fit.predict_actual(chosen)[0] == pytest.approx(28.27, abs=1e-6)
    assert r["predicted"] == pytest.approx(28.27, abs=1e-6)
    for f, v in chosen.items():
        lo, hi = sorted((fmap[f].low, fmap[f].high))
        assert lo - 1e-12 <= v <= hi + 1e-12
    opt = pd.read_csv(out / "optimum_aor_deg.csv")
    assert len(opt) > 10 and opt["chosen"].sum() == 1
    np.testing.assert_allclose(opt["predicted"], 28.27, atol=1e-5)
    assert (opt[["C_coded", "D_coded", "E_coded"]].abs() <= 1 + 1e-9).all().all()
    row = opt[opt["chosen"]].iloc[0]
    assert row["distance_coded"] == pytest.approx(opt["distance_coded"].min())
    assert row["C"] == pytest.approx(chosen["C"])

    md = (out / "report.md").read_text()
    for text in (
        "# Pellets BBD",
        "Box-Behnken",
        "17 (0 failed)",
        "| Lack of Fit |",
        "< 0.0001",
        "Adeq Precision",
        "C.V. %",
        "Reachable",
        "nearest the design centre",
        "![Pareto chart of aor_deg](pareto_aor_deg.png)",
        "(contour_aor_deg_C_D.png)",
        "seed 000 Table 10",
        "Reversed coding",
        fit.equation_string("coded", 6),
        "### Fit summary",
        "| Quadratic vs 2FI |",
        "**Suggested:** Quadratic",
        "### Diagnostics",
        "Cook's distance:",
        "Box-Cox: ln(residual SS) stays inside its confidence limit",
        "(diagnostics_aor_deg.png)",
    ):
        assert text in md, text
    assert r["suggested_model"] == "Quadratic"
    d = r["diagnostics"]
    assert d["lines"]["cooks_line"] == pytest.approx(4 / 17) and d["lines"]["leverage_line"] == pytest.approx(20 / 17)


def test_ccd_report_alpha_two_lack_of_fit(ccd_report):
    """Seed 001's CCD (alpha 2, 9 centre runs): significant lack of fit against 8 df of pure
    error is reported; the target 54.25 deg is solved in the axial region [-2, 2]^3."""
    out, res, runs, factors = ccd_report
    fit = fit_model(runs, "aor_deg", ["X1", "X2", "X3"], "quadratic", factors)
    csv = _anova_csv_matches_fit(out / "anova_aor_deg.csv", fit).set_index("Source")
    assert csv.loc["Pure Error", "df"] == 8 and csv.loc["Lack of Fit", "df"] == 5
    assert csv.loc["Lack of Fit", "p-value"] == "< 0.0001"
    assert csv.loc["Lack of Fit", "Significance"] == "significant"
    r = res["aor_deg"]
    assert r["reachable"] and r["predicted"] == pytest.approx(54.25, abs=1e-6)
    opt = pd.read_csv(out / "optimum_aor_deg.csv")
    coded = opt[["X1_coded", "X2_coded", "X3_coded"]].abs()
    assert (coded <= 2 + 1e-9).all().all() and coded.max().max() > 1  # the axial region, not the cube
    md = (out / "report.md").read_text()
    assert "lack of fit is significant" in md
    assert "| Pure Error | 4.88 | 8 |" in md


def test_pb_linear_report_and_unreachable_target(tmp_path):
    """Seed 000's 12-run Plackett-Burman, linear model: R^2 0.9441 (Table 7), no lack of fit
    row without replicates; a 90 deg target is outside the predicted range and reported as
    unreachable, with no chosen settings; the alias structure is listed (partial, 1/3)."""
    runs, factors, labels = _pb()
    res = _aor_report(tmp_path, (runs, factors, labels), "Pellets PB", 90.0, "linear", design_kind="Plackett-Burman")
    fit = fit_model(runs, "aor_deg", list("ABCDEF"), "linear", factors)
    csv = _anova_csv_matches_fit(tmp_path / "anova_aor_deg.csv", fit)
    assert "Lack of Fit" not in set(csv["Source"])
    r = res["aor_deg"]
    assert round(r["r2"], 4) == 0.9441
    assert r["reachable"] is False and r["chosen"] is None
    assert r["closest"]["predicted"] == pytest.approx(r["predicted_range"][1])
    assert r["predicted_range"][1] < 90
    assert (tmp_path / "pareto_aor_deg.png").exists()
    assert len([f for f in res["files"] if f.startswith("contour_")]) == 3
    md = (tmp_path / "report.md").read_text()
    assert "**Not reachable**" in md and "outside the predicted range" in md
    # seed 000's PB has 6 factors in 12 runs: each main effect carries 1/3 of the 10 two-factor interactions
    # without it, and its report lists them
    assert "### Alias structure" in md and len(r["aliases"]) == 7
    assert all(line.count("0.333") == 10 for line in r["aliases"][1:])


def test_failed_run_excluded_and_listed(tmp_path):
    """A run whose response is NaN (a failed simulation) is left out of the fit, which then
    equals fit_model on the other 16 runs, and is listed as failed; optional run-table columns
    (point_type, replicate, wall_s) are shown."""
    runs, factors, labels = _bbd()
    runs = runs.assign(
        point_type=np.where(runs["run"] > 12, "center", "edge"), replicate=1, wall_s=np.linspace(10, 20, len(runs))
    )
    runs.loc[runs["run"] == 5, "aor_deg"] = np.nan
    res = _aor_report(tmp_path, (runs, factors, labels), "BBD with a failure", None)
    r = res["aor_deg"]
    assert r["failed_runs"] == [5] and r["n_used"] == 16
    assert r["chosen"] is None and r["reachable"] is None and "optimum_aor_deg.csv" not in res["files"]
    fit = fit_model(runs[runs["run"] != 5], "aor_deg", ["C", "D", "E"], "quadratic")
    _anova_csv_matches_fit(tmp_path / "anova_aor_deg.csv", fit)
    assert r["r2"] == pytest.approx(fit.stats["r2"])
    md = (tmp_path / "report.md").read_text()
    assert "17 (1 failed)" in md and "### Failed runs" in md
    assert "| 5 | edge | aor_deg |" in md
    assert "failed runs left out: 5" in md
    assert "| replicate | wall_s |" in md


def test_model_fallback_to_largest_estimable(tmp_path):
    """A 2^3 factorial with centre points cannot separate A^2, B^2, C^2 (all equal 1 on the
    corners and 0 at the centre): a requested quadratic falls back to 2FI, not linear; the PB
    design cannot even estimate 2FI and falls back to linear. Both are said in the notes."""
    d = full_factorial(3, center_points=3).reset_index(drop=True)
    noise = np.array([0.1, -0.2, 0.15, 0.05, -0.1, 0.2, -0.05, 0.0, 0.3, -0.2, 0.1])
    d["y"] = 10 + 2 * d["A"] - d["B"] + 0.5 * d["A"] * d["B"] + noise
    factors = [Factor("A", 0, 1), Factor("B", 10, 20, "K"), Factor("C", -1, 1)]
    res = write_report(
        tmp_path / "ff",
        d,
        title="FF",
        factors=factors,
        labels={"A": "first"},
        responses=[{"name": "y", "unit": "", "target": 11.0}],
        model="quadratic",
    )
    r = res["y"]
    assert r["model"] == "2FI" and r["terms"] == ["A", "B", "C", "AB", "AC", "BC"]
    assert "2FI" in r["model_fallback"]
    md = (tmp_path / "ff" / "report.md").read_text()
    assert "Model fallback" in md and "not estimable" in md.split("## Notes")[1]

    res = _aor_report(tmp_path / "pb", _pb(), "PB", None, "2fi")
    assert res["aor_deg"]["terms"] == list("ABCDEF") and "Linear" in res["aor_deg"]["model_fallback"]


def test_elimination_reported(tmp_path):
    """eliminate=True gives backward_eliminate's hierarchical model (seed 001 CCD at alpha
    0.05) and lists the removed terms with their p-values."""
    runs, factors, labels = _ccd()
    res = _aor_report(tmp_path, (runs, factors, labels), "CCD reduced", None, eliminate=True)
    back = backward_eliminate(runs, "aor_deg", ["X1", "X2", "X3"], "quadratic", 0.05, levels=factors)
    r = res["aor_deg"]
    assert r["terms"] == back.labels and r["eliminated"] == [e["removed"] for e in back.elimination]
    assert r["model"] == "Reduced Quadratic"
    _anova_csv_matches_fit(tmp_path / "anova_aor_deg.csv", back)
    md = (tmp_path / "report.md").read_text()
    assert "Eliminated (backward, hierarchical" in md
    assert f"| {back.elimination[0]['removed']} | {format_p(back.elimination[0]['p'])} |" in md


def test_format_anova_and_p_values():
    """The terminal ANOVA has Design-Expert's columns and rows; p-values print as
    '< 0.0001' below 1e-4, four decimals otherwise, blank when undefined."""
    runs, factors, _ = _bbd()
    fit = fit_model(runs, "aor_deg", ["C", "D", "E"], "quadratic", factors)
    text = format_anova(fit)
    for src in (
        "Source",
        "Sum of Squares",
        "Mean Square",
        "F-value",
        "p-value",
        "Model",
        "C^2",
        "Residual",
        "Lack of Fit",
        "Pure Error",
        "Cor Total",
        "< 0.0001",
        "not significant",
    ):
        assert src in text, src
    assert text.splitlines()[0].startswith("ANOVA for Quadratic model")
    assert format_p(3e-5) == "< 0.0001" and format_p(0.00482) == "0.0048" and format_p(float("nan")) == ""
    assert format_p(1e-4) == "0.0001"


def test_desirability_of_two_responses(tmp_path):
    """Seed 000's Box-Behnken with a second response, y2 = 2 + C (coded), to minimise on [1, 3], and the angle
    aimed at 24 deg in [18, 30] (importance 5 against 1): the report's multi-response section and
    desirability.csv; the best solution's D is the Derringer-Suich D of the two fitted models at its
    settings, it is at least the D of every design run (the search starts from them), and it lies in the
    design region."""
    from warpdem.study.analysis import Goal, desirability, fit_model

    runs, factors, labels = _bbd()
    runs = runs.copy()
    runs["y2"] = 2.0 + runs["C"]
    goals = {"aor_deg": Goal("target", 18, 30, target=24, importance=5), "y2": Goal("minimize", 1, 3, importance=1)}
    responses = [{**AOR, "target": None, "goal": goals["aor_deg"]}, {"name": "y2", "unit": "", "goal": goals["y2"]}]
    res = write_report(
        tmp_path, runs, title="BBD", factors=factors, labels=labels, responses=responses, model="quadratic"
    )
    md = (tmp_path / "report.md").read_text()
    assert "## Multi-response optimisation (desirability)" in md and (tmp_path / "desirability.csv").exists()
    sols = pd.read_csv(tmp_path / "desirability.csv")
    fits = {r: fit_model(runs, r, list("CDE"), "quadratic") for r in goals}
    best = sols.iloc[0]
    x = best[list("CDE")].to_numpy(dtype=float)[None, :]
    D = desirability({r: fits[r].predict(x) for r in goals}, goals)[0]
    assert best["desirability"] == pytest.approx(D, rel=1e-9) == pytest.approx(res["desirability"]["desirability"])
    D_runs = desirability({r: fits[r].predict(runs[list("CDE")]) for r in goals}, goals)
    assert best["desirability"] >= D_runs.max() - 1e-9
    assert np.all(np.abs(x) <= 1 + 1e-9)


def test_model_graphs_data_against_the_fit_and_scipy(tmp_path):
    """The model graphs' numbers: the perturbation curve of each factor is the fit's prediction with that factor
    alone moved; the interaction plot's two lines are the predictions at B = -1 and +1; the cube's corners are the
    predictions there; the half-normal quantiles are SciPy's halfnorm.ppf((i - 0.5) / m). A two-level design's
    report draws the half-normal plot; the Box-Behnken's (not two-level) draws the cube and no half-normal."""
    from scipy import stats

    from warpdem.study.analysis import cube, half_normal, interaction, perturbation

    runs = full_factorial(3).assign(centre=0)
    runs = pd.concat([runs, pd.DataFrame({"A": [0.0] * 3, "B": [0.0] * 3, "C": [0.0] * 3})], ignore_index=True)
    rng = np.random.default_rng(2)
    runs["y"] = 20 + 3 * runs.A - 2 * runs.B + 1.5 * runs.A * runs.B + 0.5 * runs.C + rng.normal(0, 0.2, len(runs))
    fit = fit_model(runs, "y", ["A", "B", "C"], "2fi")
    pert = perturbation(fit)
    a_curve = pert[pert["factor"] == "A"]
    pts = pd.DataFrame({"A": a_curve["deviation"], "B": 0.0, "C": 0.0})
    np.testing.assert_allclose(a_curve["predicted"], fit.predict_response(pts), rtol=1e-12)
    inter = interaction(fit, "A", "B")
    high = inter[inter["b"] == 1.0]
    np.testing.assert_allclose(
        high["predicted"], fit.predict_response(pd.DataFrame({"A": high["a"], "B": 1.0, "C": 0.0}))
    )
    cb = cube(fit, ["A", "B", "C"])
    np.testing.assert_allclose(cb["predicted"], fit.predict_response(cb[["A", "B", "C"]]), rtol=1e-12)
    hn = half_normal(pd.Series({"A": 6.0, "B": -4.0, "C": 1.0, "A*B": 3.0}))
    assert list(hn["term"]) == ["C", "A*B", "B", "A"]
    np.testing.assert_allclose(hn["quantile"], stats.halfnorm.ppf((np.arange(1, 5) - 0.5) / 4), rtol=1e-12)
    two = write_report(
        tmp_path / "two",
        runs,
        title="t",
        factors=[Factor(f, 0, 1) for f in "ABC"],
        labels={},
        responses=[{"name": "y", "unit": ""}],
        model="2fi",
    )
    md = (tmp_path / "two" / "report.md").read_text()
    assert "half-normal plot" in md and "interaction plot" in md and "cube plot" in md and two["y"]["r2"] > 0.9
    assert (tmp_path / "two" / "model_graphs_y.png").exists()


def test_contour_plots_share_one_colour_scale():
    """_shared_levels spans every grid of a response, so one colour means one value in each of its plots."""
    from warpdem.study.report import _shared_levels

    levels = _shared_levels([np.array([[1.0, 2.0]]), np.array([[0.5, 4.0]])])
    assert levels[0] == 0.5 and levels[-1] == 4.0 and len(levels) == 15


@pytest.mark.parametrize("target, inside", [(10.0, True), (12.0, False)])
def test_mean_model_target_against_its_interval(tmp_path, target, inside):
    """With no factor significant, backward elimination leaves the mean model; the report then places the target
    against the mean's confidence interval, which is scipy's one-sample t interval of the runs. Data: a 2^3
    factorial with two centre points whose response is noise alone (SD 0.5 about 10), the hidden effect none."""
    from scipy import stats

    factors = [Factor(f, 0.0, 1.0) for f in "ABC"]
    runs = full_factorial(3)
    runs = pd.concat([runs, pd.DataFrame({f: [0.0, 0.0] for f in "ABC"})], ignore_index=True)
    runs["run"] = np.arange(1, len(runs) + 1)
    runs["aor_deg"] = np.random.default_rng(7).normal(10.0, 0.5, len(runs))
    res = _aor_report(tmp_path, (runs, factors, {}), "noise", target, model="linear", eliminate=True)
    r = res["aor_deg"]
    assert r["terms"] == [] and r["chosen"] is None
    y = runs["aor_deg"]
    lo, hi = stats.t.interval(0.95, len(y) - 1, loc=y.mean(), scale=stats.sem(y))
    assert r["mean_interval"] == pytest.approx([lo, hi], rel=1e-12)
    assert r["predicted"] == pytest.approx(y.mean(), rel=1e-12)
    assert r["reachable"] is inside
    md = (tmp_path / "report.md").read_text()
    assert f"The target lies **{'inside' if inside else 'outside'}** that interval" in md
    assert ("outside the mean model's interval" in md) is (not inside)
