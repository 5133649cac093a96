"""Properties of the classical designs in warpdem.study.designs."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from warpdem.study import designs as ds

REF = Path(__file__).resolve().parents[2] / "studies" / "reference"


def _matrix(df: pd.DataFrame) -> np.ndarray:
    return df.drop(columns=["kind"]).to_numpy()


@pytest.mark.parametrize("n", [12, 20])
@pytest.mark.parametrize("layout", ["rows", "columns"])
def test_plackett_burman_orthogonal_and_balanced(n, layout):
    """PB12/PB20, both layouts: X'X = N I (orthogonal columns) and every column has N/2 plus
    and N/2 minus signs (balance); the last run is all minus."""
    d = ds.plackett_burman(n - 1, n, layout=layout)
    X = _matrix(d)
    assert X.shape == (n, n - 1)
    np.testing.assert_array_equal(X.T @ X, n * np.eye(n - 1))
    np.testing.assert_array_equal(X.sum(axis=0), np.zeros(n - 1))
    assert (X[-1] == -1).all()
    assert set(d["kind"]) == {"factorial"}


@pytest.mark.parametrize("n, gen", [(12, "++-+++---+-"), (20, "++--++++-+-+----++-")])
def test_plackett_burman_generator_rows(n, gen):
    """The first run is the classical generator and each run is the previous one shifted right
    by one (Design-Expert layout); Minitab's layout is the transpose of the cyclic block."""
    g = np.array([1.0 if c == "+" else -1.0 for c in gen])
    rows = _matrix(ds.plackett_burman(n - 1, n, layout="rows"))
    cols = _matrix(ds.plackett_burman(n - 1, n, layout="columns"))
    np.testing.assert_array_equal(rows[0], g)
    for i in range(1, n - 1):
        np.testing.assert_array_equal(rows[i], np.roll(rows[i - 1], 1))
    np.testing.assert_array_equal(cols[:-1], rows[:-1].T)
    np.testing.assert_array_equal(cols[:, 0][:-1], g)


def test_plackett_burman_matches_seed_tables():
    """Seed 000 Table 6 is the first six columns of PB12 in standard order; seed 001 Table 3
    holds the same 12 rows (seven columns) in a randomised order."""
    p = pd.read_csv(REF / "pellets_pb_runs.csv")
    np.testing.assert_array_equal(_matrix(ds.plackett_burman(6)), p[list("ABCDEF")].to_numpy())
    w = pd.read_csv(REF / "wetfeed_pb_runs.csv")
    ours = sorted(map(tuple, _matrix(ds.plackett_burman(7))))
    assert ours == sorted(map(tuple, w[list("ABCDEFG")].to_numpy().astype(float)))


def test_plackett_burman_run_count_and_errors():
    """Default run count is the smallest of 12/20/24 that holds k; too many factors is refused."""
    assert len(ds.plackett_burman(6)) == 12
    assert len(ds.plackett_burman(11)) == 12
    assert len(ds.plackett_burman(12)) == 20
    assert len(ds.plackett_burman(5, center_points=3)) == 15
    with pytest.raises(ValueError):
        ds.plackett_burman(12, 12)
    with pytest.raises(ValueError):
        ds.plackett_burman(3, 16)


def test_full_factorial_yates_order():
    """2^3: 8 runs in Yates order (A alternates fastest), orthogonal, plus centre points."""
    d = ds.full_factorial(3, center_points=2)
    assert ds.design_counts(d) == {"factorial": 8, "axial": 0, "center": 2, "total": 10}
    X = _matrix(d)[:8]
    np.testing.assert_array_equal(X[:, 0], [-1, 1] * 4)
    np.testing.assert_array_equal(X[:, 2], [-1] * 4 + [1] * 4)
    np.testing.assert_array_equal(X.T @ X, 8 * np.eye(3))
    assert len(ds.full_factorial(["x", "y"], replicates=3)) == 12


def test_fractional_factorial_resolution_v():
    """2^(5-1) with E=ABCD: I = ABCDE, resolution V, A = BCDE, AB = CDE; main effects and all
    two-factor interaction columns are mutually orthogonal; the table equals seed 002 Fig. 14."""
    d = ds.fractional_factorial(5, ["E=ABCD"])
    X = _matrix(d)
    assert X.shape == (16, 5)
    np.testing.assert_array_equal(X[:, 4], X[:, :4].prod(axis=1))
    cols = [X[:, i] for i in range(5)] + [X[:, i] * X[:, j] for i, j in itertools.combinations(range(5), 2)]
    M = np.column_stack(cols)
    np.testing.assert_array_equal(M.T @ M, 16 * np.eye(15))
    al = ds.alias_structure(5, "E=ABCD")
    assert al.resolution == 5 and al.resolution_roman == "V"
    assert al.defining_relation == ["ABCDE"]
    assert al.aliases["A"] == ["BCDE"]
    assert al.aliases["AB"] == ["CDE"]
    f = pd.read_csv(REF / "phosphate_ffd_runs.csv")
    coded = np.column_stack([np.where(f[c] == f[c].max(), 1.0, -1.0) for c in f.columns[1:6]])
    np.testing.assert_array_equal(coded, X)


