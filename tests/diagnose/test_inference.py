"""Statistics of warpdem.diagnose.inference against answers known in closed form or from the libraries."""

from __future__ import annotations

import gc
import math

import numpy as np
import pandas as pd
import pytest
import statsmodels.api as sm
from scipy import stats
from statsmodels.stats.multitest import multipletests

from warpdem.diagnose import inference as inf

# --------------------------------------------------------------------------------------------
# space_filling
# --------------------------------------------------------------------------------------------


def test_space_filling_is_a_seeded_latin_hypercube():
    """Shape (n, d), inside the unit cube, exactly one point in each of the n strata of every dimension
    (the Latin-hypercube property, which the random-cd optimisation must keep), and the same seed gives the
    same points while another seed does not."""
    n, d = 23, 4
    X = inf.space_filling(n, d, seed=3)
    assert X.shape == (n, d)
    assert np.all((X >= 0) & (X < 1))
    for j in range(d):
        assert np.array_equal(np.sort(np.floor(n * X[:, j]).astype(int)), np.arange(n))
    assert np.array_equal(X, inf.space_filling(n, d, seed=3))
    assert not np.allclose(X, inf.space_filling(n, d, seed=4))


# --------------------------------------------------------------------------------------------
# Surrogate
# --------------------------------------------------------------------------------------------

NOISE = 0.05


def _smooth(X: np.ndarray) -> np.ndarray:
    return np.sin(3.0 * X[:, 0]) + 2.0 * (X[:, 1] - 0.5) ** 2


@pytest.fixture(scope="module")
def noisy_fit():
    X = inf.space_filling(60, 2, seed=0)
    y = _smooth(X) + NOISE * np.random.default_rng(1).standard_normal(60)
    return X, y, inf.Surrogate(seed=0).fit(X, y)


def test_surrogate_predicts_a_smooth_function_within_its_sd(noisy_fit):
    """sin + quadratic in 2-D with noise of SD 0.05 on a 60-point design: at 200 held-out points the
    latent mean is closer to the truth than one noise SD (RMS), the truth lies within 3 predictive SD at
    >= 90 % of them, and the SD excludes the white noise (it is well below the noise SD in the interior)."""
    _, _, s = noisy_fit
    Xt = inf.space_filling(200, 2, seed=99)
    mean, sd = s.predict(Xt)
    err = mean - _smooth(Xt)
    assert mean.shape == sd.shape == (200,)
    assert math.sqrt(np.mean(err**2)) < NOISE
    assert np.mean(np.abs(err) < 3 * sd) >= 0.9
    assert np.median(sd) < 0.7 * NOISE


