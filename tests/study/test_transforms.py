"""Response transforms (study.transforms, fit_model(transform=...)): the model of f(y + k) is statsmodels' OLS of
f(y + k), predictions, intervals and solutions come back through f's inverse, and bad values are refused naming
the response, the value and what would fit."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import statsmodels.api as sm

from warpdem.study.analysis import box_cox, confirmation_interval, fit_model, solve_target
from warpdem.study.designs import Factor
from warpdem.study.spec import AnalysisSpec, ResponseSpec, StudyError
from warpdem.study.transforms import TRANSFORMS, Transform


def _multiplicative() -> pd.DataFrame:
    a, b = np.meshgrid([-1.0, 0.0, 1.0], [-1.0, 0.0, 1.0])
    d = pd.DataFrame({"A": np.tile(a.ravel(), 2), "B": np.tile(b.ravel(), 2)})
    rng = np.random.default_rng(4)
    return d.assign(y=np.exp(2.0 + 0.8 * d.A - 0.4 * d.B + rng.normal(0, 0.05, len(d))))


@pytest.mark.parametrize(
    "t", [Transform(k) for k in TRANSFORMS if k != "power"] + [Transform("power", 0.25), Transform("ln", k=1.5)]
)
def test_every_transform_comes_back(t):
    """f's inverse undoes f (with the constant k) on values inside f's domain."""
    y = np.array([0.3, 1.0, 2.5, 40.0])
    np.testing.assert_allclose(t.inverse(t.forward(y)), y, rtol=1e-12)


def test_the_ln_model_is_statsmodels_ols_of_ln_y():
    """A log-linear response: the ln model's coefficients and ANOVA residual are statsmodels' OLS of ln y with the
    columns written out here; its back-transformed prediction is exp of statsmodels'; the confirmation interval
    of one run is exp of statsmodels' obs_ci; the equation reads ln(y); the Box-Cox plot is of the response
    itself (the untransformed fit's, lambda_hat near 0), marking the current lambda 0."""
    d = _multiplicative()
    fit = fit_model(d, "y", ["A", "B"], "linear", transform=Transform("ln"))
    X = np.column_stack([np.ones(len(d)), d.A, d.B])
    ref = sm.OLS(np.log(d.y.to_numpy()), X).fit()
    np.testing.assert_allclose(fit.coefficients["coef"].to_numpy(), ref.params, rtol=1e-10)
    assert fit.anova.loc["Residual", "sum_sq"] == pytest.approx(ref.ssr, rel=1e-10)
    x0 = np.array([[1.0, 0.5, -0.25]])
    assert fit.predict_response({"A": 0.5, "B": -0.25})[0] == pytest.approx(np.exp(ref.predict(x0)[0]), rel=1e-10)
    ci = confirmation_interval(fit, {"A": 0.5, "B": -0.25}, alpha=0.05)
    obs = ref.get_prediction(x0).summary_frame(alpha=0.05)
    assert (ci["low"], ci["high"]) == pytest.approx(
        (np.exp(obs["obs_ci_lower"][0]), np.exp(obs["obs_ci_upper"][0])), rel=1e-9
    )
    assert fit.equation_string().startswith("ln(y) = ")
    bc, plain = box_cox(fit), box_cox(fit_model(d, "y", ["A", "B"], "linear"))
    assert bc["lambda_current"] == 0.0 and plain["lambda_current"] == 1.0
    assert bc["lambda_hat"] == pytest.approx(plain["lambda_hat"], abs=1e-9) and -0.3 < bc["lambda_hat"] < 0.1


def test_a_falling_transform_keeps_its_interval_in_order():
    """The inverse (1/y) falls as y rises: the interval brought back has its ends swapped so low < predicted <
    high, each the inverse of the model scale's other end."""
    d = _multiplicative()
    fit = fit_model(d, "y", ["A", "B"], "linear", transform=Transform("inverse"))
    ci = confirmation_interval(fit, {"A": 0.0, "B": 0.0})
    ms = ci["model_scale"]
    assert ci["low"] < ci["predicted"] < ci["high"]
    assert ci["low"] == pytest.approx(1.0 / ms["high"]) and ci["high"] == pytest.approx(1.0 / ms["low"])


def test_a_target_is_solved_in_the_responses_units():
    """With ln, the target contour is solved at ln(target): the chosen settings predict the target itself (in
    y's units), and the predicted range is the back-transformed one."""
    d = _multiplicative()
    fit = fit_model(d, "y", ["A", "B"], "linear", [Factor("A", 0, 1), Factor("B", 0, 1)], Transform("ln"))
    sol = solve_target(fit, 10.0, n_samples=20, seed=0)
    assert sol.reachable and sol.target == 10.0
    assert sol.chosen["predicted"] == pytest.approx(10.0, rel=1e-6)
    x = {f: sol.chosen[f] for f in ("A", "B")}
    assert fit.predict_response(x)[0] == pytest.approx(10.0, rel=1e-6)
    lo, hi = sol.predicted_range
    assert lo == pytest.approx(np.exp(fit.coef() - abs(fit.coef("A")) - abs(fit.coef("B"))), rel=1e-6)
    assert hi == pytest.approx(np.exp(fit.coef() + abs(fit.coef("A")) + abs(fit.coef("B"))), rel=1e-6)


def test_values_outside_the_domain_and_bad_keys_are_refused():
    """ln of a zero response names the response, the value and transform_k; the study file's keys are checked
    where they are read, naming the table, the key and the value."""
    d = _multiplicative().assign(y=lambda t: t.y - t.y.min())
    with pytest.raises(ValueError, match=r"response 'y' = 0.0 cannot be transformed by ln\(y\): .*transform_k"):
        fit_model(d, "y", ["A", "B"], "linear", transform=Transform("ln"))
    assert fit_model(d, "y", ["A", "B"], "linear", transform=Transform("ln", k=1.0)).transform.k == 1.0
    with pytest.raises(StudyError, match=r"\[analysis\].*transform.*'log'.*did you mean"):
        AnalysisSpec(transform="log")
    with pytest.raises(StudyError, match=r"transform_power = 0.5 is not allowed for transform = 'ln'"):
        AnalysisSpec(transform="ln", transform_power=0.5)
    with pytest.raises(StudyError, match=r"\[\[responses\]\] 'y'.*transform_power = None is not allowed"):
        ResponseSpec("y", "angle_fit_deg", transform="power")
    a = AnalysisSpec(transform="sqrt")
    assert a.transform_for(ResponseSpec("y", "angle_fit_deg")) == Transform("sqrt")
    assert a.transform_for(ResponseSpec("z", "angle_fit_deg", transform="ln")) == Transform("ln")


@pytest.fixture(scope="module")
def ln_report(tmp_path_factory):
    """write_report of the log-linear response with ln as its transform and a target of 10: (folder, summary)."""
    from warpdem.study.report import write_report

    out = tmp_path_factory.mktemp("ln_report")
    res = write_report(
        out,
        _multiplicative(),
        title="t",
        factors=[Factor("A", 0.0, 1.0), Factor("B", 0.0, 1.0)],
        labels={},
        responses=[{"name": "y", "unit": "", "target": 10.0, "transform": Transform("ln")}],
        model="linear",
    )
    return out, res


def test_the_report_fits_the_transform_and_says_so(ln_report):
    """write_report with a response's transform: report.md says which scale the model is on, the equation is
    ln(y)'s, and the target solution predicts the target in y's units."""
    out, res = ln_report
    md = (out / "report.md").read_text()
    assert "**Transform:** the model is fitted to ln(y)" in md and "ln(y) = " in md
    assert res["y"]["predicted"] == pytest.approx(10.0, rel=1e-6)


def test_confirmation_runs_are_judged_on_the_models_scale(ln_report):
    """The report entry keeps the model scale's prediction and the transform; the interval for a mean of four
    confirmation runs is exp of the ln scale's interval for four runs (mean_prediction_interval), not an interval
    of mixed scales."""
    from warpdem.study.analysis import mean_prediction_interval
    from warpdem.study.execute import confirmation_runs_interval

    _, res = ln_report
    conf = res["y"]["confirmation"]
    assert conf["predicted"] == pytest.approx(np.log(10.0), rel=1e-6) and conf["transform"]["kind"] == "ln"
    lo, hi = mean_prediction_interval(conf["predicted"], conf["mse"], conf["h0"], conf["df"], 4, conf["alpha"])
    assert confirmation_runs_interval(conf, 4) == pytest.approx((np.exp(lo), np.exp(hi)), rel=1e-12)
    assert confirmation_runs_interval(conf, 4)[0] < 10.0 < confirmation_runs_interval(conf, 4)[1]
