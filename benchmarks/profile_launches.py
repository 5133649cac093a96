"""Where the wall time of the diagnosis's funnel launches goes, alone and side by side: the launches of
``synthetic.FUNNEL_*`` (spheres at 3, 4 and 5 mm, ``--worlds`` worlds each) run to ``--until`` seconds as
``run_scene`` runs them, first each alone, then all together (``runner.run_together``, a CUDA stream each),
under Python's profiler. Prints the wall times and the functions that took the most time of the host
(waiting for the GPU shows as the stream synchronisations).

    python benchmarks/profile_launches.py --device cuda [--worlds 9] [--until 1.0] [--top 25]
"""

import argparse
import cProfile
import dataclasses
import pstats
import time

import warp as wp

from warpdem.diagnose import synthetic as syn
from warpdem.scene import rigs
from warpdem.scene.runner import run_scene, run_scene_iter, run_together

wp.config.quiet = True

p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
p.add_argument("--device", default="cuda")
p.add_argument("--worlds", type=int, default=9)
p.add_argument("--until", type=float, default=1.0, help="simulated seconds [s]")
p.add_argument("--top", type=int, default=25)
p.add_argument("--skip-alone", action="store_true")
a = p.parse_args()
wp.init()
specs, ids = [], []
for e in syn.funnel_experiments():
    ids.append(e["id"])
    spec = rigs.spec("funnel", {**syn.FUNNEL_FIXED, **{k: e[k] for k in ("particle_radius", "count", "rate")}})
    specs.append(dataclasses.replace(spec, run=dataclasses.replace(spec.run, duration=a.until)))
seeds = list(range(1, a.worlds + 1))
# compile every kernel first, so neither timing below pays for it
run_scene(dataclasses.replace(specs[2], run=dataclasses.replace(specs[2].run, duration=0.02)), a.device, frames=False)


def alone():
    for i, s in zip(ids, specs):
        t0 = time.perf_counter()
        run_scene(s, a.device, world_count=a.worlds, world_seeds=seeds, frames=False, quiet=True)
        print(f"  alone: {i}: {time.perf_counter() - t0:.1f} s", flush=True)


def together():
    starts = [
        (lambda s=s: run_scene_iter(s, a.device, world_count=a.worlds, world_seeds=seeds, frames=False, quiet=True))
        for s in specs
    ]
    out = run_together(starts, a.device, 10**9)
    bad = [o for o in out if isinstance(o, BaseException)]
    if bad:
        raise bad[0]


for name, fn in (("alone", alone), ("together", together)):
    if name == "alone" and a.skip_alone:
        continue
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    fn()
    prof.disable()
    print(
        f"{name}: {time.perf_counter() - t0:.1f} s wall for {len(specs)} launches to {a.until} s, "
        f"{wp.get_device(a.device).name}",
        flush=True,
    )
    pstats.Stats(prof).sort_stats("tottime").print_stats(a.top)
