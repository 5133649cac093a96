"""Synthetic "measured" data for checking a diagnosis: the engine run with a hidden setting the diagnosis never
sees, at world seeds it never uses, plus Gaussian measurement noise of a stated SD, written as a data file.

Used by the tests, the false-positive benchmark (``benchmarks/diagnose_false_positives.py``) and the README's
worked example.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

DATA_SEEDS = (501, 502, 503)
"""Default world seeds of the 'measurements' (a diagnosis uses 0, 1, 2, ... and 101, 102, ...)."""


def run_worlds(rig: str, smoke: bool, rig_values: dict, overrides: dict, seeds, device: str = "cpu") -> list[dict]:
    """The metrics of one world per world seed in ``seeds``, from the rig ``rig`` with ``rig_values`` and the
    override keys ``overrides`` (the hidden setting among them), on ``device``. A scene whose worlds share the
    wall they are measured by (the die press) runs one world per launch."""
    from warpdem.scene import rigs
    from warpdem.scene.runner import independent_worlds, run_scene
    from warpdem.scene.stage import apply_overrides

    scene = apply_overrides(rigs.spec(rig, rig_values, smoke), overrides)
    seeds = [int(s) for s in seeds]
    if independent_worlds(scene):
        return run_scene(scene, device, world_count=len(seeds), world_seeds=seeds, frames=False, quiet=True).metrics
    return [
        run_scene(scene, device, world_count=1, world_seeds=[s], frames=False, quiet=True).metrics[0] for s in seeds
    ]


def noisy_rows(experiments: list[dict], metrics: list[list[dict]], sd: dict, rng: np.random.Generator) -> list[dict]:
    """Table rows: for experiment k (a dict of ``id`` and its condition columns) one row per world of
    ``metrics[k]`` (replicates 1, 2, ...), with each response of ``sd`` ({metric: noise SD}) plus N(0, SD) noise
    drawn from ``rng``. Raises ValueError when a world did not measure a response."""
    rows = []
    for e, mets in zip(experiments, metrics):
        for j, m in enumerate(mets):
            row = {**e, "replicate": j + 1}
            for r, s in sd.items():
                if r not in m:
                    raise ValueError(f"experiment {e['id']!r}, replicate {j + 1}: the run did not measure {r!r}")
                row[r] = float(m[r]) + float(rng.normal(0.0, s))
            rows.append(row)
    return rows


def write_case(directory, name: str, toml: str, rows: list[dict]) -> Path:
    """Write ``rows`` as ``NAME.csv`` and ``toml`` (a template with ``{name}`` and ``{csv}`` fields) as
    ``NAME.toml`` into ``directory``; return the TOML's path."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(rows).to_csv(directory / f"{name}.csv", index=False)
    path = directory / f"{name}.toml"
    path.write_text(toml.format(csv=f"{name}.csv", name=name))
    return path


# --------------------------------------------------------------------------------------------------
# the lab-size funnel cases (benchmarks/diagnose_gpu.py, benchmarks/diagnose_confounded.py)
# --------------------------------------------------------------------------------------------------

FUNNEL_FIXED = {
    "particle": "sphere",
    "material": "pellet",
    "plate_static_friction": 0.8,
    "plate_rolling_friction": 0.3,
    "gate_time": 1.0,
}
"""Rig parameters of every run of the funnel cases: spheres with the pellet contacts, on a rough plate (a pile of
spheres on the polished one spreads into a layer a few grains thick); the gated funnel fills and settles for 1 s
(its bulk density is measured then), then discharges (its rate) onto the plate (the pile's angle)."""

FUNNEL_SIZES = (0.0015, 0.002, 0.0025)
"""Grain radii [m] of the funnel cases' experiments (their condition): 3, 4 and 5 mm grains."""

FUNNEL_NOISE_SD = {"angle_fit_deg": 0.5, "bulk_density_kg_m3": 5.0}
"""Measurement noise SD of the funnel cases: 0.5 deg, 5 kg/m^3."""


