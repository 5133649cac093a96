"""Design-Expert's diagnostics (analysis.influence, analysis.box_cox, report.diagnostics) against statsmodels and
SciPy on the same data, and on data with a planted outlier or a multiplicative response."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import statsmodels.api as sm
from scipy import stats

from warpdem.study.analysis import box_cox, fit_model, influence
from warpdem.study.report import diagnostics


def _factorial(reps: int = 2) -> pd.DataFrame:
    a, b = np.meshgrid([-1.0, 0.0, 1.0], [-1.0, 0.0, 1.0])
    return pd.DataFrame({"A": np.tile(a.ravel(), reps), "B": np.tile(b.ravel(), reps)})


def test_influence_matches_statsmodels_on_a_design_matrix_built_by_hand():
    """A quadratic in two factors: the per-run table equals statsmodels' OLSInfluence of the same least squares
    with the columns written out here (1, A, B, AB, A^2, B^2), not by the fit's own term code."""
    d = _factorial()
    rng = np.random.default_rng(3)
    d["y"] = 10 + 2 * d.A - d.B + 0.5 * d.A * d.B + 1.5 * d.A**2 + rng.normal(0, 0.3, len(d))
    fit = fit_model(d, "y", ["A", "B"], "quadratic")
    X = np.column_stack([np.ones(len(d)), d.A, d.B, d.A * d.B, d.A**2, d.B**2])
    ref = sm.OLS(d.y.to_numpy(), X).fit().get_influence()
    got = influence(fit)
    np.testing.assert_allclose(got["leverage"], ref.hat_matrix_diag, rtol=1e-10)
    np.testing.assert_allclose(got["externally_studentized"], ref.resid_studentized_external, rtol=1e-8)
    np.testing.assert_allclose(got["cooks_distance"], ref.cooks_distance[0], rtol=1e-8)
    np.testing.assert_allclose(got["dffits"], ref.dffits[0], rtol=1e-8)
    np.testing.assert_allclose(got["actual"] - got["predicted"], got["residual"], atol=1e-12)


def test_influence_on_seed_000s_published_box_behnken_matches_statsmodels():
    """#20's diagnostics on a published data set: seed 000's Box-Behnken (17 runs of angle of repose, the paper's
    own table). Leverage, externally studentized residuals, Cook's distance and DFFITS of its quadratic equal
    statsmodels' OLSInfluence on the design matrix written out here; and, as the design's symmetry requires, the 5
    centre points share one leverage and the 12 edge midpoints another, larger one."""
    from pathlib import Path

    runs = pd.read_csv(Path(__file__).parents[2] / "studies" / "reference" / "pellets_bbd_runs.csv")
    c, d, e = (runs[f].to_numpy(dtype=float) for f in "CDE")
    X = np.column_stack([np.ones(len(c)), c, d, e, c * d, c * e, d * e, c * c, d * d, e * e])
    ref = sm.OLS(runs["aor_deg"].to_numpy(dtype=float), X).fit().get_influence()
    got = influence(fit_model(runs, "aor_deg", ["C", "D", "E"], "quadratic"))
    np.testing.assert_allclose(got["leverage"], ref.hat_matrix_diag, rtol=1e-10)
    np.testing.assert_allclose(got["externally_studentized"], ref.resid_studentized_external, rtol=1e-8)
    np.testing.assert_allclose(got["cooks_distance"], ref.cooks_distance[0], rtol=1e-8)
    np.testing.assert_allclose(got["dffits"], ref.dffits[0], rtol=1e-8)
    centre = (c == 0) & (d == 0) & (e == 0)
    lev = np.asarray(got["leverage"])
    assert centre.sum() == 5 and np.allclose(lev[centre], lev[centre][0]) and np.allclose(lev[~centre], lev[~centre][0])
    assert lev[centre][0] < lev[~centre][0]


def test_box_cox_of_the_mean_model_is_scipys_maximum_likelihood_lambda():
    """With no terms the Box-Cox profile is SciPy's: the same lambda (the residual sum of squares of the
    geometric-mean-scaled transform is minimal where the Box-Cox likelihood is maximal)."""
    y = np.random.default_rng(0).lognormal(1.0, 0.4, 25)
    fit = fit_model(pd.DataFrame({"A": np.linspace(-1, 1, 25), "y": y}), "y", ["A"], [])
    assert box_cox(fit)["lambda_hat"] == pytest.approx(stats.boxcox(y)[1], abs=1e-4)


