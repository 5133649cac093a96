"""The diagnosis: calibrate the base model, test its adequacy, try the candidate extensions, name the cause and
measure its gain on held-out data (``warpdem diagnose DATA.toml``).

Stages (every simulated world is stored as it finishes, ``OUT/runs/<id>.json``, so a rerun reuses them):

1. **Noise budget.** The SD of one measurement: the stated ``sd_<response>`` or the pooled scatter of the
   replicates. The simulation's own scatter: :attr:`DiagnosisSpec.sim_seeds` world seeds at the centre of the
   free parameters' ranges at every training condition, pooled, or, where larger, the scatter of the base
   model's design runs about its surrogates (their white-noise term: a response that is not smooth in the
   parameters scatters over them as it does over seeds). A measured mean of n replicates is compared
   with the model through the variance max(s_meas^2, s_sim^2) / n (a measurement cannot be known better than
   the pile-to-pile scatter the model itself shows) plus the model side's own variance: s_seed^2 / k for the
   mean of k confirming simulations (or the surrogate's variance) plus the roughness max(s_nugget^2 - s_seed^2,
   0), which k world seeds at one parameter point do not average away (a press whose fill ignores the seed
   gives k equal runs).
2. **Calibration.** A space-filling design (:func:`design_points`) over the free parameters, at every
   condition (training and test), each condition's worlds batched in one launch where the scene allows (a rig
   parameter, which cannot vary per world, takes :data:`LAUNCH_LEVELS` values, one scene each); a
   Gaussian-process surrogate per (condition, response) (:class:`inference.Surrogate`: smooth, interpolating,
   with its own predictive variance, which the likelihood takes in); the posterior on a flat prior over the
   ranges by MCMC on the surrogates (:func:`inference.calibrate`); the maximum a posteriori point confirmed by
   :attr:`DiagnosisSpec.confirm_seeds` real simulations at every condition. Where those miss the surrogates'
   prediction by more than its variance and the seed scatter allow (:meth:`Evaluator.surrogate_check`, a
   chi-square test at alpha), they join the design, the surrogates are refitted and the model is recalibrated
   and confirmed again, once.
3. **Adequacy.** Standardised residuals of the confirmed means against the training data; chi-square, per
   experiment and trend tests against the noise budget, Holm-corrected as one family
   (:func:`inference.adequacy`). Nothing significant: ADEQUATE, and the diagnosis stops.
4. **Candidates** (:mod:`.candidates`): each one's effect at the calibrated point (simulations at its screening
   value with the confirming runs' world seeds, so most of the seed scatter cancels) against the residual
   pattern, with the base parameters free to re-tune along the surrogates' gradients (:func:`inference.screen`);
   every one that passes (p < alpha) is recalibrated as in step 2 with its parameter added. (A cap of three, the
   largest screen statistics, once kept the GPU's launches few; it dropped rolling friction, the very rival of
   shape in angle data, at a statistic of 57 against the third's 59. Scenes now share launches, so the cap went.)
5. **Held-out data.** With a ``split`` column, the test experiments; without, each training condition in turn is
   left out, the model recalibrated on the rest (on the surrogates) and simulated at the left-out condition.
   Per experiment: squared standardised error and Gaussian negative log-likelihood, from real simulations.

Data with no more measured values than free parameters (a seed's one angle) allow no adequacy test and no
held-out comparison: the diagnosis then asks only which models reach the data (:mod:`.reach`).

The naming rule (:func:`verdict`), fixed here and never tuned to a data set. One model *beats* another on the
held-out data when its summed held-out log predictive likelihood exceeds the other's by more than
:data:`EVIDENCE` (2 ln K > 6: "strong" evidence on Kass & Raftery's 1995 scale). The noise enters through
the likelihoods, whose variances are the noise budget's; a likelihood ratio, unlike a bootstrap of per-experiment
differences, still means something with three held-out experiments (the report gives the bootstrap interval too).
A candidate *contends* when its likelihood-ratio test against the base (on the training data, from the confirming
simulations; boundary corrected when its off value is an end of its range) has p < alpha and it beats the base
on the held-out data (with no held-out data this condition is waived and the report says so). The best
contender (lowest held-out NLL) is the CAUSE when its 95 % posterior interval excludes the off value, the
extended model passes the adequacy test, and it beats every other contender; contenders it does not beat tie
with it: AMBIGUOUS, and the report names the measurement that separates them best
(:func:`separating_measurement`). No contender that qualifies: UNEXPLAINED (the model is wrong in a way no
candidate fixes).
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from warpdem.study import execute
from warpdem.study import spec as sp
from warpdem.study.folder import copy_atomic, hold

from . import candidates as cands
from . import inference as inf
from .data import DiagnoseError, DiagnosisSpec, Experiments, load_diagnosis, training_values

LAUNCH_LEVELS = 5
"""Values a design takes along a parameter that cannot vary per world (0, 1/4, ..., 1 of its range): each value is
a scene of its own (on a GPU they share the stage's launch; on a CPU a launch each, costing their worlds as any
launch does). Three levels were too few for shape: a rod's sphere count changes in steps with its aspect ratio,
and the estimate settled in the middle level's step."""

DESIGN_SEED = 0
"""World seed of the space-filling design's simulations (the factories' own placement)."""

CENTRE_SEEDS = 1
"""First world seed of the simulation-scatter runs at the centre of the ranges (then +1, +2, ...)."""

CONFIRM_SEEDS = 101
"""First world seed of the confirming simulations (then +1, +2, ...); the screen reuses them."""

SEPARATING = (
    "bulk_density_kg_m3",
    "angle_fit_deg",
    "pile_height_m",
    "discharge_rate_kg_s",
    "dynamic_angle_deg",
    "fluctuation_index",
    "residual_set_ratio",
    "max_displacement_m",
    "compression_ratio",
    "unloading_stiffness_n_m",
    "loading_exponent",
)
"""The measurements a lab can make that :func:`separating_measurement` may name (packing fraction is bulk
density over the solid density; the angle's other estimators measure the same pile)."""

EVIDENCE = 3.0
"""Log likelihood ratio [nats] by which one model must beat another: summed over the held-out data, or, with none,
half the AIC difference (2 ln K = 6)."""

VERDICTS = ("adequate", "cause", "ambiguous", "unexplained")
"""The verdicts of diagnosis.json."""


# --------------------------------------------------------------------------------------------------
# simulations
# --------------------------------------------------------------------------------------------------


class Stopped(RuntimeError):
    """The wall-time limit stopped the launches (each saved its checkpoint)."""


