"""Particle factories: size distributions, regions, random sequential addition fills, release schedules.

Statistical checks use a fixed seed and a tolerance of 5 standard errors (computed from the theory where
the sample cannot give it), so a correct sampler fails with probability below 1e-6 for any seed.
"""

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import integrate, stats
from scipy.spatial import cKDTree

from warpdem.engine import factories as fa

PSD_CSV = Path(__file__).resolve().parents[2] / "studies" / "reference" / "phosphate_psd.csv"
Z = 5.0  # tolerance in standard errors

REGIONS = {
    "box": fa.Box((0.0, 0.0, 0.0), (0.04, 0.05, 0.06)),
    "cylinder": fa.Cylinder((0.1, -0.2, 0.3), (1.0, 2.0, 2.0), radius=0.025, height=0.07),
    # A funnel (wider at the top), tilted, and a cone narrowing to an apex.
    "funnel": fa.Cone((0.0, 0.0, 0.0), (0.0, 0.6, 0.8), base_radius=0.01, top_radius=0.04, height=0.06),
    "apex_cone": fa.Cone((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), base_radius=0.04, top_radius=0.0, height=0.05),
}


# -- independent geometry for the checks -----------------------------------------------------------------------


def _segment_distance(px, py, ax, ay, bx, by):
    """Distance from points (px, py) to the segment a-b in a plane."""
    dx, dy = bx - ax, by - ay
    length2 = dx * dx + dy * dy
    t = np.clip(((px - ax) * dx + (py - ay) * dy) / length2, 0.0, 1.0) if length2 > 0 else 0.0
    return np.hypot(px - ax - t * dx, py - ay - t * dy)


def _depth(region, x):
    """Signed depth of points inside the region (distance to the boundary; < 0 outside), by brute geometry.

    For the solids of revolution the nearest boundary point lies in the point's meridian half-plane, where
    the region is the trapezoid (0, 0), (Rb, 0), (Rt, H), (0, H); the axis edge is not a boundary.
    """
    x = np.atleast_2d(x)
    if isinstance(region, fa.Box):
        return np.min(np.concatenate([x - region.lo, np.asarray(region.hi) - x], axis=1), axis=1)
    rb, rt = (
        (region.radius, region.radius) if isinstance(region, fa.Cylinder) else (region.base_radius, region.top_radius)
    )
    a = np.asarray(region.axis)
    d = x - np.asarray(region.base_center)
    h = d @ a
    rho = np.linalg.norm(d - h[:, None] * a, axis=1)
    height = region.height
    dist = np.minimum.reduce(
        [
            _segment_distance(rho, h, 0.0, 0.0, rb, 0.0),
            _segment_distance(rho, h, rb, 0.0, rt, height),
            _segment_distance(rho, h, rt, height, 0.0, height),
        ]
    )
    inside = (h >= 0) & (h <= height) & (rho <= rb + (rt - rb) * h / height)
    return np.where(inside, dist, -dist)


def _min_gap(x, r):
    """Smallest |x_i - x_j| - r_i - r_j over all pairs [m] (inf for fewer than 2 spheres)."""
    if len(x) < 2:
        return math.inf
    pairs = cKDTree(x).query_pairs(2.0 * float(r.max()), output_type="ndarray")
    if len(pairs) == 0:
        return math.inf
    i, j = pairs[:, 0], pairs[:, 1]
    return float(np.min(np.linalg.norm(x[i] - x[j], axis=1) - r[i] - r[j]))


def _radius_for_fraction(region, n, phi):
    return (phi * region.volume / n / (4.0 / 3.0 * math.pi)) ** (1.0 / 3.0)


