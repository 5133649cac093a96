"""Full-size runs of the four rigs (the README's GPU wall times): prints one line per rig and writes each
run's metrics.json and final.npz under OUT/<rig>/ (no USD/VTK frames: the GPU machine has no usd-core).

    python benchmarks/rigs_full.py --device cuda --out OUT [--rig funnel --rig die_press ...] [--set RIG.KEY=VALUE]
        [--smoke] [--stop-after SECONDS]

``--set RIG.KEY=VALUE`` sets a rig parameter (``die_press.surface_energy=0.5``) or any other override
``warpdem run --set`` takes (``die_press.interaction.feed.feed.static_friction=0.6``) on that rig's scene.

``--smoke`` runs the CPU smoke size instead; ``--stop-after`` saves a checkpoint and exits 3 before a run would
pass that many wall seconds (the same command resumes it), so a long run fits a device's time limit.
"""

import argparse
import json
import sys
import time

import warp as wp

from warpdem.engine.keys import is_rig_key
from warpdem.scene import rigs
from warpdem.scene.runner import RunStopped, run_scene
from warpdem.scene.stage import apply_overrides

wp.config.quiet = True

p = argparse.ArgumentParser()
p.add_argument("--device", default="cuda")
p.add_argument("--out", default="runs/full")
p.add_argument("--rig", action="append")
p.add_argument("--set", action="append", default=[], help="RIG.KEY=VALUE")
p.add_argument("--smoke", action="store_true", help="the CPU smoke size")
p.add_argument("--stop-after", type=float, default=0.0, help="wall seconds; 0: no limit")
a = p.parse_args()
wp.init()
for rig in a.rig or list(rigs.RIGS):
    values = {}
    for item in a.set:
        k, v = item.split("=", 1)
        r, name = k.split(".", 1)
        if r == rig:
            values[name] = v
    rig_values = {k: v for k, v in values.items() if is_rig_key(k)}
    spec = rigs.spec(rig, rig_values, smoke=a.smoke)
    apply_overrides(spec, {k: v for k, v in values.items() if k not in rig_values})
    t0 = time.perf_counter()
    last = [0.0]

    def progress(frac, msg, rig=rig, t0=t0, last=last):
        # a line per tenth of the run, so a run cut off by a time limit still shows how far it got
        if frac >= last[0] + 0.1 or frac >= 1.0:
            last[0] = frac
            print(f"  {rig}: {100 * frac:.0f} % {msg} after {time.perf_counter() - t0:.0f} s", flush=True)

    try:
        res = run_scene(
            spec,
            device=a.device,
            out_dir=f"{a.out}/{rig}",
            frames=False,
            progress=progress,
            checkpoint_every=60.0 if a.stop_after else 0.0,
            stop_after=a.stop_after,
        )
    except RunStopped as e:
        print(
            f"  {rig}: stopped at {e.simulated_s:.4f} s simulated after {e.wall_s:.0f} s; rerun to resume", flush=True
        )
        sys.exit(3)
    i = res.info
    m = {k: v for k, v in res.metrics[0].items() if not isinstance(v, (list, dict))}
    print(
        json.dumps(
            {
                "rig": rig,
                "device": wp.get_device(a.device).name,
                "wall_s": round(time.perf_counter() - t0, 1),
                "spheres": i["spheres"],
                "clumps": i["clumps"],
                "glued": i["glued_spheres"],
                "dt_s": i["dt_s"],
                "dt_range_s": i["dt_range_s"],
                "step_margin_max": round(i["step_margin_max"], 3),
                "steps": i["steps"],
                "simulated_s": round(i["simulated_s"], 3),
                "stop": i["stop"],
                **m,
            }
        ),
        flush=True,
    )
