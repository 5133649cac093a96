"""docs/seeds/run_seeds.py's step names: a study file is a step without an entry of its own, a misspelt one is
refused by name."""

from pathlib import Path

import pytest

from tests.conftest import load_seed_script

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def run_seeds():
    return load_seed_script("run_seeds.py")


def test_a_study_file_is_a_step(run_seeds, tmp_path):
    ((name, argv),) = run_seeds.parse_lane("cuda:0,cuda:1=pellets_bbd_standard_own", tmp_path)
    assert name == "pellets_bbd_standard_own"
    assert argv[argv.index("study") + 1] == "studies/pellets_bbd_standard_own.toml"
    assert argv[argv.index("--device") + 1] == "cuda:0,cuda:1"
    assert argv[argv.index("--out") + 1] == str(tmp_path / name)


def test_a_named_step_keeps_its_own_command(run_seeds, tmp_path):
    ((_, argv),) = run_seeds.parse_lane("cuda:0=wetfeed_gamma_scan", tmp_path)
    assert "--no-verify" in argv  # a plain study step would verify


def test_the_default_lanes_resolve(run_seeds, tmp_path):
    for lane in run_seeds.LANES:
        assert run_seeds.parse_lane(lane, tmp_path)


@pytest.mark.parametrize("lane", ["cuda:0=pellets_bdd", "cuda:0=", "=wetfeed_pb"])
def test_an_unknown_step_is_refused_by_name(run_seeds, tmp_path, lane):
    with pytest.raises(SystemExit) as e:
        run_seeds.parse_lane(lane, tmp_path)
    assert repr(lane) in str(e.value)
    if lane.endswith("pellets_bdd"):
        assert "not found: pellets_bdd" in str(e.value)


def test_the_scaled_presses_carry_the_recalibrated_set(run_seeds, tmp_path):
    """Both presses of seed 001's recalibrated model set the sixteenth stage's X1, X2, X3 and the standard rolling
    model on the feed's pairs; the fuller one adds only the fill height, and the words stay words."""
    ((_, base),) = run_seeds.parse_lane("cuda:0=die_press_standard_scaled", tmp_path)
    ((_, full),) = run_seeds.parse_lane("cuda:0=die_press_standard_scaled_80", tmp_path)
    sets = [base[i + 1] for i, a in enumerate(base) if a == "--set"]
    assert sets == [
        "die_press.interaction.feed.feed.rolling_friction=0.2752",
        "die_press.interaction.feed.feed.static_friction=0.5904",
        "die_press.interaction.feed.feed.surface_energy=0.1052",
        "die_press.interaction.feed.feed.rolling_model=standard",
        "die_press.interaction.feed.steel.rolling_model=standard",
    ]
    assert [full[i + 1] for i, a in enumerate(full) if a == "--set"] == sets + ["die_press.fill_height=0.0835"]
    assert full[full.index("--out") + 1] == str(tmp_path / "die_press_standard_scaled_80")


def test_the_seed_size_press_reads_the_landed_point(run_seeds, tmp_path):
    """The press at the seed's size sets the X1, X2, X3 of the study that landed at 25,000 grains (read from its
    design, not written again), the standard rolling model and the fuller die's fill height."""
    import tomllib

    study = tomllib.loads((ROOT / "studies" / f"{run_seeds.SEED_SIZE_STUDY}.toml").read_text())
    point = study["design"]["points"][0]
    ((_, cmd),) = run_seeds.parse_lane("cuda:0=die_press_seed_size_80", tmp_path)
    sets = dict(cmd[i + 1].removeprefix("die_press.").split("=") for i, a in enumerate(cmd) if a == "--set")
    for f, key in run_seeds.PRESS_KEYS.items():
        assert float(sets.pop(key)) == pytest.approx(point[f], rel=1e-6), f
    assert sets == {
        "interaction.feed.feed.rolling_model": "standard",
        "interaction.feed.steel.rolling_model": "standard",
        "fill_height": "0.0835",
    }
    assert cmd[cmd.index("--out") + 1] == str(tmp_path / "die_press_seed_size_80")