def test_box_cox_recommends_ln_for_a_multiplicative_response_and_nothing_for_an_additive_one():
    """A response whose factor effects multiply (log-linear, a 55-fold range) gets ln; the same effects added
    (a linear response with normal noise) get no transform: its interval holds 1."""
    d = _factorial(reps=3)
    rng = np.random.default_rng(1)
    mult = d.assign(y=np.exp(1.0 + 1.5 * d.A + 0.5 * d.B + rng.normal(0, 0.1, len(d))))
    bc = box_cox(fit_model(mult, "y", ["A", "B"], "linear"))
    lo, hi = bc["interval"]
    assert bc["recommended"] == "ln" and lo < 0 < hi < 1
    add = d.assign(y=20.0 + 3.0 * d.A + 1.0 * d.B + rng.normal(0, 0.3, len(d)))
    assert box_cox(fit_model(add, "y", ["A", "B"], "linear"))["recommended"] == "none"
    neg = d.assign(y=d.A + rng.normal(0, 0.1, len(d)))
    assert "error" in box_cox(fit_model(neg, "y", ["A", "B"], "linear"))


def test_a_planted_outlier_is_named_and_clean_runs_are_not():
    """Run 7 of a replicated 3x3 factorial is shifted by 8 noise SD: it is beyond the Bonferroni limit and the
    Cook's line, and the readings name it and put it in the notes; without the shift no run is named."""
    d = _factorial()
    rng = np.random.default_rng(5)
    d["y"] = 30 + 2 * d.A + d.B + rng.normal(0, 0.5, len(d))
    runs = list(range(1, len(d) + 1))
    clean = diagnostics(fit_model(d, "y", ["A", "B"], "linear"), runs)
    assert clean["flagged"]["outliers"] == [] and not clean["notes"]
    assert any(line.startswith("Residuals vs predicted: no run") for line in clean["readings"])
    d.loc[6, "y"] += 4.0
    bad = diagnostics(fit_model(d, "y", ["A", "B"], "linear"), runs)
    assert bad["flagged"]["outliers"] == [7] and 7 in bad["flagged"]["cooks"]
    assert any("run(s) 7 beyond" in line for line in bad["readings"])
    assert any("run(s) 7" in n for n in bad["notes"])


def test_spread_across_levels_is_brown_forsythe_and_not_judged_on_levels_of_two():
    """The spread reading is SciPy's Brown-Forsythe test on the externally studentized residuals per level: a
    replicated 3x3 factorial with the noise ten times larger at A = +1 is uneven across A's levels and even across
    B's. A line through three levels of two runs each (as an explicit design with two seeds a point gives) is not
    judged: two runs sit at the same distance from their median, so the test would divide by zero and call any
    difference between the levels uneven."""
    d = _factorial(reps=4)
    rng = np.random.default_rng(11)
    d["y"] = 30 + 2 * d.A + d.B + rng.normal(0, 1, len(d)) * np.where(d.A > 0, 3.0, 0.3)
    fit = fit_model(d, "y", ["A", "B"], "linear")
    ext = np.asarray(influence(fit)["externally_studentized"])
    p_a = stats.levene(*[ext[d.A.to_numpy() == v] for v in (-1, 0, 1)], center="median").pvalue
    assert p_a < 0.05
    reading = diagnostics(fit, range(1, len(d) + 1))["readings"]
    assert "Residuals vs each factor: uneven spread across the levels of A (Brown-Forsythe)." in reading
    line = pd.DataFrame({"X": [-1.0, -1.0, 0.0, 0.0, 1.0, 1.0], "y": [50.0, 51.0, 53.5, 54.5, 57.2, 58.0]})
    with np.errstate(all="raise"):
        reading = diagnostics(fit_model(line, "y", ["X"], "linear"), range(1, 7))["readings"]
    assert any("Residuals vs each factor: too few runs per level to judge" in r for r in reading)


def test_a_negative_prediction_of_a_positive_response_is_a_note(tmp_path):
    """A linear model of a response that falls steeply and levels off (all runs above zero) predicts below zero
    at a corner of the region: the report's notes say so, with the value and where; a model that stays
    positive gets no such note."""
    from warpdem.study.designs import Factor
    from warpdem.study.report import write_report

    d = _factorial()
    steep = d.assign(y=np.exp(2.0 - 1.6 * d.A - 1.6 * d.B))
    factors = [Factor("A", 0.0, 1.0), Factor("B", 0.0, 1.0)]
    kw = dict(title="t", factors=factors, labels={}, responses=[{"name": "y", "unit": ""}], model="linear")
    write_report(tmp_path / "steep", steep, **kw)
    notes = (tmp_path / "steep" / "report.md").read_text().split("## Notes")[1]
    assert "y: the model predicts -" in notes and "A +1.00, B +1.00" in notes
    flat = d.assign(y=30.0 + d.A + 0.5 * d.B)
    write_report(tmp_path / "flat", flat, **kw)
    assert "the model predicts" not in (tmp_path / "flat" / "report.md").read_text()


