"""What a diagnosis can say when the data hold no more measured values than the model has free parameters (a
seed's one angle of repose): whether the base model reaches the data at all, and which candidates do.

With n measured values and k >= n free parameters a calibration fits any data the model can reach, exactly, so
no adequacy test and no held-out comparison exists (:mod:`.pipeline` needs more values than parameters). What
one number can still test is reach. Stages (the simulations stored and reused as in :mod:`.pipeline`):

1. **Noise budget and the base model's design**, as in a full diagnosis (:mod:`.pipeline`, stages 1 and 2).
2. **Reach of a model.** On its surrogates, the point that brings the data closest (the maximum of the Gaussian
   likelihood, :func:`inference.calibrate` without sampling) and, over a dense space-filling cover of the
   parameter box, the range each measured value's prediction spans and the part of the box whose predictions fit
   (chi-square over the n values with n degrees of freedom, p >= alpha: nothing is subtracted for fitted
   parameters, since the test asks whether any point fits, and one that fits exactly scores 0). Then real
   simulations at the closest point (the confirming world seeds): the same chi-square from their means against
   the noise budget. The model **reaches** the data when that confirmed p-value is at least alpha.
3. **Repeatability** (:func:`repeatability`). The base model's scatter over the confirming world seeds at its
   closest point against the measurement's (its replicates' pooled SD, or the stated SD), one-sided
   (:func:`inference.scatter_excess`), Holm-corrected over the responses. The noise budget takes the larger of
   the two scatters, so a model whose piles scatter far more than the material's reaches any mean near its own;
   this is the one model error a single mean can still show.
4. **The verdict** (:data:`VERDICTS`). The base reaches the data and repeats no worse than the measurement: NOT
   TESTABLE (no evidence of a model error, and none could show in the mean). It reaches the data but scatters
   more: OVERDISPERSED (a model error; the candidates, judged by the mean, are not tried). Then each other rolling
   model of the grain (:func:`candidates.rolling_alternatives`: a discrete switch, the same free parameters) is
   taken through stage 2 and judged by its scatter (:func:`try_laws`): one that reaches the data, repeats no worse
   than the measurement and scatters significantly less than the base (one-sided F, Holm over the laws and
   responses) is named the cause; the verdict stays OVERDISPERSED, since the base model is what was tested. When
   none repeats alone, each is tried again with the cohesion weakened by a free factor
   (:func:`candidates.cohesion_strength`), a two-change model judged by the same rule. It does not reach: every
   candidate of the library is taken through stage 2 with its parameter added. One reaches: it is the only one
   (named by reach alone, never by held-out data, which one value cannot give); several: NOT IDENTIFIABLE, with
   the measurement that best separates them (:func:`pipeline.separating_measurement`); none: UNEXPLAINED.
   Each model that reaches the data gives its predictions of the measurements the data lack
   (:func:`predictions`): the held-out test to make next.

The gain of a candidate is measured on the confirming simulations at each model's closest point: the base's
misfit against the candidate's, in the response's unit and in noise-budget SDs. It is a gain on the data fitted,
not on held-out data; the report says so.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from warpdem.scene.export import save_figure

from . import candidates as cands
from . import inference as inf

DENSE = 4096
"""Points of the space-filling cover of a model's parameter box on which its reach is read off its surrogates."""

VERDICTS = ("not_testable", "overdispersed", "only_one_reaches", "not_identifiable", "unexplained")
"""The verdicts of a reach diagnosis (diagnosis.json's ``verdict``, with ``mode`` "reach")."""

WORDS = {
    "not_testable": "NOT TESTABLE: the base model reaches the data; no evidence of a model error, and with no more "
    "measured values than free parameters none could show",
    "overdispersed": "OVERDISPERSED: the base model reaches the data's mean, but its runs there scatter more than the "
    "measurement repeats ({scatter}): a model error one mean cannot show; the candidates, judged by the mean, are "
    "not tried; {laws}",
    "only_one_reaches": "OUT OF REACH of the base model; only {names} reaches the data (named by reach alone: one "
    "value per free parameter leaves no held-out test)",
    "not_identifiable": "NOT IDENTIFIABLE: out of reach of the base model; {names} each reach the data, and these "
    "data cannot tell them apart",
    "unexplained": "UNEXPLAINED: out of reach of the base model and of every candidate tried",
}
"""One line per verdict (``{names}``: the candidates that reach the data; ``{scatter}``: the responses that scatter
more, :func:`scatter_words`; ``{laws}``: what the rolling models tried by their scatter showed, :func:`law_words`),
for the report and the CLI."""