def test_surrogate_predicts_as_sklearn_does(noisy_fit):
    """The prediction written out (the sampler's hot path) equals sklearn's GaussianProcessRegressor.predict
    with the same fitted kernel, mean and SD, at points inside and outside the design and at a design point."""
    X, _, s = noisy_fit
    Xt = np.vstack([inf.space_filling(50, 2, seed=7), X[:3], [[0.0, 1.0], [1.0, 1.0]]])
    mean, sd = s.predict(Xt)
    ref_mean, ref_sd = s._gp.predict(Xt, return_std=True)
    np.testing.assert_allclose(mean, s._offset + s._scale * ref_mean, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(sd, s._scale * ref_sd, rtol=1e-7, atol=1e-9)


def test_surrogate_noise_and_cross_validation(noisy_fit):
    """The fitted white-noise SD is within a factor 1.5 of the true 0.05; K-fold cross-validated RMSE of a
    noisy observation is about the noise SD (the surrogate error adds a little); Q^2 near 1 for a function
    whose range (~1.3) dwarfs the noise."""
    _, y, s = noisy_fit
    assert NOISE / 1.5 < s.noise_sd < 1.5 * NOISE
    cv = s.cv()
    assert cv["folds"] == inf.KFOLD
    assert NOISE / 1.5 < cv["rmse"] < 1.5 * NOISE
    assert cv["q2"] > 0.95
    assert cv["rmse_range"] == pytest.approx(cv["rmse"] / np.ptp(y))


def test_surrogate_leave_one_out_matches_closed_form():
    """With the hyperparameters fixed, leave-one-out residuals of a GP are [K^-1 z]_i / [K^-1]_ii
    (Rasmussen & Williams 2006, eq. 5.12), with K the fitted kernel (white noise included) on the
    standardised y: the refitting cross-validation on 25 points must reproduce that RMSE and Q^2."""
    X = inf.space_filling(25, 3, seed=7)
    y = 4.0 + X[:, 0] - np.cos(2 * X[:, 1]) + 0.1 * np.random.default_rng(2).standard_normal(25)
    s = inf.Surrogate(seed=1).fit(X, y)
    cv = s.cv()
    assert cv["folds"] == 25
    Kinv = np.linalg.inv(s.kernel(X))
    z = (y - y.mean()) / y.std()
    e = y.std() * (Kinv @ z) / np.diag(Kinv)
    assert cv["rmse"] == pytest.approx(math.sqrt(np.mean(e**2)), rel=1e-6)
    assert cv["q2"] == pytest.approx(1 - np.sum(e**2) / np.sum((y - y.mean()) ** 2), rel=1e-6)


def test_surrogate_takes_replicates_and_drops_failed_runs():
    """World-seed replicates (each of 20 design points run 3 times, noise SD 0.05) pin the noise: its
    estimate is within 25 %; cross-validation leaves out whole design points (20 folds). Non-finite y
    (failed simulations) are dropped with their X: the fit equals the fit without those rows."""
    X = np.repeat(inf.space_filling(20, 2, seed=5), 3, axis=0)
    y = _smooth(X) + NOISE * np.random.default_rng(3).standard_normal(60)
    s = inf.Surrogate(seed=0).fit(X, y)
    assert NOISE / 1.25 < s.noise_sd < 1.25 * NOISE
    assert s.cv()["folds"] == 20

    y_failed = y.copy()
    y_failed[[4, 17, 30]] = [np.nan, np.inf, np.nan]
    keep = np.isfinite(y_failed)
    a = inf.Surrogate(seed=0).fit(X, y_failed)
    b = inf.Surrogate(seed=0).fit(X[keep], y[keep])
    Xt = inf.space_filling(10, 2, seed=6)
    assert a.X.shape == (57, 2)
    np.testing.assert_allclose(a.predict(Xt), b.predict(Xt))


def test_surrogate_of_a_constant_response():
    """A response that does not vary (e.g. a clamped output) is predicted as that constant with zero SD
    and zero noise; cross-validation is exact."""
    X = inf.space_filling(12, 3, seed=0)
    s = inf.Surrogate().fit(X, np.full(12, 2.5))
    mean, sd = s.predict(inf.space_filling(5, 3, seed=1))
    assert np.array_equal(mean, np.full(5, 2.5)) and np.array_equal(sd, np.zeros(5))
    assert s.noise_sd == 0.0
    assert s.cv() == {"rmse": 0.0, "q2": 1.0, "rmse_range": 0.0, "folds": 0}


def test_surrogate_rejects_points_outside_the_unit_cube():
    """The surrogate lives on the unit cube; physical parameter values are a caller's mistake."""
    with pytest.raises(ValueError, match="unit cube"):
        inf.Surrogate().fit(np.array([[0.1, 0.2], [1.5, 0.3], [0.4, 0.9]]), np.array([1.0, 2.0, 3.0]))


# --------------------------------------------------------------------------------------------
# calibrate
# --------------------------------------------------------------------------------------------


def _linear_problem(u_true, n=12, seed=5):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, len(u_true)))
    b = rng.normal(size=n)
    variance = 0.05**2 * rng.uniform(0.5, 2.0, n)
    return A, b, variance, rng


