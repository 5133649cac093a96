"""Faults a study or a diagnosis must survive: a first write cut short (a full disk), and a folder left by one;
a second process on the same output folder (its lock), and the lock of one killed. The study is test_execute's
tiny funnel (40 spheres, 0.3 s), whose kernels the other tests compile. Other processes holding a lock are forks
of this one (no second import of Warp)."""

from __future__ import annotations

import contextlib
import errno
import json
import os
import socket
import time

import pytest

from warpdem.errors import BusyError
from warpdem.study import execute
from warpdem.study.folder import LOCK_NAME, PARTIAL_SUFFIX, FolderLock
from warpdem.study.spec import StudyError

from .test_execute import STUDY, _run, _study

pytest.importorskip("warp")


def _disk_full(*args, **kwargs):
    """Fail as a write to a full disk does where a library finds it (at close): without a file's name."""
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def _full_disk_at(name: str):
    """An ``os.fsync`` that fails as on a full disk for a file whose name holds ``name`` (the data written
    cannot be kept), and syncs any other."""
    fsync = os.fsync

    def fail(fd):
        if name in os.readlink(f"/proc/self/fd/{fd}"):
            _disk_full()
        return fsync(fd)

    return fail


def _files(out) -> list[str]:
    return sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())


@pytest.mark.parametrize("first, left", [(LOCK_NAME, []), ("study.toml", ["log.txt"])])
def test_a_first_write_on_a_full_disk_leaves_the_folder_to_a_rerun(tmp_path, monkeypatch, first, left):
    """The disk fills as the study's first files are written (the lock, then the copy of the study file): the
    error is an OSError naming the file, neither it (empty or partial) nor a temporary file is left, and the
    same call then runs the study through."""
    study = _study(tmp_path)
    out = tmp_path / "out"
    with monkeypatch.context() as m:
        m.setattr(os, "fsync", _full_disk_at(first))
        with pytest.raises(OSError) as err:
            _run(study, out, analyze_after=False)
    assert err.value.errno == errno.ENOSPC and err.value.filename == str(out / first)
    assert _files(out) == left
    res = _run(study, out, analyze_after=False)
    assert res["ran"] == 6 and res["stopped"] is None
    assert (out / "study.toml").read_text() == study.path.read_text()
    assert not list(out.rglob("*.partial"))