# -- regions -------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(REGIONS))
def test_region_contains_matches_distance_to_boundary(name):
    """contains(p, margin) is True exactly where the distance from p to the boundary is >= margin (the
    sphere of radius margin fits), and inset(margin) contains the same points."""
    region = REGIONS[name]
    rng = np.random.default_rng(1)
    lo, hi = region.bounds()
    p = lo + rng.random((20000, 3)) * (hi - lo)
    margin = 0.2 * region.inradius
    depth = _depth(region, p)
    clear = np.abs(depth - margin) > 1e-9  # away from the inset boundary, where round-off decides
    assert np.array_equal(region.contains(p, margin)[clear], (depth >= margin)[clear])
    assert np.array_equal(region.contains(p)[np.abs(depth) > 1e-9], (depth >= 0)[np.abs(depth) > 1e-9])
    assert np.array_equal(region.inset(margin).contains(p)[clear], (depth >= margin)[clear])


@pytest.mark.parametrize("name", list(REGIONS))
def test_region_volume_and_uniform_sampling(name):
    """volume equals the Monte Carlo volume (fraction of bounding-box points inside, 5 SE); sample_uniform
    lands inside and spreads uniformly: the share below half height equals that part's volume (5 SE)."""
    region = REGIONS[name]
    rng = np.random.default_rng(2)
    n = 40000
    lo, hi = region.bounds()
    p = lo + rng.random((n, 3)) * (hi - lo)
    frac = float(region.contains(p).mean())
    box = float(np.prod(hi - lo))
    assert region.volume == pytest.approx(frac * box, abs=Z * box * math.sqrt(frac * (1 - frac) / n))

    s = region.sample_uniform(rng, n)
    assert np.all(_depth(region, s) >= -1e-12)
    if isinstance(region, fa.Box):
        lower_share = 0.5
        below = s[:, 2] < 0.5 * (region.lo[2] + region.hi[2])
    else:
        h = (s - np.asarray(region.base_center)) @ np.asarray(region.axis)
        below = h < 0.5 * region.height
        rb = region.radius if isinstance(region, fa.Cylinder) else region.base_radius
        rt = region.radius if isinstance(region, fa.Cylinder) else region.top_radius
        rm = 0.5 * (rb + rt)
        lower_share = (rb * rb + rb * rm + rm * rm) / 4.0 / ((rb * rb + rb * rt + rt * rt) / 2.0)
    assert below.mean() == pytest.approx(lower_share, abs=Z * math.sqrt(lower_share * (1 - lower_share) / n))


def test_cone_inset_cuts_at_apex():
    """Insetting a funnel by more than its narrow end allows leaves a full cone whose apex is where a sphere
    of that radius wedges between the slanted walls: R(h) = margin * sqrt(1 + slope^2)."""
    funnel = fa.Cone((0, 0, 0), (0, 0, 1), base_radius=0.0, top_radius=0.03, height=0.06)
    m = 0.005
    inner = funnel.inset(m)
    slope = 0.03 / 0.06
    assert inner.base_radius == pytest.approx(0.0, abs=1e-15)
    assert inner.base_center[2] == pytest.approx(m * math.sqrt(1 + slope**2) / slope)
    assert inner.base_center[2] + inner.height == pytest.approx(0.06 - m)


# -- static fill ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(REGIONS))
def test_fill_region_exact_count_no_overlap_inside(name):
    """fill_region places exactly `count` spheres (polydisperse, 25 % volume fraction), each fully inside the
    region and with zero overlap: |x_i - x_j| >= r_i + r_j (to round-off, 1e-12 of the radius)."""
    region = REGIONS[name]
    n = 1500
    r0 = _radius_for_fraction(region, n, 0.25)
    sizes = fa.TruncatedNormal(mean=r0, std=0.2 * r0, low=0.6 * r0, high=1.3 * r0)
    x, r = fa.fill_region(region, sizes, count=n, rng_seed=3)
    assert x.shape == (n, 3) and r.shape == (n,)
    assert np.all(_depth(region, x) >= r - 1e-12 * r)
    assert _min_gap(x, r) >= -1e-12 * r0


