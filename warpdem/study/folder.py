"""An output folder (a study's, a diagnosis's): its lock, whole-file writes, and file-system errors that name the
path.

:func:`hold` keeps ``OUT/.warpdem.lock`` while a study or a diagnosis writes the folder: a JSON record of the
holder (pid, host, start time, command line), created with ``O_CREAT | O_EXCL``, so a second process on the same
folder is refused (:class:`~warpdem.errors.BusyError`) instead of mixing its files in. A lock whose holder is gone
(this host, its pid no longer running, or running another program) or that cannot be read (empty, cut short)
is taken over; one from another host cannot be checked and is refused with the way to remove it. Every change
of the lock is made under an advisory ``flock`` of the folder itself, so two processes that find the same stale
lock cannot both take it over.

:func:`write_atomic` and :func:`copy_atomic` write a whole file or nothing (a temporary name in the same folder,
fsync, ``os.replace``): a write cut short by a full disk or a kill leaves the old file or none, never an empty
one. :func:`clean_partials` removes the temporaries such a cut leaves, and :func:`naming` gives a file-system
error raised without a path (a write that fails at ``close``, deep in a library) the folder's.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import shlex
import socket
import sys
import time
from pathlib import Path

from warpdem.errors import BusyError

LOCK_NAME = ".warpdem.lock"
"""The lock's file name in an output folder."""

PARTIAL_SUFFIX = ".partial"
"""Ending of :func:`write_atomic`'s temporary files (``.NAME.PID.partial``, next to NAME)."""

FILE_SYSTEM_ERRNOS = frozenset(
    {errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM, errno.EFBIG, errno.EIO}
)
"""The errors of a folder that cannot be written: :func:`naming` gives them the folder's path."""


def _process_start(pid: int) -> str | None:
    """When ``pid`` started (clock ticks since boot, ``/proc/PID/stat``), to tell it from a later process that
    reuses its pid; None where there is no ``/proc`` or no such process."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            stat = fh.read().decode(errors="replace")
    except OSError:
        return None
    # field 22 (starttime) counts from the field after the command name, which may hold spaces and parentheses
    fields = stat[stat.rfind(")") + 2 :].split()
    return fields[19] if len(fields) > 19 else None


def _alive(pid: int, started: str | None) -> bool:
    """Whether process ``pid`` of this host runs, and is the one that started at ``started`` (when known)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process: it runs
        pass
    now = _process_start(pid)
    return started is None or now is None or now == started


def _fsync_dir(folder: Path) -> None:
    """Make a rename in ``folder`` durable (best effort: some file systems refuse to fsync a folder)."""
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def with_path(e: OSError, path) -> OSError:
    """``e`` as an OSError of the same kind (errno) naming ``path`` (``e`` itself when it names one already)."""
    if e.filename is not None:
        return e
    return OSError(e.errno, e.strerror or str(e), str(path))


