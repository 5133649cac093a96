"""Run a scene: build the model, step it in output intervals, record what the rig measures, write results.

``run_scene`` is what ``warpdem run`` calls and what the study runner calls with several worlds (one design
point each). Between output ticks the solver runs captured steps with no host synchronisation; at a tick
the host reads positions, velocities and the walls' running impulses once.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
import warnings
from collections.abc import Generator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from warpdem.engine import suspect
from warpdem.engine.types import device_kind, host
from warpdem.errors import InputError, PhysicsWarning

from . import measure as ms
from .stage import SceneSpec, StageError, build, unload_keyframes


@dataclass
class RunResult:
    """Outcome of :func:`run_scene`: ``metrics`` per world (list of dicts) and the run's facts."""

    metrics: list
    info: dict = field(default_factory=dict)
    series: dict = field(default_factory=dict)


def _host(model):
    """Host copies of the static arrays the recorder needs."""
    h = {
        "radius": host(model.sphere_radius).astype(np.float64),
        "world": host(model.sphere_world),
        "clump": host(model.sphere_clump),
        "glued": host(model.sphere_wall),
        "material": host(model.sphere_material),
    }
    dens = host(model.material_density)
    w_of = h["world"] % dens.shape[0]
    h["density"] = dens[w_of, h["material"]]
    h["mass"] = h["density"] * host(model.sphere_body_volume)
    h["free"] = (h["clump"] < 0) & (h["glued"] < 0)
    if model.clump_count:
        cd = dens[host(model.clump_world) % dens.shape[0], host(model.clump_material)]
        h["clump_mass"] = cd * host(model.clump_volume)
        h["clump_world"] = host(model.clump_world)
        h["clump_first"] = host(model.clump_sphere_start)
    return h


def _motion(model, state, h) -> tuple[np.ndarray, np.ndarray]:
    """Mean translational kinetic energy per active particle [J] and the fastest particle's speed [m/s], in each
    world: two arrays of shape (world_count,)."""
    W = model.world_count
    act = host(state.sphere_active).astype(bool)
    v = host(state.sphere_v)
    sel = act & h["free"]
    e = np.zeros(W)
    n = np.zeros(W)
    fastest = np.zeros(W)
    v2 = np.sum(v[sel] ** 2, axis=1)
    np.add.at(e, h["world"][sel], 0.5 * h["mass"][sel] * v2)
    np.add.at(n, h["world"][sel], 1)
    np.maximum.at(fastest, h["world"][sel], v2)
    if model.clump_count:
        cv = host(state.clump_v)
        cact = act[h["clump_first"]]
        c2 = np.sum(cv[cact] ** 2, axis=1)
        np.add.at(e, h["clump_world"][cact], 0.5 * h["clump_mass"][cact] * c2)
        np.add.at(n, h["clump_world"][cact], 1)
        np.maximum.at(fastest, h["clump_world"][cact], c2)
    return e / np.maximum(n, 1), np.sqrt(fastest)


def _overlaps(model, state, h) -> dict:
    """:func:`warpdem.engine.suspect.overlaps` of the active particle spheres (glued wall coats left out)."""
    act = host(state.sphere_active).astype(bool) & (h["glued"] < 0)
    n = len(h["radius"])
    body = np.where(h["clump"] >= 0, h["clump"], n + np.arange(n))
    x = host(state.sphere_x).astype(np.float64)
    found = suspect.overlaps(x[act], h["radius"][act], h["world"][act], body[act], model.world_count)
    return {k: v.tolist() for k, v in found.items()}


def _escaped(model, state, h, piston: int) -> np.ndarray:
    """Particle spheres above the bar's face, or removed from the domain, in each world, shape (world_count,):
    at the force limit the whole bed lies below the bar, so these were squeezed past its rim."""
    act = host(state.sphere_active).astype(bool) & (h["glued"] < 0)
    face = float(host(state.wall_pose)[piston, 2])
    above = act & (host(state.sphere_x)[:, 2] > face)
    return np.bincount(h["world"][above], minlength=model.world_count) + host(state.world_removed)


def _bodies(model, state, h) -> np.ndarray:
    """Active bodies (free spheres and clumps) in each world, shape (world_count,)."""
    act = host(state.sphere_active).astype(bool)
    n = np.bincount(h["world"][act & h["free"]], minlength=model.world_count)
    if model.clump_count:
        n = n + np.bincount(h["clump_world"][act[h["clump_first"]]], minlength=model.world_count)
    return n


def _warning_lines(metrics: list[dict]) -> list[str]:
    """One line per kind of warning of a launch's worlds: the worlds and the first one's words."""
    lines = []
    for check in dict.fromkeys(x["check"] for mw in metrics for x in mw["warnings"]):
        hit = [(mw["world"], x["detail"]) for mw in metrics for x in mw["warnings"] if x["check"] == check]
        worlds = "world " if len(hit) == 1 else f"{len(hit)} worlds, e.g. world "
        lines.append(f"{worlds}{hit[0][0]}: {hit[0][1]}" if len(metrics) > 1 else hit[0][1])
    return lines


def _particle_mask(state, h, world: int) -> np.ndarray:
    """Mask of the active particle spheres (glued ones excluded) of ``world``, shape (sphere_count,)."""
    return host(state.sphere_active).astype(bool) & (h["glued"] < 0) & (h["world"] == world)


def _mean_diameter(h, world: int) -> float:
    """Mean diameter [m] of ``world``'s free particle spheres."""
    return 2.0 * float(np.mean(h["radius"][(h["world"] == world) & h["free"]]))


PILE_METRICS = (
    "detached",
    "particles",
    "pile_height_m",
    "angle_fit_deg",
    "angle_fit_sd_deg",
    "angle_fit_slices_deg",
    "angle_image_deg",
    "angle_image_sd_deg",
    "angle_cone_deg",
    "pile_offset_m",
    "angle_error",
)
"""The metrics :func:`measure_pile` writes: what a stored final state can be measured for again."""


def pile_select(x, r, m) -> tuple[np.ndarray, np.ndarray, int]:
    """The pile among one world's free particle spheres (centres ``x`` (n, 3) [m], radii ``r`` (n,) [m]) under the
    angle-of-repose measure settings ``m``: spheres below the base (rolled off the plate), those not connected
    to it (stuck to a lifted wall, in the air) and those lying apart from the pile on the plate are not the pile
    (:func:`measure.pile_spheres`). Returns its centres (k, 3) [m], radii (k,) [m] and how many spheres above the
    base were left out (``detached``)."""
    x, r = np.asarray(x, dtype=np.float64).reshape(-1, 3), np.asarray(r, dtype=np.float64).reshape(-1)
    keep = x[:, 2] - r > m.base_height - 2 * r.max(initial=0.0)
    x, r = x[keep], r[keep]
    on = ms.pile_spheres(x, r, base_z=m.base_height, apart=m.pile_apart) if len(r) else np.zeros(0, bool)
    return x[on], r[on], int(len(r) - on.sum())


def measure_pile(x, r, m) -> dict:
    """The pile metrics of one world (:data:`PILE_METRICS`) from its free particle spheres at the end of a run:
    centres ``x`` (n, 3) [m] and radii ``r`` (n,) [m] (glued spheres excluded), under the angle-of-repose measure
    settings ``m`` (a ``MeasureSpec``: base_height, center), on the pile :func:`pile_select` finds. Used at the end
    of a run and on a stored final state (a study's ``runs/<point_id>.npz``), so both give the same numbers."""
    x, r, detached = pile_select(x, r, m)
    mw = {
        "detached": detached,
        "particles": int(len(r)),
        "pile_height_m": float((x[:, 2] + r).max() - m.base_height) if len(r) else 0.0,
    }
    try:
        fit = ms.angle_surface_fit(x, r, base_z=m.base_height, center=m.center)
        img = ms.angle_image(x, r, base_z=m.base_height, center=m.center)
        mw.update(
            angle_fit_deg=fit["mean_deg"],
            angle_fit_sd_deg=fit["sd_deg"],
            angle_fit_slices_deg=list(map(float, fit["per_slice_deg"])),
            angle_image_deg=img["mean_deg"],
            angle_image_sd_deg=img["sd_deg"],
            angle_cone_deg=float(ms.angle_cone(x, r, base_z=m.base_height, center=m.center)),
            pile_offset_m=ms.pile_offset(x, r, center=m.center),
        )
    except ValueError as e:
        mw["angle_error"] = str(e)
    return mw