def test_fit_summary_of_seed_000s_box_behnken_against_statsmodels():
    """Seed 000's Box-Behnken (17 runs, 5 centre points): each sequential row is statsmodels' F test of the
    order against the one below it (compare_f_test, on design matrices written out here); the lack of fit is
    fit_model's; the cubic is aliased, and the suggested model is the quadratic the paper fitted."""
    from pathlib import Path

    from warpdem.study.analysis import fit_summary

    runs = pd.read_csv(Path(__file__).parents[2] / "studies" / "reference" / "pellets_bbd_runs.csv")
    c, d, e = (runs[f].to_numpy(dtype=float) for f in "CDE")
    y = runs["aor_deg"].to_numpy(dtype=float)
    one = np.ones(len(y))
    mats = {
        "Mean": np.column_stack([one]),
        "Linear": np.column_stack([one, c, d, e]),
        "2FI": np.column_stack([one, c, d, e, c * d, c * e, d * e]),
        "Quadratic": np.column_stack([one, c, d, e, c * d, c * e, d * e, c * c, d * d, e * e]),
    }
    fits = {k: sm.OLS(y, X).fit() for k, X in mats.items()}
    summ = fit_summary(runs, "aor_deg", ["C", "D", "E"])
    seq = summ["sequential"]
    for big, small in (("Linear", "Mean"), ("2FI", "Linear"), ("Quadratic", "2FI")):
        f, p, ddf = fits[big].compare_f_test(fits[small])
        assert seq.loc[big, "F"] == pytest.approx(f, rel=1e-9) and seq.loc[big, "p"] == pytest.approx(p, rel=1e-9)
        assert seq.loc[big, "df"] == ddf
        assert seq.loc[big, "sum_sq"] == pytest.approx(fits[small].ssr - fits[big].ssr, rel=1e-9)
    quad = fit_model(runs, "aor_deg", ["C", "D", "E"], "quadratic")
    assert summ["lack_of_fit"].loc["Quadratic", "p"] == pytest.approx(quad.anova.loc["Lack of Fit", "p"])
    assert summ["statistics"].loc["Quadratic", "pred_r2"] == pytest.approx(quad.stats["pred_r2"])
    assert bool(seq.loc["Cubic", "aliased"]) and summ["suggested"] == "Quadratic"


def test_confirmation_interval_against_statsmodels_and_by_hand():
    """The quadratic of the first test at an off-design point (A 0.4, B -0.7): for one run the interval is
    statsmodels' ``obs_ci`` of the same least squares built by hand; for four runs only the run-to-run part
    shrinks: predicted +/- t(0.975, df) sqrt(MSE (1/4 + h0)), with h0 the point's leverage from (X'X)^-1 by hand.
    A mean of four runs at the prediction lies inside, one 3 SE off lies outside."""
    from warpdem.study.analysis import confirmation_interval

    d = _factorial()
    rng = np.random.default_rng(3)
    d["y"] = 10 + 2 * d.A - d.B + 0.5 * d.A * d.B + 1.5 * d.A**2 + rng.normal(0, 0.3, len(d))
    fit = fit_model(d, "y", ["A", "B"], "quadratic")
    X = np.column_stack([np.ones(len(d)), d.A, d.B, d.A * d.B, d.A**2, d.B**2])
    ols = sm.OLS(d.y.to_numpy(), X).fit()
    x0 = np.array([[1.0, 0.4, -0.7, 0.4 * -0.7, 0.16, 0.49]])
    frame = ols.get_prediction(x0).summary_frame(alpha=0.05)
    one = confirmation_interval(fit, {"A": 0.4, "B": -0.7}, runs=1)
    assert one["predicted"] == pytest.approx(float(frame["mean"].iloc[0]), rel=1e-12)
    assert one["low"] == pytest.approx(float(frame["obs_ci_lower"].iloc[0]), rel=1e-10)
    assert one["high"] == pytest.approx(float(frame["obs_ci_upper"].iloc[0]), rel=1e-10)
    four = confirmation_interval(fit, {"A": 0.4, "B": -0.7}, runs=4)
    h0 = float(x0[0] @ np.linalg.inv(X.T @ X) @ x0[0])
    half = stats.t.ppf(0.975, ols.df_resid) * np.sqrt(ols.mse_resid * (0.25 + h0))
    assert four["h0"] == pytest.approx(h0, rel=1e-10) and four["df"] == 12
    assert (four["low"], four["high"]) == pytest.approx((one["predicted"] - half, one["predicted"] + half), rel=1e-10)
    assert four["high"] - four["low"] < one["high"] - one["low"]
    se = np.sqrt(ols.mse_resid * (0.25 + h0))
    assert four["low"] < one["predicted"] < four["high"] and not (
        four["low"] < one["predicted"] + 3 * se < four["high"]
    )


