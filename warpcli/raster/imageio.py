"""Image I/O: OpenImageIO read/write keeping pixel type, channels and metadata."""

from __future__ import annotations

import contextlib
import functools
import logging
import os
import re
import threading
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..budget import check_fits
from ..capture import c_stderr, one_line
from ..errors import ImageInputError, ImageIOError
from ..files import check_regular_file, format_bytes
from ..outputs import (
    RunInputs, atomic_path, check_output_path, check_room, copy_from_memory, final_path, memory_file, write_failure_message,
)
from .dtypes import DTYPES, PNG_COMPRESSION
from .pixels import from_unit, premultiplied, to_unit

#: numpy dtype -> OpenImageIO type name, for the pixel types warpcli reads and writes.
OIIO_TYPES = {
    np.dtype(np.uint8): "uint8",
    np.dtype(np.int8): "int8",
    np.dtype(np.uint16): "uint16",
    np.dtype(np.int16): "int16",
    np.dtype(np.uint32): "uint",
    np.dtype(np.int32): "int",
    np.dtype(np.float16): "half",
    np.dtype(np.float32): "float",
    np.dtype(np.float64): "double",
}

# Attributes that describe the file rather than the picture, that OpenImageIO
# manages itself, or that no longer hold for a warped image (a thumbnail of the
# input; the orientation, which is applied on reading; a texture's layout, which
# the warped image, one level and not tiled, does not have: "textureformat" on a
# scanline OpenEXR made a file OpenImageIO could not read back): not carried over.
_DROP_PREFIXES = (
    "oiio:", "png:", "jpeg:", "tiff:", "openexr:", "Exif:PixelXDimension", "Exif:PixelYDimension",
    "thumbnail", "Orientation", "textureformat", "wrapmodes", "fovcot",
)  # fmt: skip
_KEEP = ("oiio:ColorSpace",)

_log = logging.getLogger("warpcli")


@dataclass(frozen=True)
class RasterImage:
    """Pixels with the channel names and metadata of the file they came from.

    Attributes
    ----------
    pixels : (H, W, C) ndarray
        In the file's own pixel type (uint8, uint16, float16, float32, ...).
    channel_names : tuple of str
    alpha_channel : int or None
    attributes : tuple of (name, type name, value)
        Metadata to carry over to a derived image.
    associated_alpha : bool
        Whether colour is premultiplied by alpha (OpenEXR; TIFF marked so), or
        straight as the file stores it (PNG, most TIFF): warpcli reads what
        the file stores, premultiplies only to blend, and writes it back alike.
    """

    pixels: NDArray
    channel_names: tuple[str, ...] = ()
    alpha_channel: int | None = None
    attributes: tuple = field(default=(), repr=False)
    associated_alpha: bool = True

    def __post_init__(self) -> None:
        if self.pixels.ndim != 3:
            raise ValueError(f"pixels must be (H, W, C), got shape {self.pixels.shape}")
        if self.channel_names and len(self.channel_names) != self.pixels.shape[2]:
            raise ValueError(
                f"{len(self.channel_names)} channel names for {self.pixels.shape[2]} channels"
            )

    @property
    def width(self) -> int:
        return self.pixels.shape[1]

    @property
    def height(self) -> int:
        return self.pixels.shape[0]


