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
        monkeypatch.setattr(pipeline, "_laws", lambda spec, ex, conds: ([], "no rolling friction here"))
        results, decision = reach.run(ev, SimpleNamespace(name="base"), ev.spec, ex, log=lambda *a: None)
        assert decision["verdict"] == verdict
        assert decision["scatter"]["angle"]["exceeds"] == (simulated[0] == 28.0)
        assert decision["rolling_models"]["law"] is None and decision["cause"] is None


BASE_RUNS = [28.0, 31.0, 33.0]
"""The base model's confirming runs at its closest point: SD 2.52 on 2 df, against replicates 30.0, 30.1, 29.9."""


STRENGTH = {"cohesion_strength.base": 10.0, "cohesion_strength.surface_energy": 0.5, "cohesion_strength.target": "g"}
"""The shared overrides of the constructed cases' cohesion_strength candidate."""


def _law_case(
    monkeypatch,
    law_runs: dict,
    law_reaches: dict | None = None,
    pair_runs: dict | None = None,
    pair_reaches: dict | None = None,
    pair_x: float = -0.7,
):
    """An OVERDISPERSED base (:data:`BASE_RUNS`) and two rolling models whose confirming runs are ``law_runs``
    ({model: runs}) and which reach the data as ``law_reaches`` says (default: both). With ``pair_runs``, each
    model with the cohesion weakened (closest point x = ``pair_x``) has those runs and reaches as ``pair_reaches``
    says (default: all); without, the strength candidate does not apply. Returns the decision and the names of the
    models that ran."""
    from warpdem.diagnose import candidates as cands
    from warpdem.diagnose import pipeline

    ev, ex, base_res = _case(False, [30.0, 30.1, 29.9], BASE_RUNS)
    reaches = {m: True for m in law_runs} | (law_reaches or {})
    paired = {m: True for m in pair_runs or {}} | (pair_reaches or {})
    switches = [cands.LawSwitch(m, {"interaction.grain.grain.rolling_model": m}) for m in law_runs]
    strength = cands.Candidate("cohesion_strength", cands.STRENGTH_EXPONENT, 0.0, -1.0, 0.0, "log10", STRENGTH)
    ev.sims = SimpleNamespace(run=lambda *a: [])
    ev.design_requests = lambda models: []
    ran = []

    def finish(ev, f):
        m = f["model"]
        ran.append(m.name)
        if m.law is None:
            return {**base_res, "reaches": True}
        if m.candidate is not None:
            runs = np.asarray(pair_runs[m.law.model], float)[:, None]
            return {
                "confirm": {0: {"values": runs}},
                "reaches": paired[m.law.model],
                "theta": {m.candidate.name: pair_x},
            }
        runs = np.asarray(law_runs[m.law.model], float)[:, None]
        return {"confirm": {0: {"values": runs}}, "reaches": reaches[m.law.model], "theta": {}}

    monkeypatch.setattr(reach, "fit", lambda ev, model: {"requests": [], "model": model})
    monkeypatch.setattr(reach, "finish", finish)
    monkeypatch.setattr(pipeline, "_laws", lambda spec, ex, conds: (switches, None))
    monkeypatch.setattr(
        pipeline, "_strength", lambda spec, ex, conds: (strength, None) if pair_runs else (None, "no cohesion here")
    )
    results, decision = reach.run(ev, pipeline.Model("base", []), ev.spec, ex, log=lambda *a: None)
    assert decision["verdict"] == "overdispersed" and set(results) == set(ran)
    return decision, ran


