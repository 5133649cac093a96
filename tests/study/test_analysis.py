"""Design-Expert style statistics of warpdem.study.analysis on data with known answers."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import statsmodels.formula.api as smf
from statsmodels.stats.anova import anova_lm
from statsmodels.stats.outliers_influence import OLSInfluence

from warpdem.study import analysis as an
from warpdem.study import designs as ds

REF = Path(__file__).resolve().parents[2] / "studies" / "reference"
TRUE = {
    "Intercept": 10.0,
    "A": 2.0,
    "B": -1.0,
    "C": 0.5,
    "AB": 0.3,
    "AC": 0.0,
    "BC": -0.2,
    "A^2": -1.5,
    "B^2": 0.4,
    "C^2": 0.1,
}
CENTRE_NOISE = np.array([0.3, -0.1, -0.2, 0.2, -0.4, 0.2])  # sums to zero; sum of squares 0.38


def _truth(d: pd.DataFrame) -> np.ndarray:
    A, B, C = d["A"], d["B"], d["C"]
    return (
        TRUE["Intercept"]
        + TRUE["A"] * A
        + TRUE["B"] * B
        + TRUE["C"] * C
        + TRUE["AB"] * A * B
        + TRUE["AC"] * A * C
        + TRUE["BC"] * B * C
        + TRUE["A^2"] * A**2
        + TRUE["B^2"] * B**2
        + TRUE["C^2"] * C**2
    ).to_numpy()


def _ccd_with_centre_noise(cubic: float = 0.0) -> pd.DataFrame:
    d = ds.central_composite(3, "rotatable", center_points=6).reset_index(drop=True)
    y = _truth(d) + cubic * d["A"].to_numpy() ** 3
    y[d["kind"].to_numpy() == "center"] += CENTRE_NOISE
    d["y"] = y
    return d


def test_exact_quadratic_recovered_and_lack_of_fit_zero():
    """Exact quadratic on a rotatable CCD, zero-mean noise on the 6 centre runs only: the
    coefficients are recovered exactly, residual = pure error = 0.38 on 5 df, lack of fit = 0
    on 5 df, and the ANOVA rows add up (Model + Residual = Cor Total)."""
    d = _ccd_with_centre_noise()
    fit = an.fit_model(d, "y", ["A", "B", "C"], "quadratic")
    for lab, v in TRUE.items():
        assert fit.coefficients.loc[lab, "coef"] == pytest.approx(v, abs=1e-10)
    a = fit.anova
    assert a.loc["Residual", "sum_sq"] == pytest.approx(0.38)
    assert a.loc["Pure Error", "sum_sq"] == pytest.approx(0.38)
    assert a.loc["Pure Error", "df"] == 5 and a.loc["Lack of Fit", "df"] == 5
    assert a.loc["Lack of Fit", "sum_sq"] == pytest.approx(0.0, abs=1e-10)
    assert a.loc["Model", "sum_sq"] + a.loc["Residual", "sum_sq"] == pytest.approx(a.loc["Cor Total", "sum_sq"])
    assert a.loc["Model", "df"] == 9 and a.loc["Cor Total", "df"] == 19


def test_lack_of_fit_from_missing_cubic_term():
    """Adding 0.7 A^3 (not in the model) to the same data: in a rotatable CCD A^3 projects only
    onto A, so b_A = 2 + 0.7 sum(x^4)/sum(x^2), pure error is unchanged (0.38) and the lack of
    fit SS is 0.7^2 (sum(x^6) - sum(x^4)^2 / sum(x^2)); F = MS_LOF / MS_PE."""
    d = _ccd_with_centre_noise(cubic=0.7)
    fit = an.fit_model(d, "y", ["A", "B", "C"], "quadratic")
    x = d["A"].to_numpy()
    s2, s4, s6 = (x**2).sum(), (x**4).sum(), (x**6).sum()
    assert fit.coef("A") == pytest.approx(2.0 + 0.7 * s4 / s2)
    lof = 0.49 * (s6 - s4**2 / s2)
    a = fit.anova
    assert a.loc["Pure Error", "sum_sq"] == pytest.approx(0.38)
    assert a.loc["Lack of Fit", "sum_sq"] == pytest.approx(lof)
    assert a.loc["Lack of Fit", "F"] == pytest.approx((lof / 5) / (0.38 / 5))
    assert a.loc["Residual", "sum_sq"] == pytest.approx(lof + 0.38)


def test_anova_and_fit_statistics_match_statsmodels():
    """Noisy BBD: term sums of squares equal statsmodels anova_lm (types II and III), R^2 and
    adjusted R^2 equal statsmodels', PRESS equals OLSInfluence.ess_press, predicted R^2 =
    1 - PRESS/SST, adequate precision = range(yhat) / sqrt(p MSE / n), C.V. = 100 sd / mean."""
    d = ds.box_behnken(3).reset_index(drop=True)
    rng = np.random.default_rng(42)
    d["y"] = _truth(d) + rng.normal(0, 0.3, len(d))
    fit = an.fit_model(d, "y", ["A", "B", "C"], "quadratic")
    m = smf.ols("y ~ A + B + C + A:B + A:C + B:C + I(A**2) + I(B**2) + I(C**2)", d).fit()
    names = {
        "A": "A",
        "B": "B",
        "C": "C",
        "AB": "A:B",
        "AC": "A:C",
        "BC": "B:C",
        "A^2": "I(A ** 2)",
        "B^2": "I(B ** 2)",
        "C^2": "I(C ** 2)",
    }
    t2, t3 = anova_lm(m, typ=2), anova_lm(m, typ=3)
    for ours, theirs in names.items():
        assert fit.anova.loc[ours, "sum_sq"] == pytest.approx(t2.loc[theirs, "sum_sq"], rel=1e-9)
        assert fit.anova.loc[ours, "sum_sq"] == pytest.approx(t3.loc[theirs, "sum_sq"], rel=1e-9)
        assert fit.anova.loc[ours, "p"] == pytest.approx(t3.loc[theirs, "PR(>F)"], rel=1e-7)
    s = fit.stats
    assert s["r2"] == pytest.approx(m.rsquared)
    assert s["adj_r2"] == pytest.approx(m.rsquared_adj)
    press = OLSInfluence(m).ess_press
    assert s["press"] == pytest.approx(press)
    sst = ((d["y"] - d["y"].mean()) ** 2).sum()
    assert s["pred_r2"] == pytest.approx(1 - press / sst)
    yhat = m.fittedvalues
    assert s["adeq_precision"] == pytest.approx((yhat.max() - yhat.min()) / math.sqrt(10 * m.mse_resid / len(d)))
    assert s["cv_pct"] == pytest.approx(100 * math.sqrt(m.mse_resid) / d["y"].mean())


def test_pellets_pb_fit_statistics():
    """Seed 000 Table 7 from Table 6: R^2 0.9441, adj 0.8771, pred 0.6782, adeq precision
    11.599, SS(D) 132.07, and the actual-units slopes of eq. (5)."""
    p = pd.read_csv(REF / "pellets_pb_runs.csv")
    lv = pd.read_csv(REF / "pellets_pb_levels.csv")
    levels = [ds.Factor(r.factor, r.low, r.high) for r in lv.itertuples()]
    fit = an.fit_model(p, "aor_deg", list("ABCDEF"), "linear", levels)
    assert round(fit.stats["r2"], 4) == 0.9441
    assert round(fit.stats["adj_r2"], 4) == 0.8771
    assert round(fit.stats["pred_r2"], 4) == 0.6782
    assert round(fit.stats["adeq_precision"], 3) == 11.599
    assert round(fit.anova.loc["D", "sum_sq"], 2) == 132.07
    eq = fit.equation("actual")
    assert round(eq[("B",)], 2) == -48.71 and round(eq[("E",)], 2) == 59.75


def test_actual_equation_equals_fit_in_actual_units():
    """The coded quadratic expanded to actual units equals an OLS fit done directly in actual
    units (seed 002 BBD, ranges 0.4-1.0, 0-0.4, 0.8-1.2)."""
    q = pd.read_csv(REF / "phosphate_bbd_runs.csv")
    q.columns = ["run", "B", "C", "D", "y"]
    lv = [ds.Factor("B", 0.4, 1.0), ds.Factor("C", 0.0, 0.4), ds.Factor("D", 0.8, 1.2)]
    fit = an.fit_model(q, "y", ["B", "C", "D"], "quadratic", lv)
    act = pd.DataFrame({f.name: f.to_actual(q[f.name]) for f in lv})
    act["y"] = q["y"]
    m = smf.ols("y ~ B + C + D + B:C + B:D + C:D + I(B**2) + I(C**2) + I(D**2)", act).fit()
    eq = fit.equation("actual")
    pairs = {
        (): "Intercept",
        ("B",): "B",
        ("C",): "C",
        ("D",): "D",
        ("B", "C"): "B:C",
        ("B", "D"): "B:D",
        ("C", "D"): "C:D",
        ("B", "B"): "I(B ** 2)",
        ("C", "C"): "I(C ** 2)",
        ("D", "D"): "I(D ** 2)",
    }
    for mono, name in pairs.items():
        assert eq[mono] == pytest.approx(m.params[name], rel=1e-8, abs=1e-8)
    pt = {"B": 0.7, "C": 0.3, "D": 1.0}
    assert fit.predict_actual(pt)[0] == pytest.approx(m.predict(pd.DataFrame([pt]))[0])
    assert "B^2" in fit.equation_string("actual")


def test_backward_elimination_keeps_hierarchy():
    """y = 5 + 3B + 2AB + noise on a replicated 2^3: hierarchical elimination drops C, AC, BC
    but keeps A (its main effect is 0) because AB stays; without hierarchy A goes too."""
    d = ds.full_factorial(3, replicates=2).reset_index(drop=True)
    rng = np.random.default_rng(3)
    d["y"] = 5 + 3 * d["B"] + 2 * d["A"] * d["B"] + rng.normal(0, 0.1, len(d))
    h = an.backward_eliminate(d, "y", ["A", "B", "C"], "2fi", alpha=0.05)
    assert h.labels == ["A", "B", "AB"]
    assert {e["removed"] for e in h.elimination} == {"C", "AC", "BC"}
    assert all(e["p"] > 0.05 for e in h.elimination)
    n = an.backward_eliminate(d, "y", ["A", "B", "C"], "2fi", alpha=0.05, hierarchical=False)
    assert n.labels == ["B", "AB"]


def test_backward_elimination_reproduces_seed_002_model():
    """Seed 002's BBD: elimination at alpha 0.05 and 0.10 both leave B, C, D, B^2, C^2, the
    terms of the published eq. (20), with R^2 = 0.9858."""
    q = pd.read_csv(REF / "phosphate_bbd_runs.csv")
    q.columns = ["run", "B", "C", "D", "y"]
    for alpha in (0.05, 0.10):
        f = an.backward_eliminate(q, "y", ["B", "C", "D"], "quadratic", alpha)
        assert f.labels == ["B", "C", "D", "B^2", "C^2"]
        assert round(f.stats["r2"], 4) == 0.9858


def test_effects_and_lenth():
    """Effect = mean(high) - mean(low) = 2 x coefficient; in a saturated 2^3 the % contributions
    add to 100 and the standardized effect is effect / Lenth PSE; Lenth's PSE of a textbook
    vector is 2.8125."""
    d = ds.full_factorial(3).reset_index(drop=True)
    d["y"] = [3.0, 7.0, 4.0, 9.5, 2.0, 8.0, 5.5, 10.0]
    e = an.effects_table(d, "y", ["A", "B", "C"], ["A", "B", "C", "AB", "AC", "BC", "ABC"])
    for f in "ABC":
        hi, lo = d.loc[d[f] > 0, "y"].mean(), d.loc[d[f] < 0, "y"].mean()
        assert e.loc[f, "effect"] == pytest.approx(hi - lo)
    assert e["pct_contribution"].sum() == pytest.approx(100.0)
    pse = an.lenth_pse(e["effect"])
    np.testing.assert_allclose(e["standardized"], e["effect"] / pse)
    assert list(e["rank"]) == list(range(1, 8))
    assert e.index[0] == "A"
    assert an.lenth_pse([-8, 24, -2.25, -5.5, 1, 1.5, 0.75]) == pytest.approx(2.8125)
    lin = an.effects_table(d, "y", ["A", "B", "C"])
    assert lin.attrs["method"].startswith("t, 4")
    np.testing.assert_allclose(lin.loc[["A", "B", "C"], "effect"], e.loc[["A", "B", "C"], "effect"])


def test_solve_target_family_and_choice():
    """y = x1 + x2 on a 2^2 (+ centre): the target-1 contour is the segment x1 + x2 = 1 in the
    square; every sampled point lies on it, the chosen point is the one nearest the centre,
    (0.5, 0.5); an unreachable target returns the nearest corner; a fixed factor is honoured."""
    d = ds.full_factorial(["x1", "x2"], center_points=2).reset_index(drop=True)
    d["y"] = d["x1"] + d["x2"]
    fit = an.fit_model(d, "y", ["x1", "x2"], "linear")
    s = an.solve_target(fit, 1.0, n_samples=30, seed=1)
    assert s.reachable
    assert s.chosen["x1"] == pytest.approx(0.5, abs=1e-6) and s.chosen["x2"] == pytest.approx(0.5, abs=1e-6)
    fam = s.family
    assert len(fam) > 10
    np.testing.assert_allclose(fam["x1"] + fam["x2"], 1.0, atol=1e-6)
    assert (fam[["x1", "x2"]].abs() <= 1 + 1e-9).all().all()
    assert fam["distance"].min() == pytest.approx(math.sqrt(0.5), abs=1e-6)
    assert fam["x1"].max() - fam["x1"].min() > 0.5  # a set, not a point
    u = an.solve_target(fit, 3.0)
    assert not u.reachable and u.chosen["x1"] == pytest.approx(1) and u.chosen["predicted"] == pytest.approx(2)
    f = an.solve_target(fit, 0.5, fixed={"x2": 0.0}, n_samples=5)
    assert f.chosen["x1"] == pytest.approx(0.5, abs=1e-6) and f.chosen["x2"] == 0.0


def test_solve_target_axial_region_and_actual_units():
    """With bounds='design' a CCD with alpha 2 is searched in [-2, 2]^k; chosen points come
    back in actual units too and predict the target."""
    d = ds.central_composite(["A", "B"], alpha=2, center_points=3).reset_index(drop=True)
    d["y"] = 1 + d["A"] + 0.5 * d["B"]
    lv = [ds.Factor.from_centre_step("A", 0.3, 0.1), ds.Factor.from_centre_step("B", 0.6, 0.15)]
    fit = an.fit_model(d, "y", ["A", "B"], "linear", lv)
    s = an.solve_target(fit, 3.2, bounds="design", n_samples=10)
    assert s.bounds["A"] == (-2.0, 2.0)
    assert s.reachable and s.chosen["predicted"] == pytest.approx(3.2, abs=1e-6)
    assert s.chosen["A"] == pytest.approx(2.2 / 1.25, abs=1e-5)  # nearest point: along (1, 0.5)
    assert s.chosen_actual["A"] == pytest.approx(0.3 + 0.1 * s.chosen["A"])
    assert not an.solve_target(fit, 3.2, bounds="cube", n_samples=5).reachable


def test_term_parsing_and_labels():
    """Terms given as 'AB', 'A*B', 'A:B', 'A^2', 'A2', 'X1X2', 'X1^2' or tuples are parsed to
    canonical tuples; labels follow Design-Expert (AB, A^2) or X1*X2 for longer names."""
    f = ["A", "B", "C"]
    assert an.parse_term("BA", f) == ("A", "B")
    assert an.parse_term("A*B", f) == an.parse_term("A:B", f) == ("A", "B")
    assert an.parse_term("A^2", f) == an.parse_term("A2", f) == an.parse_term("A²", f) == ("A", "A")
    x = ["X1", "X2", "X3"]
    assert an.parse_term("X1X2", x) == ("X1", "X2")
    assert an.parse_term("X1^2", x) == ("X1", "X1")
    assert an.term_label(("A", "A"), f) == "A^2" and an.term_label(("X1", "X3"), x) == "X1*X3"
    assert [an.term_label(t, f) for t in an.model_terms("quadratic", f)] == [
        "A",
        "B",
        "C",
        "AB",
        "AC",
        "BC",
        "A^2",
        "B^2",
        "C^2",
    ]
    with pytest.raises(ValueError):
        an.parse_term("AQ", f)
    with pytest.raises(ValueError):
        an.fit_model(pd.DataFrame({"A": [-1, 1, -1, 1], "y": [1, 2, 3, 4]}), "y", ["A"], ["A", "A^2"])
