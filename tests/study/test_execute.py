"""Study execution: batched worlds, one result file per finished point, resume after a crash, analysis and
verification. The scene is the smoke funnel cut to 40 spheres and 0.3 s, so each launch takes seconds."""

from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pandas as pd
import pytest

from warpdem.study import execute
from warpdem.study.spec import StudyError, load_study

pytest.importorskip("warp")

STUDY = """
[study]
name = "tiny"
rig = "funnel"
smoke = true
seed = 3
batch = {batch}

[fixed]
count = 40
duration = 0.3
# a fixed step: one the solver halves for the stiffest contact is the batch's, so another split of the study
# could step differently (SolverOptions.dt_levels)
"run.dt_levels" = 0
# 40 grains poured for 0.3 s lie scattered in one layer, not in a pile: measure every grain on the base
"measure.pile_apart" = 0.0

[[factors]]
name = "A"
parameter = "interaction.grain.grain.static_friction"
low = 0.2
high = 0.8

[[factors]]
name = "B"
parameter = "interaction.grain.grain.rolling_friction"
low = 0.05
high = 0.3

[design]
kind = "full_factorial"
center_points = 2

[[responses]]
name = "height"
measure = "pile_height_m"
unit = "m"
target = {target}

[analysis]
model = "linear"

[verification]
replicates = {verify}
"""


def _study(tmp_path, batch=0, target=0.0, verify=0):
    path = tmp_path / "tiny.toml"
    path.write_text(STUDY.format(batch=batch, target=target, verify=verify))
    return load_study(path)


def _run(study, out, **kw):
    return execute.run_study(study, out, progress=False, log=lambda *a: None, **kw)


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """The tiny study run once in one batch (6 worlds: 4 corners and 2 centre points)."""
    tmp = tmp_path_factory.mktemp("study")
    study = _study(tmp)
    res = _run(study, tmp / "out", analyze_after=False)
    return study, tmp / "out", res


def test_a_log_file_in_the_output_folder(finished):
    """The study keeps log.txt in its output folder, time-stamped, whatever the console got (the fixture's log
    callable drops every line): the study file and device, the launch with its runs, worlds and wall time, and
    the count of finished runs."""
    study, out, _ = finished
    text = (out / "log.txt").read_text()
    assert f"{study.name}: study {study.path} on cpu" in text
    assert "launch 1 of 1 done after" in text and "(runs 1, 2, 3, 4, 5, 6): 6 world(s) saved" in text
    assert "6 of 6 runs finished (6 now, in" in text
    assert all(line[:4].isdigit() for line in text.splitlines())


def test_one_launch_one_file_per_point(finished):
    """All six runs share the scene, so they run as six worlds of one launch, and each finished point has
    its own result file named by its point id, holding its overrides and a finite response."""
    study, out, res = finished
    assert res["runs"] == 6 and res["ran"] == 6 and res["batches"] == 1
    table = execute.load_results(out, study)
    for _, row in table.iterrows():
        rec = json.loads((out / "runs" / f"{row['point_id']}.json").read_text())
        assert rec["info"]["batch_worlds"] == 6
        assert rec["overrides"]["interaction.grain.grain.static_friction"] == pytest.approx(row["A_actual"])
        assert math.isfinite(rec["responses"]["height"]) and rec["responses"]["height"] > 0


def test_centre_points_differ_by_world_seed(finished):
    """The two centre points have the same parameters; only their world seeds differ, so their responses
    differ (the engine is deterministic: equal seeds would give equal piles and no pure error)."""
    study, out, _ = finished
    table = execute.load_results(out, study)
    centre = table[table["point_type"] == "centre"]
    assert sorted(centre["world_seed"]) == [0, 1]
    assert centre["height"].iloc[0] != centre["height"].iloc[1]


def test_rerun_resumes_without_recomputing(finished):
    """Running the same study again finds every point finished and launches nothing."""
    study, out, _ = finished
    before = {p.name: p.stat().st_mtime_ns for p in (out / "runs").glob("*.json")}
    res = _run(study, out, analyze_after=False)
    assert res["ran"] == 0 and res["skipped"] == 6 and res["batches"] == 0
    assert {p.name: p.stat().st_mtime_ns for p in (out / "runs").glob("*.json")} == before


def test_crash_loses_nothing_finished(tmp_path, monkeypatch):
    """With at most 2 worlds per launch the study is 3 launches; a crash in the second leaves the first
    launch's 2 results on disk (whole files, no temporaries), and the rerun runs only the other 4."""
    study = _study(tmp_path, batch=2)
    out = tmp_path / "out"
    real = execute.run_batch_iter
    calls = []

    def crashing(*a, **kw):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt("killed")
        return real(*a, **kw)

    monkeypatch.setattr(execute, "run_batch_iter", crashing)
    with pytest.raises(KeyboardInterrupt):
        _run(study, out, analyze_after=False)
    assert len(list((out / "runs").glob("*.json"))) == 2
    assert not list((out / "runs").glob("*.tmp"))
    monkeypatch.setattr(execute, "run_batch_iter", real)
    res = _run(study, out, analyze_after=False)
    assert res["skipped"] == 2 and res["ran"] == 4 and res["batches"] == 2
    assert len(list((out / "runs").glob("*.json"))) == 6


def test_another_study_in_the_folder_is_refused(finished, tmp_path):
    study, out, _ = finished
    other = tmp_path / "other.toml"
    other.write_text(STUDY.format(batch=0, target=0.0, verify=0).replace('name = "tiny"', 'name = "other"'))
    with pytest.raises(ValueError, match="holds study 'tiny', not 'other'"):
        _run(load_study(other), out)


