"""Post-processing measures (warpdem.scene.measure): angle of repose on synthetic cones of known slope,
the rotating drum's surface on synthetic beds of known slope, die-press curves, wall impact summaries, the settling monitor, the plots and the input checks."""

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from warpdem.scene.measure import (
    BoxRegion,
    CylinderRegion,
    SettleMonitor,
    angle_cone,
    angle_image,
    angle_surface_fit,
    beverloo_band,
    beverloo_rate,
    discharge_rate,
    drum_metrics,
    drum_surface,
    flank_lines,
    hopper_angle_factor,
    impact_summary,
    packing_core,
    packing_fraction,
    pile_offset,
    plot_angles,
    plot_drum,
    plot_impacts,
    plot_press,
    press_curve,
    press_loading,
    press_summary,
    press_unload,
    silhouette,
    synthetic_cone,
)

R_BASE = 0.06  # cone base radius [m]
R_SPHERE = 0.002  # sphere radius [m]
ANGLES = [20.0, 30.0, 45.0]
# (polydispersity, base_z [m], center [m]) of the piles every method is checked on
PILES = [(0.0, 0.0, (0.0, 0.0)), (0.1, 0.0, (0.0, 0.0)), (0.1, 0.25, (0.3, -0.2))]


def _cone(angle, pd=0.0, base_z=0.0, center=(0.0, 0.0), seed=0):
    return synthetic_cone(angle, R_BASE, R_SPHERE, seed=seed, polydispersity=pd, base_z=base_z, center=center)


# --------------------------------------------------------------------------------------------------
# the synthetic cone itself
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("angle", ANGLES)
@pytest.mark.parametrize("pd,base_z,center", PILES)
def test_synthetic_cone_geometry(angle, pd, base_z, center):
    """synthetic_cone: tops under the cone surface, bottom layer on the base, no overlaps, radii within
    r(1 +- pd), a few thousand spheres at most, and every sphere either within 0.3 r of the surface or
    covered by a sphere right above it (dense outermost layer)."""
    x, r = _cone(angle, pd, base_z, center)
    assert 100 < len(r) < 4000
    assert np.all(r >= R_SPHERE * (1 - pd) - 1e-15) and np.all(r <= R_SPHERE * (1 + pd) + 1e-15)
    tan_a = math.tan(math.radians(angle))
    rho = np.hypot(x[:, 0] - center[0], x[:, 1] - center[1])
    gap = (base_z + R_BASE * tan_a - tan_a * rho) - (x[:, 2] + r)
    assert gap.min() >= -1e-12
    assert np.all(x[:, 2] - r >= base_z - 1e-12)
    assert np.isclose((x[:, 2] - r).min(), base_z)
    pairs = cKDTree(x).query_pairs(2.0 * r.max(), output_type="ndarray")
    dist = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1)
    assert np.all(dist >= r[pairs[:, 0]] + r[pairs[:, 1]] - 1e-12)
    # covered: another sphere above within half a radius horizontally
    tree2 = cKDTree(x[:, :2])
    covered = np.zeros(len(r), bool)
    for i, j in tree2.query_pairs(0.5 * R_SPHERE):
        covered[i if x[i, 2] < x[j, 2] else j] = True
    assert np.all(covered | (gap <= 0.3 * r + 1e-12))


def test_synthetic_cone_seeded():
    """synthetic_cone is reproducible for a seed and differs between seeds."""
    a, ra = _cone(30.0, 0.1, seed=5)
    b, rb = _cone(30.0, 0.1, seed=5)
    c, _ = _cone(30.0, 0.1, seed=6)
    assert np.array_equal(a, b) and np.array_equal(ra, rb)
    assert a.shape != c.shape or not np.array_equal(a, c)


# --------------------------------------------------------------------------------------------------
# angle of repose
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("angle", ANGLES)
@pytest.mark.parametrize("pd,base_z,center", PILES)
def test_surface_fit_within_half_degree(angle, pd, base_z, center):
    """angle_surface_fit recovers the synthetic cone slope within 0.5 deg in 8 sectors (monodisperse,
    10 % polydisperse, shifted base and axis)."""
    x, r = _cone(angle, pd, base_z, center)
    res = angle_surface_fit(x, r, base_z=base_z, center=center)
    assert res["slices"] == 8 and len(res["per_slice_deg"]) == 8
    assert res["mean_deg"] == pytest.approx(angle, abs=0.5)
    assert res["sd_deg"] == pytest.approx(np.std(res["per_slice_deg"], ddof=1))
    assert res["bin_width_m"] >= 2.5 * 2 * r.mean() - 1e-12


@pytest.mark.parametrize("angle", ANGLES)
@pytest.mark.parametrize("pd,base_z,center", PILES)
@pytest.mark.parametrize("axis", ["y", "x"])
def test_flank_lines_lie_on_the_cone(angle, pd, base_z, center, axis):
    """flank_lines (the gallery's protractor) on a synthetic cone: a right and a left flank, each at the cone's
    angle within the surface fit's own 0.5 deg, on its side of the axis, apex end first, and lying under the cone
    surface by less than one sphere radius at both ends (the fitted sphere tops sit below the surface by at most
    r (1 / cos(angle) - 1) plus the 0.3 r gap the synthetic cone allows, 0.72 r at 45 deg)."""
    x, r = _cone(angle, pd, base_z, center)
    fit = angle_surface_fit(x, r, base_z=base_z, center=center)
    flanks = flank_lines(fit, base_z, axis)
    assert [f["side"] for f in flanks] == ["right", "left"]
    h0 = center[0] if axis == "y" else center[1]
    tan_a = math.tan(math.radians(angle))
    for f, sign in zip(flanks, (1.0, -1.0)):
        assert f["angle_deg"] == pytest.approx(angle, abs=0.5)
        (ha, za), (hb, zb) = f["points"]
        assert sign * (hb - ha) > 0 and sign * (ha - h0) >= 0 and za > zb
        for h, z in ((ha, za), (hb, zb)):
            surface = base_z + (R_BASE - abs(h - h0)) * tan_a
            assert 0.0 <= surface - z < R_SPHERE


def test_flank_lines_refuses_a_vertical_view():
    """A top view has no flanks: axis "z" is refused, naming the argument and what is allowed."""
    x, r = _cone(30.0)
    with pytest.raises(ValueError, match=r"flank_lines: axis = 'z' is not allowed; expected \"x\" or \"y\""):
        flank_lines(angle_surface_fit(x, r), 0.0, "z")


@pytest.mark.parametrize("angle", ANGLES)
@pytest.mark.parametrize("pd,base_z,center", PILES)
def test_image_within_one_degree(angle, pd, base_z, center):
    """angle_image (4 orthographic silhouettes, 8 flanks) recovers the synthetic cone slope within 1 deg."""
    x, r = _cone(angle, pd, base_z, center)
    res = angle_image(x, r, base_z=base_z, center=center)
    assert res["views"] == 4 and len(res["per_side_deg"]) == 8
    assert res["mean_deg"] == pytest.approx(angle, abs=1.0)


@pytest.mark.parametrize("angle", ANGLES)
def test_cone_formula_bias_is_the_toe(angle):
    """The seed formula atan(2h/d) reads steeper than the flanks by exactly the toe effect: no sphere fits
    under the last 2r/tan(angle) of the cone, so d/2 = R - 2r/tan(angle) + r; the angle matches
    atan(h / (R - 2r/tan(angle) + r)) within 0.4 deg (an error of +1 to +3 deg here)."""
    x, r = _cone(angle)
    tan_a = math.tan(math.radians(angle))
    predicted = math.degrees(math.atan(R_BASE * tan_a / (R_BASE - 2 * R_SPHERE / tan_a + R_SPHERE)))
    assert angle_cone(x, r) == pytest.approx(predicted, abs=0.4)


