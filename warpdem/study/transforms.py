"""Response transforms of Design-Expert's analysis: the model is fitted to y' = f(y + k), its ANOVA, diagnostics
and equation are on that scale, and its predictions are brought back to the response's own units by f's inverse
(the back-transformed mean is then the median of the response where the errors are symmetric on the model scale,
as Design-Expert reports it).

Light (NumPy only), so that a study file's ``transform`` is checked when it is read.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from warpdem.errors import InputError

TRANSFORMS = ("none", "sqrt", "ln", "log10", "inverse_sqrt", "inverse", "power")
"""The transform names a study accepts: Design-Expert's None, Square Root, Natural Log, Base 10 Log, Inverse Sqrt,
Inverse and Power (y + k)^lambda."""

_POWER = {"none": 1.0, "sqrt": 0.5, "inverse_sqrt": -0.5, "inverse": -1.0}
"""The transforms that are powers of y + k (ln and log10 are the limit lambda = 0)."""


@dataclass(frozen=True)
class Transform:
    """y' = f(y + k): ``kind`` one of :data:`TRANSFORMS`, ``power`` the exponent of ``kind = "power"`` (not 0:
    that is ``ln``), ``k`` a constant added first (so that y + k > 0 where f needs it)."""

    kind: str = "none"
    power: float | None = None
    k: float = 0.0

    def __post_init__(self):
        if self.kind not in TRANSFORMS:
            raise InputError(f"transform = {self.kind!r} is not allowed; expected one of {', '.join(TRANSFORMS)}")
        if self.kind == "power":
            if self.power is None or not math.isfinite(float(self.power)) or float(self.power) == 0:
                raise InputError(
                    f"transform_power = {self.power!r} is not allowed for transform = 'power'; expected a finite "
                    "exponent other than 0 (0 is transform = 'ln')"
                )
        elif self.power is not None:
            raise InputError(
                f"transform_power = {self.power!r} is not allowed for transform = {self.kind!r}; it is read only "
                "with transform = 'power'"
            )
        if not math.isfinite(float(self.k)):
            raise InputError(f"transform_k = {self.k!r} is not allowed; expected a finite constant")

    @property
    def exponent(self) -> float | None:
        """lambda of the power family (None for the logarithms)."""
        return float(self.power) if self.kind == "power" else _POWER.get(self.kind)

    @property
    def decreasing(self) -> bool:
        """True when f falls as y rises (a negative power): intervals swap their ends when brought back."""
        lam = self.exponent
        return lam is not None and lam < 0

    def _domain(self) -> str:
        lam = self.exponent
        if lam is None or lam < 0 or (lam != int(lam)):
            return "positive"
        return "any" if lam >= 1 else "non-negative"

    def forward(self, y, name: str = "the response"):
        """f(y + k), elementwise; raises ValueError naming ``name`` and the first value outside f's domain."""
        u = np.asarray(y, dtype=float) + float(self.k)
        dom = self._domain()
        bad = ~np.isfinite(u) | ((u <= 0) if dom == "positive" else (u < 0) if dom == "non-negative" else False)
        if np.any(bad):
            v = float(np.asarray(y, dtype=float).reshape(-1)[np.flatnonzero(np.reshape(bad, -1))[0]])
            need = "> 0" if dom == "positive" else ">= 0"
            raise InputError(
                f"{name} = {v!r} cannot be transformed by {self.label('y')}: y + k must be {need}; "
                f"choose transform_k (now {self.k:g}) so that every value qualifies, or another transform"
            )
        if self.kind == "ln":
            return np.log(u)
        if self.kind == "log10":
            return np.log10(u)
        return u**self.exponent

    def inverse(self, yt):
        """y from y' (the response's own units), elementwise."""
        v = np.asarray(yt, dtype=float)
        if self.kind == "ln":
            u = np.exp(v)
        elif self.kind == "log10":
            u = 10.0**v
        else:
            lam = self.exponent
            with np.errstate(invalid="ignore", divide="ignore"):
                u = np.sign(v) * np.abs(v) ** (1.0 / lam) if lam == int(lam) and int(lam) % 2 else v ** (1.0 / lam)
        return u - float(self.k)

    def interval(self, lo: float, hi: float) -> tuple[float, float]:
        """A model-scale interval [lo, hi] in the response's units (ends swapped for a falling f)."""
        a, b = float(self.inverse(lo)), float(self.inverse(hi))
        return (b, a) if self.decreasing else (a, b)

    def label(self, name: str) -> str:
        """How the model's left-hand side reads, e.g. ``ln(aor_deg)``, ``(aor_deg + 1)^0.25``."""
        y = f"{name} + {self.k:g}" if self.k else name
        if self.kind == "none":
            return name
        if self.kind in ("ln", "log10"):
            return f"{self.kind}({y})"
        if self.kind == "sqrt":
            return f"sqrt({y})"
        if self.kind == "inverse":
            return f"1/({y})"
        if self.kind == "inverse_sqrt":
            return f"1/sqrt({y})"
        return f"({y})^{self.exponent:g}"


NONE = Transform()
"""The identity: the model is fitted to the response itself."""