def test_analysis_and_verification(finished, tmp_path):
    """The analysis of the finished runs writes report.md and the ANOVA; with a target inside the fitted
    range the chosen settings predict it, and the verification runs (2 replicates, world seeds 1 and 2) are
    summarised with mean, SD and relative error against the target, and judged against the prediction interval
    for a mean of 2 runs at the chosen point, in verification.json and report.md; a verification launch stopped
    by the wall-time limit resumes from its checkpoint."""
    study, out, _ = finished
    table = execute.load_results(out, study)
    target = float(table["height"].median())
    path = tmp_path / "tiny.toml"
    path.write_text(STUDY.format(batch=0, target=target, verify=2))
    study2 = load_study(path)
    # a wall-time limit stops the verification launch with a checkpoint; the next call resumes it
    res = _run(study2, out, stop_after=1e-9)
    assert res["stopped"].startswith("verification:") and res["verification"] is None
    assert len(list((out / "verification" / "launches").glob("*/checkpoint.npz"))) == 1
    res = _run(study2, out)  # same point ids (target and verification do not change the runs): no new design runs
    assert res["ran"] == 0 and res["stopped"] is None
    rep = json.loads((out / "verification" / "replicate_1.json").read_text())
    assert rep["info"]["resumed_from_s"] > 0
    s = res["analysis"]["height"]
    assert (out / "analysis" / "report.md").exists() and (out / "analysis" / "anova_height.csv").exists()
    assert s["reachable"] and s["predicted"] == pytest.approx(target, rel=1e-6)
    v = res["verification"]
    assert len(v["values"]) == 2 and v["values"][0] != v["values"][1]
    mean = sum(v["values"]) / 2
    assert v["mean"] == pytest.approx(mean)
    assert v["relative_error_pct"] == pytest.approx(100 * abs(mean - target) / target)
    # the confirmation interval: the fit's own prediction interval for a mean of 2 runs at the chosen point
    from scipy import stats

    c = s["confirmation"]
    half = stats.t.ppf(0.975, c["df"]) * (c["mse"] * (0.5 + c["h0"])) ** 0.5
    assert v["prediction_interval"] == pytest.approx([c["predicted"] - half, c["predicted"] + half], rel=1e-10)
    assert v["within_prediction_interval"] == (c["predicted"] - half <= mean <= c["predicted"] + half)
    report = (out / "analysis" / "report.md").read_text()
    assert "## Verification" in report and "prediction interval for a mean of 2 runs" in report
    # a new analysis rewrites the report and keeps the verification section
    execute.analyze(out)
    assert (out / "analysis" / "report.md").read_text().count("## Verification") == 1


def test_verification_replicates_are_checked_like_design_runs(finished, tmp_path, capsys):
    """Each verification replicate goes through the design runs' checks. The tiny study's 0.3 s piles are all
    still moving, so all three replicates are flagged "unsettled" and no summary without them is left. Edited so
    that replicate 1 carries a slid pile's warning and replicates 2 and 3 settled, replicate 1 alone is flagged
    (both checks) and the summary without it is the mean, SD and t test of the other two (scipy), in
    verification.json and report.md, and the console names the flag; the t test of all three is scipy's too, and
    the report's replicate table gives each replicate's other pile metrics beside the response."""
    from scipy import stats

    from warpdem.engine import suspect

    study, done, _ = finished
    out = tmp_path / "out"
    shutil.copytree(done, out, ignore=shutil.ignore_patterns("verification"))
    target = float(execute.load_results(out, study)["height"].median())
    path = tmp_path / "tiny.toml"
    path.write_text(STUDY.format(batch=0, target=target, verify=3))
    study3 = load_study(path)
    v = _run(study3, out)["verification"]
    assert [(c["replicate"], c["check"]) for c in v["checks"]] == [(1, "unsettled"), (2, "unsettled"), (3, "unsettled")]
    assert "unflagged" not in v
    test = stats.ttest_1samp(v["values"], target)
    assert v["t"] == pytest.approx(test.statistic, rel=1e-12) and v["p"] == pytest.approx(test.pvalue, rel=1e-12)
    # what else each replicate measured, the response's own metric (pile_height_m) left out
    recs = [json.loads((out / "verification" / f"replicate_{k}.json").read_text()) for k in (1, 2, 3)]
    assert "pile_height_m" not in v["metrics"]
    assert v["metrics"]["angle_cone_deg"] == [r["metrics"]["angle_cone_deg"] for r in recs]
    head = next(
        line for line in (out / "analysis" / "report.md").read_text().splitlines() if line.startswith("| replicate |")
    )
    assert head.startswith("| replicate | height | ") and "| angle_cone_deg |" in head
    for k in (1, 2, 3):
        f = out / "verification" / f"replicate_{k}.json"
        rec = json.loads(f.read_text())
        if k == 1:
            rec["metrics"]["warnings"] = [suspect.off_axis_warning(0.03, 0.02)]
        else:
            rec["metrics"]["stop"] = "settled"
        f.write_text(json.dumps(rec))
    v = _run(study3, out)["verification"]
    assert [(c["replicate"], c["check"]) for c in v["checks"]] == [(1, "unsettled"), (1, "off_axis")]
    u, kept = v["unflagged"], v["values"][1:]
    assert u["left_out"] == [1] and u["n"] == 2 and u["mean"] == pytest.approx(sum(kept) / 2)
    assert u["p"] == pytest.approx(stats.ttest_1samp(kept, target).pvalue, rel=1e-12)
    assert json.loads((out / "verification" / "verification.json").read_text())["unflagged"]["left_out"] == [1]
    report = (out / "analysis" / "report.md").read_text()
    assert "- Check: pile off its axis: replicate 1: the pile's centre of mass lies 30 mm off" in report
    assert "Without replicate 1 (flagged by the checks): 2 runs, mean" in report
    from warpdem.cli import main

    capsys.readouterr()
    assert main(["study", str(path), "--out", str(out), "--no-progress", "--device", "cpu"]) == 0
    assert "verification: check: pile off its axis: replicate 1: the pile's" in capsys.readouterr().out


def _assert_resumed_like_uninterrupted(study, tmp_path):
    """tmp_path/out was resumed from a checkpoint and holds the responses of an uninterrupted study."""
    rec = json.loads(next((tmp_path / "out" / "runs").glob("*.json")).read_text())
    assert rec["info"]["resumed_from_s"] > 0
    _run(study, tmp_path / "ref", analyze_after=False)
    got = execute.load_results(tmp_path / "out", study)["height"].tolist()
    ref = execute.load_results(tmp_path / "ref", study)["height"].tolist()
    assert got == ref


def test_crash_inside_a_launch_resumes_from_its_checkpoint(tmp_path, monkeypatch):
    """A launch killed half way (after some checkpoints) is resumed from its checkpoint by the rerun, not
    started again, and gives the same responses as an uninterrupted study."""
    from warpdem.scene import runner

    study = _study(tmp_path)
    real = runner.run_scene_iter

    class Crash(Exception):
        pass

    def killed(*a, **kw):
        def kill(frac, msg):
            if frac > 0.5:
                raise Crash

        return real(*a, **(kw | {"progress": kill, "checkpoint_every": 1e-9}))

    monkeypatch.setattr(runner, "run_scene_iter", killed)
    with pytest.raises(Crash):
        _run(study, tmp_path / "out", analyze_after=False)
    assert list((tmp_path / "out" / "launches").glob("*/checkpoint.npz"))
    monkeypatch.setattr(runner, "run_scene_iter", lambda *a, **kw: real(*a, **(kw | {"checkpoint_every": 1e-9})))
    _run(study, tmp_path / "out", analyze_after=False)
    _assert_resumed_like_uninterrupted(study, tmp_path)


