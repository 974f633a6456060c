"""What a figure the reports write must be: a PNG of a readable size that is not blank."""

from __future__ import annotations

from pathlib import Path

MIN_PIXELS, MAX_PIXELS = (600, 400), (3000, 3000)


def check_png(path: Path) -> None:
    """Fail unless ``path`` is a PNG between :data:`MIN_PIXELS` and :data:`MAX_PIXELS` with contrast in it."""
    from PIL import Image

    assert path.is_file(), f"{path} was not written"
    with Image.open(path) as im:
        assert im.format == "PNG", f"{path}: format {im.format}, expected PNG"
        w, h = im.size
        assert MIN_PIXELS[0] <= w <= MAX_PIXELS[0] and MIN_PIXELS[1] <= h <= MAX_PIXELS[1], \
            f"{path}: {w} x {h} px, expected between {MIN_PIXELS} and {MAX_PIXELS}"
        lo, hi = im.convert("L").getextrema()
        assert hi - lo > 100, f"{path}: grey levels {lo}..{hi}: a blank image"