def read_image(path: str | os.PathLike[str]) -> RasterImage:
    """Read an image file in its own pixel type.

    Only regular files are opened (a FIFO or a device is refused at once, as it
    could block or never end), and the image's size is checked against memory
    (`warpcli.budget.check_fits`) from its header, before any pixel is decoded. What the C
    libraries print (libpng's "libpng error: ...") is kept off stderr and
    folded into the error message.

    Parameters
    ----------
    path : path-like
        Any format OpenImageIO reads. The EXIF orientation is applied, so the
        pixels are the image as displayed. The first subimage is read, at its
        full resolution (with a warning if there are more, or deep data).

    Returns
    -------
    RasterImage
        Pixels (H, W, C) in the file's type, channel names, alpha, metadata.

    Raises
    ------
    ImageInputError
        If the file is missing, is not a regular file, is not an image
        OpenImageIO can read (or is cut short), or is too large for memory.
    """
    import OpenImageIO as oiio

    name = os.fspath(path)
    inp, config = open_input(name)
    try:
        spec = inp.spec()
        oriented = spec.get_int_attribute("Orientation", 1) != 1
        _check_spec_fits(spec, name, copies=2 if oriented else 1)
        with c_stderr() as said:
            pixels = inp.read_image(oiio.UNKNOWN)
        problem = inp.geterror()
        if pixels is None:
            raise ImageInputError(f"{name}: cannot read image: {one_line(problem, oiio.geterror(), said.text)}")
        if problem:
            # Pixels came back, with a complaint: libjpeg fills a truncated
            # file with grey and says "Premature end of JPEG file".
            if _TRUNCATED.search(problem):
                raise ImageInputError(f"{name}: cannot read image: {one_line(problem, said.text)}")
            _log.debug("%s: %s", name, one_line(problem, said.text))
        _say_what_is_left(inp, spec, name)
    finally:
        with c_stderr():
            inp.close()
        inp.geterror()  # nothing left pending to be printed later
    pixels = np.asarray(pixels)
    if oriented:
        # Polygons are drawn on the image as displayed (labelme, for one,
        # applies the orientation), so apply it and write the result upright.
        with c_stderr() as said:
            buf = oiio.ImageBufAlgo.reorient(oiio.ImageBuf(name, 0, 0, config))
            oriented_px = None if buf.has_error else buf.get_pixels(oiio.TypeDesc(OIIO_TYPES.get(pixels.dtype, "float")))
        if oriented_px is None:
            raise ImageInputError(f"{name}: cannot read image: {one_line(buf.geterror(), oiio.geterror(), said.text)}")
        pixels = np.asarray(oriented_px)
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    attrs, alpha, associated = _file_metadata(spec)
    return RasterImage(np.ascontiguousarray(pixels), tuple(spec.channelnames), alpha, attrs, associated)


def ready_to_write(image: RasterImage, path: str | os.PathLike[str]) -> None:
    """Do now the set-up OpenImageIO would do when ``image`` is opened for writing at ``path``:
    for a caller that has a moment to spare (a warp waiting for its map).

    A writer given an ``oiio:ColorSpace`` (every JPEG and TIFF read carries one, and
    every PNG that `output_spec` does not leave to the writer's sRGB) loads OpenImageIO's
    colour configuration when the file is opened, the first time in a process:
    about 20 ms, during which OpenImageIO holds the GIL. In a warp that was the start
    of the encoder, when the rows it encodes were being resampled on another thread:
    that thread stood still too (measured at 1 MP, 20 ms of a 60 ms write). Done here,
    it happens while nothing else waits for it. The configuration is OpenImageIO's own
    and the same whoever loads it: the files written are the same bytes.
    """
    import OpenImageIO as oiio

    if not any(attr[0] == "oiio:ColorSpace" for attr in written_attributes(oiio, output_format(path), image.attributes)):
        return
    with contextlib.suppress(Exception):  # only ever a head start: the writer loads it anyway
        oiio.ColorConfig.default_colorconfig().getNumColorSpaces()


def output_format(path: str | os.PathLike[str]) -> str:
    """The format OpenImageIO writes for ``path``'s extension ("" if none)."""
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(os.fspath(path))
    oiio.geterror()
    return "" if out is None else out.format_name()


#: OpenImageIO's names of sRGB, as its readers give them (PNG, JPEG: ``srgb_rec709_scene``).
#: From OpenImageIO 3.2 (`PNG_DEFAULT_SRGB`), a PNG writer told one of them writes the sRGB
#: chunks it writes for an image told no colour space, the same bytes (``tests/test_imageio.py``
#: writes both and compares them), but it first loads OpenImageIO's colour configuration to
#: find that out: 24 ms of CPU in every process that writes a PNG (measured, 3.2.2), a
#: sixteenth of a 1 MP warp.
PNG_SRGB_NAMES = ("srgb_rec709_scene", "sRGB")

#: The first OpenImageIO whose PNG writer takes sRGB for an image told no colour space without
#: loading the colour configuration (3.0 writes no sRGB chunks for one; 3.1 writes them but
#: loads the configuration all the same): before it, every attribute is given as it is.
PNG_DEFAULT_SRGB = 30200


