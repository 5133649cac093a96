"""Which of our screening effects differ from the papers' beyond the noise of both, seed by seed.

    python docs/seeds/effect_differences.py [--out FILE]

A screening's effect (high minus low, twice the coded least-squares coefficient of the main-effects model,
statsmodels OLS) is an estimate with a standard error from its own residuals: the papers' (their run tables,
``studies/reference/``) and ours (the records' ``results.csv``) each have one. For each factor the difference of
the two effects is tested with a Welch t: the difference over the root of the summed squared standard errors, on
Welch-Satterthwaite's degrees of freedom from the two fits' residual degrees of freedom (two-sided). The six or
seven factors of one comparison are one family, Holm-corrected: a difference is "beyond the noise" when its Holm p
is below 0.05. A difference within the noise is no evidence that the model differs from the paper's; one beyond it
must be explained.

The screenings compared (:data:`SCREENINGS`): seed 000's Plackett-Burman (Tables 5-7) with each contact setup we
ran, seed 001's Plackett-Burman (Tables 2-4) likewise, and seed 002's 2^(5-1) (Fig. 14) where all 16 runs have
run. Output of this script: ``effect_differences.txt`` beside it (README, issue 23's nineteenth stage).
"""

from __future__ import annotations

import math
from pathlib import Path

HERE = Path(__file__).resolve().parent
REF = HERE.parents[1] / "studies" / "reference"
ALPHA = 0.05
"""The family-wise level of the Holm correction."""

SCREENINGS = (
    (
        "seed 000, Plackett-Burman",
        "pellets_pb_runs.csv",
        "ABCDEF",
        (
            ("type A, the plate fixed", "000/pb"),
            ("type A, the plate following the wall factors", "000/pb_plate"),
            ("EDEM's standard, the plate following", "000/pb_standard"),
            ("EDEM's standard, the plate held at the calibrated friction", "000/pb_standard_plate_held"),
        ),
    ),
    (
        "seed 001, Plackett-Burman",
        "wetfeed_pb_runs.csv",
        "ABCDEFG",
        (
            ("our spheres' EPSD", "001/pb"),
            ("EDEM's standard", "001/pb_standard"),
            ("EDEM's standard, surface energy x 0.2", "001/pb_standard_scaled"),
            ("type A, surface energy x 0.2", "001/pb_type_a_scaled"),
        ),
    ),
    (
        "seed 002, 2^(5-1)",
        None,
        "ABCDE",
        (
            ("type A", "002/ffd"),
            ("type A, surface energy x s", "002/ffd_gamma_s"),
            ("EDEM's standard", "002/ffd_standard"),
        ),
    ),
)
"""(label, the paper's coded run table under studies/reference (None: seed 002's, in actual units, coded by
:func:`paper_runs`), factors, ((record label, record folder under docs/seeds), ...))."""


def _read(path: Path):
    import pandas as pd

    return pd.read_csv(path)


def paper_runs(table: str | None, factors: str):
    """A paper's screening runs: coded factor columns and the angle as ``y`` [deg]. Seed 002's table is in actual
    units and is coded by its published ranges (docs/seeds/002/screening_laws.py)."""
    if table is None:
        import importlib.util

        path = HERE / "002" / "screening_laws.py"
        spec = importlib.util.spec_from_file_location("screening_laws", path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        return mod.paper()
    t = _read(REF / table)
    out = t[list(factors)].astype(float).copy()
    out["y"] = t.aor_deg.astype(float)
    return out


def our_runs(folder: str, factors: str):
    """A record's finished runs: coded factor columns and ``aor_deg`` as ``y`` [deg]."""
    t = _read(HERE / folder / "results.csv").dropna(subset=["aor_deg"])
    out = t[list(factors)].astype(float).copy()
    out["y"] = t.aor_deg.astype(float)
    return out


def effects(df, factors: str):
    """(effects [deg], their standard errors [deg], residual df) of the main-effects model in coded units."""
    import statsmodels.formula.api as smf

    from warpdem.study.report import settle

    fit = smf.ols("y ~ " + " + ".join(factors), df).fit()
    return (
        {f: settle(2.0 * float(fit.params[f])) for f in factors},
        {f: 2.0 * float(fit.bse[f]) for f in factors},
        float(fit.df_resid),
    )


def differences(paper, ours, factors: str) -> list[dict]:
    """Per factor: the paper's and our effect, their difference (ours - paper's) [deg], its standard error, Welch
    df, two-sided p and Holm p over the factors; ``beyond`` when the Holm p is below :data:`ALPHA`."""
    from scipy import stats
    from statsmodels.stats.multitest import multipletests

    ep, sp, dfp = effects(paper, factors)
    eo, so, dfo = effects(ours, factors)
    rows = []
    for f in factors:
        se = math.hypot(sp[f], so[f])
        df = se**4 / (sp[f] ** 4 / dfp + so[f] ** 4 / dfo)
        d = eo[f] - ep[f]
        p = float(2.0 * stats.t.sf(abs(d) / se, df))
        rows.append({"factor": f, "paper": ep[f], "ours": eo[f], "diff": d, "se": se, "df": df, "p": p})
    holm = multipletests([r["p"] for r in rows], method="holm")[1]
    for r, q in zip(rows, holm):
        r["p_holm"] = float(q)
        r["beyond"] = bool(q < ALPHA)
    return rows


def comparisons():
    """Every comparison of :data:`SCREENINGS` whose record has all of the design's runs: (screening label, record
    label, folder, rows of :func:`differences`)."""
    out = []
    for label, table, factors, records in SCREENINGS:
        paper = paper_runs(table, factors)
        for rlabel, folder in records:
            ours = our_runs(folder, factors)
            if len(ours) < len(paper):
                continue
            out.append((label, rlabel, folder, differences(paper, ours, factors)))
    return out


def report() -> str:
    lines: list[str] = []
    put = lines.append
    put("== Screening effects, ours against the paper's: high - low [deg]; the difference's Welch t, Holm over the")
    put(f"   factors of one comparison (beyond the noise: Holm p < {ALPHA})")
    last = None
    for label, rlabel, folder, rows in comparisons():
        if label != last:
            put("")
            put(label)
            last = label
        put(f"  {rlabel} ({folder}):")
        for r in rows:
            mark = "  BEYOND THE NOISE" if r["beyond"] else ""
            put(
                f"    {r['factor']}: paper {r['paper']:+.2f}, ours {r['ours']:+.2f}; difference {r['diff']:+.2f} "
                f"+- {r['se']:.2f} ({r['df']:.1f} df), p {r['p']:.2g}, Holm {r['p_holm']:.2g}{mark}"
            )
        beyond = [r["factor"] for r in rows if r["beyond"]]
        put(f"    beyond the noise: {', '.join(beyond) or 'none'}")
    skipped = [
        f"{folder} ({len(our_runs(folder, factors))} of {len(paper_runs(table, factors))} runs)"
        for _, table, factors, records in SCREENINGS
        for _, folder in records
        if len(our_runs(folder, factors)) < len(paper_runs(table, factors))
    ]
    if skipped:
        put("")
        put(f"not compared, the design not yet run whole: {', '.join(skipped)}")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    import sys

    sys.path.insert(0, str(HERE))  # docs/seeds, for the shared command line
    from report_cli import main as report_main

    return report_main(__doc__, report, argv)


if __name__ == "__main__":
    raise SystemExit(main())
