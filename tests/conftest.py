import importlib.util
from pathlib import Path

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


DOCS_SEEDS = Path(__file__).resolve().parents[1] / "docs" / "seeds"


def load_seed_script(relpath: str):
    """A script under docs/seeds (not part of the package), imported as a module by its file path."""
    path = DOCS_SEEDS / relpath
    spec = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
