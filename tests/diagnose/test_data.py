"""Diagnosis files (DATA.toml) and their experiments tables (CSV), loaded by warpdem.diagnose.data: a valid file
comes out as written (replicates, splits, conditions, stated SDs, curves) with the pooled replicate SD of its
data, its equivalent study builds, and every class of bad input is refused with a message naming the file, the
key or column (and line) and the value. No simulation runs: the scene is only built."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from warpdem.diagnose import DiagnoseError, DiagnosisSpec, Experiments, ParameterSpec, load_diagnosis
from warpdem.diagnose.data import training_values
from warpdem.scene import rigs
from warpdem.scene.runner import COMMON_METRICS, MEASURE_METRICS, METRIC_NEEDS, measured_metrics
from warpdem.study.spec import MEASURES, StudyError, check_scene_overrides, design_table

ROOT = Path(__file__).resolve().parents[2]

TOML = """\
[diagnose]
name = "pellet_pile"
title = "smoke funnel piles"
rig = "funnel"
smoke = true
seed = 3

[fixed]
interaction.grain.grain.restitution = 0.3

[[parameters]]
name = "mu_s"
parameter = "interaction.grain.grain.static_friction"
low = 0.2
high = 1.0
label = "particle-particle static friction"

[experiments]
file = "experiments.csv"

[noise]
sim_seeds = 4

[calibration]
points = 0
confirm_seeds = 3
mcmc_steps = 2000
alpha = 0.05

[candidates]
use = ["cohesion", "rolling_friction"]
ranges = { cohesion = [0.0, 0.2] }
"""

CSV = """\
id,replicate,split,particle_radius,angle_fit_deg,sd_angle_fit_deg
r2,1,train,0.002,24.0,0.8
r2,2,train,0.002,25.0,0.8
r2,3,train,0.002,26.0,
r3,1,test,0.003,27.5,

