"""Images read and written part by part, for images larger than memory (`warpcli.tiled`).

`PartReader` reads any rectangle of an image through OpenImageIO's
ImageCache: tiles (or, for files stored in scanlines, strips of 256 rows)
decoded on demand and kept up to a memory budget, so reading a part costs
memory in proportion to the part, not to the image. The cache holds 32-bit
integers and doubles as float32: those are read from blocks of their own
(`_ExactBlocks`), kept to the same budget. `StripWriter` writes an
image strip after strip, tiled where the format stores tiles (TIFF, OpenEXR),
in scanlines otherwise, under a temporary name renamed into place when the
last strip is written and the file reads back whole (`warpcli.outputs.atomic_path`).

Both keep what `warpcli.raster.imageio` keeps: the file's own pixel type,
channel names, alpha and its convention, and metadata.
"""

from __future__ import annotations

import errno
import os
import threading
from collections import OrderedDict

import numpy as np
from numpy.typing import NDArray

from ..capture import c_stderr, one_line
from ..errors import ImageInputError, ImageIOError
from ..outputs import check_room, file_size_limit, write_failure_message
from .imageio import OIIO_TYPES, ImageHeader, open_input, output_spec, size_limit_lifted, verify_written
from .pixels import premultiplied

#: Rows of a strip, and the side of a tile in tiled outputs.
TILE = 256
#: Memory OpenImageIO's cache (or `_ExactBlocks`) may keep of decoded input tiles, in megabytes.
CACHE_MB = 512.0
#: Pixel types OpenImageIO's ImageCache holds as they are. It holds the others (32-bit
#: integers, doubles) as float32: ids near 2^32 came back off by up to 129.
CACHED_TYPES = frozenset(np.dtype(t) for t in (np.uint8, np.int8, np.uint16, np.int16, np.float16, np.float32))


