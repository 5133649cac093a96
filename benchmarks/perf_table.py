"""The README's performance table, from a record that benchmarks/perf_record.py wrote.

    python benchmarks/perf_table.py RECORD.json [--readme README.md]

Prints a Markdown table: one row per case, the median sphere-steps/s of each tree (the trees in the order the
record lists them, oldest first), the newest / oldest ratio, contacts and device bytes per sphere (newest
tree), and DEME's rate and our / DEME ratio where the record has DEME for the case. With --readme, the table
replaces the text between the lines ``<!-- perf-record:begin -->`` and ``<!-- perf-record:end -->`` of that
file. The output depends on the record only.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
from pathlib import Path

BEGIN = "<!-- perf-record:begin -->"
END = "<!-- perf-record:end -->"
RATE = "particle_steps_per_s"
"""The bench figure every table compares: sphere-steps/s (every sphere of every world) [1/s]."""
_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def sci(x: float) -> str:
    """``x`` to 3 significant digits as the README writes numbers, e.g. 1.23 × 10⁹."""
    if x == 0 or not math.isfinite(x):
        return f"{x:g}"
    e = math.floor(math.log10(abs(x)))
    m = round(x / 10.0**e, 2)
    if abs(m) >= 10.0:  # 9.996 rounds up to 10.00
        m, e = m / 10.0, e + 1
    return f"{m:.2f}" if e == 0 else f"{m:.2f} × 10{str(e).translate(_SUPERSCRIPT)}"


def grouped(x: int) -> str:
    """An integer with spaces between groups of three digits, as the README writes counts (999 045)."""
    return f"{x:,}".replace(",", " ")


def _median(runs: list[dict], key: str) -> float | None:
    vals = [float(r["figures"][key]) for r in runs if "figures" in r and key in r["figures"]]
    return statistics.median(vals) if vals else None


def summarize(record: dict) -> list[dict]:
    """One entry per case, in the record's order: ``case``, ``trees`` ({label: {"rate", "status", "figures"}}
    with rate the median sphere-steps/s or None, status ok, unsupported, failed or missing, figures those of the
    newest run that has them), ``ratio`` (newest / oldest tree's rate or None) and ``deme`` (DEME's median rate
    or None)."""
    labels = list(record.get("trees", {}))
    cases: list[str] = []
    for r in record.get("runs", []) + record.get("deme", []):
        if r["case"] not in cases:
            cases.append(r["case"])
    out = []
    for case in cases:
        trees = {}
        for label in labels:
            runs = [r for r in record.get("runs", []) if r["case"] == case and r["tree"] == label]
            rate = _median(runs, RATE)
            with_figures = [r["figures"] for r in runs if "figures" in r]
            if rate is not None:
                status = "ok"
            elif any(r.get("unsupported") for r in runs):
                status = "unsupported"
            elif runs:
                status = "failed"
            else:
                status = "missing"
            trees[label] = {
                "rate": rate,
                "status": status,
                "figures": with_figures[-1] if with_figures else {},
                "contacts_per_sphere": _median(runs, "contacts_per_sphere"),
                "bytes_per_sphere": _median(runs, "bytes_per_sphere"),
            }
        first, last = (trees[labels[0]]["rate"], trees[labels[-1]]["rate"]) if labels else (None, None)
        deme_runs = [r for r in record.get("deme", []) if r["case"] == case]
        out.append(
            {
                "case": case,
                "trees": trees,
                "ratio": last / first if first and last else None,
                "deme": _median(deme_runs, RATE),
                "deme_runs": len(deme_runs),
            }
        )
    return out


def _case_label(entry: dict, newest: str) -> str:
    """``case: N spheres`` with the worlds when there are several, from the newest tree that has figures."""
    figs = entry["trees"][newest]["figures"] or next(
        (t["figures"] for t in entry["trees"].values() if t["figures"]), {}
    )
    if "spheres" not in figs:
        return entry["case"]
    spheres, worlds = int(figs["spheres"]), int(figs.get("worlds", 1))
    if worlds > 1:
        return f"{entry['case']}: {worlds} worlds × {grouped(spheres // worlds)} = {grouped(spheres)} spheres"
    return f"{entry['case']}: {grouped(spheres)} spheres"


def _tree_name(label: str, meta: dict) -> str:
    sha = str(meta.get("sha", ""))[:7]
    dirty = " + changes" if meta.get("dirty") else ""
    return f"{label} ({sha}{dirty})" if sha else label


def markdown(record: dict) -> str:
    """The table as Markdown: a 'Measured ...' line, a blank line, then the table (and the batched / single
    line when the record has both ``batched17`` and ``single340k``)."""
    trees = record.get("trees", {})
    labels = list(trees)
    if not labels:
        raise ValueError("the record names no tree")
    newest, oldest = labels[-1], labels[0]
    rows = summarize(record)
    has_deme = any(e["deme"] is not None for e in rows)
    meta = trees[newest]
    sha = str(meta.get("sha", "?"))[:12] + (" with uncommitted changes" if meta.get("dirty") else "")
    command = record.get("command", "python benchmarks/perf_record.py run ...")
    # a record may span several calls (--resume): its first command, and how many more calls completed it
    repeats = 1 + max((int(r.get("repeat", 0)) for r in record.get("runs", [])), default=0)
    resumed = len(record.get("resumed", []))
    more = f", then {resumed} more call{'s' * (resumed > 1)} with --resume" if resumed else ""
    lines = [
        f"Measured {str(record.get('date', '?'))[:10]} on {record.get('device') or '?'}, Warp {record.get('warp') or '?'}, "
        f"commit {sha}; {f'medians of {repeats} repeats' if repeats > 1 else 'one run of each'} (`{command}`{more})",
        "",
    ]
    header = ["case"] + [f"{_tree_name(label, trees[label])} sphere-steps/s" for label in labels]
    if len(labels) > 1:
        header.append(f"{newest} / {oldest}")
    header += ["contacts per sphere", "bytes per sphere"]
    if has_deme:
        header += ["DEME sphere-steps/s", f"{newest} / DEME"]
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for e in rows:
        cells = [_case_label(e, newest)]
        for label in labels:
            t = e["trees"][label]
            cells.append(sci(t["rate"]) if t["rate"] is not None else t["status"])
        if len(labels) > 1:
            cells.append(f"{e['ratio']:.2f}" if e["ratio"] is not None else "")
        new = e["trees"][newest]
        z, b = new["contacts_per_sphere"], new["bytes_per_sphere"]
        cells += [f"{z:.2f}" if z is not None else "", f"{b:.0f}" if b is not None else ""]
        if has_deme:
            rate = new["rate"]
            if e["deme"] is not None:
                cells += [sci(e["deme"]), f"{rate / e['deme']:.2f}" if rate is not None else ""]
            else:
                cells += ["failed" if e["deme_runs"] else "", ""]
        lines.append("| " + " | ".join(cells) + " |")
    by_case = {e["case"]: e["trees"][newest]["rate"] for e in rows}
    if by_case.get("batched17") and by_case.get("single340k"):
        lines += [
            "",
            f"Batched / single world at the same total sphere count ({newest}): "
            f"{by_case['batched17'] / by_case['single340k']:.2f}.",
        ]
    return "\n".join(lines) + "\n"


def replace_block(text: str, block: str, name: str = "README") -> str:
    """``text`` with the lines between the BEGIN and END marker lines replaced by ``block`` (blank lines around
    it, so the Markdown renders as a table); the rest of the text unchanged."""
    lines = text.splitlines(keepends=True)
    begins = [i for i, line in enumerate(lines) if line.strip() == BEGIN]
    ends = [i for i, line in enumerate(lines) if line.strip() == END]
    if len(begins) != 1 or len(ends) != 1 or ends[0] < begins[0]:
        raise ValueError(
            f"{name}: expected one line {BEGIN} followed by one line {END}; found {len(begins)} and {len(ends)}"
            + (" in the wrong order" if begins and ends and ends[0] < begins[0] else "")
        )
    return "".join(lines[: begins[0] + 1]) + "\n" + block.rstrip("\n") + "\n\n" + "".join(lines[ends[0] :])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("record", help="the JSON record perf_record.py wrote")
    p.add_argument("--readme", help="replace the marked block of this Markdown file by the table")
    a = p.parse_args(argv)
    table = markdown(json.loads(Path(a.record).read_text()))
    print(table, end="")
    if a.readme:
        path = Path(a.readme)
        try:
            new = replace_block(path.read_text(), table, str(path))
        except ValueError as e:
            print(f"error: {e}", file=sys.stderr)
            return 2
        path.write_text(new)
        print(f"wrote the table into {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
