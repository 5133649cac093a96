"""Run some design points of a study as one launch, without the study's folder; print their responses and the
wall time. For diagnosing one world of a batch: a world gives the same numbers alone as in its batch when every
world releases the same particles.

    python benchmarks/study_point.py studies/pellets_bbd.toml 2        # design run 2 on CUDA
    python benchmarks/study_point.py studies/pellets_bbd.toml 1,2 cpu
"""

import json
import sys
import time

import warp as wp

from warpdem.study import execute as ex
from warpdem.study import spec as sp

wp.config.quiet = True

study = sp.load_study(sys.argv[1])
table = sp.design_table(study)
runs = [int(a) for a in sys.argv[2].split(",")]
rows = [
    {
        "run": int(r["run"]),
        "point_id": r["point_id"],
        "world_seed": int(r["world_seed"]),
        "overrides": sp.run_overrides(study, r),
    }
    for _, r in table.iterrows()
    if int(r["run"]) in runs
]
t0 = time.perf_counter()
recs = ex.run_batch(study, rows, sys.argv[3] if len(sys.argv) > 3 else "cuda")
wall = time.perf_counter() - t0
for row, rec in zip(rows, recs):
    print(
        "run",
        row["run"],
        {k: v for k, v in row["overrides"].items() if "." in k},
        "responses",
        rec["responses"],
        flush=True,
    )
print("info", json.dumps(recs[0]["info"], default=str)[:600])
print(f"wall {wall:.1f} s")
