"""Seed 001 recalibrated with EDEM's standard rolling friction: our screenings, composites and verifications beside
the paper's, run by run.

    python docs/seeds/001/standard_recalibration.py [--out FILE]

Reads the records kept in the repository (``results.csv`` and ``verification/verification.json`` of each folder in
:data:`SCREENINGS`, :data:`COMPOSITES` and :data:`VERIFICATIONS`) and the paper's run tables
(``studies/reference/wetfeed_pb_runs.csv``, Table 3; ``wetfeed_ccd_runs.csv``, Table 6). For the image angle [deg],
the seed's response, it prints:

- the paper's own screening and composite fitted the same way; its published coefficients (Table 4) and sums of
  squares (Table 7) check the reading;
- each Plackett-Burman screening's range and mean, each factor's effect (high minus low, the coded least-squares
  coefficient times 2, statsmodels OLS on the coded columns) with its p-value, and the Pearson correlation of its
  12 angles with the paper's, run matched to run by the coded settings;
- each central composite's range, the quadratic's R^2 and its terms significant at 0.05 (statsmodels OLS on the
  coded columns), the centre points' mean and SD with the F test of their variance against the paper's nine (one
  sided), and the Pearson correlation with the paper's angles over the 14 non-centre points and the centre mean;
- each verification's piles, mean, SD, 95 % interval of the mean and t test against the measured 54.25 deg, beside
  the paper's five verification angles;
- for each setting poured with 6,000 and with the seed's 25,000 grains (:data:`SIZE_PAIRS`), the difference of the
  means (Welch's t test) and the ratio of the variances (F test, one-sided: does the smaller pile scatter more);
- for each pair of verifications that differ in one factor alone (:data:`SLOPES`: the surface energy X3, then the
  rolling friction X1), the pile's slope in that factor measured between them with its 95 % interval (Welch's for
  the difference of the means, over the step), beside the scaled composite's slope at the midpoint, and the two sizes' mean heap heights (a cohesive share of the angle
  going as the cohesive stress over the heap's weight, gamma / (R rho g H), makes the slope go as 1 / H).

Output of this script: ``standard_recalibration.txt`` beside it (README, "Seed 001 recalibrated", issue 23's
sixteenth to nineteenth stages).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from warpdem.study.audit import published

HERE = Path(__file__).resolve().parent
REF = HERE.parents[2] / "studies" / "reference"
_PUBLISHED = published()["wetfeed"]
"""Seed 001's published figures (studies/reference/published.toml)."""
TARGET = float(_PUBLISHED["measured_aor_deg"])
"""The seed's measured angle of repose [deg] (studies/reference/published.toml)."""
SEED_VERIFICATION = tuple(float(v) for v in _PUBLISHED["verification_aor_deg"])
"""The seed's five verification angles at its optimum [deg] (001_7b23801dd6850ee1.txt, optimisation section)."""
PB = tuple("ABCDEFG")
CCD = ("X1", "X2", "X3")
QUADRATIC = "y ~ X1 + X2 + X3 + X1:X2 + X1:X3 + X2:X3 + I(X1**2) + I(X2**2) + I(X3**2)"

SCREENINGS = (
    ("our spheres' EPSD", "pb"),
    ("EDEM's standard", "pb_standard"),
    ("EDEM's standard, surface energy x 0.2", "pb_standard_scaled"),
)
COMPOSITES = (
    ("our spheres' EPSD", "ccd"),
    ("EDEM's standard", "ccd_standard"),
    ("EDEM's standard, surface energy x 0.2", "ccd_standard_scaled"),
)
VERIFICATIONS = (
    ("EPSD composite's optimum, 6,000 grains", "ccd/verification/verification.json"),
    ("standard composite's optimum, 6,000 grains", "ccd_standard/verification/verification.json"),
    ("standard composite's optimum, 25,000 grains", "verify_large_standard/results.csv"),
    ("scaled composite's optimum, 6,000 grains", "ccd_standard_scaled/verification/verification.json"),
    ("one step in X3 past it, 6,000 grains", "verify_standard_scaled_step/results.csv"),
    ("the same point, 25,000 grains", "verify_large_standard_scaled/results.csv"),
    ("one more step in X3, 25,000 grains", "verify_large_standard_scaled_step/results.csv"),
    ("a step in X1 from there, 25,000 grains", "verify_large_standard_scaled_friction/results.csv"),
)
"""(label, file under this folder): a verification.json's ``values`` or a results.csv's ``aor_deg``."""
SIZE_PAIRS = (
    (
        "standard composite's optimum",
        "ccd_standard/verification/verification.json",
        "verify_large_standard/results.csv",
    ),
    ("one step in X3 past the scaled optimum", VERIFICATIONS[4][1], VERIFICATIONS[5][1]),
)
"""(label, 6,000-grain piles, 25,000-grain piles): one setting poured at both sizes."""
SLOPES = (
    ("6,000 grains, the scaled optimum to the step past it", VERIFICATIONS[3][1], VERIFICATIONS[4][1]),
    ("25,000 grains, the step's point to one more step", VERIFICATIONS[5][1], VERIFICATIONS[6][1]),
    ("25,000 grains, that step's point to a step in X1", VERIFICATIONS[6][1], VERIFICATIONS[7][1]),
)
"""(label, piles at one setting, piles at a setting that differs in one factor alone): the pile's slope in that
factor measured between two verifications, beside the scaled composite's (fitted on 6,000-grain piles)."""
COMPOSITE_FOR_SLOPE = "ccd_standard_scaled"


