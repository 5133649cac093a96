"""Before/after performance record: `warpdem bench` of two or more commits, alternated in one call on one GPU.

Timings differ from machine to machine and from call to call, so a before/after is only fair on the same GPU in
the same call. This script makes importable copies of the commits ("trees") and runs every case's bench in each
tree in turn, repeat after repeat, writing every run to one JSON record (benchmarks/perf_table.py turns it into
the README's table).

Here, from the repository root (the trees go to the git-ignored .ab/; --old is any commit, tag or branch):

    python benchmarks/perf_record.py prepare --old REF

On the GPU machine (a device call with carry [".ab"], once Warp is staged as ../shared/tools/gpu/README.md
says), oldest tree first:

    . ~/stage/activate.sh && python3 benchmarks/perf_record.py run --trees .ab/old .ab/new --out $OUT/record.json

Then here: ``python benchmarks/perf_table.py record.json --readme README.md``.

Each bench runs in its own process, from a temporary folder, with the tree first on PYTHONPATH (from the
repository root Python would import the source folder instead). A case that an older tree's bench does not
know (``--worlds`` before it existed) is recorded as unsupported; a bench that fails is recorded with the end of
its stderr; both leave the run going. The record is rewritten after every bench, and --resume skips the benches
a record already holds, so a run cut short by a time limit goes on where it stopped.
"""

from __future__ import annotations

import argparse
import datetime
import io
import json
import os
import shlex
import shutil
import socket
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from perf_table import RATE, sci, summarize

CASES = {
    "hm": [],
    "clumps8": ["--clumps", "8", "--count", "200000"],
    # the clump bed with rolling friction: type A (the seeds' default) and EDEM's standard model, whose lever is
    # the clump's centre of mass (state.clump_x read in the step)
    "clumps8_roll": ["--clumps", "8", "--count", "200000", "--rolling", "constant_torque"],
    "clumps8_std": ["--clumps", "8", "--count", "200000", "--rolling", "standard"],
    "jkr": ["--law", "JKR"],
    "eepa": ["--law", "EEPA"],
    "batched17": ["--worlds", "17", "--count", "20000"],
    # the same total sphere count as batched17 in one world: the pair gives the cost of batching
    "single340k": ["--count", "340000"],
}
"""The bench arguments of each case (on CUDA the bench's default bed is 1 M spheres)."""
DEME_CASES = {"hm": [], "clumps8": ["--clumps", "8", "--count", "200000"]}
"""The cases that deme_bench.py (../shared/tools/gpu/) can build, with its arguments for each."""
SCHEMA = 1
TAIL = 2000
"""Characters of a failed process's stderr kept in the record."""
_BENCH = "import sys; from warpdem.cli import main; sys.exit(main(sys.argv[1:]))"
_WHERE = (
    "import json, warp, warpdem, warpdem.kernels; "
    "print(json.dumps({'warpdem': warpdem.__file__, 'kernels': warpdem.kernels.__file__, 'warp': warp.__version__}))"
)


def _git(*args: str, cwd: Path | None = None, binary: bool = False):
    out = subprocess.run(["git", *args], cwd=cwd, capture_output=True, check=False)
    if out.returncode != 0:
        raise SystemExit(f"error: git {' '.join(args)}: {out.stderr.decode(errors='replace').strip()}")
    return out.stdout if binary else out.stdout.decode().strip()


def tree_path(path: str) -> str | None:
    """Where a repository file goes in a tree (``kernels/`` becomes ``warpdem/kernels/``); None to leave it out
    (tests, scenes, caches: a tree holds only the package)."""
    if "__pycache__" in path.split("/") or path.endswith(".pyc"):
        return None
    if path.startswith("kernels/"):
        return "warpdem/" + path
    if path.startswith("warpdem/") and not path.startswith("warpdem/kernels/"):
        return path
    return None


def _fresh(tree: Path) -> None:
    """Empty ``tree`` for a new copy, refusing a folder that this script did not make."""
    if tree.exists():
        if set(p.name for p in tree.iterdir()) - {"warpdem", "COMMIT.json"}:
            raise SystemExit(f"error: {tree} holds files that prepare did not write; give another folder")
        shutil.rmtree(tree)
    tree.mkdir(parents=True)


def _commit_info(root: Path, sha: str) -> dict:
    subject, date = _git("log", "-1", "--format=%s%n%cI", sha, cwd=root).split("\n", 1)
    return {"sha": sha, "subject": subject, "date": date}


