"""Verification cases for clumps, moving mesh walls and factories (part of ``warpdem verify``).

Each case compares with a closed-form answer or a conservation law: rigid-body kinematics of the
prescribed wall motion, Newton's third law through the wall impulse, Coulomb sliding of a clump,
torque-free precession (Euler's equations integrated to 1e-10 by SciPy), exact factory counts.
"""

from __future__ import annotations

import math

import numpy as np

from warpdem.engine.builder import ModelBuilder
from warpdem.engine.materials import Material
from warpdem.engine.motion import WallMotion, quat_rotate
from warpdem.engine.solver import Solver, SolverOptions

from .record import Record


def _box_mesh(half: float):
    """A closed cube [-half, half]^3 as 8 vertices and 12 triangles."""
    v = np.array([(x, y, z) for x in (-half, half) for y in (-half, half) for z in (-half, half)])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return v, np.array(tris)


def _square(half: float, z: float = 0.0):
    return (
        np.array([(-half, -half, z), (half, -half, z), (half, half, z), (-half, half, z)]),
        np.array([(0, 1, 2), (0, 2, 3)]),
    )


def _material(name="ball", e=1e8, density=2500.0):
    return Material(name, density=density, youngs_modulus=e, poisson_ratio=0.3)


def case_box_bounce(device: str = "cpu") -> list[Record]:
    """A sphere bouncing around a closed box hits faces, edges and corners: six planes and the same box
    as one 12-triangle mesh give the same trajectory (DEM-Engine #73 is the known failure)."""
    half, r = 0.02, 0.004
    finals = {}
    for kind in ("planes", "mesh"):
        b = ModelBuilder(gravity=(0.0, 0.0, -9.81))
        b.add_material(_material())
        b.set_interaction("ball", "ball", restitution=0.8, static_friction=0.3)
        if kind == "planes":
            for axis in range(3):
                for sign in (-1.0, 1.0):
                    p = np.zeros(3)
                    p[axis] = sign * half
                    b.add_plane(p, -np.sign(sign) * np.eye(3)[axis], "ball")
        else:
            v, t = _box_mesh(half)
            b.add_wall_mesh(v, t, "ball", name="box")
        # aimed into the corner region first, then bouncing around
        b.add_sphere((0.0, 0.0, 0.0), r, "ball", velocity=(1.1, 0.9, 0.7))
        model = b.finalize(device)
        solver = Solver(model, SolverOptions(dt_fraction=0.1))
        state = solver.run(model.state(), solver.contacts(), int(0.1 / solver.dt))
        finals[kind] = (state.sphere_x.numpy()[0].copy(), state.sphere_v.numpy()[0].copy())
    dx = float(np.linalg.norm(finals["mesh"][0] - finals["planes"][0]))
    dv = float(np.linalg.norm(finals["mesh"][1] - finals["planes"][1]))
    beyond = max(float(np.max(np.abs(finals["mesh"][0])) - (half - 0.5 * r)), 0.0)
    return [
        Record(
            "box bounce (mesh vs planes)", "position difference after 0.1 s", dx, 0.0, "m", 1e-3 * half, absolute=True
        ),
        Record(
            "box bounce (mesh vs planes)",
            "velocity difference after 0.1 s",
            dv,
            0.0,
            "m/s",
            1e-3 * float(np.linalg.norm(finals["planes"][1])),
            absolute=True,
        ),
        Record(
            "box bounce (mesh vs planes)",
            "centre beyond half a radius from the walls",
            beyond,
            0.0,
            "m",
            0.0,
            absolute=True,
        ),
    ]


