"""The output resampled band by band while its first bands are encoded (issue 24): the same bytes."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from helpers import star, write_png, write_polygon

from warpcli.pipeline import warp_file, warp_image
from warpcli.raster.imageio import RasterImage, read_image, write_image


@pytest.mark.parametrize("band", [1, 5, 32, 500])
@pytest.mark.parametrize("channels", [1, 4])
def test_render_rows_makes_render_s_pixels_and_covers_every_row_in_order(band, channels):
    rng = np.random.default_rng(band + channels)
    px = rng.integers(0, 256, (70, 90, channels), dtype=np.uint8)
    # A target well inside the output: rows above and below the window are background.
    res = warp_image(px, star(6, 45, 35, 10, 25), star(6, 45, 35, 8, 22, 0.3), alpha_channel=3 if channels == 4 else None)
    out = np.empty_like(res.pixels)
    rows = list(res.plan.render_rows(px, out, alpha_channel=3 if channels == 4 else None, band=band))
    assert rows[0][0] == 0 and rows[-1][1] == px.shape[0]
    assert all(a[1] == b[0] and a[0] < a[1] for a, b in itertools.pairwise(rows))
    assert out.tobytes() == res.pixels.tobytes()


@pytest.mark.parametrize("ext", ["png", "tif"])
@pytest.mark.parametrize("channels", [3, 4])
def test_a_streamed_warp_file_writes_the_bytes_of_the_whole_image_written_at_once(tmp_path, ext, channels):
    rng = np.random.default_rng(channels)
    px = rng.integers(0, 256, (300, 110, channels), dtype=np.uint8)  # several bands of 128 rows
    inp = write_png(tmp_path / "in.png", px)
    src = write_polygon(tmp_path / "s.json", star(6, 55, 150, 30, 140))
    dst = write_polygon(tmp_path / "d.json", star(6, 55, 150, 25, 145, 0.2))
    streamed = tmp_path / f"streamed.{ext}"
    result = warp_file(inp, streamed, src, dst)
    image = read_image(inp)
    whole = tmp_path / f"whole.{ext}"
    write_image(whole, RasterImage(result.pixels, image.channel_names, image.alpha_channel, image.attributes,
                                   image.associated_alpha))  # fmt: skip
    assert streamed.read_bytes() == whole.read_bytes()
    # and the pixels are those of the warp made whole in memory
    assert result.pixels.tobytes() == warp_image(image.pixels, read_polygon_points(src), read_polygon_points(dst),
                                                 alpha_channel=image.alpha_channel).pixels.tobytes()  # fmt: skip


def read_polygon_points(path):
    import json

    with open(path) as fh:
        return np.asarray(json.load(fh), dtype=np.float64)