@pytest.mark.parametrize("surrogate_share", [0.0, 1.0])
def test_calibrate_linear_gaussian_posterior(surrogate_share):
    """predict(u) = A u + b with a constant surrogate variance (0 or equal to the noise): the posterior is
    Gaussian, mean = the weighted least-squares solution with weights 1/(variance + surrogate variance),
    covariance (A^T W A)^-1, well inside the cube. The MAP equals the WLS solution to 1 % of a posterior SD;
    the sample SDs match the analytic ones within 15 %, the 95 % intervals the analytic ones within 0.3 SD."""
    A, b, variance, rng = _linear_problem([0.4, 0.6])
    measured = A @ [0.4, 0.6] + b + np.sqrt(variance) * rng.standard_normal(len(b))
    s_var = surrogate_share * variance

    def predict(U):
        return U @ A.T + b, np.broadcast_to(s_var, (U.shape[0], len(b)))

    out = inf.calibrate(predict, measured, variance, d=2, seed=0)
    W = np.diag(1 / (variance + s_var))
    cov = np.linalg.inv(A.T @ W @ A)
    mean = cov @ A.T @ W @ (measured - b)
    sd = np.sqrt(np.diag(cov))
    assert np.all((mean - 4 * sd > 0) & (mean + 4 * sd < 1))
    np.testing.assert_allclose(out["map"], mean, atol=0.01 * sd.min())
    np.testing.assert_allclose(out["samples"].std(axis=0), sd, rtol=0.15)
    analytic = mean[:, None] + stats.norm.ppf(0.975) * sd[:, None] * [-1, 1]
    np.testing.assert_allclose(out["interval"], analytic, atol=0.3 * sd.min())
    assert np.array_equal(out["at_bound"], [0, 0])
    assert 0.2 < out["acceptance"] < 0.9
    total = variance + s_var
    r = measured - A @ mean - b
    assert out["loglik"] == pytest.approx(-0.5 * np.sum(np.log(2 * np.pi * total) + r**2 / total))


def test_calibrate_maximum_on_the_boundary():
    """One parameter, predict linear, the data pulling to u = -0.02 (as half of all noisy data sets from a
    truth at the off value u = 0 do): the MAP is 0, the interval starts at 0 and ends at the 95th
    percentile of the posterior, a normal truncated to u >= 0 (scipy truncnorm), within 10 %."""
    A, b, variance, _ = _linear_problem([0.0], n=8, seed=9)
    measured = A @ [-0.02] + b

    def predict(U):
        return U @ A.T + b, np.zeros((U.shape[0], len(b)))

    out = inf.calibrate(predict, measured, variance, d=1, seed=2)
    sd = 1 / math.sqrt(np.sum(A[:, 0] ** 2 / variance))
    assert out["map"][0] == pytest.approx(0.0, abs=1e-9)
    assert out["at_bound"][0] == -1
    assert out["interval"][0, 0] == 0.0
    upper = stats.truncnorm.ppf(0.95, (0 + 0.02) / sd, np.inf, loc=-0.02, scale=sd)
    assert out["interval"][0, 1] == pytest.approx(upper, rel=0.10)
    assert out["samples"].min() >= 0.0


def test_calibrate_repeats_with_its_seed():
    """The same seed gives the same MAP and the same samples (space-filling starts and emcee's state)."""
    A, b, variance, rng = _linear_problem([0.3, 0.7])
    measured = A @ [0.3, 0.7] + b

    def predict(U):
        return U @ A.T + b, np.zeros((U.shape[0], len(b)))

    a = inf.calibrate(predict, measured, variance, d=2, seed=4, steps=200, x0=[0.5, 0.5])
    c = inf.calibrate(predict, measured, variance, d=2, seed=4, steps=200, x0=[0.5, 0.5])
    assert np.array_equal(a["map"], c["map"]) and np.array_equal(a["samples"], c["samples"])


