"""Multi-sphere clumps: mass properties of the union of spheres, principal frames, auto-fill, templates."""

import math

import numpy as np
import pytest
from numpy.polynomial import Polynomial

from warpdem.engine.clumps import (
    PELLET_SIZE,
    PHOSPHATE_MEDIAN_DIAMETER,
    ROD_SPACING,
    ClumpTemplate,
    pellet_template,
    phosphate_template,
    rod_template,
    sum_of_spheres_properties,
    union_volume_properties,
)

BOX = (10e-3, 8e-3, 6e-3)  # three unequal edges so the principal axes are unique


def _box_mesh(size):
    """Closed, outward-oriented 12-triangle mesh of a box centred at the origin."""
    half = 0.5 * np.asarray(size)
    v = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float) * half
    # two triangles per face, the faces at -x, +x, -y, +y, -z, +z (vertex index = 4 ix + 2 iy + iz)
    f = np.array(
        [
            [[0, 1, 3], [0, 3, 2]],
            [[4, 6, 7], [4, 7, 5]],
            [[0, 4, 5], [0, 5, 1]],
            [[2, 3, 7], [2, 7, 6]],
            [[0, 2, 6], [0, 6, 4]],
            [[1, 5, 7], [1, 7, 3]],
        ]
    ).reshape(-1, 3)
    return v, f


def _box_moments(size, volume=None):
    """Principal moments per unit density of a solid box, ascending: V (b^2 + c^2) / 12, ..."""
    a, b, c = size
    volume = a * b * c if volume is None else volume
    return np.sort(np.array([b * b + c * c, a * a + c * c, a * a + b * b]) * volume / 12.0)


def _lens_union(r, d):
    """Exact union of two radius-r spheres at z = -d/2, +d/2: (volume, I_xx, I_zz) per unit density.

    The cross-section at height z >= 0 is a disc of radius^2 rho^2 = r^2 - (z - d/2)^2, so volume
    and moments are integrals of polynomials in z (the other half by symmetry).
    """
    rho2 = Polynomial([r * r - 0.25 * d * d, d, -1.0])  # r^2 - (z - d/2)^2
    z2 = Polynomial([0.0, 0.0, 1.0])
    top = 0.5 * d + r

    def integral(p):
        q = p.integ()
        return 2.0 * (q(top) - q(0.0))

    volume = math.pi * integral(rho2)
    i_zz = 0.5 * math.pi * integral(rho2**2)
    i_xx = math.pi * integral(0.25 * rho2**2 + rho2 * z2)
    return volume, i_xx, i_zz


@pytest.fixture(scope="module")
def box_fill():
    return ClumpTemplate.from_box("box", BOX, cells=30, smoothing=1.5)


def test_box_fill_reproduces_solid_box_mass_and_inertia(box_fill):
    """A volume-matched fill of a 10 x 8 x 6 mm box has the solid box's mass and principal moments.

    Mass: re-integrated on a 2x finer grid (independent of the grid the overlap was solved on), within
    1 % of rho a b c. Inertia: each principal moment within 1 % of rho V (b^2 + c^2) / 12 etc.; the
    fill moves material from the rounded edges (radius ~ one cell, 0.2 mm) to the faces, which costs
    about 0.3 % at 30 cells. The principal axes are the box's, long edge first.
    """
    rho = 1330.0
    volume_fine, _, inertia_fine = union_volume_properties(box_fill.sphere_offset, box_fill.sphere_radius, 16)
    assert rho * volume_fine == pytest.approx(rho * np.prod(BOX), rel=0.01)
    assert box_fill.mass(rho) == pytest.approx(rho * np.prod(BOX), rel=0.01)
    np.testing.assert_allclose(box_fill.inertia(rho), rho * _box_moments(BOX), rtol=0.01)
    np.testing.assert_allclose(np.linalg.eigvalsh(inertia_fine), _box_moments(BOX), rtol=0.01)
    # body x, y, z = input x, y, z up to sign (moments ascend with edge length descending)
    np.testing.assert_allclose(np.abs(box_fill.body_from_input), np.eye(3), atol=0.02)
    assert abs(box_fill.volume_error) < 1e-3


