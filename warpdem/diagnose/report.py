"""A diagnosis's outputs: ``report.md``, ``diagnosis.json`` and the pictures (measured vs simulated per condition,
standardised residuals vs each condition, press curves overlaid)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from warpdem.scene.export import save_figure
from warpdem.scene.runner import _json_default

from . import candidates as cands
from . import inference as inf


def _f(x, digits: int = 4) -> str:
    if x is None:
        return "-"
    try:
        x = float(x)
    except (TypeError, ValueError):
        return str(x)
    return "-" if not math.isfinite(x) else f"{x:.{digits}g}"


def _interval(iv, digits: int = 4) -> str:
    return f"[{_f(iv[0], digits)}, {_f(iv[1], digits)}]" if iv is not None else "-"


def _on(test) -> str:
    """What an adequacy test is on: its experiment, or the condition of a trend, or nothing (the chi-square)."""
    for k in ("experiment", "condition"):
        if isinstance(test[k], str):
            return test[k]
    return ""


def _model_json(ev: dict) -> dict:
    m = ev["model"]
    out = {
        "parameters": {
            d.name: {
                "key": d.key,
                "estimate": ev["theta"][d.name],
                "interval_95": ev["interval"][d.name],
                "unit": d.unit,
            }
            for d in m.dims
        },
        "adequate": bool(ev["adequacy"]["adequate"]),
        "failed_tests": [
            {"kind": t["kind"], "response": t["response"], "on": _on(t), "p_holm": float(t["p_holm"])}
            for _, t in ev["adequacy"]["tests"].iterrows()
            if t["significant"]
        ],
        "loglik_train": ev["loglik"],
        "n_train": ev["n_train"],
        "surrogate_accuracy": ev["surrogate_accuracy"].to_dict(orient="records"),
        "surrogate_check": ev.get("surrogate_check"),
    }
    if ev["held_out"] is not None:
        h = ev["held_out"]
        out["held_out"] = {
            "rmse": {
                r: float(np.sqrt(np.mean(h.loc[h["response"] == r, "residual"] ** 2))) for r in set(h["response"])
            },
            "nll_mean": float(h["nll"].mean()),
            "experiments": int(len(h)),
        }
    return out


def _plots(out: Path, prob, evals: dict, named: str | None) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    files = []
    obs = prob.obs
    numeric = [c for c in prob.experiments.conditions if obs[c].dtype.kind in "if"]
    conds = prob.trend_conditions
    models = ["base"] + ([named] if named and named in evals else [])
    for r in prob.experiments.responses:
        o = obs[obs["response"] == r]
        if o.empty:
            continue
        x_name = numeric[0] if numeric else None
        x = o[x_name].to_numpy(dtype=float) if x_name else np.arange(len(o), dtype=float)
        fig, ax = plt.subplots(figsize=(6, 4))
        sd = np.sqrt(np.maximum(o["var_one"].to_numpy(), prob.sim_var.get(r, 0.0)) / o["n"].to_numpy())
        ax.errorbar(x, o["mean"], yerr=2 * sd, fmt="ko", capsize=3, label="measured (mean, 2 SE)")
        for k, name in enumerate(models):
            conf = evals[name]["confirm"]
            j = list(prob.experiments.responses).index(r)
            xs, ms, es = [], [], []
            for c, xv in zip(o["condition"], x):
                v = conf[c]["values"][:, j]
                v = v[np.isfinite(v)]
                if len(v):
                    xs.append(xv + (k + 1) * 0.01 * (np.ptp(x) or 1.0))
                    ms.append(v.mean())
                    es.append(2 * v.std(ddof=1) / math.sqrt(len(v)) if len(v) > 1 else 0.0)
            ax.errorbar(xs, ms, yerr=es, fmt="s" if k == 0 else "D", capsize=3, label=f"{name} (simulated)")
        ax.set_xlabel(x_name or "experiment")
        ax.set_ylabel(r)
        ax.set_title(f"{r}: measured and simulated at the calibrated point")
        ax.legend(fontsize=8)
        fig.tight_layout()
        f = out / f"measured_vs_simulated_{r}.png"
        save_figure(fig, f, dpi=110)
        plt.close(fig)
        files.append(f.name)
    train = prob.train
    for c in conds:
        fig, ax = plt.subplots(figsize=(6, 4))
        xv = obs.loc[train, c].to_numpy(dtype=float)
        for k, name in enumerate(models):
            ev = evals[name]
            z = ev["residual"] / np.sqrt(ev["variance"])
            ax.plot(xv + k * 0.01 * (np.ptp(xv) or 1.0), z, "o" if k == 0 else "D", label=name)
        ax.axhline(0, color="k", lw=0.8)
        for s in (-2, 2):
            ax.axhline(s, color="grey", ls="--", lw=0.8)
        ax.set_xlabel(c)
        ax.set_ylabel("standardised residual (measured - simulated) / SE")
        ax.set_title(f"Residuals vs {c} (training data)")
        ax.legend(fontsize=8)
        fig.tight_layout()
        f = out / f"residuals_vs_{c.replace('.', '_')}.png"
        save_figure(fig, f, dpi=110)
        plt.close(fig)
        files.append(f.name)
    if prob.experiments.curves:
        fig, ax = plt.subplots(figsize=(6, 4))
        for _id, cur in prob.experiments.curves.items():
            ax.plot(cur["displacement_m"] * 1e3, cur["force_n"], "k-", lw=1, alpha=0.6)
        for k, name in enumerate(models):
            for conf in evals[name]["confirm"].values():
                m = conf["metrics"][0]
                if "force_n" in m:
                    ax.plot(np.asarray(m["displacement_m"]) * 1e3, m["force_n"], f"C{k}-", lw=1)
                if "unload_force_n" in m:
                    ax.plot(np.asarray(m["unload_displacement_m"]) * 1e3, m["unload_force_n"], f"C{k}--", lw=1)
        ax.set_xlabel("displacement [mm]")
        ax.set_ylabel("force [N]")
        ax.set_title("Press curves: measured (black), base (C0) and extended (C1)")
        fig.tight_layout()
        f = out / "press_curves.png"
        save_figure(fig, f, dpi=110)
        plt.close(fig)
        files.append(f.name)
    return files


def write(out: Path, prob, evals: dict, decision: dict, screens, skipped, separating, gains, checks=None) -> dict:
    """Write report.md, diagnosis.json and the PNGs into ``out``; return the diagnosis (diagnosis.json's content)."""
    out = Path(out)
    spec = prob.spec
    base = evals["base"]
    named = decision.get("cause") or (decision["tied"][0] if decision["tied"] else decision.get("best"))
    pictures = _plots(out, prob, evals, named)
    diag = {
        "name": spec.name,
        "verdict": decision["verdict"],
        "cause": decision.get("cause"),
        "cause_words": cands.CAUSES.get(decision.get("cause") or "", None),
        "tied": decision["tied"],
        "separating_measurement": separating[0]["measurement"] if separating else None,
        "noise": {
            "simulation_sd": {r: math.sqrt(v) for r, v in prob.sim_var.items()},
            "seed_sd": {r: math.sqrt(v) for r, v in prob.seed_var.items()},
            "roughness_sd": {r: math.sqrt(v) for r, v in prob.rough_var.items()},
            "measurement_sd": {
                r: float(np.sqrt(prob.obs.loc[prob.obs["response"] == r, "var_one"].mean()))
                for r in prob.experiments.responses
            },
        },
        "base": _model_json(base),
        "adequacy_tests": base["adequacy"]["tests"].to_dict(orient="records"),
        "screen": [
            {k: v for k, v in s.items() if k != "effect"} | {"effect": list(map(float, s["effect"]))} for s in screens
        ],
        "not_applicable": skipped,
        "candidates": decision["table"],
        "extended": {n: _model_json(e) for n, e in evals.items() if n != "base"},
        "gain": gains,
        "pictures": pictures,
        "checks": checks,
    }
    with open(out / "diagnosis.json", "w") as fh:
        json.dump(diag, fh, indent=1, default=_json_default)
    (out / "report.md").write_text(_markdown(prob, evals, decision, diag, screens, skipped, separating, gains))
    return diag


def _markdown(prob, evals, decision, diag, screens, skipped, separating, gains) -> str:
    spec = prob.spec
    base = evals["base"]
    v = decision["verdict"]
    L = [f"# Diagnosis: {spec.title or spec.name}", ""]
    if v == "adequate":
        L.append("**Verdict: ADEQUATE.** The calibrated base model fits the training data within the noise budget: ")
        L.append("no adequacy test is significant after the Holm correction. The diagnosis stops here.")
    elif v == "cause":
        c = decision["cause"]
        L.append(f"**Verdict: CAUSE = {c}** ({cands.CAUSES[c]}). The base model misfits the data; adding this ")
        L.append("mechanism removes the misfit and improves the prediction of held-out data beyond the noise.")
    elif v == "ambiguous":
        t = decision["tied"]
        L.append(f"**Verdict: AMBIGUOUS** between {', '.join(t)}: each explains the misfit and neither predicts the ")
        L.append("held-out data better than the other by more than the noise allows.")
        if separating:
            s = separating[0]
            L.append(
                f"The measurement that separates them best is **{s['measurement']}**: their calibrated models predict "
                f"it {s['z']:.1f} standard errors apart (mean over {s['conditions']} conditions)."
            )
    else:
        L.append("**Verdict: UNEXPLAINED.** The base model misfits the data and no candidate extension explains the ")
        L.append(
            "misfit by the naming rule" + (f" (the closest: {decision['best']})." if decision.get("best") else ".")
        )
    L += ["", "## Data and noise budget", ""]
    L.append(
        f"{len(prob.experiments.summary())} experiments, {len(prob.obs)} measured means "
        f"({int(prob.train.sum())} training); responses: {', '.join(prob.experiments.responses)}; conditions: "
        f"{', '.join(prob.experiments.conditions) or 'none'}."
    )
    L += [
        "",
        "| response | measurement SD (one) | simulation SD: over world seeds | roughness in the parameters, beyond "
        "(design runs about their surrogates) |",
        "|---|---|---|---|",
    ]
    nz = diag["noise"]
    for r in prob.experiments.responses:
        L.append(
            f"| {r} | {_f(nz['measurement_sd'][r])} | {_f(nz['seed_sd'].get(r, math.nan))} | "
            f"{_f(nz['roughness_sd'].get(r, math.nan))} |"
        )
    ck = diag.get("checks") or {}
    if ck.get("over_stable_step"):
        L += [
            "",
            f"**Check:** {ck['over_stable_step']} of the {ck['worlds']} simulated worlds stepped past the stable step "
            f"of their stiffest contact in some tick (worst {_f(ck['worst_step_margin'], 3)} of it): leapfrog beyond "
            "its stability limit, so their figures are less trustworthy than the noise budget says. A lower "
            "`run.dt_fraction` in `[fixed]` removes it (at the cost of more steps).",
        ]
    L += ["", "## Base model: calibrated parameters", ""]
    L += _params_table(base)
    L += ["", _surrogate_line(base), ""]
    L += ["## What the base model gets wrong (training data, confirming simulations)", ""]
    L += _residual_table(prob, base)
    L += ["", "Adequacy tests (Holm-corrected as one family):", ""]
    L += _tests_table(base["adequacy"]["tests"])
    if screens:
        L += ["", "## Candidates", "", "Screen at the calibrated point (effect of moving each candidate from off "]
        L += ["halfway to the far end of its range, base parameters free to re-tune):", ""]
        L += ["| candidate | test value | delta chi2 | coefficient | p | recalibrated |", "|---|---|---|---|---|---|"]
        done = {r["candidate"] for r in decision["table"]}
        for s in screens:
            L.append(
                f"| {s['candidate']} | {_f(s['test_value'])} | {_f(s['delta_chi2'], 3)} | {_f(s['coefficient'], 3)} | "
                f"{_f(s['p'], 3)} | {'yes' if s['candidate'] in done else 'no'} |"
            )
    if skipped:
        L += ["", "Not tried: " + "; ".join(f"{k} ({v})" for k, v in skipped.items()) + "."]
    if decision["table"]:
        L += ["", "Recalibrated candidates:", ""]
        L += [
            "| candidate | estimate [95 % interval] | excludes off | LRT | p | AIC | BIC | adequate | held-out NLL | "
            "held-out evidence over base [nats] | mean NLL gain per experiment (bootstrap 95 %) |",
            "|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in decision["table"]:
            L.append(
                f"| {r['candidate']} | {_f(r['estimate'])} {_interval(r['interval'])} | {'yes' if r['excludes_off'] else 'no'} "
                f"| {_f(r['lrt'], 3)} | {_f(r['p'], 3)} | {_f(r['aic'], 4)} | {_f(r['bic'], 4)} | "
                f"{'yes' if r['adequate'] else 'no'} | {_f(r['held_out_nll'], 3)} | "
                f"{_f(r.get('held_out_evidence', math.nan), 3)} | {_interval(r.get('gain_interval'), 3)} |"
            )
        for name, ev in evals.items():
            if name == "base":
                continue
            L += ["", f"### Extended model: base + {name}", ""]
            L += _params_table(ev)
            L += ["", _surrogate_line(ev), "", "Its misfit (training data, confirming simulations):", ""]
            L += _residual_table(prob, ev)
            failed = ev["adequacy"]["tests"]
            failed = failed[failed["significant"].astype(bool)]
            if len(failed):
                L += ["", "Adequacy tests that fail (Holm-corrected as one family):", ""]
                L += _tests_table(failed)
            else:
                L += ["", "No adequacy test is significant (Holm-corrected as one family): adequate."]
    if gains:
        L += ["", "## Gain on held-out data", ""]
        if gains["rmse"]:
            L += [
                "| response | RMSE base [95 %] | RMSE extended [95 %] | reduction | chi-square p vs noise, base / extended |",
                "|---|---|---|---|---|",
            ]
            rows = [*gains["rmse"].items(), ("all (standardised: error / noise-budget SD)", gains["z_rms"])]
            for r, g in rows:
                p = g.get("noise_p")
                noise = f"{_f(p['base'], 3)} / {_f(p['extended'], 3)}" if p else "-"
                L.append(
                    f"| {r} | {_f(g['base'])} {_interval(g['base_interval'])} | {_f(g['extended'])} "
                    f"{_interval(g['extended_interval'])} | {100 * g['reduction']:.0f} % | {noise} |"
                )
            L += [
                "",
                "A gain is confirmed where the base's held-out errors exceed the noise budget (small p) and the "
                "extended model's do not.",
            ]
            n = gains["nll"]
            L += [
                "",
                f"Mean held-out NLL: base {_f(n['base'], 3)} {_interval(n['base_interval'], 3)}, extended "
                f"{_f(n['extended'], 3)} {_interval(n['extended_interval'], 3)}; paired difference "
                f"{_interval(n['difference_interval'], 3)}.",
            ]
        else:
            L.append("No held-out data (a single condition and no test split): the gain cannot be measured.")
        L += ["", "Base parameters before and after adding the cause:", ""]
        L += ["| parameter | base [95 %] | extended | shift |", "|---|---|---|---|"]
        for k, s in gains["shift"].items():
            L.append(
                f"| {k} | {_f(s['base'])} {_interval(s['base_interval'])} | {_f(s['extended'])} | {_f(s['shift'], 3)} |"
            )
    if separating:
        L += ["", "## Measurements that would separate the tied candidates", ""]
        L += ["| measurement | separation (SE) |", "|---|---|"]
        L += [f"| {s['measurement']} | {_f(s['z'], 3)} |" for s in separating]
    if diag["pictures"]:
        L += ["", "## Pictures", ""]
        L += [f"![{p}]({p})" for p in diag["pictures"]]
    return "\n".join(L) + "\n"


def _residual_table(prob, ev: dict) -> list[str]:
    """Measured against the model's confirming simulations, per training observation, with z = residual over the
    noise budget's SD."""
    L = ["| experiment | response | measured | simulated | z |", "|---|---|---|---|---|"]
    obs = prob.obs[prob.train]
    z = ev["residual"] / np.sqrt(ev["variance"])
    for (_, o), r, zz in zip(obs.iterrows(), ev["residual"], z):
        L.append(f"| {o['id']} | {o['response']} | {_f(o['mean'])} | {_f(o['mean'] - r)} | {_f(zz, 3)} |")
    return L


def _tests_table(tests) -> list[str]:
    L = ["| test | response | on | statistic | p | p (Holm) | significant |", "|---|---|---|---|---|---|---|"]
    for _, t in tests.iterrows():
        L.append(
            f"| {t['kind']} | {t['response']} | {_on(t)} | {_f(t['statistic'], 3)} | {_f(t['p'], 3)} | "
            f"{_f(t['p_holm'], 3)} | {'yes' if t['significant'] else 'no'} |"
        )
    return L


def _params_table(ev: dict) -> list[str]:
    L = ["| parameter | key | estimate | 95 % interval |", "|---|---|---|---|"]
    for d in ev["model"].dims:
        L.append(f"| {d.name} | `{d.key}` | {_f(ev['theta'][d.name])} | {_interval(ev['interval'][d.name])} |")
    return L


def _surrogate_line(ev: dict) -> str:
    acc = ev["surrogate_accuracy"]
    cal = ev["calibration"]
    q2 = acc["q2"].to_numpy(dtype=float) if "q2" in acc else np.array([np.nan])
    rmse = acc["rmse"].to_numpy(dtype=float) if "rmse" in acc else np.array([np.nan])
    chk = ev.get("surrogate_check")
    check = ""
    if chk:
        check = (
            f" The confirming simulations against the surrogates at the calibrated point: chi-square "
            f"{_f(chk['statistic'], 3)} on {chk['df']} df, p = {_f(chk['p'], 3)}, largest |z| {_f(chk['max_abs_z'], 3)}"
            + (
                "; they missed, so they joined the design, the surrogates were refitted and the model recalibrated "
                "and confirmed again (the figures above are the refitted ones)."
                if chk["refine"]
                else "; they agree."
            )
        )
    return (
        f"Surrogates: Gaussian processes (Matern 5/2, one length scale per parameter, white noise), one per condition "
        f"and response, {len(acc)} in all; leave-one-out Q^2 from {_f(np.nanmin(q2), 3)} to {_f(np.nanmax(q2), 3)}, "
        f"RMSE up to {_f(np.nanmax(rmse), 3)}. Posterior by MCMC (emcee), acceptance "
        f"{_f(cal.get('acceptance'), 2)}, {cal.get('steps', 0)} steps per walker (doubled until the kept half spans "
        f"{inf.TAU_SPAN} autocorrelation times), about {_f(cal.get('effective_samples'), 3)} independent samples."
        + check
    )
