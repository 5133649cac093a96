"""Throughput and memory benchmark: a settled bed of monodisperse spheres (Hertz-Mindlin with history).

The bed matches benchmarks/lammps_bed.py: d = 5 mm, rho = 2500 kg/m^3, E = 1e8 Pa, nu = 0.3, e = 0.5,
mu = 0.5, dt = 1e-5 s, a jittered lattice of 5 layers dropped into a box with a floor and four side
walls, settled, then timed.
"""

from __future__ import annotations

import math
import time

import numpy as np
import warp as wp

from .builder import ModelBuilder
from .materials import Material
from .solver import Solver, SolverOptions

DIAMETER = 0.005


def build_bed(count: int, device: str, seed: int = 1):
    """Model of ``count`` spheres (rounded to full 5-layer lattices) in a square box; returns (model, side [m])."""
    layers = 5
    per_side = max(2, int(round(math.sqrt(count / layers))))
    side = per_side * DIAMETER
    rng = np.random.default_rng(seed)
    i, j, k = np.meshgrid(np.arange(per_side), np.arange(per_side), np.arange(layers), indexing="ij")
    pts = np.stack([(i + 0.5) * DIAMETER, (j + 0.5) * DIAMETER, 0.5 * DIAMETER + k * 1.1 * DIAMETER + 0.0005],
                   axis=-1).reshape(-1, 3)
    pts[:, :2] += rng.uniform(-2e-4, 2e-4, (len(pts), 2))
    b = ModelBuilder()
    b.add_material(Material("bed", density=2500.0, youngs_modulus=1e8, poisson_ratio=0.3))
    b.set_default_interaction(restitution=0.5, static_friction=0.5, rolling_friction=0.0)
    b.add_plane((0, 0, 0), (0, 0, 1), "bed")
    b.add_plane((0, 0, 0), (1, 0, 0), "bed")
    b.add_plane((side, 0, 0), (-1, 0, 0), "bed")
    b.add_plane((0, 0, 0), (0, 1, 0), "bed")
    b.add_plane((0, side, 0), (0, -1, 0), "bed")
    b.add_spheres(pts, 0.5 * DIAMETER, "bed")
    return b.finalize(device), side


def contacts_per_sphere(state, contacts, model) -> float:
    """Mean number of touching partners (spheres and walls) per sphere."""
    x = state.sphere_x.numpy()
    r = model.sphere_radius.numpy()
    cnt = contacts.neighbor_count.numpy()
    idx = contacts.neighbor_index.numpy()
    total = 0
    for k in range(idx.shape[0]):
        live = k < cnt
        j = idx[k][live]
        i = np.flatnonzero(live)
        total += int(np.sum(np.linalg.norm(x[j] - x[i], axis=1) < r[i] + r[j]))
    pn = model.plane_normal.numpy()
    pp = model.plane_point.numpy()
    for p in range(len(pn)):
        total += int(np.sum((x - pp[p]) @ pn[p] < r))
    return total / len(x)


def device_bytes(obj) -> int:
    """Bytes of every Warp array held by a Model/State/Contacts (hash grid excluded)."""
    total = 0
    for v in vars(obj).values():
        if isinstance(v, wp.array):
            total += v.capacity
        elif isinstance(v, dict):
            total += sum(a.capacity for a in v.values() if isinstance(a, wp.array))
    return total


def run_bench(device: str = "cpu", count: int | None = None, steps: int | None = None,
              settle_steps: int = 20000) -> dict:
    """Settle the bed, then time ``steps`` steps; returns the figures."""
    is_cuda = wp.get_device(device).is_cuda
    count = count or (1_000_000 if is_cuda else 2000)
    steps = steps or (2000 if is_cuda else 5000)
    model, side = build_bed(count, device)
    solver = Solver(model, SolverOptions(dt=1e-5))
    state = model.state()
    contacts = solver.contacts()
    t0 = time.perf_counter()
    state = solver.run(state, contacts, settle_steps)
    wp.synchronize_device(device)
    settle_s = time.perf_counter() - t0
    # warm the timed path (graph capture on CUDA) before timing
    state = solver.run(state, contacts, 2)
    wp.synchronize_device(device)
    t0 = time.perf_counter()
    state = solver.run(state, contacts, steps)
    wp.synchronize_device(device)
    wall = time.perf_counter() - t0
    z = contacts_per_sphere(state, contacts, model)
    n = model.sphere_count
    b_model, b_state, b_contacts = device_bytes(model), 2 * device_bytes(state), device_bytes(contacts)
    ke = 0.5 * float(np.sum(state.sphere_v.numpy() ** 2)) / n
    return {
        "device": str(wp.get_device(device).name if is_cuda else "cpu"),
        "spheres": n,
        "steps": steps,
        "wall_s": wall,
        "particle_steps_per_s": n * steps / wall,
        "contacts_per_sphere": z,
        "bytes_per_sphere": (b_model + b_state + b_contacts) / n,
        "contact_bytes_per_contact": b_contacts / max(z * n, 1.0),
        "neighbor_capacity": contacts.neighbor_capacity,
        "settle_s": settle_s,
        "ke_per_mass": ke,
    }