def test_study_stops_at_its_wall_time_limit_and_resumes(tmp_path):
    """stop_after: the study stops by itself inside its first launch (checkpoint saved, nothing finished,
    ``stopped`` says why); the same call resumes from the checkpoint and gives the same responses as an
    uninterrupted study."""
    study = _study(tmp_path)
    res = _run(study, tmp_path / "out", analyze_after=False, stop_after=1e-9)
    assert res["stopped"] and "launch 1 of" in res["stopped"] and res["ran"] == 0
    assert list((tmp_path / "out" / "launches").glob("*/checkpoint.npz"))
    assert not list((tmp_path / "out" / "runs").glob("*.json"))
    res = _run(study, tmp_path / "out", analyze_after=False)
    assert res["stopped"] is None and res["ran"] == res["runs"]
    _assert_resumed_like_uninterrupted(study, tmp_path)


def test_two_cpu_processes_give_the_single_launch_numbers(finished, tmp_path):
    """'cpu,cpu' splits the six runs into two launches of three, run at once in two processes; each point
    is saved with its launch's size and device, and since a world never reads another world's spheres and the
    step is fixed, every response equals the one-launch response to the last bit."""
    study, out1, _ = finished
    out2 = tmp_path / "out"
    res = _run(study, out2, device="cpu,cpu", analyze_after=False)
    assert res["ran"] == 6 and res["batches"] == 2 and res["stopped"] is None
    one, two = execute.load_results(out1, study), execute.load_results(out2, study)
    assert list(one["height"]) == list(two["height"])
    for pid in two["point_id"]:
        rec = json.loads((out2 / "runs" / f"{pid}.json").read_text())
        assert rec["info"]["batch_worlds"] == 3 and rec["device"] == "cpu"


def test_runs_split_evenly_over_devices(tmp_path):
    """17 runs over 4 devices: launches of 5, 4, 4, 4 worlds, one per device; a [study] batch cap still
    holds (7 runs, at most 3 per launch, 2 devices: 3 launches of 3, 2, 2)."""
    study = _study(tmp_path)
    rows = [{"overrides": {}, "point_id": str(k)} for k in range(17)]
    sizes = [len(b) for b in execute._batches(study, rows, 4)]
    assert sizes == [5, 4, 4, 4]
    capped = _study(tmp_path, batch=3)
    batches = execute._batches(capped, rows[:7], 2)
    assert [len(b) for b in batches] == [3, 2, 2]
    assert [len(b) for b in execute._batches(study, rows[:3], 1)] == [3]


@pytest.mark.parametrize("device", ["gpu", "cuda:x", "cpu,,cpu"])
def test_bad_device_names_the_value(device):
    with pytest.raises(ValueError, match=f"device = {device!r}: .* is not a device; expected 'cpu', 'cuda'"):
        execute.parse_devices(device)


def test_two_processes_stop_and_resume(finished, tmp_path):
    """With a wall-time limit already spent, each of the two CPU processes stops its launch after its first
    output tick, saving a checkpoint; the rerun resumes both launches from their checkpoints and ends with
    the one-launch responses to the last bit."""
    study, out1, _ = finished
    out2 = tmp_path / "out"
    res = _run(study, out2, device="cpu,cpu", analyze_after=False, stop_after=1e-6)
    assert res["stopped"] and res["stopped"].count("checkpoint saved") == 2 and res["ran"] == 0
    assert len(list((out2 / "launches").glob("*/checkpoint.npz"))) == 2
    res = _run(study, out2, device="cpu,cpu", analyze_after=False)
    assert res["stopped"] is None and res["ran"] == 6
    for pid in execute.load_results(out2, study)["point_id"]:
        rec = json.loads((out2 / "runs" / f"{pid}.json").read_text())
        assert 0 < rec["info"]["resumed_from_s"] < 0.3
    assert list(execute.load_results(out1, study)["height"]) == list(execute.load_results(out2, study)["height"])


def test_verification_replicates_spread_over_devices(finished, tmp_path):
    """On 'cpu,cpu' the 2 verification replicates are two launches, one per process (a full-size replicate
    fills a GPU): stopped at once, each saves its own checkpoint; the rerun finishes both."""
    study, done, _ = finished
    out = tmp_path / "out"  # the design runs without another test's verification
    shutil.copytree(done, out, ignore=shutil.ignore_patterns("verification"))
    path = tmp_path / "tiny.toml"
    path.write_text(STUDY.format(batch=0, target=float(execute.load_results(out, study)["height"].median()), verify=2))
    study2 = load_study(path)
    res = _run(study2, out, device="cpu,cpu", stop_after=1e-6)
    assert res["stopped"].startswith("verification:") and res["ran"] == 0
    assert len(list((out / "verification" / "launches").glob("*/checkpoint.npz"))) == 2
    res = _run(study2, out, device="cpu,cpu")
    assert res["stopped"] is None and len(res["verification"]["values"]) == 2


def test_press_runs_one_world_per_launch(tmp_path):
    """The press's bar is one wall for all batched worlds (its force sums theirs, its force limit turns all their
    strokes at once): a press study splits into single-world launches, and run_scene refuses to batch one."""
    from warpdem.scene import rigs
    from warpdem.scene.runner import run_scene

    text = STUDY.format(batch=0, target=0.0, verify=0).replace('rig = "funnel"', 'rig = "die_press"')
    text = text.replace("count = 40\nduration = 0.3\n", "").replace("pile_height_m", "residual_set_ratio")
    path = tmp_path / "press.toml"
    path.write_text(text)
    study = load_study(path, check_scene=False)
    rows = [{"overrides": execute.sp.run_overrides(study, r)} for _, r in execute.sp.design_table(study).iterrows()]
    assert [len(b) for b in execute._batches(study, rows)] == [1] * len(rows)
    with pytest.raises(ValueError, match="world_count = 2 is not allowed for a 'press' measurement"):
        run_scene(rigs.spec("die_press", smoke=True), world_count=2, frames=False)


