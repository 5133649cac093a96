"""docs/seeds/001/pile_scatter.py reads every 25,000-grain pile kept in the repository, and its pure error is the
residual of the one-way model (one mean per repeated setting) that statsmodels fits to the same piles; it reads the
Bond-number study's piles too."""

import pytest

from tests.conftest import load_seed_script


@pytest.fixture(scope="module")
def scatter():
    return load_seed_script("001/pile_scatter.py")


def test_every_kept_pile_is_read(scatter):
    df = scatter.piles()
    # 9 composite, 5 old-optimum, 5 verification and 12 diagnosis piles, all inside (or at) the friction box
    assert sorted(df.source.str.split().str[0].value_counts().items()) == [
        ("composite", 9),
        ("diagnosis", 12),
        ("old", 5),
        ("verification", 5),
    ]
    assert df.X1.abs().max() < 1.06 and df.X2.abs().max() < 1.0 + 1e-9
    assert df.y.between(0.0, 90.0).all()
    # the two piles earlier stages found slid off the axis: the composite's run 2 and the old optimum's seed 1
    assert sorted(df[df.flagged].offset_mm.round(1)) == [20.5, 21.1]


def test_pure_error_is_the_one_way_residual(scatter):
    import statsmodels.formula.api as smf

    df = scatter.piles()
    var, dof, groups = scatter.pure_error(df)
    repeated = df.groupby(["X1_actual", "X2_actual"]).y.transform("size") > 1
    sub = df[repeated].assign(point=lambda d: d.X1_actual.astype(str) + "," + d.X2_actual.astype(str))
    fit = smf.ols("y ~ C(point)", sub).fit()
    assert dof == fit.df_resid == len(sub) - len(groups)
    assert var == pytest.approx(fit.scale, rel=1e-12)


def test_the_seed_centre_points(scatter):
    # Table 6 of the seed: runs 15-23 are its nine centre points
    assert len(scatter.seed_centre_points()) == 9
    assert scatter.seed_centre_points().mean() == pytest.approx(54.05, abs=0.005)


def test_the_bond_studies_piles(scatter):
    df = scatter.bond_piles()
    counts = df.groupby(["rolling_model", "gamma"]).size()
    assert sorted(counts.items()) == [
        (("EPSD", 0.1), 4),
        (("EPSD", 0.5), 4),
        (("standard", 0.1), 4),
        (("standard", 0.5), 4),
    ]
    for _, g in df.groupby(["rolling_model", "gamma"]):
        assert list(g.seed) == [0, 1, 2, 3]
    assert df.pile_height_m.between(10.0, 300.0).all()  # read in mm
    text = scatter.bond_report()
    assert text.count("EPSD scatters more than standard") == len(scatter.READINGS) and "nan" not in text
