"""Impact records on mesh walls and particle-coated (glued) walls, against closed forms."""

import math

import warpdem as wd
from warpdem.engine import geometry as geo


def _builder(e=0.5):
    b = wd.ModelBuilder()
    b.add_material(wd.Material("g", density=2500, youngs_modulus=1e7, poisson_ratio=0.3))
    b.add_material(wd.Material("s", density=7800, youngs_modulus=2e11, poisson_ratio=0.3))
    b.set_interaction("g", "g", restitution=e, static_friction=0.5)
    b.set_interaction("g", "s", restitution=e, static_friction=0.5)
    return b


def test_first_impact_speed_is_free_fall():
    """A sphere dropped from h hits the plate at sqrt(2 g h): the largest recorded normal impact speed matches
    it within 0.1 % (leapfrog's half-step velocity differs by g dt / 2), the first impact's energy is
    0.5 m v^2, and bounces with e = 0.5 add impacts at e^k v down to impact_speed_min."""
    b = _builder()
    v, t = geo.grid_plate(0.1, 0.1, 0.1)
    b.add_wall_mesh(v, t, "s", name="plate")
    h, r = 0.05, 0.002
    b.add_sphere((0.011, 0.013, h + r), r, "g")
    m = b.finalize("cpu")
    s = wd.Solver(m, wd.SolverOptions(impact_speed_min=0.05))
    st, c = m.state(), s.contacts()
    st = s.run(st, c, int(0.3 / s.dt))
    v0 = math.sqrt(2 * 9.81 * h)
    mass = 2500 * 4 / 3 * math.pi * r**3
    count = st.face_impact_count.numpy().sum()
    assert abs(st.face_impact_speed.numpy().max() - v0) < 1e-3 * v0
    # bounces at e^k v0 >= 0.05 m/s: k = 0..4 (0.99, 0.50, 0.25, 0.12, 0.06)
    assert count == 5
    e_total = st.face_impact_energy.numpy().sum()
    expected = 0.5 * mass * v0**2 * sum(0.25**k for k in range(5))
    # realised restitution differs from e by a few percent at these speeds: bound the sum, not each term
    assert 0.9 * expected < e_total < 1.02 * expected
    st.reset_impacts()
    assert st.face_impact_count.numpy().sum() == 0


def test_glued_spheres_carry_and_load_the_wall():
    """A sphere resting on a coated plate moving at 0.05 m/s is carried at the plate's speed (static friction
    holds), and the plate feels the sphere's weight m g through its glued spheres (within 0.5 %)."""
    b = _builder(e=0.3)
    v, t = geo.grid_plate(0.04, 0.04, 0.04)
    b.add_wall_mesh(v, t, "s", name="plate", motion=wd.WallMotion.linear((0.05, 0.0, 0.0)))
    glued = b.coat_wall("plate", 0.002, "g", seed=1)
    assert len(glued) > 30
    r = 0.002
    b.add_sphere((0.0, 0.0, 0.012), r, "g")
    m = b.finalize("cpu")
    s = wd.Solver(m)
    st, c = m.state(), s.contacts()
    st = s.run(st, c, int(0.4 / s.dt))
    x, vel = st.sphere_x.numpy(), st.sphere_v.numpy()
    assert abs(vel[-1, 0] - 0.05) < 1e-3
    # glued spheres sit one radius above the plate and moved with it
    g0 = glued[0]
    assert abs(x[g0, 2] - 0.002) < 1e-6
    assert abs(vel[g0, 0] - 0.05) < 1e-6
    mass = 2500 * 4 / 3 * math.pi * r**3
    fz = st.wall_f.numpy()[0, 2]
    assert abs(-fz - mass * 9.81) < 5e-3 * mass * 9.81