def test_plan_runs_nothing(finished, tmp_path, monkeypatch, capsys):
    """``warpdem study --plan``: the run table with coded and actual values, finished or pending, the launches and
    their cost, from the design alone: 6 runs in launches of at most 4 worlds (4 + 2), 40 spheres for at most
    0.3 s each, so 6 x 0.3 = 1.8 world-seconds and 72 particle-seconds; nothing runs (a launch would raise) and
    no output folder is made. A finished study's plan has every run finished and no launch."""
    from warpdem.cli import main

    def refuse(*a, **k):
        raise AssertionError("--plan ran a launch")

    monkeypatch.setattr(execute, "run_batch_iter", refuse)
    study = _study(tmp_path, batch=4)
    out = tmp_path / "never"
    assert main(["study", str(study.path), "--plan", "--out", str(out)]) == 0
    assert not out.exists()
    text = capsys.readouterr().out
    assert "A actual" in text and "0.8" in text and "pending" in text
    assert "1, 2, 3, 4" in text  # a plain table when the output is not a terminal: no cell cut or wrapped
    plan = execute.plan_study(study, out)
    assert [L["worlds"] for L in plan["launches"]] == [4, 2]
    assert sorted(r for L in plan["launches"] for r in L["runs"]) == list(range(1, 7))
    assert all(L["particles"] == 40 and L["duration_s"] == pytest.approx(0.3) for L in plan["launches"])
    assert plan["cost"]["world_s"] == pytest.approx(1.8) and plan["cost"]["particle_s"] == pytest.approx(72.0)
    assert set(plan["table"]["A_actual"]) == {0.2, 0.5, 0.8}
    done_study, done_out, _ = finished
    done = execute.plan_study(done_study, done_out)
    assert set(done["table"]["status"]) == {"finished"} and done["launches"] == []
    assert plan["verification"] is None and done["verification"] is None  # the tiny study has none