def test_inscribed_fill_stays_inside_and_converges():
    """With zero overlap every sphere is inscribed in the box; the volume deficit (rounded edges and
    dimples between spheres, both of the order of a grid cell) shrinks as the grid is refined."""
    half = 0.5 * np.asarray(BOX)
    errors = []
    for cells in (12, 24):
        t = ClumpTemplate.from_box("box", BOX, cells=cells, overlap=0.0)
        reach = np.abs(t.input_sphere_offset) + t.sphere_radius[:, None]
        assert np.all(reach <= half * (1 + 1e-9))
        errors.append(t.volume_error)
    assert errors[0] < errors[1] < 0.0
    assert abs(errors[1]) < 0.7 * abs(errors[0])


def test_two_overlapping_spheres_union_vs_lens_formula():
    """Two r = 1 mm spheres 1.2 mm apart: the union volume is 2 (4/3 pi r^3) minus the lens
    pi (4r + d)(2r - d)^2 / 12 within 0.5 % (the grid error at the default 32 cells per radius is
    about 0.03 %); the naive sum overstates it by the lens (10 %). The union's inertia matches the
    exact cross-section integrals within 0.5 % (grid error about 0.1 %); the naive sum's is 6 % high."""
    r, d = 1e-3, 1.2e-3
    centres = [[0.0, 0.0, -0.5 * d], [0.0, 0.0, 0.5 * d]]
    lens = math.pi * (4 * r + d) * (2 * r - d) ** 2 / 12.0
    exact_volume = 2 * 4.0 / 3.0 * math.pi * r**3 - lens
    volume, com, inertia = union_volume_properties(centres, [r, r])
    assert volume == pytest.approx(exact_volume, rel=0.005)
    np.testing.assert_allclose(com, 0.0, atol=1e-6 * r)

    naive_volume, naive_com, naive_inertia = sum_of_spheres_properties(centres, [r, r])
    assert naive_volume == pytest.approx(8.0 / 3.0 * math.pi * r**3, rel=1e-12)
    assert naive_volume - volume == pytest.approx(lens, rel=0.05)
    assert naive_volume / volume - 1 > 0.09

    v_exact, ixx, izz = _lens_union(r, d)
    assert v_exact == pytest.approx(exact_volume, rel=1e-12)
    np.testing.assert_allclose(np.diag(inertia), [ixx, ixx, izz], rtol=0.005)
    assert abs(inertia[0, 1]) + abs(inertia[0, 2]) + abs(inertia[1, 2]) < 1e-6 * izz
    assert naive_inertia[2, 2] / izz - 1 > 0.05


def test_union_converges_under_grid_refinement():
    """The column-grid error (from the silhouette columns, ~ resolution^-1.5) falls with the grid:
    two unit spheres 0.8 apart on an axis tilted off the grid are within 1 % of the exact volume
    and moments at 8 cells per radius and within 0.02 % at 96."""
    r, d = 1.0, 0.8
    v_exact, ixx, izz = _lens_union(r, d)
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    perp = np.array([2.0, -2.0, 1.0]) / 3.0
    for resolution, tol in ((8, 1e-2), (96, 2e-4)):
        volume, com, inertia = union_volume_properties([-0.5 * d * axis, 0.5 * d * axis], [r, r], resolution)
        assert volume == pytest.approx(v_exact, rel=tol)
        # the union is axisymmetric: izz about its axis, ixx about any perpendicular line
        np.testing.assert_allclose([axis @ inertia @ axis, perp @ inertia @ perp], [izz, ixx], rtol=tol)
        np.testing.assert_allclose(com, 0.0, atol=1e-9 * r)


def test_single_sphere_exact():
    """One sphere: V = 4/3 pi r^3 and I = 2/5 V r^2 exactly, centred on the body origin."""
    r = 2e-3
    t = ClumpTemplate.from_spheres("ball", [[1e-3, 2e-3, 3e-3]], [r])
    assert t.volume == pytest.approx(4.0 / 3.0 * math.pi * r**3, rel=1e-14)
    np.testing.assert_allclose(t.inertia_unit, 0.4 * t.volume * r * r, rtol=1e-14)
    np.testing.assert_array_equal(t.sphere_offset, [[0.0, 0.0, 0.0]])
    np.testing.assert_allclose(t.input_com, [1e-3, 2e-3, 3e-3])
    assert t.equivalent_radius == pytest.approx(r, rel=1e-14)
    assert t.bounding_radius == pytest.approx(r)


