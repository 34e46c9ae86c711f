"""Image I/O through OpenImageIO: formats, bit depths, channels, metadata, --dtype."""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest

from helpers import write_polygon
from warpcli.cli import main
from warpcli.raster.imageio import convert_pixels, read_image

TYPES = {np.dtype(np.uint8): "uint8", np.dtype(np.uint16): "uint16", np.dtype(np.float16): "half", np.dtype(np.float32): "float"}


def write(path, px, names=None, attrs=()):
    h, w, c = px.shape
    spec = oiio.ImageSpec(w, h, c, TYPES[px.dtype])
    if names:
        spec.channelnames = tuple(names)
    if names and "A" in names:
        spec.alpha_channel = list(names).index("A")
        spec.attribute("oiio:UnassociatedAlpha", 1)  # store the values as given
    for name, kind, value in attrs:
        spec.attribute(name, oiio.TypeDesc(kind), value)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec), out.geterror()
    assert out.write_image(np.ascontiguousarray(px))
    out.close()
    return str(path)


def spec_of(path):
    inp = oiio.ImageInput.open(str(path))
    spec = inp.spec()
    px = inp.read_image(oiio.UNKNOWN)
    inp.close()
    return spec, px if px.ndim == 3 else px[:, :, None]


def pattern(h, w, c, dtype):
    rng = np.random.default_rng(12)
    x = rng.random((h, w, c))
    if np.issubdtype(dtype, np.integer):
        return (x * np.iinfo(dtype).max).astype(dtype)
    return (x * 3.0 - 1.0).astype(dtype)  # floats beyond 0..1 must survive


CASES = [
    ("png", np.uint8, 1), ("png", np.uint8, 2), ("png", np.uint8, 3), ("png", np.uint8, 4),
    ("png", np.uint16, 1), ("png", np.uint16, 3), ("png", np.uint16, 4),
    ("tif", np.uint8, 3), ("tif", np.uint8, 5), ("tif", np.uint16, 3), ("tif", np.float32, 1), ("tif", np.float32, 4),
    ("exr", np.float16, 3), ("exr", np.float16, 4), ("exr", np.float32, 1), ("exr", np.float32, 3), ("exr", np.float32, 6),
]  # fmt: skip


@pytest.mark.parametrize("ext,dtype,channels", CASES, ids=[f"{e}-{np.dtype(d).name}-{c}ch" for e, d, c in CASES])
def test_identity_warp_round_trips_every_format_exactly(tmp_path, ext, dtype, channels):
    h, w = 24, 32
    px = pattern(h, w, channels, dtype)
    inp = write(tmp_path / f"in.{ext}", px)
    full = write_polygon(tmp_path / "full.json", [[0, 0], [w, 0], [w, h], [0, h]])
    out = tmp_path / f"out.{ext}"
    assert main([inp, str(out), "--src", full, "--dst", full, "--interp", "nearest"]) == 0
    spec_in, back_in = spec_of(inp)
    spec_out, back = spec_of(out)
    assert back.dtype == back_in.dtype == np.dtype(dtype)
    assert spec_out.channelnames == spec_in.channelnames
    assert spec_out.alpha_channel == spec_in.alpha_channel
    np.testing.assert_array_equal(back, back_in)


def test_jpeg_keeps_8_bits_and_the_picture(tmp_path):
    y, x = np.mgrid[0:48, 0:64]
    px = np.stack([x * 4, y * 5, (x + y) * 2], axis=2).astype(np.uint8)
    inp = write(tmp_path / "in.jpg", px)
    full = write_polygon(tmp_path / "full.json", [[0, 0], [64, 0], [64, 48], [0, 48]])
    assert main([inp, str(tmp_path / "out.jpg"), "--src", full, "--dst", full]) == 0
    _, a = spec_of(inp)
    _, b = spec_of(tmp_path / "out.jpg")
    assert b.dtype == np.uint8 and b.shape == a.shape
    assert np.abs(a.astype(int) - b.astype(int)).mean() < 2.0  # a second JPEG encoding


def test_channel_names_are_kept(tmp_path):
    px = pattern(16, 16, 5, np.float32)
    names = ("R", "G", "B", "A", "Z")
    inp = write(tmp_path / "in.exr", px, names)
    tri = write_polygon(tmp_path / "t.json", [[1, 1], [15, 2], [3, 15]])
    assert main([inp, str(tmp_path / "out.exr"), "--src", tri, "--dst", tri]) == 0
    spec, _ = spec_of(tmp_path / "out.exr")
    assert spec.channelnames == names and spec.alpha_channel == 3


def test_icc_profile_and_resolution_are_kept(tmp_path):
    px = pattern(16, 20, 3, np.uint16)
    icc = np.arange(16, dtype=np.uint8)
    attrs = [("ICCProfile", "uint8[16]", icc), ("XResolution", "float", 300.0), ("YResolution", "float", 300.0)]
    inp = write(tmp_path / "in.tif", px, attrs=attrs)  # TIFF stores both
    tri = write_polygon(tmp_path / "t.json", [[1, 1], [19, 2], [3, 15]])
    assert main([inp, str(tmp_path / "out.tif"), "--src", tri, "--dst", tri]) == 0
    spec, _ = spec_of(tmp_path / "out.tif")
    assert np.array_equal(np.asarray(spec.getattribute("ICCProfile")), icc)
    assert spec.getattribute("XResolution") == pytest.approx(300.0)


