"""Where launches run: in this process on one device (:class:`InProcess`), or as tasks of a Dask cluster
(:class:`DaskExecutor`), one launch a task.

Several devices of one host (``--device cpu,cpu``, ``cuda:0,cuda:1``, ``cuda:all``) are a Dask ``LocalCluster``
with one worker process per device (:meth:`DaskExecutor.local`); a cluster elsewhere is reached by its
scheduler's address (:meth:`DaskExecutor.connect`). Either way the client writes each finished launch into the
output folder the moment its task returns (``OUT/runs``: each run's JSON and its world's final state), so a
rerun sends only what is missing, and no file system needs to be shared: a task returns its records and its
worlds' final states. A worker lost mid-launch loses nothing finished: Dask runs the task again on another
worker (the launch restarts, or resumes from its checkpoint where the workers share ``checkpoint_root``), and
the client saves the launch once, when its task first returns.

Dask (``distributed``) is the choice, not a pool of our own: a ``LocalCluster`` for one host, ``dask-jobqueue``
for SLURM, PBS and LSF, resources (``GPU=1``) per worker, task retries when a worker dies, and a dashboard.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

try:
    from distributed.diagnostics.plugin import WorkerPlugin
except ImportError:  # one device in this process (InProcess) needs no Dask; DaskExecutor imports it and says so
    WorkerPlugin = object

from . import spec as sp

DEVICE_ENV = "WARPDEM_DEVICE"
"""Environment variable naming a worker's Warp device ("cpu", "cuda:0"); a worker without it takes "cuda:0" when
it has a CUDA device and "cpu" otherwise."""

SCHEDULER_ENV = "WARPDEM_SCHEDULER"
"""Environment variable naming a Dask scheduler's address, used where no ``scheduler`` is given."""

CONNECT_TIMEOUT_S = 10.0
"""Seconds a client waits for a scheduler to answer before the study stops with an error."""


def worker_device() -> str:
    """The Warp device of this worker process: :data:`DEVICE_ENV`, else "cuda:0" where CUDA is, else "cpu"."""
    named = os.environ.get(DEVICE_ENV)
    if named:
        return named
    import warp as wp

    return "cuda:0" if wp.get_cuda_device_count() > 0 else "cpu"


def run_launch(
    study, batch: list[dict], checkpoint_root: str | None, checkpoint_every: float, deadline: float, first: bool
):
    """One launch, in a worker: ``batch``'s runs as the worlds of one launch on :func:`worker_device`.

    ``checkpoint_root``: a folder every worker can write (the output folder on one host): the launch checkpoints
    into ``ROOT/launches/<id>/`` and a retry resumes there; None: a folder of the worker's own, so a retry
    restarts the launch. ``deadline`` (``time.time()``; 0: none): the launch stops with a checkpoint at its
    first output tick past it, and does not start past it unless ``first`` (one of the first launches, one per
    worker, which always start, so that every call advances). Returns {"records", "states" ({point_id: world
    state}), "wall_s", "device"}, or {"stopped": message} ({"stopped", "started": False} for one not started)."""
    import tempfile

    from warpdem.engine.types import init_warp
    from warpdem.scene.runner import RunStopped

    from .execute import _launch_id, run_batch, world_states

    if deadline and not first and time.time() >= deadline:
        return {"stopped": "the wall-time limit came before it started", "started": False}
    device = worker_device()
    init_warp(device)
    root = Path(checkpoint_root) if checkpoint_root else Path(tempfile.gettempdir()) / "warpdem-launches"
    out_dir = root / "launches" / _launch_id(batch)
    t0 = time.perf_counter()
    try:
        records = run_batch(
            study,
            batch,
            device,
            out_dir=out_dir,
            checkpoint_every=checkpoint_every,
            stop_after=max(deadline - time.time(), 1e-9) if deadline else 0.0,
        )
    except RunStopped as e:
        return {"stopped": f"{device}: {e}"}
    wall = time.perf_counter() - t0
    return {"records": records, "states": world_states(batch, records), "wall_s": wall, "device": device}


