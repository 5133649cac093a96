"""docs/seeds/press_checkpoint.py: a press checkpoint's loading figures are the run's own rule
(measure.press_loading) on the series the checkpoint holds, and a checkpoint taken before the bar turned back is
refused by name."""

import json

import numpy as np
import pytest

from tests.conftest import load_seed_script
from warpdem.scene.measure import press_loading
from warpdem.scene.rigs import DiePress


@pytest.fixture(scope="module")
def pc():
    return load_seed_script("press_checkpoint.py")


def _checkpoint(path, series, time=1.3):
    meta = {"time": time, "series": series}
    np.savez(path, meta=np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8), other=np.zeros(3))
    return path


def _series(turn=None):
    """A bar that approaches, presses a bed of F = k d^2 past the force limit, then turns back."""
    z = np.linspace(0.12, 0.035, 900)
    f = 2.0e5 * np.clip(0.0802 - z, 0, None) ** 2
    top = np.linspace(0.0812, 0.0802, len(z))
    s = {"piston_z": z.tolist(), "piston_force": f.tolist(), "bed_top": top.tolist()}
    s |= {"peak_overlap": {"deepest": [1.4], "mean": [0.3]}, "escaped": [12]}
    if turn is not None:
        s |= {"unload_index": turn, "unload_start_s": 1.1}
    return s


def test_the_figures_are_the_runs_rule_on_the_checkpoints_series(pc, tmp_path):
    limit = DiePress().force_limit
    s = _series()
    turn = int(np.argmax(np.asarray(s["piston_force"]) >= limit)) + 2
    path = _checkpoint(tmp_path / "checkpoint.npz", _series(turn))
    got = pc.read(path)
    want = press_loading(s["piston_z"], s["piston_force"], s["bed_top"], limit, 0.0, turn)
    for key in ("fill_height_m", "max_displacement_m", "compression_ratio"):
        assert got[key] == want[key], key
    # F = 2e5 (0.0802 - z)^2 reaches 300 N at 38.7 mm of travel below the bed's top
    assert got["limit_reached"] is True
    assert got["max_displacement_m"] == pytest.approx(
        np.sqrt(limit / 2.0e5) - (0.0802 - got["fill_height_m"]), abs=1e-4
    )
    assert (got["peak_overlap_max"], got["peak_overlap_mean"], got["escaped"]) == (1.4, 0.3, 12)
    out = tmp_path / "loading.json"
    assert pc.main([str(path), "--json", str(out)]) == 0
    (row,) = json.loads(out.read_text())
    assert row["compression_ratio"] == got["compression_ratio"] and "curve" not in row


def test_a_checkpoint_before_the_turn_is_refused_by_name(pc, tmp_path):
    path = _checkpoint(tmp_path / "early.npz", _series(turn=None), time=0.9)
    with pytest.raises(SystemExit, match=r"early\.npz: the bar has not turned back yet .* at 0\.9 s"):
        pc.read(path)
    np.savez(tmp_path / "plain.npz", x=np.zeros(2))
    with pytest.raises(SystemExit, match=r"plain\.npz: no 'meta' array"):
        pc.read(tmp_path / "plain.npz")