def written_attributes(oiio, fmt: str, attributes: tuple) -> tuple:
    """``attributes`` as a writer of format ``fmt`` is given them: with OpenImageIO 3.2 or
    later (``oiio``, the module), a PNG's sRGB colour space is left for the writer's default,
    which is the same (`PNG_SRGB_NAMES`)."""
    if fmt != "png" or int(getattr(oiio, "VERSION", 0)) < PNG_DEFAULT_SRGB:
        return tuple(attributes)
    return tuple(a for a in attributes if not (a[0] == "oiio:ColorSpace" and a[2] in PNG_SRGB_NAMES))


def _file_metadata(spec) -> tuple[tuple, int | None, bool]:
    """What a derived image keeps of a file's header: its metadata (less what describes the
    file), its alpha channel, and whether its colour is premultiplied by alpha."""
    attrs = tuple(
        (a.name, str(a.type), a.value)
        for a in spec.extra_attribs
        if a.name in _KEEP or not a.name.startswith(_DROP_PREFIXES)
    )
    alpha = spec.alpha_channel if spec.alpha_channel >= 0 else None
    return attrs, alpha, spec.get_int_attribute("oiio:UnassociatedAlpha", 0) != 1


def _check_spec_fits(spec, name: str, copies: int = 1) -> None:
    """Refuse, from its header, an image whose pixels (``copies`` of them) would not fit in memory."""
    sizes = [spec.format.size(), *(f.size() for f in spec.channelformats)]
    check_fits(
        spec.width, spec.height * max(spec.depth, 1), spec.nchannels, max(sizes), name, copies=copies,
        why="to apply the orientation",
    )  # fmt: skip


def open_input(name: str):
    """An OpenImageIO ImageInput on the regular file ``name``, and the configuration it was opened with
    (straight colour where the file stores it so). For a reader that decodes only parts (a header,
    `warpcli.raster.parts`), open it within `size_limit_lifted`.

    Raises
    ------
    ImageInputError
        If the file is missing, not a regular file, or not an image OpenImageIO reads.
    """
    import OpenImageIO as oiio

    # Only regular files: opening a FIFO blocks until a writer comes, /dev/zero never ends.
    check_regular_file(name, "image", ImageInputError)
    # Ask for straight colour where the file stores it so (PNG): OpenImageIO
    # would otherwise premultiply it in 8 bits, losing the colour of
    # transparent pixels and precision at low alpha.
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    with c_stderr() as said:
        inp = oiio.ImageInput.open(name, config)
    if inp is None:
        raise ImageInputError(f"{name}: cannot read image: {one_line(oiio.geterror(), said.text)}")
    spec = inp.spec()
    if inp.format_name() == "tiff" and spec.tile_width > 0 and spec.format == oiio.TypeDesc("double"):
        # OpenImageIO 3.2's TIFF reader takes a tile's 64-bit samples for packed bits
        # (TIFFInput::bit_convert): values of 1e276 where 0.4 was written, with no error.
        with c_stderr():
            inp.close()
        raise ImageInputError(
            f"{name}: a tiled TIFF of 64-bit floats, which OpenImageIO {oiio.__version__} misreads; "
            "save it in strips (untiled) or as 32-bit float"
        )
    return inp, config


#: The files `_say_what_is_left` has warned about in this process.
_WARNED_LEFT: set[str] = set()


def _say_what_is_left(inp, spec, name: str) -> None:
    """Warn, once per file, that only its first subimage is warped (a multi-part OpenEXR, a
    multi-page TIFF), that deep data is flattened, and that a data window other than the display
    window (an autocropped or overscan render) is taken as the image: nothing of a file is dropped
    or moved unsaid."""
    with c_stderr():
        more = inp.seek_subimage(1, 0)
    inp.geterror()
    left = []
    if more:
        left.append("only its first subimage (part, page) is warped, the others are not written")
    if spec.deep:
        left.append("its deep samples are flattened into one value per pixel")
    window = (spec.x, spec.y, spec.width, spec.height)
    display = (spec.full_x, spec.full_y, spec.full_width, spec.full_height)
    if spec.full_width > 0 and spec.full_height > 0 and window != display:
        left.append(
            f"its data window ({spec.width} x {spec.height} at ({spec.x}, {spec.y})) is not its display window "
            f"({spec.full_width} x {spec.full_height} at ({spec.full_x}, {spec.full_y})): the polygons are taken in the "
            "data window's pixels, from its top-left corner, and the output's display window is its data window"
        )
    if left and name not in _WARNED_LEFT:
        _WARNED_LEFT.add(name)
        _log.warning("%s: %s", name, "; ".join(left))