class Simulations:
    """Simulated worlds by identity (:func:`warpdem.study.spec.point_key` of the overrides and world seed),
    stored one JSON per world under ``OUT/runs`` the moment its launch finishes; requests already stored are
    never run again."""

    def __init__(self, study, out: Path, devices: list[str], progress: bool, log, stop_after: float):
        self.study, self.out, self.devices, self.progress, self.log = study, out, devices, progress, log
        self.stop_after, self.t0 = stop_after, time.perf_counter()
        self.runs = out / "runs"
        self.runs.mkdir(parents=True, exist_ok=True)
        self._cache: dict[str, dict] = {}
        self.launched = 0
        self._executor = None
        self.scheduler: str | None = None
        self.shared_dir: str | None = None

    @property
    def executor(self):
        """The diagnosis's executor (:func:`warpdem.study.executor.executor_for`), made on first use and kept for
        every stage, so that a cluster's workers keep Warp and its compiled kernels loaded between stages."""
        if self._executor is None:
            from warpdem.study.executor import executor_for

            self._executor = executor_for(self.devices, self.scheduler, self.shared_dir)
            if getattr(self._executor, "dashboard", None):
                self.log(f"{len(self._executor.devices)} worker(s), Dask dashboard {self._executor.dashboard}")
        return self._executor

    def close(self) -> None:
        if self._executor is not None:
            self._executor.close()
            self._executor = None

    def key(self, overrides: dict, seed: int) -> str:
        return sp.point_key(self.study, overrides, seed)

    def run(self, requests: list[tuple[dict, int]], stage: str) -> list[dict]:
        """The metrics of each (overrides, world seed) in ``requests``, running those not yet stored (batched
        by what they share); raises :class:`Stopped` when the wall-time limit stops a launch."""
        rows, seen = [], set()
        for ov, seed in requests:
            pid = self.key(ov, seed)
            if pid in seen or (self.runs / f"{pid}.json").exists():
                continue
            seen.add(pid)
            rows.append({"run": len(rows) + 1, "point_id": pid, "world_seed": int(seed), "overrides": ov})
            rows[-1]["row"] = {"stage": stage}
        if rows:
            batches = execute._batches(self.study, rows, self.executor.parallel, execute.merges_scenes(self.devices))
            self.log(f"{stage}: {len(rows)} simulation(s) in {len(batches)} launch(es)")
            bar = execute._progress_bar(len(rows), 0, stage, self.progress)
            try:
                stopped = self.executor.run(
                    self.study, self.out, batches, bar, self.t0, 60.0, self.stop_after, self.log
                )
                if stopped:
                    raise Stopped(stopped)
            finally:
                if bar is not None:
                    bar.close()
            self.launched += len(batches)
        return [self.metrics(self.key(ov, seed)) for ov, seed in requests]

    def metrics(self, pid: str) -> dict:
        if pid not in self._cache:
            with open(self.runs / f"{pid}.json") as fh:
                self._cache[pid] = json.load(fh)["metrics"]
        return self._cache[pid]


def response(metrics: dict, name: str) -> float:
    """Response ``name`` (a metric key) of one world's metrics; NaN where the run could not measure it."""
    return execute._response(metrics, name)


# --------------------------------------------------------------------------------------------------
# models
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Dim:
    """One calibrated parameter: its ``name``, override ``key`` and range [``low``, ``high``]."""

    name: str
    key: str
    low: float
    high: float
    unit: str = ""

    def value(self, u: float) -> float:
        return self.low + float(u) * (self.high - self.low)

    def unit_value(self, v: float) -> float:
        return (float(v) - self.low) / (self.high - self.low)


@dataclass
class Model:
    """The base model (``candidate`` and ``law`` None), the base plus one candidate (its parameter the last
    dimension), the base with its rolling model switched (``law``; the same parameters), or both changes."""

    name: str
    dims: list[Dim]
    shared: dict = field(default_factory=dict)
    candidate: cands.Candidate | None = None
    law: cands.LawSwitch | None = None

    @property
    def is_base(self) -> bool:
        return self.candidate is None and self.law is None

    @classmethod
    def extended(cls, base: Model, cand: cands.Candidate) -> Model:
        """``base`` plus the candidate ``cand``, whose parameter is the last dimension; a ``base`` with a rolling
        model switched keeps it (a two-change model, named ``<switch>+<candidate>``)."""
        name = f"{base.law.name}+{cand.name}" if base.law else cand.name
        dims = [*base.dims, Dim(cand.name, cand.key, cand.low, cand.high, cand.unit)]
        return cls(name, dims, {**base.shared, **cand.shared}, cand, base.law)

    @classmethod
    def switched(cls, base: Model, law: cands.LawSwitch) -> Model:
        """``base`` with the rolling model of ``law``: the same free parameters, the switch's overrides added."""
        return cls(law.name, list(base.dims), {**base.shared, **law.shared}, None, law)

    def overrides(self, u) -> dict:
        """The overrides of the model at unit-cube point ``u`` (d,)."""
        out = dict(self.shared)
        for d, x in zip(self.dims, u):
            out[d.key] = d.value(x)
        return out


def design_points(dims: list[Dim], n: int, seed: int) -> np.ndarray:
    """``n`` design points over ``dims`` in the unit cube, shape (n, len(dims)): a space-filling Latin
    hypercube (:func:`inference.space_filling`) whose coordinates along a parameter that cannot vary between
    the worlds of a launch (a rig parameter such as shape's aspect ratio) are rounded to
    :data:`LAUNCH_LEVELS` values, so that the design costs that many scenes per condition instead of n."""
    U = inf.space_filling(n, len(dims), seed)
    step = 1.0 / (LAUNCH_LEVELS - 1)
    for j, dim in enumerate(dims):
        if not cands.varies_per_world(dim.key):
            U[:, j] = np.round(U[:, j] / step) * step
    return U


@dataclass
class Problem:
    """The data of one diagnosis, arranged for the stages: ``obs`` (one row per measured mean: experiment id,
    response, condition index, mean, replicates n, variance of one measurement, split), the distinct
    ``conditions`` (override dicts) and the training condition indices; per response the simulation's variances:
    ``seed_var`` (over world seeds) and ``rough_var`` (the design runs' scatter about the surrogates beyond it);
    :attr:`sim_var` is one simulated pile's, their sum."""

    spec: DiagnosisSpec
    experiments: Experiments
    obs: pd.DataFrame
    conditions: list[dict]
    seed_var: dict = field(default_factory=dict)
    rough_var: dict = field(default_factory=dict)

    @property
    def sim_var(self) -> dict:
        """Variance of one simulated pile per response: the seed scatter plus the roughness beyond it."""
        return {r: v + self.rough_var.get(r, 0.0) for r, v in self.seed_var.items()}

    @property
    def trend_conditions(self) -> list[str]:
        """The condition columns a residual trend is tested (and plotted) against: numeric, with three or more
        distinct values among the training rows, and not a linear function of an earlier one (a cylinder scaled
        with the grain: its diameter, height and base would repeat the radius's test in the Holm family)."""
        obs = self.obs[self.train]
        keep: list[str] = []
        for c in self.experiments.conditions:
            col = obs[c]
            if not (pd.api.types.is_numeric_dtype(col) and col.nunique() >= 3):
                continue
            x = col.to_numpy(dtype=float)
            if any(abs(np.corrcoef(x, obs[k].to_numpy(dtype=float))[0, 1]) > 1 - 1e-9 for k in keep):
                continue
            keep.append(c)
        return keep

    @property
    def train(self) -> np.ndarray:
        return (self.obs["split"] == "train").to_numpy()

    def budget(self, k_model) -> np.ndarray:
        """Variance (per observation) of measured mean minus model mean: max(s_meas^2, s_sim^2) / n plus
        s_seed^2 / k_model plus s_rough^2 (k_model: the simulations averaged, an array or a number; inf for a
        surrogate)."""
        resp = self.obs["response"]
        s_seed = resp.map(self.seed_var).to_numpy(dtype=float)
        s_sim = resp.map(self.sim_var).to_numpy(dtype=float)
        s_rough = s_sim - s_seed
        one = np.maximum(self.obs["var_one"].to_numpy(dtype=float), s_sim)
        return one / self.obs["n"].to_numpy(dtype=float) + s_seed / np.asarray(k_model, dtype=float) + s_rough


