"""Write the README's worked example: a die-press data set with hidden EEPA plasticity, as a data file anyone can
diagnose (``studies/diagnose/press_plasticity.toml`` and its CSV).

    python benchmarks/diagnose_example.py [--out studies/diagnose]
    warpdem diagnose studies/diagnose/press_plasticity.toml --device cpu,cpu --out runs/diagnose/press_plasticity

The data are the test case's (``tests/diagnose/test_diagnose.py::test_press_plasticity_is_named``): the 94-sphere
smoke die press pressed to 0.5, 1 and 2 N, EEPA with plasticity ratio 0.7 and feed-feed static friction 0.5, three
replicates per force limit at world seeds the diagnosis never uses, plus 0.005 of measurement noise on the
residual-set ratio. The data file is ``synthetic.PRESS_TOML``: Hertz-Mindlin with the static friction free, and
plasticity and cohesion the candidates.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from warpdem.diagnose import synthetic as syn


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="studies/diagnose")
    a = ap.parse_args()
    rows = syn.press_rows("eepa", 0.7, 0.5, 0.005, np.random.default_rng(7))
    print(syn.write_case(Path(a.out), "press_plasticity", syn.PRESS_TOML, rows))


if __name__ == "__main__":
    main()