def fit(ev, model) -> dict:
    """Stage 2 on the surrogates: the closest point ``u`` (d,) in the unit box, its surrogate chi-square and
    p-value, the span (low, high) of each training value's prediction over the box, the part of each parameter's
    range (physical units) where the prediction fits, and the confirming simulations' ``requests``."""
    from scipy import stats

    from .pipeline import _seed

    prob, mask = ev.prob, ev.prob.train
    gps, _ = ev.surrogates(model, f"{model.name}: design")
    if model.is_base:
        ev.roughness(gps)
    y = prob.obs.loc[mask, "mean"].to_numpy(dtype=float)
    var = prob.budget(np.inf)[mask]
    u = np.asarray(ev.calibrate(model, gps, mask, "reach", sample=False)["map"], dtype=float)
    d = len(model.dims)
    U = np.vstack([inf.space_filling(DENSE, d, _seed(ev.spec, f"reach:{model.name}")), ev.design(model), u[None]])
    mean, gvar = ev.predictor(gps, mask)(U)
    chi = (((y - mean) ** 2) / (var + gvar)).sum(axis=1)
    p = stats.chi2.sf(chi, len(y))
    fits = p >= ev.spec.alpha
    region = {
        dim.name: (dim.value(U[fits, j].min()), dim.value(U[fits, j].max())) if fits.any() else None
        for j, dim in enumerate(model.dims)
    }
    return {
        "model": model,
        "u": u,
        "surrogate_chi2": float(chi[-1]),
        "surrogate_p": float(p[-1]),
        "span": [(float(lo), float(hi)) for lo, hi in zip(mean.min(axis=0), mean.max(axis=0))],
        "region": region,
        "requests": ev.confirm_requests(model, u, range(len(prob.conditions))),
    }


def finish(ev, fitted: dict) -> dict:
    """Stage 2's confirmation, once ``fitted["requests"]`` have run: the simulated means at the closest point,
    residuals and their noise-budget variances over the training values, the confirmed chi-square, p-value and
    whether the model reaches the data."""
    from scipy import stats

    prob, mask, model = ev.prob, ev.prob.train, fitted["model"]
    conf = ev.confirm(model, fitted["u"], range(len(prob.conditions)), f"{model.name}: confirm")
    r, var = ev.residuals(conf, mask)
    sim, k = ev._sim_means(conf, mask)
    ok = np.isfinite(r)
    chi = float(np.sum(r[ok] ** 2 / var[ok]))
    p = float(stats.chi2.sf(chi, int(ok.sum()))) if ok.any() else math.nan
    return {
        **{key: fitted[key] for key in ("model", "u", "surrogate_chi2", "surrogate_p", "span", "region")},
        "theta": {dim.name: dim.value(x) for dim, x in zip(model.dims, fitted["u"])},
        "confirm": conf,
        "simulated": sim,
        "simulations": k,
        "residual": r,
        "variance": var,
        "chi2": chi,
        "p": p,
        "reaches": bool(ok.all() and p >= ev.spec.alpha),
    }


def repeatability(ev, ex, res: dict) -> dict:
    """Stage 3: per response, the scatter of ``res``'s confirming simulations (a :func:`finish` result) over world
    seeds, pooled over the training conditions, against the measurement's: the stated SD where the data give
    ``sd_<response>`` (taken as known), else the replicates' pooled SD (:meth:`Experiments.replicate_sd`).
    {response: {"simulated_sd", "simulated_df", "measured_sd", "measured_df" (None for a stated SD), "ratio" (SD
    over SD), "F", "p", "p_holm" (over the responses), "exceeds" (p_holm < alpha)}}. A response is left out when
    no condition has two finite runs, or when its replicates agree exactly (no scale to compare with)."""
    prob = ev.prob
    conds = sorted(set(prob.obs.loc[prob.train, "condition"]))
    out = {}
    for j, r in enumerate(ev.responses):
        groups = (res["confirm"][c]["values"][:, j] for c in conds if c in res["confirm"])
        sim_var, sim_df = inf.pooled_variance(groups)
        rows = prob.obs[prob.train & (prob.obs["response"] == r).to_numpy()]
        if not sim_df or rows.empty:
            continue
        col = f"sd_{r}"
        if col in ex.table and ex.table[col].notna().any():
            meas_var, meas_df = float(rows["var_one"].mean()), math.inf
        else:
            sd, meas_df = ex.replicate_sd(r)
            meas_var = sd**2
        if not meas_var > 0:
            continue
        f, p = inf.scatter_excess(sim_var, sim_df, meas_var, meas_df)
        out[r] = {
            "simulated_sd": math.sqrt(sim_var),
            "simulated_df": int(sim_df),
            "measured_sd": math.sqrt(meas_var),
            "measured_df": None if math.isinf(meas_df) else int(meas_df),
            "ratio": math.sqrt(f),
            "F": f,
            "p": p,
        }
    for o, q in zip(out.values(), inf.holm([o["p"] for o in out.values()]) if out else []):
        o["p_holm"] = float(q)
        o["exceeds"] = bool(q < ev.spec.alpha)
    return out


