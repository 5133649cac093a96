"""A cheap CPU lifting cylinder that tells elongation from rolling friction: both raise the angle of repose, but
rods pack denser and rolling resistance looser. One launch per aspect ratio (a rig parameter), each design
point x world seed a world of it; prints per point the mean +- SD over the seeds of ``angle_fit_deg`` and
``bulk_density_kg_m3`` (the bed before the lift) and each launch's wall time.

    python benchmarks/shape_rolling_scene.py                     # spheres: 4 points x 4 seeds; rods: 1 x 4
    python benchmarks/shape_rolling_scene.py --aspect-ratio 1.5  # cheaper rods (3 spheres instead of 5)

The scene: 500 ore spheres of 2.5 mm (+-5 %) poured into a 55 x 35 mm cylinder on a plain plate, settled,
the cylinder lifted at 0.5 m/s. For speed (about 1.5 s of one CPU core per sphere world): shear modulus
0.25 MPa, Hertz-Mindlin instead of EEPA between grains, restitution 0.5 on every ore pair (Tsuji's dashpot at
the ore's 0.15 limits the step 1.6-2.2 times more) and 0.17 of the Rayleigh time, which holds the step at half
the base step all run instead of halving it again for a few outputs.

On one core of the development machine (world seeds 1-4):

    spheres, 16 worlds, 8848 steps over 0.59 s: 24 s (1.5 s per world)
      mu_r 0.02 (mu_s 0.7)    angle 19.4 +- 0.9 deg   bulk density 1436 +-  6 kg/m^3
      mu_r 0.3                angle 27.7 +- 0.8 deg   bulk density 1389 +- 14 kg/m^3
      mu_r 0.02, mu_s 0.3     angle 18.8 +- 0.4 deg   bulk density 1488 +- 12 kg/m^3
      mu_r 0.02, mu_s 0.8     angle 20.3 +- 1.1 deg   bulk density 1436 +-  6 kg/m^3
    rods of aspect ratio 1.8 (5 spheres), 4 worlds, 31101 steps over 0.82 s: 74 s (18 s per world)
      mu_r 0.02               angle 25.2 +- 1.2 deg   bulk density 1512 +- 11 kg/m^3
    rods of aspect ratio 1.5 (3 spheres), 4 worlds, 25167 steps over 0.72 s: 40 s (10 s per world)
      mu_r 0.02               angle 23.8 +- 1.3 deg   bulk density 1498 +-  5 kg/m^3

Rods cost 12 times a sphere world: five spheres each, a step halved twice (their stiffest contacts), and a
pour 2.7 times slower (the rig's pour rate allows for their bounding spheres). That slower pour does not make
their density: in a variant of this scene (cylinder 50 mm high, lifted at 0.3 m/s; one world) rods poured at
the spheres' rate (``factory.pour.rate``) packed at 1498 kg/m^3, at their own rate at 1512.
"""

import argparse
import time

import numpy as np
import warp as wp

from warpdem.scene import rigs, runner
from warpdem.scene.stage import apply_overrides

wp.config.quiet = True

SCENE = {
    "coated": False,
    "count": 500,
    "radius_spread": 0.05,
    "inner_diameter": 0.055,
    "height": 0.035,
    "pour_speed": 1.0,
    "pour_height": 0.03,
    "settle_time": 0.1,
    "lift_speed": 0.5,
    "after_lift": 0.25,
    "base_size": 0.14,
    "plate_static_friction": 0.8,
    "plate_rolling_friction": 0.3,
}
"""Lifting-cylinder overrides over its SMOKE set."""

SET = {
    "material.ore.shear_modulus": 2.5e5,
    "interaction.ore.ore.law": "HERTZ_MINDLIN",
    "interaction.ore.ore.restitution": 0.5,
    "interaction.ore.steel.restitution": 0.5,
    "interaction.ore.plate.restitution": 0.5,
    "run.dt_fraction": 0.17,
}
"""Scene overrides (``--set``) that make the steps long."""

MU_R, MU_S = "interaction.ore.ore.rolling_friction", "interaction.ore.ore.static_friction"
POINTS = {
    "mu_r 0.02": {MU_R: 0.02},
    "mu_r 0.3": {MU_R: 0.3},
    "mu_r 0.02, mu_s 0.3": {MU_R: 0.02, MU_S: 0.3},
    "mu_r 0.02, mu_s 0.8": {MU_R: 0.02, MU_S: 0.8},
}
"""Design points of the sphere launch (mu_s 0.7, the ore's, where not given; constant-torque rolling)."""


def launch(aspect_ratio: float, points: dict, seeds: list) -> None:
    """Run one launch of ``points`` x ``seeds`` worlds and print its table."""
    spec = rigs.spec("lifting_cylinder", {**SCENE, "aspect_ratio": aspect_ratio}, smoke=True)
    apply_overrides(spec, SET)
    keys = sorted({k for p in points.values() for k in p})
    default = {k: own_value(spec, k) for k in keys}
    labels = [label for label in points for _ in seeds]
    variations = {k: [points[label].get(k, default[k]) for label in labels] for k in keys}
    t0 = time.perf_counter()
    res = runner.run_scene(
        spec,
        device="cpu",
        world_count=len(labels),
        frames=False,
        variations=variations,
        world_seeds=list(seeds) * len(points),
        quiet=True,
    )
    wall = time.perf_counter() - t0
    info = res.info
    print(
        f"aspect ratio {aspect_ratio}: {len(labels)} worlds of {(info['clumps'] or info['spheres']) // len(labels)} "
        f"particles ({info['spheres'] // len(labels)} spheres), "
        f"{info['steps']} steps (dt {info['dt_range_s'][0]:.2g}-{info['dt_range_s'][1]:.2g} s) over "
        f"{info['simulated_s']:.2f} s; wall {wall:.1f} s = {wall / len(labels):.2f} s per world"
    )
    for label in points:
        ms = [m for m, lab in zip(res.metrics, labels) if lab == label]
        angle = np.array([m.get("angle_fit_deg", np.nan) for m in ms], float)
        rho = np.array([m.get("bulk_density_kg_m3", np.nan) for m in ms], float)
        print(
            f"  {label:<22} angle {angle.mean():5.1f} +- {angle.std(ddof=1):4.1f} deg   "
            f"bulk density {rho.mean():6.0f} +- {rho.std(ddof=1):3.0f} kg/m^3"
        )


def own_value(spec, key: str) -> float:
    """The scene's own value of an ``interaction.A.B.FIELD`` key."""
    _, a, b, name = key.split(".")
    return next(getattr(ia, name) for pa, pb, ia in spec.pairs if {pa, pb} == {a, b})


if __name__ == "__main__":
    p = argparse.ArgumentParser()
    p.add_argument("--aspect-ratio", type=float, default=1.8, help="the rods' length / width")
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4], help="world seeds per point")
    p.add_argument("--rods-only", action="store_true", help="skip the sphere launch")
    a = p.parse_args()
    wp.init()
    if not a.rods_only:
        launch(1.0, POINTS, a.seeds)
    launch(a.aspect_ratio, {"mu_r 0.02": POINTS["mu_r 0.02"]}, a.seeds)
