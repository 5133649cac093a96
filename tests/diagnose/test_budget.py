"""The noise budget and residuals of the diagnosis (pipeline.Problem.budget, Evaluator.residuals) on constructed
data: two responses, a subset of the observations (a held-out fold), against the formula written out by hand."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("scipy")

from warpdem.diagnose.pipeline import Evaluator, Problem  # noqa: E402


def _problem() -> Problem:
    obs = pd.DataFrame(
        {
            "id": ["A", "A", "B", "B"],
            "response": ["angle", "density", "angle", "density"],
            "condition": [0, 0, 1, 1],
            "mean": [30.0, 800.0, 25.0, 820.0],
            "n": [3, 3, 2, 2],
            "var_one": [0.25, 100.0, 0.25, 100.0],
            "split": ["train"] * 4,
        }
    )
    spec = SimpleNamespace(path="case.toml", confirm_seeds=2)
    prob = Problem(spec, SimpleNamespace(responses=["angle", "density"]), obs, [{}, {}])
    prob.seed_var = {"angle": 1.0, "density": 25.0}
    return prob


def test_budget_is_the_larger_scatter_over_n_plus_the_model_side():
    prob = _problem()
    k = np.array([2.0, 2.0, 4.0, 4.0])
    expect = np.array([1.0 / 3 + 1.0 / 2, 100.0 / 3 + 25.0 / 2, 1.0 / 2 + 1.0 / 4, 100.0 / 2 + 25.0 / 4])
    np.testing.assert_allclose(prob.budget(k), expect)


def test_roughness_does_not_average_over_seeds():
    """A response rough in the parameters but deaf to the seed (a press fill): k equal confirming runs leave the
    roughness whole, only the seed part shrinks with k."""
    prob = _problem()
    prob.seed_var = {"angle": 0.0, "density": 25.0}
    prob.rough_var = {"angle": 1.0, "density": 0.0}
    k = np.array([2.0, 2.0, 4.0, 4.0])
    expect = np.array([1.0 / 3 + 1.0, 100.0 / 3 + 25.0 / 2, 1.0 / 2 + 1.0, 100.0 / 2 + 25.0 / 4])
    np.testing.assert_allclose(prob.budget(k), expect)


def test_residuals_of_a_fold_with_two_responses():
    """A fold holds one condition's two responses: each residual gets its own response's budget with the number of
    simulations that measured it (a failed one drops out)."""
    prob = _problem()
    ev = Evaluator(prob, sims=None, log=print)
    conf = {1: {"values": np.array([[24.0, 810.0], [26.0, np.nan]]), "metrics": [{}, {}]}}
    mask = np.array([False, False, True, True])
    r, var = ev.residuals(conf, mask)
    np.testing.assert_allclose(r, [25.0 - 25.0, 820.0 - 810.0])
    np.testing.assert_allclose(var, [1.0 / 2 + 1.0 / 2, 100.0 / 2 + 25.0 / 1])


def test_trend_conditions_drop_repeats_and_columns_of_two_values():
    """A cylinder scaled with the grain repeats the radius's trend test; the count (radius^-3) does not; a
    column with two values has no trend to test."""
    radius = np.array([0.005, 0.0075, 0.01125])
    obs = pd.DataFrame(
        {
            "id": ["A", "B", "C"],
            "response": ["angle"] * 3,
            "condition": [0, 1, 2],
            "mean": [30.0, 28.0, 26.0],
            "n": [3] * 3,
            "var_one": [0.25] * 3,
            "split": ["train"] * 3,
            "particle_radius": radius,
            "inner_diameter": 22 * radius,
            "count": np.round(500 * (0.005 / radius) ** 3),
            "plate": [0.3, 0.8, 0.3],
        }
    )
    ex = SimpleNamespace(responses=["angle"], conditions=["particle_radius", "inner_diameter", "count", "plate"])
    prob = Problem(SimpleNamespace(path="case.toml"), ex, obs, [{}, {}, {}])
    assert prob.trend_conditions == ["particle_radius", "count"]


def test_design_levels_of_a_rig_parameter():
    """A parameter that cannot vary per world (a rig parameter: each value is a scene) takes LAUNCH_LEVELS
    values, evenly over its range; a per-world parameter keeps its Latin hypercube strata."""
    from warpdem.diagnose.pipeline import LAUNCH_LEVELS, Dim, design_points

    dims = [Dim("mu_r", "interaction.g.g.rolling_friction", 0.0, 0.5), Dim("shape", "aspect_ratio", 1.0, 2.5)]
    U = design_points(dims, 12, seed=3)
    assert U.shape == (12, 2)
    assert np.array_equal(np.sort(np.floor(U[:, 0] * 12)), np.arange(12))  # one point per stratum
    assert set(np.round(U[:, 1], 12)) == {0.0, 0.25, 0.5, 0.75, 1.0} and LAUNCH_LEVELS == 5


class _FixedSurrogate:
    """A surrogate that predicts ``mean`` with SD ``sd`` everywhere."""

    def __init__(self, mean: float, sd: float):
        self.mean, self.sd = mean, sd

    def predict(self, U):
        n = np.atleast_2d(U).shape[0]
        return np.full(n, self.mean), np.full(n, self.sd)


def _check(gp_means: dict, values: dict) -> dict:
    """surrogate_check of a two-condition problem whose confirming runs gave ``values`` ({condition: (seeds,
    responses)}) and whose surrogates predict ``gp_means`` ({(condition, response): mean}, SD 0.1)."""
    prob = _problem()
    prob.spec.alpha = 0.05
    ev = Evaluator(prob, sims=None, log=print)
    ev._confirmed = lambda fitted: [(c, fitted["u_map"], v) for c, v in values.items()]
    gps = {k: _FixedSurrogate(m, 0.1) for k, m in gp_means.items()}
    return ev.surrogate_check({"u_map": np.array([0.5]), "gps": gps})


def test_surrogate_check_against_chi_square_by_hand():
    """Confirmed means against the surrogates' predictions: z = (mean - prediction) / sqrt(0.1^2 + s_sim^2 / k),
    summed squares against chi-square with a degree of freedom per (condition, response); a failed run drops
    out of its mean."""
    from scipy import stats

    values = {0: np.array([[30.0, 805.0], [31.0, 815.0]]), 1: np.array([[26.0, 830.0], [27.0, np.nan]])}
    gp = {(0, "angle"): 30.0, (0, "density"): 800.0, (1, "angle"): 25.0, (1, "density"): 820.0}
    res = _check(gp, values)
    z = [
        (30.5 - 30.0) / np.sqrt(0.01 + 1.0 / 2),
        (810.0 - 800.0) / np.sqrt(0.01 + 25.0 / 2),
        (26.5 - 25.0) / np.sqrt(0.01 + 1.0 / 2),
        (830.0 - 820.0) / np.sqrt(0.01 + 25.0 / 1),
    ]
    stat = float(np.sum(np.square(z)))
    assert res["df"] == 4
    assert res["statistic"] == pytest.approx(stat)
    assert res["p"] == pytest.approx(stats.chi2.sf(stat, 4))
    assert res["max_abs_z"] == pytest.approx(max(abs(x) for x in z))


def test_surrogate_check_refines_only_a_miss():
    """Runs within their scatter of the prediction leave the calibration alone; runs 5 seed-SDs off refine it."""
    values = {0: np.array([[30.2, 801.0], [29.9, 798.0]]), 1: np.array([[25.3, 822.0], [24.8, 818.0]])}
    gp = {(0, "angle"): 30.0, (0, "density"): 800.0, (1, "angle"): 25.0, (1, "density"): 820.0}
    assert not _check(gp, values)["refine"]
    off = {0: values[0] + [5.0, 0.0], 1: values[1]}
    res = _check(gp, off)
    assert res["refine"] and res["p"] < 0.05


def test_step_checks_count_the_worlds_past_the_stable_step(tmp_path):
    """step_checks reads every stored world's info: those with a step warning are counted, with the largest margin
    among them; a world without one (or with no info) is counted as a world only."""
    import json

    from warpdem.diagnose.pipeline import step_checks

    runs = tmp_path / "runs"
    runs.mkdir()
    infos = [
        {"step_warning": "the step reached 1.35 ...", "step_margin_max": 1.35},
        {"step_warning": "the step reached 1.10 ...", "step_margin_max": 1.1},
        {"step_margin_max": 0.6},
        {},
    ]
    for k, info in enumerate(infos):
        (runs / f"w{k}.json").write_text(json.dumps({"metrics": {}, "info": info}))
    assert step_checks(runs) == {"worlds": 4, "over_stable_step": 2, "worst_step_margin": 1.35}
    assert step_checks(tmp_path / "none") == {"worlds": 0, "over_stable_step": 0, "worst_step_margin": None}