def reached_verdict(scatter: dict) -> str:
    """The verdict of a base model that reaches the data, given its :func:`repeatability`: "overdispersed" when a
    response scatters more than its measurement, else "not_testable"."""
    return "overdispersed" if any(s["exceeds"] for s in scatter.values()) else "not_testable"


def scatter_words(scatter: dict) -> str:
    """The responses that scatter more, for the verdict line: "r: SD a against b, p q; ..."."""
    return "; ".join(
        f"{r}: SD {_num(s['simulated_sd'], 3)} against {_num(s['measured_sd'], 3)}, p {_num(s['p_holm'], 2)}"
        for r, s in scatter.items()
        if s["exceeds"]
    )


def no_laws(why: str | None = None) -> dict:
    """A decision's ``rolling_models`` when none was tried (``why``: the reason, None when none was due)."""
    return {"tried": {}, "not_tried": why, "pairs_not_tried": why, "repeating": [], "law": None, "with": None}


def scatter_gain(base: dict, law: dict) -> dict:
    """Per response the base scatters more on (its :func:`repeatability` ``exceeds``): the base's confirming runs'
    variance over the law's, one-sided (:func:`inference.scatter_excess`: does the base scatter more than the
    law), {response: {"F", "p"}}; a response the law's runs could not measure is left out."""
    out = {}
    for r, b in base.items():
        if b["exceeds"] and r in law:
            s = law[r]
            f, p = inf.scatter_excess(
                b["simulated_sd"] ** 2, b["simulated_df"], s["simulated_sd"] ** 2, s["simulated_df"]
            )
            out[r] = {"F": f, "p": p}
    return out


def _judge(ev, ex, models: list, results: dict, scatter: dict, stage: str, log) -> dict:
    """Stage 2 for each of ``models`` (rolling models switched, alone or with a second change) at its own closest
    point (its results join ``results`` under its name), and its scatter: {name: {"model" (the rolling model),
    "with" (the second change, {"name", "factor"} at the closest point, or None), "reaches", "scatter" (its
    :func:`repeatability`), "gain" (:func:`scatter_gain`)}}. ``repeats`` is set by :func:`_decide`."""
    from .data import DiagnoseError

    ev.sims.run(ev.design_requests(models), f"{stage}: design")
    fitted, laws = [], {}

    def second(m, theta):
        if m.candidate is None:
            return None
        x = theta.get(m.candidate.name) if theta else None
        return {"name": m.candidate.name, "factor": None if x is None else 10.0 ** float(x)}

    for m in models:
        try:
            fitted.append(fit(ev, m))
        except DiagnoseError as e:  # a law whose piles cannot be measured over the box
            laws[m.name] = {
                "model": m.law.model,
                "with": second(m, None),
                "reaches": False,
                "scatter": {},
                "gain": {},
                "repeats": False,
            }
            log(f"{ev.spec.name}: {m.name} left out: {e}")
    ev.sims.run([q for f in fitted for q in f["requests"]], f"{stage}: confirm")
    for f in fitted:
        m = f["model"]
        res = results[m.name] = finish(ev, f)
        rep = repeatability(ev, ex, res)
        laws[m.name] = {
            "model": m.law.model,
            "with": second(m, res.get("theta")),
            "reaches": res["reaches"],
            "scatter": rep,
            "gain": scatter_gain(scatter, rep),
        }
    return laws