def test_calibrate_runs_the_chain_to_fifty_autocorrelation_times():
    """A posterior ridge (two parameters that trade off, correlation -0.998) mixes slowly: 200 steps leave the
    kept half far short of 50 autocorrelation times, so the chain is doubled until it spans them (or reaches
    the cap of 8 x steps); a well-determined posterior (tau about 30) given 4000 steps keeps them. Steps 0 gives
    the maximum alone."""
    A = np.array([[1.0, 1.0], [1.0, 1.02], [1.0, 0.98]])
    b = np.zeros(3)
    variance = np.full(3, 0.02**2)
    measured = A @ [0.5, 0.5]

    def ridge(U):
        return U @ A.T + b, np.zeros((U.shape[0], 3))

    out = inf.calibrate(ridge, measured, variance, d=2, seed=3, steps=200)
    kept = out["steps"] - out["steps"] // 2
    assert out["steps"] > 200
    assert kept >= inf.TAU_SPAN * np.max(out["tau"]) or out["steps"] == inf.MAX_STEPS_FACTOR * 200
    assert out["effective_samples"] == pytest.approx(16 * kept / np.max(out["tau"]))

    A2, b2, var2, _ = _linear_problem([0.4, 0.6])
    easy = inf.calibrate(
        lambda U: (U @ A2.T + b2, np.zeros((U.shape[0], len(b2)))),
        A2 @ [0.4, 0.6] + b2,
        var2 / 1e4,
        d=2,
        seed=0,
        steps=4000,
    )
    assert easy["steps"] == 4000 and 2000 >= inf.TAU_SPAN * np.max(easy["tau"])
    only = inf.calibrate(ridge, measured, variance, d=2, seed=3, steps=0)
    assert set(only) == {"map", "loglik", "at_bound"}
    np.testing.assert_allclose(only["map"], out["map"])


# --------------------------------------------------------------------------------------------
# holm
# --------------------------------------------------------------------------------------------


def test_holm_by_hand_and_against_statsmodels():
    """p = (0.01, 0.04, 0.03, 0.005): sorted 0.005 x 4 = 0.02, 0.01 x 3 = 0.03, 0.03 x 2 = 0.06,
    0.04 x 1 -> 0.06 (monotone); NaN is left out of the family (two tests: 0.01 x 2, 0.04 x 1); a longer
    vector equals statsmodels' multipletests."""
    np.testing.assert_allclose(inf.holm([0.01, 0.04, 0.03, 0.005]), [0.03, 0.06, 0.06, 0.02])
    np.testing.assert_allclose(inf.holm([0.01, np.nan, 0.04]), [0.02, np.nan, 0.04])
    p = np.random.default_rng(0).uniform(0, 0.2, 15)
    np.testing.assert_allclose(inf.holm(p), multipletests(p, method="holm")[1])
    assert np.all(np.isnan(inf.holm([np.nan, np.nan])))


# --------------------------------------------------------------------------------------------
# adequacy
# --------------------------------------------------------------------------------------------

SIZES = np.array([1e-3, 2e-3, 3e-3, 4e-3])  # particle diameter, m
FILLS = np.array([0.3, 0.5, 0.7])


def _experiments() -> tuple[pd.DataFrame, np.ndarray, np.ndarray]:
    """12 experiments (4 sizes x 3 fill fractions), 2 responses each: conditions (24 rows, indexed by
    experiment), response labels and noise variances."""
    size, fill = (g.ravel() for g in np.meshgrid(SIZES, FILLS, indexing="ij"))
    names = [f"e{i:02d}" for i in range(size.size)]
    one = pd.DataFrame({"size": size, "fill": fill, "material": "glass"}, index=names)
    conditions = pd.concat([one, one])
    responses = np.repeat(["angle", "flow"], size.size)
    variance = np.r_[np.full(size.size, 0.5**2), np.full(size.size, 0.02**2)] * np.tile(np.linspace(0.5, 2, 12), 2)
    return conditions, responses, variance