r25,1,train,0.0025,30.0,
r25,2,train,0.0025,31.0,
"""


def _write(tmp_path: Path, toml: str = TOML, csv: str = CSV) -> Path:
    path = tmp_path / "data.toml"
    path.write_text(toml)
    (tmp_path / "experiments.csv").write_text(csv)
    return path


def _replace(text: str, old: str, new: str) -> str:
    assert old in text, old
    return text.replace(old, new)


# --------------------------------------------------------------------------------------------------
def test_a_smoke_funnel_file_loads(tmp_path):
    """The file's fields come out as written, the CSV as one row per line (line numbers count the header and
    the blank line), ids as text, and the summary, pooled replicate SD and overrides follow from the rows: r2
    has 24, 25, 26 (SS 2, 2 dof) and r25 30, 31 (SS 0.5, 1 dof), so the pooled SD is sqrt(2.5 / 3)."""
    spec, exps = load_diagnosis(_write(tmp_path))
    assert isinstance(spec, DiagnosisSpec) and isinstance(exps, Experiments)
    assert (spec.name, spec.title, spec.rig, spec.scene, spec.smoke, spec.seed, spec.batch) == (
        "pellet_pile",
        "smoke funnel piles",
        "funnel",
        None,
        True,
        3,
        0,
    )
    assert dict(spec.fixed) == {"interaction.grain.grain.restitution": 0.3}
    assert spec.parameters == (
        ParameterSpec("mu_s", "interaction.grain.grain.static_friction", 0.2, 1.0, "particle-particle static friction"),
    )
    assert spec.parameter_names == ["mu_s"]
    assert (spec.experiments_file, spec.curves, spec.experiments_path) == (
        "experiments.csv",
        None,
        tmp_path / "experiments.csv",
    )
    assert (spec.sim_seeds, spec.points, spec.confirm_seeds, spec.mcmc_steps, spec.alpha) == (4, 0, 3, 2000, 0.05)
    assert spec.calibration_points == 8  # 4 + 4 x 1 parameter
    assert spec.candidates == ("cohesion", "rolling_friction")
    assert dict(spec.candidate_ranges) == {"cohesion": (0.0, 0.2)}
    assert spec.path == tmp_path / "data.toml"
    hash(spec)

    t = exps.table
    assert list(t.columns) == [
        "line",
        "id",
        "replicate",
        "split",
        "particle_radius",
        "angle_fit_deg",
        "sd_angle_fit_deg",
    ]
    assert list(t["line"]) == [2, 3, 4, 5, 7, 8]
    assert list(t["id"]) == ["r2", "r2", "r2", "r3", "r25", "r25"]
    assert all(isinstance(x, str) for x in t["id"])
    assert list(t["replicate"]) == [1, 2, 3, 1, 1, 2]
    assert list(t["split"]) == ["train"] * 3 + ["test"] + ["train"] * 2
    assert exps.conditions == ("particle_radius",) and exps.responses == ("angle_fit_deg",)
    assert exps.curves == {} and exps.source == tmp_path / "experiments.csv" and exps.rig == "funnel"
    assert exps.ids == ["r2", "r3", "r25"] and exps.ids_of("test") == ["r3"]

    s = exps.summary()
    assert list(s.columns) == ["id", "split", "particle_radius", "angle_fit_deg", "n_angle_fit_deg", "sd_angle_fit_deg"]
    assert list(s["id"]) == ["r2", "r3", "r25"]
    np.testing.assert_allclose(s["angle_fit_deg"], [25.0, 27.5, 30.5])
    assert list(s["n_angle_fit_deg"]) == [3, 1, 2]
    assert s["sd_angle_fit_deg"].iloc[0] == pytest.approx(0.8)
    assert s["sd_angle_fit_deg"].iloc[1:].isna().all()

    sd, dof = exps.replicate_sd("angle_fit_deg")
    assert dof == 3 and sd == pytest.approx(math.sqrt(2.5 / 3))
    assert exps.overrides("r25") == {"particle_radius": 0.0025}
    with pytest.raises(KeyError, match="no experiment 'r9'"):
        exps.overrides("r9")


def test_the_equivalent_study_builds_its_scene(tmp_path):
    """spec.study(): the same scene and [fixed], one factor per free parameter with its range, one design point
    at the centre, a response per measure and no model; the study's own scene check accepts it."""
    spec, _ = load_diagnosis(_write(tmp_path))
    study = spec.study(["angle_fit_deg", "pile_height_m"])
    assert (study.name, study.rig, study.smoke, study.seed, study.path) == ("pellet_pile", "funnel", True, 3, spec.path)
    assert dict(study.fixed) == dict(spec.fixed)
    assert [(f.name, f.parameter, f.low, f.high) for f in study.factors] == [
        ("mu_s", "interaction.grain.grain.static_friction", 0.2, 1.0)
    ]
    assert [(r.name, r.measure) for r in study.responses] == [("angle_fit_deg",) * 2, ("pile_height_m",) * 2]
    assert study.analysis.model == "none"
    table = design_table(study)
    assert len(table) == 1 and table["mu_s_actual"].iloc[0] == pytest.approx(0.6)
    check_scene_overrides(study)


