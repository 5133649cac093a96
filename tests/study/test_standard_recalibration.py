"""docs/seeds/001/standard_recalibration.py reads the paper's tables as published (its coefficients, Table 4, and
sums of squares, Table 7, come out of the run tables), pairs our runs with the paper's by coded point, reads every
record it names, and its kept output is what it prints now."""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tests.conftest import load_seed_script

ROOT = Path(__file__).resolve().parents[2]
HERE = ROOT / "docs" / "seeds" / "001"
REF = ROOT / "studies" / "reference"


@pytest.fixture(scope="module")
def recal():
    return load_seed_script("001/standard_recalibration.py")


def test_the_paper_screening_gives_its_published_coefficients(recal):
    effects, pvalues = recal.screening_fit(recal.paper_screening())
    published = pd.read_csv(REF / "wetfeed_pb_anova_published.csv").set_index("source")
    for f in recal.PB:
        # Table 4 prints 2-3 significant digits: the coded coefficient is half the effect
        assert effects[f] / 2.0 == pytest.approx(published.loc[f, "coefficient"], abs=0.006), f
    assert {f for f in recal.PB if pvalues[f] < 0.01} == {"B", "C", "G"}


def test_the_paper_composite_gives_its_published_sums_of_squares(recal):
    import statsmodels.api as sm

    fit = recal.composite_fit(recal.paper_composite())
    ss = sm.stats.anova_lm(fit, typ=2)["sum_sq"].rename(lambda t: recal._term(t).replace("*", ""))
    published = pd.read_csv(REF / "wetfeed_ccd_anova_published.csv").set_index("source")["sum_sq"]
    for term in ("X1", "X2", "X3", "X1X2", "X1X3", "X2X3", "X1^2", "X2^2", "X3^2"):
        assert ss[term] == pytest.approx(published[term], abs=0.01), term
    assert ss["Residual"] == pytest.approx(published["Residual"], abs=0.02)


def test_runs_pair_with_the_paper_by_coded_point(recal):
    for _, folder in recal.SCREENINGS:
        a, b = recal.matched(recal.ours(folder), recal.paper_screening(), recal.PB)
        assert a.size == b.size == 12
    for _, folder in recal.COMPOSITES:
        df = recal.ours(folder)
        assert len(df) == 23 and recal.centre(df, recal.CCD).size == 9
        a, b = recal.matched(df, recal.paper_composite(), recal.CCD)
        # 8 factorial + 6 axial points, and the nine centre points as one mean
        assert a.size == b.size == 15
        assert b[np.isclose(b, 54.05, atol=0.005)].size == 1


def test_every_verification_has_five_piles_and_its_interval(recal):
    from statsmodels.stats.weightstats import DescrStatsW

    for _, rel in recal.VERIFICATIONS:
        v = recal.verification_values(rel)
        assert v.size == 5 and np.all((v > 0.0) & (v < 90.0))
        m, s, (lo, hi), t, p = recal.one_sample(v)
        d = DescrStatsW(v)
        assert (lo, hi) == pytest.approx(d.tconfint_mean(0.05), rel=1e-12)
        assert t == pytest.approx(d.ttest_mean(recal.TARGET)[0], rel=1e-12)


def test_the_kept_output_is_current(recal):
    assert (HERE / "standard_recalibration.txt").read_text() == recal.report()


def test_size_pairs_pour_one_setting_and_agree_with_statsmodels(recal):
    """Each pair's two records share their settings, and the Welch t test and variance ratio equal statsmodels'
    (ttest_ind with unequal variances) and the ratio of the sample variances."""
    from statsmodels.stats.weightstats import ttest_ind

    for _, small, large in recal.SIZE_PAIRS:
        a, b = recal.verification_values(small), recal.verification_values(large)
        d, t, p, f, pf = recal.size_effect(a, b)
        t_sm, p_sm, _ = ttest_ind(b, a, usevar="unequal")
        assert (d, t, p) == pytest.approx((b.mean() - a.mean(), t_sm, p_sm), rel=1e-10)
        assert f == pytest.approx(a.var(ddof=1) / b.var(ddof=1), rel=1e-12) and 0.0 < pf < 1.0
    # the step's point: the 25,000-grain record runs it with the 6,000-grain record's settings
    cols = ["X1_actual", "X2_actual", "X3_actual"]
    small, large = (pd.read_csv(HERE / rel) for rel in recal.SIZE_PAIRS[1][1:])
    assert small[cols].equals(large[cols])


