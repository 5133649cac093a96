"""Rewrite record pictures as 256-colour palette PNGs where that is smaller (about four times for plots and pile
renders, with no visible change). Run it on a record folder before committing it:

    python docs/seeds/shrink_pictures.py docs/seeds/001/some_record [...]

The repository travels to the GPU machine beside a piece of Warp's wheel under one size limit, so the records'
pictures are kept small. Prints the bytes before and after.
"""

from __future__ import annotations

import io
import sys
from pathlib import Path


def shrink(path: Path) -> tuple[int, int]:
    """Rewrite one PNG as a palette image if that is smaller; (bytes before, bytes after)."""
    from PIL import Image

    before = path.stat().st_size
    with Image.open(path) as im:
        im.load()
        if im.mode == "P":
            return before, before
        buf = io.BytesIO()
        im.convert("RGBA").quantize(256, method=Image.Quantize.FASTOCTREE).save(buf, "PNG", optimize=True)
    if buf.tell() >= before:
        return before, before
    path.write_bytes(buf.getvalue())
    return before, buf.tell()


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
