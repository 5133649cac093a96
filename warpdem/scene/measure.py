"""Post-processing of DEM results: angle of repose, die-press curves, wall impacts, settling.

Pure NumPy/SciPy (no Warp): every function takes plain arrays copied off the device, so results from
any run, saved file or synthetic test pile can be measured the same way. SI units throughout
(m, N, J, s); angles are returned in degrees.

Pile conventions: ``x`` are sphere centres [m], shape (n, 3), ``r`` radii [m], shape (n,); z is up,
the pile stands on the base plane z = ``base_z`` and its axis is the vertical line through
``center = (cx, cy)``. ``center=None`` estimates the axis as the mean xy of the highest 5 % of the
spheres (by the height of their tops).

Angle-of-repose methods (after the seed papers):

* :func:`angle_surface_fit`: line fits of the highest sphere tops per radial bin in azimuthal sectors
  (seed 000 averages front/rear/left/right flank angles; any number of sectors is allowed here).
* :func:`angle_cone`: the cone formula atan(2h/d) (seed 002).
* :func:`angle_image`: the photographic method (silhouette -> binary image -> top boundary -> line
  fit per flank) done with orthographic projections instead of photos.

Rotating drum (:func:`drum_surface` per frame, :func:`drum_metrics` over frames): the free surface of the bed
in the drum's cross-section, its dynamic angle of repose and the surface-fluctuation index.

:func:`synthetic_cone` builds piles of known slope to check them.
"""

from __future__ import annotations

import functools
import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from warpdem.engine.checks import fail, finite_number
from warpdem.errors import InputError

from .export import save_figure

__all__ = [
    "SettleMonitor",
    "angle_cone",
    "angle_image",
    "angle_surface_fit",
    "BoxRegion",
    "CylinderRegion",
    "beverloo_band",
    "beverloo_rate",
    "discharge_rate",
    "drum_metrics",
    "drum_section",
    "drum_surface",
    "hopper_angle_factor",
    "impact_summary",
    "packing_core",
    "packing_fraction",
    "plot_angles",
    "plot_drum",
    "plot_press",
    "press_curve",
    "press_summary",
    "press_unload",
    "silhouette",
    "synthetic_cone",
]

# A radial bin must be wide enough to hold at least one sphere of the outermost layer in every sector;
# otherwise its highest top comes from a buried sphere and drags the fitted line down unevenly.
QUASI_STATIC_INERTIAL_NUMBER = 1.0e-3
"""Inertial number I = (shear rate) d / sqrt(p / rho) below which granular flow is quasi-static (GDR MiDi 2004): a
press or shear test run faster than this measures inertia as well as the bed."""

MIN_BIN_DIAMETERS = 2.5
# Spheres whose centre is this many (largest) radii or less above the base form the bottom layer.
BASE_LAYER_RADII = 2.5
# Percentile of the base radius: ignores a few spheres that rolled away from the toe.
BASE_PERCENTILE = 98.0
# Fraction of the spheres (highest tops) whose mean xy estimates the pile axis when center=None.
APEX_FRACTION = 0.05
# Pairs (sphere, image column) rasterised per chunk: bounds the temporary memory of angle_image.
_RASTER_CHUNK = 1 << 21
# (radial, along-arc) offsets of the cell grids of angle_surface_fit, in cells.
_GRID_SHIFTS = ((0.0, 0.0), (0.5, 0.0), (0.0, 0.5), (0.5, 0.5))
# Turn of the synthetic_cone lattice [rad] against the x axis (see there).
_LATTICE_TURN = math.atan(1.0 / ((1.0 + math.sqrt(5.0)) / 2.0) ** 2)


# --------------------------------------------------------------------------------------------------
# input checks
# --------------------------------------------------------------------------------------------------


def _bad(name: str, value, allowed: str):
    fail("", name, value, allowed)


