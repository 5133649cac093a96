"""Would launches side by side on one GPU finish sooner than one after another? The diagnosis's funnel launches
(``synthetic.FUNNEL_*``: spheres at 3, 4 and 5 mm, ``--worlds`` worlds each) are filled to ``--warm`` seconds,
then each replays ``--blocks`` of its captured step graph: first one launch after another, then all at once on
a stream each. Prints each launch's milliseconds per step both ways, the ratio of the wall times, and the
kernel time per step of the 3 mm launch (Warp's timer), which says how much of a step is the GPU idling
between small kernels.

    python benchmarks/concurrent_streams.py --device cuda [--worlds 9] [--warm 0.6] [--blocks 20]
"""

import argparse
import time

import warp as wp

from warpdem.diagnose import synthetic as syn
from warpdem.scene import rigs
from warpdem.scene.runner import scene_solver
from warpdem.scene.stage import build
from warpdem.verify.bench import kernel_profile

wp.config.quiet = True

p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
p.add_argument("--device", default="cuda")
p.add_argument("--worlds", type=int, default=9)
p.add_argument("--warm", type=float, default=0.6, help="simulated seconds of filling before timing [s]")
p.add_argument("--blocks", type=int, default=20, help="graph blocks replayed per launch")
p.add_argument("--copies", type=int, default=1, help="launches per size")
a = p.parse_args()
wp.init()
dev = wp.get_device(a.device)
jobs = []
for e in syn.funnel_experiments() * a.copies:
    spec = rigs.spec("funnel", {**syn.FUNNEL_FIXED, **{k: e[k] for k in ("particle_radius", "count", "rate")}})
    model = build(spec, a.worlds).finalize(a.device)
    solver = scene_solver(model, spec.run)
    state, contacts = model.state(), solver.contacts()
    t0 = time.perf_counter()
    state = solver.advance(state, contacts, a.warm)
    # one more run of a whole number of blocks captures the block graph the replays below use
    state = solver.run(state, contacts, 1 + 2 * solver.cuda_graph_steps)
    wp.synchronize_device(dev)
    print(f"{e['id']}: {model.sphere_count} spheres, dt {solver.dt:.3g} s, filled in {time.perf_counter() - t0:.1f} s")
    jobs.append({"id": e["id"], "solver": solver, "state": state, "contacts": contacts, "stream": wp.Stream(dev)})

for j in jobs:
    block = j["solver"].cuda_graph_steps
    j["graph"] = next(v[0][0] for k, v in j["solver"]._graph.items() if k[-1] == block)
    j["steps"] = a.blocks * j["solver"].cuda_graph_steps


def replay(j, stream=None):
    for _ in range(a.blocks):
        wp.capture_launch(j["graph"], stream=stream)


serial = {}
t0 = time.perf_counter()
for j in jobs:
    tj = time.perf_counter()
    replay(j)
    wp.synchronize_device(dev)
    serial[j["id"]] = time.perf_counter() - tj
t_serial = time.perf_counter() - t0
t0 = time.perf_counter()
done = {}
for j in jobs:
    replay(j, j["stream"])
for j in jobs:
    wp.synchronize_stream(j["stream"])
    done[j["id"]] = time.perf_counter() - t0
t_conc = time.perf_counter() - t0
for j in jobs:
    print(
        f"{j['id']}: {j['steps']} steps, {1e3 * serial[j['id']] / j['steps']:.3f} ms/step alone, "
        f"done after {done[j['id']]:.2f} s side by side"
    )
print(f"one after another {t_serial:.2f} s, side by side {t_conc:.2f} s: {t_serial / t_conc:.2f}x, {dev.name}")
j = jobs[0]
print(f"kernel time of {j['id']} ({a.worlds} worlds):")
_, ms = kernel_profile(j["solver"], j["state"], j["contacts"], 50)
print(f"{ms:.3f} ms of kernel time per step against {1e3 * serial[j['id']] / j['steps']:.3f} ms of wall per step")
