"""Image I/O through OpenImageIO: formats, bit depths, channels, metadata, --dtype."""

from __future__ import annotations

import types

import numpy as np
import OpenImageIO as oiio
import pytest

from helpers import write_polygon
from warpcli.cli import main
from warpcli.raster.imageio import (
    PNG_DEFAULT_SRGB,
    PNG_SRGB_NAMES,
    RasterImage,
    convert_pixels,
    output_spec,
    read_image,
    ready_to_write,
    write_image,
    written_attributes,
)

#: OpenImageIO's own names (`TypeDesc`), typed here from its documentation: 32-bit integers are
#: "uint" and "int" ("uint32" is no name of OpenImageIO's: TypeDesc("uint32") is UNKNOWN).
TYPES = {
    np.dtype(np.uint8): "uint8", np.dtype(np.int8): "int8", np.dtype(np.uint16): "uint16", np.dtype(np.int16): "int16",
    np.dtype(np.uint32): "uint", np.dtype(np.int32): "int", np.dtype(np.float16): "half", np.dtype(np.float32): "float",
    np.dtype(np.float64): "double",
}  # fmt: skip


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
    # every integer width and sign TIFF stores, and OpenEXR's 32-bit unsigned channels (ids, labels)
    ("tif", np.int8, 1), ("tif", np.int16, 2), ("tif", np.uint32, 1), ("tif", np.int32, 3), ("tif", np.float64, 1),
    ("exr", np.uint32, 1), ("exr", np.uint32, 4),
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


@pytest.mark.parametrize("ext", ["tif", "exr"])
@pytest.mark.parametrize("tiled", [False, True])
def test_32_bit_ids_keep_their_type_and_every_value(tmp_path, ext, tiled):
    # Ids beyond float32's exact integers (2^24), through the whole image and through strips:
    # an identity warp with nearest gives every id back, in a 32-bit file.
    h, w = 40, 56
    px = (np.arange(h * w, dtype=np.uint64).reshape(h, w, 1) * 2_654_435_761 % 2**32).astype(np.uint32)
    inp = write(tmp_path / f"in.{ext}", px)
    full = write_polygon(tmp_path / "full.json", [[0, 0], [w, 0], [w, h], [0, h]])
    out = tmp_path / f"out.{ext}"
    args = [inp, str(out), "--src", full, "--dst", full, "--interp", "nearest"] + (["--tiled"] if tiled else [])
    assert main(args) == 0
    spec_out, back = spec_of(out)
    assert str(spec_out.format) == "uint"
    np.testing.assert_array_equal(back, px)


@pytest.mark.parametrize("kind", ["Plain Texture", "Shadow", "LatLong Environment"])
@pytest.mark.parametrize("tex_ext", ["exr", "tif"])
@pytest.mark.parametrize("out_ext", ["exr", "tif", "png"])
def test_a_texture_warps_to_a_plain_image_every_format_reads_back(tmp_path, kind, tex_ext, out_ext):
    # A mip-mapped, tiled texture (maketx, oiiotool -otex) carries "textureformat", "wrapmodes" and
    # "fovcot": carried onto a scanline OpenEXR, "textureformat" made a file OpenImageIO could not read.
    buf = oiio.ImageBuf(oiio.ImageSpec(64, 32, 1 if kind == "Shadow" else 3, "half"))
    oiio.ImageBufAlgo.checker(buf, 8, 8, 1, (0.1, 0.2, 0.3), (0.9, 0.8, 0.7))
    config = oiio.ImageSpec()
    config.attribute("wrapmodes", "periodic,clamp")
    how = {"Plain Texture": oiio.MakeTxTexture, "Shadow": oiio.MakeTxShadow, "LatLong Environment": oiio.MakeTxEnvLatl}[kind]
    tex = str(tmp_path / f"tex.{tex_ext}")
    assert oiio.ImageBufAlgo.make_texture(how, buf, tex, config), oiio.geterror()
    spec_in, px_in = spec_of(tex)
    assert spec_in.get_string_attribute("textureformat") == kind
    full = write_polygon(tmp_path / "full.json", [[0, 0], [64, 0], [64, 32], [0, 32]])
    out = tmp_path / f"out.{out_ext}"
    assert main([tex, str(out), "--src", full, "--dst", full, "--interp", "nearest"]) == 0
    spec_out, px_out = spec_of(out)  # every pixel decodes
    assert not any(spec_out.getattribute(name) for name in ("textureformat", "wrapmodes", "fovcot"))
    if out_ext != "png":
        np.testing.assert_array_equal(px_out, px_in)


