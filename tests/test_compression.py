"""--compression: the zlib level of PNG outputs (issue 24), read back from the files' own zlib headers.

A zlib stream's second byte holds FLEVEL (RFC 1950, 2.2), which zlib sets from the
level it was given: 0 for levels 0-1, 1 for 2-5, 2 for 6, 3 for 7-9. So the level a
file was written at is checked in the file, not through warpcli; and the pixels
decoded from every level are the same.
"""

from __future__ import annotations

import struct

import numpy as np
import pytest

from helpers import read_pixels, run_cli, star, write_png, write_polygon
from warpcli.errors import InputError
from warpcli.options import PNG_COMPRESSION, WarpOptions


def flevel(path) -> int:
    """FLEVEL of the zlib stream in a PNG's first IDAT chunk."""
    data = open(path, "rb").read()
    pos = 8  # the PNG signature
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        if data[pos + 4 : pos + 8] == b"IDAT":
            cmf, flg = data[pos + 8], data[pos + 9]
            assert cmf & 0x0F == 8 and (cmf * 256 + flg) % 31 == 0  # deflate, a valid header
            return flg >> 6
        pos += 12 + length
    raise AssertionError(f"{path}: no IDAT")


def zlib_flevel(level: int) -> int:
    return 0 if level < 2 else 1 if level < 6 else 2 if level == 6 else 3


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("compression")
    rng = np.random.default_rng(5)
    y, x = np.mgrid[0:96, 0:112]
    px = np.stack([x * 2, y * 2, (x + y) % 256], axis=2).astype(np.uint8) + rng.integers(0, 8, (96, 112, 3), dtype=np.uint8)
    src = write_polygon(d / "src.json", star(6, 56, 48, 18, 44))
    dst = write_polygon(d / "dst.json", star(6, 56, 48, 14, 44, phase=0.3))
    return d, write_png(d / "in.png", px), src, dst


def test_default_level_is_written_and_levels_keep_the_pixels(files):
    d, image, src, dst = files
    outs = {}
    for level in (None, 0, 6, 9):
        out = d / f"out_{level}.png"
        extra = [] if level is None else ["--compression", level]
        code, err = run_cli([image, "--src", src, "--dst", dst, out, "-q", *extra])
        assert code == 0, err
        assert flevel(out) == zlib_flevel(PNG_COMPRESSION if level is None else level)
        outs[level] = out
    ref = read_pixels(outs[None])
    for level, out in outs.items():
        assert np.array_equal(read_pixels(out), ref), level
    # Level 0 stores the rows: the file is the largest; 9 is at most 6's size.
    sizes = {level: out.stat().st_size for level, out in outs.items()}
    assert sizes[0] == max(sizes.values()) and sizes[9] <= sizes[6]


def test_strips_and_apply_map_take_the_level(files):
    d, image, src, dst = files
    tiled, whole = d / "tiled.png", d / "whole.png"
    assert run_cli([image, "--src", src, "--dst", dst, tiled, "--tiled", "--compression", 9, "-q"])[0] == 0
    assert run_cli([image, "--src", src, "--dst", dst, whole, "--save-map", d / "map.exr", "-q"])[0] == 0
    assert flevel(tiled) == 3 and np.array_equal(read_pixels(tiled), read_pixels(whole))
    applied = d / "applied.png"
    assert run_cli(["apply-map", d / "map.exr", image, applied, "--compression", 0, "-q"])[0] == 0
    assert flevel(applied) == 0


@pytest.mark.parametrize("bad", [-1, 10, 2.5, True, "1"])
def test_levels_outside_0_to_9_are_refused(bad):
    with pytest.raises(InputError, match="compression"):
        WarpOptions(compression=bad)


def test_cli_refuses_a_bad_level(files):
    d, image, src, dst = files
    code, err = run_cli([image, "--src", src, "--dst", dst, d / "never.png", "--compression", 10])
    assert code == 2 and "--compression" in err and not (d / "never.png").exists()