def test_a_rolling_model_that_repeats_is_named(monkeypatch):
    """The hidden effect: one rolling model's runs repeat (SD 0.025 against the replicates' 0.1), the other's
    scatter as the base's. The base's variance over the first's is F = 6.33 / 0.00063 on (2, 2) df, whose
    one-sided p is 1 / (1 + F); Holm over the two tests doubles the smaller. The first is named, the verdict stays
    OVERDISPERSED (the base model is what was tested)."""
    d, ran = _law_case(monkeypatch, {"standard": [29.98, 30.0, 30.03], "constant_torque": [27.0, 30.0, 34.0]})
    rm = d["rolling_models"]
    good, bad = rm["tried"]["rolling_model=standard"], rm["tried"]["rolling_model=constant_torque"]
    g = good["gain"]["angle"]
    assert g["F"] == pytest.approx(np.var(BASE_RUNS, ddof=1) / np.var([29.98, 30.0, 30.03], ddof=1), rel=1e-9)
    assert g["p"] == pytest.approx(1.0 / (1.0 + g["F"]), rel=1e-9)
    assert g["p_holm"] == pytest.approx(2.0 * g["p"], rel=1e-9) and g["significant"]
    assert good["repeats"] and not good["scatter"]["angle"]["exceeds"]
    assert not bad["repeats"] and bad["scatter"]["angle"]["exceeds"] and not bad["gain"]["angle"]["significant"]
    assert rm["repeating"] == ["rolling_model=standard"] and rm["law"] == "standard" and d["cause"] == "rolling_model"
    words = reach.law_words(d)
    assert words.startswith("the rolling model standard reaches the data and repeats (angle: variance ratio")
    assert reach._cause_words(d) == "rolling-resistance model (type A, C or EDEM standard): standard"
    rows = [line for line in reach._laws_markdown(rm, {}) if line.startswith("| standard")]
    assert len(rows) == 1 and rows[0].endswith("| yes |")
    assert rm["with"] is None and rm["pairs_not_tried"] == "a rolling model alone repeats"
    assert not any("+" in n for n in ran)  # no two-change model once one law alone repeats


def test_no_rolling_model_that_repeats_names_none(monkeypatch):
    """No effect: both rolling models scatter as the base does (SD 2.5-3.5 against 0.1): none is named, and the
    verdict line says so."""
    d, _ = _law_case(monkeypatch, {"standard": [27.5, 31.0, 32.5], "constant_torque": [27.0, 30.0, 34.0]})
    rm = d["rolling_models"]
    assert not rm["repeating"] and rm["law"] is None and d["cause"] is None
    assert all(law["scatter"]["angle"]["exceeds"] for law in rm["tried"].values())
    assert reach.law_words(d) == (
        "none of the rolling models tried (standard, constant_torque) reaches the data and repeats"
    )


def test_a_rolling_model_must_reach_the_data_to_be_named(monkeypatch):
    """Runs that repeat far from the data's mean do not explain the scatter: a model that repeats but does not
    reach is not named; two that reach and repeat are both listed and neither is named."""
    tight = [29.98, 30.0, 30.03]
    d, _ = _law_case(monkeypatch, {"standard": tight, "epsd": tight}, {"standard": False})
    assert d["rolling_models"]["repeating"] == ["rolling_model=epsd"] and d["rolling_models"]["law"] == "epsd"
    d, _ = _law_case(monkeypatch, {"standard": tight, "epsd": tight})
    rm = d["rolling_models"]
    assert rm["repeating"] == ["rolling_model=standard", "rolling_model=epsd"] and rm["law"] is None
    assert "cannot tell them apart" in reach.law_words(d)


SCATTER = {"standard": [27.5, 31.0, 32.5], "constant_torque": [27.0, 30.0, 34.0]}
"""Two rolling models whose runs scatter as the base's (SD 2.5-3.5 against the replicates' 0.1)."""


