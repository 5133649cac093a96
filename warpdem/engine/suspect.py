"""Signs that a run's physics may be wrong although nothing failed: bodies lost through the domain, a step so
large that bodies jump past their neighbours, overlaps at the start, deep overlaps (a material too soft), a
pile that grew up to its funnel's outlet, one that stands off its axis and one that holds too little of its bed,
and a press whose spheres were squeezed past its bar.

Pure functions of host arrays. :meth:`warpdem.ModelBuilder.finalize` warns of overlaps at the start;
:mod:`warpdem.scene.runner` writes what it finds into each world's metrics (``warnings``: a list of {"check",
"detail"}) and warns, and a study's run checks list it.
"""

from __future__ import annotations

import numpy as np

LOST_FRACTION_MAX = 0.02
"""The fraction of a world's bodies that may leave its domain without a warning (a pile loses a few over its
plate's edge; more means bodies passed through a wall, or a domain too small)."""
STEP_TRAVEL_MAX = 0.5
"""The most a body may move in one step, in radii of the smallest sphere: the neighbour lists are rebuilt when
a body has moved half its skin (0.4 radii by default), and a body that moves further than this between steps
meets a contact already deep, or passes a thin wall."""
START_OVERLAP_MAX = 0.01
"""The deepest overlap two spheres of different bodies may start with, as a fraction of the smaller radius: a
deeper one releases its elastic energy at the first step and launches both."""
OVERLAP_MAX = 0.1
"""The deepest overlap at the end of a run, as a fraction of the smaller radius, before the run is flagged as
too soft: Hertz contact theory holds for overlaps of a few per cent of the radius."""
PILE_APART_MAX = 0.2
"""The largest fraction of a pile test's particle spheres above its base that may lie apart from the pile
(``detached``: hung in a lifted cylinder or a funnel, stuck to a wall, scattered on the plate) before the run is
flagged: the test measures the heap its whole bed forms, and a bed of which a fifth never joined the heap is
not the test the rig defines. Strays alone stay well below it (at most 7.3 % in the seed runs' 458 piles)."""
COINCIDENT = 1e-6
"""Centres closer than this fraction of the smaller radius coincide: the contact normal is undefined, and the
two spheres push on each other in no direction, so they stay together for ever."""


def overlaps(x: np.ndarray, r: np.ndarray, world: np.ndarray, body: np.ndarray, world_count: int) -> dict:
    """The deepest overlap between spheres of different bodies, per world.

    Args:
        x: sphere centres (n, 3) [m]; r: radii (n,) [m]; world: world of each sphere (n,); body: an id shared by
            the spheres of one rigid body (a clump's spheres), distinct otherwise (n,).
    Returns:
        {"deepest": (world_count,) overlap / smaller radius [-] (0 without contacts), "mean": (world_count,) the
        mean of that over the overlapping pairs [-] (0 without), "pairs": (world_count,) count of pairs deeper
        than :data:`START_OVERLAP_MAX`, "coincident": (world_count,) count of pairs whose centres coincide}.
    """
    from scipy.spatial import cKDTree

    deepest = np.zeros(world_count)
    mean = np.zeros(world_count)
    pairs = np.zeros(world_count, dtype=np.int64)
    coincident = np.zeros(world_count, dtype=np.int64)
    if len(r) < 2:
        return {"deepest": deepest, "mean": mean, "pairs": pairs, "coincident": coincident}
    # the worlds share one space: a fourth coordinate far apart per world keeps their spheres from pairing
    span = float(np.ptp(x, axis=0).max()) + 4.0 * float(r.max()) + 1.0
    pts = np.column_stack([x, world.astype(np.float64) * 10.0 * span])
    ij = cKDTree(pts).query_pairs(2.0 * float(r.max()), output_type="ndarray")
    if len(ij) == 0:
        return {"deepest": deepest, "mean": mean, "pairs": pairs, "coincident": coincident}
    i, j = ij[:, 0], ij[:, 1]
    keep = body[i] != body[j]
    i, j = i[keep], j[keep]
    d = np.linalg.norm(x[i] - x[j], axis=1)
    small = np.minimum(r[i], r[j])
    depth = (r[i] + r[j] - d) / small
    w = world[i]
    np.maximum.at(deepest, w, np.maximum(depth, 0.0))
    np.add.at(pairs, w, depth > START_OVERLAP_MAX)
    np.add.at(coincident, w, d < COINCIDENT * small)
    touching = depth > 0.0
    total = np.bincount(w[touching], weights=depth[touching], minlength=world_count)
    count = np.bincount(w[touching], minlength=world_count)
    mean = np.divide(total, count, out=mean, where=count > 0)
    return {"deepest": deepest, "mean": mean, "pairs": pairs, "coincident": coincident}


