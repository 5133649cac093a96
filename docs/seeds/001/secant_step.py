"""Seed 001 at the seed's 25,000 grains: the secant step in the surface energy X3 between the two verifications
poured at that size, written as a study only where the second one missed 54.25 deg by more than 1 deg.

    python docs/seeds/001/secant_step.py [STEP_RECORD] [--write]

The first verification (``verify_large_standard_scaled``, X3 0.1052 J/m^2) and the step from it along the 6,000-grain
composite's slope (``verify_large_standard_scaled_step``, X3 0.0909 J/m^2; STEP_RECORD, default its folder beside
this script) hold X1 and X2. Their two means give the slope at the seed's size [deg per J/m^2]; the secant point
is where that line meets the target. With ``--write`` the point is written as
``studies/wetfeed_verify_large_standard_scaled_secant.toml`` (the step's study with X3 changed, nothing else), so
the run that follows is the tool's, not a hand-picked value. Nothing is written where the step already lands
within 1 deg, or where the two means do not differ beyond their scatter (the slope is then not measured).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
STUDIES = HERE.parents[2] / "studies"
STEP = "wetfeed_verify_large_standard_scaled_step"
SECANT = "wetfeed_verify_large_standard_scaled_secant"
TOLERANCE_DEG = 1.0
"""Issue 23's tolerance on the measured angle [deg]."""


def piles(record: Path):
    """(X3 [J/m^2], angles [deg]) of a one-point verification record's ``results.csv``."""
    import pandas as pd

    t = pd.read_csv(record / "results.csv")
    x3 = t["X3_actual"].unique()
    if len(x3) != 1:
        raise SystemExit(f"{record / 'results.csv'}: X3_actual holds {list(x3)}; a one-point verification expected")
    return float(x3[0]), t["aor_deg"].to_numpy(float)


def secant(first, second, target: float):
    """The secant point and its reasoning: (x3 or None, slope [deg per J/m^2], the two-sample t of the means).

    ``first`` and ``second`` are (X3, angles) pairs; None where the step is within the tolerance of ``target`` or
    where Welch's t of the two means is below 2 (the line through them is then noise)."""
    from scipy import stats

    (x0, y0), (x1, y1) = first, second
    slope = (y1.mean() - y0.mean()) / (x1 - x0)
    t = stats.ttest_ind(y1, y0, equal_var=False).statistic
    if abs(y1.mean() - target) <= TOLERANCE_DEG or not abs(t) >= 2.0:
        return None, slope, t
    return x1 + (target - y1.mean()) / slope, slope, t


def main(argv=None) -> int:
    from warpdem.study.audit import published

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("step_record", nargs="?", default=str(HERE / "verify_large_standard_scaled_step"))
    p.add_argument("--write", action="store_true", help=f"write studies/{SECANT}.toml when a step is due")
    a = p.parse_args(argv)
    target = float(published()["wetfeed"]["measured_aor_deg"])
    first = piles(HERE / "verify_large_standard_scaled")
    second = piles(Path(a.step_record))
    x3, slope, t = secant(first, second, target)
    for label, (x, y) in (("first", first), ("step", second)):
        print(f"{label}: X3 {x:.4f} J/m^2, {y.mean():.2f} +- {y.std(ddof=1):.2f} deg ({len(y)} piles)")
    print(f"slope at 25,000 grains {slope:.1f} deg per J/m^2 (Welch t {t:.2f}); target {target} deg")
    if x3 is None:
        print("no secant step: the step lands within 1 deg, or the two means do not differ beyond their scatter")
        return 0
    x3 = round(x3, 4)
    print(f"secant point X3 {x3:.4f} J/m^2")
    if not math.isfinite(x3) or x3 <= 0.0:
        print(f"the secant point {x3} is not a surface energy: no study written", file=sys.stderr)
        return 1
    if a.write:
        text = (STUDIES / f"{STEP}.toml").read_text()
        text = text[text.index("[study]") :]
        old = f"X3 = {second[0]:.4f}"
        if text.count(old) != 5:
            raise SystemExit(f"studies/{STEP}.toml: expected five points '{old}'")
        header = (
            f"# Seed 001: the secant step at the seed's 25,000 grains, written by docs/seeds/001/secant_step.py from\n"
            f"# the two verifications at that size: X3 {first[0]:.4f} J/m^2 read {first[1].mean():.2f} deg, "
            f"X3 {second[0]:.4f} read {second[1].mean():.2f} deg;\n"
            f"# their line ({slope:.1f} deg per J/m^2) meets {target} deg at X3 {x3:.4f}. Otherwise {STEP}.toml.\n"
        )
        body = text.replace(old, f"X3 = {x3:.4f}").replace(STEP, SECANT, 1)
        body = body.replace('title = "Wet feed: one step in X3', 'title = "Wet feed: the secant step in X3', 1)
        (STUDIES / f"{SECANT}.toml").write_text(header + "\n" + body)
        print(f"wrote studies/{SECANT}.toml")
    return 0


if __name__ == "__main__":
    sys.exit(main())