class Executor:
    """Runs launches (lists of run rows, :func:`execute._batches`) and saves each as it finishes. ``devices``:
    the devices named (what a launch's worlds may share follows from them); ``parallel``: how many launches run
    at once, so into how many a study's runs are cut at least."""

    devices: list[str]

    @property
    def parallel(self) -> int:
        return len(self.devices)

    def run(
        self,
        study,
        out: Path,
        batches: list[list[dict]],
        bar,
        t0: float,
        checkpoint_every: float,
        stop_after: float,
        log,
        on_saved=None,
        save=None,
    ) -> str | None:
        """Run ``batches``; each finished launch is saved into ``out`` (``OUT/runs``; or by ``save(batch, records,
        wall_s, device, states)``) at once, then ``on_saved()`` is called. ``stop_after``: wall seconds since ``t0`` (perf_counter) after which no launch
        starts and a running one stops at a checkpoint. Returns the stop message(s), or None; a failing launch's
        error is raised once the others have ended."""
        raise NotImplementedError

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class InProcess(Executor):
    """One device, in this process: on a GPU the launches run side by side (a CUDA stream each); on the CPU one
    after another (:func:`execute._run_on_device`)."""

    def __init__(self, device: str):
        self.devices = [device]

    def run(self, study, out, batches, bar, t0, checkpoint_every, stop_after, log, on_saved=None, save=None):
        from .execute import _run_on_device

        return _run_on_device(
            study, out, batches, self.devices[0], bar, t0, checkpoint_every, stop_after, on_saved, log=log, save=save
        )