def test_a_folder_whose_first_write_was_cut_starts_again(tmp_path):
    """A folder an older warpdem left on a full disk: an empty study.toml, a temporary file, no run. A rerun
    starts the study again (saying so in the log) instead of refusing a folder that "holds study None"."""
    study = _study(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    (out / "study.toml").write_text("")
    (out / ".design.csv.123.partial").write_text("run,")
    res = _run(study, out, analyze_after=False)
    assert res["ran"] == 6
    assert (out / "study.toml").read_text() == study.path.read_text()
    assert not (out / ".design.csv.123.partial").exists()
    assert f"{out / 'study.toml'}: is empty and no run has finished" in (out / "log.txt").read_text()


@pytest.mark.parametrize("text, reason", [("", "is empty"), ("[study]\nname = 'ti", "is not TOML")])
def test_a_broken_study_copy_beside_finished_runs_is_refused(tmp_path, text, reason):
    """Finished runs beside a study.toml that is empty or cut short: which study they ran is unknown, so the
    study is refused with the file named and how to put it back, and nothing in the folder is touched."""
    study = _study(tmp_path)
    out = tmp_path / "out"
    (out / "runs").mkdir(parents=True)
    (out / "runs" / "abc.json").write_text("{}")
    (out / "study.toml").write_text(text)
    with pytest.raises(StudyError, match=rf"{out / 'study.toml'}: {reason}.* holds 1 finished run\(s\); put back"):
        execute._check_folder(out, study, print)
    assert (out / "study.toml").read_text() == text


def test_a_diagnosis_whose_first_copy_fails_leaves_no_partial_copy(tmp_path, monkeypatch):
    """A diagnosis's first writes (the copies of its data file and table) on a full disk: an OSError naming the
    copy, and neither a partial copy nor a temporary file, so the next start writes them whole."""
    from tests.diagnose.test_data import _write
    from warpdem.diagnose.pipeline import diagnose

    out = tmp_path / "out"
    with monkeypatch.context() as m:
        m.setattr(os, "fsync", _full_disk_at("data.toml"))
        with pytest.raises(OSError) as err:
            diagnose(_write(tmp_path), out, progress=False, log=lambda *a: None)
    assert err.value.errno == errno.ENOSPC and err.value.filename == str(out / "data.toml")
    assert _files(out) == []


@contextlib.contextmanager
def _forked(fn):
    """Run ``fn()`` in a forked child (its exit code: 0, or 1 if it raised), which starts when the block is
    entered and waits there until its stdin-like pipe closes: ``fn`` gets ``wait()``, which returns once the
    block is left. Yields the child's pid; on leaving, the child is let go and waited for."""
    go_r, go_w = os.pipe()
    ready_r, ready_w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: never returns into pytest
        code = 1
        try:
            os.close(go_w)
            os.close(ready_r)

            def wait():
                os.write(ready_w, b"1")
                os.read(go_r, 1)

            fn(wait)
            code = 0
        finally:
            os._exit(code)
    os.close(go_r)
    os.close(ready_w)
    try:
        assert os.read(ready_r, 1) == b"1", "the child ended before it was ready"
        yield pid
    finally:
        os.close(go_w)
        os.close(ready_r)
        os.waitpid(pid, 0)


def test_a_second_study_on_a_held_folder_is_refused(tmp_path):
    """Another process holds the folder (its lock names it): the study is refused at once with a BusyError
    naming the folder, the holder's pid and host and what to do; nothing of the study is written, and the
    holder's lock is left as it was. Once that process has ended, its lock is gone."""
    study = _study(tmp_path)
    out = tmp_path / "out"

    def hold_it(wait):
        with FolderLock(out, "study tiny"):
            wait()

    out.mkdir()
    with _forked(hold_it) as holder:
        before = (out / LOCK_NAME).read_text()
        t0 = time.perf_counter()
        with pytest.raises(BusyError) as err:
            _run(study, out, analyze_after=False)
        assert time.perf_counter() - t0 < 2
        msg = str(err.value)
        assert msg.startswith(f"{out}: in use by study tiny, pid {holder} on {socket.gethostname()!r} since ")
        assert f"wait for it to end (or stop it: kill {holder}), or choose another output folder" in msg
        assert err.value.exit_code == 7
        assert (out / LOCK_NAME).read_text() == before and sorted(p.name for p in out.iterdir()) == [LOCK_NAME]
    assert not (out / LOCK_NAME).exists()


def test_a_diagnosis_on_a_held_folder_is_refused(tmp_path):
    """The diagnosis takes the same lock: refused while another process holds its folder."""
    from tests.diagnose.test_data import _write
    from warpdem.diagnose.pipeline import diagnose

    out = tmp_path / "out"
    out.mkdir()
    with _forked(lambda wait: FolderLock(out, "study tiny").acquire() and wait()) as holder:
        with pytest.raises(BusyError, match=rf"{out}: in use by study tiny, pid {holder} "):
            diagnose(_write(tmp_path), out, progress=False, log=lambda *a: None)


def test_the_lock_of_a_killed_study_is_taken_over(tmp_path):
    """A study killed (its process gone without a word) left its lock: the next study on the folder takes it
    over, says so in log.txt with the dead pid, runs, and removes its own lock when it ends."""
    study = _study(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    dead = os.fork()
    if dead == 0:  # takes the lock and dies holding it
        try:
            FolderLock(out, "study tiny").acquire()
        finally:
            os._exit(0)
    os.waitpid(dead, 0)
    held = json.loads((out / LOCK_NAME).read_text())
    assert held["pid"] == dead and held["host"] == socket.gethostname()
    res = _run(study, out, analyze_after=False)
    assert res["ran"] == 6
    log = (out / "log.txt").read_text()
    assert f"{out / LOCK_NAME}: took over a stale lock (its holder, pid {dead}, is no longer running)" in log
    assert not (out / LOCK_NAME).exists()


def test_an_unreadable_lock_is_taken_over_one_from_another_host_is_not(tmp_path):
    """An empty lock file (a holder killed as it wrote it) is taken over; a lock of another host, whose process
    this one cannot check, is refused with the file to remove if that process is gone, and left as it was."""
    (tmp_path / LOCK_NAME).write_text("")
    with FolderLock(tmp_path, "study tiny") as lock:
        assert "it is empty or cannot be read" in lock.took_over
        assert json.loads((tmp_path / LOCK_NAME).read_text())["pid"] == os.getpid()
    assert not (tmp_path / LOCK_NAME).exists()
    other = {"pid": 1, "host": "elsewhere.example", "started": "2026-01-01T00:00:00", "command": "warpdem study x"}
    (tmp_path / LOCK_NAME).write_text(json.dumps(other))
    with pytest.raises(BusyError) as err:
        FolderLock(tmp_path).acquire()
    msg = str(err.value)
    assert "pid 1 on 'elsewhere.example' since 2026-01-01T00:00:00 (warpdem study x), on another host" in msg
    assert f"if that process is gone, remove {tmp_path / LOCK_NAME} and run again" in msg
    assert json.loads((tmp_path / LOCK_NAME).read_text()) == other


def test_processes_racing_for_a_stale_lock_take_it_once(tmp_path):
    """Six processes find the same stale lock at once: exactly one takes it over, the others are refused (the
    winner is alive), and the lock left is the winner's."""
    (tmp_path / LOCK_NAME).write_text(json.dumps({"pid": 2**22 + 1, "host": socket.gethostname()}))
    results_r, results_w = os.pipe()
    start_r, start_w = os.pipe()
    pids = []
    for _ in range(6):
        pid = os.fork()
        if pid == 0:
            code = 1
            try:
                os.close(start_w)
                os.read(start_r, 1)  # all start when the pipe closes
                try:
                    lock = FolderLock(tmp_path).acquire()
                except BusyError:
                    os.write(results_w, b"b")
                else:
                    os.write(results_w, b"w")
                    time.sleep(1.0)  # held while the others try
                    lock.release()
                code = 0
            finally:
                os._exit(code)
        pids.append(pid)
    os.close(start_w)
    os.close(results_w)
    try:
        got = b""
        while chunk := os.read(results_r, 16):
            got += chunk
    finally:
        for pid in pids:
            os.waitpid(pid, 0)
    assert sorted(got) == sorted(b"wbbbbb"), got
    assert not (tmp_path / LOCK_NAME).exists()


def test_a_full_disk_deep_in_a_launch_names_the_folder_and_a_rerun_resumes(tmp_path, monkeypatch):
    """The disk fills as a launch draws its pile (a library's write fails at close, with no file named): the
    study ends in an OSError naming its output folder (the command line's "OUT: No space left on device", exit
    code 5), its lock is released, and the same call, with room again, runs the study through."""
    from warpdem.errors import ExitCode, classify
    from warpdem.scene import export

    study = _study(tmp_path)
    out = tmp_path / "out"
    with monkeypatch.context() as m:
        m.setattr(export, "side_view_png", _disk_full)
        with pytest.raises(OSError) as err:
            _run(study, out, analyze_after=False)
    assert err.value.errno == errno.ENOSPC and err.value.filename == str(out)
    assert classify(err.value) == (ExitCode.FILE_SYSTEM, f"{out}: {os.strerror(errno.ENOSPC)}")
    assert not (out / LOCK_NAME).exists() and not list((out / "runs").glob("*.json"))
    res = _run(study, out, analyze_after=False)
    assert res["ran"] == 6 and res["stopped"] is None


@pytest.fixture
def small_disk(tmp_path):
    """A 64 KiB tmpfs mounted at ``tmp_path/disk`` (skips where mounting is not allowed); unmounted after."""
    import subprocess

    disk = tmp_path / "disk"
    disk.mkdir()
    mount = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(disk)], capture_output=True)
    if mount.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {mount.stderr.decode().strip()}")

    def remount(options: str) -> None:
        subprocess.run(["mount", "-o", f"remount,{options}", str(disk)], check=True, capture_output=True)

    try:
        yield disk, remount
    finally:
        subprocess.run(["umount", "-l", str(disk)], capture_output=True)