def _particles(model, state, h, world: int):
    """Centres (n, 3) and radii (n,) of the active particle spheres (glued ones excluded) of ``world``."""
    sel = _particle_mask(state, h, world)
    return host(state.sphere_x)[sel].astype(np.float64), h["radius"][sel]


def _frame(writer, model, state, h, spec, t):
    """Hand world 0 of ``state`` to the results writer."""
    act = host(state.sphere_active).astype(bool)
    x, v = host(state.sphere_x), host(state.sphere_v)
    loose = act & (h["clump"] < 0) & (h["world"] == 0)
    kw = dict(sphere_x=x[loose], sphere_r=h["radius"][loose], sphere_id=np.flatnonzero(loose), sphere_v=v[loose])
    if model.clump_count:
        sel = act[h["clump_first"]] & (h["clump_world"] == 0)
        ids = np.flatnonzero(sel)
        kw.update(
            clump_x=host(state.clump_x)[sel],
            clump_q=host(state.clump_q)[sel],
            clump_shape=np.asarray(model.clump_template)[sel],
            clump_scale=np.asarray(model.clump_scale)[sel],
            clump_id=ids,
            clump_v=host(state.clump_v)[sel],
        )
    if model.wall_count:
        kw["wall_pose"] = host(state.wall_pose)[: model.wall_count]
        counts = host(state.face_impact_count)[0]
        energy = host(state.face_impact_energy)[0]
        start = host(model.wall_face_start)
        kw["face_impacts"] = [counts[start[k] : start[k + 1]] for k in range(model.wall_count)]
        kw["face_energy"] = [energy[start[k] : start[k + 1]].astype(np.float32) for k in range(model.wall_count)]
    writer.add_frame(t, **kw)


def _world_walls(model, state):
    """Wall meshes moved to their current pose: list of (vertices (V, 3), triangles (F, 3))."""
    from .export import quat_to_matrix

    out = []
    poses = host(state.wall_pose)
    for k, mesh in enumerate(model.wall_meshes):
        v = host(mesh.points).astype(np.float64)
        t = host(mesh.indices).reshape(-1, 3)
        R = quat_to_matrix(poses[k, 3:7][None, :])[0]
        out.append((v @ R.T + poses[k, :3], t))
    return out


class RunStopped(RuntimeError):
    """A run reached its wall-time limit (``stop_after``) and saved a checkpoint; the same call resumes it.

    Attributes: ``checkpoint`` (path of the saved checkpoint), ``simulated_s`` (simulated time reached [s]).
    """

    def __init__(self, checkpoint, simulated_s: float, wall_s: float):
        self.checkpoint, self.simulated_s, self.wall_s = Path(checkpoint), float(simulated_s), float(wall_s)
        super().__init__(
            f"stopped after {wall_s:.0f} s of wall time at {simulated_s:.4g} s simulated; "
            f"checkpoint saved to {checkpoint}; run the same command again to resume"
        )


def check_stop_after(stop_after: float, out_dir, frames: bool) -> None:
    """Raise ValueError unless ``stop_after`` [s] is usable: >= 0, and > 0 only with an out_dir and no frames."""
    if not (math.isfinite(stop_after) and stop_after >= 0):
        raise InputError(f"stop_after = {stop_after!r} is not allowed; expected wall seconds >= 0 (0: no limit)")
    if stop_after > 0 and (out_dir is None or frames):
        raise InputError(
            "stop_after needs out_dir and frames=False, i.e. warpdem run --no-frames (it stops by saving a checkpoint)"
        )


def scene_solver(model, run, skin: float | None = None):
    """The Solver a scene's run uses: ``run`` (RunSpec) sets the step, impact threshold, clump damping
    convention and skin (``skin`` [m] overrides it), with room for the contacts of rig meshes and dense beds."""
    from warpdem.engine.solver import Solver, SolverOptions

    # rig meshes have fans and seams where one sphere may touch many triangles
    solver = Solver(
        model,
        SolverOptions(
            dt_fraction=run.dt_fraction,
            impact_speed_min=run.impact_speed_min,
            mesh_capacity=32,
            clump_contact_mass=run.clump_contact_mass,
            skin_fraction=run.skin_fraction,
            skin=skin,
            dt_margin=run.dt_margin,
            dt_levels=int(run.dt_levels),
        ),
    )
    # a compacted bed (die press) or glued layers hold more partners per sphere than a loose packing
    solver.options = dataclasses.replace(solver.options, neighbor_capacity=max(32, solver.default_neighbor_capacity()))
    return solver


SHARED_WALL_MEASURES = ("press",)
"""Measure kinds read from a wall's force and motion, which the batched worlds share: the bar's force is the
sum over the worlds, and its force limit turns the stroke of all of them at once. Such a scene runs one world
per launch."""


def independent_worlds(spec: SceneSpec) -> bool:
    """True when the batched worlds of ``spec`` measure independently (its measure kind is not in
    :data:`SHARED_WALL_MEASURES`)."""
    return spec.measure.kind not in SHARED_WALL_MEASURES


@dataclass(frozen=True)
class WorldGroup:
    """Worlds of another scene that run in the same launch as :func:`run_scene_iter`'s own (``also``): its
    ``world_count`` worlds of ``spec``, with ``variations`` and ``world_seeds`` as that function takes them.
    The scenes must share a launch (:func:`shares_launch`)."""

    spec: SceneSpec
    world_count: int = 1
    variations: dict | None = None
    world_seeds: tuple | None = None


LAUNCH_RUN_FIELDS = ("duration", "settle_energy", "settle_after")
"""RunSpec fields in which scenes that share a launch may differ: the launch runs to the longest duration and
the latest settle_after, and each world settles by its own settle_energy (:func:`launch_run`)."""

WORLD_MEASURE_FIELDS = ("packing_radius", "packing_margin", "packing_base", "pour_radius")
"""MeasureSpec fields read per world after the run (a fill's core, sized by its grains; the radius a pile was
poured within, a funnel's outlet), in which scenes that share a launch may differ; every other field steers the run itself."""


def shares_launch(a: SceneSpec, b: SceneSpec) -> bool:
    """True when the worlds of ``a`` and ``b`` can run as one launch (``ModelBuilder.stack``): the same rig,
    materials, pairs, gravity and walls by name, the same run settings but :data:`LAUNCH_RUN_FIELDS`, the same
    measure but :data:`WORLD_MEASURE_FIELDS`, and worlds that measure independently. Particles, factories,
    shapes, the walls' shapes and motions and the domain may differ."""

    def fields(obj, skip):
        return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj) if f.name not in skip}

    return (
        a.rig == b.rig
        and independent_worlds(a)
        and independent_worlds(b)
        and repr(a.materials) == repr(b.materials)
        and repr(a.pairs) == repr(b.pairs)
        and tuple(a.gravity) == tuple(b.gravity)
        and [w.name for w in a.walls] == [w.name for w in b.walls]
        and fields(a.run, LAUNCH_RUN_FIELDS) == fields(b.run, LAUNCH_RUN_FIELDS)
        and repr(fields(a.measure, WORLD_MEASURE_FIELDS)) == repr(fields(b.measure, WORLD_MEASURE_FIELDS))
    )


def launch_run(specs) -> tuple:
    """The run settings of one launch of ``specs`` (SceneSpecs that :func:`shares_launch`): the first's, run to
    the longest ``duration`` and the latest ``settle_after``, and the settle threshold of each scene [J] (one per
    spec)."""
    run = dataclasses.replace(
        specs[0].run,
        duration=max(s.run.duration for s in specs),
        settle_after=max(s.run.settle_after for s in specs),
    )
    return run, [s.run.settle_energy for s in specs]


COMMON_METRICS = ("time_s",)
"""Scalar metrics every world writes, whatever its scene measures."""

