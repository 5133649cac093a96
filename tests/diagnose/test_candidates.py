"""The candidate library (warpdem.diagnose.candidates): which extensions apply to a scene, their off values and
ranges, and why the others do not. No simulation runs: the scenes are only built."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from warpdem.diagnose import candidates as cands
from warpdem.diagnose import load_diagnosis
from warpdem.scene import rigs

pytest.importorskip("sklearn")

from warpdem.diagnose.data import DiagnoseError  # noqa: E402
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
    assert set(skipped) == {"rolling_model", "coarse_graining", "cohesion_strength"}
    assert "HERTZ_MINDLIN, neither JKR nor EEPA" in skipped["coarse_graining"]
    assert "a second change only" in skipped["cohesion_strength"]
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


# --------------------------------------------------------------------------------------------------
# coarse-graining: the surface energy scaled with the grain size
# --------------------------------------------------------------------------------------------------

GAMMA = "interaction.grain.grain.surface_energy"


def _cohesive_funnel(gamma: float = 0.05, **values):
    from warpdem.scene.stage import apply_overrides

    scene, params = _funnel(particle="sphere", **values)
    return apply_overrides(scene, {"interaction.grain.grain.law": "JKR", GAMMA: gamma}), params


def test_coarse_graining_applies_to_a_cohesive_coarse_grained_scene():
    """JKR grains 5 times the measured ones: the exponent k of gamma s^k, off 0 at the end of [0, 2], carrying
    s = 5, the scene's surface energy and the key it scales; cohesion (the law is JKR already) does not apply."""
    scene, params = _cohesive_funnel()
    radius = cands._grain(scene)[1]
    lib, skipped = cands.library(scene, params, set(), grain_radius=radius / 5.0)
    c = next(c for c in lib if c.name == "coarse_graining")
    assert (c.key, c.off, c.low, c.high, c.off_at_edge) == (cands.COARSE_EXPONENT, 0.0, 0.0, 2.0, True)
    assert c.shared["coarse_graining.size_ratio"] == pytest.approx(5.0, rel=1e-12)
    assert c.shared["coarse_graining.surface_energy"] == pytest.approx(0.05)
    assert c.shared["coarse_graining.target"] == GAMMA
    assert "cohesion" in skipped and "coarse_graining" not in skipped
    # the surface energy is a free parameter: the scene's value is never used, so none is carried
    lib, _ = cands.library(scene, params, {GAMMA}, grain_radius=radius / 5.0)
    assert next(c for c in lib if c.name == "coarse_graining").shared["coarse_graining.surface_energy"] == 0.0


@pytest.mark.parametrize(
    "gamma, ratio, why",
    [
        (0.05, None, "no [candidates] grain_radius"),
        (0.05, 1.0, "the measured size"),
        (0.0, 5.0, "is 0: no cohesion to scale"),
    ],
)
def test_coarse_graining_is_skipped_with_the_reason(gamma, ratio, why):
    scene, params = _cohesive_funnel(gamma)
    radius = cands._grain(scene)[1]
    lib, skipped = cands.library(scene, params, set(), grain_radius=None if ratio is None else radius / ratio)
    assert "coarse_graining" not in {c.name for c in lib}
    assert why in skipped["coarse_graining"]


def test_resolve_scales_the_surface_energy_by_hand():
    """gamma s^k from the overrides' surface energy, else the scene's; the candidate's own keys are gone and the
    others kept; overrides without the exponent come back unchanged."""
    shared = {"coarse_graining.size_ratio": 4.0, "coarse_graining.surface_energy": 0.3, "coarse_graining.target": GAMMA}
    other = {"interaction.grain.grain.rolling_friction": 0.2}
    for k, factor in ((0.0, 1.0), (1.0, 4.0), (2.0, 16.0), (0.5, 2.0)):
        out = cands.resolve({**other, **shared, cands.COARSE_EXPONENT: k})
        assert out == {**other, GAMMA: pytest.approx(0.3 * factor, rel=1e-12)}
        out = cands.resolve({**other, **shared, GAMMA: 1.5, cands.COARSE_EXPONENT: k})
        assert out == {**other, GAMMA: pytest.approx(1.5 * factor, rel=1e-12)}
    assert cands.resolve(other) == other


