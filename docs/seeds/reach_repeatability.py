"""The reach diagnoses' repeatability check applied to the seed records' stored runs.

    python docs/seeds/reach_repeatability.py [--out FILE]

The first three reach diagnoses kept under ``docs/seeds/`` (:data:`RECORDS`) ran before the check existed and said
NOT TESTABLE; the fourth, seed 001's recalibrated model (EDEM's standard rolling friction, the surface energy's range
times 0.2), ran with it. Each record keeps its simulated worlds (``runs/*.json``), among them the confirming runs at the base
model's closest point (stage "base: confirm"). This script reads those runs and the data file the diagnosis read
(``studies/diagnose/NAME.toml``, its experiments checked equal to the record's ``experiments.csv``) and applies
:func:`warpdem.diagnose.reach.repeatability` to them, as a diagnosis run now would at that closest point (a rerun
recalibrates: on another machine's CPU its closest point is not bit-identical to the recorded one, so it asks for
new confirming runs, at the seed's size a GPU's work).
It prints, per record, the runs, their SD against the measurement's, the test and the verdict it gives now; then
the gain in repeatability of the recalibrated model over the one it replaced (:data:`GAIN`): the ratio of the two
models' confirming-run variances at their closest points, one-sided F test.

Its output: ``reach_repeatability.txt`` beside it (README, "Diagnose", the repeatability check).
"""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np

HERE = Path(__file__).resolve().parent
STUDIES = HERE.parents[1] / "studies" / "diagnose"
RECORDS = (
    ("000/reach", "seed000_pellets"),
    ("001/reach", "seed001_wetfeed"),
    ("001/reach_large", "seed001_wetfeed_large"),
    ("001/reach_standard_scaled", "seed001_wetfeed_standard_scaled"),
)
"""(record folder under docs/seeds, its data file's name under studies/diagnose)."""
GAIN = (RECORDS[1], RECORDS[3])
"""(the base model's record, the recalibrated model's): seed 001 at 6,000 grains, our spheres' EPSD against EDEM's
standard rolling friction with the surface energy scaled."""
STAGE = "base: confirm"


def confirming_runs(record: Path, responses) -> np.ndarray:
    """The base model's confirming runs in ``record``: shape (runs, responses), ordered by world seed."""
    runs = [json.loads(p.read_text()) for p in sorted((record / "runs").glob("*.json"))]
    runs = sorted((r for r in runs if r["design"].get("stage") == STAGE), key=lambda r: r["world_seed"])
    return np.array([[r["responses"].get(k, np.nan) for k in responses] for r in runs], float)


def check(folder: str, name: str) -> tuple[dict, np.ndarray, dict]:
    """(repeatability result, the confirming runs, the record's diagnosis.json) of one record."""
    import pandas as pd

    from warpdem.diagnose import pipeline, reach
    from warpdem.diagnose.data import load_diagnosis

    record = HERE / folder
    spec, ex = load_diagnosis(STUDIES / f"{name}.toml", check_scene=False)
    kept = pd.read_csv(record / "experiments.csv")
    if not kept.equals(pd.read_csv(spec.experiments_path)):
        raise SystemExit(f"{record / 'experiments.csv'}: not the data file's experiments ({spec.experiments_path})")
    prob = pipeline._problem(spec, ex)
    if len(prob.conditions) != 1:
        raise SystemExit(f"{record}: {len(prob.conditions)} conditions; this script reads records of one")
    values = confirming_runs(record, list(ex.responses))
    ev = SimpleNamespace(prob=prob, responses=list(ex.responses), spec=spec)
    diag = json.loads((record / "diagnosis.json").read_text())
    return reach.repeatability(ev, ex, {"confirm": {0: {"values": values}}}), values, diag


def report() -> str:
    from warpdem.diagnose import reach

    lines, kept = [], {}
    for folder, name in RECORDS:
        scatter, values, diag = check(folder, name)
        kept[folder] = values
        lines.append(f"{folder} ({name}): recorded verdict {diag['verdict']}, base reaches: {diag['base']['reaches']}")
        for j, (r, s) in enumerate(scatter.items()):
            df = "stated" if s["measured_df"] is None else f"{s['measured_df']} df"
            lines.append(f"  {r}: runs {', '.join(f'{v:.2f}' for v in values[:, j])}")
            lines.append(
                f"  SD {s['simulated_sd']:.2f} ({s['simulated_df']} df) against {s['measured_sd']:.2f} ({df}): "
                f"ratio {s['ratio']:.2f}, p {s['p_holm']:.2g}, scatters more: {'yes' if s['exceeds'] else 'no'}"
            )
        now = reach.reached_verdict(scatter) if diag["base"]["reaches"] else diag["verdict"]
        lines.append(f"  verdict now: {reach.WORDS[now].split(':')[0]}")
    (old, _), (new, _) = GAIN
    f, p, df = gain(kept[old], kept[new])
    lines.append(f"gain in repeatability, {new} over {old}: variance ratio {f:.1f} on ({df[0]}, {df[1]}) df, p {p:.2g}")
    return "\n".join(lines) + "\n"


def gain(old: np.ndarray, new: np.ndarray):
    """(variance ratio old / new, its one-sided F p, (df old, df new)) of two models' confirming runs, shape (runs,
    1) each: the repeatability check's own test (:func:`warpdem.diagnose.inference.scatter_excess`) with the new
    model's runs in the measurement's place."""
    from warpdem.diagnose import inference as inf

    if old.shape[1] != 1 or new.shape[1] != 1:
        raise SystemExit(f"gain: one response each expected, got shapes {old.shape} and {new.shape}")
    df = (old.shape[0] - 1, new.shape[0] - 1)
    f, p = inf.scatter_excess(float(old[:, 0].var(ddof=1)), df[0], float(new[:, 0].var(ddof=1)), df[1])
    return f, p, df


def main(argv=None) -> int:
    import sys

    sys.path.insert(0, str(HERE))  # for the shared command line beside this script
    from report_cli import main as report_main

    return report_main(__doc__, report, argv)


if __name__ == "__main__":
    raise SystemExit(main())
