"""Particle factories, host side: size distributions, regions, static fills and dynamic release schedules.

Everything here is NumPy/SciPy on the host; the engine calls it while building a model (static fill) or
between frames (dynamic factory) and uploads the result.

* Size distributions (:class:`FixedSize`, :class:`TruncatedNormal`, :class:`LogNormal`, :class:`SieveTable`)
  draw particle radii [m]. For a clump the drawn size means "scale factor times the template's
  volume-equivalent radius": ``sample`` returns that size and the caller decides how to apply it; the fill
  functions take ``bounding_ratio`` (template bounding radius / equivalent radius) to keep clumps apart.
* Regions (:class:`Box`, :class:`Cylinder`, :class:`Cone`) answer ``contains``, ``sample_uniform``,
  ``volume`` and ``inset``; a sphere of radius r centred in ``region.inset(r)`` lies inside the region.
* :func:`fill_region` places non-overlapping spheres by random sequential addition (RSA).
* :class:`DynamicFactory` pre-draws every size once (deterministic for its seed, so the engine can
  preallocate exactly ``capacity()`` particles), plans release batches and places each batch.
"""

from __future__ import annotations

import csv
import enum
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from warpdem.errors import InputError

from .checks import check, check_number, enum_value, float_array, integer, positive, vec3

RSA_SATURATION = 0.38
"""Jamming volume fraction of random sequential addition of equal spheres in bulk [-] (0.3841,
Zhang & Torquato 2013); walls and a finite number of attempts lower what a fill reaches."""

_FRACTION_TOL = 1e-6


# --------------------------------------------------------------------------------------------------------------
# Small helpers


def _rng(rng) -> np.random.Generator:
    """A Generator from a Generator (returned as is) or an integer seed."""
    return np.random.default_rng(rng)


def _count(where: str, name: str, value) -> int:
    return integer(where, name, value, 0)


def _points(points) -> np.ndarray:
    p = np.asarray(points, dtype=float)
    if p.ndim == 1 and p.shape[0] == 3:
        p = p[None, :]
    if p.ndim != 2 or p.shape[1] != 3:
        raise InputError(f"points: shape {p.shape} is not allowed; expected (n, 3)")
    return p


def _margins(where: str, margin, n: int) -> np.ndarray:
    m = np.asarray(margin, dtype=float)
    check(bool(np.all(np.isfinite(m))) and bool(np.all(m >= 0.0)), where, "margin", margin, "finite values >= 0 [m]")
    return np.broadcast_to(m, (n,))


def _norm_interval(a, b):
    """P(a < Z < b) for a standard normal Z, accurate in either tail."""
    from scipy import special

    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return np.where(a > 0.0, special.ndtr(-a) - special.ndtr(-b), special.ndtr(b) - special.ndtr(a))


def sphere_volume(radius):
    """Volume 4/3 pi r^3 [m^3] of spheres of ``radius`` [m] (any shape)."""
    return (4.0 / 3.0) * math.pi * np.asarray(radius, dtype=float) ** 3


def random_quaternions(rng, n: int) -> np.ndarray:
    """Rotations uniform on SO(3) (Shoemake 1992), shape (n, 4), components (x, y, z, w) as ``wp.quat``.

    ``rng`` is a ``numpy.random.Generator`` or an integer seed.
    """
    n = _count("random_quaternions", "n", n)
    u1, u2, u3 = _rng(rng).random((3, n))
    a, b = np.sqrt(1.0 - u1), np.sqrt(u1)
    t2, t3 = 2.0 * math.pi * u2, 2.0 * math.pi * u3
    return np.stack([a * np.sin(t2), a * np.cos(t2), b * np.sin(t3), b * np.cos(t3)], axis=1)


# --------------------------------------------------------------------------------------------------------------
# Size distributions
#
# Every distribution has ``sample(rng, count) -> radii (count,) [m]``, ``radius_range() -> (min, max) [m]``,
# ``moment(k) -> E[r^k] [m^k]``, ``mean_volume() -> E[4/3 pi r^3] [m^3]`` and ``mean_mass(density) [kg]``.


class _Moments:
    def moment(self, k: int) -> float:  # pragma: no cover - every distribution overrides it
        raise NotImplementedError

    def mean_radius(self) -> float:
        """Mean radius E[r] [m]."""
        return self.moment(1)

    def mean_volume(self) -> float:
        """Mean particle volume E[4/3 pi r^3] [m^3]."""
        return (4.0 / 3.0) * math.pi * self.moment(3)

    def mean_mass(self, density: float) -> float:
        """Mean particle mass [kg] at solid ``density`` [kg/m^3]."""
        return float(density) * self.mean_volume()


@dataclass(frozen=True)
class FixedSize(_Moments):
    """Every particle has the same radius.

    Attributes:
        radius: particle radius [m], > 0.
    """

    radius: float

    def __post_init__(self):
        object.__setattr__(self, "radius", positive("FixedSize", "radius", self.radius, "a radius > 0 m"))

    def sample(self, rng, count: int) -> np.ndarray:
        """Radii [m], shape (count,)."""
        return np.full(_count("FixedSize.sample", "count", count), self.radius)

    def radius_range(self) -> tuple[float, float]:
        return (self.radius, self.radius)

    def moment(self, k: int) -> float:
        return self.radius**k


@dataclass(frozen=True)
class TruncatedNormal(_Moments):
    """Radius normally distributed, truncated to [low, high] (``scipy.stats.truncnorm``).

    Attributes:
        mean: mean of the untruncated normal [m], > 0 (it may lie outside [low, high]).
        std: standard deviation of the untruncated normal [m], >= 0 (0 gives every particle ``mean``).
        low: smallest radius [m], > 0.
        high: largest radius [m], > low.
    """

    mean: float
    std: float
    low: float
    high: float

    def __post_init__(self):
        where = "TruncatedNormal"
        positive(where, "mean", self.mean, "a radius > 0 m")
        check_number(where, "std", self.std, lambda v: v >= 0.0, "a standard deviation >= 0 m")
        low = positive(where, "low", self.low, "a radius > 0 m (radii must be positive)")
        check_number(where, "high", self.high, lambda v: v > low, f"a radius > low = {low!r} m")
        if self.std == 0.0:
            check(
                low <= self.mean <= self.high,
                where,
                "mean",
                self.mean,
                f"a radius in [low, high] = [{low!r}, {self.high!r}] m when std = 0",
            )
        for name in ("mean", "std", "low", "high"):
            object.__setattr__(self, name, float(getattr(self, name)))

    def _dist(self):
        from scipy import stats

        return stats.truncnorm(
            (self.low - self.mean) / self.std, (self.high - self.mean) / self.std, loc=self.mean, scale=self.std
        )

    def sample(self, rng, count: int) -> np.ndarray:
        """Radii [m], shape (count,)."""
        count = _count("TruncatedNormal.sample", "count", count)
        if self.std == 0.0:
            return np.full(count, self.mean)
        return np.clip(self._dist().rvs(size=count, random_state=_rng(rng)), self.low, self.high)

    def radius_range(self) -> tuple[float, float]:
        return (self.low, self.high)

    def moment(self, k: int) -> float:
        return self.mean**k if self.std == 0.0 else float(self._dist().moment(k))


