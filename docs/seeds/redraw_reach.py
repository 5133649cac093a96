"""Redraw a reach diagnosis record's pictures from its diagnosis.json, with the current layout.

    python docs/seeds/redraw_reach.py docs/seeds/001/reach_confirm6

A record's pictures are drawn by the run; a rerun on another machine recalibrates and asks for new simulations
(docs/seeds/reach_repeatability.py says why), so a picture whose layout was mended since is redrawn from what the
record keeps: each model's span over its box, its simulated mean at its closest point and whether it reaches
(``base`` and ``extended`` of diagnosis.json), the measured value and the band the diagnosis drew around it
(the larger of the measurement's SD and the model's seed scatter, ``noise.simulation_sd``, over the replicates).
It writes over the record's ``reach_RESPONSE_I.png`` files and prints their names.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from warpdem.diagnose import reach


def redraw(folder: Path) -> list[str]:
    import pandas as pd

    diag = json.loads((folder / "diagnosis.json").read_text())
    if not (folder / "experiments.csv").exists():
        raise SystemExit(f"{folder}: no experiments.csv (the record's measured data) to draw the band from")
    table = pd.read_csv(folder / "experiments.csv")
    responses = [c for c in table.columns if c != "id" and not c.startswith("sd_")]
    rows = []
    for _, t in table.iterrows():
        for r in responses:
            rows.append(
                {"id": t["id"], "response": r, "mean": float(t[r]), "n": 1, "var_one": float(t[f"sd_{r}"]) ** 2}
            )
    obs = pd.DataFrame(rows)
    sim_sd = diag["noise"]["simulation_sd"]
    prob = SimpleNamespace(obs=obs, train=np.ones(len(obs), bool), sim_var={r: s**2 for r, s in sim_sd.items()})
    results = {"base": diag["base"], **diag["extended"]}
    return reach._plot(folder, prob, results)


if __name__ == "__main__":
    for name in redraw(Path(sys.argv[1])):
        print(name)