def write_atomic(path, data: bytes | str) -> None:
    """Write ``data`` to ``path`` whole or not at all: into ``.NAME.PID.partial`` next to it, fsync, then
    ``os.replace``. On failure the temporary file is removed, ``path`` keeps what it held, and the OSError
    raised names the file that could not be written."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}{PARTIAL_SUFFIX}")
    raw = data.encode() if isinstance(data, str) else data
    try:
        with open(tmp, "wb") as fh:
            fh.write(raw)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as e:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise with_path(e, path) from e
    _fsync_dir(path.parent)


def copy_atomic(src, dst) -> None:
    """Copy the file ``src`` to ``dst`` whole or not at all (:func:`write_atomic`)."""
    try:
        data = Path(src).read_bytes()
    except OSError as e:
        raise with_path(e, src) from e
    write_atomic(dst, data)


def clean_partials(folder) -> list[Path]:
    """Remove the temporary files a cut-short :func:`write_atomic` left in ``folder`` and ``folder/runs``
    (``.NAME.PID.partial``; a run's state ``NAME.tmp.npz``; ``NAME.json.tmp`` of older versions); returns them.
    Call it holding the folder's lock: no live writer's temporaries are then there."""
    folder = Path(folder)
    found = [p for d in (folder, folder / "runs") for p in d.glob(f".*{PARTIAL_SUFFIX}")]
    found += [*(folder / "runs").glob("*.json.tmp"), *(folder / "runs").glob("*.tmp.npz")]
    for p in found:
        with contextlib.suppress(FileNotFoundError):
            p.unlink()
    return found


@contextlib.contextmanager
def naming(folder):
    """Give a file-system OSError raised inside without a path (a full disk found by ``close`` or ``flush``,
    deep in a library) the path of ``folder``, so the message says where (:func:`warpdem.errors.classify`)."""
    try:
        yield
    except OSError as e:
        if e.filename is not None or e.errno not in FILE_SYSTEM_ERRNOS:
            raise
        raise with_path(e, folder) from e


@contextlib.contextmanager
def _guard(folder: Path):
    """An exclusive ``flock`` of ``folder`` itself for the span of one change of its lock file; where the file
    system has none (some network ones), the ``O_EXCL`` creation and the check after it stand alone."""
    try:
        import fcntl
    except ImportError:  # not POSIX
        yield
        return
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError as e:
        raise with_path(e, folder) from e
    try:
        with contextlib.suppress(OSError):
            fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the flock


def _read_lock(path: Path) -> dict | None:
    """The holder recorded in lock file ``path``; None when it is empty or not a holder's record (a write cut
    short); raises FileNotFoundError when there is none."""
    try:
        data = json.loads(path.read_bytes() or b"null")
    except (ValueError, UnicodeDecodeError):
        return None
    return data if isinstance(data, dict) and isinstance(data.get("pid"), int) else None


def _holder(what: str) -> dict:
    pid = os.getpid()
    return {
        "pid": pid,
        "host": socket.gethostname(),
        "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "process_start": _process_start(pid),
        "command": shlex.join(sys.argv) if sys.argv and sys.argv[0] else what,
        "what": what,
    }


def _describe(h: dict) -> str:
    return f"pid {h.get('pid')} on {h.get('host')!r} since {h.get('started')} ({h.get('command')})"


class FolderLock:
    """The lock of output folder ``folder`` (:data:`LOCK_NAME`), for ``what`` (a study, a diagnosis: it names the
    holder in the lock); :meth:`acquire` takes it or raises :class:`BusyError`, :meth:`release` removes it if it
    is still this one's. A context manager; prefer :func:`hold`."""

    def __init__(self, folder, what: str = "warpdem"):
        self.folder = Path(folder)
        self.path = self.folder / LOCK_NAME
        self.what = what
        self.me: dict | None = None
        self.took_over: str | None = None
        """Why a stale lock was taken over (its holder is gone, or it could not be read), or None."""

    def _busy(self, h: dict) -> BusyError:
        here = h.get("host") == socket.gethostname()
        if here:
            return BusyError(
                f"{self.folder}: in use by {h.get('what', 'another warpdem')}, {_describe(h)}; wait for it to end "
                f"(or stop it: kill {h.get('pid')}), or choose another output folder"
            )
        return BusyError(
            f"{self.folder}: locked by {h.get('what', 'another warpdem')}, {_describe(h)}, on another host, which "
            f"this one cannot check; if that process is gone, remove {self.path} and run again, or choose another "
            "output folder"
        )

    def _stale(self, h: dict | None) -> str | None:
        """Why lock record ``h`` is stale (may be taken over), or None when its holder may still run."""
        if h is None:
            return "it is empty or cannot be read"
        if h.get("host") != socket.gethostname():
            return None
        if not _alive(int(h["pid"]), h.get("process_start")):
            return f"its holder, pid {h['pid']}, is no longer running"
        return None

    def _create(self, me: dict) -> bool:
        """Create the lock file holding ``me``; False when one exists. A failed write removes it again."""
        try:
            fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            return False
        except OSError as e:
            raise with_path(e, self.path) from e
        try:
            with os.fdopen(fd, "w") as fh:
                json.dump(me, fh, indent=1)
                fh.write("\n")
                fh.flush()
                os.fsync(fh.fileno())
        except OSError as e:
            with contextlib.suppress(OSError):
                self.path.unlink()
            raise with_path(e, self.path) from e
        return True

    def acquire(self) -> FolderLock:
        me = _holder(self.what)
        with _guard(self.folder):
            for _ in range(3):
                if self._create(me):
                    break
                try:
                    h = _read_lock(self.path)
                except FileNotFoundError:  # released in between
                    continue
                why = self._stale(h)
                if why is None:
                    raise self._busy(h)
                with contextlib.suppress(FileNotFoundError):
                    self.path.unlink()
                self.took_over = f"{self.path}: took over a stale lock ({why})" + (
                    f"; it was {_describe(h)}" if h else ""
                )
            else:
                raise BusyError(f"{self.folder}: its lock {self.path} keeps changing; another process is taking it")
            # where the flock did nothing (some network file systems), another process may have replaced the file
            try:
                now = _read_lock(self.path)
            except FileNotFoundError:
                now = None
            if now != me:
                raise self._busy(now) if now else BusyError(f"{self.folder}: another process took its lock {self.path}")
        self.me = me
        return self

    def release(self) -> None:
        """Remove the lock, if it is still this one's (a process that took it over as stale keeps its own)."""
        if self.me is None:
            return
        with contextlib.suppress(OSError), _guard(self.folder):
            if _read_lock(self.path) == self.me:
                self.path.unlink()
        self.me = None

    def __enter__(self) -> FolderLock:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()


@contextlib.contextmanager
def hold(folder, what: str = "warpdem"):
    """Create ``folder`` if need be and hold its lock (:class:`FolderLock`, yielded: its ``took_over`` says
    whether a stale one was taken over) inside; temporaries of a write cut short are removed once the lock is
    held (:func:`clean_partials`), and a file-system error raised inside without a path names the folder
    (:func:`naming`)."""
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise with_path(e, folder) from e
    with FolderLock(folder, what) as lock, naming(folder):
        clean_partials(folder)
        yield lock