def _problem(spec: DiagnosisSpec, ex: Experiments) -> Problem:
    summ = ex.summary()
    cond_cols = list(ex.conditions)
    keys, conditions, rows = {}, [], []
    pooled = {r: ex.replicate_sd(r) for r in ex.responses}
    for _, e in summ.iterrows():
        ckey = tuple(sp._canon(e[c]) for c in cond_cols)
        if ckey not in keys:
            keys[ckey] = len(conditions)
            conditions.append(ex.overrides(e["id"]))
        for r in ex.responses:
            if not (e[f"n_{r}"] > 0 and np.isfinite(e[r])):
                continue
            sd = e.get(f"sd_{r}", math.nan)
            if not np.isfinite(sd):
                sd = pooled[r][0]
            if not np.isfinite(sd):
                raise DiagnoseError(
                    f"{ex.source}: response {r!r} has no replicates (no id with two or more values) and no "
                    f"sd_{r} column: its measurement noise is unknown; give replicates or the stated SD"
                )
            rows.append(
                {
                    "id": e["id"],
                    "response": r,
                    "condition": keys[ckey],
                    "mean": float(e[r]),
                    "n": int(e[f"n_{r}"]),
                    "var_one": float(sd) ** 2,
                    "split": e["split"],
                    **{c: e[c] for c in cond_cols},
                }
            )
    return Problem(spec, ex, pd.DataFrame(rows), conditions)


# --------------------------------------------------------------------------------------------------
# one model: design, surrogates, calibration, confirmation, held-out
# --------------------------------------------------------------------------------------------------


def _seed(spec: DiagnosisSpec, text: str) -> int:
    """A seed for one stage, derived from the data file's ``seed`` and the stage's name."""
    return int(hashlib.sha1(f"{spec.seed}:{text}".encode()).hexdigest()[:8], 16)


