"""`warpdem bench` on tiny CPU beds: what it counts and which step it runs (no timing is checked)."""

import warnings

import numpy as np

from warpdem.verify.bench import DT, build_bed, run_bench

TINY = {"device": "cpu", "count": 100, "steps": 10, "settle_steps": 10}


def test_worlds_count_every_sphere():
    """Two batched worlds report worlds = 2 and twice the spheres of one world, at the plain bed's DT."""
    one = run_bench(**TINY)
    two = run_bench(**TINY, worlds=2)
    assert one["worlds"] == 1 and two["worlds"] == 2
    assert two["spheres"] == 2 * one["spheres"] > 0
    assert one["dt"] == two["dt"] == DT


def test_clump_bed_runs_within_rayleigh_limit():
    """The clump bed's 1 mm sub-spheres need a step below DT: the bench takes the solver's automatic step
    (<= 20 % of the Rayleigh time) instead of warning that DT under-resolves the contacts."""
    rayleigh = build_bed(TINY["count"], "cpu", clumps=8)[0].rayleigh_time
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = run_bench(**TINY, clumps=8)
    assert res["dt"] <= 0.2 * rayleigh < DT
    assert res["spheres"] == 8 * res["clumps"]


def test_shuffled_bed_is_the_same_bed_in_another_order():
    """--shuffle renumbers the spheres, nothing else: the same positions, a different order."""
    x = build_bed(200, "cpu")[0].initial["sphere_x"]
    y = build_bed(200, "cpu", shuffle=True)[0].initial["sphere_x"]
    assert not np.array_equal(x, y)
    assert np.array_equal(x[np.lexsort(x.T)], y[np.lexsort(y.T)])
