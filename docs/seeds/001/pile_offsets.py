"""Where each pile of a funnel study stands: its angles, and its centre of mass off the funnel's axis.

    python docs/seeds/001/pile_offsets.py STUDY_DIR [RECORD_DIR]

STUDY_DIR is a study's output folder with its runs' final states (``runs/<point_id>.npz``, kept on the machine
that ran it); RECORD_DIR (default STUDY_DIR) holds its ``results.csv`` and ``runs/<point_id>.json``. Prints, per
run, the image, fit and cone angles [deg] the run recorded, and of its pile (``measure.pile_spheres``, the
default rule) the horizontal distance of its centre of mass from the axis at (0, 0) (``measure.pile_offset``,
which every run now records as ``pile_offset_m``), its radius about that
centre (98th percentile) and its height [mm]; then Spearman's rank correlation of the image angle with the offset
and with the height. Seed 001's cohesive columns that toppled lie far off the axis (README, "Seed 001 read
again"); ``ccd/pile_offsets.txt`` is this script's output for the fourth stage's central composite.
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import numpy as np

from warpdem.scene.measure import pile_centroid, pile_offset, pile_spheres


def pile_figures(npz: Path) -> tuple[float, float, float]:
    """The pile's centre of mass off the axis, its radius about that centre and its height [m]."""
    state = np.load(npz)
    on = pile_spheres(state["sphere_x"], state["sphere_r"], 0.0)
    x, r = state["sphere_x"][on], state["sphere_r"][on]
    radius = np.percentile(np.hypot(*(x[:, :2] - pile_centroid(x, r)).T), 98)
    return pile_offset(x, r), float(radius), float(x[:, 2].max())


def main(study: Path, record: Path) -> None:
    from scipy.stats import spearmanr

    rows = list(csv.DictReader(open(record / "results.csv")))
    table = []
    for row in rows:
        metrics = json.loads((record / "runs" / f"{row['point_id']}.json").read_text())["metrics"]
        off, radius, height = pile_figures(study / "runs" / f"{row['point_id']}.npz")
        angles = [metrics[k] for k in ("angle_image_deg", "angle_fit_deg", "angle_cone_deg")]
        table.append([*angles, off, height])
        print(
            f"{int(row['run']):2d} {row['point_type']:<9} image {angles[0]:5.1f} fit {angles[1]:5.1f} cone "
            f"{angles[2]:5.1f} | centroid off axis {1e3 * off:5.1f} mm, radius {1e3 * radius:5.1f} mm, "
            f"height {1e3 * height:5.1f} mm"
        )
    t = np.array(table)
    for name, col in (("offset", 3), ("height", 4)):
        rho, p = spearmanr(t[:, col], t[:, 0])
        print(f"{name} against the image angle: Spearman {rho:+.3f}, p {p:.2g}")


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2] if len(sys.argv) > 2 else sys.argv[1]))
