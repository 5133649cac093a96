"""Verification cases for the cohesive laws (JKR, EEPA) through the whole engine (part of ``warpdem verify``).

Quasi-static, displacement-controlled tests: a mesh plate with prescribed motion presses into a
sphere so heavy that it does not move (1e12 kg/m^3) and withdraws, with e = 1 (no dashpot); the
plate's reported force against the measured overlap is compared with the closed forms of
warpdem/engine/analytic.py. Then dynamic checks: the sticking speed of a JKR sphere against the energy
balance, and a dense cohesive pile at a large step that must stay finite.
"""

from __future__ import annotations

import math

import numpy as np

from warpdem.engine import analytic
from warpdem.engine.builder import ModelBuilder
from warpdem.engine.materials import Material, effective_moduli
from warpdem.engine.motion import Segment, WallMotion
from warpdem.engine.solver import SimulationError, Solver, SolverOptions

from .record import Record

R = 1.0e-3
"""Sphere radius of the quasi-static tests [m]."""
E = 1.0e7
"""Sphere Young's modulus [Pa] (the plate is 1e6 times stiffer)."""


HEAVY_BALL = Material("ball", density=1e12, youngs_modulus=E, poisson_ratio=0.3)
"""So heavy that the plate's pull and push do not move it: the plate prescribes the overlap."""
PLATE = Material("plate", density=7800.0, youngs_modulus=E * 1e6, poisson_ratio=0.3)
PRESS_E_STAR = effective_moduli(HEAVY_BALL, PLATE)[0]