def test_a_request_of_the_extended_model_carries_the_scaled_surface_energy(tmp_path):
    """Through the pipeline: the data file's grain_radius gives s, the extended model's design keeps the exponent
    continuous (it is a surface energy, which varies per world), and each request's surface energy is the free
    parameter's value times s^k."""
    from warpdem.diagnose.pipeline import Dim, Evaluator, Model, design_points

    fixed = '"interaction.grain.grain.law" = "JKR"\nparticle_radius = 0.002'
    csv = "id,replicate,angle_fit_deg\na,1,24.0\na,2,25.0\n"
    tmp_path.mkdir(exist_ok=True)
    (tmp_path / "experiments.csv").write_text(csv)
    toml = TOML.replace("{fixed}", fixed).replace("interaction.grain.grain.static_friction", GAMMA)
    path = tmp_path / "data.toml"
    path.write_text(toml + "\n[candidates]\ngrain_radius = 0.0004\n")
    spec, ex = load_diagnosis(path)
    assert spec.grain_radius == 0.0004
    prob = _problem(spec, ex)
    lib, skipped = _library(spec, ex, prob.conditions)
    cand = next(c for c in lib if c.name == "coarse_graining")
    assert cand.shared["coarse_graining.size_ratio"] == pytest.approx(5.0, rel=1e-12)
    base = Model("base", [Dim(p.name, p.parameter, p.low, p.high) for p in spec.parameters])
    ext = Model.extended(base, cand)
    U = design_points(ext.dims, 12, 1)
    assert len(set(np.round(U[:, -1], 9))) == 12  # not rounded to a few launch levels
    ov, seed = Evaluator(prob, None, None)._request(ext, [0.5, 0.25], 0, 7)
    gamma = 0.2 + 0.5 * (1.0 - 0.2)  # the free parameter at u = 0.5 of [0.2, 1.0]
    assert ov[GAMMA] == pytest.approx(gamma * 5.0**0.5, rel=1e-12) and seed == 7
    assert not any(k.startswith("coarse_graining.") for k in ov)


def test_coarse_graining_needs_one_size_ratio(tmp_path):
    """Experiments at two grain sizes against one measured radius: s differs between them, so the candidate is
    skipped with the reason rather than read as one rule."""
    fixed = f'"interaction.grain.grain.law" = "JKR"\n"{GAMMA}" = 0.05'
    (tmp_path / "experiments.csv").write_text(CSV)
    (tmp_path / "data.toml").write_text(TOML.replace("{fixed}", fixed) + "\n[candidates]\ngrain_radius = 0.0004\n")
    spec, ex = load_diagnosis(tmp_path / "data.toml")
    lib, skipped = _library(spec, ex, _problem(spec, ex).conditions)
    assert "coarse_graining" not in {c.name for c in lib}
    assert "coarse_graining.size_ratio differs between the experiments" in skipped["coarse_graining"]


# --------------------------------------------------------------------------------------------------
# cohesion_strength: the surface energy weakened, the second part of a two-change model
# --------------------------------------------------------------------------------------------------


def test_cohesion_strength_of_a_cohesive_scene():
    """JKR grains: x of gamma 10^x, off 0 at the top of [-1, 0], carrying the base 10, the scene's surface energy and
    the key it scales; a free surface energy carries 0 (the request's own value is scaled). Hertz-Mindlin grains, or
    a surface energy of 0 that the data file does not set, have nothing to weaken."""
    scene, _ = _cohesive_funnel(0.05)
    c, why = cands.cohesion_strength(scene, set())
    assert why is None
    assert (c.name, c.key, c.off, c.low, c.high, c.off_at_edge) == (
        "cohesion_strength",
        cands.STRENGTH_EXPONENT,
        0.0,
        -1.0,
        0.0,
        True,
    )
    assert c.shared == {
        "cohesion_strength.base": 10.0,
        "cohesion_strength.surface_energy": pytest.approx(0.05),
        "cohesion_strength.target": GAMMA,
    }
    assert cands.cohesion_strength(scene, {GAMMA})[0].shared["cohesion_strength.surface_energy"] == 0.0
    c, why = cands.cohesion_strength(_cohesive_funnel(0.0)[0], set())
    assert c is None and "is 0: no cohesion to scale" in why
    assert cands.cohesion_strength(_cohesive_funnel(0.0)[0], {GAMMA})[0] is not None
    c, why = cands.cohesion_strength(_funnel(particle="sphere")[0], set())
    assert c is None and "HERTZ_MINDLIN, neither JKR nor EEPA" in why