@dataclass(frozen=True)
class LogNormal(_Moments):
    """Radius log-normally distributed, ln r ~ N(ln median, sigma_log^2), optionally truncated to [low, high].

    Attributes:
        median: median radius exp(mu) [m], > 0.
        sigma_log: standard deviation of ln r [-], >= 0.
        low: smallest radius [m], > 0, or None (no lower cut).
        high: largest radius [m], > low, or None (no upper cut).
    """

    median: float
    sigma_log: float
    low: float | None = None
    high: float | None = None

    def __post_init__(self):
        where = "LogNormal"
        object.__setattr__(self, "median", positive(where, "median", self.median, "a radius > 0 m"))
        check_number(where, "sigma_log", self.sigma_log, lambda v: v >= 0.0, "a standard deviation of ln r >= 0")
        object.__setattr__(self, "sigma_log", float(self.sigma_log))
        if self.low is not None:
            object.__setattr__(self, "low", positive(where, "low", self.low, "a radius > 0 m or None"))
        if self.high is not None:
            lo = self.low if self.low is not None else 0.0
            check_number(where, "high", self.high, lambda v: v > lo, f"a radius > {lo!r} m or None")
            object.__setattr__(self, "high", float(self.high))
        lo, hi = self.radius_range()
        if self.sigma_log == 0.0:
            check(
                lo <= self.median <= hi,
                where,
                "median",
                self.median,
                f"a radius in [low, high] = [{self.low!r}, {self.high!r}] m when sigma_log = 0",
            )
        else:
            check(
                float(_norm_interval(*self._z_bounds())) > 0.0,
                where,
                "sigma_log",
                self.sigma_log,
                f"a spread that leaves [low, high] = [{self.low!r}, {self.high!r}] m a non-zero probability",
            )

    def _z_bounds(self) -> tuple[float, float]:
        """Truncation bounds in standard-normal units of ln r (-inf, inf when not truncated); sigma_log > 0."""
        s = self.sigma_log
        a = -math.inf if self.low is None else math.log(self.low / self.median) / s
        b = math.inf if self.high is None else math.log(self.high / self.median) / s
        return a, b

    def sample(self, rng, count: int) -> np.ndarray:
        """Radii [m], shape (count,)."""
        count = _count("LogNormal.sample", "count", count)
        rng = _rng(rng)
        if self.sigma_log == 0.0:
            return np.full(count, self.median)
        a, b = self._z_bounds()
        if math.isinf(a) and math.isinf(b):
            z = rng.standard_normal(count)
        else:
            from scipy import stats

            z = stats.truncnorm.rvs(a, b, size=count, random_state=rng)
        r = self.median * np.exp(self.sigma_log * z)
        lo, hi = self.radius_range()
        return np.clip(r, lo, hi)

    def radius_range(self) -> tuple[float, float]:
        return (0.0 if self.low is None else self.low, math.inf if self.high is None else self.high)

    def moment(self, k: int) -> float:
        """E[r^k] = median^k exp(k^2 s^2 / 2) P(a - k s < Z < b - k s) / P(a < Z < b) [m^k]."""
        s = self.sigma_log
        if s == 0.0:
            return self.median**k
        a, b = self._z_bounds()
        ratio = float(_norm_interval(a - k * s, b - k * s) / _norm_interval(a, b))
        return self.median**k * math.exp(0.5 * (k * s) ** 2) * ratio


class SizeSpread(enum.Enum):
    """How diameters spread inside one sieve class (by number)."""

    UNIFORM = 0
    """Diameter uniform between the class edges."""
    LOG_UNIFORM = 1
    """ln(diameter) uniform between the class edges: sieve series are geometric, so this is the default."""