def _decide(laws: dict, scatter: dict, alpha: float) -> list[str]:
    """Holm over every law's and response's scatter gain in ``laws`` (:func:`_judge`), then each law's
    ``repeats``: it reaches the data, no response scatters more than the measurement, and the base scatters
    significantly more than it on every response the base exceeds. Returns the names that repeat."""
    tests = [g for law in laws.values() for g in law["gain"].values()]
    for g, q in zip(tests, inf.holm([g["p"] for g in tests]) if tests else []):
        g["p_holm"] = float(q)
        g["significant"] = bool(q < alpha)
    exceeded = [r for r, s in scatter.items() if s["exceeds"]]
    for law in laws.values():
        law["repeats"] = bool(
            law["reaches"]
            and not any(s["exceeds"] for s in law["scatter"].values())
            and all(law["gain"].get(r, {}).get("significant", False) for r in exceeded)
        )
    return [n for n, law in laws.items() if law["repeats"]]


def try_laws(ev, base_model, spec, ex, results: dict, scatter: dict, log) -> dict:
    """Stage 4 of an OVERDISPERSED base: each other rolling model (:func:`pipeline._laws`) through stage 2 at its
    own closest point, judged by its scatter (:func:`_judge`, :func:`_decide`). When none repeats, each again with
    the cohesion weakened (:func:`candidates.cohesion_strength`, its factor free; :func:`pipeline._strength`): a
    two-change model, judged by the same rule, Holm over the single and the paired models together. Returns the
    decision's entries: "rolling_models" {"tried": {name: :func:`_judge`'s entry with "repeats"}, "not_tried" (why
    none was tried, or None), "pairs_not_tried" (why no two-change model was tried, or None), "repeating" (the
    names that repeat), "law" (the one model that does, else None), "with" (its second change, else None)} and
    "cause" ("rolling_model" when one does, else None)."""
    from .pipeline import Model, _laws, _strength

    conds = ev.prob.conditions
    switches, why = _laws(spec, ex, conds)
    if why:
        return {"rolling_models": no_laws(why)}
    models = [Model.switched(base_model, sw) for sw in switches]
    laws = _judge(ev, ex, models, results, scatter, "rolling models", log)
    repeating = _decide(laws, scatter, spec.alpha)
    pairs_why = "a rolling model alone repeats"
    if not repeating:
        strength, pairs_why = _strength(spec, ex, conds)
        if strength is not None:
            pairs = [Model.extended(m, strength) for m in models]
            laws.update(_judge(ev, ex, pairs, results, scatter, "rolling models with weaker cohesion", log))
            repeating = _decide(laws, scatter, spec.alpha)
    one = laws[repeating[0]] if len(repeating) == 1 else None
    return {
        "rolling_models": {
            "tried": laws,
            "not_tried": None,
            "pairs_not_tried": pairs_why,
            "repeating": repeating,
            "law": one["model"] if one else None,
            "with": one["with"] if one else None,
        },
        "cause": "rolling_model" if one else None,
    }


def undecided(rm: dict) -> list[str]:
    """The tried rolling models (names) that reach the data and do not scatter more than the measurement, but whose
    runs do not show the base scatters more than they do: what more confirming runs could still name."""
    return [
        n
        for n, law in rm["tried"].items()
        if law["reaches"]
        and law["scatter"]
        and not law["repeats"]
        and not any(s["exceeds"] for s in law["scatter"].values())
    ]


def law_label(law: dict) -> str:
    """A tried rolling model in the report's words: its name, and its second change where it has one."""
    w = law.get("with")
    if not w:
        return law["model"]
    factor = "" if w["factor"] is None else f" times {_num(w['factor'], 2)}"
    return f"{law['model']} with the surface energy{factor} ({w['name']})"


def law_words(decision: dict) -> str:
    """What the rolling models tried by their scatter showed, for the OVERDISPERSED verdict line."""
    rm = decision["rolling_models"]
    laws, rep = rm["tried"], rm["repeating"]
    if not laws:
        return f"no rolling model was tried ({rm['not_tried'] or 'none applies'})"
    if not rep:
        tried = ", ".join(law["model"] for law in laws.values() if not law.get("with"))
        paired = any(law.get("with") for law in laws.values())
        alone = ", alone or with a weaker cohesion," if paired else ""
        words = f"none of the rolling models tried ({tried}){alone} reaches the data and repeats"
        close = undecided(rm)
        if close:
            words += (
                f"; {' and '.join(law_label(laws[n]) for n in close)} "
                f"{'reaches' if len(close) == 1 else 'each reach'} it within the measurement's scatter, but too few "
                "confirming runs to show less scatter than the base: more confirming seeds ([calibration] "
                "confirm_seeds) would decide"
            )
        return words

    def gain(n):
        g = laws[n]["gain"]
        return ", ".join(f"{r}: variance ratio {_num(x['F'], 3)}, p {_num(x['p_holm'], 2)}" for r, x in g.items())

    if len(rep) == 1:
        return f"the rolling model {law_label(laws[rep[0]])} reaches the data and repeats ({gain(rep[0])})"
    both = "; ".join(law_label(laws[n]) for n in rep)
    return f"the rolling models {both} each reach the data and repeat; these data cannot tell them apart"


