"""Study definitions (studies/*.toml) and their loader warpdem.study.spec: the seed papers' designs and
levels come out of the files exactly, repeated points get distinct world seeds, run identities are
stable, and every class of bad input is refused with a message naming the file and the field."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from warpdem.study.spec import StudyError, batch_key, design_table, load_study, run_overrides, varies_per_world

ROOT = Path(__file__).resolve().parents[2]
STUDIES = ROOT / "studies"
REF = STUDIES / "reference"
RECORDS_001 = ROOT / "docs" / "seeds" / "001"
FILES = sorted(STUDIES.glob("*.toml"))

COUNTS = {
    "pellets_pb": 12,
    "pellets_steepest": 6,
    "pellets_bbd": 17,
    "pellets_verify": 4,
    "pellets_pb_standard": 12,
    "pellets_calibrated_standard": 4,
    "pellets_pb_standard_plate_held": 12,
    "pellets_steepest_standard": 6,
    "pellets_bbd_standard": 17,
    "pellets_bbd_standard_own": 17,
    "pellets_verify_standard": 8,
    "pellets_verify_standard_step": 8,
    "pellets_verify_standard_secant": 8,
    "wetfeed_pb": 12,
    "wetfeed_ccd": 23,
    "phosphate_ffd": 16,
    "phosphate_ffd_gamma_s": 16,
    "phosphate_bbd": 15,
    "phosphate_gamma_scaled": 4,
    "phosphate_gamma_scan": 4,
    "main_funnel_pb": 12,
    "wetfeed_gamma_scan": 5,
    "wetfeed_verify_large": 5,
    "wetfeed_large_gamma": 6,
    "wetfeed_large_friction": 9,
    "wetfeed_scatter_bond": 8,
    "wetfeed_scatter_bond_standard": 8,
    "wetfeed_pb_standard": 12,
    "wetfeed_ccd_standard": 23,
    "phosphate_ffd_standard": 16,
    "phosphate_bbd_standard": 15,
    "phosphate_ffd_standard_gamma_s": 16,
    "wetfeed_verify_large_standard": 5,
    "wetfeed_pb_standard_scaled": 12,
    "wetfeed_pb_type_a_scaled": 12,
    "wetfeed_ccd_standard_scaled": 23,
    "wetfeed_verify_standard_scaled_step": 5,
    "wetfeed_verify_large_standard_scaled": 5,
    "wetfeed_verify_large_standard_scaled_step": 5,
    "wetfeed_verify_large_standard_scaled_friction": 5,
    "wetfeed_press_seed_size": 5,
}


@pytest.fixture(scope="module")
def studies():
    return {p.stem: load_study(p) for p in FILES}


@pytest.fixture(scope="module")
def tables(studies):
    return {name: design_table(s) for name, s in studies.items()}


def _rows(df: pd.DataFrame, cols) -> list[tuple]:
    return sorted(tuple(round(float(v), 9) for v in r) for r in df[list(cols)].to_numpy())


def _by_actual(spec, row) -> dict:
    return {f.name: run_overrides(spec, row)[f.parameter] for f in spec.factors}


# --------------------------------------------------------------------------------------------------
def test_every_study_file_is_listed_and_loads(studies, tables):
    """Each studies/*.toml loads (scene built, fixed and extreme factor values applied), its name is its
    file name, and its design table has the documented columns with runs 1..N."""
    assert set(studies) == set(COUNTS), "a study file was added or removed: update COUNTS"
    for name, spec in studies.items():
        assert spec.name == name
        t = tables[name]
        names = spec.factor_names
        assert list(t.columns) == (
            ["run", "std_order", "point_type", "replicate", "world_seed"]
            + names
            + [f"{n}_actual" for n in names]
            + ["point_id"]
        )
        assert list(t["run"]) == list(range(1, len(t) + 1))
        assert sorted(t["std_order"]) == list(range(1, len(t) + 1))


def test_design_counts_match_the_seeds(tables):
    """Run counts: PB 12 (seeds 000 Table 6, 001 Table 3), steepest path 6 (000 Table 8), 2^(5-1) = 16
    (002 Fig. 14), BBD 12 + 5 centre = 17 (000 Table 10), 12 + 3 = 15 (002 Fig. 18), CCD 8 + 6 + 9 = 23
    (001 Table 6)."""
    for name, n in COUNTS.items():
        assert len(tables[name]) == n, name
    pt = {name: t["point_type"].value_counts().to_dict() for name, t in tables.items()}
    assert pt["wetfeed_ccd"] == {"factorial": 8, "axial": 6, "centre": 9}
    assert pt["pellets_bbd"] == {"factorial": 12, "centre": 5}
    assert pt["phosphate_bbd"] == {"factorial": 12, "centre": 3}
    assert pt["pellets_steepest"] == {"path": 6}
    assert pt["phosphate_ffd"] == {"factorial": 16}
    # seed 000's replicates sit on one Box-Behnken point, the region's high corner in D and E
    assert pt["pellets_verify"] == {"point": 4}
    acts = ["C_actual", "D_actual", "E_actual"]
    points = {
        name: {tuple(r) for r in tables[name][acts].to_numpy().round(9)} for name in ("pellets_verify", "pellets_bbd")
    }
    assert points["pellets_verify"] == {(0.45, 0.75, 0.07)} and (0.45, 0.75, 0.07) in points["pellets_bbd"]


def test_standard_rolling_studies_differ_from_their_twins_only_in_the_rolling_model(studies, tables):
    """pellets_pb_standard runs pellets_pb's 12 points and pellets_calibrated_standard the paper's calibrated set
    (A 0.52, B 0.03, C 0.45, D 0.55, E 0.05, F 0.37; seed 000's Table 12) four times; each fixes EDEM's standard
    rolling friction on every pellet pair and differs from its type-A twin in nothing else."""
    model = {f"interaction.grain.{b}.rolling_model": "standard" for b in ("grain", "steel", "plate")}
    pb, pbs = studies["pellets_pb"], studies["pellets_pb_standard"]
    assert dict(pbs.fixed) == dict(pb.fixed) | model
    cols = [c for c in tables["pellets_pb"].columns if c != "point_id"]
    assert tables["pellets_pb_standard"][cols].equals(tables["pellets_pb"][cols])
    cal = studies["pellets_calibrated_standard"]
    assert dict(cal.fixed) == dict(studies["pellets_verify"].fixed) | model
    fixed = {
        k: cal.fixed[k]
        for k in (
            "interaction.grain.steel.static_friction",
            "interaction.grain.steel.rolling_friction",
            "interaction.grain.grain.restitution",
        )
    }
    assert list(fixed.values()) == [0.52, 0.03, 0.37]
    t = tables["pellets_calibrated_standard"]
    assert {tuple(r) for r in t[["C_actual", "D_actual", "E_actual"]].to_numpy().round(9)} == {(0.45, 0.55, 0.05)}
    assert list(t["world_seed"]) == [0, 1, 2, 3]


@pytest.mark.parametrize("name", ["pellets_steepest", "pellets_bbd"])
def test_later_standard_stages_differ_from_their_twins_only_in_the_rolling_model(studies, tables, name):
    """The steepest ascent and the Box-Behnken with EDEM's standard rolling friction run their type-A twins' points
    with the same analysis and verification; only the three pellet pairs' rolling model is fixed on top."""
    model = {f"interaction.grain.{b}.rolling_model": "standard" for b in ("grain", "steel", "plate")}
    twin, std = studies[name], studies[f"{name}_standard"]
    assert dict(std.fixed) == dict(twin.fixed) | model
    assert std.analysis == twin.analysis and std.verification == twin.verification
    assert std.responses == twin.responses
    cols = [c for c in tables[name].columns if c != "point_id"]
    assert tables[f"{name}_standard"][cols].equals(tables[name][cols])


@pytest.mark.parametrize(
    "name, pairs",
    [
        ("wetfeed_pb", ("grain.grain", "grain.steel")),
        ("wetfeed_ccd", ("grain.grain", "grain.steel")),
        ("wetfeed_scatter_bond", ("grain.grain", "grain.steel")),
        ("phosphate_ffd", ("ore.ore", "ore.steel")),
    ],
)
def test_seed_001_and_002_standard_twins_differ_only_in_the_rolling_model(studies, tables, name, pairs):
    """Seed 001's and 002's studies with EDEM's standard rolling friction run their twins' points with the same
    factors, analysis, verification and responses; only the named pairs' rolling model is fixed on top (and seed
    002's screening is cut into launches of 8 worlds, one GPU's side-by-side limit at 131,000 spheres each)."""
    model = {f"interaction.{p}.rolling_model": "standard" for p in pairs}
    twin, std = studies[name], studies[f"{name}_standard"]
    assert dict(std.fixed) == dict(twin.fixed) | model
    assert std.factors == twin.factors and std.responses == twin.responses
    assert std.analysis == twin.analysis and std.verification == twin.verification
    assert std.batch == (8 if name == "phosphate_ffd" else twin.batch)
    cols = [c for c in tables[name].columns if c != "point_id"]
    assert tables[f"{name}_standard"][cols].equals(tables[name][cols])


@pytest.mark.parametrize("name, factor", [("wetfeed_pb", "G"), ("wetfeed_ccd", "X3")])
def test_seed_001_scaled_studies_differ_from_their_standard_twins_only_in_the_surface_energy(
    studies, tables, name, factor
):
    """wetfeed_pb_standard_scaled and wetfeed_ccd_standard_scaled run their standard-rolling twins' coded points
    with the surface energy's levels (and the fixed value that switches JKR on) times 0.2; nothing else changes."""
    twin, scaled = studies[f"{name}_standard"], studies[f"{name}_standard_scaled"]
    assert dict(scaled.fixed) == dict(twin.fixed) | {"surface_energy": round(0.2 * twin.fixed["surface_energy"], 12)}
    for a, b in zip(scaled.factors, twin.factors, strict=True):
        expected = (
            dataclasses.replace(b, low=round(0.2 * b.low, 12), high=round(0.2 * b.high, 12)) if a.name == factor else b
        )
        assert a == expected
    assert scaled.responses == twin.responses and scaled.analysis == twin.analysis
    assert scaled.verification == twin.verification
    t, t_twin = tables[f"{name}_standard_scaled"], tables[f"{name}_standard"]
    coded = [c for c in t.columns if c != "point_id" and not c.endswith("_actual")]
    assert t[coded].equals(t_twin[coded])
    np.testing.assert_allclose(t[f"{factor}_actual"], 0.2 * t_twin[f"{factor}_actual"], rtol=1e-12)


def test_seed_002_standard_scaled_screening_is_both_twins(studies, tables):
    """phosphate_ffd_standard_gamma_s is phosphate_ffd_gamma_s (D's levels 0.3 and 1.5 J/m^2 times s = 25.6) with
    the standard law fixed on the ore's pairs, and phosphate_ffd_standard with D's levels times s: the same 16 coded
    points, world seeds and launches of 8 as both."""
    model = {f"interaction.{p}.rolling_model": "standard" for p in ("ore.ore", "ore.steel")}
    spec, scaled, std = (
        studies[n] for n in ("phosphate_ffd_standard_gamma_s", "phosphate_ffd_gamma_s", "phosphate_ffd_standard")
    )
    assert dict(spec.fixed) == dict(scaled.fixed) | model == dict(std.fixed)
    assert spec.factors == scaled.factors and spec.responses == std.responses and spec.analysis == std.analysis
    d = {f.name: f for f in std.factors}["D"]
    assert {f.name: f for f in spec.factors}["D"] == dataclasses.replace(d, low=7.68, high=38.4)
    assert (7.68, 38.4) == (round(0.3 * 25.6, 9), round(1.5 * 25.6, 9)) and spec.batch == std.batch == 8
    t = tables["phosphate_ffd_standard_gamma_s"]
    cols = [c for c in t.columns if c != "point_id"]
    assert t[cols].equals(tables["phosphate_ffd_gamma_s"][cols])
    coded = [c for c in cols if not c.endswith("_actual")]
    assert t[coded].equals(tables["phosphate_ffd_standard"][coded])


def test_seed_001_type_a_screening_differs_from_its_twin_only_in_the_rolling_model(studies, tables):
    """wetfeed_pb_type_a_scaled runs wetfeed_pb_standard_scaled's 12 points with type A (constant torque) in place
    of EDEM's standard rolling friction on the grain's pairs, and differs from it in nothing else."""
    twin, spec = studies["wetfeed_pb_standard_scaled"], studies["wetfeed_pb_type_a_scaled"]
    model = {f"interaction.grain.{b}.rolling_model": "constant_torque" for b in ("grain", "steel")}
    assert dict(spec.fixed) == dict(twin.fixed) | model
    assert spec.factors == twin.factors and spec.responses == twin.responses and spec.analysis == twin.analysis
    cols = [c for c in tables["wetfeed_pb_standard_scaled"].columns if c != "point_id"]
    assert tables["wetfeed_pb_type_a_scaled"][cols].equals(tables["wetfeed_pb_standard_scaled"][cols])


def test_seed_001_verification_points_come_from_their_records(studies, tables):
    """wetfeed_verify_large_standard pours the seed's 25,000 grains at wetfeed_ccd_standard's chosen settings (its
    record's verification.json, to 4 decimals). wetfeed_verify_standard_scaled_step keeps the scaled composite's
    X1 and X2 and moves X3 by (54.25 - the verification's mean) over the fitted surface's slope in X3 there (its
    record's actual coefficients), the step its header states: 0.0941 + 1.86 / 166.9 = 0.1052 J/m^2.
    wetfeed_verify_large_standard_scaled pours the seed's 25,000 grains at that step's point, and
    wetfeed_verify_large_standard_scaled_step steps again from its mean: 0.1052 - 2.36 / 165.5 = 0.0909 J/m^2.
    wetfeed_verify_large_standard_scaled_friction steps from that record's mean in X1 instead, along the surface's
    slope in X1 there: 0.2752 - 1.81 / 64.0 = 0.2470."""
    import json

    names = ("X1", "X2", "X3")
    large, ccd = studies["wetfeed_verify_large_standard"], studies["wetfeed_ccd_standard"]
    resized = {"count": 25000, "outlet_height": 0.35, "duration": 16.0}
    assert dict(large.fixed) == dict(ccd.fixed) | resized
    chosen = json.loads((RECORDS_001 / "ccd_standard" / "verification" / "verification.json").read_text())
    t = tables["wetfeed_verify_large_standard"]
    assert {tuple(r) for r in t[[f"{n}_actual" for n in names]].to_numpy()} == {
        tuple(round(chosen["settings"][n], 4) for n in names)
    }
    assert list(t["world_seed"]) == [0, 1, 2, 3, 4]

    step = studies["wetfeed_verify_standard_scaled_step"]
    assert dict(step.fixed) == dict(studies["wetfeed_ccd_standard_scaled"].fixed)
    record = RECORDS_001 / "ccd_standard_scaled"
    v = json.loads((record / "verification" / "verification.json").read_text())
    x1, x2, x3 = (v["settings"][n] for n in names)
    b = pd.read_csv(record / "analysis" / "coefficients_aor_deg.csv").set_index("Term")["Actual Coefficient"]
    slope = b["X3"] + b["X1*X3"] * x1 + b["X2*X3"] * x2 + 2.0 * b["X3^2"] * x3
    assert slope == pytest.approx(166.9, abs=0.05)
    x3_step = x3 + (v["target"] - float(np.mean(v["values"]))) / slope
    t = tables["wetfeed_verify_standard_scaled_step"]
    assert {tuple(r) for r in t[[f"{n}_actual" for n in names]].to_numpy()} == {
        (round(x1, 4), round(x2, 4), round(x3_step, 4))
    }
    assert list(t["world_seed"]) == [0, 1, 2, 3, 4]

    # wetfeed_verify_large_standard_scaled: the step's point, resized to the seed's 25,000 grains as above
    large_step = studies["wetfeed_verify_large_standard_scaled"]
    assert dict(large_step.fixed) == dict(step.fixed) | resized
    assert large_step.factors == step.factors
    assert tables["wetfeed_verify_large_standard_scaled"].drop(columns="point_id").equals(t.drop(columns="point_id"))

    # wetfeed_verify_large_standard_scaled_step: the same step again, from that record's mean, along the slope there
    again = studies["wetfeed_verify_large_standard_scaled_step"]
    assert dict(again.fixed) == dict(large_step.fixed) and again.factors == large_step.factors
    x3 = round(x3_step, 4)
    slope = b["X3"] + b["X1*X3"] * x1 + b["X2*X3"] * x2 + 2.0 * b["X3^2"] * x3
    assert slope == pytest.approx(165.5, abs=0.05)
    mean = pd.read_csv(RECORDS_001 / "verify_large_standard_scaled" / "results.csv")["aor_deg"].mean()
    t = tables["wetfeed_verify_large_standard_scaled_step"]
    assert {tuple(r) for r in t[[f"{n}_actual" for n in names]].to_numpy()} == {
        (round(x1, 4), round(x2, 4), round(x3 + (v["target"] - mean) / slope, 4))
    }
    assert list(t["world_seed"]) == [0, 1, 2, 3, 4]

    # wetfeed_verify_large_standard_scaled_friction: from that step's mean, along the slope in X1 there, X2, X3 held
    friction = studies["wetfeed_verify_large_standard_scaled_friction"]
    assert dict(friction.fixed) == dict(again.fixed) and friction.factors == again.factors
    x1, x2, x3 = round(x1, 4), round(x2, 4), round(x3 + (v["target"] - mean) / slope, 4)
    slope_x1 = b["X1"] + b["X1*X2"] * x2 + b["X1*X3"] * x3 + 2.0 * b["X1^2"] * x1
    assert slope_x1 == pytest.approx(64.0, abs=0.05)
    mean = pd.read_csv(RECORDS_001 / "verify_large_standard_scaled_step" / "results.csv")["aor_deg"].mean()
    t = tables["wetfeed_verify_large_standard_scaled_friction"]
    assert {tuple(r) for r in t[[f"{n}_actual" for n in names]].to_numpy()} == {
        (round(x1 + (v["target"] - mean) / slope_x1, 4), x2, x3)
    }
    assert list(t["world_seed"]) == [0, 1, 2, 3, 4]


def test_plate_held_screening_differs_only_in_the_plate(studies, tables):
    """pellets_pb_standard_plate_held runs pellets_pb_standard's 12 points with the plate's friction held at the
    paper's calibrated particle-wall values (Table 12: A 0.52, B 0.03), nothing else changed."""
    held, pbs = studies["pellets_pb_standard_plate_held"], studies["pellets_pb_standard"]
    assert dict(held.fixed) == dict(pbs.fixed) | {"plate_static_friction": 0.52, "plate_rolling_friction": 0.03}
    cols = [c for c in tables["pellets_pb_standard"].columns if c != "point_id"]
    assert tables["pellets_pb_standard_plate_held"][cols].equals(tables["pellets_pb_standard"][cols])


@pytest.mark.parametrize("name", ["pellets_pb", "wetfeed_pb", "pellets_bbd", "wetfeed_ccd", "phosphate_bbd"])
def test_coded_matrix_equals_published_table(studies, tables, name):
    """Coded design = the seed's printed run table up to row order: seed 000 Tables 6 and 10, seed 001
    Tables 3 and 6, seed 002 Fig. 18."""
    ref = pd.read_csv(REF / f"{name}_runs.csv")
    names = studies[name].factor_names
    cols = names if name != "phosphate_bbd" else ["static_friction", "rolling_friction", "surface_energy"]
    assert _rows(tables[name], names) == _rows(ref, cols)


def test_phosphate_ffd_actual_levels_equal_fig14(studies, tables):
    """Seed 002 Fig. 14 (actual units) = the 2^(5-1) with E = ABCD at the Table 5 levels, row for row up
    to order; the pull-off constant is -0.009 at coded -1 and 0 at +1."""
    spec, t = studies["phosphate_ffd"], tables["phosphate_ffd"]
    ref = pd.read_csv(REF / "phosphate_ffd_runs.csv")
    cols = ["restitution", "static_friction", "rolling_friction", "surface_energy_J_m2", "pull_off_constant"]
    ours = pd.DataFrame([_by_actual(spec, r) for _, r in t.iterrows()])
    assert _rows(ours, spec.factor_names) == _rows(ref, cols)
    e = t[["A", "B", "C", "D", "E"]].to_numpy()
    np.testing.assert_array_equal(e[:, 4], np.prod(e[:, :4], axis=1))
    assert set(t.loc[t["E"] == -1, "E_actual"]) == {-0.009} and set(t.loc[t["E"] == 1, "E_actual"]) == {0.0}


def test_run_overrides_equal_seed_levels(studies, tables):
    """Override values are the seeds' actual levels: seed 000 Table 5 (PB), Table 9 reversed coding
    (-1 = 0.49, 0.75, 0.07), seed 001 Table 5 (-2..+2 = 0.1..0.5, 0.3..0.9, 0.2..0.8), and the fixed
    non-significant factors of each later stage."""
    spec, t = studies["pellets_pb"], tables["pellets_pb"]
    lv = pd.read_csv(REF / "pellets_pb_levels.csv").set_index("factor")
    for _, row in t.iterrows():
        ov = run_overrides(spec, row)
        for f in spec.factors:
            expect = lv.loc[f.name, "low"] if row[f.name] == -1 else lv.loc[f.name, "high"]
            assert ov[f.parameter] == expect
        assert ov["particle"] == "pellet" and ov["material"] == "pellet"

    spec, t = studies["pellets_bbd"], tables["pellets_bbd"]
    lv = pd.read_csv(REF / "pellets_bbd_levels.csv").set_index("factor")
    col = {-1: "level_minus1", 0: "level_0", 1: "level_plus1"}
    for _, row in t.iterrows():
        ov = run_overrides(spec, row)
        for f in spec.factors:
            assert ov[f.parameter] == lv.loc[f.name, col[int(row[f.name])]]
        assert ov["interaction.grain.steel.static_friction"] == 0.52
        assert ov["interaction.grain.steel.rolling_friction"] == 0.03
        assert ov["interaction.grain.grain.restitution"] == 0.37

    spec, t = studies["wetfeed_ccd"], tables["wetfeed_ccd"]
    lv = pd.read_csv(REF / "wetfeed_ccd_levels.csv").set_index("factor")
    col = {-2: "level_minus2", -1: "level_minus1", 0: "level_0", 1: "level_plus1", 2: "level_plus2"}
    for _, row in t.iterrows():
        ov = run_overrides(spec, row)
        for f in spec.factors:
            assert ov[f.parameter] == lv.loc[f.name, col[int(row[f.name])]]
        assert ov["interaction.grain.grain.restitution"] == 0.15
        assert ov["surface_energy"] > 0  # JKR grain-grain pair

    spec, t = studies["phosphate_bbd"], tables["phosphate_bbd"]
    ranges = {"B": (0.4, 1.0), "C": (0.0, 0.4), "D": (0.8, 1.2)}
    for _, row in t.iterrows():
        ov = run_overrides(spec, row)
        for f in spec.factors:
            lo, hi = ranges[f.name]
            assert ov[f.parameter] == pytest.approx(lo + (row[f.name] + 1) / 2 * (hi - lo), abs=1e-12)
        assert ov["interaction.ore.ore.pull_off_force"] == -0.009


def test_steepest_path_is_table8(studies, tables):
    """Seed 000 Table 8: six runs from C, D, E = 0.39, 0.45, 0.02 in steps of 0.02, 0.06, 0.01, in path
    order (not randomised)."""
    spec, t = studies["pellets_steepest"], tables["pellets_steepest"]
    ref = pd.read_csv(REF / "pellets_steepest_ascent.csv")
    ours = pd.DataFrame([_by_actual(spec, r) for _, r in t.iterrows()])
    np.testing.assert_array_equal(ours[["C", "D", "E"]].to_numpy(), ref[["C", "D", "E"]].to_numpy())
    assert list(t["std_order"]) == list(range(1, 7))


def test_gradient_path_and_explicit_points(tmp_path, studies):
    """The gradient form of steepest ascent follows designs.steepest_path: from the PB model of seed 000
    (eq. 5 in coded units: C 1.3275, D 3.318, E 1.7925) a D step of 0.06 moves C by 0.008 and E by
    0.00648, which is why Table 8's fixed steps are encoded as `step`. An explicit design runs the
    given actual points as they are, and its repeats get new world seeds."""
    text = (
        (STUDIES / "pellets_steepest.toml")
        .read_text()
        .replace(
            "step = { C = 0.02, D = 0.06, E = 0.01 }",
            'coefficients = { C = 1.3275, D = 3.318, E = 1.7925 }\nbase = "D"\nbase_step = 0.06',
        )
    )
    p = tmp_path / "grad.toml"
    p.write_text(text)
    t = design_table(load_study(p))
    np.testing.assert_allclose(np.diff(t["D_actual"]), 0.06, atol=1e-12)
    np.testing.assert_allclose(np.diff(t["C_actual"]), 0.06 * 1.3275 / 3.318 * 0.05 / 0.15, atol=1e-9)
    np.testing.assert_allclose(np.diff(t["E_actual"]), 0.06 * 1.7925 / 3.318 * 0.03 / 0.15, atol=1e-9)
    assert t["C_actual"].iloc[0] == 0.39
    text = (STUDIES / "pellets_steepest.toml").read_text()
    head = text.split("[design]")[0]
    tail = text.split("[[responses]]")[1]
    pts = "[{C = 0.45, D = 0.55, E = 0.05}, {C = 0.41, D = 0.51, E = 0.03}, {C = 0.45, D = 0.55, E = 0.05}]"
    p = tmp_path / "explicit.toml"
    p.write_text(head + f'[design]\nkind = "explicit"\npoints = {pts}\nrandomize = false\n[[responses]]' + tail)
    spec = load_study(p)
    t = design_table(spec)
    assert list(t["point_type"]) == ["point"] * 3 and list(t["world_seed"]) == [0, 0, 1]
    assert [_by_actual(spec, r) for _, r in t.iterrows()][1] == {"C": 0.41, "D": 0.51, "E": 0.03}
    assert t.loc[1, "C"] == pytest.approx(-0.6)


def test_spec_is_frozen_and_picklable(studies):
    """A StudySpec is immutable, hashable and survives pickling (a runner may hand it to workers)."""
    import dataclasses
    import pickle

    spec = studies["wetfeed_ccd"]
    assert pickle.loads(pickle.dumps(spec)) == spec and hash(spec)
    with pytest.raises(dataclasses.FrozenInstanceError):
        spec.seed = 2
    with pytest.raises(TypeError):
        spec.fixed["count"] = 1
    assert [f.name for f in spec.levels] == spec.factor_names == ["X1", "X2", "X3"]
    assert spec.factors[0].factor.to_actual(2.0) == pytest.approx(0.5)


def test_world_seed_distinct_for_repeated_points(tables):
    """A deterministic simulation repeats a point exactly: the 5 (seed 000), 3 (seed 002) and 9 (seed 001)
    centre runs get world seeds 0..n-1, every other point 0, and no (point, world_seed) pair repeats."""
    for name, t in tables.items():
        acts = [c for c in t.columns if c.endswith("_actual")]
        keys = [tuple(r) for r in t[acts + ["world_seed"]].to_numpy()]
        assert len(set(keys)) == len(keys), name
        for _, grp in t.groupby(acts):
            assert sorted(grp["world_seed"]) == list(range(len(grp))), name
    centres = {"pellets_bbd": 5, "phosphate_bbd": 3, "wetfeed_ccd": 9}
    for name, n in centres.items():
        t = tables[name]
        assert sorted(t.loc[t["point_type"] == "centre", "world_seed"]) == list(range(n))


def test_point_id_unique_stable_and_order_free(tmp_path, tables):
    """point_id is unique, equal across two loads, and follows the run, not its position: a different
    randomisation seed reorders the runs but keeps each run's id."""
    for name, t in tables.items():
        assert t["point_id"].is_unique, name
        again = design_table(load_study(STUDIES / f"{name}.toml"))
        assert list(again["point_id"]) == list(t["point_id"]), name
    text = (STUDIES / "pellets_bbd.toml").read_text().replace("seed = 1\n", "seed = 7\n", 1)
    other = tmp_path / "pellets_bbd.toml"
    other.write_text(text)
    t2 = design_table(load_study(other))
    t1 = tables["pellets_bbd"]
    assert list(t2["std_order"]) != list(t1["std_order"])
    assert dict(zip(t1["std_order"], t1["point_id"])) == dict(zip(t2["std_order"], t2["point_id"]))


def test_replicates_get_new_world_seeds(tmp_path):
    """Whole-design replicates repeat every point: the second copy runs with world seed 1 (the first
    with 0), so replicates give pure error; std_order runs over both copies."""
    text = (STUDIES / "pellets_pb.toml").read_text().replace("replicates = 1\nrandomize", "replicates = 2\nrandomize")
    p = tmp_path / "pellets_pb.toml"
    p.write_text(text)
    t = design_table(load_study(p))
    assert len(t) == 24 and sorted(t["std_order"]) == list(range(1, 25))
    assert (t.groupby("replicate")["world_seed"].apply(set) == pd.Series({0: {0}, 1: {1}})).all()
    assert t["point_id"].is_unique


def test_batch_key_groups_runs(studies, tables, tmp_path):
    """Interaction fields and material scalars vary per world, so each seed study is one batch; a factor on a
    rig parameter (the funnel's integer placement seed; the press's fill seed in wetfeed_press_seed_size) makes one
    batch per level."""
    per_level = {"wetfeed_press_seed_size": 5}
    assert varies_per_world("interaction.grain.grain.static_friction")
    assert varies_per_world("material.grain.density")
    assert varies_per_world("interaction.grain.grain.law")
    assert not varies_per_world("count") and not varies_per_world("run.duration")
    for name, spec in studies.items():
        keys = {batch_key(spec, run_overrides(spec, r)) for _, r in tables[name].iterrows()}
        assert len(keys) == per_level.get(name, 1), name
    text = (
        (STUDIES / "main_funnel_pb.toml")
        .read_text()
        .replace(
            'parameter = "interaction.grain.grain.restitution"\nlow = 0.05\nhigh = 0.1',
            'parameter = "seed"\nlow = 1\nhigh = 3',
        )
    )
    p = tmp_path / "main_funnel_pb.toml"
    p.write_text(text)
    spec = load_study(p)
    ovs = [run_overrides(spec, r) for _, r in design_table(spec).iterrows()]
    assert {o["seed"] for o in ovs} == {1, 3} and all(isinstance(o["seed"], int) for o in ovs)
    assert len({batch_key(spec, o) for o in ovs}) == 2


def test_fixed_clump_contact_mass_reaches_the_scene(tmp_path):
    """[fixed] "run.clump_contact_mass" = "body" (EDEM's damping convention, for comparing with EDEM) is the
    run setting of every run's scene."""
    from warpdem.study.execute import _scene

    p = tmp_path / "s.toml"
    p.write_text(
        BASE.replace(
            '"interaction.grain.grain.restitution" = 0.3',
            '"interaction.grain.grain.restitution" = 0.3\n"run.clump_contact_mass" = "body"',
        )
    )
    spec = load_study(p)
    row = design_table(spec).iloc[0]
    assert _scene(spec, run_overrides(spec, row)).run.clump_contact_mass == "body"


def test_scene_study_and_bare_dotted_keys(tmp_path):
    """A study may name a stage relative to its file instead of a rig; a bare dotted [fixed] key (a TOML
    sub-table) means the same as the quoted key."""
    scene = os.path.relpath(ROOT / "scenes" / "funnel.usda", tmp_path)
    text = BASE.replace('rig = "funnel"\nsmoke = true', f'scene = "{scene}"').replace(
        '"interaction.grain.grain.restitution" = 0.3', "interaction.grain.grain.restitution = 0.3"
    )
    p = tmp_path / "s.toml"
    p.write_text(text)
    spec = load_study(p)
    assert spec.scene_path == (ROOT / "scenes" / "funnel.usda").resolve()
    assert spec.fixed["interaction.grain.grain.restitution"] == 0.3


# --------------------------------------------------------------------------------------------------
BASE = """
[study]
name = "bad_case"
title = "a small valid study that each case breaks"
rig = "funnel"
smoke = true
seed = 1
batch = 0

[fixed]
"interaction.grain.grain.restitution" = 0.3

[[factors]]
name = "A"
parameter = "interaction.grain.grain.static_friction"
low = 0.4
high = 0.8

[[factors]]
name = "B"
parameter = "interaction.grain.steel.static_friction"
low = 0.3
high = 0.6

[[factors]]
name = "C"
parameter = "interaction.grain.grain.rolling_friction"
low = 0.1
high = 0.2

[design]
kind = "plackett_burman"
runs = 12
replicates = 1

[[responses]]
name = "aor_deg"
measure = "angle_fit_deg"

[analysis]
model = "linear"

[verification]
replicates = 0
"""

_PB = 'kind = "plackett_burman"\nruns = 12'
_FAC_B = 'name = "B"\nparameter = "interaction.grain.steel.static_friction"\nlow = 0.3\nhigh = 0.6'
_FIXED = '"interaction.grain.grain.restitution" = 0.3'
_B_PARAMETER = '"interaction.grain.steel.static_friction"\nlow = 0.3'


def _fixed(case, line, *needles):
    """A case replacing BASE's [fixed] override by ``line``; the message must name [fixed] and ``needles``."""
    return (case, _FIXED, line, ["[fixed]", *needles])


def _parameter_b(case, key, *needles):
    """A case giving factor B the parameter ``key``; the message must name the factor and ``needles``."""
    return (case, _B_PARAMETER, f'"{key}"\nlow = 0.3', ["[[factors]] 'B'", *needles])


BAD = [
    # (id, old, new, substrings the message must contain)
    ("toml-syntax", "seed = 1", "seed = = 1", ["not valid TOML"]),
    ("unknown-table", "[design]", "[desing]", ["[desing]", "did you mean 'design'"]),
    ("unknown-key", "seed = 1", "sed = 1", ["[study]", "'sed'", "did you mean 'seed'"]),
    ("missing-design", "[design]\n" + _PB + "\nreplicates = 1", "", ["[design] is missing"]),
    ("bad-name", 'name = "bad_case"', 'name = "Bad Case"', ["[study]", "name = 'Bad Case'"]),
    ("unknown-rig", 'rig = "funnel"', 'rig = "funel"', ["rig = 'funel'", "did you mean 'funnel'"]),
    ("rig-and-scene", "smoke = true", 'smoke = true\nscene = "x.usda"', ["exactly one of rig"]),
    ("missing-scene", 'rig = "funnel"\nsmoke = true', 'scene = "nowhere/funnel.usda"', ["scene =", "does not exist"]),
    ("negative-seed", "seed = 1", "seed = -1", ["seed = -1", "integer >= 0"]),
    _fixed(
        "fixed-unknown-field", _FIXED.replace("restitution", "restitutoin"), "restitutoin", "did you mean 'restitution'"
    ),
    _fixed("fixed-unknown-rig-param", "partcle_radius = 0.003", "partcle_radius", "did you mean 'particle_radius'"),
    _fixed(
        "fixed-unknown-material",
        _FIXED.replace("grain.grain", "grian.grain"),
        "interaction.grian.grain.restitution",
        "material 'grian'",
    ),
    _fixed("fixed-value-refused", _FIXED.replace("0.3", "1.5"), "restitution = 1.5", "(0, 1]"),
    _fixed("fixed-rig-value-refused", 'material = "wood"', "material = 'wood'", "pellet or feed"),
    _parameter_b("factor-key-form", "interaction.grain.static_friction", "parameter", "interaction.A.B.FIELD"),
    _parameter_b("factor-not-numeric", "interaction.grain.steel.law", "parameter", "numeric interaction field"),
    _parameter_b("factor-bool-rig-param", "particle", "numeric funnel parameter"),
    (
        "factor-missing-key",
        _FAC_B,
        'name = "B"\nparameter = "interaction.grain.steel.static_friction"\nlow = 0.3',
        ["[[factors]] #2 'B'", "high is missing"],
    ),
    ("factor-unknown-key", _FAC_B, _FAC_B + '\nunits = "-"', ["[[factors]] #2 'B'", "did you mean 'unit'"]),
    ("duplicate-factor", 'name = "B"', 'name = "A"', ["[[factors]] 'A'", "unique factor names"]),
    _parameter_b("duplicate-parameter", "interaction.grain.grain.static_friction", "already sets it"),
    (
        "factor-also-fixed",
        _FIXED,
        '"interaction.grain.steel.static_friction" = 0.3',
        ["[[factors]] 'B'", "[fixed] sets it too"],
    ),
    (
        "low-equals-high",
        "low = 0.3\nhigh = 0.6",
        "low = 0.3\nhigh = 0.3",
        ["[[factors]] 'B'", "low = 0.3 and high = 0.3"],
    ),
    ("bad-factor-name", 'name = "B"', 'name = "2B"', ["[[factors]]", "name = '2B'"]),
    ("reserved-factor-name", 'name = "B"', 'name = "run"', ["[[factors]] 'run'", "design-table column"]),
    (
        "extreme-value-refused",
        _PB,
        'kind = "central_composite"\nalpha = 4.0',
        ["[[factors]] 'A'", "static_friction = -0.2", "lowest"],
    ),
    ("replicates-zero", "replicates = 1", "replicates = 0", ["[design]", "replicates = 0", "integer >= 1"]),
    ("unknown-kind", '"plackett_burman"', '"plackett_burmann"', ["kind = 'plackett_burmann'", "did you mean"]),
    ("pb-runs", "runs = 12", "runs = 16", ["[design]", "runs = 16", "12 or 20"]),
    ("option-of-other-kind", "runs = 12", "runs = 12\nalpha = 2.0", ["alpha = 2.0", "central_composite"]),
    ("ff-no-generators", _PB, 'kind = "fractional_factorial"', ["[design]", "generators is missing", "E = ABCD"]),
    (
        "ff-bad-generator",
        _PB,
        'kind = "fractional_factorial"\ngenerators = ["C = AZ"]',
        ["[design]", "unknown factors"],
    ),
    ("ccd-bad-alpha", _PB, 'kind = "central_composite"\nalpha = "rotatible"', ["alpha = 'rotatible'", "rotatable"]),
    (
        "steepest-missing-factor",
        _PB,
        'kind = "steepest_ascent"\nsteps = 4\nstep = {A = 0.1, B = 0.05}',
        ["[design]", "step", "lacks factor(s) C"],
    ),
    (
        "steepest-unknown-factor",
        _PB,
        'kind = "steepest_ascent"\nsteps = 4\nstep = {A = 0.1, B = 0.05, Z = 0.1}',
        ["[design]", "'Z'", "not a factor"],
    ),
    (
        "steepest-both",
        _PB,
        'kind = "steepest_ascent"\nsteps = 4\nstep = {A = 0.1, B = 0.05, C = 0.01}\nbase = "A"',
        ["[design]", "not both"],
    ),
    ("explicit-missing", _PB, 'kind = "explicit"\npoints = [{A = 0.5, B = 0.4}]', ["points[0]", "lacks factor(s) C"]),
    (
        "unknown-measure",
        'measure = "angle_fit_deg"',
        'measure = "angle_fit"',
        ["[[responses]] 'aor_deg'", "did you mean 'angle_fit_deg'"],
    ),
    ("no-responses", '[[responses]]\nname = "aor_deg"\nmeasure = "angle_fit_deg"', "", ["[responses] is missing"]),
    ("model-not-estimable", 'model = "linear"', 'model = "quadratic"', ["[analysis]", "model = 'quadratic'", "rank"]),
    ("model-unknown-term", 'model = "linear"', 'model = ["A", "A*Z"]', ["[analysis]", "A*Z"]),
    ("model-unknown-name", 'model = "linear"', 'model = "cubic"', ["[analysis]", "model = 'cubic'"]),
    ("analysis-alpha", 'model = "linear"', 'model = "linear"\nalpha = 1.5', ["[analysis]", "alpha = 1.5", "(0, 1)"]),
    ("verification-negative", "replicates = 0", "replicates = -1", ["[verification]", "replicates = -1"]),
    (
        "goal-unknown",
        'measure = "angle_fit_deg"',
        'measure = "angle_fit_deg"\ngoal = "maximise"\nlow = 20\nhigh = 40',
        ["[[responses]] 'aor_deg'", "goal = 'maximise'", "did you mean 'maximize'"],
    ),
    (
        "goal-no-high",
        'measure = "angle_fit_deg"',
        'measure = "angle_fit_deg"\ngoal = "minimize"\nlow = 20',
        ["[[responses]] 'aor_deg'", "high", "needs both low and high"],
    ),
    (
        "goal-target-outside",
        'measure = "angle_fit_deg"',
        'measure = "angle_fit_deg"\ntarget = 45.0\ngoal = "target"\nlow = 20\nhigh = 40',
        ["[[responses]] 'aor_deg'", "target = 45.0", "strictly between low 20.0 and high 40.0"],
    ),
    (
        "goal-limits-without-goal",
        'measure = "angle_fit_deg"',
        'measure = "angle_fit_deg"\nlow = 20',
        ["[[responses]] 'aor_deg'", "low = 20", "a goal"],
    ),
    (
        "goal-importance",
        'measure = "angle_fit_deg"',
        'measure = "angle_fit_deg"\ngoal = "maximize"\nlow = 20\nhigh = 40\nimportance = 7',
        ["[[responses]] 'aor_deg'", "importance = 7", "1 to 5"],
    ),
    (
        "clump-mass-word",
        '"interaction.grain.grain.restitution" = 0.3',
        '"interaction.grain.grain.restitution" = 0.3\n"run.clump_contact_mass" = "half"',
        ["[fixed]", "run.clump_contact_mass = 'half'", "shared or body"],
    ),
]


@pytest.mark.parametrize("case, old, new, needles", BAD, ids=[b[0] for b in BAD])
def test_bad_input_raises_study_error_naming_the_field(tmp_path, case, old, new, needles):
    """Each class of bad input raises StudyError (a ValueError) whose message names the file and the
    table/field, the value and what is allowed."""
    assert old in BASE, case
    p = tmp_path / f"{case}.toml"
    p.write_text(BASE.replace(old, new, 1))
    with pytest.raises(StudyError) as err:
        load_study(p)
    msg = str(err.value)
    assert str(p) in msg
    for needle in needles:
        assert needle in msg, f"{case}: {needle!r} not in {msg!r}"


def test_factors_must_be_an_array_of_tables(tmp_path):
    """[factors] written as one table (not [[factors]]) is refused with the right spelling."""
    head, rest = BASE.split("[[factors]]", 1)
    text = (
        head + '[factors]\nname = "A"\nparameter = "interaction.grain.grain.static_friction"\nlow = 0.4\n'
        "high = 0.8\n\n[design]" + rest.split("[design]", 1)[1]
    )
    p = tmp_path / "table.toml"
    p.write_text(text)
    with pytest.raises(StudyError, match=r"\[factors\]: expected an array of tables, written \[\[factors\]\]"):
        load_study(p)


def test_base_case_is_valid(tmp_path):
    """The template the bad cases break is itself a valid study (so each case fails for its own reason);
    it also loads with a Box-Behnken and a central composite design."""
    for text in (
        BASE,
        BASE.replace(_PB, 'kind = "box_behnken"\ncenter_points = 3'),
        BASE.replace(_PB, 'kind = "central_composite"\nalpha = "face"').replace('"linear"', '"quadratic"'),
    ):
        p = tmp_path / "ok.toml"
        p.write_text(text)
        assert len(design_table(load_study(p))) > 0


PRESS_STUDY = """
[study]
name = "press_repeats"
rig = "die_press"
smoke = true

[[factors]]
name = "mu"
parameter = "interaction.feed.feed.static_friction"
low = 0.4
high = 0.6
{extra}
[design]
kind = "explicit"
points = [{points}]

[[responses]]
name = "ratio"
measure = "compression_ratio"

[verification]
replicates = {replicates}
"""


@pytest.mark.parametrize(
    "points, extra, replicates, needle",
    [
        ("{ mu = 0.5 }, { mu = 0.5 }", "", 0, "[design]: run 2 repeats an earlier point with world seed 1"),
        ("{ mu = 0.5 }, { mu = 0.6 }", "", 2, "[verification]: replicates = 2 repeat one point"),
    ],
)
def test_repeats_of_a_static_fill_are_refused(tmp_path, points, extra, replicates, needle):
    """The die press's bed is a static fill, which a world seed does not move (world seeds place dynamic
    factories' particles only): repeated points or verification replicates would be identical runs, so the study
    is refused, naming the file, the run and the fill; repeats through the rig's own seed load."""
    from warpdem.scene import rigs
    from warpdem.scene.stage import world_seeds_move

    assert not world_seeds_move(rigs.spec("die_press", {}, smoke=True))
    assert world_seeds_move(rigs.spec("funnel", {}, smoke=True))
    p = tmp_path / "press.toml"
    p.write_text(PRESS_STUDY.format(points=points, extra=extra, replicates=replicates))
    with pytest.raises(StudyError) as err:
        load_study(p)
    msg = str(err.value)
    assert msg.startswith(f"{p}: {needle}") and "static fills only (factories: 'fill')" in msg, msg
    seeded = '\n[[factors]]\nname = "S"\nparameter = "seed"\nlow = 1\nhigh = 2\n'
    p.write_text(PRESS_STUDY.format(points="{ mu = 0.5, S = 1 }, { mu = 0.5, S = 2 }", extra=seeded, replicates=1))
    spec = load_study(p)
    assert [run_overrides(spec, r)["seed"] for _, r in design_table(spec).iterrows()] == [1, 2]
