"""Verification against analytic answers (``cases``, ``bodies``, ``cohesion``), their records
(``record``) and the throughput benchmark (``bench``).

May import: ``warpdem.engine`` (and SciPy inside a case). Never imports ``warpdem.scene``,
``warpdem.study`` or ``warpdem.cli``.
"""
