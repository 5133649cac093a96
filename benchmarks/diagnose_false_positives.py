"""False-positive rate of ``warpdem diagnose``: how often data from the base model itself are called inadequate.

Each replicate makes null data for the die-press case (``warpdem.diagnose.synthetic``: Hertz-Mindlin, mu_s = 0.5,
no plasticity; three force limits, three replicates each) with its own world seeds and its own measurement
noise, and diagnoses it. Any verdict but ADEQUATE is a false positive. The replicates share one store of
simulated worlds (the base model's design is the same for all), so each costs only its data, its confirming and
its held-out simulations, plus the candidates' when it errs. Prints one line per replicate and the rate with its
Clopper-Pearson 95 % interval; the nominal rate is the adequacy tests' alpha (0.05, Holm-corrected as one
family, so at most about alpha).

    python benchmarks/diagnose_false_positives.py [--replicates 20] [--sd 0.005] [--device cpu] [--out DIR]

About 40 s of CPU per replicate (2 s per press world). Rerunning with the same --out resumes.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from scipy import stats

from warpdem.diagnose import synthetic as syn
from warpdem.diagnose.pipeline import diagnose


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--replicates", type=int, default=20, help="null data sets (default 20)")
    ap.add_argument("--sd", type=float, default=0.005, help="measurement noise SD of the residual set (default 0.005)")
    ap.add_argument("--device", default="cpu", help="device(s) of the diagnosis, as a study takes (default cpu)")
    ap.add_argument("--out", default="runs/bench_false_positives", help="output folder (resumable)")
    a = ap.parse_args()
    out = Path(a.out)
    runs = out / "runs"
    runs.mkdir(parents=True, exist_ok=True)
    verdicts = []
    for k in range(a.replicates):
        case = out / f"null_{k:02d}"
        done = case / "out" / "diagnosis.json"
        t0 = time.perf_counter()
        if not done.exists():
            seeds = [1000 + 3 * k + j for j in range(3)]
            rows = syn.press_rows("hertz_mindlin", 0.0, 0.5, a.sd, np.random.default_rng(k), seeds)
            path = syn.write_case(case, f"null_{k:02d}", syn.PRESS_TOML, rows)
            (case / "out").mkdir(exist_ok=True)
            link = case / "out" / "runs"
            if not link.exists():
                link.symlink_to(runs.resolve(), target_is_directory=True)
            diagnose(str(path), case / "out", device=a.device, progress=False, log=lambda *x: None)
        d = json.loads(done.read_text())
        verdicts.append(d["verdict"])
        chi2 = next(t for t in d["adequacy_tests"] if t["kind"] == "chi2")
        print(
            f"replicate {k:2d}: {d['verdict']:<11s} chi2 p = {chi2['p']:.3f}  "
            f"mu_s = {d['base']['parameters']['mu_s']['estimate']:.3f}  ({time.perf_counter() - t0:.0f} s)",
            flush=True,
        )
    n, fp = len(verdicts), sum(v != "adequate" for v in verdicts)
    lo = stats.beta.ppf(0.025, fp, n - fp + 1) if fp > 0 else 0.0
    hi = stats.beta.ppf(0.975, fp + 1, n - fp) if fp < n else 1.0
    print(f"false positives: {fp} of {n} = {fp / n:.3f} (Clopper-Pearson 95 %: [{lo:.3f}, {hi:.3f}]); alpha 0.05")


if __name__ == "__main__":
    main()