def test_principal_frame_is_rotation_invariant():
    """Rotating the input spheres rigidly leaves the principal moments unchanged (within the grid
    error, which depends on orientation, ~0.1 %); in the body frame the union's centre of mass is at
    the origin and its inertia tensor is diagonal and ascending."""
    offsets = np.array([[0.0, 0.0, 0.0], [1.5, 0.2, 0.0], [-0.8, 0.9, 0.3], [0.3, -0.6, 1.1], [2.4, 0.5, -0.4]])
    radii = np.array([1.0, 0.8, 0.7, 0.6, 0.5])
    rng = np.random.default_rng(20240611)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    rot = q * np.sign(np.linalg.det(q))  # a proper rotation
    a = ClumpTemplate.from_spheres("a", offsets, radii)
    b = ClumpTemplate.from_spheres("b", offsets @ rot.T + [5.0, -3.0, 2.0], radii)
    assert np.all(np.diff(a.inertia_unit) > 0.01 * a.inertia_unit[0])  # distinct moments
    np.testing.assert_allclose(b.inertia_unit, a.inertia_unit, rtol=2e-3)
    assert b.volume == pytest.approx(a.volume, rel=2e-3)

    volume, com, inertia = union_volume_properties(b.sphere_offset, b.sphere_radius)
    assert np.linalg.norm(com) < 2e-3 * b.equivalent_radius
    off = inertia - np.diag(np.diag(inertia))
    assert np.abs(off).max() < 2e-3 * b.inertia_unit[0]
    np.testing.assert_allclose(np.diag(inertia), b.inertia_unit, rtol=2e-3)
    # the stored rotation maps the input spheres onto the body spheres
    np.testing.assert_allclose(b.input_sphere_offset, offsets @ rot.T + [5.0, -3.0, 2.0], atol=1e-12)


def test_mesh_fill_agrees_with_box_fill():
    """A closed 12-triangle box mesh fills like the analytic box: same enclosed volume (divergence
    theorem, exact), same volume and principal moments of the fill."""
    v, f = _box_mesh(BOX)
    from_mesh = ClumpTemplate.from_mesh("mesh", v, f, cells=16, smoothing=2.0)
    from_box = ClumpTemplate.from_box("box", BOX, cells=16, smoothing=2.0)
    assert from_mesh.volume_target == pytest.approx(np.prod(BOX), rel=1e-12)
    assert from_mesh.volume == pytest.approx(from_box.volume, rel=1e-3)
    np.testing.assert_allclose(from_mesh.inertia_unit, from_box.inertia_unit, rtol=1e-3)
    np.testing.assert_allclose(from_mesh.inertia_unit, _box_moments(BOX), rtol=0.02)
    # inward-facing triangles describe the same solid
    flipped = ClumpTemplate.from_mesh("mesh", v, f[:, ::-1], cells=16, smoothing=2.0)
    assert flipped.volume == pytest.approx(from_mesh.volume, rel=1e-9)


def test_open_or_inconsistent_mesh_rejected():
    """Inside/outside is undefined for a surface with a hole: a box with a missing triangle is refused,
    naming the boundary edges; so is a mesh with one triangle turned over."""
    v, f = _box_mesh(BOX)
    with pytest.raises(ValueError, match=r"not form a closed surface \(3 boundary edge\(s\) used by one face"):
        ClumpTemplate.from_mesh("open", v, f[:-1])
    bad = f.copy()
    bad[0] = bad[0, ::-1]
    with pytest.raises(ValueError, match="not consistently oriented"):
        ClumpTemplate.from_mesh("twisted", v, bad)
    with pytest.raises(ValueError, match=r"faces\[3\] = \[0, 0, 1\].*degenerate"):
        ClumpTemplate.from_mesh("flat", v, np.vstack([f[:3], [[0, 0, 1]], f[4:]]))


@pytest.mark.parametrize(
    "offsets,radii,pattern",
    [
        ([[0, 0, 0], [1e-3, 0, 0]], [1e-3, -1e-3], r"sphere_radius\[1\] = -0\.001 is not allowed.*> 0"),
        ([[0, 0, 0], [1e-3, 0, 0]], [1e-3, 1e-3, 1e-3], r"sphere_radius\.shape = \(3,\).*\(2,\)"),
        ([[0, 0, 0], [np.nan, 0, 0]], [1e-3, 1e-3], r"sphere_offset\[1\] = .*finite"),
        ([[0, 0], [1, 0]], [1e-3, 1e-3], r"sphere_offset\.shape = \(2, 2\).*\(n, 3\)"),
        ([[0, 0, 0]], [0.0], r"sphere_radius\[0\] = 0\.0"),
    ],
)
def test_template_fields_validated(offsets, radii, pattern):
    """Radii must be finite and > 0, offsets finite with shape (n, 3), one radius per sphere;
    the error names the field and the value."""
    with pytest.raises(ValueError, match=pattern):
        ClumpTemplate("t", offsets, radii, 1e-9, [1e-15, 1e-15, 1e-15])


