"""The statistics of a diagnosis: designs, surrogates, calibration, adequacy, model comparison.

A diagnosis calibrates the free parameters theta (d of them) of a DEM model to measured experiments, tests
whether the calibrated model is adequate, tries candidate extensions (one extra parameter each, whose "off"
value reduces it to the base model and usually lies at the edge of its range) and measures the gain on
held-out data. Everything here works in the unit cube [0, 1]^d of the parameters (the caller maps to physical
units) and on plain arrays; nothing here runs a simulation.

``space_filling``  a seeded, optimised Latin hypercube: where to simulate.
``Surrogate``      one Gaussian process per (condition, response) over the unit cube, with its noise
                   (world-seed scatter) and a cross-validated accuracy.

Every random choice takes a seed, so a diagnosis repeats exactly.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

__all__ = [
    "Surrogate",
    "space_filling",
]

LOO_MAX = 30
"""Surrogate cross-validation leaves one design point out up to this many points, and is K-fold above."""

KFOLD = 10
"""Folds of the surrogate cross-validation above ``LOO_MAX`` design points."""


def _vector(name: str, a, n: int | None = None) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.ndim != 1:
        raise ValueError(f"{name} must be one-dimensional, got shape {a.shape}")
    if n is not None and a.shape[0] != n:
        raise ValueError(f"{name} has {a.shape[0]} values, expected {n}")
    return a


# --------------------------------------------------------------------------------------------
# Design and surrogate
# --------------------------------------------------------------------------------------------


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
            raise ValueError(f"X must be (n, d), got shape {X.shape}")
        y = _vector("y", y, X.shape[0])
        if not np.all(np.isfinite(X)) or X.min(initial=0.0) < -1e-9 or X.max(initial=1.0) > 1 + 1e-9:
            raise ValueError("X must lie in the unit cube [0, 1]^d")
        keep = np.isfinite(y)
        X, y = X[keep], y[keep]
        if y.size == 0:
            raise ValueError("no finite response to fit")
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
        return self

    def predict(self, X) -> tuple[np.ndarray, np.ndarray]:
        """Mean (m,) and SD of the latent mean (m,) at points ``X`` (m, d) of the unit cube, in y units."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        if self._constant is not None:
            return np.full(X.shape[0], self._constant), np.zeros(X.shape[0])
        if self._gp is None:
            raise RuntimeError("fit the surrogate first")
        mean, sd = self._gp.predict(X, return_std=True)
        return self._offset + self._scale * mean, self._scale * sd

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
