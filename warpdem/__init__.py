"""warpdem: Discrete Element Method on NVIDIA Warp.

The public API, listed once in ``__all__``. The study and diagnosis layers (designs of experiments, their
analysis, the diagnosis of a calibrated model) need pandas, SciPy and statsmodels, so their names load on first
use (:data:`_LAZY`): ``import warpdem`` stays an engine import.
"""

import importlib

from .engine import geometry
from .engine.builder import ModelBuilder
from .engine.clumps import ClumpTemplate, pellet_template, phosphate_template, rod_template
from .engine.factories import (
    Box,
    Cone,
    Cylinder,
    DynamicFactory,
    FixedSize,
    LogNormal,
    SieveTable,
    TruncatedNormal,
    fill_region,
    random_quaternions,
)
from .engine.materials import Interaction, InteractionTable, Material, effective_moduli
from .engine.motion import MotionTable, Segment, WallMotion
from .engine.solver import SimulationError, Solver, SolverOptions
from .engine.types import ContactLaw, Contacts, Control, Model, Overflow, RollingModel, SphereActivity, State
from .scene import measure, rigs
from .scene.export import ResultWriter, ShapeGeometry, WallGeometry, side_view_png
from .scene.runner import RunResult, RunStopped, run_scene
from .scene.stage import SceneSpec, StageError, read_stage, write_stage

__version__ = "0.1.0"

_LAZY = {
    "StudyError": "warpdem.study.spec",
    "StudySpec": "warpdem.study.spec",
    "load_study": "warpdem.study.spec",
    "run_study": "warpdem.study.execute",
    "analyze_study": "warpdem.study.execute:analyze",
    "load_results": "warpdem.study.execute",
    "DiagnoseError": "warpdem.diagnose.data",
    "DiagnosisSpec": "warpdem.diagnose.data",
    "load_diagnosis": "warpdem.diagnose.data",
    "run_diagnosis": "warpdem.diagnose.pipeline:diagnose",
}
"""Public names of the study and diagnosis layers -> "module" or "module:attribute" they load from (the
diagnosis is ``run_diagnosis``: ``warpdem.diagnose`` is its subpackage)."""


def __getattr__(name: str):
    if name not in _LAZY:
        raise AttributeError(f"module 'warpdem' has no attribute {name!r}")
    module, _, attr = _LAZY[name].partition(":")
    value = getattr(importlib.import_module(module), attr or name)
    globals()[name] = value
    return value


__all__ = [
    "geometry",
    "measure",
    "rigs",
    "ResultWriter",
    "RunResult",
    "RunStopped",
    "SceneSpec",
    "ShapeGeometry",
    "StageError",
    "WallGeometry",
    "read_stage",
    "run_scene",
    "side_view_png",
    "write_stage",
    "Box",
    "ClumpTemplate",
    "Cone",
    "Cylinder",
    "DynamicFactory",
    "FixedSize",
    "LogNormal",
    "MotionTable",
    "Segment",
    "SieveTable",
    "TruncatedNormal",
    "WallMotion",
    "fill_region",
    "pellet_template",
    "phosphate_template",
    "rod_template",
    "random_quaternions",
    "ContactLaw",
    "Contacts",
    "Control",
    "Interaction",
    "InteractionTable",
    "Material",
    "Model",
    "ModelBuilder",
    "Overflow",
    "RollingModel",
    "SphereActivity",
    "SimulationError",
    "Solver",
    "SolverOptions",
    "State",
    "effective_moduli",
    *_LAZY,
]