def test_a_rolling_model_that_repeats_only_with_weaker_cohesion_is_named(monkeypatch):
    """The hidden effect seed 001 showed: no rolling model alone repeats, but one does with the surface energy
    weakened (its closest point at x = -0.7, a factor 10^-0.7 = 0.20). Both two-change models run, after the
    single ones; Holm runs over the four tests (the best pair's p times four, the single laws' tests included); the
    pair is named with its factor, and the words say both changes."""
    tight = [29.98, 30.0, 30.03]
    d, ran = _law_case(monkeypatch, SCATTER, pair_runs={"standard": tight, "constant_torque": [26.0, 30.5, 33.0]})
    assert ran[:3] == ["base", "rolling_model=standard", "rolling_model=constant_torque"]
    assert ran[3:] == ["rolling_model=standard+cohesion_strength", "rolling_model=constant_torque+cohesion_strength"]
    rm = d["rolling_models"]
    good = rm["tried"]["rolling_model=standard+cohesion_strength"]
    g = good["gain"]["angle"]
    assert g["p"] == pytest.approx(1.0 / (1.0 + np.var(BASE_RUNS, ddof=1) / np.var(tight, ddof=1)), rel=1e-9)
    assert g["p_holm"] == pytest.approx(4.0 * g["p"], rel=1e-9) and good["repeats"]
    assert good["with"]["name"] == "cohesion_strength" and good["with"]["factor"] == pytest.approx(10**-0.7)
    assert rm["repeating"] == ["rolling_model=standard+cohesion_strength"] and d["cause"] == "rolling_model"
    assert rm["law"] == "standard" and rm["with"] == good["with"]
    assert not any(law["repeats"] for n, law in rm["tried"].items() if n != "rolling_model=standard+cohesion_strength")
    assert reach.law_words(d).startswith(
        "the rolling model standard with the surface energy times 0.2 (cohesion_strength) reaches the data and repeats"
    )
    words = reach._cause_words(d)
    assert words.startswith("rolling-resistance model (type A, C or EDEM standard): standard with the surface energy")
    assert words.endswith("; and cohesion too strong for the grains (the surface energy weakened)")
    lines = reach._laws_markdown(rm, {})
    assert any(line.startswith("No rolling model alone repeated") for line in lines)
    rows = [line for line in lines if line.startswith("| standard with the surface energy times 0.2")]
    assert len(rows) == 1 and rows[0].endswith("| yes |")


def test_no_two_change_model_that_repeats_names_none(monkeypatch):
    """No effect: the pairs scatter as the base does, or repeat without reaching the data: none is named, and the
    verdict line says the laws were tried alone and with a weaker cohesion."""
    d, ran = _law_case(monkeypatch, SCATTER, pair_runs=SCATTER)
    rm = d["rolling_models"]
    assert len(ran) == 5 and not rm["repeating"] and rm["law"] is None and rm["with"] is None and d["cause"] is None
    assert reach.law_words(d) == (
        "none of the rolling models tried (standard, constant_torque), alone or with a weaker cohesion, reaches the "
        "data and repeats"
    )
    tight = [29.98, 30.0, 30.03]
    d, _ = _law_case(
        monkeypatch,
        SCATTER,
        pair_runs={"standard": tight, "constant_torque": tight},
        pair_reaches={"standard": False, "constant_torque": False},
    )
    assert not d["rolling_models"]["repeating"] and d["cause"] is None


def test_a_model_too_few_runs_can_judge_is_pointed_out(monkeypatch):
    """Seed 001's case on the GPU: a pair whose runs (SD 0.35 on 2 df) do not exceed the replicates' scatter (SD 0.1:
    F 12.25 on (2, 2), p 0.075) but cannot show the base scatters more (F 6.33 / 0.1225 = 51.7, p 0.019, times four
    by Holm 0.076): not named, and the verdict line says more confirming seeds would decide. A pair that does not
    reach the data is not pointed out."""
    loose = [29.65, 30.0, 30.35]
    d, _ = _law_case(monkeypatch, SCATTER, pair_runs={"standard": loose, "constant_torque": SCATTER["standard"]})
    rm = d["rolling_models"]
    pair = rm["tried"]["rolling_model=standard+cohesion_strength"]
    assert pair["gain"]["angle"]["p"] == pytest.approx(1.0 / (1.0 + np.var(BASE_RUNS, ddof=1) / 0.1225), rel=1e-9)
    assert pair["gain"]["angle"]["p_holm"] == pytest.approx(4.0 * pair["gain"]["angle"]["p"], rel=1e-9)
    assert pair["scatter"]["angle"]["p"] == pytest.approx(1.0 / (1.0 + 12.25), rel=1e-9)
    assert not pair["gain"]["angle"]["significant"] and not pair["scatter"]["angle"]["exceeds"]
    assert d["cause"] is None and reach.undecided(rm) == ["rolling_model=standard+cohesion_strength"]
    words = reach.law_words(d)
    assert words.endswith(
        "; standard with the surface energy times 0.2 (cohesion_strength) reaches it within the measurement's "
        "scatter, but too few confirming runs to show less scatter than the base: more confirming seeds "
        "([calibration] confirm_seeds) would decide"
    )
    d, _ = _law_case(
        monkeypatch,
        SCATTER,
        pair_runs={"standard": loose, "constant_torque": loose},
        pair_reaches={"standard": False, "constant_torque": False},
    )
    assert reach.undecided(d["rolling_models"]) == [] and "would decide" not in reach.law_words(d)


