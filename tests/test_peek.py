"""A PNG's size from its first bytes (`warpcli.raster.peek`), against OpenImageIO's reading of the same files."""

from __future__ import annotations

import os
import struct
import zlib

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from warpcli.errors import ImageInputError
from warpcli.raster.imageio import read_header
from warpcli.raster.peek import PNG_SIGNATURE, parse_png_header, png_size

from .helpers import write_png


def _oiio_size(path):
    """(width, height, channels) as OpenImageIO reads the file's header, or None if it refuses it."""
    try:
        h = read_header(path)
    except ImageInputError:
        return None
    return h.width, h.height, h.channels


def _ihdr(width, height, depth=8, colour=2, compression=0, filtering=0, interlace=0, crc=None):
    body = b"IHDR" + struct.pack(">IIBBBBB", width, height, depth, colour, compression, filtering, interlace)
    return struct.pack(">I", 13) + body + struct.pack(">I", zlib.crc32(body) if crc is None else crc)


@settings(max_examples=15, deadline=None)
@given(
    w=st.integers(1, 40), h=st.integers(1, 40), channels=st.sampled_from([1, 2, 3, 4]),
    dtype=st.sampled_from([np.uint8, np.uint16]),
)
def test_the_size_of_a_png_is_the_one_openimageio_reads(tmp_path_factory, w, h, channels, dtype):
    path = tmp_path_factory.mktemp("peek") / "a.png"
    px = np.random.default_rng(w * h).integers(0, 200, (h, w, channels)).astype(dtype)
    write_png(path, px)
    assert png_size(path) == _oiio_size(path) == (w, h, channels)


@settings(max_examples=25, deadline=None)
@given(data=st.data())
def test_a_damaged_or_hostile_header_gives_no_size_or_the_one_openimageio_reads(tmp_path_factory, data):
    """Cut short, bytes changed, sizes out of range, CRCs that do not match: never an exception, and a
    size only where OpenImageIO reads the same one (or refuses the file: the caller then drops the guess)."""
    path = tmp_path_factory.mktemp("peek") / "b.png"
    write_png(path, np.zeros((9, 13, 3), dtype=np.uint8))
    good = bytearray(path.read_bytes())
    kind = data.draw(st.sampled_from(["cut", "flip", "ihdr"]))
    if kind == "cut":
        bad = bytes(good[: data.draw(st.integers(0, len(good) - 1))])
    elif kind == "flip":
        bad = bytearray(good)
        for _ in range(data.draw(st.integers(1, 3))):
            at = data.draw(st.integers(0, 40))
            bad[at] = data.draw(st.integers(0, 255))
        bad = bytes(bad)
    else:  # a well-formed chunk stating any size, depth and colour type, its CRC right or not
        side = st.one_of(st.integers(0, 3), st.integers(2**20 - 2, 2**20 + 2), st.sampled_from([2**31 - 1, 2**31, 2**32 - 1]), st.integers(1, 64))
        head = _ihdr(
            data.draw(side), data.draw(side), data.draw(st.sampled_from([1, 2, 4, 8, 16, 3, 0])),
            data.draw(st.sampled_from([0, 2, 3, 4, 6, 1, 7])), data.draw(st.sampled_from([0, 0, 1])),
            0, data.draw(st.sampled_from([0, 1, 2])), crc=data.draw(st.sampled_from([None, None, 0])),
        )  # fmt: skip
        bad = PNG_SIGNATURE + head + bytes(good[33:])
    path.write_bytes(bad)
    found = png_size(path)
    assert found == parse_png_header(bad[:33])
    if found is not None:
        theirs = _oiio_size(path)
        assert theirs is None or theirs[:2] == found[:2]


def test_what_is_not_a_png_file_gives_no_size(tmp_path):
    jpeg = tmp_path / "a.png"  # a JPEG named .png
    import OpenImageIO as oiio

    buf = oiio.ImageBuf(oiio.ImageSpec(8, 8, 3, "uint8"))
    assert buf.write(str(tmp_path / "a.jpg"))
    os.replace(tmp_path / "a.jpg", jpeg)
    assert png_size(jpeg) is None
    assert png_size(tmp_path / "missing.png") is None
    assert png_size(tmp_path) is None  # a directory
    fifo = tmp_path / "f.png"
    os.mkfifo(fifo)
    assert png_size(fifo) is None  # not opened for reading: no writer would ever come


def test_limits_and_doctest_values():
    assert parse_png_header(PNG_SIGNATURE + _ihdr(640, 480)) == (640, 480, 3)
    assert parse_png_header(PNG_SIGNATURE + _ihdr(1_000_000, 1, 16, 0)) == (1_000_000, 1, 1)
    assert parse_png_header(PNG_SIGNATURE + _ihdr(1_000_001, 1)) is None
    assert parse_png_header(PNG_SIGNATURE + _ihdr(0, 5)) is None
    assert parse_png_header(PNG_SIGNATURE + _ihdr(5, 5, 16, 3)) is None  # no 16-bit palette
    assert parse_png_header(PNG_SIGNATURE + _ihdr(5, 5, crc=1)) is None
    assert parse_png_header((PNG_SIGNATURE + _ihdr(5, 5))[:32]) is None


@settings(max_examples=10, deadline=None)
@given(
    side=st.sampled_from([(70, 60), (3000, 3000), (4000, 2500), (70000, 70000), (1_000_001, 2)]),
    rest=st.sampled_from(["none", "junk", "idat-cut"]), crc=st.sampled_from([None, 0]),
)
def test_a_hostile_png_header_is_one_line_exit_2_and_leaves_nothing(tmp_path_factory, side, rest, crc):
    """A PNG stating a size its data does not hold (the map may be started from it before OpenImageIO
    reads the header): the run still ends in one line naming the file, exit 2, and no output."""
    from .helpers import run_cli, star, write_polygon

    tmp = tmp_path_factory.mktemp("hostile")
    path = tmp / "in.png"
    write_png(path, np.zeros((60, 70, 3), dtype=np.uint8))
    good = path.read_bytes()
    tail = {"none": b"", "junk": bytes(range(256)) * 4, "idat-cut": good[33 : len(good) // 2]}[rest]
    path.write_bytes(PNG_SIGNATURE + _ihdr(*side, crc=crc) + tail)
    a = write_polygon(tmp / "a.json", star(6, 35, 30, 12, 27))
    b = write_polygon(tmp / "b.json", star(6, 35, 30, 9, 28, 0.3))
    code, err = run_cli([path, tmp / "out.png", "--src", a, "--dst", b, "-q"])
    assert code == 2 and err.startswith(f"warp: error: {path}") and len(err.strip().splitlines()) == 1, err
    assert sorted(p.name for p in tmp.iterdir()) == ["a.json", "b.json", "in.png"]
