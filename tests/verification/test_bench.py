"""`warpdem bench` on tiny CPU beds: what it counts and which step it runs (no timing is checked)."""

import warnings

import numpy as np
import pytest

from warpdem import RollingModel
from warpdem.verify.bench import DT, ROLLING_FRICTION, build_bed, run_bench

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


def test_rolling_bed_gives_every_pair_the_model():
    """--rolling sets the named model with mu_r = ROLLING_FRICTION on every pair (the default bed has mu_r = 0); an
    unknown model is refused with the allowed ones."""
    plain = build_bed(100, "cpu")[0].pair_params.numpy()
    std = build_bed(100, "cpu", clumps=8, rolling="standard")[0].pair_params.numpy()
    assert np.all(plain["mu_r"] == 0.0)
    assert np.all(std["rolling_model"] == RollingModel.STANDARD)
    assert np.allclose(std["mu_r"], ROLLING_FRICTION)
    with pytest.raises(ValueError, match="rolling = 'type_b'.*none, constant_torque, epsd, standard"):
        build_bed(100, "cpu", rolling="type_b")