class PartReader:
    """Rectangles of one image file, decoded on demand through a private ImageCache.

    Pixel types the cache does not hold exactly (`CACHED_TYPES`) are read from
    blocks decoded by an ImageInput instead (`_ExactBlocks`).

    Parameters
    ----------
    path : path-like
    header : ImageHeader
        Its `warpcli.raster.imageio.read_header`.

    Raises
    ------
    ImageInputError
        If the file can no longer be opened (read exactly).
    """

    def __init__(self, path: str | os.PathLike[str], header: ImageHeader) -> None:
        import OpenImageIO as oiio

        self.name = os.fspath(path)
        self.header = header
        self._oiio = oiio
        self._cache = self._blocks = None
        if header.dtype not in CACHED_TYPES:
            self._blocks = _ExactBlocks(self.name, header)
            return
        self._cache = oiio.ImageCache(False)  # private: its memory is freed with it
        self._cache.attribute("max_memory_MB", CACHE_MB)
        self._cache.attribute("autotile", TILE)  # scanline files in strips, not whole
        self._cache.attribute("unassociatedalpha", 1)
        self._type = oiio.TypeDesc(OIIO_TYPES[header.dtype])

    def read(self, x0: int, y0: int, x1: int, y1: int) -> NDArray:
        """Pixels of columns ``x0 <= x < x1`` and rows ``y0 <= y < y1``: (rows, columns, C).

        Raises
        ------
        ImageInputError
            If the file cannot be decoded there (cut short, damaged).
        """
        if self._blocks is not None:
            return self._blocks.read(x0, y0, x1, y1)
        with c_stderr() as said:
            px = self._cache.get_pixels(self.name, 0, 0, x0, x1, y0, y1, 0, 1, self._type)
        problem = self._cache.geterror()
        if px is None or problem:
            raise ImageInputError(f"{self.name}: cannot read image: {one_line(problem, said.text)}")
        px = np.asarray(px)
        if px.ndim == 2:
            px = px[:, :, None]
        return px.reshape(y1 - y0, x1 - x0, self.header.channels)

    def close(self) -> None:
        if self._cache is not None:
            self._cache.invalidate(self.name)
            self._cache = None
        if self._blocks is not None:
            self._blocks.close()
            self._blocks = None

    def __enter__(self) -> PartReader:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class _ExactBlocks:
    """Rectangles of an image file in its own pixel type, from blocks an ImageInput decodes whole.

    A file in scanlines is read in bands of `TILE` full rows (``read_scanlines``
    gives whole rows; fewer rows where four bands would pass the budget); a tiled
    file in blocks of whole tiles of about `TILE` x `TILE` pixels (``read_tiles``:
    ``read_scanlines`` refuses tiled files). Blocks are kept, the least recently used
    dropped beyond `CACHE_MB`, so that the chunks of one strip, which reach the same
    rows, decode them once, and memory stays bounded however large the image.
    """

    def __init__(self, name: str, header: ImageHeader) -> None:
        import OpenImageIO as oiio

        self.name, self.header = name, header
        self._oiio = oiio
        # Opened as `read_image` opens a file (straight colour, as the ImageCache reads it too),
        # without OpenImageIO's image-size limit: only parts are decoded, and strips exist for
        # images larger than it (opened within the limit, an 800 x 600 uint32 TIFF under a 1 MB
        # limit was refused).
        with size_limit_lifted():
            inp, _ = open_input(name)
        self._inp = inp
        spec = inp.spec()
        self._origin = (spec.x, spec.y, spec.z)  # the data window's, which read_image starts at
        self._type = oiio.TypeDesc(OIIO_TYPES[header.dtype])
        self._budget = int(CACHE_MB * 2**20)
        self._tiled = spec.tile_width > 0
        self._whole_chunks, self._chunk = False, 1
        if self._tiled:
            tw, th = spec.tile_width, spec.tile_height
            self._rows, self._cols = th * -(-TILE // th), tw * -(-TILE // tw)
        else:
            row = header.width * header.channels * header.dtype.itemsize
            rows = max(1, min(TILE, self._budget // (4 * row)))
            chunk = max(1, spec.get_int_attribute("oiio:RowsPerChunk", 1))  # a TIFF's strip, an EXR's block
            # Bands of whole chunks, each decoded once. And OpenImageIO's TIFF reader reads
            # 64-bit samples right only in whole strips of more than a row: elsewhere it
            # takes them for packed bits (TIFFInput::bit_convert), whatever the budget.
            self._whole_chunks = inp.format_name() == "tiff" and header.dtype.itemsize == 8
            if self._whole_chunks or 4 * chunk * row <= self._budget:
                rows = chunk * -(-rows // chunk)
            self._rows, self._cols, self._chunk = rows, header.width, chunk
        self._kept_blocks: OrderedDict[tuple[int, int], NDArray] = OrderedDict()
        self._kept = 0  # bytes
        self._lock = threading.Lock()  # the ImageCache it stands for may be read from any thread

    def read(self, x0: int, y0: int, x1: int, y1: int) -> NDArray:
        out = np.empty((y1 - y0, x1 - x0, self.header.channels), dtype=self.header.dtype)
        rows, cols = self._rows, self._cols
        with self._lock:
            for by in range(y0 // rows, (y1 - 1) // rows + 1):
                for bx in range(x0 // cols, (x1 - 1) // cols + 1):
                    block = self._block((by, bx))
                    top, left = by * rows, bx * cols
                    a, b = max(y0, top), min(y1, top + block.shape[0])
                    c, d = max(x0, left), min(x1, left + block.shape[1])
                    out[a - y0 : b - y0, c - x0 : d - x0] = block[a - top : b - top, c - left : d - left]
        return out

    def _block(self, key: tuple[int, int]) -> NDArray:
        """Block ``key`` (band, column block), decoded unless kept; blocks beyond the budget dropped,
        least recently used first (copied from already: a read crossing more blocks than the budget
        holds decodes each once)."""
        kept = self._kept_blocks
        if key in kept:
            kept.move_to_end(key)
            return kept[key]
        block = self._decode(key)
        kept[key] = block
        self._kept += block.nbytes
        while self._kept > self._budget and len(kept) > 1:
            self._kept -= kept.popitem(last=False)[1].nbytes
        return block

    def _decode(self, key: tuple[int, int]) -> NDArray:
        by, bx = key
        h, w, nc = self.header.height, self.header.width, self.header.channels
        top, bottom = by * self._rows, min(h, (by + 1) * self._rows)
        left, right = bx * self._cols, min(w, (bx + 1) * self._cols)
        x, y, z = self._origin
        # A last band of one row is read with the strip before it (see `_whole_chunks`).
        first = top - self._chunk if self._whole_chunks and bottom - top == 1 and top > 0 else top
        with c_stderr() as said:
            if self._tiled:
                px = self._inp.read_tiles(0, 0, x + left, x + right, y + top, y + bottom, z, z + 1, 0, nc, self._type)
            else:
                px = self._inp.read_scanlines(0, 0, y + first, y + bottom, z, 0, nc, self._type)
        problem = self._inp.geterror()
        if px is None or problem:
            why = one_line(problem, self._oiio.geterror(), said.text)
            raise ImageInputError(f"{self.name}: cannot read image: {why}")
        px = np.asarray(px).reshape(bottom - first, right - left, nc)
        return px if first == top else px[top - first :].copy()

    def close(self) -> None:
        with c_stderr():
            self._inp.close()
        self._inp.geterror()  # nothing left pending to be printed later
        self._kept_blocks.clear()
        self._kept = 0


#: Formats whose files cannot be written strip by strip, by name for messages: libjpeg
#: ends the process when a write fails and the room for the whole file cannot be
#: checked first; libwebp's writer never returns from a failed write (a full
#: disk); OpenImageIO's JPEG 2000 writer leaves an empty file when given strips.
NOT_IN_PARTS = {"jpeg": "JPEG", "webp": "WebP", "jpeg2000": "JPEG 2000"}


def check_writable_in_parts(fmt: str, shown_name: str) -> None:
    """Refuse a format that cannot be written strip by strip (`NOT_IN_PARTS`).

    Raises
    ------
    ImageInputError
        ``"OUT: JPEG cannot be written in parts; write TIFF, OpenEXR or PNG"``.
    """
    if fmt in NOT_IN_PARTS:
        raise ImageInputError(f"{shown_name}: {NOT_IN_PARTS[fmt]} cannot be written in parts; write TIFF, OpenEXR or PNG")


#: Formats written without compression, whose files hold at least a byte per
#: sample (when no "compression" attribute asks otherwise): a file smaller than
#: that was cut short, although their writers report no error (a full disk, a
#: file size limit: BMP, SGI and FITS writers ignore failed writes).
UNCOMPRESSED = ("bmp", "cineon", "dpx", "fits", "pnm", "sgi", "targa")


def _uncompressed(spec) -> bool:
    return spec.get_string_attribute("compression", "none").lower() in ("", "none")


def _first_hole(filename: str, size: int) -> int | None:
    """The offset of the first hole (bytes never written) in a file, or None (or where unknown)."""
    if not hasattr(os, "SEEK_HOLE"):
        return None
    fd = os.open(filename, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
    try:
        at = os.lseek(fd, 0, os.SEEK_HOLE)
    except OSError:
        return None
    finally:
        os.close(fd)
    return at if at < size else None


def _nearly_full(filename: str) -> bool:
    try:
        vfs = os.statvfs(os.path.dirname(os.path.abspath(filename)))
    except OSError:
        return False
    return vfs.f_bavail * vfs.f_frsize < 2 * max(vfs.f_bsize, 4096)


class StripWriter:
    """An image file written strip after strip, top to bottom.

    Open it on the temporary path of `warpcli.outputs.atomic_path`; `write` each strip of
    `TILE` rows (the last may be shorter), then `close`, which checks that the
    file reads back with its size. Every write is checked: a full disk is an
    `ImageIOError` naming ``shown_name``.

    Parameters
    ----------
    filename : str
        Where to write (the format comes from the extension).
    shown_name : str
        The name given in messages (the user's path).
    width, height : int
    header : ImageHeader
        Pixel type, channels, alpha and metadata of the output.
    """

    def __init__(self, filename: str, shown_name: str, width: int, height: int, header: ImageHeader) -> None:
        import OpenImageIO as oiio

        self._oiio = oiio
        self.filename, self.shown_name = filename, shown_name
        out = oiio.ImageOutput.create(filename)
        if out is None:
            raise ImageIOError(f"{shown_name}: cannot write: {one_line(oiio.geterror())}")
        self._out = out
        self.format = out.format_name()
        check_writable_in_parts(self.format, shown_name)
        spec, self._premultiply = output_spec(
            oiio, self.format, (width, height, header.channels), OIIO_TYPES[header.dtype], header.channel_names,
            header.alpha_channel, header.associated_alpha, header.attributes,
        )  # fmt: skip
        if self.format in UNCOMPRESSED and _uncompressed(spec):
            # Their writers ignore failed writes, and FITS's seeks over what it could
            # not write (a sparse file of the full size): room for them is checked first.
            least = width * height * header.channels
            check_room(filename, shown_name, least, f"a {self.format.upper()} of {width} x {height} takes at least {least} bytes")
        # Not a TIFF of doubles: OpenImageIO misreads tiled ones (`warpcli.raster.imageio`
        # refuses them as input), so they are written in strips of rows.
        self.tiled = bool(out.supports("tiles")) and not (self.format == "tiff" and header.dtype.itemsize == 8)
        if self.tiled:
            spec.tile_width = spec.tile_height = TILE
        if self.format == "tiff":
            # With 3 or more threads, OpenImageIO's TIFF writer compresses a strip's tiles
            # in parallel (8 and 16 bits, zip): with a zlib call of its own, giving other
            # bytes than libtiff's, and partial tiles padded with memory as it was found,
            # so that the file changed with the thread count and from run to run. Off,
            # every thread count writes the bytes 1 and 2 threads wrote.
            spec.attribute("tiff:multithread", 0)
        self._spec = spec
        self._next = 0
        with c_stderr() as said:
            ok = bool(out.open(filename, spec))
        if not ok:
            self._fail(one_line(out.geterror(), oiio.geterror(), said.text))

    def write(self, pixels: NDArray) -> None:
        """Write the next strip, (rows, width, C) in the header's pixel type."""
        rows = pixels.shape[0]
        y0, y1 = self._next, self._next + rows
        if y1 > self._spec.height or (rows != TILE and y1 != self._spec.height):
            raise ValueError(f"strip of rows {y0}-{y1} does not fit a {self._spec.height}-row image in strips of {TILE}")
        px = pixels if self._premultiply is None else premultiplied(pixels, self._premultiply)
        px = np.ascontiguousarray(px)
        with c_stderr() as said:
            if self.tiled:
                ok = self._out.write_tiles(0, self._spec.width, y0, y1, 0, 1, px)
            else:
                ok = self._out.write_scanlines(y0, y1, 0, px)
        # Some writers (PNG) report a failed write (a full disk, a file size limit) as an error
        # of the file but go on returning success: without this, every strip to the end of an
        # image of any size was still computed and compressed before close() said so.
        if not ok or self._out.has_error:
            self._fail(one_line(self._out.geterror(), said.text))
        self._next = y1

    def _fail(self, text: str) -> None:
        # The temporary name replaced by the output's, and the OS's likely
        # reason (a full disk, a file size limit) added where the library gave none.
        raise ImageIOError(write_failure_message(self.shown_name, text, self.filename, self.filename, True))

    def close(self) -> None:
        """Finish the file and check that it reads back whole."""
        if self._next != self._spec.height:
            raise ValueError(f"{self._next} of {self._spec.height} rows written")
        with c_stderr() as said:
            ok = bool(self._out.close())
        problem = one_line(self._out.geterror(), said.text, default="")
        if not ok:
            self._fail(problem or "unknown error")
        spec = self._spec
        if self.format in UNCOMPRESSED and _uncompressed(spec):
            least = spec.width * spec.height * spec.nchannels
            try:
                actual = os.stat(self.filename).st_size
                hole = _first_hole(self.filename, actual)
            except OSError as err:
                raise ImageIOError(f"{self.shown_name}: cannot write: {err.strerror or err}") from err
            if actual < least:
                limit = file_size_limit()
                why = f"{os.strerror(errno.EFBIG)}: " if limit is not None and least > limit else ""
                self._fail(f"{why}the {self.format.upper()} file is cut short at {actual} bytes (at least {least} expected)")
            if hole is not None and _nearly_full(self.filename):
                # A hole the writer seeked over on a full disk (a file system that
                # compresses may also store zeros as holes: only a full disk counts).
                self._fail(f"{os.strerror(errno.ENOSPC)}: the {self.format.upper()} file has unwritten bytes from {hole}")
        # The read-back opens the header only; OpenImageIO's size limit must not refuse it.
        with size_limit_lifted():
            verify_written(self._oiio, self.filename, self.format, spec, None, self.shown_name, problem)

    def abandon(self) -> None:
        """Give up the file (its temporary path is removed by `warpcli.outputs.atomic_path`)."""
        with c_stderr():
            self._out.close()
        self._out.geterror()