class DaskExecutor(Executor):
    """Launches as tasks of a Dask cluster: one task per launch, asking for ``GPU=1`` on a cluster whose workers
    all declare GPUs (a worker's thread otherwise). ``connect()`` returns (client, cluster or None); a local
    cluster is started on first use, so a study with nothing left to run starts none."""

    def __init__(self, devices: list[str], connect, checkpoint_root: str | None = None):
        self.devices, self._connect, self.checkpoint_root = devices, connect, checkpoint_root
        self._client = self._cluster = None
        self.resources = None

    @property
    def client(self):
        if self._client is None:
            self._client, self._cluster = self._connect()
            info = self._client.scheduler_info()
            gpus = [w.get("resources", {}).get("GPU", 0) for w in info.get("workers", {}).values()]
            self.resources = {"GPU": 1} if gpus and all(g >= 1 for g in gpus) else None
        return self._client

    @classmethod
    def local(cls, devices: list[str]) -> DaskExecutor:
        """A ``LocalCluster`` on this host with one worker process (one thread) per entry of ``devices``, each
        worker on its device; the output folder is shared, so launches checkpoint there."""

        def connect():
            from distributed import Client, LocalCluster

            cluster = LocalCluster(
                n_workers=len(devices), threads_per_worker=1, processes=True, dashboard_address=":0", silence_logs=50
            )
            client = Client(cluster, set_as_default=False)
            client.register_plugin(_DevicePlugin(devices), name="warpdem-devices")
            return client, cluster

        return cls(devices, connect, checkpoint_root="")

    @classmethod
    def connect(cls, address: str, devices=("cpu",), checkpoint_root: str | None = None, timeout: float | None = None):
        """A client of the scheduler at ``address`` (``tcp://HOST:8786``), connected at once, for launches of
        ``devices``' kind (each worker runs on its own device, :func:`worker_device`); raises StudyError naming
        the address when it does not answer within ``timeout`` seconds (default :data:`CONNECT_TIMEOUT_S`)."""
        timeout = CONNECT_TIMEOUT_S if timeout is None else timeout

        def connect():
            from distributed import Client

            try:
                return Client(address, timeout=timeout, set_as_default=False), None
            except (OSError, TimeoutError) as e:
                raise sp.StudyError(
                    f"scheduler = {address!r}: no Dask scheduler answered within {timeout:.0f} s ({e}); start one "
                    "(dask scheduler) or give the address it prints"
                ) from e

        ex = cls(list(devices), connect, checkpoint_root=checkpoint_root)
        ex.client  # noqa: B018  (fail here, before anything runs)
        return ex

    @property
    def parallel(self) -> int:
        if self._cluster is None and self._client is not None:  # a remote cluster: its workers
            return max(len(self._client.scheduler_info().get("workers", {})), 1)
        return len(self.devices)

    @property
    def dashboard(self) -> str | None:
        return getattr(self.client, "dashboard_link", None)

    def run(self, study, out, batches, bar, t0, checkpoint_every, stop_after, log, on_saved=None, save=None):
        from distributed import as_completed

        from .execute import _launch_id, _save_batch

        out = Path(out)
        root = str(out) if self.checkpoint_root == "" else self.checkpoint_root
        deadline = time.time() + max(stop_after - (time.perf_counter() - t0), 1e-9) if stop_after > 0 else 0.0
        workers = max(len(self.client.scheduler_info().get("workers", {})), 1)
        futures = {}
        for k, batch in enumerate(batches):
            fut = self.client.submit(
                run_launch,
                study,
                batch,
                root,
                checkpoint_every,
                deadline,
                k < workers,
                key=f"launch-{_launch_id(batch)}-{k}",
                resources=self.resources,
                pure=False,
            )
            futures[fut.key] = (k, fut)
        left = 0
        stops, errors = [], []
        base = bar.n if bar is not None else 0
        saved = 0
        for fut in as_completed([f for _, f in futures.values()], loop=self.client.loop):
            k, _ = futures[fut.key]
            try:
                res = fut.result()
            except Exception as e:  # kept, raised once every launch has ended
                errors.append(e)
                log(f"launch {k + 1} of {len(batches)} failed: {e}")
                continue
            if "stopped" in res:
                if res.get("started", True):
                    stops.append(f"launch {k + 1} of {len(batches)}: {res['stopped']}")
                else:
                    left += 1
                continue
            if save is None:
                _save_batch(
                    study, out / "runs", batches[k], res["records"], res["wall_s"], res["device"], res["states"]
                )
            else:
                save(batches[k], res["records"], res["wall_s"], res["device"], res["states"])
            saved += len(batches[k])
            if bar is not None:
                bar.n = base + saved
                bar.refresh()
            if on_saved is not None:
                on_saved()
            log(
                f"launch {k + 1} of {len(batches)} done after {res['wall_s']:.1f} s on {res['device']}: "
                f"{len(batches[k])} world(s) saved"
            )
        if errors:
            raise errors[0]
        if left and not stops:
            stops.append(f"the wall-time limit ({stop_after:.0f} s) came before {left} of {len(batches)} launch(es)")
        return "; ".join(stops) or None

    def close(self) -> None:
        if self._client is not None:
            self._client.close()
        if self._cluster is not None:
            self._cluster.close()
        self._client = self._cluster = None


class _DevicePlugin(WorkerPlugin):
    """Gives worker ``k`` of a LocalCluster (named 0, 1, ...) its device ``devices[k]`` (:data:`DEVICE_ENV`),
    again on a worker the nanny restarted."""

    idempotent = True

    def __init__(self, devices: list[str]):
        self.devices = list(devices)

    def setup(self, worker) -> None:
        os.environ[DEVICE_ENV] = self.devices[int(worker.name) % len(self.devices)]


def executor_for(devices: list[str], scheduler: str | None = None, checkpoint_root: str | None = None) -> Executor:
    """The executor of ``devices`` (:func:`execute.parse_devices`): a cluster's when ``scheduler`` (else the
    environment variable ``WARPDEM_SCHEDULER``) names one, one device in this process, or a LocalCluster of one
    worker per device."""
    scheduler = scheduler or os.environ.get(SCHEDULER_ENV)
    if scheduler:
        return DaskExecutor.connect(scheduler, devices, checkpoint_root)
    if len(devices) == 1:
        return InProcess(devices[0])
    return DaskExecutor.local(devices)