class Evaluator:
    """Runs and evaluates models of one problem (:meth:`evaluate`)."""

    def __init__(self, prob: Problem, sims: Simulations, log):
        self.prob, self.sims, self.log = prob, sims, log
        self.spec = prob.spec
        self.responses = list(prob.experiments.responses)

    @property
    def confirm_seeds(self) -> list[int]:
        """World seeds of every confirming simulation (the screen and the held-out folds use them too)."""
        return [CONFIRM_SEEDS + k for k in range(self.spec.confirm_seeds)]

    def _request(self, model: Model, u, cond: int, seed: int) -> tuple[dict, int]:
        ov = {**self.spec.fixed, **self.prob.conditions[cond], **model.overrides(u)}
        return cands.resolve(ov), seed

    def _values(self, metrics: list[dict]) -> np.ndarray:
        """(len(metrics), responses) response values."""
        return np.array([[response(m, r) for r in self.responses] for m in metrics], dtype=float)

    def design(self, model: Model) -> np.ndarray:
        d = len(model.dims)
        n = self.spec.points or 4 + 4 * d
        return design_points(model.dims, n, _seed(self.spec, f"design:{model.name}"))

    def surrogates(self, model: Model, stage: str, extra: dict | None = None) -> tuple[dict, pd.DataFrame]:
        """Design simulations at every condition and one surrogate per (condition, response); ``extra``
        ({condition: (U (m, d), values (m, responses))}, :meth:`confirmed_points`) joins a condition's design."""
        U = self.design(model)
        C = len(self.prob.conditions)
        reqs = [self._request(model, u, c, DESIGN_SEED) for c in range(C) for u in U]
        mets = self.sims.run(reqs, stage)
        vals = self._values(mets).reshape(C, len(U), len(self.responses))
        gps, acc = {}, []
        for c in range(C):
            Uc, vc = U, vals[c]
            if extra and c in extra:
                Uc, vc = np.vstack([U, extra[c][0]]), np.vstack([vals[c], extra[c][1]])
            for j, r in enumerate(self.responses):
                ok = int(np.isfinite(vals[c, :, j]).sum())
                if ok < len(model.dims) + 2:
                    # a surrogate needs a few points per parameter; name what the failed runs said
                    errs = sorted(
                        {
                            str(v)
                            for m in mets[c * len(U) : (c + 1) * len(U)]
                            for k, v in m.items()
                            if k.endswith("_error")
                        }
                    )
                    raise DiagnoseError(
                        f"{self.spec.path}: the {model.name} model's design simulations measured {r!r} in only {ok} "
                        f"of {len(U)} worlds at conditions {self.prob.conditions[c]}; at least {len(model.dims) + 2} are "
                        f"needed for a surrogate. The runs said: {'; '.join(errs) or 'nothing (no *_error metric)'}"
                    )
                gp = inf.Surrogate(seed=_seed(self.spec, f"gp:{model.name}:{c}:{r}")).fit(Uc, vc[:, j])
                gps[(c, r)] = gp
                acc.append({"model": model.name, "condition": c, "response": r, **gp.cv(), "noise_sd": gp.noise_sd})
        return gps, pd.DataFrame(acc)

    def predictor(self, gps: dict, mask: np.ndarray):
        obs = self.prob.obs[mask]
        pairs = list(zip(obs["condition"], obs["response"]))

        def predict(U):
            U = np.atleast_2d(U)
            mean = np.empty((len(U), len(pairs)))
            var = np.empty_like(mean)
            for k, key in enumerate(pairs):
                m, s = gps[key].predict(U)
                mean[:, k], var[:, k] = m, s**2
            return mean, var

        return predict

    def calibrate(self, model: Model, gps: dict, mask: np.ndarray, tag: str, sample: bool = True) -> dict:
        obs = self.prob.obs[mask]
        var = self.prob.budget(np.inf)[mask]
        return inf.calibrate(
            self.predictor(gps, mask),
            obs["mean"].to_numpy(dtype=float),
            var,
            len(model.dims),
            seed=_seed(self.spec, f"mcmc:{model.name}:{tag}"),
            steps=self.spec.mcmc_steps if sample else 0,  # a fold uses its maximum only
        )

    def confirm_requests(self, model: Model, u, conds) -> list[tuple[dict, int]]:
        """The simulations of :meth:`confirm`: ``model`` at ``u`` at each of ``conds`` over the confirming seeds
        (condition-major)."""
        return [self._request(model, u, c, s) for c in conds for s in self.confirm_seeds]

    def confirm(self, model: Model, u, conds, stage: str) -> dict:
        """Real simulations of ``model`` at ``u`` at conditions ``conds``: {condition: (seeds, responses) values,
        and the full metrics}."""
        seeds = self.confirm_seeds
        mets = self.sims.run(self.confirm_requests(model, u, conds), stage)
        out = {}
        for i, c in enumerate(conds):
            m = mets[i * len(seeds) : (i + 1) * len(seeds)]
            out[c] = {"values": self._values(m), "metrics": m}
        return out

    def _sim_means(self, conf: dict, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Simulated mean and the number of finite simulations per observation of ``mask``."""
        obs = self.prob.obs[mask]
        mean, k = np.full(len(obs), np.nan), np.zeros(len(obs))
        for i, (c, r) in enumerate(zip(obs["condition"], obs["response"])):
            if c in conf:
                v = conf[c]["values"][:, self.responses.index(r)]
                v = v[np.isfinite(v)]
                if len(v):
                    mean[i], k[i] = v.mean(), len(v)
        return mean, k

    def residuals(self, conf: dict, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        sim, k = self._sim_means(conf, mask)
        r = self.prob.obs["mean"].to_numpy(dtype=float)[mask] - sim
        k_all = np.ones(len(self.prob.obs))
        k_all[mask] = np.maximum(k, 1)
        return r, self.prob.budget(k_all)[mask]

    def roughness(self, gps: dict) -> None:
        """Set the problem's ``rough_var`` from the base model's surrogates ``gps`` (on its design alone)."""
        # the world seeds measure the scatter a factory's placement gives; a model whose response is not
        # smooth in its parameters (contact networks rearrange) scatters over them too, which the surrogates'
        # white-noise term measures. One pile scatters by the larger; the excess over the seeds' is fixed at
        # a parameter point, so averaging seeds there does not shrink it. Measured on the space-filling design
        # alone: a refit's confirming runs repeat one parameter point over world seeds, and where the scene
        # ignores the seed (a press) their equal values drove the white-noise term, and with it every
        # model's budget, to nothing (roughness SD 0.0017 against the design's 0.022)
        prob = self.prob
        for r in self.responses:
            seed = prob.seed_var[r]
            nug = float(np.nanmean([gps[(c, r)].noise_sd ** 2 for c in range(len(prob.conditions))]))
            nug = nug if np.isfinite(nug) else 0.0
            prob.rough_var[r] = max(nug - seed, 0.0)

    def fit(self, model: Model, extra: dict | None = None) -> dict:
        """The first half of :meth:`evaluate`, which needs only the design simulations: surrogates and their
        accuracy, the calibration on the training data and on each held-out fold's, and the ``requests`` of
        every confirming simulation those calibrations need (run them together, then :meth:`finish`).
        ``extra``: simulations that join the design (:meth:`surrogates`)."""
        prob = self.prob
        gps, acc = self.surrogates(model, f"{model.name}: design", extra)
        if model.is_base and not extra:
            self.roughness(gps)
        cal = self.calibrate(model, gps, prob.train, "all")
        u_map = np.asarray(cal["map"], dtype=float)
        folds = self.folds()
        fold_maps = [
            None if c is None else np.asarray(self.calibrate(model, gps, fit, f"fold{c}", sample=False)["map"], float)
            for fit, _, c in folds
        ]
        requests = self.confirm_requests(model, u_map, range(len(prob.conditions)))
        for (_, _, c), u in zip(folds, fold_maps):
            if c is not None:
                requests += self.confirm_requests(model, u, [c])
        return {
            "model": model,
            "gps": gps,
            "surrogate_accuracy": acc,
            "calibration": cal,
            "u_map": u_map,
            "folds": folds,
            "fold_maps": fold_maps,
            "requests": requests,
        }

    def finish(self, fitted: dict) -> dict:
        """The rest of :meth:`evaluate` once the confirming simulations of :meth:`fit` have run: confirmation at
        every condition, adequacy on the training data, held-out errors, the likelihood of the training data."""
        prob = self.prob
        train = prob.train
        model, cal, u_map = fitted["model"], fitted["calibration"], fitted["u_map"]
        conf = self.confirm(model, u_map, range(len(prob.conditions)), f"{model.name}: confirm")
        r, var = self.residuals(conf, train)
        obs_t = prob.obs[train]
        cond_df = obs_t[prob.trend_conditions].astype(float)
        cond_df.index = obs_t["id"].to_numpy()
        labels = obs_t["response"].to_numpy()
        ok = np.isfinite(r)
        if not ok.all():
            bad = obs_t[~ok]
            raise DiagnoseError(
                f"{self.spec.path}: the {model.name} model's confirming simulations could not measure "
                f"{', '.join(sorted(set(bad['response'])))} at experiment(s) {', '.join(map(str, bad['id']))}"
            )
        adequacy = inf.adequacy(r, var, len(model.dims), cond_df, labels, self.spec.alpha)
        loglik = float(-np.sum(inf.gaussian_nll(r[ok], var[ok])))
        out = {k: fitted[k] for k in ("model", "gps", "surrogate_accuracy", "calibration", "u_map")}
        out["surrogate_check"] = fitted.get("surrogate_check")
        out.update(
            theta={d.name: d.value(x) for d, x in zip(model.dims, u_map)},
            interval={
                d.name: (d.value(lo), d.value(hi)) for d, (lo, hi) in zip(model.dims, np.asarray(cal["interval"]))
            },
            confirm=conf,
            residual=r,
            variance=var,
            adequacy=adequacy,
            loglik=loglik,
            n_train=int(ok.sum()),
            held_out=self.held_out(model, fitted["folds"], fitted["fold_maps"], conf),
        )
        return out

    def evaluate(self, models: list[Model], stage: str, dropped: dict | None = None) -> list[dict]:
        """Everything about each of ``models`` (:meth:`fit`, then :meth:`finish`); their confirming simulations
        go in one request, so that models that can share launches do. A model whose confirming simulations
        miss its surrogates (:meth:`surrogate_check`) is refitted once with them joining its design, and
        confirmed again at the new calibration. With ``dropped`` (a dict), a model whose simulations cannot
        measure a response at its calibration is left out, its reason recorded there, instead of stopping
        the diagnosis (a candidate at the edge of its range may pack no measurable core)."""
        if dropped is not None:
            kept = []
            for m in models:
                try:
                    kept.append(self.fit(m))
                except DiagnoseError as e:
                    dropped[m.name] = str(e)
            return self._evaluate_fitted(kept, stage, dropped)
        return self._evaluate_fitted([self.fit(m) for m in models], stage, None)

    def _evaluate_fitted(self, fitted: list[dict], stage: str, dropped: dict | None) -> list[dict]:
        self.sims.run([q for f in fitted for q in f["requests"]], stage)
        again = []
        for i, f in enumerate(fitted):
            check = self.surrogate_check(f)
            if check["refine"]:
                fitted[i] = self.fit(f["model"], extra=self.confirmed_points(f))
                again.append(fitted[i])
            fitted[i]["surrogate_check"] = check
        if again:
            self.sims.run([q for f in again for q in f["requests"]], f"{stage} (refined)")
        if dropped is None:
            return [self.finish(f) for f in fitted]
        out = []
        for f in fitted:
            try:
                out.append(self.finish(f))
            except DiagnoseError as e:
                dropped[f["model"].name] = str(e)
        return out

    def _confirmed(self, fitted: dict) -> list[tuple[int, np.ndarray, np.ndarray]]:
        """(condition, u (d,), values (seeds, responses)) of every confirming simulation of ``fitted``: the
        calibration at every condition, each fold's at its held-out condition (already run)."""
        C = range(len(self.prob.conditions))
        conf = self.confirm(fitted["model"], fitted["u_map"], C, f"{fitted['model'].name}: confirm")
        out = [(c, fitted["u_map"], conf[c]["values"]) for c in C]
        for (_, _, c), u in zip(fitted["folds"], fitted["fold_maps"]):
            if c is not None:
                fconf = self.confirm(fitted["model"], u, [c], f"{fitted['model'].name}: held-out")
                out.append((c, u, fconf[c]["values"]))
        return out

    def confirmed_points(self, fitted: dict) -> dict:
        """Every confirming simulation of ``fitted`` as extra design points: {condition: (U (m, d), values
        (m, responses))}."""
        out: dict = {}
        for c, u, v in self._confirmed(fitted):
            U = np.repeat(np.asarray(u, dtype=float)[None], len(v), axis=0)
            if c in out:
                U, v = np.vstack([out[c][0], U]), np.vstack([out[c][1], v])
            out[c] = (U, v)
        return out

    def surrogate_check(self, fitted: dict) -> dict:
        """Do the real simulations at the calibrated point agree with the surrogates' prediction there? Over every
        (condition, response) with a finite confirmed mean of k runs: z = (mean - prediction) / sqrt(surrogate
        variance + s_sim^2 / k), and sum z^2 against chi-square with one degree of freedom per pair. ``refine``
        when p < alpha: a space-filling design of tens of points can miss a step (a rod's sphere count changes
        with its aspect ratio) or a narrow valley by more than its own predictive variance says, and the MAP
        then sits where the surrogate, not the model, fits the data. Returns statistic, df, p, refine and the
        largest |z|."""
        u = fitted["u_map"]
        sim_var = self.prob.sim_var
        zs = []
        for c, uc, v in self._confirmed(fitted)[: len(self.prob.conditions)]:
            for j, r in enumerate(self.responses):
                x = v[:, j][np.isfinite(v[:, j])]
                if not len(x):
                    continue
                m, sd = fitted["gps"][(c, r)].predict(np.asarray(uc)[None])
                zs.append((x.mean() - m[0]) / math.sqrt(sd[0] ** 2 + sim_var.get(r, 0.0) / len(x)))
        zs = np.asarray(zs, dtype=float)
        stat = float(np.sum(zs**2))
        p = _noise_p(zs**2)
        return {
            "statistic": stat,
            "df": int(len(zs)),
            "p": p,
            "refine": bool(p < self.spec.alpha),
            "max_abs_z": float(np.max(np.abs(zs))) if len(zs) else math.nan,
            "u_map": np.asarray(u, dtype=float).tolist(),
        }

    def folds(self) -> list[tuple[np.ndarray, np.ndarray, int | None]]:
        """(fit mask, held-out mask, held-out condition or None) per fold: the data's split, or each training
        condition left out in turn."""
        obs = self.prob.obs
        train = self.prob.train
        test = ~train
        if test.any():
            # the data's split: one fold, the test experiments simulated at the training calibration
            return [(train, test, None)]
        conds = sorted(set(obs.loc[train, "condition"]))
        if len(conds) < 2:
            return []
        return [
            (train & (obs["condition"] != c).to_numpy(), train & (obs["condition"] == c).to_numpy(), c) for c in conds
        ]

    def held_out(self, model: Model, folds: list, fold_maps: list, conf: dict) -> pd.DataFrame | None:
        """Standardised errors of each fold's held-out experiments, simulated at the fold's calibration
        (``fold_maps``; None: the training calibration, whose confirmation ``conf`` is)."""
        if not folds:
            return None
        parts = []
        for (_, test, c), u in zip(folds, fold_maps):
            fconf = conf if c is None else self.confirm(model, u, [c], f"{model.name}: held-out")
            r, var = self.residuals(fconf, test)
            part = self.prob.obs[test][["id", "response", "condition"]].copy()
            part["residual"], part["variance"] = r, var
            parts.append(part)
        out = pd.concat(parts, ignore_index=True)
        out["sq"] = out["residual"] ** 2 / out["variance"]
        out["nll"] = inf.gaussian_nll(out["residual"].to_numpy(), out["variance"].to_numpy())
        return out

    def design_requests(self, models: list[Model]) -> list[tuple[dict, int]]:
        """The design simulations of ``models`` at every condition."""
        C = len(self.prob.conditions)
        return [self._request(m, u, c, DESIGN_SEED) for m in models for c in range(C) for u in self.design(m)]

    def jacobian(self, gps: dict, mask: np.ndarray, u_map, h: float = 0.05) -> np.ndarray:
        """d(prediction)/d(u) of the surrogates at ``u_map`` by central differences, (n_obs, d)."""
        predict = self.predictor(gps, mask)
        d = len(u_map)
        J = np.zeros((int(mask.sum()), d))
        for i in range(d):
            a, b = u_map.copy(), u_map.copy()
            a[i], b[i] = max(u_map[i] - h, 0.0), min(u_map[i] + h, 1.0)
            J[:, i] = (predict(b[None])[0][0] - predict(a[None])[0][0]) / (b[i] - a[i])
        return J


# --------------------------------------------------------------------------------------------------
# the diagnosis
# --------------------------------------------------------------------------------------------------


def _scatter_requests(ev: Evaluator, base: Model) -> list[tuple[dict, int]]:
    """The simulations of :func:`_sim_scatter`: the centre of the ranges at every training condition, over
    ``sim_seeds`` world seeds (condition-major)."""
    prob = ev.prob
    conds = sorted(set(prob.obs.loc[prob.train, "condition"]))
    centre = np.full(len(base.dims), 0.5)
    return [ev._request(base, centre, c, CENTRE_SEEDS + k) for c in conds for k in range(ev.spec.sim_seeds)]


def _sim_scatter(ev: Evaluator, base: Model) -> dict:
    """Pooled SD of the responses over world seeds at the centre of the ranges, at every training condition:
    {response: variance}."""
    reqs = _scatter_requests(ev, base)
    vals = ev._values(ev.sims.run(reqs, "noise: simulation scatter")).reshape(-1, ev.spec.sim_seeds, len(ev.responses))
    conds = range(vals.shape[0])
    out = {}
    for j, r in enumerate(ev.responses):
        out[r] = inf.pooled_variance(vals[c, :, j] for c in conds)[0]
        if not np.isfinite(out[r]):
            raise DiagnoseError(
                f"{ev.spec.path}: the simulations could not measure {r!r} at the centre of the parameter ranges "
                f"(values {vals[:, :, j].tolist()}); check the scene and the response"
            )
    return out


def screen(ev: Evaluator, base_eval: dict, gps: dict, lib: list[cands.Candidate]) -> list[dict]:
    """Each candidate's effect at the calibrated point against the base residuals (:func:`inference.screen`); the
    candidates' simulations go in one request, so that those that can share launches do."""
    prob = ev.prob
    train = prob.train
    u = base_eval["u_map"]
    conds = sorted(set(prob.obs.loc[train, "condition"]))
    moved = []
    for cand in lib:
        test = dict(cand.shared)
        test[cand.key] = cand.test_value
        moved.append(Model(cand.name, list(base_eval["model"].dims), test))
    ev.sims.run([q for m in moved for q in ev.confirm_requests(m, u, conds)], "screen")
    sim_b, _ = ev._sim_means(base_eval["confirm"], train)
    J = ev.jacobian(gps, train, u)
    r, var = base_eval["residual"], base_eval["variance"]
    out = []
    for cand, m in zip(lib, moved):
        sim_c, _ = ev._sim_means(ev.confirm(m, u, conds, f"screen: {cand.name}"), train)
        effect = sim_c - sim_b
        ok = np.isfinite(effect) & np.isfinite(r)  # a candidate run that could not measure drops out
        res = inf.screen(r[ok], var[ok], J[ok], effect[ok])
        if not cand.off_at_edge:
            # an interior off value: the candidate may move either way; screen both directions
            res2 = inf.screen(r[ok], var[ok], J[ok], -effect[ok])
            if res2["delta_chi2"] > res["delta_chi2"]:
                res = res2
        out.append({"candidate": cand.name, "test_value": cand.test_value, "effect": effect, **res})
    return out


def _boot(losses: dict, seed: int) -> dict:
    """:func:`inference.bootstrap` as {"mean": {model: mean}, "interval": {model: (low, high)}, "difference":
    {(a, b): (low, high) of mean a - mean b}}."""
    b = inf.bootstrap(losses, seed=seed)
    out = {"mean": {}, "interval": {}, "difference": {}}
    for _, m in b["models"].iterrows():
        out["mean"][m["model"]] = float(m["mean"])
        out["interval"][m["model"]] = (float(m["low"]), float(m["high"]))
    for _, p in b["pairs"].iterrows():
        out["difference"][(p["model_a"], p["model_b"])] = (float(p["low"]), float(p["high"]))
        out["difference"][(p["model_b"], p["model_a"])] = (-float(p["high"]), -float(p["low"]))
    return out


def _lrt(base: dict, ext: dict, cand: cands.Candidate) -> tuple[float, float]:
    from scipy import stats

    if cand.off_at_edge:
        return inf.lrt_boundary(base["loglik"], ext["loglik"])
    lr = max(2.0 * (ext["loglik"] - base["loglik"]), 0.0)
    return lr, float(stats.chi2.sf(lr, 1)) if lr > 0 else 1.0


def _evidence(a: pd.DataFrame, b: pd.DataFrame) -> float:
    """Summed held-out log predictive likelihood of ``b`` over ``a`` [nats] (both on the same held-out rows)."""
    return float(a["nll"].sum() - b["nll"].sum())


def verdict(base: dict, results: list[dict], alpha: float, seed: int) -> dict:
    """The fixed naming rule (module docstring) over the recalibrated candidates ``results``."""
    held_base = base["held_out"]
    rows = []
    for res in results:
        c = res["model"].candidate
        stat, p = _lrt(base, res, c)
        lo, hi = res["interval"][c.name]
        excludes = not (lo <= c.off <= hi)
        row = {
            "candidate": c.name,
            "lrt": stat,
            "p": p,
            "aic": inf.aic(res["loglik"], len(res["model"].dims)),
            "bic": inf.bic(res["loglik"], len(res["model"].dims), res["n_train"]),
            "estimate": res["theta"][c.name],
            "interval": (lo, hi),
            "excludes_off": excludes,
            "adequate": bool(res["adequacy"]["adequate"]),
            "held_out_nll": math.nan,
            "beats_base": None,
        }
        if held_base is not None and res["held_out"] is not None:
            boot = _boot({"base": held_base["nll"].to_numpy(), c.name: res["held_out"]["nll"].to_numpy()}, seed)
            row["held_out_nll"] = boot["mean"][c.name]
            row["gain_interval"] = boot["difference"][("base", c.name)]
            row["held_out_evidence"] = _evidence(held_base, res["held_out"])
            row["beats_base"] = row["held_out_evidence"] > EVIDENCE
        rows.append(row)
    contenders = [r for r in rows if r["p"] < alpha and r["beats_base"] in (True, None)]
    out = {"table": rows, "verdict": "unexplained", "cause": None, "tied": []}
    if not contenders:
        return out
    if held_base is not None:
        contenders.sort(key=lambda r: r["held_out_nll"])
    else:
        contenders.sort(key=lambda r: r["aic"])
    best = contenders[0]
    by_name = {res["model"].candidate.name: res for res in results}
    tied = []
    for other in contenders[1:]:
        if held_base is None:
            # no held-out data: only the training likelihood, penalised for parameters, can separate them
            if (other["aic"] - best["aic"]) / 2.0 <= EVIDENCE:
                tied.append(other["candidate"])
            continue
        held = by_name[other["candidate"]]["held_out"], by_name[best["candidate"]]["held_out"]
        if _evidence(*held) <= EVIDENCE:
            tied.append(other["candidate"])
    if tied:
        out.update(verdict="ambiguous", tied=[best["candidate"], *tied])
    elif best["excludes_off"] and best["adequate"]:
        out.update(verdict="cause", cause=best["candidate"])
    else:
        out["best"] = best["candidate"]
    return out


def separating_measurement(prob: Problem, results: dict, names: list[str]) -> list[dict]:
    """Rank the measurements of :data:`SEPARATING` the data do not hold by how far the calibrated models
    ``names`` apart predict them: per condition |difference of means| / its standard error (from the
    confirming simulations' seed scatter), averaged over the conditions; best first."""
    have = set(prob.experiments.responses)
    scores = []
    for metric in SEPARATING:
        if metric in have:
            continue
        per = []
        for c in range(len(prob.conditions)):
            vals = []
            for n in names[:2]:
                conf = results[n]["confirm"].get(c)
                v = np.array([response(m, metric) for m in conf["metrics"]]) if conf else np.array([])
                vals.append(v[np.isfinite(v)])
            a, b = vals
            if len(a) < 2 or len(b) < 2:
                continue
            se = math.sqrt(a.var(ddof=1) / len(a) + b.var(ddof=1) / len(b))
            diff = abs(a.mean() - b.mean())
            per.append(diff / se if se > 0 else (math.inf if diff > 0 else 0.0))
        if per:
            scores.append({"measurement": metric, "z": float(np.mean(per)), "conditions": len(per)})
    return sorted(scores, key=lambda s: -s["z"])


def _rms(base_sq: np.ndarray, ext_sq: np.ndarray, seed: int) -> dict:
    """Root mean square of the base's and the extended model's squared held-out errors, with bootstrap intervals
    (paired over the held-out rows), and the extended model's reduction."""
    boot = _boot({"base": base_sq, "extended": ext_sq}, seed)
    rb, re_ = math.sqrt(base_sq.mean()), math.sqrt(ext_sq.mean())
    return {
        "base": rb,
        "extended": re_,
        "base_interval": tuple(math.sqrt(max(x, 0.0)) for x in boot["interval"]["base"]),
        "extended_interval": tuple(math.sqrt(max(x, 0.0)) for x in boot["interval"]["extended"]),
        "reduction": 1.0 - re_ / rb if rb > 0 else math.nan,
    }


def _noise_p(sq: np.ndarray) -> float:
    """Chi-square p of standardised squared errors ``sq`` (n,) against the noise budget, on n degrees of freedom:
    for errors of rows nothing was fitted to (held-out experiments, confirming runs against their surrogates).
    Small: the errors are more than the noise explains; 1 with no rows (no evidence of a misfit)."""
    from scipy import stats

    return float(stats.chi2.sf(float(np.sum(sq)), len(sq))) if len(sq) else 1.0


def gain(prob: Problem, base: dict, ext: dict, seed: int) -> dict:
    """Held-out RMSE (per response, in its units), RMS standardised error (``z_rms``, over every response; each
    error over its noise-budget SD) and NLL of the base and the extended model, with bootstrap intervals over the
    held-out experiments, and how far the base parameters moved. Each RMSE and ``z_rms`` also carries
    ``noise_p`` {"base", "extended"}: the chi-square p of its held-out errors against the noise budget. A gain is
    confirmed when the base's errors exceed the noise and the extended model's do not; how large the reduction is
    depends on how far the hidden effect moves the response against the noise, so the reduction alone cannot
    say it. (With a handful of held-out rows a bootstrap interval of the fall is no test: from three rows its
    2.5 % bound is the smallest row's fall.)"""
    hb, he = base["held_out"], ext["held_out"]
    out = {"rmse": {}, "z_rms": None, "nll": None, "shift": {}}
    if hb is not None and he is not None:
        # one held-out error over every response: the root mean square of the standardised errors
        out["z_rms"] = _rms(hb["sq"].to_numpy(), he["sq"].to_numpy(), seed)
        out["z_rms"]["noise_p"] = {"base": _noise_p(hb["sq"].to_numpy()), "extended": _noise_p(he["sq"].to_numpy())}
        for r in sorted(set(hb["response"])):
            mb, me = (hb["response"] == r).to_numpy(), (he["response"] == r).to_numpy()
            a = hb.loc[mb, "residual"].to_numpy() ** 2
            b = he.loc[me, "residual"].to_numpy() ** 2
            out["rmse"][r] = _rms(a, b, seed)
            out["rmse"][r]["noise_p"] = {
                "base": _noise_p(hb.loc[mb, "sq"].to_numpy()),
                "extended": _noise_p(he.loc[me, "sq"].to_numpy()),
            }
        boot = _boot({"base": hb["nll"].to_numpy(), "extended": he["nll"].to_numpy()}, seed)
        out["nll"] = {
            "base": boot["mean"]["base"],
            "extended": boot["mean"]["extended"],
            "base_interval": boot["interval"]["base"],
            "extended_interval": boot["interval"]["extended"],
            "difference_interval": boot["difference"][("base", "extended")],
        }
    for d in base["model"].dims:
        b, e = base["theta"][d.name], ext["theta"][d.name]
        lo, hi = base["interval"][d.name]
        out["shift"][d.name] = {"base": b, "extended": e, "shift": e - b, "base_interval": (lo, hi)}
    return out


def step_checks(runs_dir) -> dict:
    """How many of the stored worlds under ``runs_dir`` stepped past the stable step of their stiffest contact in
    some tick (``info.step_warning``, as a study's run checks flag it): {"worlds", "over_stable_step",
    "worst_step_margin"} (the largest ``step_margin_max`` among those, or None). Leapfrog beyond its stability
    limit makes a world's figures less trustworthy; a diagnosis built on them must say so."""
    worlds = over = 0
    worst = None
    for f in sorted(Path(runs_dir).glob("*.json")):
        with open(f) as fh:
            info = json.load(fh).get("info", {})
        worlds += 1
        if info.get("step_warning"):
            over += 1
            m = float(info.get("step_margin_max", math.nan))
            worst = m if worst is None or m > worst else worst
    return {"worlds": worlds, "over_stable_step": over, "worst_step_margin": worst}


def diagnose(
    source,
    out_dir=None,
    device: str = "cpu",
    progress: bool = True,
    log=print,
    stop_after: float = 0.0,
    scheduler: str | None = None,
    shared_dir: str | None = None,
) -> dict:
    """Diagnose the data file ``source`` (a path, or a (DiagnosisSpec, Experiments) pair) into ``out_dir``
    (default ``runs/diagnose/<name>``): report.md, diagnosis.json and PNGs (:mod:`.report`). Resumable: every
    simulation is stored as it finishes and a rerun reuses it. ``device`` is any a study accepts (one device,
    or a comma-separated list, launches then spread over them). With ``stop_after`` [wall s] the diagnosis
    stops once that much time has passed (a launch saves its checkpoint); the same call resumes. Returns the
    diagnosis (as written to diagnosis.json) plus ``out``, ``wall_s``, ``worlds``, ``launches`` and ``stopped``.
    ``scheduler`` (else ``WARPDEM_SCHEDULER``): a Dask scheduler's address, whose cluster then runs every launch
    (as for :func:`warpdem.study.execute.run_study`); several devices of this host are a local cluster, kept for
    the whole diagnosis; ``shared_dir`` as for a study."""
    from warpdem.scene.runner import RunStopped

    spec, ex = load_diagnosis(source) if not isinstance(source, tuple) else source
    out = Path(out_dir) if out_dir else Path("runs") / "diagnose" / spec.name
    # the folder's lock for the whole diagnosis (a second one on it is refused); whole copies (a start cut short
    # leaves none, and the next overwrites them)
    with hold(out, f"diagnosis {spec.name}") as lock:
        if lock.took_over:
            log(lock.took_over)
        if spec.path is not None:
            copy_atomic(spec.path, out / "data.toml")
            copy_atomic(ex.source, out / "experiments.csv")
        study = spec.study(list(ex.responses))
        sims = Simulations(study, out, execute.parse_devices(device), progress, log, stop_after)
        sims.scheduler = scheduler
        sims.shared_dir = shared_dir
        t0 = time.perf_counter()
        prob = _problem(spec, ex)
        ev = Evaluator(prob, sims, log)
        base = Model("base", [Dim(p.name, p.parameter, p.low, p.high, p.unit) for p in spec.parameters])
        result: dict = {"name": spec.name, "out": str(out), "stopped": None}
        try:
            # the scatter and the base design need nothing else: one request, so that they share launches
            sims.run(_scatter_requests(ev, base) + ev.design_requests([base]), "base: scatter and design")
            prob.seed_var = _sim_scatter(ev, base)
            if training_values(ex) <= len(spec.parameters):
                result.update(_reach(ev, base, spec, ex, out, log))
            else:
                result.update(_full(ev, base, spec, ex, out, log))
        except (RunStopped, Stopped) as e:
            result["stopped"] = str(e)
            log(f"{spec.name}: stopped; {e}")
        finally:
            sims.close()
        result["wall_s"] = time.perf_counter() - t0
        result["worlds"] = len(list((out / "runs").glob("*.json")))
        result["launches"] = sims.launched
        return result


def _full(ev: Evaluator, base: Model, spec: DiagnosisSpec, ex: Experiments, out: Path, log) -> dict:
    """Stages 2 to 5 of the module docstring once the noise budget is set; writes the report, returns the
    diagnosis."""
    from .report import write

    prob, sims = ev.prob, ev.sims
    (base_eval,) = ev.evaluate([base], "base: confirm")
    evals = {"base": base_eval}
    screens, skipped, results, decision = [], {}, [], None
    if base_eval["adequacy"]["adequate"]:
        decision = {"verdict": "adequate", "cause": None, "tied": [], "table": []}
    else:
        lib, skipped = _library(spec, ex, prob.conditions)
        screens = screen(ev, base_eval, base_eval["gps"], lib) if lib else []
        passed = sorted([s for s in screens if s["p"] < spec.alpha], key=lambda s: -s["delta_chi2"])
        models = []
        for s in passed:
            c = next(c for c in lib if c.name == s["candidate"])
            models.append(Model.extended(base, c))
        if models:
            sims.run(ev.design_requests(models), "candidates: design")
            failed: dict = {}
            results = ev.evaluate(models, "candidates: confirm", dropped=failed)
            for name, why in failed.items():
                log(f"{spec.name}: candidate {name} left out: {why}")
                skipped[name] = f"recalibrated, then left out: {why}"
            evals.update({r["model"].name: r for r in results})
        decision = verdict(base_eval, results, spec.alpha, _seed(spec, "bootstrap"))
    separating = []
    if decision["verdict"] == "ambiguous":
        separating = separating_measurement(prob, evals, decision["tied"])
    named = decision.get("cause") or (decision["tied"][0] if decision["tied"] else decision.get("best"))
    gains = gain(prob, base_eval, evals[named], _seed(spec, "gain")) if named else None
    return write(
        out,
        prob,
        evals,
        decision,
        screens=screens,
        skipped=skipped,
        separating=separating,
        gains=gains,
        checks=step_checks(out / "runs"),
    )


def _reach(ev: Evaluator, base: Model, spec: DiagnosisSpec, ex: Experiments, out: Path, log) -> dict:
    """The diagnosis of data with no more measured values than free parameters (:mod:`.reach`)."""
    from . import reach

    results, decision = reach.run(ev, base, spec, ex, log)
    return reach.write(out, ev.prob, results, decision, checks=step_checks(out / "runs"))


def _taken(spec: DiagnosisSpec, ex: Experiments) -> set[str]:
    """The override keys the data file decides: its free parameters, conditions and ``[fixed]`` keys."""
    return {p.parameter for p in spec.parameters} | set(ex.conditions) | set(spec.fixed)


def _condition_scenes(spec: DiagnosisSpec, conditions: list[dict]):
    """Per condition (override dicts), the base model's scene (a SceneSpec with every value the condition's runs
    have, per-world keys included: a launch's shared scene lacks those) and its rig parameters (None for a stage
    without a rig)."""
    from warpdem.scene import rigs
    from warpdem.scene.stage import apply_overrides

    for cond in conditions:
        ov = {**spec.fixed, **cond}
        rig_cond = {k: v for k, v in cond.items() if sp.is_rig_key(k)}
        scene = apply_overrides(sp.fixed_scene(spec, rig_cond), {k: v for k, v in cond.items() if k not in rig_cond})
        rig_params = None
        if spec.rig is not None:
            base = dict(rigs.SMOKE[spec.rig]) if spec.smoke else {}
            base.update({k: v for k, v in ov.items() if sp.is_rig_key(k)})
            p = rigs.params(spec.rig, base)
            rig_params = {f: getattr(p, f) for f in p.__dataclass_fields__}
        yield scene, rig_params


def _laws(spec: DiagnosisSpec, ex: Experiments, conditions: list[dict]) -> tuple[list, str | None]:
    """The rolling models the reach diagnosis tries when the base is OVERDISPERSED
    (:func:`candidates.rolling_alternatives`, the same for every condition), and None; or ([], why not)."""
    if spec.candidates is not None and "rolling_model" not in spec.candidates:
        return [], "not in the data file's [candidates] use list"
    taken = _taken(spec, ex)
    found = None
    for scene, _ in _condition_scenes(spec, conditions):
        laws, why = cands.rolling_alternatives(scene, taken)
        if why:
            return [], why
        if found is not None and laws != found:
            return [], "the grain's rolling model or its pairs differ between the experiments"
        found = laws
    return found or [], None


def _strength(spec: DiagnosisSpec, ex: Experiments, conditions: list[dict]) -> tuple:
    """The cohesion_strength candidate the reach diagnosis pairs with each rolling model
    (:func:`candidates.cohesion_strength`, the same for every condition; its range as the data file's ``[candidates]
    ranges`` says), and None; or (None, why not)."""
    if spec.candidates is not None and "cohesion_strength" not in spec.candidates:
        return None, "not in the data file's [candidates] use list"
    taken = _taken(spec, ex)
    found = None
    for scene, _ in _condition_scenes(spec, conditions):
        cand, why = cands.cohesion_strength(scene, taken)
        if why:
            return None, why
        if found is not None and cand != found:
            return None, "the grain's surface energy differs between the experiments"
        found = cand
    return (_user_range(spec, found) if found is not None else None), None


def _user_range(spec: DiagnosisSpec, c: cands.Candidate) -> cands.Candidate:
    """``c`` over the data file's ``[candidates] ranges`` entry for it, when there is one."""
    if c.name not in spec.candidate_ranges:
        return c
    lo, hi = spec.candidate_ranges[c.name]
    try:
        return cands.with_range(c, lo, hi)
    except ValueError as e:
        raise DiagnoseError(f"{spec.path}: [candidates] ranges.{c.name} = [{lo}, {hi}]: {e}") from None


def _library(spec: DiagnosisSpec, ex: Experiments, conditions: list[dict]) -> tuple[list, dict]:
    """The candidates that apply (the data file's ``use`` list, ranges replaced as it says). A range that
    depends on the scene (cohesion's, through the grain's weight) is the narrowest over the conditions: its
    bound then holds for every grain of the data (the widest gave the smallest grains of a size series Bond
    numbers of 25, piles that stand as columns and cannot be measured)."""
    taken = _taken(spec, ex)
    merged: dict[str, cands.Candidate] = {}
    skipped: dict[str, str] = {}
    differs: dict[str, str] = {}
    for scene, rig_params in _condition_scenes(spec, conditions):
        lib, skipped = cands.library(scene, rig_params, taken, spec.grain_radius)
        for c in lib:
            m = merged.get(c.name)
            if m is not None and m.shared != c.shared:
                # coarse-graining's size ratio (or the scene's surface energy) differs between experiments
                differs[c.name] = f"{', '.join(k for k in c.shared if m.shared.get(k) != c.shared[k])} differs"
            merged[c.name] = c if m is None else cands.with_range(m, max(m.low, c.low), min(m.high, c.high))
    for name, why in differs.items():
        del merged[name]
        skipped[name] = f"{why} between the experiments: one scaling rule cannot be read from them"
    lib = [merged[n] for n in cands.CANDIDATE_NAMES if n in merged]
    if spec.candidates is not None:
        for c in lib:
            if c.name not in spec.candidates:
                skipped[c.name] = "not in the data file's [candidates] use list"
        lib = [c for c in lib if c.name in spec.candidates]
    return [_user_range(spec, c) for c in lib], skipped