def _z_rms(res: dict) -> float:
    z2 = res["residual"] ** 2 / res["variance"]
    return float(math.sqrt(np.nanmean(z2)))


def gain(ev, base: dict, ext: dict) -> dict:
    """The misfit at each model's closest point, from its confirming simulations: RMS of the residuals per
    response (its unit) and of the standardised residuals, base and extended, and the reduction."""
    obs = ev.prob.obs[ev.prob.train]
    out = {"z_rms": {"base": _z_rms(base), "extended": _z_rms(ext)}, "rmse": {}, "on": "the data fitted"}
    zb, ze = out["z_rms"]["base"], out["z_rms"]["extended"]
    out["z_rms"]["reduction"] = 1.0 - ze / zb if zb > 0 else math.nan
    for r in dict.fromkeys(obs["response"]):
        m = (obs["response"] == r).to_numpy()
        b = float(math.sqrt(np.nanmean(base["residual"][m] ** 2)))
        e = float(math.sqrt(np.nanmean(ext["residual"][m] ** 2)))
        out["rmse"][r] = {"base": b, "extended": e, "reduction": 1.0 - e / b if b > 0 else math.nan}
    return out


def run(ev, base_model, spec, ex, log) -> tuple[dict, dict]:
    """Stages 2 to 4 (the noise budget is set): {model name: result} and the decision {"verdict", "scatter",
    "reaching", "cause", "skipped", "separating", "gains"}."""
    from .data import DiagnoseError
    from .pipeline import Model, _library, separating_measurement

    sims = ev.sims
    base_fit = fit(ev, base_model)
    sims.run(base_fit["requests"], "base: confirm")
    results = {"base": finish(ev, base_fit)}
    scatter = repeatability(ev, ex, results["base"])
    decision = {
        "verdict": "not_testable",
        "scatter": scatter,
        "reaching": [],
        "cause": None,
        "skipped": {},
        "separating": [],
        "predictions": {},
        "gains": {},
        "rolling_models": no_laws(),
    }
    if results["base"]["reaches"]:
        decision["verdict"] = reached_verdict(scatter)
        if decision["verdict"] == "overdispersed":
            decision.update(try_laws(ev, base_model, spec, ex, results, scatter, log))
        return results, decision
    lib, skipped = _library(spec, ex, ev.prob.conditions)
    models = [Model.extended(base_model, c) for c in lib]
    if models:
        sims.run(ev.design_requests(models), "candidates: design")
    fitted = []
    for m in models:
        try:
            fitted.append(fit(ev, m))
        except DiagnoseError as e:  # a candidate at the edge of its range may pack no measurable core
            skipped[m.name] = f"its design could not be measured: {e}"
            log(f"{spec.name}: candidate {m.name} left out: {e}")
    if fitted:
        sims.run([q for f in fitted for q in f["requests"]], "candidates: confirm")
    for f in fitted:
        results[f["model"].name] = finish(ev, f)
    reaching = [n for n, r in results.items() if n != "base" and r["reaches"]]
    verdict = "unexplained" if not reaching else "only_one_reaches" if len(reaching) == 1 else "not_identifiable"
    decision.update(
        verdict=verdict,
        reaching=reaching,
        cause=reaching[0] if len(reaching) == 1 else None,
        skipped=skipped,
        # the base at its closest point misses the data, so only models that reach them are worth separating
        separating=separating_measurement(ev.prob, results, reaching) if len(reaching) > 1 else [],
        predictions={n: predictions(ev, results[n]) for n in reaching},
        gains={n: gain(ev, results["base"], results[n]) for n in reaching},
    )
    return results, decision


def predictions(ev, res: dict) -> dict:
    """What a model that reaches the data predicts, at its closest point, for the measurements the data lack
    (:data:`pipeline.SEPARATING`): {measurement: {"mean", "sd", "runs"}} over the confirming simulations at the
    training conditions. A second measurement held out against these is the test one value cannot give."""
    from .pipeline import SEPARATING, response

    conds = sorted(set(ev.prob.obs.loc[ev.prob.train, "condition"]))
    out = {}
    for metric in SEPARATING:
        if metric in ev.responses:
            continue
        v = np.array([response(m, metric) for c in conds for m in res["confirm"][c]["metrics"]], dtype=float)
        v = v[np.isfinite(v)]
        if len(v):
            out[metric] = {
                "mean": float(v.mean()),
                "sd": float(v.std(ddof=1)) if len(v) > 1 else math.nan,
                "runs": len(v),
            }
    return out