MEASURE_METRICS = {
    "angle_of_repose": (
        "angle_fit_deg",
        "angle_fit_sd_deg",
        "angle_image_deg",
        "angle_image_sd_deg",
        "angle_cone_deg",
        "pile_height_m",
        "pile_offset_m",
        "particles",
        "packing_fraction",
        "bulk_density_kg_m3",
        "discharge_rate_kg_s",
    ),
    "drum": ("dynamic_angle_deg", "fluctuation_index"),
    "press": (
        "residual_set_ratio",
        "loading_exponent",
        "unloading_stiffness_n_m",
        "max_displacement_m",
        "compression_ratio",
        "max_force_n",
        "final_height_m",
        "fill_height_m",
        "peak_overlap_max",
        "peak_overlap_mean",
        "escaped",
        "inertial_number_max",
    ),
    "impacts": (),
}
"""The scalar metrics (keys of each world's ``metrics.json`` entry) that :func:`run_scene` writes for each measure
kind (``MeasureSpec.kind``), besides :data:`COMMON_METRICS`; those of :data:`METRIC_NEEDS` only when the scene
sets the measurement up. impacts writes only nested metrics (``phases.PHASE.WALL.KEY``). A failed measurement
writes an ``*_error`` key instead of its metrics."""

METRIC_NEEDS = {
    "packing_fraction": "packing_time",
    "bulk_density_kg_m3": "packing_time",
    "discharge_rate_kg_s": "outlet_height",
    "residual_set_ratio": "unload_speed",
    "loading_exponent": "unload_speed",
    "unloading_stiffness_n_m": "unload_speed",
}
"""Metrics of :data:`MEASURE_METRICS` written only when the ``MeasureSpec`` field named here is set (> 0, or for
``outlet_height`` not None): the packing at ``packing_time``, the discharge rate below ``outlet_height``, the
unloading branch of a press that retracts at ``unload_speed``."""


METRIC_ERRORS = {"packing_time": "packing_error", "outlet_height": "discharge_error", "unload_speed": "press_error"}
"""The ``*_error`` key a run writes in place of the metrics that need this ``MeasureSpec`` field
(:data:`METRIC_NEEDS`); a kind's other metrics fail under :data:`KIND_ERRORS`."""

KIND_ERRORS = {"angle_of_repose": "angle_error", "press": "press_error", "drum": "drum_error"}
"""The ``*_error`` key a run writes in place of its measure kind's own metrics."""


def metric_error(metrics: dict, kind: str, metric: str) -> str | None:
    """Why one world's ``metrics`` (of a scene whose measure is ``kind``) lack ``metric``: the error the run wrote
    in its place, or None."""
    key = METRIC_ERRORS.get(METRIC_NEEDS.get(metric, ""), KIND_ERRORS.get(kind))
    return metrics.get(key) if key else None


def metric_needs_met(measure, metric: str) -> bool:
    """True when a scene measuring with ``measure`` (a ``MeasureSpec``) sets up what ``metric`` needs
    (:data:`METRIC_NEEDS`; always True for a metric that needs nothing)."""
    need = METRIC_NEEDS.get(metric)
    if need is None:
        return True
    v = getattr(measure, need)
    return v is not None if need == "outlet_height" else v > 0


def measured_metrics(measure) -> tuple[str, ...]:
    """The scalar metrics a run of a scene measuring with ``measure`` (a ``MeasureSpec``) writes per world:
    :data:`COMMON_METRICS` and its kind's :data:`MEASURE_METRICS` whose :data:`METRIC_NEEDS` it meets."""
    own = MEASURE_METRICS.get(measure.kind, ())
    return tuple(k for k in own if metric_needs_met(measure, k)) + COMMON_METRICS


SIDE_BY_SIDE_SPHERES = 1_000_000
"""Spheres that the launches running side by side on one GPU may hold together (:func:`run_together`): about
where one launch alone fills an H100 (``warpdem bench``), so a full-size launch runs alone and the small launches
of a diagnosis or of a study's rig-parameter groups share the GPU."""


def run_together(starts, device: str, load_limit: int | None = None, admit=None, on_end=None) -> list:
    """Run launches side by side on one device: each of ``starts`` is a callable returning a generator like
    :func:`run_scene_iter` (its first yield the launch's load in spheres, its return value the result), and
    each launch queues its steps on a CUDA stream of its own, so the small launches of a diagnosis or a study
    share the GPU instead of leaving it idle between their small kernels. One thread runs them all, in turns:
    a launch's turn queues its next steps and returns before waiting for them.

    Launches start in order while the running ones hold fewer than ``load_limit`` spheres (the first always
    starts; one at a time with 0; None: :data:`SIDE_BY_SIDE_SPHERES` on CUDA, 0 on the CPU, where nothing runs
    asynchronously); ``admit(i)``, if given,
    is asked before launch i starts, and False starts no further launch. ``on_end(i, outcome)`` is called as
    launch i ends. Returns each launch's outcome: its result, the exception it raised (a failing launch does
    not stop the others), or None where it did not start.
    """
    import warp as wp

    dev = wp.get_device(device)
    if load_limit is None:
        load_limit = SIDE_BY_SIDE_SPHERES if dev.is_cuda else 0
    outcomes: list = [None] * len(starts)
    pending, live = list(range(len(starts))), {}

    def turn(i) -> None:
        gen, stream, _ = live[i]
        try:
            # a stream of its own: what the launch queues waits only for its own work
            with wp.ScopedStream(stream, sync_enter=False):
                load = next(gen)
            if isinstance(load, int):
                live[i] = (gen, stream, load)
            return
        except StopIteration as stop:
            outcomes[i] = stop.value
        except Exception as e:  # kept: the other launches go on
            outcomes[i] = e
        del live[i]
        if on_end is not None:
            on_end(i, outcomes[i])

    while pending or live:
        while pending and (not live or sum(x[2] for x in live.values()) < load_limit):
            i = pending.pop(0)
            if admit is not None and not admit(i):
                pending.clear()
                break
            live[i] = (starts[i](), wp.Stream(dev) if dev.is_cuda else None, 0)
            turn(i)
        for i in list(live):
            turn(i)
    return outcomes


def run_scene(spec: SceneSpec, device: str = "cpu", out_dir=None, **kw) -> RunResult:
    """Run ``spec`` on ``device``; with ``out_dir`` write metrics.json, result.usdc (+ VTK series), pile.png.
    The arguments are :func:`run_scene_iter`'s; this runs it to the end."""
    from warpdem.engine.solver import drive

    return drive(run_scene_iter(spec, device, out_dir, **kw))