def test_adequacy_false_positive_rate_of_an_exact_model(monkeypatch):
    """Measured = a model linear in 2 parameters + noise of the stated variance, the parameters fitted by
    WLS, residuals tested: over 200 seeded repetitions the fraction declared inadequate at alpha = 0.05 is
    at most alpha + 3 standard errors (Holm over chi-square, point and trend tests controls the family-wise
    error)."""
    # statsmodels' Holm runs gc.collect() on every call (~0.1 s in a test process full of modules)
    monkeypatch.setattr(gc, "collect", lambda *args: 0)
    conditions, responses, variance = _experiments()
    G = np.random.default_rng(10).normal(size=(24, 2))
    rng = np.random.default_rng(11)
    rejected = 0
    for _ in range(200):
        measured = G @ [1.0, -0.5] + np.sqrt(variance) * rng.standard_normal(24)
        theta = sm.WLS(measured, G, weights=1 / variance).fit().params
        out = inf.adequacy(measured - G @ theta, variance, 2, conditions, responses, alpha=0.05)
        rejected += not out["adequate"]
    assert rejected / 200 <= 0.05 + 3 * math.sqrt(0.05 * 0.95 / 200)


def test_adequacy_finds_a_trend_in_one_condition():
    """A residual that grows by 3 sigma per size step in the angle response: not adequate, the angle-size
    trend is significant with a 95 % CI covering the true slope, while the trend in fill fraction (no
    trend there) and the flow response's trends are not. The text column (material) is not regressed on."""
    conditions, responses, variance = _experiments()
    sd = np.sqrt(variance)
    step = np.searchsorted(SIZES, conditions["size"].to_numpy())
    residual = sd * np.random.default_rng(4).standard_normal(24)
    angle = responses == "angle"
    residual[angle] += 3 * 0.5 * (step[angle] - 1.5)  # 3 x the mean angle SD (0.5) per step
    out = inf.adequacy(residual, variance, 2, conditions, responses)
    tests = out["tests"]
    assert not out["adequate"]
    trend = tests[tests["kind"] == "trend"].set_index(["response", "condition"])
    assert set(trend.index) == {("angle", "size"), ("angle", "fill"), ("flow", "size"), ("flow", "fill")}
    assert trend.loc[("angle", "size"), "significant"]
    true_slope = 1.5 / 1e-3
    assert trend.loc[("angle", "size"), "ci_low"] < true_slope < trend.loc[("angle", "size"), "ci_high"]
    assert not trend.loc[("angle", "fill"), "significant"]
    assert not trend.loc[("flow", "size"), "significant"] and not trend.loc[("flow", "fill"), "significant"]


def test_adequacy_tables_against_scipy_and_statsmodels():
    """Every number in the table, recomputed independently: z = r / sd; chi-square per response on
    df = 12 - 2 x 12 / 24 = 11; two-sided normal p per point; the WLS slope, CI and p equal statsmodels'
    formula API on the same rows; p_holm is Holm over the whole family."""
    conditions, responses, variance = _experiments()
    residual = np.sqrt(variance) * np.random.default_rng(8).standard_normal(24) * 1.3
    out = inf.adequacy(residual, variance, 2, conditions, responses, alpha=0.05)
    z = residual / np.sqrt(variance)
    np.testing.assert_allclose(out["z"]["z"], z)
    assert list(out["z"]["experiment"]) == list(conditions.index)
    tests = out["tests"]

    chi = tests[tests["kind"] == "chi2"].set_index("response")
    angle = responses == "angle"
    assert chi.loc["angle", "df"] == 11
    assert chi.loc["angle", "p"] == pytest.approx(stats.chi2.sf(np.sum(z[angle] ** 2), 11))

    point = tests[tests["kind"] == "point"]
    np.testing.assert_allclose(point["p"], 2 * stats.norm.sf(np.abs(z)))
    assert list(point["experiment"]) == list(conditions.index)

    import statsmodels.formula.api as smf

    data = conditions[~angle].assign(r=residual[~angle], w=1 / variance[~angle])
    ref = smf.wls("r ~ size", data=data, weights=data["w"]).fit()
    row = tests[(tests["kind"] == "trend") & (tests["response"] == "flow") & (tests["condition"] == "size")].iloc[0]
    assert row["slope"] == pytest.approx(ref.params["size"])
    assert (row["ci_low"], row["ci_high"]) == pytest.approx(tuple(ref.conf_int(0.05).loc["size"]))
    assert row["p"] == pytest.approx(ref.pvalues["size"])
    assert row["df"] == 10

    np.testing.assert_allclose(tests["p_holm"], multipletests(tests["p"], method="holm")[1])
    assert out["adequate"] == (not np.any(tests["p_holm"] < 0.05))