# A complaint that comes with pixels but means the file was cut short.
_TRUNCATED = re.compile(r"premature end|truncat|unexpected end", re.I)


@dataclass(frozen=True)
class ImageHeader:
    """What an image file's header says: its size, pixel type, channels and metadata."""

    width: int
    height: int
    channels: int
    dtype: np.dtype
    channel_names: tuple[str, ...] = ()
    alpha_channel: int | None = None
    attributes: tuple = field(default=(), repr=False)
    associated_alpha: bool = True
    orientation: int = 1

    @property
    def oriented(self) -> bool:
        """Whether `read_image` turns or flips the pixels (an EXIF orientation other than 1)."""
        return self.orientation != 1

    @property
    def displayed_size(self) -> tuple[int, int]:
        """``(width, height)`` of the image as `read_image` returns it: orientations 5 to 8 turn it a quarter."""
        return (self.height, self.width) if self.orientation in (5, 6, 7, 8) else (self.width, self.height)


_limit_lock = threading.Lock()
_limit_users = 0
_limit_saved = 0


@contextlib.contextmanager
def size_limit_lifted() -> Iterator[None]:
    """OpenImageIO's image-size limit lifted for the block.

    OpenImageIO refuses to open an image whose decoded size exceeds
    ``limits:imagesize_MB`` (by default about the machine's memory), a guard
    for readers that decode a whole image. A header read decodes nothing, and
    strips (`warpcli.raster.parts`) read and write parts: there the limit
    would refuse exactly the images they exist for. Whole images are guarded
    by `warpcli.budget.check_fits` from their headers. The attribute is
    global: nested and concurrent blocks share one lift, undone by the last.
    """
    import OpenImageIO as oiio

    global _limit_users, _limit_saved
    with _limit_lock:
        if _limit_users == 0:
            _limit_saved = oiio.get_int_attribute("limits:imagesize_MB", 0)
            oiio.attribute("limits:imagesize_MB", 0)  # 0: no limit
        _limit_users += 1
    try:
        yield
    finally:
        with _limit_lock:
            _limit_users -= 1
            if _limit_users == 0:
                oiio.attribute("limits:imagesize_MB", _limit_saved)


def read_header(path: str | os.PathLike[str]) -> ImageHeader:
    """The header of the image at ``path``, as `read_image` would read it, without its pixels.

    Raises
    ------
    ImageInputError
        If the file is missing, not a regular file, not an image OpenImageIO
        reads, or of a pixel type with no numpy twin (or per-channel types).
    """
    name = os.fspath(path)
    with size_limit_lifted():  # no pixel is decoded
        inp, _ = open_input(name)
    try:
        spec = inp.spec()
        _say_what_is_left(inp, spec, name)
    finally:
        with c_stderr():
            inp.close()
        inp.geterror()
    dtype = next((d for d, oiio_name in OIIO_TYPES.items() if oiio_name == str(spec.format)), None)
    if dtype is None or spec.channelformats:
        raise ImageInputError(f"{name}: pixel type {spec.format} (or per-channel types) cannot be warped in parts")
    attrs, alpha, associated = _file_metadata(spec)
    return ImageHeader(
        int(spec.width), int(spec.height), int(spec.nchannels), dtype, tuple(spec.channelnames), alpha, attrs,
        associated, spec.get_int_attribute("Orientation", 1),
    )  # fmt: skip


def convert_pixels(pixels: NDArray, dtype: str) -> NDArray:
    """Convert pixels to another type, keeping their meaning: integer types span 0..1.

    >>> convert_pixels(np.array([0, 128, 255], dtype=np.uint8), "uint16").tolist()
    [0, 32896, 65535]
    >>> convert_pixels(np.array([-0.5, 0.5, 2.0], dtype=np.float32), "uint8").tolist()
    [0, 128, 255]
    """
    target = np.dtype(DTYPES[dtype])
    px = np.asarray(pixels)
    if px.dtype == target:
        return px
    return from_unit(to_unit(px), target)


