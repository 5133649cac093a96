"""The DEM engine: Model / State / Control / Contacts, materials and the interaction table, the model
builder, the solver (a step is a short list of launcher calls into ``warpdem.kernels``), wall motion,
clumps, factories, mesh geometry and the closed forms the engine needs.

May import: Warp, NumPy, SciPy (inside the functions that need it), ``warpdem.kernels``. Never imports
usd-core, pandas, statsmodels, matplotlib, or another warpdem subpackage.
"""
