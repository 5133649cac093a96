"""Verification cases for clumps, moving mesh walls and factories (part of ``warpdem verify``).

Each case compares with a closed-form answer or a conservation law: rigid-body kinematics of the
prescribed wall motion, Newton's third law through the wall impulse, Coulomb sliding of a clump,
torque-free precession (Euler's equations integrated to 1e-10 by SciPy), exact factory counts.
"""

from __future__ import annotations

import math

import numpy as np

from .builder import ModelBuilder
from .materials import Material
from .motion import WallMotion, quat_rotate
from .solver import Solver, SolverOptions
from .record import RIGID, Record


def _box_mesh(half: float):
    """A closed cube [-half, half]^3 as 8 vertices and 12 triangles."""
    v = np.array([(x, y, z) for x in (-half, half) for y in (-half, half) for z in (-half, half)])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return v, np.array(tris)


def _square(half: float, z: float = 0.0):
    return (np.array([(-half, -half, z), (half, -half, z), (half, half, z), (-half, half, z)]),
            np.array([(0, 1, 2), (0, 2, 3)]))


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
        Record("box bounce (mesh vs planes)", "position difference after 0.1 s", dx, 0.0, "m", 1e-3 * half, absolute=True),
        Record("box bounce (mesh vs planes)", "velocity difference after 0.1 s", dv, 0.0, "m/s",
               1e-3 * float(np.linalg.norm(finals["planes"][1])), absolute=True),
        Record("box bounce (mesh vs planes)", "centre beyond half a radius from the walls", beyond, 0.0, "m", 0.0,
               absolute=True),
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
    keys = WallMotion.keyframes([0.0, 0.2, 0.4], [(0, 0, 0), (0.01, 0, 0.02), (0.01, 0.03, 0.02)],
                                [(0, 0, 0, 1), (0, 0, math.sin(0.25), math.cos(0.25)), (0, 0, 0, 1)])
    b.add_wall_mesh(v, t, "ball", name="hinged", motion=hinge)
    b.add_wall_mesh(v, t, "ball", name="keyed", motion=keys)
    b.add_sphere((0, 0, 1.0), 0.001, "ball")
    model = b.finalize(device)
    solver = Solver(model)
    state = solver.run(model.state(), solver.contacts(), int(round(0.3 / solver.dt)))
    poses = state.wall_pose.numpy()
    for k, (name, motion) in enumerate((("hinge", hinge), ("keyframes", keys))):
        pos, quat = motion.pose(state.time)
        corner = np.array([0.05, 0.05, 0.0])
        host = pos + quat_rotate(quat, corner)
        dev = poses[k, :3] + quat_rotate(poses[k, 3:], corner)
        out.append(Record(f"wall motion ({name})", "corner position at ~0.3 s vs host pose",
                          float(np.linalg.norm(dev - host)), 0.0, "m", 1e-6, absolute=True))
    # analytic hinge: rotated by 0.5 rad/s x (t - 0.1 s) about y through (0.05, 0, 0)
    angle = 0.5 * (state.time - 0.1)
    corner = np.array([-0.05, 0.0, 0.0]) - np.array([0.05, 0, 0])
    expected = np.array([0.05, 0, 0]) + np.array([corner[0] * math.cos(angle), 0.0, -corner[0] * math.sin(angle)])
    dev = poses[0, :3] + quat_rotate(poses[0, 3:], np.array([-0.05, 0.0, 0.0]))
    out.append(Record("wall motion (hinge)", "edge position vs rotation formula", float(np.linalg.norm(dev - expected)),
                      0.0, "m", 1e-6, absolute=True))

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
            pts = [(i * 2.05 * r, j * 2.05 * r, -r - 0.001 - k * 2.05 * r)
                   for i in range(-2, 3) for j in range(-2, 3) for k in range(2)]
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
            out.append(Record("piston", "particle momentum + wall impulse (relative)",
                              float(np.linalg.norm(momentum + impulse_half)) / scale, 0.0, "-", 1e-3, absolute=True))
            out.append(Record("piston", "momentum gained along the stroke", float(-momentum[2]), 0.0, "N s",
                              math.inf, absolute=True))
        else:
            out.append(Record("piston (no particles)", "impulse magnitude", float(np.linalg.norm(impulse)), 0.0,
                              "N s", 0.0, absolute=True))
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
        out.append(Record(f"thin shell ({label})", "closest centre-to-shell distance / radius", lowest / r, 0.0, "-",
                          math.inf, absolute=True))
        out.append(Record(f"thin shell ({label})", "centre stayed on its side", float(lowest > 0.0), 1.0, "-", 0.0,
                          absolute=True))
    return out


BODY_CASES = {
    "box_bounce": case_box_bounce,
    "wall_motion": case_wall_motion,
    "piston": case_piston,
    "thin_shell": case_thin_shell,
}
