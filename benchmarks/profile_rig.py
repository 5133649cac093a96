"""Where the time of a full-size rig goes as it runs: the rig a study runs (by default seed 000's pellet funnel,
141-sphere clumps, as the Box-Behnken study), built and stepped exactly as ``run_scene`` does, with ``--worlds``
copies. Prints per output interval: wall seconds, steps per second, steps per neighbour-list rebuild, contacts per
sphere and the spheres in play (a factory's spheres count once poured); then, at each ``--profile-at`` time,
per-kernel GPU time over ``--steps`` eager steps (Warp's timing API, CUDA only).

    python benchmarks/profile_rig.py --device cuda --worlds 4 --until 1.6 --profile-at 0.4 --profile-at 1.5
    python benchmarks/profile_rig.py --rig lifting_cylinder --until 1.2 --interval 0.2 --profile-at 0.6

``--set KEY=VALUE`` changes a rig parameter (``--set particle=sphere --set particle_radius=0.0015``: the
diagnosis's lab-size funnels).

The 5-world launch of the Box-Behnken study on an NVIDIA H200 took 3.2 ms per step up to 1.15 s and
15.6 ms per step from 1.7 s to 2.1 s; this script was written to say why. The lifting cylinder of seed 002 runs at
a third of the bench's sphere-steps per second, the skin ruled out; ``--rig lifting_cylinder`` asks the same.
"""

import argparse
import time

import warp as wp

from warpdem.scene import rigs
from warpdem.scene.runner import scene_solver
from warpdem.scene.stage import build
from warpdem.verify.bench import contacts_per_sphere, kernel_profile

wp.config.quiet = True

p = argparse.ArgumentParser()
p.add_argument("--device", default="cuda")
p.add_argument("--rig", default="funnel", choices=sorted(rigs.RIGS))
p.add_argument("--worlds", type=int, default=1)
p.add_argument("--until", type=float, default=1.6, help="simulated seconds [s]")
p.add_argument("--interval", type=float, default=0.1, help="report every this many simulated seconds [s]")
p.add_argument("--profile-at", type=float, action="append", default=[], help="profile kernels at this time [s]")
p.add_argument("--steps", type=int, default=100, help="eager steps per kernel profile")
p.add_argument("--smoke", action="store_true", help="the CPU smoke size instead of the full size")
p.add_argument("--count", type=int, help="bodies per world (default: the rig's)")
p.add_argument("--skin", type=float, help="Verlet skin [m] (default: the solver's, 0.4 x the smallest radius)")
p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="a rig parameter, e.g. particle=sphere")
a = p.parse_args()
wp.init()
# the funnel's default is seed 000's pellets, the scene this script was first written for
params = {"particle": "pellet", "material": "pellet"} if a.rig == "funnel" else {}
params |= {"count": a.count} if a.count else {}
for item in a.set:
    key, _, value = item.partition("=")
    try:
        params[key] = float(value) if key not in ("particle", "material") else value
    except ValueError:
        params[key] = value
spec = rigs.spec(a.rig, params, a.smoke)
model = build(spec, a.worlds).finalize(a.device)
solver = scene_solver(model, spec.run, skin=a.skin)
state, contacts = model.state(), solver.contacts()
print(
    f"{a.worlds} world(s), {model.sphere_count} spheres, {model.clump_count} clumps, dt {solver.dt:.3g} s, "
    f"skin {solver.skin * 1e3:.3f} mm, neighbour slots {solver.options.neighbor_capacity}, "
    f"{wp.get_device(a.device).name}"
)
print(f"{'t [s]':>6} {'wall [s]':>9} {'steps/s':>8} {'steps/rebuild':>14} {'contacts/sphere':>16} {'active':>9}")
pending = sorted(a.profile_at)
t_wall0 = time.perf_counter()
while state.time < a.until - 0.5 * solver.dt:
    t_next = min(state.time + a.interval, a.until)
    if pending and pending[0] < t_next:
        t_next = max(pending[0], state.time + solver.dt)
    step0, reb0, t0 = state.step, solver.rebuild_count, time.perf_counter()
    state = solver.advance(state, contacts, t_next - state.time)
    wp.synchronize()
    wall = time.perf_counter() - t0
    steps, reb = state.step - step0, solver.rebuild_count - reb0
    active = int(state.sphere_active.numpy().sum())
    print(
        f"{state.time:6.3f} {wall:9.2f} {steps / max(wall, 1e-9):8.0f} {steps / max(reb, 1):14.1f} "
        f"{contacts_per_sphere(state, contacts, model):16.2f} {active:9d}",
        flush=True,
    )
    if pending and state.time >= pending[0] - 0.5 * solver.dt:
        pending.pop(0)
        if not wp.get_device(a.device).is_cuda:
            continue
        print(f"  kernels at t = {state.time:.3f} s, over {a.steps} eager steps:")
        state, ms = kernel_profile(solver, state, contacts, a.steps)
        print(f"  {ms:.3f} ms of kernel time per step")
print(f"total wall {time.perf_counter() - t_wall0:.1f} s")
