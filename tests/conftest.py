import pytest
import warp as wp

wp.config.quiet = True
wp.init()


def cuda_available() -> bool:
    return wp.get_cuda_device_count() > 0


requires_cuda = pytest.mark.skipif(not cuda_available(), reason="no CUDA device (CI has none)")


class RunKilled(Exception):
    """Raised by a :func:`kill_past` callback: a crash in the middle of a run."""


def kill_past(fraction: float):
    """A run's ``progress`` callback that kills the run (raises RunKilled) once it is past ``fraction`` of its
    duration."""

    def kill(frac, msg):
        if frac > fraction:
            raise RunKilled

    return kill