def _read(path: Path):
    import pandas as pd

    return pd.read_csv(path)


def paper_screening():
    """The paper's Table 3: coded A..G and the angle, as a DataFrame with column ``y``."""
    return _read(REF / "wetfeed_pb_runs.csv").rename(columns={"aor_deg": "y"})


def paper_composite():
    """The paper's Table 6: coded X1..X3 and the angle, as a DataFrame with column ``y``."""
    return _read(REF / "wetfeed_ccd_runs.csv").rename(columns={"aor_deg": "y"})


def ours(folder: str):
    """A record's design runs: coded factor columns and the angle as ``y``."""
    return _read(HERE / folder / "results.csv").rename(columns={"aor_deg": "y"})


def screening_fit(df):
    """(effects, p-values) of the linear model in coded A..G: effect = 2 x coded coefficient [deg]."""
    import statsmodels.formula.api as smf

    fit = smf.ols("y ~ " + " + ".join(PB), df).fit()
    return {f: 2.0 * fit.params[f] for f in PB}, {f: fit.pvalues[f] for f in PB}


def composite_fit(df):
    """The quadratic in coded X1..X3 (statsmodels OLS result)."""
    import statsmodels.formula.api as smf

    return smf.ols(QUADRATIC, df).fit()


def _key(row, names):
    return tuple(round(float(row[n]), 6) for n in names)


def matched(df, ref, names):
    """Pairs (ours, paper's) matched by coded point; repeated points (centres) enter once, as their means."""
    a = df.groupby([df[n].round(6) for n in names]).y.mean()
    b = ref.groupby([ref[n].round(6) for n in names]).y.mean()
    common = a.index.intersection(b.index)
    return a.loc[common].to_numpy(), b.loc[common].to_numpy()


def _term(name: str) -> str:
    """A formula term as Design-Expert writes it: X1*X2, X1^2."""
    return name.replace(":", "*").replace("I(", "").replace(" ** 2)", "^2")


def centre(df, names):
    """The angles at the design centre (every coded factor 0)."""
    return df[np.all(np.isclose(df[list(names)].to_numpy(), 0.0), axis=1)].y.to_numpy()


def verification_values(rel: str):
    """The piles [deg] of one verification, from its record."""
    path = HERE / rel
    if path.suffix == ".json":
        return np.asarray(json.loads(path.read_text())["values"], float)
    return _read(path).aor_deg.to_numpy(float)


def settings(rel: str) -> dict:
    """The X1, X2, X3 [actual units] of one verification record (a one-point ``results.csv`` or a
    verification.json's ``settings``)."""
    path = HERE / rel
    if path.suffix == ".json":
        return {n: float(v) for n, v in json.loads(path.read_text())["settings"].items()}
    t = _read(path)
    out = {}
    for n in CCD:
        values = t[f"{n}_actual"].unique()
        if values.size != 1:
            raise SystemExit(f"{path}: {n}_actual holds {list(values)}; a one-point verification expected")
        out[n] = float(values[0])
    return out


def pile_heights(rel: str) -> np.ndarray:
    """The heap heights [m] of one verification's piles, in the order of :func:`verification_values` (a
    verification.json's ``metrics``, or each results.csv row's run record under ``runs/``)."""
    path = HERE / rel
    if path.suffix == ".json":
        return np.asarray(json.loads(path.read_text())["metrics"]["pile_height_m"], float)
    runs = path.parent / "runs"
    return np.array(
        [json.loads((runs / f"{pid}.json").read_text())["metrics"]["pile_height_m"] for pid in _read(path).point_id]
    )