def test_fill_region_mass_target_within_one_particle():
    """A mass target gives the fewest particles whose mass reaches it: M - m_last < target <= M."""
    region = REGIONS["cylinder"]
    density = 2650.0
    sizes = fa.LogNormal(median=1.5e-3, sigma_log=0.25, low=1e-3, high=2.5e-3)
    target = 0.25 * region.volume * density
    x, r = fa.fill_region(region, sizes, mass=target, density=density, rng_seed=4)
    m = density * 4.0 / 3.0 * math.pi * r**3
    assert m.sum() >= target > m.sum() - m[-1]
    assert np.all(_depth(region, x) >= r * (1 - 1e-12))
    assert _min_gap(x, r) >= -1e-15


def test_fill_region_seeded():
    """The same seed reproduces the fill bit for bit; another seed gives another fill."""
    region = REGIONS["funnel"]
    sizes = fa.FixedSize(_radius_for_fraction(region, 500, 0.2))
    a = fa.fill_region(region, sizes, count=500, rng_seed=7)
    b = fa.fill_region(region, sizes, count=500, rng_seed=7)
    c = fa.fill_region(region, sizes, count=500, rng_seed=8)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert not np.allclose(a[0], c[0])


def test_fill_region_avoids_existing_particles():
    """New spheres do not overlap particles already in the region (given as centres and bounding radii)."""
    region = REGIONS["box"]
    r0 = _radius_for_fraction(region, 800, 0.15)
    x0, r_old = fa.fill_region(region, fa.FixedSize(r0), count=800, rng_seed=1)
    x1, r1 = fa.fill_region(region, fa.FixedSize(0.7 * r0), count=800, rng_seed=2, existing_x=x0, existing_r=r_old)
    assert _min_gap(np.concatenate([x0, x1]), np.concatenate([r_old, r1])) >= -1e-12 * r0


def test_fill_region_clumps_use_bounding_radius_and_orientations():
    """With bounding_ratio b, spheres of radius b * r are kept apart and inside; orientations come back as
    unit quaternions without changing positions or sizes."""
    region = REGIONS["box"]
    r0 = _radius_for_fraction(region, 400, 0.2) / 1.8
    x, r, q = fa.fill_region(region, fa.FixedSize(r0), count=400, rng_seed=5, bounding_ratio=1.8, orientations=True)
    assert np.all(_depth(region, x) >= 1.8 * r * (1 - 1e-12))
    assert _min_gap(x, 1.8 * r) >= -1e-12 * r0
    assert q.shape == (400, 4) and np.allclose(np.linalg.norm(q, axis=1), 1.0)
    x2, r2 = fa.fill_region(region, fa.FixedSize(r0), count=400, rng_seed=5, bounding_ratio=1.8)
    assert np.array_equal(x, x2) and np.array_equal(r, r2)


def test_fill_region_overfull_names_counts_and_rsa_limit():
    """Asking for a 50 % volume fraction (above the ~0.38 random sequential addition limit) raises an error
    saying how many fitted and pointing at the limit."""
    region = fa.Box((0, 0, 0), (0.01, 0.01, 0.01))
    r0 = _radius_for_fraction(region, 300, 0.5)
    with pytest.raises(fa.RegionFullError, match=r"only \d+ of 300 .*0\.38.*larger region") as err:
        fa.fill_region(region, fa.FixedSize(r0), count=300, rng_seed=1, max_attempts=300)
    assert 0 < err.value.placed < 300


# -- size distributions --------------------------------------------------------------------------------------


