"""Studies on a Dask cluster (warpdem.study.executor): a LocalCluster of two worker processes stands in for a
cluster, reached by its scheduler's address as a remote one would be. The study is test_execute's tiny funnel
(40 spheres, 0.3 s, a fixed step), cut into launches of three worlds."""

from __future__ import annotations

import json
import os
import signal
import threading
import time

import pytest

from warpdem.study import execute
from warpdem.study.spec import StudyError

from .test_execute import _run, _study

pytest.importorskip("warp")
distributed = pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The tiny study in this process, in one launch: the responses a cluster must reproduce."""
    tmp = tmp_path_factory.mktemp("ref")
    study = _study(tmp)
    _run(study, tmp / "out", analyze_after=False)
    return execute.load_results(tmp / "out", study)


@pytest.fixture
def cluster():
    """A LocalCluster of two single-thread worker processes (nannies restart a worker that dies); yields
    (cluster, client)."""
    from distributed import Client, LocalCluster

    c = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0", silence_logs=50)
    client = Client(c, set_as_default=False)
    yield c, client
    client.close()
    c.close()


def _heights(out, study):
    return list(execute.load_results(out, study)["height"])


def test_a_cluster_gives_the_in_process_numbers(reference, cluster, tmp_path):
    """Sent to a scheduler by its address, the six runs (two launches, one task each) come back to the last bit
    as one launch in this process gave them: a world never reads another world's spheres, and the step is
    fixed. Each run is saved with its world's final state, though no file system is shared with the workers."""
    c, _ = cluster
    study = _study(tmp_path, batch=3)
    res = _run(study, tmp_path / "out", analyze_after=False, scheduler=c.scheduler_address)
    assert res["ran"] == 6 and res["batches"] == 2 and res["stopped"] is None
    assert _heights(tmp_path / "out", study) == list(reference["height"])
    assert len(list((tmp_path / "out" / "runs").glob("*.npz"))) == 6


def test_a_worker_killed_mid_launch_loses_nothing(reference, cluster, tmp_path):
    """A worker killed (SIGKILL) while it runs a launch: the scheduler sends the launch to a worker again and
    the study finishes with every point saved once, each launch logged done once, and the responses of the
    run that lost no worker."""
    c, client = cluster
    study = _study(tmp_path, batch=3)
    lines, result = [], {}

    def study_thread():
        result["res"] = execute.run_study(
            study,
            tmp_path / "out",
            progress=False,
            log=lines.append,
            analyze_after=False,
            scheduler=c.scheduler_address,
        )

    t = threading.Thread(target=study_thread)
    t.start()
    victim = None
    deadline = time.time() + 120
    while victim is None and time.time() < deadline and t.is_alive():
        busy = [addr for addr, keys in client.processing().items() if keys]
        if busy:
            victim = busy[0]
            break
        time.sleep(0.05)
    assert victim is not None, "no launch was seen running"
    time.sleep(0.5)  # inside the launch: a worker takes seconds to import Warp and step 0.3 s
    pid = client.run(os.getpid, workers=[victim])[victim]
    assert client.processing().get(victim), "the launch ended before the kill"
    os.kill(pid, signal.SIGKILL)
    t.join(timeout=300)
    assert not t.is_alive()
    res = result["res"]
    assert res["ran"] == 6 and res["stopped"] is None
    done = [ln for ln in lines if " done after " in ln]
    assert len(done) == 2, done
    assert len(list((tmp_path / "out" / "runs").glob("*.json"))) == 6
    assert _heights(tmp_path / "out", study) == list(reference["height"])


def test_a_rerun_sends_only_what_is_missing(reference, cluster, tmp_path):
    """A client stopped before it saved one launch (its three runs' files removed, as a client killed then
    would leave the folder) is rerun against the same folder: it sends that launch only, the other three runs'
    files are not touched, and the responses are the in-process ones."""
    c, _ = cluster
    study = _study(tmp_path, batch=3)
    out = tmp_path / "out"
    _run(study, out, analyze_after=False, scheduler=c.scheduler_address)
    recs = {f: json.loads(f.read_text()) for f in (out / "runs").glob("*.json")}
    lost = [f for f, r in recs.items() if r["run"] in (4, 5, 6)]
    kept = {f: f.stat().st_mtime_ns for f in recs if f not in lost}
    for f in lost:
        f.unlink()
        f.with_suffix(".npz").unlink()
    res = _run(study, out, analyze_after=False, scheduler=c.scheduler_address)
    # three runs left, cut over the two workers
    assert res["ran"] == 3 and res["skipped"] == 3 and res["batches"] == 2 and res["stopped"] is None
    assert {f: f.stat().st_mtime_ns for f in kept} == kept
    assert _heights(out, study) == list(reference["height"])


def test_a_scheduler_that_does_not_answer_is_a_clear_error(tmp_path, monkeypatch):
    """An address where no scheduler listens: a StudyError naming the address, within the connect timeout (2 s
    here) and a margin, not a hang."""
    from warpdem.study import executor

    monkeypatch.setattr(executor, "CONNECT_TIMEOUT_S", 2.0)
    study = _study(tmp_path)
    t0 = time.perf_counter()
    with pytest.raises(StudyError, match=r"scheduler = 'tcp://127\.0\.0\.1:9': no Dask scheduler answered within 2 s"):
        _run(study, tmp_path / "out", analyze_after=False, scheduler="tcp://127.0.0.1:9")
    assert time.perf_counter() - t0 < 30


def test_the_slurm_example_compiles_and_sends_the_study_to_its_cluster():
    """The README's dask-jobqueue example (not run: no SLURM here) is valid Python that asks one GPU per worker
    and sends the study to its cluster's scheduler."""
    from pathlib import Path

    path = Path(__file__).parents[2] / "docs" / "cluster" / "slurm_study.py"
    text = path.read_text()
    compile(text, str(path), "exec")
    assert '"--resources", "GPU=1"' in text and "scheduler=cluster.scheduler_address" in text