def test_the_press_replicates_press_the_seed_size_set_with_new_fills(run_seeds):
    """wetfeed_press_seed_size presses the set of the seed-size press step (run_seeds.seed_size_set, the fuller
    die's fill height) in every run, each with its own fill seed, none of them the rig run's."""
    from warpdem.scene.rigs import DiePress
    from warpdem.study.spec import design_table, load_study, run_overrides

    spec = load_study(ROOT / "studies" / "wetfeed_press_seed_size.toml")
    rows = [run_overrides(spec, row) for _, row in design_table(spec).iterrows()]
    expected = dict(run_seeds.seed_size_set()) | dict([run_seeds.FULLER_FILL])
    seeds = []
    for ov in rows:
        seeds.append(ov.pop("seed"))
        assert ov.keys() == expected.keys()
        for key, value in expected.items():
            assert ov[key] == (pytest.approx(value, rel=1e-12) if isinstance(value, float) else value), key
    assert sorted(seeds) == [2, 3, 4, 5, 6] and all(isinstance(s, int) for s in seeds)
    assert DiePress.seed not in seeds


def test_the_further_fills_and_the_stiff_press_add_one_override_each(run_seeds, tmp_path):
    """Fills 2-6 are the seed-size press with the rig's seed set, the stiff press with the feed's shear modulus ten
    times the seed's 10 MPa; every other override is die_press_seed_size_80's, so the presses compare like with
    like. The large rolling-model check runs its own data file."""
    ((_, base),) = run_seeds.parse_lane("cuda:0=die_press_seed_size_80", tmp_path)
    sets = [base[i + 1] for i, a in enumerate(base) if a == "--set"]
    for n in (2, 3, 4, 5, 6):
        ((_, cmd),) = run_seeds.parse_lane(f"cuda:0=die_press_seed_size_80_s{n}", tmp_path)
        assert [cmd[i + 1] for i, a in enumerate(cmd) if a == "--set"] == sets + [f"die_press.seed={n}"]
        assert cmd[cmd.index("--out") + 1] == str(tmp_path / f"die_press_seed_size_80_s{n}")
    ((_, stiff),) = run_seeds.parse_lane("cuda:0=die_press_seed_size_80_stiff", tmp_path)
    extra = [stiff[i + 1] for i, a in enumerate(stiff) if a == "--set"][len(sets) :]
    assert extra == ["die_press.material.feed.shear_modulus=1e+08"] and float(extra[0].split("=")[1]) == 10 * 1.0e7
    ((_, diag),) = run_seeds.parse_lane("cuda:0=seed001_reach_large_confirm6", tmp_path)
    assert diag[diag.index("diagnose") + 1] == "studies/diagnose/seed001_wetfeed_large_confirm6.toml"


def test_the_gamma_press_changes_only_the_surface_energy(run_seeds, tmp_path):
    """The press with the sixteenth stage's surface energy is die_press_seed_size_80 with X3 replaced in place (no
    second X3 override), to the sixteenth stage's value; replacing a key the set lacks is refused by name."""

    def sets(step):
        ((_, cmd),) = run_seeds.parse_lane(f"cuda:0={step}", tmp_path)
        return [cmd[i + 1] for i, a in enumerate(cmd) if a == "--set"]

    base, gamma = sets("die_press_seed_size_80"), sets("die_press_seed_size_80_gamma")
    changed = [(a, b) for a, b in zip(base, gamma, strict=True) if a != b]
    assert changed == [
        (
            "die_press.interaction.feed.feed.surface_energy=0.0909",
            "die_press.interaction.feed.feed.surface_energy=0.1052",
        )
    ]
    assert run_seeds.SIXTEENTH_GAMMA == ("interaction.feed.feed.surface_energy", 0.1052)
    with pytest.raises(KeyError, match="material.feed.shear_modulus"):
        run_seeds.replaced(run_seeds.seed_size_set(), run_seeds.STIFF_FEED)