def test_truncated_normal_moments_and_bounds():
    """Sample mean and variance of TruncatedNormal match the truncated-normal formulas
    mean = mu + s (phi(a) - phi(b)) / Z, var = s^2 [1 + (a phi(a) - b phi(b)) / Z - ((phi(a) - phi(b)) / Z)^2],
    within 5 standard errors (SE of the mean sd / sqrt(n); of the variance sqrt((m4 - var^2) / n));
    no radius leaves [low, high]."""
    mu, s, low, high = 1.0e-3, 0.4e-3, 0.6e-3, 1.5e-3
    d = fa.TruncatedNormal(mean=mu, std=s, low=low, high=high)
    n = 20000
    r = d.sample(np.random.default_rng(11), n)
    a, b = (low - mu) / s, (high - mu) / s
    zn = stats.norm.cdf(b) - stats.norm.cdf(a)
    pa, pb = stats.norm.pdf(a), stats.norm.pdf(b)
    mean = mu + s * (pa - pb) / zn
    var = s * s * (1 + (a * pa - b * pb) / zn - ((pa - pb) / zn) ** 2)
    m4 = np.mean((r - r.mean()) ** 4)
    assert r.min() >= low and r.max() <= high
    assert r.mean() == pytest.approx(mean, abs=Z * math.sqrt(var / n))
    assert r.var() == pytest.approx(var, abs=Z * math.sqrt((m4 - var**2) / n))
    assert d.mean_radius() == pytest.approx(mean, rel=1e-9)


def test_lognormal_moments():
    """ln r of an untruncated LogNormal has mean ln(median) and sd sigma_log (5 SE: sigma/sqrt(n) and
    sigma/sqrt(2n)); E[r] = median exp(sigma^2 / 2) from the moment formula."""
    d = fa.LogNormal(median=2e-3, sigma_log=0.3)
    n = 20000
    lr = np.log(d.sample(np.random.default_rng(12), n))
    assert lr.mean() == pytest.approx(math.log(2e-3), abs=Z * 0.3 / math.sqrt(n))
    assert lr.std() == pytest.approx(0.3, abs=Z * 0.3 / math.sqrt(2 * n))
    assert d.mean_radius() == pytest.approx(2e-3 * math.exp(0.045), rel=1e-12)


def test_truncated_lognormal_bounds_and_moments():
    """A truncated LogNormal stays within [low, high]; its moment(k) equals the integral of r^k over the
    truncated density; the sample mean matches E[r] within 5 SE."""
    d = fa.LogNormal(median=1e-3, sigma_log=0.5, low=0.7e-3, high=2.5e-3)
    n = 20000
    r = d.sample(np.random.default_rng(13), n)
    assert r.min() >= 0.7e-3 and r.max() <= 2.5e-3
    pdf = stats.lognorm(s=0.5, scale=1e-3).pdf
    norm = integrate.quad(pdf, 0.7e-3, 2.5e-3)[0]
    for k in (1, 2, 3):
        expected = integrate.quad(lambda x, k=k: x**k * pdf(x), 0.7e-3, 2.5e-3, epsrel=1e-12)[0] / norm
        assert d.moment(k) == pytest.approx(expected, rel=1e-7)
    sd = math.sqrt(d.moment(2) - d.moment(1) ** 2)
    assert r.mean() == pytest.approx(d.moment(1), abs=Z * sd / math.sqrt(n))


def _sieve_mass_fraction_se(table: fa.SieveTable, n: int) -> np.ndarray:
    """Standard error of the sample mass fraction sum_i V_i 1_c / sum_i V_i of each class (delta method):
    Var = ((1 - 2 F) E[V^2 1_c] + F^2 E[V^2]) / (n E[V]^2), with the class moments of d^3 and d^6 for a
    log-uniform diameter, E[d^k] = (b^k - a^k) / (k ln(b / a))."""
    e = np.asarray(table.sizes)
    lo, hi = e[:-1], e[1:]
    f = np.asarray(table.mass_fractions)

    def mom(k):
        return (hi**k - lo**k) / (k * np.log(hi / lo))

    p = f / mom(3)
    p /= p.sum()
    ev = np.sum(p * mom(3))
    ev2_c = p * mom(6)
    var = ((1 - 2 * f) * ev2_c + f**2 * ev2_c.sum()) / (n * ev**2)
    return np.sqrt(var)