UNITS = {"X1": "unit", "X2": "unit", "X3": "J/m^2"}
"""Each composite factor's unit, for the slopes' "deg per ..." (X1 and X2 are friction coefficients)."""


def composite_slope(x: dict, factor: str = "X3") -> float:
    """The scaled composite's d(angle)/d(factor) [deg per unit of the factor] at the point ``x`` (its record's
    actual coefficients)."""
    b = _read(HERE / COMPOSITE_FOR_SLOPE / "analysis" / "coefficients_aor_deg.csv").set_index("Term")
    b = b["Actual Coefficient"]
    slope = b[factor] + 2.0 * b[f"{factor}^2"] * x[factor]
    for other in CCD:
        if other != factor:
            term = "*".join(sorted((factor, other)))
            slope += b[term] * x[other]
    return float(slope)


def step_slope(first: str, second: str):
    """(the factor stepped, measured slope [deg per unit of it], its 95 % interval, Welch's two-sided p, the
    composite's slope at the midpoint) between two verifications that differ in one factor alone; the interval is
    Welch's for the difference of the means over the step."""
    from scipy import stats

    xa, xb = settings(first), settings(second)
    # the studies write a chosen point to 4 decimals
    moved = [n for n in CCD if round(xa[n], 4) != round(xb[n], 4)]
    if len(moved) != 1:
        raise SystemExit(f"{first}, {second}: not one step in one factor alone ({xa}, {xb})")
    (factor,) = moved
    a, b = verification_values(first), verification_values(second)
    w = stats.ttest_ind(b, a, equal_var=False)
    lo, hi = w.confidence_interval(0.95)
    dx = xb[factor] - xa[factor]
    mid = xa | {factor: 0.5 * (xa[factor] + xb[factor])}
    slope = (b.mean() - a.mean()) / dx
    return factor, slope, tuple(sorted((lo / dx, hi / dx))), float(w.pvalue), composite_slope(mid, factor)


def one_sample(values):
    """(mean, SD, 95 % interval of the mean, t, p) against :data:`TARGET`."""
    from scipy import stats

    v = np.asarray(values, float)
    m, s = v.mean(), v.std(ddof=1)
    half = stats.t.ppf(0.975, v.size - 1) * s / np.sqrt(v.size)
    t = stats.ttest_1samp(v, TARGET)
    return m, s, (m - half, m + half), float(t.statistic), float(t.pvalue)


def size_effect(small, large):
    """(mean difference large - small [deg], Welch's t, its two-sided p, variance ratio small / large, its one-sided
    F p) for the piles of one setting poured at two sizes."""
    from scipy import stats

    a, b = np.asarray(small, float), np.asarray(large, float)
    w = stats.ttest_ind(b, a, equal_var=False)
    f = a.var(ddof=1) / b.var(ddof=1)
    return b.mean() - a.mean(), float(w.statistic), float(w.pvalue), f, float(stats.f.sf(f, a.size - 1, b.size - 1))