def _press(device: str, law: str, stroke: list[tuple[float, float, int]], dt: float = 2e-7, **interaction):
    """Drive a plate along z from a gap of 2 um through ``stroke`` [(target overlap [m], speed [m/s],
    sample every k steps)], against a sphere too heavy to move.

    Returns (overlap [m], force on the plate along -z [N], stroke segment) at the samples, and the E* of the pair.
    """
    b = ModelBuilder(gravity=(0, 0, 0))
    b.add_material(HEAVY_BALL)
    b.add_material(PLATE)
    b.set_interaction("ball", "plate", restitution=1.0, static_friction=0.0, law=law, **interaction)
    gap0 = 2e-6
    segments, chunks, t, pos = [], [], 0.0, -gap0
    for target, speed, every in stroke:
        duration = abs(target - pos) / speed
        segments.append(Segment(t, t + duration, velocity=(0.0, 0.0, math.copysign(speed, target - pos))))
        chunks.append((int(round(duration / dt)), every))
        t += duration
        pos = target
    half = 5 * R
    verts = [(-half, -half, 0.0), (half, -half, 0.0), (half, half, 0.0), (-half, half, 0.0)]
    b.add_wall_mesh(verts, [(0, 1, 2), (0, 2, 3)], "plate", name="plate", motion=WallMotion.schedule(segments))
    b.add_sphere((0.0, 0.0, R + gap0), R, "ball")
    model = b.finalize(device)
    solver = Solver(model, SolverOptions(dt=dt))
    state, contacts = model.state(), solver.contacts()
    overlap, force, segment = [], [], []
    for k, (steps, every) in enumerate(chunks):
        for _ in range(max(steps // every, 1)):
            state = solver.run(state, contacts, every, use_graph=True)
            overlap.append(R - (state.sphere_x.numpy()[0, 2] - state.wall_pose.numpy()[0, 2]))
            force.append(-state.wall_f.numpy()[model.plane_count, 2])
            segment.append(k)
    return np.array(overlap), np.array(force), np.array(segment), PRESS_E_STAR


def case_jkr_quasi_static(device: str = "cpu") -> list[Record]:
    """JKR sphere on a plate, displacement-controlled: F(delta) on the stable branch at 20 points (1 %),
    peak attraction -3 pi gamma R* (1 %), force at break -1.832 pi gamma R* and break overlap delta_c (2 %)."""
    gamma = 0.1
    dc = analytic.jkr_break_overlap(R, PRESS_E_STAR, gamma)
    # slow and finely sampled near the break, where the force turns steeply
    overlap, force, _, e_star = _press(
        device, "JKR", [(2e-6, 2e-3, 100), (0.9 * dc, 2e-3, 100), (1.2 * dc, 2e-4, 6)], surface_energy=gamma
    )
    out = []
    unloading = np.arange(len(overlap)) > np.argmax(overlap)
    live = unloading & (np.abs(force) > 0)
    # 20 points of the withdrawal, from the deepest overlap to just above the break
    pick = np.flatnonzero(live)[np.linspace(0, int(live.sum()) - 2, 20).astype(int)]
    expected = analytic.jkr_force(overlap[pick], R, e_star, gamma)
    scale = 3.0 * math.pi * gamma * R
    worst = float(np.max(np.abs(force[pick] - expected)) / scale)
    out.append(
        Record(
            "JKR quasi-static",
            "worst |F - F_JKR| / (3 pi gamma R*) over 20 points",
            worst,
            0.0,
            "-",
            0.01,
            absolute=True,
        )
    )
    out.append(Record("JKR quasi-static", "peak attraction", float(force.min()), -scale, "N", 0.01))
    last = np.flatnonzero(live)[-1]
    out.append(
        Record(
            "JKR quasi-static",
            "force at break",
            float(force[last]),
            analytic.jkr_break_force(R, e_star, gamma),
            "N",
            0.02,
        )
    )
    # the contact ends between the last sample that carries a force and the next one
    broke_at = 0.5 * (overlap[last] + overlap[last + 1])
    out.append(Record("JKR quasi-static", "break overlap delta_c", broke_at, dc, "m", 0.02))
    return out


def case_eepa_loop(device: str = "cpu") -> list[Record]:
    """EEPA sphere on a plate: load to d1 and withdraw to separation (virgin, unloading and adhesive branches
    within 1 % of the peak force; residual plastic overlap lambda_p^(1/n) d_max; dissipated energy = loop
    area within 2 %); load, unload into the adhesive branch, reload past d1 (reloading climbs the unloading
    line, then the virgin branch); the same stroke with f0 shifts every force by f0."""
    params = dict(surface_energy=0.05, plasticity_ratio=0.4, slope_exponent=1.5, tensile_exponent=1.5)
    lam, n, chi, gamma = params["plasticity_ratio"], 1.5, 1.5, params["surface_energy"]
    d1, d2 = 4e-6, 6e-6
    d_p = analytic.eepa_plastic_overlap(d1, lam, n)
    speed, every = 2e-3, 50
    cycle = [(d1, speed, every), (-1e-6, speed, every)]
    reload = [(d1, speed, every), (0.5 * d_p, speed, every), (d2, speed, every), (-1e-6, speed, every)]
    runs = {
        "cycle": _press(device, "EEPA", cycle, **params),
        "cycle f0": _press(device, "EEPA", cycle, pull_off_force=-2e-4, **params),
        "reload": _press(device, "EEPA", reload, **params),
    }
    out = []

    def expected(overlap):
        # the law's history: the running maximum of the overlap while the contact lasts
        d_max = np.maximum.accumulate(np.maximum(overlap, 0.0))
        return np.array(
            [
                analytic.eepa_force(d, m, e_star, R, 0.0, n, lam, chi, gamma) if d > 0 else 0.0
                for d, m in zip(overlap, d_max)
            ]
        )

    overlap, force, segment, e_star = runs["cycle"]
    ref = expected(overlap)
    peak = float(np.max(np.abs(ref)))
    for name, mask in (("virgin loading", segment == 0), ("unloading and adhesion", segment == 1)):
        err = float(np.max(np.abs(force[mask] - ref[mask]))) / peak
        out.append(Record("EEPA loop", f"{name}: worst |F - F_EEPA| / F_peak", err, 0.0, "-", 0.01, absolute=True))
    unload = np.flatnonzero((segment == 1) & (overlap > 0))
    cross = unload[np.argmax(force[unload] <= 0.0)]
    measured = float(np.interp(0.0, [force[cross], force[cross - 1]], [overlap[cross], overlap[cross - 1]]))
    out.append(Record("EEPA loop", "residual plastic overlap", measured, d_p, "m", 0.01))
    work = float(np.trapezoid(force, overlap))
    out.append(
        Record(
            "EEPA loop",
            "energy dissipated by the cycle",
            work,
            analytic.eepa_loop_energy(d1, e_star, R, n, lam, chi, gamma),
            "J",
            0.02,
        )
    )
    f_shift = runs["cycle f0"][1]
    both = (overlap > 0.05 * d1) & (runs["cycle f0"][0] > 0.05 * d1)
    out.append(
        Record(
            "EEPA loop", "loop shift with f0 = -2e-4 N", float(np.median(f_shift[both] - force[both])), -2e-4, "N", 0.01
        )
    )

    overlap, force, segment, _ = runs["reload"]
    ref = expected(overlap)
    mask = (segment == 2) & (overlap > 0)
    err = float(np.max(np.abs(force[mask] - ref[mask]))) / peak
    out.append(
        Record("EEPA loop", "reloading past d_max: worst |F - F_EEPA| / F_peak", err, 0.0, "-", 0.01, absolute=True)
    )
    return out


def case_jkr_sticking(device: str = "cpu") -> list[Record]:
    """An elastic (e = 1) JKR sphere dropped onto a plate at 0.5 v_c stays bound and at 2 v_c escapes; the
    engine's critical speed (bisection) agrees with the energy balance m v_c^2 / 2 = W_adh (the hysteresis of
    JKR: the contact forms at delta = 0 and breaks at delta_c) within 10 %.

    With damping (e < 1) the closed form sqrt(2 W_adh / m) / e assumes the dashpot takes (1 - e^2) of the
    impact energy as in a Hertz impact; JKR's larger contact radius and the attractive phase make it take
    more, so that estimate is a lower bound (reported, not asserted)."""
    rho, gamma = 2500.0, 0.05
    ball = Material("ball", density=rho, youngs_modulus=E, poisson_ratio=0.3)
    plate = PLATE
    e_star, _ = effective_moduli(ball, plate)
    m = rho * 4.0 / 3.0 * math.pi * R**3

    def rebounds(v, e):
        b = ModelBuilder(gravity=(0, 0, 0))
        b.add_material(ball)
        b.add_material(plate)
        b.set_interaction("ball", "plate", restitution=e, static_friction=0.3, law="JKR", surface_energy=gamma)
        b.add_plane((0, 0, 0), (0, 0, 1), "plate")
        b.add_sphere((0, 0, R + 1e-6), R, "ball", velocity=(0, 0, -v))
        model = b.finalize(device)
        solver = Solver(model)
        t_contact = 40.0 * 2.87 * (m * m / (R * e_star**2 * max(v, 1e-3))) ** 0.2
        state = solver.run(model.state(), solver.contacts(), int(t_contact / solver.dt) + 200)
        return float(state.sphere_x.numpy()[0, 2]) > R + 2.0 * abs(analytic.jkr_break_overlap(R, e_star, gamma))

    def critical(e):
        v_c = analytic.jkr_critical_speed(m, R, e_star, gamma, e)
        lo, hi = 0.3 * v_c, 3.0 * v_c
        for _ in range(7):
            mid = math.sqrt(lo * hi)
            if rebounds(mid, e):
                hi = mid
            else:
                lo = mid
        return math.sqrt(lo * hi), v_c

    v_e1, v_c = critical(1.0)
    out = [
        Record(
            "JKR sticking (e = 1)",
            "stays at 0.5 v_c",
            float(not rebounds(0.5 * v_c, 1.0)),
            1.0,
            "-",
            0.0,
            absolute=True,
        ),
        Record(
            "JKR sticking (e = 1)", "escapes at 2 v_c", float(rebounds(2.0 * v_c, 1.0)), 1.0, "-", 0.0, absolute=True
        ),
        Record("JKR sticking (e = 1)", "critical speed (bisection)", v_e1, v_c, "m/s", 0.10),
    ]
    v_e7, v_c7 = critical(0.7)
    out.append(
        Record(
            "JKR sticking (e = 0.7)",
            "critical speed vs the Hertz-damping estimate (information)",
            v_e7,
            v_c7,
            "m/s",
            math.inf,
        )
    )
    return out


def case_cohesive_stress(device: str = "cpu", steps: int = 100_000) -> list[Record]:
    """A dense cohesive pile of spheres and clumps (EEPA particle-particle, JKR particle-wall, e = 0.1, strong
    adhesion, dt_fraction 0.5) runs 10^5 steps without a NaN and loses kinetic energy (LAMMPS #4180)."""
    rng = np.random.default_rng(3)
    b = ModelBuilder()
    b.add_material(Material("ore", density=2000.0, youngs_modulus=5e6, poisson_ratio=0.3))
    b.add_material(Material("steel", density=7800.0, youngs_modulus=2e11, poisson_ratio=0.3))
    sticky = dict(restitution=0.1, rolling_friction=0.1, rolling_model="EPSD", surface_energy=5.0)
    b.set_interaction(
        "ore", "ore", static_friction=0.6, law="EEPA", pull_off_force=-1e-4, plasticity_ratio=0.6, **sticky
    )
    b.set_interaction("ore", "steel", static_friction=0.5, law="JKR", **sticky)
    b.add_plane((0, 0, 0), (0, 0, 1), "steel")
    for axis in (0, 1):
        for side in (-1.0, 1.0):
            p = np.zeros(3)
            p[axis] = side * 0.006
            b.add_plane(p, -side * np.eye(3)[axis], "steel")
    r = 0.001
    pts = np.array([(i, j, k) for i in range(-2, 3) for j in range(-2, 3) for k in range(4)], dtype=float)
    pts = pts * 2.0 * r + np.array([0.0, 0.0, r]) + rng.uniform(-1e-4, 1e-4, pts.shape)
    b.add_spheres(pts, r * rng.uniform(0.9, 1.0, len(pts)), "ore", velocities=rng.normal(0.0, 0.3, pts.shape))
    # cohesive clumps mixed with the spheres, dropped on top
    from warpdem.engine.clumps import phosphate_template

    tpl = phosphate_template()
    on_top = [(-0.003, -0.003, 0.011), (0.003, 0.0, 0.012), (0.0, 0.003, 0.015)]
    b.add_clumps(tpl, on_top, "ore", scale=1.2e-3 / tpl.bounding_radius)
    model = b.finalize(device)
    solver = Solver(model, SolverOptions(dt_fraction=0.5))
    state = model.state()
    # kinetic energy of the spheres' translation (the clumps start at rest and only add potential energy)
    free = model.sphere_clump.numpy() < 0
    mass = 2000.0 * 4.0 / 3.0 * np.pi * model.sphere_radius.numpy()[free].astype(np.float64) ** 3
    ke0 = 0.5 * float(np.sum(mass * np.sum(state.sphere_v.numpy()[free].astype(np.float64) ** 2, axis=1)))
    finite, ke = 1.0, math.nan
    try:
        state = solver.run(state, solver.contacts(), steps)
        v = state.sphere_v.numpy()[free].astype(np.float64)
        finite = float(np.all(np.isfinite(v)) and np.all(np.isfinite(state.sphere_x.numpy())))
        ke = 0.5 * float(np.sum(mass * np.sum(v**2, axis=1)))
    except SimulationError:
        finite = 0.0
    return [
        Record("cohesive stress test", f"finite after {steps} steps at 0.5 T_R", finite, 1.0, "-", 0.0, absolute=True),
        Record(
            "cohesive stress test",
            "final / initial kinetic energy (dissipative: below 1)",
            ke / ke0,
            0.0,
            "-",
            1.0,
            absolute=True,
        ),
    ]


COHESION_CASES = {
    "jkr_quasi_static": case_jkr_quasi_static,
    "eepa_loop": case_eepa_loop,
    "jkr_sticking": case_jkr_sticking,
    "cohesive_stress": case_cohesive_stress,
}