@pytest.mark.parametrize("angle", ANGLES)
@pytest.mark.parametrize("pd,base_z,center", PILES)
def test_cone_formula_toe_corrected_within_1p5_degree(angle, pd, base_z, center):
    """angle_cone(toe_correction=True), the cone through the sphere tops, is within 1.5 deg."""
    x, r = _cone(angle, pd, base_z, center)
    assert angle_cone(x, r, base_z=base_z, center=center, toe_correction=True) == pytest.approx(angle, abs=1.5)


def test_center_none_estimates_the_axis():
    """center=None finds the axis of an off-centre cone within one radius, and the angles follow."""
    x, r = _cone(30.0, 0.1, 0.25, (0.3, -0.2))
    res = angle_surface_fit(x, r, base_z=0.25, center=None)
    assert np.hypot(res["center"][0] - 0.3, res["center"][1] + 0.2) < R_SPHERE
    assert res["mean_deg"] == pytest.approx(30.0, abs=0.5)
    assert angle_image(x, r, base_z=0.25, center=None)["mean_deg"] == pytest.approx(30.0, abs=1.0)


def test_image_is_the_silhouette():
    """The binary image is the union of the projected discs: its top boundary equals the brute-force
    silhouette height max_i z_i + sqrt(r_i^2 - (u - u_i)^2) within one pixel in every column, the apex
    column within one pixel of the highest top, and the pile is solid below the boundary."""
    x, r = _cone(30.0, 0.1, 0.25, (0.3, -0.2))
    res = angle_image(x, r, base_z=0.25, center=(0.3, -0.2), return_images=True)
    p = res["pixel_m"]
    assert p == pytest.approx(r.min() / 4)
    assert len(res["images"]) == 4
    for k, (img, geo) in enumerate(zip(res["images"], res["geometry"])):
        assert img.dtype == bool
        t = 2 * math.pi * k / 4
        u = -(x[:, 0] - 0.3) * math.sin(t) + (x[:, 1] + 0.2) * math.cos(t)
        uc = geo["u0_m"] + p * np.arange(img.shape[1])
        du = uc[None, :] - u[:, None]
        h2 = r[:, None] ** 2 - du**2
        brute = np.where(h2 > 0, x[:, 2:3] + np.sqrt(np.maximum(h2, 0)), -np.inf).max(axis=0)
        filled = img.any(axis=0)
        assert np.array_equal(filled, np.isfinite(brute))
        top_row = np.argmax(img, axis=0)
        height = geo["z0_m"] - p * top_row
        assert np.all(np.abs(height[filled] - brute[filled]) <= p)
        # apex
        a = int(np.argmax(x[:, 2] + r))
        col = geo["axis_column"] + int(round(u[a] / p))
        assert abs(height[col] - (x[a, 2] + r[a])) <= p
        # solid: every column filled from its boundary down to the base
        base_row = (geo["z0_m"] - 0.25) / p
        expected = np.clip(base_row - top_row[filled] + 0.5, 0, None).sum()
        assert img.sum() == pytest.approx(expected, rel=0.03)


def test_silhouette_disc_area():
    """One sphere rasterises to a disc of area pi r^2 (within 1 %) with the axis on a pixel column."""
    x, r = np.array([[0.01, 0.003, 0.05]]), np.array([0.002])
    out = silhouette(x, r, azimuth_deg=90.0, pixel=r[0] / 25)
    img = out["image"]
    assert img.sum() * out["pixel_m"] ** 2 == pytest.approx(math.pi * r[0] ** 2, rel=0.01)
    # seen from +y (azimuth 90) the image axis u runs along -x: the disc is left of the axis column
    cols = np.flatnonzero(img.any(axis=0))
    centre_u = out["u0_m"] + out["pixel_m"] * cols.mean()
    assert centre_u == pytest.approx(-0.01, abs=out["pixel_m"])


def test_image_speed_20000_spheres():
    """angle_image on about 20,000 spheres with 4 views runs well under 5 s on one core."""
    import time

    x, r = synthetic_cone(35.0, 0.15, R_SPHERE, seed=3, polydispersity=0.1)
    assert len(r) > 19000
    t0 = time.perf_counter()
    res = angle_image(x, r)
    assert time.perf_counter() - t0 < 5.0
    assert res["mean_deg"] == pytest.approx(35.0, abs=1.0)


def test_small_pile_is_rejected():
    """A pile too small for 3 cells of 2.5 sphere diameters per sector raises a ValueError that says so."""
    x, r = synthetic_cone(30.0, 0.012, R_SPHERE)
    with pytest.raises(ValueError, match="too small"):
        angle_surface_fit(x, r)


@pytest.mark.parametrize("pd", [0.0, 0.1])
def test_pile_offset_is_the_distance_of_its_centre_of_mass_from_the_axis(pd):
    """A cone built about (0.03, -0.04) m lies 50 mm off the axis at the origin and on its own axis. Its
    lattice is symmetric about its central column, so only the jitter (0.1 of the largest radius at most) and,
    for unequal radii, their scatter (a volume-weighted mean over about 2,000 spheres) move the centre of
    mass: a tenth of a sphere radius bounds both."""
    x, r = synthetic_cone(45.0, R_BASE, R_SPHERE, seed=2, polydispersity=pd, center=(0.03, -0.04))
    assert pile_offset(x, r) == pytest.approx(0.05, abs=0.1 * R_SPHERE)
    assert pile_offset(x, r, center=(0.03, -0.04)) < 0.1 * R_SPHERE


# --------------------------------------------------------------------------------------------------
# die press
# --------------------------------------------------------------------------------------------------


def _stroke(z_end=0.0297, fill=0.08, k=2.0e7, z_start=0.09, n=2001):
    z = np.linspace(z_start, z_end, n)
    f = k * np.clip(fill - z, 0, None) ** 2
    return z, f


def test_press_summary_seed_001_numbers():
    """press_summary reproduces seed 001: a fill of 80 mm pressed to 29.7 mm gives 50.3 mm travel and a
    compression ratio of 0.629 (to 1e-3); max force and final height follow from F = k d^2."""
    z, f = _stroke()
    s = press_summary(z, f, fill_height=0.08)
    assert s["max_displacement_m"] == pytest.approx(0.0503, abs=1e-6)
    assert s["compression_ratio"] == pytest.approx(0.629, abs=1e-3)
    assert s["final_height_m"] == pytest.approx(0.0297, abs=1e-9)
    assert s["max_force_n"] == pytest.approx(2.0e7 * 0.0503**2, rel=1e-9)
    assert s["limit_reached"] is False


def test_press_summary_force_limit_and_backstop():
    """With force_limit the stroke ends where F first reaches the limit (interpolated between samples);
    heights are measured from backstop_z."""
    z, f = _stroke()
    limit = 2.0e7 * 0.04**2
    s = press_summary(z + 0.5, f, fill_height=0.08, force_limit=limit, backstop_z=0.5)
    assert s["limit_reached"] is True
    assert s["max_displacement_m"] == pytest.approx(0.04, abs=2e-5)
    assert s["compression_ratio"] == pytest.approx(0.5, abs=3e-4)
    assert s["final_height_m"] == pytest.approx(0.04, abs=2e-5)
    assert s["max_force_n"] == limit