def test_plan_says_where_the_verification_goes(finished, tmp_path, capsys):
    """With verification replicates, ``--plan`` says what follows the design: before the design is finished and
    analysed, that they wait for it; then the settings the analysis chose (read from its summary.json) and how
    many replicates have a record; or that it chose none, so none will run."""
    from warpdem.cli import main

    study, done, _ = finished
    path = tmp_path / "tiny.toml"
    path.write_text(STUDY.format(batch=0, target=0.05, verify=2))
    pending = execute.plan_study(load_study(path), tmp_path / "never")["verification"]
    assert pending == {
        "replicates": 2,
        "response": "height",
        "target": 0.05,
        "finished": 0,
        "analysed": False,
        "chosen": None,
    }
    out = tmp_path / "out"
    shutil.copytree(done, out, ignore=shutil.ignore_patterns("verification", "analysis"))
    (out / "analysis").mkdir()
    (out / "analysis" / "summary.json").write_text(json.dumps({"height": {"chosen": {"A": 0.35, "B": 0.125}}}))
    (out / "verification").mkdir()
    (out / "verification" / "replicate_1.json").write_text("{}")
    assert main(["study", str(path), "--plan", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "then 2 verification run(s) for height = 0.05 at A = 0.35, B = 0.125" in text
    assert "1 of 2 finished" in text
    (out / "analysis" / "summary.json").write_text(json.dumps({"height": {"closest": {"A": 0.8, "B": 0.3}}}))
    assert main(["study", str(path), "--plan", "--out", str(out)]) == 0
    assert "no 2 verification run(s) for height = 0.05: the analysis" in capsys.readouterr().out


def test_no_cuda_driver_line_unless_a_gpu_is_asked_for(tmp_path):
    """On a machine without a GPU, Warp's C++ start-up writes "Could not find or load the NVIDIA CUDA driver" to
    the terminal at every command; a command given a CPU device (here ``study --plan``, in a fresh process) no
    longer shows it. On a machine with a driver there is no such line either way."""
    import subprocess
    import sys

    study = _study(tmp_path)
    res = subprocess.run(
        [sys.executable, "-m", "warpdem.cli", "study", str(study.path), "--plan", "--out", str(tmp_path / "o")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr
    assert "CUDA driver" not in res.stderr and "run" in res.stdout


def test_progress_counts_whole_runs(tmp_path):
    """The progress bar counts whole runs (it showed 3.6434989000174096/12); the running launch's own share is in
    its postfix as a percentage. A stand-in bar records every count the study sets."""

    class Bar:
        def __init__(self):
            self.n, self.counts, self.posts = 0, [], []

        def set_postfix_str(self, text, refresh=False):
            self.posts.append(text)

        def refresh(self):
            self.counts.append(self.n)

    study = _study(tmp_path)
    rows = [
        {"run": int(r["run"]), "point_id": r["point_id"], "world_seed": int(r["world_seed"]), "row": r.to_dict()}
        | {"overrides": execute.sp.run_overrides(study, r)}
        for _, r in execute.sp.design_table(study).iterrows()
    ]
    bar = Bar()
    (tmp_path / "o" / "runs").mkdir(parents=True)
    execute._run_on_device(study, tmp_path / "o", execute._batches(study, rows), "cpu", bar, 0.0, 0.0, 0.0)
    assert len(bar.counts) > 2 and all(isinstance(n, int) for n in bar.counts)
    assert bar.counts[-1] == 6 and sorted(bar.counts) == bar.counts
    assert any("%" in p for p in bar.posts)


def test_scenes_of_other_grains_share_a_launch_on_gpus(tmp_path):
    """Runs whose scenes differ only in their particles (here the pour's count) join one launch where launches
    hold several scenes (GPUs; ``merge``), each scene's runs as one group of worlds; not on CPUs. At a fixed
    step the launch is the separate launches again: every run's pile to the last bit, in the order asked."""
    study = _study(tmp_path)
    base = {"count": 40, "duration": 0.3, "run.dt_levels": 0, "measure.pile_apart": 0.0}
    asked = [({**base}, 0), ({**base, "count": 25}, 0), ({**base}, 7)]
    rows = [{"overrides": ov, "world_seed": s, "point_id": str(k)} for k, (ov, s) in enumerate(asked)]
    assert execute.merges_scenes(["cuda:0", "cuda:1"]) and not execute.merges_scenes(["cpu"])
    apart = execute._batches(study, rows)
    assert [[r["point_id"] for r in b] for b in apart] == [["0", "2"], ["1"]]
    together = execute._batches(study, rows, merge=True)
    assert [[r["point_id"] for r in b] for b in together] == [["0", "2", "1"]]
    merged = execute.run_batch(study, rows, "cpu")
    separate = {r["point_id"]: rec for b in apart for r, rec in zip(b, execute.run_batch(study, b, "cpu"))}
    for r, rec in zip(rows, merged):
        solo = separate[r["point_id"]]
        assert rec["metrics"]["particles"] == solo["metrics"]["particles"]
        assert rec["metrics"]["angle_fit_deg"] == solo["metrics"]["angle_fit_deg"]
        assert rec["responses"] == solo["responses"]
    assert merged[1]["metrics"]["particles"] <= 25 < merged[0]["metrics"]["particles"]
    plan = execute.plan_study(study, tmp_path / "nothing", device="cpu")
    assert plan["launches"][0]["particles"] == 40


def test_runs_that_may_be_wrong_are_flagged(finished, tmp_path):
    """run_checks reads each finished run: the tiny study's 0.3 s piles are still moving when they stop (the
    funnel stops once settled), which it says of every run, in the log and the report's notes. A run edited to
    lose 3 of its 40 spheres (7.5 %, over 2 %: the run's own warning), to fail its measurement, to press faster than quasi-static and to
    step above the stable step gets each of those flags with its figures; one that lost none gets no such flag."""
    import shutil

    study, out1, res = finished
    assert {f["check"] for f in res["checks"]} == {"unsettled"} and len(res["checks"]) == 6
    assert (
        "check: did not settle: runs 1, 2, 3, 4, 5, 6 (run 1: still moving at the end of its 0.3 s)"
        in (out1 / "log.txt").read_text()
    )
    out = tmp_path / "copy"
    shutil.copytree(out1, out)
    pid = execute.load_results(out, study)["point_id"][1]
    path = out / "runs" / f"{pid}.json"
    rec = json.loads(path.read_text())
    from warpdem.engine import suspect

    lost = suspect.world_warnings(3, 40, 0.1, (1e-5, 1e-5), None, 0.0)
    rec["metrics"].update(removed=3, inertial_number_max=0.02, angle_error="no pile", warnings=lost)
    rec["responses"]["height"] = None
    rec["info"]["step_warning"] = "the step reached 1.20 of the stable step"
    path.write_text(json.dumps(rec))
    flags = [f for f in execute.run_checks(out, study) if f["run"] == 2]
    details = {f["check"]: f["detail"] for f in flags}
    assert details["lost"].startswith("3 of 40 bodies (7.5 %) left the domain")
    assert details["measurement"] == "no height (pile_height_m): no pile"
    assert details["inertial"].startswith("inertial number 0.02, above the quasi-static 0.001")
    assert details["step"] == "the step reached 1.20 of the stable step"
    assert not any(f["check"] == "lost" for f in execute.run_checks(out, study) if f["run"] != 2)
    execute.analyze(out, study)
    report = (out / "analysis" / "report.md").read_text()
    assert "- Check: lost particles: run 2: 3 of 40 bodies (7.5 %) left the domain" in report
    assert "- Check: did not settle: runs 1, 2, 3, 4, 5, 6" in report


def test_a_pile_holding_too_little_of_its_bed_is_flagged_once(finished, tmp_path):
    """A run whose record says 30 of its 40 spheres lie apart from the pile (75 %, over the 20 % allowed) is
    flagged ``pile_apart`` from its metrics, as records made before the run itself checked are; one that carries
    the run's own warning is flagged once, not twice; 8 of 40 (20 %) is not flagged."""
    from warpdem.engine import suspect

    study, out1, _ = finished
    out = tmp_path / "copy"
    shutil.copytree(out1, out)
    pids = execute.load_results(out, study)["point_id"]
    for k, (detached, particles, own) in enumerate([(30, 10, False), (30, 10, True), (8, 32, False)]):
        path = out / "runs" / f"{pids[k]}.json"
        rec = json.loads(path.read_text())
        rec["metrics"].update(detached=detached, particles=particles)
        rec["metrics"]["warnings"] = [suspect.pile_apart_warning(detached, particles)] if own else []
        path.write_text(json.dumps(rec))
    flags = [(f["run"], f["detail"]) for f in execute.run_checks(out, study) if f["check"] == "pile_apart"]
    assert [run for run, _ in flags] == [1, 2]
    assert flags[0][1].startswith("30 of the 40 particle spheres above the base (75.0 %) are not in the pile")
    assert suspect.pile_apart_warning(8, 32) is None and suspect.pile_apart_warning(9, 31)["check"] == "pile_apart"


def test_settling_of_every_run_is_kept_and_drawn(finished, tmp_path):
    """Each run keeps its kinetic energy per particle at every output tick and its scene's settle threshold; the
    report draws them all (settling.png) and says how many ended below it: none of the tiny study's 0.3 s piles,
    each of which stopped at its duration with its last energy above the threshold, as run_checks says."""
    import shutil

    from warpdem.scene import rigs

    study, out1, _ = finished
    out = tmp_path / "copy"
    shutil.copytree(out1, out)
    threshold = rigs.spec("funnel", {"count": 40, "duration": 0.3}, smoke=True).run.settle_energy
    for pid in execute.load_results(out, study)["point_id"]:
        rec = json.loads((out / "runs" / f"{pid}.json").read_text())
        st = rec["metrics"]["settling"]
        assert st["threshold_j"] == pytest.approx(threshold) and rec["metrics"]["stop"] == "duration"
        assert st["time_s"][-1] == pytest.approx(0.3, abs=1e-4) and len(st["kinetic_energy_j"]) == len(st["time_s"])
        assert st["kinetic_energy_j"][-1] > threshold
    execute.analyze(out, study)
    report = (out / "analysis" / "report.md").read_text()
    assert (
        "0 of 6 runs end below their settle threshold" in report and "![settling of each run](settling.png)" in report
    )
    # every run's curve is drawn: the picture holds each of the first six colours of matplotlib's cycle (in its
    # curve and legend), up to the palette's rounding
    from matplotlib import colors
    from PIL import Image

    with Image.open(out / "analysis" / "settling.png") as im:
        px = np.asarray(im.convert("RGB"), int).reshape(-1, 3)
    for k in range(6):
        rgb = np.round(255 * np.array(colors.to_rgb(f"C{k}")))
        assert (np.abs(px - rgb).max(axis=1) <= 8).sum() >= 20, f"C{k}"


def test_a_study_files_transform_reaches_the_report(finished, tmp_path):
    """``[analysis] transform = "ln"`` in the study file: a target of 0 is refused where the file is read (ln
    cannot take it); with 0.01, analyze fits ln(height) to the same finished runs (their point ids do not depend
    on the analysis) and the report says so."""
    import shutil

    study, out1, _ = finished
    out = tmp_path / "copy"
    shutil.copytree(out1, out)
    path = tmp_path / "ln.toml"
    text = STUDY.format(batch=0, target=0.0, verify=0).replace('model = "linear"', 'model = "linear"\ntransform = "ln"')
    path.write_text(text)
    with pytest.raises(StudyError, match=r"\[\[responses\]\] 'height': target = 0.0 cannot be transformed by ln"):
        load_study(path)
    path.write_text(text.replace("target = 0.0", "target = 0.01"))
    ln_study = load_study(path)
    assert [r["point_id"] for r in execute._study_rows(ln_study, execute.sp.design_table(ln_study))] == [
        r["point_id"] for r in execute._study_rows(study, execute.sp.design_table(study))
    ]
    execute.analyze(out, ln_study)
    md = (out / "analysis" / "report.md").read_text()
    assert "**Transform:** the model is fitted to ln(height)" in md and "ln(height) = " in md


def test_a_response_added_later_comes_from_the_stored_metrics(finished, tmp_path):
    """#20's re-analysis: the study file gains a response (the surface-fit angle) after its runs; analyze reads it
    from each run's stored metrics, and it equals what a fresh run of the new file records, run by run."""
    import shutil

    study, out1, _ = finished
    out = tmp_path / "copy"
    shutil.copytree(out1, out)
    text = STUDY.format(batch=0, target=0.0, verify=0)
    text = text.replace(
        "[analysis]", '[[responses]]\nname = "angle"\nmeasure = "angle_fit_deg"\nunit = "deg"\n\n[analysis]'
    )
    path = tmp_path / "more.toml"
    path.write_text(text)
    more = load_study(path)
    later = execute.load_results(out, more)
    fresh_out = tmp_path / "fresh"
    _run(more, fresh_out, analyze_after=False)
    fresh = execute.load_results(fresh_out, more)
    assert list(later["point_id"]) == list(fresh["point_id"])
    assert np.isfinite(later["angle"]).all() and list(later["angle"]) == list(fresh["angle"])
    execute.analyze(out, more)
    assert "## Response angle" in (out / "analysis" / "report.md").read_text()


PILE_KEYS = ("particles", "detached", "pile_height_m", "angle_fit_deg", "angle_image_deg", "angle_cone_deg")


def test_every_run_keeps_its_state_and_measures_again_to_its_numbers(finished):
    """#20's stored states: each finished run keeps its own world's final state (runs/<point_id>.npz, cut from its
    launch's final.npz, which holds all six worlds), and measuring that state again gives the run's stored pile
    metrics exactly (the same function on the same spheres; another world's state would give another pile)."""
    study, out, _ = finished
    again = execute.remeasure(out, study)
    assert len(again) == 6
    counts = set()
    for f in (out / "runs").glob("*.json"):
        rec = json.loads(f.read_text())
        state = np.load(out / "runs" / f"{rec['point_id']}.npz")
        assert state["sphere_x"].shape == (len(state["sphere_r"]), 3) and len(state["sphere_r"]) == 40
        counts.add(float(state["sphere_x"][:, 2].sum()))
        for k in PILE_KEYS:
            assert again[rec["point_id"]][k] == rec["metrics"][k], (rec["run"], k)
    assert len(counts) == 6  # six different piles, not one world six times
    launch = np.load(next((out / "launches").glob("*/final.npz")))
    assert sorted(set(launch["sphere_world"].tolist())) == list(range(6))


def test_measured_again_under_other_settings_equals_a_fresh_run(finished, tmp_path):
    """Measuring the stored states again with measure.base_height raised by 2 mm gives, run by run, exactly what a
    fresh run of the study with that setting in [fixed] records (the setting does not touch the dynamics); the
    pile heights fall, and the report says how the runs were measured."""
    import shutil

    study, out1, _ = finished
    out = tmp_path / "copy"
    shutil.copytree(out1, out)
    raised = {"measure.base_height": 0.002}
    again = execute.remeasure(out, study, raised)
    text = STUDY.format(batch=0, target=0.0, verify=0).replace(
        '"run.dt_levels" = 0', '"run.dt_levels" = 0\n"measure.base_height" = 0.002'
    )
    path = tmp_path / "raised.toml"
    path.write_text(text)
    fresh_study = load_study(path)
    _run(fresh_study, tmp_path / "fresh", analyze_after=False)
    fresh = {r["run"]: r for r in (json.loads(f.read_text()) for f in (tmp_path / "fresh" / "runs").glob("*.json"))}
    stored = {r["run"]: r for r in (json.loads(f.read_text()) for f in (out / "runs").glob("*.json"))}
    for run, rec in stored.items():
        for k in PILE_KEYS:
            assert again[rec["point_id"]][k] == fresh[run]["metrics"][k], (run, k)
        assert again[rec["point_id"]]["pile_height_m"] < rec["metrics"]["pile_height_m"]
    execute.analyze(out, study, measure=raised)
    table = execute.load_results(out, study, again)
    assert list(table["height"]) == [fresh[run]["metrics"]["pile_height_m"] for run in table["run"]]
    assert (
        "Measured again from each run's stored final state (6 runs) with measure.base_height = 0.002"
        in (out / "analysis" / "report.md").read_text()
    )


def test_measuring_again_refuses_what_it_cannot_do(finished, tmp_path):
    """A key that is not a measure setting, and a run without a stored state (one made before the states were
    kept), are refused naming the key or the run and what to do."""
    import shutil

    study, out1, _ = finished
    with pytest.raises(
        StudyError, match=r"interaction.grain.grain.static_friction = 0.5 is not allowed; expected measure"
    ):
        execute.remeasure(out1, study, {"interaction.grain.grain.static_friction": 0.5})
    out = tmp_path / "old"
    shutil.copytree(out1, out)
    victim = sorted((out / "runs").glob("*.npz"))[0]
    victim.unlink()
    with pytest.raises(StudyError, match=rf"has no stored final state \(runs/{victim.stem}.npz\)"):
        execute.remeasure(out, study)


def test_the_gallery_has_a_picture_per_run(finished, tmp_path):
    """The report gathers a side view per finished run, named by run number (analysis/gallery/run_NN.png), with the
    surface fit's flanks drawn; six runs, six pictures, in rows of three."""
    import shutil

    study, out1, _ = finished
    out = tmp_path / "copy"
    shutil.copytree(out1, out)
    execute.analyze(out, study)
    md = (out / "analysis" / "report.md").read_text()
    # the section alone: a verification section, which another test may have added to the shared folder, follows
    gallery = md.split("## Gallery")[1].split("\n## ")[0]
    runs = sorted(json.loads(f.read_text())["run"] for f in (out / "runs").glob("*.json"))
    for run in runs:
        assert f"![run {run}](gallery/run_{run:02d}.png)" in gallery
        assert (out / "analysis" / "gallery" / f"run_{run:02d}.png").stat().st_size > 1000
    assert gallery.count("|---|---|---|") == 2


def test_the_analysis_as_an_excel_workbook(finished, tmp_path):
    """#20's optional Excel export: a Summary sheet with each response's fit statistics as summary.json has them,
    then one sheet per table the analysis wrote, each reading back equal to its CSV (the runs the model was
    fitted to, the ANOVA, the coefficients); a folder with no analysis is refused, naming what to run."""
    import shutil

    pytest.importorskip("openpyxl")
    study, out1, _ = finished
    out = tmp_path / "copy"
    shutil.copytree(out1, out)
    shutil.rmtree(out / "analysis", ignore_errors=True)  # other tests analyse the shared folder first
    with pytest.raises(StudyError, match="no analysis to export"):
        execute.export_excel(out, tmp_path / "none.xlsx")
    execute.analyze(out, study)
    path = execute.export_excel(out, tmp_path / "tiny.xlsx")
    book = pd.read_excel(path, sheet_name=None)
    summary = json.loads((out / "analysis" / "summary.json").read_text())["height"]
    row = book["Summary"].set_index("response").loc["height"]
    for k in ("r2", "adj_r2", "pred_r2", "model_p", "adeq_precision"):
        assert row[k] == pytest.approx(summary[k], rel=1e-12), k
    for name in ("runs", "anova_height", "coefficients_height"):
        want = pd.read_csv(out / "analysis" / f"{name}.csv")
        pd.testing.assert_frame_equal(book[name], want, check_dtype=False)
    assert len(book["runs"]) == 6


def test_runs_made_elsewhere_are_analysed_from_a_csv(finished, tmp_path, capsys):
    """``warpdem analyze OUT --study S --runs runs.csv``: the finished runs written out as a table in actual units
    (as an EDEM run table would be) give the same fit as the study folder; a missing column, a cell that is not a
    number or an empty factor cell is named with the file, column and row; --runs without --study is refused
    without a traceback."""
    from warpdem.cli import main

    study, out1, _ = finished
    table = execute.load_results(out1, study)
    csv = tmp_path / "runs.csv"
    pd.DataFrame({"A": table["A_actual"], "B": table["B_actual"], "height": table["height"]}).to_csv(csv, index=False)
    ref = execute.analyze(out1, study)
    got = execute.analyze(tmp_path / "ext", study, runs=csv)
    assert got["height"]["equation_coded"] == ref["height"]["equation_coded"]
    assert got["height"]["r2"] == pytest.approx(ref["height"]["r2"], rel=1e-12)
    bad = tmp_path / "bad.csv"
    pd.DataFrame({"A": table["A_actual"], "height": table["height"]}).to_csv(bad, index=False)
    with pytest.raises(StudyError, match=r"bad.csv: column 'B' is missing"):
        execute.external_runs(bad, study)
    odd = pd.DataFrame({"A": table["A_actual"], "B": table["B_actual"], "height": table["height"].astype(object)})
    odd.loc[2, "height"] = "n/a"
    odd.to_csv(bad, index=False)
    with pytest.raises(StudyError, match=r"bad.csv: column 'height', row 4: 'n/a' is not a number"):
        execute.external_runs(bad, study)
    odd.loc[2, "height"], odd.loc[3, "A"] = 0.01, None
    odd.to_csv(bad, index=False)
    with pytest.raises(StudyError, match=r"bad.csv: column 'A', row 5 is empty; a factor needs a value"):
        execute.external_runs(bad, study)
    assert main(["analyze", str(tmp_path / "x"), "--runs", str(csv)]) == 2
    assert "give the study file" in capsys.readouterr().err


def test_json_records_of_an_analysis(finished, tmp_path, monkeypatch):
    """``warpdem analyze DIR --json FILE``: per response the model's p (expected below alpha), R², adjusted and
    predicted R², adequate precision (expected above 4) and the prediction at the target, each a record with name,
    value, expected, unit and pass; each run check a failing record (the tiny study's piles did not settle).
    ``warpdem study --json`` writes the same after running the study afresh (the engine is deterministic). Each
    command checks the runs once, for its report and its records alike."""
    import shutil

    from warpdem.cli import main

    study, out1, _ = finished
    out = tmp_path / "copy"
    shutil.copytree(out1, out)
    checked = []
    real_checks = execute.run_checks
    monkeypatch.setattr(execute, "run_checks", lambda *a, **k: checked.append(a) or real_checks(*a, **k))
    assert main(["analyze", str(out), "--json", str(tmp_path / "a.json")]) == 0
    assert len(checked) == 1
    recs = json.loads((tmp_path / "a.json").read_text())
    assert all(set(r) >= {"name", "value", "expected", "unit", "pass"} for r in recs)
    by = {r["name"]: r for r in recs}
    summary = json.loads((out / "analysis" / "summary.json").read_text())["height"]
    assert by["height.r2"]["value"] == pytest.approx(summary["r2"])
    p = by["height.model_p"]
    assert p["expected"] == "< 0.05" and p["pass"] == (p["value"] < 0.05)
    assert by["height.adeq_precision"]["pass"] == (summary["adeq_precision"] > 4)
    # the folder's own study file (another test of this module may have rerun it with another target)
    target = load_study(out / "study.toml", check_scene=False).responses[0].target
    assert by["height.predicted"]["expected"] == target and by["height.predicted"]["pass"] == summary["reachable"]
    assert [r["name"] for r in recs if r["name"].startswith("run ")] == [f"run {k}.unsettled" for k in range(1, 7)]
    assert not any(r["pass"] for r in recs if r["name"].startswith("run "))
    # warpdem study --json writes the same records after its analysis
    argv = ["study", str(study.path), "--out", str(tmp_path / "s"), "--device", "cpu", "--no-progress"]
    assert main(argv + ["--json", str(tmp_path / "s.json")]) == 0
    assert len(checked) == 2
    again = {r["name"]: r for r in json.loads((tmp_path / "s.json").read_text())}
    assert again["height.r2"]["value"] == pytest.approx(by["height.r2"]["value"], rel=1e-12)


def _without_model(out1, tmp_path):
    """A copy of the shared study folder whose study fits no model (``[analysis] model = "none"``)."""
    out = tmp_path / "copy"
    shutil.copytree(out1, out)
    shutil.rmtree(out / "analysis", ignore_errors=True)
    text = (out / "study.toml").read_text()
    (out / "study.toml").write_text(text.replace('model = "linear"', 'model = "none"'))
    return out


def _as_replicates(out) -> None:
    """Folder ``out``'s runs read as replicates of one setting: its design table edited to one A and one B."""
    design = pd.read_csv(out / "design.csv")
    design["A_actual"], design["B_actual"] = 0.5, 0.175
    design.to_csv(out / "design.csv", index=False)


def test_replicates_without_a_model_are_summarised_against_their_target(finished, tmp_path, capsys):
    """``[analysis] model = "none"`` (replicate runs, as a verification study has): ``warpdem analyze`` no longer
    refuses the folder. Runs at one setting get each response's mean, SD, the mean's t interval and a one-sample t
    test against its target, each equal to statsmodels' on the same values, with the runs' gallery (summary.json
    holds the same numbers); runs at several settings (a steepest-ascent path) are listed without a summary."""
    from statsmodels.stats.weightstats import DescrStatsW

    from warpdem.cli import main

    study, out1, _ = finished
    out = _without_model(out1, tmp_path)
    # the fixture's six runs lie at five settings: listed, with no mean over them (a path's mean means nothing)
    assert main(["analyze", str(out)]) == 0
    assert "6 runs at 5 setting(s)" in (out / "analysis" / "report.md").read_text()
    assert json.loads((out / "analysis" / "summary.json").read_text()) == {}
    assert "t test" not in capsys.readouterr().out
    # the same runs read as replicates of one setting
    _as_replicates(out)
    assert main(["analyze", str(out)]) == 0
    printed = capsys.readouterr().out
    table = execute.load_results(out1, study)
    ref = DescrStatsW(table["height"].to_numpy())
    # the target the copy was analysed against (other tests of the shared folder may have rewritten its study)
    target = load_study(out / "study.toml", check_scene=False).responses[0].target
    t, p, _ = ref.ttest_mean(target)
    lo, hi = ref.tconfint_mean(0.05)
    got = json.loads((out / "analysis" / "summary.json").read_text())["height"]
    assert got["n"] == 6 and got["mean"] == pytest.approx(ref.mean, rel=1e-12)
    assert got["sd"] == pytest.approx(ref.std_mean * math.sqrt(6), rel=1e-12)
    assert got["ci"] == pytest.approx([lo, hi], rel=1e-10)
    assert got["t"] == pytest.approx(t, rel=1e-10) and got["p"] == pytest.approx(p, rel=1e-8, abs=1e-300)
    assert f"height: 6 runs, mean {ref.mean:.4g}" in printed and f"t {t:.3g}, p {p:.3g}" in printed
    assert "unflagged" not in got and "Without run" not in printed  # the checks flag all six: none would be left
    md = (out / "analysis" / "report.md").read_text()
    assert "6 runs at 1 setting(s)" in md and "## Gallery" in md and "one-sample t test" in md
    assert (out / "analysis" / "gallery" / "run_06.png").exists()


def test_replicates_flagged_by_the_checks_are_also_summarised_without_them(finished, tmp_path, capsys, monkeypatch):
    """A replicate the run checks flag (a pile that slid off its axis) is kept in the summary, and the summary is
    given again without it: n, mean, SD, interval and t test equal to statsmodels' on the other five values; the
    report and the console name the run left out."""
    from statsmodels.stats.weightstats import DescrStatsW

    from warpdem.cli import main

    study, out1, _ = finished
    out = _without_model(out1, tmp_path)
    _as_replicates(out)
    slid = {"run": 2, "point_id": "x", "check": "off_axis", "detail": "the pile's centre of mass lies 21 mm off"}
    monkeypatch.setattr(execute, "run_checks", lambda out, study=None: [slid])
    assert main(["analyze", str(out), "--json", str(tmp_path / "r.json")]) == 0
    printed = capsys.readouterr().out
    table = execute.load_results(out1, study)
    target = load_study(out / "study.toml", check_scene=False).responses[0].target
    got = json.loads((out / "analysis" / "summary.json").read_text())["height"]
    assert got["n"] == 6
    rest = DescrStatsW(table.loc[table["run"] != 2, "height"].to_numpy())
    t, p, _ = rest.ttest_mean(target)
    u = got["unflagged"]
    assert u["left_out"] == [2] and u["n"] == 5 and u["mean"] == pytest.approx(rest.mean, rel=1e-12)
    assert u["ci"] == pytest.approx(list(rest.tconfint_mean(0.05)), rel=1e-10)
    assert u["t"] == pytest.approx(t, rel=1e-10) and u["p"] == pytest.approx(p, rel=1e-8, abs=1e-300)
    line = f"Without run 2 (flagged by the checks): 5 runs, mean {rest.mean:.4g}"
    assert line in printed and line in (out / "analysis" / "report.md").read_text()
    # --json: the mean passes when its interval holds the target, with and without the flagged run
    by = {r["name"]: r for r in json.loads((tmp_path / "r.json").read_text())}
    for key, s in (("height", got), ("height.unflagged", u)):
        mean = by[f"{key}.mean"]
        assert mean["value"] == pytest.approx(s["mean"], rel=1e-12) and mean["expected"] == target
        assert mean["pass"] == (s["ci"][0] <= target <= s["ci"][1])
        assert by[f"{key}.n"]["value"] == s["n"] and by[f"{key}.sd"]["value"] == pytest.approx(s["sd"], rel=1e-12)
    assert by["run 2.off_axis"]["pass"] is False


def test_a_run_kept_without_its_state_keeps_its_picture(finished, tmp_path):
    """A record copied without ``runs/*.npz`` (the seed records) keeps, on a new analysis, the gallery picture its
    run had; a run with neither has none."""
    study, out1, _ = finished
    out = tmp_path / "copy"
    shutil.copytree(out1, out)
    execute.analyze(out, study)
    first, second = sorted(execute.load_results(out, study)["point_id"])[:2]
    runs = {json.loads((out / "runs" / f"{pid}.json").read_text())["run"]: pid for pid in (first, second)}
    for pid in runs.values():
        (out / "runs" / f"{pid}.npz").unlink()
    gone, kept = sorted(runs)
    (out / "analysis" / "gallery" / f"run_{gone:02d}.png").unlink()
    execute.analyze(out, study)
    gallery = (out / "analysis" / "report.md").read_text().split("## Gallery")[1]
    assert f"![run {kept}](gallery/run_{kept:02d}.png)" in gallery
    assert f"run_{gone:02d}.png" not in gallery and not (out / "analysis" / "gallery" / f"run_{gone:02d}.png").exists()


def test_a_replicate_summary_with_too_few_values_says_so_by_nan():
    """One finite value has no SD, interval or test (NaN, not an error); NaN runs are left out; without a target
    there is no test. Checked against statsmodels on the values left."""
    from statsmodels.stats.weightstats import DescrStatsW

    one = execute.replicate_summary([1.0, math.nan], 2.0)
    assert one["n"] == 1 and one["mean"] == 1.0 and math.isnan(one["sd"]) and math.isnan(one["p"])
    three = execute.replicate_summary([56.21, 41.67, math.nan, 59.10], None, alpha=0.1)
    ref = DescrStatsW(np.array([56.21, 41.67, 59.10]))
    assert three["ci"] == pytest.approx(list(ref.tconfint_mean(0.1)), rel=1e-10) and math.isnan(three["t"])
    assert (three["min"], three["max"]) == (41.67, 59.10)


def test_one_device_needs_no_dask():
    """A study on one device runs in this process (``InProcess``); on a machine without ``distributed`` (the GPU
    machines here) ``warpdem study --device cuda:0`` stopped at import with "the package 'distributed' is not
    installed". In a fresh process where importing ``distributed`` fails, the executor module imports and one
    device is an ``InProcess``."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        "for name in ('distributed', 'distributed.diagnostics', 'distributed.diagnostics.plugin'):\n"
        "    sys.modules[name] = None\n"
        "from warpdem.study import executor\n"
        "print(type(executor.executor_for(['cpu'])).__name__)\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "InProcess"
