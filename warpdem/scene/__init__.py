"""Scenes: USD stages <-> SceneSpec (``stage``), the rigs authored from parameters (``rigs``), running a
scene (``runner``), measurements on its results (``measure``) and export to USD, VTK and pictures
(``export``).

May import: ``warpdem.engine``, NumPy, SciPy, and (inside the functions that need them) usd-core,
pyvista and matplotlib. Never imports ``warpdem.study``, ``warpdem.verify`` or ``warpdem.cli``.
"""
