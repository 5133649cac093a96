"""Every pile of seed 001's wet feed at the seed's 25,000 grains in the friction box, read together: does the
friction move the pile, and how much do piles of one setting scatter against the seed's own?

    python docs/seeds/001/pile_scatter.py [--out FILE]

Reads the run records kept in the repository, all of one scene (studies/wetfeed_large_friction.toml: 2 mm
spheres, JKR surface energy 0.5506 J/m^2) with the particle-particle rolling friction X1 and static friction X2
set per pile (:data:`SOURCES`): the face-centred composite (``large_friction/runs/``, 9 piles), its verification
(``large_friction/verification/``, 5), the first verification at the small composite's optimum
(``verify_large/runs/``, 5, X1 0.3241 just past the box's 0.32) and the reach diagnosis (``reach_large/runs/``,
12). Prints, for the image angle [deg] (the seed's response):

- each pile, with the composite model's prediction and 95 % prediction interval for the piles made after it;
- the full quadratic in X1, X2 refitted on every pile (statsmodels OLS), its R^2 and overall F test;
- the pure error (piles that repeat one setting) against the seed's nine centre points of Table 6
  (``studies/reference/wetfeed_ccd_runs.csv``) and its five verification angles (:data:`SEED_VERIFICATION`),
  with the F test of the two variances;
- the mean of every pile against the measured 54.25 deg, and the piles a 1 deg, 95 % interval would need;

the last three again without the piles the runs' off-axis check flags (a pile that slid off the funnel's axis
after it was built: two, each read on its side). Then the piles of ``scatter_bond/`` and ``scatter_bond_standard/``
(studies/wetfeed_scatter_bond.toml and its twin with EDEM's standard rolling friction: 6,000 grains, four world
seeds at each of two surface energies): each reading's mean and SD per rolling model and surface energy, the F tests
of their variances, and the standard model's low-Bond piles against the target and the seed's centre points.

Output of this script for the fifteenth stage: ``pile_scatter.txt`` beside it (README, "Seed 001 diagnosed",
issue 23's fifteenth stage).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from warpdem.study.audit import published

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[2]
_PUBLISHED = published()["wetfeed"]
"""Seed 001's published figures (studies/reference/published.toml)."""
TARGET = float(_PUBLISHED["measured_aor_deg"])
"""The seed's measured angle of repose [deg] (studies/reference/published.toml)."""
SEED_VERIFICATION = tuple(float(v) for v in _PUBLISHED["verification_aor_deg"])
"""The seed's five verification angles at its optimum [deg] (001_7b23801dd6850ee1.txt, optimisation section)."""
X1_KEY, X2_KEY = "interaction.grain.grain.rolling_friction", "interaction.grain.grain.static_friction"
CENTRE, HALF = (0.24, 0.50), 0.08
"""The friction box's centre (X1, X2) and half-width, as coded in studies/wetfeed_large_friction.toml."""
MODEL = "y ~ X1 + X2 + X1:X2 + I(X1**2) + I(X2**2)"


SOURCES = (
    ("composite", "large_friction/runs/*.json"),
    ("old optimum", "verify_large/runs/*.json"),
    ("verification", "large_friction/verification/replicate_*.json"),
    ("diagnosis", "reach_large/runs/*.json"),
)
"""Where each group's run records lie, under this folder."""


def piles():
    """One row per pile (a pandas DataFrame, in the order of :data:`SOURCES` and then of the file names): source,
    X1 and X2 (actual), world seed, image angle ``y`` [deg], the pile's centre off the funnel's axis
    ``offset_mm`` and ``flagged`` (the run's off-axis check, :func:`warpdem.engine.suspect.off_axis_warning`)."""
    import pandas as pd

    from warpdem.engine.suspect import off_axis_warning
    from warpdem.scene.rigs import Funnel

    outlet_radius = Funnel().outlet_diameter / 2
    rows = []
    for name, pattern in SOURCES:
        for f in sorted(HERE.glob(pattern)):
            d = json.loads(f.read_text())
            o, m = d["overrides"], d["metrics"]
            if "design" in d and "stage" in d["design"]:
                name_ = f"{name} {d['design']['stage'].split(': ')[1]}"
            else:
                name_ = name
            off = m["pile_offset_m"]
            flagged = off_axis_warning(off, outlet_radius) is not None
            rows.append((name_, o[X1_KEY], o[X2_KEY], d["world_seed"], m["angle_image_deg"], 1000 * off, flagged))
    cols = ["source", "X1_actual", "X2_actual", "seed", "y", "offset_mm", "flagged"]
    df = pd.DataFrame(rows, columns=cols)
    df["X1"] = (df.X1_actual - CENTRE[0]) / HALF
    df["X2"] = (df.X2_actual - CENTRE[1]) / HALF
    return df