def run_scene_iter(
    spec: SceneSpec,
    device: str = "cpu",
    out_dir=None,
    world_count: int = 1,
    variations: dict | None = None,
    frames: bool = True,
    progress=None,
    quiet: bool = False,
    world_seeds=None,
    checkpoint_every: float = 0.0,
    stop_after: float = 0.0,
    also=(),
) -> Generator[int | None, None, RunResult]:
    """Run ``spec`` on ``device`` as a generator (:func:`run_scene` runs it to the end); with ``out_dir`` write
    metrics.json, result.usdc (+ VTK series), pile.png.

    The generator yields the model's sphere count once it is built (the launch's load on the device), then None
    each time the launch's steps are queued on the device's current stream and the host is about to wait for
    them: :func:`run_together` queues other launches on other streams of one GPU meanwhile.

    Args:
        world_count: batched worlds; ``variations`` maps ``material.NAME.FIELD`` / ``interaction.A.B.FIELD``
            to one value per world (a design point per world; all worlds share geometry and walls);
            ``world_seeds`` one dynamic-factory placement seed per world (0: the factory's own).
        frames: write the time-sampled USD / VTK of world 0 (every ``run.output_interval``).
        quiet: record the physics warnings (``info.step_warning``, ``info.warnings``) without warning of them
            (a study lists them among its run checks).
        progress: callable(fraction in [0, 1], message) called at each output tick.
        checkpoint_every: with ``out_dir`` and no frames, save the run's whole state to
            ``out_dir/checkpoint.npz`` at the first output tick after this many wall seconds (0: never);
            a later call with the same inputs resumes from it, and a finished run deletes it. A checkpoint
            also forces a neighbour-list rebuild, which the resumed run repeats, so the resumed run is
            bit-identical to one that was never interrupted.
        also: :class:`WorldGroup` s of other scenes that share this launch (:func:`shares_launch`), their worlds
            after this scene's: world k of the first group is world ``world_count + k``. The launch steps every
            world at the shortest step any needs and runs to :func:`launch_run`'s settings; each world is
            measured by its own scene's measure.
        stop_after: with ``out_dir`` and no frames, save a checkpoint and raise :class:`RunStopped` at the
            last output tick from which one more tick (taken to last as long as the one just run) would end
            past this many wall seconds from the call's start (0: never), e.g. to fit a job into a batch
            system's or a device's time limit; the same call resumes the run. The first tick always runs,
            and the save itself is not predicted: leave room for it (seconds per GB written).
    Returns:
        RunResult with one metrics dict per world.
    """
    check_stop_after(stop_after, out_dir, frames)
    if world_count > 1 and not independent_worlds(spec):
        raise InputError(
            f"run_scene: world_count = {world_count} is not allowed for a {spec.measure.kind!r} measurement; "
            "expected 1 (its worlds would share the wall it is read from)"
        )
    also = tuple(also)
    for g in also:
        if not shares_launch(spec, g.spec):
            raise InputError(
                f"run_scene: also = a {g.spec.rig!r} scene that cannot share a launch with this {spec.rig!r} one; "
                "expected scenes that differ only in their particles, factories, wall shapes and domain"
            )
    t_wall0 = time.perf_counter()
    builder = build(spec, world_count, variations, world_seeds)
    for g in also:
        builder.stack(build(g.spec, g.world_count, g.variations, g.world_seeds))
    model = builder.finalize(device, warn_overlaps=False)  # the state's own check below records them per world
    yield model.sphere_count
    run, settle_energies = launch_run([spec, *(g.spec for g in also)])
    # each world is measured by its own scene's measure (a fill's core is sized by its grains)
    measures = [spec.measure] * world_count + [g.spec.measure for g in also for _ in range(g.world_count)]
    solver = scene_solver(model, run)
    state, contacts = model.state(), solver.contacts()
    h = _host(model)
    W = model.world_count
    names = list(model.wall_names)
    planes = model.plane_count
    out = Path(out_dir) if out_dir else None
    writer = None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    if out is not None and frames:
        from .export import ResultWriter, ShapeGeometry, WallGeometry

        walls = [
            WallGeometry(n, host(m.points), host(m.indices).reshape(-1, 3)) for n, m in zip(names, model.wall_meshes)
        ]
        shapes = [ShapeGeometry.from_template(t) for t in model.clump_templates]
        writer = ResultWriter(out, walls, shapes, usd_name="result.usdc")

    m = spec.measure
    piston = names.index(m.piston) if m.kind == "press" else None
    phase_ends = list(m.phase_ends) if m.kind == "impacts" else []
    first_window = m.first_contact_window if m.kind == "impacts" else 0.0
    packing_time = m.packing_time if m.kind == "angle_of_repose" and m.packing_time > 0 else None
    phase_snap = []
    # tick_wall_s and rebuilds say where the wall time of a long run went (a dense pile, a flowing stream)
    # dt_s and step_margin: the step each tick ran at and the fraction of the stable step it used (SolverOptions)
    series = {
        "time": [],
        "kinetic_energy": [],
        "wall_force": [],
        "tick_wall_s": [],
        "rebuilds": [],
        "dt_s": [],
        "step_margin": [],
    }
    if piston is not None:
        series.update(piston_z=[], piston_force=[], bed_top=[])
    impulse_prev = host(state.wall_impulse).copy()
    t_prev = 0.0
    stop_reason = "duration"
    # RunSpec: settled when every world stays below settle_energy for three outputs in a row
    settle = ms.SettleMonitor(run.settle_energy, window=3) if run.settle_energy > 0 else None
    settle_scale = None
    if min(settle_energies) <= 0:
        settle = None  # a scene that never counts as settled keeps the launch running
    elif len(set(settle_energies)) > 1:
        # scenes of one launch settle by their own thresholds: the monitor reads each world's energy over its own
        counts = [world_count] + [g.world_count for g in also]
        settle_scale = np.repeat(np.asarray(settle_energies, dtype=np.float64), counts)
        settle = ms.SettleMonitor(1.0, window=3)
    # when each world settled and was held (SphereActivity.SETTLED): it ends as it would in a launch of its own
    settled_s = np.full(W, np.nan)
    eps = 0.5 * solver.dt
    ckpt = (
        out / "checkpoint.npz"
        if (out is not None and (checkpoint_every > 0 or stop_after > 0) and writer is None)
        else None
    )
    fingerprint = _fingerprint(spec, device, world_count, variations, world_seeds, also)
    resumed_from = None
    if ckpt is not None and ckpt.exists():
        book = _load_checkpoint(ckpt, fingerprint, state, contacts)
        if book is not None:
            series, impulse_prev, t_prev = book["series"], book["impulse_prev"], book["t_prev"]
            phase_snap = book["phase_snap"]
            solver.restore_dt_state(book["dt_state"])
            if settle is not None:
                settle.streak = book["settled_since"]
                if book.get("world_settled_since") is not None:
                    settle.world_streak = np.asarray(book["world_settled_since"], dtype=np.int64)
            if book.get("world_settled_s") is not None:
                settled_s = np.asarray(book["world_settled_s"], dtype=float)
            resumed_from = state.time
            if "unload_start_s" in series:
                _start_unloading(spec, model, solver, piston, series["unload_start_s"])
            series.setdefault("tick_wall_s", [])
            series.setdefault("rebuilds", [])
    if resumed_from is None:
        series["start_overlap"] = _overlaps(model, state, h)
        if first_window > 0:
            series["first_contact"] = {k: [None] * W for k in ("after_s", "seen_s", "end_s", "snap")}
    first_faces = _measured_faces(model, names, m) if first_window > 0 else None
    series.setdefault("step_travel", [])
    # radii of the smallest particle sphere a body may move per step (suspect.STEP_TRAVEL_MAX)
    r_small = float(h["radius"][h["glued"] < 0].min()) if np.any(h["glued"] < 0) else 1.0
    t_ckpt = time.perf_counter()
    rebuilds_total = solver.rebuild_count
    if writer is not None:
        _frame(writer, model, state, h, spec, 0.0)
    while state.time < run.duration - eps:
        t_tick = time.perf_counter()
        t_next = min(state.time + run.output_interval, run.duration)
        for te in phase_ends + ([packing_time] if packing_time is not None else []):
            if state.time + eps < te < t_next - eps:
                t_next = te
        step0 = state.step
        state = yield from solver.advance_iter(state, contacts, t_next - state.time)
        t = state.time
        count = solver.rebuild_count
        rebuilds, rebuilds_total = count - rebuilds_total, count
        series["tick_wall_s"].append(time.perf_counter() - t_tick)
        series["rebuilds"].append(rebuilds)
        series["dt_s"].append(solver.dt)
        series["step_margin"].append(solver.step_margin)
        imp = host(state.wall_impulse)
        force = (imp - impulse_prev) / max(t - t_prev, 1e-300)
        impulse_prev, t_prev = imp.copy(), t
        ke, fastest = _motion(model, state, h)
        series["step_travel"].append((fastest * solver.dt / r_small).tolist())
        if m.outlet_height is not None:
            series.setdefault("discharged_kg", []).append(_discharged_mass(model, state, h, m.outlet_height).tolist())
        series["time"].append(t)
        series["kinetic_energy"].append(ke.tolist())
        series["wall_force"].append(force[:, 2].tolist())
        if piston is not None:
            series["piston_z"].append(float(host(state.wall_pose)[piston, 2]))
            series["piston_force"].append(float(force[planes + piston, 2]))
            xb, rb = _particles(model, state, h, 0)
            series["bed_top"].append(float(np.percentile(xb[:, 2] + rb, 99)) if len(rb) else 0.0)
        if first_window > 0:
            phase_end = any(abs(t - te) <= eps for te in phase_ends)
            t_before = series["time"][-2] if len(series["time"]) > 1 else 0.0
            _first_contacts(series["first_contact"], state, first_faces, t, t_before, first_window - eps, phase_end)
        for te in phase_ends:
            if abs(t - te) <= eps and len(phase_snap) < len(phase_ends):
                phase_snap.append(
                    {
                        "count": host(state.face_impact_count).copy(),
                        "energy": host(state.face_impact_energy).copy(),
                        "speed": host(state.face_impact_speed).copy(),
                    }
                )
                state.reset_impacts()
        if m.kind == "drum" and t >= m.average_from - eps:
            series.setdefault("drum", []).append([_drum_frame(model, state, h, w, m, t) for w in range(W)])
        # the tick that ends at the packing time lands within half a step of it (advance rounds to whole steps),
        # which a tolerance of exactly half a step can miss by rounding: take the first tick at or past it
        if packing_time is not None and t >= packing_time - eps and "packing" not in series:
            series["packing"] = [_packing_metrics(model, state, h, w, measures[w]) for w in range(W)]
        if writer is not None:
            _frame(writer, model, state, h, spec, t)
        if progress:
            steps = state.step - step0
            progress(
                min(t / run.duration, 1.0),
                f"t = {t:.3f} s, {steps / max(series['tick_wall_s'][-1], 1e-9):.0f} steps/s, "
                f"a rebuild every {steps / max(rebuilds, 1):.1f} steps",
            )
        loading = piston is not None and "unload_start_s" not in series
        if loading and m.force_limit > 0 and series["piston_force"][-1] >= m.force_limit:
            # the bed at its heaviest load: the end's overlaps are those of the bed unloaded
            series["peak_overlap"] = _overlaps(model, state, h)
            series["escaped"] = _escaped(model, state, h, piston).tolist()
            if m.unload_speed <= 0:
                stop_reason = "force_limit"
                break
            # the stroke ends here: the piston holds, then returns (the rest of the run is the unloading branch)
            series["unload_index"] = len(series["piston_z"]) - 1
            series["unload_start_s"] = t
            series["unload_end_s"] = _start_unloading(spec, model, solver, piston, t)
        if "unload_end_s" in series and t >= series["unload_end_s"] - eps:
            stop_reason = "unloaded"
            break
        factories_done = all(
            state.released.get(f, {}).get("count", 0) >= rec["count"] for f, rec in enumerate(model.factories)
        )
        if settle is not None and t >= run.settle_after and factories_done:
            every = settle.update(t, ke if settle_scale is None else ke / settle_scale)
            newly = settle.settled_worlds & np.isnan(settled_s)
            settled_s[newly] = t
            if every:
                stop_reason = "settled"
                break
            # a settled world is held where it is: the rest of the launch steps only the worlds still moving
            solver.settle_worlds(state, np.flatnonzero(newly))
        now = time.perf_counter()
        # a dense bed can take a minute per tick on the GPU: stop before the tick that would overrun
        stopping = stop_after > 0 and (now - t_wall0) + (now - t_tick) >= stop_after
        if ckpt is not None and (stopping or (checkpoint_every > 0 and now - t_ckpt >= checkpoint_every)):
            _save_checkpoint(
                ckpt,
                fingerprint,
                state,
                contacts,
                {
                    "series": series,
                    "impulse_prev": impulse_prev,
                    "t_prev": t_prev,
                    "phase_snap": phase_snap,
                    "settled_since": settle.streak if settle is not None else 0,
                    "world_settled_since": (
                        settle.world_streak.tolist() if settle is not None and settle.world_streak is not None else None
                    ),
                    "world_settled_s": settled_s.tolist(),
                    "dt_state": solver.dt_state(),
                },
            )
            t_ckpt = time.perf_counter()
            if stopping:
                raise RunStopped(ckpt, state.time, time.perf_counter() - t_wall0)
    wall_s = time.perf_counter() - t_wall0

    # the scalar metrics each kind writes are listed in MEASURE_METRICS and METRIC_NEEDS: keep them in step
    metrics = []
    removed = host(state.world_removed)
    thresholds = np.repeat(settle_energies, [world_count] + [g.world_count for g in also])
    ke_series = np.asarray(series["kinetic_energy"], dtype=np.float64).reshape(len(series["time"]), W)
    dt_range = [min(series["dt_s"], default=solver.dt), max(series["dt_s"], default=solver.dt)]
    end_overlap = _overlaps(model, state, h)
    bodies = _bodies(model, state, h) + removed
    travel = np.asarray(series["step_travel"], dtype=np.float64).reshape(-1, W).max(axis=0, initial=0.0)
    start = series.get("start_overlap")
    peak = series.get("peak_overlap")
    for w in range(W):
        # removed: bodies that left the scene's domain (e.g. rolled off the plate's edge)
        mw = {"world": w, "time_s": state.time, "stop": stop_reason, "removed": int(removed[w])}
        mw["warnings"] = suspect.world_warnings(
            int(removed[w]),
            int(bodies[w]),
            float(travel[w]),
            dt_range,
            None if start is None else {k: v[w] for k, v in start.items()},
            float(end_overlap["deepest"][w]),
            None if peak is None else {k: v[w] for k, v in peak.items()},
        )
        if np.isfinite(settled_s[w]):
            # held since it settled: its state is that instant's, whatever its launch-mates did after
            mw.update(time_s=float(settled_s[w]), stop="settled")
        # how the world came to rest: its kinetic energy per particle at every output tick, and the threshold
        mw["settling"] = {
            "time_s": list(map(float, series["time"])),
            "kinetic_energy_j": ke_series[:, w].tolist(),
            "threshold_j": float(thresholds[w]),
        }
        if m.kind == "angle_of_repose":
            mw.update(measure_pile(*_particles(model, state, h, w), m))
            found = suspect.pile_apart_warning(mw["detached"], mw["particles"])
            if found is not None:
                mw["warnings"].append(found)
            if measures[w].pour_radius > 0 and "pile_offset_m" in mw:
                found = suspect.off_axis_warning(mw["pile_offset_m"], measures[w].pour_radius)
                if found is not None:
                    mw["warnings"].append(found)
            if m.outlet_height is not None:
                mw.update(_discharge_metrics(series, w))
                found = suspect.outlet_warning(m.base_height + mw["pile_height_m"], m.outlet_height, 2 * r_small)
                if found is not None:
                    mw["warnings"].append(found)
            if packing_time is not None:
                mw.update(series.get("packing", [{"packing_error": "the run ended before the packing time"}] * W)[w])
        elif m.kind == "press":
            z = np.asarray(series["piston_z"])
            f = np.asarray(series["piston_force"])
            mw.update(_press_metrics(spec, model, state, h, w, z, f, series))
            found = suspect.escape_warning(mw["escaped"], _piston_clearance(model, m.piston))
            if found is not None:
                mw["warnings"].append(found)
        elif m.kind == "impacts":
            mw["phases"] = _impact_metrics(model, names, m, phase_snap, w)
            if first_window > 0:
                phase, when = _first_contact_metrics(model, names, m, series["first_contact"], w)
                if phase is not None:
                    mw["phases"]["first_contacts"] = phase
                mw.update(when)
        elif m.kind == "drum":
            mw.update(_drum_metrics(series, h, w))
        metrics.append(mw)
    info = {
        "rig": spec.rig,
        "device": str(device),
        "worlds": W,
        "spheres": model.sphere_count,
        "clumps": model.clump_count,
        "glued_spheres": model.attached_count,
        "dt_s": solver.dt_base,
        "dt_range_s": dt_range,
        "step_margin_max": solver.step_margin_max,
        "steps": state.step,
        "simulated_s": state.time,
        "wall_s": wall_s,
        "stop": stop_reason,
        "resumed_from_s": resumed_from,
        "rebuilds": int(sum(series.get("rebuilds", []))),
        "tick_time_s": list(series["time"]),
        "tick_wall_s": list(series.get("tick_wall_s", [])),
        "tick_rebuilds": list(series.get("rebuilds", [])),
    }
    if solver.step_margin_max > 1.0:
        # leapfrog was unstable in some tick: say so where the figures are read, not only on stderr
        info["step_warning"] = (
            f"the step reached {solver.step_margin_max:.2f} of the stable step of the stiffest contact (stable "
            f"below 1; dt {dt_range[0]:.3g} to {dt_range[1]:.3g} s, dt_levels "
            f"{solver.options.dt_levels}): figures from those ticks are not to be trusted; lower run.dt_fraction"
        )
        if not quiet:
            warnings.warn(info["step_warning"], PhysicsWarning, stacklevel=2)
    info["warnings"] = _warning_lines(metrics)
    for line in [] if quiet else info["warnings"]:
        warnings.warn(line, PhysicsWarning, stacklevel=2)
    result = RunResult(metrics, info, series)
    if out is not None:
        files = {}
        if writer is not None:
            files.update(writer.close())
        files.update(_final_npz(out, model, state, h))
        try:
            files.update(_pictures(out, spec, model, state, h, result))
        except ImportError as e:  # a machine without matplotlib still gets metrics and final.npz
            info["pictures_skipped"] = str(e)
        faces = {}
        for mw in metrics:
            for phase, walls in mw.get("phases", {}).items():
                for wall, summ in walls.items():
                    for key, arr in summ.pop("faces").items():
                        faces[f"world{mw['world']}/{phase}/{wall}/{key}"] = arr
        if faces:
            np.savez_compressed(out / "impacts.npz", **faces)
            files["impacts_npz"] = str(out / "impacts.npz")
        info["files"] = files
        with open(out / "metrics.json", "w") as fh:
            json.dump({"info": info, "metrics": metrics}, fh, indent=1, default=_json_default)
    if ckpt is not None and ckpt.exists():
        ckpt.unlink()
    return result