def test_constructor_arguments_validated():
    """Factories name the offending argument: radii in from_spheres, the box size, a minimum radius
    larger than any inscribed sphere, an inertia that no rigid body can have."""
    with pytest.raises(ValueError, match=r"radii\[0\] = -1\.0"):
        ClumpTemplate.from_spheres("t", [[0, 0, 0]], [-1.0])
    with pytest.raises(ValueError, match=r"radii\.shape = \(1,\).*\(2,\)"):
        ClumpTemplate.from_spheres("t", [[0, 0, 0], [1, 0, 0]], [1.0])
    with pytest.raises(ValueError, match=r"size = \(1, -2, 3\)"):
        ClumpTemplate.from_box("t", (1, -2, 3))
    with pytest.raises(ValueError, match=r"min_radius = 0\.01 is not allowed.*largest inscribed radius"):
        ClumpTemplate.from_box("t", BOX, cells=8, min_radius=0.01)
    with pytest.raises(ValueError, match=r"inertia_unit = .*triangle inequality"):
        ClumpTemplate("t", [[0, 0, 0]], [1.0], 1.0, [1.0, 1.0, 3.0])


def test_scaling_and_derived_quantities():
    """Scaling lengths by s scales volume by s^3 and inertia per density by s^5; mass = rho V,
    inertia = rho I_unit; the volume-equivalent radius scales by s."""
    t = ClumpTemplate.from_spheres("pair", [[0, 0, 0], [1.5, 0, 0]], [1.0, 0.8])
    s = 1e-3
    u = t.scaled(s)
    assert u.volume == pytest.approx(t.volume * s**3, rel=1e-12)
    np.testing.assert_allclose(u.inertia_unit, t.inertia_unit * s**5, rtol=1e-12)
    np.testing.assert_allclose(u.sphere_offset, t.sphere_offset * s)
    assert u.equivalent_radius == pytest.approx(t.equivalent_radius * s, rel=1e-12)
    assert u.bounding_radius == pytest.approx(t.bounding_radius * s, rel=1e-12)
    assert u.mass(2500.0) == pytest.approx(2500.0 * u.volume)
    np.testing.assert_allclose(u.inertia(2500.0), 2500.0 * u.inertia_unit)
    # the bounding sphere encloses the union, the equivalent sphere lies between the radii
    assert t.bounding_radius >= np.max(np.linalg.norm(t.sphere_offset, axis=1) + t.sphere_radius) - 1e-12
    assert 1.0 < t.equivalent_radius < t.bounding_radius
    with pytest.raises(ValueError, match=r"factor = -2"):
        t.scaled(-2)


def test_pellet_template_matches_seed_000_pellet():
    """Seed 000 pellet (6.18 x 6.34 x 3.41 mm, EDEM auto-fill, 30 cells, min radius 0.5 mm): the union's
    extents along the box axes are within 6 % of the measured means (Table 1's thickness sd is
    0.22 mm = 6.5 %), no sphere is below 0.5 mm, and the volume matches the box."""
    t = pellet_template()
    c, r = t.input_sphere_offset, t.sphere_radius
    extents = (c + r[:, None]).max(axis=0) - (c - r[:, None]).min(axis=0)
    np.testing.assert_allclose(extents, PELLET_SIZE, rtol=0.06)
    assert np.all(extents >= np.asarray(PELLET_SIZE))
    assert r.min() >= 0.5e-3
    assert abs(t.volume_error) < 1e-3
    assert t.volume_target == pytest.approx(np.prod(PELLET_SIZE))
    np.testing.assert_allclose(t.inertia_unit, _box_moments(PELLET_SIZE), rtol=0.02)
    assert 20 <= t.sphere_count <= 400
    assert pellet_template() is t  # built once