def test_press_loading_reads_the_fill_before_the_first_push_and_stops_at_the_turn():
    """press_loading reads the fill at the sample before the force first passes 5 % of the limit (the bed's top
    there, above the backstop), ends the stroke where the force reaches the limit, and ignores the samples after
    the bar turned back; a bar that never pressed gives None."""
    z, f = _stroke(z_end=0.035, n=1101)
    # the bed's top sinks as it settles (a percentile of its particles, not the bar's height)
    top = np.linspace(0.0815, 0.0795, len(z))
    limit = 2.0e7 * 0.04**2  # reached at 40 mm of travel below the 80 mm fill
    turn = int(np.argmax(f >= limit)) + 3
    back = np.linspace(z[turn], z[turn] + 0.01, 50)[1:]
    zz, ff = np.concatenate([z[: turn + 1] + 0.5, back + 0.5]), np.concatenate([f[: turn + 1], np.zeros(49)])
    tt = np.concatenate([top[: turn + 1] + 0.5, np.full(49, top[turn] + 0.5)])
    s = press_loading(zz, ff, tt, force_limit=limit, backstop_z=0.5, unload_index=turn)
    first = int(np.argmax(f > 0.05 * limit))
    assert s["fill_height_m"] == pytest.approx(top[first - 1], abs=1e-12)
    assert top[first] < s["fill_height_m"] < top[first - 2]
    fill = s["fill_height_m"]
    assert s["limit_reached"] is True and s["max_force_n"] == limit
    # F = k (0.08 - z)^2 reaches the limit at z = 0.04; the travel counts from the fill read
    assert s["max_displacement_m"] == pytest.approx(fill - 0.04, abs=2e-5)
    assert s["compression_ratio"] == pytest.approx((fill - 0.04) / fill, abs=3e-4)
    assert len(s["load_z"]) == turn + 1 and np.all(np.diff(s["load_z"]) <= 0)
    assert s["displacement_m"][0] == pytest.approx(0.0, abs=z[0] - z[1])
    assert press_loading(zz, np.zeros_like(ff), tt, force_limit=limit) is None


def test_press_curve_from_contact():
    """press_curve starts at contact: at the given contact_z (displacement = contact_z - z), or at the first
    force above 1 % of the maximum."""
    z, f = _stroke()
    c = press_curve(z, f, contact_z=0.08)
    assert c["displacement_m"][0] == pytest.approx(0.0, abs=z[0] - z[1])
    assert np.allclose(c["displacement_m"], 0.08 - z[c["contact_index"] :])
    assert np.allclose(c["force_n"], 2.0e7 * np.clip(c["displacement_m"], 0, None) ** 2, rtol=1e-9, atol=1e-6)
    zl = np.linspace(0.09, 0.03, 601)
    fl = 1.0e6 * np.clip(0.08 - zl, 0, None)  # linear: 1 % of max at 0.5 mm past contact
    c = press_curve(zl, fl)
    i = c["contact_index"]
    assert fl[i] > 0.01 * fl.max() >= fl[i - 1]
    assert c["displacement_m"][0] == 0.0 and len(c["force_n"]) == len(zl) - i
    assert c["contact_z_m"] == pytest.approx(0.08 - 0.0005, abs=1e-4)


# --------------------------------------------------------------------------------------------------
# impacts
# --------------------------------------------------------------------------------------------------


def test_impact_summary_hand_made():
    """impact_summary: totals, the fastest face, count-weighted mean energy, energy per area and the
    most-hit faces (most first, faces without impacts left out)."""
    count = np.array([3, 0, 10, 1, 5])
    energy = np.array([0.3, 0.0, 2.0, 0.5, 0.2])
    speed = np.array([1.0, 0.0, 2.5, 4.0, 0.7])
    area = np.array([1e-4, 2e-4, 1e-4, 1e-4, 5e-5])
    s = impact_summary(count, energy, speed, area)
    assert s["total_count"] == 19
    assert s["total_energy_j"] == pytest.approx(3.0)
    assert s["max_speed_m_s"] == 4.0 and s["max_speed_face"] == 3
    assert s["mean_energy_per_impact_j"] == pytest.approx(3.0 / 19)
    assert s["hot_faces"] == [2, 4, 0, 3]
    assert s["energy_per_area_j_m2"] == pytest.approx(3.0 / 5.5e-4)
    assert np.allclose(s["face_energy_per_area_j_m2"], energy / area)
    many = impact_summary(np.arange(30), np.ones(30), np.ones(30))
    assert many["hot_faces"] == list(range(29, 19, -1))
    assert "energy_per_area_j_m2" not in many
    assert math.isnan(impact_summary([0, 0], [0, 0], [0, 0])["mean_energy_per_impact_j"])


# --------------------------------------------------------------------------------------------------
# settling
# --------------------------------------------------------------------------------------------------


def test_settle_monitor():
    """SettleMonitor: True only after `window` consecutive samples below the threshold; a sample above
    restarts the count; the history keeps every (t, ke) and settled_time the first settling."""
    m = SettleMonitor(1e-6, window=3)
    ke = [1e-3, 5e-7, 5e-7, 2e-6, 5e-7, 5e-7, 5e-7, 1e-7, 1e-3]
    got = [m.update(0.1 * i, e) for i, e in enumerate(ke)]
    assert got == [False, False, False, False, False, False, True, True, False]
    assert m.history == [(pytest.approx(0.1 * i), e) for i, e in enumerate(ke)]
    assert m.settled_time == pytest.approx(0.6)
    one = SettleMonitor(1.0, window=1)
    assert one.update(0.0, 0.5) is True
    assert SettleMonitor(1.0).update(0.0, 1.0) is False  # "below" is strict


def test_settle_monitor_per_world():
    """SettleMonitor with one energy per world: a sample is below the threshold only when every world is,
    a NaN world (blown up) is not below, and the streak can be restored (a resumed run). Each world keeps its own
    streak: world 0, below in every sample, has settled after two while world 1 has not."""
    m = SettleMonitor(1e-6, window=2)
    assert len(m.settled_worlds) == 0
    assert m.update(0.0, np.array([5e-7, 2e-6])) is False and m.streak == 0
    assert m.settled_worlds.tolist() == [False, False]
    assert m.update(0.1, np.array([5e-7, 5e-7])) is False and m.streak == 1
    assert m.settled_worlds.tolist() == [True, False] and m.world_streak.tolist() == [2, 1]
    assert m.update(0.2, np.array([5e-7, np.nan])) is False and m.streak == 0
    assert m.world_streak.tolist() == [3, 0]
    resumed = SettleMonitor(1e-6, window=2)
    resumed.streak = 1
    assert resumed.update(0.3, np.array([1e-7, 1e-7])) is True
    with pytest.raises(ValueError, match="kinetic_energy_per_particle = "):
        m.update(0.3, np.array([1e-7, -1e-7]))


# --------------------------------------------------------------------------------------------------
# plots
# --------------------------------------------------------------------------------------------------


def test_plots_write_png(tmp_path):
    """plot_press and plot_angles write PNG files."""
    z, f = _stroke()
    p1 = tmp_path / "press.png"
    plot_press(press_curve(z, f), p1)
    x, r = _cone(30.0)
    p2 = tmp_path / "angles.png"
    plot_angles(angle_surface_fit(x, r), p2)
    p3 = tmp_path / "flanks.png"
    plot_angles(angle_image(x, r), p3)
    for p in (p1, p2, p3):
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# --------------------------------------------------------------------------------------------------
# input checks
# --------------------------------------------------------------------------------------------------

_X, _R = synthetic_cone(30.0, 0.03, 0.002)
_Z, _F = np.linspace(0.09, 0.03, 50), np.linspace(0.0, 100.0, 50)


