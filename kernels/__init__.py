"""Warp kernels of warpdem (installed as ``warpdem.kernels``).

Each contact law is a small pure ``@wp.func`` in its own file (``law_*.py``); ``step.py`` and
``neighbors.py`` hold the only kernels, so Warp compiles two modules on first use, each kernel with its
launcher beside it. ``enums.py`` defines the enums (re-exported by ``warpdem.engine.types``) and
``params.py`` the structs: the per-pair parameters and the per-contact history.
"""
