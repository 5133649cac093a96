"""Classical designs of experiments, in coded units, as pandas DataFrames.

Every generator returns a DataFrame whose index is the standard order (``std_order``, 1-based),
with one column per factor (coded levels) and a ``kind`` column: ``"factorial"`` (a two-level
corner point; Plackett–Burman rows and the +-1 edge points of a Box–Behnken design included),
``"axial"`` (a star point of a central composite design) or ``"center"``. :func:`randomize`
shuffles the rows with an explicit seed and adds a ``run_order`` column.

Factor names default to the Design-Expert/Minitab letters A, B, C, ... (the letter I is skipped,
as both packages do). Coding follows the usual convention x = (X - centre) / half_range, so -1 is
the low and +1 the high level; :class:`Factor` converts both ways and also accepts a reversed
factor (``low > high``), as seed 000's Table 9 prints one.

Conventions, stated once:

* Plackett–Burman: the classical generator row is shifted cyclically, one shift per row, and a row
  of all minus signs is appended (``layout="rows"``). This is the layout of the Design-Expert
  tables in seeds 000 and 001 (seed 000 Table 6 is exactly its first six columns in standard
  order). Minitab instead uses the generator as the *first column* (``layout="columns"``, the
  transpose of the cyclic block). Both are orthogonal arrays.
* Fractional factorials: base factors in Yates order (first factor alternates fastest), generated
  columns from strings such as ``"E=ABCD"`` or ``"F=-ABC"``.
* Box–Behnken (k = 3, 4, 5): every pair of factors runs a 2^2 factorial at +-1 with the other
  factors at 0 (pairs in lexicographic order), then the centre points. For k = 3 this is the
  standard order of seed 000 Table 10 and seed 002 Fig. 18.
* Central composite: factorial block (Yates order), then axial points (-alpha, +alpha for each
  factor in turn), then centre points.
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from warpdem.errors import InputError

__all__ = [
    "FACTOR_LETTERS",
    "PB_GENERATORS",
    "AliasStructure",
    "Factor",
    "alias_structure",
    "box_behnken",
    "ccd_alpha",
    "central_composite",
    "design_counts",
    "factor_names",
    "fractional_factorial",
    "full_factorial",
    "plackett_burman",
    "randomize",
    "steepest_path",
    "to_actual",
    "to_coded",
]

#: Factor letters in Design-Expert/Minitab order (no I).
FACTOR_LETTERS = "ABCDEFGHJKLMNOPQRSTUVWXYZ"

#: Classical Plackett & Burman (1946) generator rows, keyed by number of runs.
PB_GENERATORS: dict[int, str] = {
    8: "+++-+--",
    12: "++-+++---+-",
    20: "++--++++-+-+----++-",
    24: "+++++-+-++--++--+-+----",
}


# --------------------------------------------------------------------------------------------
# Factors and coding
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Factor:
    """One numeric factor and its coding, x = (X - centre) / half_range.

    ``low`` is the actual value at coded -1 and ``high`` the value at coded +1. ``low > high`` is
    allowed (a reversed coding, as in seed 000 Table 9 where -1 is the high value).
    """

    name: str
    low: float
    high: float
    unit: str = ""

    def __post_init__(self):
        if not (math.isfinite(self.low) and math.isfinite(self.high)) or self.low == self.high:
            raise InputError(
                f"Factor {self.name!r}: low and high must be finite and different, got {self.low!r}, {self.high!r}"
            )

    @classmethod
    def from_centre_step(cls, name: str, centre: float, step: float, unit: str = "") -> Factor:
        """Factor whose coded 0 is ``centre`` and coded +1 is ``centre + step``."""
        return cls(name, centre - step, centre + step, unit)

    @property
    def centre(self) -> float:
        return 0.5 * (self.low + self.high)

    @property
    def half_range(self) -> float:
        """Actual change per coded unit (negative for a reversed factor)."""
        return 0.5 * (self.high - self.low)

    def to_coded(self, actual):
        return (np.asarray(actual, dtype=float) - self.centre) / self.half_range

    def to_actual(self, coded):
        return self.centre + np.asarray(coded, dtype=float) * self.half_range


def _factor_map(factors: Iterable[Factor] | Mapping[str, Factor]) -> dict[str, Factor]:
    if isinstance(factors, Mapping):
        return dict(factors)
    return {f.name: f for f in factors}


def _convert(df: pd.DataFrame, factors, convert) -> pd.DataFrame:
    """Copy of ``df`` with every column named by a factor converted by ``convert(factor, values)``."""
    out = df.copy()
    for name, f in _factor_map(factors).items():
        if name in out.columns:
            out[name] = convert(f, out[name].to_numpy(dtype=float))
    return out


def to_coded(df: pd.DataFrame, factors: Iterable[Factor] | Mapping[str, Factor]) -> pd.DataFrame:
    """Copy of ``df`` with every column named by a factor converted from actual to coded units."""
    return _convert(df, factors, Factor.to_coded)


def to_actual(df: pd.DataFrame, factors: Iterable[Factor] | Mapping[str, Factor]) -> pd.DataFrame:
    """Copy of ``df`` with every column named by a factor converted from coded to actual units."""
    return _convert(df, factors, Factor.to_actual)


def factor_names(k: int) -> list[str]:
    """The first ``k`` Design-Expert letters (A, B, ..., H, J, ...)."""
    if not 1 <= k <= len(FACTOR_LETTERS):
        raise InputError(f"number of factors must be in 1..{len(FACTOR_LETTERS)}, got {k}")
    return list(FACTOR_LETTERS[:k])


def _names(factors: int | Sequence[str]) -> list[str]:
    if isinstance(factors, (int, np.integer)):
        return factor_names(int(factors))
    names = [str(n) for n in factors]
    if len(set(names)) != len(names) or not names:
        raise InputError(f"factor names must be unique and non-empty, got {names}")
    if "kind" in names or "run_order" in names:
        raise InputError("'kind' and 'run_order' are reserved column names")
    return names


def _frame(points: np.ndarray, names: list[str], kinds: list[str]) -> pd.DataFrame:
    df = pd.DataFrame(np.asarray(points, dtype=float), columns=names)
    df["kind"] = kinds
    df.index = pd.RangeIndex(1, len(df) + 1, name="std_order")
    return df


def _centre_block(n: int, k: int) -> np.ndarray:
    if n < 0:
        raise InputError(f"number of centre points must be >= 0, got {n}")
    return np.zeros((n, k))


def design_counts(design: pd.DataFrame) -> dict[str, int]:
    """Number of factorial, axial and centre runs in a design (plus the total)."""
    counts = design["kind"].value_counts().to_dict()
    out = {kind: int(counts.get(kind, 0)) for kind in ("factorial", "axial", "center")}
    out["total"] = int(len(design))
    return out


# --------------------------------------------------------------------------------------------
# Two-level designs
# --------------------------------------------------------------------------------------------


def _yates(k: int) -> np.ndarray:
    """2^k full factorial in Yates (standard) order, first column alternating fastest."""
    n = 2**k
    idx = np.arange(n)[:, None]
    return np.where((idx >> np.arange(k)[None, :]) & 1, 1.0, -1.0)


def full_factorial(factors: int | Sequence[str], center_points: int = 0, replicates: int = 1) -> pd.DataFrame:
    """Two-level full factorial 2^k in standard order, replicated, plus centre points."""
    names = _names(factors)
    if replicates < 1:
        raise InputError(f"replicates must be >= 1, got {replicates}")
    pts = np.vstack([_yates(len(names))] * replicates)
    kinds = ["factorial"] * len(pts)
    pts = np.vstack([pts, _centre_block(center_points, len(names))])
    kinds += ["center"] * center_points
    return _frame(pts, names, kinds)


_GEN_RE = re.compile(r"^\s*([A-Za-z]\w*)\s*=\s*([+-]?)\s*(.+?)\s*$")


def _parse_generator(gen: str, names: list[str]) -> tuple[str, int, list[str]]:
    """'E=ABCD' -> ('E', +1, ['A','B','C','D']); names may be multi-character if joined by '*'."""
    m = _GEN_RE.match(gen)
    if not m:
        raise InputError(f"cannot parse generator {gen!r}; expected e.g. 'E=ABCD' or 'F=-ABC'")
    target, sign, word = m.group(1), m.group(2), m.group(3)
    if "*" in word or ":" in word:
        letters = [w.strip() for w in re.split(r"[*:]", word) if w.strip()]
    else:
        letters = list(word.replace(" ", ""))
    unknown = [x for x in letters + [target] if x not in names]
    if unknown:
        raise InputError(f"generator {gen!r} names unknown factors {unknown}; factors are {names}")
    if len(set(letters)) != len(letters):
        raise InputError(f"generator {gen!r} repeats a factor")
    return target, (-1 if sign == "-" else 1), letters


def fractional_factorial(
    factors: int | Sequence[str], generators: str | Sequence[str], center_points: int = 0
) -> pd.DataFrame:
    """Two-level fractional factorial 2^(k-p) from generator strings.

    ``generators`` is a list such as ``["E=ABCD"]`` (or one string, comma/space separated). The
    generated factors are computed from the base factors, which run a full 2^(k-p) factorial in
    Yates order.
    """
    names = _names(factors)
    gens = _split_generators(generators)
    parsed = [_parse_generator(g, names) for g in gens]
    generated = [t for t, _, _ in parsed]
    if len(set(generated)) != len(generated):
        raise InputError(f"a factor is generated twice in {gens}")
    base = [n for n in names if n not in generated]
    for t, _, word in parsed:
        bad = [w for w in word if w not in base]
        if bad:
            raise InputError(f"generator for {t} uses generated factor(s) {bad}; use base factors only")
    cols = dict(zip(base, _yates(len(base)).T))
    for t, s, word in parsed:
        cols[t] = s * np.prod([cols[w] for w in word], axis=0)
    pts = np.column_stack([cols[n] for n in names])
    kinds = ["factorial"] * len(pts)
    pts = np.vstack([pts, _centre_block(center_points, len(names))])
    kinds += ["center"] * center_points
    return _frame(pts, names, kinds)


def _split_generators(generators: str | Sequence[str]) -> list[str]:
    if isinstance(generators, str):
        return [g for g in re.split(r"[,;]\s*|\s+(?=[A-Za-z]\w*\s*=)", generators.strip()) if g]
    return list(generators)


@dataclass
class AliasStructure:
    """Defining relation, resolution and alias chains of a regular two-level fraction.

    Words are written as strings of factor names joined by ``"*"`` when names are longer than one
    character, else concatenated ("ABCDE"); a leading ``-`` marks a negative word.
    """

    factors: list[str]
    generators: list[str]
    defining_relation: list[str]
    resolution: int | None
    aliases: dict[str, list[str]] = field(default_factory=dict)

    @property
    def resolution_roman(self) -> str:
        if self.resolution is None:
            return "full"
        return (
            ["", "I", "II", "III", "IV", "V", "VI", "VII", "VIII", "IX", "X"][self.resolution]
            if self.resolution <= 10
            else str(self.resolution)
        )


def _word(letters: Iterable[str], names: list[str], sign: int = 1) -> str:
    letters = sorted(letters, key=names.index)
    sep = "" if all(len(n) == 1 for n in names) else "*"
    return ("-" if sign < 0 else "") + sep.join(letters)


def alias_structure(
    factors: int | Sequence[str], generators: str | Sequence[str], max_order: int = 2
) -> AliasStructure:
    """Resolution and alias structure of the 2^(k-p) fraction defined by ``generators``.

    The defining relation is the group generated by the words I = t*word for each generator;
    the resolution is the length of its shortest word. ``aliases`` maps every effect of order
    <= ``max_order`` to the effects it is aliased with (of any order), without sign.
    """
    names = _names(factors)
    parsed = [_parse_generator(g, names) for g in _split_generators(generators)]
    base_words = [(frozenset([t, *w]), s) for t, s, w in parsed]
    group: dict[frozenset, int] = {}
    for r in range(1, len(base_words) + 1):
        for combo in itertools.combinations(base_words, r):
            word: frozenset = frozenset()
            sign = 1
            for w, s in combo:
                word = word.symmetric_difference(w)
                sign *= s
            group[word] = sign
    words = sorted(group.items(), key=lambda ws: (len(ws[0]), [names.index(x) for x in sorted(ws[0], key=names.index)]))
    defining = [_word(w, names, s) for w, s in words]
    resolution = min((len(w) for w in group), default=None)
    aliases: dict[str, list[str]] = {}
    for order in range(1, max_order + 1):
        for eff in itertools.combinations(names, order):
            e = frozenset(eff)
            chain = sorted(
                (e.symmetric_difference(w) for w in group),
                key=lambda a: (len(a), [names.index(x) for x in sorted(a, key=names.index)]),
            )
            aliases[_word(eff, names)] = [_word(a, names) for a in chain if a]
    return AliasStructure(names, [g for g in _split_generators(generators)], defining, resolution, aliases)


def plackett_burman(
    factors: int | Sequence[str], n_runs: int | None = None, layout: str = "rows", center_points: int = 0
) -> pd.DataFrame:
    """Plackett–Burman screening design from the classical cyclic generators.

    ``n_runs`` is 8, 12, 20 or 24 (default: the smallest of 12, 20, 24 that holds ``k`` factors,
    k <= n_runs - 1, as in Minitab, whose Plackett–Burman list starts at 12 runs).
    ``layout="rows"`` (default) writes the generator as the first row and shifts it right by one
    per row (Design-Expert; seeds 000 and 001); ``layout="columns"`` writes it as the first column
    (Minitab). The first ``k`` columns are kept; the last run is all minus.
    """
    names = _names(factors)
    k = len(names)
    if n_runs is None:
        n_runs = min((n for n in PB_GENERATORS if n >= 12 and n - 1 >= k), default=0)
        if not n_runs:
            raise InputError(f"at most 23 factors are supported, got {k}")
    if n_runs not in PB_GENERATORS:
        raise InputError(f"n_runs must be one of {sorted(PB_GENERATORS)}, got {n_runs}")
    if k > n_runs - 1:
        raise InputError(f"a {n_runs}-run Plackett–Burman design holds at most {n_runs - 1} factors, got {k}")
    g = np.array([1.0 if c == "+" else -1.0 for c in PB_GENERATORS[n_runs]])
    m = n_runs - 1
    i = np.arange(m)[:, None]
    j = np.arange(m)[None, :]
    if layout == "rows":
        block = g[(j - i) % m]
    elif layout == "columns":
        block = g[(i - j) % m]
    else:
        raise InputError(f"layout must be 'rows' (Design-Expert) or 'columns' (Minitab), got {layout!r}")
    pts = np.vstack([block, -np.ones((1, m))])[:, :k]
    kinds = ["factorial"] * n_runs
    pts = np.vstack([pts, _centre_block(center_points, k)])
    kinds += ["center"] * center_points
    return _frame(pts, names, kinds)


# --------------------------------------------------------------------------------------------
# Response-surface designs
# --------------------------------------------------------------------------------------------

_BBD_DEFAULT_CENTRE = {3: 5, 4: 5, 5: 6}  # Design-Expert defaults (Minitab: 3, 3, 6)


def box_behnken(factors: int | Sequence[str], center_points: int | None = None) -> pd.DataFrame:
    """Box–Behnken design for k = 3, 4 or 5 factors.

    Each pair of factors runs a 2^2 factorial (Yates order) with the others at 0; then
    ``center_points`` centre runs (default: Design-Expert's 5, 5, 6 for k = 3, 4, 5).
    The edge midpoints are the two-level (+-1) part of the design and get ``kind="factorial"``
    (Minitab calls them edge points, PtType 2); there are no axial points.
    """
    names = _names(factors)
    k = len(names)
    if k not in (3, 4, 5):
        raise InputError(f"Box–Behnken designs are provided for 3 to 5 factors, got {k}")
    if center_points is None:
        center_points = _BBD_DEFAULT_CENTRE[k]
    rows = []
    for a, b in itertools.combinations(range(k), 2):
        for xb, xa in itertools.product((-1.0, 1.0), repeat=2):
            r = np.zeros(k)
            r[a], r[b] = xa, xb
            rows.append(r)
    pts = np.vstack([np.array(rows), _centre_block(center_points, k)])
    kinds = ["factorial"] * len(rows) + ["center"] * center_points
    return _frame(pts, names, kinds)


def ccd_alpha(alpha: str | float, n_factorial: int, n_runs: int | None = None) -> float:
    """Axial distance of a central composite design.

    * ``"rotatable"``: alpha = n_factorial ** (1/4);
    * ``"orthogonal"``: the pure quadratic columns are orthogonal after centring,
      alpha = sqrt((sqrt(n_factorial * n_runs) - n_factorial) / 2), n_runs = total runs of the
      unblocked design (Box & Hunter 1957; Myers & Montgomery);
    * ``"face"``: alpha = 1;
    * a number: used as given.
    """
    if isinstance(alpha, str):
        a = alpha.lower()
        if a in ("rotatable", "rotational"):
            return float(n_factorial) ** 0.25
        if a in ("face", "faced", "face-centred", "face-centered"):
            return 1.0
        if a == "orthogonal":
            if n_runs is None:
                raise InputError("orthogonal alpha needs the total number of runs")
            val = (math.sqrt(n_factorial * n_runs) - n_factorial) / 2.0
            if val <= 0:
                raise InputError("orthogonal alpha undefined for this design")
            return math.sqrt(val)
        raise InputError(f"alpha must be 'rotatable', 'orthogonal', 'face' or a number, got {alpha!r}")
    a = float(alpha)
    if not (math.isfinite(a) and a > 0):
        raise InputError(f"alpha must be > 0, got {alpha!r}")
    return a


def central_composite(
    factors: int | Sequence[str],
    alpha: str | float = "rotatable",
    center_points: int | tuple[int, int] = 6,
    generators: str | Sequence[str] | None = None,
) -> pd.DataFrame:
    """Central composite design: 2^k (or 2^(k-p) with ``generators``) + 2k axial + centre points.

    ``center_points`` is the total number of centre runs, or a pair (runs with the factorial
    block, runs with the axial block) that are simply added here (no blocking column).
    Seed 001's design is ``central_composite(3, alpha=2, center_points=9)`` (8 + 6 + 9 = 23 runs).
    The chosen alpha is stored in ``df.attrs["alpha"]``.
    """
    names = _names(factors)
    k = len(names)
    if k < 2:
        raise InputError("a central composite design needs at least 2 factors")
    if generators:
        fact = fractional_factorial(names, generators)[names].to_numpy()
    else:
        fact = _yates(k)
    nc = sum(center_points) if isinstance(center_points, tuple) else int(center_points)
    nf = len(fact)
    a = ccd_alpha(alpha, nf, nf + 2 * k + nc)
    axial = np.zeros((2 * k, k))
    for i in range(k):
        axial[2 * i, i] = -a
        axial[2 * i + 1, i] = a
    pts = np.vstack([fact, axial, _centre_block(nc, k)])
    kinds = ["factorial"] * nf + ["axial"] * (2 * k) + ["center"] * nc
    df = _frame(pts, names, kinds)
    df.attrs["alpha"] = a
    return df


# --------------------------------------------------------------------------------------------
# Run order and the path of steepest ascent
# --------------------------------------------------------------------------------------------


def randomize(design: pd.DataFrame, seed: int) -> pd.DataFrame:
    """Rows of ``design`` in a random run order drawn with ``numpy.random.default_rng(seed)``.

    The index (standard order) is kept; a ``run_order`` column 1..n is added.
    """
    if seed is None:
        raise InputError("randomize needs an explicit seed (reproducible run order)")
    rng = np.random.default_rng(seed)
    out = design.iloc[rng.permutation(len(design))].copy()
    out["run_order"] = np.arange(1, len(out) + 1)
    return out


def steepest_path(
    coefficients: Mapping[str, float],
    base: str,
    base_step: float,
    n_steps: int = 5,
    levels: Iterable[Factor] | Mapping[str, Factor] | None = None,
    start: Mapping[str, float] | None = None,
    step_units: str = "coded",
    descent: bool = False,
) -> pd.DataFrame:
    """Path of steepest ascent (or descent) from a first-order model in coded units.

    The coded step of factor j is ``dx_j = dx_base * b_j / b_base`` with
    ``|dx_base| = base_step`` (converted from actual units when ``step_units="actual"``) and the
    sign that increases (ascent) or decreases (descent) the response. Rows 0..n_steps are
    ``start + i * dx``; ``start`` defaults to the design centre (coded 0) and is given in the
    same units as ``step_units``. With ``levels`` the actual values are added as ``<name>_actual``.
    """
    names = list(coefficients)
    if base not in coefficients:
        raise InputError(f"base factor {base!r} is not among the coefficients {names}")
    b = np.array([float(coefficients[n]) for n in names])
    bb = float(coefficients[base])
    if bb == 0:
        raise InputError("the base factor's coefficient is zero: no direction")
    fmap = _factor_map(levels) if levels is not None else {}
    if step_units not in ("coded", "actual"):
        raise InputError("step_units must be 'coded' or 'actual'")
    step = float(base_step)
    if step_units == "actual":
        if base not in fmap:
            raise InputError("an actual step needs the base factor's levels")
        step = step / abs(fmap[base].half_range)
    sgn = -1.0 if descent else 1.0
    dx = sgn * abs(step) * b / abs(bb)
    if start is None:
        x0 = np.zeros(len(names))
    elif step_units == "actual":
        x0 = np.array([fmap[n].to_coded(start[n]) for n in names], dtype=float)
    else:
        x0 = np.array([float(start[n]) for n in names])
    steps = np.arange(n_steps + 1)[:, None]
    pts = x0[None, :] + steps * dx[None, :]
    df = pd.DataFrame(pts, columns=names)
    df.index = pd.RangeIndex(0, n_steps + 1, name="step")
    for n in names:
        if n in fmap:
            df[f"{n}_actual"] = fmap[n].to_actual(df[n].to_numpy())
    df.attrs["coded_step"] = dict(zip(names, dx))
    if fmap:
        df.attrs["actual_step"] = {n: d * fmap[n].half_range for n, d in zip(names, dx) if n in fmap}
    return df