def _multi(path, kind):
    """A file of two subimages (an OpenEXR of two parts, a TIFF of two pages), or a deep OpenEXR."""
    if kind == "deep":
        spec = oiio.ImageSpec(16, 8, 2, "float")
        spec.channelnames, spec.deep = ("R", "Z"), True
        buf = oiio.ImageBuf(spec)
        for y in range(8):
            for x in range(16):
                buf.set_deep_samples(x, y, 0, 1)
                buf.set_deep_value(x, y, 0, 0, 0, 0.5)
                buf.set_deep_value(x, y, 0, 1, 0, 1.0)
        assert buf.write(str(path)), buf.geterror()
        return str(path)
    if kind == "window":  # an autocropped render: 16 x 8 of data at (3, 2) in a 24 x 12 display window
        spec = oiio.ImageSpec(16, 8, 3, "half")
        spec.x, spec.y, spec.full_x, spec.full_y, spec.full_width, spec.full_height = 3, 2, 0, 0, 24, 12
        out = oiio.ImageOutput.create(str(path))
        assert out.open(str(path), spec), out.geterror()
        out.write_image(np.zeros((8, 16, 3), np.float16))
        out.close()
        return str(path)
    specs = [oiio.ImageSpec(16, 8, 3, "half"), oiio.ImageSpec(16, 8, 1, "half")]
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), specs), out.geterror()
    out.write_image(np.zeros((8, 16, 3), np.float16))
    out.open(str(path), specs[1], "AppendSubimage")
    out.write_image(np.ones((8, 16, 1), np.float16))
    out.close()
    return str(path)


@pytest.mark.parametrize(
    "kind, ext", [("parts", "exr"), ("parts", "tif"), ("deep", "exr"), ("window", "exr"), ("one", "exr"), ("one", "tif")]
)
@pytest.mark.parametrize("tiled", [False, True])
def test_what_a_warp_leaves_out_of_a_file_is_said_once(tmp_path, capfd, kind, ext, tiled):
    # Parts and pages after the first, and deep samples, do not reach the output: a warning says so,
    # once, whether the image is read whole or in strips; a file of one flat image gets none.
    inp = _multi(tmp_path / f"in.{ext}", kind) if kind != "one" else write(tmp_path / f"in.{ext}", pattern(8, 16, 3, np.float16))
    full = write_polygon(tmp_path / "full.json", [[0, 0], [16, 0], [16, 8], [0, 8]])
    assert main([inp, str(tmp_path / "out.exr"), "--src", full, "--dst", full] + (["--tiled"] if tiled else [])) == 0
    said = [line for line in capfd.readouterr().err.splitlines() if inp in line]
    expected = {
        "parts": "only its first subimage", "deep": "deep samples are flattened",
        "window": "data window (16 x 8 at (3, 2)) is not its display window (24 x 12 at (0, 0))",
    }.get(kind)  # fmt: skip
    assert len(said) == (1 if expected else 0), said
    assert expected is None or expected in said[0]


def test_a_tiled_tiff_of_doubles_is_refused_not_misread(tmp_path):
    # OpenImageIO 3.2 decodes a tiled TIFF's 64-bit samples as packed bits: garbage, and no error.
    px = pattern(40, 56, 1, np.float64)
    full = write_polygon(tmp_path / "full.json", [[0, 0], [56, 0], [56, 40], [0, 40]])
    for tiled in (False, True):
        spec = oiio.ImageSpec(56, 40, 1, "double")
        if tiled:
            spec.tile_width = spec.tile_height = 16
        path = str(tmp_path / f"in{int(tiled)}.tif")
        out = oiio.ImageOutput.create(path)
        assert out.open(path, spec) and out.write_image(px)
        out.close()
        for strips in ([], ["--tiled"]):
            target = tmp_path / f"out{int(tiled)}{len(strips)}.tif"
            code = main([path, str(target), "--src", full, "--dst", full, "--interp", "nearest", *strips])
            if tiled:
                assert code == 2 and not target.exists()
            else:
                assert code == 0
                np.testing.assert_array_equal(spec_of(target)[1], px)
    with pytest.raises(ImageInputError, match=r"in1.tif: a tiled TIFF of 64-bit floats, which OpenImageIO .* misreads"):
        read_image(str(tmp_path / "in1.tif"))


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


