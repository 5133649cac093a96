"""benchmarks/perf_record.py and perf_table.py: the trees, the record's structure and the README table (CPU; no
timing is checked)."""

import copy
import importlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))
perf_table = importlib.import_module("perf_table")
perf_record = importlib.import_module("perf_record")


def _run(tree, case, repeat, rate=None, **figures):
    entry = {"tree": tree, "case": case, "repeat": repeat, "argv": ["bench"]}
    if rate is None:
        return entry | figures
    return entry | {"figures": {"particle_steps_per_s": rate, "worlds": 1} | figures}


HM = {"spheres": 999045, "bytes_per_sphere": 1416.0}
RECORD = {
    "schema": 1,
    "date": "2026-11-24T10:00:00+00:00",
    "device": "NVIDIA H100 80GB HBM3",
    "warp": "1.19.0",
    "host": "gpu",
    "command": "python benchmarks/perf_record.py run --trees .ab/old .ab/new --out record.json",
    "trees": {
        "old": {"sha": "a" * 40, "subject": "before"},
        "new": {"sha": "b" * 40, "subject": "after", "dirty": True},
    },
    "runs": [
        _run("old", "hm", 0, 1.0e9, contacts_per_sphere=4.1, **HM),
        _run("new", "hm", 0, 1.3e9, contacts_per_sphere=4.3, **HM),
        _run("new", "hm", 1, 1.5e9, contacts_per_sphere=4.5, **HM),
        _run("old", "hm", 1, 1.2e9, contacts_per_sphere=4.1, **HM),
        _run("old", "batched17", 0, error="unrecognized arguments: --worlds 17", unsupported=True),
        _run("new", "batched17", 0, 6.0e8, spheres=339660, worlds=17, contacts_per_sphere=4.0, bytes_per_sphere=1500.0),
        _run("old", "single340k", 0, error="Traceback ...\nRuntimeError: out of memory"),
        _run("new", "single340k", 0, 8.0e8, spheres=339660, contacts_per_sphere=4.2, bytes_per_sphere=1420.4),
    ],
    "deme": [
        {"case": "hm", "repeat": 0, "argv": [], "figures": {"particle_steps_per_s": 4.0e8}},
        {"case": "hm", "repeat": 1, "argv": [], "figures": {"particle_steps_per_s": 4.2e8}},
    ],
}
TABLE = [
    "Measured 2026-11-24 on NVIDIA H100 80GB HBM3, Warp 1.19.0, commit bbbbbbbbbbbb with uncommitted changes; "
    "medians of 2 repeats (`python benchmarks/perf_record.py run --trees .ab/old .ab/new --out record.json`)",
    "",
    "| case | old (aaaaaaa) sphere-steps/s | new (bbbbbbb + changes) sphere-steps/s | new / old | contacts per sphere "
    "| bytes per sphere | DEME sphere-steps/s | new / DEME |",
    "|---|---|---|---|---|---|---|---|",
    "| hm: 999 045 spheres | 1.10 × 10⁹ | 1.40 × 10⁹ | 1.27 | 4.40 | 1416 | 4.10 × 10⁸ | 3.41 |",
    "| batched17: 17 worlds × 19 980 = 339 660 spheres | unsupported | 6.00 × 10⁸ |  | 4.00 | 1500 |  |  |",
    "| single340k: 339 660 spheres | failed | 8.00 × 10⁸ |  | 4.20 | 1420 |  |  |",
    "",
    "Batched / single world at the same total sphere count (new): 0.75.",
]


def test_sci_three_significant_digits():
    assert perf_table.sci(1.234e9) == "1.23 × 10⁹"
    assert perf_table.sci(9.996e8) == "1.00 × 10⁹"
    assert perf_table.sci(2.5e-6) == "2.50 × 10⁻⁶"
    assert perf_table.sci(5.0) == "5.00"


def test_table_rows_and_ratios():
    """Medians over repeats, newest / oldest, unsupported and failed cells, DEME only where it ran."""
    assert perf_table.markdown(RECORD).splitlines() == TABLE
    assert perf_table.markdown(copy.deepcopy(RECORD)) == perf_table.markdown(RECORD)


