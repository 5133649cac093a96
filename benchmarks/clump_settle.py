"""Drop N of seed 000's pellets (141-sphere clumps) into a 40 x 40 mm steel box on CPU and print, every 10 ms, the
mean kinetic energy per pellet and the fastest spin and speed: how a clump pile settles with each damping
convention of SolverOptions.clump_contact_mass.

    python benchmarks/clump_settle.py shared 60
    python benchmarks/clump_settle.py body 60
"""

import sys
import time

import numpy as np
import warp as wp

from warpdem.engine.builder import ModelBuilder
from warpdem.engine.clumps import pellet_template
from warpdem.engine.materials import Interaction, Material, RollingModel
from warpdem.engine.solver import Solver, SolverOptions
from warpdem.scene.rigs import STEEL

wp.config.quiet = True

mode = sys.argv[1] if len(sys.argv) > 1 else "shared"
n = int(sys.argv[2]) if len(sys.argv) > 2 else 60
tpl = pellet_template()
b = ModelBuilder(gravity=(0, 0, -9.81))
b.add_material(Material("grain", density=1330.0, poisson_ratio=0.35, shear_modulus=1.45e6))
b.add_material(STEEL)
ct = RollingModel.CONSTANT_TORQUE
b.set_interaction(
    "grain", "grain", Interaction(restitution=0.37, static_friction=0.63, rolling_friction=0.05, rolling_model=ct)
)
b.set_interaction(
    "grain", "steel", Interaction(restitution=0.45, static_friction=0.52, rolling_friction=0.03, rolling_model=ct)
)
b.set_interaction("steel", "steel", Interaction(restitution=0.5, static_friction=0.3))
L = 0.02
b.add_plane((0, 0, 0), (0, 0, 1), "steel")
for ax in (0, 1):
    for sg in (-1, 1):
        p = [0, 0, 0]
        p[ax] = sg * L
        nrm = [0, 0, 0]
        nrm[ax] = -sg
        b.add_plane(p, nrm, "steel")
rng = np.random.default_rng(1)
pos = []
k = 0
# layers of 5 x 5 pellets 7.5 mm apart, randomly oriented
for z in range(20):
    for i in range(-2, 3):
        for j in range(-2, 3):
            if k < n:
                pos.append((i * 0.0075, j * 0.0075, 0.004 + z * 0.0075))
                k += 1
q = rng.normal(size=(n, 4))
q /= np.linalg.norm(q, axis=1)[:, None]
b.add_clumps(tpl, pos, "grain", orientations=q)
m = b.finalize("cpu")
s = Solver(m, SolverOptions(clump_contact_mass=mode))
st, c = m.state(), s.contacts()
mass = 1330 * tpl.volume
t0 = time.time()
for _ in range(40):
    st = s.run(st, c, int(0.01 / s.dt))
    v = st.clump_v.numpy()
    w = st.clump_w.numpy()
    ke = 0.5 * mass * (v * v).sum(1).mean()
    print(
        f"{mode} t {st.time:.2f} s KE/particle {ke:.3e} J  max|w| {np.linalg.norm(w, axis=1).max():.2f}  max|v| {np.linalg.norm(v, axis=1).max():.3f}  wall {time.time() - t0:.0f}s",
        flush=True,
    )