def _fingerprint(spec, device, world_count, variations, world_seeds, also=()) -> str:
    """Hash of what a run is made of: a checkpoint only resumes the run it was saved from. The device counts by
    its kind only: a study's launch resumed by another call may land on another GPU of the machine (Dask picks
    the worker), and with the ordinal in the hash it restarted from nothing (seed 001's reach diagnosis, on 2
    H200s, lost two launches of 185 s that way)."""
    import hashlib

    more = [[repr(g.spec), int(g.world_count), g.variations, g.world_seeds] for g in also]
    text = json.dumps(
        [repr(spec), device_kind(device), int(world_count), variations, world_seeds] + more,
        sort_keys=True,
        default=_json_default,
    )
    return hashlib.sha1(text.encode()).hexdigest()


CHECKPOINT_FORMAT = 5
"""Version of the arrays a checkpoint holds (4: contact history in the slot type of ``StepFeatures.history_type``;
live masks of the neighbour and plane slots; 5: the solver's step level, ``Solver.dt_state``).
A checkpoint of another version, or one whose history slot has another layout, belongs to other code: the run
starts afresh instead of resuming from it."""


def _checkpoint_format(contacts) -> list:
    """The version and the history slot's layout (its record's fields, or its vector type), as saved in a
    checkpoint's meta."""
    dtype = contacts.neighbor_history.dtype
    layout = dtype.numpy_dtype() if hasattr(dtype, "numpy_dtype") else dtype.__name__
    return [CHECKPOINT_FORMAT, repr(layout)]


