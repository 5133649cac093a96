"""The angle-of-repose measures of the main job, on synthetic cones with a known angle."""

import math

import numpy as np
import pytest

from warpdem.pile import angle_cone, angle_surface_fit


def _cone(angle_deg, base_radius=0.05, r=0.001, seed=0):
    """Spheres filling a cone of the given slope (centres one radius under the surface)."""
    rng = np.random.default_rng(seed)
    pts = []
    h = base_radius * math.tan(math.radians(angle_deg))
    for _ in range(40000):
        x, y = rng.uniform(-base_radius, base_radius, 2)
        rho = math.hypot(x, y)
        if rho > base_radius:
            continue
        top = h * (1 - rho / base_radius)
        z = rng.uniform(0, max(top - r, 0)) if top > r else 0.0
        pts.append((x, y, z))
    return np.array(pts), np.full(len(pts), r)


@pytest.mark.parametrize("angle", [20.0, 30.0, 45.0])
def test_surface_fit_recovers_cone_angle(angle):
    """Line fits of the highest tops per radial bin, over 8 slices, recover a synthetic cone's slope within 1.5 deg."""
    x, r = _cone(angle)
    mean, sd, per = angle_surface_fit(x, r)
    assert len(per) == 8
    assert mean == pytest.approx(angle, abs=1.5)


def test_cone_formula_on_exact_cone():
    """atan(2h/d) returns the slope of a full cone within 2 deg (the base diameter uses the 98th percentile)."""
    x, r = _cone(30.0)
    assert angle_cone(x, r) == pytest.approx(30.0, abs=2.0)
