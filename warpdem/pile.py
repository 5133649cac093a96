"""A small poured pile on a plate and its angle of repose: the main job until the study runner lands.

A column of spheres (jittered lattice inside a cylinder of radius ``column_radius``) collapses onto
a rough plate and settles into a cone. The angle of repose is measured two ways:
(a) surface line fit per azimuthal slice: the highest sphere top per radial bin, apex and toe
    zones dropped, a straight line fitted, the mean and SD over slices reported;
(b) the cone formula atan(2 h / d) with h the pile height and d the base diameter.
"""

from __future__ import annotations

import math
import time

import numpy as np

from .builder import ModelBuilder
from .materials import Material
from .solver import Solver, SolverOptions


def build_pile(count: int = 800, device: str = "cpu", seed: int = 1, radius: float = 0.002,
               column_radius: float = 0.025, mu_s: float = 0.8, mu_r: float = 0.4):
    """Model of a column of ``count`` spheres (radius +-10 %) above a plate."""
    rng = np.random.default_rng(seed)
    spacing = 2.25 * radius
    g = np.arange(-column_radius, column_radius + 1e-12, spacing)
    xy = np.array([(x, y) for x in g for y in g if x * x + y * y <= (column_radius - radius) ** 2])
    layers = int(math.ceil(count / len(xy)))
    pts = np.concatenate([np.column_stack([xy, np.full(len(xy), 1.2 * radius + k * spacing)]) for k in range(layers)])
    pts = pts[:count]
    pts[:, :2] += rng.uniform(-0.1 * radius, 0.1 * radius, (len(pts), 2))
    b = ModelBuilder()
    b.add_material(Material("grain", density=1500.0, youngs_modulus=5e6, poisson_ratio=0.3))
    b.add_material(Material("plate", density=7900.0, youngs_modulus=1.9e11, poisson_ratio=0.3))
    b.set_interaction("grain", "grain", restitution=0.5, static_friction=mu_s, rolling_friction=mu_r,
                      rolling_model="epsd")
    b.set_interaction("grain", "plate", restitution=0.5, static_friction=mu_s, rolling_friction=mu_r,
                      rolling_model="epsd")
    b.add_plane((0, 0, 0), (0, 0, 1), "plate")
    b.add_spheres(pts, radius * rng.uniform(0.9, 1.1, len(pts)), "grain")
    return b.finalize(device)


def angle_surface_fit(x: np.ndarray, r: np.ndarray, slices: int = 8, bins: int = 12):
    """Angle of repose [deg] by line fits of the pile surface in ``slices`` azimuthal sectors.

    Args:
        x: sphere centres [m], shape (n, 3), the plate at z = 0 and the pile axis at x = y = 0.
        r: radii [m], shape (n,).
    Returns:
        (mean angle, SD over slices, per-slice angles), in degrees.
    """
    top = x[:, 2] + r
    rho = np.hypot(x[:, 0], x[:, 1])
    phi = np.arctan2(x[:, 1], x[:, 0])
    on_pile = top > 0
    extent = np.percentile(rho[on_pile], 98)
    angles = []
    for s in range(slices):
        lo = -math.pi + 2 * math.pi * s / slices
        sel = (phi >= lo) & (phi < lo + 2 * math.pi / slices)
        edges = np.linspace(0, extent, bins + 1)
        rb, zb = [], []
        for k in range(bins):
            m = sel & (rho >= edges[k]) & (rho < edges[k + 1])
            if np.any(m):
                rb.append(0.5 * (edges[k] + edges[k + 1]))
                zb.append(top[m].max())
        rb, zb = np.array(rb), np.array(zb)
        # drop the rounded apex (inner 20 %) and the toe (outer 20 %)
        keep = (rb > 0.2 * extent) & (rb < 0.8 * extent)
        if keep.sum() >= 3:
            slope = np.polyfit(rb[keep], zb[keep], 1)[0]
            angles.append(math.degrees(math.atan(-slope)))
    a = np.array(angles)
    return float(a.mean()), float(a.std(ddof=1)) if len(a) > 1 else 0.0, a


def angle_cone(x: np.ndarray, r: np.ndarray) -> float:
    """Angle of repose [deg] from the cone formula atan(2h/d): h the highest top, d twice the 98th-percentile base radius."""
    h = float((x[:, 2] + r).max())
    base = x[:, 2] < 2.5 * r.max()
    d = 2.0 * float(np.percentile(np.hypot(x[base, 0], x[base, 1]) + r[base], 98))
    return math.degrees(math.atan(2 * h / d))


def run_pile(device: str = "cpu", count: int = 800, seed: int = 1, duration: float = 1.5,
             ke_threshold: float = 1e-6) -> dict:
    """Pour and settle the pile; stops at ``duration`` [s] or once kinetic energy per mass < ``ke_threshold`` [J/kg]."""
    model = build_pile(count, device, seed)
    solver = Solver(model, SolverOptions())
    state, contacts = model.state(), solver.contacts()
    t0 = time.perf_counter()
    chunk = max(1, int(0.05 / solver.dt))
    while state.time < duration:
        state = solver.run(state, contacts, chunk)
        v = state.sphere_v.numpy()
        if state.time > 1.0 and 0.5 * float(np.mean(np.sum(v * v, axis=1))) < ke_threshold:
            break
    wall = time.perf_counter() - t0
    x, r = state.sphere_x.numpy(), model.sphere_radius.numpy()
    mean, sd, per = angle_surface_fit(x, r)
    return {"spheres": model.sphere_count, "simulated_s": state.time, "wall_s": wall, "dt": solver.dt,
            "angle_fit_deg": mean, "angle_fit_sd_deg": sd, "slices": len(per),
            "angle_cone_deg": angle_cone(x, r), "seed": seed}
