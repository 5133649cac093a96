"""Response-surface statistics in the Design-Expert style, on statsmodels OLS.

The model is fitted in coded units (factor columns of the data frame, -1..+1 for the design's
range). A model is a list of *terms*; a term is a tuple of factor names with repetition for powers:
``("A",)`` is A, ``("A", "B")`` is AB, ``("A", "A")`` is A^2. Strings are accepted wherever a term
is: ``"A"``, ``"AB"``, ``"A*B"``, ``"A:B"``, ``"A^2"``, ``"A2"``, ``"X1X2"``, ``"X1^2"``.

What :func:`fit_model` reports, and how (Design-Expert conventions, see
``shared/anchors/verification-ecosystem.md`` section 3(c)):

* ANOVA rows ``Model``, one per term, ``Residual``, ``Lack of Fit``, ``Pure Error``,
  ``Cor Total`` with sum of squares, df, mean square, F and p. Term sums of squares are Type III
  (partial: the increase in residual SS when the term alone is dropped), which equals Type II for
  the orthogonal designs of the seeds. Pure error is pooled over all replicated settings,
  df = sum(n_i - 1); lack of fit is Residual - Pure Error, F = MS_LOF / MS_PE.
* Fit statistics: std dev = sqrt(MS_res), mean, C.V.% = 100 sd / mean, R^2, adjusted R^2,
  PRESS = sum((e_i / (1 - h_ii))^2), predicted R^2 = 1 - PRESS / SS_total (no blocks and no
  separate curvature term here, so nothing is subtracted from SS_total), adequate precision =
  (max yhat - min yhat) / sqrt(p MS_res / n) with p the number of model parameters (intercept
  included) and yhat at the design points.
* The regression equation in coded units and, given the factors' levels, in actual units
  (the coded polynomial expanded exactly, x = (X - centre) / half_range).

Also: hierarchical backward elimination (:func:`backward_eliminate`), effects and standardized
effects of two-level designs with Lenth's pseudo standard error for saturated designs
(:func:`effects_table`, the data of a Pareto chart), and the set of factor settings whose
prediction hits a target (:func:`solve_target`).
"""

from __future__ import annotations

import itertools
import math
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import statsmodels.api as sm
from scipy import optimize, stats

from warpdem.errors import InputError

from .designs import Factor
from .goals import GOALS, Goal
from .transforms import NONE, Transform

__all__ = [
    "GOALS",
    "Goal",
    "ModelFit",
    "TargetSolution",
    "alias_lines",
    "alias_matrix",
    "backward_eliminate",
    "box_cox",
    "confirmation_interval",
    "desirability",
    "effects_table",
    "fit_model",
    "fit_summary",
    "influence",
    "lenth_pse",
    "mean_prediction_interval",
    "model_terms",
    "optimize_desirability",
    "outlier_limit",
    "parse_term",
    "pure_error",
    "response_range",
    "solve_target",
    "term_label",
]

Term = tuple[str, ...]

_SUPERSCRIPT = {"²": 2, "³": 3}


# --------------------------------------------------------------------------------------------
# Terms
# --------------------------------------------------------------------------------------------


def _canonical(term: Iterable[str], factors: Sequence[str]) -> Term:
    term = tuple(term)
    bad = [t for t in term if t not in factors]
    if bad:
        raise InputError(f"term {term} names unknown factor(s) {bad}; factors are {list(factors)}")
    if not term:
        raise InputError("empty term (the intercept is always in the model)")
    return tuple(sorted(term, key=list(factors).index))


def parse_term(spec: str | Sequence[str], factors: Sequence[str]) -> Term:
    """Turn a term given as a string or a tuple into the canonical tuple of factor names."""
    factors = list(factors)
    if not isinstance(spec, str):
        return _canonical(spec, factors)
    s = spec.strip().replace(" ", "")
    if s in factors:
        return (s,)
    single = all(len(f) == 1 for f in factors)
    out: list[str] = []
    for part in (p for p in s.replace(":", "*").split("*") if p):
        i = 0
        while i < len(part):
            name = max((f for f in factors if part.startswith(f, i)), key=len, default=None)
            if name is None:
                raise InputError(f"cannot parse term {spec!r} with factors {factors}")
            i += len(name)
            power = 1
            if i < len(part) and part[i] == "^":
                j = i + 1
                while j < len(part) and part[j].isdigit():
                    j += 1
                power, i = int(part[i + 1 : j]), j
            elif i < len(part) and part[i] in _SUPERSCRIPT:
                power, i = _SUPERSCRIPT[part[i]], i + 1
            elif single and i < len(part) and part[i].isdigit():
                power, i = int(part[i]), i + 1
            out += [name] * power
    return _canonical(out, factors)


def term_label(term: Term, factors: Sequence[str] | None = None) -> str:
    """Design-Expert style label: ``A``, ``AB``, ``A^2``; ``X1*X2``, ``X1^2`` for longer names."""
    names = list(dict.fromkeys(term))
    counts = Counter(term)
    single = all(len(n) == 1 for n in (factors if factors is not None else names))
    parts = [n + (f"^{counts[n]}" if counts[n] > 1 else "") for n in names]
    return "".join(parts) if single else "*".join(parts)


def model_terms(model: str | Sequence, factors: Sequence[str]) -> list[Term]:
    """Terms of a named model (``"linear"``, ``"2fi"``, ``"quadratic"``) or of a list of terms.

    Named models list terms in Design-Expert order: main effects, two-factor interactions,
    pure quadratics.
    """
    factors = list(factors)
    if isinstance(model, str):
        m = model.lower()
        if m not in ("linear", "2fi", "quadratic"):
            raise InputError(f"model must be 'linear', '2fi', 'quadratic' or a list of terms, got {model!r}")
        terms: list[Term] = [(f,) for f in factors]
        if m in ("2fi", "quadratic"):
            terms += list(itertools.combinations(factors, 2))
        if m == "quadratic":
            terms += [(f, f) for f in factors]
        return terms
    terms = [parse_term(t, factors) for t in model]
    if len(set(terms)) != len(terms):
        raise InputError(f"a term is repeated in {model}")
    return terms


def _contains(big: Term, small: Term) -> bool:
    """True when ``small`` is a proper sub-term of ``big`` (e.g. A in AB, A in A^2)."""
    if big == small:
        return False
    cb, cs = Counter(big), Counter(small)
    return all(cb[k] >= v for k, v in cs.items())


def _columns(x: np.ndarray, terms: Sequence[Term], factors: Sequence[str]) -> np.ndarray:
    idx = {f: i for i, f in enumerate(factors)}
    x = np.atleast_2d(np.asarray(x, dtype=float))
    cols = [np.ones(len(x))]
    for t in terms:
        cols.append(np.prod([x[:, idx[f]] for f in t], axis=0))
    return np.column_stack(cols)


