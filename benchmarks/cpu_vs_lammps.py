"""warpdem vs LAMMPS on the same 2000-sphere settled bed, one process each, in one run.

    python benchmarks/cpu_vs_lammps.py [--steps 5000] [--settle-steps 20000]

Prints both particle-steps/s and their ratio. LAMMPS is installed into /tmp/lammps-venv on first use
(benchmarks/lammps_bed.py); it is never a test dependency.
"""

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import warp as wp
from lammps_bed import run_lammps_bed

from warpdem.verify.bench import run_bench


def main():
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--steps", type=int, default=5000)
    p.add_argument("--settle-steps", type=int, default=20000)
    p.add_argument("--json")
    a = p.parse_args()
    wp.config.quiet = True
    ours = run_bench("cpu", 2000, a.steps, a.settle_steps)
    theirs = run_lammps_bed(steps=a.steps, settle_steps=a.settle_steps, ranks=1)
    ratio = theirs["particle_steps_per_s"] / ours["particle_steps_per_s"]
    print(
        f"warpdem (cpu, 1 process): {ours['particle_steps_per_s']:.3e} particle-steps/s, "
        f"Z = {ours['contacts_per_sphere']:.2f}"
    )
    print(
        f"LAMMPS  ({theirs['lammps_version']}, 1 rank): {theirs['particle_steps_per_s']:.3e} particle-steps/s, "
        f"Z = {theirs.get('coordination_with_walls') or theirs.get('coordination')}"
    )
    print(f"LAMMPS / warpdem = {ratio:.2f} (goal: <= 2)")
    if a.json:
        Path(a.json).write_text(json.dumps({"warpdem": ours, "lammps": theirs, "ratio": ratio}, indent=1))


if __name__ == "__main__":
    main()
