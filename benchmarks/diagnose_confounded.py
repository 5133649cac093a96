"""The confounded case on a GPU: hidden particle shape in funnel piles, diagnosed from the angle alone, then from
the angle and the bulk density.

Elongated grains and rolling resistance both steepen a pile, so from angles alone a diagnosis cannot tell them
apart; they pack differently, so the bulk density can. The scene is the funnel rig at lab size (as
``diagnose_gpu.py``: ISO 4324 funnel, rough plate, seed 000's pellet contacts with Hertz-Mindlin and
constant-torque rolling friction 0.05), the gate opened at 1 s. The hidden setting: rods of aspect ratio
:data:`ASPECT` (the same volume as the spheres the rig's radius names) at three sizes. Three replicates per size
at world seeds 501-503, plus measurement noise. The base model is spheres with grain-grain static friction free;
every candidate that applies is tried (cohesion, plasticity, shape, size distribution, rolling friction, wall
friction). Two data files, one data set: ``angle`` holds the angle only, ``both`` the angle and the bulk density.
The two diagnoses share their stored worlds.

    python benchmarks/diagnose_confounded.py [--device cuda] [--out DIR] [--case angle|both|all]
        [--stop-after S] [--aspect A]

Prints each diagnosis's verdict, its cause or tie, the separating measurement it names, the wall time, the
worlds and the launches; resumes from DIR.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from warpdem.diagnose import synthetic as syn
from warpdem.diagnose.pipeline import diagnose

ASPECT = 2.0
"""Hidden aspect ratio (length / width) of the grains."""

MU_S = 0.55
"""Grain-grain static friction of the data (seed 000's calibrated value); the diagnosis calibrates it."""

PARAMETER = {
    "name": "mu_s",
    "label": "particle-particle static friction",
    "parameter": "interaction.grain.grain.static_friction",
    "low": 0.3,
    "high": 0.9,
}
"""The base model's free parameter."""


def make_data(out: Path, device: str, aspect: float = ASPECT) -> dict[str, Path]:
    """The two data files (``angle``, ``both``) of one simulated data set; made once, then reused."""
    paths = {case: out / f"shape_{case}.toml" for case in ("angle", "both")}
    if all(p.exists() for p in paths.values()):
        return paths
    hidden = {"interaction.grain.grain.static_friction": MU_S}
    rows = syn.funnel_data(syn.funnel_experiments(), {"aspect_ratio": aspect}, hidden, device, seed=2027)
    angle_rows = [{k: v for k, v in r.items() if k != "bulk_density_kg_m3"} for r in rows]
    for name, what, case_rows in (
        ("shape_angle", "angle only", angle_rows),
        ("shape_both", "angle and bulk density", rows),
    ):
        toml = syn.funnel_toml(f"Hidden grain shape in funnel piles ({what})", PARAMETER)
        syn.write_case(out, name, toml, case_rows)
    return paths


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--out", default="runs/diagnose_confounded")
    ap.add_argument("--case", choices=("data", "angle", "both", "all"), default="all")
    ap.add_argument("--stop-after", type=float, default=0.0, help="wall seconds after which a diagnosis stops")
    ap.add_argument("--aspect", type=float, default=ASPECT, help="hidden aspect ratio of the data (length / width)")
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    paths = make_data(out, a.device, a.aspect)
    cases = {"data": [], "all": ["angle", "both"]}.get(a.case, [a.case])
    runs = out / "runs"
    runs.mkdir(exist_ok=True)
    t0 = time.perf_counter()
    for case in cases:
        target = out / case
        target.mkdir(exist_ok=True)
        if not (target / "runs").exists():
            # one store of worlds: the second diagnosis reuses the first's design, scatter and screens
            (target / "runs").symlink_to(runs.resolve(), target_is_directory=True)
        left = a.stop_after - (time.perf_counter() - t0) if a.stop_after else 0.0
        if a.stop_after and left <= 0:
            print(f"{case}: not started, the wall-time limit is spent")
            return
        res = diagnose(str(paths[case]), target, device=a.device, progress=False, stop_after=left)
        if res.get("stopped"):
            print(f"{case}: stopped after {res['wall_s']:.0f} s: {res['stopped']}")
            return
        summary = {
            "case": case,
            "verdict": res["verdict"],
            "cause": res["cause"],
            "tied": res["tied"],
            "separating": res.get("separating_measurement"),
            "wall_s": round(res["wall_s"], 1),
            "worlds": res["worlds"],
            "launches": res["launches"],
            "candidates": [
                {k: c[k] for k in ("candidate", "estimate", "interval", "adequate", "held_out_evidence")}
                for c in res["candidates"]
            ],
        }
        print(json.dumps(summary, indent=1, default=str), flush=True)


if __name__ == "__main__":
    main()
