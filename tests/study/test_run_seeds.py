"""docs/seeds/run_seeds.py's step names: a study file is a step without an entry of its own, a misspelt one is
refused by name."""

import pytest

from tests.conftest import load_seed_script


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