def test_sieve_table_samples_carry_the_mass_fractions():
    """20 000 radii drawn by number from a sieve table carry the table's MASS fractions, within 5 SE of the
    ratio estimator; every diameter lies within the table's edges."""
    table = fa.SieveTable(sizes=[1e-3, 1.4e-3, 2e-3, 2.8e-3, 4e-3], mass_fractions=[0.1, 0.3, 0.4, 0.2])
    n = 20000
    r = table.sample(np.random.default_rng(14), n)
    assert 2 * r.min() >= 1e-3 and 2 * r.max() <= 4e-3
    got = table.mass_fractions_of(r)
    se = _sieve_mass_fraction_se(table, n)
    assert np.all(np.abs(got - table.mass_fractions) <= Z * se), (got, se)
    assert got.sum() == pytest.approx(1.0)


def test_phosphate_psd_loads_and_samples():
    """phosphate_psd.csv (seed 002 Table 1) loads as 7 mass classes from 42.7 um (pan, extrapolated) to 5 mm
    (above the 2 mm sieve, extrapolated), fractions = retained % / 99.77 % (sieving loss spread); the class
    counts of 20 000 samples follow the number fractions (multinomial, 5 SE) and their mass fractions follow
    the table within 5 SE (large for the rare coarse classes)."""
    table = fa.SieveTable.from_csv(PSD_CSV)
    assert table.spread is fa.SizeSpread.LOG_UNIFORM
    assert np.allclose(table.sizes, np.array([80**2 / 150, 80, 150, 250, 500, 800, 2000, 5000]) * 1e-6)
    retained_pct = np.array([3.02, 10.02, 18.71, 26.6, 26.63, 11.47, 3.32])  # pan first
    assert np.allclose(table.mass_fractions, retained_pct / retained_pct.sum(), rtol=1e-12)
    n = 20000
    r = table.sample(np.random.default_rng(15), n)
    cls = np.searchsorted(np.asarray(table.sizes), 2 * r, side="right") - 1
    p = table.number_fractions()
    counts = np.bincount(cls, minlength=7)
    assert np.all(np.abs(counts - n * p) <= Z * np.sqrt(n * p * (1 - p)) + 1)
    got = table.mass_fractions_of(r)
    assert np.all(np.abs(got - table.mass_fractions) <= Z * _sieve_mass_fraction_se(table, n))


def test_sieve_table_from_cumulative_passing(tmp_path):
    """A sheet with only cumulative % passing (no pan row) gives the same classes: differences of passing,
    and what passes the finest sieve becomes the finest class."""
    csv = tmp_path / "psd.csv"
    csv.write_text("sieve_mm,cumulative_passing_pct\n4,100\n2,60\n1,20\n")
    table = fa.SieveTable.from_csv(csv, pan_size=0.5e-3)
    assert np.allclose(table.sizes, [0.5e-3, 1e-3, 2e-3, 4e-3])
    assert np.allclose(table.mass_fractions, [0.2, 0.4, 0.4])


def test_mass_fractions_of_counts_volume():
    """mass_fractions_of weighs particles by r^3; particles outside the edges count only in the total."""
    table = fa.SieveTable(sizes=[1.0, 2.0, 4.0], mass_fractions=[0.5, 0.5])
    got = table.mass_fractions_of(np.array([0.75, 1.5, 1.5, 3.0]) / 2)  # diameters 0.75 (outside), 1.5, 1.5, 3
    total = 0.75**3 + 2 * 1.5**3 + 3.0**3
    assert np.allclose(got, [2 * 1.5**3 / total, 3.0**3 / total])


# -- dynamic factory -----------------------------------------------------------------------------------------


def test_dynamic_plan_count_rate():
    """The plan releases exactly `count` particles; at each batch time the cumulative count equals
    floor(rate (t - start)) (until the total is reached), so it lags the continuous rate by < one batch;
    the default interval gives at least one particle per batch."""
    f = fa.DynamicFactory(REGIONS["box"], fa.FixedSize(1e-3), rate=370.0, count=1000, start_time=0.5, interval=0.013)
    plan = f.plan()
    t = np.array([p[0] for p in plan])
    cum = np.cumsum([p[1] for p in plan])
    assert cum[-1] == 1000 == f.capacity()
    assert np.all(np.diff(t) > 0) and t[0] > 0.5
    assert np.array_equal(cum[:-1], np.floor(370.0 * (t[:-1] - 0.5) + 1e-9).astype(int))
    assert cum[-1] - 370.0 * (t[-1] - 0.5) < 1
    default = fa.DynamicFactory(REGIONS["box"], fa.FixedSize(1e-3), rate=2000.0, count=300).plan()
    assert len(default) == 300 and all(c == 1 for _, c in default)