def test_table_says_one_run_without_repeats():
    record = copy.deepcopy(RECORD)
    record["runs"] = [r for r in record["runs"] if r["repeat"] == 0]
    record["deme"] = [d for d in record["deme"] if d["repeat"] == 0]
    header = perf_table.markdown(record).splitlines()[0]
    assert "; one run of each (`python" in header
    assert "medians" not in header


def test_readme_block_replaced_and_rest_kept(tmp_path, capsys):
    record = tmp_path / "record.json"
    record.write_text(json.dumps(RECORD))
    readme = tmp_path / "README.md"
    head = "# Title\n\n## Performance (`warpdem bench`)\n\n"
    tail = "\nText after.\n## Next\n"
    readme.write_text(head + f"{perf_table.BEGIN}\nan old table\n{perf_table.END}\n" + tail)
    assert perf_table.main([str(record), "--readme", str(readme)]) == 0
    text = readme.read_text()
    assert text == head + perf_table.BEGIN + "\n\n" + "\n".join(TABLE) + "\n\n" + perf_table.END + "\n" + tail
    assert perf_table.main([str(record), "--readme", str(readme)]) == 0
    assert readme.read_text() == text, "a second run changed the README"


def test_readme_without_markers_is_refused(tmp_path, capsys):
    record = tmp_path / "record.json"
    record.write_text(json.dumps(RECORD))
    readme = tmp_path / "NOTES.md"
    readme.write_text(f"# Notes\n{perf_table.END}\n{perf_table.BEGIN}\n")
    assert perf_table.main([str(record), "--readme", str(readme)]) == 2
    err = capsys.readouterr().err
    assert str(readme) in err and perf_table.BEGIN in err
    assert readme.read_text() == f"# Notes\n{perf_table.END}\n{perf_table.BEGIN}\n"
    with pytest.raises(ValueError, match="NOTES"):
        perf_table.replace_block("no markers\n", "table", "NOTES.md")


@pytest.fixture(scope="module")
def trees(tmp_path_factory):
    """`prepare --old HEAD` into a temporary folder: (old, new)."""
    if shutil.which("git") is None or subprocess.run(["git", "-C", str(ROOT), "rev-parse"]).returncode != 0:
        pytest.skip("needs git and a git checkout")
    base = tmp_path_factory.mktemp("ab")
    old, new = base / "old", base / "new"
    assert perf_record.main(["prepare", "--old", "HEAD", "--old-dir", str(old), "--new-dir", str(new)]) == 0
    return old, new


def test_prepare_makes_importable_trees(trees):
    """Each tree holds only the package, kernels as a real warpdem/kernels folder, and imports from itself."""
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True).stdout
    for tree in trees:
        assert sorted(p.name for p in tree.iterdir()) == ["COMMIT.json", "warpdem"]
        kernels = tree / "warpdem" / "kernels"
        assert kernels.is_dir() and not kernels.is_symlink() and (kernels / "step.py").is_file()
        assert json.loads((tree / "COMMIT.json").read_text())["sha"] == head.strip()
        where = perf_record.check_tree(tree, sys.executable)
        assert Path(where["kernels"]).is_relative_to(tree)
    assert "dirty" in json.loads((trees[1] / "COMMIT.json").read_text())


def test_cpu_smoke_run_record(trees, tmp_path):
    """One tiny CPU bench of the new tree: the record's structure (the figures are not judged)."""
    out = tmp_path / "record.json"
    argv = ["run", "--trees", str(trees[1]), "--cases", "hm", "--repeat", "1", "--device", "cpu", "--out", str(out)]
    assert perf_record.main(argv + ["--bench-args", "--count 100 --steps 5 --settle-steps 5"]) == 0
    rec = json.loads(out.read_text())
    assert {"schema", "date", "device", "warp", "host", "trees", "runs", "deme"} <= set(rec)
    assert rec["schema"] == 1 and rec["device"] == "cpu" and rec["deme"] == []
    assert list(rec["trees"]) == ["new"] and rec["trees"]["new"]["sha"]
    (run,) = rec["runs"]
    assert (run["tree"], run["case"], run["repeat"]) == ("new", "hm", 0)
    assert run["argv"][:3] == ["bench", "--device", "cpu"] and "error" not in run
    fig = run["figures"]
    assert fig["worlds"] == 1 and fig["spheres"] > 0 and fig["particle_steps_per_s"] > 0