# --------------------------------------------------------------------------------------------------
# report
# --------------------------------------------------------------------------------------------------


def _num(x, digits: int = 4) -> str:
    return "–" if x is None or not np.isfinite(x) else f"{x:.{digits}g}"


def _model_json(res: dict) -> dict:
    return {
        "parameters": res["theta"],
        "reaching_region": res["region"],
        "span": res["span"],
        "surrogate": {"chi2": res["surrogate_chi2"], "p": res["surrogate_p"]},
        "simulated": [float(x) for x in res["simulated"]],
        "simulations": [int(x) for x in res["simulations"]],
        "residual": [float(x) for x in res["residual"]],
        "z": [float(x) for x in res["residual"] / np.sqrt(res["variance"])],
        "chi2": res["chi2"],
        "p": res["p"],
        "reaches": res["reaches"],
    }


def _plot(out: Path, prob, results: dict) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    obs = prob.obs[prob.train].reset_index(drop=True)
    files = []
    names = list(results)
    # a two-change model's name runs to 40 characters: widen the figure with the longest, so that the axes keep
    # their width once the constrained layout has made room for the labels
    width = max(6.0, 3.5 + 0.08 * max(len(n) for n in names))
    for i, o in obs.iterrows():
        fig, ax = plt.subplots(figsize=(width, 0.6 * len(names) + 2.4), layout="constrained")
        sd = math.sqrt(max(o["var_one"], prob.sim_var.get(o["response"], 0.0)) / o["n"])
        ax.axvspan(o["mean"] - 2 * sd, o["mean"] + 2 * sd, color="0.85", label="measured, 2 SE")
        ax.axvline(o["mean"], color="k")
        for y, n in enumerate(names):
            lo, hi = results[n]["span"][i]
            ax.plot([lo, hi], [y, y], lw=6, color="C0" if results[n]["reaches"] else "C3", solid_capstyle="butt")
            ax.plot(results[n]["simulated"][i], y, "kD")
        ax.set_yticks(range(len(names)), names)
        ax.set_xlabel(o["response"])
        fig.suptitle(
            f"Reach of each model, experiment {o['id']}\nbar: its surrogate's span over the parameter box "
            "(blue: reaches);\ndiamond: simulated at its closest point",
            fontsize=9,
        )
        # below the axes: inside them it covered the lowest model's bar and diamond
        fig.legend(fontsize=8, loc="outside lower center")
        f = out / f"reach_{o['response']}_{i}.png"
        save_figure(fig, f, dpi=110)
        plt.close(fig)
        files.append(f.name)
    return files


def _cause_words(decision: dict) -> str | None:
    words = cands.CAUSES.get(decision["cause"] or "", None)
    rm = decision["rolling_models"]
    if not (words and rm["law"]):
        return words
    w = rm.get("with")
    if not w:
        return f"{words}: {rm['law']}"
    return f"{words}: {law_label({'model': rm['law'], 'with': w})}; and {cands.CAUSES[w['name']]}"


def write(out: Path, prob, results: dict, decision: dict, checks=None) -> dict:
    """Write report.md, diagnosis.json and the reach pictures into ``out``; return diagnosis.json's content."""
    from warpdem.scene.runner import _json_default

    out = Path(out)
    spec = prob.spec
    names = ", ".join(decision["reaching"])
    diag = {
        "name": spec.name,
        "mode": "reach",
        "verdict": decision["verdict"],
        "verdict_words": WORDS[decision["verdict"]].format(
            names=names, scatter=scatter_words(decision["scatter"]), laws=law_words(decision)
        ),
        "cause": decision["cause"],
        "cause_words": _cause_words(decision),
        "reaching": decision["reaching"],
        "tied": decision["reaching"] if decision["verdict"] == "not_identifiable" else [],
        "separating_measurement": decision["separating"][0]["measurement"] if decision["separating"] else None,
        "separating": decision["separating"],
        "predictions": decision["predictions"],
        "measured_values": int(prob.train.sum()),
        "free_parameters": len(spec.parameters),
        "noise": {
            "simulation_sd": {r: math.sqrt(v) for r, v in prob.sim_var.items()},
            "seed_sd": {r: math.sqrt(v) for r, v in prob.seed_var.items()},
        },
        "scatter": decision["scatter"],
        "base": _model_json(results["base"]),
        "extended": {n: _model_json(r) for n, r in results.items() if n != "base"},
        "rolling_models": decision["rolling_models"],
        "not_applicable": decision["skipped"],
        "gain": decision["gains"],
        "pictures": _plot(out, prob, results),
        "checks": checks,
    }
    with open(out / "diagnosis.json", "w") as fh:
        json.dump(diag, fh, indent=1, default=_json_default)
    (out / "report.md").write_text(_markdown(prob, results, diag))
    return diag