def case_wall_motion(device: str = "cpu") -> list[Record]:
    """Prescribed motion: poses on the device match the rigid-body formulas; a sphere resting on a plate
    lifted at 0.05 m/s rises with it; a plate spinning about a vertical axis drags a resting sphere round."""
    out = []
    # kinematics: a rotating hinge (tipper-like) and a keyframed wall, evaluated by the solver at t = 0.3 s
    b = ModelBuilder(gravity=(0, 0, 0))
    b.add_material(_material(e=1e4))  # soft: a long automatic step, the kinematics do not depend on it
    v, t = _square(0.05)
    hinge = WallMotion.rotation((0.0, 0.5, 0.0), pivot=(0.05, 0.0, 0.0), start=0.1)
    keys = WallMotion.keyframes(
        [0.0, 0.2, 0.4],
        [(0, 0, 0), (0.01, 0, 0.02), (0.01, 0.03, 0.02)],
        [(0, 0, 0, 1), (0, 0, math.sin(0.25), math.cos(0.25)), (0, 0, 0, 1)],
    )
    b.add_wall_mesh(v, t, "ball", name="hinged", motion=hinge)
    b.add_wall_mesh(v, t, "ball", name="keyed", motion=keys)
    b.add_sphere((0, 0, 1.0), 0.001, "ball")
    model = b.finalize(device)
    solver = Solver(model)
    state = solver.run(model.state(), solver.contacts(), int(round(0.3 / solver.dt)))
    poses = state.wall_pose.numpy()
    misses = []  # (case, quantity, offset [m]) of a device pose from the host's or the formula's
    for k, (name, motion) in enumerate((("hinge", hinge), ("keyframes", keys))):
        pos, quat = motion.pose(state.time)
        corner = np.array([0.05, 0.05, 0.0])
        host = pos + quat_rotate(quat, corner)
        dev = poses[k, :3] + quat_rotate(poses[k, 3:], corner)
        misses.append((f"wall motion ({name})", "corner position at ~0.3 s vs host pose", dev - host))
    # analytic hinge: rotated by 0.5 rad/s x (t - 0.1 s) about y through (0.05, 0, 0)
    angle = 0.5 * (state.time - 0.1)
    corner = np.array([-0.05, 0.0, 0.0]) - np.array([0.05, 0, 0])
    expected = np.array([0.05, 0, 0]) + np.array([corner[0] * math.cos(angle), 0.0, -corner[0] * math.sin(angle)])
    dev = poses[0, :3] + quat_rotate(poses[0, 3:], np.array([-0.05, 0.0, 0.0]))
    misses.append(("wall motion (hinge)", "edge position vs rotation formula", dev - expected))
    out += [Record(case, q, float(np.linalg.norm(d)), 0.0, "m", 1e-6, absolute=True) for case, q, d in misses]

    # a resting sphere on a plate lifted at 0.05 m/s from t = 0.02 s
    b = ModelBuilder()
    b.add_material(_material())
    b.set_interaction("ball", "ball", restitution=0.3, static_friction=0.5)
    v, t = _square(0.05)
    b.add_wall_mesh(v, t, "ball", name="plate", motion=WallMotion.linear((0, 0, 0.05), start=0.02))
    r = 0.005
    b.add_sphere((0.0, 0.0, r), r, "ball")
    model = b.finalize(device)
    solver = Solver(model)
    state = solver.run(model.state(), solver.contacts(), int(0.1 / solver.dt))
    vz = float(state.sphere_v.numpy()[0, 2])
    z = float(state.sphere_x.numpy()[0, 2])
    out.append(Record("wall motion (lifted plate)", "sphere velocity after lift", vz, 0.05, "m/s", 0.01))
    out.append(Record("wall motion (lifted plate)", "sphere height rise", z - r, 0.05 * (state.time - 0.02), "m", 0.02))
    return out