def test_step_slopes_agree_with_statsmodels(recal):
    """Each slope pair steps one factor alone; the slope is the difference of the means over the step and its
    interval statsmodels' Welch interval of that difference over the same step. The composite's slopes are the
    ones the step studies followed: 166.9 deg per J/m^2 in X3 at the scaled optimum
    (wetfeed_verify_standard_scaled_step.toml) and 64.0 deg per unit in X1 at the last X3 step's point
    (wetfeed_verify_large_standard_scaled_friction.toml)."""
    from statsmodels.stats.weightstats import CompareMeans, DescrStatsW

    moved = []
    for _, first, second in recal.SLOPES:
        a, b = recal.verification_values(first), recal.verification_values(second)
        factor, slope, (lo, hi), p, _ = recal.step_slope(first, second)
        xa, xb = recal.settings(first), recal.settings(second)
        # the studies write a chosen point to 4 decimals
        assert [n for n in recal.CCD if abs(xa[n] - xb[n]) > 5e-5] == [factor]
        dx = xb[factor] - xa[factor]
        cm = CompareMeans(DescrStatsW(b), DescrStatsW(a))
        d_lo, d_hi = cm.tconfint_diff(usevar="unequal")
        assert slope == pytest.approx((b.mean() - a.mean()) / dx, rel=1e-12)
        assert (lo, hi) == pytest.approx(tuple(sorted((d_lo / dx, d_hi / dx))), rel=1e-9)
        assert p == pytest.approx(cm.ttest_ind(usevar="unequal")[1], rel=1e-9)
        moved.append(factor)
    assert moved == ["X3", "X3", "X1"]
    optimum = recal.settings(recal.VERIFICATIONS[3][1])
    assert recal.composite_slope(optimum) == pytest.approx(166.9, abs=0.05)
    last = recal.settings(recal.VERIFICATIONS[6][1])
    assert recal.composite_slope(last, "X1") == pytest.approx(64.0, abs=0.05)


def test_composite_slope_is_the_quadratics_derivative(recal):
    """The analytic slope equals a central difference of the composite's own prediction (its actual
    coefficients), in each factor."""
    import pandas as pd

    b = pd.read_csv(HERE / recal.COMPOSITE_FOR_SLOPE / "analysis" / "coefficients_aor_deg.csv").set_index("Term")
    b = b["Actual Coefficient"]

    def angle(x):
        y = b["Intercept"] + sum(b[n] * x[n] + b[f"{n}^2"] * x[n] ** 2 for n in recal.CCD)
        return y + b["X1*X2"] * x["X1"] * x["X2"] + b["X1*X3"] * x["X1"] * x["X3"] + b["X2*X3"] * x["X2"] * x["X3"]

    x = recal.settings(recal.VERIFICATIONS[6][1])
    for n in recal.CCD:
        h = 1e-4
        fd = (angle(x | {n: x[n] + h}) - angle(x | {n: x[n] - h})) / (2 * h)
        assert recal.composite_slope(x, n) == pytest.approx(fd, rel=1e-6), n


def test_pile_heights_belong_to_the_piles_read(recal):
    """Each slope verification's heap heights come one per pile, from the same runs as its angles (a results.csv
    row's run record has that row's angle), and the seed's 25,000 grains stand taller than 6,000."""
    import json

    for rel in {rel for _, *pair in recal.SLOPES for rel in pair}:
        h = recal.pile_heights(rel)
        assert h.shape == recal.verification_values(rel).shape and np.all((h > 0.02) & (h < 0.5))
        if rel.endswith(".csv"):
            t = pd.read_csv(HERE / rel)
            for pid, angle in zip(t.point_id, t.aor_deg):
                kept = json.loads((HERE / rel).parent.joinpath("runs", f"{pid}.json").read_text())
                assert kept["responses"]["aor_deg"] == pytest.approx(angle, rel=1e-12)
    (_, small, _), (_, large, _) = recal.SIZE_PAIRS[1], recal.SLOPES[1]
    assert recal.pile_heights(large).mean() > 1.3 * recal.pile_heights(small).mean()