def seed_centre_points() -> np.ndarray:
    """The seed's central-composite centre points (Table 6, every factor coded 0) [deg]."""
    with open(ROOT / "studies" / "reference" / "wetfeed_ccd_runs.csv", newline="") as f:
        return np.array([float(r["aor_deg"]) for r in csv.DictReader(f) if r["X1"] == r["X2"] == r["X3"] == "0"])


def pure_error(df) -> tuple[float, int, list[np.ndarray]]:
    """The pure-error variance [deg^2] and its degrees of freedom, pooled over the settings (X1, X2) that ``df``
    repeats (:func:`warpdem.study.analysis.pure_error`, as the studies' ANOVA takes it), and each repeated
    setting's angles."""
    from warpdem.study.analysis import pure_error as sums

    ss, dof = sums(df.y, zip(df.X1_actual, df.X2_actual))
    groups = [g.y.to_numpy() for _, g in df.groupby(["X1_actual", "X2_actual"]) if len(g) > 1]
    return ss / dof, dof, groups


def together(df, label: str) -> list[str]:
    """Lines on the piles of ``df`` read together: the quadratic refitted on them, their pure error against the
    seed's, and their mean against the target; ``label`` names them."""
    import statsmodels.formula.api as smf
    from scipy import stats

    out = []
    full = smf.ols(MODEL, df).fit()
    out.append(f"\nThe quadratic refitted on {label}:")
    out.append(full.summary2().tables[1].round(3).to_string())
    out.append(
        f"R^2 {full.rsquared:.3f} (adjusted {full.rsquared_adj:.3f}), residual SD {np.sqrt(full.scale):.2f} on "
        f"{full.df_resid:.0f} df; overall F {full.fvalue:.2f}, p {full.f_pvalue:.3f}"
    )
    pe_var, pe_df, groups = pure_error(df)
    out.append("\nPure error (piles repeating one setting):")
    for (x1, x2), g in df.groupby(["X1_actual", "X2_actual"]):
        if len(g) > 1:
            out.append(f"  X1 {x1:.4f}, X2 {x2:.4f}: {len(g)} piles, {g.y.mean():.2f} +- {g.y.std(ddof=1):.2f}")
    lev = stats.levene(*groups)
    out.append(f"  pooled SD {np.sqrt(pe_var):.2f} on {pe_df} df (Levene across the settings: p {lev.pvalue:.2f})")
    centre, ver = seed_centre_points(), np.array(SEED_VERIFICATION)
    out.append(
        f"The seed's {len(centre)} centre points: {centre.mean():.2f} +- {centre.std(ddof=1):.2f}; its "
        f"{len(ver)} verification runs: {ver.mean():.2f} +- {ver.std(ddof=1):.2f}"
    )
    f_ratio = pe_var / centre.var(ddof=1)
    out.append(
        f"Variance ratio, ours / the seed's centre points: F {f_ratio:.1f} on ({pe_df}, {len(centre) - 1}) df, "
        f"p {stats.f.sf(f_ratio, pe_df, len(centre) - 1):.2g}; SD ratio {np.sqrt(f_ratio):.1f}"
    )
    m, s, n = df.y.mean(), df.y.std(ddof=1), len(df)
    t = stats.ttest_1samp(df.y, TARGET)
    lo, hi = stats.t.interval(0.95, n - 1, m, s / np.sqrt(n))
    out.append(
        f"\n{label.capitalize()}: {m:.2f} +- {s:.2f} deg, 95 % interval of the mean {lo:.1f}-{hi:.1f}; against "
        f"{TARGET}: t {t.statistic:.2f}, p {t.pvalue:.2f}"
    )
    out.append(
        f"Piles at one setting for a 95 % interval of +-1 deg at the pure-error SD: "
        f"{(1.96 * np.sqrt(pe_var)) ** 2:.0f}; at the seed's centre-point SD: {(1.96 * centre.std(ddof=1)) ** 2:.1f}"
    )
    return out


def report(df) -> str:
    """The printed analysis of :func:`piles` (``df``)."""
    import statsmodels.formula.api as smf
    from scipy import stats

    out = []
    comp = smf.ols(MODEL, df[df.source == "composite"]).fit()
    later = df.source != "composite"
    pred = comp.get_prediction(df).summary_frame(alpha=0.05)
    df = df.assign(pred=pred["mean"].to_numpy(), pi_low=pred["obs_ci_lower"].to_numpy())
    df = df.assign(pi_high=pred["obs_ci_upper"].to_numpy())
    out.append(f"{len(df)} piles of 25,000 grains (image angle, deg); pred: the composite's quadratic (9 piles)")
    out.append(df.round(4).to_string(index=False))
    res = df.y[later] - df.pred[later]
    t = stats.ttest_1samp(res, 0.0)
    inside = ((df.y >= df.pi_low) & (df.y <= df.pi_high))[later].sum()
    out.append(
        f"\nThe {later.sum()} later piles against the composite's model: residual mean {res.mean():.2f}, "
        f"SD {res.std(ddof=1):.2f} (t {t.statistic:.2f}, p {t.pvalue:.3f}); {inside} inside its 95 % prediction "
        f"interval; the composite's own residual SD {np.sqrt(comp.scale):.2f} on {comp.df_resid:.0f} df"
    )
    out += together(df, f"all {len(df)} piles")
    kept = df[~df.flagged]
    out += together(kept, f"the {len(kept)} piles the off-axis check leaves (without {int(df.flagged.sum())})")
    return "\n".join(out) + "\n"


