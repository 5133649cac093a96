"""Run a study: every design point as a world of a batched launch, results kept as they finish, resumable.

Layout of a study's output folder ``OUT``::

    OUT/.warpdem.lock       while the study runs: who runs it (pid, host, start, command; :mod:`.folder`)
    OUT/study.toml          copy of the study file the runs came from
    OUT/design.csv          the design table (run order, coded and actual values, world seeds, point ids)
    OUT/runs/<point_id>.json one file per finished run: its design row, overrides, responses, metrics
    OUT/runs/<point_id>.npz  its world's final state (spheres and walls), to draw and measure again
    OUT/launches/<id>/      each launch's metrics.json, final.npz, pile.png and, while it runs, checkpoint.npz
    OUT/results.csv         the design table with the responses of the finished runs (rewritten per batch)
    OUT/analysis/           report.md, ANOVA tables, plots (:func:`analyze`)
    OUT/verification/       runs at the chosen optimum and their summary (``verification.json``)

A run is finished when its JSON exists; a JSON is written to a temporary name and renamed, so a study
killed at any moment leaves only whole files, and running the same command again skips every finished
point (matched by ``point_id``, which hashes the scene, the run's overrides and its world seed, so an edited
study never mistakes an old result for a new point). The runs of one batch share one launch and finish
together; the launch checkpoints its whole state every minute (``OUT/launches/<id>/checkpoint.npz``) and a
rerun resumes it from there, bit-identical to an uninterrupted launch; ``[study] batch`` caps the worlds
per launch.

On one CUDA device the launches run side by side, a CUDA stream each, up to ``runner.SIDE_BY_SIDE_SPHERES``
spheres together (:func:`_run_on_device`); on the CPU one after another. Several devices
(``device="cuda:0,cuda:1"``, ``"cuda:all"``, or ``"cpu,cpu"`` for two CPU processes) are a Dask LocalCluster
of one worker process per device, and a scheduler's address a cluster elsewhere (:mod:`.executor`): each group
of runs is cut into at least one launch per worker, as even as the runs allow, and each launch is a task,
saved here as it returns. Launch ids hash the point ids, so a resumed study must keep the same number of
devices to pick up a checkpoint; finished points are kept whatever the devices.
"""

from __future__ import annotations

import functools
import json
import math
import os
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from warpdem.engine import suspect
from warpdem.engine.types import device_kind, device_names
from warpdem.scene.runner import _json_default

from . import spec as sp
from .folder import copy_atomic, hold, with_path, write_atomic


def _write_json(path: Path, data) -> None:
    """Write ``data`` as JSON to ``path``, whole or not at all (:func:`folder.write_atomic`)."""
    write_atomic(path, json.dumps(data, indent=1, default=_json_default))


def _scene(study: sp.StudySpec, overrides: dict):
    """SceneSpec with the overrides that must be shared by a batch (rig parameters first, then the rest)."""
    from warpdem.scene import rigs
    from warpdem.scene.stage import apply_overrides

    rig_vals = {k: v for k, v in overrides.items() if sp.is_rig_key(k)}
    if study.rig is not None:
        scene = rigs.spec(study.rig, rig_vals, study.smoke)
    else:
        scene = rigs.load(study.scene_path, rig_vals)
    shared = {k: v for k, v in overrides.items() if not sp.is_rig_key(k) and not sp.varies_per_world(k)}
    return apply_overrides(scene, shared)


def _response(metrics: dict, measure: str):
    """The metric named by ``measure`` (a key, or a dotted path into nested metrics); NaN when missing."""
    v = metrics
    for part in measure.split("."):
        if not isinstance(v, dict) or part not in v:
            return math.nan
        v = v[part]
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def parse_devices(device: str) -> list[str]:
    """The devices named by ``device`` (:func:`warpdem.engine.types.device_names`)."""
    return device_names(device)


def merges_scenes(devices: list[str]) -> bool:
    """Whether launches on ``devices`` hold worlds of several scenes (:func:`_batches`): on GPUs, where a launch
    costs about its steps whatever its worlds; not on CPUs, where it costs its particle-steps and a scene of
    larger grains would step at the smaller grains' step."""
    return all(device_kind(d) == "cuda" for d in devices)