# --------------------------------------------------------------------------------------------
# lrt_boundary, aic, bic
# --------------------------------------------------------------------------------------------


def test_lrt_boundary_mixture():
    """Self & Liang's 50:50 mixture of chi2_0 and chi2_1: p = P(chi2_1 > LR) / 2, so LR = 2.71 (the
    chi2_1 90 % point) gives p = 0.05; no gain gives p = 1; with one more interior parameter the mixture
    is of chi2_1 and chi2_2."""
    lr, p = inf.lrt_boundary(-10.0, -8.0)
    assert lr == 4.0 and p == pytest.approx(0.5 * stats.chi2.sf(4.0, 1))
    assert inf.lrt_boundary(0.0, 2.71 / 2)[1] == pytest.approx(0.05, abs=5e-4)
    assert inf.lrt_boundary(-3.0, -3.0) == (0.0, 1.0)
    assert inf.lrt_boundary(-3.0, -3.5)[1] == 1.0
    assert inf.lrt_boundary(0.0, 2.0, df=2)[1] == pytest.approx(
        0.5 * stats.chi2.sf(4.0, 2) + 0.5 * stats.chi2.sf(4.0, 1)
    )


def test_lrt_boundary_is_the_one_sided_z_test_of_a_mean():
    """For n draws from N(mu, sigma^2), mu >= 0 with null mu = 0, LR = n max(xbar, 0)^2 / sigma^2, and the
    exact one-sided test of the mean has p = P(Z > sqrt(n) xbar / sigma): the boundary mixture must give
    that p for every xbar > 0."""
    n, sigma = 9, 2.0
    for xbar in (0.1, 0.8, 1.5, 3.0):
        ll_base = -0.5 * n * xbar**2 / sigma**2  # the Gaussian log-likelihood up to a shared constant
        _, p = inf.lrt_boundary(ll_base, 0.0)
        assert p == pytest.approx(stats.norm.sf(math.sqrt(n) * xbar / sigma))


def test_information_criteria():
    """AIC = 2k - 2 loglik, BIC = k ln n - 2 loglik (Akaike 1974, Schwarz 1978)."""
    assert inf.aic(-10.0, 3) == 26.0
    assert inf.bic(-10.0, 3, 100) == pytest.approx(3 * math.log(100) + 20.0)


# --------------------------------------------------------------------------------------------
# screen
# --------------------------------------------------------------------------------------------


def _screen_problem(seed=0):
    rng = np.random.default_rng(seed)
    n = 15
    variance = rng.uniform(0.5, 2.0, n) ** 2
    J = rng.normal(size=(n, 2))
    return rng, variance, J


def test_screen_effect_equal_to_residual():
    """An effect that is exactly the residual explains it all at coefficient 1 with theta untouched: the
    extended chi-square is 0, delta chi-square is the base model's, p is tiny."""
    rng, variance, J = _screen_problem()
    r = 3 * np.sqrt(variance) * rng.standard_normal(15)
    out = inf.screen(r, variance, J, r)
    assert out["coefficient"] == pytest.approx(1.0)
    np.testing.assert_allclose(out["theta_shift"], 0.0, atol=1e-9)
    assert out["chi2_ext"] == pytest.approx(0.0, abs=1e-9)
    assert out["delta_chi2"] == pytest.approx(out["chi2_base"]) and out["delta_chi2"] > 50
    assert out["p"] < 1e-6


