"""The diagnosis end to end on data with a hidden effect it never sees, and on data with none.

"Measured" data are made here by running the engine with a hidden setting (world seeds the diagnosis never uses,
so its scatter is the model's own) and adding measurement noise of a stated SD; the diagnosis sees only the CSV.
The scenes are cut to a few seconds of one CPU core per world (tiny funnel piles, a 94-sphere die press).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("warp")
pytest.importorskip("sklearn")
pytest.importorskip("emcee")

from warpdem.diagnose.pipeline import diagnose  # noqa: E402
from warpdem.scene import rigs  # noqa: E402
from warpdem.scene.runner import run_scene  # noqa: E402
from warpdem.scene.stage import apply_overrides  # noqa: E402

DATA_SEEDS = (501, 502, 503)
"""World seeds of the 'measurements' (the diagnosis uses 0, 1, 2, ... and 101, 102, ...)."""


def _measure(rig: str, smoke: bool, rig_values: dict, overrides: dict, seeds, measure: str) -> list[float]:
    """Run the engine with the hidden setting: one value of ``measure`` per world seed."""
    scene = apply_overrides(rigs.spec(rig, rig_values, smoke), overrides)
    if scene.measure.kind == "press":
        mets = [run_scene(scene, world_count=1, world_seeds=[s], frames=False).metrics[0] for s in seeds]
    else:
        mets = run_scene(scene, world_count=len(seeds), world_seeds=list(seeds), frames=False).metrics
    return [float(m[measure]) for m in mets]


def _write_case(tmp_path, name: str, toml: str, rows: list[dict]) -> str:
    import pandas as pd

    pd.DataFrame(rows).to_csv(tmp_path / f"{name}.csv", index=False)
    path = tmp_path / f"{name}.toml"
    path.write_text(toml.format(csv=f"{name}.csv", name=name))
    return str(path)


# --------------------------------------------------------------------------------------------------
# the die press: plasticity hidden
# --------------------------------------------------------------------------------------------------

PRESS_RIG = {
    "die_diameter": 0.005,
    "fill_height": 0.006,
    "inlet_diameter": 0.008,
    "gap": 0.001,
    "settle_time": 0.05,
    "surface_energy": 0.0,
}
PRESS_SOFT = {"material.feed.shear_modulus": 1.0e6}
FORCES = (0.5, 1.0, 2.0)
PRESS_TOML = """
[diagnose]
name = "{name}"
rig = "die_press"
smoke = true
seed = 1

[fixed]
law = "hertz_mindlin"
die_diameter = 0.005
fill_height = 0.006
inlet_diameter = 0.008
gap = 0.001
settle_time = 0.05
surface_energy = 0.0
"material.feed.shear_modulus" = 1.0e6

[[parameters]]
name = "mu_s"
parameter = "interaction.feed.feed.static_friction"
low = 0.1
high = 1.0

[experiments]
file = "{csv}"

[noise]
sim_seeds = 2

[calibration]
points = 6
confirm_seeds = 2
mcmc_steps = 400

[candidates]
use = ["plasticity", "cohesion"]
"""


def _press_rows(hidden_law: str, plasticity: float, sd: float, rng, mu_s: float = 0.5) -> list[dict]:
    rows = []
    for k, force in enumerate(FORCES):
        values = _measure(
            "die_press",
            True,
            {**PRESS_RIG, "law": hidden_law, "plasticity_ratio": plasticity, "force_limit": force},
            {**PRESS_SOFT, "interaction.feed.feed.static_friction": mu_s},
            DATA_SEEDS,
            "residual_set_ratio",
        )
        for j, v in enumerate(values):
            rows.append(
                {"id": f"F{k}", "replicate": j + 1, "force_limit": force, "residual_set_ratio": v + rng.normal(0, sd)}
            )
    return rows


@pytest.fixture(scope="module")
def press_runs(tmp_path_factory):
    """One store of simulated worlds for the press cases: the null and the plasticity case share the scene, the
    conditions and the base model's design, so the second reuses the first's worlds (as a rerun would)."""
    return tmp_path_factory.mktemp("press_runs")


def _diagnose_sharing(path, out, runs):
    out.mkdir()
    (out / "runs").symlink_to(runs, target_is_directory=True)
    return diagnose(path, out, device="cpu,cpu", progress=False, log=lambda *a: None)


def test_press_null_is_adequate(tmp_path, press_runs):
    """Data from the base model itself (Hertz-Mindlin, mu_s = 0.5): ADEQUATE, and the diagnosis stops."""
    rng = np.random.default_rng(8)
    path = _write_case(tmp_path, "press_null", PRESS_TOML, _press_rows("hertz_mindlin", 0.0, 0.005, rng, mu_s=0.5))
    res = _diagnose_sharing(path, tmp_path / "out", press_runs)
    assert res["verdict"] == "adequate", res
    assert res["cause"] is None and not res["candidates"]
    assert not any(t["significant"] for t in res["adequacy_tests"])


def test_press_plasticity_is_named(tmp_path, press_runs):
    """EEPA plasticity (lambda_p = 0.7) hidden in the press data: the diagnosis names plasticity (not cohesion,
    the other candidate tried), its interval covers 0.7, and the held-out error of the residual set falls by at
    least half."""
    rng = np.random.default_rng(7)
    path = _write_case(tmp_path, "press_plastic", PRESS_TOML, _press_rows("eepa", 0.7, 0.005, rng))
    res = _diagnose_sharing(path, tmp_path / "out", press_runs)
    assert res["verdict"] == "cause", res
    assert res["cause"] == "plasticity"
    lo, hi = res["extended"]["plasticity"]["parameters"]["plasticity"]["interval_95"]
    assert lo <= 0.7 <= hi
    assert res["gain"]["rmse"]["residual_set_ratio"]["reduction"] >= 0.5
    saved = json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    assert saved["verdict"] == "cause" and (tmp_path / "out" / "report.md").exists()
