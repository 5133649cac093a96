"""docs/seeds/report_cli.py, the command line of the seed report scripts: the report goes to stdout and, with
--out, to the file unchanged; each script's main runs through it."""

import pytest

from tests.conftest import load_seed_script


def test_the_report_is_printed_and_written(tmp_path, capsys):
    cli = load_seed_script("report_cli.py")
    out = tmp_path / "report.txt"
    assert cli.main("A report.\n\nMore.", lambda: "line 1\nline 2\n", ["--out", str(out)]) == 0
    assert capsys.readouterr().out == "line 1\nline 2\n" == out.read_text()
    with pytest.raises(SystemExit):
        cli.main("A report.", lambda: "", ["--bad"])


def test_a_script_runs_through_it(tmp_path, capsys):
    rr = load_seed_script("reach_repeatability.py")
    out = tmp_path / "r.txt"
    assert rr.main(["--out", str(out)]) == 0
    assert out.read_text() == capsys.readouterr().out == rr.report()