def test_defaults_curves_and_rig_parameter_types(tmp_path):
    """Without replicate and split columns the replicates are numbered in file order and every experiment is
    train; an integer rig parameter comes back as an int and a text one as text; a curve file is read for the
    experiment that has one (branch defaults to load); a packing response loads once the funnel is gated."""
    toml = _replace(TOML, 'file = "experiments.csv"', 'file = "experiments.csv"\ncurves = "curves/{id}.csv"')
    toml = _replace(toml, "[fixed]\n", "[fixed]\ngate_time = 0.5\n")
    csv = "id,count,particle,bulk_density_kg_m3\na,300,sphere,610\na,300,sphere,\nb,250,sphere,640\nc,200,sphere,650\n"
    curve = "displacement_m,force_n\n0.0,0.0\n0.001,2.5\n"
    spec, exps = load_diagnosis(_write(tmp_path, toml, csv))
    t = exps.table
    assert list(t["replicate"]) == [1, 2, 1, 1] and set(t["split"]) == {"train"}
    assert t["sd_bulk_density_kg_m3"].isna().all()
    ov = exps.overrides("b")
    assert ov == {"count": 250, "particle": "sphere"} and isinstance(ov["count"], int)
    assert exps.curves == {}  # no curve file yet
    (tmp_path / "curves").mkdir()
    (tmp_path / "curves" / "a.csv").write_text(curve + "0.0005,1.0\n")
    (tmp_path / "curves" / "b.csv").write_text("displacement_m,force_n,branch\n0,0,load\n0.001,2,unload\n")
    _, exps = load_diagnosis(tmp_path / "data.toml")
    assert sorted(exps.curves) == ["a", "b"]
    a = exps.curves["a"]
    np.testing.assert_allclose(a["force_n"], [0.0, 2.5, 1.0])
    assert list(a["branch"]) == ["load"] * 3 and list(exps.curves["b"]["branch"]) == ["load", "unload"]
    sd, dof = exps.replicate_sd("bulk_density_kg_m3")
    assert math.isnan(sd) and dof == 0  # a's second replicate was not measured


def test_every_rigs_metrics_are_measures():
    """The runner's table of what each measure kind writes is the study's MEASURES; each smoke rig measures
    a subset of it, the funnel's packing only with a gate and the die press's unloading only with unload."""
    assert set(MEASURES) == {k for keys in MEASURE_METRICS.values() for k in keys} | set(COMMON_METRICS)
    assert set(METRIC_NEEDS) <= set(MEASURES)
    for rig in rigs.RIGS:
        got = measured_metrics(rigs.spec(rig, {}, True).measure)
        assert set(got) <= set(MEASURES) and "time_s" in got, rig
    assert "bulk_density_kg_m3" not in measured_metrics(rigs.spec("funnel", {}, True).measure)
    assert "bulk_density_kg_m3" in measured_metrics(rigs.spec("funnel", {"gate_time": 0.5}, True).measure)
    assert "residual_set_ratio" not in measured_metrics(rigs.spec("die_press", {"unload": False}, True).measure)
    assert "residual_set_ratio" not in measured_metrics(rigs.spec("funnel", {}, True).measure)


def test_a_stage_diagnosis_reads_the_rig_from_the_stage(tmp_path):
    """A diagnosis of a stage (scene = ...) checks its columns against the rig the stage was authored from, so a
    misspelt response is refused with a did-you-mean, as with rig = ...; without the scene check it is taken
    as a rig parameter of a rig not known."""
    toml = _replace(TOML, 'rig = "funnel"\nsmoke = true', f'scene = "{ROOT / "scenes" / "funnel.usda"}"')
    csv = "id,angle_fit_dg,angle_fit_deg\na,1,2\nb,1,3\n"
    path = _write(tmp_path, toml, csv)
    with pytest.raises(DiagnoseError, match=r"column 'angle_fit_dg' is not allowed \(did you mean 'angle_fit_deg'"):
        load_diagnosis(path)
    _, exps = load_diagnosis(path, check_scene=False)
    assert exps.conditions == ("angle_fit_dg",) and exps.overrides("a") == {"angle_fit_dg": 1.0}


def test_the_scene_check_can_be_skipped(tmp_path):
    """check_scene=False builds nothing: a response the scene does not measure passes."""
    csv = "id,residual_set_ratio\na,0.1\nb,0.2\n"
    _, exps = load_diagnosis(_write(tmp_path, csv=csv), check_scene=False)
    assert exps.responses == ("residual_set_ratio",)


# --------------------------------------------------------------------------------------------------
# bad input: (id, TOML edits [(old, new)], CSV or None for the valid one, file the message names, needles)

_TWO = (
    "\n[[parameters]]\nname = 'mu_r'\nparameter = 'interaction.grain.grain.rolling_friction'\nlow = 0.0\nhigh = 0.3\n"
)

