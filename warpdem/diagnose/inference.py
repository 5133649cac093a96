"""The statistics of a diagnosis: designs, surrogates, calibration, adequacy, model comparison.

A diagnosis calibrates the free parameters theta (d of them) of a DEM model to measured experiments, tests
whether the calibrated model is adequate, tries candidate extensions (one extra parameter each, whose "off"
value reduces it to the base model and usually lies at the edge of its range) and measures the gain on
held-out data. Everything here works in the unit cube [0, 1]^d of the parameters (the caller maps to physical
units) and on plain arrays; nothing here runs a simulation.

``space_filling``  a seeded, optimised Latin hypercube: where to simulate.
``Surrogate``      one Gaussian process per (condition, response) over the unit cube, with its noise
                   (world-seed scatter) and a cross-validated accuracy.
``calibrate``      MAP (multi-start L-BFGS-B) and posterior samples (emcee) of theta given measured means.
``adequacy``       chi-square, per-point and trend tests of the standardised residuals, Holm-adjusted together.
``screen``         whether a candidate's effect, with theta re-tuned, can explain the residual (linearised).
``lrt_boundary``   likelihood-ratio test of an extra parameter whose null value is on its range's boundary;
                   ``aic`` and ``bic``.
``bootstrap``      paired bootstrap over experiments of held-out losses (``experiment_losses``,
                   ``gaussian_nll``) of several models.

Every random choice takes a seed, so a diagnosis repeats exactly.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from warpdem.errors import InputError

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "Surrogate",
    "adequacy",
    "aic",
    "bic",
    "bootstrap",
    "calibrate",
    "experiment_losses",
    "gaussian_nll",
    "holm",
    "lrt_boundary",
    "scatter_excess",
    "screen",
    "space_filling",
]

LOO_MAX = 30
"""Surrogate cross-validation leaves one design point out up to this many points, and is K-fold above."""

KFOLD = 10
"""Folds of the surrogate cross-validation above ``LOO_MAX`` design points."""

EDGE = 1e-6
"""A MAP coordinate this close to 0 or 1 lies on the cube's boundary (L-BFGS-B stops exactly on a bound)."""


def _vector(name: str, a, n: int | None = None) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.ndim != 1:
        raise InputError(f"{name} must be one-dimensional, got shape {a.shape}")
    if n is not None and a.shape[0] != n:
        raise InputError(f"{name} has {a.shape[0]} values, expected {n}")
    return a


def _variance(name: str, v, n: int) -> np.ndarray:
    v = _vector(name, v, n)
    if not np.all(np.isfinite(v) & (v > 0)):
        raise InputError(f"{name} must be finite and positive")
    return v


# --------------------------------------------------------------------------------------------
# Design and surrogate
# --------------------------------------------------------------------------------------------


def pooled_variance(groups) -> tuple[float, int]:
    """(pooled within-group variance, its degrees of freedom) of ``groups`` (an iterable of 1-D arrays; NaNs
    dropped): sum of squared deviations from each group's mean over sum (n - 1), from the groups with two or more
    values; (NaN, 0) when none has two."""
    ss, dof = 0.0, 0
    for g in groups:
        v = np.asarray(g, dtype=float)
        v = v[np.isfinite(v)]
        if len(v) >= 2:
            ss += float(((v - v.mean()) ** 2).sum())
            dof += len(v) - 1
    return (ss / dof, dof) if dof else (math.nan, 0)


def space_filling(n: int, d: int, seed: int = 0) -> np.ndarray:
    """``n`` points in [0, 1]^d, shape (n, d): a Latin hypercube (each dimension has exactly one point in each
    of its n equal strata) whose centred discrepancy is lowered by random coordinate swaps (``random-cd``,
    which keeps the Latin property). The same seed gives the same points."""
    import inspect

    from scipy.stats import qmc

    # scipy >= 1.15 names the generator argument `rng`; `seed` is the older name (and draws differently)
    key = "rng" if "rng" in inspect.signature(qmc.LatinHypercube).parameters else "seed"
    return qmc.LatinHypercube(d, optimization="random-cd", **{key: seed}).random(n)