def test_screen_orthogonal_and_wrong_way_effects():
    """An effect orthogonal, in the 1/variance inner product, to the residual and to the Jacobian's columns
    explains nothing (delta chi2 = 0, p = 1); an effect pointing against the residual is held at its
    bound, coefficient 0, which is the base fit."""
    rng, variance, J = _screen_problem(1)
    w = 1 / np.sqrt(variance)
    Q, _ = np.linalg.qr(np.column_stack([J * w[:, None], rng.normal(size=(15, 2))]))
    r = Q[:, 2] * 4 / w  # weighted residual orthogonal to the weighted Jacobian
    e = Q[:, 3] / w  # weighted effect orthogonal to both
    out = inf.screen(r, variance, J, e)
    assert out["delta_chi2"] == pytest.approx(0.0, abs=1e-9) and out["p"] == 1.0
    assert out["chi2_base"] == pytest.approx(16.0)

    out = inf.screen(r, variance, J, -r)
    assert out["coefficient"] == 0.0
    assert out["delta_chi2"] == pytest.approx(0.0, abs=1e-9) and out["p"] == 1.0


def test_screen_against_the_projection_formula():
    """With the coefficient unconstrained-positive, adding a regressor e to a weighted fit on J drops the
    chi-square by (e_perp . r_perp)^2 / |e_perp|^2, with _perp the weighted residuals after projecting out
    J (Frisch-Waugh-Lovell); the coefficient is (e_perp . r_perp) / |e_perp|^2. A Jacobian column of
    zeros (a parameter with no sensitivity) changes nothing."""
    rng, variance, J = _screen_problem(2)
    r = np.sqrt(variance) * rng.standard_normal(15) + J @ [0.3, -0.2]
    e = 0.5 * r + np.sqrt(variance) * rng.standard_normal(15)
    w = 1 / np.sqrt(variance)
    P = np.eye(15) - (J * w[:, None]) @ np.linalg.pinv(J * w[:, None])
    r_perp, e_perp = P @ (r * w), P @ (e * w)
    coef = (e_perp @ r_perp) / (e_perp @ e_perp)
    assert coef > 0
    out = inf.screen(r, variance, np.column_stack([J, np.zeros(15)]), e)
    assert out["coefficient"] == pytest.approx(coef, rel=1e-6)
    assert out["delta_chi2"] == pytest.approx((e_perp @ r_perp) ** 2 / (e_perp @ e_perp), rel=1e-6)
    assert out["p"] == pytest.approx(0.5 * stats.chi2.sf(out["delta_chi2"], 1))


# --------------------------------------------------------------------------------------------
# held-out losses and bootstrap
# --------------------------------------------------------------------------------------------


def test_gaussian_nll_and_experiment_losses():
    """The NLL is minus scipy's normal log-density; per experiment, z^2 and NLL are averaged over its rows
    (hand-worked: e1 has z = 1 and 2, e2 has z = 3)."""
    r, v = np.array([0.5, -2.0, 3.0]), np.array([0.25, 1.0, 1.0])
    np.testing.assert_allclose(inf.gaussian_nll(r, v), -stats.norm.logpdf(r, scale=np.sqrt(v)))
    losses = inf.experiment_losses(r, v, ["e1", "e1", "e2"])
    assert list(losses.index) == ["e1", "e2"]
    np.testing.assert_allclose(losses["z2"], [2.5, 9.0])
    np.testing.assert_allclose(losses.loc["e2", "nll"], -stats.norm.logpdf(3.0))


def test_bootstrap_covers_the_known_mean():
    """Losses z^2 of standard-normal z have mean 1: the 95 % percentile interval of the mean of 100 such
    losses covers 1 in about 95 % of 200 seeded data sets (>= 90 %: the percentile interval of a skewed
    chi2_1 mean under-covers a little at n = 100)."""
    rng = np.random.default_rng(0)
    covered = 0
    for i in range(200):
        loss = rng.standard_normal(100) ** 2
        row = inf.bootstrap({"m": loss}, seed=i, n_boot=1000)["models"].iloc[0]
        assert row["mean"] == pytest.approx(loss.mean())
        covered += row["low"] <= 1.0 <= row["high"]
    assert covered / 200 >= 0.90