BAD = [
    ("toml-syntax", [("seed = 3", "seed = = 3")], None, "data.toml", ["not valid TOML"]),
    ("unknown-table", [("[noise]", "[nosie]")], None, "data.toml", ["[nosie]", "did you mean 'noise'"]),
    (
        "unknown-key",
        [("sim_seeds = 4", "sim_seed = 4")],
        None,
        "data.toml",
        ["[noise]", "'sim_seed'", "did you mean 'sim_seeds'"],
    ),
    (
        "unknown-parameter-key",
        [('label = "particle', 'lable = "particle')],
        None,
        "data.toml",
        ["[[parameters]] #1 'mu_s'", "'lable'", "did you mean 'label'"],
    ),
    ("missing-experiments", [("[experiments]\nfile", "[experiment]\nfile")], None, "data.toml", ["[experiment]"]),
    (
        "bad-name",
        [('name = "pellet_pile"', 'name = "Pellet Pile"')],
        None,
        "data.toml",
        ["[diagnose]", "'Pellet Pile'"],
    ),
    ("rig-and-scene", [("smoke = true", 'smoke = true\nscene = "x.usda"')], None, "data.toml", ["exactly one of rig"]),
    ("sim-seeds", [("sim_seeds = 4", "sim_seeds = 1")], None, "data.toml", ["[noise]", "sim_seeds = 1", ">= 2"]),
    ("mcmc-steps", [("mcmc_steps = 2000", "mcmc_steps = 50")], None, "data.toml", ["mcmc_steps = 50", ">= 100"]),
    ("alpha", [("alpha = 0.05", "alpha = 0.5")], None, "data.toml", ["[calibration]", "alpha = 0.5", "(0, 0.5)"]),
    (
        "parameter-range",
        [("low = 0.2", "low = 1.0")],
        None,
        "data.toml",
        ["[[parameters]] 'mu_s'", "low = 1.0", "high = 1.0", "low < high"],
    ),
    (
        "parameter-unknown-field",
        [("grain.grain.static_friction", "grain.grain.static_fricton")],
        None,
        "data.toml",
        ["[[parameters]] 'mu_s'", "static_fricton", "did you mean 'static_friction'"],
    ),
    (
        "parameter-in-fixed",
        [("grain.grain.static_friction", "grain.grain.restitution")],
        None,
        "data.toml",
        ["[[parameters]] 'mu_s'", "interaction.grain.grain.restitution", "[fixed] sets it"],
    ),
    (
        "parameter-value-refused",
        [("grain.grain.static_friction", "grain.plate.restitution"), ("high = 1.0", "high = 1.5")],
        None,
        "data.toml",
        ["[[parameters]] 'mu_s'", "high = 1.5", "(0, 1]"],
    ),
    (
        "unknown-candidate",
        [('"cohesion", "rolling', '"cohesoin", "rolling')],
        None,
        "data.toml",
        ["[candidates]", "'cohesoin'", "did you mean 'cohesion'"],
    ),
    (
        "range-order",
        [("cohesion = [0.0, 0.2]", "cohesion = [0.2, 0.1]")],
        None,
        "data.toml",
        ["[candidates]", "ranges.cohesion = [0.2, 0.1]", "low < high"],
    ),
    (
        "range-unknown-candidate",
        [("cohesion = [0.0, 0.2]", "cohesio = [0.0, 0.2]")],
        None,
        "data.toml",
        ["[candidates]", "'cohesio'", "did you mean 'cohesion'"],
    ),
    ("curves-without-id", [("[noise]", 'curves = "c.csv"\n[noise]')], None, "data.toml", ["curves = 'c.csv'", "{id}"]),
    (
        "missing-csv",
        [('file = "experiments.csv"', 'file = "nowhere.csv"')],
        None,
        "data.toml",
        ["[experiments] file = 'nowhere.csv'", "does not exist"],
    ),
    ("missing-id", [], "name,angle_fit_deg\na,1\nb,2\n", "experiments.csv", ["column 'id' is missing", "name"]),
    (
        "missing-responses",
        [],
        "id,particle_radius\na,0.002\nb,0.003\n",
        "experiments.csv",
        ["no response column", "angle_fit_deg", "columns: id, particle_radius"],
    ),
    (
        "unknown-column",
        [],
        "id,angle_fit_dg,angle_fit_deg\na,1,2\nb,1,3\n",
        "experiments.csv",
        ["column 'angle_fit_dg' is not allowed", "did you mean 'angle_fit_deg'"],
    ),
    (
        "unknown-rig-column",
        [],
        "id,partcle_radius,angle_fit_deg\na,1,2\nb,1,3\n",
        "experiments.csv",
        ["column 'partcle_radius'", "did you mean 'particle_radius'"],
    ),
    (
        "sd-of-no-response",
        [],
        "id,angle_fit_deg,sd_pile_height_m\na,1,2\nb,1,3\n",
        "experiments.csv",
        ["column 'sd_pile_height_m'", "pile_height_m is not a response column"],
    ),
    (
        "not-measured-by-the-scene",
        [],
        "id,residual_set_ratio\na,0.1\nb,0.2\n",
        "experiments.csv",
        ["line 2", "residual_set_ratio = 0.1", "experiment 'a' does not measure", "angle_fit_deg"],
    ),
    (
        "packing-without-gate",
        [],
        "id,angle_fit_deg,bulk_density_kg_m3\na,20,\nb,21,600\n",
        "experiments.csv",
        ["line 3", "bulk_density_kg_m3 = 600.0", "measure.packing_time", "gate_time > 0"],
    ),
    (
        "no-training-value",
        [],
        "id,split,angle_fit_deg\na,test,20\nb,train,\n",
        "experiments.csv",
        ["no training experiment has a measured value of angle_fit_deg", "expected at least one"],
    ),
    (
        "non-numeric-cell",
        [],
        "id,angle_fit_deg\na,20\nb,abc\n",
        "experiments.csv",
        ["experiments.csv, line 3: angle_fit_deg = 'abc' is not allowed", "a finite number"],
    ),
    (
        "condition-differs",
        [],
        "id,particle_radius,angle_fit_deg\na,0.002,20\na,0.003,21\nb,0.003,22\n",
        "experiments.csv",
        ["line 3: particle_radius = '0.003' is not allowed", "0.002 as on line 2", "experiment 'a'"],
    ),
    (
        "condition-empty",
        [],
        "id,particle_radius,angle_fit_deg\na,0.002,20\nb,,22\n",
        "experiments.csv",
        ["line 3: particle_radius = ''", "a value"],
    ),
    (
        "split",
        [],
        "id,split,angle_fit_deg\na,train,20\nb,training,22\n",
        "experiments.csv",
        ["line 3: split = 'training'", "train or test", "did you mean 'train'"],
    ),
    (
        "split-differs",
        [],
        "id,split,angle_fit_deg\na,train,20\na,test,21\nb,train,22\n",
        "experiments.csv",
        ["line 3: split = 'test'", "'train' as on line 2"],
    ),
    (
        "no-train",
        [],
        "id,split,angle_fit_deg\na,test,20\nb,test,22\n",
        "experiments.csv",
        ["column 'split' has no train experiment"],
    ),
    (
        "sd-zero",
        [],
        "id,angle_fit_deg,sd_angle_fit_deg\na,20,0.5\nb,22,0\n",
        "experiments.csv",
        ["line 3: sd_angle_fit_deg = '0'", "> 0"],
    ),
    (
        "replicate-twice",
        [],
        "id,replicate,angle_fit_deg\na,1,20\na,1,21\nb,1,22\n",
        "experiments.csv",
        ["line 3: replicate = '1'", "line 2 is replicate 1 of experiment 'a'"],
    ),
    ("replicate-zero", [], "id,replicate,angle_fit_deg\na,0,20\nb,1,22\n", "experiments.csv", ["replicate = '0'"]),
    (
        "response-without-value",
        [],
        "id,angle_fit_deg,pile_height_m\na,20,\nb,22,\n",
        "experiments.csv",
        ["column 'pile_height_m' has no value"],
    ),
    (
        "parameter-as-condition",
        [],
        "id,interaction.grain.grain.static_friction,angle_fit_deg\na,0.5,20\nb,0.6,22\n",
        "experiments.csv",
        ["column 'interaction.grain.grain.static_friction' is not allowed", "[[parameters]] 'mu_s'"],
    ),
    (
        "fixed-as-condition",
        [],
        "id,interaction.grain.grain.restitution,angle_fit_deg\na,0.5,20\nb,0.6,22\n",
        "experiments.csv",
        ["column 'interaction.grain.grain.restitution' is not allowed", "[fixed] sets"],
    ),
    (
        "condition-value-refused",
        [],
        "id,interaction.grain.plate.restitution,angle_fit_deg\na,0.5,20\nb,1.5,22\n",
        "experiments.csv",
        ["line 3: interaction.grain.plate.restitution = 1.5", "experiment 'b'", "(0, 1]"],
    ),
    (
        "condition-unknown-material",
        [],
        "id,interaction.grian.plate.restitution,angle_fit_deg\na,0.5,20\nb,0.6,22\n",
        "experiments.csv",
        ["line 2: interaction.grian.plate.restitution = 0.5", "material 'grian'", "did you mean 'grain'"],
    ),
    (
        "condition-rig-value-refused",
        [],
        "id,particle,angle_fit_deg\na,sphere,20\nb,cube,22\n",
        "experiments.csv",
        ["line 3", "particle = 'cube'", "experiment 'b'", "sphere, pellet, phosphate"],
    ),
    (
        "condition-not-numeric",
        [],
        "id,count,angle_fit_deg\na,300,20\nb,many,22\n",
        "experiments.csv",
        ["line 3: count = 'many'", "a finite number"],
    ),
    (
        "condition-key-form",
        [],
        "id,interaction.grain.law,angle_fit_deg\na,1,20\nb,1,22\n",
        "experiments.csv",
        ["column = 'interaction.grain.law' is not allowed", "interaction.A.B.FIELD"],
    ),
    ("ragged-row", [], "id,angle_fit_deg\na,20\nb,22,3\n", "experiments.csv", ["not a readable CSV", "line 3"]),
    ("header-only", [], "id,angle_fit_deg\n", "experiments.csv", ["a header but no rows"]),
]


