"""Warnings of suspect physics (warpdem.engine.suspect): overlaps measured against the geometry, the thresholds
applied as documented, and the warnings of a real run: a pour too fast for its step, a material too soft, two
spheres placed on top of each other."""

import warnings

import numpy as np
import pytest

import warpdem as wd
from warpdem.engine import suspect


def test_overlaps_are_the_geometry():
    """Two unit spheres 1.9 apart overlap by 0.1 of a radius; the same pair in two different worlds, or as two
    spheres of one clump, does not count; coincident centres are counted as such."""
    x = np.array([[0, 0, 0], [1.9, 0, 0], [10, 0, 0], [11.5, 0, 0], [20, 0, 0], [20, 0, 0]], dtype=float)
    r = np.array([1, 1, 1, 1, 0.5, 0.5])
    world = np.array([0, 0, 0, 1, 1, 1])
    body = np.array([0, 1, 2, 3, 4, 5])
    got = suspect.overlaps(x, r, world, body, 2)
    assert got["deepest"][0] == pytest.approx(0.1) and got["pairs"].tolist() == [1, 1]
    assert got["deepest"][1] == pytest.approx(2.0) and got["coincident"].tolist() == [0, 1]
    # spheres 2 (world 0) and 3 (world 1) are 1.5 apart: different worlds never touch
    same_body = suspect.overlaps(x[:2], r[:2], world[:2], np.array([7, 7]), 1)
    assert same_body["deepest"][0] == 0.0 and same_body["pairs"][0] == 0


def test_overlaps_mean_is_over_the_touching_pairs():
    """Pairs overlapping by 0.1 and 0.3 of a radius average 0.2; a pair apart adds nothing to the mean, and a
    world without contacts reads 0."""
    x = np.array([[0, 0, 0], [1.9, 0, 0], [10, 0, 0], [11.7, 0, 0], [20, 0, 0], [22.5, 0, 0]], dtype=float)
    got = suspect.overlaps(x, np.ones(6), np.zeros(6, dtype=int), np.arange(6), 2)
    assert got["mean"][0] == pytest.approx(0.2) and got["deepest"][0] == pytest.approx(0.3)
    assert got["mean"][1] == 0.0


def test_the_soft_check_reads_the_heaviest_load_where_it_is_deeper():
    """A press's bed at its force limit overlaps deeper than the unloaded bed at the end: the warning gives the
    peak's deepest and mean contact; a peak shallower than the end leaves the end's words."""
    start = {"deepest": 0.0, "pairs": 0, "coincident": 0}
    deep = suspect.world_warnings(0, 100, 0.1, (1e-5, 1e-5), start, 0.05, {"deepest": 1.14, "mean": 0.18})
    assert [w["check"] for w in deep] == ["soft"]
    assert "114 % of the smaller radius at the heaviest load (the mean contact by 18 %)" in deep[0]["detail"]
    shallow = suspect.world_warnings(0, 100, 0.1, (1e-5, 1e-5), start, 0.5, {"deepest": 0.2, "mean": 0.01})
    assert "50 % of the smaller radius at the end" in shallow[0]["detail"]
    assert suspect.world_warnings(0, 100, 0.1, (1e-5, 1e-5), start, 0.05, {"deepest": 0.1, "mean": 0.01}) == []


def test_escape_threshold():
    """No sphere past the bar: no warning; two: the count and the clearance in mm."""
    assert suspect.escape_warning(0, 1e-4) is None
    hit = suspect.escape_warning(2, 1e-4)
    assert hit["check"] == "escaped" and hit["detail"].startswith("2 spheres") and "0.1 mm" in hit["detail"]


def test_thresholds():
    """A world loses up to LOST_FRACTION_MAX of its bodies quietly; a body may move STEP_TRAVEL_MAX radii per
    step; the end overlap may reach OVERLAP_MAX: just past each, one warning of its kind."""
    quiet = suspect.world_warnings(2, 100, 0.5, (1e-5, 1e-5), {"deepest": 0.01, "pairs": 0, "coincident": 0}, 0.1)
    assert quiet == []
    loud = suspect.world_warnings(3, 100, 0.51, (1e-5, 2e-5), {"deepest": 0.5, "pairs": 2, "coincident": 1}, 0.11)
    assert [w["check"] for w in loud] == ["lost", "fast", "start_overlap", "soft"]
    assert loud[0]["detail"].startswith("3 of 100 bodies (3.0 %) left the domain")
    assert "0.51 radii" in loud[1]["detail"] and "dt 2e-05 s" in loud[1]["detail"]
    assert "2 pairs" in loud[2]["detail"] and "1 of them with coincident centres" in loud[2]["detail"]
    assert "11 %" in loud[3]["detail"]


def test_outlet_threshold():
    """A pile whose top comes within one particle diameter of its funnel's outlet is flagged, one just below is
    not; the words give both heights in mm."""
    assert suspect.outlet_warning(0.0989, 0.1, 0.001) is None
    hit = suspect.outlet_warning(0.0991, 0.1, 0.001)
    assert hit["check"] == "outlet" and "(99 mm)" in hit["detail"] and "(100 mm)" in hit["detail"]


def test_off_axis_threshold():
    """A pile whose centre of mass lies beyond the radius it was poured within is flagged, one within it is not;
    the words give both distances in mm."""
    assert suspect.off_axis_warning(0.0199, 0.02) is None
    hit = suspect.off_axis_warning(0.0261, 0.02)
    assert hit["check"] == "off_axis" and "26.1 mm off" in hit["detail"] and "the 20 mm it" in hit["detail"]


def test_pile_apart_threshold():
    """A heap holding less than four fifths of the spheres above its base is flagged, with both counts and the
    share; one holding four fifths is not, nor an empty world."""
    assert suspect.pile_apart_warning(20, 80) is None
    assert suspect.pile_apart_warning(0, 0) is None
    hit = suspect.pile_apart_warning(109590, 17835)
    assert hit["check"] == "pile_apart" and "109590 of the 127425" in hit["detail"] and "(86.0 %)" in hit["detail"]


def test_coincident_spheres_warn_at_finalize():
    """Two spheres placed at one point: finalize warns (they would push in no direction and stay together);
    two spheres apart do not."""

    def builder(second):
        b = wd.ModelBuilder()
        b.add_material(wd.Material("m", density=1000, shear_modulus=1e7, poisson_ratio=0.3))
        b.add_spheres([(0, 0, 0), second], radius=0.001, material="m")
        return b

    with pytest.warns(UserWarning, match="1 pairs .* coincident centres"):
        builder((0, 0, 0))._warn_start_overlaps()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        builder((0.003, 0, 0))._warn_start_overlaps()
