"""A die press's loading figures read from its checkpoint, once the bar has turned back (issue 23).

    python docs/seeds/press_checkpoint.py CHECKPOINT.npz [CHECKPOINT.npz ...] [--json OUT.json] [--png OUT.png]

A press run (``benchmarks/rigs_full.py --rig die_press``, ``--stop-after``) saves its output series in each
checkpoint. Once the force has reached the limit and the bar turned back (the series' ``unload_index``), the
loading branch is whole: its fill, maximum displacement and compression ratio are what the finished run will
report, read here by the run's own rule (:func:`warpdem.scene.measure.press_loading`, with the die press's force
limit and backstop). The unloading figures (residual set, unloading stiffness) need the finished run.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from warpdem.scene.measure import plot_press, press_loading
from warpdem.scene.rigs import DiePress
from warpdem.scene.runner import checkpoint_meta

MEASURED = {"max_displacement_m": 0.05081, "compression_ratio": 0.635}
"""Seed 001's single pellet press, measured (its EDEM run: 50.30 mm, 0.629)."""


def read(path: Path, force_limit: float = DiePress.force_limit, backstop_z: float = 0.0) -> dict:
    """The loading figures of the press checkpoint at ``path``: the simulated time it reached [s], the fill [m],
    the maximum displacement [m], the compression ratio, the overlaps and escapes recorded at the force limit and
    the loading ``curve`` (displacement [m] and force [N] from the loose bed's top, shape (m,) each).
    ``force_limit`` [N] and ``backstop_z`` [m] are the press's (the die press rig's by default). Raises SystemExit
    naming the file when it holds no series or the bar has not turned back yet."""
    meta = checkpoint_meta(path)
    if meta is None:
        raise SystemExit(f"{path}: no 'meta' array; expected a checkpoint of a scene run")
    series = meta.get("series", {})
    turn = series.get("unload_index")
    if turn is None or "piston_z" not in series:
        raise SystemExit(
            f"{path}: the bar has not turned back yet (no unload_index in the series, at {meta.get('time')} s); "
            "the loading branch is whole only after it"
        )
    load = press_loading(series["piston_z"], series["piston_force"], series["bed_top"], force_limit, backstop_z, turn)
    if load is None:
        raise SystemExit(f"{path}: the bar never pressed the bed")
    peak = series.get("peak_overlap", {})
    return {
        "checkpoint": str(path),
        "simulated_s": meta["time"],
        "unload_start_s": series.get("unload_start_s"),
        "fill_height_m": load["fill_height_m"],
        "max_displacement_m": load["max_displacement_m"],
        "compression_ratio": load["compression_ratio"],
        "limit_reached": bool(load["limit_reached"]),
        "peak_overlap_max": peak.get("deepest", [None])[0],
        "peak_overlap_mean": peak.get("mean", [None])[0],
        "escaped": series.get("escaped", [None])[0],
        "curve": {"displacement_m": load["displacement_m"], "force_n": load["force_n"]},
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("checkpoints", nargs="+", type=Path)
    p.add_argument("--json", type=Path, help="write the figures here too")
    p.add_argument("--png", type=Path, help="draw the (first) checkpoint's loading branch here")
    a = p.parse_args(argv)
    rows = [read(c) for c in a.checkpoints]
    for r in rows:
        off = {k: 100 * (r[k] / v - 1) for k, v in MEASURED.items()}
        print(
            f"{r['checkpoint']}: at {r['simulated_s']:.3f} s (turned back at {r['unload_start_s']:.3f} s): "
            f"fill {1e3 * r['fill_height_m']:.2f} mm, maximum displacement {1e3 * r['max_displacement_m']:.2f} mm "
            f"({off['max_displacement_m']:+.1f} % against the measured 50.81 mm), compression ratio "
            f"{r['compression_ratio']:.4f} ({off['compression_ratio']:+.1f} % against 0.635); deepest / mean overlap "
            f"at the limit {r['peak_overlap_max']:.0%} / {r['peak_overlap_mean']:.0%}, {r['escaped']} past the bar"
        )
    if a.png:
        plot_press(rows[0]["curve"], a.png, force_limit=DiePress.force_limit)
    if a.json:
        a.json.write_text(json.dumps([{k: v for k, v in r.items() if k != "curve"} for r in rows], indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
