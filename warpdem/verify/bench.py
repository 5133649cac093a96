"""Throughput and memory benchmark: a settled bed of monodisperse spheres (Hertz-Mindlin with history).

The bed matches benchmarks/lammps_bed.py: d = 5 mm, rho = 2500 kg/m^3, E = 1e8 Pa, nu = 0.3, e = 0.5,
mu = 0.5, dt = 1e-5 s, a jittered lattice of 5 layers dropped into a box with a floor and four side
walls, settled, then timed. A bed whose automatic step is shorter (the clump bed's 1 mm sub-spheres) runs at
its automatic step instead, so that no bench runs above 20 % of the Rayleigh time.
"""

from __future__ import annotations

import math
import time

import numpy as np
import warp as wp

from warpdem.engine.builder import ModelBuilder
from warpdem.engine.materials import Material
from warpdem.engine.solver import Solver, SolverOptions
from warpdem.engine.types import RollingModel

DIAMETER = 0.005
DT = 1e-5
"""The bench's time step [s]: the plain-sphere bed keeps it, so its figures compare with older records."""
ROLLING_FRICTION = 0.1
"""Rolling friction coefficient of every pair when the bench runs a rolling model (``rolling``)."""
ROLLING_CHOICES = tuple(m.name.lower() for m in RollingModel)
"""The bench's ``rolling`` values: a :class:`RollingModel` name in lower case ("none": no rolling friction)."""
SETTLE_TIME = 0.2
"""Simulated time [s] the bed settles for before it is timed (unless ``settle_steps`` is given)."""
UNITS = {
    "dt": "s",
    "clump_steps_per_s": "1/s",
    "wall_s": "s",
    "particle_steps_per_s": "1/s",
    "bytes_per_sphere": "B",
    "contact_bytes_per_contact": "B",
    "settle_s": "s",
    "ke_per_mass": "J/kg",
}
"""SI unit of each figure of :func:`run_bench` that has one (the others are counts, ratios or labels)."""


def bench_template(spheres: int):
    """A clump of ``spheres`` (8: a 2 x 2 x 2 block of overlapping spheres) that fits a sphere of d = 5 mm."""
    from warpdem.engine.clumps import ClumpTemplate

    if spheres != 8:
        raise ValueError(f"bench: clumps = {spheres} is not allowed; expected 8 (the issue's benchmark clump)")
    a, rs = 0.12 * DIAMETER, 0.2 * DIAMETER
    offsets = [(x, y, z) for x in (-a, a) for y in (-a, a) for z in (-a, a)]
    return ClumpTemplate.from_spheres("bench8", offsets, [rs] * 8)


def _box_mesh(side: float, height: float, cells: int):
    """Floor and four side walls of the bed's box as one mesh, each face split into cells x cells quads."""
    g = np.linspace(0.0, 1.0, cells + 1)
    u, v = np.meshgrid(g, g, indexing="ij")
    quads = [
        (i * (cells + 1) + j, (i + 1) * (cells + 1) + j, (i + 1) * (cells + 1) + j + 1, i * (cells + 1) + j + 1)
        for i in range(cells)
        for j in range(cells)
    ]
    faces = [
        np.stack([u * side, v * side, 0 * u], -1),
        np.stack([0 * u, u * side, v * height], -1),
        np.stack([0 * u + side, u * side, v * height], -1),
        np.stack([u * side, 0 * u, v * height], -1),
        np.stack([u * side, 0 * u + side, v * height], -1),
    ]
    verts, tris = [], []
    for f in faces:
        base = sum(len(x) for x in verts)
        verts.append(f.reshape(-1, 3))
        tris.extend(
            [(base + a, base + b, base + c) for a, b, c, d in quads]
            + [(base + a, base + c, base + d) for a, b, c, d in quads]
        )
    return np.concatenate(verts), np.array(tris)