def prepare_old(root: Path, ref: str, tree: Path) -> dict:
    """``tree`` <- the package of commit ``ref`` (through ``git archive``); returns its COMMIT.json content."""
    sha = _git("rev-parse", "--verify", f"{ref}^{{commit}}", cwd=root)
    _fresh(tree)
    with tarfile.open(fileobj=io.BytesIO(_git("archive", "--format=tar", sha, cwd=root, binary=True))) as tar:
        for member in tar:
            dest = tree_path(member.name) if member.isfile() else None
            if dest:
                (tree / dest).parent.mkdir(parents=True, exist_ok=True)
                (tree / dest).write_bytes(tar.extractfile(member).read())
    info = {"ref": ref} | _commit_info(root, sha)
    (tree / "COMMIT.json").write_text(json.dumps(info, indent=1) + "\n")
    return info


def prepare_new(root: Path, tree: Path) -> dict:
    """``tree`` <- the package of the working tree (tracked and untracked files that git does not ignore);
    returns its COMMIT.json content, saying whether those files differ from HEAD."""
    listed = _git("ls-files", "-co", "--exclude-standard", "-z", cwd=root, binary=True).decode().split("\0")
    _fresh(tree)
    for path in listed:
        src = root / path
        dest = tree_path(path)
        # a symlink (such as a checkout's warpdem/kernels -> ../kernels) is left out: kernels/ is copied itself
        if dest and src.is_file() and not src.is_symlink():
            (tree / dest).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(src, tree / dest)
    status = _git("status", "--porcelain", "-z", "--untracked-files=all", "--", "warpdem", "kernels", cwd=root)
    changes = sorted(
        {e[3:] for e in status.split("\0") if len(e) > 3 and tree_path(e[3:]) and not (root / e[3:]).is_symlink()}
    )
    info = {"ref": "working tree"} | _commit_info(root, _git("rev-parse", "HEAD", cwd=root))
    info |= {"dirty": bool(changes), "changes": changes}
    (tree / "COMMIT.json").write_text(json.dumps(info, indent=1) + "\n")
    return info


def cmd_prepare(a) -> int:
    root = Path(_git("rev-parse", "--show-toplevel", cwd=Path(__file__).resolve().parent))
    for label, tree, make in (
        ("old", root / a.old_dir, lambda t: prepare_old(root, a.old, t)),
        ("new", root / a.new_dir, lambda t: prepare_new(root, t)),
    ):
        info = make(tree)
        files = sum(1 for p in tree.rglob("*") if p.is_file())
        dirty = " + uncommitted changes" if info.get("dirty") else ""
        print(f"{label}: {tree} ({files} files) = {info['sha'][:12]}{dirty} {info['subject']}")
        # inside the repository the trees must be ignored, or they would be copied as sources (and committed)
        inside = tree.resolve().is_relative_to(root.resolve())
        if inside and subprocess.run(["git", "check-ignore", "-q", str(tree)], cwd=root).returncode != 0:
            print(f"warning: {tree} is not git-ignored; add it to .gitignore", file=sys.stderr)
    return 0


# run ---------------------------------------------------------------------------------------------------------