def _device_arrays(obj) -> dict:
    import warp as wp

    return {k: v for k, v in vars(obj).items() if isinstance(v, wp.array)}


def _save_checkpoint(path: Path, fingerprint: str, state, contacts, book: dict) -> None:
    """State, contact lists and history, and the runner's bookkeeping, written to a temporary file and
    renamed (a crash while saving leaves the previous checkpoint whole). Flags a list rebuild, which a
    resumed run repeats, so both continue from identical lists."""
    contacts.rebuild.fill_(1)
    arrays = {f"state.{k}": host(v) for k, v in _device_arrays(state).items()}
    # list slots past the longest list are never read (a rebuild follows the load): keep only the used rows
    used = {k: int(host(getattr(contacts, f"{k}_count")).max(initial=0)) for k in ("neighbor", "mesh")}
    for k, v in _device_arrays(contacts).items():
        group = k.split("_")[0]
        rows = used.get(group) if v.ndim == 2 and k != f"{group}_count" else None
        arrays[f"contacts.{k}"] = host(v)[:rows] if rows is not None else host(v)
    arrays["book.impulse_prev"] = np.asarray(book["impulse_prev"])
    for i, snap in enumerate(book["phase_snap"]):
        for k, v in snap.items():
            arrays[f"snap.{i}.{k}"] = v
    meta = {
        "fingerprint": fingerprint,
        "format": _checkpoint_format(contacts),
        "time": state.time,
        "step": state.step,
        "half_step": state.half_step,
        "released": {str(f): v for f, v in state.released.items()},
        "series": book["series"],
        "t_prev": book["t_prev"],
        "settled_since": book["settled_since"],
        "world_settled_since": book.get("world_settled_since"),
        "world_settled_s": book.get("world_settled_s"),
        "dt_state": book["dt_state"],
        "snaps": len(book["phase_snap"]),
    }
    arrays["meta"] = np.frombuffer(json.dumps(meta, default=_json_default).encode(), dtype=np.uint8)
    tmp = path.with_name(path.stem + ".tmp.npz")
    np.savez(tmp, **arrays)
    tmp.replace(path)


def checkpoint_meta(path: Path) -> dict | None:
    """A scene run's checkpoint's bookkeeping (simulated ``time``, ``step``, the output ``series`` so far, ...), as
    :func:`_save_checkpoint` wrote it; None when the file holds none."""
    with np.load(path) as z:
        return _meta(z) if "meta" in z.files else None


def _meta(z) -> dict:
    return json.loads(bytes(z["meta"]).decode())


def _load_checkpoint(path: Path, fingerprint: str, state, contacts) -> dict | None:
    """Restore a checkpoint into a fresh ``state`` and ``contacts``; None when it belongs to another run."""
    with np.load(path) as z:
        meta = _meta(z)
        if meta["fingerprint"] != fingerprint or meta.get("format") != _checkpoint_format(contacts):
            return None
        arrays = [
            (prefix + k, v)
            for prefix, obj in (("state.", state), ("contacts.", contacts))
            for k, v in _device_arrays(obj).items()
        ]
        if any(name not in z.files for name, _ in arrays):  # checked before any is restored
            return None
        for name, v in arrays:
            a = z[name]
            if v.ndim == 2 and a.shape[0] != v.shape[0]:  # list slots trimmed at saving: the rest are zero
                full = np.zeros((v.shape[0],) + a.shape[1:], dtype=a.dtype)
                full[: a.shape[0]] = a
                a = full
            v.assign(a)
        book = {
            "impulse_prev": z["book.impulse_prev"].copy(),
            "phase_snap": [
                {k.split(".", 2)[2]: z[k].copy() for k in z.files if k.startswith(f"snap.{i}.")}
                for i in range(meta["snaps"])
            ],
        }
    state.time, state.step, state.half_step = meta["time"], meta["step"], meta["half_step"]
    state.released = {int(f): v for f, v in meta["released"].items()}
    book.update(
        series=meta["series"],
        t_prev=meta["t_prev"],
        settled_since=meta["settled_since"],
        world_settled_since=meta.get("world_settled_since"),
        world_settled_s=meta.get("world_settled_s"),
        dt_state=meta["dt_state"],
    )
    return book


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def _discharged_mass(model, state, h, outlet_height: float) -> np.ndarray:
    """Mass [kg] of the bodies below ``outlet_height`` [m] (by their centres) in each world, shape (world_count,)."""
    act = host(state.sphere_active).astype(bool)
    x = host(state.sphere_x)
    out = np.zeros(model.world_count)
    sel = act & h["free"] & (x[:, 2] < outlet_height)
    np.add.at(out, h["world"][sel], h["mass"][sel])
    if model.clump_count:
        cx = host(state.clump_x)
        csel = act[h["clump_first"][: len(cx)]] & (cx[:, 2] < outlet_height)
        np.add.at(out, h["clump_world"][csel], h["clump_mass"][csel])
    return out


def _discharge_metrics(series, w: int) -> dict:
    """The steady discharge rate of world ``w`` from the discharged mass per output (``measure.discharge_rate``)."""
    mass = np.asarray(series.get("discharged_kg", []), dtype=float)
    try:
        got = ms.discharge_rate(series["time"], mass[:, w] if mass.ndim == 2 else mass)
    except ValueError as e:
        return {"discharge_error": str(e)}
    return {k: got[k] for k in ("discharge_rate_kg_s", "discharged_kg", "steady_from_s", "steady_to_s")}


def _packing_metrics(model, state, h, w: int, m) -> dict:
    """Packing fraction and bulk density of world ``w``'s bed in its container's core (``MeasureSpec.packing_*``)."""
    sel = _particle_mask(state, h, w)
    if not sel.any():
        return {"packing_error": "no particles in the container"}
    x, r, rho = host(state.sphere_x)[sel].astype(np.float64), h["radius"][sel], h["density"][sel]
    try:
        base = m.base_height if m.packing_base is None else m.packing_base
        core = ms.packing_core(x, r, m.center, m.packing_radius, base, m.packing_margin)
    except ValueError as e:
        return {"packing_error": str(e)}
    got = ms.packing_fraction(x, r, core, density=rho)
    return {
        "packing_fraction": got["packing_fraction"],
        "bulk_density_kg_m3": got["bulk_density_kg_m3"],
        "packing_core": {"radius_m": core.radius, "z_low_m": core.z_low, "z_high_m": core.z_high},
    }