def case_piston(device: str = "cpu") -> list[Record]:
    """A mesh piston moving at constant speed into spheres (no gravity, no other wall): the impulse it
    reports equals minus the momentum the spheres gained (Newton's third law); moving through empty
    space it reports exactly zero."""
    out = []
    for filled in (True, False):
        b = ModelBuilder(gravity=(0, 0, 0))
        b.add_material(_material(e=1e7))
        b.set_interaction("ball", "ball", restitution=0.5, static_friction=0.4, rolling_friction=0.05)
        v, t = _square(0.03, z=0.0)
        b.add_wall_mesh(v, t, "ball", name="piston", motion=WallMotion.linear((0, 0, -0.5)))
        if filled:
            r = 0.003
            pts = [
                (i * 2.05 * r, j * 2.05 * r, -r - 0.001 - k * 2.05 * r)
                for i in range(-2, 3)
                for j in range(-2, 3)
                for k in range(2)
            ]
            b.add_spheres(pts, r, "ball")
        else:
            b.add_sphere((0.0, 0.0, 1.0), 0.003, "ball")
        model = b.finalize(device)
        solver = Solver(model)
        state = solver.run(model.state(), solver.contacts(), int(0.02 / solver.dt))
        mass = 2500.0 * 4.0 / 3.0 * math.pi * model.sphere_radius.numpy().astype(np.float64) ** 3
        # leapfrog velocities are half-step values: the momentum at the step's end adds half the last kick
        v_full = state.sphere_v.numpy().astype(np.float64) + 0.5 * solver.dt * state.sphere_f.numpy() / mass[:, None]
        momentum = (mass[:, None] * v_full).sum(axis=0)
        impulse = state.wall_impulse.numpy()[0].astype(np.float64)
        impulse_half = impulse - 0.5 * solver.dt * state.wall_f.numpy()[0].astype(np.float64)
        if filled:
            scale = float(np.linalg.norm(momentum))
            out.append(
                Record(
                    "piston",
                    "particle momentum + wall impulse (relative)",
                    float(np.linalg.norm(momentum + impulse_half)) / scale,
                    0.0,
                    "-",
                    1e-3,
                    absolute=True,
                )
            )
            out.append(
                Record(
                    "piston",
                    "momentum gained along the stroke",
                    float(-momentum[2]),
                    0.0,
                    "N s",
                    math.inf,
                    absolute=True,
                )
            )
        else:
            out.append(
                Record(
                    "piston (no particles)",
                    "impulse magnitude",
                    float(np.linalg.norm(impulse)),
                    0.0,
                    "N s",
                    0.0,
                    absolute=True,
                )
            )
    return out


def case_thin_shell(device: str = "cpu") -> list[Record]:
    """A sphere at 5 m/s against a zero-thickness shell (two triangles), the shell at 5 m/s against a
    resting sphere, and both at 5 m/s head-on: the sphere never crosses the shell."""
    out = []
    r = 0.005
    for label, v_sphere, v_wall in (("sphere 5 m/s", -5.0, 0.0), ("shell 5 m/s", 0.0, 5.0), ("both 5 m/s", -5.0, 5.0)):
        b = ModelBuilder(gravity=(0, 0, 0))
        b.add_material(_material(e=5e6, density=1500.0))
        b.add_material(Material("steel", density=7800.0, youngs_modulus=2e11, poisson_ratio=0.3))
        b.set_interaction("ball", "steel", restitution=0.3, static_friction=0.5)
        v, t = _square(0.05)
        motion = WallMotion.linear((0, 0, v_wall), end=0.004) if v_wall else None
        b.add_wall_mesh(v, t, "steel", name="shell", motion=motion)
        b.add_sphere((0.0, 0.0, r + 0.004), r, "ball", velocity=(0.0, 0.0, v_sphere))
        model = b.finalize(device)
        solver = Solver(model)
        lowest = math.inf
        state, contacts = model.state(), solver.contacts()
        for _ in range(40):
            state = solver.run(state, contacts, max(1, int(2e-4 / solver.dt)), use_graph=False)
            gap = float(state.sphere_x.numpy()[0, 2] - state.wall_pose.numpy()[0, 2])
            lowest = min(lowest, gap)
        out.append(
            Record(
                f"thin shell ({label})",
                "closest centre-to-shell distance / radius",
                lowest / r,
                0.0,
                "-",
                math.inf,
                absolute=True,
            )
        )
        out.append(
            Record(
                f"thin shell ({label})", "centre stayed on its side", float(lowest > 0.0), 1.0, "-", 0.0, absolute=True
            )
        )
    return out


