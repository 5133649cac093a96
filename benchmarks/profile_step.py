"""Where a step's time goes on a dense bed of seed-000 feed pellets (141-sphere clumps) in a box:
per-kernel GPU time over eager steps (Warp's timing API) and graph-replayed steps per second, for one
world and for a batch of worlds. Prints a table per world count.

    python benchmarks/profile_step.py [--device cuda] [--pellets 1500] [--worlds 1 --worlds 17]
"""

import argparse
import time

import numpy as np
import warp as wp

import warpdem as wd
from warpdem.engine.clumps import pellet_template
from warpdem.verify.bench import kernel_profile

wp.config.quiet = True

p = argparse.ArgumentParser()
p.add_argument("--device", default="cuda")
p.add_argument("--pellets", type=int, default=1500)
p.add_argument("--worlds", type=int, action="append")
p.add_argument("--fall", type=float, default=0.15, help="simulated seconds before profiling [s]")
p.add_argument("--steps", type=int, default=100, help="eager steps profiled")
p.add_argument("--skin-fraction", type=float, default=0.4, help="Verlet skin / smallest sphere radius")
p.add_argument("--capacity", type=int, help="neighbour slots per sphere (default: the solver's estimate)")
a = p.parse_args()
wp.init()
template = pellet_template()
for worlds in a.worlds or [1, 17]:
    b = wd.ModelBuilder()
    b.add_material(wd.Material("pellet", density=1250, youngs_modulus=4e6, poisson_ratio=0.4))
    b.add_material(wd.Material("steel", density=7900, shear_modulus=7e10, poisson_ratio=0.3))
    b.set_interaction("pellet", "pellet", restitution=0.37, static_friction=0.6, rolling_friction=0.05)
    b.set_interaction("pellet", "steel", restitution=0.45, static_friction=0.52, rolling_friction=0.03)
    side = int(np.ceil(np.sqrt(a.pellets / 10)))
    lattice = [(i, j, k) for k in range(10 * a.pellets) for j in range(side) for i in range(side)][: a.pellets]
    pos = (np.asarray(lattice, float) - [side / 2, side / 2, -0.5]) * 0.0085
    rng = np.random.default_rng(0)
    q = rng.normal(size=(a.pellets, 4))
    b.add_clumps(template, pos, "pellet", orientations=q / np.linalg.norm(q, axis=1, keepdims=True))
    half = side * 0.0085 / 2 + 0.004
    b.add_plane((0, 0, 0), (0, 0, 1), "steel")
    for axis in range(2):
        for sign in (1, -1):
            n = np.zeros(3)
            n[axis] = sign
            b.add_plane(-n * half, n, "steel")
    b.replicate(worlds)
    m = b.finalize(a.device)
    s = wd.Solver(m, wd.SolverOptions(neighbor_capacity=a.capacity, skin_fraction=a.skin_fraction))
    state, c = m.state(), s.contacts()
    steps = int(a.fall / s.dt)
    state = s.run(state, c, steps)
    wp.synchronize()
    rebuilds = s.rebuild_count
    t0 = time.perf_counter()
    state = s.run(state, c, 2048)
    wp.synchronize()
    rate = 2048 / (time.perf_counter() - t0)
    rebuilds = s.rebuild_count - rebuilds
    print(
        f"{worlds} worlds, {m.sphere_count} spheres ({m.clump_count} clumps), dt {s.dt:.3g} s, "
        f"skin {s.skin * 1e3:.3f} mm, {c.neighbor_capacity} slots, {wp.get_device(a.device).name}: {rate:.0f} graph steps/s = "
        f"{rate * m.sphere_count / 1e6:.0f} M sphere-steps/s, {2048 / max(rebuilds, 1):.1f} steps per rebuild; "
        f"eager kernels over {a.steps} steps:"
    )
    state, ms = kernel_profile(s, state, c, a.steps, top=100)
    print(f"   {ms:.3f} ms of kernel time per step")