def check_image_output(path: str | os.PathLike[str], inputs: tuple[str | os.PathLike[str], ...] | RunInputs = ()) -> None:
    """Check before any work that an image can be written at ``path``.

    `warpcli.outputs.check_output_path`'s checks, then that OpenImageIO
    writes a format of ``path``'s extension.

    Parameters
    ----------
    path : path-like
        The output; its extension picks the format.
    inputs : tuple of path-like, or warpcli.outputs.RunInputs
        Paths that must not be overwritten.

    Raises
    ------
    ImageInputError
        If the format is unknown, or as `warpcli.outputs.check_output_path` says.
    """
    import OpenImageIO as oiio

    name = os.fspath(path)
    check_output_path(name, inputs)
    out = oiio.ImageOutput.create(name)
    if out is None:
        _oiio_error(oiio)
        ext = os.path.splitext(name)[1] or "(none)"
        raise ImageInputError(f"{name}: unknown output image format for extension {ext}")


#: Formats whose writers the tests exercise for every type and channel count a warp writes:
#: `check_writes` tries the others on a small image before any work.
_TRUSTED_FORMATS = ("png", "tiff", "openexr", "jpeg")


def check_writes(path: str | os.PathLike[str], channels: int, dtype, output_dtype: str | None = None) -> None:
    """Check before any work that ``path``'s format takes an image of ``channels`` and ``dtype``.

    Some of OpenImageIO's writers take only some images (a ZFILE one channel), or
    write files their own reader cannot read (JPEG 2000, in some builds): found
    only once the work was done, that was a write failure (exit 1). A 4 x 4 ramp
    and 4 x 4 noise of the same channels and type (``output_dtype``, a `--dtype`
    name, if given) are written to a temporary directory first, through the same
    path as the output, after the ramp as TIFF (if that fails too, the disk is at
    fault, not the format, and nothing is refused); the format is refused only if
    neither is written. The answer is kept for the process. A writer that fails
    on some images and not others (JPEG XL here) still fails at the end, where
    the written file is read back.

    Raises
    ------
    ImageInputError
        Naming ``path`` and what went wrong.
    """
    fmt = output_format(path)
    if fmt in _TRUSTED_FORMATS or not fmt:
        return
    target = np.dtype(DTYPES[output_dtype]) if output_dtype is not None else np.dtype(dtype)
    ext = os.path.splitext(os.fspath(path))[1].lower()
    failure = _write_fails(ext, int(channels), target.str)
    if failure is not None:
        raise ImageInputError(
            f"{os.fspath(path)}: OpenImageIO cannot write a {channels}-channel {target.name} image as {fmt} here: {failure}"
        )


@functools.lru_cache(maxsize=64)
def _write_fails(ext: str, channels: int, dtype: str) -> str | None:
    """What writing a small image of ``channels`` and ``dtype`` with extension ``ext`` says (None: it works)."""
    import tempfile

    kind = np.dtype(dtype)
    # Two images, and a format refused only if neither is written: this OpenImageIO's JPEG XL
    # writer makes files its reader refuses for some images (a constant one, a one-channel 8-bit
    # ramp, 32-bit noise) and not others; a format that cannot hold the type or channels at all
    # fails on both.
    ramp = np.arange(16 * channels, dtype=np.float64).reshape(4, 4, channels) / (16 * channels - 1)
    noise = np.random.default_rng(0).random((4, 4, channels))
    images = [from_unit(ramp, kind), from_unit(noise, kind)]
    try:
        folder = tempfile.mkdtemp(prefix="warpcli-probe-")
    except OSError:
        return None  # no room to try: the real write will say
    try:
        try:  # the same image as TIFF, which takes every image: if that fails, the disk does, not the format
            write_image(os.path.join(folder, "control.tif"), RasterImage(images[0]))
        except ImageIOError:
            return None
        said = None
        for k, pixels in enumerate(images):
            probe = os.path.join(folder, f"probe{k}{ext}")
            try:
                write_image(probe, RasterImage(pixels))
                return None
            except ImageIOError as err:
                text = str(err).replace(probe + ": ", "").replace(probe, "a test image")
                said = said or text.removeprefix("cannot write: ")
        return said
    finally:
        import shutil

        shutil.rmtree(folder, ignore_errors=True)


