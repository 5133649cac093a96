"""warpdem: Discrete Element Method on NVIDIA Warp.

The public API, listed once in ``__all__``.
"""

from .builder import ModelBuilder
from .materials import Interaction, InteractionTable, Material, effective_moduli
from .solver import SimulationError, Solver, SolverOptions
from .types import ContactLaw, Contacts, Control, Model, Overflow, RollingModel, State

__version__ = "0.1.0"

__all__ = [
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
