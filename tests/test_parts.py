"""Images read and written part by part (`warpcli.raster.parts`): every value read, the same bytes written."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

import warpcli.raster.parts as parts
from warpcli.raster.imageio import OIIO_TYPES, ImageHeader, read_header
from warpcli.raster.parts import PartReader, StripWriter

from .helpers import read_pixels


def _random_image(dtype, rng, h: int, w: int, c: int):
    """Values over the whole range of ``dtype``: 32-bit integers beyond float32's exact ones (2^24)."""
    dtype = np.dtype(dtype)
    if dtype.kind == "f":
        return (rng.normal(0.0, 1e6, (h, w, c)) * rng.random((h, w, c))).astype(dtype)
    info = np.iinfo(dtype)
    return rng.integers(info.min, info.max, (h, w, c), dtype=np.int64, endpoint=True).astype(dtype)


def _write(path, px, tile: int | None = None) -> str:
    """``px`` written to ``path`` in its own pixel type, in tiles of ``tile`` pixels or in scanlines."""
    import OpenImageIO as oiio

    h, w, c = px.shape
    spec = oiio.ImageSpec(w, h, c, OIIO_TYPES[px.dtype])
    if tile is not None:
        spec.tile_width = spec.tile_height = tile
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec), out.geterror()
    assert out.write_image(px), out.geterror()
    out.close()
    return str(path)


def _rectangles(rng, w: int, h: int, n: int):
    """``n`` rectangles in no order, most crossing band boundaries, and the whole image and one pixel."""
    boxes = [(0, 0, w, h), (w - 1, h - 1, w, h)]
    for _ in range(n):
        x0, y0 = int(rng.integers(0, w)), int(rng.integers(0, h))
        x1, y1 = int(rng.integers(x0 + 1, w + 1)), int(rng.integers(y0 + 1, h + 1))
        boxes.append((x0, y0, x1, y1))
    return [boxes[k] for k in rng.permutation(len(boxes))]


@pytest.mark.parametrize(
    "ext, tile, dtype",
    [
        ("tif", None, np.uint32), ("tif", None, np.int32), ("tif", None, np.float64),
        ("tif", 16, np.uint32), ("tif", 32, np.int32),
        ("exr", None, np.uint32), ("exr", 16, np.uint32),
        ("tif", 16, np.uint16), ("exr", None, np.float32),  # read through OpenImageIO's cache, exact
    ],
)  # fmt: skip
@pytest.mark.parametrize("seed", range(3))
def test_every_value_of_a_part_is_the_files(tmp_path, monkeypatch, ext, tile, dtype, seed):
    # OpenImageIO's ImageCache holds 32-bit integers and doubles as float32 (ids
    # near 2^32 were off by up to 129). Bands of 16 rows (of 20 in one case, not a
    # multiple of the file's tiles), and a budget of a few bands: rectangles cross
    # bands, come back to bands evicted, and go backwards in the file.
    rng = np.random.default_rng(seed)
    monkeypatch.setattr(parts, "TILE", 16 if seed != 1 else 20)
    h, w, c = int(rng.integers(40, 90)), int(rng.integers(30, 70)), int(rng.integers(1, 4))
    monkeypatch.setattr(parts, "CACHE_MB", 3 * 16 * w * c * np.dtype(dtype).itemsize / 2**20)
    px = _random_image(dtype, rng, h, w, c)
    path = _write(tmp_path / f"in.{ext}", px, tile)
    whole = read_pixels(path)
    assert whole.dtype == px.dtype and np.array_equal(whole, px)
    with PartReader(path, read_header(path)) as reader:
        for x0, y0, x1, y1 in _rectangles(rng, w, h, 25):
            part = reader.read(x0, y0, x1, y1)
            assert part.dtype == px.dtype and part.shape == (y1 - y0, x1 - x0, c)
            np.testing.assert_array_equal(part, px[y0:y1, x0:x1], err_msg=f"part {(x0, y0, x1, y1)}")


@pytest.mark.parametrize("height", [65, 66, 97, 1000])
def test_every_row_of_a_tiff_of_doubles_is_read_exactly(tmp_path, monkeypatch, height):
    # OpenImageIO's TIFF reader reads 64-bit samples right only in whole strips of
    # more than one row (one row at a time, it takes them for packed bits): bands
    # are whole strips (of 32 rows here), a last band of one row (65, 97) read
    # with the strip before it.
    monkeypatch.setattr(parts, "TILE", 20)
    px = _random_image(np.float64, np.random.default_rng(height), height, 40, 1)
    path = _write(tmp_path / "in.tif", px)
    with PartReader(path, read_header(path)) as reader:
        for y in reversed(range(height)):
            np.testing.assert_array_equal(reader.read(3, y, 40, y + 1), px[y : y + 1, 3:], err_msg=f"row {y}")


