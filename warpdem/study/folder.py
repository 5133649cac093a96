"""An output folder (a study's, a diagnosis's): whole-file writes, and file-system errors that name the path.

:func:`write_atomic` and :func:`copy_atomic` write a whole file or nothing (a temporary name in the same folder,
fsync, ``os.replace``): a write cut short by a full disk or a kill leaves the old file or none, never an empty
one. :func:`clean_partials` removes the temporaries such a cut leaves.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

PARTIAL_SUFFIX = ".partial"
"""Ending of :func:`write_atomic`'s temporary files (``.NAME.PID.partial``, next to NAME)."""


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
    Call it before anything writes the folder."""
    folder = Path(folder)
    found = [p for d in (folder, folder / "runs") for p in d.glob(f".*{PARTIAL_SUFFIX}")]
    found += [*(folder / "runs").glob("*.json.tmp"), *(folder / "runs").glob("*.tmp.npz")]
    for p in found:
        with contextlib.suppress(FileNotFoundError):
            p.unlink()
    return found