def write_image(path: str | os.PathLike[str], image: RasterImage, rows: Iterable[tuple[int, int]] | None = None) -> None:
    """Write an image atomically: to a temporary file beside ``path``, then rename.

    An interrupted or failed write leaves no partial file at ``path``, and no
    temporary file (`warpcli.outputs.TEMP_NAME_PATTERN`) unless the process is
    killed outright (`warpcli.outputs.atomic_path`).
    Every step is checked: OpenImageIO's status and errors, the bytes reaching
    the disk (fsync), and the file reading back at the size it should have.
    The same image gives a byte-identical file, run after run: no DateTime is
    written unless ``image.attributes`` has one (OpenImageIO's TIFF and OpenEXR
    writers would stamp the time of writing).

    On Linux the file is encoded in memory (an anonymous memfd) and copied to
    the temporary file by Python, so every OS error, "No space left on device"
    first, comes back as an exception: written directly, libpng truncates the
    file without an error, and libjpeg ends the process. Where there is no
    memfd, a JPEG is refused beforehand unless the free space (and the file
    size limit, ``ulimit -f``) leave room for twice its uncompressed size.

    Parameters
    ----------
    path : path-like
        The output; its extension picks the format.
    image : RasterImage
        Pixels (H, W, C) and what to carry over (channel names, alpha, its
        convention, metadata).
    rows : iterable of (int, int) or None
        The pixels are still being made: each ``(y0, y1)`` it yields says
        that those rows are done, in order from row 0 to H. A PNG encodes
        each band as it comes (scanlines: the same bytes as the whole image
        at once); other formats are written once all rows are done.

    Raises
    ------
    ImageInputError
        If ``path`` cannot be written (see `check_image_output`).
    ImageIOError
        If writing fails; the message names ``path`` and the OS's reason.
    """
    import OpenImageIO as oiio

    name = os.fspath(path)
    check_image_output(name)
    with atomic_path(name) as tmp:
        _write(oiio, tmp, image, shown_name=name, rows=rows)


def _write(oiio, filename: str, image: RasterImage, *, shown_name: str, rows=None) -> None:
    if rows is not None and not image.pixels.flags.c_contiguous:
        rows = _drained(rows)  # copied whole below
    px = np.ascontiguousarray(image.pixels)
    h, w, nc = px.shape
    try:
        type_name = OIIO_TYPES[px.dtype]
    except KeyError:
        raise ImageIOError(f"{shown_name}: unsupported pixel type {px.dtype}") from None
    out = oiio.ImageOutput.create(filename)
    if out is None:
        raise ImageIOError(f"{shown_name}: cannot write: {_oiio_error(oiio)}")
    fmt = out.format_name()
    if fmt == "jpeg" and (image.alpha_channel is not None or nc in (2, 4)):
        _log.warning(
            "%s: JPEG has no alpha channel: the image's alpha is dropped (PNG, TIFF and OpenEXR keep it)",
            final_path(shown_name),
        )
    spec, premultiply = output_spec(
        oiio, fmt, (w, h, nc), type_name, image.channel_names, image.alpha_channel, image.associated_alpha,
        image.attributes,
    )  # fmt: skip
    if rows is not None and (fmt != "png" or premultiply is not None):
        # Only PNG's scanlines written in bands make the bytes of the whole image written
        # at once (libpng filters and deflates row by row, one stream); and premultiplying
        # takes the whole image.
        rows = _drained(rows)
    if premultiply is not None:
        px = premultiplied(px, premultiply)
    staged = memory_file("warpcli-image")
    target = filename if staged is None else f"/proc/self/fd/{staged}"
    try:
        _check_room(fmt, image, px, filename, shown_name, staged=staged is not None)
        with c_stderr() as said:
            ok = bool(out.open(target, spec))
            if ok and rows is not None:
                done = 0
                for y0, y1 in rows:
                    if y0 != done or not y0 < y1 <= h:
                        raise ValueError(f"rows {y0}-{y1} do not follow row {done} of {h}")
                    # PNG's writer reports a failed write on the file, not in its return value.
                    ok = bool(out.write_scanlines(y0, y1, 0, px[y0:y1])) and not out.has_error
                    done = y1
                    if not ok:
                        break
                if ok and done != h:
                    raise ValueError(f"{done} of {h} rows were made")
            elif ok:
                ok = bool(out.write_image(px))
            closed = bool(out.close())
        problem = one_line(out.geterror(), oiio.geterror(), said.text, default="")
        if not (ok and closed):
            raise ImageIOError(write_failure_message(shown_name, problem or "unknown error", target, filename, staged is None))
        size = None
        if staged is not None:
            size = copy_from_memory(staged, filename, shown_name)
    finally:
        if staged is not None:
            os.close(staged)
    # An error reported beside a success is not always one (libtiff 4.7 with
    # OpenImageIO 3.2 reports "failed TIFFWriteCustomDirectory() of the Exif
    # data" for every TIFF, which reads back whole): the file decides.
    verify_written(oiio, filename, fmt, spec, size, shown_name, problem)
    if problem:
        _log.debug("%s: %s", shown_name, problem)