@dataclass(frozen=True)
class SieveTable(_Moments):
    """Sieve analysis: the fraction of MASS in each size class between sieve apertures.

    Sampling is by number, weighted so that the samples carry the table's mass fractions: class i is
    drawn with probability proportional to ``mass_fractions[i] / E[particle volume in class i]``, then a
    diameter is drawn inside the class by ``spread`` (log-uniform by default) and halved to a radius.

    Attributes:
        sizes: class edges, sieve apertures as DIAMETERS [m], shape (k + 1,), > 0 and strictly increasing.
        mass_fractions: mass fraction of each class [-], shape (k,), >= 0, summing to 1 within 1e-6
            (use :meth:`normalised` to rescale, e.g. percentages or a table with sieving loss).
        spread: SizeSpread (or its name) inside a class.
    """

    sizes: tuple
    mass_fractions: tuple
    spread: SizeSpread = SizeSpread.LOG_UNIFORM

    def __post_init__(self):
        where = "SieveTable"
        allowed = "at least 2 finite class edges (diameters [m])"
        d = float_array(where, "sizes", self.sizes, allowed).ravel()
        check(d.size >= 2 and bool(np.all(np.isfinite(d))), where, "sizes", self.sizes, allowed)
        bad = np.flatnonzero(d <= 0.0)
        check(
            bad.size == 0,
            where,
            f"sizes[{bad[0] if bad.size else 0}]",
            float(d[bad[0]]) if bad.size else None,
            "a diameter > 0 m (give the pan class a positive lower edge)",
        )
        steps = np.flatnonzero(np.diff(d) <= 0.0)
        check(
            steps.size == 0,
            where,
            f"sizes[{steps[0] + 1 if steps.size else 0}]",
            float(d[steps[0] + 1]) if steps.size else None,
            f"strictly increasing edges (> {float(d[steps[0]]) if steps.size else 0.0!r} m)",
        )
        allowed = f"{d.size - 1} values, one per class between the {d.size} edges"
        f = float_array(where, "mass_fractions", self.mass_fractions, allowed).ravel()
        check(f.size == d.size - 1, where, "mass_fractions", self.mass_fractions, allowed)
        bad = np.flatnonzero(~np.isfinite(f) | (f < 0.0))
        check(
            bad.size == 0,
            where,
            f"mass_fractions[{bad[0] if bad.size else 0}]",
            float(f[bad[0]]) if bad.size else None,
            "a mass fraction >= 0",
        )
        total = float(f.sum())
        if not abs(total - 1.0) <= _FRACTION_TOL:
            raise InputError(
                f"{where}: mass_fractions = {[float(x) for x in f]} (sum {total!r}) is not allowed; "
                f"expected fractions summing to 1 within 1e-6 (percentages: divide by 100; a table "
                f"with sieving loss: SieveTable.normalised(...) spreads the loss over the classes)"
            )
        object.__setattr__(self, "sizes", tuple(float(x) for x in d))
        object.__setattr__(self, "mass_fractions", tuple(float(x) for x in f / total))
        object.__setattr__(self, "spread", enum_value(SizeSpread, where, "spread", self.spread))

    @classmethod
    def normalised(cls, sizes, mass_fractions, spread=SizeSpread.LOG_UNIFORM) -> SieveTable:
        """A table whose fractions are ``mass_fractions / sum(mass_fractions)``.

        The rule for a sieve analysis that does not add up to 100 % (mass lost in sieving, or masses in
        grams): the missing mass is spread over the classes in proportion to what they hold.
        """
        f = np.asarray(mass_fractions, dtype=float)
        total = float(f.sum()) if f.size else 0.0
        check(
            np.isfinite(total) and total > 0.0,
            "SieveTable.normalised",
            "mass_fractions",
            mass_fractions,
            "non-negative values with a positive sum",
        )
        return cls(sizes, tuple(f / total), spread)

    @classmethod
    def from_csv(
        cls,
        path,
        *,
        top_size: float | None = None,
        pan_size: float | None = None,
        column: str | None = None,
        spread=SizeSpread.LOG_UNIFORM,
    ) -> SieveTable:
        """Read a sieve analysis (one row per sieve, as printed in a lab sheet) into a table.

        Rows: a size column (``sieve_um``, ``sieve_mm``, ``size_m``, ...; the name's suffix gives the unit)
        and one or more mass columns. A row holds what stayed ON that sieve, i.e. the class from its
        aperture up to the next larger one; a row of aperture 0 is the pan. The mass column is the first
        of these that exists (or ``column``), best first because it needs no differencing:

        1. retained per sieve in percent / fraction (``retained_pct``);
        2. retained per sieve in mass (``retained_g``);
        3. cumulative retained (differenced, from the coarsest sieve down);
        4. cumulative passing in percent (``100 - passing`` above the coarsest sieve, then differences;
           with a pan row its passing value is the sieving loss and is dropped; without one, what passes
           the finest sieve becomes the finest class).

        Empty classes at either end are dropped (a sheet showing 100 % passing its coarsest sieve would
        otherwise reach up to an extrapolated edge), and the fractions are normalised (:meth:`normalised`),
        which spreads any sieving loss over the classes. The classes open at either end need an edge,
        ``top_size`` above the coarsest sieve and ``pan_size`` below the finest one (diameters [m]); by default
        each is extrapolated geometrically from the two nearest sieves (coarsest^2 / second coarsest,
        finest^2 / second finest). For
        ``phosphate_psd.csv`` (seed 002 Table 1) that is 5 mm and 42.7 um, and ``retained_pct`` is used:
        its ``retained_g`` at 150 um (280.5 g) disagrees with its own percent and cumulative columns, which
        imply 280.65 g.
        """
        path = Path(path)
        where = f"SieveTable.from_csv({path.name!r})"
        with open(path, newline="") as fh:
            rows = [r for r in csv.DictReader(fh)]
        if not rows:
            raise InputError(f"{where}: the file has no data rows")
        names = list(rows[0].keys())
        low = {n: n.strip().lower() for n in names}
        size_col = next((n for n in names if low[n].startswith(("sieve", "size", "aperture", "mesh_"))), None)
        if size_col is None:
            raise InputError(
                f"{where}: columns {names} have no sieve size column; expected a name starting "
                f"with 'sieve', 'size' or 'aperture' and ending in _um, _mm or _m"
            )
        scale = next(
            (
                s
                for suffix, s in (("_um", 1e-6), ("_µm", 1e-6), ("_micron", 1e-6), ("_mm", 1e-3), ("_m", 1.0))
                if low[size_col].endswith(suffix)
            ),
            None,
        )
        if scale is None:
            raise InputError(f"{where}: size column {size_col!r} has no unit suffix; expected one of _um, _mm, _m")

        def is_cum(n):
            return "cum" in low[n]

        candidates = [
            n
            for n in names
            if "retained" in low[n] and not is_cum(n) and any(t in low[n] for t in ("pct", "percent", "%", "frac"))
        ]
        candidates += [n for n in names if "retained" in low[n] and not is_cum(n) and n not in candidates]
        candidates += [n for n in names if "retained" in low[n] and is_cum(n)]
        candidates += [n for n in names if any(t in low[n] for t in ("passing", "finer", "undersize"))]
        if column is not None:
            if column not in names:
                raise InputError(f"{where}: column = {column!r} is not allowed; expected one of {names}")
            candidates = [column]
        if not candidates:
            raise InputError(f"{where}: columns {names} have no retained or passing column")
        col = candidates[0]
        try:
            table = sorted(((float(r[size_col]), float(r[col])) for r in rows), key=lambda t: -t[0])
        except (TypeError, ValueError) as exc:
            raise InputError(f"{where}: a value in columns {size_col!r}/{col!r} is not a number ({exc})") from None
        aperture = np.array([t[0] for t in table]) * scale
        value = np.array([t[1] for t in table])
        has_pan = aperture[-1] == 0.0
        if is_cum(col) and "retained" in low[col]:
            retained = np.diff(value, prepend=0.0)
        elif "retained" in low[col]:
            retained = value
        else:  # cumulative passing, coarsest sieve first
            total = 100.0 if value.max() <= 100.0 + 1e-9 else float(value.max())
            retained = -np.diff(value, prepend=total)
            if not has_pan:
                retained = np.append(retained, value[-1])
                aperture = np.append(aperture, 0.0)
                has_pan = True
        sieves = aperture[:-1] if has_pan else aperture
        if sieves.size < 2:
            raise InputError(
                f"{where}: {sieves.size} sieve(s) with an aperture > 0; expected at least 2 to "
                f"extrapolate the open classes"
            )
        if top_size is None:
            top_size = sieves[0] ** 2 / sieves[1]
        check_number(
            where, "top_size", top_size, lambda v: v > sieves[0], f"a diameter > the coarsest sieve {sieves[0]!r} m"
        )
        edges = [float(top_size), *sieves]
        if has_pan:
            if pan_size is None:
                pan_size = sieves[-1] ** 2 / sieves[-2]
            check_number(
                where,
                "pan_size",
                pan_size,
                lambda v: 0.0 < v < sieves[-1],
                f"a diameter in (0, {sieves[-1]!r}) m, below the finest sieve",
            )
            edges.append(float(pan_size))
        edges, retained = np.array(edges[::-1]), np.asarray(retained[::-1], dtype=float)
        # Empty classes at either end (e.g. 100 % passing the coarsest sieve) carry no mass: drop them so
        # that the table does not reach to an extrapolated edge no particle comes from.
        used = np.flatnonzero(retained > 0.0)
        if used.size == 0:
            raise InputError(f"{where}: column {col!r} gives no retained mass in any class")
        keep = slice(used[0], used[-1] + 1)
        return cls.normalised(edges[used[0] : used[-1] + 2], retained[keep], spread)

    # -- derived quantities

    @property
    def class_count(self) -> int:
        return len(self.mass_fractions)

    def _class_diameter_moment(self, k: int) -> np.ndarray:
        """E[d^k | class] [m^k], shape (k,), for the number distribution inside each class."""
        d = np.asarray(self.sizes)
        lo, hi = d[:-1], d[1:]
        if self.spread is SizeSpread.UNIFORM:
            return (hi ** (k + 1) - lo ** (k + 1)) / ((k + 1) * (hi - lo))
        if k == 0:
            return np.ones_like(lo)
        return (hi**k - lo**k) / (k * np.log(hi / lo))

    def number_fractions(self) -> np.ndarray:
        """Probability that a drawn particle falls in each class [-], shape (k,): f_i / E[V_i], normalised."""
        w = np.asarray(self.mass_fractions) / self._class_diameter_moment(3)
        return w / w.sum()

    def sample(self, rng, count: int) -> np.ndarray:
        """Radii [m], shape (count,): half of the drawn diameters."""
        count = _count("SieveTable.sample", "count", count)
        rng = _rng(rng)
        cls_idx = rng.choice(self.class_count, size=count, p=self.number_fractions())
        u = rng.random(count)
        d = np.asarray(self.sizes)
        lo, hi = d[cls_idx], d[cls_idx + 1]
        if self.spread is SizeSpread.UNIFORM:
            diam = lo + u * (hi - lo)
        else:
            diam = lo * np.exp(u * np.log(hi / lo))
        return 0.5 * np.clip(diam, lo, hi)

    def radius_range(self) -> tuple[float, float]:
        nonzero = np.flatnonzero(np.asarray(self.mass_fractions) > 0.0)
        return (0.5 * self.sizes[nonzero[0]], 0.5 * self.sizes[nonzero[-1] + 1])

    def moment(self, k: int) -> float:
        return float(np.dot(self.number_fractions(), self._class_diameter_moment(k))) / 2.0**k

    def mass_fractions_of(self, radii) -> np.ndarray:
        """Mass fraction [-] of ``radii`` [m] (any shape) in each class of this table, shape (k,).

        Equal density is assumed, so mass goes as r^3. A particle whose diameter lies outside the table's
        edges counts in the total but in no class, so the fractions then sum to less than 1.
        """
        d = 2.0 * np.asarray(radii, dtype=float).ravel()
        v = d**3
        edges = np.asarray(self.sizes)
        idx = np.searchsorted(edges, d, side="right") - 1
        idx[d == edges[-1]] = self.class_count - 1  # the top edge belongs to the top class
        inside = (idx >= 0) & (idx < self.class_count)
        total = v.sum()
        if total <= 0.0:
            return np.zeros(self.class_count)
        return np.bincount(idx[inside], weights=v[inside], minlength=self.class_count) / total


