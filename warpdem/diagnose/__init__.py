"""Diagnose: from measured data to whether the calibrated model is adequate, the cause of its misfit, the
extended model and its gain on held-out data (``warpdem diagnose DATA.toml``)."""