# --- Determinism, checked writes, hostile inputs -------------------------------------------

import math  # noqa: E402
import os  # noqa: E402
import re  # noqa: E402
import socket  # noqa: E402
import stat  # noqa: E402
import struct  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
import zlib  # noqa: E402

from warpcli import budget  # noqa: E402
from warpcli.budget import MAX_IMAGE_BYTES_ENV, max_image_bytes  # noqa: E402
from warpcli.errors import ImageInputError, ImageIOError  # noqa: E402
from warpcli.outputs import atomic_path, check_output_path  # noqa: E402
from warpcli.raster.imageio import check_image_output  # noqa: E402
from warpcli.raster.stmap import save_stmap  # noqa: E402

# Every format and pixel type warpcli writes, as (extension, dtype, channels).
WRITE_CASES = [
    ("png", np.uint8, 3), ("png", np.uint16, 4), ("jpg", np.uint8, 3), ("tif", np.uint8, 3),
    ("tif", np.uint16, 2), ("tif", np.float32, 4), ("exr", np.float16, 3), ("exr", np.float32, 4),
]  # fmt: skip
WRITE_IDS = [f"{e}-{np.dtype(d).name}-{c}ch" for e, d, c in WRITE_CASES]


def stmap_points(h, w):
    rng = np.random.default_rng(5)
    pts = rng.random((h, w, 2)) * [w, h]
    pts[0, 0] = np.nan
    return pts


def test_every_format_is_byte_identical_run_after_run(tmp_path):
    # OpenImageIO's TIFF and OpenEXR writers stamp the time of writing (to the
    # second) unless told a DateTime: two writes a second apart must not differ.
    images = {f"{e}-{np.dtype(d).name}.{e}": RasterImage(pattern(20, 24, c, d)) for e, d, c in WRITE_CASES}

    def write_all(directory):
        directory.mkdir()
        for name, image in images.items():
            write_image(directory / name, image)
        for ext in ("exr", "tif"):
            save_stmap(directory / f"map.{ext}", stmap_points(20, 24), (24, 20))
        return sorted(p.name for p in directory.iterdir())

    first = write_all(tmp_path / "a")
    # Into the next second of the clock, not a whole second more (0.6 s on average): every
    # file of the second run is written in a later second than every file of the first.
    time.sleep(math.floor(time.time()) + 1.02 - time.time())
    assert write_all(tmp_path / "b") == first and len(first) == len(WRITE_CASES) + 2
    for name in first:
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
        spec, _ = spec_of(tmp_path / "a" / name)
        stamped = [a.name for a in spec.extra_attribs if a.name in ("DateTime", "Software", "HostComputer")]
        assert stamped == [], (name, stamped)


@pytest.mark.parametrize("ext", ["tif", "exr", "jpg", "png"])
def test_an_input_datetime_is_kept_as_it_was(tmp_path, ext):
    image = RasterImage(pattern(8, 8, 3, np.uint8), attributes=(("DateTime", "string", "2001:02:03 04:05:06"),))
    write_image(tmp_path / f"a.{ext}", image)
    back = read_image(tmp_path / f"a.{ext}")
    if ext in ("tif", "exr"):  # the formats that store it (OpenImageIO's PNG and JPEG writers do not)
        assert ("DateTime", "string", "2001:02:03 04:05:06") in back.attributes


def test_an_unwritable_pixel_type_leaves_nothing(tmp_path):
    with pytest.raises(ImageIOError, match="unsupported pixel type complex64"):
        write_image(tmp_path / "out.tif", RasterImage(np.zeros((4, 4, 1), dtype=np.complex64)))
    assert list(tmp_path.iterdir()) == []


def make_special(tmp_path, kind):
    """A path to something that is not a regular file."""
    if kind == "fifo":
        os.mkfifo(tmp_path / "in.png")  # no writer: open() would block forever
        return str(tmp_path / "in.png")
    if kind == "socket":
        sock = socket.socket(socket.AF_UNIX)
        sock.bind(str(tmp_path / "in.png"))
        return str(tmp_path / "in.png")
    if kind == "symlink-to-zero":
        os.symlink("/dev/zero", tmp_path / "in.png")
        return str(tmp_path / "in.png")
    if kind == "directory":
        (tmp_path / "in.png").mkdir()
        return str(tmp_path / "in.png")
    return kind  # a device