def funnel_experiments(count_at_2mm: int = 1500, pour_time: float = 0.75) -> list[dict]:
    """The funnel cases' experiments: at each of :data:`FUNNEL_SIZES` the solid volume of ``count_at_2mm`` grains
    of 2 mm radius, poured in ``pour_time`` [s]: dicts of id, particle_radius, count, rate. Full size only: the
    smoke funnel's 20 mm outlet leaves no core for the bulk density of these grains."""
    out = []
    for k, r in enumerate(FUNNEL_SIZES):
        count = int(round(count_at_2mm * (0.002 / r) ** 3))
        out.append({"id": f"R{k}", "particle_radius": r, "count": count, "rate": round(count / pour_time, 1)})
    return out


def funnel_data(
    exps: list[dict], rig: dict, overrides: dict, device: str, seed: int, world_seeds=DATA_SEEDS
) -> list[dict]:
    """Rows of the funnel case: the worlds of each experiment of ``exps`` with the rig parameters ``rig`` (the
    hidden setting among them or among ``overrides``) at ``world_seeds`` (one replicate each), plus
    :data:`FUNNEL_NOISE_SD` noise drawn from ``seed``; the experiments' launches run side by side on a GPU
    (``runner.run_together``). Prints each experiment's simulated values."""
    import time

    from warpdem.scene import rigs
    from warpdem.scene.runner import run_scene_iter, run_together
    from warpdem.scene.stage import apply_overrides

    seeds = [int(k) for k in world_seeds]
    scenes = [
        apply_overrides(
            rigs.spec("funnel", {**FUNNEL_FIXED, **rig, **{k: e[k] for k in ("particle_radius", "count", "rate")}}),
            overrides,
        )
        for e in exps
    ]
    t0 = time.perf_counter()
    outcomes = run_together(
        [
            lambda s=s: run_scene_iter(s, device, world_count=len(seeds), world_seeds=seeds, frames=False, quiet=True)
            for s in scenes
        ],
        device,
    )
    for o in outcomes:
        if isinstance(o, BaseException):
            raise o
    values = [o.metrics for o in outcomes]
    for e, v in zip(exps, values):
        seen = {r: [round(m.get(r, np.nan), 4) for m in v] for r in FUNNEL_NOISE_SD}
        print(f"data {e['id']}: {seen}", flush=True)
    print(f"data: {len(exps)} launches in {time.perf_counter() - t0:.0f} s", flush=True)
    return noisy_rows(exps, values, FUNNEL_NOISE_SD, np.random.default_rng(seed))


def funnel_toml(title: str, parameter: dict) -> str:
    """A funnel case's data file (a :func:`write_case` template): ``title``, :data:`FUNNEL_FIXED`, the one free
    ``parameter`` (name, label, parameter, low, high), three simulation and confirming seeds, and 2,000 MCMC
    steps."""
    import json

    def lines(d: dict) -> str:
        return "\n".join(f"{k} = {json.dumps(v)}" for k, v in d.items())

    head = {"name": "{name}", "title": title, "rig": "funnel", "smoke": False, "seed": 1}
    return (
        f"[diagnose]\n{lines(head)}\n\n[fixed]\n{lines(FUNNEL_FIXED)}\n\n[[parameters]]\n{lines(parameter)}\n\n"
        '[experiments]\nfile = "{csv}"\n\n[noise]\nsim_seeds = 3\n\n'
        "[calibration]\nconfirm_seeds = 3\nmcmc_steps = 2000\n"
    )


# --------------------------------------------------------------------------------------------------
# the die press case: residual set after pressing to three force limits
# --------------------------------------------------------------------------------------------------