def test_descriptive_metadata_is_kept(tmp_path):
    # (No OpenImageIO writer here can store a thumbnail, so the dropping of
    # thumbnail_* attributes is not exercised end to end.)
    px = pattern(16, 20, 3, np.float32)
    inp = write(tmp_path / "in.exr", px, attrs=[("ImageDescription", "string", "kept")])
    tri = write_polygon(tmp_path / "t.json", [[1, 1], [19, 2], [3, 15]])
    assert main([inp, str(tmp_path / "out.exr"), "--src", tri, "--dst", tri]) == 0
    spec, _ = spec_of(tmp_path / "out.exr")
    assert spec.getattribute("ImageDescription") == "kept"


def test_orientation_is_applied_on_reading_and_not_written(tmp_path):
    px = np.zeros((20, 30, 3), dtype=np.uint8)
    px[:5, :10] = 255  # a white block at the top-left of the stored pixels
    inp = write(tmp_path / "in.tif", px, attrs=[("Orientation", "int", 6)])  # display: rotate 90 cw
    img = read_image(inp)
    assert img.pixels.shape == (30, 20, 3)  # as displayed
    assert img.pixels[:10, -5:].min() == 255  # the block is now top-right
    assert "Orientation" not in [a[0] for a in img.attributes]
    full = write_polygon(tmp_path / "full.json", [[0, 0], [20, 0], [20, 30], [0, 30]])
    assert main([inp, str(tmp_path / "out.tif"), "--src", full, "--dst", full, "--interp", "nearest"]) == 0
    spec, back = spec_of(tmp_path / "out.tif")
    assert spec.get_int_attribute("Orientation", 1) == 1
    np.testing.assert_array_equal(back, img.pixels)


@pytest.mark.parametrize("dtype", ["uint8", "uint16", "half", "float"])
def test_dtype_option_converts_keeping_meaning(tmp_path, dtype):
    px = np.full((8, 8, 3), 255, dtype=np.uint8)
    px[:, :4] = 0
    inp = write(tmp_path / "in.tif", px)
    full = write_polygon(tmp_path / "full.json", [[0, 0], [8, 0], [8, 8], [0, 8]])
    out = tmp_path / ("out.exr" if dtype == "half" else "out.tif")  # TIFF has no half
    assert main([inp, str(out), "--src", full, "--dst", full, "--interp", "nearest", "--dtype", dtype]) == 0
    _, back = spec_of(out)
    assert back.dtype == {"uint8": np.uint8, "uint16": np.uint16, "half": np.float16, "float": np.float32}[dtype]
    white = 1.0 if dtype in ("half", "float") else np.iinfo(back.dtype).max
    assert back[0, 7, 0] == white and back[0, 0, 0] == 0


def test_convert_pixels_round_trips_integers():
    x = np.arange(256, dtype=np.uint8)
    assert np.array_equal(convert_pixels(convert_pixels(x, "uint16"), "uint8"), x)
    assert np.array_equal(convert_pixels(convert_pixels(x, "float"), "uint8"), x)


def test_straight_alpha_png_blends_premultiplied_and_keeps_8_bit_colour(tmp_path):
    # Opaque red | half-transparent red | transparent green: blending between the
    # first two stays pure red (premultiplied), and green never bleeds in.
    px = np.array([[[255, 0, 0, 255], [255, 0, 0, 128], [0, 255, 0, 0]]] * 4, dtype=np.uint8)
    inp = write(tmp_path / "in.png", px, names=("R", "G", "B", "A"))
    src = write_polygon(tmp_path / "s.json", [[0, 0], [3, 0], [3, 4], [0, 4]])
    dst = write_polygon(tmp_path / "d.json", [[0, 0], [6, 0], [6, 4], [0, 4]])  # stretch x2
    assert main([inp, str(tmp_path / "out.png"), "--src", src, "--dst", dst, "--size", "6x4"]) == 0
    out = read_image(tmp_path / "out.png").pixels  # as stored: straight colour
    row = out[1]
    opaque = row[:, 3] > 0
    assert (row[opaque, 0] == 255).all() and (row[opaque, 1] == 0).all()  # no green fringe
    assert row[0, 3] == 255 and 128 <= row[2, 3] <= 255
    # Nearest keeps every stored value, even the colour of transparent pixels.
    same = write_polygon(tmp_path / "same.json", [[0, 0], [3, 0], [3, 4], [0, 4]])
    assert main([inp, str(tmp_path / "id.png"), "--src", same, "--dst", same, "--interp", "nearest"]) == 0
    np.testing.assert_array_equal(read_image(tmp_path / "id.png").pixels, px)


def test_straight_alpha_written_to_openexr_is_premultiplied(tmp_path):
    # OpenEXR colour is premultiplied by definition; PNG's is straight.
    px = np.array([[[200, 100, 50, 128]] * 4] * 4, dtype=np.uint8)
    inp = write(tmp_path / "in.png", px, names=("R", "G", "B", "A"))
    sq = write_polygon(tmp_path / "sq.json", [[0, 0], [4, 0], [4, 4], [0, 4]])
    out = tmp_path / "out.exr"
    assert main([inp, str(out), "--src", sq, "--dst", sq, "--interp", "nearest", "--dtype", "float"]) == 0
    _, back = spec_of(out)
    a = 128 / 255
    np.testing.assert_allclose(back[1, 1], [200 / 255 * a, 100 / 255 * a, 50 / 255 * a, a], rtol=1e-6)
    # And back to PNG: straight colour again (within the one level lost by
    # quantizing premultiplied colour to 8 bits before dividing by alpha).
    assert main([str(out), str(tmp_path / "again.png"), "--src", sq, "--dst", sq, "--interp", "nearest", "--dtype", "uint8"]) == 0
    back_png = read_image(tmp_path / "again.png").pixels[1, 1].astype(int)
    assert np.abs(back_png - [200, 100, 50, 128]).max() <= 1