def build_bed(
    count: int,
    device: str,
    seed: int = 1,
    clumps: int = 0,
    walls: str = "planes",
    law: str = "HM",
    mesh_cells: int = 40,
    worlds: int = 1,
    shuffle: bool = False,
    rolling: str = "none",
):
    """Model of ``count`` bodies per world (rounded to full 5-layer lattices) in a square box, replicated into
    ``worlds`` identical worlds; returns (model, side [m]).

    ``clumps`` = 8 makes each body an 8-sphere clump (random orientation) instead of a sphere; ``walls`` =
    "mesh" replaces the five planes by one triangle mesh of 10 mesh_cells^2 triangles (a funnel-sized mesh);
    ``law`` (HM, JKR, EEPA) sets the contact law of every pair, with moderate cohesion. ``shuffle`` numbers the
    same bodies in a random order (a lattice is numbered row by row, so neighbours are near in memory; a poured
    or flowing bed's numbering is not). ``rolling`` (one of ``ROLLING_CHOICES``) gives every pair that rolling
    model with mu_r = ``ROLLING_FRICTION``, so the rolling branches of the step are timed too.
    """
    layers = 5
    per_side = max(2, int(round(math.sqrt(count / layers))))
    side = per_side * DIAMETER
    rng = np.random.default_rng(seed)
    i, j, k = np.meshgrid(np.arange(per_side), np.arange(per_side), np.arange(layers), indexing="ij")
    pts = np.stack(
        [(i + 0.5) * DIAMETER, (j + 0.5) * DIAMETER, 0.5 * DIAMETER + k * 1.1 * DIAMETER + 0.0005], axis=-1
    ).reshape(-1, 3)
    pts[:, :2] += rng.uniform(-2e-4, 2e-4, (len(pts), 2))
    if shuffle:
        pts = pts[np.random.default_rng(seed + 1).permutation(len(pts))]
    b = ModelBuilder()
    b.add_material(Material("bed", density=2500.0, youngs_modulus=1e8, poisson_ratio=0.3))
    cohesion = {
        "HM": {},
        "JKR": {"law": "JKR", "surface_energy": 0.5},
        "EEPA": {"law": "EEPA", "surface_energy": 0.5, "pull_off_force": -1e-4, "plasticity_ratio": 0.3},
    }
    if law not in cohesion:
        raise ValueError(f"bench: law = {law!r} is not allowed; expected HM, JKR or EEPA")
    if rolling not in ROLLING_CHOICES:
        raise ValueError(f"bench: rolling = {rolling!r} is not allowed; expected one of {', '.join(ROLLING_CHOICES)}")
    roll = (
        {"rolling_friction": 0.0}
        if rolling == "none"
        else {"rolling_friction": ROLLING_FRICTION, "rolling_model": RollingModel[rolling.upper()]}
    )
    b.set_default_interaction(restitution=0.5, static_friction=0.5, **roll, **cohesion[law])
    if walls == "planes":
        b.add_plane((0, 0, 0), (0, 0, 1), "bed")
        b.add_plane((0, 0, 0), (1, 0, 0), "bed")
        b.add_plane((side, 0, 0), (-1, 0, 0), "bed")
        b.add_plane((0, 0, 0), (0, 1, 0), "bed")
        b.add_plane((0, side, 0), (0, -1, 0), "bed")
    elif walls == "mesh":
        # triangles of about two diameters or more, up to mesh_cells per face edge (a funnel has ~10^4)
        cells = int(max(2, min(mesh_cells, side / (2.0 * DIAMETER))))
        v, t = _box_mesh(side, layers * 1.1 * DIAMETER + DIAMETER, cells)
        b.add_wall_mesh(v, t, "bed", name="box")
    else:
        raise ValueError(f"bench: walls = {walls!r} is not allowed; expected planes or mesh")
    if clumps:
        from warpdem.engine.factories import random_quaternions

        b.add_clumps(bench_template(clumps), pts, "bed", orientations=random_quaternions(rng, len(pts)))
    else:
        b.add_spheres(pts, 0.5 * DIAMETER, "bed")
    b.replicate(worlds)
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


