"""Analytic verification cases, shared by ``warpdem verify`` and the test suite.

Every case builds a tiny scene, runs it, and compares what it measured with a closed-form answer
(Hertz theory, Tsuji damping, Coulomb and rolling-friction mechanics, kinematics). Tolerances are
the issue's acceptance limits; each record says which.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from warpdem.engine.builder import ModelBuilder
from warpdem.engine.materials import Material, effective_moduli
from warpdem.engine.solver import Solver, SolverOptions
from warpdem.errors import PhysicsWarning

from .bodies import BODY_CASES
from .cohesion import COHESION_CASES
from .record import RIGID, Record

# ------------------------------------------------------------------------------------------------
# helpers


def _two_body_scene(mat: Material, wall: bool, **interaction) -> ModelBuilder:
    """A builder without gravity holding ``mat`` and, with ``wall``, the plane z = 0 of a rigid copy of it;
    ``interaction`` (set_interaction's keywords) applies between ``mat`` and the plane, or ``mat`` itself."""
    b = ModelBuilder(gravity=(0.0, 0.0, 0.0))
    b.add_material(mat)
    if wall:
        b.add_material(
            Material("rigid", density=mat.density, poisson_ratio=mat.poisson_ratio, youngs_modulus=mat.E * RIGID)
        )
    if interaction:
        b.set_interaction(mat.name, "rigid" if wall else mat.name, **interaction)
    if wall:
        b.add_plane((0, 0, 0), (0, 0, 1), "rigid")
    return b


def _run_contact(solver: Solver, state, contacts, gap_fn, max_steps: int):
    """Step until a contact has begun and ended; return the peak force, peak overlap and contact time.

    ``gap_fn(x)`` returns the overlap [m] from the positions. The contact time is interpolated
    linearly between the steps where the overlap changes sign.
    """
    spare = solver.model.state()
    a, b = state, spare
    prev = gap_fn(a.sphere_x.numpy())
    t_start = t_end = None
    f_max = d_max = 0.0
    for _ in range(max_steps):
        solver.step(a, b, None, contacts)
        a, b = b, a
        ov = gap_fn(a.sphere_x.numpy())
        if ov > 0:
            f_max = max(f_max, float(np.linalg.norm(a.sphere_f.numpy()[0])))
            d_max = max(d_max, ov)
        if prev <= 0 < ov and t_start is None:
            t_start = a.time - solver.dt * ov / (ov - prev)
        if prev > 0 >= ov and t_start is not None:
            t_end = a.time - solver.dt * ov / (ov - prev)
            break
        prev = ov
    if t_end is None:
        raise RuntimeError("contact did not end within the step budget")
    return f_max, d_max, t_end - t_start, a


def hertz_static_overlap(force: float, e_star: float, r_star: float) -> float:
    """Hertz overlap [m] under a static normal ``force`` [N]: (3 F / (4 E* sqrt(R*)))^(2/3)."""
    return (3 * force / (4 * e_star * math.sqrt(r_star))) ** (2 / 3)


def hertz_expected(e_star: float, r_star: float, m_star: float, v: float):
    """Hertz impact: (F_max [N], delta_max [m], t_c [s]) for approach speed v [m/s]."""
    d_max = (15.0 * m_star * v * v / (16.0 * e_star * math.sqrt(r_star))) ** 0.4
    f_max = 4.0 / 3.0 * e_star * math.sqrt(r_star) * d_max**1.5
    t_c = 2.87 * (m_star * m_star / (r_star * e_star * e_star * v)) ** 0.2
    return f_max, d_max, t_c


# ------------------------------------------------------------------------------------------------
# Chung & Ooi (2011) tests 1-4


def _normal_impacts(
    device, test: str, materials, R: float, v: float, wall: bool, *, static_friction: float, dt_fraction: float
) -> list[Record]:
    """Chung & Ooi tests 1 and 2: an elastic head-on impact for each of ``materials``, two spheres of radius
    ``R`` [m] meeting at +-``v`` [m/s] or, with ``wall``, one hitting a rigid plane at ``v``; the peak force
    [N], peak overlap [m] and contact time [s] against Hertz within 1 %."""
    out = []
    for mat in materials:
        b = _two_body_scene(mat, wall, restitution=1.0, static_friction=static_friction)
        m = mat.density * 4 / 3 * math.pi * R**3
        if wall:
            b.add_sphere((0, 0, R + 1e-6), R, mat.name, velocity=(0, 0, -v))
            nu = mat.poisson_ratio
            expected = hertz_expected(mat.E / (1 - nu * nu), R, m, v)
        else:
            b.add_sphere((-R - 1e-5, 0, 0), R, mat.name, velocity=(v, 0, 0))
            b.add_sphere((R + 1e-5, 0, 0), R, mat.name, velocity=(-v, 0, 0))
            expected = hertz_expected(effective_moduli(mat, mat)[0], R / 2, m / 2, 2 * v)
        model = b.finalize(device)
        solver = Solver(model, SolverOptions(dt_fraction=dt_fraction))
        f, d, tc, _ = _run_contact(
            solver,
            model.state(),
            solver.contacts(),
            lambda x: R - x[0, 2] if wall else 2 * R - (x[1, 0] - x[0, 0]),
            20000,
        )
        case = f"{test} {mat.name}"
        out += [
            Record(case, "peak force", f, expected[0], "N", 0.01),
            Record(case, "peak overlap", d, expected[1], "m", 0.01),
            Record(case, "contact time", tc, expected[2], "s", 0.01),
        ]
    return out


def case_chung_ooi_1(device: str = "cpu") -> list[Record]:
    """Test 1: two identical spheres, normal elastic impact at +-10 m/s (glass, limestone)."""
    glass = Material("glass", density=2800.0, youngs_modulus=48e9, poisson_ratio=0.20)
    limestone = Material("limestone", density=2500.0, youngs_modulus=20e9, poisson_ratio=0.25)
    return _normal_impacts(
        device, "Chung-Ooi 1", (glass, limestone), 0.01, 10.0, wall=False, static_friction=0.35, dt_fraction=0.02
    )


def case_chung_ooi_2(device: str = "cpu") -> list[Record]:
    """Test 2: sphere (R = 0.1 m) on a rigid plane at 0.2 m/s (Al alloy, Mg alloy)."""
    al = Material("Al alloy", density=2699.0, youngs_modulus=70e9, poisson_ratio=0.30)
    mg = Material("Mg alloy", density=1800.0, youngs_modulus=40e9, poisson_ratio=0.35)
    return _normal_impacts(device, "Chung-Ooi 2", (al, mg), 0.1, 0.2, wall=True, static_friction=0.0, dt_fraction=0.005)


def case_chung_ooi_3(device: str = "cpu") -> list[Record]:
    """Test 3: restitution sweep, alumina sphere (R = 2.5 mm) on a rigid plane at 3.9 m/s."""
    mat = Material("alumina", density=4000.0, youngs_modulus=380e9, poisson_ratio=0.23)
    R, v = 0.0025, 3.9
    es = (0.1, 0.3, 0.5, 0.7, 0.9)
    b = _two_body_scene(mat, wall=True)
    b.add_sphere((0, 0, R + 1e-6), R, "alumina", velocity=(0, 0, -v))
    # one world per restitution: the sweep is one batched launch
    b.replicate(len(es))
    b.vary("interaction.alumina.rigid.restitution", es)
    b.vary("interaction.alumina.rigid.static_friction", [0.0] * len(es))
    model = b.finalize(device)
    # e = 0.1 is critically damped within a few steps: resolve the contact with ~600 steps
    solver = Solver(model, SolverOptions(dt_fraction=0.005))
    state = model.state()
    contacts = solver.contacts()
    e_star = 380e9 / (1 - 0.23**2)
    t_c = hertz_expected(e_star, R, 4000.0 * 4 / 3 * math.pi * R**3, v)[2]
    state = solver.run(state, contacts, int(3.0 * t_c / solver.dt) + 10)
    vz = state.sphere_v.numpy()[:, 2]
    return [Record("Chung-Ooi 3", f"restitution e={e}", float(vz[k] / v), e, "-", 0.01) for k, e in enumerate(es)]


def case_chung_ooi_4(device: str = "cpu") -> list[Record]:
    """Test 4: oblique impact at |v| = 3.9 m/s, alumina (mu = 0.092, e = 0.98), gross sliding (theta > 32.5 deg).

    Closed form (rigid-body impulse with Coulomb sliding throughout): |w'| = 2.5 mu (1+e) v_n / R,
    e_t = 1 - mu (1+e) / tan(theta), contact-point rebound angle atan((tan(theta) - 3.5 mu (1+e)) / e).
    """
    mat = Material("alumina", density=4000.0, youngs_modulus=380e9, poisson_ratio=0.23)
    R, v, mu, e = 0.0025, 3.9, 0.092, 0.98
    angles = (40.0, 50.0, 60.0, 70.0, 80.0)
    b = _two_body_scene(mat, wall=True, restitution=e, static_friction=mu)
    b.add_sphere((0, 0, R + 1e-6), R, "alumina")
    b.replicate(len(angles))
    model = b.finalize(device)
    init_v = np.array([[v * math.sin(math.radians(t)), 0.0, -v * math.cos(math.radians(t))] for t in angles])
    model.initial["sphere_v"] = init_v.astype(np.float32)
    solver = Solver(model, SolverOptions(dt_fraction=0.02))
    state = model.state()
    e_star = 380e9 / (1 - 0.23**2)
    t_c = hertz_expected(e_star, R, 4000.0 * 4 / 3 * math.pi * R**3, v * math.cos(math.radians(80)))[2]
    state = solver.run(state, solver.contacts(), int(3.0 * t_c / solver.dt) + 10)
    vel, om = state.sphere_v.numpy(), state.sphere_w.numpy()
    out = []
    for k, theta in enumerate(angles):
        th = math.radians(theta)
        vn, vt = v * math.cos(th), v * math.sin(th)
        w_exp = 2.5 * mu * (1 + e) * vn / R
        et_exp = 1 - mu * (1 + e) / math.tan(th)
        reb_exp = math.degrees(math.atan((math.tan(th) - 3.5 * mu * (1 + e)) / e))
        w_sim = abs(float(om[k, 1]))
        et_sim = float(vel[k, 0]) / vt
        # contact-point tangential velocity after impact: v_t' - w' R (the spin opposes the slip)
        vcp = float(vel[k, 0]) - float(om[k, 1]) * R
        reb_sim = math.degrees(math.atan2(vcp, float(vel[k, 2])))
        case = f"Chung-Ooi 4 theta={theta:g}"
        out += [
            Record(case, "spin |w'|", w_sim, w_exp, "rad/s", 0.03),
            Record(case, "tangential restitution", et_sim, et_exp, "-", 0.03),
            Record(case, "rebound angle", reb_sim, reb_exp, "deg", 0.03),
        ]
    return out


# ------------------------------------------------------------------------------------------------
# rolling resistance


def _rolling_scene(device, model_name: str, mu_r: float, tilt_deg: float = 0.0, v0: float = 0.0, worlds=None):
    """A sphere (R = 5 mm) resting on a plane at its static Hertz overlap; gravity tilted by ``tilt_deg``."""
    R, rho, E, nu = 0.005, 2500.0, 1e8, 0.3
    mat = Material("ball", density=rho, youngs_modulus=E, poisson_ratio=nu)
    g = 9.81
    tilts = worlds if worlds is not None else [tilt_deg]
    b = ModelBuilder()
    b.add_material(mat)
    b.add_material(Material("floor", density=rho, youngs_modulus=E * RIGID, poisson_ratio=nu))
    b.set_interaction(
        "ball", "floor", restitution=0.5, static_friction=1.0, rolling_friction=mu_r, rolling_model=model_name
    )
    b.add_plane((0, 0, 0), (0, 0, 1), "floor")
    m = rho * 4 / 3 * math.pi * R**3
    e_star = E / (1 - nu * nu)
    d0 = hertz_static_overlap(m * g, e_star, R)
    b.add_sphere((0, 0, R - d0), R, "ball", velocity=(v0, 0, 0), angular_velocity=(0, v0 / R, 0))
    b.replicate(len(tilts))
    b.vary("gravity", [(g * math.sin(math.radians(t)), 0.0, -g * math.cos(math.radians(t))) for t in tilts])
    return b.finalize(device)


ROLLING_LABELS = {"constant_torque": "type A", "epsd": "type C (EPSD)", "standard": "EDEM standard"}
"""The rolling models the cases run, by name, and how their records name them."""


def case_rolling_plane(device: str = "cpu") -> list[Record]:
    """A ball rolling on a plane decelerates at (5/7) mu_r g (every model: on a wall R* = R_i = R); EPSD comes to
    rest."""
    out = []
    mu_r, v0, g = 0.1, 0.3, 9.81
    a_exp = 5.0 / 7.0 * mu_r * g
    t_stop = v0 / a_exp
    for name, label in ROLLING_LABELS.items():
        model = _rolling_scene(device, name, mu_r, v0=v0)
        solver = Solver(model)
        state, contacts = model.state(), solver.contacts()
        chunk = max(1, int(0.01 / solver.dt))
        ts, vs = [], []
        while state.time < 0.8 * t_stop:
            state = solver.run(state, contacts, chunk)
            ts.append(state.time)
            vs.append(float(state.sphere_v.numpy()[0, 0]))
        ts, vs = np.array(ts), np.array(vs)
        keep = ts > 0.1 * t_stop
        slope = np.polyfit(ts[keep], vs[keep], 1)[0]
        out.append(Record(f"rolling on plane {label}", "deceleration", -slope, a_exp, "m/s^2", 0.02))
        if name == "epsd":
            state = solver.run(state, contacts, int((0.5 * t_stop) / solver.dt))
            w_end = float(np.linalg.norm(state.sphere_w.numpy()[0]))
            v_end = float(np.linalg.norm(state.sphere_v.numpy()[0]))
            # at rest: the residual speed is below 0.1 % of the initial speed
            out.append(
                Record(
                    f"rolling on plane {label}",
                    "speed after stop",
                    v_end + w_end * 0.005,
                    0.0,
                    "m/s",
                    1e-3 * v0,
                    absolute=True,
                )
            )
    return out


def case_rolling_incline(device: str = "cpu") -> list[Record]:
    """A ball on an incline stays iff tan(theta) <= mu_r (every model; mu_s = 1, no sliding)."""
    out = []
    mu_r = 0.2
    tilts = [math.degrees(math.atan(0.8 * mu_r)), math.degrees(math.atan(1.25 * mu_r))]
    for name, label in ROLLING_LABELS.items():
        model = _rolling_scene(device, name, mu_r, worlds=tilts)
        solver = Solver(model)
        state = solver.run(model.state(), solver.contacts(), int(0.3 / solver.dt))
        x = state.sphere_x.numpy()[:, 0]
        # below the limit: creep under 1 % of the radius in 0.3 s; above: rolls (net torque >= 0.25 of
        # the driving torque gives a travel of > 2 mm in 0.3 s)
        out.append(
            Record(
                f"incline {label} tan={0.8 * mu_r:.2f}", "displacement", abs(float(x[0])), 0.0, "m", 5e-5, absolute=True
            )
        )
        moved = float(x[1])
        a_exp = 5.0 / 7.0 * 9.81 * (math.sin(math.radians(tilts[1])) - mu_r * math.cos(math.radians(tilts[1])))
        out.append(
            Record(f"incline {label} tan={1.25 * mu_r:.2f}", "displacement", moved, 0.5 * a_exp * 0.3**2, "m", 0.05)
        )
    return out


# ------------------------------------------------------------------------------------------------
# kinematics and energy


def _spin_deceleration(device, build, probe, w0: float, t_end: float) -> float:
    """Angular deceleration [rad/s^2] of the spin ``probe(state)`` [rad/s] of the scene ``build(device)`` while
    it is between 90 % and 20 % of ``w0``, from a line fitted over 1 ms samples up to ``t_end`` [s]."""
    model = build(device)
    solver = Solver(model)
    state, contacts = model.state(), solver.contacts()
    chunk = max(1, int(0.001 / solver.dt))
    ts, ws = [], []
    while state.time < t_end:
        state = solver.run(state, contacts, chunk)
        ts.append(state.time)
        ws.append(probe(state))
    ts, ws = np.array(ts), np.array(ws)
    keep = (ws < 0.9 * w0) & (ws > 0.2 * w0)
    if keep.sum() < 5:
        return float("nan")
    return -float(np.polyfit(ts[keep], ws[keep], 1)[0])


def case_rolling_lever(device: str = "cpu") -> list[Record]:
    """EDEM's standard rolling friction takes each body's own lever R_i, the contact point's distance from its
    centre of mass, and resists a spin about the normal too (mu_s = 0 here, so nothing else does).

    - A sphere spinning about the vertical on top of an equal sphere that rests on a plane:
      dw/dt = mu_r m g R_i / (2/5 m R^2), R_i = R less half the overlap; type A (R* = R/2, twisting not
      resisted) leaves the spin alone.
    - A dumbbell clump (two spheres R, centres +-L from its centre of mass) lying on a plane, spinning about the
      vertical: dw/dt = mu_r g sqrt(L^2 + R^2) / (2/5 R^2 + L^2), each sphere's lever reaching from the clump's
      centre of mass to its contact point (a sphere's own R would give 2.2 times less).
    """
    from warpdem.engine.clumps import ClumpTemplate

    R, rho, E, nu, g, mu_r, L = 0.005, 2500.0, 1e8, 0.3, 9.81, 0.1, 0.010
    m = rho * 4.0 / 3.0 * math.pi * R**3

    def materials(b, model_name):
        b.add_material(Material("ball", density=rho, youngs_modulus=E, poisson_ratio=nu))
        b.add_material(Material("floor", density=rho, youngs_modulus=E * RIGID, poisson_ratio=nu))
        b.set_interaction("ball", "floor", restitution=0.5, static_friction=0.0, rolling_friction=0.0)
        b.set_interaction(
            "ball", "ball", restitution=0.5, static_friction=0.0, rolling_friction=mu_r, rolling_model=model_name
        )
        b.add_plane((0, 0, 0), (0, 0, 1), "floor")

    # static overlaps: the lower sphere carries 2 m g on the rigid floor, the pair m g at R* = R/2
    e_floor = E / (1 - nu * nu)
    d_floor = hertz_static_overlap(2 * m * g, e_floor, R)
    d_pair = hertz_static_overlap(m * g, 0.5 * e_floor, 0.5 * R)
    w0_stack = 50.0

    def stack(model_name):
        def build(device):
            b = ModelBuilder()
            materials(b, model_name)
            b.add_sphere((0, 0, R - d_floor), R, "ball")
            b.add_sphere((0, 0, 3 * R - d_floor - d_pair), R, "ball", angular_velocity=(0, 0, w0_stack))
            return b.finalize(device)

        return build

    top_spin = lambda state: float(state.sphere_w.numpy()[1, 2])  # noqa: E731
    a_stack = 2.5 * mu_r * g * (R - 0.5 * d_pair) / R**2
    out = [
        Record(
            "spin on a sphere, EDEM standard",
            "spin deceleration",
            _spin_deceleration(device, stack("standard"), top_spin, w0_stack, 1.2 * w0_stack / a_stack),
            a_stack,
            "rad/s^2",
            0.02,
        )
    ]
    # type A resists only the rolling part of the relative rotation: the top sphere keeps its spin
    model = stack("constant_torque")(device)
    solver = Solver(model)
    state = solver.run(model.state(), solver.contacts(), int(0.5 * w0_stack / a_stack / solver.dt))
    out.append(Record("spin on a sphere, type A", "spin kept", top_spin(state), w0_stack, "rad/s", 1e-3))

    # the dumbbell: two spheres on the floor, each at m g / 2 on the rigid plane
    tpl = ClumpTemplate.from_spheres("dumbbell", [(-L, 0, 0), (L, 0, 0)], [R, R])
    d_each = hertz_static_overlap(m * g, e_floor, R)
    w0_bell = 20.0

    def bell(device):
        b = ModelBuilder()
        materials(b, "standard")
        b.set_interaction(
            "ball", "floor", restitution=0.5, static_friction=0.0, rolling_friction=mu_r, rolling_model="standard"
        )
        b.add_clump(tpl, (0, 0, R - d_each), "ball", angular_velocity=(0, 0, w0_bell))
        return b.finalize(device)

    lever = math.sqrt(L**2 + (R - 0.5 * d_each) ** 2)
    a_bell = mu_r * g * lever / (0.4 * R**2 + L**2)
    bell_spin = lambda state: float(state.clump_w.numpy()[0, 2])  # noqa: E731
    out.append(
        Record(
            "spinning dumbbell clump, EDEM standard",
            "spin deceleration",
            _spin_deceleration(device, bell, bell_spin, w0_bell, 1.2 * w0_bell / a_bell),
            a_bell,
            "rad/s^2",
            0.02,
        )
    )
    return out


def case_free_fall(device: str = "cpu") -> list[Record]:
    """Free fall from h0 = 1 m for 0.4 s: z = h0 - g t^2 / 2 (leapfrog is exact for constant acceleration)."""
    b = ModelBuilder()
    b.add_material(Material("ball", density=2500.0, youngs_modulus=1e8, poisson_ratio=0.3))
    b.add_sphere((0, 0, 1.0), 0.005, "ball")
    model = b.finalize(device)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # no contact in free flight: the Rayleigh limit does not apply
        solver = Solver(model, SolverOptions(dt=1e-4))
    state = solver.run(model.state(), solver.contacts(), 4000)
    z = float(state.sphere_x.numpy()[0, 2])
    t = state.time
    # leapfrog stores v(t - dt/2)
    vz = float(state.sphere_v.numpy()[0, 2])
    # float32 round-off: a random walk of ~1 ulp of 1 m per step, i.e. ~1e-7 sqrt(steps); 10x margin
    return [
        Record("free fall", "height", z, 1.0 - 0.5 * 9.81 * t * t, "m", 1e-6 * 4000**0.5, absolute=True),
        # float32 velocity sum: each of the 4000 kicks rounds by at most half an ulp of |v| (2^-23 * 4)
        Record(
            "free fall", "velocity at t - dt/2", vz, -9.81 * (t - 0.5e-4), "m/s", 4000 * 2.0**-23 * 4.0, absolute=True
        ),
    ]


def _bounce_energy_error(device: str, dt_fraction: float) -> float:
    b = ModelBuilder()
    mat = Material("ball", density=2500.0, youngs_modulus=1e7, poisson_ratio=0.3)
    b.add_material(mat)
    b.set_interaction("ball", "ball", restitution=1.0, static_friction=0.0)
    b.add_plane((0, 0, 0), (0, 0, 1), "ball")
    R, h0 = 0.005, 0.02
    b.add_sphere((0, 0, h0), R, "ball")
    model = b.finalize(device)
    solver = Solver(model, SolverOptions(dt_fraction=dt_fraction))
    state = solver.run(model.state(), solver.contacts(), int(0.5 / solver.dt))
    m = 2500.0 * 4 / 3 * math.pi * R**3
    z = float(state.sphere_x.numpy()[0, 2])
    # leapfrog velocities lag half a step: bring v back to the position's time with the force of this step
    v = state.sphere_v.numpy()[0] - 0.5 * solver.dt * (state.sphere_f.numpy()[0] / m + np.array([0, 0, -9.81]))
    overlap = max(R - z, 0.0)
    e_star = 1.0 / (2 * (1 - 0.09) / 1e7)
    pe_spring = 8.0 / 15.0 * e_star * math.sqrt(R) * overlap**2.5
    energy = 0.5 * m * float(v @ v) + m * 9.81 * z + pe_spring
    return abs(energy / (m * 9.81 * h0) - 1.0)


def case_elastic_bounce(device: str = "cpu") -> list[Record]:
    """e = 1, mu = 0 bouncing sphere: energy error after 0.5 s shrinks with dt (second order: ~4x per halving)."""
    e1 = _bounce_energy_error(device, 0.2)
    e2 = _bounce_energy_error(device, 0.05)
    return [
        Record("elastic bounce", "energy error at 0.2 T_R", e1, 0.0, "-", 2e-2, absolute=True),
        Record("elastic bounce", "energy error ratio 0.05/0.2 T_R", e2 / max(e1, 1e-30), 0.0, "-", 0.5, absolute=True),
    ]


# ------------------------------------------------------------------------------------------------
# walls and batching


def case_mesh_vs_plane(device: str = "cpu") -> list[Record]:
    """A sphere bouncing obliquely on a two-triangle square and on the same plane rebounds alike; a sphere
    resting exactly on the shared diagonal carries its weight once (no double contact)."""
    out = []
    results = {}
    for kind in ("plane", "mesh"):
        for x0 in (0.0, 0.01):  # 0.0 lands on the shared diagonal, 0.01 inside one triangle
            b = ModelBuilder()
            b.add_material(Material("ball", density=2500.0, youngs_modulus=1e8, poisson_ratio=0.3))
            b.set_interaction("ball", "ball", restitution=0.6, static_friction=0.3)
            if kind == "plane":
                b.add_plane((0, 0, 0), (0, 0, 1), "ball")
            else:
                L = 0.1
                b.add_wall_mesh([(-L, -L, 0), (L, -L, 0), (L, L, 0), (-L, L, 0)], [(0, 1, 2), (0, 2, 3)], "ball")
            b.add_sphere((x0, x0, 0.006), 0.005, "ball", velocity=(0.3, -0.2, -1.0))
            model = b.finalize(device)
            solver = Solver(model)
            state = solver.run(model.state(), solver.contacts(), int(0.01 / solver.dt))
            results[kind, x0] = (state.sphere_v.numpy()[0].copy(), state.sphere_w.numpy()[0].copy())
    for x0 in (0.0, 0.01):
        vp, wp_ = results["plane", x0]
        vm, wm = results["mesh", x0]
        where = "diagonal" if x0 == 0.0 else "face"
        out.append(
            Record(
                f"mesh vs plane ({where})",
                "rebound velocity difference",
                float(np.linalg.norm(vm - vp)),
                0.0,
                "m/s",
                1e-3 * float(np.linalg.norm(vp)),
                absolute=True,
            )
        )
        out.append(
            Record(
                f"mesh vs plane ({where})",
                "spin difference",
                float(np.linalg.norm(wm - wp_)),
                0.0,
                "rad/s",
                1e-3 * max(float(np.linalg.norm(wp_)), 1.0),
                absolute=True,
            )
        )
    return out


def _pile_scene(device, worlds):
    rng = np.random.default_rng(7)
    b = ModelBuilder()
    b.add_material(Material("grain", density=1500.0, youngs_modulus=5e6, poisson_ratio=0.3))
    b.add_material(Material("steel", density=7800.0, youngs_modulus=2e11, poisson_ratio=0.3))
    b.set_interaction("grain", "grain", restitution=0.5, static_friction=0.5, rolling_friction=0.05)
    b.set_interaction("grain", "steel", restitution=0.5, static_friction=0.5, rolling_friction=0.05)
    b.add_plane((0, 0, 0), (0, 0, 1), "steel")
    pts = np.array([(i * 0.0045, j * 0.0045, 0.003 + k * 0.0045) for i in range(3) for j in range(3) for k in range(3)])
    pts += rng.uniform(-3e-4, 3e-4, pts.shape)
    b.add_spheres(pts, rng.uniform(0.0018, 0.0021, len(pts)), "grain")
    b.replicate(len(worlds))
    b.vary("interaction.grain.grain.static_friction", [w[0] for w in worlds])
    b.vary("interaction.grain.grain.restitution", [w[1] for w in worlds])
    return b.finalize(device)


def case_batch_invariance(device: str = "cpu") -> list[Record]:
    """World k of a batch of W gives the same trajectory as a solo run of its parameters (rel. 1e-6)."""
    worlds = [(0.3, 0.4), (0.5, 0.5), (0.7, 0.8)]
    steps = 1500
    model = _pile_scene(device, worlds)
    solver = Solver(model)
    batch = solver.run(model.state(), solver.contacts(), steps).sphere_x.numpy().reshape(len(worlds), -1, 3)
    out = []
    for k, w in enumerate(worlds):
        solo_model = _pile_scene(device, [w])
        solo_solver = Solver(solo_model, SolverOptions(dt=solver.dt))
        solo = solo_solver.run(solo_model.state(), solo_solver.contacts(), steps).sphere_x.numpy()
        scale = float(np.max(np.abs(solo)))
        out.append(
            Record(
                "batch invariance",
                f"world {k} of {len(worlds)} vs solo",
                float(np.max(np.abs(batch[k] - solo))) / scale,
                0.0,
                "-",
                1e-6,
                absolute=True,
            )
        )
    return out


CASES = {
    "chung_ooi_1": case_chung_ooi_1,
    "chung_ooi_2": case_chung_ooi_2,
    "chung_ooi_3": case_chung_ooi_3,
    "chung_ooi_4": case_chung_ooi_4,
    "rolling_plane": case_rolling_plane,
    "rolling_incline": case_rolling_incline,
    "rolling_lever": case_rolling_lever,
    "free_fall": case_free_fall,
    "elastic_bounce": case_elastic_bounce,
    "mesh_vs_plane": case_mesh_vs_plane,
    "batch_invariance": case_batch_invariance,
    # the cases of the other capabilities live beside this module
    **BODY_CASES,
    **COHESION_CASES,
}


def run_all(device: str = "cpu", only: list[str] | None = None) -> list[Record]:
    """Run every case (or those named in ``only``) and return all records."""
    records = []
    with warnings.catch_warnings():
        # the cases place their bodies on purpose (a pair starting at a given overlap, a lattice started compressed)
        # and check the answers against closed forms: finalize's physics warnings say nothing here
        warnings.simplefilter("ignore", PhysicsWarning)
        for name, fn in CASES.items():
            if only and name not in only:
                continue
            records += fn(device)
    return records
