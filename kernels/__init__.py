"""Warp kernels of warpdem (installed as ``warpdem.kernels``).

Each contact law is a small pure ``@wp.func`` in its own file (``law_*.py``); ``step.py`` and
``neighbors.py`` hold the only kernels, so Warp compiles two modules on first use.
"""