def test_dynamic_plan_mass_rate_and_mass_target():
    """A mass target pre-draws the fewest particles reaching it (M - m_last < target <= M); with a mass rate
    the cumulative released mass never exceeds mass_rate (t - start) and trails it by less than one
    particle; sizes are the same for the same seed."""
    sizes = fa.LogNormal(median=1e-3, sigma_log=0.3, low=0.5e-3, high=2e-3)
    f = fa.DynamicFactory(REGIONS["box"], sizes, mass_rate=0.02, mass=0.5, density=2500.0, seed=3, interval=0.05)
    m = f.masses
    assert m.sum() >= 0.5 > m.sum() - m[-1]
    plan = f.plan()
    cum_n = np.cumsum([c for _, c in plan])
    assert cum_n[-1] == f.capacity() == len(f.radii)
    cum_m = np.cumsum(m)[cum_n - 1]
    target = 0.02 * np.array([t for t, _ in plan])
    assert np.all(cum_m[:-1] <= target[:-1] * (1 + 1e-9))
    assert np.all(cum_m[:-1] + m[cum_n[:-1]] > target[:-1])  # the next particle would overshoot
    g = fa.DynamicFactory(REGIONS["box"], sizes, mass_rate=0.02, mass=0.5, density=2500.0, seed=3)
    assert np.array_equal(f.radii, g.radii)
    assert all(c >= 1 for _, c in g.plan())


def test_dynamic_place_avoids_overlap_and_defers_when_crowded():
    """place() puts a batch clear of existing particles and of itself; in a crowded region it returns the
    leading particles that fitted (with their pre-drawn sizes) and leaves the rest for the caller to defer."""
    region = fa.Box((0, 0, 0), (0.01, 0.01, 0.01))
    r0 = _radius_for_fraction(region, 200, 0.1)
    f = fa.DynamicFactory(region, fa.FixedSize(r0), rate=100.0, count=2000, max_attempts=50)
    x, r = f.place(None, 100, first=0)
    assert len(x) == 100 and np.array_equal(r, f.radii[:100])
    x2, r2 = f.place(None, 400, x, r, first=100)
    assert len(x2) < 400 and np.array_equal(r2, f.radii[100 : 100 + len(x2)])
    assert _min_gap(np.concatenate([x, x2]), np.concatenate([r, r2])) >= -1e-12 * r0
    assert np.all(region.contains(x2, r2))


# -- orientations --------------------------------------------------------------------------------------------


def test_random_quaternions_uniform_on_so3():
    """Quaternions are unit; rotating e_z by them gives points uniform on the sphere: mean z = 0 and
    mean z^2 = 1/3 within 5 SE (Var z = 1/3, Var z^2 = 1/5 - 1/9 = 4/45); the (x, y, z, w) order agrees with
    wp.quat_rotate."""
    import warp as wp

    n = 20000
    q = fa.random_quaternions(np.random.default_rng(16), n)
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    x, y, z, w = q.T
    ez = np.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)], axis=1)
    for k in range(3):
        assert ez[:, k].mean() == pytest.approx(0.0, abs=Z * math.sqrt(1 / 3 / n))
        assert (ez[:, k] ** 2).mean() == pytest.approx(1 / 3, abs=Z * math.sqrt(4 / 45 / n))
    for i in range(3):
        v = wp.quat_rotate(wp.quat(*q[i].astype(np.float32)), wp.vec3(0.0, 0.0, 1.0))
        assert np.allclose(np.array(v), ez[i], atol=1e-5)