def test_a_real_full_disk_then_a_read_only_one(small_disk, tmp_path):
    """On a real 64 KiB file system the study fills the disk in its first launch: an OSError (ENOSPC) naming
    a path inside the output folder, the lock released. Made read-only, the folder is refused at its lock, named.
    With room again, the same call runs the study through in the folder the full disk left."""
    disk, remount = small_disk
    study = _study(tmp_path)
    out = disk / "out"
    with pytest.raises(OSError) as err:
        _run(study, out, analyze_after=False)
    assert err.value.errno == errno.ENOSPC and str(err.value.filename).startswith(str(out))
    assert (out / "study.toml").read_text() == study.path.read_text() and not (out / LOCK_NAME).exists()
    remount("ro")
    with pytest.raises(OSError) as err:
        _run(study, out, analyze_after=False)
    assert err.value.errno == errno.EROFS and err.value.filename == str(out / LOCK_NAME)
    remount("rw,size=16m")
    res = _run(study, out, analyze_after=False)
    assert res["ran"] == 6 and res["stopped"] is None
    assert not list(out.rglob(f"*{PARTIAL_SUFFIX}")) and not (out / LOCK_NAME).exists()


def _group(pgid: int) -> list[int]:
    """The live processes (not zombies) of process group ``pgid``, from ``/proc``."""
    pids = []
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/stat", "rb") as fh:
                stat = fh.read().decode(errors="replace")
        except OSError:  # ended meanwhile
            continue
        state, _, pgrp = stat[stat.rfind(")") + 2 :].split()[:3]
        if int(pgrp) == pgid and state != "Z":
            pids.append(int(d))
    return pids


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="reads the process table from /proc (Linux)")
def test_the_workers_of_a_killed_study_end_with_it(tmp_path):
    """``warpdem study --device cpu,cpu`` (a LocalCluster: two worker processes, each running a launch) is
    killed (SIGKILL, no chance to clean up) while its launches run: within 30 s no process of its process group
    is left, so no orphaned worker goes on computing, or holds the folder. (Dask's nanny gives each worker a
    pipe from its parent and the worker exits when the pipe closes; this checks it, whatever Dask's version.)"""
    import signal
    import subprocess
    import sys
    from pathlib import Path

    path = tmp_path / "long.toml"
    path.write_text(STUDY.format(batch=0, target=0.0, verify=0).replace("duration = 0.3", "duration = 30.0"))
    out = tmp_path / "out"
    root = str(Path(__file__).parents[2])
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")])))
    cmd = [sys.executable, "-m", "warpdem.cli", "study", str(path), "--device", "cpu,cpu", "--out", str(out)]
    with open(tmp_path / "console.txt", "w") as console:
        parent = subprocess.Popen(
            [*cmd, "--no-progress", "--no-verify"],
            stdout=console,
            stderr=subprocess.STDOUT,
            env=env,
            start_new_session=True,
        )
    left = []
    try:
        # running: both launches' folders made by the workers, and three processes at least besides the parent
        deadline = time.time() + 120
        while time.time() < deadline and parent.poll() is None:
            launches = list((out / "launches").glob("*")) if (out / "launches").is_dir() else []
            if len(launches) == 2 and len(_group(parent.pid)) >= 3:
                break
            time.sleep(0.1)
        assert parent.poll() is None, (tmp_path / "console.txt").read_text()[-3000:]
        assert len(launches) == 2, "no launch was seen running within 120 s"
        time.sleep(1.0)  # inside the launches
        workers = [p for p in _group(parent.pid) if p != parent.pid]
        assert not list((out / "runs").glob("*.json")), "a launch ended before the kill"
        os.kill(parent.pid, signal.SIGKILL)
        parent.wait()
        t0 = time.time()
        while (left := _group(parent.pid)) and time.time() - t0 < 30:
            time.sleep(0.1)
        assert not left, f"processes of the killed study still run 30 s after it: {left} (of {workers})"
    finally:
        if parent.poll() is None:
            parent.kill()
            parent.wait()
        for pid in _group(parent.pid):
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