def _gradient(x: np.ndarray, beta: np.ndarray, terms: Sequence[Term], factors: Sequence[str]) -> np.ndarray:
    """d yhat / d x at one coded point x (length k)."""
    idx = {f: i for i, f in enumerate(factors)}
    g = np.zeros(len(factors))
    for b, t in zip(beta[1:], terms):
        cnt = Counter(t)
        for f, m in cnt.items():
            d = m * x[idx[f]] ** (m - 1)
            for h, mh in cnt.items():
                if h != f:
                    d *= x[idx[h]] ** mh
            g[idx[f]] += b * d
    return g


# --------------------------------------------------------------------------------------------
# The fit
# --------------------------------------------------------------------------------------------


@dataclass
class ModelFit:
    """A fitted polynomial model in coded units, with its Design-Expert ANOVA.

    Attributes:
        response: name of the response column.
        factors: factor names (columns of the coded data), in order.
        terms: model terms (without the intercept).
        data: the coded data used (factor columns and the response).
        coefficients: coded coefficients with std_err, t, p (index: ``Intercept`` and labels).
        anova: ANOVA table (index: Model, term labels, Residual, [Lack of Fit, Pure Error],
            Cor Total; columns sum_sq, df, mean_sq, F, p).
        stats: std_dev, mean, cv_pct, r2, adj_r2, pred_r2, press, adeq_precision, n, p.
        fitted, residuals, leverage: per-run arrays.
        levels: factor levels used for the actual-units equation, when given.
        elimination: log of :func:`backward_eliminate` (removed term, its p), else empty.
        ols: the statsmodels results object.
        transform: the response transform the model is fitted to (:mod:`.transforms`): the ANOVA, ``data``'s
            response column, fitted values, residuals and :meth:`predict` are on that scale; :meth:`to_response`
            brings values back to the response's units.
    """

    response: str
    factors: list[str]
    terms: list[Term]
    data: pd.DataFrame
    coefficients: pd.DataFrame
    anova: pd.DataFrame
    stats: dict
    fitted: np.ndarray
    residuals: np.ndarray
    leverage: np.ndarray
    levels: dict[str, Factor] | None = None
    elimination: list[dict] = field(default_factory=list)
    ols: object = None
    transform: Transform = NONE

    @property
    def labels(self) -> list[str]:
        return [term_label(t, self.factors) for t in self.terms]

    def coef(self, term: str | Term = "Intercept") -> float:
        """Coded coefficient of one term (or of the intercept)."""
        if term == "Intercept":
            return float(self.coefficients.loc["Intercept", "coef"])
        t = parse_term(term, self.factors)
        return float(self.coefficients.loc[term_label(t, self.factors), "coef"])

    def _x(self, x) -> np.ndarray:
        if isinstance(x, pd.DataFrame):
            return x[self.factors].to_numpy(dtype=float)
        if isinstance(x, Mapping):
            return np.array([[float(x[f]) for f in self.factors]])
        return np.atleast_2d(np.asarray(x, dtype=float))

    def to_response(self, values) -> np.ndarray:
        """Model-scale ``values`` (of :meth:`predict`) in the response's own units (the transform's inverse)."""
        return np.asarray(self.transform.inverse(values), dtype=float)

    def predict_response(self, x) -> np.ndarray:
        """Prediction at coded points in the response's own units (:meth:`predict`, back-transformed)."""
        return self.to_response(self.predict(x))

    def predict(self, x) -> np.ndarray:
        """Prediction at coded points (DataFrame with factor columns, mapping, or array n x k), on the model's
        scale (the transformed response; see :meth:`predict_response`)."""
        beta = self.coefficients["coef"].to_numpy()
        return _columns(self._x(x), self.terms, self.factors) @ beta

    def predict_actual(self, x) -> np.ndarray:
        """Prediction at points given in actual units (needs ``levels``)."""
        lv = self._levels()
        xa = self._x(x)
        xc = np.column_stack([lv[f].to_coded(xa[:, i]) for i, f in enumerate(self.factors)])
        return self.predict(xc)

    def _levels(self) -> dict[str, Factor]:
        if not self.levels:
            raise InputError("this fit has no factor levels: pass levels=... to fit_model")
        missing = [f for f in self.factors if f not in self.levels]
        if missing:
            raise InputError(f"no levels for factor(s) {missing}")
        return self.levels

    def equation(self, units: str = "coded") -> dict[Term, float]:
        """Polynomial coefficients keyed by monomial (``()`` is the constant).

        ``units="actual"`` expands the coded model with x = (X - centre) / half_range; the result
        is the model a fit in actual units would give (the same least-squares polynomial).
        """
        beta = self.coefficients["coef"].to_numpy()
        if units == "coded":
            out = {(): float(beta[0])}
            out.update({t: float(b) for t, b in zip(self.terms, beta[1:])})
            return out
        if units != "actual":
            raise InputError("units must be 'coded' or 'actual'")
        lv = self._levels()
        poly: dict[Term, float] = {(): float(beta[0])}
        for t, b in zip(self.terms, beta[1:]):
            # each factor occurrence contributes X/h (pick it) or -c/h (constant)
            choices = [((f,), 1.0 / lv[f].half_range, -lv[f].centre / lv[f].half_range) for f in t]
            for pick in itertools.product((True, False), repeat=len(t)):
                mono: list[str] = []
                c = float(b)
                for (name, inv_h, const), p in zip(choices, pick):
                    if p:
                        mono += list(name)
                        c *= inv_h
                    else:
                        c *= const
                key = _canonical(mono, self.factors) if mono else ()
                poly[key] = poly.get(key, 0.0) + c
        return poly

    def equation_string(self, units: str = "coded", digits: int = 4) -> str:
        """The regression equation as text, e.g. ``aor = 28.34 + 1.295*C - 0.986*C^2``."""
        eq = self.equation(units)
        parts = [f"{eq[()]:.{digits}g}"]
        for mono, c in eq.items():
            if mono == ():
                continue
            cnt = Counter(mono)
            name = "*".join(n + (f"^{cnt[n]}" if cnt[n] > 1 else "") for n in dict.fromkeys(mono))
            parts.append(("- " if c < 0 else "+ ") + f"{abs(c):.{digits}g}*{name}")
        return f"{self.transform.label(self.response)} = " + " ".join(parts)

    def summary(self) -> str:
        """ANOVA table, fit statistics and the coded equation as plain text."""
        a = self.anova.copy()
        with pd.option_context("display.float_format", lambda v: f"{v:.6g}", "display.width", 120):
            lines = [f"Response {self.response}: model {', '.join(self.labels) or 'mean'}", a.to_string(), ""]
        s = self.stats
        lines += [
            f"Std. Dev. {s['std_dev']:.6g}   Mean {s['mean']:.6g}   C.V.% {s['cv_pct']:.4g}",
            f"R^2 {s['r2']:.4f}   Adj R^2 {s['adj_r2']:.4f}   Pred R^2 {s['pred_r2']:.4f}   "
            f"Adeq Precision {s['adeq_precision']:.3f}   PRESS {s['press']:.6g}",
            self.equation_string("coded"),
        ]
        if self.levels:
            lines.append(self.equation_string("actual"))
        return "\n".join(lines)


