"""Experiment: what each kernel of a step costs inside a CUDA graph, on the diagnosis's 3 mm lab funnel
(3 worlds) filled to 0.5 s: a graph of N whole steps against graphs of N launches of one step kernel."""

import time

import warp as wp

from warpdem.diagnose import synthetic as syn
from warpdem.kernels import step as st
from warpdem.scene import rigs
from warpdem.scene.runner import scene_solver
from warpdem.scene.stage import build

wp.config.quiet = True
wp.init()
e = syn.funnel_experiments()[0]
spec = rigs.spec("funnel", {**syn.FUNNEL_FIXED, **{k: e[k] for k in ("particle_radius", "count", "rate")}})
model = build(spec, 3).finalize("cuda")
solver = scene_solver(model, spec.run)
state, contacts = model.state(), solver.contacts()
state = solver.advance(state, contacts, 0.5)
wp.synchronize()
N = 1000
b, m = solver._buffers, model
other = model.state()


def timed(name, fn):
    with wp.ScopedCapture() as cap:
        fn()
    wp.capture_launch(cap.graph)
    wp.synchronize()
    t0 = time.perf_counter()
    for _ in range(5):
        wp.capture_launch(cap.graph)
    wp.synchronize()
    print(f"{name:28s} {(time.perf_counter() - t0) / (5 * N) * 1e6:7.2f} us per step", flush=True)


def steps():
    solver._alternate(state, other, N, None, contacts)


timed("whole step", steps)
timed("begin_step", lambda: [st.launch_begin_step(m, b, solver.dt) for _ in range(N)])
timed("sum_wall_forces", lambda: [st.launch_sum_wall_forces(m, state, other, b, solver.dt) for _ in range(N)])
timed(
    "move_walls",
    lambda: [
        st.launch_move_walls(m, solver.control, contacts, other, b, skin=solver.skin, rebuild=b.no_rebuild)
        for _ in range(N)
    ],
)
timed(
    "step_spheres",
    lambda: [
        st.launch_step_spheres(
            m,
            contacts,
            state,
            other,
            b,
            features=solver.features,
            dt=solver.dt,
            kick=solver.dt,
            skin=solver.skin,
            velocity_limit=solver.options.velocity_limit,
            impact_speed_min=solver.options.impact_speed_min,
        )
        for _ in range(N)
    ],
)
timed("rebuild", lambda: [solver.rebuild(state, contacts) for _ in range(N // 10)])