@pytest.mark.parametrize(
    "call,names",
    [
        (lambda: angle_surface_fit(np.zeros((0, 3)), np.zeros(0)), "x = "),
        (lambda: angle_surface_fit(_X, _R[:-1]), "r = "),
        (lambda: angle_surface_fit(_X, -_R), "r = "),
        (lambda: angle_surface_fit(_X, _R, slices=1), "slices = 1"),
        (lambda: angle_surface_fit(_X, _R, bins=2), "bins = 2"),
        (lambda: angle_surface_fit(_X, _R, inner=0.9, outer=0.5), "outer = 0.5"),
        (lambda: angle_surface_fit(_X, _R, center=(0.0,)), "center = "),
        (lambda: angle_surface_fit(_X, _R, base_z=1.0), "base_z = 1.0"),
        (lambda: angle_cone(_X, _R, base_z=float("nan")), "base_z = nan"),
        (lambda: angle_image(_X, _R, views=0), "views = 0"),
        (lambda: angle_image(_X, _R, pixel=0.0), "pixel = 0.0"),
        (lambda: angle_image(_X, _R, inner=-0.1), "inner = -0.1"),
        (lambda: synthetic_cone(90.0, 0.06, 0.002), "angle_deg = 90.0"),
        (lambda: synthetic_cone(30.0, -0.06, 0.002), "base_radius = -0.06"),
        (lambda: synthetic_cone(30.0, 0.06, 0.0), "sphere_radius = 0.0"),
        (lambda: synthetic_cone(30.0, 0.06, 0.002, polydispersity=1.0), "polydispersity = 1.0"),
        (lambda: synthetic_cone(30.0, 0.001, 0.002), "base_radius = 0.001"),
        (lambda: press_curve(_Z[:1], _F[:1]), "piston_z = "),
        (lambda: press_curve(_Z, _F[:-1]), "piston_force = "),
        (lambda: press_curve(_Z[::-1], _F), "piston_z = .*downward"),
        (lambda: press_curve(_Z, np.zeros(50)), "piston_force = "),
        (lambda: press_curve(_Z, _F, contact_z=0.01), "contact_z = 0.01"),
        (lambda: press_summary(_Z, _F, fill_height=0.0), "fill_height = 0.0"),
        (lambda: press_summary(_Z, _F, fill_height=0.08, force_limit=-1.0), "force_limit = -1.0"),
        (lambda: impact_summary([], [], []), "face_count = "),
        (lambda: impact_summary([1, -1], [0, 0], [0, 0]), "face_count = "),
        (lambda: impact_summary([1.5, 1], [0, 0], [0, 0]), "face_count = "),
        (lambda: impact_summary([1, 1], [0, 0, 0], [0, 0]), "face_energy = "),
        (lambda: impact_summary([1, 1], [0, 0], [0, -1.0]), "face_max_speed = "),
        (lambda: impact_summary([1, 1], [0, 0], [0, 0], face_area=[1.0, 0.0]), "face_area = "),
        (lambda: SettleMonitor(0.0), "threshold = 0.0"),
        (lambda: SettleMonitor(-1e-6), "threshold = -1e-06"),
        (lambda: SettleMonitor(1e-6, window=0), "window = 0"),
        (lambda: SettleMonitor(1e-6).update(0.0, -1.0), "kinetic_energy_per_particle = -1.0"),
        (lambda: SettleMonitor(1e-6).update(0.0, float("nan")), "kinetic_energy_per_particle = nan"),
        (lambda: SettleMonitor(1e-6).update(0.0, float("inf")), "kinetic_energy_per_particle = inf"),
        (
            lambda: SettleMonitor(1e-6).update(0.0, [1e-7, -1e-7]),
            r"kinetic_energy_per_particle = \[ 1\.e-07, -1\.e-07\] is",
        ),
        (lambda: plot_press({}, "x.png"), "curve = "),
        (lambda: plot_angles({}, "x.png"), "result = "),
    ],
)
def test_bad_input_names_argument(call, names):
    """Bad input raises ValueError naming the argument and its value, and saying what is allowed."""
    with pytest.raises(ValueError, match=names) as err:
        call()
    assert "expected" in str(err.value) or "need" in str(err.value)


def test_settle_monitor_time_must_not_go_back():
    """SettleMonitor.update rejects a time before the previous update's."""
    m = SettleMonitor(1e-6)
    m.update(1.0, 1.0)
    with pytest.raises(ValueError, match="time = 0.5"):
        m.update(0.5, 1.0)


def test_pile_spheres_drops_grains_off_the_pile():
    """A 30 deg cone is one connected pile (every sphere kept); a cluster held 0.2 m above it (grains stuck
    to a lifted cylinder) and a lone sphere in flight are not connected to the base and are dropped, and the
    surface fit of what is kept returns the cone's 30 deg within the method's 0.5 deg. The synthetic lattice
    leaves up to 0.4 r between neighbours (its spheres never overlap), so touching is taken within 30 %."""
    from warpdem.scene.measure import angle_surface_fit, pile_spheres

    x, r = _cone(30.0, 0.0, 0.0, (0.0, 0.0), 0)
    assert pile_spheres(x, r, gap=0.3).all()
    top = x[:, 2].max()
    stuck = np.array([[0.0, 0.0, top + 0.2], [2 * R_SPHERE, 0.0, top + 0.2], [4 * R_SPHERE, 0.0, top + 0.2]])
    flying = np.array([[0.0, 0.03, top + 0.05]])
    xa = np.vstack([x, stuck, flying])
    ra = np.r_[r, np.full(4, R_SPHERE)]
    on = pile_spheres(xa, ra, gap=0.3)
    assert on[: len(r)].all() and not on[len(r) :].any()
    assert abs(angle_surface_fit(xa[on], ra[on])["mean_deg"] - 30.0) < 0.5


def test_pile_spheres_drops_strays_lying_apart_on_the_plate():
    """Grains that bounced off a pile and lie apart on the plate (more than a diameter from any other grain), out
    to three base radii, stand on the base but are not the pile: kept (``apart`` = 0), they set the flank's foot
    and the image method reads the 45 deg cone below 30 deg; left out, the cone reads 45 deg within the
    method's 1 deg."""
    from warpdem.scene.measure import pile_spheres

    x, r = _cone(45.0, 0.0, 0.0, (0.0, 0.0), 0)
    rng = np.random.default_rng(5)
    phi = rng.uniform(0.0, 2.0 * np.pi, 40)
    rho = rng.uniform(1.3 * R_BASE, 3.0 * R_BASE, 40)
    strays = np.c_[rho * np.cos(phi), rho * np.sin(phi), np.full(40, R_SPHERE)]
    xa, ra = np.vstack([x, strays]), np.r_[r, np.full(40, R_SPHERE)]
    assert angle_image(xa, ra)["mean_deg"] < 30.0
    alone = pile_spheres(x, r, gap=0.3)  # the lattice lifts a few top spheres clear of their column
    assert alone.mean() > 0.99
    on = pile_spheres(xa, ra, gap=0.3)
    assert np.array_equal(on[: len(r)], alone) and not on[len(r) :].any()
    assert angle_image(xa[on], ra[on])["mean_deg"] == pytest.approx(45.0, abs=1.0)
    off = pile_spheres(xa, ra, gap=0.3, apart=0.0)  # every grain on the base, the strays too
    assert np.array_equal(off[: len(r)], alone) and off[len(r) :].all()
    # two piles on one plate: the larger is the pile
    small = x[x[:, 2] < 2.5 * R_SPHERE][:30] + np.array([4.0 * R_BASE, 0.0, 0.0])
    keep = pile_spheres(np.vstack([x, small]), np.r_[r, np.full(len(small), R_SPHERE)], gap=0.3)
    assert np.array_equal(keep[: len(r)], alone) and not keep[len(r) :].any()


