"""The reach diagnosis's repeatability check (reach.repeatability, inference.scatter_excess) on constructed data:
the statistic against published table values, which scatter it compares, and the verdict it turns."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("scipy")

from warpdem.diagnose import inference as inf  # noqa: E402
from warpdem.diagnose import reach  # noqa: E402
from warpdem.diagnose.pipeline import Problem  # noqa: E402
from warpdem.errors import InputError  # noqa: E402


def test_scatter_excess_at_published_critical_values():
    """At the upper 5 % points of F(2, 4) = 6.94 and of chi-square(2) = 5.99 (e.g. NIST/SEMATECH e-Handbook,
    tables 1.3.6.7.3 and 1.3.6.7.4) the p-value is 0.05; at F(3, 8) = 4.07 too; a model that scatters less than
    the measurement is no evidence (p above one half)."""
    assert inf.scatter_excess(6.944, 2, 1.0, 4)[1] == pytest.approx(0.05, abs=2e-4)
    assert inf.scatter_excess(2 * 4.066, 3, 2.0, 8)[1] == pytest.approx(0.05, abs=2e-4)
    f, p = inf.scatter_excess(5.991 / 2, 2, 1.0, math.inf)
    assert f == pytest.approx(2.9955) and p == pytest.approx(0.05, abs=2e-4)
    assert inf.scatter_excess(0.5, 4, 1.0, 4)[1] > 0.5
    with pytest.raises(InputError, match="degrees of freedom"):
        inf.scatter_excess(1.0, 0, 1.0, 4)
    with pytest.raises(InputError, match="variances"):
        inf.scatter_excess(1.0, 2, 0.0, 4)


def _case(stated: bool, measured, simulated) -> tuple[SimpleNamespace, SimpleNamespace, dict]:
    """One experiment, one response ``angle``: ``measured`` replicates (stated SD 1.0 when ``stated``) and
    ``simulated`` confirming runs at the closest point."""
    measured = np.asarray(measured, float)
    table = pd.DataFrame({"id": ["A"] * len(measured), "angle": measured, "sd_angle": 1.0 if stated else np.nan})
    sd = 1.0 if stated else float(measured.std(ddof=1))
    obs = pd.DataFrame(
        {
            "id": ["A"],
            "response": ["angle"],
            "condition": [0],
            "mean": [measured.mean()],
            "n": [len(measured)],
            "var_one": [sd**2],
            "split": ["train"],
        }
    )
    ex = SimpleNamespace(
        table=table,
        responses=["angle"],
        replicate_sd=lambda r: (float(table[r].std(ddof=1)), len(table) - 1),
    )
    spec = SimpleNamespace(path="case.toml", confirm_seeds=len(simulated), alpha=0.05)
    prob = Problem(spec, ex, obs, [{}])
    ev = SimpleNamespace(prob=prob, responses=["angle"], spec=spec)
    res = {"confirm": {0: {"values": np.asarray(simulated, float)[:, None]}}}
    return ev, ex, res


def test_replicates_against_the_model_runs():
    """Replicates 30.0, 30.1, 29.9 (SD 0.1, 2 df) against runs 28, 31, 33 (SD 2.52, 2 df): F = 633.3 on (2, 2),
    p = 1 / (1 + F) for two and two degrees of freedom."""
    ev, ex, res = _case(False, [30.0, 30.1, 29.9], [28.0, 31.0, 33.0])
    s = reach.repeatability(ev, ex, res)["angle"]
    assert s["measured_df"] == 2 and s["simulated_df"] == 2
    assert s["F"] == pytest.approx(np.var([28, 31, 33], ddof=1) / 0.01)
    assert s["p"] == pytest.approx(1.0 / (1.0 + s["F"]), rel=1e-9) and s["exceeds"]
    assert s["ratio"] == pytest.approx(math.sqrt(s["F"]))
    assert "angle: SD 2.52 against 0.1, p" in reach.scatter_words({"angle": s})


def test_a_stated_sd_is_taken_as_known():
    """A stated SD of 1.0 (the replicates' own scatter ignored, as the noise budget ignores it): runs with SD
    1.2 on 2 df give chi-square 2 * 1.44 on 2 df, p = exp(-1.44): no evidence."""
    ev, ex, res = _case(True, [30.0, 30.1, 29.9], [28.8, 30.0, 31.2])
    s = reach.repeatability(ev, ex, res)["angle"]
    assert s["measured_df"] is None and s["measured_sd"] == pytest.approx(1.0)
    assert s["p"] == pytest.approx(math.exp(-1.44), rel=1e-9) and not s["exceeds"]


def test_the_verdict_turns_only_when_the_base_reaches(monkeypatch):
    """The base reaches the mean: OVERDISPERSED when its runs scatter more, NOT TESTABLE when not. Out of reach,
    the scatter is reported and the candidates decide (none here: UNEXPLAINED)."""
    from warpdem.diagnose import pipeline

    for simulated, reaches, verdict in (
        ([28.0, 31.0, 33.0], True, "overdispersed"),
        ([29.95, 30.0, 30.08], True, "not_testable"),
        ([28.0, 31.0, 33.0], False, "unexplained"),
    ):
        ev, ex, res = _case(False, [30.0, 30.1, 29.9], simulated)
        ev.sims = SimpleNamespace(run=lambda *a: [])
        monkeypatch.setattr(reach, "fit", lambda ev, model: {"requests": []})
        monkeypatch.setattr(reach, "finish", lambda ev, f, res=res, ok=reaches: {**res, "reaches": ok})
        monkeypatch.setattr(pipeline, "_library", lambda spec, ex, conds: ([], {}))
        results, decision = reach.run(ev, SimpleNamespace(name="base"), ev.spec, ex, log=lambda *a: None)
        assert decision["verdict"] == verdict
        assert decision["scatter"]["angle"]["exceeds"] == (simulated[0] == 28.0)