def _drum_frame(model, state, h, w: int, m, t: float) -> dict:
    """World ``w``'s bed surface at time ``t`` [s] (``measure.drum_surface``), as JSON-able numbers for the
    series (and so for a checkpoint): time, angle, the surface points and the line; or the error."""
    x, r = _particles(model, state, h, w)
    try:
        got = ms.drum_surface(x, r, m.drum_center, m.drum_radius, axis=m.drum_axis)
    except ValueError as e:
        return {"time": t, "error": str(e)}
    return {
        "time": t,
        "angle_deg": got["angle_deg"],
        "slope": got["slope"],
        "intercept_m": got["intercept_m"],
        "chord_m": list(got["chord_m"]),
        "surface_s": got["surface_s"].tolist(),
        "surface_h": got["surface_h"].tolist(),
        "detached": got["detached"],
    }


def _drum_metrics(series, h, w: int) -> dict:
    """Dynamic angle and fluctuation index of world ``w`` over its measured frames (``measure.drum_metrics``)."""
    frames = [tick[w] for tick in series.get("drum", [])]
    good = [f for f in frames if "angle_deg" in f]
    out = {"frames": len(good), "frame_errors": len(frames) - len(good)}
    d = _mean_diameter(h, w)
    try:
        got = ms.drum_metrics(good, d)
    except ValueError as e:
        out["drum_error"] = str(e)
        return out
    out.update(
        dynamic_angle_deg=got["dynamic_angle_deg"],
        dynamic_angle_sd_deg=got["dynamic_angle_sd_deg"],
        fluctuation_index=got["fluctuation_index"],
        mean_diameter_m=d,
        detached_mean=float(np.mean([f["detached"] for f in good])),
    )
    return out


def _start_unloading(spec, model, solver, piston: int, t_stop: float) -> float:
    """Move the piston's last keyframes so that its stroke ends at ``t_stop`` [s] where it is then, holds for
    ``measure.hold_time`` and returns at ``measure.unload_speed`` (``stage.unload_keyframes``), in the solver's
    Control in place; returns the time [s] the return ends."""
    from warpdem.engine.motion import MotionTable, WallMotion

    m = spec.measure
    wall = next(w for w in spec.walls if w.name == m.piston)
    if wall.times is None or len(wall.times) < 4:
        raise StageError(
            f"/World/Walls/{m.piston}: keyframes = {0 if wall.times is None else len(wall.times)} are not allowed "
            "with warpdem:measure:unloadSpeed > 0; expected at least 4 (the stroke, its end, the hold and return)"
        )
    stop, _ = model.wall_motions[piston].pose(t_stop)
    times, tr = unload_keyframes(wall.times[:-2], wall.translations[:-2], t_stop, stop, m.hold_time, m.unload_speed)
    motions = list(model.wall_motions)
    motions[piston] = WallMotion.keyframes(times, tr, np.tile(wall.rotations[0], (len(times), 1)))
    solver.control.assign(MotionTable.build(motions))
    return float(times[-1])


def _press_metrics(spec, model, state, h, w, z, f, series) -> dict:
    """Force-displacement of the bar, fill height and compression ratio, the bed's overlaps and the spheres
    squeezed past the bar at the force limit, and the inertial number."""
    m = spec.measure
    z_all, f_all = z, f
    stop = series.get("unload_index")
    load = ms.press_loading(z, f, series["bed_top"], m.force_limit, m.backstop_height, stop)
    if load is None:
        return {"press_error": "the bar never pressed the bed"}
    z, f, fill = load.pop("load_z"), load.pop("load_force"), load["fill_height_m"]
    curve = {k: load.pop(k) for k in ("displacement_m", "force_n")}
    mat = model.materials[int(h["material"][h["world"] == w][0])]
    d = _mean_diameter(h, w)
    area = math.pi * _piston_radius(model, m.piston) ** 2
    t = np.asarray(series["time"])[: len(z)]
    speed = np.abs(np.gradient(z, t)) if len(z) > 2 else np.zeros_like(z)
    height = np.maximum(z - m.backstop_height, 1e-9)
    p = np.maximum(f, 0) / area
    pressing = p > 0.01 * p.max()
    inertial = speed[pressing] / height[pressing] * d / np.sqrt(p[pressing] / mat.density)
    out = {k: (float(v) if np.isscalar(v) else v) for k, v in load.items()}
    # the bed at the force limit (a run that never reached it: at its end)
    peak = series.get("peak_overlap") or _overlaps(model, state, h)
    escaped = series.get("escaped") or _escaped(model, state, h, list(model.wall_names).index(m.piston)).tolist()
    out.update(
        peak_overlap_max=float(peak["deepest"][w]),
        peak_overlap_mean=float(peak["mean"][w]),
        escaped=int(escaped[w]),
        inertial_number_max=float(inertial.max()) if inertial.size else None,
        displacement_m=list(map(float, curve["displacement_m"])),
        force_n=list(map(float, curve["force_n"])),
    )
    if stop is not None:
        cycle = ms.press_unload(
            z - m.backstop_height,
            f,
            z_all[stop:] - m.backstop_height,
            f_all[stop:],
            contact_z=fill,
            fill_height=fill,
            interval_means=True,
        )
        out.update(
            {k: v for k, v in cycle.items() if not k.startswith("unload_") and k != "max_displacement_m"},
            unload_start_s=float(series["unload_start_s"]),
            unload_displacement_m=list(map(float, cycle["unload_displacement_m"])),
            unload_force_n=list(map(float, cycle["unload_force_n"])),
        )
    return out


def _piston_radius(model, name) -> float:
    k = list(model.wall_names).index(name)
    v = host(model.wall_meshes[k].points)
    return float(np.hypot(v[:, 0], v[:, 1]).max())


def _piston_clearance(model, name) -> float:
    """The gap [m] between the bar's rim and the die: the radius of the nearest point of another wall beyond the
    rim, less the rim's (a faceted die's vertices; its flats lie a little closer)."""
    k = list(model.wall_names).index(name)
    r_bar = _piston_radius(model, name)
    others = [host(mesh.points) for j, mesh in enumerate(model.wall_meshes) if j != k]
    radii = np.concatenate([np.hypot(v[:, 0], v[:, 1]) for v in others]) if others else np.zeros(0)
    outside = radii[radii >= r_bar]
    return float(outside.min() - r_bar) if outside.size else math.inf


def _impact_metrics(model, names, m, snaps, w) -> dict:
    """Per phase and wall: impact summary from the snapshots taken at each phase end."""
    return {name: _wall_impacts(model, names, m, snap, w) for name, snap in zip(m.phase_names, snaps)}


def _wall_impacts(model, names, m, snap, w) -> dict:
    """Per measured wall: world ``w``'s impact summary from a snapshot of the face records (count, energy,
    speed; each shape (worlds, faces))."""
    from warpdem.engine.geometry import face_areas

    start = host(model.wall_face_start)
    phase = {}
    for wall in m.walls:
        k = names.index(wall)
        sl = slice(start[k], start[k + 1])
        mesh = model.wall_meshes[k]
        area = face_areas(host(mesh.points).astype(np.float64), host(mesh.indices).reshape(-1, 3))
        s = ms.impact_summary(snap["count"][w, sl], snap["energy"][w, sl], snap["speed"][w, sl], face_area=area)
        # per-face arrays live in the USD primvars and impacts.npz; metrics.json keeps the summary
        phase[wall] = {k: v for k, v in s.items() if not (isinstance(v, (list, np.ndarray)) and len(v) > 10)}
        phase[wall]["faces"] = {
            "count": snap["count"][w, sl],
            "energy_j": snap["energy"][w, sl],
            "max_speed_m_s": snap["speed"][w, sl],
        }
    return phase


def _measured_faces(model, names, m) -> np.ndarray:
    """Indices of the faces of the measured walls (``m.walls``) in the face records."""
    start = host(model.wall_face_start)
    return np.concatenate([np.arange(start[k], start[k + 1]) for k in (names.index(w) for w in m.walls)])


def _first_contacts(book, state, faces, t, t_before, window, phase_end) -> None:
    """At an output tick ``t`` [s] (the one before at ``t_before``): for each world, note the first tick that sees
    an impact on the measured walls (their ``faces``, :func:`_measured_faces`), and copy the face records at the first tick at least ``window`` s after it
    (the window less half a step: ticks land within that of their time), or at a phase end that is about to
    reset them if that comes first. ``book`` (the run's series, checkpointed as JSON): per world
    ``after_s``, ``seen_s`` and ``end_s`` [s] and ``snap`` (count, energy, speed of every face, as lists)."""
    pending = [w for w, e in enumerate(book["end_s"]) if e is None]
    if not pending:
        return
    count = host(state.face_impact_count)
    snap = None
    for w in pending:
        if book["seen_s"][w] is None:
            if count[w, faces].sum() == 0:
                continue
            book["after_s"][w], book["seen_s"][w] = t_before, t
        if t >= book["seen_s"][w] + window or phase_end:
            if snap is None:
                snap = {
                    "count": count,
                    "energy": host(state.face_impact_energy),
                    "speed": host(state.face_impact_speed),
                }
            book["end_s"][w] = t
            book["snap"][w] = {k: v[w].tolist() for k, v in snap.items()}