@pytest.mark.parametrize("case, edits, csv, where, needles", BAD, ids=[c[0] for c in BAD])
def test_bad_input_is_refused_naming_file_key_and_value(tmp_path, case, edits, csv, where, needles):
    """Each bad input raises DiagnoseError (a StudyError, which the CLI reports) naming the file and the
    table key or CSV column (with its line and value where there is one)."""
    toml = TOML
    for old, new in edits:
        toml = _replace(toml, old, new)
    path = _write(tmp_path, toml, CSV if csv is None else csv)
    with pytest.raises(DiagnoseError) as err:
        load_diagnosis(path)
    msg = str(err.value)
    assert isinstance(err.value, StudyError)
    assert str(tmp_path / where) in msg, msg
    for n in needles:
        assert n in msg, f"{n!r} not in: {msg}"


def test_bad_curve_files_name_the_file_line_and_column(tmp_path):
    """A curve file's unknown column, non-numeric cell and unknown branch are refused naming that file."""
    toml = _replace(TOML, 'file = "experiments.csv"', 'file = "experiments.csv"\ncurves = "curves/{id}.csv"')
    path = _write(tmp_path, toml)
    curve = tmp_path / "curves" / "r2.csv"
    curve.parent.mkdir()
    for text, needles in [
        ("displacement_m,force\n0,0\n1,1\n", ["column 'force' is not allowed", "did you mean 'force_n'"]),
        ("displacement_m,force_n\n0,0\n0.001,x\n", ["line 3: force_n = 'x'"]),
        ("displacement_m,force_n,branch\n0,0,load\n0.001,1,unlaod\n", ["branch = 'unlaod'", "did you mean 'unload'"]),
        ("displacement_m,force_n\n0,0\n", ["1 row(s)", ">= 2 points"]),
    ]:
        curve.write_text(text)
        with pytest.raises(DiagnoseError) as err:
            load_diagnosis(path)
        assert str(curve) in str(err.value)
        for n in needles:
            assert n in str(err.value), str(err.value)


