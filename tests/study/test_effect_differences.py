"""docs/seeds/effect_differences.py: each effect's standard error is the orthogonal design's closed form, the
difference's degrees of freedom are Welch-Satterthwaite's, the Holm correction is statsmodels', every record it
compares has the paper's design points, and its kept output is what it prints now."""

from pathlib import Path

import numpy as np
import pytest

from tests.conftest import load_seed_script

HERE = Path(__file__).resolve().parents[2] / "docs" / "seeds"


@pytest.fixture(scope="module")
def eff():
    return load_seed_script("effect_differences.py")


def test_effect_errors_are_the_orthogonal_designs_closed_form(eff):
    """On a two-level orthogonal design of n runs the coded coefficient's SE is s / sqrt(n), s the residual SD:
    the effect's is twice that, for the papers' tables and ours alike."""
    for _, table, factors, records in eff.SCREENINGS:
        for df in [eff.paper_runs(table, factors)] + [eff.our_runs(folder, factors) for _, folder in records[:1]]:
            x = df[list(factors)].to_numpy()
            X = np.column_stack([np.ones(len(df)), x])
            assert np.allclose(X.T @ X, len(df) * np.eye(X.shape[1]))
            e, se, dof = eff.effects(df, factors)
            beta = np.linalg.solve(X.T @ X, X.T @ df.y.to_numpy())
            resid = df.y.to_numpy() - X @ beta
            s = np.sqrt(resid @ resid / dof)
            assert dof == len(df) - len(factors) - 1
            for j, f in enumerate(factors):
                assert e[f] == pytest.approx(2.0 * beta[j + 1], abs=1e-9)
                assert se[f] == pytest.approx(2.0 * s / np.sqrt(len(df)), rel=1e-9)


def test_welch_degrees_of_freedom_and_holm(eff):
    """The difference's SE is the root of the two effects' squared SEs, its df Welch-Satterthwaite's (two fits with
    equal SEs and df give twice the df, and never fewer than the smaller fit's); the Holm p-values are
    statsmodels'; the paper compared with itself differs in nothing."""
    from statsmodels.stats.multitest import multipletests

    paper = eff.paper_runs("pellets_pb_runs.csv", "ABCDEF")
    rows = eff.differences(paper, paper, "ABCDEF")
    assert all(r["diff"] == 0.0 and r["p"] == pytest.approx(1.0) and not r["beyond"] for r in rows)
    assert all(r["df"] == pytest.approx(2 * 5) for r in rows)
    for label, _, folder, rows in eff.comparisons():
        table, factors = next((t, f) for lab, t, f, _ in eff.SCREENINGS if lab == label)
        _, sp, dfp = eff.effects(eff.paper_runs(table, factors), factors)
        _, so, dfo = eff.effects(eff.our_runs(folder, factors), factors)
        for r in rows:
            f = r["factor"]
            assert r["se"] == pytest.approx(np.hypot(sp[f], so[f]), rel=1e-12)
            assert r["df"] == pytest.approx(r["se"] ** 4 / (sp[f] ** 4 / dfp + so[f] ** 4 / dfo), rel=1e-12)
            assert r["df"] >= min(dfp, dfo) - 1e-9
        ps = [r["p"] for r in rows]
        assert [r["p_holm"] for r in rows] == pytest.approx(list(multipletests(ps, method="holm")[1]), rel=1e-12)


def test_records_hold_the_papers_design_points(eff):
    """Each record compared has the paper's coded points, one run each."""
    for _, table, factors, records in eff.SCREENINGS:
        paper = eff.paper_runs(table, factors)
        pts = {tuple(row) for row in paper[list(factors)].round().astype(int).to_numpy()}
        for _, folder in records:
            ours = eff.our_runs(folder, factors)
            got = [tuple(row) for row in ours[list(factors)].round().astype(int).to_numpy()]
            assert len(set(got)) == len(got) and set(got) <= pts


def test_the_kept_output_is_current(eff):
    assert (HERE / "effect_differences.txt").read_text() == eff.report()