def test_bootstrap_pairs_are_paired():
    """Resamples are shared by all models: identical models differ by exactly 0 in every resample, a model
    worse by a constant 0.5 on every experiment differs by 0.5 with a zero-width interval, and a noisier
    model's difference interval covers its true excess (1 for z^2 of SD sqrt(2) vs 1)."""
    rng = np.random.default_rng(1)
    base = rng.standard_normal(200) ** 2
    noisy = 2 * rng.standard_normal(200) ** 2
    out = inf.bootstrap({"base": base, "same": base.copy(), "shifted": base + 0.5, "noisy": noisy}, seed=3)
    pairs = out["pairs"].set_index(["model_a", "model_b"])
    assert len(pairs) == 6
    assert tuple(pairs.loc[("base", "same"), ["difference", "low", "high"]]) == (0.0, 0.0, 0.0)
    np.testing.assert_allclose(pairs.loc[("base", "shifted"), ["difference", "low", "high"]], -0.5)
    assert pairs.loc[("base", "noisy"), "low"] < -1.0 < pairs.loc[("base", "noisy"), "high"]
    assert list(out["models"]["model"]) == ["base", "same", "shifted", "noisy"]


def test_pooled_variance_is_the_one_way_anova_residual_mean_square():
    """Pooled within-group variance = the residual mean square of OLS on group dummies (statsmodels); groups of
    one value and NaNs add nothing."""
    rng = np.random.default_rng(3)
    groups = [rng.normal(m, 2.0, n) for m, n in ((0.0, 4), (5.0, 3), (-2.0, 6))]
    var, dof = inf.pooled_variance([*groups, np.array([7.0]), np.array([np.nan, np.nan])])
    y = np.concatenate(groups)
    X = np.zeros((len(y), 3))
    X[np.arange(len(y)), np.repeat(np.arange(3), [4, 3, 6])] = 1.0
    fit = sm.OLS(y, X).fit()
    assert dof == int(fit.df_resid) == 10
    assert var == pytest.approx(fit.scale, rel=1e-12)
    assert inf.pooled_variance([np.array([1.0])]) == (pytest.approx(float("nan"), nan_ok=True), 0)


def test_trend_scale_is_never_below_the_budget():
    """Three residuals on a line well inside the noise budget (a null press's -0.57, -0.52, -0.41 SD at 0.5, 1 and
    2 N) show no trend: the slope is tested against the budget's scale (statsmodels' fixed-scale z-test), not
    against their near-zero scatter about the line. Residuals scattered beyond the budget keep the t-test on
    their own scale, and a real trend (-13, -8, -6 SD) is found either way."""
    import pandas as pd

    force = pd.DataFrame({"force": [0.5, 1.0, 2.0]}, index=["F0", "F1", "F2"])
    labels = np.array(["set"] * 3)
    var = np.full(3, 0.01**2)
    out = inf.adequacy(np.array([-0.571, -0.518, -0.406]) * 0.01, var, 1, force, labels)
    row = out["tests"].query("kind == 'trend'").iloc[0]
    x = np.column_stack([np.ones(3), force["force"]])
    ref = sm.WLS(np.array([-0.571, -0.518, -0.406]) * 0.01, x, weights=1 / var).fit(
        cov_type="fixed scale", cov_kwds={"scale": 1.0}
    )
    assert row["p"] == pytest.approx(ref.pvalues[1]) and row["p"] > 0.5
    assert out["adequate"]
    wide = np.array([-2.0, 2.5, -1.0]) * 0.01
    row = inf.adequacy(wide, var, 1, force, labels)["tests"].query("kind == 'trend'").iloc[0]
    assert row["p"] == pytest.approx(sm.WLS(wide, x, weights=1 / var).fit().pvalues[1])
    strong = inf.adequacy(np.array([-13.0, -8.0, -6.0]) * 0.01, var, 1, force, labels)
    assert not strong["adequate"]
