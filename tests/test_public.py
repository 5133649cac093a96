"""The one public surface: ``warpdem.__all__``."""

import subprocess
import sys

import warpdem as wd


def test_every_public_name_resolves():
    """Each name of ``__all__`` is an attribute (the study and diagnosis names load on first use) and is the
    object its own module defines."""
    for name in wd.__all__:
        assert getattr(wd, name) is not None, name
    from warpdem.diagnose.pipeline import diagnose
    from warpdem.study.execute import analyze, run_study

    assert wd.run_diagnosis is diagnose and wd.run_study is run_study and wd.analyze_study is analyze


def test_engine_import_stays_light():
    """``import warpdem`` loads neither pandas nor SciPy (the study layer's libraries); a misspelt name raises
    AttributeError naming it."""
    code = (
        "import sys, warpdem\n"
        "assert not {'pandas', 'scipy', 'statsmodels'} & set(sys.modules), sorted(sys.modules)\n"
        "try:\n    warpdem.diagnoze\nexcept AttributeError as e:\n    assert \"'diagnoze'\" in str(e)\n"
        "else:\n    raise SystemExit('no AttributeError')\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)