def _sse(X: np.ndarray, y: np.ndarray) -> float:
    beta = np.linalg.lstsq(X, y, rcond=None)[0]
    r = y - X @ beta
    return float(r @ r)


def pure_error(y, settings: Sequence) -> tuple[float, int]:
    """The pure-error sum of squares and its degrees of freedom: the squared deviations of each response in ``y``
    (n,) from the mean of those sharing its setting (``settings``: n hashable keys, e.g. rounded factor tuples),
    summed over the settings; n minus the number of distinct settings df."""
    groups = pd.Series(np.asarray(y, dtype=float)).groupby(pd.Series(list(settings), dtype=object).astype(str))
    return float(groups.apply(lambda g: ((g - g.mean()) ** 2).sum()).sum()), int((groups.size() - 1).sum())


def _f_p(ms: float, ms_err: float, df1: float, df2: float) -> tuple[float, float]:
    if not (df1 > 0 and df2 > 0 and ms_err > 0 and np.isfinite(ms_err)):
        return math.nan, math.nan
    f = ms / ms_err
    return f, float(stats.f.sf(f, df1, df2))


def fit_model(
    data: pd.DataFrame,
    response: str,
    factors: Sequence[str],
    model: str | Sequence = "quadratic",
    levels: Iterable[Factor] | Mapping[str, Factor] | None = None,
    transform: Transform | None = None,
) -> ModelFit:
    """Fit ``model`` to the coded ``data`` by OLS and build the Design-Expert ANOVA.

    Args:
        data: one row per run; the factor columns in coded units, and the response.
        response: name of the response column.
        factors: names of the factor columns.
        model: ``"linear"``, ``"2fi"``, ``"quadratic"`` or a list of terms.
        levels: :class:`~warpdem.study.designs.Factor` per factor, for the actual-units equation.
        transform: fit the model to this transform of the response (default none).
    """
    factors = list(factors)
    terms = model_terms(model, factors)
    transform = NONE if transform is None else transform
    df = data[factors + [response]].astype(float).reset_index(drop=True)
    if df.isna().any().any():
        raise InputError("data contains missing values")
    if transform != NONE:
        df[response] = transform.forward(df[response].to_numpy(), f"response {response!r}")
    y = df[response].to_numpy()
    xk = df[factors].to_numpy()
    X = _columns(xk, terms, factors)
    n, p = X.shape
    if np.linalg.matrix_rank(X) < p:
        raise InputError(
            "the model is not estimable from this design (aliased terms); "
            f"rank {np.linalg.matrix_rank(X)} < {p} parameters"
        )
    labels = [term_label(t, factors) for t in terms]
    res = sm.OLS(y, pd.DataFrame(X, columns=["Intercept"] + labels)).fit()
    fitted = np.asarray(res.fittedvalues)
    resid = y - fitted
    sse = float(resid @ resid)
    df_res = n - p
    ms_res = sse / df_res if df_res > 0 else math.nan
    sst = float(((y - y.mean()) ** 2).sum())

    rows = []
    ss_model = sst - sse
    f, pv = _f_p(ss_model / (p - 1) if p > 1 else math.nan, ms_res, p - 1, df_res)
    rows.append(("Model", ss_model, p - 1, ss_model / (p - 1) if p > 1 else math.nan, f, pv))
    for j, lab in enumerate(labels, start=1):
        ss = _sse(np.delete(X, j, axis=1), y) - sse
        ss = max(ss, 0.0)
        f, pv = _f_p(ss, ms_res, 1, df_res)
        rows.append((lab, ss, 1, ss, f, pv))
    rows.append(("Residual", sse, df_res, ms_res, math.nan, math.nan))
    ss_pe, df_pe = pure_error(y, [tuple(np.round(r, 9)) for r in xk])
    df_lof = df_res - df_pe
    if df_pe > 0 and df_lof > 0:
        ss_lof = sse - ss_pe
        ms_pe = ss_pe / df_pe
        f, pv = _f_p(ss_lof / df_lof, ms_pe, df_lof, df_pe)
        rows.append(("Lack of Fit", ss_lof, df_lof, ss_lof / df_lof, f, pv))
        rows.append(("Pure Error", ss_pe, df_pe, ms_pe, math.nan, math.nan))
    rows.append(("Cor Total", sst, n - 1, math.nan, math.nan, math.nan))
    anova = pd.DataFrame(rows, columns=["source", "sum_sq", "df", "mean_sq", "F", "p"]).set_index("source")
    anova["df"] = anova["df"].astype(int)

    # leverage and PRESS
    if df_res > 0:
        h = np.asarray(res.get_influence().hat_matrix_diag)
    else:
        h = np.ones(n)
    with np.errstate(divide="ignore", invalid="ignore"):
        press = float(np.sum((resid / (1.0 - h)) ** 2)) if np.all(h < 1 - 1e-10) else math.nan
    mean = float(y.mean())
    sd = math.sqrt(ms_res) if df_res > 0 else math.nan
    st = {
        "n": n,
        "p": p,
        "std_dev": sd,
        "mean": mean,
        "cv_pct": 100.0 * sd / mean if mean != 0 else math.nan,
        "r2": 1.0 - sse / sst if sst > 0 else math.nan,
        "adj_r2": 1.0 - ms_res / (sst / (n - 1)) if (sst > 0 and df_res > 0) else math.nan,
        "press": press,
        "pred_r2": 1.0 - press / sst if sst > 0 else math.nan,
        "adeq_precision": (fitted.max() - fitted.min()) / math.sqrt(p * ms_res / n)
        if df_res > 0 and ms_res > 0
        else math.nan,
    }
    se = np.asarray(res.bse) if df_res > 0 else np.full(p, math.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        tval = np.asarray(res.params) / se
    pcoef = 2 * stats.t.sf(np.abs(tval), df_res) if df_res > 0 else np.full(p, math.nan)
    coefs = pd.DataFrame(
        {"coef": np.asarray(res.params), "std_err": se, "t": tval, "p": pcoef},
        index=pd.Index(["Intercept"] + labels, name="term"),
    )
    lv = None
    if levels is not None:
        lv = dict(levels) if isinstance(levels, Mapping) else {f.name: f for f in levels}
    return ModelFit(response, factors, terms, df, coefs, anova, st, fitted, resid, h, lv, [], res, transform)


def backward_eliminate(
    data: pd.DataFrame,
    response: str,
    factors: Sequence[str],
    model: str | Sequence = "quadratic",
    alpha: float = 0.05,
    hierarchical: bool = True,
    levels: Iterable[Factor] | Mapping[str, Factor] | None = None,
    transform: Transform | None = None,
) -> ModelFit:
    """Backward elimination of non-significant terms, one at a time, largest p first (of the model of the
    ``transform`` ed response, see :func:`fit_model`).

    A term is removed when its p-value exceeds ``alpha`` (0.05 or 0.1 are usual). With
    ``hierarchical=True`` a term is kept while a higher-order term containing it stays in the
    model (A stays while AB or A^2 does). The returned fit's ``elimination`` lists the removed
    terms with the p-value they had when removed.
    """
    factors = list(factors)
    terms = model_terms(model, factors)
    log: list[dict] = []
    while True:
        fit = fit_model(data, response, factors, terms, levels, transform)
        cand = [t for t in terms if not (hierarchical and any(_contains(u, t) for u in terms))]
        pv = {t: fit.anova.loc[term_label(t, factors), "p"] for t in cand}
        pv = {t: v for t, v in pv.items() if np.isfinite(v)}
        if not pv:
            break
        worst = max(pv, key=pv.get)
        if pv[worst] <= alpha:
            break
        log.append({"removed": term_label(worst, factors), "p": float(pv[worst])})
        terms = [t for t in terms if t != worst]
    fit.elimination = log
    return fit


# --------------------------------------------------------------------------------------------
# Effects of two-level designs
# --------------------------------------------------------------------------------------------


def lenth_pse(effects: Sequence[float]) -> float:
    """Lenth's (1989) pseudo standard error of a set of effects."""
    c = np.abs(np.asarray(effects, dtype=float))
    s0 = 1.5 * np.median(c)
    small = c[c < 2.5 * s0]
    return float(1.5 * np.median(small)) if len(small) else float(s0)


def effects_table(
    data: pd.DataFrame, response: str, factors: Sequence[str], model: str | Sequence = "linear"
) -> pd.DataFrame:
    """Effects and standardized effects of a two-level design (the data of a Pareto chart).

    effect = 2 x coded coefficient (high minus low mean for an orthogonal +-1 design).
    The standardized effect is the t value, effect / SE(effect), when the model leaves residual
    degrees of freedom; for a saturated model it is effect / PSE with Lenth's pseudo standard
    error, referred to t with m/3 df (as Minitab does). Sorted by |standardized effect|, with
    the rank, the % contribution (SS / SS_total) and the 5 % critical value (``t_crit``).
    """
    factors = list(factors)
    fit = fit_model(data, response, factors, model)
    labels = fit.labels
    coef = fit.coefficients.loc[labels, "coef"].to_numpy()
    eff = 2.0 * coef
    sst = fit.anova.loc["Cor Total", "sum_sq"]
    ss = fit.anova.loc[labels, "sum_sq"].to_numpy()
    df_res = int(fit.anova.loc["Residual", "df"])
    if df_res > 0:
        std = fit.coefficients.loc[labels, "t"].to_numpy()
        p = fit.coefficients.loc[labels, "p"].to_numpy()
        tcrit = float(stats.t.ppf(0.975, df_res))
        method = f"t, {df_res} residual df"
    else:
        pse = lenth_pse(eff)
        d = len(eff) / 3.0
        std = eff / pse
        p = 2 * stats.t.sf(np.abs(std), d)
        tcrit = float(stats.t.ppf(0.975, d))
        method = f"Lenth PSE = {pse:.6g}, {d:.3g} df"
    out = pd.DataFrame(
        {
            "term": labels,
            "coefficient": coef,
            "effect": eff,
            "sum_sq": ss,
            "pct_contribution": 100.0 * ss / sst,
            "standardized": std,
            "p": p,
        }
    )
    out = out.reindex(out["standardized"].abs().sort_values(ascending=False).index)
    out["rank"] = np.arange(1, len(out) + 1)
    out = out.set_index("term")
    out.attrs["t_crit"] = tcrit
    out.attrs["method"] = method
    return out


# --------------------------------------------------------------------------------------------
# Hitting a target
# --------------------------------------------------------------------------------------------


@dataclass
class TargetSolution:
    """Factor settings whose predicted response equals a target.

    Attributes:
        target: the target response.
        reachable: whether the target lies within the predicted range over the region.
        chosen: the chosen point (coded factors, ``predicted``, ``distance`` from the centre),
            by ``rule``.
        chosen_actual: the chosen point in actual units (when the fit has levels).
        family: sampled points of the target contour inside the region (same columns plus
            ``<factor>_actual``), sorted by distance from the design centre.
        rule: how ``chosen`` was picked.
        bounds: coded (low, high) per factor.
        predicted_range: (min, max) of the prediction over the region.
    """

    target: float
    reachable: bool
    chosen: pd.Series
    chosen_actual: pd.Series | None
    family: pd.DataFrame
    rule: str
    bounds: dict[str, tuple[float, float]]
    predicted_range: tuple[float, float]


def _bounds(fit: ModelFit, bounds) -> dict[str, tuple[float, float]]:
    if isinstance(bounds, str):
        if bounds == "cube":
            b = 1.0
        elif bounds in ("design", "axial"):
            b = float(np.abs(fit.data[fit.factors].to_numpy()).max())
        else:
            raise InputError("bounds must be 'cube', 'design'/'axial', a number, a pair or a mapping")
        return {f: (-b, b) for f in fit.factors}
    if isinstance(bounds, Mapping):
        return {f: tuple(map(float, bounds.get(f, (-1.0, 1.0)))) for f in fit.factors}
    if np.ndim(bounds) == 0:
        b = float(bounds)
        return {f: (-b, b) for f in fit.factors}
    lo, hi = map(float, bounds)
    return {f: (lo, hi) for f in fit.factors}


class _Surface:
    """Fast scalar prediction and gradient over the free factors (the others held fixed)."""

    def __init__(self, fit: ModelFit, free: list[str], fixed: Mapping[str, float]):
        self.fit = fit
        self.free_idx = [fit.factors.index(f) for f in free]
        self.base = [float(fixed.get(f, 0.0)) for f in fit.factors]
        beta = fit.coefficients["coef"].to_numpy()
        self.b0 = float(beta[0])
        self.beta = beta
        self.terms = [(float(b), [fit.factors.index(f) for f in t]) for b, t in zip(beta[1:], fit.terms)]

    def full(self, z) -> np.ndarray:
        x = np.array(self.base)
        x[self.free_idx] = z
        return x

    def __call__(self, z) -> float:
        x = self.base.copy()
        for i, v in zip(self.free_idx, np.asarray(z, dtype=float).tolist()):
            x[i] = v
        val = self.b0
        for b, ii in self.terms:
            for i in ii:
                b *= x[i]
            val += b
        return val

    def grad(self, z) -> np.ndarray:
        return _gradient(self.full(z), self.beta, self.fit.terms, self.fit.factors)[self.free_idx]


def _region(fit: ModelFit, bounds, fixed):
    fixed = dict(fixed or {})
    b = _bounds(fit, bounds)
    free = [f for f in fit.factors if f not in fixed]
    if not free:
        raise InputError("all factors are fixed")
    lo = np.array([b[f][0] for f in free])
    hi = np.array([b[f][1] for f in free])
    return b, free, lo, hi, _Surface(fit, free, fixed)


def response_range(
    fit: ModelFit, bounds="cube", fixed: Mapping[str, float] | None = None, n_starts: int = 16, seed: int = 0
) -> tuple[tuple[float, np.ndarray], tuple[float, np.ndarray]]:
    """((min, argmin), (max, argmax)) of the prediction over the coded region (multi-start)."""
    _, free, lo, hi, surf = _region(fit, bounds, fixed)
    rng = np.random.default_rng(seed)
    starts = [0.5 * (lo + hi)] + list(lo + (hi - lo) * rng.random((n_starts, len(free))))
    out = []
    for sign in (1.0, -1.0):
        best_v, best_z = math.inf, None
        for x0 in starts:
            r = optimize.minimize(
                lambda z, sign=sign: sign * surf(z),
                x0,
                jac=lambda z, sign=sign: sign * surf.grad(z),
                method="L-BFGS-B",
                bounds=list(zip(lo, hi)),
            )
            if r.fun < best_v:
                best_v, best_z = float(r.fun), np.clip(r.x, lo, hi)
        out.append((sign * best_v, surf.full(best_z)))
    return out[0], out[1]


def response_extremes(
    fit: ModelFit, bounds="cube", fixed: Mapping[str, float] | None = None, seed: int = 0
) -> tuple[tuple[float, np.ndarray], tuple[float, np.ndarray]]:
    """:func:`response_range` in the response's own units: ((min, argmin), (max, argmax)) of the back-transformed
    prediction (the model scale's ends swapped for a falling transform)."""
    (lo, x_lo), (hi, x_hi) = response_range(fit, bounds, fixed, seed=seed)
    a, b = (float(fit.to_response(lo)), x_lo), (float(fit.to_response(hi)), x_hi)
    return (b, a) if fit.transform.decreasing else (a, b)


def solve_target(
    fit: ModelFit,
    target: float,
    bounds="cube",
    fixed: Mapping[str, float] | None = None,
    n_samples: int = 100,
    seed: int = 0,
    tol: float | None = None,
) -> TargetSolution:
    """Settings in the coded region whose prediction equals ``target``.

    The target contour {x : yhat(x) = target} is a set, not a point. It is sampled by projecting
    ``n_samples`` random points of the region onto it (each projection: the nearest point of the
    contour inside the region, scipy SLSQP), and the solution reported as ``chosen`` is the
    contour point nearest the design centre (smallest Euclidean norm in coded units over the
    free factors), refined by a direct minimisation. ``bounds``: ``"cube"`` ([-1, 1]^k,
    default), ``"design"``/``"axial"`` (the largest |coded value| in the data, e.g. +-alpha of a
    CCD), a number b for [-b, b], a pair, or a mapping per factor. ``fixed`` holds factors at
    coded values. When the target is outside the predicted range, ``reachable`` is False and
    the extreme nearest the target is returned. ``target`` and the ``predicted`` values are in the response's
    units; with a transform the contour is solved on the model's scale, at the transformed target.
    """
    b, free, lo, hi, surf = _region(fit, bounds, fixed)
    (vmin, xmin), (vmax, xmax) = response_range(fit, b, fixed, seed=seed)
    target_response, target = float(target), float(fit.transform.forward(target, "target"))
    tol = 1e-7 * max(1.0, abs(target), vmax - vmin) if tol is None else tol
    rng = np.random.default_rng(seed)
    fi = surf.free_idx

    def record(z) -> dict:
        x = surf.full(z)
        row = {f: float(x[i]) for i, f in enumerate(fit.factors)}
        row["predicted"] = float(fit.to_response(surf(z)))
        row["distance"] = float(np.linalg.norm(x[fi]))
        return row

    reachable = vmin - tol <= target <= vmax + tol
    rows: list[dict] = []
    chosen_row = None
    if reachable:
        cons = [{"type": "eq", "fun": lambda z: surf(z) - target, "jac": lambda z: surf.grad(z)[None, :]}]
        bnds = list(zip(lo, hi))
        opts = {"ftol": 1e-12, "maxiter": 300}

        def project(anchor, x0):
            r = optimize.minimize(
                lambda z: float(np.sum((z - anchor) ** 2)),
                x0,
                jac=lambda z: 2.0 * (z - anchor),
                method="SLSQP",
                bounds=bnds,
                constraints=cons,
                options=opts,
            )
            z = np.clip(r.x, lo, hi)
            return z if abs(surf(z) - target) <= tol else None

        for a in lo + (hi - lo) * rng.random((n_samples, len(free))):
            z = project(a, a)
            if z is not None:
                rows.append(record(z))
        # the contour point nearest the centre: project the centre, from several starts
        centre = np.clip(np.zeros(len(free)), lo, hi)
        starts = [np.array([r[f] for f in free]) for r in sorted(rows, key=lambda r: r["distance"])[:5]]
        starts += [centre, xmin[fi], xmax[fi]]
        best = None
        for x0 in starts:
            z = project(np.zeros(len(free)), x0)
            if z is not None and (best is None or z @ z < best @ best):
                best = z
        if best is not None:
            chosen_row = record(best)
            rows.append(chosen_row)
        elif rows:
            chosen_row = min(rows, key=lambda r: r["distance"])
        else:
            reachable = False
    if not reachable:
        x = xmax if target > vmax else xmin
        chosen_row = record(x[fi])
        rows = [chosen_row]
    family = pd.DataFrame(rows).drop_duplicates(subset=fit.factors).sort_values("distance")
    family = family.reset_index(drop=True)
    chosen = pd.Series(chosen_row)
    chosen_actual = None
    if fit.levels and all(f in fit.levels for f in fit.factors):
        for f in fit.factors:
            family[f"{f}_actual"] = fit.levels[f].to_actual(family[f].to_numpy())
        chosen_actual = pd.Series({f: float(fit.levels[f].to_actual(chosen[f])) for f in fit.factors})
        chosen_actual["predicted"] = chosen["predicted"]
    rule = (
        "contour point nearest the design centre (smallest Euclidean distance in coded units over the free factors)"
        if reachable
        else "target outside the predicted range: the region's extreme nearest the target"
    )
    return TargetSolution(
        target_response, bool(reachable), chosen, chosen_actual, family, rule, b, fit.transform.interval(vmin, vmax)
    )


# --------------------------------------------------------------------------------------------
# Model graphs (Design-Expert's): perturbation, interaction, half-normal, cube
# --------------------------------------------------------------------------------------------


def perturbation(fit: ModelFit, reference: Mapping[str, float] | None = None, n: int = 21) -> pd.DataFrame:
    """Design-Expert's perturbation plot: the prediction (in the response's units) as each factor alone moves from
    -1 to +1 coded about the ``reference`` point (coded; default the centre), the others held there. Columns
    ``factor``, ``deviation`` (coded), ``predicted``; a steep curve is a factor the response is sensitive to."""
    ref = {f: float((reference or {}).get(f, 0.0)) for f in fit.factors}
    dev = np.linspace(-1.0, 1.0, n)
    rows = []
    for f in fit.factors:
        pts = pd.DataFrame({g: np.full(n, ref[g]) for g in fit.factors})
        pts[f] = ref[f] + dev
        rows.append(pd.DataFrame({"factor": f, "deviation": dev, "predicted": fit.predict_response(pts)}))
    return pd.concat(rows, ignore_index=True)


def interaction(fit: ModelFit, a: str, b: str, n: int = 21) -> pd.DataFrame:
    """Design-Expert's interaction plot of factors ``a`` and ``b``: the prediction (response units) along ``a``
    (coded -1 to +1) with ``b`` at -1 and at +1, the others at the centre. Columns ``a``, ``b``, ``predicted``;
    lines that are not parallel are the interaction."""
    x = np.linspace(-1.0, 1.0, n)
    rows = []
    for level in (-1.0, 1.0):
        pts = pd.DataFrame({g: np.zeros(n) for g in fit.factors})
        pts[a], pts[b] = x, level
        rows.append(pd.DataFrame({"a": x, "b": level, "predicted": fit.predict_response(pts)}))
    return pd.concat(rows, ignore_index=True)


def half_normal(effects) -> pd.DataFrame:
    """Half-normal plot of effects (Daniel 1959): the absolute effects sorted, against the half-normal quantiles
    Phi^-1(0.5 + 0.5 (i - 0.5) / m), i = 1..m. Inert effects fall on a line through the origin; active ones stand
    off it to the right. Columns ``term``, ``abs_effect``, ``quantile``."""
    e = pd.Series(effects, dtype=float).abs().sort_values()
    m = len(e)
    q = stats.norm.ppf(0.5 + 0.5 * (np.arange(1, m + 1) - 0.5) / m)
    return pd.DataFrame({"term": list(e.index), "abs_effect": e.to_numpy(), "quantile": q})


def cube(fit: ModelFit, factors: Sequence[str]) -> pd.DataFrame:
    """Design-Expert's cube plot of three ``factors``: the prediction (response units) at the eight corners of
    their coded cube, the other factors at the centre. Columns: the three factors (+-1) and ``predicted``."""
    a, b, c = factors
    corners = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))
    pts = pd.DataFrame({g: np.zeros(8) for g in fit.factors})
    pts[a], pts[b], pts[c] = corners[:, 0], corners[:, 1], corners[:, 2]
    return pts[[a, b, c]].assign(predicted=fit.predict_response(pts))