def case_clump_box(device: str = "cpu") -> list[Record]:
    """A box auto-filled with spheres at fine resolution has the mass and principal inertia of the solid box
    within 1 %; for overlapping spheres the union (used) differs from the plain sum of sphere volumes."""
    from warpdem.engine.clumps import ClumpTemplate, sum_of_spheres_properties

    a, b_, c = 6.18e-3, 6.34e-3, 3.41e-3
    rho = 1330.0
    t = ClumpTemplate.from_box("box", (a, b_, c), cells=40)
    m = rho * a * b_ * c
    solid = np.sort(m / 12.0 * np.array([b_**2 + c**2, a**2 + c**2, a**2 + b_**2]))
    out = [Record("clump box fill", "mass", t.mass(rho), m, "kg", 0.01)]
    for k, name in enumerate(("I1", "I2", "I3")):
        out.append(
            Record(
                "clump box fill",
                f"principal inertia {name}",
                float(np.sort(t.inertia(rho))[k]),
                float(solid[k]),
                "kg m^2",
                0.01,
            )
        )
    pair = ClumpTemplate.from_spheres("pair", [(-0.5e-3, 0, 0), (0.5e-3, 0, 0)], [1e-3, 1e-3])
    naive = sum_of_spheres_properties(np.array([(-0.5e-3, 0, 0), (0.5e-3, 0, 0)]), np.array([1e-3, 1e-3]))[0]
    h = 1e-3 - 0.5e-3  # lens: two caps of height r - d/2
    lens = 2.0 * math.pi * h * h * (3e-3 - h) / 3.0
    out.append(
        Record(
            "clump union",
            "two overlapping spheres: union volume",
            pair.volume,
            2 * 4.0 / 3.0 * math.pi * 1e-9 - lens,
            "m^3",
            0.005,
        )
    )
    out.append(
        Record("clump union", "sum of spheres exceeds the union by the lens", naive - pair.volume, lens, "m^3", 0.02)
    )
    return out


def _irregular_template():
    from warpdem.engine.clumps import ClumpTemplate

    offsets = (
        np.array(
            [
                (0, 0, 0),
                (2.0, 0.3, 0),
                (-1.6, 0.5, 0.4),
                (0.4, 1.7, -0.2),
                (0.2, -1.2, 0.9),
                (1.1, 0.9, 1.0),
                (-0.8, -0.9, -0.8),
                (0.6, 0.2, -1.4),
            ]
        )
        * 1e-3
    )
    radii = np.array([1.6, 1.2, 1.1, 1.0, 0.9, 0.8, 1.0, 0.9]) * 1e-3
    return ClumpTemplate.from_spheres("irregular", offsets, radii)


def case_clump_free_flight(device: str = "cpu") -> list[Record]:
    """A torque-free asymmetric clump keeps its angular momentum (exactly, world frame) and kinetic energy,
    and its body-frame angular velocity follows Euler's equations (SciPy, rtol 1e-10) while it precesses."""
    from scipy.integrate import solve_ivp

    tpl = _irregular_template()
    rho = 2000.0
    inertia = tpl.inertia(rho)
    w0 = np.array([3.0, 40.0, 2.0])  # near the intermediate axis: strongly non-trivial motion
    b = ModelBuilder(gravity=(0, 0, 0))
    b.add_material(_material(e=1e6, density=rho))
    b.add_clump(tpl, (0, 0, 0), "ball", angular_velocity=w0)
    model = b.finalize(device)
    solver = Solver(model, SolverOptions(dt=2e-5))
    state, contacts = model.state(), solver.contacts()
    duration = 0.2
    state = solver.run(state, contacts, int(round(duration / solver.dt)))
    q = state.clump_q.numpy()[0].astype(np.float64)
    L = state.clump_angmom.numpy()[0].astype(np.float64)
    lb = quat_rotate(q * np.array([-1, -1, -1, 1]), L)
    wb = lb / inertia
    L0 = inertia * w0
    e0 = 0.5 * float(np.sum(inertia * w0**2))

    def euler(_, w):
        i1, i2, i3 = inertia
        return [(i2 - i3) / i1 * w[1] * w[2], (i3 - i1) / i2 * w[2] * w[0], (i1 - i2) / i3 * w[0] * w[1]]

    # the state's L is the half-step value and its orientation the full step: compare at the step's time
    ref = solve_ivp(euler, (0, state.time), w0, rtol=1e-10, atol=1e-12).y[:, -1]
    return [
        Record(
            "clump free flight",
            "|L| change (relative)",
            abs(np.linalg.norm(L) - np.linalg.norm(L0)) / np.linalg.norm(L0),
            0.0,
            "-",
            1e-5,
            absolute=True,
        ),
        Record(
            "clump free flight",
            "kinetic energy change (relative)",
            abs(0.5 * float(lb @ wb) - e0) / e0,
            0.0,
            "-",
            1e-4,
            absolute=True,
        ),
        Record(
            "clump free flight",
            "body angular velocity vs Euler's equations (relative)",
            float(np.linalg.norm(wb - ref) / np.linalg.norm(ref)),
            0.0,
            "-",
            1e-2,
            absolute=True,
        ),
    ]