def _first_contact_metrics(model, names, m, book, w) -> tuple[dict | None, dict]:
    """World ``w``'s ``first_contacts`` phase (``phases.first_contacts.WALL.KEY``, the impacts from the start to
    ``first_contacts_s.end_s``) and the metrics that say when: ``first_contacts_s`` (the first impact came after
    ``after_s`` and by ``seen_s``); or (None, ``first_contacts_error``)."""
    if book["snap"][w] is None:
        why = "no impact on the measured walls" if book["seen_s"][w] is None else "the run ended inside the window"
        return None, {"first_contacts_error": f"{why} ({', '.join(m.walls)})"}
    snap = {k: np.asarray(v)[None, :] for k, v in book["snap"][w].items()}
    when = {"first_contacts_s": {k: book[k][w] for k in ("after_s", "seen_s", "end_s")}}
    return _wall_impacts(model, names, m, snap, 0), when


def _final_npz(out: Path, model, state, h) -> dict:
    """final.npz: every world's active spheres at the end (``sphere_world`` says whose; glued ones flagged by
    ``sphere_glued``, the wall index, or -1) and the walls, enough to redraw each world and re-measure it without
    rerunning (:func:`world_state` cuts one world out; a study keeps each run's as ``runs/<point_id>.npz``)."""
    act = host(state.sphere_active).astype(bool)
    walls = _world_walls(model, state)
    arrays = {
        "sphere_x": host(state.sphere_x)[act],
        "sphere_r": h["radius"][act],
        "sphere_glued": h["glued"][act],
        "sphere_world": h["world"][act],
    }
    for k, (v, t) in enumerate(walls):
        arrays[f"wall{k}_vertices"] = v
        arrays[f"wall{k}_triangles"] = t
    arrays["wall_names"] = np.asarray(model.wall_names)
    arrays["wall_pose"] = host(state.wall_pose)
    np.savez_compressed(out / "final.npz", **arrays)
    return {"final_npz": str(out / "final.npz")}


def world_state(data, world: int) -> dict:
    """One world of a ``final.npz``'s arrays (``data``, {name: array}): its spheres (``sphere_x`` (n, 3) [m],
    ``sphere_r`` (n,) [m], ``sphere_glued`` (n,)) and every wall (``wall<k>_vertices``, ``wall<k>_triangles``,
    ``wall_names``, ``wall_pose``), as arrays to save or measure. A file written before ``sphere_world`` existed
    holds world 0 only."""
    sel = data["sphere_world"] == world if "sphere_world" in data else np.full(len(data["sphere_r"]), world == 0)
    out = {k: np.asarray(data[k])[sel] for k in ("sphere_x", "sphere_r", "sphere_glued")}
    out.update({k: np.asarray(data[k]) for k in data.keys() if k.startswith("wall")})
    return out


def state_walls(state: dict) -> list[tuple[np.ndarray, np.ndarray]]:
    """The walls of a :func:`world_state` as (vertices (V, 3) [m], triangles (F, 3)), in wall order."""
    return [(state[f"wall{k}_vertices"], state[f"wall{k}_triangles"]) for k in range(len(state["wall_names"]))]


def _impact_frame(wall_names, walls, measured, x) -> tuple | None:
    """The part of an impact scene's side view (x, z) worth showing [m]: the measured walls (a dump body and its
    tailgate) where they are, and the middle 98 % of the particles, with a margin; the site's ground and the
    loader otherwise shrink a 5 m body to a few specks on a 12 m axis."""
    boxes = [v[:, [0, 2]] for name, (v, _) in zip(wall_names, walls) if name in measured]
    if len(x):
        boxes.append(np.percentile(x[:, [0, 2]], [1, 99], axis=0))
    if not boxes:
        return None
    pts = np.concatenate(boxes)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = 0.08 * float(np.max(hi - lo))
    return ((lo[0] - pad, lo[1] - pad), (hi[0] + pad, hi[1] + pad))


def _plot_impacts(out: Path, model, spec, m0) -> str:
    """impacts.png: world 0's impact energy per area on each measured wall, summed over the phases
    (``measure.plot_impacts``)."""
    walls = []
    for name in spec.measure.walls:
        k = model.wall_names.index(name)
        mesh = model.wall_meshes[k]
        faces = [m0["phases"][ph][name]["faces"] for ph in m0["phases"] if name in m0["phases"][ph]]
        energy = np.sum([np.asarray(f["energy_j"], dtype=float) for f in faces], axis=0)
        count = np.sum([np.asarray(f["count"], dtype=float) for f in faces], axis=0)
        walls.append((name, host(mesh.points).astype(np.float64), host(mesh.indices).reshape(-1, 3), energy, count))
    phases = ", ".join(m0["phases"])
    return ms.plot_impacts(
        walls, out / "impacts.png", title=f"{spec.rig.replace('_', ' ')}: impacts of world 0 ({phases})"
    )


def _pictures(out: Path, spec, model, state, h, result) -> dict:
    """pile.png (side view of world 0 at the end, like the seeds' photos) and rig plots (press.png, drum.png)."""
    from .export import side_view_png

    files = {}
    x, r = _particles(model, state, h, 0)
    act = host(state.sphere_active).astype(bool)
    # a coating is drawn where it stayed: on a wall that moved (a lifted cylinder) it would hide the pile
    poses = host(state.wall_pose)
    still = np.all(np.abs(poses[:, :6]) < 1e-9, axis=1) if model.wall_count else np.zeros(0, bool)
    glued = act & (h["glued"] >= 0) & (h["world"] == 0)
    glued &= np.isin(h["glued"], np.flatnonzero(still))
    xs = np.concatenate([x, host(state.sphere_x)[glued]])
    rs = np.concatenate([r, h["radius"][glued]])
    walls = _world_walls(model, state)
    m0 = result.metrics[0]
    title = spec.rig.replace("_", " ")
    if "angle_fit_deg" in m0:
        title += f": angle of repose {m0['angle_fit_deg']:.1f} deg (fit), {m0['angle_image_deg']:.1f} deg (image)"
    frame = None
    if spec.measure.kind == "impacts":
        frame = _impact_frame(model.wall_names, walls, spec.measure.walls, xs)
        title = f"{title}: world 0 at {state.time:.2f} s"
    files["pile_png"] = side_view_png(
        str(out / "pile.png"), xs, rs, walls_world=walls, axis="y", title=title, frame=frame
    )
    if spec.measure.kind == "impacts" and "phases" in m0:
        files["impacts_png"] = _plot_impacts(out, model, spec, m0)
    frames = [tick[0] for tick in result.series.get("drum", []) if "angle_deg" in tick[0]]
    if spec.measure.kind == "drum" and frames:
        m = spec.measure
        s, z = ms.drum_section(x, m.drum_center, m.drum_axis)
        last = frames[-1]
        title = f"rotating drum: last frame {last['angle_deg']:.1f} deg at t = {last['time']:.2f} s"
        if "dynamic_angle_deg" in m0:
            title += f"\ndynamic angle {m0['dynamic_angle_deg']:.1f} +- {m0['dynamic_angle_sd_deg']:.1f} deg"
            title += f" over {m0['frames']} frames"
        files["drum_png"] = ms.plot_drum(s, z, r, last, str(out / "drum.png"), m.drum_radius, title=title)
    if spec.measure.kind == "press" and "force_n" in m0:
        unload = None
        if "unload_force_n" in m0:
            unload = {"displacement_m": m0["unload_displacement_m"], "force_n": m0["unload_force_n"]}
        ms.plot_press(
            {"displacement_m": np.asarray(m0["displacement_m"]), "force_n": np.asarray(m0["force_n"])},
            str(out / "press.png"),
            unload=unload,
            force_limit=spec.measure.force_limit or None,
        )
        files["press_png"] = str(out / "press.png")
    return files