# -- errors --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "build, pattern",
    [
        (lambda: fa.FixedSize(-1e-3), r"radius = -0\.001 .*> 0"),
        (lambda: fa.TruncatedNormal(1e-3, -1e-4, 5e-4, 2e-3), r"std = -0\.0001 .*>= 0"),
        (lambda: fa.TruncatedNormal(1e-3, 1e-4, 2e-3, 1e-3), r"high = 0\.001 .*> low"),
        (lambda: fa.LogNormal(0.0, 0.3), r"median = 0\.0 .*> 0"),
        (lambda: fa.LogNormal(1e-3, 0.3, low=2e-3, high=1e-3), r"high = 0\.001"),
        (lambda: fa.SieveTable([1e-3, 2e-3, 4e-3], [0.5, 0.6]), r"mass_fractions = .*sum 1\.1.*sum.*1 within 1e-6"),
        (lambda: fa.SieveTable([1e-3, 2e-3, 4e-3], [50, 50]), r"percentages: divide by 100"),
        (lambda: fa.SieveTable([0.0, 2e-3, 4e-3], [0.5, 0.5]), r"sizes\[0\] = 0\.0 .*> 0"),
        (lambda: fa.SieveTable([1e-3, 4e-3, 2e-3], [0.5, 0.5]), r"sizes\[2\] = 0\.002 .*increasing"),
        (lambda: fa.SieveTable([1e-3, 2e-3], [-0.5]), r"mass_fractions\[0\] = -0\.5"),
        (lambda: fa.SieveTable([1e-3, 2e-3, 4e-3], [0.5, 0.5], spread="cubic"), r"spread = 'cubic'.*LOG_UNIFORM"),
        (lambda: fa.Box((0, 0, 0), (1, -1, 1)), r"hi = \(1, -1, 1\).*> lo"),
        (lambda: fa.Cylinder((0, 0, 0), (0, 0, 0), 1.0, 1.0), r"axis = \(0, 0, 0\).*non-zero"),
        (lambda: fa.Cylinder((0, 0, 0), (0, 0, 1), -1.0, 1.0), r"radius = -1\.0"),
        (lambda: fa.Cone((0, 0, 0), (0, 0, 1), 0.0, 0.0, 1.0), r"top_radius = 0\.0"),
        (lambda: fa.Box((0, 0, 0), (1, 1, 1)).inset(0.6), r"margin = 0\.6 .*\[0, 0\.5\)"),
        (
            lambda: fa.fill_region(fa.Box((0, 0, 0), (1, 1, 1)), fa.FixedSize(0.1), count=5, mass=1.0),
            r"count/mass = \(5, 1\.0\).*exactly one",
        ),
        (lambda: fa.fill_region(fa.Box((0, 0, 0), (1, 1, 1)), fa.FixedSize(0.1), mass=1.0), r"density = None"),
        (lambda: fa.fill_region(fa.Box((0, 0, 0), (1, 1, 1)), fa.FixedSize(0.6), count=1), r"bounding radius 0\.6 m"),
        (lambda: fa.fill_region(fa.Box((0, 0, 0), (1, 1, 1)), fa.FixedSize(0.1), count=-3), r"count = -3 .*>= 0"),
        (lambda: fa.DynamicFactory(fa.Box((0, 0, 0), (1, 1, 1)), fa.FixedSize(0.1), count=5), r"rate/mass_rate"),
        (
            lambda: fa.DynamicFactory(fa.Box((0, 0, 0), (1, 1, 1)), fa.FixedSize(0.1), rate=-2.0, count=5),
            r"rate = -2\.0 .*> 0",
        ),
        (
            lambda: fa.DynamicFactory(fa.Box((0, 0, 0), (1, 1, 1)), fa.FixedSize(0.1), rate=2.0, count=5, interval=0.0),
            r"interval = 0\.0",
        ),
    ],
)
def test_errors_name_field_and_value(build, pattern):
    """Bad input raises ValueError naming the field, the value and what is allowed."""
    with pytest.raises(ValueError, match=pattern):
        build()