def test_alias_matrix_of_a_half_fraction_a_plackett_burman_and_the_defining_relation():
    """Design-Expert's alias list, from the alias matrix of the runs:
    - 2^(3-1) with C = AB, linear model: [Intercept] = Intercept + ABC, [A] = A + BC, [B] = B + AC, [C] = C + AB;
    - the 12-run Plackett-Burman in 5 factors: each main effect carries 1/3 of every two-factor interaction
      without it (6 of them) and none with it (the published partial aliasing of that design);
    - 2^(5-2) with D = AB, E = AC: the full aliases of every main effect among the two-factor interactions
      equal those of the defining relation I = ABD = ACE = BCDE (designs.alias_structure, group algebra)."""
    from warpdem.study import designs as ds
    from warpdem.study.analysis import alias_lines, alias_matrix

    half = ds.fractional_factorial(3, "C=AB").reset_index(drop=True)
    half["y"] = np.arange(4.0)
    lines = alias_lines(alias_matrix(fit_model(half, "y", ["A", "B", "C"], "linear")))
    assert lines == ["[Intercept] = Intercept + ABC", "[A] = A + BC", "[B] = B + AC", "[C] = C + AB"]

    pb = ds.plackett_burman(5).reset_index(drop=True)
    pb["y"] = np.random.default_rng(0).normal(size=12)
    A = alias_matrix(fit_model(pb, "y", list("ABCDE"), "linear"), max_order=2)
    for f in "ABCDE":
        row = A.loc[f]
        assert set(np.round(np.abs(row[row != 0]), 12)) == {round(1 / 3, 12)}
        assert sorted(row[row != 0].index) == sorted(c for c in A.columns if f not in c)

    frac = ds.fractional_factorial(5, ["D=AB", "E=AC"]).reset_index(drop=True)
    frac["y"] = np.arange(8.0)
    A = alias_matrix(fit_model(frac, "y", list("ABCDE"), "linear"), max_order=2)
    group = ds.alias_structure(5, ["D=AB", "E=AC"], max_order=1).aliases
    for f in "ABCDE":
        row = A.loc[f]
        full = sorted(c for c in row[np.isclose(np.abs(row), 1.0)].index)
        assert full == sorted(a for a in group[f] if len(a) == 2)


def test_desirability_by_hand_and_its_optimum():
    """Derringer-Suich desirabilities against values worked by hand:
    - maximize on [10, 20], weight 2: y = 15 gives (5/10)^2 = 0.25; below 10, 0; above 20, 1;
    - minimize on [1, 5], weight 1: y = 2 gives 3/4;
    - target 30 in [20, 35], weights 1 below and 0.5 above: y = 25 gives 0.5, y = 32.5 gives 0.5^0.5;
    - in range [0, 1]: 1 inside, 0 outside;
    overall, importances 3 and 1: (0.25^3 x 0.75)^(1/4) = 0.3290. Then two fitted planes, y1 = 15 + 5A
    (maximize on [10, 20]) and y2 = 30 + 5B (target 30 in [20, 40]): the optimum is A = 1, B = 0, D = 1."""
    from warpdem.study.analysis import Goal, desirability, optimize_desirability

    up = Goal("maximize", 10, 20, weight=2, importance=3)
    down = Goal("minimize", 1, 5, importance=1)
    aim = Goal("target", 20, 35, target=30, weight=1, weight_high=0.5)
    inside = Goal("in_range", 0, 1)
    np.testing.assert_allclose(up.d([15, 9, 25]), [0.25, 0.0, 1.0])
    assert down.d(2.0) == pytest.approx(0.75)
    np.testing.assert_allclose(aim.d([25, 32.5, 19, 36]), [0.5, 0.5**0.5, 0.0, 0.0])
    np.testing.assert_allclose(inside.d([-0.1, 0.5, 1.2]), [0, 1, 0])
    D = desirability({"y1": np.array([15.0]), "y2": np.array([2.0])}, {"y1": up, "y2": down})
    assert D[0] == pytest.approx((0.25**3 * 0.75) ** 0.25, rel=1e-12)
    with pytest.raises(ValueError, match="target = 40"):
        Goal("target", 20, 35, target=40)

    d = _factorial()
    d["y1"] = 15 + 5 * d.A
    d["y2"] = 30 + 5 * d.B
    fits = {r: fit_model(d, r, ["A", "B"], "linear") for r in ("y1", "y2")}
    goals = {"y1": Goal("maximize", 10, 20), "y2": Goal("target", 20, 40, target=30)}
    best = optimize_desirability(fits, goals, starts=10, seed=1).iloc[0]
    assert best["A"] == pytest.approx(1.0, abs=1e-3) and best["B"] == pytest.approx(0.0, abs=2e-3)
    assert best["desirability"] == pytest.approx(1.0, abs=1e-3)