def test_fractional_factorial_other_resolutions():
    """Textbook fractions: the saturated 2^(7-4) (D=AB, E=AC, F=BC, G=ABC) is resolution III
    with 15 words in its defining relation; 2^(6-2) with E=ABC, F=BCD is resolution IV
    (I = ABCE = BCDF = ADEF); a negative generator flips the column and the word's sign."""
    al3 = ds.alias_structure(7, ["D=AB", "E=AC", "F=BC", "G=ABC"])
    assert al3.resolution == 3 and len(al3.defining_relation) == 15
    assert len(ds.fractional_factorial(7, ["D=AB", "E=AC", "F=BC", "G=ABC"])) == 8
    al4 = ds.alias_structure(6, ["E=ABC", "F=BCD"])
    assert al4.resolution == 4
    assert sorted(al4.defining_relation) == sorted(["ABCE", "BCDF", "ADEF"])
    d = ds.fractional_factorial(4, "D=-ABC")
    X = _matrix(d)
    np.testing.assert_array_equal(X[:, 3], -X[:, :3].prod(axis=1))
    assert ds.alias_structure(4, "D=-ABC").defining_relation == ["-ABCD"]


def test_fractional_factorial_bad_generators():
    """Generators naming unknown or generated factors are refused with a clear error."""
    with pytest.raises(ValueError):
        ds.fractional_factorial(5, ["E=ABCX"])
    with pytest.raises(ValueError):
        ds.fractional_factorial(6, ["E=ABCD", "F=ABE"])


@pytest.mark.parametrize("k, edges, centre", [(3, 12, 5), (4, 24, 5), (5, 40, 6)])
def test_box_behnken_counts_and_structure(k, edges, centre):
    """BBD point counts (12/24/40 edge runs + Design-Expert default centre runs); every edge
    run has exactly two factors at +-1; columns are balanced and orthogonal."""
    d = ds.box_behnken(k)
    c = ds.design_counts(d)
    assert c["factorial"] == edges and c["center"] == centre and c["axial"] == 0
    X = _matrix(d)
    edge = X[d["kind"].to_numpy() == "factorial"]
    assert ((edge != 0).sum(axis=1) == 2).all()
    np.testing.assert_array_equal(X.sum(axis=0), np.zeros(k))
    G = X.T @ X
    np.testing.assert_array_equal(G - np.diag(np.diag(G)), np.zeros((k, k)))
    assert len(ds.box_behnken(k, center_points=3)) == edges + 3


def test_box_behnken_matches_seed_standard_order():
    """Seed 000 Table 10 (5 centre runs) and seed 002 Fig. 18 (3 centre runs) are the
    3-factor BBD in standard order."""
    p = pd.read_csv(REF / "pellets_bbd_runs.csv")
    np.testing.assert_array_equal(_matrix(ds.box_behnken(["C", "D", "E"], 5)), p[["C", "D", "E"]].to_numpy())
    q = pd.read_csv(REF / "phosphate_bbd_runs.csv")
    np.testing.assert_array_equal(_matrix(ds.box_behnken(3, 3)), q.iloc[:, 1:4].to_numpy())
    with pytest.raises(ValueError):
        ds.box_behnken(2)


@pytest.mark.parametrize("k", [2, 3, 4, 5])
def test_ccd_rotatable_alpha_and_counts(k):
    """Rotatable CCD: alpha = (2^k)^(1/4); 2^k factorial + 2k axial + centre runs; the
    prediction variance of the full quadratic is the same at every point of a sphere."""
    d = ds.central_composite(k, "rotatable", center_points=5)
    alpha = (2**k) ** 0.25
    assert d.attrs["alpha"] == pytest.approx(alpha)
    assert ds.design_counts(d) == {"factorial": 2**k, "axial": 2 * k, "center": 5, "total": 2**k + 2 * k + 5}
    X = _matrix(d)
    assert np.abs(X).max() == pytest.approx(alpha)

    def model(x):
        x = np.atleast_2d(x)
        cols = [np.ones(len(x))] + [x[:, i] for i in range(k)]
        cols += [x[:, i] * x[:, j] for i, j in itertools.combinations(range(k), 2)]
        cols += [x[:, i] ** 2 for i in range(k)]
        return np.column_stack(cols)

    inv = np.linalg.inv(model(X).T @ model(X))
    rng = np.random.default_rng(1)
    u = rng.normal(size=(20, k))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.einsum("ij,jk,ik->i", model(0.8 * u), inv, model(0.8 * u))
    assert v.max() - v.min() < 1e-10 * v.max()


