"""The command line the docs/seeds report scripts share: print the report and, with ``--out FILE``, write it there
too (each script keeps its output beside it, and the script's test checks that output is what it prints now)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path


def main(doc: str, report: Callable[[], str], argv: list[str] | None = None) -> int:
    """Parse ``argv`` (``--out FILE``), print ``report()`` and write it to FILE; ``doc`` is the script's docstring,
    whose first paragraph describes the command. Returns the exit code, 0."""
    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    ap.add_argument("--out", type=Path, help="also write the report to this file")
    args = ap.parse_args(argv)
    text = report()
    print(text, end="")
    if args.out:
        args.out.write_text(text)
    return 0