def _batches(study: sp.StudySpec, rows: list[dict], parts: int = 1, merge: bool = False) -> list[list[dict]]:
    """Runs grouped by what they must share (scene, rig parameters); with ``merge``, groups whose scenes differ
    only in their particles (grain size, shape, count, feed: ``runner.shares_launch``) join one group, each
    scene's runs together; each group cut to ``study.batch`` (to single runs where the worlds would share the wall they are
    measured by, ``runner.independent_worlds``); with ``parts`` > 1 (devices) each group is also cut into at
    least ``parts`` launches (as many as it has runs at most), their sizes differing by one at most."""
    from warpdem.scene.runner import independent_worlds, shares_launch

    by_key: dict[tuple, list[dict]] = {}
    for row in rows:
        by_key.setdefault(sp.batch_key(study, row["overrides"]), []).append(row)
    # a GPU launch costs about its steps, whatever its worlds: scenes that can share one do
    groups: list[tuple] = []  # (scene, rows)
    for g in by_key.values():
        scene = _scene(study, g[0]["overrides"])
        mate = next((k for k, (other, _) in enumerate(groups) if merge and shares_launch(other, scene)), None)
        if mate is None:
            groups.append((scene, list(g)))
        else:
            groups[mate][1].extend(g)
    out = []
    for scene, g in groups:
        if not independent_worlds(scene):
            out += [[r] for r in g]
            continue
        if parts <= 1:
            size = study.batch or len(g)
            out += [g[i : i + size] for i in range(0, len(g), size)]
            continue
        n = max(-(-len(g) // study.batch) if study.batch else 1, min(parts, len(g)))
        q, r = divmod(len(g), n)
        starts = [k * q + min(k, r) for k in range(n + 1)]
        out += [g[starts[k] : starts[k + 1]] for k in range(n)]
    return out


def _launch_id(rows: list[dict]) -> str:
    import hashlib

    return hashlib.sha1(",".join(r["point_id"] for r in rows).encode()).hexdigest()[:12]


def run_batch(
    study: sp.StudySpec,
    rows: list[dict],
    device: str,
    progress=None,
    out_dir=None,
    checkpoint_every: float = 0.0,
    stop_after: float = 0.0,
) -> list[dict]:
    """Run ``rows`` (dicts with ``overrides`` and ``world_seed``) as the worlds of one launch; returns one
    record per row: responses, the world's metrics, run info. With ``out_dir`` the launch checkpoints every
    ``checkpoint_every`` wall seconds there and resumes from its checkpoint (see ``run_scene``); with
    ``stop_after`` it saves a checkpoint and raises ``runner.RunStopped`` after that many wall seconds."""
    from warpdem.engine.solver import drive

    return drive(run_batch_iter(study, rows, device, progress, out_dir, checkpoint_every, stop_after))


def run_batch_iter(
    study: sp.StudySpec,
    rows: list[dict],
    device: str,
    progress=None,
    out_dir=None,
    checkpoint_every: float = 0.0,
    stop_after: float = 0.0,
):
    """:func:`run_batch` as a generator that yields as :func:`runner.run_scene_iter` does."""
    from warpdem.scene.runner import WorldGroup, run_scene_iter

    # the rows of each scene (rig parameters and shared overrides) are one group of worlds (see _batches)
    by_key: dict[tuple, list[int]] = {}
    for i, r in enumerate(rows):
        by_key.setdefault(sp.batch_key(study, r["overrides"]), []).append(i)
    varying = sorted({k for r in rows for k in r["overrides"] if sp.varies_per_world(k)})
    groups = []
    for idx in by_key.values():
        part = [rows[i] for i in idx]
        # a world whose run does not set a varied key keeps the scene's value (None)
        variations = {k: [r["overrides"].get(k) for r in part] for k in varying}
        seeds = [int(r["world_seed"]) for r in part]
        groups.append(
            WorldGroup(
                _scene(study, part[0]["overrides"]),
                len(part),
                variations or None,
                tuple(seeds) if any(seeds) else None,
            )
        )
    first = groups[0]
    res = yield from run_scene_iter(
        first.spec,
        device=device,
        out_dir=out_dir,
        world_count=first.world_count,
        variations=first.variations,
        frames=False,
        progress=progress,
        world_seeds=list(first.world_seeds) if first.world_seeds else None,
        checkpoint_every=checkpoint_every,
        stop_after=stop_after,
        also=groups[1:],
        quiet=True,  # the run checks list the warnings, once per study
    )
    info = dict(res.info)
    out: list = [None] * len(rows)
    for i, m in zip([i for idx in by_key.values() for i in idx], res.metrics):
        responses = {r.name: _response(m, r.measure) for r in study.responses}
        out[i] = {"responses": responses, "metrics": m, "info": info}
    return out


def _time_left(stop_after: float, t0: float) -> float:
    """Wall seconds left of ``stop_after`` since ``t0`` (perf_counter), at least 1 ns so a launch always
    starts and checkpoints; 0 (no limit) stays 0."""
    return max(stop_after - (time.perf_counter() - t0), 1e-9) if stop_after > 0 else 0.0


def _progress_bar(total: int, initial: int, desc: str, enabled: bool):
    if not enabled:
        return None
    try:
        from tqdm import tqdm
    except ImportError:  # tqdm is a dependency; the GPU machine may lack it
        return None
    return tqdm(total=total, initial=initial, desc=desc, unit="run", smoothing=0.0)


def _check_folder(out: Path, study: sp.StudySpec, log) -> None:
    """An output folder holds one study: refuse to mix another study's runs into it. A copy of the study file
    that names no study (empty or cut short: a first start that failed, on a full disk say) is removed while no
    run has finished, so that the study starts again; with finished runs it is refused, naming the file."""
    copy_ = out / "study.toml"
    if not copy_.exists():
        return
    try:
        with open(copy_, "rb") as fh:
            name = sp.tomllib.load(fh).get("study", {}).get("name")
        reason = None if isinstance(name, str) else "names no study ([study] name)"
    except (sp.tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        reason = f"is not TOML ({e})"
    except OSError as e:
        raise with_path(e, copy_) from e
    if reason is not None:
        if copy_.stat().st_size == 0:
            reason = "is empty"
        done = len(list((out / "runs").glob("*.json")))
        if done:
            raise sp.StudyError(
                f"{copy_}: {reason}, yet {out / 'runs'} holds {done} finished run(s); put back the study file they "
                f"ran (cp STUDY.toml {copy_}) and run again, or choose another --out"
            )
        log(f"{copy_}: {reason} and no run has finished (a first start cut short): starting again")
        copy_.unlink()
        return
    if name != study.name:
        raise sp.StudyError(f"{out}: holds study {name!r}, not {study.name!r}; choose another --out")


def world_states(batch: list[dict], records: list[dict]) -> dict:
    """{point_id: world state}: each run's own world cut out of its launch's final.npz (every world's final state
    is kept, so a run can be drawn and measured again without rerunning); {} for a run whose launch wrote
    none."""
    from warpdem.scene.runner import world_state

    finals: dict = {}
    out = {}
    for row, rec in zip(batch, records):
        path = rec["info"].get("files", {}).get("final_npz")
        if not path or not Path(path).exists():
            continue
        if path not in finals:
            with np.load(path) as data:
                finals[path] = {k: data[k] for k in data.keys()}
        out[row["point_id"]] = world_state(finals[path], int(rec["metrics"]["world"]))
    return out


def _save_batch(
    study, runs_dir: Path, batch: list[dict], records: list[dict], wall: float, device: str, states=None
) -> None:
    """Write each run of ``batch``: its world's final state (``runs/<point_id>.npz``, from ``states``, as a
    cluster's task returns them, else :func:`world_states`), then its JSON."""
    states = world_states(batch, records) if states is None else states
    for row, rec in zip(batch, records):
        # the state before the record: a run is finished when its JSON exists, and then its state does too
        if row["point_id"] in states:
            tmp = runs_dir / f"{row['point_id']}.tmp.npz"
            np.savez_compressed(tmp, **states[row["point_id"]])
            os.replace(tmp, runs_dir / f"{row['point_id']}.npz")
        _write_json(
            runs_dir / f"{row['point_id']}.json",
            {
                "study": study.name,
                "run": row["run"],
                "point_id": row["point_id"],
                "world_seed": row["world_seed"],
                "design": row["row"],
                "overrides": row["overrides"],
                "responses": rec["responses"],
                "metrics": rec["metrics"],
                "info": rec["info"] | {"batch_worlds": len(batch), "batch_wall_s": wall},
                "device": device,
            },
        )


def _run_on_device(
    study,
    out: Path,
    batches: list[list[dict]],
    device: str,
    bar,
    t0: float,
    checkpoint_every: float,
    stop_after: float,
    on_saved=None,
    log=None,
    save=None,
) -> str | None:
    """Run ``batches`` on one device: side by side on a GPU (:func:`runner.run_together`, up to
    ``runner.SIDE_BY_SIDE_SPHERES``), one after another on the CPU; each launch is saved (``OUT/runs``, or by
    ``save(batch, records, wall_s, device, None)``) the moment it ends, then ``on_saved()`` is called. With ``stop_after`` (wall seconds since ``t0``) a launch saves its
    checkpoint and stops, and no launch starts past the limit but the first. A failing launch lets the running
    ones end, starts no other, and its error is raised. Returns the stop message(s), or None."""
    from warpdem.scene.runner import RunStopped, run_together

    runs_dir = out / "runs"
    base = bar.n if bar is not None else 0
    done = [0.0] * len(batches)
    started: dict[int, float] = {}
    stops, errors = [], []

    def show(k: int, frac: float, msg: str) -> None:
        done[k] = frac * len(batches[k])
        if bar is not None:
            bar.n = int(base + sum(done))  # whole runs: the launch's own share is in the postfix
            bar.set_postfix_str(
                f"launch {k + 1}/{len(batches)}: {len(batches[k])} worlds, {frac:.0%}, {msg}", refresh=False
            )
            bar.refresh()

    def start(k: int):
        started[k] = time.perf_counter()
        return run_batch_iter(
            study,
            batches[k],
            device,
            progress=functools.partial(show, k),
            out_dir=out / "launches" / _launch_id(batches[k]),
            checkpoint_every=checkpoint_every,
            stop_after=_time_left(stop_after, t0),
        )

    def admit(k: int) -> bool:
        # the first launch of a call always starts (and saves a checkpoint at least), so every call advances
        late = stop_after > 0 and k > 0 and time.perf_counter() - t0 >= stop_after
        return not (late or stops or errors)

    def end(k: int, outcome) -> None:
        wall = time.perf_counter() - started[k]
        if isinstance(outcome, RunStopped):
            what = "stopped"
            stops.append(f"launch {k + 1} of {len(batches)}: {outcome}")
        elif isinstance(outcome, BaseException):
            what = "failed"
            errors.append(outcome)
        else:
            what = "done"
            if save is None:
                _save_batch(study, runs_dir, batches[k], outcome, wall, device)
            else:
                save(batches[k], outcome, wall, device, None)
            show(k, 1.0, "done")
            if on_saved is not None:
                on_saved()
        if log is not None:
            runs = ", ".join(str(r["run"]) for r in batches[k])
            told = f"{len(batches[k])} world(s) saved" if what == "done" else str(outcome)
            log(f"launch {k + 1} of {len(batches)} {what} after {wall:.1f} s on {device} (runs {runs}): {told}")

    outcomes = run_together([functools.partial(start, k) for k in range(len(batches))], device, admit=admit, on_end=end)
    if errors:
        raise errors[0]
    left = sum(o is None for o in outcomes)
    if left and not stops:
        stops.append(f"the wall-time limit ({stop_after:.0f} s) came before {left} of {len(batches)} launch(es)")
    return "; ".join(stops) or None


def _study_rows(study: sp.StudySpec, table: pd.DataFrame) -> list[dict]:
    """One launch row per run of the design ``table`` (run number, point id, world seed, overrides, table row)."""
    return [
        {
            "run": int(r["run"]),
            "point_id": r["point_id"],
            "world_seed": int(r["world_seed"]),
            "overrides": sp.run_overrides(study, r),
            "row": r.to_dict(),
        }
        for _, r in table.iterrows()
    ]


def _logging_to(path: Path, log):
    """``log`` that also appends each message, time-stamped, to ``path`` (the study's log.txt: what ran, where,
    how long, and every stop and failure, kept after the console is gone)."""

    def both(msg: str) -> None:
        if log is not None:
            log(msg)
        try:
            with open(path, "a", encoding="utf-8") as fh:
                fh.write(f"{time.strftime('%Y-%m-%d %H:%M:%S')} {msg}\n")
        except OSError as e:  # a full disk shows at close, without the file's name
            raise with_path(e, path) from e

    return both


def plan_study(study, out_dir=None, device: str = "cpu") -> dict:
    """What :func:`run_study` would run, without running anything: ``table`` (the design, coded and actual, with
    a ``status`` column: finished in ``out_dir`` or pending), ``launches`` (one dict per launch of the pending
    runs: ``runs`` (run numbers), ``worlds``, ``particles`` per world (the factories' counts, the
    mean where the launch's scenes differ; None where a factory gives a mass), ``duration_s`` simulated at most) and ``cost``: the launches' simulated seconds and
    world-seconds, and particle-seconds where every count is known (a run that settles stops sooner)."""
    study = study if isinstance(study, sp.StudySpec) else sp.load_study(study)
    out = Path(out_dir) if out_dir else Path("runs") / study.name
    table = sp.design_table(study)
    rows = _study_rows(study, table)
    done = {r["point_id"] for r in rows if (out / "runs" / f"{r['point_id']}.json").exists()}
    table["status"] = ["finished" if pid in done else "pending" for pid in table["point_id"]]
    pending = [r for r in rows if r["point_id"] not in done]
    launches = []
    devices = parse_devices(device)
    scene_of = _scene_cache(study)
    for batch in _batches(study, pending, len(devices), merges_scenes(devices)) if pending else []:
        scenes = [scene_of(r["overrides"]) for r in batch]
        counts = [f.count for scene in scenes for f in scene.factories]
        particles = None if any(c is None for c in counts) else int(sum(counts)) / len(batch)
        launches.append(
            {
                "runs": [r["run"] for r in batch],
                "worlds": len(batch),
                "particles": particles if particles is None or particles % 1 else int(particles),
                "duration_s": max(float(scene.run.duration) for scene in scenes),
            }
        )
    known = all(L["particles"] is not None for L in launches)
    cost = {
        "runs": len(rows),
        "pending": len(pending),
        "launches": len(launches),
        "simulated_s": sum(L["duration_s"] for L in launches),
        "world_s": sum(L["worlds"] * L["duration_s"] for L in launches),
        "particle_s": sum(L["worlds"] * L["particles"] * L["duration_s"] for L in launches) if known else None,
    }
    return {
        "study": study,
        "out": str(out),
        "table": table,
        "launches": launches,
        "cost": cost,
        "verification": _plan_verification(study, out, finished=not pending),
    }


def replicate_file(vdir: Path, k: int) -> Path:
    """Verification replicate ``k`` (1-based)'s record in ``vdir`` (``OUT/verification``)."""
    return vdir / f"replicate_{k}.json"


def verification_response(study: sp.StudySpec):
    """The response the verification runs check (the first with a target), or None where the study makes no
    verification runs: no replicates, no model to choose their settings, or no target."""
    if study.verification.replicates <= 0 or study.analysis.model == "none":
        return None
    return next((r for r in study.responses if r.target is not None), None)


def _plan_verification(study, out: Path, finished: bool) -> dict | None:
    """The verification runs :func:`run_study` would make after the design, or None when the study has none:
    ``replicates``, ``response`` (the first with a target), ``finished`` (replicates with a record), ``analysed``
    (every design run finished and ``OUT/analysis/summary.json`` written) and ``chosen`` (its chosen settings
    for that response; None where the analysis chose none or has not run)."""
    resp = verification_response(study)
    if resp is None:
        return None
    n = study.verification.replicates
    summary = out / "analysis" / "summary.json"
    analysed = finished and summary.exists()
    chosen = (json.loads(summary.read_text()).get(resp.name) or {}).get("chosen") if analysed else None
    return {
        "replicates": n,
        "response": resp.name,
        "target": resp.target,
        "finished": sum(replicate_file(out / "verification", k + 1).exists() for k in range(n)),
        "analysed": analysed,
        "chosen": chosen,
    }


def run_study(
    study,
    out_dir=None,
    device: str = "cpu",
    progress: bool = True,
    analyze_after: bool = True,
    verify: bool = True,
    log=print,
    checkpoint_every: float = 60.0,
    stop_after: float = 0.0,
    scheduler: str | None = None,
    shared_dir: str | None = None,
) -> dict:
    """Run (or resume) ``study`` (a path or a StudySpec) into ``out_dir`` (default ``runs/<name>``).

    Finished points are skipped; the rest run batch by batch (a batch = runs that share a scene, as
    worlds of one launch). A launch also checkpoints every ``checkpoint_every`` wall seconds into
    ``OUT/launches/<id>/`` (id: hash of its point ids), so a crash mid-launch resumes there. Then, unless
    disabled, the analysis (:func:`analyze`) and the verification
    runs at the chosen optimum. ``device`` may name several devices (:func:`parse_devices`): the runs are then
    split into one launch per device, run at once on a local Dask cluster, one worker per device; the
    verification runs go to the same executor. With ``stop_after`` (wall seconds from the call, the cluster's start
    included; 0: none) the study stops by itself once that much wall time has passed: a launch then saves its
    checkpoint at its next output tick, no further launch starts, and ``stopped`` in the result says where; the same
    call resumes. Returns
    {"out", "runs", "ran", "skipped", "wall_s", "batches", "analysis", "verification", "stopped"}.

    ``scheduler`` (else the environment variable ``WARPDEM_SCHEDULER``): the address of a Dask scheduler
    (``tcp://HOST:8786``); each launch is then a task of its cluster (:mod:`.executor`), and ``device`` says
    what kind of device the launches are cut for. ``shared_dir``: a folder every worker of that cluster can
    write; launches checkpoint there, so a launch retried on another worker resumes instead of restarting.
    """
    # the wall-time limit counts from here, as a diagnosis's does: a Dask cluster's start (its workers' first kernel
    # compile on a fresh machine) is wall time too, and left out it made a 530 s limit overrun a 600 s device call
    t0 = time.perf_counter()
    study = study if isinstance(study, sp.StudySpec) else sp.load_study(study)
    out = Path(out_dir) if out_dir else Path("runs") / study.name
    # the folder's lock (OUT/.warpdem.lock) for the whole study: a second study on it is refused; the first writes
    # are whole files (a start cut short, by a full disk say, leaves none, and a rerun starts again)
    with hold(out, f"study {study.name}") as lock:
        log = _logging_to(out / "log.txt", log)
        if lock.took_over:
            log(lock.took_over)
        _check_folder(out, study, log)
        log(f"{study.name}: study {study.path or '(in memory)'} on {device}, into {out}")
        if study.path is not None:
            copy_atomic(study.path, out / "study.toml")
        table = sp.design_table(study)
        write_atomic(out / "design.csv", table.to_csv(index=False))
        runs_dir = out / "runs"
        runs_dir.mkdir(exist_ok=True)
        rows = _study_rows(study, table)
        devices = parse_devices(device)
        from .executor import executor_for

        # a cluster is reached (or refused) before anything is counted or drawn
        ex = executor_for(devices, scheduler, shared_dir)
        pending = [r for r in rows if not (runs_dir / f"{r['point_id']}.json").exists()]
        done0 = len(rows) - len(pending)
        if done0:
            log(f"{study.name}: {done0} of {len(rows)} runs already finished in {out}; running {len(pending)}")
        bar = _progress_bar(len(rows), done0, study.name, progress)
        batches = _batches(study, pending, ex.parallel, merges_scenes(devices)) if pending else []
        stopped = None
        with ex:
            if batches:
                if getattr(ex, "dashboard", None):
                    log(f"{study.name}: {len(ex.devices)} worker(s), Dask dashboard {ex.dashboard}")
                stopped = ex.run(
                    study,
                    out,
                    batches,
                    bar,
                    t0,
                    checkpoint_every,
                    stop_after,
                    lambda m: log(f"{study.name}: {m}"),
                    on_saved=lambda: _results_csv(study, out),
                )
                _results_csv(study, out)
            return _finish_study(
                study,
                out,
                rows,
                done0,
                t0,
                bar,
                batches,
                stopped,
                progress,
                log,
                ex,
                analyze_after,
                verify,
                checkpoint_every,
                stop_after,
            )


def _finish_study(
    study,
    out,
    rows,
    done0,
    t0,
    bar,
    batches,
    stopped,
    progress,
    log,
    ex,
    analyze_after,
    verify,
    checkpoint_every,
    stop_after,
) -> dict:
    """The rest of :func:`run_study` once its launches have ended: counts, run checks, the analysis and the
    verification runs on the study's executor ``ex``."""
    from warpdem.scene.runner import RunStopped

    runs_dir = out / "runs"
    if bar is not None:
        bar.close()
    wall = time.perf_counter() - t0
    finished = sum((runs_dir / f"{r['point_id']}.json").exists() for r in rows)
    log(f"{study.name}: {finished} of {len(rows)} runs finished ({finished - done0} now, in {wall:.1f} s)")
    flags = run_checks(out, study)
    for line in check_lines(flags):
        log(f"{study.name}: check: {line}")
    result = {
        "out": str(out),
        "runs": len(rows),
        "ran": finished - done0,
        "skipped": done0,
        "wall_s": wall,
        "batches": len(batches),
        "analysis": None,
        "verification": None,
        "stopped": stopped,
        "checks": flags,
    }
    if not batches or stopped:
        _results_csv(study, out)
    if stopped:
        log(f"{study.name}: stopped, {finished} of {len(rows)} runs finished; {stopped}")
        return result
    if analyze_after:
        result["analysis"] = analyze(out, study, flags=flags)
        if verify and verification_response(study) is not None:
            try:
                result["verification"] = run_verification(
                    study,
                    out,
                    result["analysis"],
                    ex.devices[0],
                    progress,
                    log,
                    checkpoint_every=checkpoint_every,
                    stop_after=_time_left(stop_after, t0),
                    executor=ex,
                )
            except RunStopped as e:
                result["stopped"] = f"verification: {e}"
            v = result["verification"]
            if isinstance(v, dict) and v.get("stopped"):
                result["stopped"], result["verification"] = f"verification: {v['stopped']}", None
            if result["stopped"]:
                log(f"{study.name}: stopped in the verification runs; {result['stopped']}")
    return result


def load_results(out, study: sp.StudySpec | None = None, metrics: dict | None = None) -> pd.DataFrame:
    """The design table of ``out`` with one column per response (NaN where a run has not finished); a response
    its runs did not record (one added to the study file since) is read from each run's stored metrics. With
    ``metrics`` ({point_id: metrics}, :func:`remeasure`) every response of those runs is read from them instead."""
    out = Path(out)
    study = study or sp.load_study(out / "study.toml", check_scene=False)
    table = pd.read_csv(out / "design.csv")
    for r in study.responses:
        table[r.name] = math.nan
    table["wall_s"] = math.nan
    for i, pid in enumerate(table["point_id"]):
        f = out / "runs" / f"{pid}.json"
        if f.exists():
            with open(f) as fh:
                rec = json.load(fh)
            for r in study.responses:
                # a response added to the study after its runs is read from their stored metrics
                if metrics is not None and pid in metrics:
                    v = _response(metrics[pid], r.measure)
                elif r.name in rec["responses"]:
                    v = rec["responses"][r.name]
                else:
                    v = _response(rec["metrics"], r.measure)
                table.loc[i, r.name] = math.nan if v is None else v
            table.loc[i, "wall_s"] = rec["info"].get("batch_wall_s", math.nan)
    return table


def _checks_of(rec: dict, scene, study: sp.StudySpec) -> list[tuple[str, str]]:
    """(check, detail) of one run's record (see :func:`run_checks`); ``scene`` is the run's SceneSpec."""
    from warpdem.scene.measure import QUASI_STATIC_INERTIAL_NUMBER
    from warpdem.scene.runner import metric_error

    m, info, found = rec["metrics"], rec["info"], []
    for r in study.responses:
        v = rec["responses"].get(r.name)
        if v is None or not math.isfinite(float(v)):
            why = metric_error(m, scene.measure.kind, r.measure.split(".")[0])
            found.append(("measurement", f"no {r.name} ({r.measure})" + (f": {why}" if why else "")))
    if scene.run.settle_energy > 0 and m.get("stop", info.get("stop")) == "duration":
        found.append(("unsettled", f"still moving at the end of its {m.get('time_s', scene.run.duration):.3g} s"))
    # the run's own physics warnings (warpdem.engine.suspect): lost bodies, too long a step, overlaps
    warned = m.get("warnings", [])
    found += [(x["check"], x["detail"]) for x in warned]
    # a pile measured before runs checked their pile's share of the bed is checked from its record
    if "detached" in m and not any(x["check"] == "pile_apart" for x in warned):
        late = suspect.pile_apart_warning(m["detached"], m.get("particles", 0))
        if late is not None:
            found.append((late["check"], late["detail"]))
    inertial = m.get("inertial_number_max")
    if inertial is not None and inertial > QUASI_STATIC_INERTIAL_NUMBER:
        found.append(
            (
                "inertial",
                f"inertial number {inertial:.3g}, above the quasi-static {QUASI_STATIC_INERTIAL_NUMBER:g}: slow the "
                "piston",
            )
        )
    if info.get("step_warning"):
        found.append(("step", info["step_warning"]))
    return found


def run_checks(out, study: sp.StudySpec | None = None) -> list[dict]:
    """What may make a finished run's numbers wrong, per run of ``out`` (run, point_id, check, detail), in run
    order: ``measurement`` (a response it could not measure, with the metric's own error), ``unsettled`` (a scene
    that stops once settled ran to its duration instead), ``lost`` (more than :data:`warpdem.engine.suspect.LOST_FRACTION_MAX` of its
    bodies left the domain), ``fast``, ``start_overlap``, ``soft`` and ``outlet`` (the run's own warnings, see
    :mod:`warpdem.engine.suspect`), ``inertial`` (a press faster than
    :data:`warpdem.scene.measure.QUASI_STATIC_INERTIAL_NUMBER`), ``step`` (the step exceeded the stable step
    in some tick), ``outlet`` (a pile that grew up to its funnel's outlet), ``off_axis`` (a pile that moved off
    the axis it was poured on) and ``pile_apart`` (a heap that holds too little of its bed), the last three the
    run's own warnings (``pile_apart`` is also read off older records' metrics)."""
    out = Path(out)
    study = study or sp.load_study(out / "study.toml", check_scene=False)
    flags, scene = [], _scene_cache(study)
    for row, rec in _finished_records(out, study):
        for check, detail in _checks_of(rec, scene(row["overrides"]), study):
            flags.append({"run": row["run"], "point_id": row["point_id"], "check": check, "detail": detail})
    return flags


def _finished_records(out: Path, study: sp.StudySpec):
    """(design row, stored run record) of each finished run of ``out``, in run order."""
    for row in _study_rows(study, sp.design_table(study)):
        f = out / "runs" / f"{row['point_id']}.json"
        if f.exists():
            with open(f) as fh:
                yield row, json.load(fh)


def _scene_cache(study: sp.StudySpec):
    """:func:`_scene` of a run's overrides, built once per batch key (the runs that share a scene)."""
    scenes: dict[tuple, object] = {}

    def scene(overrides: dict):
        key = sp.batch_key(study, overrides)
        if key not in scenes:
            scenes[key] = _scene(study, overrides)
        return scenes[key]

    return scene


def check_lines(flags: list[dict], key: str = "run") -> list[str]:
    """:func:`run_checks`' flags as one line per check: its runs (or, with ``key="replicate"``, a verification's
    replicates), and the first one's detail."""
    lines = []
    for check in dict.fromkeys(f["check"] for f in flags):
        these = [f for f in flags if f["check"] == check]
        first = these[0]
        if len(these) == 1:
            lines.append(f"{CHECK_WORDS[check]}: {key} {first[key]}: {first['detail']}")
        else:
            runs = ", ".join(str(f[key]) for f in these)
            lines.append(f"{CHECK_WORDS[check]}: {key}s {runs} ({key} {first[key]}: {first['detail']})")
    return lines


CHECK_WORDS = {
    "measurement": "measurement failed",
    "unsettled": "did not settle",
    "lost": "lost particles",
    "fast": "too long a step for the speed",
    "start_overlap": "overlaps at the start",
    "soft": "deep overlaps",
    "inertial": "not quasi-static",
    "step": "step above the stable step",
    "outlet": "pile reached the funnel",
    "off_axis": "pile off its axis",
    "pile_apart": "bed not in the pile",
    "escaped": "spheres squeezed past the bar",
}
"""How the report and the console name each of :func:`run_checks`' checks."""


def _results_csv(study, out: Path) -> None:
    write_atomic(out / "results.csv", load_results(out, study).to_csv(index=False))


def external_runs(path, study: sp.StudySpec) -> pd.DataFrame:
    """Runs made elsewhere (an EDEM run table, a lab's), as :func:`load_results` gives a study's: the CSV at
    ``path`` holds one row per run with a column per factor of ``study`` (actual units) and per response, and
    optionally ``run``; an empty response cell is a run that could not be measured (left out). Raises StudyError
    naming the file, the column and the value."""
    path = Path(path)
    try:
        # only an empty cell is a missing value (a failed run's response); "n/a" and the like are refused
        raw = pd.read_csv(path, keep_default_na=False, na_values=[""])
    except (OSError, pd.errors.ParserError, pd.errors.EmptyDataError) as e:
        raise sp.StudyError(f"{path}: cannot be read as a CSV run table: {e}") from None
    need = [f.name for f in study.factors] + [r.name for r in study.responses]
    missing = [c for c in need if c not in raw.columns]
    if missing:
        raise sp.StudyError(
            f"{path}: column {missing[0]!r} is missing; expected a column per factor (actual units) and per "
            f"response: {', '.join(need)}"
        )
    out = pd.DataFrame({"run": raw["run"] if "run" in raw.columns else np.arange(1, len(raw) + 1)})
    for c in need:
        vals = pd.to_numeric(raw[c], errors="coerce")
        bad = vals.isna() & raw[c].notna()
        if bad.any():
            i = int(np.flatnonzero(bad.to_numpy())[0])
            raise sp.StudyError(f"{path}: column {c!r}, row {i + 2}: {raw[c].iloc[i]!r} is not a number")
        out[c] = vals
    for f in study.factors:
        if out[f.name].isna().any():
            i = int(np.flatnonzero(out[f.name].isna().to_numpy())[0])
            raise sp.StudyError(f"{path}: column {f.name!r}, row {i + 2} is empty; a factor needs a value in every run")
    for f in study.levels:
        out[f"{f.name}_actual"] = out[f.name]
        out[f.name] = f.to_coded(out[f.name].to_numpy(dtype=float))
    return out


def analyze(
    out, study: sp.StudySpec | None = None, runs=None, measure: Mapping | None = None, flags: list | None = None
) -> dict:
    """Fit the study's model to the finished runs of ``out`` and write ``out/analysis`` (report.md, ANOVA
    tables, Pareto and contour plots, target solutions, the gallery of the runs). With ``runs`` (a CSV run table,
    :func:`external_runs`) analyse those instead, into ``out``. With ``measure`` ({``measure.FIELD``: value},
    possibly empty) every run is measured again from its stored final state under those settings
    (:func:`remeasure`) and analysed so. ``flags``: :func:`run_checks` of ``out`` where the caller has them
    already (default: checked here; none for ``runs``). Returns :func:`report.write_report`'s summary (with
    ``[analysis] model = "none"``, :func:`_replicate_report`'s)."""
    out = Path(out)
    study = study or sp.load_study(out / "study.toml", check_scene=False)
    notes = []
    remeasured = None
    if measure is not None:
        if runs is not None:
            raise sp.StudyError(f"--runs {runs}: runs made elsewhere have no stored state to measure again")
        remeasured = remeasure(out, study, measure)
        told = ", ".join(f"{k} = {v}" for k, v in measure.items()) or "the study's own measure settings"
        notes.append(f"Measured again from each run's stored final state ({len(remeasured)} runs) with {told}.")
    data = load_results(out, study, remeasured) if runs is None else external_runs(runs, study)
    finished = data[[r.name for r in study.responses]].notna().any(axis=1)
    if not finished.all():
        notes.append(f"{int((~finished).sum())} of {len(data)} runs have not finished; they are left out.")
    if flags is None:
        flags = run_checks(out, study) if runs is None else []
    if runs is None:
        notes += [f"Check: {line}." for line in check_lines(flags)]
    else:
        notes.append(f"Runs read from {runs} (made elsewhere): {len(data)} rows.")
    model = study.analysis.model
    used = data[finished].reset_index(drop=True)
    if model == "none":
        flagged = sorted({int(f["run"]) for f in flags})
        summary = _replicate_report(out / "analysis", study, used, notes, flagged)
    else:
        summary = _model_report(out / "analysis", study, used, notes)
    with open(out / "analysis" / "summary.json", "w") as fh:
        json.dump(summary, fh, indent=1, default=_json_default)
    used.to_csv(out / "analysis" / "runs.csv", index=False)  # the table the model was fitted to
    if runs is not None:
        return summary
    _append_settling(out, study)
    _append_gallery(out, study, measure)
    vfile = out / "verification" / "verification.json"
    if vfile.exists():
        with open(vfile) as fh:
            _append_verification(out, json.load(fh))
    return summary


def _model_report(folder: Path, study: sp.StudySpec, data: pd.DataFrame, notes: list[str]) -> dict:
    """The fitted model's report.md, tables and plots in ``folder`` (:func:`report.write_report`); its summary."""
    from .report import write_report

    model = study.analysis.model
    return write_report(
        folder,
        data,
        title=study.title or study.name,
        factors=study.levels,
        labels={f.name: f.label for f in study.factors},
        responses=[
            {
                "name": r.name,
                "unit": r.unit,
                "target": r.target,
                "goal": r.desirability_goal(),
                "transform": study.analysis.transform_for(r),
            }
            for r in study.responses
        ],
        model=list(model) if isinstance(model, tuple) else model,
        alpha=study.analysis.alpha,
        eliminate=study.analysis.eliminate,
        design_kind=study.design.kind,
        notes=notes,
    )


def replicate_summary(values, target: float | None, alpha: float = 0.05) -> dict:
    """Replicate runs of one setting against a measured ``target``: n, mean, SD (n - 1), standard error, range,
    the mean's two-sided (1 - ``alpha``) t interval and a one-sample t test of mean = target (scipy). NaN values
    are left out; the interval and test need two values, the test a target. Units are the values'."""
    from scipy import stats

    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    n = len(v)
    out = {"n": n, "mean": float(v.mean()) if n else math.nan, "min": float(v.min()) if n else math.nan}
    out["max"] = float(v.max()) if n else math.nan
    out |= {"sd": math.nan, "se": math.nan, "ci": [math.nan, math.nan], "alpha": alpha, "target": target}
    out |= {"t": math.nan, "p": math.nan}
    if n > 1:
        out["sd"] = float(v.std(ddof=1))
        out["se"] = out["sd"] / math.sqrt(n)
        out["ci"] = [float(x) for x in stats.t.interval(1.0 - alpha, n - 1, loc=out["mean"], scale=out["se"])]
        if target is not None and out["se"] > 0:
            test = stats.ttest_1samp(v, target)
            out["t"], out["p"] = float(test.statistic), float(test.pvalue)
    return out


def _replicate_report(
    folder: Path, study: sp.StudySpec, data: pd.DataFrame, notes: list[str], flagged: Sequence[int] = ()
) -> dict:
    """``[analysis] model = "none"`` (replicates, a steepest-ascent path, points without a model): report.md in
    ``folder`` with the runs and, where every run shares one setting (replicates), per response
    :func:`replicate_summary` against its target. Where :func:`run_checks` flags some of the runs (``flagged``,
    run numbers) and at least two are left, each summary also holds ``unflagged``: the same without them, with
    ``left_out`` naming them; a pile that slid as a body is not a replicate of the angle. Returns {response:
    summary}, empty where the runs lie at several settings (a mean over a path would mean nothing)."""
    folder.mkdir(parents=True, exist_ok=True)
    alpha = study.analysis.alpha
    settings = [f"{f.name}_actual" for f in study.levels]
    count = len(data[settings].drop_duplicates()) if len(data) else 0
    one = count == 1
    summary = {r.name: replicate_summary(data[r.name], r.target, alpha) for r in study.responses} if one else {}
    if one and "run" in data:
        ids = [int(k) for k in data["run"]]
        for r in study.responses:
            unflagged = unflagged_summary(data[r.name], ids, flagged, r.target, alpha)
            if unflagged is not None:
                summary[r.name]["unflagged"] = unflagged
    cols = [c for c in ("run", "world_seed") if c in data] + settings + [r.name for r in study.responses]
    lines = [
        f"# {study.title or study.name}",
        "",
        f"{len(data)} runs at {count} setting(s), no model fitted (`[analysis] model = none`)"
        + ("." if one else ": each run is listed, without a summary over settings."),
        "",
    ]
    lines += [f"- {n}" for n in notes] + ([""] if notes else [])
    lines += ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(f"{row[c]:.6g}" for c in cols) + " |" for _, row in data[cols].iterrows()]
    level = 100.0 * (1.0 - alpha)
    for r in study.responses if one else ():
        s = summary[r.name]
        unit = f" {r.unit}" if r.unit else ""
        lines += ["", f"## {r.name}", "", f"{s['n']} runs: mean {s['mean']:.4g}{unit}, SD {s['sd']:.3g}, "]
        lines[-1] += f"range {s['min']:.4g}–{s['max']:.4g}; {level:.0f} % interval of the mean "
        lines[-1] += f"[{s['ci'][0]:.4g}, {s['ci'][1]:.4g}]."
        if r.target is not None:
            lines += [
                "",
                f"Target {r.target:g}{unit}: the mean is {s['mean'] - r.target:+.3g}{unit} from it; one-sample t test "
                f"t = {s['t']:.3g}, p = {s['p']:.3g}.",
            ]
        if "unflagged" in s:
            lines += ["", replicate_line(s["unflagged"], unit) + "."]
    (folder / "report.md").write_text("\n".join(lines) + "\n")
    return summary


def unflagged_summary(values, ids, flagged, target: float | None, alpha: float = 0.05) -> dict | None:
    """:func:`replicate_summary` of ``values`` without those whose id (``ids``, one per value: run or replicate
    numbers) is among ``flagged``, with ``left_out`` (the flagged ids present, sorted); None when none is flagged
    or fewer than two are left. A pile that slid as a body is not a replicate of the angle."""
    left_out = sorted(set(flagged) & set(ids))
    kept = [v for i, v in zip(ids, values) if i not in left_out]
    if not left_out or len(kept) < 2:
        return None
    return replicate_summary(kept, target, alpha) | {"left_out": left_out}


def replicate_line(s: dict, unit: str = "", key: str = "run") -> str:
    """:func:`replicate_summary` ``s`` in one line: n, mean, SD, the mean's interval and the t test against the
    target; for a summary without the flagged runs (``unflagged``, with ``left_out``) led by the runs (``key``:
    or replicates) left out."""
    line = f"{s['n']} runs, mean {s['mean']:.4g}{unit}, SD {s['sd']:.3g}, "
    line += f"{100 * (1 - s['alpha']):.0f} % interval of the mean [{s['ci'][0]:.4g}, {s['ci'][1]:.4g}]"
    if s["target"] is not None:
        line += f"; target {s['target']:g}: t {s['t']:.3g}, p {s['p']:.3g}"
    if "left_out" in s:
        runs = ", ".join(str(k) for k in s["left_out"])
        line = f"Without {key}{'s' if len(s['left_out']) > 1 else ''} {runs} (flagged by the checks): " + line
    return line


EXCEL_FIT_KEYS = ("model", "n_used", "model_p", "r2", "adj_r2", "pred_r2", "adeq_precision", "suggested_model")
"""The fit statistics the workbook's Summary sheet gives per response (from summary.json)."""


def export_excel(out, path) -> Path:
    """The analysis of study folder ``out`` as an Excel workbook at ``path`` (pandas with openpyxl): a Summary
    sheet (per response: model, runs used, model p, R², adjusted and predicted R², adequate precision, the
    suggested model order, the equations), then one sheet per table the analysis wrote (``analysis/*.csv``: the
    runs it fitted, ANOVA, coefficients, target solutions, desirability), named after the file (cut to Excel's 31
    characters). Run :func:`analyze` first. Raises StudyError without an analysis or without openpyxl."""
    out, path = Path(out), Path(path)
    folder = out / "analysis"
    if not (folder / "summary.json").exists():
        raise sp.StudyError(f"{out}: no analysis to export (analysis/summary.json); run warpdem analyze {out} first")
    try:
        import openpyxl  # noqa: F401
    except ImportError:
        raise sp.StudyError(
            f"--excel {path}: writing a workbook needs openpyxl: python3 -m pip install 'warpdem[excel]'"
        ) from None
    with open(folder / "summary.json") as fh:
        summary = json.load(fh)
    rows = []
    for name, s in summary.items():
        if isinstance(s, dict) and "r2" in s:
            row = {"response": name} | {k: s.get(k) for k in EXCEL_FIT_KEYS}
            row.update(equation_coded=s.get("equation_coded"), equation_actual=s.get("equation_actual"))
            rows.append(row)
    sheets, used = {"Summary": pd.DataFrame(rows)}, {"Summary"}
    for csv in sorted(folder.glob("*.csv")):
        name = csv.stem[:31]
        k = 2
        while name in used:  # two long names cut to one
            name = f"{csv.stem[: 31 - len(str(k)) - 1]}~{k}"
            k += 1
        used.add(name)
        sheets[name] = pd.read_csv(csv)
    path.parent.mkdir(parents=True, exist_ok=True)
    with pd.ExcelWriter(path, engine="openpyxl") as xl:
        for name, table in sheets.items():
            table.to_excel(xl, sheet_name=name, index=False)
    return path


def confirmation_runs_interval(conf: dict, runs: int) -> tuple[float, float]:
    """The prediction interval for the mean of ``runs`` confirmation runs from a report entry's ``confirmation``
    (the model scale's prediction, mse, h0, df, alpha and transform), in the response's units: computed on the
    model's scale and brought back through the transform."""
    from .analysis import mean_prediction_interval
    from .transforms import Transform

    lo, hi = mean_prediction_interval(conf["predicted"], conf["mse"], conf["h0"], conf["df"], runs, conf["alpha"])
    return Transform(**conf.get("transform", {})).interval(lo, hi)


ADEQUATE_PRECISION_MIN = 4.0
"""Design-Expert's bound on adequate precision (signal to noise): above it the model can navigate the design
space."""


def study_records(out, study: sp.StudySpec, summary: dict, flags: list | None = None) -> list[dict]:
    """The analysis of ``out`` as ``--json`` records (name, value, expected, unit, pass), per response: the model's
    p (expected below alpha), R², adjusted and predicted R², adequate precision (expected above
    :data:`ADEQUATE_PRECISION_MIN`) and, with a target, the prediction at the chosen settings (expected: the
    target; passes when the target is reachable); for replicates without a model (:func:`_replicate_report`) the
    mean (expected: the target; passes when the mean's interval holds it), SD and count, and the same under
    ``unflagged.`` without the flagged runs; and one failing record per :func:`run_checks` flag (``flags``, where
    the caller has them already: the ones the analysis used)."""
    alpha = study.analysis.alpha
    recs: list[dict] = []
    for r in study.responses:
        s = summary.get(r.name)

        def rec(key, value, expected=None, passed=None, unit="", name=r.name):
            v = None if value is None or (isinstance(value, float) and not math.isfinite(value)) else value
            recs.append({"name": f"{name}.{key}", "value": v, "expected": expected, "unit": unit, "pass": passed})

        if isinstance(s, dict) and "ci" in s:
            for prefix, rs in (("", s), ("unflagged.", s.get("unflagged"))):
                if rs is None:
                    continue
                lo, hi = rs["ci"]
                held = (
                    None if r.target is None or not (math.isfinite(lo) and math.isfinite(hi)) else lo <= r.target <= hi
                )
                rec(f"{prefix}mean", rs["mean"], r.target, held, r.unit)
                rec(f"{prefix}sd", rs["sd"], unit=r.unit)
                rec(f"{prefix}n", rs["n"])
            continue
        if not isinstance(s, dict) or s.get("r2") is None:
            continue

        p = s.get("model_p")
        rec("model_p", p, f"< {alpha:g}", None if p is None else bool(p < alpha))
        for key in ("r2", "adj_r2", "pred_r2"):
            rec(key, s.get(key))
        ap = s.get("adeq_precision")
        ok = None if ap is None or not math.isfinite(ap) else bool(ap > ADEQUATE_PRECISION_MIN)
        rec("adeq_precision", ap, f"> {ADEQUATE_PRECISION_MIN:g}", ok)
        if r.target is not None:
            pred = s.get("predicted")
            if pred is None and isinstance(s.get("closest"), dict):
                pred = s["closest"].get("predicted")
            rec("predicted", pred, r.target, bool(s.get("reachable")), r.unit)
    for f in run_checks(out, study) if flags is None else flags:
        recs.append(
            {"name": f"run {f['run']}.{f['check']}", "value": f["detail"], "expected": None, "unit": "", "pass": False}
        )
    return recs


def _write_records(path, records: list[dict]) -> None:
    """``records`` as JSON to ``path`` ('-': stdout)."""
    text = json.dumps(records, indent=1, default=_json_default)
    if str(path) == "-":
        print(text)
    else:
        Path(path).write_text(text + "\n")


def _measure_overrides(measure: Mapping, where: str) -> dict:
    """``measure`` checked: keys ``measure.FIELD`` (the settings a stored state can be measured under again)."""
    out = {}
    for k, v in measure.items():
        if not str(k).startswith("measure."):
            raise sp.StudyError(
                f"{where}: {k} = {v!r} is not allowed; expected measure.FIELD keys (e.g. measure.base_height)"
            )
        out[str(k)] = v
    return out


def _run_state(out: Path, point_id: str) -> dict | None:
    """The stored final state of run ``point_id`` (``runs/<point_id>.npz``, :func:`_save_batch`), or None."""
    f = out / "runs" / f"{point_id}.npz"
    if not f.exists():
        return None
    with np.load(f) as data:
        return {k: data[k] for k in data.keys()}


def _free_spheres(state: dict) -> tuple[np.ndarray, np.ndarray]:
    """Centres (n, 3) and radii (n,) of a stored state's free particle spheres (glued ones excluded)."""
    free = state["sphere_glued"] < 0
    return state["sphere_x"][free].astype(np.float64), state["sphere_r"][free].astype(np.float64)


def _stored_piles(out: Path, study: sp.StudySpec, measure: Mapping | None, where: str):
    """(design row, run record, measure settings, stored state) of each finished run of ``out``: for a pile (an
    angle-of-repose scene) its measure settings with ``measure`` ({``measure.FIELD``: value}) applied and its
    stored state (``runs/<point_id>.npz``, None when it has none); for any other scene its own settings and None.
    Each caller decides what a missing state means. Raises StudyError for a key that is not a measure setting or a
    value the stage grammar refuses (``where`` names the caller in the message)."""
    from warpdem.scene.stage import StageError, apply_overrides

    ov = _measure_overrides(measure or {}, f"{out}: {where}")
    scene = _scene_cache(study)
    for row, rec in _finished_records(out, study):
        sc = scene(row["overrides"])
        if sc.measure.kind != "angle_of_repose":
            yield row, rec, sc.measure, None
            continue
        try:
            m = apply_overrides(sc, ov).measure if ov else sc.measure
        except (StageError, ValueError) as e:
            raise sp.StudyError(f"{out}: {where}: {e}") from None
        yield row, rec, m, _run_state(out, row["point_id"])


def remeasure(out, study: sp.StudySpec | None = None, measure: Mapping | None = None) -> dict[str, dict]:
    """Every finished run of ``out`` measured again from its stored final state (``runs/<point_id>.npz``): the
    pile metrics (``runner.PILE_METRICS``) under the run's own measure settings with ``measure``
    ({``measure.FIELD``: value}, e.g. ``measure.base_height``) applied, the run's other
    metrics as stored. Same function as at the end of a run (``runner.measure_pile``), so with no ``measure``
    the numbers are the stored ones. Returns {point_id: metrics}. Raises StudyError for a scene that is not an
    angle of repose, a key that is not a measure setting, or a run stored without its state (made before the
    states were kept: run it again)."""
    from warpdem.scene.runner import PILE_METRICS, measure_pile

    out = Path(out)
    study = study or sp.load_study(out / "study.toml", check_scene=False)
    result = {}
    for row, rec, m, state in _stored_piles(out, study, measure, "measure again"):
        if m.kind != "angle_of_repose":
            raise sp.StudyError(
                f"{out}: measure again: the scene measures {m.kind!r}; only an angle_of_repose pile is "
                "measured from its final state (a press curve or a drum's frames need the run itself)"
            )
        if state is None:
            raise sp.StudyError(
                f"{out}: run {row['run']} ({row['point_id']}) has no stored final state (runs/{row['point_id']}.npz); "
                "it was made before every run's state was kept: delete its runs/ JSON and run the study again"
            )
        metrics = {k: v for k, v in rec["metrics"].items() if k not in PILE_METRICS}
        metrics.update(measure_pile(*_free_spheres(state), m))
        result[row["point_id"]] = metrics
    return result


GALLERY_RUNS_PER_ROW = 3
"""Pictures per row of the report's gallery."""


def _append_gallery(out: Path, study: sp.StudySpec, measure: Mapping | None) -> None:
    """A side view per finished run of a pile (``analysis/gallery/run_NN.png``, named by run number) with the
    fitted flanks drawn on it (``measure.flank_lines``: the protractor), gathered in report.md. Only the surface
    fit is computed again (the flanks are its lines), not the run's other measurements. A run kept without its
    final state (a record copied without ``runs/*.npz``) keeps the picture drawn while it had one, unless the
    piles are measured again (``measure``), which that picture would not show."""
    from warpdem.scene.export import side_view_png
    from warpdem.scene.measure import angle_surface_fit, flank_lines
    from warpdem.scene.runner import pile_select, state_walls

    shots = []
    folder = out / "analysis" / "gallery"
    for row, _, m, state in _stored_piles(out, study, measure, "gallery"):
        name = f"run_{int(row['run']):02d}.png"
        if state is None:
            if measure is None and (folder / name).exists():
                shots.append((int(row["run"]), name))
            continue
        x, r, _ = pile_select(*_free_spheres(state), m)
        lines, frame, title = [], None, f"run {row['run']}: {len(r)} particles in the pile"
        try:
            fit = angle_surface_fit(x, r, base_z=m.base_height, center=m.center)
        except ValueError:
            fit = None  # too small a pile to fit: drawn without the protractor, as its run recorded the error
        if fit is not None:
            flanks = flank_lines(fit, m.base_height, "y")
            lines = [(f["points"][0], f["points"][1], f"{f['angle_deg']:.1f}°") for f in flanks]
            title = f"run {row['run']}: {fit['mean_deg']:.1f}° (fit, mean of {len(fit['lines'])} sectors)"
            reach = 1.15 * fit["extent_m"]
            height = float((x[:, 2] + r).max() - m.base_height)
            top = m.base_height + max(height, 0.3 * fit["extent_m"])
            frame = (
                (fit["center"][0] - reach, m.base_height - 0.1 * reach),
                (fit["center"][0] + reach, top + 0.15 * reach),
            )
        folder.mkdir(parents=True, exist_ok=True)
        glued = state["sphere_glued"] >= 0
        xs = np.concatenate([x, state["sphere_x"][glued]])
        rs = np.concatenate([r, state["sphere_r"][glued]])
        side_view_png(
            folder / name, xs, rs, state_walls(state), "y", title, figsize=(4.5, 3.0), dpi=90, lines=lines, frame=frame
        )
        shots.append((int(row["run"]), name))
    if not shots:
        return
    lines = [
        "",
        "## Gallery",
        "",
        "Each run's pile at its end, seen from -y, with the flanks the surface fit measured (red; the sectors facing "
        "each way, weighted; labelled with their angle). Named by run number.",
        "",
    ]
    for i in range(0, len(shots), GALLERY_RUNS_PER_ROW):
        part = shots[i : i + GALLERY_RUNS_PER_ROW]
        lines.append("| " + " | ".join(f"run {k}" for k, _ in part) + " |")
        lines.append("|" + "---|" * len(part))
        lines.append("| " + " | ".join(f"![run {k}](gallery/{n})" for k, n in part) + " |")
        lines.append("")
    with open(out / "analysis" / "report.md", "a") as fh:
        fh.write("\n".join(lines) + "\n")


def _append_settling(out: Path, study: sp.StudySpec) -> None:
    """Add the settling picture of every finished run to the report (see ``report.settling_section``)."""
    from .report import settling_section

    runs = [(row["run"], rec["metrics"].get("settling")) for row, rec in _finished_records(out, study)]
    lines = settling_section(out / "analysis", runs)
    if lines:
        with open(out / "analysis" / "report.md", "a") as fh:
            fh.write("\n".join(lines))


def _cell(x) -> str:
    """A table cell of a number to 4 significant digits; a response a replicate could not measure is a dash."""
    return f"{x:.4g}" if x is not None and math.isfinite(x) else "–"


def _append_verification(out: Path, v: dict) -> None:
    """Add the verification section to the report (report.md is rewritten by every analysis)."""
    n = len(v["values"])
    lines = [
        "",
        "## Verification",
        "",
        f"{n} replicate runs (world seeds 1..{n}) at the chosen settings "
        + ", ".join(f"{k} = {val:.6g}" for k, val in v["settings"].items())
        + ":",
        "",
    ]
    # records written before the replicates' other metrics were kept have none
    other = v.get("metrics", {})
    lines += ["| replicate | " + " | ".join([v["response"], *other]) + " |", "|---|" + "---|" * (1 + len(other))]
    lines += [
        f"| {k + 1} | " + " | ".join(_cell(x) for x in [val, *(vals[k] for vals in other.values())]) + " |"
        for k, val in enumerate(v["values"])
    ]
    lines += [
        "",
        f"Mean {v['mean']:.4g}, SD {v['sd']:.3g}, predicted {v['predicted']}, target {v['target']}, "
        f"relative error of the mean {v['relative_error_pct']:.3g} %.",
        "",
    ]
    # records written before the verification was t-tested and checked have neither
    if math.isfinite(v.get("p", math.nan)):
        lines += [f"One-sample t test of the mean against the target: t = {v['t']:.3g}, p = {v['p']:.3g}.", ""]
    checks = v.get("checks", [])
    lines += [f"- Check: {line}." for line in check_lines(checks, key="replicate")] + ([""] if checks else [])
    if "unflagged" in v:
        lines += [replicate_line(v["unflagged"], key="replicate") + ".", ""]
    pi, within = v.get("prediction_interval"), v.get("within_prediction_interval")
    if within is not None:
        level = 100.0 * (1.0 - v["interval_alpha"])
        lines += [
            f"Confirmation (Design-Expert's): the mean of the {n} runs lies "
            + ("**inside**" if within else "**outside**")
            + f" the {level:.0f} % prediction interval for a mean of {n} runs at these settings, "
            f"[{pi[0]:.4g}, {pi[1]:.4g}]"
            + (": the model is confirmed there." if within else ": the model does not hold there."),
            "",
        ]
    with open(out / "analysis" / "report.md", "a") as fh:
        fh.write("\n".join(lines))


def run_verification(
    study: sp.StudySpec,
    out,
    summary: dict,
    device: str = "cpu",
    progress: bool = True,
    log=print,
    checkpoint_every: float = 60.0,
    stop_after: float = 0.0,
    executor=None,
) -> dict | None:
    """Verification replicates at the chosen optimum of the first response with a target: ``replicates``
    runs (world seeds 1..n, so they differ from each other) as one launch per device of ``executor`` (the
    study's; by default ``device`` in this process); writes ``out/verification/verification.json`` with each
    value, the mean, SD, relative error and one-sample t test against the target, each replicate's other scalar
    metrics of its measure (``metrics``: name -> one value per replicate, from
    :data:`warpdem.scene.runner.MEASURE_METRICS`), each replicate's run checks
    (``checks``: replicate, check, detail, as :func:`run_checks` gives a design run's) and, where some are
    flagged and at least two are left, the summary without them (``unflagged``, with ``left_out``), and appends
    them to the report. Resumes like the design runs (one file per replicate); each launch checkpoints into
    ``out/verification/launches/<id>/`` and, with ``stop_after`` (wall seconds), returns {"stopped": message}
    once it has saved its checkpoint."""
    out = Path(out)
    resp = verification_response(study)
    if resp is None:
        return None
    s = summary.get(resp.name) or {}
    chosen = s.get("chosen")
    if not chosen:
        why = "no factor moves the response" if s.get("mean_interval") else "it is not reachable in the design region"
        log(f"{study.name}: no verification at target {resp.target}: {why}")
        return None
    n = study.verification.replicates
    vdir = out / "verification"
    vdir.mkdir(exist_ok=True)
    base = dict(study.fixed)
    for f in study.factors:
        v = float(chosen[f.name])
        base[f.parameter] = sp.rig_value(study, f.parameter, v) if sp.is_rig_key(f.parameter) else v
    rows = [
        {
            "run": k + 1,
            "point_id": f"verification_{k + 1}_{sp.point_key(study, base, k + 1)}",
            "world_seed": k + 1,
            "overrides": base,
            "row": {"stage": "verification"},
            "file": replicate_file(vdir, k + 1),
        }
        for k in range(n)
    ]
    pending = [r for r in rows if not r["file"].exists()]
    if pending:
        from .executor import InProcess

        def save(batch, records, wall, dev, states):
            for row, rec in zip(batch, records):
                _write_json(
                    row["file"],
                    {
                        "world_seed": row["world_seed"],
                        "overrides": row["overrides"],
                        "responses": rec["responses"],
                        "metrics": rec["metrics"],
                        "info": rec["info"],
                        "device": dev,
                    },
                )

        ex = executor or InProcess(device)
        # replicates of a full-size scene fill a GPU each: spread them over the executor's devices
        batches = _batches(study, pending, ex.parallel)
        bar = _progress_bar(len(pending), 0, f"{study.name} verification", progress)
        try:
            # the verification folder holds its launches (OUT/verification/launches/<id>)
            stopped = ex.run(
                study, vdir, batches, bar, time.perf_counter(), checkpoint_every, stop_after, log, save=save
            )
        finally:
            if bar is not None:
                bar.close()
        if stopped:
            return {"stopped": stopped}
    from warpdem.scene.runner import MEASURE_METRICS

    values, checks, scene, metrics = [], [], _scene(study, base), []
    for r in rows:
        with open(r["file"]) as fh:
            rec = json.load(fh)
        values.append(rec["responses"][resp.name])
        metrics.append(rec["metrics"])
        # a replicate is checked like a design run: a pile that slid or a bed that hung is no replicate
        checks += [{"replicate": r["run"], "check": c, "detail": d} for c, d in _checks_of(rec, scene, study)]
    alpha = study.analysis.alpha
    rep = replicate_summary(values, resp.target, alpha)
    mean = rep["mean"]
    # Design-Expert's confirmation: the mean of the k runs against the prediction interval for a mean of k runs
    conf, k = s.get("confirmation"), rep["n"]
    pi = confirmation_runs_interval(conf, k) if conf and k else (math.nan, math.nan)
    result = {
        "response": resp.name,
        "target": resp.target,
        "settings": chosen,
        "predicted": s.get("predicted"),
        "values": values,
        "mean": mean,
        "sd": rep["sd"],
        "relative_error_pct": 100.0 * abs(mean - resp.target) / abs(resp.target) if resp.target else math.nan,
        "prediction_interval": list(pi),
        "within_prediction_interval": bool(pi[0] <= mean <= pi[1]) if math.isfinite(pi[0]) else None,
        "interval_alpha": conf["alpha"] if conf else None,
        "t": rep["t"],
        "p": rep["p"],
        "checks": checks,
        # what else each replicate measured (a pile's height and offset, the other angle readings): where
        # replicates scatter, these say how their piles differ
        "metrics": {
            k: [float(m[k]) for m in metrics]
            for k in MEASURE_METRICS.get(scene.measure.kind, ())
            if k != resp.measure.split(".")[0] and all(isinstance(m.get(k), (int, float)) for m in metrics)
        },
    }
    unflagged = unflagged_summary(
        values, [r["run"] for r in rows], [c["replicate"] for c in checks], resp.target, alpha
    )
    if unflagged is not None:
        result["unflagged"] = unflagged
    _write_json(vdir / "verification.json", result)
    _append_verification(out, result)
    return result
