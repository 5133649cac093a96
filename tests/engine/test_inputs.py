"""Bad input gets an error naming the field, the value and what is allowed."""

import math

import pytest

import warpdem as wd


def test_negative_friction_rejected():
    """A negative Coulomb friction coefficient is refused, naming the field and the range."""
    with pytest.raises(ValueError, match=r"static_friction = -0.1.*>= 0"):
        wd.Interaction(static_friction=-0.1)


@pytest.mark.parametrize("e", [0.0, -0.2, 1.2, float("nan")])
def test_restitution_outside_range_rejected(e):
    """Restitution must lie in (0, 1]."""
    with pytest.raises(ValueError, match=r"restitution = .*\(0, 1\]"):
        wd.Interaction(restitution=e)


def test_shear_modulus_above_half_e_rejected():
    """G > E/2 is impossible for a non-negative Poisson ratio (seed 001 prints such a pair)."""
    with pytest.raises(ValueError, match=r"shear_modulus = .*at most E/2"):
        wd.Material("m", density=1000, youngs_modulus=1e8, shear_modulus=6e7, poisson_ratio=0.3)


def test_inconsistent_moduli_rejected():
    """E, G and nu given together must agree through G = E / (2 (1 + nu))."""
    with pytest.raises(ValueError, match=r"E/\(2\(1\+nu\)\)"):
        wd.Material("m", density=1000, youngs_modulus=1e8, shear_modulus=2e7, poisson_ratio=0.3)


def test_modulus_derived_from_the_other():
    """Giving only G derives E = 2 G (1 + nu), and vice versa."""
    m = wd.Material("m", density=1000, shear_modulus=1e7, poisson_ratio=0.25)
    assert m.E == pytest.approx(2.5e7)
    m2 = wd.Material("m", density=1000, youngs_modulus=2.6e7, poisson_ratio=0.3)
    assert m2.G == pytest.approx(1e7)


@pytest.mark.parametrize(
    "kw,field",
    [
        ({"density": -1}, "density"),
        ({"poisson_ratio": 0.5}, "poisson_ratio"),
        ({"youngs_modulus": 0}, "youngs_modulus"),
    ],
)
def test_material_fields_checked(kw, field):
    """Density > 0, nu in (-1, 0.5), E > 0."""
    args = dict(name="m", density=1000.0, youngs_modulus=1e7, poisson_ratio=0.3) | kw
    with pytest.raises(ValueError, match=field):
        wd.Material(**args)


def test_rolling_model_names():
    """Rolling models are accepted by name, EDEM type letter or EDEM model name; unknown names list the choices.
    EDEM's "standard rolling friction" is a model of its own (each body's lever), its "RVD" model type A."""
    assert wd.Interaction(rolling_model="type_c").rolling_model == wd.RollingModel.EPSD
    assert wd.Interaction(rolling_model="A").rolling_model == wd.RollingModel.CONSTANT_TORQUE
    assert wd.Interaction(rolling_model="rvd").rolling_model == wd.RollingModel.CONSTANT_TORQUE
    assert wd.Interaction(rolling_model="Standard").rolling_model == wd.RollingModel.STANDARD
    with pytest.raises(ValueError, match="rolling_model = 'spring'.*CONSTANT_TORQUE"):
        wd.Interaction(rolling_model="spring")


def test_builder_errors():
    """Unknown materials, non-positive radii and wrong per-world value counts are reported precisely."""
    b = wd.ModelBuilder()
    b.add_material(wd.Material("a", density=1000, youngs_modulus=1e7, poisson_ratio=0.3))
    with pytest.raises(ValueError, match="material = 'b' is not defined; defined materials: a"):
        b.add_sphere((0, 0, 0), 0.01, "b")
    with pytest.raises(ValueError, match=r"radius = -0.01 .*> 0 m"):
        b.add_sphere((0, 0, 0), -0.01, "a")
    b.replicate(3)
    with pytest.raises(ValueError, match="2 values given; expected world_count = 3"):
        b.vary("interaction.a.a.restitution", [0.5, 0.6])
    with pytest.raises(ValueError, match="restitution = 1.5"):
        b.vary("interaction.a.a.restitution", [0.5, 0.6, 1.5])
        b.add_sphere((0, 0, 0), 0.01, "a")
        b.finalize("cpu")
    with pytest.raises(ValueError, match=r"vary 'interaction.a.a.law': value = 'jrk' .*one of .*JKR"):
        b.vary("interaction.a.a.law", [None, "jkr", "jrk"])
    with pytest.raises(ValueError, match=r"vary 'interaction.a.a.static_friction': value = 'x'"):
        b.vary("interaction.a.a.static_friction", [0.5, "x", None])


def test_solver_options_checked():
    """Solver options are validated at construction."""
    with pytest.raises(ValueError, match="dt_fraction = 1.5"):
        wd.SolverOptions(dt_fraction=1.5)
    with pytest.raises(ValueError, match="dt = -1"):
        wd.SolverOptions(dt=-1)
    with pytest.raises(ValueError, match='clump_contact_mass = \'half\'.*"shared" or "body"'):
        wd.SolverOptions(clump_contact_mass="half")
    with pytest.raises(ValueError, match="skin_fraction = 0.0 is not allowed; expected a fraction of the smallest"):
        wd.SolverOptions(skin_fraction=0.0)


def test_large_dt_warns():
    """A user time step above dt_fraction x Rayleigh time triggers a warning naming both."""
    b = wd.ModelBuilder()
    b.add_material(wd.Material("a", density=1000, youngs_modulus=1e7, poisson_ratio=0.3))
    b.add_sphere((0, 0, 0), 0.001, "a")
    m = b.finalize("cpu")
    with pytest.warns(UserWarning, match="exceeds 20% of the Rayleigh time"):
        wd.Solver(m, wd.SolverOptions(dt=1e-3))
    # the Rayleigh time itself: T_R = pi R sqrt(rho/G) / (0.1631 nu + 0.8766)
    g = 1e7 / 2.6
    assert m.rayleigh_time == pytest.approx(math.pi * 0.001 * math.sqrt(1000 / g) / (0.1631 * 0.3 + 0.8766), rel=1e-6)


@pytest.mark.parametrize("value", [[[0.0, 0.0, 1.0]], [0.0, 1.0], [0.0, float("nan"), 1.0], "abc"])
def test_vectors_are_three_finite_numbers(value):
    """A point, normal or velocity is exactly three finite numbers: a nested [[x, y, z]], two numbers, a NaN or
    a word is refused, naming the argument and the value (one rule for the builder and the factories)."""
    b = wd.ModelBuilder()
    with pytest.raises(ValueError, match="add_plane: normal = .* is not allowed; expected three finite numbers"):
        b.add_plane((0, 0, 0), value, "a")
    with pytest.raises(ValueError, match="initial_velocity = .* is not allowed; expected three finite numbers"):
        wd.DynamicFactory(wd.Box((0, 0, 0), (1, 1, 1)), wd.FixedSize(0.01), count=1, rate=1.0, initial_velocity=value)


@pytest.mark.parametrize(
    "make, says",
    [
        (lambda: wd.Material("a", density=True, youngs_modulus=1e7, poisson_ratio=0.3), "density = true"),
        (lambda: wd.Interaction(restitution=True), "restitution = true"),
        (lambda: wd.FixedSize(True), "radius = true"),
    ],
)
def test_a_bool_is_not_a_number(make, says):
    """True given for a density, a restitution or a radius is refused, not read as 1 (one rule for "a finite
    number" in warpdem.engine.checks)."""
    with pytest.raises(ValueError, match=says):
        make()