def test_no_two_change_model_without_a_surface_energy(monkeypatch):
    """Where the strength candidate does not apply, only the single laws run and the report says why no pair
    was tried."""
    d, ran = _law_case(monkeypatch, SCATTER)
    assert len(ran) == 3 and d["rolling_models"]["pairs_not_tried"] == "no cohesion here"
    assert "No two-change model was tried: no cohesion here." in reach._laws_markdown(d["rolling_models"], {})


def test_rolling_alternatives_of_a_rig_scene():
    """The smoke funnel's spheres roll with EPSD: the alternatives are type A (constant torque) and EDEM's
    standard model, each set on the grain-grain pair and the grain's pairs with rolling friction (not the walls'
    own pairs). A key the data file decides, or no rolling friction, leaves none."""
    from warpdem.diagnose import candidates as cands
    from warpdem.scene import rigs
    from warpdem.scene.stage import apply_overrides

    scene = rigs.spec("funnel", dict(rigs.SMOKE["funnel"]), True)
    laws, why = cands.rolling_alternatives(scene, set())
    assert why is None and [law.model for law in laws] == ["constant_torque", "standard"]
    keys = set(laws[0].shared)
    assert "interaction.grain.grain.rolling_model" in keys and all(".grain." in k for k in keys)
    assert all(set(law.shared.values()) == {law.model} and law.name == f"rolling_model={law.model}" for law in laws)
    laws, why = cands.rolling_alternatives(scene, {"interaction.grain.grain.rolling_model"})
    assert not laws and "decided by the data file" in why
    scene = apply_overrides(scene, {"interaction.grain.grain.rolling_friction": 0.0})
    laws, why = cands.rolling_alternatives(scene, set())
    assert not laws and "rolling friction is 0" in why


def test_the_reach_picture_keeps_every_label_and_marker_in_view(monkeypatch, tmp_path):
    """Seed 001's five models (the two-change names run to 40 characters): every tick label, the title and the
    legend lie inside the figure, and the legend covers no model's diamond (inside the axes it hid the base's)."""
    ev, _, _ = _case(True, [54.0, 55.0, 54.5], [50.0, 51.0, 52.0])
    names = [
        "base",
        "rolling_model=constant_torque",
        "rolling_model=standard",
        "rolling_model=constant_torque+cohesion_strength",
        "rolling_model=standard+cohesion_strength",
    ]
    results = {
        n: {"span": [(22.5 + k, 80.0 - k)], "simulated": [48.0 + 4 * k], "reaches": True} for k, n in enumerate(names)
    }
    figs = []

    def keep(fig, path, **kw):
        fig.canvas.draw()
        figs.append(fig)

    monkeypatch.setattr(reach, "save_figure", keep)
    monkeypatch.setattr("matplotlib.pyplot.close", lambda fig: None)
    assert reach._plot(tmp_path, ev.prob, results) == ["reach_angle_0.png"]
    (fig,) = figs
    r = fig.canvas.get_renderer()
    box = fig.bbox
    ax = fig.axes[0]
    texts = [*ax.get_yticklabels(), ax.xaxis.label, fig._suptitle or ax.title]
    (legend,) = fig.legends or [ax.get_legend()]  # the figure's or the axes', wherever it is drawn
    for t in texts:
        e = t.get_window_extent(r)
        assert e.x0 >= box.x0 - 0.5 and e.x1 <= box.x1 + 0.5 and e.y0 >= box.y0 - 0.5 and e.y1 <= box.y1 + 0.5, t
    assert [t.get_text() for t in ax.get_yticklabels()] == names
    lb = legend.get_window_extent(r)
    assert box.x0 <= lb.x0 and lb.x1 <= box.x1 and box.y0 <= lb.y0 and lb.y1 <= box.y1
    for k in range(len(names)):
        x, y = ax.transData.transform((48.0 + 4 * k, k))
        assert not (lb.x0 <= x <= lb.x1 and lb.y0 <= y <= lb.y1), names[k]