def start_overlap_words(found: dict) -> str | None:
    """One world's :func:`overlaps` at the start ({"deepest", "pairs", "coincident"} of that world) in words, or
    None when no pair is deeper than :data:`START_OVERLAP_MAX`."""
    if not (found["pairs"] or found["coincident"]):
        return None
    words = (
        f"{int(found['pairs'])} pairs of spheres of different bodies overlap at the start (the deepest by "
        f"{100 * found['deepest']:.3g} % of the smaller radius)"
    )
    if found["coincident"]:
        words += f", {int(found['coincident'])} of them with coincident centres (they push in no direction and stay together)"
    return words + ": place the spheres apart"


def world_warnings(
    removed: int,
    bodies: int,
    step_travel: float,
    dt_range: tuple[float, float],
    start: dict | None,
    end_deepest: float,
    peak: dict | None = None,
) -> list[dict]:
    """The warnings of one world: {"check": lost | fast | start_overlap | soft, "detail": words}.

    Args:
        removed: bodies that left the domain; bodies: bodies released in the world (removed included).
        step_travel: the largest distance a body moved in one step over the run, in radii of the smallest sphere.
        dt_range: the smallest and largest step of the run [s].
        start: this world's entry of :func:`overlaps` at the start ({"deepest", "pairs", "coincident"}), None
            for a run resumed from a checkpoint saved before this check existed.
        end_deepest: the deepest overlap at the end / smaller radius.
        peak: this world's entry of :func:`overlaps` ({"deepest", "mean"}) at its heaviest load (a press at its
            force limit), or None; where it is the deeper, the soft check reports it instead of the end's.
    """
    out = []
    if bodies and removed > LOST_FRACTION_MAX * bodies:
        out.append(
            {
                "check": "lost",
                "detail": f"{removed} of {bodies} bodies ({100 * removed / bodies:.1f} %) left the domain and were "
                "removed: more than a pile loses over its plate's edge; bodies may have passed through a wall (too "
                "fast for the step: lower run.dt_fraction) or the domain is too small",
            }
        )
    if step_travel > STEP_TRAVEL_MAX:
        out.append(
            {
                "check": "fast",
                "detail": f"a body moved {step_travel:.3g} radii of the smallest sphere in one step (dt "
                f"{dt_range[1]:.3g} s), more than {STEP_TRAVEL_MAX:g}: contacts are met late and thin walls can be "
                "passed; lower run.dt_fraction (a soft material's Rayleigh step is long)",
            }
        )
    words = None if start is None else start_overlap_words(start)
    if words:
        out.append({"check": "start_overlap", "detail": words})
    when = "at the end"
    if peak is not None and peak["deepest"] > end_deepest:
        end_deepest = peak["deepest"]
        when = f"at the heaviest load (the mean contact by {100 * peak['mean']:.3g} %)"
    if end_deepest > OVERLAP_MAX:
        out.append(
            {
                "check": "soft",
                "detail": f"the deepest contact overlaps by {100 * end_deepest:.3g} % of the smaller radius {when}, "
                f"more than {100 * OVERLAP_MAX:g} %: Hertz contact holds for small overlaps; a stiffer shear modulus "
                "(or a smaller load) keeps them small",
            }
        )
    return out