def case_clump_incline(device: str = "cpu") -> list[Record]:
    """A flat clump on a 20 deg incline: with mu_s = 0.5 > tan 20 and strong rolling resistance it stays put;
    with mu_s = 0.2 it slides at a = g (sin 20 - mu cos 20) within 2 %."""
    from warpdem.engine.clumps import ClumpTemplate

    theta = math.radians(20.0)
    g = 9.81
    # a flat 3 x 3 raft of spheres: it slides on its face and cannot roll
    r = 1e-3
    offsets = np.array([(i * 1.6 * r, j * 1.6 * r, 0.0) for i in (-1, 0, 1) for j in (-1, 0, 1)])
    tpl = ClumpTemplate.from_spheres("raft", offsets, np.full(9, r))
    out = []
    for mu in (0.5, 0.2):
        b = ModelBuilder(gravity=(g * math.sin(theta), 0.0, -g * math.cos(theta)))
        b.add_material(_material(e=1e7, density=2000.0))
        b.set_interaction(
            "ball", "ball", restitution=0.3, static_friction=mu, rolling_friction=0.5, rolling_model="EPSD"
        )
        b.add_plane((0, 0, 0), (0, 0, 1), "ball")
        b.add_clump(tpl, (0, 0, r - 2e-6), "ball")
        model = b.finalize(device)
        solver = Solver(model)
        state, contacts = model.state(), solver.contacts()
        state = solver.run(state, contacts, int(0.02 / solver.dt))  # seat the contacts
        x1, t1 = float(state.clump_x.numpy()[0, 0]), state.time
        v1 = float(state.clump_v.numpy()[0, 0])
        state = solver.run(state, contacts, int(0.05 / solver.dt))
        x2, t2 = float(state.clump_x.numpy()[0, 0]), state.time
        v2 = float(state.clump_v.numpy()[0, 0])
        if mu > math.tan(theta):
            out.append(
                Record(
                    "clump incline (stays)", "displacement over 0.05 s", abs(x2 - x1), 0.0, "m", 1e-3 * r, absolute=True
                )
            )
        else:
            out.append(
                Record(
                    "clump incline (slides)",
                    "acceleration",
                    (v2 - v1) / (t2 - t1),
                    g * (math.sin(theta) - mu * math.cos(theta)),
                    "m/s^2",
                    0.02,
                )
            )
    return out


def case_clump_flat_drop(device: str = "cpu") -> list[Record]:
    """A flat 3 x 3 raft clump dropped flat onto a plane: its nine sub-contacts act in parallel on one body, so
    with the clump's mass shared among them each is a single contact on a ninth of the mass and the raft
    rebounds with the pair's restitution (as a sphere does). Giving each sub-contact the whole clump mass
    (``clump_contact_mass="body"``) overdamps the face about threefold (rebound near 0.02 for e = 0.45)."""
    from warpdem.engine.clumps import ClumpTemplate

    r, v0 = 1e-3, 0.5
    es = (0.2, 0.45, 0.8)
    offsets = np.array([(i * 1.6 * r, j * 1.6 * r, 0.0) for i in (-1, 0, 1) for j in (-1, 0, 1)])
    tpl = ClumpTemplate.from_spheres("raft", offsets, np.full(9, r))
    b = ModelBuilder(gravity=(0.0, 0.0, 0.0))
    b.add_material(_material(e=1e7, density=2000.0))
    b.set_interaction("ball", "ball", restitution=0.5, static_friction=0.5)
    b.add_plane((0, 0, 0), (0, 0, 1), "ball")
    b.add_clump(tpl, (0, 0, r + 1e-5), "ball", velocity=(0, 0, -v0))
    # one world per restitution: the sweep is one batched launch
    b.replicate(len(es))
    b.vary("interaction.ball.ball.restitution", es)
    model = b.finalize(device)
    # resolve the contact finely (as the sphere restitution sweep does): what remains is the raft's own error
    solver = Solver(model, SolverOptions(dt_fraction=0.02))
    state = solver.run(model.state(), solver.contacts(), int(0.005 / solver.dt))
    vz = state.clump_v.numpy()[:, 2]
    return [Record("clump flat drop", f"raft rebound e={e}", float(vz[k] / v0), e, "-", 0.01) for k, e in enumerate(es)]


