"""Steps per second on CUDA with the rebuild as a conditional graph node (blocks of ``cuda_graph_steps``)
against the fallback that reads the rebuild flag on the host every step, on the first part of a rig run.
Prints one line per mode and the largest difference between the two final states.

    python benchmarks/cuda_graph.py [--rig die_press] [--duration 0.05] [--set param=value] [--out DIR]
"""

import argparse
import dataclasses
import json
import time

import numpy as np
import warp as wp

from warpdem.engine import solver
from warpdem.scene import rigs
from warpdem.scene.runner import run_scene

wp.config.quiet = True

p = argparse.ArgumentParser()
p.add_argument("--rig", default="die_press")
p.add_argument("--duration", type=float, default=0.05)
p.add_argument("--set", action="append", default=[], help="param=value")
p.add_argument("--out", default="runs/cuda_graph")
a = p.parse_args()
wp.init()
# a short run first, so that neither timed mode pays for compiling the kernels
values = dict(item.split("=", 1) for item in a.set)


def shortened(duration):
    spec = rigs.spec(a.rig, values)
    return dataclasses.replace(spec, run=dataclasses.replace(spec.run, duration=duration))


run_scene(shortened(0.002), device="cuda", out_dir=f"{a.out}/warmup", frames=False)
final = {}
for block in (solver.CUDA_GRAPH_STEPS, 0):
    solver.CUDA_GRAPH_STEPS = block
    spec = shortened(a.duration)
    t0 = time.perf_counter()
    res = run_scene(spec, device="cuda", out_dir=f"{a.out}/{block}", frames=False)
    wall = time.perf_counter() - t0
    i = res.info
    final[block] = np.load(f"{a.out}/{block}/final.npz")
    print(
        json.dumps(
            {
                "rig": a.rig,
                "device": wp.get_device("cuda").name,
                "graph_steps": block,
                "spheres": i["spheres"],
                "steps": i["steps"],
                "wall_s": round(wall, 1),
                "steps_per_s": round(i["steps"] / wall),
            }
        ),
        flush=True,
    )
x, y = final.values()
print(
    json.dumps(
        {k: float(np.max(np.abs(x[k] - y[k]))) for k in x.files if x[k].dtype.kind == "f" and x[k].shape == y[k].shape}
    )
)