# --------------------------------------------------------------------------------------------
# Several responses, aliases, confirmation
# --------------------------------------------------------------------------------------------


def desirability(values: Mapping[str, np.ndarray], goals: Mapping[str, Goal]) -> np.ndarray:
    """Overall desirability D = (prod d_i^r_i)^(1 / sum r_i) of the responses' ``values`` (each (n,)) under their
    ``goals`` (r_i: importance); 0 wherever one response is undesirable."""
    total = sum(g.importance for g in goals.values())
    d = {name: g.d(values[name]) for name, g in goals.items()}
    logs = [g.importance * np.log(np.maximum(d[name], 1e-300)) for name, g in goals.items()]
    zero = np.any([d[name] <= 0.0 for name in goals], axis=0)
    return np.where(zero, 0.0, np.exp(np.sum(logs, axis=0) / total))


def optimize_desirability(
    fits: Mapping[str, ModelFit], goals: Mapping[str, Goal], bounds="cube", starts: int = 40, seed: int = 0
) -> pd.DataFrame:
    """Settings that maximise the overall :func:`desirability` of the fitted models ``fits`` (one per goal,
    the same factors) over the coded region ``bounds``: L-BFGS-B from ``starts`` seeded uniform points and
    the design's runs, on a smoothed D (each d_i floored at 1e-6, so that a start where a response is
    undesirable still has a slope). Distinct solutions (coded settings to 3 decimals) ranked by D, best first:
    coded factors, each response's prediction and d, and ``desirability``."""
    names = list(goals)
    fit0 = fits[names[0]]
    factors = fit0.factors
    b = _bounds(fit0, bounds)
    lo = np.array([b[f][0] for f in factors])
    hi = np.array([b[f][1] for f in factors])
    total = sum(goals[n].importance for n in names)

    def smooth(z):
        x = z[None, :]
        s_ = sum(
            goals[n].importance * math.log(max(float(goals[n].d(fits[n].predict_response(x))[0]), 1e-6)) for n in names
        )
        return -s_ / total

    pts = lo + (hi - lo) * np.random.default_rng(seed).random((starts, len(factors)))
    runs = np.clip(fit0.data[factors].to_numpy(dtype=float), lo, hi)
    rows = []
    for z0 in np.vstack([pts, runs]):
        res = optimize.minimize(smooth, z0, method="L-BFGS-B", bounds=list(zip(lo, hi)))
        rows.append(np.clip(res.x, lo, hi))
    X = np.unique(np.round(np.array(rows), 3), axis=0)
    out = pd.DataFrame(X, columns=factors)
    values = {n: fits[n].predict_response(X) for n in names}
    for n in names:
        out[n] = values[n]
        out[f"d_{n}"] = goals[n].d(values[n])
    out["desirability"] = desirability(values, goals)
    return out.sort_values("desirability", ascending=False, kind="stable").reset_index(drop=True)