@pytest.mark.parametrize("apart", [0.0, 0.3, 1.0, 2.5])
def test_pile_spheres_equals_its_definition_by_brute_force(apart):
    """On scattered clusters of spheres of mixed sizes (touching groups, grains a little apart, grains far off,
    some in the air), the mask equals the definition worked out over every pair: spheres connected to the base
    by chains of centres closer than 1.1 (r_i + r_j), and of those the largest cluster whose pairs are closer
    than (1 + apart) (r_i + r_j). The selection asks only the grains outside the largest touching group for
    their wide neighbours; this checks that nothing is lost by it."""
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial.distance import cdist

    from warpdem.scene.measure import PILE_GAP, pile_spheres

    # a touching block of 1 mm spheres on the plate, grains at surface gaps of 0.2, 0.7 and 2 (r_i + r_j) from
    # its edge, one touching the 0.7 grain (a chain), and scattered clusters of mixed sizes 0.3 m off
    block = np.stack(np.meshgrid(np.arange(8), np.arange(8), np.arange(3), indexing="ij"), -1).reshape(-1, 3)
    block = 2.0e-3 * block + 1.0e-3
    edge = block[:, 0].max()
    sat = np.array([[edge + 2e-3 * (1 + g), 2e-3 * k + 1e-3, 1e-3] for k, g in enumerate((0.2, 0.7, 2.0))])
    chain = sat[1] + [0.0, 0.0, 2.0e-3]
    rng = np.random.default_rng(11)
    seeds = rng.uniform([0.25, -0.05, 0.0], [0.35, 0.05, 0.02], (25, 3))
    scatter = np.concatenate([s + rng.normal(0.0, 0.004, (rng.integers(1, 40), 3)) for s in seeds])
    x = np.vstack([block, sat, chain, scatter])
    r = np.r_[np.full(len(block) + 4, 1.0e-3), rng.uniform(0.6e-3, 1.8e-3, len(scatter))]
    x[:, 2] = np.maximum(np.abs(x[:, 2]), r)  # no sphere below the plate
    d = cdist(x, x) / (r[:, None] + r[None, :])
    touch = connected_components(d < 1.0 + PILE_GAP, directed=False)[1]
    on = np.isin(touch, touch[x[:, 2] - r <= PILE_GAP * r])
    assert 0 < on.sum() < len(r)
    if apart > 0:
        near = connected_components((d < 1.0 + apart) & on[:, None] & on[None, :], directed=False)[1]
        on &= near == np.argmax(np.bincount(near[on]))
    assert 0 < on.sum()
    assert np.array_equal(pile_spheres(x, r, apart=apart), on)


# --------------------------------------------------------------------------------------------------
# packing fraction and bulk density
# --------------------------------------------------------------------------------------------------


def _lattice(cells: int, basis, a: float) -> np.ndarray:
    """Centres of a cubic lattice of ``cells`` cells a side with cell size a [m] and the given basis."""
    idx = np.stack(np.meshgrid(*[np.arange(cells)] * 3, indexing="ij"), axis=-1).reshape(-1, 1, 3)
    return ((idx + np.asarray(basis)[None]) * a).reshape(-1, 3)


def _core(cells: int, a: float) -> BoxRegion:
    """A core two cells from the lattice's edge, a whole number of cells a side (so its solid fraction is the
    lattice's), its faces at odd fractions of a cell so that they cut spheres."""
    lo = np.array([2.13, 2.29, 2.41]) * a
    return BoxRegion(tuple(lo), tuple(lo + (cells - 5) * a))


def test_packing_fraction_of_simple_cubic_and_fcc_lattices():
    a = 0.01
    sc = _lattice(9, [(0.0, 0.0, 0.0)], a)
    got = packing_fraction(sc, np.full(len(sc), a / 2), _core(9, a))
    assert got["packing_fraction"] == pytest.approx(math.pi / 6, rel=0.01)
    fcc = _lattice(9, [(0, 0, 0), (0.5, 0.5, 0), (0.5, 0, 0.5), (0, 0.5, 0.5)], a)
    got = packing_fraction(fcc, np.full(len(fcc), a / (2 * math.sqrt(2))), _core(9, a))
    assert got["packing_fraction"] == pytest.approx(math.pi / (3 * math.sqrt(2)), rel=0.01)
    assert got["samples"] == 2**17 and got["region_volume_m3"] == pytest.approx(_core(9, a).volume)


def test_packing_fraction_counts_a_clumps_union_volume():
    """Dimers of two overlapping spheres: the solid is their union (two spheres less the lens), which differs
    from the sum of the sphere volumes by far more than the tolerance."""
    a, rad, d = 0.01, 0.003, 0.003
    centres = _lattice(9, [(0.5, 0.5, 0.5)], a)
    x = np.concatenate([centres - (d / 2, 0, 0), centres + (d / 2, 0, 0)])
    lens = math.pi * (4 * rad + d) * (2 * rad - d) ** 2 / 12
    union = 2 * (4 / 3) * math.pi * rad**3 - lens
    assert lens / union > 0.1
    got = packing_fraction(x, np.full(len(x), rad), _core(9, a))
    assert got["packing_fraction"] == pytest.approx(union / a**3, rel=0.01)


def test_packing_fraction_and_bulk_density_of_polydisperse_spheres_in_a_cylinder():
    """Spheres of two materials and random radii, each whole inside a cylinder: the fraction is the sum of
    their volumes over the cylinder's, the bulk density their mass over it."""
    rng = np.random.default_rng(3)
    a, radius, height = 0.01, 0.045, 0.06
    grid = _lattice(10, [(0.5, 0.5, 0.5)], a) - (0.05, 0.05, 0.0)
    r = rng.uniform(0.002, 0.0048, len(grid))
    inside = (np.hypot(grid[:, 0], grid[:, 1]) + r < radius) & (grid[:, 2] - r > 0) & (grid[:, 2] + r < height)
    x, r = grid[inside], r[inside]
    rho = np.where(rng.random(len(r)) < 0.5, 1500.0, 2500.0)
    region = CylinderRegion((0.0, 0.0), radius, 0.0, height)
    got = packing_fraction(x, r, region, density=rho, samples_log2=18, seed=7)
    volumes = 4 / 3 * math.pi * r**3
    assert got["packing_fraction"] == pytest.approx(volumes.sum() / region.volume, rel=0.01)
    assert got["bulk_density_kg_m3"] == pytest.approx((rho * volumes).sum() / region.volume, rel=0.01)
    assert got["spheres"] == len(r)
    # explicit seeds: the same inputs give the same numbers
    assert packing_fraction(x, r, region, density=rho, samples_log2=18, seed=7) == got


def test_packing_fraction_refuses_bad_input():
    x, r = np.zeros((1, 3)), np.ones(1)
    box = BoxRegion((0, 0, 0), (1, 1, 1))
    with pytest.raises(ValueError, match="region"):
        packing_fraction(x, r, ((0, 0, 0), (1, 1, 1)))
    with pytest.raises(ValueError, match="samples_log2"):
        packing_fraction(x, r, box, samples_log2=30)
    with pytest.raises(ValueError, match="density"):
        packing_fraction(x, r, box, density=[-1.0])
    with pytest.raises(ValueError, match="hi"):
        BoxRegion((0, 0, 0), (1, -1, 1))
    with pytest.raises(ValueError, match="radius"):
        CylinderRegion((0, 0), 0.0, 0.0, 1.0)
    with pytest.raises(ValueError, match="z_high"):
        CylinderRegion((0, 0), 1.0, 1.0, 1.0)