SPECIALS = {
    "fifo": "FIFO", "socket": "socket", "/dev/zero": "character device", "/dev/null": "character device",
    "/dev/urandom": "character device", "symlink-to-zero": "character device", "directory": "directory",
}  # fmt: skip


@pytest.mark.parametrize("kind", list(SPECIALS))
def test_anything_but_a_regular_file_is_refused_at_once(tmp_path, kind):
    path = make_special(tmp_path, kind)
    if not os.path.exists(path) and not stat.S_ISSOCK(os.lstat(path).st_mode):
        pytest.skip(f"{path} does not exist here")
    result = {}

    def read():
        try:
            read_image(path)
        except ImageInputError as err:
            result["error"] = err

    reader = threading.Thread(target=read, daemon=True)  # a hang must fail the test, not stall it
    reader.start()
    reader.join(timeout=20)
    assert not reader.is_alive(), f"read_image({path!r}) blocked"
    msg = str(result["error"])
    assert msg.startswith(f"{path}: cannot read image: it is ") and SPECIALS[kind] in msg and "\n" not in msg


def test_an_output_that_is_not_a_regular_file_is_never_replaced(tmp_path):
    os.mkfifo(tmp_path / "out.png")
    os.mkfifo(tmp_path / "report.json")
    with pytest.raises(ImageInputError, match="is a FIFO .*an output must be a regular file"):
        check_image_output(tmp_path / "out.png")
    with pytest.raises(ImageInputError, match="is a FIFO"):
        check_output_path(tmp_path / "report.json")
    with pytest.raises(ImageInputError, match="is a FIFO"):
        write_image(tmp_path / "out.png", RasterImage(pattern(4, 4, 3, np.uint8)))
    with pytest.raises(ImageInputError, match="is a FIFO"):
        with atomic_path(str(tmp_path / "report.json")):
            pass
    assert all(stat.S_ISFIFO(os.lstat(p).st_mode) for p in tmp_path.iterdir())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.png", "report.json"]