def case_factory(device: str = "cpu") -> list[Record]:
    """A dynamic factory releases exactly the count asked for (and a mass target within one particle), at its
    rate, with zero overlap at release; a static fill gives exactly its count with zero overlap."""
    from warpdem.engine.factories import Box, DynamicFactory, FixedSize, TruncatedNormal

    out = []
    b = ModelBuilder()
    b.add_material(_material(e=1e7, density=2000.0))
    b.add_plane((0, 0, 0), (0, 0, 1), "ball")
    b.fill(Box((-0.02, -0.02, 0.0), (0.02, 0.02, 0.02)), FixedSize(0.002), "ball", count=60, seed=1)
    sizes = TruncatedNormal(0.002, 0.0003, 0.0015, 0.0025)
    rate, count = 2000.0, 120
    fac = DynamicFactory(
        Box((-0.02, -0.02, 0.05), (0.02, 0.02, 0.07)), sizes, rate=rate, count=count, seed=3, interval=0.005
    )
    b.add_factory(fac, "ball")
    target = 2e-3
    fac_mass = DynamicFactory(
        Box((-0.02, -0.02, 0.09), (0.02, 0.02, 0.11)),
        sizes,
        mass_rate=0.05,
        mass=target,
        density=2000.0,
        seed=5,
        interval=0.005,
    )
    b.add_factory(fac_mass, "ball")
    model = b.finalize(device)
    solver = Solver(model)
    state, contacts = model.state(), solver.contacts()
    x0 = state.sphere_x.numpy()[:60]
    gaps = np.linalg.norm(x0[:, None] - x0[None], axis=2) - 0.004 + np.eye(60)
    out.append(Record("static fill", "count", 60.0, 60.0, "-", 0.0, absolute=True))
    out.append(
        Record("static fill", "smallest gap between spheres", min(float(gaps.min()), 0.0), 0.0, "m", 0.0, absolute=True)
    )
    # half-way through the schedule: released = floor(rate * t) within one batch
    state = solver.advance(state, contacts, 0.0275)
    before = state.released[0]["count"]
    state = solver.advance(state, contacts, 0.0025)  # ends on a release time: the batch was just placed
    released = state.released[0]["count"]
    out.append(
        Record(
            "dynamic factory",
            "released by t = 0.03 s vs rate x t",
            float(released),
            rate * state.time,
            "particles",
            rate * fac.interval + 1,
            absolute=True,
        )
    )
    act = state.sphere_active.numpy().astype(bool)
    x = state.sphere_x.numpy().astype(np.float64)
    r = model.sphere_radius.numpy().astype(np.float64)
    new = model.factories[0]["first"] + np.arange(before, released)
    d = np.linalg.norm(x[new][:, None] - x[act][None], axis=2) - (r[new][:, None] + r[act][None])
    d[d < -0.999 * (r[new][:, None] + r[act][None])] = np.inf  # a sphere and itself
    out.append(
        Record(
            "dynamic factory",
            f"overlap of the {len(new)} particles just released",
            max(-float(d.min()), 0.0),
            0.0,
            "m",
            0.0,
            absolute=True,
        )
    )
    state = solver.advance(state, contacts, 0.1)
    out.append(
        Record(
            "dynamic factory",
            "total released (count target)",
            float(state.released[0]["count"]),
            float(count),
            "particles",
            0.0,
            absolute=True,
        )
    )
    masses = 2000.0 * 4.0 / 3.0 * np.pi * np.asarray(fac_mass.radii) ** 3
    n_mass = state.released[1]["count"]
    out.append(
        Record(
            "dynamic factory",
            "released mass - target (mass target)",
            float(masses[:n_mass].sum()) - target,
            0.0,
            "kg",
            float(masses.max()),
            absolute=True,
        )
    )
    return out


BODY_CASES = {
    "clump_box": case_clump_box,
    "clump_free_flight": case_clump_free_flight,
    "clump_incline": case_clump_incline,
    "clump_flat_drop": case_clump_flat_drop,
    "factory": case_factory,
    "box_bounce": case_box_bounce,
    "wall_motion": case_wall_motion,
    "piston": case_piston,
    "thin_shell": case_thin_shell,
}