def alias_matrix(fit: ModelFit, max_order: int = 3, tol: float = 1e-9) -> pd.DataFrame:
    """Design-Expert's alias matrix of ``fit``'s design: A = (X1'X1)^-1 X1'X2, with X1 the model's columns
    (intercept and terms) and X2 every interaction of distinct factors up to ``max_order`` that the model
    lacks. Entry (model term, potential term) is how much of that term's effect the model term's estimate
    absorbs: 1 for a full alias (a 2^(k-p) fraction), a fraction for a partial one (Plackett-Burman's +/-1/3).
    Rows: ``Intercept`` and the term labels; only columns with an entry above ``tol``."""
    factors = fit.factors
    x = fit.data[factors].to_numpy(dtype=float)
    have = {tuple(sorted(t)) for t in fit.terms}
    potential = [
        t
        for order in range(2, min(max_order, len(factors)) + 1)
        for t in itertools.combinations(factors, order)
        if tuple(sorted(t)) not in have
    ]
    X2 = _columns(x, potential, factors)[:, 1:]
    # the fit's own model matrix X1 and (X1'X1)^-1
    A = np.asarray(fit.ols.normalized_cov_params) @ np.asarray(fit.ols.model.exog).T @ X2
    A[np.abs(A) < tol] = 0.0
    keep = np.abs(A).max(axis=0) > 0 if A.size else np.zeros(0, bool)
    return pd.DataFrame(
        A[:, keep],
        index=["Intercept", *fit.labels],
        columns=[term_label(t, factors) for t, k in zip(potential, keep) if k],
    )