def escape_warning(escaped: int, clearance: float) -> dict | None:
    """A press whose spheres were squeezed past its bar, or None.

    Args:
        escaped: particle spheres above the bar's face at the force limit, or removed from the domain by then;
            clearance: the gap [m] between the bar's rim and the die.

    A sphere pressed into the rim of the bar overlaps both it and the die, and once its centre passes the rim
    the stored elastic energy throws it out: seed 001's press at 300 N had thrown two of 6,575 out at 16-25 m/s
    by 0.97 s, and 129 by the end of another fill's stroke (twenty-first stage). It no longer carries load, and
    each flying sphere that stays in the scene rebuilds the neighbour lists every few steps."""
    if escaped <= 0:
        return None
    return {
        "check": "escaped",
        "detail": f"{escaped} spheres were squeezed past the bar's rim (a clearance of {1000 * clearance:.3g} mm): "
        "contacts so deep that a sphere fits through a gap narrower than itself; the bed lost them, and its "
        "contacts at the rim are past what Hertz contact describes (a stiffer shear modulus or a smaller load)",
    }


def outlet_warning(pile_top: float, outlet: float, diameter: float) -> dict | None:
    """A pile that reached the funnel it was poured from, or None.

    Args:
        pile_top: the height [m] of the pile's highest sphere top (spheres connected to the base, so a column
            standing into the funnel counts); outlet: the height [m] of the outlet's lower edge; diameter: the
            smallest particle's diameter [m], the margin.

    A funnel whose outlet the pile reaches stops discharging: what it holds stands on the pile as a column, and
    the angle methods measure that column's flanks, not a free slope (seed 001's wet feed at 2 mm: 9 centre
    points of one design ranged from 3 to 52 degrees)."""
    if pile_top < outlet - diameter:
        return None
    return {
        "check": "outlet",
        "detail": f"the pile's top ({1000 * pile_top:.0f} mm) reached the funnel's outlet ({1000 * outlet:.0f} mm): "
        "the funnel stopped discharging into a column standing on the pile, and its angle is that column's; "
        "raise outlet_height or pour fewer particles",
    }


def off_axis_warning(offset: float, pour_radius: float) -> dict | None:
    """A pile that stands off the axis it was poured on, or None.

    Args:
        offset: how far [m] the pile's centre of mass lies from the axis (``measure.pile_offset``); pour_radius:
            the radius [m] of what it was poured from or lifted out of (a funnel's outlet, a lifting cylinder).

    Grains poured from an outlet land within its footprint, and a pile lifted out of a cylinder slumps around
    it, so the pile grows around the axis. A centre of mass beyond that radius means the pile moved as a body
    after it was built: seed 001's cohesive wet feed built columns, and the eight that fell over stood 25-38 mm
    off a 20 mm outlet's axis and read 29-50 deg; of the 20 within 18 mm, all but one read 45-70 deg.
    The angle methods read slopes about the axis, so they read the fallen pile's side."""
    if offset <= pour_radius:
        return None
    return {
        "check": "off_axis",
        "detail": f"the pile's centre of mass lies {1000 * offset:.3g} mm off its axis, beyond the "
        f"{1000 * pour_radius:.3g} mm it was poured within: it moved as a body after it was built (a column that fell over, a pile that "
        "slid), and its angle is that of its side",
    }


def pile_apart_warning(detached: int, particles: int) -> dict | None:
    """A pile test whose heap holds too little of its bed, or None.

    Args:
        detached: particle spheres above the base that are not the pile (``measure_pile``'s ``detached``);
            particles: the pile's own spheres (``particles``).

    More than :data:`PILE_APART_MAX` of them apart means a good part of the bed stayed where the test should
    have emptied it, or left the heap (in seed 002's screening with the surface energy times 25.6, 86 % of one
    cohesive phosphate bed never joined the heap, and the 14 % in it read 27.4 deg against 28.9-42.7 deg for the
    screening's other runs)."""
    total = detached + particles
    if total == 0 or detached <= PILE_APART_MAX * total:
        return None
    return {
        "check": "pile_apart",
        "detail": f"{detached} of the {total} particle spheres above the base ({100 * detached / total:.1f} %) are "
        f"not in the pile, more than {100 * PILE_APART_MAX:.0f} %: the bed hung in its cylinder or funnel, stuck "
        "to a wall or scattered, and the angle is that of the part that formed the heap",
    }