def test_packing_core_of_a_bed_in_a_cylinder():
    """An FCC bed cut to a cylinder (radius 0.04 m) with a flat top 0.05 m above its base: the core stands two
    diameters inside the wall, above the base and below the top, and holds the lattice's 0.7405 within 1 %;
    a bed shallower than five diameters leaves no core."""
    a = 0.01
    x = _lattice(12, [(0, 0, 0), (0.5, 0.5, 0), (0.5, 0, 0.5), (0, 0.5, 0.5)], a) - (0.06, 0.06, 0.0)
    r = np.full(len(x), a / (2 * math.sqrt(2)))
    keep = (np.hypot(x[:, 0], x[:, 1]) + r <= 0.04) & (x[:, 2] - r >= 0.0) & (x[:, 2] + r <= 0.05)
    x, r = x[keep], r[keep]
    top = float((x[:, 2] + r).max())
    d = 2 * r[0]
    core = packing_core(x, r, (0.0, 0.0), 0.04, 0.0)
    assert core.radius == pytest.approx(0.04 - 2 * d)
    assert core.z_low == pytest.approx(2 * d)
    assert core.z_high == pytest.approx(top - 2 * d)
    assert packing_fraction(x, r, core)["packing_fraction"] == pytest.approx(math.pi / (3 * math.sqrt(2)), rel=0.01)
    shallow = x[:, 2] + r <= 4.5 * d
    with pytest.raises(ValueError, match="deeper than 5 diameters"):
        packing_core(x[shallow], r[shallow], (0.0, 0.0), 0.04, 0.0)


@pytest.mark.parametrize("adhesive", [False, True])
def test_press_unload_reads_back_a_synthetic_cycle(adhesive):
    """Loading F = k d^1.7 to 12 N; a hold at the stop that relaxes the force to 10 N; linear unloading of
    stiffness 4e4 N/m from there, to zero force and beyond, where the piston leaves the bed (zero force after)
    or, for an adhesive bed, pulls on it (the line goes on below zero). Exponent, stiffness and set (between the
    branches' crossings of 5 % of the largest force, each at a sample) come back exactly."""
    zc, fill, n, k = 0.01, 0.01, 1.7, 2.0e4
    d_max = (12.0 / k) ** (1 / n)
    d_on = (0.6 / k) ** (1 / n)
    d_load = np.sort(np.concatenate([np.linspace(0.0, d_max, 40), [d_on]]))
    f_load = k * d_load**n
    f_hold, s = 10.0, 4.0e4
    d_off = d_max - (f_hold - 0.6) / s
    d_back = np.sort(np.concatenate([np.linspace(d_max, d_max - 1.5e-3, 25)[1:], [d_off]]))[::-1]
    f_back = f_hold - s * (d_max - d_back)
    if not adhesive:
        f_back = np.maximum(f_back, 0.0)
    uz = zc - np.concatenate([[d_max] * 3, d_back])
    uf = np.concatenate([[f_load[-1], 11.0, f_hold], f_back])
    d_res = d_off - d_on
    got = press_unload(zc - d_load, f_load, uz, uf, contact_z=zc, fill_height=fill)
    assert got["loading_exponent"] == pytest.approx(n, rel=1e-9)
    assert got["unloading_stiffness_n_m"] == pytest.approx(s, rel=1e-6)
    assert got["residual_set_m"] == pytest.approx(d_res, rel=1e-9)
    assert got["residual_set_ratio"] == pytest.approx(d_res / fill, rel=1e-9)
    assert got["max_displacement_m"] == pytest.approx(d_max)


def test_press_unload_pairs_interval_means_with_their_middles():
    """An elastic bed, F = k d^1.5 on the way down and back along the same curve (no set), sampled as a scene run
    samples it: each force the mean over an output interval (exact: k (b^2.5 - a^2.5) / (2.5 (b - a)) over the
    interval's travel a..b), at the interval's end height. Paired with the middles (``interval_means``) the set
    reads zero to second order in the interval (the mean of a convex curve sits above its middle value; below
    5 % of the interval's travel h here, h = d_max / 40); paired with the ends it reads one interval low."""
    zc, fill, k, d_max = 0.01, 0.01, 2.0e5, 2.0e-3
    edges = np.linspace(0.0, d_max, 41)
    h = edges[1] - edges[0]

    def means(a, b):
        return k * (b**2.5 - a**2.5) / (2.5 * (b - a))

    f_load = means(edges[:-1], edges[1:])
    back = edges[::-1]
    f_back = means(back[1:], back[:-1])
    load_z = zc - edges[1:]
    unload_z = np.concatenate([[load_z[-1]], zc - back[1:]])
    unload_f = np.concatenate([[f_load[-1]], f_back])
    mid = press_unload(load_z, f_load, unload_z, unload_f, contact_z=zc, fill_height=fill, interval_means=True)
    end = press_unload(load_z, f_load, unload_z, unload_f, contact_z=zc, fill_height=fill)
    assert abs(mid["residual_set_m"]) < 0.05 * h
    assert end["residual_set_m"] == pytest.approx(-h, rel=0.05)