def report() -> str:
    from scipy import stats

    lines: list[str] = []
    put = lines.append
    paper_pb, paper_ccd = paper_screening(), paper_composite()

    put("== Plackett-Burman screenings (Table 3 coded points; effect = high - low [deg], p)")
    eff, p = screening_fit(paper_pb)
    put(f"paper: {paper_pb.y.min():.1f}-{paper_pb.y.max():.1f} deg, mean {paper_pb.y.mean():.2f}")
    put("  " + ", ".join(f"{f} {eff[f]:+.2f} ({p[f]:.2g})" for f in PB))
    for label, folder in SCREENINGS:
        df = ours(folder)
        eff, p = screening_fit(df)
        a, b = matched(df, paper_pb, PB)
        r = stats.pearsonr(a, b)
        put(f"{label} ({folder}): {df.y.min():.1f}-{df.y.max():.1f} deg, mean {df.y.mean():.2f}")
        put("  " + ", ".join(f"{f} {eff[f]:+.2f} ({p[f]:.2g})" for f in PB))
        put(f"  significant at 0.05: {', '.join(f for f in PB if p[f] < 0.05) or 'none'}")
        put(f"  Pearson with the paper's 12 angles: {r.statistic:.2f} (p {r.pvalue:.2g}, {a.size} points)")

    put("")
    put("== Central composites (Table 6 coded points; quadratic in coded units)")
    paper_centre = centre(paper_ccd, CCD)
    for label, df in [("paper", paper_ccd)] + [(f"{lab} ({fol})", ours(fol)) for lab, fol in COMPOSITES]:
        fit = composite_fit(df)
        terms = [_term(t) for t in fit.params.index[1:] if fit.pvalues[t] < 0.05]
        c = centre(df, CCD)
        put(f"{label}: {df.y.min():.2f}-{df.y.max():.2f} deg; R^2 {fit.rsquared:.3f}, model F p {fit.f_pvalue:.2g}")
        put(f"  significant at 0.05: {', '.join(terms) or 'none'}")
        put(f"  centre: {c.size} points, {c.mean():.2f} +- {c.std(ddof=1):.2f} deg")
        if label != "paper":
            f = c.var(ddof=1) / paper_centre.var(ddof=1)
            pf = stats.f.sf(f, c.size - 1, paper_centre.size - 1)
            a, b = matched(df, paper_ccd, CCD)
            r = stats.pearsonr(a, b)
            put(f"  centre variance against the paper's: F {f:.2f}, p {pf:.2g} (one-sided)")
            put(f"  Pearson with the paper's angles: {r.statistic:.2f} (p {r.pvalue:.2g}, {a.size} points)")
        else:
            import statsmodels.api as sm

            ss = sm.stats.anova_lm(fit, typ=2)["sum_sq"]
            put("  coded coefficients: " + ", ".join(f"{_term(t)} {fit.params[t]:+.3f}" for t in fit.params.index[1:]))
            put("  sums of squares: " + ", ".join(f"{_term(t)} {ss[t]:.2f}" for t in ss.index[:-1]))

    put("")
    put(f"== Verifications against {TARGET} deg (mean +- SD, 95 % interval of the mean, t, p)")
    rows = [("paper's optimum (seed, EDEM)", np.asarray(SEED_VERIFICATION))]
    rows += [(label, verification_values(rel)) for label, rel in VERIFICATIONS]
    for label, v in rows:
        m, s, (lo, hi), t, pt = one_sample(v)
        put(f"{label}: {', '.join(f'{x:.1f}' for x in v)}")
        put(f"  {m:.2f} +- {s:.2f} deg ({lo:.2f}-{hi:.2f}); {m - TARGET:+.2f} deg; t {t:.2f}, p {pt:.2g}")

    put("")
    put("== One setting at both sizes (25,000 grains minus 6,000: Welch's t; variance ratio 6,000 / 25,000, F)")
    for label, small, large in SIZE_PAIRS:
        d, t, pt, f, pf = size_effect(verification_values(small), verification_values(large))
        put(f"{label}: {d:+.2f} deg, t {t:.2f}, p {pt:.2g}; variance ratio {f:.1f}, p {pf:.2g} (one-sided)")

    put("")
    put("== The pile's slope in one factor between two verifications [deg per unit] (95 % interval, Welch), beside")
    put(f"   the scaled composite's at the midpoint ({COMPOSITE_FOR_SLOPE}, fitted on 6,000-grain piles)")
    for label, first, second in SLOPES:
        factor, slope, (lo, hi), pw, model = step_slope(first, second)
        xa, xb = settings(first)[factor], settings(second)[factor]
        span = f"{factor} {xa:.4f} to {xb:.4f} {UNITS[factor]}"
        put(f"{label} ({span}): {slope:.1f} deg per {UNITS[factor]} ({lo:.1f} to {hi:.1f}), p {pw:.2g}")
        put(f"  the composite's: {model:.1f}; measured / composite {slope / model:.2f}")
    # cohesion's share of the angle goes as the bulk cohesive stress (gamma / R) over the heap's weight stress
    # (rho g H): the same grains in a taller heap should feel X3 as 1 / H
    h_small = np.concatenate([pile_heights(rel) for rel in SLOPES[0][1:]]).mean()
    h_large = np.concatenate([pile_heights(rel) for rel in SLOPES[1][1:]]).mean()
    put(
        f"heap height: {1e3 * h_small:.1f} mm at 6,000 grains, {1e3 * h_large:.1f} mm at 25,000; a slope going as "
        f"1 / H would fall to {h_small / h_large:.2f} of the 6,000-grain one at the larger size"
    )
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    import sys

    sys.path.insert(0, str(HERE.parent))  # docs/seeds, for the shared command line
    from report_cli import main as report_main

    return report_main(__doc__, report, argv)


if __name__ == "__main__":
    raise SystemExit(main())