def _tree_env(tree: Path) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(tree.resolve()) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def check_tree(tree: Path, python: str) -> dict:
    """Where ``tree``'s ``warpdem`` and ``warpdem.kernels`` import from (and Warp's version); exits when either
    comes from outside the tree (an installed copy would be measured instead)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = subprocess.run([python, "-c", _WHERE], cwd=tmp, env=_tree_env(tree), capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"error: {tree}: warpdem does not import:\n{out.stderr[-TAIL:]}")
    where = json.loads(out.stdout.strip().splitlines()[-1])
    for key in ("warpdem", "kernels"):
        if not Path(where[key]).resolve().is_relative_to(tree.resolve()):
            raise SystemExit(f"error: {tree}: {key} imports from {where[key]}, outside the tree")
    return where


def _figures(path: Path) -> dict:
    """The bench's --json output as {name: value}: a list of {name, value, unit} (every commit so far) or a
    plain object."""
    data = json.loads(path.read_text())
    return {d["name"]: d["value"] for d in data} if isinstance(data, list) else dict(data)


def _run(cmd: list[str], env: dict, timeout: float, result: str) -> dict:
    """Run ``cmd`` from a temporary folder; returns {"figures": ...} read from the file ``result`` it wrote
    there, or {"error": ..., and "unsupported": True when argparse refused an argument}."""
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        try:
            out = subprocess.run(cmd, cwd=tmp, env=env, capture_output=True, text=True, timeout=timeout or None)
        except subprocess.TimeoutExpired:
            return {"error": f"timed out after {timeout:g} s", "elapsed_s": time.perf_counter() - t0}
        elapsed = time.perf_counter() - t0
        if out.returncode == 0 and (Path(tmp) / result).is_file():
            return {"figures": _figures(Path(tmp) / result), "elapsed_s": elapsed}
    err = (out.stderr or out.stdout)[-TAIL:]
    res = {"error": err, "returncode": out.returncode, "elapsed_s": elapsed}
    # argparse exits with 2 on an option or a choice that an older bench does not have
    if out.returncode == 2 and ("unrecognized arguments" in err or "invalid choice" in err):
        res["unsupported"] = True
    return res


def _write(record: dict, path: Path) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(record, indent=1) + "\n")
    os.replace(tmp, path)  # a kill mid-write leaves the previous record whole


def _done(entries: list[dict], **key) -> bool:
    """Whether ``entries`` hold a finished run (figures, or unsupported) matching ``key``."""
    return any(all(e.get(k) == v for k, v in key.items()) and ("figures" in e or e.get("unsupported")) for e in entries)


def _rate(res: dict) -> str:
    if "figures" in res:
        return f"{sci(float(res['figures'].get(RATE, float('nan'))))} sphere-steps/s"
    last = (res["error"].strip().splitlines() or ["(no output)"])[-1]
    return "unsupported" if res.get("unsupported") else f"FAILED: {last[:200]}"


def cmd_run(a) -> int:
    trees = [Path(t) for t in a.trees]
    labels = [t.name for t in trees]
    if len(set(labels)) != len(labels):
        raise SystemExit(f"error: --trees: the folder names label the trees and must differ; got {labels}")
    cases = [c.strip() for c in a.cases.split(",") if c.strip()]
    unknown = [c for c in cases if c not in CASES]
    if unknown:
        raise SystemExit(f"error: --cases: {unknown} not known; expected some of {','.join(CASES)}")
    where = {label: check_tree(t, a.python) for label, t in zip(labels, trees)}
    out = Path(a.out)
    meta = {label: _commit_meta(t) for label, t in zip(labels, trees)}
    record_command = "python benchmarks/perf_record.py " + shlex.join(_shown_argv(a))
    record = {
        "schema": SCHEMA,
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "device": None,
        "warp": where[labels[-1]]["warp"],
        "host": socket.gethostname(),
        "command": record_command,
        "trees": meta,
        "runs": [],
        "deme": [],
    }
    if a.resume and out.is_file():
        old = json.loads(out.read_text())
        if old.get("trees") != meta:
            raise SystemExit(f"error: --resume: {out} records other trees ({list(old.get('trees', {}))})")
        record = old
        stamp = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
        record.setdefault("resumed", []).append({"date": stamp, "command": record_command})
    out.parent.mkdir(parents=True, exist_ok=True)
    _write(record, out)
    bench_args = shlex.split(a.bench_args)
    total = a.repeat * (len(cases) * len(trees) + (sum(c in DEME_CASES for c in cases) if a.deme else 0))
    n = 0
    for k in range(a.repeat):
        # the trees take turns leading, so a drift of the machine (clocks, temperature) hits each alike
        order = list(zip(labels, trees))[k % len(trees) :] + list(zip(labels, trees))[: k % len(trees)]
        for case in cases:
            for label, tree in order:
                n += 1
                if _done(record["runs"], tree=label, case=case, repeat=k):
                    continue
                argv = ["bench", "--device", a.device, *CASES[case], *bench_args, "--json", "bench.json"]
                res = _run([a.python, "-c", _BENCH, *argv], _tree_env(tree), a.timeout, "bench.json")
                record["runs"] = [
                    r for r in record["runs"] if (r["tree"], r["case"], r["repeat"]) != (label, case, k)
                ] + [{"tree": label, "case": case, "repeat": k, "argv": argv} | res]
                if record["device"] is None and "figures" in res:
                    record["device"] = res["figures"].get("device")
                _write(record, out)
                print(f"[{n}/{total}] repeat {k} {case} {label}: {_rate(res)} ({res['elapsed_s']:.0f} s)", flush=True)
            if a.deme and case in DEME_CASES:
                n += 1
                if _done(record["deme"], case=case, repeat=k):
                    continue
                res = _run_deme(a, case, k, record)
                record["deme"] = [d for d in record["deme"] if (d["case"], d["repeat"]) != (case, k)] + [res]
                _write(record, out)
                print(
                    f"[{n}/{total}] repeat {k} {case} DEME: {_rate(res)} ({res.get('elapsed_s', 0):.0f} s)", flush=True
                )
    print_summary(record)
    print(f"record: {out}")
    return 0


def _commit_meta(tree: Path) -> dict:
    f = tree / "COMMIT.json"
    return json.loads(f.read_text()) if f.is_file() else {"path": str(tree)}


def _shown_argv(a) -> list[str]:
    """The run's command line as the README shows it: the output file by its name only (the GPU machine's
    $OUT is a temporary folder)."""
    argv = a.argv
    return [Path(x).name if i > 0 and argv[i - 1] == "--out" else x for i, x in enumerate(argv)]


def _run_deme(a, case: str, k: int, record: dict) -> dict:
    """DEME's bench of ``case`` (its own process, with only DEME's site on PYTHONPATH: its CUDA 12.8 packages
    would shadow the machine's CUDA 13 ones elsewhere), at the step the newest tree ran this case with."""
    site = os.environ.get("DEME_SITE")
    entry = {"case": case, "repeat": k}
    if not site:
        return entry | {"error": "DEME_SITE is not set: source ~/stage/deme-activate.sh first", "elapsed_s": 0.0}
    last = list(record["trees"])[-1]
    newest = [r for r in record["runs"] if (r["tree"], r["case"], r["repeat"]) == (last, case, k)]
    dt = newest[0].get("figures", {}).get("dt") if newest else None
    argv = [
        str(Path(a.deme).resolve()),
        *DEME_CASES[case],
        *(["--dt", repr(float(dt))] if dt else []),
        *shlex.split(a.deme_args),
    ]
    env = dict(os.environ, PYTHONPATH=site)
    res = _run([a.python, *argv, "--json", "deme.json"], env, a.timeout, "deme.json")
    if "figures" in res:
        res["figures"].pop("settle_log", None)  # one row per settle chunk: long, and not a figure
    return entry | {"argv": argv} | res


