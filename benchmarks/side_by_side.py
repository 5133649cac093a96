"""Side by side or one after another: the launches of one stage of a diagnosis, run to ``--until`` simulated
seconds on one GPU under several load limits of ``runner.run_together`` (0: one launch at a time; 1e6: the
default, every launch of the stage at once). Prints each limit's wall time and each launch's.

The worlds are a finished diagnosis's (its ``runs/*.json``: overrides and world seeds, grouped into launches
exactly as the diagnosis grouped them), so the launches are the real ones of that stage.

    python benchmarks/side_by_side.py DATA.toml RUNS_DIR --stage "candidates: design" --until 0.6 \
        [--limits 0,1000000] [--device cuda]
"""

from __future__ import annotations

import argparse
import functools
import glob
import json
import time

import warp as wp

from warpdem.diagnose.data import load_diagnosis
from warpdem.scene.runner import run_together
from warpdem.study import execute

wp.config.quiet = True

p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
p.add_argument("data", help="the diagnosis's data file")
p.add_argument("runs", help="its runs folder (one JSON per world)")
p.add_argument("--stage", default="candidates: design")
p.add_argument("--until", type=float, default=0.6, help="simulated seconds [s]")
p.add_argument("--limits", default="0,1000000", help="comma-separated load limits [spheres]")
p.add_argument("--device", default="cuda")
a = p.parse_args()
wp.init()
spec, ex = load_diagnosis(a.data)
study = spec.study(list(ex.responses))
rows = []
for f in sorted(glob.glob(f"{a.runs}/*.json")):
    with open(f) as fh:
        d = json.load(fh)
    if d["design"].get("stage") == a.stage:
        ov = {**d["overrides"], "run.duration": a.until}
        rows.append({"run": len(rows) + 1, "point_id": d["point_id"], "world_seed": d["world_seed"], "overrides": ov})
batches = execute._batches(study, rows, merge=execute.merges_scenes([a.device]))
print(f"{a.stage}: {len(rows)} worlds in {len(batches)} launches, to {a.until} s, {wp.get_device(a.device).name}")
# compile every kernel variant first, so no limit's timing pays for it
for b in batches:
    b_short = [{**b[0], "overrides": {**b[0]["overrides"], "run.duration": 0.01}}]
    run_together([functools.partial(execute.run_batch_iter, study, b_short, a.device)], a.device, 0)


def measure(limit: int) -> None:
    walls, started = {}, {}

    def start(k):
        started[k] = time.perf_counter()
        return execute.run_batch_iter(study, batches[k], a.device)

    def end(k, outcome):
        walls[k] = time.perf_counter() - started[k]
        if isinstance(outcome, BaseException):
            print(f"  launch {k + 1}: {outcome!r}")

    t0 = time.perf_counter()
    run_together([functools.partial(start, k) for k in range(len(batches))], a.device, limit, on_end=end)
    wall = time.perf_counter() - t0
    each = ", ".join(f"{len(batches[k])}w {walls[k]:.1f}" for k in sorted(walls))
    print(f"load limit {limit}: {wall:.1f} s in all; per launch (worlds, wall s): {each}", flush=True)


for limit in a.limits.split(","):
    measure(int(float(limit)))
