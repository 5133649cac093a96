"""docs/seeds/002/screening_laws.py codes the paper's Fig. 14 runs onto the half fraction, its effects are the
least-squares ones (on the full, orthogonal fraction: the difference of the high and low means), it compares the
records on the runs they share, and its kept output is what it prints now."""

from pathlib import Path

import numpy as np
import pytest

from tests.conftest import load_seed_script

HERE = Path(__file__).resolve().parents[2] / "docs" / "seeds" / "002"


@pytest.fixture(scope="module")
def laws():
    return load_seed_script("002/screening_laws.py")


def test_the_paper_runs_are_the_half_fraction_e_abcd(laws):
    ref = laws.paper()
    x = ref[list(laws.FACTORS)].to_numpy()
    assert len(ref) == 16 and np.allclose(np.abs(x), 1.0)
    assert np.allclose(x[:, 4], x[:, :4].prod(axis=1))
    assert len(laws._points(ref)) == 16


def test_effects_on_the_full_fraction_are_differences_of_means(laws):
    ref = laws.paper()
    eff, p, dof = laws.effects(ref)
    assert dof == 10
    for f in laws.FACTORS:
        high, low = ref.y[ref[f] > 0].mean(), ref.y[ref[f] < 0].mean()
        assert eff[f] == pytest.approx(high - low, abs=1e-9), f
    # the seed's ordering of significance (section 5): static friction, then surface energy
    assert max(eff, key=lambda f: abs(eff[f])) == "B" and p["B"] < 0.001 and p["D"] < 0.001


def test_effects_on_a_subset_are_least_squares(laws):
    """On the runs the records share the columns are not orthogonal: the effects are twice numpy's
    least-squares coefficients, and the residual degrees of freedom are the runs less six."""
    common = laws.common_points()
    assert 6 < len(common) <= 16
    for _, folder in laws.SCREENINGS:
        df = laws.restrict(laws.ours(folder, "aor_deg"), common)
        eff, _, dof = laws.effects(df)
        X = np.column_stack([np.ones(len(df)), df[list(laws.FACTORS)].to_numpy()])
        beta = np.linalg.lstsq(X, df.y.to_numpy(), rcond=None)[0]
        assert dof == len(df) - 6
        assert [eff[f] for f in laws.FACTORS] == pytest.approx(list(2.0 * beta[1:]), abs=1e-9)


def test_records_pair_with_the_paper_run_by_run(laws):
    """Every finished run of every record has its coded point in the paper's table, with our design's values."""
    ref = laws.paper()
    for _, folder in laws.SCREENINGS:
        for _, column in laws.RESPONSES:
            df = laws.ours(folder, column)
            a, b = laws.matched(df, ref)
            assert a.size == b.size == len(df) and np.all((a > 0.0) & (a < 90.0))


def test_the_kept_output_is_current(laws):
    assert (HERE / "screening_laws.txt").read_text() == laws.report()
