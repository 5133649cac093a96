"""The record every verification case returns (``warpdem verify`` prints and saves them)."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

RIGID = 1.0e6  # factor on E for a "rigid" wall material: E* then differs from the sphere's own by < 1e-6


@dataclass
class Record:
    """One verified quantity."""

    case: str
    name: str
    value: float
    expected: float
    unit: str
    tolerance: float
    """Allowed relative error (or absolute, when ``absolute`` is True)."""
    absolute: bool = False

    @property
    def error(self) -> float:
        if self.absolute:
            return abs(self.value - self.expected)
        return abs(self.value - self.expected) / max(abs(self.expected), 1e-300)

    @property
    def passed(self) -> bool:
        return bool(np.isfinite(self.value) and self.error <= self.tolerance)

    def as_json(self) -> dict:
        d = {k: (float(v) if isinstance(v, (float, np.floating)) else v) for k, v in asdict(self).items()}
        d.update(
            {
                "name": f"{self.case}: {self.name}",
                "quantity": self.name,
                "error": float(self.error),
                "pass": self.passed,
            }
        )
        return d