class Surrogate:
    """A Gaussian-process surrogate of one response over the unit cube of the parameters.

    The kernel is ConstantKernel * Matern(nu=2.5, one length scale per parameter) + WhiteKernel, fitted by
    maximum marginal likelihood with ``restarts`` extra optimiser starts drawn from ``seed``. y is
    standardised before the fit (what ``normalize_y`` does, done here so that the noise and the
    predictive SD scale back explicitly). The white-noise term absorbs the world-seed scatter, so design
    points may repeat (replicates); :meth:`predict` gives the SD of the latent mean, without that noise.

    Attributes after :meth:`fit`: ``X`` (n, d) and ``y`` (n,) the finite training data, ``kernel`` the fitted
    sklearn kernel (None for a constant response), ``noise_sd`` the fitted white-noise SD in y units.
    """

    # length scales below ~1/20 of the cube resolve nothing a space-filling design of tens of points can see;
    # above ~100 the response is flat in that parameter, and the bound only stops the optimiser wandering
    LENGTH_SCALE_BOUNDS = (0.05, 100.0)
    # of the standardised y: a 1e-4 SD floor keeps the Cholesky factor of exact replicates stable
    NOISE_BOUNDS = (1e-8, 10.0)
    # a smooth response is fitted as a huge amplitude with long length scales (a GP's low-order polynomial):
    # 100 x the variance of y is plenty for that and stops the pair running away together
    AMPLITUDE_BOUNDS = (1e-2, 1e2)

    def __init__(self, seed: int = 0, restarts: int = 4):
        self.seed = seed
        self.restarts = restarts
        self.kernel = None
        self.noise_sd = math.nan
        self._gp = None  # the latent GP (kernel without the white term, its noise as alpha)
        self._unfitted = None
        self._constant: float | None = None

    def fit(self, X, y) -> Surrogate:
        """Fit to design points ``X`` (n, d) in the unit cube and responses ``y`` (n,). Non-finite y (failed
        simulations) are dropped with their X. Returns self."""
        from sklearn.exceptions import ConvergenceWarning
        from sklearn.gaussian_process import GaussianProcessRegressor
        from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel

        X = np.asarray(X, dtype=float)
        if X.ndim != 2:
            raise InputError(f"X must be (n, d), got shape {X.shape}")
        y = _vector("y", y, X.shape[0])
        if not np.all(np.isfinite(X)) or X.min(initial=0.0) < -1e-9 or X.max(initial=1.0) > 1 + 1e-9:
            raise InputError("X must lie in the unit cube [0, 1]^d")
        keep = np.isfinite(y)
        X, y = X[keep], y[keep]
        if y.size == 0:
            raise InputError("no finite response to fit")
        self.X, self.y = X, y
        self._offset, self._scale = float(y.mean()), float(y.std())
        if np.ptp(y) <= 1e-12 * np.abs(y).max():
            self._constant, self.kernel, self.noise_sd = self._offset, None, 0.0
            return self
        self._constant = None
        z = (y - self._offset) / self._scale
        d = X.shape[1]
        kernel = ConstantKernel(1.0, self.AMPLITUDE_BOUNDS) * Matern(
            length_scale=np.full(d, 0.3), length_scale_bounds=self.LENGTH_SCALE_BOUNDS, nu=2.5
        ) + WhiteKernel(1e-2, self.NOISE_BOUNDS)
        gp = GaussianProcessRegressor(kernel, n_restarts_optimizer=self.restarts, random_state=self.seed)
        with warnings.catch_warnings():
            # a length scale at its upper bound is an answer (y does not depend on that parameter), not a failure
            warnings.simplefilter("ignore", ConvergenceWarning)
            gp.fit(X, z)
        self.kernel = gp.kernel_
        noise = float(self.kernel.k2.noise_level)
        self.noise_sd = self._scale * math.sqrt(noise)
        # the same posterior mean, with the white noise moved from the kernel into alpha (the training
        # diagonal only): predict()'s SD is then that of the latent mean, and refits keep the hyperparameters
        self._unfitted = GaussianProcessRegressor(self.kernel.k1, alpha=noise, optimizer=None)
        self._gp = GaussianProcessRegressor(self.kernel.k1, alpha=noise, optimizer=None).fit(X, z)
        # what predict() needs, kept as plain arrays: the sampler calls it some 10^5 times, and sklearn's
        # predict spends most of each call validating its input (27 of a GPU diagnosis's 36 s of statistics)
        self._amplitude = float(self.kernel.k1.k1.constant_value)
        self._length = np.broadcast_to(np.asarray(self.kernel.k1.k2.length_scale, dtype=float), (d,)).copy()
        self._alpha, self._chol = self._gp.alpha_, self._gp.L_
        return self

    def predict(self, X) -> tuple[np.ndarray, np.ndarray]:
        """Mean (m,) and SD of the latent mean (m,) at points ``X`` (m, d) of the unit cube, in y units."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        if self._constant is not None:
            return np.full(X.shape[0], self._constant), np.zeros(X.shape[0])
        if self._gp is None:
            raise RuntimeError("fit the surrogate first")
        from scipy.linalg import solve_triangular
        from scipy.spatial.distance import cdist

        # sklearn's GaussianProcessRegressor.predict(X, return_std=True) for amplitude * Matern(nu=2.5), written
        # out: k = a (1 + s + s^2 / 3) exp(-s) with s = sqrt(5) |(x - x') / length|
        s = math.sqrt(5.0) * cdist(X / self._length, self.X / self._length)
        k = self._amplitude * (1.0 + s + s * s / 3.0) * np.exp(-s)
        mean = k @ self._alpha
        v = solve_triangular(self._chol, k.T, lower=True, check_finite=False)
        var = np.maximum(self._amplitude - np.einsum("ij,ij->j", v, v), 0.0)
        return self._offset + self._scale * mean, self._scale * np.sqrt(var)

    def cv(self) -> dict:
        """Cross-validated accuracy: leave one design point out (all its replicates together) up to
        ``LOO_MAX`` distinct points, seeded ``KFOLD``-fold above, refitting with the hyperparameters fixed.

        Returns ``rmse`` (root mean square of y - prediction over all rows, in y units, so >= noise_sd for
        noisy y), ``q2`` = 1 - PRESS / sum (y - mean y)^2, ``rmse_range`` = rmse / (max y - min y), ``folds``.
        A constant response is predicted exactly: rmse 0, q2 1, rmse_range 0.
        """
        from sklearn.model_selection import PredefinedSplit, cross_val_predict

        if self._constant is not None:
            return {"rmse": 0.0, "q2": 1.0, "rmse_range": 0.0, "folds": 0}
        if self._gp is None:
            raise RuntimeError("fit the surrogate first")
        _, group = np.unique(self.X, axis=0, return_inverse=True)
        group = group.ravel()
        g = int(group.max()) + 1
        if g < 2:
            return {"rmse": math.nan, "q2": math.nan, "rmse_range": math.nan, "folds": 0}
        if g <= LOO_MAX:
            fold, folds = group, g
        else:
            fold, folds = np.random.default_rng(self.seed).permutation(g)[group] % KFOLD, KFOLD
        z = (self.y - self._offset) / self._scale
        pred = self._offset + self._scale * cross_val_predict(self._unfitted, self.X, z, cv=PredefinedSplit(fold))
        press = float(np.sum((self.y - pred) ** 2))
        rmse = math.sqrt(press / self.y.size)
        return {
            "rmse": rmse,
            "q2": 1.0 - press / float(np.sum((self.y - self.y.mean()) ** 2)),
            "rmse_range": rmse / float(np.ptp(self.y)),
            "folds": folds,
        }


# --------------------------------------------------------------------------------------------
# Calibration
# --------------------------------------------------------------------------------------------

TAU_SPAN = 50
"""Autocorrelation times the kept half of a chain must span (emcee's documentation advises about 50)."""

MAX_STEPS_FACTOR = 8
"""A chain is doubled at most until it is this many times the steps asked for."""


def calibrate(
    predict: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    measured,
    variance,
    d: int,
    seed: int = 0,
    steps: int = 2000,
    walkers: int | None = None,
    x0=None,
    n_starts: int = 10,
) -> dict:
    """Posterior of the unit-cube parameters u (d,) given n measured values.

    ``predict(U)`` takes U (m, d) and returns the predicted mean (m, n) of every measured value and its
    surrogate variance (m, n). The likelihood is Gaussian and independent with total variance ``variance``
    (n,) (the noise budget of the measured means) + the surrogate variance; the prior is flat on [0, 1]^d.

    The MAP is the best of L-BFGS-B runs from ``n_starts`` seeded space-filling points and ``x0`` (d,) if
    given (e.g. the best design point). Posterior samples: emcee's stretch move with ``walkers`` (default
    max(4d, 16)) started in a small ball round the MAP, ``steps`` steps, the first half discarded as burn-in,
    thinned by half the largest autocorrelation time.

    With ``steps`` = 0 only ``map``, ``loglik`` and ``at_bound`` are returned (no sampling). The chain is
    doubled until its kept half spans :data:`TAU_SPAN` autocorrelation times of the slowest
    parameter, or reaches :data:`MAX_STEPS_FACTOR` x ``steps``.

    Returns ``map`` (d,), ``loglik`` at the MAP, ``samples`` (k, d), ``interval`` (d, 2), ``at_bound`` (d,)
    -1/0/+1, ``acceptance`` (mean acceptance fraction), ``tau`` (d,) autocorrelation times, ``thin``, ``steps``
    (per walker, all), ``effective_samples`` (walkers x kept steps / the largest tau).
    The interval is the 2.5-97.5 percentile range, except where the MAP lies on a face of the cube (a
    candidate at its off value): there the equal-tailed interval would exclude the most probable value, so
    it is one-sided, from the face to the 95th (or from the 5th) percentile.
    """
    import emcee
    from scipy.optimize import minimize

    y = _vector("measured", measured)
    v = _variance("variance", variance, y.size)

    def loglik(U: np.ndarray) -> np.ndarray:
        mean, var = predict(U)
        mean = np.asarray(mean, dtype=float).reshape(U.shape[0], y.size)
        total = v + np.asarray(var, dtype=float).reshape(U.shape[0], y.size)
        ll = -0.5 * np.sum(np.log(2 * np.pi * total) + (y - mean) ** 2 / total, axis=1)
        return np.where(np.isfinite(ll), ll, -np.inf)

    def logpost(U: np.ndarray) -> np.ndarray:
        U = np.atleast_2d(U)
        inside = np.all((U >= 0) & (U <= 1), axis=1)
        out = np.full(U.shape[0], -np.inf)
        if inside.any():
            out[inside] = loglik(U[inside])
        return out

    starts = space_filling(n_starts, d, seed)
    if x0 is not None:
        starts = np.vstack([starts, np.clip(_vector("x0", x0, d), 0, 1)])
    best = None
    for u in starts:
        res = minimize(lambda u: -loglik(u[None])[0], u, method="L-BFGS-B", bounds=[(0.0, 1.0)] * d)
        if np.isfinite(res.fun) and (best is None or res.fun < best.fun):
            best = res
    if best is None:
        raise InputError("the log-likelihood is not finite at any start")
    u_map = np.clip(best.x, 0.0, 1.0)
    at_bound = np.where(u_map <= EDGE, -1, np.where(u_map >= 1 - EDGE, 1, 0))
    if steps == 0:
        return {"map": u_map, "loglik": float(-best.fun), "at_bound": at_bound}

    nwalkers = walkers or max(4 * d, 16)
    nwalkers += nwalkers % 2  # the stretch move updates two equal halves of the ensemble
    if nwalkers < 2 * d:
        raise InputError(f"emcee needs at least 2d = {2 * d} walkers, got {nwalkers}")
    rng = np.random.default_rng(seed)
    # reflected into the cube: a MAP on a face must not pin every walker to it (the ensemble would never leave)
    p0 = np.abs(u_map + 1e-3 * rng.standard_normal((nwalkers, d)))
    p0 = 1.0 - np.abs(1.0 - p0)
    state = emcee.State(p0, random_state=np.random.RandomState(int(rng.integers(2**32))).get_state())
    sampler = emcee.EnsembleSampler(nwalkers, d, logpost, vectorize=True)
    sampler.run_mcmc(state, steps, progress=False)
    total = steps
    while True:
        burn = total // 2
        tau = sampler.get_autocorr_time(discard=burn, tol=0, quiet=True)
        tau_max = float(np.nanmax(tau)) if np.any(np.isfinite(tau)) else math.inf
        # an interval's ends are tail percentiles: with fewer than TAU_SPAN autocorrelation times kept (emcee's
        # advice) they move by much of their width from one seed or machine to the next; double the chain
        if total - burn >= TAU_SPAN * tau_max or total >= MAX_STEPS_FACTOR * steps:
            break
        sampler.run_mcmc(None, total, progress=False)
        total *= 2
    thin = max(1, int(tau_max / 2)) if math.isfinite(tau_max) else 1
    samples = sampler.get_chain(discard=burn, thin=thin, flat=True)

    interval = np.percentile(samples, [2.5, 97.5], axis=0).T
    for j in np.flatnonzero(at_bound):
        interval[j] = (
            (0.0, np.percentile(samples[:, j], 95)) if at_bound[j] < 0 else (np.percentile(samples[:, j], 5), 1.0)
        )
    return {
        "map": u_map,
        "loglik": float(-best.fun),
        "samples": samples,
        "interval": interval,
        "at_bound": at_bound,
        "acceptance": float(np.mean(sampler.acceptance_fraction)),
        "tau": tau,
        "thin": thin,
        "steps": total,
        "effective_samples": float(nwalkers * (total - burn) / tau_max) if math.isfinite(tau_max) else math.nan,
    }


# --------------------------------------------------------------------------------------------
# Adequacy
# --------------------------------------------------------------------------------------------


def holm(pvalues) -> np.ndarray:
    """Holm-adjusted p-values (statsmodels ``multipletests``) of a 1-D family; NaN entries stay NaN and are
    not counted in the family."""
    from statsmodels.stats.multitest import multipletests

    p = _vector("pvalues", pvalues)
    out = np.full(p.shape, np.nan)
    ok = np.isfinite(p)
    if ok.any():
        out[ok] = multipletests(p[ok], method="holm")[1]
    return out


def scatter_excess(sim_var: float, sim_df: int, meas_var: float, meas_df: float) -> tuple[float, float]:
    """One-sided test that a model's runs at one parameter point scatter more than the measurement repeats:
    (F, p) with F = sim_var / meas_var.

    Args:
        sim_var: pooled variance of the simulated response over world seeds [unit^2], >= 0.
        sim_df: its degrees of freedom, >= 1.
        meas_var: the variance of one measurement [unit^2], > 0: the replicates' pooled variance, or a stated SD
            squared.
        meas_df: its degrees of freedom, >= 1; ``math.inf`` for a stated SD, taken as known.

    Both sample variances of normal scatter: F on (sim_df, meas_df) degrees of freedom. A known measurement
    variance: sim_df * F is chi-square on sim_df. A mean alone cannot show a model whose piles scatter far more
    than the material's, since the noise budget takes the larger of the two scatters (``Problem.budget``); this
    test can.
    """
    from scipy import stats

    if not (sim_df >= 1 and meas_df >= 1):
        raise InputError(f"scatter_excess: degrees of freedom ({sim_df}, {meas_df}) are not allowed; expected >= 1")
    if not (np.isfinite(sim_var) and sim_var >= 0 and np.isfinite(meas_var) and meas_var > 0):
        raise InputError(
            f"scatter_excess: variances ({sim_var}, {meas_var}) are not allowed; expected finite, the second > 0"
        )
    f = float(sim_var / meas_var)
    if math.isinf(meas_df):
        return f, float(stats.chi2.sf(sim_df * f, sim_df))
    return f, float(stats.f.sf(f, sim_df, meas_df))


def adequacy(
    residual,
    variance,
    n_params: int,
    conditions: pd.DataFrame,
    responses: Sequence,
    alpha: float = 0.05,
) -> dict:
    """Is the calibrated model adequate? Tests of the standardised residuals z = residual / sqrt(variance).

    Each of the n rows is one (experiment, response): ``residual`` (n,) measured mean - simulated mean,
    ``variance`` (n,) its noise-budget variance, ``conditions`` (n rows) the experiment's conditions, its
    index naming the experiment, ``responses`` (n,) the response labels. ``n_params`` parameters were
    calibrated on these rows.

    Tests (one family, Holm-adjusted together; ``adequate`` when no adjusted p is below ``alpha``):

    * ``chi2``: per response, sum z^2 against chi-square with df = max(n_r - n_params n_r / n, 1) (the
      parameters are shared by all responses, so each response is charged its share);
    * ``point``: per row, two-sided normal test of z;
    * ``trend``: per response and numeric condition column with >= 3 distinct values among its rows, the
      slope of the weighted least-squares line residual ~ 1 + condition (statsmodels WLS, weights
      1 / variance), tested against the larger of two scales: the noise budget's (a z-test, the scale fixed
      at 1) and the scatter about the line (a t-test), so that an understated budget (the chi-square's
      business) does not masquerade as a trend, and three residuals that happen to lie on a line, well
      inside the budget, do not either (with one degree of freedom the scatter can be near zero: a press's
      residuals of -0.57, -0.52 and -0.41 SD gave t = 102).

    Returns ``z`` (DataFrame: experiment, response, the conditions, residual, variance, z), ``tests``
    (DataFrame: kind, response, experiment, condition, statistic (chi-square, z or t), df, p, p_holm,
    significant, slope, ci_low, ci_high (95 %)) and ``adequate``.
    """
    import pandas as pd
    import statsmodels.api as sm
    from scipy import stats

    r = _vector("residual", residual)
    n = r.size
    v = _variance("variance", variance, n)
    if not np.all(np.isfinite(r)):
        raise InputError("residual must be finite")
    conditions = pd.DataFrame(conditions)
    if len(conditions) != n:
        raise InputError(f"conditions has {len(conditions)} rows, expected {n}")
    responses = np.asarray(responses, dtype=object)
    if responses.shape != (n,):
        raise InputError(f"responses must have {n} labels")
    z = r / np.sqrt(v)
    experiments = list(conditions.index)

    table = conditions.reset_index(drop=True)
    table.insert(0, "response", responses)
    table.insert(0, "experiment", experiments)
    table = table.assign(residual=r, variance=v, z=z)

    rows = []
    blank = {"experiment": None, "condition": None, "slope": np.nan, "ci_low": np.nan, "ci_high": np.nan}
    for resp in pd.unique(responses):
        m = responses == resp
        df = max(m.sum() - n_params * m.sum() / n, 1.0)
        stat = float(np.sum(z[m] ** 2))
        rows.append(
            {**blank, "kind": "chi2", "response": resp, "statistic": stat, "df": df, "p": stats.chi2.sf(stat, df)}
        )
    numeric = [c for c in conditions.columns if pd.api.types.is_numeric_dtype(conditions[c])]
    for resp in pd.unique(responses):
        m = responses == resp
        for col in numeric:
            x = conditions[col].to_numpy(dtype=float)[m]
            if np.unique(x).size < 3:
                continue
            model = sm.WLS(r[m], np.column_stack([np.ones(x.size), x]), weights=1.0 / v[m])
            fit = model.fit()
            if fit.scale < 1.0:
                fit = model.fit(cov_type="fixed scale", cov_kwds={"scale": 1.0})
            lo, hi = fit.conf_int(0.05)[1]
            rows.append(
                {
                    **blank,
                    "kind": "trend",
                    "response": resp,
                    "condition": col,
                    "statistic": float(fit.tvalues[1]),
                    "df": float(fit.df_resid),
                    "p": float(fit.pvalues[1]),
                    "slope": float(fit.params[1]),
                    "ci_low": float(lo),
                    "ci_high": float(hi),
                }
            )
    for i in range(n):
        p = 2.0 * stats.norm.sf(abs(z[i]))
        rows.append(
            {
                **blank,
                "kind": "point",
                "response": responses[i],
                "experiment": experiments[i],
                "statistic": z[i],
                "df": np.nan,
                "p": p,
            }
        )

    columns = ["kind", "response", "experiment", "condition", "statistic", "df", "p", "p_holm", "significant"]
    tests = pd.DataFrame(rows)
    tests["p_holm"] = holm(tests["p"].to_numpy(dtype=float))
    tests["significant"] = tests["p_holm"] < alpha
    tests = tests[columns + ["slope", "ci_low", "ci_high"]]
    return {"z": table, "tests": tests, "adequate": not bool(tests["significant"].any())}


# --------------------------------------------------------------------------------------------
# Model comparison
# --------------------------------------------------------------------------------------------


def lrt_boundary(loglik_base: float, loglik_ext: float, df: int = 1) -> tuple[float, float]:
    """Likelihood-ratio test of an extension with ``df`` extra parameters, one of whose null (off) value lies
    on the boundary of its range (Self & Liang 1987): LR = 2 (loglik_ext - loglik_base) is then a 50:50
    mixture of chi2_(df-1) and chi2_df (chi2_0 = a point mass at 0), so for df = 1 p = P(chi2_1 > LR) / 2.
    Returns (LR, p); p = 1 when LR <= 0 (the extension fits no better)."""
    from scipy import stats

    if df < 1:
        raise InputError("df must be >= 1")
    lr = 2.0 * (float(loglik_ext) - float(loglik_base))
    if not lr > 0:
        return lr, 1.0
    below = stats.chi2.sf(lr, df - 1) if df > 1 else 0.0
    return lr, float(0.5 * stats.chi2.sf(lr, df) + 0.5 * below)


def aic(loglik: float, k: int) -> float:
    """Akaike information criterion 2k - 2 loglik of a model with k free parameters."""
    return 2.0 * k - 2.0 * float(loglik)


def bic(loglik: float, k: int, n: int) -> float:
    """Bayesian information criterion k ln(n) - 2 loglik of a model with k parameters fitted to n values."""
    return k * math.log(n) - 2.0 * float(loglik)


def screen(residual, variance, jacobian, effect) -> dict:
    """Can a candidate explain the residual, with theta re-tuned? A linearised check before any simulation
    of the extended model.

    ``residual`` (n,) measured - predicted by the base model, ``variance`` (n,), ``jacobian`` (n, d) the base
    model's sensitivities to theta (so that re-tuning theta can absorb what it can), ``effect`` (n,) the
    change of each prediction when the candidate moves from off to a test value with theta held. Weighted
    least squares (weights 1 / variance) of the residual on [jacobian] and on [jacobian, effect], the
    effect's coefficient constrained >= 0 since the candidate moves one way from off (scipy ``lsq_linear``).

    Returns ``delta_chi2`` (drop of sum (residual - fit)^2 / variance from adding the effect), ``coefficient``
    (the effect's: 1 = the test value explains it, to first order), ``p`` (of delta_chi2 under the boundary
    mixture, as :func:`lrt_boundary`), ``chi2_base``, ``chi2_ext`` and ``theta_shift`` (d,) in the extended fit.
    """
    from scipy.optimize import lsq_linear

    r = _vector("residual", residual)
    n = r.size
    w = 1.0 / np.sqrt(_variance("variance", variance, n))
    J = np.asarray(jacobian, dtype=float).reshape(n, -1)
    e = _vector("effect", effect, n)
    rw, Jw, ew = r * w, J * w[:, None], e * w
    d = J.shape[1]
    base = rw - Jw @ np.linalg.lstsq(Jw, rw, rcond=None)[0] if d else rw
    chi2_base = float(base @ base)
    A = np.column_stack([Jw, ew])
    lower = np.r_[np.full(d, -np.inf), 0.0]
    sol = lsq_linear(A, rw, bounds=(lower, np.full(d + 1, np.inf)), method="bvls")
    ext = rw - A @ sol.x
    chi2_ext = float(ext @ ext)
    delta = chi2_base - chi2_ext
    # at a zero coefficient the two fits are the same problem: their difference is the solvers' rounding,
    # and must not become p = 0.5 (the boundary mixture jumps from 1 to 1/2 at any positive delta)
    if delta <= 1e-9 * max(chi2_base, 1.0):
        delta = 0.0
    _, p = lrt_boundary(0.0, 0.5 * delta)
    return {
        "delta_chi2": delta,
        "coefficient": float(sol.x[-1]),
        "p": p,
        "chi2_base": chi2_base,
        "chi2_ext": chi2_ext,
        "theta_shift": sol.x[:d],
    }


def gaussian_nll(residual, variance) -> np.ndarray:
    """Negative log-likelihood of each residual under N(0, variance), elementwise:
    0.5 log(2 pi variance) + 0.5 residual^2 / variance."""
    r = np.asarray(residual, dtype=float)
    v = np.asarray(variance, dtype=float)
    return 0.5 * np.log(2 * np.pi * v) + 0.5 * r**2 / v


def experiment_losses(residual, variance, experiments: Sequence) -> pd.DataFrame:
    """Held-out losses per experiment from residuals (n,) and predictive variances (n,) of the rows
    (experiment, response), ``experiments`` (n,) labelling each row's experiment: a DataFrame indexed by
    experiment (in first-seen order) with ``z2`` the mean squared standardised error (about 1 for a model
    whose variance is right) and ``nll`` the mean :func:`gaussian_nll` over the experiment's rows."""
    import pandas as pd

    r = _vector("residual", residual)
    v = _variance("variance", variance, r.size)
    frame = pd.DataFrame({"experiment": list(experiments), "z2": r**2 / v, "nll": gaussian_nll(r, v)})
    return frame.groupby("experiment", sort=False)[["z2", "nll"]].mean()


def bootstrap(losses: Mapping[str, np.ndarray], seed: int = 0, n_boot: int = 2000, level: float = 0.95) -> dict:
    """Paired bootstrap over experiments of the mean held-out loss of several models.

    ``losses`` maps a model name to its loss per experiment (n,), the experiments in the same order for
    every model (e.g. one column of :func:`experiment_losses`). Experiments are resampled with replacement,
    the same resamples for every model, so that differences between models are paired.

    Returns ``models`` (DataFrame: model, mean, low, high: the mean loss and its ``level`` percentile
    interval) and ``pairs`` (DataFrame: model_a, model_b, difference = mean a - mean b, low, high).
    """
    import pandas as pd

    names = list(losses)
    if not names:
        raise InputError("no models")
    L = [_vector(f"losses[{k!r}]", losses[k]) for k in names]
    n = L[0].size
    if n == 0 or any(a.size != n for a in L) or not all(np.all(np.isfinite(a)) for a in L):
        raise InputError("every model needs the same number (>= 1) of finite losses")
    index = np.random.default_rng(seed).integers(0, n, size=(n_boot, n))
    boot = np.array([a[index].mean(axis=1) for a in L])  # (models, n_boot)
    q = 50.0 * (1.0 - level), 50.0 * (1.0 + level)
    models = pd.DataFrame(
        [
            {"model": k, "mean": float(a.mean()), **dict(zip(("low", "high"), np.percentile(b, q)))}
            for k, a, b in zip(names, L, boot)
        ]
    )
    pairs = []
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            low, high = np.percentile(boot[i] - boot[j], q)
            pairs.append(
                {
                    "model_a": names[i],
                    "model_b": names[j],
                    "difference": float(L[i].mean() - L[j].mean()),
                    "low": float(low),
                    "high": float(high),
                }
            )
    columns = ["model_a", "model_b", "difference", "low", "high"]
    return {"models": models, "pairs": pd.DataFrame(pairs, columns=columns)}