SizeDistribution = FixedSize | TruncatedNormal | LogNormal | SieveTable


# --------------------------------------------------------------------------------------------------------------
# Regions
#
# Every region has ``contains(points, margin=0) -> bool (n,)`` (True where a sphere of radius ``margin``
# centred at the point lies inside), ``sample_uniform(rng, n) -> (n, 3)``, ``volume`` [m^3],
# ``inset(margin)``, ``inradius`` [m] (the largest sphere that fits) and ``bounds() -> (lo (3,), hi (3,))``.
# Containment allows a round-off slack of 1e-9 of the region size so that sampled points always pass.

_SLACK = 1e-9


@dataclass(frozen=True)
class Box:
    """Axis-aligned box.

    Attributes:
        lo: lower corner [m], shape (3,).
        hi: upper corner [m], shape (3,), > lo in every component.
    """

    lo: tuple
    hi: tuple

    def __post_init__(self):
        where = "Box"
        lo, hi = vec3(where, "lo", self.lo), vec3(where, "hi", self.hi)
        check(all(b > a for a, b in zip(lo, hi)), where, "hi", self.hi, f"every component > lo = {lo}")
        object.__setattr__(self, "lo", lo)
        object.__setattr__(self, "hi", hi)

    @property
    def volume(self) -> float:
        """Volume [m^3]."""
        return float(np.prod(np.subtract(self.hi, self.lo)))

    @property
    def inradius(self) -> float:
        """Radius of the largest sphere that fits [m]."""
        return 0.5 * float(np.min(np.subtract(self.hi, self.lo)))

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounding box (lo (3,), hi (3,)) [m]."""
        return np.array(self.lo), np.array(self.hi)

    def contains(self, points, margin=0.0) -> np.ndarray:
        """Whether spheres of radius ``margin`` [m] (scalar or (n,)) at ``points`` (n, 3) [m] lie inside, (n,)."""
        p = _points(points)
        m = _margins("Box.contains", margin, len(p))[:, None]
        tol = _SLACK * float(np.max(np.subtract(self.hi, self.lo)))
        return np.all((p >= np.asarray(self.lo) + m - tol) & (p <= np.asarray(self.hi) - m + tol), axis=1)

    def inset(self, margin: float) -> Box:
        """The box shrunk by ``margin`` [m] on every side."""
        margin = _inset_margin(self, margin, "half the smallest side")
        return Box(np.add(self.lo, margin), np.subtract(self.hi, margin))

    def sample_uniform(self, rng, n: int) -> np.ndarray:
        """Points uniform in the box [m], shape (n, 3)."""
        return self._sample_inset(_rng(rng), np.zeros(_count("Box.sample_uniform", "n", n)))

    def _fits(self, margin) -> np.ndarray:
        return np.asarray(margin) <= self.inradius * (1.0 + 1e-12)

    def _sample_inset(self, rng, margin: np.ndarray) -> np.ndarray:
        """Points uniform in ``inset(margin[i])`` for each i, shape (n, 3); the margins must fit."""
        m = np.minimum(margin, self.inradius)[:, None]
        lo, hi = np.asarray(self.lo) + m, np.asarray(self.hi) - m
        return lo + rng.random((len(m), 3)) * (hi - lo)


def _inset_margin(region, margin, inradius_is: str) -> float:
    """``margin`` [m] of ``region.inset``: at least 0 and below the region's inradius (``inradius_is`` says
    what that is for this kind of region)."""
    inradius = region.inradius
    allowed = f"a margin in [0, {inradius!r}) m ({inradius_is})"
    return check_number(f"{type(region).__name__}.inset", "margin", margin, lambda v: 0.0 <= v < inradius, allowed)


def _unit_axis(where: str, value) -> tuple[float, float, float]:
    a = np.asarray(vec3(where, "axis", value))
    n = float(np.linalg.norm(a))
    check(n > 0.0, where, "axis", value, "a non-zero direction (normalised on construction)")
    return tuple(float(x) for x in a / n)


def _perpendicular_basis(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(axis, e1)


class _Frustum:
    """Shared geometry of Cylinder and Cone: a frustum of revolution from ``base_center`` along ``axis``.

    The radius varies linearly, R(h) = Rb + s h with s = (Rt - Rb) / H. A sphere of radius m at axial
    height h and distance rho from the axis lies inside iff m <= h <= H - m and rho <= R(h) - m sqrt(1 + s^2)
    (its distance to the slanted side in the meridian plane); that set is again a frustum, possibly ending
    at an apex, which is what :meth:`inset` returns.
    """

    base_center: tuple
    axis: tuple

    def _check_frame(self) -> str:
        """Check and normalise ``base_center``, ``axis`` and ``height``; returns the class name for messages."""
        where = type(self).__name__
        object.__setattr__(self, "base_center", vec3(where, "base_center", self.base_center))
        object.__setattr__(self, "axis", _unit_axis(where, self.axis))
        object.__setattr__(self, "height", positive(where, "height", self.height, "a height > 0 m"))
        return where

    def _radii_height(self) -> tuple[float, float, float]:
        raise NotImplementedError  # pragma: no cover

    def _scale(self) -> float:
        rb, rt, h = self._radii_height()
        return max(rb, rt, h)

    @property
    def volume(self) -> float:
        """Volume pi H (Rb^2 + Rb Rt + Rt^2) / 3 [m^3]."""
        rb, rt, h = self._radii_height()
        return math.pi * h * (rb * rb + rb * rt + rt * rt) / 3.0

    def _inset_params(self, margin, slack: float = 1e-12):
        """Axial range [h0, h1] and radii (r0, r1) at its ends of the frustum inset by ``margin``, and fit mask
        (allowing ``slack`` times the region size for round-off)."""
        rb, rt, height = self._radii_height()
        m = np.asarray(margin, dtype=float)
        s = (rt - rb) / height
        c = math.sqrt(1.0 + s * s)
        h0, h1 = m.copy(), height - m
        if s > 0.0:
            h0 = np.maximum(h0, (m * c - rb) / s)
        elif s < 0.0:
            h1 = np.minimum(h1, (m * c - rb) / s)
        r0, r1 = rb + s * h0 - m * c, rb + s * h1 - m * c
        tol = slack * self._scale()
        fits = (h1 - h0 >= -tol) & (r0 >= -tol) & (r1 >= -tol)
        return h0, np.maximum(h1, h0), np.maximum(r0, 0.0), np.maximum(r1, 0.0), fits

    def _fits(self, margin) -> np.ndarray:
        return self._inset_params(margin)[4]

    @property
    def inradius(self) -> float:
        """Radius of the largest sphere that fits [m] (bisection to round-off)."""
        lo, hi = 0.0, self._scale()
        for _ in range(100):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if bool(self._inset_params(mid, slack=0.0)[4]) else (lo, mid)
        return lo

    def _axial(self, p: np.ndarray):
        a = np.asarray(self.axis)
        d = p - np.asarray(self.base_center)
        h = d @ a
        rho = np.linalg.norm(d - h[:, None] * a, axis=1)
        return h, rho

    def contains(self, points, margin=0.0) -> np.ndarray:
        """Whether spheres of radius ``margin`` [m] (scalar or (n,)) at ``points`` (n, 3) [m] lie inside, (n,)."""
        p = _points(points)
        m = _margins(type(self).__name__ + ".contains", margin, len(p))
        rb, rt, height = self._radii_height()
        s = (rt - rb) / height
        h, rho = self._axial(p)
        tol = _SLACK * self._scale()
        return (h >= m - tol) & (h <= height - m + tol) & (rho <= rb + s * h - m * math.sqrt(1 + s * s) + tol)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounding box (lo (3,), hi (3,)) [m]: that of the two end disks."""
        rb, rt, height = self._radii_height()
        a, c = np.asarray(self.axis), np.asarray(self.base_center)
        reach = np.sqrt(np.clip(1.0 - a * a, 0.0, 1.0))  # disk of unit radius, normal a: half-extent per axis
        ends = [(c, rb), (c + height * a, rt)]
        lo = np.min([p - r * reach for p, r in ends], axis=0)
        hi = np.max([p + r * reach for p, r in ends], axis=0)
        return lo, hi

    def sample_uniform(self, rng, n: int) -> np.ndarray:
        """Points uniform in the region [m], shape (n, 3)."""
        return self._sample_inset(_rng(rng), np.zeros(_count(type(self).__name__ + ".sample_uniform", "n", n)))

    def _sample_inset(self, rng, margin: np.ndarray) -> np.ndarray:
        """Points uniform in ``inset(margin[i])`` for each i, shape (n, 3); the margins must fit."""
        h0, h1, r0, r1, _ = self._inset_params(margin)
        u = rng.random((3, len(h0)))
        # Axial position with density ~ R(h)^2 by inverting the cumulative volume (R^3 is linear in it).
        dr = r1 - r0
        slanted = np.abs(dr) > 1e-12 * np.maximum(np.maximum(r0, r1), 1e-300)
        safe = np.where(slanted, dr, 1.0)
        radius_at = np.where(slanted, np.cbrt(r0**3 + u[0] * (r1**3 - r0**3)), r0)
        h = np.where(slanted, h0 + (radius_at - r0) / safe * (h1 - h0), h0 + u[0] * (h1 - h0))
        rho = radius_at * np.sqrt(u[1])
        phi = 2.0 * math.pi * u[2]
        a = np.asarray(self.axis)
        e1, e2 = _perpendicular_basis(a)
        return (
            np.asarray(self.base_center)
            + h[:, None] * a
            + (rho * np.cos(phi))[:, None] * e1
            + (rho * np.sin(phi))[:, None] * e2
        )