def alias_lines(aliases: pd.DataFrame, digits: int = 3) -> list[str]:
    """Design-Expert's alias list: ``[A] = A - 0.333 BC + 0.333 BD`` for each row of :func:`alias_matrix`."""
    out = []
    for term, row in aliases.iterrows():
        parts = [term]
        for col, a in row.items():
            if a == 0.0:
                continue
            mag = abs(a)
            coef = "" if abs(mag - 1.0) < 10**-digits else f"{mag:.{digits}g} "
            parts.append(f"{'-' if a < 0 else '+'} {coef}{col}")
        out.append(f"[{term}] = " + " ".join(parts))
    return out


def mean_prediction_interval(
    predicted: float, mse: float, h0: float, df: int, runs: int = 1, alpha: float = 0.05
) -> tuple[float, float]:
    """Two-sided ``1 - alpha`` prediction interval for the mean of ``runs`` new runs at a point of leverage
    ``h0`` whose model prediction is ``predicted``: predicted +/- t(1 - alpha/2, df) sqrt(mse (1/runs + h0))
    (Design-Expert's confirmation interval; ``mse`` the residual mean square on ``df`` degrees of freedom)."""
    from scipy import stats

    if int(runs) < 1:
        raise InputError(f"mean_prediction_interval: runs = {runs}; expected an integer >= 1")
    if df <= 0 or not math.isfinite(mse):
        return math.nan, math.nan
    half = float(stats.t.ppf(1.0 - alpha / 2.0, df)) * math.sqrt(mse * (1.0 / int(runs) + h0))
    return predicted - half, predicted + half