def kernel_profile(solver, state, contacts, steps: int, top: int = 12):
    """Run ``steps`` eager steps under Warp's timer (CUDA only) and print kernels, copies and fills by GPU time.
    Returns (state, milliseconds of kernel time per step)."""
    wp.timing_begin(cuda_filter=wp.TIMING_KERNEL | wp.TIMING_MEMCPY | wp.TIMING_MEMSET)
    state = solver.run(state, contacts, steps, use_graph=False)
    per = {}
    for r in wp.timing_end():
        per.setdefault(r.name, [0, 0.0])
        per[r.name][0] += 1
        per[r.name][1] += r.elapsed
    total = sum(v[1] for v in per.values())
    for name, (count, ms) in sorted(per.items(), key=lambda kv: -kv[1][1])[:top]:
        print(f"   {name[:60]:60s} {count:6d} launches {ms:9.2f} ms {100 * ms / max(total, 1e-12):5.1f} %")
    return state, total / steps


def device_bytes(obj) -> int:
    """Bytes of every Warp array held by a Model/State/Contacts (hash grid excluded)."""
    total = 0
    for v in vars(obj).values():
        if isinstance(v, wp.array):
            total += v.capacity
        elif isinstance(v, dict):
            total += sum(a.capacity for a in v.values() if isinstance(a, wp.array))
    return total


def run_bench(
    device: str = "cpu",
    count: int | None = None,
    steps: int | None = None,
    settle_steps: int | None = None,
    clumps: int = 0,
    walls: str = "planes",
    law: str = "HM",
    worlds: int = 1,
    shuffle: bool = False,
    rolling: str = "none",
) -> dict:
    """Settle the bed, then time ``steps`` steps; returns the figures.

    ``count`` is the bodies (spheres or clumps) of one world; the figures count every sphere of all ``worlds``.
    The step is ``DT`` or the solver's automatic step (20 % of the Rayleigh time), whichever is shorter.
    """
    is_cuda = wp.get_device(device).is_cuda
    count = count or (1_000_000 if is_cuda else 2000)
    steps = steps or (2000 if is_cuda else 5000)
    model, side = build_bed(
        count, device, clumps=clumps, walls=walls, law=law, worlds=worlds, shuffle=shuffle, rolling=rolling
    )
    mesh_capacity = 32 if walls == "mesh" else 16
    solver = Solver(model, SolverOptions(dt=None, mesh_capacity=mesh_capacity))
    if solver.dt > DT:
        # the automatic step is the solver's to compute (EEPA's unloading branch included); only cap it
        del solver
        solver = Solver(model, SolverOptions(dt=DT, mesh_capacity=mesh_capacity))
    state = model.state()
    contacts = solver.contacts()
    t0 = time.perf_counter()
    # settle for SETTLE_TIME of simulated time whatever the step (20,000 steps of the sphere bed's 1e-5 s)
    settle_steps = settle_steps if settle_steps is not None else int(round(SETTLE_TIME / solver.dt))
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
        "law": law,
        "rolling": rolling,
        "worlds": model.world_count,
        "shuffled": shuffle,
        "dt": solver.dt,
        "walls": walls if walls == "planes" else f"mesh ({model.triangle_wall.shape[0]} triangles)",
        "clumps": model.clump_count,
        "clump_steps_per_s": model.clump_count * steps / wall if model.clump_count else 0.0,
        "spheres": n,
        "steps": steps,
        "wall_s": wall,
        "particle_steps_per_s": n * steps / wall,
        "contacts_per_sphere": z,
        "bytes_per_sphere": (b_model + b_state + b_contacts) / n,
        "contact_bytes_per_contact": b_contacts / max(z * n, 1.0),
        "neighbor_capacity": contacts.neighbor_capacity,
        "settle_steps": settle_steps,
        "settle_s": settle_s,
        "ke_per_mass": ke,
    }
