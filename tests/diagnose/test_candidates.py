"""The candidate library (warpdem.diagnose.candidates): which extensions apply to a scene, their off values and
ranges, and why the others do not. No simulation runs: the scenes are only built."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from warpdem.diagnose import candidates as cands
from warpdem.diagnose import load_diagnosis
from warpdem.scene import rigs

pytest.importorskip("sklearn")

from warpdem.diagnose.pipeline import _library, _problem  # noqa: E402


def _funnel(**values):
    scene = rigs.spec("funnel", values, True)
    p = rigs.params("funnel", {**rigs.SMOKE["funnel"], **values})
    return scene, {f: getattr(p, f) for f in p.__dataclass_fields__}


def _bond_range(scene) -> float:
    """The surface energy [J/m^2] of granular Bond number BOND_MAX for the scene's grains, by hand: the JKR pull-off
    force 1.5 pi gamma R* with R* = R/2 equal to BOND_MAX weights rho g 4/3 pi R^3, so gamma = BOND_MAX 16/9 rho g
    R^2."""
    material, radius, density = cands._grain(scene)
    return cands.BOND_MAX * 16.0 / 9.0 * density * 9.81 * radius**2


def test_sphere_funnel_library():
    """Spheres on the funnel: every one-parameter candidate applies, each with its off value inside its range;
    cohesion's range ends at Bond number 5; the rolling-resistance model is named as not tried."""
    scene, params = _funnel(particle="sphere")
    lib, skipped = cands.library(scene, params, set())
    by = {c.name: c for c in lib}
    assert list(by) == ["cohesion", "plasticity", "shape", "size_distribution", "rolling_friction", "wall_friction"]
    assert set(skipped) == {"rolling_model"}
    assert by["cohesion"].off == 0.0 and by["cohesion"].high == pytest.approx(_bond_range(scene), rel=1e-12)
    assert by["cohesion"].shared == {"interaction.grain.grain.law": "JKR"}
    assert (by["shape"].key, by["shape"].off, by["shape"].high) == ("aspect_ratio", 1.0, 2.5)
    assert by["size_distribution"].off == params["radius_spread"]
    mu_r = next(ia for a, b, ia in scene.pairs if a == b == "grain").rolling_friction
    assert by["rolling_friction"].off == pytest.approx(mu_r)
    for c in lib:
        assert c.low <= c.off <= c.high, c


def test_decided_keys_and_shapes_are_skipped():
    """A candidate whose parameter the data file decides, or that the scene cannot carry, is skipped with the
    reason: a free rolling friction, a fixed law, clump grains (no aspect ratio to stretch)."""
    scene, params = _funnel(particle="pellet")
    taken = {"interaction.grain.grain.rolling_friction", "interaction.grain.grain.law"}
    lib, skipped = cands.library(scene, params, taken)
    names = {c.name for c in lib}
    assert not names & {"rolling_friction", "cohesion", "plasticity", "shape"}
    assert "interaction.grain.grain.rolling_friction is already decided" in skipped["rolling_friction"]
    assert "interaction.grain.grain.law" in skipped["cohesion"]
    assert "not spheres" in skipped["shape"]


TOML = """\
[diagnose]
name = "piles"
rig = "funnel"
smoke = true

[fixed]
particle = "sphere"
{fixed}

[[parameters]]
name = "mu_s"
parameter = "interaction.grain.grain.static_friction"
low = 0.2
high = 1.0

[experiments]
file = "experiments.csv"
"""

CSV = "id,replicate,particle_radius,angle_fit_deg\na,1,0.002,24.0\na,2,0.002,25.0\nb,1,0.003,27.0\nb,2,0.003,28.0\n"


def _diagnosis_library(tmp_path: Path, fixed: str):
    tmp_path.mkdir()
    (tmp_path / "experiments.csv").write_text(CSV)
    path = tmp_path / "data.toml"
    path.write_text(TOML.replace("{fixed}", fixed))
    spec, ex = load_diagnosis(path)
    prob = _problem(spec, ex)
    return _library(spec, ex, prob.conditions)


def test_library_reads_the_data_files_values(tmp_path):
    """The library sees the scene the data file describes, per-world keys included: a [fixed] grain density
    twice the rig's doubles cohesion's range, which is the narrowest over the conditions (the smallest grain's)."""
    lib, _ = _diagnosis_library(tmp_path / "a", "")
    scene, _ = _funnel(particle="sphere", particle_radius=0.002)
    gamma_max = next(c for c in lib if c.name == "cohesion").high
    assert gamma_max == pytest.approx(_bond_range(scene), rel=1e-12)
    rho = cands._grain(scene)[2]
    lib2, _ = _diagnosis_library(tmp_path / "b", f'"material.grain.density" = {2 * rho}')
    assert next(c for c in lib2 if c.name == "cohesion").high == pytest.approx(2 * gamma_max, rel=1e-12)
    assert math.isfinite(gamma_max) and gamma_max > 0
