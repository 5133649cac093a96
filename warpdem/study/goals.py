"""Desirability goals of a study's responses (Derringer and Suich 1980, as Design-Expert names them): what each
response should do, for the multi-response optimisation of :func:`warpdem.study.analysis.optimize_desirability`.
Light on purpose: the study file's loader validates goals without importing the statistics."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["GOALS", "Goal"]

GOALS = ("maximize", "minimize", "target", "in_range")
"""Desirability goals of a response (Derringer and Suich 1980, as Design-Expert names them)."""


@dataclass(frozen=True)
class Goal:
    """One response's goal for :func:`desirability`: ``kind`` in :data:`GOALS`, the limits ``low`` < ``high``
    (response units), ``target`` (for ``target``, strictly between them), the shape ``weight`` (> 0; 1 linear,
    above 1 stricter near the goal; ``weight_high`` for a target's upper side, default ``weight``) and the
    ``importance`` (1 to 5) of the response in the overall desirability."""

    kind: str
    low: float
    high: float
    target: float | None = None
    weight: float = 1.0
    weight_high: float | None = None
    importance: int = 3

    def __post_init__(self):
        def bad(field_: str, value, allowed: str):
            return ValueError(f"Goal: {field_} = {value!r}; expected {allowed}")

        if self.kind not in GOALS:
            raise bad("kind", self.kind, " | ".join(GOALS))
        if not (math.isfinite(self.low) and math.isfinite(self.high) and self.low < self.high):
            raise bad("low/high", (self.low, self.high), "finite limits with low < high")
        if self.kind == "target" and (self.target is None or not self.low < self.target < self.high):
            raise bad("target", self.target, f"a value strictly between low {self.low} and high {self.high}")
        for name, w in (("weight", self.weight), ("weight_high", self.weight_high)):
            if w is not None and not (math.isfinite(w) and w > 0):
                raise bad(name, w, "a number > 0")
        if self.importance not in (1, 2, 3, 4, 5):
            raise bad("importance", self.importance, "an integer from 1 to 5")

    def d(self, y) -> np.ndarray:
        """Individual desirability of the values ``y``, in [0, 1]."""
        y = np.asarray(y, dtype=float)
        lo, hi, w = self.low, self.high, self.weight
        if self.kind == "maximize":
            return np.clip((y - lo) / (hi - lo), 0.0, 1.0) ** w
        if self.kind == "minimize":
            return np.clip((hi - y) / (hi - lo), 0.0, 1.0) ** w
        if self.kind == "in_range":
            return ((y >= lo) & (y <= hi)).astype(float)
        t, w2 = self.target, self.weight if self.weight_high is None else self.weight_high
        below = np.clip((y - lo) / (t - lo), 0.0, 1.0) ** w
        above = np.clip((hi - y) / (hi - t), 0.0, 1.0) ** w2
        return np.where(y <= t, below, above)