def mean_interval(fit: ModelFit, alpha: float = 0.05) -> tuple[float, float, float]:
    """The mean response of a model with no terms left (the mean model, what backward elimination leaves when no
    factor is significant) and its two-sided ``1 - alpha`` confidence interval: statsmodels' ``conf_int`` of the
    intercept, brought back to the response's units through the fit's transform. It is what such a model
    predicts at every setting of the design region. Returns (mean, low, high)."""
    if fit.terms:
        raise InputError(f"mean_interval: the model of {fit.response} has terms {fit.labels}; expected none")
    low, high = (float(v) for v in np.asarray(fit.ols.conf_int(alpha))[0])
    mean = float(np.asarray(fit.ols.params)[0])
    if fit.transform != NONE:
        mean = float(fit.to_response(mean))
        low, high = fit.transform.interval(low, high)
    return mean, float(low), float(high)


def confirmation_interval(fit: ModelFit, x, runs: int = 1, alpha: float = 0.05) -> dict:
    """Design-Expert's confirmation check at the coded point ``x`` (mapping or (k,) array): the prediction,
    its leverage h0 = x0' (X'X)^-1 x0, the residual mean square and its df, and
    :func:`mean_prediction_interval` for ``runs`` runs (for one run it is statsmodels' ``obs_ci``). With a
    transform the interval is the model scale's, brought back to the response's units (``predicted``, ``low``,
    ``high``; ``model_scale`` keeps the model scale's three)."""
    x0 = _columns(fit._x(x), fit.terms, fit.factors)[0]
    df = int(fit.ols.df_resid)
    mse = float(fit.ols.mse_resid) if df > 0 else math.nan
    h0 = float(x0 @ np.asarray(fit.ols.normalized_cov_params) @ x0)
    y0 = float(fit.predict(fit._x(x))[0])
    low, high = mean_prediction_interval(y0, mse, h0, df, runs, alpha)
    out = {"predicted": y0, "low": low, "high": high, "mse": mse, "h0": h0, "df": df, "runs": int(runs)}
    if fit.transform != NONE:
        out["model_scale"] = {"predicted": y0, "low": low, "high": high}
        out["predicted"] = float(fit.to_response(y0))
        out["low"], out["high"] = fit.transform.interval(low, high)
    return out


# --------------------------------------------------------------------------------------------
# Diagnostics (Design-Expert's diagnostics node)
# --------------------------------------------------------------------------------------------

BOX_COX_STANDARD = {-1.0: "inverse", -0.5: "inverse square root", 0.0: "ln", 0.5: "square root", 1.0: "none"}
"""The power transforms Design-Expert recommends by name, by their lambda."""


def influence(fit: ModelFit) -> pd.DataFrame:
    """Per-run diagnostics of ``fit`` from statsmodels' OLSInfluence, one row per run used (in the fit's order):
    ``actual``, ``predicted``, ``residual``, ``leverage``, ``studentized`` (internally), ``externally_studentized``
    (Design-Expert's "externally studentized residual", R-Student), ``cooks_distance`` and ``dffits``."""
    import warnings

    with warnings.catch_warnings():
        # a run of leverage 1 (a saturated corner) has no studentized residual: NaN, said by the readings
        warnings.simplefilter("ignore")
        inf = fit.ols.get_influence()
        return pd.DataFrame(
            {
                "actual": np.asarray(fit.ols.model.endog, dtype=float),
                "predicted": np.asarray(fit.ols.fittedvalues, dtype=float),
                "residual": np.asarray(fit.ols.resid, dtype=float),
                "leverage": inf.hat_matrix_diag,
                "studentized": inf.resid_studentized_internal,
                "externally_studentized": inf.resid_studentized_external,
                "cooks_distance": inf.cooks_distance[0],
                "dffits": inf.dffits[0],
            }
        )


def outlier_limit(fit: ModelFit, alpha: float = 0.05) -> float:
    """Bonferroni limit of the externally studentized residuals: t(1 - alpha / 2n, n - p - 1), as Design-Expert
    draws it on its residual plots."""
    n, p = int(fit.ols.nobs), int(fit.ols.df_model) + 1
    return float(stats.t.ppf(1.0 - alpha / (2 * n), max(n - p - 1, 1)))