def _int_at_least(name: str, value, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < low:
        _bad(name, value, f"an integer >= {low}")
    return int(value)


def _positive(name: str, value, unit: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not (math.isfinite(value) and value > 0):
        _bad(name, value, f"a finite number > 0 {unit}".rstrip())
    return float(value)


def _finite_number(name: str, value, unit: str) -> float:
    return finite_number("", name, value, f"a finite number {unit}".rstrip())


def _spheres(x, r) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(x, dtype=float)
    r = np.asarray(r, dtype=float)
    if x.ndim != 2 or x.shape[1] != 3 or x.shape[0] == 0:
        _bad("x", x, "sphere centres [m] of shape (n, 3) with n >= 1")
    if r.shape != (x.shape[0],):
        _bad("r", r, f"radii [m] of shape ({x.shape[0]},), one per row of x")
    if not np.all(np.isfinite(x)):
        _bad("x", x, "finite coordinates (found NaN or inf)")
    if not np.all(np.isfinite(r) & (r > 0)):
        _bad("r", r, "finite radii > 0 m")
    return x, r


def _zones(inner, outer) -> tuple[float, float]:
    inner = _finite_number("inner", inner, "")
    outer = _finite_number("outer", outer, "")
    if not 0 <= inner < 1:
        _bad("inner", inner, "a fraction of the pile extent in [0, 1)")
    if not inner < outer <= 1:
        _bad("outer", outer, f"a fraction of the pile extent in (inner = {inner}, 1]")
    return inner, outer


def _axis(x: np.ndarray, r: np.ndarray, center) -> tuple[float, float]:
    """The pile axis (cx, cy) [m]: as given, or the mean xy of the highest spheres for center=None."""
    if center is None:
        top = x[:, 2] + r
        k = max(1, int(math.ceil(APEX_FRACTION * len(top))))
        idx = np.argpartition(-top, k - 1)[:k]
        return float(x[idx, 0].mean()), float(x[idx, 1].mean())
    try:
        cx, cy = (float(c) for c in center)
    except (TypeError, ValueError):
        _bad("center", center, "(cx, cy) in m, or None to estimate the axis from the apex")
    if not (math.isfinite(cx) and math.isfinite(cy)):
        _bad("center", center, "finite (cx, cy) in m, or None")
    return cx, cy


def _base_layer(x: np.ndarray, r: np.ndarray, base_z: float) -> np.ndarray:
    """Mask of the spheres touching or near the base plane."""
    top = x[:, 2] + r
    if top.max() <= base_z:
        _bad("base_z", base_z, f"a base plane under the pile (the highest sphere top is at z = {top.max():.6g} m)")
    # spheres wholly under the base fell through it: not part of the pile
    near = (top > base_z) & ((x[:, 2] - base_z) < BASE_LAYER_RADII * r.max())
    if not near.any():
        _bad(
            "x",
            x,
            f"a pile with spheres on the base plane z = base_z = {base_z} m "
            f"(none has its centre within {BASE_LAYER_RADII} radii of it)",
        )
    return near


# --------------------------------------------------------------------------------------------------
# angle of repose
# --------------------------------------------------------------------------------------------------


PILE_GAP = 0.1
"""How near two spheres' surfaces come [-, in units of r_i + r_j] to count as touching in a pile (``pile_spheres``):
a settled pile's contacts overlap, and the margin keeps a contact that has just opened."""


def pile_spheres(x, r, base_z: float = 0.0, gap: float = PILE_GAP, apart: float = 1.0) -> np.ndarray:
    """Mask of the spheres that belong to the pile: connected to the base through a chain of touching spheres,
    and not lying apart from the pile's main body.

    Two spheres touch when their centres are closer than (1 + ``gap``) (r_i + r_j); the chain starts at the
    spheres within ``gap`` r of the base plane ``base_z`` [m]. Grains stuck to a lifted cylinder, carried by
    a wall or still in flight are not part of the pile and would read as a tall column. Of what stands on the
    base, the pile is the largest cluster of spheres whose surfaces come within ``apart`` times (r_i + r_j)
    of each other (one diameter, for ``apart`` = 1): grains that bounced or rolled off and lie apart on the
    plate are left out (``apart`` = 0: none is). Every angle method takes the pile's foot from its outermost
    grains, and a few strays 0.2 m out turned a cohesive mound into an 8 deg "pile" (seed 001's wet feed); a
    sparse toe, or a small pile whose grains do not all touch, stays whole.

    Args:
        x: sphere centres [m], shape (n, 3); r: radii [m], shape (n,).
        base_z: base plane [m]; gap: touching tolerance [-], >= 0; apart: the largest surface gap within the
            pile, in units of r_i + r_j [-], >= gap, or 0 for no limit.
    Returns:
        bool mask, shape (n,).
    """
    x, r = _spheres(x, r)
    gap = _finite_number("gap", gap, "[-]")
    apart = _finite_number("apart", apart, "[-]")
    if not (apart == 0 or apart >= gap):
        _bad("apart", apart, f"0 (no limit) or a surface gap in units of r_i + r_j, >= gap = {gap}")
    label = _touching_groups(x, r, gap)
    grounded = x[:, 2] - r <= base_z + gap * r
    on = np.isin(label, np.unique(label[grounded]))
    if apart == 0 or not on.any():
        return on
    # spheres that touch are near too, so only a pair with a sphere outside the largest touching group can join
    # groups. Asking every sphere for its neighbours within the wide gap found hundreds of sub-spheres of nearby
    # pellets for each of a seed 000 pile's 211,500 and took 8 times as long (benchmarks/pile_select.py)
    idx = np.flatnonzero(on)
    rest = idx[label[idx] != np.argmax(np.bincount(label[idx]))]
    i, j, _ = _near_pairs_from(x, r, rest, idx, apart)
    # the touching groups joined by those pairs: a group's spheres stay together
    cluster = _components(int(label.max()) + 1, label[i], label[j])[label]
    return on & (cluster == np.argmax(np.bincount(cluster[on], minlength=len(r))))


def _near_pairs(x: np.ndarray, r: np.ndarray, gap: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The index pairs (i, j) of spheres whose centres are closer than (1 + ``gap``) (r_i + r_j), and each pair's
    centre distance over r_i + r_j (all of shape (k,))."""
    from scipy.spatial import cKDTree

    pairs = cKDTree(x).query_pairs(_reach(r, gap), output_type="ndarray").reshape(-1, 2)
    i, j = pairs[:, 0], pairs[:, 1]
    return _closer_than(r, i, j, np.linalg.norm(x[i] - x[j], axis=1), gap)


def _near_pairs_from(
    x: np.ndarray, r: np.ndarray, some: np.ndarray, among: np.ndarray, gap: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pairs (i, j) with i in the sphere indices ``some`` and j in ``among`` whose centres are closer than
    (1 + ``gap``) (r_i + r_j), and each pair's centre distance over r_i + r_j (all of shape (k,))."""
    from scipy.spatial import cKDTree

    if not len(some) or not len(among):
        return _closer_than(r, some[:0], among[:0], np.zeros(0), gap)
    d = cKDTree(x[some]).sparse_distance_matrix(cKDTree(x[among]), _reach(r, gap), output_type="ndarray")
    return _closer_than(r, some[d["i"]], among[d["j"]], d["v"], gap)


def _reach(r: np.ndarray, gap: float) -> float:
    """The centre distance [m] within which any two of the spheres of radii ``r`` may be closer than (1 + ``gap``)
    (r_i + r_j): the search radius of the neighbour queries."""
    return 2.0 * (1.0 + gap) * float(r.max())


def _closer_than(r, i, j, dist, gap) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Of the pairs (i, j) with centre distances ``dist`` [m], those closer than (1 + ``gap``) (r_i + r_j), and
    their distance over r_i + r_j."""
    ratio = dist / (r[i] + r[j])
    keep = ratio < 1.0 + gap
    return i[keep].astype(np.int64, copy=False), j[keep].astype(np.int64, copy=False), ratio[keep]


def _components(n: int, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Label (n,) of each of n nodes' connected component over the edges (i, j)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    graph = coo_matrix((np.ones(len(i)), (i, j)), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def _touching_groups(x: np.ndarray, r: np.ndarray, gap: float) -> np.ndarray:
    """Label (n,) of each sphere's group of spheres connected by contacts: two spheres touch when their
    centres are closer than (1 + ``gap``) (r_i + r_j)."""
    i, j, _ = _near_pairs(x, r, gap)
    return _components(len(r), i, j)


def pile_centroid(x, r) -> np.ndarray:
    """The pile's centre of mass (x, y) [m], shape (2,): spheres ``x`` (n, 3) [m], ``r`` (n,) [m] of one density,
    weighted by their volumes."""
    x, r = _spheres(x, r)
    w = r**3
    return (w @ x[:, :2]) / w.sum()


def pile_offset(x, r, center=(0.0, 0.0)) -> float:
    """How far [m] the pile's centre of mass (:func:`pile_centroid`) lies from its axis ``center`` (cx, cy) [m],
    horizontally: spheres ``x`` (n, 3) [m], ``r`` (n,) [m]. A pile poured or lifted on its axis grows around it;
    one that stands far off it moved as a body after it was built (a cohesive column that fell over), and the
    angle methods, which read slopes about the axis, read its side."""
    x, r = _spheres(x, r)
    cx, cy = _axis(x, r, center)
    gx, gy = pile_centroid(x, r)
    return float(math.hypot(gx - cx, gy - cy))


def angle_surface_fit(
    x,
    r,
    slices: int = 8,
    bins: int = 12,
    base_z: float = 0.0,
    center=(0.0, 0.0),
    inner: float = 0.2,
    outer: float = 0.8,
) -> dict:
    """Angle of repose [deg] by straight-line fits of the pile surface in azimuthal sectors.

    The pile is cut into ``slices`` equal sectors around its axis. In each sector the radial range
    0..extent is divided into bins, and each bin along the arc into cells as long as the bin is wide;
    the highest sphere top (z + r) of each cell is a surface point, taken at that sphere's own
    horizontal distance rho from the axis. Bins whose centre lies in the apex zone
    (< ``inner`` * extent) or the toe zone (> ``outer`` * extent) are dropped, a line z(rho) is
    fitted to the points of the sector and the sector angle is atan(-slope). The cells of three more
    grids, shifted by half a cell radially and/or along the arc, add points (each sphere once).

    Why this is unbiased: the tops of the surface spheres lie on a surface parallel to the pile
    surface, so the slope is right as long as every cell holds a surface sphere and the roughness
    lifts the highest top of every cell alike. Hence (1) cells are at least 2.5 mean sphere diameters
    wide (fewer bins than ``bins`` when needed); (2) all cells have the same area, so the same number
    of candidates: the maximum of more rough tops sits higher, and whole sector bins, whose arc grows
    with rho, would flatten the line; (3) a point sits at its sphere's rho, not at the bin centre
    (the highest top of a bin is near its inner edge).

    Args:
        x: sphere centres [m], shape (n, 3).
        r: sphere radii [m], shape (n,).
        slices: number of azimuthal sectors, >= 2.
        bins: requested number of radial bins over 0..extent, >= 3 (widened if narrower than 2.5
            mean diameters).
        base_z: height of the base plane [m].
        center: pile axis (cx, cy) [m], or None to estimate it from the highest spheres.
        inner, outer: apex and toe limits as fractions of the extent, 0 <= inner < outer <= 1.

    The extent [m] is the 98th percentile of rho + r over the spheres of the bottom layer (centre
    less than 2.5 largest radii above the base).

    Returns:
        dict with ``mean_deg`` (mean over the sectors used), ``sd_deg`` (sample SD, ddof=1),
        ``per_slice_deg`` (list, one angle per sector used), ``slices`` (number of sectors used),
        ``extent_m``, ``bin_width_m``, ``center`` (the axis used, m), ``lines`` (per sector used: its middle
        ``azimuth_deg`` as atan2(dy, dx) gives it, and the fitted sphere tops z - base_z = ``intercept_m`` +
        ``slope`` * rho) and ``fit_range_m`` (the rho range the points came from, m).

    Raises:
        ValueError: bad arguments, or fewer than 2 sectors with 3 or more surface points (the pile is
        too small for the bin width, or too few spheres).
    """
    x, r = _spheres(x, r)
    slices = _int_at_least("slices", slices, 2)
    bins = _int_at_least("bins", bins, 3)
    base_z = _finite_number("base_z", base_z, "m")
    inner, outer = _zones(inner, outer)
    cx, cy = _axis(x, r, center)

    dx, dy = x[:, 0] - cx, x[:, 1] - cy
    rho = np.hypot(dx, dy)
    top = x[:, 2] + r - base_z
    base = _base_layer(x, r, base_z)
    extent = float(np.percentile(rho[base] + r[base], BASE_PERCENTILE))

    width = max(extent / bins, MIN_BIN_DIAMETERS * 2.0 * float(r.mean()))
    width = extent / max(1, int(extent // width))

    turn = (np.arctan2(dy, dx) + math.pi) / (2 * math.pi) * slices  # sector units, 0..slices
    sector = np.minimum(turn.astype(int), slices - 1)
    # Cell maxima of a grid and of grids shifted by half a cell: about 2-4 times more surface points
    # for the same cell size, so less scatter; a sphere found twice counts once.
    picks = [
        _cell_maxima(rho, turn - sector, sector, top, width, extent, inner, outer, slices, shift)
        for shift in _GRID_SHIFTS
    ]
    best = np.unique(np.concatenate(picks))
    best_sector = sector[best]

    angles, lines = [], []
    for s in range(slices):
        pick = best[best_sector == s]
        if len(pick) < 3:
            continue
        slope, intercept = np.polyfit(rho[pick], top[pick], 1)
        angles.append(math.degrees(math.atan(-slope)))
        azimuth = -180.0 + (s + 0.5) * 360.0 / slices  # the sector's middle, as atan2 measures it
        lines.append({"azimuth_deg": azimuth, "slope": float(slope), "intercept_m": float(intercept)})
    if len(angles) < 2:
        raise InputError(
            f"angle_surface_fit: only {len(angles)} of slices = {slices} sectors have >= 3 surface points "
            f"between inner = {inner} and outer = {outer} of the extent {extent:.4g} m with bins "
            f"{width:.4g} m wide (>= {MIN_BIN_DIAMETERS} sphere diameters); the pile is too small or too "
            f"sparse: need >= 2 sectors with >= 3 points (use fewer slices or a larger pile)"
        )
    a = np.array(angles)
    return {
        "mean_deg": float(a.mean()),
        "sd_deg": float(a.std(ddof=1)),
        "per_slice_deg": a.tolist(),
        "slices": len(a),
        "extent_m": extent,
        "bin_width_m": width,
        "center": (cx, cy),
        "lines": lines,
        "fit_range_m": (inner * extent, outer * extent),
    }


def _cell_maxima(rho, frac, sector, top, width, extent, inner, outer, slices, shift) -> np.ndarray:
    """Indices of the highest top in each cell of the grid of angle_surface_fit.

    Radial bins of ``width`` start at ``shift[0] * width``; only bins whose centre lies between
    ``inner`` and ``outer`` of ``extent`` are used. ``frac`` is each sphere's position across its
    sector (0..1).
    """
    # The highest of N rough tops sits higher the larger N, and a bin's arc (so N) grows with rho:
    # whole sector bins would lift the outer points and flatten the line. Each bin is therefore cut
    # along the arc into cells exactly as long as the bin is wide (equal areas, so the same N
    # everywhere), centred in the sector; the leftover ends of the arc are not used. A bin whose arc
    # is shorter than its width is one cell.
    rb = np.floor(rho / width - shift[0]).astype(np.int64)
    centre = (rb + shift[0] + 0.5) * width
    idx = np.flatnonzero((rb >= 0) & (centre > 0) & (centre >= inner * extent) & (centre <= outer * extent))
    rb, centre = rb[idx], centre[idx]
    arc = centre * 2 * math.pi / slices
    full = np.maximum(1, np.floor(arc / width)).astype(np.int64)
    cell_len = np.minimum(width, arc)
    start = 0.5 * (arc - full * cell_len) + shift[1] * cell_len
    # the shifted grid loses the cell that would stick out of the centred span
    cells = full - (1 if shift[1] else 0)
    sub = np.floor((frac[idx] * arc - start) / cell_len).astype(np.int64)
    ok = (sub >= 0) & (sub < cells)
    idx, rb, sub, cells = idx[ok], rb[ok], sub[ok], cells[ok]
    if idx.size == 0:
        return idx
    # one integer key per (sector, bin, cell); sort by key, then top, and keep the last of each key
    nb = int(rb.max()) + 1
    nc = int(cells.max()) + 1
    key = (sector[idx] * nb + rb) * nc + sub
    order = np.lexsort((top[idx], key))
    k = key[order]
    return idx[order[np.flatnonzero(np.r_[k[1:] != k[:-1], True])]]


def flank_lines(fit: dict, base_z: float = 0.0, axis: str = "y") -> list[dict]:
    """The pile's two flanks as a side view along ``axis`` ("y": x to the right, "x": y to the right) sees them,
    from :func:`angle_surface_fit`'s per-sector lines: the sectors facing each way (middle within 90 deg of the
    view plane's +h or -h direction), weighted by how squarely they face it (the cosine), over the rho range the
    fit used. The protractor of a gallery picture: what was measured, drawn where it was measured.

    Args:
        fit: :func:`angle_surface_fit`'s result.
        base_z: height of the base plane [m] (as given to the fit).
        axis: "y" or "x".

    Returns:
        list (one per side with a facing sector, "right" then "left") of dicts with ``side``, ``angle_deg`` (the
        weighted line's) and ``points`` ((h0, z0), (h1, z1)) [m] in the view plane, apex end first.
    """
    if axis not in ("x", "y"):
        raise InputError(f'flank_lines: axis = {axis!r} is not allowed; expected "x" or "y"')
    cx, cy = fit["center"]
    h0 = cx if axis == "y" else cy
    facing = 0.0 if axis == "y" else 90.0  # the azimuth of +h
    lo, hi = fit["fit_range_m"]
    out = []
    for side, sign in (("right", 1.0), ("left", -1.0)):
        w, slope, icpt = [], [], []
        for line in fit["lines"]:
            c = sign * math.cos(math.radians(line["azimuth_deg"] - facing))
            if c > 1e-9:
                w.append(c)
                slope.append(line["slope"])
                icpt.append(line["intercept_m"])
        if not w:
            continue
        b, a = float(np.average(slope, weights=w)), float(np.average(icpt, weights=w))
        pts = tuple((h0 + sign * rho, base_z + a + b * rho) for rho in (lo, hi))
        out.append({"side": side, "angle_deg": math.degrees(math.atan(-b)), "points": pts})
    return out


def angle_cone(x, r, base_z: float = 0.0, center=(0.0, 0.0), toe_correction: bool = False) -> float:
    """Angle of repose [deg] from the cone formula atan(2h/d) of seed 002.

    h [m] is the highest sphere top above the base; d [m] is twice the 98th percentile of rho + r over
    the bottom layer (centres less than 2.5 largest radii above the base), rho being the horizontal
    distance from the axis.

    Known bias (why the formula reads steeper than the flanks of a sphere pile): the flank line
    through the sphere tops reaches the height of one diameter at the outermost bottom sphere, and
    no sphere can sit further out under it, so the base is short by about 2r/tan(angle) - r. For
    r / base radius = 1/30 this is +3 deg at 20 deg, +2 deg at 30 deg, +1 deg at 45 deg, and it
    shrinks in proportion to r / base radius.

    Args:
        x: sphere centres [m], shape (n, 3).
        r: sphere radii [m], shape (n,).
        base_z: height of the base plane [m].
        center: pile axis (cx, cy) [m], or None to estimate it from the highest spheres.
        toe_correction: False (default) is the seed formula above. True uses the cone through the
            sphere tops instead: atan((h - 2 r_b) / rho_b) with rho_b the 98th percentile of the
            bottom-layer centres' rho and r_b their mean radius (the top of the bottom layer is the
            foot of the flank line), which removes the toe bias.

    Returns:
        the angle in degrees.
    """
    x, r = _spheres(x, r)
    base_z = _finite_number("base_z", base_z, "m")
    cx, cy = _axis(x, r, center)
    if not isinstance(toe_correction, (bool, np.bool_)):
        _bad("toe_correction", toe_correction, "True or False")
    base = _base_layer(x, r, base_z)
    h = float((x[:, 2] + r).max()) - base_z
    rho = np.hypot(x[base, 0] - cx, x[base, 1] - cy)
    if toe_correction:
        rb = float(np.percentile(rho, BASE_PERCENTILE))
        hb = h - 2.0 * float(r[base].mean())
        if rb <= 0 or hb <= 0:
            _bad("x", x, "a pile wider and higher than its bottom layer for toe_correction=True")
        return math.degrees(math.atan2(hb, rb))
    d = 2.0 * float(np.percentile(rho + r[base], BASE_PERCENTILE))
    return math.degrees(math.atan2(2.0 * h, d))


def silhouette(
    x, r, azimuth_deg: float = 0.0, pixel: float | None = None, base_z: float = 0.0, center=(0.0, 0.0)
) -> dict:
    """Binary side view of a sphere pile: every sphere projected orthographically as a filled disc.

    The camera looks horizontally at the axis from azimuth ``azimuth_deg`` (0 = from +x, 90 = from +y).
    The image coordinate u [m] runs along (-sin az, cos az, 0) from the axis (left to right in the
    picture), rows run top to bottom. A pixel is filled when its centre lies inside a disc. Column
    centres sit at whole multiples of ``pixel`` from the axis, so the axis is one column.

    Args:
        x: sphere centres [m], shape (n, 3).
        r: sphere radii [m], shape (n,).
        azimuth_deg: viewing direction [deg].
        pixel: pixel size [m]; None = smallest radius / 4.
        base_z: base plane [m]; the image reaches down to it (or to the lowest sphere bottom).
        center: pile axis (cx, cy) [m], or None to estimate it.

    Returns:
        dict with ``image`` (bool, shape (rows, cols), row 0 at the top), ``pixel_m``, ``u0_m`` (u of
        column 0's centre), ``z0_m`` (absolute z of row 0's centre), ``axis_column`` (column of u = 0)
        and ``center``.
    """
    x, r = _spheres(x, r)
    az = _finite_number("azimuth_deg", azimuth_deg, "deg")
    base_z = _finite_number("base_z", base_z, "m")
    p = float(r.min()) / 4.0 if pixel is None else _positive("pixel", pixel, "m")
    cx, cy = _axis(x, r, center)
    t = math.radians(az)
    u = -(x[:, 0] - cx) * math.sin(t) + (x[:, 1] - cy) * math.cos(t)
    return _raster(u, x[:, 2], r, p, base_z) | {"center": (cx, cy)}


def _raster(u: np.ndarray, z: np.ndarray, r: np.ndarray, p: float, base_z: float) -> dict:
    """Union of discs (u, z, r) on a grid of pixel p, by per-column run-length fills.

    Each disc covers, in each column it spans, one run of rows; the runs go into a difference image
    (+1 at the first row, -1 after the last) whose cumulative sum down the columns is > 0 exactly on
    the filled pixels. That is O(spheres x columns per sphere) rather than O(pixels per sphere).
    """
    c_lo = np.floor((u - r) / p).astype(np.int64)
    c_hi = np.ceil((u + r) / p).astype(np.int64)
    axis_col = int(max(0, -c_lo.min())) + 1
    ncols = int(max(c_hi.max(), 0)) + axis_col + 2
    z_top = float((z + r).max()) + p
    z_bot = min(base_z, float((z - r).min()))
    nrows = int(math.ceil((z_top - z_bot) / p)) + 1
    z0 = z_top - 0.5 * p  # centre of row 0

    span = int((c_hi - c_lo).max()) + 1
    offs = np.arange(span)
    diff = np.zeros((nrows + 1) * ncols, dtype=np.int64)
    chunk = max(1, _RASTER_CHUNK // span)
    for i in range(0, len(u), chunk):
        sl = slice(i, i + chunk)
        cols = c_lo[sl, None] + offs[None, :]
        du = cols * p - u[sl, None]
        h2 = r[sl, None] ** 2 - du * du
        ok = h2 > 0
        hh = np.sqrt(np.where(ok, h2, 0.0))
        zs = z[sl, None]
        # rows whose centre z0 - j p lies in [z - hh, z + hh]
        j_lo = np.ceil((z0 - (zs + hh)) / p - 1e-9).astype(np.int64)
        j_hi = np.floor((z0 - (zs - hh)) / p + 1e-9).astype(np.int64)
        j_lo = np.maximum(j_lo, 0)
        j_hi = np.minimum(j_hi, nrows - 1)
        ok &= j_lo <= j_hi
        c = (cols + axis_col)[ok]
        diff += np.bincount(j_lo[ok] * ncols + c, minlength=diff.size)
        diff -= np.bincount((j_hi[ok] + 1) * ncols + c, minlength=diff.size)
    image = np.cumsum(diff.reshape(nrows + 1, ncols), axis=0)[:nrows] > 0
    return {"image": image, "pixel_m": p, "u0_m": -axis_col * p, "z0_m": z0, "axis_column": axis_col}


def _top_boundary(image: np.ndarray) -> np.ndarray:
    """Row of the top-most filled pixel in each column, -1 for empty columns."""
    filled = image.any(axis=0)
    return np.where(filled, np.argmax(image, axis=0), -1)


def angle_image(
    x,
    r,
    views: int = 4,
    pixel: float | None = None,
    base_z: float = 0.0,
    center=(0.0, 0.0),
    inner: float = 0.2,
    outer: float = 0.8,
    return_images: bool = False,
) -> dict:
    """Angle of repose [deg] by the seeds' image method on orthographic side views of the pile.

    For each of ``views`` viewing directions evenly spaced in azimuth (4 = front, right, rear, left)
    the spheres are drawn as filled discs into a binary image (the silhouette, see :func:`silhouette`),
    the boundary is the top-most filled pixel of every column, and it is split at the axis column
    into a left and a right flank. On each flank the columns between ``inner`` and ``outer`` of the
    flank width (axis to outermost filled column) are kept, a line z(u) is fitted and the flank angle
    is atan(|slope|).

    Orthographic views from opposite sides are mirror images, so with an even number of views each
    silhouette is measured twice (as in photographing front and rear); only views/2 are independent.

    Args:
        x: sphere centres [m], shape (n, 3).
        r: sphere radii [m], shape (n,).
        views: number of viewing directions, >= 1.
        pixel: pixel size [m]; None = smallest radius / 4.
        base_z: base plane [m].
        center: pile axis (cx, cy) [m], or None to estimate it from the highest spheres.
        inner, outer: kept part of each flank as fractions of its width, 0 <= inner < outer <= 1.
        return_images: also return the binary images.

    Returns:
        dict with ``mean_deg``, ``sd_deg`` (ddof=1), ``per_side_deg`` (list of 2 * views angles: left,
        right of view 0, then view 1, ...), ``views``, ``pixel_m``, ``center``; with
        ``return_images=True`` also ``images`` (list of bool arrays, shape (rows, cols), row 0 at the
        top) and ``geometry`` (per view: ``u0_m``, ``z0_m``, ``axis_column``, see :func:`silhouette`).

    Raises:
        ValueError: bad arguments, or a flank with fewer than 3 columns in the fit zone.
    """
    x, r = _spheres(x, r)
    views = _int_at_least("views", views, 1)
    base_z = _finite_number("base_z", base_z, "m")
    inner, outer = _zones(inner, outer)
    p = float(r.min()) / 4.0 if pixel is None else _positive("pixel", pixel, "m")
    cx, cy = _axis(x, r, center)
    dx, dy, z = x[:, 0] - cx, x[:, 1] - cy, x[:, 2]

    angles, images, geometry = [], [], []
    for k in range(views):
        t = 2.0 * math.pi * k / views
        u = -dx * math.sin(t) + dy * math.cos(t)
        sil = _raster(u, z, r, p, base_z)
        img = sil["image"]
        rows = _top_boundary(img)
        cols = np.flatnonzero(rows >= 0)
        height = sil["z0_m"] - rows[cols] * p
        uc = (cols - sil["axis_column"]) * p
        for side in (-1.0, 1.0):
            on = side * uc > 0
            if not on.any():
                raise InputError(
                    f"angle_image: view {k} has no silhouette on the "
                    f"{'left' if side < 0 else 'right'} of the axis center = {(cx, cy)}; "
                    f"expected a pile around the axis"
                )
            w = float((side * uc[on]).max())
            keep = on & (side * uc >= inner * w) & (side * uc <= outer * w)
            if keep.sum() < 3:
                raise InputError(
                    f"angle_image: view {k}, {'left' if side < 0 else 'right'} flank has "
                    f"{int(keep.sum())} columns between inner = {inner} and outer = {outer} of its "
                    f"width {w:.4g} m at pixel = {p:.4g} m; expected >= 3 (use a smaller pixel)"
                )
            slope = np.polyfit(uc[keep], height[keep], 1)[0]
            angles.append(math.degrees(math.atan(abs(slope))))
        if return_images:
            images.append(img)
            geometry.append({"u0_m": sil["u0_m"], "z0_m": sil["z0_m"], "axis_column": sil["axis_column"]})
    a = np.array(angles)
    out = {
        "mean_deg": float(a.mean()),
        "sd_deg": float(a.std(ddof=1)),
        "per_side_deg": a.tolist(),
        "views": views,
        "pixel_m": p,
        "center": (cx, cy),
    }
    if return_images:
        out["images"] = images
        out["geometry"] = geometry
    return out


def synthetic_cone(
    angle_deg: float,
    base_radius: float,
    sphere_radius: float,
    seed: int = 0,
    polydispersity: float = 0.0,
    base_z: float = 0.0,
    center=(0.0, 0.0),
):
    """A sphere pile of known slope, for testing the angle-of-repose measures.

    The cone has slope ``angle_deg``, base radius ``base_radius`` [m] and apex height
    base_radius * tan(angle) above ``base_z``, axis through ``center``. Spheres sit on a square
    lattice of columns (spacing 2.2 largest radii, one column on the axis, turned by 20.9 deg about
    it so that no lattice row lines up with a side view, jittered by up to 0.1 largest radius along
    each lattice axis and in z, so no two spheres overlap), stacked from the base (the bottom layer touches it) while their tops
    stay below the cone. The top sphere of every column is then lifted so that its top lies
    0..0.3 r below the cone surface: the outermost layer follows the surface closely, as the
    surface spheres of a real pile do. Each sphere's top is below the cone surface above its centre.

    Near the toe no sphere fits under a surface lower than one diameter, so the pile ends at
    rho = base_radius - 2r/tan(angle) (the flank line through the tops still meets the base at
    base_radius).

    Args:
        angle_deg: cone slope [deg], in (0, 90).
        base_radius: cone base radius [m].
        sphere_radius: mean sphere radius r [m].
        seed: seed of ``np.random.default_rng``.
        polydispersity: radii uniform in r * (1 +- polydispersity), in [0, 1).
        base_z: base plane [m].
        center: cone axis (cx, cy) [m].

    Returns:
        (x, r): centres [m], shape (n, 3), and radii [m], shape (n,).
    """
    a = _finite_number("angle_deg", angle_deg, "deg")
    if not 0 < a < 90:
        _bad("angle_deg", angle_deg, "a slope in (0, 90) deg")
    big_r = _positive("base_radius", base_radius, "m")
    r0 = _positive("sphere_radius", sphere_radius, "m")
    pd = _finite_number("polydispersity", polydispersity, "")
    if not 0 <= pd < 1:
        _bad("polydispersity", polydispersity, "a fraction in [0, 1)")
    base_z = _finite_number("base_z", base_z, "m")
    if center is None:
        _bad("center", center, "(cx, cy) in m")
    cx, cy = _axis(np.zeros((1, 3)), np.ones(1), center)
    tan_a = math.tan(math.radians(a))
    height = big_r * tan_a
    r_max = r0 * (1 + pd)
    if height < 2 * r_max:
        _bad(
            "base_radius",
            base_radius,
            f"a cone at least one largest sphere diameter ({2 * r_max:.4g} m) high; "
            f"base_radius * tan(angle_deg) = {height:.4g} m",
        )
    rng = np.random.default_rng(seed)
    spacing = 2.2 * r_max
    jit = 0.1 * r_max
    n = int(math.ceil(math.sqrt(2.0) * big_r / spacing)) + 1
    i, j = (m.ravel() * spacing for m in np.meshgrid(np.arange(-n, n + 1), np.arange(-n, n + 1), indexing="ij"))
    # jitter along the lattice axes, before turning, keeps neighbouring columns >= 2 r_max apart
    i = i + rng.uniform(-jit, jit, i.size)
    j = j + rng.uniform(-jit, jit, j.size)
    # A lattice row seen end-on puts all its columns at the same image positions, leaving see-through
    # gaps in side views; turned by atan(1/phi^2) (phi the golden ratio) the rows near any view's
    # mid-plane fall at well-spread offsets for views 0, 45, 90, ... deg.
    c, s = math.cos(_LATTICE_TURN), math.sin(_LATTICE_TURN)
    gx, gy = c * i - s * j, s * i + c * j
    inside = np.hypot(gx, gy) <= big_r
    gx, gy = gx[inside], gy[inside]
    surface = height - tan_a * np.hypot(gx, gy)  # cone height above the base over each column
    layers = int(math.ceil(height / spacing)) + 1

    col = np.repeat(np.arange(gx.size), layers)
    k = np.tile(np.arange(layers), gx.size)
    rad = r0 * (1 + pd * rng.uniform(-1.0, 1.0, col.size))
    # bottom layer rests on the base; above it the layers keep >= 2 r_max centre spacing despite jitter
    z = np.where(k == 0, rad, r_max + k * spacing + rng.uniform(-jit, jit, col.size))
    keep = z + rad <= surface[col]
    col, z, rad = col[keep], z[keep], rad[keep]

    # the highest sphere of each column goes up to just under the surface
    top_of_col = np.r_[col[1:] != col[:-1], True]
    lifted = surface[col] - rad - rng.uniform(0.0, 0.3, col.size) * rad
    z = np.where(top_of_col, np.maximum(z, lifted), z)
    x = np.column_stack([gx[col] + cx, gy[col] + cy, z + base_z])
    return x, rad


# --------------------------------------------------------------------------------------------------
# die press
# --------------------------------------------------------------------------------------------------


# --------------------------------------------------------------------------------------------------
# packing fraction and bulk density
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class BoxRegion:
    """An axis-aligned box [m] from ``lo`` to ``hi`` (each (x, y, z)), where a packing is measured."""

    lo: tuple
    hi: tuple

    def __post_init__(self):
        lo = _point3("lo", self.lo)
        hi = _point3("hi", self.hi)
        if not np.all(hi > lo):
            _bad("hi", self.hi, f"a corner above lo = {tuple(lo)} along x, y and z")
        object.__setattr__(self, "lo", tuple(lo))
        object.__setattr__(self, "hi", tuple(hi))

    @property
    def volume(self) -> float:
        """[m^3]"""
        return float(np.prod(np.subtract(self.hi, self.lo)))

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return np.array(self.lo), np.array(self.hi)

    def from_unit(self, u: np.ndarray) -> np.ndarray:
        """Points of the unit cube, shape (n, 3), mapped onto the box uniformly."""
        lo, hi = self.bounds()
        return lo + u * (hi - lo)


@dataclass(frozen=True)
class CylinderRegion:
    """A vertical cylinder [m] of ``radius`` about the axis through ``center`` (x, y), from ``z_low`` to
    ``z_high``, where a packing is measured."""

    center: tuple
    radius: float
    z_low: float
    z_high: float

    def __post_init__(self):
        try:
            cx, cy = (float(c) for c in self.center)
        except (TypeError, ValueError):
            _bad("center", self.center, "(cx, cy) in m")
        if not (math.isfinite(cx) and math.isfinite(cy)):
            _bad("center", self.center, "finite (cx, cy) in m")
        object.__setattr__(self, "center", (cx, cy))
        object.__setattr__(self, "radius", _positive("radius", self.radius, "m"))
        z0 = _finite_number("z_low", self.z_low, "m")
        z1 = _finite_number("z_high", self.z_high, "m")
        if not z1 > z0:
            _bad("z_high", self.z_high, f"a height above z_low = {z0} m")
        object.__setattr__(self, "z_low", z0)
        object.__setattr__(self, "z_high", z1)

    @property
    def volume(self) -> float:
        """[m^3]"""
        return math.pi * self.radius**2 * (self.z_high - self.z_low)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        cx, cy = self.center
        return (
            np.array([cx - self.radius, cy - self.radius, self.z_low]),
            np.array([cx + self.radius, cy + self.radius, self.z_high]),
        )

    def from_unit(self, u: np.ndarray) -> np.ndarray:
        """Points of the unit cube, shape (n, 3), mapped onto the cylinder uniformly (an area-preserving map,
        so low-discrepancy points stay evenly spread)."""
        rho = self.radius * np.sqrt(u[:, 0])
        phi = 2.0 * math.pi * u[:, 1]
        return np.column_stack(
            (
                self.center[0] + rho * np.cos(phi),
                self.center[1] + rho * np.sin(phi),
                self.z_low + u[:, 2] * (self.z_high - self.z_low),
            )
        )


def _point3(name: str, value) -> np.ndarray:
    try:
        a = np.array(value, dtype=float)
    except (TypeError, ValueError):
        _bad(name, value, "(x, y, z) in m")
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        _bad(name, value, "finite (x, y, z) in m")
    return a


@functools.lru_cache(maxsize=4)
def _sobol_cube(m: int, seed: int) -> np.ndarray:
    """2**m scrambled Sobol points in the unit cube, shape (2**m, 3), read-only: the same for every world of a
    launch, and generating them took a third of a packing measurement."""
    from scipy.stats import qmc

    u = qmc.Sobol(d=3, scramble=True, seed=seed).random_base2(m)
    u.flags.writeable = False
    return u


def packing_fraction(x, r, region, density=None, samples_log2: int = 17, seed: int = 0) -> dict:
    """Solid fraction of a packing inside ``region``, and its bulk density.

    The solid is the union of the spheres, so the overlapping spheres of a clump count once (their union
    volume) and polydisperse spheres their own volumes; spheres cut by the region's boundary count only
    their part inside. The region is sampled by 2**``samples_log2`` scrambled Sobol points (scipy.stats.qmc,
    seeded by ``seed``, so repeatable); the fraction is the share of points inside some sphere. Its error
    falls nearly as 1/points for a smooth solid (far below 0.1 % at the default), not as 1/sqrt(points).

    Args:
        x: sphere centres [m], shape (n, 3).
        r: radii [m], shape (n,).
        region: a :class:`BoxRegion` or :class:`CylinderRegion`, e.g. a core away from the walls and the free
            surface (about two particle diameters from each).
        density: solid density of each sphere [kg/m^3], shape (n,) (a clump's spheres share their material's);
            None: no bulk density.
        samples_log2: base-2 logarithm of the number of sample points, 10..24.
        seed: the Sobol scrambling seed.

    Returns:
        dict with ``packing_fraction`` [-], ``bulk_density_kg_m3`` (None without ``density``),
        ``region_volume_m3``, ``solid_volume_m3``, ``samples`` and ``spheres`` (those reaching into the region).
    """
    from scipy.spatial import cKDTree

    x, r = _spheres(x, r)
    if not isinstance(region, (BoxRegion, CylinderRegion)):
        _bad("region", region, "a BoxRegion or CylinderRegion")
    m = _int_at_least("samples_log2", samples_log2, 10)
    if m > 24:
        _bad("samples_log2", samples_log2, "an integer in 10..24")
    rho = None
    if density is not None:
        rho = np.asarray(density, dtype=float)
        if rho.shape != r.shape or not np.all(np.isfinite(rho) & (rho > 0)):
            _bad("density", density, f"finite densities > 0 kg/m^3 of shape {r.shape}, one per sphere")
    points = region.from_unit(_sobol_cube(m, _int_at_least("seed", seed, 0)))
    lo, hi = region.bounds()
    near = np.flatnonzero(np.all((x + r[:, None] > lo) & (x - r[:, None] < hi), axis=1))
    owner = np.full(len(points), -1)
    if near.size:
        hits = cKDTree(points).query_ball_point(x[near], r[near])
        lengths = np.fromiter((len(h) for h in hits), dtype=int, count=len(hits))
        if lengths.sum():
            owner[np.concatenate([np.asarray(h, dtype=int) for h in hits if h])] = np.repeat(near, lengths)
    solid = owner >= 0
    phi = float(solid.mean())
    bulk = None if rho is None else float(rho[owner[solid]].sum() / len(points))
    return {
        "packing_fraction": phi,
        "bulk_density_kg_m3": bulk,
        "region_volume_m3": region.volume,
        "solid_volume_m3": phi * region.volume,
        "samples": len(points),
        "spheres": int(np.count_nonzero(lengths)) if near.size else 0,
    }


def packing_core(x, r, center, radius: float, base_z: float, margin: float = 2.0) -> CylinderRegion:
    """The core of a bed filling a vertical cylindrical container: ``margin`` particle diameters inside its wall,
    above its base and below the lowest point of the free surface (wall and surface loosen a packing over a
    few diameters).

    The free surface is the highest sphere top in each square column, two diameters wide, that lies wholly
    inside the core's disc; the core ends ``margin`` diameters below the lowest of them.

    Args:
        x: sphere centres [m], shape (n, 3); r: radii [m], shape (n,).
        center: the container's axis (cx, cy) [m]; radius: its inner radius [m], > 0.
        base_z: the height of its base [m]; margin: in diameters of the largest sphere, >= 0.

    Raises:
        ValueError: when the bed is too narrow or too shallow to leave a core (naming the sizes).
    """
    x, r = _spheres(x, r)
    cx, cy = _axis(x, r, center)
    radius = _positive("radius", radius, "m")
    base_z = _finite_number("base_z", base_z, "m")
    margin = _finite_number("margin", margin, "diameters")
    if margin < 0:
        _bad("margin", margin, "a number of particle diameters >= 0")
    d = 2.0 * float(r.max())
    core_r = radius - margin * d
    width = 2.0 * d
    if core_r < width:
        _bad("radius", radius, f"a container wider than {margin} diameters ({margin * d:.4g} m) a side plus two")
    # square columns of the core disc, all four corners inside it
    k = int(math.ceil(core_r / width))
    edges = np.arange(-k, k + 1) * width
    ix = np.floor((x[:, 0] - cx) / width).astype(int)
    iy = np.floor((x[:, 1] - cy) / width).astype(int)
    tops = {}
    for i, j, top in zip(ix, iy, x[:, 2] + r):
        if tops.get((i, j), -math.inf) < top:
            tops[(i, j)] = top
    inside = [
        tops.get((i, j), base_z)
        for i in range(-k, k)
        for j in range(-k, k)
        if max(abs(edges[i + k]), abs(edges[i + k + 1])) ** 2 + max(abs(edges[j + k]), abs(edges[j + k + 1])) ** 2
        <= core_r**2
    ]
    if not inside:
        _bad("radius", radius, f"a container wide enough for a column {width:.4g} m wide inside its core")
    surface = min(inside)
    z_low, z_high = base_z + margin * d, surface - margin * d
    if z_high - z_low < d:
        _bad(
            "x",
            f"a bed whose free surface is {surface - base_z:.4g} m above the base",
            f"a bed deeper than {2 * margin + 1:g} diameters ({(2 * margin + 1) * d:.4g} m) everywhere in its core",
        )
    return CylinderRegion((cx, cy), core_r, z_low, z_high)


def discharge_rate(time_s, mass_kg, low: float = 0.2, high: float = 0.8) -> dict:
    """Steady mass flow out of an outlet from the discharged mass over time.

    The steady part is where the discharged mass lies between ``low`` and ``high`` of its final value: the
    start-up (the first particles reaching the outlet) and the end (the last of the heap, or a jam) are left
    out. The rate is the slope of a least-squares line through it.

    Args:
        time_s: sample times [s], shape (k,), increasing.
        mass_kg: mass discharged by each time [kg], shape (k,).
        low, high: the steady part's bounds as fractions of the final mass, 0 <= low < high <= 1.

    Returns:
        dict with ``discharge_rate_kg_s``, ``discharged_kg`` (final), ``steady_from_s`` and ``steady_to_s`` (the
        part fitted) and ``samples`` (in it).
    """
    t, m = _paired("time_s", time_s, "sample times [s]", "mass_kg", mass_kg, "discharged masses [kg]", 3)
    if np.any(np.diff(t) <= 0):
        _bad("time_s", t, "increasing sample times [s]")
    low = _finite_number("low", low, "")
    high = _finite_number("high", high, "")
    if not 0 <= low < high <= 1:
        _bad("high", high, f"a fraction in (low = {low}, 1]")
    final = float(m[-1])
    if final <= 0:
        _bad("mass_kg", m, "some mass discharged by the last sample")
    steady = (m >= low * final) & (m <= high * final)
    if steady.sum() < 3:
        _bad(
            "time_s",
            f"{int(steady.sum())} samples between {low:g} and {high:g} of the discharged mass",
            "at least 3 (sample more often)",
        )
    slope = float(np.polyfit(t[steady], m[steady], 1)[0])
    return {
        "discharge_rate_kg_s": slope,
        "discharged_kg": final,
        "steady_from_s": float(t[steady][0]),
        "steady_to_s": float(t[steady][-1]),
        "samples": int(steady.sum()),
    }


BEVERLOO_C = (0.55, 0.65)
"""The spread of Beverloo's discharge coefficient C [-] over free-flowing materials (Nedderman 1992, ch. 10)."""

BEVERLOO_K = (1.3, 2.9)
"""The spread of Beverloo's empty-annulus coefficient k [-] (Nedderman 1992, ch. 10): about 1.3-1.5 for
spheres, larger for angular grains."""


def hopper_angle_factor(cone_half_angle: float, stagnant_angle: float = 45.0) -> float:
    """Rose and Tanaka's factor on Beverloo's rate for a conical hopper, (tan theta tan phi_d)^-0.35.

    A flat-bottomed bin discharges through a converging core bounded by stagnant material at ``stagnant_angle``
    phi_d to the horizontal; a hopper steeper than that boundary (theta < 90 deg - phi_d) guides the flow
    and discharges faster. At theta = 90 deg - phi_d the factor is 1 and it stays 1 for flatter hoppers (the
    flat-bottom limit). Rose and Tanaka (1956), as given by Nedderman (1992, ch. 10).

    Args:
        cone_half_angle: theta, the hopper wall's angle from the vertical [deg], in (0, 90).
        stagnant_angle: phi_d, the stagnant-zone boundary's angle from the horizontal in a flat-bottomed bin
            [deg], in (0, 90); 45 deg by default (free-flowing grains: about 45-60 deg).

    Returns:
        the factor [-], >= 1.
    """
    theta = _finite_number("cone_half_angle", cone_half_angle, "[deg]")
    if not 0 < theta < 90:
        _bad("cone_half_angle", cone_half_angle, "an angle from the vertical in (0, 90) deg")
    phi = _finite_number("stagnant_angle", stagnant_angle, "[deg]")
    if not 0 < phi < 90:
        _bad("stagnant_angle", stagnant_angle, "an angle from the horizontal in (0, 90) deg")
    if theta >= 90.0 - phi:
        return 1.0
    return (math.tan(math.radians(theta)) * math.tan(math.radians(phi))) ** -0.35


def beverloo_rate(
    outlet_diameter: float,
    particle_diameter: float,
    bulk_density: float,
    C: float = 0.58,
    k: float = 1.5,
    g: float = 9.81,
    cone_half_angle: float | None = None,
    stagnant_angle: float = 45.0,
) -> float:
    """Beverloo's mass discharge rate of free-flowing, cohesionless grains through a circular outlet,
    W = C rho_b sqrt(g) (D - k d)^(5/2) (Beverloo, Leniger and van de Velde 1961), times Rose and Tanaka's
    :func:`hopper_angle_factor` for a conical hopper.

    The rate does not depend on the head above the outlet once the bed is deeper than about the outlet's
    diameter, and the law holds for D above about 6 d (narrower outlets arch and jam).

    Args:
        outlet_diameter: D [m], > k d.
        particle_diameter: d [m], > 0 (the mean of a narrow size spread).
        bulk_density: rho_b of the bed in the hopper [kg/m^3], > 0.
        C: the discharge coefficient [-], > 0 (0.58: Beverloo's; spread :data:`BEVERLOO_C`).
        k: the empty-annulus coefficient [-], >= 0 (1.5: spheres; spread :data:`BEVERLOO_K`).
        g: gravity [m/s^2], > 0.
        cone_half_angle: the hopper wall's angle from the vertical [deg], in (0, 90); None: a flat-bottomed bin.
        stagnant_angle: phi_d for the hopper factor [deg] (see :func:`hopper_angle_factor`).

    Returns:
        the mass flow rate [kg/s].
    """
    D = _positive("outlet_diameter", outlet_diameter, "m")
    d = _positive("particle_diameter", particle_diameter, "m")
    rho = _positive("bulk_density", bulk_density, "kg/m^3")
    C = _positive("C", C, "")
    k = _finite_number("k", k, "")
    if k < 0:
        _bad("k", k, "a number >= 0")
    g = _positive("g", g, "m/s^2")
    if not D > k * d:
        _bad("outlet_diameter", outlet_diameter, f"more than k d = {k * d:.6g} m (k = {k}, d = {d} m)")
    factor = 1.0 if cone_half_angle is None else hopper_angle_factor(cone_half_angle, stagnant_angle)
    return C * rho * math.sqrt(g) * (D - k * d) ** 2.5 * factor


def beverloo_band(
    outlet_diameter: float,
    particle_diameter: float,
    bulk_density: float,
    g: float = 9.81,
    cone_half_angle: float | None = None,
    stagnant_angle: float = 45.0,
    C: tuple = BEVERLOO_C,
    k: tuple = BEVERLOO_K,
) -> dict:
    """The range of Beverloo's rate over the literature's spread of C and k (:func:`beverloo_rate`).

    Args:
        outlet_diameter, particle_diameter, bulk_density, g, cone_half_angle, stagnant_angle: as in
            :func:`beverloo_rate` (units m, m, kg/m^3, m/s^2, deg, deg).
        C: (low, high) discharge coefficients [-], 0 < low <= high.
        k: (low, high) empty-annulus coefficients [-], 0 <= low <= high; D must exceed high k d.

    Returns:
        dict with ``low_kg_s`` (C low, k high), ``high_kg_s`` (C high, k low), ``nominal_kg_s`` (C = 0.58,
        k = 1.5) and ``hopper_factor`` [-] (1 without ``cone_half_angle``).
    """
    for name, pair in (("C", C), ("k", k)):
        if not (isinstance(pair, (tuple, list)) and len(pair) == 2 and pair[0] <= pair[1]):
            _bad(name, pair, "a pair (low, high) with low <= high")
    kw = dict(g=g, cone_half_angle=cone_half_angle, stagnant_angle=stagnant_angle)
    args = (outlet_diameter, particle_diameter, bulk_density)
    return {
        "low_kg_s": beverloo_rate(*args, C=C[0], k=k[1], **kw),
        "high_kg_s": beverloo_rate(*args, C=C[1], k=k[0], **kw),
        "nominal_kg_s": beverloo_rate(*args, **kw),
        "hopper_factor": 1.0 if cone_half_angle is None else hopper_angle_factor(cone_half_angle, stagnant_angle),
    }


def _paired(x_name: str, x, x_what: str, y_name: str, y, y_what: str, k_min: int) -> tuple[np.ndarray, np.ndarray]:
    """Two finite 1-D series of equal length (at least ``k_min``), refused naming the one at fault; ``*_what``
    says what each holds, with its unit (e.g. "piston face heights [m]")."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if x.ndim != 1 or x.size < k_min:
        _bad(x_name, x, f"{x_what} of shape (k,) with k >= {k_min}")
    if y.shape != x.shape:
        _bad(y_name, y, f"{y_what} of shape {x.shape}, one per {x_name} sample")
    for name, a, what in ((x_name, x, x_what), (y_name, y, y_what)):
        if not np.all(np.isfinite(a)):
            _bad(name, a, f"finite {what} (found NaN or inf)")
    return x, y


def _press_arrays(piston_z, piston_force) -> tuple[np.ndarray, np.ndarray]:
    z, f = _paired("piston_z", piston_z, "piston face heights [m]", "piston_force", piston_force, "axial forces [N]", 2)
    # the stroke is a loading curve: an upward step means unloading or mixed-up samples
    tol = 1e-9 * max(float(np.ptp(z)), 1e-300)
    up = np.flatnonzero(np.diff(z) > tol)
    if up.size:
        _bad("piston_z", z, f"a monotonic downward stroke (it rises after sample {int(up[0])})")
    return z, f


def press_curve(piston_z, piston_force, contact_z: float | None = None) -> dict:
    """Force-displacement curve of a die press from first contact.

    Args:
        piston_z: piston face height [m] over time, shape (k,), non-increasing (loading stroke).
        piston_force: axial force on the piston [N], shape (k,).
        contact_z: piston height at first contact [m]; None = the first sample whose force exceeds
            1 % of the maximum force.

    Returns:
        dict with ``displacement_m`` (travel since contact [m], shape (m,), from 0 at the contact
        sample), ``force_n`` (shape (m,)), ``contact_z_m`` and ``contact_index`` (first sample kept).
    """
    z, f = _press_arrays(piston_z, piston_force)
    if contact_z is None:
        fmax = float(f.max())
        if fmax <= 0:
            _bad("piston_force", f, "some positive force (the piston never touched the bed); or give contact_z")
        i0 = int(np.argmax(f > 0.01 * fmax))
        zc = float(z[i0])
    else:
        zc = _finite_number("contact_z", contact_z, "m")
        below = np.flatnonzero(z <= zc)
        if below.size == 0:
            _bad("contact_z", contact_z, f"a height reached by the piston (lowest piston_z = {z.min():.6g} m)")
        i0 = int(below[0])
    return {"displacement_m": zc - z[i0:], "force_n": f[i0:].copy(), "contact_z_m": zc, "contact_index": i0}


def press_summary(
    piston_z, piston_force, fill_height: float, force_limit: float | None = None, backstop_z: float = 0.0
) -> dict:
    """Key numbers of a die-press stroke (seed 001 reports max displacement and compression ratio).

    The loose bed fills the die from the backstop at ``backstop_z`` to ``backstop_z + fill_height``.
    The stroke ends at the lowest piston position, or, with ``force_limit``, where the force first
    reaches that limit (interpolated linearly between samples).

    Args:
        piston_z: piston face height [m], shape (k,), non-increasing, same frame as ``backstop_z``.
        piston_force: axial force on the piston [N], shape (k,).
        fill_height: initial (loose) bed height above the backstop [m], > 0.
        force_limit: force [N] at which the press stops, > 0, or None.
        backstop_z: height of the backstop (die bottom) [m].

    Returns:
        dict with ``max_displacement_m`` (piston travel from the top of the loose fill to the end of
        the stroke, >= 0), ``compression_ratio`` (max_displacement / fill_height), ``max_force_n``
        (up to the end of the stroke), ``final_height_m`` (bed height at the end, piston face above the
        backstop) and ``limit_reached`` (bool, False when no force_limit is given).
    """
    z, f = _press_arrays(piston_z, piston_force)
    fill = _positive("fill_height", fill_height, "m")
    backstop_z = _finite_number("backstop_z", backstop_z, "m")
    reached = False
    if force_limit is None:
        z_end, f_max = float(z.min()), float(f.max())
    else:
        lim = _positive("force_limit", force_limit, "N")
        hit = np.flatnonzero(f >= lim)
        if hit.size == 0:
            z_end, f_max = float(z.min()), float(f.max())
        else:
            reached = True
            i = int(hit[0])
            if i == 0:
                z_end = float(z[0])
            else:
                w = (lim - f[i - 1]) / (f[i] - f[i - 1])
                z_end = float(z[i - 1] + w * (z[i] - z[i - 1]))
            f_max = lim
    disp = max(0.0, backstop_z + fill - z_end)
    return {
        "max_displacement_m": disp,
        "compression_ratio": disp / fill,
        "max_force_n": f_max,
        "final_height_m": z_end - backstop_z,
        "limit_reached": reached,
    }


PRESS_FILL_FRACTION = 0.05
"""The fraction of the force limit that marks the bar's first push: the fill is the bed's top at the sample before
(a settling particle that grazes the approaching bar stays below it)."""


def press_loading(
    piston_z, piston_force, bed_top, force_limit: float = 0.0, backstop_z: float = 0.0, unload_index=None
):
    """The loading branch of a die-press run from its output series: the fill, the stroke's key numbers and the
    force-displacement curve, read the same way from a finished run and from a checkpoint taken once it unloads.

    Args:
        piston_z: bar face height [m] at each output sample, shape (k,).
        piston_force: axial force on the bar [N], shape (k,).
        bed_top: the bed's top [m] at each sample, shape (k,) (its particles' 99th-percentile height).
        force_limit: force [N] at which the stroke ends, or 0 (none: the fill is read at 5 % of the largest force).
        backstop_z: the backstop's height [m].
        unload_index: the sample at which the bar turned back (the series' ``unload_index``), or None.

    Returns:
        None when the bar never pressed the bed; else :func:`press_summary`'s dict with ``fill_height_m`` (the
        bed's top above the backstop at the sample before the force first passed :data:`PRESS_FILL_FRACTION` of
        the limit [m]), ``displacement_m`` and ``force_n`` (the curve from the loose bed's top, shape (m,)) and
        ``load_z`` and ``load_force`` (the series up to ``unload_index``, shape (n,)).
    """
    z, f = np.asarray(piston_z, dtype=float), np.asarray(piston_force, dtype=float)
    if unload_index is not None:
        z, f = z[: unload_index + 1], f[: unload_index + 1]
    top = np.asarray(bed_top, dtype=float)
    limit = force_limit if force_limit > 0 else float(f.max())
    pressing = np.flatnonzero(f > PRESS_FILL_FRACTION * limit)
    if len(pressing) == 0:
        return None
    fill = float(top[max(int(pressing[0]) - 1, 0)] - backstop_z)
    out = press_summary(z - backstop_z, f, fill_height=fill, force_limit=force_limit or None)
    curve = press_curve(z - backstop_z, f, contact_z=fill)
    out.update(
        fill_height_m=fill,
        displacement_m=curve["displacement_m"],
        force_n=curve["force_n"],
        load_z=z,
        load_force=f,
    )
    return out


# --------------------------------------------------------------------------------------------------
# impacts on wall faces
# --------------------------------------------------------------------------------------------------


def press_unload(
    load_z,
    load_force,
    unload_z,
    unload_force,
    contact_z: float,
    fill_height: float,
    contact_fraction: float = 0.05,
    interval_means: bool = False,
) -> dict:
    """The unloading branch of a press cycle against its loading branch.

    Displacements are ``contact_z`` minus the piston height. The loading exponent n is the slope of
    log F against log displacement over the upper part of the loading branch (F from 20 % of its maximum on);
    the unloading stiffness the slope of F against displacement over the upper half of the unloading branch
    after any hold (from its first sample down to half of that force); the residual set the travel between
    where the loading force first rises through ``contact_fraction`` of its maximum and where the unloading
    force falls through it again (linear between samples; the same rule on both branches, so that the
    particles the bar meets first do not count), also as a ratio of ``fill_height``: the permanent compaction.
    An elastic bed returns to (nearly) zero set; a plastic one does not. The reading is the set at the threshold
    force, not at zero: a plastic bed's loading branch crosses it at ``contact_fraction``^(1/n) of its stroke while
    the unloading branch crosses much nearer its zero-force end, so the reading is below the zero-force set (a
    column of EEPA contacts, lambda_p 0.5, n 1.5: 18 % below at 0.05, 7 % at 0.01;
    tests/verification/test_column_press.py predicts both exactly). With ``interval_means`` each force is the mean
    over the interval that ends at its height (a scene run's outputs): for the set it is paired with the middle of
    that interval, its height and the one before (the first sample of a branch keeps its own); paired with the end
    instead, each branch reads half an interval of travel late, in opposite directions, and the set one interval
    of travel low. The loading exponent uses the middles too; the unloading stiffness the ends (a line's slope
    does not move with a shift, and the middles would put the turning point's two samples at one height).

    Args:
        load_z, load_force: piston height [m] and force [N] of the loading branch, shape (k,), z non-increasing.
        unload_z, unload_force: the same after the stop, shape (u,), z non-decreasing (a hold repeats a height);
            its first sample is the loading branch's last.
        contact_z: the piston height at first contact [m], the origin of the displacements; fill_height: the
            loose fill's height [m], > 0.
        contact_fraction: the force that counts as contact, as a fraction of the largest loading force, in (0, 1).
        interval_means: the forces are means over the intervals ending at their heights (see above).

    Returns:
        dict with ``loading_exponent``, ``unloading_stiffness_n_m`` [N/m], ``residual_set_m`` [m] and
        ``residual_set_ratio`` (None where the force never fell through the threshold), ``max_displacement_m``
        and the unloading curve ``unload_displacement_m``, ``unload_force_n`` (shape (u,)).
    """
    lz, lf = _press_arrays(load_z, load_force)
    uz, uf = _paired("unload_z", unload_z, "piston heights [m]", "unload_force", unload_force, "axial forces [N]", 2)
    tol = 1e-9 * max(float(np.ptp(uz)), 1e-300)
    down = np.flatnonzero(np.diff(uz) < -tol)
    if down.size:
        _bad("unload_z", uz, f"a retraction that never moves down (it falls after sample {int(down[0])})")
    zc = _finite_number("contact_z", contact_z, "m")
    fill = _positive("fill_height", fill_height, "m")
    contact_fraction = _finite_number("contact_fraction", contact_fraction, "")
    if not 0 < contact_fraction < 1:
        _bad("contact_fraction", contact_fraction, "a fraction of the largest force in (0, 1)")
    ld, ud = zc - lz, zc - uz
    # interval means pair with their intervals' middles: for the set and the log-log exponent (a shift moves
    # neither the unloading line's slope nor, at constant speed, anything else the fits use)
    ls, us = ld, ud
    if interval_means:
        ls, us = (np.r_[d[:1], 0.5 * (d[1:] + d[:-1])] for d in (ld, ud))
    upper = (lf >= 0.2 * lf.max()) & (ls > 0)
    exponent = float(np.polyfit(np.log(ls[upper]), np.log(lf[upper]), 1)[0]) if upper.sum() >= 2 else None
    # the retraction starts at the last sample at the stop's height (after any hold)
    moving = np.flatnonzero(uz > uz[0] + tol)
    start = int(moving[0]) - 1 if moving.size else len(uz) - 1
    f0 = uf[start]
    top = np.arange(start, len(uf))
    top = top[: int(np.argmax(uf[top] < 0.5 * f0)) if np.any(uf[top] < 0.5 * f0) else len(top)]
    stiffness = float(np.polyfit(ud[top], uf[top], 1)[0]) if len(top) >= 2 and f0 > 0 else None
    # the set: between where the loading force first rose through the contact threshold and where the unloading
    # force falls through it again (the same rule on both branches, so an elastic bed shows none)
    threshold = contact_fraction * float(lf.max())
    residual = None
    rise = np.flatnonzero(lf > threshold)
    fall = np.flatnonzero(uf[start:] <= threshold)
    if rise.size and rise[0] > 0 and fall.size and f0 > threshold:
        i, j = int(rise[0]), start + int(fall[0])
        d_on = ls[i - 1] + (ls[i] - ls[i - 1]) * (threshold - lf[i - 1]) / (lf[i] - lf[i - 1])
        d_off = us[j - 1] + (us[j] - us[j - 1]) * (uf[j - 1] - threshold) / (uf[j - 1] - uf[j])
        residual = float(d_off - d_on)
    return {
        "loading_exponent": exponent,
        "unloading_stiffness_n_m": stiffness,
        "residual_set_m": residual,
        "residual_set_ratio": None if residual is None else residual / fill,
        "max_displacement_m": float(ld.max()),
        "unload_displacement_m": ud,
        "unload_force_n": uf.copy(),
    }


def _impact_arrays(face_count, face_energy, face_max_speed, face_area):
    c = np.asarray(face_count)
    if c.ndim != 1 or c.size == 0:
        _bad("face_count", c, "impact counts of shape (F,) with F >= 1")
    if not (
        np.issubdtype(c.dtype, np.integer)
        or (np.issubdtype(c.dtype, np.floating) and np.all(np.isfinite(c)) and np.all(c == np.round(c)))
    ):
        _bad("face_count", c, "whole-number impact counts")
    c = c.astype(np.int64)
    if np.any(c < 0):
        _bad("face_count", c, "counts >= 0")
    e = np.asarray(face_energy, dtype=float)
    v = np.asarray(face_max_speed, dtype=float)
    for name, a, unit in (("face_energy", e, "J"), ("face_max_speed", v, "m/s")):
        if a.shape != c.shape:
            _bad(name, a, f"shape {c.shape} like face_count")
        if not np.all(np.isfinite(a) & (a >= 0)):
            _bad(name, a, f"finite values >= 0 {unit}")
    area = None
    if face_area is not None:
        area = np.asarray(face_area, dtype=float)
        if area.shape != c.shape:
            _bad("face_area", area, f"shape {c.shape} like face_count")
        if not np.all(np.isfinite(area) & (area > 0)):
            _bad("face_area", area, "finite face areas > 0 m^2")
    return c, e, v, area


def impact_summary(face_count, face_energy, face_max_speed, face_area=None, hot: int = 10) -> dict:
    """Totals of the per-face wall impact records (``State.face_impact_*``).

    Args:
        face_count: impacts per wall face, integers, shape (F,).
        face_energy: impact kinetic energy summed per face [J], shape (F,).
        face_max_speed: highest impact speed per face [m/s], shape (F,).
        face_area: face areas [m^2], shape (F,), or None.
        hot: how many of the most-hit faces to list, >= 1.

    Returns:
        dict with ``total_count``, ``total_energy_j``, ``max_speed_m_s``, ``max_speed_face`` (index, the
        first on ties), ``mean_energy_per_impact_j`` (total energy / total count, i.e. the count-weighted
        mean of the per-face means; NaN without impacts), ``hot_faces`` (indices of up to ``hot`` faces
        with the most impacts, most first, faces without impacts left out) and, with ``face_area``,
        ``energy_per_area_j_m2`` (total energy / total area) and ``face_energy_per_area_j_m2`` (shape (F,)).
    """
    c, e, v, area = _impact_arrays(face_count, face_energy, face_max_speed, face_area)
    hot = _int_at_least("hot", hot, 1)
    total = int(c.sum())
    energy = float(e.sum())
    order = np.argsort(-c, kind="stable")
    hot_faces = [int(i) for i in order[:hot] if c[i] > 0]
    out = {
        "total_count": total,
        "total_energy_j": energy,
        "max_speed_m_s": float(v.max()),
        "max_speed_face": int(np.argmax(v)),
        "mean_energy_per_impact_j": energy / total if total > 0 else float("nan"),
        "hot_faces": hot_faces,
    }
    if area is not None:
        out["energy_per_area_j_m2"] = energy / float(area.sum())
        out["face_energy_per_area_j_m2"] = e / area
    return out


# --------------------------------------------------------------------------------------------------
# rotating drum
# --------------------------------------------------------------------------------------------------

DRUM_FIT_ROUNDS = 10
"""Most rounds of :func:`drum_surface`'s fit (points -> line -> chord -> points); it stops as soon as a round
picks the same points as the one before, which takes two or three rounds."""


def _drum_frame(center, axis) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The drum's centre (3,) [m], unit axis (3,) and the section's horizontal direction u = axis x z (3,)."""
    c = np.asarray(center, dtype=float)
    if c.shape != (3,) or not np.all(np.isfinite(c)):
        _bad("center", center, "a point on the drum's axis (x, y, z) in m, three finite numbers")
    a = np.asarray(axis, dtype=float)
    norm = float(np.linalg.norm(a)) if a.shape == (3,) and np.all(np.isfinite(a)) else 0.0
    if norm == 0.0:
        _bad("axis", axis, "the direction of the drum's angular velocity, three finite numbers, not all 0")
    a = a / norm
    if abs(a[2]) > 1e-9:
        _bad("axis", axis, "a horizontal direction (z component 0): the drum turns about a horizontal axis")
    u = np.cross(a, (0.0, 0.0, 1.0))
    return c, a, u / np.linalg.norm(u)


def drum_section(x, center=(0.0, 0.0, 0.0), axis=(0.0, 1.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """Cross-section coordinates of points in a drum that turns about the horizontal ``axis`` through ``center``.

    ``axis`` is the direction of the drum's angular velocity (right-hand rule). The section's horizontal
    coordinate s runs along u = axis x z (for axis +y, u = +x): the wall at the drum's bottom moves toward -u,
    so it carries the bed up on the -s side.

    Args:
        x: points [m], shape (n, 3).
        center: a point on the drum's axis [m], (3,).
        axis: the angular velocity's direction, (3,), horizontal, any length > 0.

    Returns:
        (s, h): the position across the drum along u [m] and the height above the axis [m], each shape (n,).
    """
    x = np.asarray(x, dtype=float)
    if x.ndim != 2 or x.shape[1] != 3:
        _bad("x", x, "points [m] of shape (n, 3)")
    c, _, u = _drum_frame(center, axis)
    d = x - c
    return d @ u, d[:, 2]


def _drum_points(s, top, window, bins: int, diameter: float) -> tuple[np.ndarray, float]:
    """Indices of the highest top in each of at most ``bins`` equal bins over ``window`` = (s0, s1) [m], at
    least MIN_BIN_DIAMETERS ``diameter`` wide, and in a second grid shifted by half a bin (each sphere once);
    and the bin width [m]."""
    s0, s1 = window
    n = min(bins, int((s1 - s0) // (MIN_BIN_DIAMETERS * diameter)))
    if n < 2:
        return np.zeros(0, dtype=np.int64), s1 - s0
    width = (s1 - s0) / n
    picks = []
    for shift in (0.0, 0.5):
        k = np.floor((s - s0) / width - shift).astype(np.int64)
        idx = np.flatnonzero((k >= 0) & (k < n - (1 if shift else 0)))
        order = np.lexsort((top[idx], k[idx]))
        kk = k[idx][order]
        picks.append(idx[order[np.flatnonzero(np.r_[kk[1:] != kk[:-1], True])]])
    return np.unique(np.concatenate(picks)), width


def _chord(slope: float, intercept: float, radius: float) -> tuple[float, float]:
    """Where the line h = intercept + slope s meets the circle s^2 + h^2 = radius^2: (s_low, s_high) [m]."""
    q = 1.0 + slope * slope
    disc = radius * radius * q - intercept * intercept
    if disc <= 0:
        _bad(
            "drum_radius",
            radius,
            f"a drum that the bed's surface line (height {intercept:.4g} m above the axis, slope {slope:.4g}) crosses",
        )
    root = math.sqrt(disc)
    return (-intercept * slope - root) / q, (-intercept * slope + root) / q


def drum_surface(
    x,
    r,
    center,
    drum_radius: float,
    axis=(0.0, 1.0, 0.0),
    bins: int = 12,
    inner: float = 0.15,
    outer: float = 0.85,
    gap: float = 0.1,
) -> dict:
    """The free surface of the bed in a rotating drum, and its angle, from one frame.

    The spheres are projected onto the drum's cross-section (:func:`drum_section`: s across, h up). Only the
    bed counts: the largest group of spheres connected through contacts (centres closer than (1 + ``gap``)
    (r_i + r_j)), so grains flying over the cascade, or carried alone by the wall, are left out. The chord
    where the surface meets the wall is cut into equal bins along s; the highest sphere top (h + r) of each
    bin is a surface point, taken at that sphere's own s (the highest top of a bin lies toward its up-slope
    edge: the bin centre would bias the slope), and a second grid shifted by half a bin adds points (each
    sphere once). Bins cover ``inner`` to ``outer`` of the chord: near the wall the bed is lifted and piles
    against it. A straight line h(s) is fitted by least squares.

    Why this is unbiased: every bin spans the drum's whole width along its axis, so all bins have the same
    area and the same number of candidate tops (the highest of more rough tops sits higher); bins are at
    least 2.5 mean diameters wide so that each holds a surface sphere. The chord comes from the surface
    itself: a first line through the bins of the middle half of the bed's width gives the chord (the line
    meets the circle of ``drum_radius``), its bins give the next line, and so on until the points repeat
    (at most DRUM_FIT_ROUNDS rounds).

    Sign: ``angle_deg`` = atan(-dh/ds) is positive when the surface rises toward -s, the side where the wall
    carries the bed up, i.e. in a drum turning the way ``axis`` says (right-hand rule). A bed tilted the other
    way reads negative.

    Args:
        x: sphere centres [m], shape (n, 3); r: radii [m], shape (n,).
        center: a point on the drum's axis [m], (3,).
        drum_radius: the drum's inner radius [m], > 0.
        axis: the direction of the drum's angular velocity, (3,), horizontal.
        bins: most bins over the part of the chord used, >= 3 (fewer when they would be narrower than 2.5
            mean diameters; at least 2 are needed).
        inner, outer: the part of the chord used, as fractions of it from its -s end, 0 <= inner < outer <= 1.
        gap: contact tolerance of the bed test, as a fraction of the radii sum [-].

    Returns:
        dict with ``angle_deg``; ``slope`` dh/ds [-] and ``intercept_m`` (the line's height above the axis at
        s = 0); ``surface_s``, ``surface_h`` [m], shape (k,): the surface points (sphere tops) in section
        coordinates, sorted by s; ``chord_m`` (s_low, s_high) where the line meets the drum; ``window_m`` (the
        part used); ``bin_width_m``; ``bed`` (bool mask, shape (n,)); ``bed_spheres``; ``detached`` (spheres
        not in the bed); ``mean_diameter_m`` of the bed; ``rounds`` of the fit.

    Raises:
        ValueError: bad arguments; a bed of fewer than 3 spheres, or one with sphere centres outside
        ``drum_radius``; fewer than 3 surface points (a bed too small for bins of 2.5 diameters); a surface
        line that misses the drum.
    """
    x, r = _spheres(x, r)
    radius = _positive("drum_radius", drum_radius, "m")
    bins = _int_at_least("bins", bins, 3)
    inner, outer = _zones(inner, outer)
    gap = _finite_number("gap", gap, "[-]")
    if gap < 0:
        _bad("gap", gap, "a contact tolerance >= 0 (a fraction of the radii sum)")
    s_all, h_all = drum_section(x, center, axis)
    label = _touching_groups(x, r, gap)
    bed = label == np.bincount(label).argmax()
    if bed.sum() < 3:
        _bad("x", f"a largest group of {int(bed.sum())} touching spheres", "a bed of at least 3 touching spheres")
    out = int(np.count_nonzero(np.hypot(s_all[bed], h_all[bed]) > radius))
    if out:
        _bad("drum_radius", radius, f"the drum's inner radius [m] (the centres of {out} bed spheres are outside it)")
    s, top, rb = s_all[bed], h_all[bed] + r[bed], r[bed]
    diameter = 2.0 * float(rb.mean())

    def fit(window):
        pick, width = _drum_points(s, top, window, bins, diameter)
        if len(pick) < 3:
            _bad(
                "x",
                f"{len(pick)} surface points over {window[1] - window[0]:.4g} m of the chord",
                f"at least 3 (bins >= {MIN_BIN_DIAMETERS} diameters = {MIN_BIN_DIAMETERS * diameter:.4g} m wide): "
                "a larger bed, smaller spheres or wider inner..outer",
            )
        slope, intercept = np.polyfit(s[pick], top[pick], 1)
        return pick, width, float(slope), float(intercept)

    lo, hi = float((s - rb).min()), float((s + rb).max())
    window = (lo + 0.25 * (hi - lo), lo + 0.75 * (hi - lo))
    pick, width, slope, intercept = fit(window)
    rounds = 1
    while rounds <= DRUM_FIT_ROUNDS:
        rounds += 1
        c0, c1 = _chord(slope, intercept, radius)
        window = (c0 + inner * (c1 - c0), c0 + outer * (c1 - c0))
        new, width, slope, intercept = fit(window)
        if np.array_equal(new, pick):
            break
        pick = new
    order = np.argsort(s[pick])
    return {
        "angle_deg": math.degrees(math.atan(-slope)),
        "slope": slope,
        "intercept_m": intercept,
        "surface_s": s[pick][order],
        "surface_h": top[pick][order],
        "chord_m": _chord(slope, intercept, radius),
        "window_m": window,
        "bin_width_m": width,
        "bed": bed,
        "bed_spheres": int(bed.sum()),
        "detached": int(len(r) - bed.sum()),
        "mean_diameter_m": diameter,
        "rounds": rounds,
    }


def drum_metrics(frames, diameter: float, positions: int = 16) -> dict:
    """Dynamic angle of repose and surface-fluctuation index of a rotating drum over its steady frames.

    ``dynamic_angle_deg`` is the mean of the frames' :func:`drum_surface` angles, ``dynamic_angle_sd_deg``
    their sample SD (ddof=1). ``fluctuation_index`` measures how much the interface moves from frame to frame:
    each frame's surface profile (its surface points, linear between them) is read at ``positions`` equally
    spaced positions across the part of the chord that every frame covers; at each position the sample SD
    (ddof=1) of the height over the frames is taken, and the index is the root mean square of these SDs over
    the positions, in mean particle diameters:

        fluctuation_index = sqrt(mean_i SD_k(h_ik)^2) / diameter.

    A free-flowing bed rolls with a steady surface (its index is the grain-scale roughness, a fraction of a
    diameter); a cohesive one avalanches and its surface swings (larger index). GranuDrum's cohesive index is
    the same idea, the interface's frame-to-frame fluctuation averaged across the drum, but normalised
    differently; a measured data set must be compared through this definition (recomputed from the measured
    interface profiles), not through the instrument's number.

    Args:
        frames: the steady frames, a sequence of :func:`drum_surface` dicts (``angle_deg``, ``surface_s`` and
            ``surface_h`` [m] are used), at least 2.
        diameter: the mean particle diameter [m], > 0.
        positions: positions across the chord, >= 2.

    Returns:
        dict with ``dynamic_angle_deg``, ``dynamic_angle_sd_deg``, ``fluctuation_index`` [diameters],
        ``frames`` (count), ``positions_m`` (shape (positions,), s [m]) and ``height_sd_m`` (the SD at each).
    """
    if isinstance(frames, Mapping) or not hasattr(frames, "__len__"):
        _bad("frames", type(frames).__name__, "a sequence of drum_surface results (dicts)")
    if len(frames) < 2:
        _bad("frames", f"{len(frames)} frames", "at least 2 frames of drum_surface")
    diameter = _positive("diameter", diameter, "m")
    positions = _int_at_least("positions", positions, 2)
    angles, profiles = [], []
    for k, f in enumerate(frames):
        if not isinstance(f, Mapping) or not {"angle_deg", "surface_s", "surface_h"} <= set(f):
            _bad(f"frames[{k}]", type(f).__name__, "a drum_surface dict with angle_deg, surface_s and surface_h")
        s, h = _paired(
            f"frames[{k}]['surface_s']",
            f["surface_s"],
            "surface positions [m]",
            "surface_h",
            f["surface_h"],
            "surface heights [m]",
            2,
        )
        angles.append(_finite_number(f"frames[{k}]['angle_deg']", f["angle_deg"], "deg"))
        order = np.argsort(s)
        profiles.append((s[order], h[order]))
    lo = max(float(s[0]) for s, _ in profiles)
    hi = min(float(s[-1]) for s, _ in profiles)
    if not hi > lo:
        _bad(
            "frames",
            f"surfaces whose common span is [{lo:.4g}, {hi:.4g}] m",
            "frames whose surfaces overlap across the drum",
        )
    grid = np.linspace(lo, hi, positions)
    heights = np.array([np.interp(grid, s, h) for s, h in profiles])
    sd = heights.std(axis=0, ddof=1)
    a = np.array(angles)
    return {
        "dynamic_angle_deg": float(a.mean()),
        "dynamic_angle_sd_deg": float(a.std(ddof=1)),
        "fluctuation_index": float(np.sqrt(np.mean(sd**2)) / diameter),
        "frames": len(frames),
        "positions_m": grid,
        "height_sd_m": sd,
    }


# --------------------------------------------------------------------------------------------------
# settling
# --------------------------------------------------------------------------------------------------


class SettleMonitor:
    """Decides when a packing has settled: kinetic energy per particle below a threshold for a while.

    Args:
        threshold: kinetic energy per particle [J], > 0.
        window: consecutive updates that must all be below the threshold, >= 1.

    Attributes:
        history: list of (time [s], kinetic energy per particle [J]), one per update, the energy as given
            (a float, or an array of one per world).
        settled_time: time [s] of the update at which the monitor first reported settled, or None.
        streak: consecutive updates below the threshold so far (a resumed run restores it).
        world_streak: with one energy per world, each world's consecutive updates below the threshold so far,
            shape (W,) int (None before the first such update; a resumed run restores it). The streak of all
            worlds together is their smallest.
    """

    def __init__(self, threshold: float, window: int = 3):
        self.threshold = _positive("threshold", threshold, "J")
        self.window = _int_at_least("window", window, 1)
        self.history: list[tuple[float, float | np.ndarray]] = []
        self.settled_time: float | None = None
        self.streak = 0
        self.world_streak: np.ndarray | None = None

    def update(self, time: float, kinetic_energy_per_particle) -> bool:
        """Record one sample: time [s] and kinetic energy per particle [J], a number or an array of one per
        world (shape (W,)); with an array the sample is below the threshold only when every world is.

        A NaN energy (a world that blew up) is not below the threshold. Returns True when the last
        ``window`` samples were all below the threshold; a sample at or above it starts the count again.
        """
        t = _finite_number("time", time, "s")
        ke = kinetic_energy_per_particle
        if np.ndim(ke) == 0:
            # one energy: it must be a finite number (a NaN is only meaningful as one world of several)
            ke = _finite_number("kinetic_energy_per_particle", ke, "J")
        else:
            ke = np.array(ke, dtype=float)
            if ke.ndim != 1 or ke.size == 0:
                _bad("kinetic_energy_per_particle", ke, "a number [J] or one per world, shape (W,)")
        if np.any(ke < 0):
            _bad("kinetic_energy_per_particle", ke, "energies >= 0 J")
        if self.history and t < self.history[-1][0]:
            _bad("time", time, f"a time >= the previous update's {self.history[-1][0]!r} s")
        self.history.append((t, ke))
        self.streak = self.streak + 1 if np.all(ke < self.threshold) else 0
        if np.ndim(ke):
            below = ke < self.threshold  # a NaN is not below
            if self.world_streak is None or self.world_streak.shape != below.shape:
                self.world_streak = np.zeros(below.shape, dtype=np.int64)
            self.world_streak = np.where(below, self.world_streak + 1, 0)
        if self.settled and self.settled_time is None:
            self.settled_time = t
        return self.settled

    @property
    def settled(self) -> bool:
        """Whether the last ``window`` updates were all below the threshold."""
        return self.streak >= self.window

    @property
    def settled_worlds(self) -> np.ndarray:
        """With one energy per world: which worlds' last ``window`` updates were all below the threshold, shape
        (W,) bool (empty before the first such update)."""
        if self.world_streak is None:
            return np.zeros(0, dtype=bool)
        return self.world_streak >= self.window


# --------------------------------------------------------------------------------------------------
# plots
# --------------------------------------------------------------------------------------------------


def _pyplot():
    import matplotlib

    # files only: no display is needed (or present on the cluster)
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_press(curve: dict, path, unload: dict | None = None, force_limit: float | None = None) -> str:
    """Write the force-displacement curve of :func:`press_curve` as a PNG (mm vs N) to ``path``, with the
    unloading branch of :func:`press_unload` and the force limit [N] when given."""
    for name, value, keys in (("curve", curve, "press_curve"), ("unload", unload, "press_unload")):
        if name == "unload" and value is None:
            continue
        if not isinstance(value, Mapping) or "displacement_m" not in value or "force_n" not in value:
            _bad(name, type(value).__name__, f"the dict of {keys} (displacement_m, force_n)")
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5, 3.5), dpi=120)
    ax.plot(1e3 * np.asarray(curve["displacement_m"]), np.asarray(curve["force_n"]), lw=1.5, label="loading")
    if unload is not None:
        ax.plot(1e3 * np.asarray(unload["displacement_m"]), np.asarray(unload["force_n"]), lw=1.5, label="unloading")
    if force_limit:
        ax.axhline(force_limit, color="0.4", ls="--", lw=1, label=f"force limit {force_limit:g} N")
    if unload is not None or force_limit:
        ax.legend(frameon=False, fontsize=8)
    ax.set_xlabel("piston displacement since contact [mm]")
    ax.set_ylabel("piston force [N]")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)
    return str(path)


def plot_angles(result: dict, path) -> str:
    """Write the per-sector (:func:`angle_surface_fit`) or per-flank (:func:`angle_image`) angles as a
    bar chart PNG with the mean +- SD to ``path``."""
    key = next((k for k in ("per_slice_deg", "per_side_deg") if isinstance(result, Mapping) and k in result), None)
    if key is None:
        _bad("result", type(result).__name__, "the dict of angle_surface_fit or angle_image")
    vals = np.asarray(result[key], dtype=float)
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5, 3.5), dpi=120)
    ax.bar(np.arange(len(vals)), vals, color="tab:blue", alpha=0.7)
    mean, sd = float(result["mean_deg"]), float(result["sd_deg"])
    ax.axhline(mean, color="k", lw=1.2, label=f"mean {mean:.2f} deg (SD {sd:.2f})")
    ax.axhspan(mean - sd, mean + sd, color="k", alpha=0.1)
    ax.set_xlabel("sector" if key == "per_slice_deg" else "flank (left, right per view)")
    ax.set_ylabel("angle of repose [deg]")
    ax.legend(loc="lower right")
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)
    return str(path)


def plot_impacts(walls, path, title: str | None = None) -> str:
    """Write a heat map of wall impacts as a PNG to ``path``: one 3-D panel per wall, each face coloured by the
    impact energy it took per unit area [J/m^2] on one logarithmic scale shared by every panel (faces with no
    impact light grey), the wall as built (before it moved), with its impact count and energy in the panel's
    title. ``walls``: a list of (name, vertices (V, 3) [m], triangles (F, 3), energy (F,) [J], count (F,)), e.g.
    one world's faces summed over the phases (``impacts.npz``)."""
    from matplotlib.colors import LogNorm
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from warpdem.engine.geometry import face_areas

    if not isinstance(walls, (list, tuple)) or not walls:
        _bad("walls", walls, "a non-empty list of (name, vertices (V, 3), triangles (F, 3), energy (F,), count (F,))")
    panels = []
    for i, item in enumerate(walls):
        if not isinstance(item, (list, tuple)) or len(item) != 5:
            _bad(f"walls[{i}]", item, "(name, vertices (V, 3), triangles (F, 3), energy (F,), count (F,))")
        name, v, t, e, c = item
        v = np.asarray(v, dtype=float)
        t = np.asarray(t)
        if v.ndim != 2 or v.shape[1] != 3 or not np.all(np.isfinite(v)):
            _bad(f"walls[{i}] ({name}) vertices", v.shape, "a finite (V, 3) array [m]")
        if t.ndim != 2 or t.shape[1] != 3 or t.size == 0 or t.min() < 0 or t.max() >= len(v):
            _bad(f"walls[{i}] ({name}) triangles", t.shape, f"an (F, 3) array of vertex indices in [0, {len(v)})")
        e, c = np.asarray(e, dtype=float), np.asarray(c, dtype=float)
        if e.shape != (len(t),) or c.shape != (len(t),) or np.any(e < 0) or np.any(c < 0):
            _bad(
                f"walls[{i}] ({name}) energy / count", (e.shape, c.shape), f"two ({len(t)},) arrays >= 0, one per face"
            )
        area = face_areas(v, t.astype(np.int64))
        panels.append((str(name), v, t, np.divide(e, area, out=np.zeros_like(e), where=area > 0), e, c))
    hot = np.concatenate([p[3][p[3] > 0] for p in panels])
    plt = _pyplot()
    fig = plt.figure(figsize=(5.0 * len(panels), 4.6), dpi=110)
    norm = LogNorm(hot.min(), max(hot.max(), hot.min() * 10)) if hot.size else None
    cmap = plt.get_cmap("inferno")
    for k, (name, v, t, density, e, c) in enumerate(panels):
        ax = fig.add_subplot(1, len(panels), k + 1, projection="3d")
        colours = np.tile([0.85, 0.85, 0.85, 1.0], (len(t), 1))
        if norm is not None:
            colours[density > 0] = cmap(norm(density[density > 0]))
        ax.add_collection3d(Poly3DCollection(v[t], facecolors=colours, edgecolors=(0, 0, 0, 0.15), linewidths=0.2))
        lo, hi = v.min(axis=0), v.max(axis=0)
        mid, half = 0.5 * (lo + hi), 0.5 * float(np.max(hi - lo))
        for setter, m_ in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), mid):
            setter(m_ - half, m_ + half)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_zlabel("z [m]")
        ax.set_title(f"{name}: {int(c.sum())} impacts, {e.sum():.3g} J", fontsize=10)
    if norm is not None:
        sm = plt.cm.ScalarMappable(norm=norm, cmap=cmap)
        fig.colorbar(sm, ax=fig.axes, shrink=0.7, label="impact energy per area [J/m²]")
    if title:
        fig.suptitle(title)
    save_figure(fig, path)
    plt.close(fig)
    return str(path)


def plot_drum(s, h, r, surface: dict, path, drum_radius: float, title: str | None = None) -> str:
    """Write the drum's cross-section as a PNG to ``path``: the spheres as discs of their radius at their
    section coordinates (``s``, ``h`` [m] of :func:`drum_section`, shape (n,); ``r`` [m], shape (n,)), the drum
    wall (``drum_radius`` [m]), one frame's surface points and fitted line (a :func:`drum_surface` dict) over
    the chord, in mm."""
    from matplotlib.collections import EllipseCollection

    s, h = _paired("s", s, "section positions [m]", "h", h, "section heights [m]", 0)
    r = np.asarray(r, dtype=float)
    if r.shape != s.shape:
        _bad("r", r, f"radii [m] of shape {s.shape}, one per sphere")
    if not isinstance(surface, Mapping) or not {"slope", "intercept_m", "chord_m"} <= set(surface):
        _bad("surface", type(surface).__name__, "the dict of drum_surface")
    radius = _positive("drum_radius", drum_radius, "m")
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5, 5), dpi=120)
    mm = 1e3
    ax.add_collection(
        EllipseCollection(
            2 * mm * r,
            2 * mm * r,
            0.0,
            units="xy",
            offsets=np.column_stack([mm * s, mm * h]),
            offset_transform=ax.transData,
            facecolors="tan",
            edgecolors="0.4",
            linewidths=0.3,
        )
    )
    phi = np.linspace(0, 2 * math.pi, 361)
    ax.plot(mm * radius * np.cos(phi), mm * radius * np.sin(phi), color="0.3", lw=1.2)
    c0, c1 = surface["chord_m"]
    line = np.array([c0, c1])
    ax.plot(mm * line, mm * (surface["intercept_m"] + surface["slope"] * line), color="tab:red", lw=1.5)
    if "surface_s" in surface:
        ax.plot(
            mm * np.asarray(surface["surface_s"]),
            mm * np.asarray(surface["surface_h"]),
            "o",
            ms=3,
            color="tab:blue",
            label="surface points",
        )
        ax.legend(loc="lower right", frameon=False, fontsize=8)
    ax.set_xlim(-1.05 * mm * radius, 1.05 * mm * radius)
    ax.set_ylim(-1.05 * mm * radius, 1.05 * mm * radius)
    ax.set_aspect("equal")
    ax.set_xlabel("across the drum, s [mm]")
    ax.set_ylabel("height above the axis [mm]")
    if title:
        ax.set_title(title, fontsize=9)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)
    return str(path)
