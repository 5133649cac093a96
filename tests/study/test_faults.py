"""Faults a study or a diagnosis must survive: a first write cut short (a full disk), and a folder left by one.
The study is test_execute's tiny funnel (40 spheres, 0.3 s), whose kernels the other tests compile."""

from __future__ import annotations

import errno
import os

import pytest

from warpdem.study import execute
from warpdem.study.spec import StudyError

from .test_execute import _run, _study

pytest.importorskip("warp")


def _no_space(*args, **kwargs):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def _files(out) -> list[str]:
    return sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())


def test_a_first_write_on_a_full_disk_leaves_the_folder_to_a_rerun(tmp_path, monkeypatch):
    """The disk fills as the study's first file is written (fsync fails, as a write does where the data cannot
    be kept): the error is an OSError naming study.toml, no study.toml (empty or partial) and no temporary file
    is left, and the same call then runs the study through."""
    study = _study(tmp_path)
    out = tmp_path / "out"
    with monkeypatch.context() as m:
        m.setattr(os, "fsync", _no_space)
        with pytest.raises(OSError) as err:
            _run(study, out, analyze_after=False)
    assert err.value.errno == errno.ENOSPC and err.value.filename == str(out / "study.toml")
    assert _files(out) == ["log.txt"]
    res = _run(study, out, analyze_after=False)
    assert res["ran"] == 6 and res["stopped"] is None
    assert (out / "study.toml").read_text() == study.path.read_text()
    assert not list(out.rglob("*.partial"))


def test_a_folder_whose_first_write_was_cut_starts_again(tmp_path):
    """A folder an older warpdem left on a full disk: an empty study.toml, a temporary file, no run. A rerun
    starts the study again (saying so in the log) instead of refusing a folder that "holds study None"."""
    study = _study(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    (out / "study.toml").write_text("")
    (out / ".design.csv.123.partial").write_text("run,")
    res = _run(study, out, analyze_after=False)
    assert res["ran"] == 6
    assert (out / "study.toml").read_text() == study.path.read_text()
    assert not (out / ".design.csv.123.partial").exists()
    assert f"{out / 'study.toml'}: is empty and no run has finished" in (out / "log.txt").read_text()


@pytest.mark.parametrize("text, reason", [("", "is empty"), ("[study]\nname = 'ti", "is not TOML")])
def test_a_broken_study_copy_beside_finished_runs_is_refused(tmp_path, text, reason):
    """Finished runs beside a study.toml that is empty or cut short: which study they ran is unknown, so the
    study is refused with the file named and how to put it back, and nothing in the folder is touched."""
    study = _study(tmp_path)
    out = tmp_path / "out"
    (out / "runs").mkdir(parents=True)
    (out / "runs" / "abc.json").write_text("{}")
    (out / "study.toml").write_text(text)
    with pytest.raises(StudyError, match=rf"{out / 'study.toml'}: {reason}.* holds 1 finished run\(s\); put back"):
        execute._check_folder(out, study, print)
    assert (out / "study.toml").read_text() == text


def test_a_diagnosis_whose_first_copy_fails_leaves_no_partial_copy(tmp_path, monkeypatch):
    """A diagnosis's first writes (the copies of its data file and table) on a full disk: an OSError naming the
    copy, and neither a partial copy nor a temporary file, so the next start writes them whole."""
    from tests.diagnose.test_data import _write
    from warpdem.diagnose.pipeline import diagnose

    out = tmp_path / "out"
    with monkeypatch.context() as m:
        m.setattr(os, "fsync", _no_space)
        with pytest.raises(OSError) as err:
            diagnose(_write(tmp_path), out, progress=False, log=lambda *a: None)
    assert err.value.errno == errno.ENOSPC and err.value.filename == str(out / "data.toml")
    assert _files(out) == []
