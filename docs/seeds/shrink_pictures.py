"""Rewrite record pictures as 256-colour palette PNGs where that is smaller (about four times for plots and pile
renders, with no visible change). The package writes its pictures so since the eighteenth stage of issue 23; run
this on a record folder made before that, or elsewhere, before committing it:

    python docs/seeds/shrink_pictures.py docs/seeds/001/some_record [...]

The repository travels to the GPU machine beside a piece of Warp's wheel under one size limit, so the records'
pictures are kept small. Prints the bytes before and after.
"""

from __future__ import annotations

import sys
from pathlib import Path


def shrink(path: Path) -> tuple[int, int]:
    """Rewrite one PNG as a palette image if that is smaller (:func:`warpdem.scene.export.palette_png`, what the
    package writes its pictures with); (bytes before, bytes after)."""
    from warpdem.scene.export import palette_png

    data = path.read_bytes()
    out = palette_png(data)
    if out is not data:
        path.write_bytes(out)
    return len(data), len(out)


def main(argv: list[str]) -> int:
    total = [0, 0]
    for arg in argv:
        p = Path(arg)
        for f in [p] if p.suffix == ".png" else sorted(p.rglob("*.png")):
            b, a = shrink(f)
            total[0] += b
            total[1] += a
    print(f"{total[0]} bytes -> {total[1]} bytes")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