def test_phosphate_template_is_irregular():
    """Seed 002 phosphate grain: more than eight spheres, three distinct principal moments (no axis of
    symmetry), volume-equivalent diameter at the PSD median (400 um)."""
    t = phosphate_template()
    assert t.sphere_count >= 8
    i1, i2, i3 = t.inertia_unit
    assert i2 / i1 > 1.1 and i3 / i2 > 1.05
    assert 2 * t.equivalent_radius == pytest.approx(PHOSPHATE_MEDIAN_DIAMETER, rel=1e-12)
    assert abs(t.volume_error) < 1e-3
    assert np.linalg.norm(union_volume_properties(t.sphere_offset, t.sphere_radius)[1]) < 1e-3 * t.equivalent_radius


def _revolution_union(offsets, radii, samples: int = 400_001):
    """Volume and moments (about the long axis, about a transverse axis through the centre of mass) per unit
    density of the union of spheres centred on the x axis, by quadrature along x: the cross-section at x is a
    disc of radius^2 rho^2 = max_i (r_i^2 - (x - x_i)^2), whatever the sizing formula says."""
    x_c = offsets[:, 0]
    x = np.linspace((x_c - radii).min(), (x_c + radii).max(), samples)
    rho2 = np.clip((radii[None, :] ** 2 - (x[:, None] - x_c[None, :]) ** 2).max(axis=1), 0.0, None)
    volume = np.trapezoid(math.pi * rho2, x)
    com = np.trapezoid(math.pi * rho2 * x, x) / volume
    i_long = np.trapezoid(0.5 * math.pi * rho2**2, x)
    i_trans = np.trapezoid(math.pi * (0.25 * rho2**2 + rho2 * (x - com) ** 2), x)
    return volume, com, i_long, i_trans


@pytest.mark.parametrize("aspect_ratio", [1.1, 1.5, 1.8, 2.0, 3.0])
def test_rod_template_is_a_volume_equivalent_chain(aspect_ratio):
    """A rod is equal spheres on its long body axis x, at most ROD_SPACING radii apart, length / width =
    aspect_ratio; the union (quadrature of its disc cross-sections, independent of both the sizing formula
    and the grid integrator) has the unit sphere's volume to 1e-6, the template's grid volume and principal
    moments agree with it to the union integrator's error at resolution 32 (0.1 %), and the naive sum of the
    overlapping spheres would overstate the volume by more than half."""
    t = rod_template(aspect_ratio)
    c, r = np.asarray(t.sphere_offset), np.asarray(t.sphere_radius)
    np.testing.assert_allclose(r, r[0], rtol=1e-12)
    np.testing.assert_allclose(c[:, 1:], 0.0, atol=1e-9)
    gaps = np.diff(np.sort(c[:, 0]))
    assert np.all(gaps <= ROD_SPACING * r[0] * (1 + 1e-9))
    length, width, depth = t.extents
    assert length / width == pytest.approx(aspect_ratio, rel=1e-9)
    assert depth == pytest.approx(width, rel=1e-9)
    assert t.bounding_radius == pytest.approx(length / 2, rel=1e-9)

    unit = 4.0 / 3.0 * math.pi
    volume, com, i_long, i_trans = _revolution_union(c, r)
    assert volume == pytest.approx(unit, rel=1e-6)
    assert com == pytest.approx(0.0, abs=1e-6)
    assert t.volume == pytest.approx(unit, rel=1e-3)
    assert t.equivalent_radius == pytest.approx(1.0, rel=1e-3)
    assert abs(t.volume_error) < 1e-3 and t.volume_target == pytest.approx(unit, rel=1e-12)
    np.testing.assert_allclose(t.inertia_unit, [i_long, i_trans, i_trans], rtol=1e-3)
    assert sum_of_spheres_properties(c, r)[0] > 1.5 * unit
    assert rod_template(aspect_ratio) is t  # built once


def test_rod_template_of_aspect_ratio_one_is_the_unit_sphere():
    """Aspect ratio 1 is one sphere of radius 1 with the exact sphere's mass properties; below 1 is refused."""
    t = rod_template(1.0)
    assert t.sphere_count == 1 and t.sphere_radius[0] == 1.0
    assert t.volume == pytest.approx(4.0 / 3.0 * math.pi, rel=1e-14)
    with pytest.raises(
        ValueError, match=r"rod_template: aspect_ratio = 0.9 is not allowed; expected a length / width >= 1"
    ):
        rod_template(0.9)
