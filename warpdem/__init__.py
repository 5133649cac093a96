"""warpdem: Discrete Element Method on NVIDIA Warp.

The public API, listed once in ``__all__``.
"""

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
from .engine.types import ContactLaw, Contacts, Control, Model, Overflow, RollingModel, State
from .scene import measure, rigs
from .scene.export import ResultWriter, ShapeGeometry, WallGeometry, side_view_png
from .scene.runner import RunResult, RunStopped, run_scene
from .scene.stage import SceneSpec, StageError, read_stage, write_stage

__version__ = "0.1.0"

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
    "SimulationError",
    "Solver",
    "SolverOptions",
    "State",
    "effective_moduli",
]