def png_of_zeros(path, w, h, rows=100):
    """A valid w x h 8-bit grey PNG of zeros, built in a few milliseconds and
    kilobytes: one deflate block of `rows` rows, repeated (each ends with a full
    flush, so it does not refer back), and the Adler-32 of h * (w + 1) zeros."""
    assert h % rows == 0

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    block = bytes((w + 1) * rows)  # each row: filter type 0, then w zeros
    co = zlib.compressobj(9)
    first = co.compress(block) + co.flush(zlib.Z_FULL_FLUSH)
    again = co.compress(block) + co.flush(zlib.Z_FULL_FLUSH)
    end = co.flush()[:-4]  # the final block, without the checksum of two blocks
    adler = ((len(block) * (h // rows)) % 65521) << 16 | 1  # a = 1, b = n for n zeros
    data = first + again * (h // rows - 1) + end + struct.pack(">I", adler)
    ihdr = struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)
    with open(path, "wb") as fh:
        fh.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", data) + chunk(b"IEND", b""))
    return str(path)


def test_the_generated_png_of_zeros_is_valid(tmp_path):
    img = read_image(png_of_zeros(tmp_path / "z.png", 300, 200, rows=20))
    assert img.pixels.shape == (200, 300, 1) and img.pixels.dtype == np.uint8 and not img.pixels.any()


def test_an_image_too_large_for_memory_is_refused_from_its_header(tmp_path, monkeypatch):
    # 30000 x 30000 decodes to 858 MiB from 0.9 MB of PNG: refused before any pixel is decoded.
    big = png_of_zeros(tmp_path / "big.png", 30000, 30000)
    assert os.path.getsize(big) < 2_000_000
    monkeypatch.setenv(MAX_IMAGE_BYTES_ENV, str(100 * 2**20))
    with pytest.raises(ImageInputError) as info:
        read_image(big)
    assert str(info.value) == (
        f"{big}: a 30000 x 30000 image of 1 channel(s) x 1 byte needs 858 MiB of memory, "
        f"more than the 100 MiB warpcli may use ({MAX_IMAGE_BYTES_ENV})"
    )


@pytest.mark.parametrize("ext,dtype,channels", WRITE_CASES, ids=WRITE_IDS)
def test_the_memory_limit_counts_every_byte(tmp_path, monkeypatch, ext, dtype, channels):
    # The limit is exact: the image's own size is allowed, one byte less is not.
    path = tmp_path / f"in.{ext}"
    write_image(path, RasterImage(pattern(12, 10, channels, dtype)))
    stored = 12 * 10 * (3 if ext == "jpg" else channels) * np.dtype(dtype).itemsize
    monkeypatch.setenv(MAX_IMAGE_BYTES_ENV, str(stored))
    assert read_image(path).pixels.nbytes == stored
    monkeypatch.setenv(MAX_IMAGE_BYTES_ENV, str(stored - 1))
    with pytest.raises(ImageInputError, match=rf"^{re.escape(str(path))}: a 10 x 12 image of .* needs {stored} bytes"):
        read_image(path)


def test_an_oriented_image_counts_twice(tmp_path, monkeypatch):
    inp = write(tmp_path / "in.tif", pattern(10, 12, 3, np.uint8), attrs=[("Orientation", "int", 6)])
    monkeypatch.setenv(MAX_IMAGE_BYTES_ENV, str(2 * 360 - 1))  # read, then reoriented
    with pytest.raises(ImageInputError, match="2 copies, to apply the orientation"):
        read_image(inp)
    monkeypatch.setenv(MAX_IMAGE_BYTES_ENV, str(2 * 360))
    assert read_image(inp).pixels.shape == (12, 10, 3)


def test_the_default_limit_is_a_share_of_the_available_memory(tmp_path, monkeypatch):
    monkeypatch.delenv(MAX_IMAGE_BYTES_ENV, raising=False)
    monkeypatch.setattr(budget, "_available_memory", lambda: 40_000)
    assert max_image_bytes() == int(40_000 * budget.MEMORY_FRACTION)
    small = write(tmp_path / "small.png", pattern(64, 64, 3, np.uint8))  # 12 KiB
    large = write(tmp_path / "large.png", pattern(128, 128, 3, np.uint8))  # 48 KiB
    assert read_image(small).pixels.shape == (64, 64, 3)
    with pytest.raises(ImageInputError, match=f"of the available memory; set {MAX_IMAGE_BYTES_ENV}"):
        read_image(large)
    monkeypatch.setattr(budget, "_available_memory", lambda: None)  # unknown: no limit
    assert max_image_bytes() > 2**60


@pytest.mark.parametrize("ext,dtype,channels", WRITE_CASES, ids=WRITE_IDS)
@pytest.mark.parametrize("keep", [0.0, 0.01, 0.3, 0.6, 0.95])
def test_a_truncated_image_fails_on_one_line_and_prints_nothing_else(tmp_path, capfd, ext, dtype, channels, keep):
    # libpng prints "libpng error: ..." on file descriptor 2 itself: captured
    # and folded into warpcli's message, never shown.
    whole = tmp_path / f"whole.{ext}"
    write_image(whole, RasterImage(pattern(48, 64, channels, dtype)))
    data = whole.read_bytes()
    cut = tmp_path / f"cut.{ext}"
    cut.write_bytes(data[: int(len(data) * keep)])
    capfd.readouterr()
    with pytest.raises(ImageInputError) as info:
        read_image(cut)
    msg = str(info.value)
    assert msg.startswith(f"{cut}: cannot read image: ") and "\n" not in msg
    assert capfd.readouterr() == ("", "")


def test_image_io_reaches_neither_maps_nor_options():
    """raster knows nothing of how maps are made, not even through options (which lists the methods)."""
    import json
    import subprocess
    import sys

    script = "import json, sys, warpcli.raster.imageio; print(json.dumps(sorted(sys.modules)))"
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    loaded = [m for m in json.loads(done.stdout) if m.startswith(("warpcli.maps", "warpcli.options", "warpcli.pipeline"))]
    assert loaded == []


SRGB_PNG_CASES = [
    (name, dtype, c, associated) for name in PNG_SRGB_NAMES for dtype in (np.uint8, np.uint16) for c in (1, 2, 3, 4)
    for associated in ((False, True) if c in (2, 4) else (False,))
]  # fmt: skip


@pytest.mark.skipif(oiio.VERSION < PNG_DEFAULT_SRGB, reason="OpenImageIO before 3.2 is given the colour space as it is")
@pytest.mark.parametrize(
    "name,dtype,channels,associated", SRGB_PNG_CASES,
    ids=[f"{n}-{np.dtype(d).name}-{c}ch{'-premultiplied' if a else ''}" for n, d, c, a in SRGB_PNG_CASES],
)  # fmt: skip
def test_an_srgb_png_is_the_file_openimageio_writes_told_its_colour_space(tmp_path, name, dtype, channels, associated):
    # The writer is not told an sRGB colour space (which costs it a load of the colour
    # configuration): its file must be, byte for byte, the one it writes when told.
    px = pattern(13, 17, channels, dtype)
    names = {1: ("Y",), 2: ("Y", "A"), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}[channels]
    alpha = channels - 1 if channels in (2, 4) else None
    attrs = (("oiio:ColorSpace", "string", name), ("ImageDescription", "string", "kept"), ("XResolution", "float", 72.0))
    image = RasterImage(px, names, alpha, attrs, associated_alpha=associated)
    ours = tmp_path / "ours.png"
    write_image(ours, image)
    spec, premultiply = output_spec(oiio, "png", (17, 13, channels), TYPES[px.dtype], names, alpha, associated, attrs)
    assert spec.get_string_attribute("oiio:ColorSpace") == ""
    assert spec.get_string_attribute("ImageDescription") == "kept"  # the rest is kept
    spec.attribute("oiio:ColorSpace", name)  # what the writer was given before
    told = tmp_path / "told.png"
    out = oiio.ImageOutput.create(str(told))
    assert premultiply is None  # PNG stores straight colour: the pixels go as they are
    assert out.open(str(told), spec) and out.write_image(np.ascontiguousarray(px)) and out.close()
    assert ours.read_bytes() == told.read_bytes()


@pytest.mark.parametrize("fmt", ["png", "tiff", "openexr", "jpeg"])
@pytest.mark.parametrize("name", ["lin_rec709_scene", "g22_rec709_scene", *PNG_SRGB_NAMES])
@pytest.mark.parametrize("version", [30000, 30105, PNG_DEFAULT_SRGB, 30300])
def test_only_a_png_from_openimageio_3_2_leaves_srgb_to_the_writers_default(fmt, name, version):
    module = types.SimpleNamespace(VERSION=version)
    attrs = (("oiio:ColorSpace", "string", name), ("ImageDescription", "string", "kept"))
    left = fmt == "png" and name in PNG_SRGB_NAMES and version >= PNG_DEFAULT_SRGB
    assert written_attributes(module, fmt, attrs) == (attrs[1:] if left else attrs)


@pytest.mark.parametrize("name", ["lin_rec709_scene", "g22_rec709_scene"])
def test_a_png_of_another_colour_space_is_written_with_it(tmp_path, name):
    px = pattern(8, 8, 3, np.uint8)
    write_image(tmp_path / "out.png", RasterImage(px, ("R", "G", "B"), None, (("oiio:ColorSpace", "string", name),)))
    assert spec_of(tmp_path / "out.png")[0].get_string_attribute("oiio:ColorSpace") == name


@pytest.mark.parametrize("ext,loads", [("png", oiio.VERSION < PNG_DEFAULT_SRGB), ("tif", True), ("jpg", True)])
def test_the_colour_configuration_is_loaded_ahead_only_for_a_writer_that_will_load_it(tmp_path, monkeypatch, ext, loads):
    calls = []
    real = oiio.ColorConfig.default_colorconfig
    monkeypatch.setattr(oiio.ColorConfig, "default_colorconfig", lambda: calls.append(1) or real())
    px = pattern(8, 8, 3, np.uint8)
    ready_to_write(RasterImage(px, ("R", "G", "B"), None, (("oiio:ColorSpace", "string", "srgb_rec709_scene"),)), tmp_path / f"o.{ext}")
    assert bool(calls) == loads
    calls.clear()
    ready_to_write(RasterImage(px, ("R", "G", "B"), None, ()), tmp_path / f"o.{ext}")  # no colour space: nothing to load
    assert not calls