def test_press_unload_refuses_a_retraction_that_moves_down():
    z = np.array([0.01, 0.009, 0.008])
    f = np.array([0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="unload_z"):
        press_unload(z, f, [0.008, 0.0085, 0.0082], [2.0, 1.0, 0.5], contact_z=0.01, fill_height=0.01)


def test_discharge_rate_fits_the_steady_part():
    """Discharged mass: nothing for 0.1 s, a quadratic start-up, 0.05 kg/s steady, then a stop at 0.4 kg. The
    fit over 20-80 % of the final mass (all steady here) gives 0.05 kg/s exactly; too few steady samples and
    bad input are refused."""
    t = np.linspace(0.0, 10.0, 201)
    m = np.where(t < 0.1, 0.0, np.where(t < 1.1, 0.025 * (t - 0.1) ** 2, 0.025 + 0.05 * (t - 1.1)))
    m = np.minimum(m, 0.4)
    got = discharge_rate(t, m)
    assert got["discharge_rate_kg_s"] == pytest.approx(0.05, rel=1e-9)
    assert got["discharged_kg"] == pytest.approx(0.4)
    # 20 % and 80 % of 0.4 kg are reached at 2.2 s and 7.0 s, within one 0.05 s sample
    assert got["steady_from_s"] == pytest.approx(2.2, abs=0.05) and got["steady_to_s"] == pytest.approx(7.0, abs=0.05)
    with pytest.raises(ValueError, match="at least 3"):
        discharge_rate([0.0, 1.0, 2.0, 3.0], [0.0, 0.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="increasing"):
        discharge_rate([0.0, 2.0, 1.0], [0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="some mass"):
        discharge_rate([0.0, 1.0, 2.0], [0.0, 0.0, 0.0])


def test_beverloo_rate_by_hand():
    """W = C rho_b sqrt(g) (D - k d)^(5/2): with D - k d = 0.04 m (0.04^2.5 = 3.2e-4 m^2.5), g = 4 m/s^2,
    rho_b = 1000 kg/m^3 and C = 0.5 the rate is 0.5 * 1000 * 2 * 3.2e-4 = 0.32 kg/s; a conical hopper of
    45 deg with phi_d = 30 deg multiplies it by (tan 45 tan 30)^-0.35 = 3^0.175."""
    got = beverloo_rate(0.055, 0.01, 1000.0, C=0.5, k=1.5, g=4.0)
    assert got == pytest.approx(0.32, rel=1e-12)
    hopper = beverloo_rate(0.055, 0.01, 1000.0, C=0.5, k=1.5, g=4.0, cone_half_angle=45.0, stagnant_angle=30.0)
    assert hopper == pytest.approx(0.32 * 3**0.175, rel=1e-12)


def test_hopper_angle_factor_and_its_flat_bottom_limit():
    """Rose and Tanaka: (tan theta tan phi_d)^-0.35 for theta < 90 - phi_d, symmetric in the two angles
    (3^0.175 for 30 and 45 deg either way); 1 at theta = 90 - phi_d and for any flatter hopper."""
    assert hopper_angle_factor(30.0, 45.0) == pytest.approx(3**0.175, rel=1e-12)
    assert hopper_angle_factor(45.0, 30.0) == pytest.approx(3**0.175, rel=1e-12)
    assert hopper_angle_factor(45.0, 45.0) == 1.0
    assert hopper_angle_factor(60.0, 45.0) == 1.0


def test_beverloo_band_by_hand():
    """The band's ends over C 0.55-0.65 and k 1.3-2.9: with d = 0.01 m and D = 0.0326 m, D - 2.9 d = 0.06^2 and
    D - 1.3 d = 0.14^2, so the low end is 0.55 rho_b sqrt(g) 0.06^5 and the high end 0.65 rho_b sqrt(g) 0.14^5
    (rho_b = 1000 kg/m^3, g = 4 m/s^2: 8.5536e-4 and 0.06991712 kg/s)."""
    band = beverloo_band(0.0326, 0.01, 1000.0, g=4.0)
    assert band["low_kg_s"] == pytest.approx(8.5536e-4, rel=1e-9)
    assert band["high_kg_s"] == pytest.approx(0.06991712, rel=1e-9)
    assert band["nominal_kg_s"] == pytest.approx(0.58 * 1000.0 * 2.0 * (0.0326 - 0.015) ** 2.5, rel=1e-12)
    assert band["hopper_factor"] == 1.0
    cone = beverloo_band(0.0326, 0.01, 1000.0, g=4.0, cone_half_angle=30.0)
    assert cone["low_kg_s"] == pytest.approx(8.5536e-4 * 3**0.175, rel=1e-9)


@pytest.mark.parametrize(
    "kw, name",
    [
        ({"outlet_diameter": 0.01}, "outlet_diameter"),  # D below k d: no flow
        ({"particle_diameter": 0.0}, "particle_diameter"),
        ({"bulk_density": -1.0}, "bulk_density"),
        ({"C": 0.0}, "C"),
        ({"k": -1.0}, "k"),
        ({"g": 0.0}, "g"),
        ({"cone_half_angle": 90.0}, "cone_half_angle"),
        ({"cone_half_angle": 30.0, "stagnant_angle": 0.0}, "stagnant_angle"),
    ],
)
def test_beverloo_rate_input_errors(kw, name):
    """Each bad argument is refused naming it."""
    args = {"outlet_diameter": 0.05, "particle_diameter": 0.01, "bulk_density": 1000.0, **kw}
    with pytest.raises(ValueError, match=f"^{name} = "):
        beverloo_rate(**args)


def test_beverloo_band_input_errors():
    """A band needs (low, high) pairs, and an outlet wider than the largest k times d."""
    with pytest.raises(ValueError, match="^C = "):
        beverloo_band(0.05, 0.01, 1000.0, C=(0.65, 0.55))
    with pytest.raises(ValueError, match="^outlet_diameter = "):
        beverloo_band(0.025, 0.01, 1000.0)


# --------------------------------------------------------------------------------------------------
# rotating drum
# --------------------------------------------------------------------------------------------------
DRUM_R = 0.042  # GranuDrum's inner radius [m]


def _drum_bed(angle_deg, r=0.0005, width=0.01, level=-0.005, seed=0, turn=0.0):
    """Spheres of radius ``r`` [m] on a jittered cubic lattice (spacing 1.9 r, so neighbours touch; +-0.1 r of
    jitter; turned by ``turn`` [rad] in the cross-section) filling a drum of radius DRUM_R about the y axis,
    ``width`` [m] deep, below the plane h = level - tan(angle) s: its top rises toward -x by ``angle_deg``."""
    rng = np.random.default_rng(seed)
    step = 1.9 * r
    g = np.arange(-1.5 * DRUM_R, 1.5 * DRUM_R, step)
    ys = np.arange(-width / 2 + r, width / 2 - r + 1e-12, step)
    S, Y, H = np.meshgrid(g, ys, g, indexing="ij")
    c, sn = math.cos(turn), math.sin(turn)
    s, h = c * S.ravel() - sn * H.ravel(), sn * S.ravel() + c * H.ravel()
    x = np.column_stack([s, Y.ravel(), h]) + rng.uniform(-0.1 * r, 0.1 * r, (s.size, 3))
    slope = -math.tan(math.radians(angle_deg))
    keep = (np.hypot(x[:, 0], x[:, 2]) <= DRUM_R - r) & (x[:, 2] + r <= level + slope * x[:, 0])
    return x[keep], np.full(int(keep.sum()), r)


@pytest.mark.parametrize("angle", [25.0, -25.0, 40.0])
@pytest.mark.parametrize("turn", [0.0, 0.3])
def test_drum_surface_recovers_the_slope(angle, turn):
    """A bed whose sphere tops lie under a plane of known slope, inside GranuDrum's 84 mm circle, reads its slope
    within 0.5 deg, sign included (rising toward -x, the side a drum turning about +y lifts, is positive). The
    tops scatter over one lattice step below the plane (SD ~0.55 r); over ~23 points across 60 % of the chord
    that moves the slope by ~0.2 deg (1 SD), so 0.5 deg is 2.5 SD. The chord is where that plane meets the
    drum."""
    x, r = _drum_bed(angle, turn=turn)
    got = drum_surface(x, r, (0.0, 0.0, 0.0), DRUM_R)
    assert got["angle_deg"] == pytest.approx(angle, abs=0.5)
    # a lattice corner cut by the drum's circle may leave a sphere or two touching none
    assert got["detached"] <= 2 and got["bed_spheres"] == len(r) - got["detached"]
    assert len(got["surface_s"]) >= 10
    # the sphere tops are at most one step (1.9 r, plus jitter) under the plane; the chord is that plane's
    slope = -math.tan(math.radians(angle))
    below = -0.005 + slope * got["surface_s"] - got["surface_h"]
    assert np.all((below >= 0) & (below <= 2.2 * r[0] * (1 + abs(slope))))
    s0, s1 = got["chord_m"]
    for s in (s0, s1):
        assert math.hypot(s, got["intercept_m"] + got["slope"] * s) == pytest.approx(DRUM_R, rel=1e-9)


def test_drum_surface_ignores_flying_spheres_and_follows_the_axis():
    """Spheres flying over the bed (isolated, 3 diameters apart, up to the drum's top) are not part of the bed:
    the surface is read exactly as without them and they are counted as detached. The same bed seen with the
    axis reversed (a drum turning the other way) reads the opposite angle, and moved with its drum it reads the
    same angle."""
    x, r = _drum_bed(25.0)
    ref = drum_surface(x, r, (0.0, 0.0, 0.0), DRUM_R)
    rng = np.random.default_rng(1)
    fly = np.column_stack(
        [np.arange(-0.02, 0.02, 6 * r[0]), rng.uniform(-0.004, 0.004, 14), rng.uniform(0.02, 0.035, 14)]
    )
    got = drum_surface(np.vstack([x, fly]), np.r_[r, np.full(len(fly), r[0])], (0.0, 0.0, 0.0), DRUM_R)
    assert got["detached"] == len(fly)
    assert got["angle_deg"] == ref["angle_deg"]
    assert np.array_equal(got["surface_h"], ref["surface_h"])
    back = drum_surface(x, r, (0.0, 0.0, 0.0), DRUM_R, axis=(0.0, -1.0, 0.0))
    assert back["angle_deg"] == pytest.approx(-ref["angle_deg"], abs=1e-9)
    moved = drum_surface(x + (0.3, -0.1, 0.5), r, (0.3, -0.1, 0.5), DRUM_R)
    assert moved["angle_deg"] == pytest.approx(ref["angle_deg"], abs=1e-9)


def _frames(heights, angles=None, n=30, span=0.03, seed=0):
    """drum_surface-like frames: surface points at jittered positions over [-span, span] [m] (each frame its
    own), heights ``heights[k](s)`` [m]."""
    rng = np.random.default_rng(seed)
    out = []
    for k, fn in enumerate(heights):
        s = np.sort(rng.uniform(-span, span, n))
        s[0], s[-1] = -span, span
        out.append({"angle_deg": 30.0 if angles is None else angles[k], "surface_s": s, "surface_h": fn(s)})
    return out


def test_drum_metrics_of_known_fluctuations():
    """Frames of a straight surface (the profile is linear between points, so it is read exactly anywhere):
    shifted up and down by +-delta in turn, the height's sample SD over K frames is delta sqrt(K / (K - 1))
    everywhere, and so is the index (in diameters); tilted by +-eps about s = 0, the SD at s is
    |s| eps sqrt(K / (K - 1)) and its rms over P equally spaced positions on [-L, L] is
    eps sqrt(K / (K - 1)) L sqrt((P + 1) / (3 (P - 1))). The angles' mean and SD are the frames'."""
    K, d, delta = 6, 0.001, 0.0004
    shifted = [(lambda s, k=k: 0.01 - 0.5 * s + (delta if k % 2 else -delta)) for k in range(K)]
    angles = [29.0, 31.0] * (K // 2)
    got = drum_metrics(_frames(shifted, angles), d)
    assert got["fluctuation_index"] == pytest.approx(delta * math.sqrt(K / (K - 1)) / d, rel=1e-9)
    assert got["dynamic_angle_deg"] == pytest.approx(30.0, abs=1e-12)
    assert got["dynamic_angle_sd_deg"] == pytest.approx(math.sqrt(K / (K - 1)), rel=1e-12)
    assert got["frames"] == K
    eps, P, L = 0.05, 16, 0.03
    tilted = [(lambda s, k=k: -0.5 * s + (eps if k % 2 else -eps) * s) for k in range(K)]
    got = drum_metrics(_frames(tilted), d, positions=P)
    assert got["positions_m"][0] == pytest.approx(-L) and got["positions_m"][-1] == pytest.approx(L)
    want = eps * math.sqrt(K / (K - 1)) * L * math.sqrt((P + 1) / (3 * (P - 1))) / d
    assert got["fluctuation_index"] == pytest.approx(want, rel=1e-9)
    # a steady surface does not fluctuate
    still = drum_metrics(_frames([(lambda s: 0.01 - 0.5 * s)] * K), d)
    assert still["fluctuation_index"] == pytest.approx(0.0, abs=1e-12)


def test_drum_metrics_reads_the_common_span():
    """Frames that cover different parts of the chord are compared only where all of them have surface points."""
    frames = _frames([lambda s: 0 * s] * 3)
    frames[1] = {**frames[1], "surface_s": frames[1]["surface_s"] * 0.5 + 0.01}
    got = drum_metrics(frames, 0.001, positions=5)
    assert got["positions_m"][0] == pytest.approx(-0.005) and got["positions_m"][-1] == pytest.approx(0.025)


def test_plot_drum_writes_png(tmp_path):
    """plot_drum writes the cross-section with the fitted surface as a PNG."""
    x, r = _drum_bed(25.0, r=0.001)
    got = drum_surface(x, r, (0.0, 0.0, 0.0), DRUM_R)
    path = plot_drum(x[:, 0], x[:, 2], r, got, tmp_path / "drum.png", DRUM_R, title="drum")
    assert (tmp_path / "drum.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.endswith("drum.png")


_DX, _DR = _drum_bed(25.0, r=0.001)
_DF = _frames([lambda s: 0 * s] * 2)


@pytest.mark.parametrize(
    "call,names",
    [
        (lambda: drum_surface(_DX, _DR, (0.0, 0.0, 0.0), 0.0), "drum_radius = 0.0"),
        (lambda: drum_surface(_DX, _DR, (0.0, 0.0, 0.0), 0.005), "drum_radius = 0.005"),
        (lambda: drum_surface(_DX, _DR, (0.0, 0.0), DRUM_R), "center = "),
        (lambda: drum_surface(_DX, _DR, (0.0, 0.0, 0.0), DRUM_R, axis=(0.0, 0.0, 1.0)), "axis = .*horizontal"),
        (lambda: drum_surface(_DX, _DR, (0.0, 0.0, 0.0), DRUM_R, axis=(0.0, 0.0, 0.0)), "axis = "),
        (lambda: drum_surface(_DX, _DR, (0.0, 0.0, 0.0), DRUM_R, bins=2), "bins = 2"),
        (lambda: drum_surface(_DX, _DR, (0.0, 0.0, 0.0), DRUM_R, inner=0.5, outer=0.5), "outer = 0.5"),
        (lambda: drum_surface(_DX, _DR, (0.0, 0.0, 0.0), DRUM_R, gap=-0.1), "gap = -0.1"),
        (lambda: drum_surface(_DX[:2], _DR[:2], (0.0, 0.0, 0.0), DRUM_R), "x = "),
        (lambda: drum_surface(_DX[:40], _DR[:40], (0.0, 0.0, 0.0), DRUM_R), "x = .*surface points"),
        (lambda: drum_metrics(_DF[:1], 0.001), "frames = "),
        (lambda: drum_metrics(_DF, 0.0), "diameter = 0.0"),
        (lambda: drum_metrics(_DF, 0.001, positions=1), "positions = 1"),
        (lambda: drum_metrics([_DF[0], {"angle_deg": 1.0}], 0.001), r"frames\[1\] = "),
        (
            lambda: drum_metrics([_DF[0], {**_DF[1], "surface_s": _DF[1]["surface_s"] + 1.0}], 0.001),
            "frames = .*overlap",
        ),
        (lambda: plot_drum(_DX[:, 0], _DX[:, 2], _DR, {}, "x.png", DRUM_R), "surface = "),
    ],
)
def test_drum_bad_input_names_argument(call, names):
    """Bad drum input raises ValueError naming the argument and its value, and saying what is allowed."""
    with pytest.raises(ValueError, match=names) as err:
        call()
    assert "expected" in str(err.value)


def test_plot_impacts_draws_and_refuses_mismatched_faces(tmp_path):
    """plot_impacts writes the heat map of two walls (one with no impact: grey, no colour scale from it) and
    refuses an energy array that is not one value per face, naming the wall."""
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    t = np.array([[0, 1, 2], [0, 2, 3]])
    walls = [("Body", v, t, np.array([2.0, 0.0]), np.array([3, 0])), ("Gate", v, t, np.zeros(2), np.zeros(2))]
    path = plot_impacts(walls, tmp_path / "impacts.png", title="two walls")
    assert path.endswith("impacts.png") and (tmp_path / "impacts.png").stat().st_size > 5000
    with pytest.raises(ValueError, match=r"walls\[0\] \(Body\) energy / count"):
        plot_impacts([("Body", v, t, np.ones(3), np.ones(2))], tmp_path / "bad.png")