def box_cox(fit: ModelFit, alpha: float = 0.05, lambdas=None) -> dict:
    """Box-Cox plot of ``fit``'s model: the residual sum of squares of the same model fitted to the transformed
    response y(lambda) = (y^lambda - 1) / (lambda g^(lambda-1)) (g y ln y at lambda = 0; g the geometric mean,
    which makes the sums comparable across lambda), its minimum lambda_hat and the confidence interval
    SS* = SS(lambda_hat) (1 + t^2(alpha/2, df) / df) (Box and Cox 1964; Montgomery, Design and Analysis of
    Experiments, 15.1.1), df the residual degrees of freedom.

    Returns ``lambdas`` (the plotted grid), ``ln_ss``, ``lambda_hat``, ``interval`` (low, high; an end is None
    where the interval runs past the grid), ``ln_ss_limit``, ``recommended`` (the name of the standard transform
    in the interval nearest lambda_hat, "none" when the interval holds 1, else "power") and ``lambda_recommended``;
    or ``error`` when a response is not positive (add a constant first).
    """
    # always of the response itself (plus the transform's constant), whatever transform the fit uses
    y = fit.to_response(np.asarray(fit.ols.model.endog, dtype=float)) + fit.transform.k
    X = np.asarray(fit.ols.model.exog, dtype=float)
    if np.any(y <= 0):
        return {"error": f"the response has values <= 0 (min {y.min():.4g}): Box-Cox needs positive values"}
    g = float(np.exp(np.mean(np.log(y))))
    df = int(round(fit.ols.df_resid))

    def ss(lam: float) -> float:
        z = g * np.log(y) if abs(lam) < 1e-9 else (y**lam - 1.0) / (lam * g ** (lam - 1.0))
        beta, *_ = np.linalg.lstsq(X, z, rcond=None)
        return float(np.sum((z - X @ beta) ** 2))

    grid = np.linspace(-3.0, 3.0, 121) if lambdas is None else np.asarray(lambdas, dtype=float)
    ln_ss = np.log([ss(lam) for lam in grid])
    k = int(np.argmin(ln_ss))
    lo_b, hi_b = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    lam_hat = float(optimize.minimize_scalar(lambda v: np.log(ss(v)), bounds=(lo_b, hi_b), method="bounded").x)
    limit = float(np.log(ss(lam_hat)) + np.log1p(stats.t.ppf(1 - alpha / 2, df) ** 2 / df)) if df > 0 else math.inf

    def edge(a: float, b: float):
        # the lambda between a (inside) and b where ln SS crosses the limit, None if it does not within the grid
        if np.log(ss(b)) <= limit:
            return None
        return float(optimize.brentq(lambda v: np.log(ss(v)) - limit, a, b))

    interval = (edge(lam_hat, float(grid[0])), edge(lam_hat, float(grid[-1])))
    low = -math.inf if interval[0] is None else interval[0]
    high = math.inf if interval[1] is None else interval[1]
    inside = [lam for lam in BOX_COX_STANDARD if low <= lam <= high]
    if 1.0 in inside:
        rec, lam_rec = "none", 1.0
    elif inside:
        lam_rec = min(inside, key=lambda v: abs(v - lam_hat))
        rec = BOX_COX_STANDARD[lam_rec]
    else:
        rec, lam_rec = "power", lam_hat
    return {
        "lambdas": grid,
        "ln_ss": ln_ss,
        "lambda_hat": lam_hat,
        "interval": interval,
        "ln_ss_limit": limit,
        "recommended": rec,
        "lambda_recommended": lam_rec,
        "lambda_current": 0.0 if fit.transform.exponent is None else fit.transform.exponent,
    }


# --------------------------------------------------------------------------------------------
# Fit summary (which model order the data support)
# --------------------------------------------------------------------------------------------

SUMMARY_ORDERS = ("linear", "2fi", "quadratic", "cubic")
"""The model orders of the fit summary, each containing the one before."""


def _order_terms(order: str, factors: Sequence[str]) -> list[Term]:
    if order != "cubic":
        return model_terms(order, factors)
    return model_terms("quadratic", factors) + [
        _canonical(t, factors) for t in itertools.combinations_with_replacement(list(factors), 3)
    ]


def fit_summary(
    data: pd.DataFrame, response: str, factors: Sequence[str], alpha: float = 0.05, transform: Transform | None = None
) -> dict:
    """Design-Expert's fit summary of the coded ``data``: for the mean and each of :data:`SUMMARY_ORDERS`,
    whether the design can estimate it (``aliased`` when not), and

    - ``sequential``: the sequential (type I) sums of squares, each order against the one before ("Linear vs
      Mean", ...): SS, df, MS, F against that order's own residual mean square, p;
    - ``lack_of_fit``: each order's lack-of-fit SS, df, MS, F against pure error, p (when replicates give pure
      error);
    - ``statistics``: each order's Std. Dev., R², adjusted and predicted R², PRESS;
    - ``suggested``: the highest non-aliased order whose sequential p < ``alpha`` and whose lack of fit is not
      significant (p >= ``alpha``, or untested), as Design-Expert suggests it; None when no order adds
      significantly to the mean.

    Returns a dict of those three DataFrames (index: the orders) and ``suggested``. With ``transform``, of the
    transformed response.
    """
    factors = list(factors)
    df = data[factors + [response]].astype(float).reset_index(drop=True)
    if transform is not None and transform != NONE:
        df[response] = transform.forward(df[response].to_numpy(), f"response {response!r}")
    y = df[response].to_numpy()
    n = len(y)
    xk = df[factors].to_numpy()
    sst = float(((y - y.mean()) ** 2).sum())
    prev_sse, prev_p = sst, 1
    seq, lof, st = [], [], []
    suggested = None
    for order in SUMMARY_ORDERS:
        terms = _order_terms(order, factors)
        X = _columns(xk, terms, factors)
        p = X.shape[1]
        aliased = np.linalg.matrix_rank(X) < p or n - p <= 0
        name = {"linear": "Linear", "2fi": "2FI", "quadratic": "Quadratic", "cubic": "Cubic"}[order]
        if aliased:
            seq.append((name, math.nan, p - prev_p, math.nan, math.nan, math.nan, True))
            lof.append((name, math.nan, math.nan, math.nan, math.nan, math.nan, True))
            st.append((name, math.nan, math.nan, math.nan, math.nan, math.nan, True))
            break
        fit = fit_model(df, response, factors, terms)
        sse = float(fit.anova.loc["Residual", "sum_sq"])
        df_res = n - p
        ss_add, df_add = prev_sse - sse, p - prev_p
        f, pv = _f_p(ss_add / df_add, sse / df_res, df_add, df_res) if df_add > 0 else (math.nan, math.nan)
        seq.append((name, ss_add, df_add, ss_add / df_add if df_add else math.nan, f, pv, False))
        if "Lack of Fit" in fit.anova.index:
            r = fit.anova.loc["Lack of Fit"]
            lof.append((name, r["sum_sq"], int(r["df"]), r["mean_sq"], r["F"], r["p"], False))
            lof_ok = not (r["p"] < alpha)
        else:
            lof.append((name, math.nan, math.nan, math.nan, math.nan, math.nan, False))
            lof_ok = True
        s = fit.stats
        st.append((name, s["std_dev"], s["r2"], s["adj_r2"], s["pred_r2"], s["press"], False))
        if pv < alpha and lof_ok:
            suggested = name
        prev_sse, prev_p = sse, p
    cols = ["sum_sq", "df", "mean_sq", "F", "p", "aliased"]
    return {
        "sequential": pd.DataFrame(seq, columns=["source"] + cols).set_index("source"),
        "lack_of_fit": pd.DataFrame(lof, columns=["source"] + cols).set_index("source"),
        "statistics": pd.DataFrame(
            st, columns=["source", "std_dev", "r2", "adj_r2", "pred_r2", "press", "aliased"]
        ).set_index("source"),
        "suggested": suggested,
    }