@dataclass(frozen=True)
class Cylinder(_Frustum):
    """Solid circular cylinder.

    Attributes:
        base_center: centre of the base disk [m], shape (3,).
        axis: direction from the base to the top [-], shape (3,), normalised on construction.
        radius: radius [m], > 0.
        height: length along the axis [m], > 0.
    """

    base_center: tuple
    axis: tuple
    radius: float
    height: float

    def __post_init__(self):
        where = self._check_frame()
        object.__setattr__(self, "radius", positive(where, "radius", self.radius, "a radius > 0 m"))

    def _radii_height(self):
        return self.radius, self.radius, self.height

    def inset(self, margin: float) -> Cylinder:
        """The cylinder shrunk by ``margin`` [m] on its side and both ends."""
        margin = _inset_margin(self, margin, "min(radius, height / 2)")
        return Cylinder(
            np.asarray(self.base_center) + margin * np.asarray(self.axis),
            self.axis,
            self.radius - margin,
            self.height - 2.0 * margin,
        )


@dataclass(frozen=True)
class Cone(_Frustum):
    """Solid truncated cone (frustum); a funnel is one with ``top_radius > base_radius``.

    Attributes:
        base_center: centre of the base disk [m], shape (3,).
        axis: direction from the base to the top [-], shape (3,), normalised on construction.
        base_radius: radius at the base [m], >= 0.
        top_radius: radius at the top [m], >= 0 (0 for a full cone with its apex at the top).
        height: length along the axis [m], > 0.
    """

    base_center: tuple
    axis: tuple
    base_radius: float
    top_radius: float
    height: float

    def __post_init__(self):
        where = self._check_frame()
        for name in ("base_radius", "top_radius"):
            value = getattr(self, name)
            check_number(where, name, value, lambda v: v >= 0.0, "a radius >= 0 m")
            object.__setattr__(self, name, float(value))
        check(
            self.base_radius > 0.0 or self.top_radius > 0.0,
            where,
            "top_radius",
            self.top_radius,
            "a radius > 0 m when base_radius is 0",
        )

    def _radii_height(self):
        return self.base_radius, self.top_radius, self.height

    def inset(self, margin: float) -> Cone:
        """The frustum of centres of spheres of radius ``margin`` [m] that fit (cut at an apex if needed)."""
        margin = _inset_margin(self, margin, "the largest sphere that fits")
        h0, h1, r0, r1, _ = (float(v) for v in self._inset_params(margin))
        return Cone(np.asarray(self.base_center) + h0 * np.asarray(self.axis), self.axis, r0, r1, h1 - h0)


Region = Box | Cylinder | Cone


# --------------------------------------------------------------------------------------------------------------
# Random sequential addition


class RegionFullError(InputError):
    """A region could not take the requested particles; ``placed`` of ``requested`` fitted."""

    def __init__(self, message: str, placed: int, requested: int):
        super().__init__(message)
        self.placed = placed
        self.requested = requested


