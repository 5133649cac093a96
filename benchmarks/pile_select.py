"""Time the pile selection (``runner.pile_select``: the spheres standing on the plate, less the grains lying
apart) on a full-size pile of seed 000's pellets: 1,500 141-sphere clumps (211,500 spheres), 1,440 of them
stacked in a 28 deg cone on the plate and 60 (4 %, as the Box-Behnken's worlds) strewn around it. Prints the
seconds per call (best of ``repeats``) and how many spheres it kept and left out.

    python benchmarks/pile_select.py [repeats]

Every angle-of-repose world is measured through this selection when its launch ends, and again by each gallery
picture and ``warpdem analyze --remeasure``.
"""

import sys
import time

import numpy as np
from scipy.spatial.transform import Rotation

from warpdem.engine.clumps import pellet_template
from warpdem.scene import rigs
from warpdem.scene.runner import pile_select

repeats = int(sys.argv[1]) if len(sys.argv) > 1 else 3
tpl = pellet_template()
offset, radius = np.asarray(tpl.sphere_offset), np.asarray(tpl.sphere_radius)
m = rigs.spec("funnel", {"particle": "pellet", "material": "pellet"}, smoke=False).measure
rng = np.random.default_rng(0)
slope, pitch, count, strays = np.tan(np.radians(28.0)), 5.0e-3, 1440, 60
# pellet centres on a lattice under the cone, lowest first, until the pile holds `count` pellets
grid = np.stack(np.meshgrid(*[np.arange(-30, 31)] * 2, np.arange(0, 30), indexing="ij"), -1).reshape(-1, 3) * pitch
grid[:, 2] *= 0.6  # pellets lie flat: 3.4 mm thick
rho = np.hypot(grid[:, 0], grid[:, 1])
top = (rho.max() - rho) * slope
cone = grid[np.argsort(grid[:, 2] - top)][:count]
cone[:, 2] += 2.0e-3
ring = rng.uniform(0.12, 0.18, strays) * np.exp(2j * np.pi * rng.uniform(size=strays))
centres = np.vstack([cone, np.column_stack([ring.real, ring.imag, np.full(strays, 2.0e-3)])])
centres += np.r_[m.center, m.base_height]
turn = Rotation.random(len(centres), random_state=1).as_matrix()
x = np.concatenate([c + offset @ q.T for c, q in zip(centres, turn)])
r = np.tile(radius, len(centres))
x[:, 2] -= (x[:, 2] - r).min() - m.base_height  # the lowest sphere rests on the plate
best = np.inf
for _ in range(repeats):
    t0 = time.perf_counter()
    xp, rp, detached = pile_select(x, r, m)
    best = min(best, time.perf_counter() - t0)
print(f"pile_select: {len(r)} spheres, {best:.2f} s (best of {repeats}); pile {len(rp)} spheres, {detached} left out")
