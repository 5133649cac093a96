"""The errors warpdem raises on purpose, and the exit code the command line gives each kind.

Every layer raises one of these (or a subclass) for a fault the user can act on; anything else reaching the
command line is a bug. :func:`classify` maps an exception to its :class:`ExitCode` and a one-line message, so
the command line and its tests agree on both. This module imports nothing of warpdem: every layer may use it.
"""

from __future__ import annotations

import enum


class ExitCode(enum.IntEnum):
    """What the command line's exit status means (README, Errors and exit codes)."""

    OK = 0
    VERIFY_FAILED = 1
    """``warpdem verify``: a case is out of its tolerance."""
    BAD_INPUT = 2
    """A file, stage, study, data file, ``--set`` override or option holds a value that is not allowed."""
    STOPPED = 3
    """Stopped at ``--stop-after``; the same command resumes."""
    SIMULATION = 4
    """A run failed: a blow-up (non-finite or runaway velocity) or a capacity overflow."""
    FILE_SYSTEM = 5
    """An output could not be written (disk full, read-only, no permission) or a file could not be read."""
    DEVICE = 6
    """The device asked for is not there, or was lost during the run."""
    BUSY = 7
    """Another study or diagnosis holds the output folder's lock."""
    MISSING_PACKAGE = 8
    """A package warpdem needs is not installed (an install without its dependencies)."""
    INTERNAL = 70
    """A bug: an exception no check anticipated (``--debug`` shows its traceback)."""
    INTERRUPTED = 130
    """Ctrl-C; what was finished is kept, and the same command resumes."""


class WarpdemError(Exception):
    """Base of the errors warpdem raises on purpose; ``exit_code`` is what the command line returns for it."""

    exit_code = ExitCode.INTERNAL


class InputError(WarpdemError, ValueError):
    """A value that is not allowed; the message names where it came from (file, prim or table, field), the
    value and what is allowed. A ``ValueError``, so code that catches those keeps working."""

    exit_code = ExitCode.BAD_INPUT


class SimulationError(WarpdemError, RuntimeError):
    """A run stopped: a sphere's velocity became non-finite or exceeded the limit, or a capacity overflowed."""

    exit_code = ExitCode.SIMULATION


class DeviceError(WarpdemError, RuntimeError):
    """The device asked for is not available."""

    exit_code = ExitCode.DEVICE


class BusyError(WarpdemError, RuntimeError):
    """An output folder is held by another live process (its lock names the pid and host)."""

    exit_code = ExitCode.BUSY


class FileSystemError(WarpdemError, OSError):
    """A file could not be read or written; the message names the path and the reason."""

    exit_code = ExitCode.FILE_SYSTEM


class PhysicsWarning(UserWarning):
    """A run whose physics is suspect although nothing stopped it (:mod:`warpdem.engine.suspect`): lost bodies,
    too long a step, overlaps."""


def classify(exc: BaseException) -> tuple[ExitCode, str]:
    """The exit code and one-line message (without "error: ") for ``exc`` as the command line reports it."""
    if isinstance(exc, KeyboardInterrupt):
        return ExitCode.INTERRUPTED, "interrupted; finished results are kept and the same command resumes"
    if isinstance(exc, WarpdemError):
        return exc.exit_code, str(exc)
    if isinstance(exc, OSError):
        where = f"{exc.filename}: " if exc.filename else ""
        reason = exc.strerror or str(exc)
        return ExitCode.FILE_SYSTEM, f"{where}{reason}"
    if isinstance(exc, ModuleNotFoundError) and exc.name and not exc.name.startswith("warpdem"):
        # an install without its dependencies (pip --no-deps, a copied tree) fails at the first import of one
        return ExitCode.MISSING_PACKAGE, (
            f"the package {exc.name.split('.')[0]!r} is not installed, and warpdem needs it: "
            "pip install -e . (or pip install warpdem) installs every dependency"
        )
    if isinstance(exc, MemoryError):
        return ExitCode.SIMULATION, "out of memory; run fewer worlds per launch or fewer particles"
    text = f"{type(exc).__name__}: {exc}"
    if "cuda" in text.lower() and ("device" in text.lower() or "driver" in text.lower()):
        return ExitCode.DEVICE, text
    return ExitCode.INTERNAL, f"internal error, {text} (a bug: rerun with --debug for the traceback and report it)"