def test_resolve_weakens_the_surface_energy_by_hand():
    """gamma 10^x: x = -1 a tenth, -0.5 one over root ten, 0 unchanged; after coarse-graining's s^k when both are
    there (gamma s^k 10^x); the candidates' own keys gone."""
    strength = {
        "cohesion_strength.base": 10.0,
        "cohesion_strength.surface_energy": 0.4,
        "cohesion_strength.target": GAMMA,
    }
    for x, factor in ((-1.0, 0.1), (-0.5, 10**-0.5), (0.0, 1.0)):
        assert cands.resolve({**strength, cands.STRENGTH_EXPONENT: x}) == {GAMMA: pytest.approx(0.4 * factor)}
        out = cands.resolve({**strength, GAMMA: 0.8, cands.STRENGTH_EXPONENT: x})
        assert out == {GAMMA: pytest.approx(0.8 * factor, rel=1e-12)}
    coarse = {"coarse_graining.size_ratio": 4.0, "coarse_graining.surface_energy": 0.4, "coarse_graining.target": GAMMA}
    out = cands.resolve({**coarse, **strength, cands.COARSE_EXPONENT: 0.5, cands.STRENGTH_EXPONENT: -1.0})
    assert out == {GAMMA: pytest.approx(0.4 * 2.0 * 0.1, rel=1e-12)}
    assert cands.varies_per_world(cands.STRENGTH_EXPONENT)


def test_a_two_change_request_carries_the_rolling_model_and_the_weaker_surface_energy(tmp_path):
    """Through the pipeline: the data file's free surface energy, a rolling model switched and the strength added
    as the last dimension (named ``<switch>+cohesion_strength``); each request sets the law and the free
    parameter's value times 10^x. A use list without the candidate, or a range the file sets, is honoured; a range
    that leaves out the off value is refused naming the file and the key."""
    from warpdem.diagnose.pipeline import Dim, Evaluator, Model, _strength

    fixed = '"interaction.grain.grain.law" = "JKR"\nparticle_radius = 0.002'
    (tmp_path / "experiments.csv").write_text("id,replicate,angle_fit_deg\na,1,24.0\na,2,25.0\n")
    toml = TOML.replace("{fixed}", fixed).replace("interaction.grain.grain.static_friction", GAMMA)
    path = tmp_path / "data.toml"
    path.write_text(toml)
    spec, ex = load_diagnosis(path)
    prob = _problem(spec, ex)
    cand, why = _strength(spec, ex, prob.conditions)
    assert why is None and (cand.low, cand.high) == (-1.0, 0.0)
    base = Model("base", [Dim(p.name, p.parameter, p.low, p.high) for p in spec.parameters])
    law = cands.LawSwitch("standard", {"interaction.grain.grain.rolling_model": "standard"})
    pair = Model.extended(Model.switched(base, law), cand)
    assert pair.name == "rolling_model=standard+cohesion_strength" and pair.law == law and pair.candidate == cand
    assert not pair.is_base and [d.name for d in pair.dims] == [*(d.name for d in base.dims), "cohesion_strength"]
    ov, _ = Evaluator(prob, None, None)._request(pair, [0.5, 0.5], 0, 7)
    gamma = 0.2 + 0.5 * (1.0 - 0.2)
    assert ov[GAMMA] == pytest.approx(gamma * 10**-0.5, rel=1e-12)
    assert ov["interaction.grain.grain.rolling_model"] == "standard"
    assert not any(k.startswith("cohesion_strength.") for k in ov)
    path.write_text(toml + '\n[candidates]\nuse = ["rolling_model"]\n')
    spec, ex = load_diagnosis(path)
    assert _strength(spec, ex, prob.conditions) == (None, "not in the data file's [candidates] use list")
    path.write_text(toml + "\n[candidates]\nranges.cohesion_strength = [-2.0, 0.0]\n")
    spec, ex = load_diagnosis(path)
    assert (_strength(spec, ex, prob.conditions)[0].low) == -2.0
    path.write_text(toml + "\n[candidates]\nranges.cohesion_strength = [-2.0, -1.0]\n")
    spec, ex = load_diagnosis(path)
    with pytest.raises(DiagnoseError, match=r"data.toml: \[candidates\] ranges.cohesion_strength = \[-2.0, -1.0\]"):
        _strength(spec, ex, prob.conditions)


@pytest.mark.parametrize("value", [0, -1e-4, "1 mm", True])
def test_a_bad_grain_radius_is_refused(tmp_path, value):
    (tmp_path / "experiments.csv").write_text(CSV)
    lit = f'"{value}"' if isinstance(value, str) else str(value).lower()
    (tmp_path / "data.toml").write_text(TOML.replace("{fixed}", "") + f"\n[candidates]\ngrain_radius = {lit}\n")
    with pytest.raises(ValueError, match=r"\[candidates\]: grain_radius = .* is not allowed; expected the measured"):
        load_diagnosis(tmp_path / "data.toml")