def _laws_markdown(rm: dict, results: dict) -> list[str]:
    """The report's section on the rolling models tried by their scatter."""
    lines = ["", "## Rolling models, judged by their scatter", ""]
    if not rm["tried"]:
        return lines + [f"None was tried: {rm['not_tried'] or 'none applies'}."]
    lines += [
        "Each other rolling model of the grain, with the base model's parameters free, taken to its own closest "
        "point; it is named when it reaches the data, its runs repeat no worse than the measurement, and the base's "
        "runs scatter more than its own (one-sided F on the two models' confirming runs, Holm over the models and "
        "responses).",
    ]
    if any(law.get("with") for law in rm["tried"].values()):
        lines += [
            "",
            "No rolling model alone repeated, so each was tried again with a second change: the grain-grain surface "
            "energy times a free factor 10^x (x the parameter `cohesion_strength`, over its range; the base's free "
            "parameters free too). Grains cohesive past a granular Bond number of a few stand as towers or fall, "
            "whatever their rolling law; the Holm correction runs over every model tried, alone or paired.",
        ]
    elif rm.get("pairs_not_tried") and not rm["repeating"]:
        lines += ["", f"No two-change model was tried: {rm['pairs_not_tried']}."]
    lines += [
        "",
        "| rolling model | reaches | closest point | response | its SD (df) | against the measurement, p | "
        "base / its variance, p (Holm) | repeats |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, law in rm["tried"].items():
        res = results.get(name)
        point = ", ".join(f"{k} {_num(v)}" for k, v in res["theta"].items()) if res else "–"
        rows = law["scatter"] or {"–": None}
        for r, s in rows.items():
            g = law["gain"].get(r)
            sd = f"{_num(s['simulated_sd'], 3)} ({s['simulated_df']})" if s else "–"
            against = _num(s["p_holm"], 2) if s else "–"
            ratio = f"{_num(g['F'], 3)}, {_num(g['p_holm'], 2)}" if g else "–"
            lines.append(
                f"| {law_label(law)} | {'yes' if law['reaches'] else 'no'} | {point} | {r} | {sd} | {against} | "
                f"{ratio} | {'yes' if law['repeats'] else 'no'} |"
            )
    return lines


def _markdown(prob, results: dict, diag: dict) -> str:
    spec, obs = prob.spec, prob.obs[prob.train].reset_index(drop=True)
    title = spec.title or spec.name
    lines = [
        f"# Diagnosis: {title}",
        "",
        f"**{diag['verdict_words']}.**",
        "",
        f"The data hold {diag['measured_values']} measured value(s) for {diag['free_parameters']} free parameter(s), so a "
        "calibration would fit any value the model can reach, exactly: no adequacy test or held-out comparison "
        "exists. This diagnosis asks which models reach the data (chi-square over the measured values, p >= "
        f"{spec.alpha}, at real simulations of each model's closest point).",
        "",
        "## Reach of each model",
        "",
        "| model | response | measured (SD of the mean) | span over the box (surrogate) | closest point | "
        "simulated there (runs) | z | p | reaches |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, res in results.items():
        point = ", ".join(f"{k} {_num(v)}" for k, v in res["theta"].items())
        for i, o in obs.iterrows():
            sd = math.sqrt(max(o["var_one"], prob.sim_var.get(o["response"], 0.0)) / o["n"])
            lo, hi = res["span"][i]
            z = res["residual"][i] / math.sqrt(res["variance"][i])
            lines.append(
                f"| {name} | {o['response']} | {_num(o['mean'])} ({_num(sd, 2)}) | {_num(lo)}–{_num(hi)} | {point} | "
                f"{_num(res['simulated'][i])} ({int(res['simulations'][i])}) | {_num(z, 3)} | {_num(res['p'], 2)} | "
                f"{'yes' if res['reaches'] else 'no'} |"
            )
    if diag["scatter"]:
        lines += [
            "",
            "## Repeatability at the base model's closest point",
            "",
            "The noise budget takes the larger of the measurement's scatter and the model's, so a model whose runs "
            "scatter more than the material repeats reaches any mean near its own. Its scatter over the confirming "
            "world seeds against the measurement's (one-sided F test; chi-square against a stated SD, taken as "
            "known; Holm over the responses):",
            "",
            "| response | model's SD (df) | measurement's SD (df) | ratio | p (Holm) | scatters more |",
            "|---|---|---|---|---|---|",
        ]
        for r, s in diag["scatter"].items():
            df = "stated" if s["measured_df"] is None else s["measured_df"]
            lines.append(
                f"| {r} | {_num(s['simulated_sd'], 3)} ({s['simulated_df']}) | {_num(s['measured_sd'], 3)} ({df}) | "
                f"{_num(s['ratio'], 3)} | {_num(s['p_holm'], 2)} | {'yes' if s['exceeds'] else 'no'} |"
            )
    reaching = diag["reaching"]
    if reaching:
        lines += [
            "",
            "## The candidates that reach the data",
            "",
            "Each candidate's own parameter reaches the data over the range below (on its surrogates, with the "
            "base parameters free): an interval, not an estimate, since one value per free parameter fixes none.",
            "",
            "| candidate | its parameter's range that fits | at the closest point | misfit RMS base → extended (SDs) |",
            "|---|---|---|---|",
        ]
        for n in reaching:
            res, g = results[n], diag["gain"][n]
            region = res["region"].get(n)
            span = f"{_num(region[0])}–{_num(region[1])}" if region else "–"
            zr = g["z_rms"]
            lines.append(
                f"| {cands.CAUSES.get(n, n)} | {span} | {_num(res['theta'][n])} | "
                f"{_num(zr['base'], 3)} → {_num(zr['extended'], 3)} |"
            )
        lines += [
            "",
            "The gain is on the data fitted (the confirming simulations at each model's closest point), not on "
            "held-out data: with one value per free parameter none is left to hold out.",
        ]
    if reaching:
        lines += [
            "",
            "## What would settle it",
            "",
            "A second measurement of the same material, held out against what each model that reaches the data "
            "predicts for it at its closest point (mean ± SD of the confirming simulations):",
            "",
            "| measurement | " + " | ".join(f"base + {n} predicts" for n in reaching) + " |",
            "|---|" + "---|" * len(reaching),
        ]
        for metric in dict.fromkeys(m for n in reaching for m in diag["predictions"][n]):
            cells = []
            for n in reaching:
                p = diag["predictions"][n].get(metric)
                cells.append(f"{_num(p['mean'])} ± {_num(p['sd'], 2)}" if p else "–")
            lines.append(f"| {metric} | " + " | ".join(cells) + " |")
        if diag["separating"]:
            lines += [
                "",
                "The measurements that best tell them apart (difference of the means over its standard error): "
                + ", ".join(f"{s['measurement']} (z {_num(s['z'], 3)})" for s in diag["separating"][:3])
                + ".",
            ]
    elif diag["verdict"] == "not_testable":
        lines += [
            "",
            "## What would test it",
            "",
            "More measured values than free parameters: a second response of the same material (its bulk density, "
            "say) or the same response at a second condition (grain size, plate, fill).",
        ]
    elif diag["verdict"] == "overdispersed":
        lines += [
            "",
            "## What it means",
            "",
            "The model reaches the measured mean only inside its own scatter: one run of it may read anywhere in "
            "that spread, where the material repeats more closely. The candidates are judged by whether they reach "
            "the mean, which the base already does, so none is tried. What to look for is what makes the runs "
            "repeat: how the grains lock (the rolling-friction law, the cohesion's strength at the grains' size) "
            "and the pile's size in grains. The rolling law is tried here, alone and, when none repeats alone, with "
            "the cohesion weakened (below); test any other change by the same check: its runs' SD against the "
            "measurement's.",
        ]
        lines += _laws_markdown(diag["rolling_models"], results)
    if diag["not_applicable"]:
        lines += ["", "## Candidates not tried", ""]
        lines += [f"- {n}: {why}" for n, why in diag["not_applicable"].items()]
    lines += ["", *[f"![{p}]({p})" for p in diag["pictures"]], ""]
    return "\n".join(lines)