def _drained(rows: Iterable[tuple[int, int]]) -> None:
    """Wait for every row (`write_image`'s ``rows``): the image is then written whole."""
    for _ in rows:
        pass


_PNG_LEVEL = "png:compressionLevel"


def with_compression(attributes: tuple, level: int | None) -> tuple:
    """``attributes`` asking a PNG writer for zlib ``level`` (0-9); None: unchanged (the default level).

    Other formats ignore the attribute.

    >>> with_compression((), 9)
    (('png:compressionLevel', 'int', 9),)
    """
    if level is None:
        return tuple(attributes)
    return (*(a for a in attributes if a[0] != _PNG_LEVEL), (_PNG_LEVEL, "int", int(level)))


def output_spec(oiio, fmt: str, size: tuple[int, int, int], type_name: str, channel_names, alpha_channel,
                associated_alpha: bool, attributes):  # fmt: skip
    """The OpenImageIO spec of an output image, and the alpha to premultiply its pixels by.

    Shared by whole-image and strip writes (`warpcli.raster.parts.StripWriter`),
    so both write the same header.

    Parameters
    ----------
    oiio : module
        The OpenImageIO module.
    fmt : str
        OpenImageIO's name of the output's format ("png", "openexr", ...).
    size : (int, int, int)
        Width, height, channels.
    type_name : str
        OpenImageIO's name of the pixel type (a value of `OIIO_TYPES`).
    channel_names : sequence of str
    alpha_channel : int or None
    associated_alpha : bool
        Whether the pixels' colour is premultiplied by alpha.
    attributes : tuple of (name, type name, value)
        Metadata; what OpenImageIO cannot store is dropped, and a PNG's sRGB
        colour space is left to the writer's default (`written_attributes`). A PNG is written
        at zlib level `warpcli.raster.dtypes.PNG_COMPRESSION` unless it has a
        ``png:compressionLevel`` (`with_compression`).

    Returns
    -------
    spec : OpenImageIO.ImageSpec
        Without a time stamp unless ``attributes`` has a DateTime.
    premultiply : int or None
        The alpha channel to premultiply the pixels by before writing them
        (straight colour into a premultiplied format), else None.
    """
    spec = oiio.ImageSpec(*size, type_name)
    if channel_names:
        spec.channelnames = tuple(channel_names)
    spec.alpha_channel = -1 if alpha_channel is None else int(alpha_channel)
    premultiply = None
    if alpha_channel is not None and not associated_alpha:
        if fmt in _PREMULTIPLIED_FORMATS:
            premultiply = alpha_channel
        else:
            spec.attribute("oiio:UnassociatedAlpha", 1)  # store the straight colour as it is
    for attr_name, attr_type, value in written_attributes(oiio, fmt, attributes):
        try:
            spec.attribute(attr_name, oiio.TypeDesc(attr_type), value)
        except (TypeError, ValueError, RuntimeError):
            continue  # metadata OpenImageIO cannot round-trip is dropped, not fatal
    if fmt == "png" and not any(attr[0] == _PNG_LEVEL for attr in attributes):
        # OpenImageIO's default is zlib's 6: several times slower to write than 1
        # for files only 12-15 % smaller (issue 24, bench/README.md).
        spec.attribute(_PNG_LEVEL, PNG_COMPRESSION)
    if not any(attr[0] == "DateTime" for attr in attributes):
        # OpenImageIO's TIFF and OpenEXR writers stamp the time of writing
        # unless told a DateTime; an empty one writes none.
        spec.attribute("DateTime", "")
    return spec, premultiply


