"""The naming rule (pipeline.verdict) on constructed results: which verdict each combination of evidence gets.

The rule is fixed in code; these cases pin each of its clauses (likelihood-ratio test, held-out evidence against
the base and between contenders, interval excluding the off value, adequacy of the extended model)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("scipy")

from warpdem.diagnose import inference as inf  # noqa: E402
from warpdem.diagnose.candidates import Candidate  # noqa: E402
from warpdem.diagnose.pipeline import EVIDENCE, Dim, Model, verdict  # noqa: E402

BASE_DIM = Dim("mu_s", "interaction.a.a.static_friction", 0.1, 1.0)


def _held(z) -> pd.DataFrame:
    """Held-out rows with unit variance and standardised residuals ``z``."""
    r = np.asarray(z, dtype=float)
    return pd.DataFrame({"residual": r, "variance": 1.0, "nll": inf.gaussian_nll(r, np.ones_like(r))})


def _base(loglik=-40.0, held=(3.0, 3.5, 4.0)) -> dict:
    return {"loglik": loglik, "held_out": _held(held) if held is not None else None, "n_train": 6}


def _result(name, loglik, held, interval, adequate=True, off=0.0) -> dict:
    c = Candidate(name, f"interaction.a.a.{name}", off, 0.0, 1.0)
    return {
        "model": Model(name, [BASE_DIM, Dim(name, c.key, 0.0, 1.0)], candidate=c),
        "loglik": loglik,
        "n_train": 6,
        "theta": {name: sum(interval) / 2},
        "interval": {name: interval},
        "adequacy": {"adequate": adequate},
        "held_out": _held(held) if held is not None else None,
    }


def test_one_clear_winner_is_the_cause():
    res = [
        _result("plasticity", -3.0, (0.1, -0.2, 0.3), (0.5, 0.8)),
        _result("cohesion", -30.0, (2.9, 3.4, 4.0), (0.1, 0.3)),
    ]
    out = verdict(_base(), res, 0.05, seed=0)
    assert out["verdict"] == "cause" and out["cause"] == "plasticity"
    rows = {r["candidate"]: r for r in out["table"]}
    assert rows["plasticity"]["beats_base"] and not rows["cohesion"]["beats_base"]


def test_two_that_predict_alike_tie():
    res = [
        _result("shape", -3.0, (0.1, -0.2, 0.3), (0.5, 0.8)),
        _result("rolling_friction", -3.5, (0.3, 0.2, -0.4), (0.4, 0.9)),
    ]
    out = verdict(_base(), res, 0.05, seed=0)
    assert out["verdict"] == "ambiguous"
    assert sorted(out["tied"]) == ["rolling_friction", "shape"]


def test_a_winner_that_stays_inadequate_leaves_the_misfit_unexplained():
    res = [_result("plasticity", -3.0, (0.1, -0.2, 0.3), (0.5, 0.8), adequate=False)]
    out = verdict(_base(), res, 0.05, seed=0)
    assert out["verdict"] == "unexplained" and out["best"] == "plasticity"


def test_an_interval_that_holds_the_off_value_is_not_a_cause():
    res = [_result("plasticity", -3.0, (0.1, -0.2, 0.3), (0.0, 0.8))]
    assert verdict(_base(), res, 0.05, seed=0)["verdict"] == "unexplained"


def test_a_held_out_gain_within_the_evidence_threshold_does_not_contend():
    # summed held-out NLL of the base exceeds the candidate's by just under EVIDENCE nats
    z = np.array([1.0, 1.0, 1.0])
    zc = np.sqrt(np.maximum(z**2 - 2 * (EVIDENCE - 0.1) / 3, 0))
    res = [_result("plasticity", -3.0, zc, (0.5, 0.8))]
    out = verdict(_base(held=z), res, 0.05, seed=0)
    assert not out["table"][0]["beats_base"]
    assert out["verdict"] == "unexplained"


def test_a_likelihood_gain_that_is_not_significant_does_not_contend():
    res = [_result("plasticity", -39.5, (0.1, -0.2, 0.3), (0.5, 0.8))]
    out = verdict(_base(), res, 0.05, seed=0)
    assert out["table"][0]["p"] > 0.05 and out["verdict"] == "unexplained"


def test_without_held_out_data_the_aic_decides():
    res = [
        _result("plasticity", -3.0, None, (0.5, 0.8)),
        _result("cohesion", -30.0, None, (0.1, 0.3)),
    ]
    assert verdict(_base(held=None), res, 0.05, seed=0)["cause"] == "plasticity"
    res[1]["loglik"] = -3.0 - (EVIDENCE - 0.5)
    assert verdict(_base(held=None), res, 0.05, seed=0)["verdict"] == "ambiguous"


def test_held_out_gain_tests_each_model_against_the_noise():
    """``gain``'s ``noise_p``: the chi-square p of each model's held-out standardised errors on n degrees of freedom
    (no held-out row was fitted), per response and over both. Sums of squares at the published 5 % points of
    chi-square (7.815 on 3 df: NIST/SEMATECH's table) give p 0.05; a base that misses every held-out row by 3 SD
    gives 27 on 3 df, p 5.89e-6 (scipy); over both responses the sums add on 6 df. A response's RMSE is in its
    own units, its p in the noise budget's."""
    from scipy import stats

    from warpdem.diagnose.pipeline import gain

    z_ext = np.sqrt(7.815 / 3.0)  # three rows whose squares sum to chi-square's 5 % point on 3 df
    rows = [{"response": r, "variance": v, "base": 3.0, "ext": z_ext} for r, v in (("angle", 4.0), ("density", 100.0))]
    t = pd.DataFrame(rows * 3)

    def held(col):
        r = t[col].to_numpy() * np.sqrt(t["variance"].to_numpy())
        h = t[["response", "variance"]].copy()
        h["residual"], h["sq"] = r, r**2 / t["variance"].to_numpy()
        h["nll"] = inf.gaussian_nll(r, t["variance"].to_numpy())
        return h

    model = Model("base", [BASE_DIM])
    base = {"model": model, "held_out": held("base"), "theta": {"mu_s": 0.5}, "interval": {"mu_s": (0.4, 0.6)}}
    ext = {"model": model, "held_out": held("ext"), "theta": {"mu_s": 0.45}, "interval": {"mu_s": (0.3, 0.6)}}
    g = gain(None, base, ext, seed=0)
    for resp, sd in (("angle", 2.0), ("density", 10.0)):
        x = g["rmse"][resp]
        assert x["noise_p"]["extended"] == pytest.approx(0.05, abs=2e-4)
        assert x["noise_p"]["base"] == pytest.approx(5.887e-6, rel=1e-3)
        assert x["base"] == pytest.approx(3.0 * sd) and x["extended"] == pytest.approx(z_ext * sd)
    assert g["z_rms"]["noise_p"]["extended"] == pytest.approx(stats.chi2.sf(2 * 7.815, 6))  # 0.0159, not 0.05
    assert g["z_rms"]["noise_p"]["base"] == pytest.approx(stats.chi2.sf(54.0, 6))