READINGS = {
    "angle_image_deg": "image angle [deg]",
    "angle_fit_deg": "surface fit [deg]",
    "angle_cone_deg": "cone formula [deg]",
    "pile_height_m": "pile height [mm]",
}
"""The readings of each pile compared at two Bond numbers (metric: label); heights printed in mm."""
GAMMA_KEY = "interaction.grain.grain.surface_energy"
BOND_STUDIES = {"EPSD": "scatter_bond", "standard": "scatter_bond_standard"}
"""The grain-grain rolling model of each Bond-number study (its folder under this one)."""


def bond_piles():
    """The piles of the :data:`BOND_STUDIES` (a pandas DataFrame): rolling model, surface energy [J/m^2], world
    seed and :data:`READINGS` (heights in mm)."""
    import pandas as pd

    rows = []
    for rolling, folder in BOND_STUDIES.items():
        for f in sorted((HERE / folder / "runs").glob("*.json")):
            d = json.loads(f.read_text())
            m = d["metrics"]
            row = {"rolling_model": rolling, "gamma": d["overrides"][GAMMA_KEY], "seed": d["world_seed"]}
            row.update({k: m[k] * (1000.0 if k.endswith("_m") else 1.0) for k in READINGS})
            rows.append(row)
    return pd.DataFrame(rows).sort_values(["rolling_model", "gamma", "seed"], ignore_index=True)


def _ratio(a, b) -> str:
    """The variance ratio of ``b`` over ``a`` and its one-sided p-value (``b`` scatters more)."""
    from scipy import stats

    f = b.var(ddof=1) / a.var(ddof=1)
    return f"F {f:.1f} on ({len(b) - 1}, {len(a) - 1}) df, p {stats.f.sf(f, len(b) - 1, len(a) - 1):.3g}"


def bond_report() -> str:
    """Each reading's mean and scatter per rolling model and surface energy of the :data:`BOND_STUDIES`, the
    one-sided F tests of the higher Bond number against the lower (per model) and of EPSD against the standard
    model at the lower, and the standard model's low-Bond piles against the seed's target and centre points."""
    from scipy import stats

    df = bond_piles()
    low, high = sorted(df.gamma.unique())
    out = [
        f"\nScatter at two Bond numbers, 6,000 grains, X1 0.3, X2 0.6 (surface energy {low:g} and {high:g} J/m^2), "
        f"with our spheres' EPSD rolling friction ({BOND_STUDIES['EPSD']}/) and EDEM's standard "
        f"({BOND_STUDIES['standard']}/)"
    ]
    out.append(df.rename(columns={"pile_height_m": "pile_height_mm"}).round(3).to_string(index=False))
    for key, label in READINGS.items():
        out.append(f"{label}:")
        g = {(r, x): df[(df.rolling_model == r) & (df.gamma == x)][key] for r in BOND_STUDIES for x in (low, high)}
        for r in BOND_STUDIES:
            a, b = g[r, low], g[r, high]
            out.append(
                f"  {r}: {a.mean():.1f} +- {a.std(ddof=1):.2f} at {low:g}, {b.mean():.1f} +- {b.std(ddof=1):.2f} "
                f"at {high:g}; more scatter at {high:g}: {_ratio(a, b)}"
            )
        out.append(f"  at {low:g}, EPSD scatters more than standard: {_ratio(g['standard', low], g['EPSD', low])}")
    std = df[(df.rolling_model == "standard") & (df.gamma == low)].angle_image_deg
    t = stats.ttest_1samp(std, TARGET)
    centre = seed_centre_points()
    f = std.var(ddof=1) / centre.var(ddof=1)
    p = 2 * min(stats.f.sf(f, len(std) - 1, len(centre) - 1), stats.f.cdf(f, len(std) - 1, len(centre) - 1))
    out.append(
        f"Standard rolling friction at {low:g} J/m^2, image angle {std.mean():.2f} +- {std.std(ddof=1):.2f}: against "
        f"{TARGET}, t {t.statistic:.2f}, p {t.pvalue:.3f}; its variance against the seed's centre points: F {f:.2f} "
        f"on ({len(std) - 1}, {len(centre) - 1}) df, p {p:.2f} (two-sided)"
    )
    return "\n".join(out) + "\n"


def main(argv=None) -> int:
    import sys

    sys.path.insert(0, str(HERE.parent))  # docs/seeds, for the shared command line
    from report_cli import main as report_main

    return report_main(__doc__, lambda: report(piles()) + bond_report(), argv)


if __name__ == "__main__":
    raise SystemExit(main())