# Formats whose library ends the process when a write fails (libjpeg's
# default error handler calls exit(), and OpenImageIO keeps it for writing).
_ABORTING_FORMATS = ("jpeg",)
# What a complete file of a format ends with: libpng writes a file cut short
# without an error.
_TRAILERS = {"png": b"IEND\xaeB`\x82", "jpeg": b"\xff\xd9"}
# Formats that store exactly the channels they are given (JPEG stores 1 or 3).
_EXACT_CHANNELS = ("png", "tiff", "openexr")


def _check_room(fmt: str, image: RasterImage, px: NDArray, filename: str, shown_name: str, *, staged: bool) -> None:
    """Refuse a JPEG that might not fit, since libjpeg would end the process.

    A baseline JPEG takes at most about 1.6 times the pixels' bytes (measured on
    noise at quality 100), so the bound is twice that, plus the metadata and
    16 KiB for the headers.
    """
    if fmt not in _ABORTING_FORMATS:
        return
    meta = sum(np.asarray(value).nbytes if not isinstance(value, str) else len(value) for _, _, value in image.attributes)
    bound = 2 * px.nbytes + meta + (16 << 10)
    what = f"a {fmt.upper()} of {px.shape[1]} x {px.shape[0]} may take up to {format_bytes(bound)}"
    # Staged in memory, the copy to the disk reports a full disk as an exception.
    check_room(filename, shown_name, bound, what, disk=not staged)


def verify_written(oiio, filename: str, fmt: str, spec, size: int | None, shown_name: str, problem: str = "") -> None:
    """Check that a written image file is whole, as its writer cannot always tell.

    libpng, for one, writes a file cut short without an error.

    Parameters
    ----------
    oiio : module
        The OpenImageIO module.
    filename : str
        The file written.
    fmt : str
        Its format, OpenImageIO's name.
    spec : OpenImageIO.ImageSpec
        The spec it was written with (`output_spec`).
    size : int or None
        The bytes that should have reached the file, if known.
    shown_name : str
        The name given in messages (the user's path).
    problem : str
        What OpenImageIO said while writing, added to a failure's message.

    Raises
    ------
    ImageIOError
        If the file is not ``size`` bytes, lacks its format's trailer, or does
        not read back with the width, height (and channels) written.
    """
    try:
        actual = os.stat(filename).st_size
        trailer = _TRAILERS.get(fmt, b"")
        with open(filename, "rb") as fh:
            fh.seek(max(actual - len(trailer), 0))
            end = fh.read()
    except OSError as err:
        raise ImageIOError(f"{shown_name}: cannot write: {err.strerror or err}") from err
    said = ""
    if size is not None and actual != size:
        failure = f"{actual} of {size} bytes reached the file"
    elif trailer and not end.endswith(trailer):
        failure = f"the {fmt.upper()} file is cut short at {actual} bytes"
    else:
        with c_stderr() as captured:
            inp = oiio.ImageInput.open(filename)
        said = captured.text
        if inp is None:
            failure = f"the written file does not read back: {one_line(oiio.geterror())}"
        else:
            try:
                back = inp.spec()
            finally:
                inp.close()
            wrote = (spec.width, spec.height) + ((spec.nchannels,) if fmt in _EXACT_CHANNELS else ())
            got = (back.width, back.height) + ((back.nchannels,) if fmt in _EXACT_CHANNELS else ())
            if wrote == got:
                return
            failure = (
                f"the written file reads back as {back.width} x {back.height} x {back.nchannels}, "
                f"not {spec.width} x {spec.height} x {spec.nchannels}"
            )
    raise ImageIOError(write_failure_message(shown_name, one_line(failure, problem, said), filename, filename, True))


# Formats whose colour is premultiplied by alpha by definition: straight colour
# must be premultiplied before it is written there (OpenImageIO does not).
_PREMULTIPLIED_FORMATS = ("openexr",)


def _oiio_error(oiio) -> str:
    """OpenImageIO's pending global error message, on one line."""
    return one_line(oiio.geterror())