class _SizeBinnedTrees:
    """Placed spheres in KD-trees, one per factor-2 band of radius.

    An overlap query for a sphere of radius a only has to look within a + (largest radius of the band) of it;
    banding keeps that reach short for small spheres among large ones, so a k-nearest query nearly always
    sees every sphere it could touch. Each band keeps a large tree and a small one of recent additions,
    merged when the small one reaches a quarter of the large: near jamming a fill takes many rounds that
    add a few spheres each, and rebuilding one tree of all spheres per round would dominate.
    """

    def __init__(self, r_ref: float):
        self.r_ref = r_ref
        self.main: dict[int, tuple | None] = {}
        self.recent: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
        self.recent_built: dict[int, tuple] = {}
        self.k = 12

    @staticmethod
    def _build(x: np.ndarray, r: np.ndarray) -> tuple:
        from scipy.spatial import cKDTree

        return (cKDTree(x), x, np.append(r, -np.inf), float(r.min()), float(r.max()))

    def add(self, x: np.ndarray, r: np.ndarray) -> None:
        if len(r) == 0:
            return
        band = np.floor(np.log2(np.maximum(r, 1e-300) / self.r_ref)).astype(int)
        for b in (int(v) for v in np.unique(band)):
            sel = band == b
            self.main.setdefault(b, None)
            self.recent.setdefault(b, []).append((x[sel], r[sel]))
            self.recent_built.pop(b, None)

    def _groups(self):
        for b in self.main:
            if self.recent[b]:
                rx = np.concatenate([t[0] for t in self.recent[b]])
                rr = np.concatenate([t[1] for t in self.recent[b]])
                main = self.main[b]
                if main is None or len(rx) > max(1024, len(main[1]) // 4):
                    if main is not None:
                        rx, rr = np.concatenate([main[1], rx]), np.concatenate([main[2][:-1], rr])
                    self.main[b], self.recent[b] = self._build(rx, rr), []
                    self.recent_built.pop(b, None)
                else:
                    self.recent[b] = [(rx, rr)]
                    if b not in self.recent_built:
                        self.recent_built[b] = self._build(rx, rr)
            yield self.main[b]
            if self.recent[b]:
                yield self.recent_built[b]

    def free(self, p: np.ndarray, a: np.ndarray) -> np.ndarray:
        """True where a sphere of radius a (n,) at p (n, 3) overlaps none of the stored spheres."""
        ok = np.ones(len(p), dtype=bool)
        for tree, x, r_ext, r_min, r_max in self._groups():
            rows = np.flatnonzero(ok)
            if len(rows) == 0:
                break
            # The nearest centre alone settles most proposals (always, for equal radii in the band): it
            # clashes if closer than a + r_min and no centre can clash if it is beyond a + r_max.
            reach = float(a[rows].max()) + r_max
            d1, _ = tree.query(p[rows], k=1, distance_upper_bound=reach, workers=_workers(len(rows)))
            ok[rows[d1 < a[rows] + r_min]] = False
            rows = rows[(d1 >= a[rows] + r_min) & (d1 < a[rows] + r_max)]
            if len(rows) == 0:
                continue
            q, qa = p[rows], a[rows]
            n = len(x)
            k = min(self.k, n)
            d, j = tree.query(q, k=k, distance_upper_bound=float(qa.max()) + r_max, workers=_workers(len(q)))
            d, j = d.reshape(len(q), k), j.reshape(len(q), k)
            clash = np.any(d < qa[:, None] + r_ext[j], axis=1)
            ok[rows[clash]] = False
            # All k neighbours within reach: there may be more, so check those points exactly.
            unsure = np.flatnonzero(~clash & np.isfinite(d[:, -1])) if n > k else np.empty(0, int)
            if len(unsure) > 0.1 * len(q):
                self.k = min(4 * self.k, 256)
            for row, near in zip(unsure, tree.query_ball_point(q[unsure], qa[unsure] + r_max) if len(unsure) else []):
                if near and np.any(np.linalg.norm(x[near] - q[row], axis=1) < qa[row] + r_ext[near]):
                    ok[rows[row]] = False
        return ok


def _workers(queries: int) -> int:
    """Threads for a k-d tree query of ``queries`` points: SciPy starts its threads at every call, which for the
    few dozen proposals of a dynamic factory's release cost more than the query (113,000 threads, a third of a
    GPU launch's wall time, in three lab-size funnel launches); the answer is the same either way."""
    return -1 if queries >= 16384 else 1


def _check_existing(where: str, existing_x, existing_r) -> tuple[np.ndarray, np.ndarray]:
    if existing_x is None and existing_r is None:
        return np.zeros((0, 3)), np.zeros(0)
    if existing_x is None or existing_r is None:
        raise InputError(f"{where}: give existing_x and existing_r together (one of them is None)")
    x = np.asarray(existing_x, dtype=float).reshape(-1, 3) if np.size(existing_x) else np.zeros((0, 3))
    r = np.asarray(existing_r, dtype=float).ravel()
    check(len(x) == len(r), where, "existing_r", f"shape {r.shape}", f"shape ({len(x)},) to match existing_x")
    check(bool(np.all(np.isfinite(x))), where, "existing_x", "non-finite entries", "finite positions [m]")
    check(
        bool(np.all(np.isfinite(r) & (r >= 0.0))),
        where,
        "existing_r",
        r[~(np.isfinite(r) & (r >= 0.0))][:3] if len(r) else r,
        "finite radii >= 0 m",
    )
    return x, r


def _rsa(
    region,
    radius: np.ndarray,
    order: np.ndarray,
    rng: np.random.Generator,
    existing_x: np.ndarray,
    existing_r: np.ndarray,
    max_attempts: int,
):
    """Random sequential addition of spheres ``radius`` (n,) into ``region``, tried in ``order``.

    Vectorised in rounds: the next B pending spheres each get T_i uniform proposals inside
    ``region.inset(r_i)``; the first proposal clear of every placed sphere is kept; of two kept proposals in
    the round that overlap, the later one in ``order`` yields and is retried. T doubles for a sphere at every
    round it fails, so a sphere early in ``order`` (a large one in a fill) is not starved by the later ones
    placed beside it in the same rounds. B and T adapt to the acceptance rates. A sphere that has used
    ``max_attempts`` proposals without being placed ends the fill.

    Returns (x (n, 3) [m], NaN where not placed; placed (n,) bool).
    """
    n = len(radius)
    x = np.full((n, 3), np.nan)
    placed = np.zeros(n, dtype=bool)
    attempts = np.zeros(n, dtype=np.int64)
    failed_rounds = np.zeros(n, dtype=np.int64)
    if n == 0:
        return x, placed
    trees = _SizeBinnedTrees(float(radius.min()) if radius.min() > 0 else 1.0)
    if len(existing_x):
        # Only existing spheres that can reach the region matter.
        lo, hi = region.bounds()
        reach = existing_r + float(radius.max())
        near = np.all((existing_x >= lo - reach[:, None]) & (existing_x <= hi + reach[:, None]), axis=1)
        trees.add(existing_x[near], existing_r[near])
    pending = np.asarray(order)
    batch, tries, max_round = 256, 1, 65536
    while len(pending):
        idx = pending[:batch]
        t = np.minimum(tries << np.minimum(failed_rounds[idx], 12), 4096)
        t = np.maximum(np.minimum(t, max_attempts - attempts[idx]), 1)
        # Bound the proposals of one round (memory), keeping at least the first sphere.
        fits = max(1, int(np.searchsorted(np.cumsum(t), max_round, side="right")))
        idx, t = idx[:fits], t[:fits]
        a = radius[idx]
        start = np.cumsum(t) - t
        a_rep = np.repeat(a, t)
        prop = region._sample_inset(rng, a_rep)
        free = trees.free(prop, a_rep)
        owner = np.repeat(np.arange(len(idx)), t)
        hits = np.flatnonzero(free)
        who, first_hit = np.unique(owner[hits], return_index=True)  # hits ascend: first free proposal each
        found = np.zeros(len(idx), dtype=bool)
        found[who] = True
        used = t.copy()
        used[who] = hits[first_hit] - start[who] + 1
        attempts[idx] += used
        failed_rounds[idx[~found]] += 1
        cand, cand_idx, cand_a = prop[hits[first_hit]], idx[who], a[who]
        keep = np.ones(len(cand_idx), dtype=bool)
        if len(cand_idx) > 1:
            from scipy.spatial import cKDTree

            pairs = cKDTree(cand).query_pairs(2.0 * float(cand_a.max()), output_type="ndarray")
            if len(pairs):
                i, j = pairs[:, 0], pairs[:, 1]
                clash = np.linalg.norm(cand[i] - cand[j], axis=1) < cand_a[i] + cand_a[j]
                # Candidates sit in ``order``; the later of a clashing pair yields (conservative: it
                # yields even if the earlier one yields to a third, which only costs a retry).
                keep[np.maximum(i, j)[clash]] = False
        acc_idx = cand_idx[keep]
        x[acc_idx] = cand[keep]
        placed[acc_idx] = True
        failed_rounds[cand_idx[~keep]] += 1
        trees.add(cand[keep], cand_a[keep])
        exhausted = (attempts[idx] >= max_attempts) & ~placed[idx]
        if exhausted.any():
            return x, placed
        pending = pending[~placed[pending]]
        # Adapt: T so that most spheres find a free spot per round, B to what the region takes per round.
        rate = float(free.mean())
        tries = int(np.clip(math.ceil(2.0 / max(rate, 1e-4)), 1, 1024))
        conflict = 1.0 - float(keep.mean()) if len(keep) else 0.0
        grow = 2 * batch if conflict < 0.05 else batch // 2 if conflict > 0.2 else batch
        batch = int(np.clip(min(grow, 2 * len(acc_idx) + 32), 16, max(16, max_round // tries)))
    return x, placed


def _sizes_for(where: str, sizes, rng: np.random.Generator, count, mass, density) -> np.ndarray:
    """Draw exactly ``count`` sizes, or the fewest whose mass (density * 4/3 pi r^3) reaches ``mass``."""
    check((count is None) != (mass is None), where, "count/mass", (count, mass), "exactly one of count or mass")
    if count is not None:
        return np.asarray(sizes.sample(rng, _count(where, "count", count)), dtype=float)
    check_number(where, "mass", mass, lambda v: v > 0.0, "a mass > 0 kg")
    check_number(where, "density", density, lambda v: v > 0.0, "a density > 0 kg/m^3 (needed for a mass target)")
    mean_mass = sizes.mean_mass(density)
    chunk = int(min(max(1.1 * mass / mean_mass + 16, 16), 1e8)) if mean_mass > 0 else 1024
    drawn, total = [], 0.0
    while True:
        r = np.asarray(sizes.sample(rng, chunk), dtype=float)
        m = density * sphere_volume(r)
        cum = total + np.cumsum(m)
        hit = np.searchsorted(cum, mass, side="left")
        if hit < len(r):
            drawn.append(r[: hit + 1])
            return np.concatenate(drawn)
        drawn.append(r)
        total = float(cum[-1])
        chunk = max(16, int(chunk * 0.5))


def _check_region_sizes(where: str, region, sizes) -> None:
    check(isinstance(region, (Box, Cylinder, Cone)), where, "region", region, "a Box, Cylinder or Cone")
    check(
        isinstance(sizes, (FixedSize, TruncatedNormal, LogNormal, SieveTable)),
        where,
        "sizes",
        sizes,
        "a FixedSize, TruncatedNormal, LogNormal or SieveTable",
    )


def _check_fits(where: str, region, bound: np.ndarray) -> None:
    if len(bound) and not bool(region._fits(float(bound.max()))):
        raise InputError(
            f"{where}: sizes: a particle of bounding radius {float(bound.max())!r} m does not fit in "
            f"{region}; expected at most {region.inradius!r} m (the largest sphere that fits): use "
            f"smaller sizes or a larger region"
        )


def _stream(seed: int, purpose: int, *more: int) -> np.random.Generator:
    # Independent streams per purpose, so that asking for orientations never changes positions or sizes.
    return np.random.default_rng([int(seed), purpose, *more])


_SIZES, _PLACE, _ORIENT, _WORLD = 0, 1, 2, 3


def fill_region(
    region,
    sizes,
    *,
    count: int | None = None,
    mass: float | None = None,
    density: float | None = None,
    rng_seed: int = 0,
    existing_x=None,
    existing_r=None,
    max_attempts: int = 10000,
    bounding_ratio: float = 1.0,
    orientations: bool = False,
):
    """Fill ``region`` with non-overlapping particles by random sequential addition (static factory).

    Sizes are drawn from ``sizes`` first: exactly ``count``, or for ``mass`` [kg] the fewest whose mass
    density * 4/3 pi r^3 reaches it (the total exceeds ``mass`` by less than the last particle). They are
    then placed largest first (large spheres are the hardest to fit, so they go in while the region is
    empty), each uniformly at random in ``region.inset(bounding_ratio * r)`` and kept only if it is clear of
    every sphere already placed and of ``existing`` ones: spheres lie fully inside the region with zero overlap.

    Args:
        region: Box, Cylinder or Cone.
        sizes: size distribution; its draws are the returned ``r``.
        count: number of particles, or
        mass: total mass [kg] (needs ``density``).
        density: solid density [kg/m^3].
        rng_seed: seed; the same seed gives the same fill.
        existing_x: centres of particles already there [m], shape (m, 3), or None.
        existing_r: their bounding radii [m], shape (m,), or None.
        max_attempts: proposals one particle may use before the fill gives up.
        bounding_ratio: bounding radius / size [-], >= 1: 1 for spheres; for clumps, whose size is the scaled
            template's volume-equivalent radius, the template's bounding radius over that radius.
        orientations: also return uniform random orientations (for clumps).

    Returns:
        x: centres [m], shape (n, 3); r: sizes [m], shape (n,) (in draw order); and with ``orientations``,
        q: quaternions (x, y, z, w), shape (n, 4).

    Raises:
        RegionFullError: the region took fewer than n particles. Random sequential addition of equal spheres
            jams near a volume fraction of 0.38 (fewer near walls), well below a settled packing (~0.6).
    """
    where = "fill_region"
    _check_region_sizes(where, region, sizes)
    integer(where, "rng_seed", rng_seed, 0)
    integer(where, "max_attempts", max_attempts, 1)
    check_number(where, "bounding_ratio", bounding_ratio, lambda v: v >= 1.0, "a ratio >= 1")
    ex_x, ex_r = _check_existing(where, existing_x, existing_r)
    r = _sizes_for(where, sizes, _stream(rng_seed, _SIZES), count, mass, density)
    bound = bounding_ratio * r
    _check_fits(where, region, bound)
    order = np.argsort(-bound, kind="stable")
    x, placed = _rsa(region, bound, order, _stream(rng_seed, _PLACE), ex_x, ex_r, max_attempts)
    if not placed.all():
        k, n = int(placed.sum()), len(r)
        phi = float(sphere_volume(bound[placed]).sum()) / region.volume
        phi_all = float(sphere_volume(bound).sum()) / region.volume
        raise RegionFullError(
            f"{where}: only {k} of {n} particles fitted in {region} (volume fraction {phi:.3f}; all {n} would "
            f"need {phi_all:.3f}) after {max_attempts} attempts for one particle. Random sequential addition "
            f"jams near a volume fraction of {RSA_SATURATION} for equal spheres (less near walls): use a larger "
            f"region, fewer or smaller particles, or fill in stages and let them settle.",
            k,
            n,
        )
    if orientations:
        return x, r, random_quaternions(_stream(rng_seed, _ORIENT), len(r))
    return x, r


# --------------------------------------------------------------------------------------------------------------
# Dynamic factory

_ROUND = 1e-12  # relative slack so that k * rate * interval = k exactly is not floored to k - 1


@dataclass(frozen=True)
class DynamicFactory:
    """Particles released in batches during a run, at a count or mass rate, up to a count or mass target.

    All sizes (and orientations) are drawn once at construction from ``seed``, so :meth:`capacity` is the
    exact number the engine preallocates and a run is reproducible. Particle i (in draw order) is the i-th
    released.

    Schedule (:meth:`plan`): batch k is released at t_k = start_time + k * interval (k = 1, 2, ...), and the
    cumulative count released by then is floor(rate * (t_k - start_time)), or for ``mass_rate`` the largest
    count whose mass does not exceed mass_rate * (t_k - start_time); the last batch releases the remainder.
    Between batches the released count lags the continuous rate by less than one batch.

    Attributes:
        region: Box, Cylinder or Cone where particles appear.
        sizes: size distribution (see :func:`fill_region` for clumps).
        rate: release rate [particles/s], > 0; or
        mass_rate: release rate [kg/s], > 0.
        count: number of particles to release; or
        mass: total mass to release [kg] (the fewest particles that reach it).
        start_time: time of the schedule's origin [s], >= 0.
        density: solid density [kg/m^3], needed with ``mass`` or ``mass_rate``.
        seed: random seed, integer >= 0.
        initial_velocity: velocity of released particles [m/s], shape (3,).
        interval: time between batches [s], > 0; default the shortest interval with at least one particle
            per batch (1 / rate, or the largest pre-drawn particle mass / mass_rate). Longer intervals mean
            fewer, larger batches (less host work, but the region must hold a whole batch at once).
        bounding_ratio: bounding radius / size [-], >= 1 (clumps).
        random_orientation: draw uniform random orientations (else identity).
        max_attempts: proposals per particle in :meth:`place` before it defers the rest.
    """

    region: Box | Cylinder | Cone
    sizes: FixedSize | TruncatedNormal | LogNormal | SieveTable
    rate: float | None = None
    mass_rate: float | None = None
    count: int | None = None
    mass: float | None = None
    start_time: float = 0.0
    density: float | None = None
    seed: int = 0
    initial_velocity: tuple = (0.0, 0.0, 0.0)
    interval: float | None = None
    bounding_ratio: float = 1.0
    random_orientation: bool = False
    max_attempts: int = 200
    _radii: np.ndarray = field(init=False, repr=False, compare=False)
    _quats: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        where = "DynamicFactory"
        _check_region_sizes(where, self.region, self.sizes)
        check(
            (self.rate is None) != (self.mass_rate is None),
            where,
            "rate/mass_rate",
            (self.rate, self.mass_rate),
            "exactly one of rate [particles/s] or mass_rate [kg/s]",
        )
        if self.rate is not None:
            object.__setattr__(self, "rate", positive(where, "rate", self.rate, "a rate > 0 particles/s"))
        if self.mass_rate is not None:
            object.__setattr__(self, "mass_rate", positive(where, "mass_rate", self.mass_rate, "a rate > 0 kg/s"))
        if self.mass_rate is not None or self.mass is not None:
            object.__setattr__(
                self,
                "density",
                positive(where, "density", self.density, "a density > 0 kg/m^3 (needed for mass or mass_rate)"),
            )
        elif self.density is not None:
            object.__setattr__(self, "density", positive(where, "density", self.density, "a density > 0 kg/m^3"))
        check_number(where, "start_time", self.start_time, lambda v: v >= 0.0, "a time >= 0 s")
        integer(where, "seed", self.seed, 0)
        object.__setattr__(self, "initial_velocity", vec3(where, "initial_velocity", self.initial_velocity))
        check_number(where, "bounding_ratio", self.bounding_ratio, lambda v: v >= 1.0, "a ratio >= 1")
        integer(where, "max_attempts", self.max_attempts, 1)
        radii = _sizes_for(where, self.sizes, _stream(self.seed, _SIZES), self.count, self.mass, self.density)
        radii.setflags(write=False)
        _check_fits(where, self.region, self.bounding_ratio * radii)
        object.__setattr__(self, "_radii", radii)
        if self.random_orientation:
            quats = random_quaternions(_stream(self.seed, _ORIENT), len(radii))
        else:
            quats = np.tile([0.0, 0.0, 0.0, 1.0], (len(radii), 1))
        quats.setflags(write=False)
        object.__setattr__(self, "_quats", quats)
        if self.interval is None:
            if self.rate is not None:
                interval = 1.0 / self.rate
            else:
                interval = float(self.masses.max()) / self.mass_rate if len(radii) else 1.0
            object.__setattr__(self, "interval", interval)
        else:
            object.__setattr__(self, "interval", positive(where, "interval", self.interval, "an interval > 0 s"))

    # -- what the engine preallocates and reads

    def capacity(self) -> int:
        """Exact number of particles this factory creates."""
        return len(self._radii)

    @property
    def radii(self) -> np.ndarray:
        """Pre-drawn sizes in release order [m], shape (capacity,), read-only."""
        return self._radii

    @property
    def masses(self) -> np.ndarray:
        """Particle masses density * 4/3 pi r^3 [kg], shape (capacity,) (needs ``density``)."""
        check(
            self.density is not None,
            "DynamicFactory",
            "density",
            self.density,
            "a density > 0 kg/m^3 to compute masses",
        )
        return self.density * sphere_volume(self._radii)

    @property
    def quaternions(self) -> np.ndarray:
        """Orientations (x, y, z, w) in release order, shape (capacity, 4), read-only."""
        return self._quats

    def world_rng(self, world_seed: int, first: int) -> np.random.Generator:
        """Placement stream of one batched world with its own seed (> 0), for particles from ``first`` on:
        independent of the factory's own stream (world seed 0) and of every other world seed."""
        return _stream(self.seed, _WORLD, int(world_seed), int(first))

    def placement_rng(self) -> np.random.Generator:
        """A fresh Generator for :meth:`place`, derived from ``seed`` (independent of the size stream)."""
        return _stream(self.seed, _PLACE)

    def plan(self) -> list[tuple[float, int]]:
        """Release batches [(time [s], count)], in time order, non-empty, counts summing to ``capacity()``."""
        n = self.capacity()
        if n == 0:
            return []
        if self.rate is not None:
            per_batch = self.rate * self.interval
            k_last = math.ceil(n / per_batch * (1.0 - _ROUND))
            k = np.arange(1, k_last + 1, dtype=float)
            cum = np.floor(k * per_batch * (1.0 + _ROUND)).astype(np.int64)
        else:
            cum_mass = np.cumsum(self.masses)
            per_batch = self.mass_rate * self.interval
            k_last = math.ceil(cum_mass[-1] / per_batch * (1.0 - _ROUND))
            k = np.arange(1, k_last + 1, dtype=float)
            cum = np.searchsorted(cum_mass, k * per_batch * (1.0 + _ROUND), side="right")
        cum = np.minimum(cum, n)
        cum[-1] = n  # the remainder, should round-off leave one behind
        counts = np.diff(cum, prepend=0)
        nonzero = np.flatnonzero(counts)
        return [(self.start_time + float(k[i]) * self.interval, int(counts[i])) for i in nonzero]

    def place(self, rng, count: int, existing_x=None, existing_r=None, *, first: int):
        """Positions for particles ``first .. first + count - 1`` (release order), clear of each other and of
        ``existing`` particles (centres (m, 3) [m], bounding radii (m,) [m]).

        A crowded region may not take the whole batch: the particles are tried in release order and the
        returned arrays cover the leading ``placed <= count`` of them (a particle gives up after
        ``max_attempts`` proposals). The caller releases those and defers the rest, e.g. by calling again
        with ``first + placed`` at the next batch.

        Args:
            rng: ``numpy.random.Generator`` (e.g. one :meth:`placement_rng` made once per run), integer seed,
                or None for a stream derived from ``seed`` and ``first``; reproducible run to run either way,
                but None repeats the same proposals when a deferred batch is retried with the same
                ``first``, which only helps if the particles in the way have moved.
            count: particles wanted now.
            first: index of the first particle (the number released so far).

        Returns:
            x: centres [m], shape (placed, 3); r: sizes [m], shape (placed,) = ``radii[first:first + placed]``.
        """
        where = "DynamicFactory.place"
        first = _count(where, "first", first)
        count = _count(where, "count", count)
        check(
            first + count <= self.capacity(),
            where,
            "count",
            count,
            f"at most capacity - first = {self.capacity() - first}",
        )
        ex_x, ex_r = _check_existing(where, existing_x, existing_r)
        rng = _stream(self.seed, _PLACE, first) if rng is None else _rng(rng)
        r = self._radii[first : first + count]
        x, placed = _rsa(self.region, self.bounding_ratio * r, np.arange(count), rng, ex_x, ex_r, self.max_attempts)
        lead = int(np.argmin(placed)) if not placed.all() else count
        return x[:lead], r[:lead].copy()