def test_parameter_and_spec_refuse_bad_values_directly():
    """The dataclasses validate themselves: a parameter range low >= high, an unknown parameter field and a
    curves pattern without {id} are refused at construction, as DiagnoseError."""
    with pytest.raises(DiagnoseError, match=r"low = 0.5 and high = 0.5 are not allowed; expected low < high"):
        ParameterSpec("mu", "interaction.grain.grain.static_friction", 0.5, 0.5)
    with pytest.raises(DiagnoseError, match=r"\[\[parameters\]\] 'mu': parameter"):
        ParameterSpec("mu", "interaction.grain.grain.friction", 0.1, 0.5)
    p = ParameterSpec("mu", "interaction.grain.grain.static_friction", 0.1, 0.5)
    kw = dict(name="x", rig="funnel", smoke=True, parameters=(p,), experiments_file="e.csv")
    assert DiagnosisSpec(**kw).calibration_points == 8
    with pytest.raises(DiagnoseError, match=r"\[experiments\]: curves = 'c.csv'"):
        DiagnosisSpec(**kw, curves="c.csv")
    with pytest.raises(DiagnoseError, match=r"\[\[parameters\]\]: expected at least one free parameter"):
        DiagnosisSpec(**{**kw, "parameters": ()})


def test_cli_reports_a_bad_data_file_without_a_traceback(tmp_path, capsys):
    """``warpdem diagnose`` prints the loader's error (file and key) and exits 2, with no traceback."""
    from warpdem.cli import main

    bad = tmp_path / "bad.toml"
    bad.write_text('[diagnose]\nname = "x"\nrig = "funnel"\n')
    assert main(["diagnose", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "bad.toml" in err and "[parameters]" in err and "Traceback" not in err


def test_repository_data_files():
    """The data files under studies/diagnose load as written: the worked example, and seeds 000's and 001's one
    measured angle each (seed 001's at two sizes, each also with six confirming seeds, and with its recalibrated
    model), no more values than free parameters, which the diagnosis takes as a reach question."""
    spec, ex = load_diagnosis(ROOT / "studies" / "diagnose" / "press_plasticity.toml")
    assert spec.rig == "die_press" and list(ex.responses) == ["residual_set_ratio"]
    spec, ex = load_diagnosis(ROOT / "studies" / "diagnose" / "seed000_pellets.toml")
    assert training_values(ex) == 1 == len(spec.parameters)
    spec, ex = load_diagnosis(ROOT / "studies" / "diagnose" / "seed001_wetfeed.toml")
    assert training_values(ex) == 1 and spec.parameter_names == ["X1", "X2", "X3"]
    base = spec
    spec, ex = load_diagnosis(ROOT / "studies" / "diagnose" / "seed001_wetfeed_standard_scaled.toml")
    # the recalibrated model: the standard rolling law and the surface energy times 0.2, nothing else changed
    law = {f"interaction.grain.{m}.rolling_model": "standard" for m in ("grain", "steel")}
    assert dict(spec.fixed) == dict(base.fixed) | law | {"surface_energy": 0.1}
    assert [(p.low, p.high) for p in spec.parameters] == [(0.1, 0.5), (0.3, 0.9), (0.04, 0.16)]
    assert spec.experiments_path == base.experiments_path
    spec, ex = load_diagnosis(ROOT / "studies" / "diagnose" / "seed001_wetfeed_confirm6.toml")
    # six confirming seeds instead of three, and nothing else changed: the same seed, so the same design and points
    assert spec.confirm_seeds == 6 != base.confirm_seeds and spec.seed == base.seed
    assert dict(spec.fixed) == dict(base.fixed) and spec.parameters == base.parameters
    spec, ex = load_diagnosis(ROOT / "studies" / "diagnose" / "seed001_wetfeed_large.toml")
    assert training_values(ex) == 1 and spec.parameter_names == ["X1", "X2"]
    # the scatter seeds and the design share one launch, then the confirming seeds: 12 worlds of 25,000 grains
    assert spec.sim_seeds + spec.calibration_points + spec.confirm_seeds == 12
    large = spec
    spec, ex = load_diagnosis(ROOT / "studies" / "diagnose" / "seed001_wetfeed_large_confirm6.toml")
    assert spec.confirm_seeds == 6 and spec.seed == large.seed and spec.calibration_points == large.calibration_points
    assert dict(spec.fixed) == dict(large.fixed) and spec.parameters == large.parameters


def _cli_prints(monkeypatch, capsys, **res) -> str:
    """What ``warpdem diagnose`` prints for a diagnosis that returns ``res`` (with a run's bookkeeping added)."""
    from warpdem.cli import main
    from warpdem.diagnose import pipeline

    res = {"stopped": None, "worlds": 42, "launches": 6, "wall_s": 12.0, "out": "o", **res}
    monkeypatch.setattr(pipeline, "diagnose", lambda *a, **k: res)
    assert main(["diagnose", "any.toml", "--no-progress"]) == 0
    return capsys.readouterr().out


def test_cli_prints_a_reach_verdict(monkeypatch, capsys):
    """A reach diagnosis (one measured value) prints its own verdict line, each reaching candidate's misfit on the
    data fitted, and the measurement that separates them; no held-out line, since there is none."""
    out = _cli_prints(
        monkeypatch,
        capsys,
        mode="reach",
        verdict="not_identifiable",
        verdict_words="NOT IDENTIFIABLE: out of reach of the base model; cohesion, plasticity each reach the data",
        gain={
            n: {"z_rms": {"base": 10.4, "extended": z}, "rmse": {}} for n, z in (("cohesion", 1.4), ("plasticity", 1.1))
        },
        separating_measurement="bulk_density_kg_m3",
    )
    assert out.startswith("NOT IDENTIFIABLE: out of reach of the base model; cohesion, plasticity")
    assert "base -> base + cohesion: 10.4 -> 1.4 SD" in out and "measure bulk_density_kg_m3" in out
    assert "held-out" not in out


def test_cli_prints_the_rolling_models_tried(monkeypatch, capsys):
    """An OVERDISPERSED reach diagnosis prints, per rolling model tried, its runs' SD, the base's variance over its
    own and whether it repeats."""
    law = {
        "model": "standard",
        "reaches": True,
        "repeats": True,
        "scatter": {"aor_deg": {"simulated_sd": 0.99}},
        "gain": {"aor_deg": {"F": 28.9, "p_holm": 0.033}},
    }
    out = _cli_prints(
        monkeypatch,
        capsys,
        mode="reach",
        verdict="overdispersed",
        verdict_words="OVERDISPERSED: ...; the rolling model standard reaches the data and repeats (...)",
        rolling_models={"tried": {"rolling_model=standard": law}},
    )
    assert "rolling model standard: aor_deg SD 0.99, base / its variance 28.9 (p 0.033); repeats" in out


def test_cli_prints_the_held_out_gain_against_the_noise(monkeypatch, capsys):
    """A CAUSE prints each response's held-out RMSE, base and extended, its fall and both models' chi-square p
    against the noise budget: the gain is confirmed by the base missing beyond the noise and the extended model
    not."""
    x = {"base": 50.73, "extended": 22.80, "reduction": 0.5506, "noise_p": {"base": 1.1e-4, "extended": 0.239}}
    out = _cli_prints(
        monkeypatch,
        capsys,
        verdict="cause",
        cause="shape",
        cause_words="particle shape (elongation)",
        gain={"rmse": {"bulk_density_kg_m3": x}},
    )
    assert out.startswith("CAUSE: shape (particle shape (elongation))")
    assert (
        "held-out RMSE of bulk_density_kg_m3: base 50.73, extended 22.8 (55 % lower; chi-square p against the "
        "noise: base 0.00011, extended 0.24)"
    ) in out