@pytest.mark.parametrize("tile", [None, 16])
def test_the_chunks_of_a_strip_decode_each_block_once_within_the_budget(tmp_path, monkeypatch, tile):
    # A strip read as chunks of columns, each reaching the same rows, then the
    # image from top to bottom: each block (a band of rows, or of whole tiles)
    # is decoded once, and what is kept stays within a budget of 6 bands.
    monkeypatch.setattr(parts, "TILE", 16)
    h, w = 200, 96
    budget = 6 * 32 * w * 8  # the file's strips are of 32 rows
    monkeypatch.setattr(parts, "CACHE_MB", budget / 2**20)
    px = _random_image(np.uint32, np.random.default_rng(4), h, w, 2)
    path = _write(tmp_path / "in.tif", px, tile)
    with PartReader(path, read_header(path)) as reader:
        blocks = reader._blocks
        decoded = []
        real = blocks._decode
        monkeypatch.setattr(blocks, "_decode", lambda key: decoded.append(key) or real(key))
        for x0 in range(0, w, 24):
            np.testing.assert_array_equal(reader.read(x0, 30, x0 + 24, 90), px[30:90, x0 : x0 + 24])
        for y0 in range(0, h, 40):
            np.testing.assert_array_equal(reader.read(0, y0, w, y0 + 40), px[y0 : y0 + 40])
            assert blocks._kept <= budget
    assert len(decoded) == len(set(decoded)) == -(-h // blocks._rows) * -(-w // blocks._cols)


def test_a_damaged_file_read_exactly_is_one_line_naming_it(tmp_path):
    from warpcli.errors import ImageInputError

    px = _random_image(np.uint32, np.random.default_rng(2), 300, 40, 1)
    path = _write(tmp_path / "ids.tif", px)
    header = read_header(path)
    with open(path, "rb") as fh:
        data = fh.read()
    with open(path, "wb") as fh:
        fh.write(data[: len(data) // 2])
    with PartReader(path, header) as reader:
        with pytest.raises(ImageInputError) as err:
            reader.read(0, 250, 40, 300)
    message = str(err.value)
    assert message.startswith(f"{path}: cannot read image") and "\n" not in message


@pytest.fixture
def threads():
    """OpenImageIO's thread count, restored after the test."""
    import OpenImageIO as oiio

    saved = oiio.get_int_attribute("threads")
    yield lambda n: oiio.attribute("threads", n)
    oiio.attribute("threads", saved)


@pytest.mark.parametrize(
    "ext, dtype, channels",
    [("tif", np.uint8, 4), ("tif", np.uint16, 3), ("tif", np.float32, 1), ("exr", np.float16, 4), ("exr", np.uint32, 1),
     ("png", np.uint8, 3)],
)  # fmt: skip
def test_strips_write_the_same_bytes_whatever_openimageio_threads(tmp_path, monkeypatch, threads, ext, dtype, channels):
    # With 3 or more threads OpenImageIO's TIFF writer compressed a strip's tiles in
    # parallel, with its own zlib call (other bytes than libtiff's), and left
    # the padding of the partial tiles at the right and bottom edges as it found
    # the memory: the file changed with the thread count and from run to run.
    monkeypatch.setattr(parts, "TILE", 16)
    h, w = 53, 75  # partial tiles along both edges
    rng = np.random.default_rng(9)
    px = (rng.random((h, w, channels)) * (200 if dtype == np.uint8 else 60000)).astype(dtype)
    px[:, :, 0] += np.arange(w, dtype=dtype)[None, :] // 4  # something zlib compresses
    header = ImageHeader(w, h, channels, np.dtype(dtype))
    hashes = {}
    for n in (1, 2, 4, 8, 4, 8):
        threads(n)
        filler = [np.full((1 << 18,), k, np.uint8) for k in range(1, 40)]  # memory left dirty to reuse
        del filler
        path = str(tmp_path / f"out_{n}.{ext}")
        writer = StripWriter(path, path, w, h, header)
        for y in range(0, h, 16):
            writer.write(px[y : y + 16])
        writer.close()
        np.testing.assert_array_equal(read_pixels(path), px)
        with open(path, "rb") as fh:
            hashes.setdefault(hashlib.sha256(fh.read()).hexdigest(), []).append(n)
    assert len(hashes) == 1, f"bytes by thread count: {list(hashes.values())}"


@pytest.mark.parametrize("dtype", [np.uint32, np.float64, np.uint8])
def test_parts_are_read_beyond_openimageios_image_size_limit(tmp_path, dtype):
    # Strips exist for images larger than OpenImageIO's limit on a whole decoded image; the exact
    # blocks opened their file within it, so an 800 x 600 uint32 TIFF under a 1 MB limit was refused.
    import OpenImageIO as oiio

    px = _random_image(dtype, np.random.default_rng(4), 600, 800, 1)
    path = _write(tmp_path / "big.tif", px)
    header = read_header(path)
    saved = oiio.get_int_attribute("limits:imagesize_MB", 0)
    oiio.attribute("limits:imagesize_MB", 1)
    try:
        with PartReader(path, header) as reader:
            got = reader.read(0, 0, 800, 600)
    finally:
        oiio.attribute("limits:imagesize_MB", saved)
    assert got.dtype == px.dtype
    np.testing.assert_array_equal(got, px)