PRESS_RIG = {
    "die_diameter": 0.005,
    "fill_height": 0.006,
    "inlet_diameter": 0.008,
    "gap": 0.001,
    "settle_time": 0.05,
    "surface_energy": 0.0,
}
"""A 94-sphere die press (about 2 s of one CPU core per world)."""

PRESS_SOFT = {"material.feed.shear_modulus": 1.0e6}
"""Softer feed: a longer step, and a residual set well above the noise."""

PRESS_FORCES = (0.5, 1.0, 2.0)
"""Force limits [N] of the experiments (their condition)."""

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
"""The press case's data file: Hertz-Mindlin with mu_s free; plasticity and cohesion the candidates."""


def press_rows(law: str, plasticity: float, mu_s: float, sd: float, rng, seeds=DATA_SEEDS) -> list[dict]:
    """Residual-set ratios of the press case with the feed-feed ``law`` ("hertz_mindlin" or "eepa" with
    ``plasticity``) and static friction ``mu_s``, one replicate per world seed at each force limit, plus
    N(0, ``sd``) noise."""
    experiments, metrics = [], []
    for k, force in enumerate(PRESS_FORCES):
        experiments.append({"id": f"F{k}", "force_limit": force})
        metrics.append(
            run_worlds(
                "die_press",
                True,
                {**PRESS_RIG, "law": law, "plasticity_ratio": plasticity, "force_limit": force},
                {**PRESS_SOFT, "interaction.feed.feed.static_friction": mu_s},
                seeds,
            )
        )
    return noisy_rows(experiments, metrics, {"residual_set_ratio": sd}, rng)


# --------------------------------------------------------------------------------------------------
# the smoke lifting cylinder at three grain sizes (tests/diagnose: the cohesion and the confounded cases)
# --------------------------------------------------------------------------------------------------

LIFT_RIG = {
    "law": "hertz_mindlin",
    "coated": False,
    "count": 500,
    "radius_spread": 0.05,
    "pour_speed": 1.0,
    "settle_time": 0.1,
    "lift_speed": 0.5,
    "after_lift": 0.25,
    "plate_static_friction": 0.8,
    "plate_rolling_friction": 0.3,
}
"""Rig parameters of the lifting-cylinder cases: the smoke rig with Hertz-Mindlin ore spheres, no coating, a rough
base plate, a short settle and a fast lift (a few seconds of one CPU core per world)."""

LIFT_SOFT = {
    "material.ore.shear_modulus": 2.5e5,
    "interaction.ore.ore.restitution": 0.5,
    "interaction.ore.steel.restitution": 0.5,
    "interaction.ore.plate.restitution": 0.5,
}
"""Soft ore (a long step) with restitution 0.5 against everything."""

LIFT_RADII = (0.005, 0.0075, 0.01125)
"""Grain radii [m] of the lifting-cylinder cases (their condition), x 1.5 apart."""


def toml_lines(values: dict) -> str:
    """``values`` ({key: number, bool or text}) as TOML key = value lines, a dotted key quoted (e.g. a data file's
    ``[fixed]`` table from :data:`LIFT_RIG` and :data:`LIFT_SOFT`)."""

    def lit(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        return f'"{v}"' if isinstance(v, str) else repr(v)

    return "\n".join(f'"{k}" = {lit(v)}' if "." in k else f"{k} = {lit(v)}" for k, v in values.items())


def lift_geometry(radius: float) -> dict:
    """The smoke lifting cylinder scaled with the grain from its 2.5 mm original (the cylinder 22 radii wide and
    14 high, a base 56 radii square, a pour region 12 radii tall), so that a pile of a given count is the same in
    grain diameters at every size: what a size series then shows comes from what does not scale (cohesion's Bond
    number), not from the rig."""
    s = radius / 0.0025
    return {
        "particle_radius": radius,
        "inner_diameter": round(0.055 * s, 6),
        "height": round(0.035 * s, 6),
        "base_size": round(0.14 * s, 6),
        "pour_height": round(0.03 * s, 6),
    }