def test_ccd_alpha_options_and_seed_001():
    """alpha 'face' = 1, a number is used as given (seed 001: alpha 2, 8 + 6 + 9 = 23 runs),
    'orthogonal' makes the centred pure-quadratic columns orthogonal."""
    assert ds.ccd_alpha("face", 8) == 1.0
    d = ds.central_composite(["X1", "X2", "X3"], alpha=2, center_points=9)
    assert ds.design_counts(d) == {"factorial": 8, "axial": 6, "center": 9, "total": 23}
    w = pd.read_csv(REF / "wetfeed_ccd_runs.csv")
    assert sorted(map(tuple, _matrix(d))) == sorted(map(tuple, w[["X1", "X2", "X3"]].to_numpy().astype(float)))
    o = ds.central_composite(3, "orthogonal", center_points=9)
    assert o.attrs["alpha"] == pytest.approx(1.668, abs=1e-3)
    Q = _matrix(o) ** 2
    Q = Q - Q.mean(axis=0)
    G = Q.T @ Q
    assert np.abs(G - np.diag(np.diag(G))).max() < 1e-9
    assert ds.ccd_alpha("rotatable", 8) == pytest.approx(1.6818, abs=1e-4)
    with pytest.raises(ValueError):
        ds.ccd_alpha("spherical-ish", 8)


def test_randomize_is_seeded_permutation():
    """The same seed gives the same run order, a different seed another; rows are a
    permutation of the standard order; an explicit seed is required."""
    d = ds.box_behnken(3)
    a, b, c = ds.randomize(d, 7), ds.randomize(d, 7), ds.randomize(d, 8)
    assert list(a.index) == list(b.index)
    assert list(a.index) != list(c.index)
    assert sorted(a.index) == list(d.index)
    assert list(a["run_order"]) == list(range(1, len(d) + 1))
    pd.testing.assert_frame_equal(a.drop(columns="run_order").sort_index(), d)
    with pytest.raises(ValueError):
        ds.randomize(d, None)


def test_coded_actual_round_trip():
    """Coded <-> actual from (low, high) and from (centre, step), reversed coding included
    (seed 000 Table 9: -1 is 0.49, +1 is 0.41)."""
    f = ds.Factor("C", 0.39, 0.49)
    assert f.centre == pytest.approx(0.44) and f.half_range == pytest.approx(0.05)
    assert f.to_coded(0.49) == pytest.approx(1.0)
    g = ds.Factor.from_centre_step("X1", 0.3, 0.1)
    assert g.to_actual(-2) == pytest.approx(0.1) and g.to_actual(2) == pytest.approx(0.5)
    r = ds.Factor("C", 0.49, 0.41)
    assert r.to_coded(0.49) == pytest.approx(-1.0) and r.to_actual(1) == pytest.approx(0.41)
    df = pd.DataFrame({"C": [0.39, 0.44, 0.49], "y": [1, 2, 3]})
    back = ds.to_actual(ds.to_coded(df, [f]), [f])
    pd.testing.assert_frame_equal(back, df.astype({"C": float}))
    np.testing.assert_allclose(ds.to_coded(df, [f])["C"], [-1, 0, 1])
    with pytest.raises(ValueError):
        ds.Factor("z", 1.0, 1.0)
    assert ds.factor_names(9)[-1] == "J"


def test_steepest_path_direction():
    """Steps are proportional to the coefficients (Box-Wilson), the base factor moves by the
    given step, descent reverses the direction, actual units follow from the levels."""
    b = {"C": 1.3275, "D": 3.3175, "E": 1.7925}
    p = ds.steepest_path(b, "D", 0.4, n_steps=5)
    step = p.diff().iloc[1].to_numpy()
    np.testing.assert_allclose(step / np.array(list(b.values())), 0.4 / 3.3175)
    assert p.loc[0].abs().sum() == 0
    q = ds.steepest_path(b, "D", 0.4, n_steps=2, descent=True)
    np.testing.assert_allclose(q.to_numpy(), -p.iloc[:3].to_numpy())
    lv = [ds.Factor("C", 0.39, 0.49), ds.Factor("D", 0.45, 0.75), ds.Factor("E", 0.02, 0.08)]
    a = ds.steepest_path(b, "D", 0.06, 5, levels=lv, start={"C": 0.39, "D": 0.45, "E": 0.02}, step_units="actual")
    np.testing.assert_allclose(a["D_actual"], [0.45, 0.51, 0.57, 0.63, 0.69, 0.75])
    assert a.attrs["actual_step"]["C"] == pytest.approx(0.4 * 1.3275 / 3.3175 * 0.05)
    with pytest.raises(ValueError):
        ds.steepest_path(b, "Q", 0.4)
