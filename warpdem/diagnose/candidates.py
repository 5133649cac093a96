"""The library of candidate model extensions a diagnosis tries (filled in by the pipeline work)."""

from __future__ import annotations

CANDIDATE_NAMES = (
    "cohesion",
    "plasticity",
    "shape",
    "size_distribution",
    "rolling_friction",
    "rolling_model",
    "wall_friction",
)
"""Names of the candidate extensions, in the order they are tried and reported."""
