"""Diagnose: from measured data to whether the calibrated model is adequate, the cause of its misfit, the
extended model and its gain on held-out data (``warpdem diagnose DATA.toml``).

``data``        the diagnosis file (TOML) and its experiments table (CSV): loading and validation.
``candidates``  the library of candidate model extensions.
"""

from .data import DiagnoseError, DiagnosisSpec, Experiments, ParameterSpec, load_diagnosis

__all__ = ["DiagnoseError", "DiagnosisSpec", "Experiments", "ParameterSpec", "load_diagnosis"]
