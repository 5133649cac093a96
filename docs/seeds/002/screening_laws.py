"""Seed 002's 2^(5-1) screening with three contact setups beside the paper's, run by run.

    python docs/seeds/002/screening_laws.py [--out FILE]

Reads the paper's run table (``studies/reference/phosphate_ffd_runs.csv``, Fig. 14) and the screening records kept
in the repository (:data:`SCREENINGS`: each folder's ``analysis/runs.csv``, the run table its analysis read, with
both readings of each pile; a run not yet finished has no angle and is left out). The three records share one design (``studies/phosphate_ffd*.toml``: E = ABCD, one world seed) and
differ in the ore's contact setup: the lifting-cylinder rig's rolling friction type A, the same with the surface
energy's levels times s, and EDEM's standard rolling friction. For the paper's angle (the cone formula,
atan(2h/d)) and for ours (the cone formula, ``aor_deg``, and the flank fit, ``flank_deg``) it prints:

- over the runs finished in every record (:func:`common_points`), and over each record's own runs: the range and
  each factor's effect (high minus low, twice the coded least-squares coefficient of the main-effects model,
  statsmodels OLS) with its p-value where residual degrees of freedom are left;
- the Pearson correlation of each record's angles with the paper's, run matched to run by the coded settings, over
  the common runs and over all of the record's.

The effect of a factor over a subset of the half fraction is a least-squares estimate: on 8 of the 16 runs the
columns are not orthogonal, and 2 residual degrees of freedom are left. Output of this script:
``screening_laws.txt`` beside it (README, issue 23's nineteenth stage).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from warpdem.study.audit import published

HERE = Path(__file__).resolve().parent
REF = HERE.parents[2] / "studies" / "reference"
FACTORS = tuple("ABCDE")
PAPER_COLUMNS = {
    "A": "restitution",
    "B": "static_friction",
    "C": "rolling_friction",
    "D": "surface_energy_J_m2",
    "E": "pull_off_constant",
}
"""The factors' letters (studies/phosphate_ffd.toml) and the paper's run-table columns in actual units."""
SCREENINGS = (
    ("type A rolling friction", "ffd"),
    ("type A, surface energy x s", "ffd_gamma_s"),
    ("EDEM's standard rolling friction", "ffd_standard"),
)
"""(label, record folder under this one)."""
RESPONSES = (("cone", "aor_deg"), ("flanks", "flank_deg"))
"""Our two readings of a pile: (label, results.csv column)."""


def _read(path: Path):
    import pandas as pd

    return pd.read_csv(path)


def paper():
    """The paper's Fig. 14 runs: coded A..E (by its published ranges) and the angle as ``y`` [deg]."""
    from warpdem.study.designs import Factor

    ranges = published()["phosphate"]["ffd_ranges"]
    t = _read(REF / "phosphate_ffd_runs.csv")
    out = t[[]].copy()
    for f, col in PAPER_COLUMNS.items():
        out[f] = Factor(f, *ranges[col]).to_coded(t[col].astype(float))
    out["y"] = t.aor_deg.astype(float)
    return out


def ours(folder: str, column: str):
    """A record's finished runs: coded A..E and ``column`` as ``y`` [deg]."""
    t = _read(HERE / folder / "analysis" / "runs.csv").dropna(subset=[column])
    out = t[list(FACTORS)].astype(float).copy()
    out["y"] = t[column].astype(float)
    return out


def _points(df) -> set:
    return {tuple(int(round(v)) for v in row) for row in df[list(FACTORS)].to_numpy()}


def common_points() -> set:
    """The coded points finished in every record of :data:`SCREENINGS`."""
    sets = [_points(ours(folder, "aor_deg")) for _, folder in SCREENINGS]
    return set.intersection(*sets)


def restrict(df, points: set):
    """The rows of ``df`` at the coded ``points``."""
    keep = [tuple(int(round(v)) for v in row) in points for row in df[list(FACTORS)].to_numpy()]
    return df[np.asarray(keep, bool)]


def effects(df):
    """(effects [deg], p-values, residual df) of the main-effects model in coded A..E: effect = 2 x coded
    coefficient; p-values are NaN where no residual degree of freedom is left."""
    import statsmodels.formula.api as smf

    fit = smf.ols("y ~ " + " + ".join(FACTORS), df).fit()
    df_resid = int(round(fit.df_resid))
    p = {f: float(fit.pvalues[f]) if df_resid > 0 else float("nan") for f in FACTORS}
    return {f: 2.0 * float(fit.params[f]) for f in FACTORS}, p, df_resid


def matched(df, ref):
    """(ours, paper's) angles [deg] matched by coded point."""
    a = df.groupby([df[f].round().astype(int) for f in FACTORS]).y.mean()
    b = ref.groupby([ref[f].round().astype(int) for f in FACTORS]).y.mean()
    common = a.index.intersection(b.index)
    return a.loc[common].to_numpy(), b.loc[common].to_numpy()


def _line(df) -> str:
    eff, p, dof = effects(df)
    parts = [f"{f} {eff[f]:+.1f}" + (f" (p {p[f]:.2g})" if dof > 0 else "") for f in FACTORS]
    return f"{df.y.min():.1f}-{df.y.max():.1f} deg; " + ", ".join(parts) + f"; {dof} residual df"


def report() -> str:
    from scipy import stats

    lines: list[str] = []
    put = lines.append
    ref = paper()
    common = common_points()
    put("== Effects: high - low [deg] (p), main-effects least squares on coded A..E")
    put("   A restitution, B static friction, C rolling friction, D surface energy, E pull-off constant")
    put(f"paper, all {len(ref)} runs: {_line(ref)}")
    put(f"paper, the {len(common)} runs finished in every record: {_line(restrict(ref, common))}")
    for label, folder in SCREENINGS:
        for rlabel, column in RESPONSES:
            df = ours(folder, column)
            put(f"{label} ({folder}), {rlabel}, the {len(common)} common runs: {_line(restrict(df, common))}")
            if len(df) > len(common):
                put(f"{label} ({folder}), {rlabel}, all {len(df)} runs: {_line(df)}")

    put("")
    put("== Pearson correlation with the paper's angles, run matched to run (r, p, points)")
    for label, folder in SCREENINGS:
        for rlabel, column in RESPONSES:
            df = ours(folder, column)
            subsets = [("common", restrict(df, common))] + ([("all", df)] if len(df) > len(common) else [])
            for which, sub in subsets:
                a, b = matched(sub, ref)
                r = stats.pearsonr(a, b)
                put(f"{label} ({folder}), {rlabel}, {which}: {r.statistic:.2f} (p {r.pvalue:.2g}, {a.size} points)")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    import sys

    sys.path.insert(0, str(HERE.parent))  # docs/seeds, for the shared command line
    from report_cli import main as report_main

    return report_main(__doc__, report, argv)


if __name__ == "__main__":
    raise SystemExit(main())