def print_summary(record: dict) -> None:
    """Case x tree median sphere-steps/s, newest / oldest, and our / DEME where DEME ran."""
    labels = list(record["trees"])
    deme = bool(record["deme"])
    head = ["case", *labels] + ([f"{labels[-1]} / {labels[0]}"] if len(labels) > 1 else [])
    head += ["DEME", f"{labels[-1]} / DEME"] if deme else []
    rows = []
    for e in summarize(record):
        cells = [e["case"]] + [
            sci(t["rate"]) if t["rate"] is not None else t["status"] for t in (e["trees"][x] for x in labels)
        ]
        if len(labels) > 1:
            cells.append(f"{e['ratio']:.3f}" if e["ratio"] is not None else "")
        if deme:
            new = e["trees"][labels[-1]]["rate"]
            cells.append(sci(e["deme"]) if e["deme"] is not None else "")
            cells.append(f"{new / e['deme']:.3f}" if e["deme"] and new else "")
        rows.append(cells)
    title = f"median sphere-steps/s on {record.get('device') or '?'}"
    try:
        from rich.console import Console
        from rich.table import Table

        t = Table(title=title)
        for h in head:
            t.add_column(h)
        for r in rows:
            t.add_row(*r)
        Console().print(t)
    except ImportError:
        print(title)
        for r in [head, *rows]:
            print(" | ".join(r))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    pr = sub.add_parser("prepare", help="make the importable trees of an older commit and of the working tree")
    pr.add_argument("--old", required=True, metavar="REF", help="the commit to compare against")
    pr.add_argument("--new-dir", default=".ab/new", help="the working tree's copy (relative: to the repository root)")
    pr.add_argument("--old-dir", default=".ab/old", help="REF's copy (relative: to the repository root)")
    pr.set_defaults(fn=cmd_prepare)
    r = sub.add_parser("run", help="run the benches of every tree, alternating, into one record")
    r.add_argument("--trees", nargs="+", required=True, metavar="DIR", help="trees, oldest first")
    r.add_argument("--cases", default=",".join(CASES), help=f"comma-separated, of {','.join(CASES)}")
    r.add_argument("--repeat", type=int, default=2, help="rounds over every case and tree")
    r.add_argument("--out", required=True, help="the JSON record (rewritten after every bench)")
    r.add_argument("--device", default="cuda")
    r.add_argument("--bench-args", default="", help='appended to every bench, e.g. "--steps 500" (last wins)')
    r.add_argument("--deme", metavar="PATH", help="deme_bench.py: run DEME for hm and clumps8 once a repeat")
    r.add_argument("--deme-args", default="", help="appended to every DEME bench")
    r.add_argument("--timeout", type=float, default=0.0, help="seconds one bench may take (0: no limit)")
    r.add_argument("--resume", action="store_true", help="keep the runs --out already holds and do the rest")
    r.add_argument("--python", default=sys.executable, help="the interpreter of the benches")
    r.set_defaults(fn=cmd_run)
    argv = sys.argv[1:] if argv is None else list(argv)
    a = p.parse_args(argv)
    a.argv = argv
    return a.fn(a)


if __name__ == "__main__":
    sys.exit(main())
