"""docs/seeds/shrink_pictures.py makes a plot-like picture smaller as a palette image without visibly changing it,
and leaves a picture alone when the palette would not be smaller."""

import numpy as np
import pytest

from tests.conftest import load_seed_script


@pytest.fixture(scope="module")
def shrink():
    return load_seed_script("shrink_pictures.py").shrink


def test_a_plot_shrinks_and_keeps_its_colours(shrink, tmp_path):
    from PIL import Image

    rng = np.random.default_rng(0)
    # a white page with 300 grains of eight browns, drawn as small squares, and a red line: a pile render's palette
    img = np.full((200, 300, 4), 255, np.uint8)
    browns = rng.integers(90, 200, (8, 3))
    for x, y, c in zip(rng.integers(0, 295, 300), rng.integers(100, 195, 300), rng.integers(0, 8, 300), strict=True):
        img[y : y + 5, x : x + 5, :3] = browns[c]
    img[np.arange(200), np.arange(200) // 2 + 50, :3] = (200, 30, 30)
    f = tmp_path / "pile.png"
    Image.fromarray(img, "RGBA").save(f)
    before, after = shrink(f)
    assert after < before and after == f.stat().st_size
    with Image.open(f) as out:
        assert out.mode == "P"
        back = np.asarray(out.convert("RGBA"), int)
    # a palette of 256 holds these 10 colours exactly, up to the quantizer's rounding
    assert np.abs(back - img.astype(int)).max() <= 8


def test_a_palette_picture_is_left_alone(shrink, tmp_path):
    from PIL import Image

    f = tmp_path / "p.png"
    Image.new("P", (10, 10)).save(f)
    data = f.read_bytes()
    assert shrink(f) == (len(data), len(data)) and f.read_bytes() == data
