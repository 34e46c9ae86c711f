"""Image I/O: OpenImageIO read/write keeping pixel type, channels and metadata."""

from __future__ import annotations

import contextlib
import errno
import logging
import math
import os
import re
import stat
import sys
import tempfile
import threading
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..errors import ImageInputError, ImageIOError, WarpError
from ..files import check_regular_file, file_kind, format_bytes
from ..options import DTYPES as DTYPE_NAMES
from .pixels import from_unit, to_unit

# numpy dtype -> OpenImageIO type name.
_OIIO_TYPES = {
    np.dtype(np.uint8): "uint8",
    np.dtype(np.int8): "int8",
    np.dtype(np.uint16): "uint16",
    np.dtype(np.int16): "int16",
    np.dtype(np.uint32): "uint32",
    np.dtype(np.int32): "int32",
    np.dtype(np.float16): "half",
    np.dtype(np.float32): "float",
    np.dtype(np.float64): "double",
}

# Attributes that describe the file rather than the picture, that OpenImageIO
# manages itself, or that no longer hold for a warped image (a thumbnail of the
# input; the orientation, which is applied on reading): not carried over.
_DROP_PREFIXES = (
    "oiio:", "png:", "jpeg:", "tiff:", "openexr:", "Exif:PixelXDimension", "Exif:PixelYDimension",
    "thumbnail", "Orientation",
)  # fmt: skip
_KEEP = ("oiio:ColorSpace",)

#: Output pixel types for ``convert_pixels`` (and ``--dtype``), by name.
DTYPES = dict(zip(DTYPE_NAMES, (np.uint8, np.uint16, np.float16, np.float32)))

#: Name of the temporary file an output is written to before it is renamed over
#: the output: hidden, in the output's directory (the same file system, so the
#: rename is atomic), with the output's stem and extension (which picks the
#: format); XXXXXXXX is random. Only a run killed outright (SIGKILL, a power
#: cut) leaves one behind; it is harmless and can be deleted.
TEMP_NAME_PATTERN = ".{stem}.warpcli-tmp-XXXXXXXX{ext}"
#: A shell pattern matching the leftovers: ``find DIR -name '.*.warpcli-tmp-*' -delete``.
TEMP_NAME_GLOB = ".*.warpcli-tmp-*"

#: Environment variable: the most bytes of pixels warpcli will hold for one
#: image (read, or made with ``--size``), overriding the default limit.
MAX_IMAGE_BYTES_ENV = "WARPCLI_MAX_IMAGE_BYTES"
#: The default limit: this share of the memory available (Linux's MemAvailable,
#: within a cgroup's limit; elsewhere the free physical memory), leaving the
#: rest for the warp's working arrays.
MEMORY_FRACTION = 0.5

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
    (`check_fits`) from its header, before any pixel is decoded. What the C
    libraries print (libpng's "libpng error: ...") is kept off stderr and
    folded into the error message.

    Parameters
    ----------
    path : path-like
        Any format OpenImageIO reads. The EXIF orientation is applied, so the
        pixels are the image as displayed. The first subimage is read, at its
        full resolution.

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
    inp, config = _open_input(name)
    try:
        spec = inp.spec()
        oriented = spec.get_int_attribute("Orientation", 1) != 1
        _check_spec_fits(spec, name, copies=2 if oriented else 1)
        with _c_stderr() as said:
            pixels = inp.read_image(oiio.UNKNOWN)
        problem = inp.geterror()
        if pixels is None:
            raise ImageInputError(f"{name}: cannot read image: {_one_line(problem, oiio.geterror(), said.text)}")
        if problem:
            # Pixels came back, with a complaint: libjpeg fills a truncated
            # file with grey and says "Premature end of JPEG file".
            if _TRUNCATED.search(problem):
                raise ImageInputError(f"{name}: cannot read image: {_one_line(problem, said.text)}")
            _log.debug("%s: %s", name, _one_line(problem, said.text))
    finally:
        with _c_stderr():
            inp.close()
        inp.geterror()  # nothing left pending to be printed later
    pixels = np.asarray(pixels)
    if oriented:
        # Polygons are drawn on the image as displayed (labelme, for one,
        # applies the orientation), so apply it and write the result upright.
        with _c_stderr() as said:
            buf = oiio.ImageBufAlgo.reorient(oiio.ImageBuf(name, 0, 0, config))
            oriented_px = None if buf.has_error else buf.get_pixels(oiio.TypeDesc(_OIIO_TYPES.get(pixels.dtype, "float")))
        if oriented_px is None:
            raise ImageInputError(f"{name}: cannot read image: {_one_line(buf.geterror(), oiio.geterror(), said.text)}")
        pixels = np.asarray(oriented_px)
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    attrs, alpha, associated = _file_metadata(spec)
    return RasterImage(np.ascontiguousarray(pixels), tuple(spec.channelnames), alpha, attrs, associated)


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


def _open_input(name: str):
    """An OpenImageIO ImageInput on the regular file ``name``, and the configuration it was opened with.

    Raises
    ------
    ImageInputError
        If the file is missing, not a regular file, or not an image OpenImageIO reads.
    """
    import OpenImageIO as oiio

    _check_input_file(name)
    # Ask for straight colour where the file stores it so (PNG): OpenImageIO
    # would otherwise premultiply it in 8 bits, losing the colour of
    # transparent pixels and precision at low alpha.
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    with _c_stderr() as said:
        inp = oiio.ImageInput.open(name, config)
    if inp is None:
        raise ImageInputError(f"{name}: cannot read image: {_one_line(oiio.geterror(), said.text)}")
    return inp, config


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


def read_header(path: str | os.PathLike[str]) -> ImageHeader:
    """The header of the image at ``path``, as `read_image` would read it, without its pixels.

    Raises
    ------
    ImageInputError
        If the file is missing, not a regular file, not an image OpenImageIO
        reads, or of a pixel type with no numpy twin (or per-channel types).
    """
    name = os.fspath(path)
    inp, _ = _open_input(name)
    try:
        spec = inp.spec()
    finally:
        with _c_stderr():
            inp.close()
        inp.geterror()
    dtype = next((d for d, oiio_name in _OIIO_TYPES.items() if oiio_name == str(spec.format)), None)
    if dtype is None or spec.channelformats:
        raise ImageInputError(f"{name}: pixel type {spec.format} (or per-channel types) cannot be warped in parts")
    attrs, alpha, associated = _file_metadata(spec)
    return ImageHeader(
        int(spec.width), int(spec.height), int(spec.nchannels), dtype, tuple(spec.channelnames), alpha, attrs,
        associated, spec.get_int_attribute("Orientation", 1),
    )  # fmt: skip


def max_image_bytes() -> int:
    """The most bytes of pixels warpcli will hold for one image.

    ``WARPCLI_MAX_IMAGE_BYTES`` if it is set, else `MEMORY_FRACTION` of the
    memory available now.

    Raises
    ------
    ImageInputError
        If ``WARPCLI_MAX_IMAGE_BYTES`` is not a positive whole number.
    """
    value = os.environ.get(MAX_IMAGE_BYTES_ENV, "").strip()
    if value:
        try:
            limit = int(value)
        except ValueError:
            limit = 0
        if limit <= 0:
            raise ImageInputError(f"{MAX_IMAGE_BYTES_ENV}={value!r}: not a positive whole number of bytes")
        return limit
    available = _available_memory()
    return sys.maxsize if available is None else int(available * MEMORY_FRACTION)


def check_fits(width: int, height: int, channels: int, bytes_per_value: int, what: str) -> None:
    """Refuse, before allocating it, an image too large for this machine's memory.

    Parameters
    ----------
    width, height, channels : int
    bytes_per_value : int
        1 for uint8, 2 for uint16 and half, 4 for float, ...
    what : str
        What the size comes from: a file name, or an option such as
        ``"--size 100000x100000"``. The message starts with it.

    Raises
    ------
    ImageInputError
        If ``width * height * channels * bytes_per_value`` is more than
        `max_image_bytes` (``WARPCLI_MAX_IMAGE_BYTES``, else half the
        available memory), with the size and the memory it needs.

    Examples
    --------
    >>> check_fits(640, 480, 3, 1, "in.png")  # 0.9 MB: fits
    """
    _check_bytes((width, height, channels, bytes_per_value), 1, what)


def _check_spec_fits(spec, name: str, copies: int = 1) -> None:
    sizes = [spec.format.size(), *(f.size() for f in spec.channelformats)]
    _check_bytes((spec.width, spec.height * max(spec.depth, 1), spec.nchannels, max(sizes)), copies, name)


def _check_bytes(dims: tuple[int, int, int, int], copies: int, what: str) -> None:
    width, height, channels, nbytes = (int(d) for d in dims)
    if min(width, height, channels, nbytes) < 0:
        raise ImageInputError(f"{what}: invalid image size {width} x {height} x {channels} channels")
    need = math.prod((width, height, channels, nbytes, copies))
    limit = max_image_bytes()
    if need > limit:
        unit = "byte" if nbytes == 1 else "bytes"
        twice = f" ({copies} copies, to apply the orientation)" if copies > 1 else ""
        source = MAX_IMAGE_BYTES_ENV if os.environ.get(MAX_IMAGE_BYTES_ENV, "").strip() else (
            f"{MEMORY_FRACTION:.0%} of the available memory; set {MAX_IMAGE_BYTES_ENV} to change it"
        )
        shown_need, shown_limit = format_bytes(need), format_bytes(limit)
        if shown_need == shown_limit:  # rounded alike: give them exactly
            shown_need, shown_limit = f"{need} bytes", f"{limit} bytes"
        raise ImageInputError(
            f"{what}: a {width} x {height} image of {channels} channel(s) x {nbytes} {unit} needs "
            f"{shown_need} of memory{twice}, more than the {shown_limit} warpcli may use ({source})"
        )


def _available_memory() -> int | None:
    """Bytes of memory this process can still get, or None if unknown."""
    available = None
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    available = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError, IndexError):
        pass
    if available is None:
        try:
            available = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (AttributeError, ValueError, OSError):
            return None
    room = _cgroup_room()
    return available if room is None else min(available, room)


def _cgroup_room() -> int | None:
    """What a cgroup v2 memory limit (a container's) still allows, or None."""
    try:
        with open("/proc/self/cgroup") as fh:
            group = next((ln.strip()[3:] for ln in fh if ln.startswith("0::")), None)
        if group is None:
            return None
        base = os.path.join("/sys/fs/cgroup", group.lstrip("/"))
        with open(os.path.join(base, "memory.max")) as fh:
            limit = fh.read().strip()
        if limit == "max":
            return None
        with open(os.path.join(base, "memory.current")) as fh:
            used = int(fh.read())
        return max(int(limit) - used, 0)
    except (OSError, ValueError):
        return None


def _check_input_file(name: str) -> None:
    """Refuse at once what is not a regular file: opening a FIFO blocks until a
    writer comes, /dev/zero never ends."""
    check_regular_file(name, "image", ImageInputError)


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


def check_output_path(
    path: str | os.PathLike[str], inputs: tuple[str | os.PathLike[str], ...] = (), *, image: bool = True
) -> None:
    """Check before any work that an output can be written at ``path``.

    Parameters
    ----------
    inputs : paths that must not be overwritten.
    image : whether the output is an image (its format must be known).

    Raises
    ------
    ImageInputError
        If the format is unknown, the directory is missing or cannot be written
        in (read-only, no permission), ``path`` exists and is not a regular
        file (a device, a FIFO: it would be replaced), or ``path`` is one of
        ``inputs`` (an input is never overwritten).
    """
    import OpenImageIO as oiio

    name = os.fspath(path)
    for other in inputs:
        if _same_file(name, os.fspath(other)):
            raise ImageInputError(f"{name}: output would overwrite the input {os.fspath(other)}")
    directory = os.path.dirname(os.path.abspath(name))
    if not os.path.isdir(directory):
        raise ImageInputError(f"{name}: output directory {directory} does not exist")
    if os.path.isdir(name):
        raise ImageInputError(f"{name}: is a directory")
    _check_replaceable(name)
    if not os.access(directory, os.W_OK | os.X_OK):
        raise ImageInputError(f"{name}: cannot write in {directory}: {_why_unwritable(directory)}")
    if not image:
        return
    out = oiio.ImageOutput.create(name)
    if out is None:
        _oiio_error(oiio)
        ext = os.path.splitext(name)[1] or "(none)"
        raise ImageInputError(f"{name}: unknown output image format for extension {ext}")


def write_image(path: str | os.PathLike[str], image: RasterImage) -> None:
    """Write an image atomically: to a temporary file beside ``path``, then rename.

    An interrupted or failed write leaves no partial file at ``path``, and no
    temporary file (`TEMP_NAME_PATTERN`) unless the process is killed outright.
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

    Raises
    ------
    ImageInputError
        If ``path`` cannot be written (see `check_output_path`).
    ImageIOError
        If writing fails; the message names ``path`` and the OS's reason.
    """
    import OpenImageIO as oiio

    name = os.fspath(path)
    check_output_path(name)
    with atomic_path(name) as tmp:
        _write(oiio, tmp, image, shown_name=name)


@contextlib.contextmanager
def atomic_path(path: str):
    """Yield a temporary path beside ``path`` (same extension); on success rename it
    over ``path``, on any failure remove it. Readers never see a partial file.

    The temporary file is named after `TEMP_NAME_PATTERN`. What the body wrote is
    flushed to the disk (fsync) before the rename, and an `OSError` raised by the
    body or by these steps becomes an `ImageIOError` naming ``path`` and the OS's
    reason (an `ImageInputError` when ``path`` cannot be written at all: no
    permission, a read-only file system).
    """
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    _check_replaceable(path)
    prefix, suffix = _temp_affixes(path, directory)
    try:
        fd, tmp = tempfile.mkstemp(prefix=prefix, suffix=suffix, dir=directory)
        os.close(fd)
    except OSError as err:
        raise _write_error(path, err) from err
    try:
        yield tmp
        _sync_file(tmp)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException as err:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(err, OSError) and not isinstance(err, WarpError):
            raise _write_error(path, err) from err
        raise
    _sync_directory(directory)


def _temp_affixes(path: str, directory: str) -> tuple[str, str]:
    """mkstemp's prefix and suffix for `TEMP_NAME_PATTERN`, the stem shortened if
    the name would be too long for the file system."""
    stem, ext = os.path.splitext(os.path.basename(path))
    head, tail = TEMP_NAME_PATTERN.split("XXXXXXXX")
    try:
        name_max = os.pathconf(directory, "PC_NAME_MAX")
    except (OSError, ValueError):
        name_max = 255
    spare = name_max - len(os.fsencode(head.format(stem="") + "XXXXXXXX" + tail.format(ext=ext)))
    raw = os.fsencode(stem)
    if len(raw) > spare:
        stem = os.fsdecode(raw[: max(spare, 0)]).rstrip("\udcff")  # never half a UTF-8 character
        while len(os.fsencode(stem)) > spare:
            stem = stem[:-1]
    return head.format(stem=stem), tail.format(ext=ext)


def _check_replaceable(name: str) -> None:
    """The output is replaced by a new file: refuse to replace anything but a file."""
    try:
        st = os.stat(name)
    except OSError:
        return
    if stat.S_ISDIR(st.st_mode):
        raise ImageInputError(f"{name}: is a directory")
    if not stat.S_ISREG(st.st_mode):
        raise ImageInputError(f"{name}: is {file_kind(st.st_mode)}; an output must be a regular file")


def _why_unwritable(directory: str) -> str:
    try:
        if os.statvfs(directory).f_flag & os.ST_RDONLY:
            return os.strerror(errno.EROFS)
    except (OSError, AttributeError):
        pass
    return os.strerror(errno.EACCES)


# OS errors that mean the output path is unusable (exit 2), not a failure
# while writing (exit 1).
_PATH_ERRNOS = {errno.EACCES, errno.EPERM, errno.EROFS, errno.ENOENT, errno.ENOTDIR, errno.EISDIR, errno.ENAMETOOLONG}


def _write_error(path: str, err: OSError) -> ImageIOError:
    cls = ImageInputError if err.errno in _PATH_ERRNOS else ImageIOError
    return cls(f"{path}: cannot write: {err.strerror or err}")


def _sync_file(name: str) -> None:
    """Flush a written file to the disk: errors deferred by the kernel (a full
    disk on NFS, an I/O error) are reported here, before the rename."""
    fd = os.open(name, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _sync_directory(directory: str) -> None:
    """Make the rename durable; best effort (not every file system can)."""
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _write(oiio, filename: str, image: RasterImage, *, shown_name: str) -> None:
    px = np.ascontiguousarray(image.pixels)
    h, w, nc = px.shape
    try:
        type_name = _OIIO_TYPES[px.dtype]
    except KeyError:
        raise ImageIOError(f"{shown_name}: unsupported pixel type {px.dtype}") from None
    out = oiio.ImageOutput.create(filename)
    if out is None:
        raise ImageIOError(f"{shown_name}: cannot write: {_oiio_error(oiio)}")
    fmt = out.format_name()
    spec, premultiply = _output_spec(
        oiio, fmt, (w, h, nc), type_name, image.channel_names, image.alpha_channel, image.associated_alpha,
        image.attributes,
    )  # fmt: skip
    if premultiply is not None:
        px = _premultiplied(px, premultiply)
    staged = _memory_file("warpcli-image")
    target = filename if staged is None else f"/proc/self/fd/{staged}"
    try:
        _check_room(fmt, image, px, filename, shown_name, staged=staged is not None)
        with _c_stderr() as said:
            ok = bool(out.open(target, spec)) and bool(out.write_image(px))
            closed = bool(out.close())
        problem = _one_line(out.geterror(), oiio.geterror(), said.text, default="")
        if not (ok and closed):
            raise ImageIOError(_write_failure(shown_name, problem or "unknown error", target, filename, staged is None))
        size = None
        if staged is not None:
            size = _copy_file(staged, filename, shown_name)
    finally:
        if staged is not None:
            os.close(staged)
    # An error reported beside a success is not always one (libtiff 4.7 with
    # OpenImageIO 3.2 reports "failed TIFFWriteCustomDirectory() of the Exif
    # data" for every TIFF, which reads back whole): the file decides.
    _verify(oiio, filename, fmt, spec, size, shown_name, problem)
    if problem:
        _log.debug("%s: %s", shown_name, problem)


def _output_spec(oiio, fmt: str, size: tuple[int, int, int], type_name: str, channel_names, alpha_channel,
                 associated_alpha: bool, attributes):  # fmt: skip
    """The ImageSpec of an output of format ``fmt``, ``size`` (width, height, channels), with
    the channel names, alpha and metadata given; and the alpha channel to premultiply the
    pixels by before writing them (straight colour into a premultiplied format), or None."""
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
    for attr_name, attr_type, value in attributes:
        try:
            spec.attribute(attr_name, oiio.TypeDesc(attr_type), value)
        except (TypeError, ValueError, RuntimeError):
            continue  # metadata OpenImageIO cannot round-trip is dropped, not fatal
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
    soft = _file_size_limit()
    if soft is not None and bound > soft:
        raise ImageIOError(
            f"{shown_name}: cannot write: {os.strerror(errno.EFBIG)}: {what}, "
            f"the file size limit (ulimit -f) is {format_bytes(soft)}"
        )
    if staged:
        return  # the copy from memory reports a full disk as an exception
    try:
        vfs = os.statvfs(os.path.dirname(os.path.abspath(filename)))
    except OSError:
        return
    free = vfs.f_bavail * vfs.f_frsize
    if free < bound:
        raise ImageIOError(f"{shown_name}: cannot write: {os.strerror(errno.ENOSPC)}: {what}, {format_bytes(free)} free")


def _file_size_limit() -> int | None:
    try:
        import resource
    except ImportError:
        return None
    soft = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    return None if soft == resource.RLIM_INFINITY else soft


def _memory_file(name: str) -> int | None:
    """An anonymous in-memory file that OpenImageIO can open by a path, or None."""
    if not hasattr(os, "memfd_create"):
        return None
    try:
        fd = os.memfd_create(name, os.MFD_CLOEXEC)
    except OSError:
        return None
    if not os.path.exists(f"/proc/self/fd/{fd}"):
        os.close(fd)
        return None
    return fd


def _copy_file(src_fd: int, filename: str, shown_name: str) -> int:
    """Copy an encoded file from memory to ``filename``, flushed to the disk;
    return its size. OS errors come back as ImageIOError with their reason."""
    size = os.fstat(src_fd).st_size
    try:
        fd = os.open(filename, os.O_WRONLY | os.O_TRUNC | getattr(os, "O_CLOEXEC", 0))
        try:
            offset = 0
            while offset < size:
                chunk = memoryview(os.pread(src_fd, min(1 << 20, size - offset), offset))
                if not chunk:
                    break
                offset += len(chunk)
                while chunk:
                    chunk = chunk[os.write(fd, chunk) :]
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError as err:
        raise ImageIOError(f"{shown_name}: cannot write: {err.strerror or err}") from err
    return size


def _verify(oiio, filename: str, fmt: str, spec, size: int | None, shown_name: str, problem: str = "") -> None:
    """Check that the written file is whole: its size, its format's trailer, and
    a header that reads back with the size and channels written. ``problem``:
    what OpenImageIO said while writing, added to a failure's message."""
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
        with _c_stderr() as captured:
            inp = oiio.ImageInput.open(filename)
        said = captured.text
        if inp is None:
            failure = f"the written file does not read back: {_one_line(oiio.geterror())}"
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
    raise ImageIOError(_write_failure(shown_name, _one_line(failure, problem, said), filename, filename, True))


def _write_failure(shown_name: str, text: str, written: str, filename: str, on_disk: bool) -> str:
    """The message for a failed write: temporary names replaced by the output's,
    and the OS's likely reason added when the library that failed did not give
    one (libpng, libtiff and OpenEXR report no errno).

    Parameters
    ----------
    written : the file the library wrote (the temporary file, or the in-memory one).
    on_disk : whether ``written`` is on the output's file system (else in memory).
    """
    text = text.replace(written, shown_name).replace(filename, shown_name)
    cause = ""
    try:
        limit = _file_size_limit()
        if limit is not None and os.stat(written).st_size >= limit:
            cause = os.strerror(errno.EFBIG)
        elif on_disk:
            vfs = os.statvfs(os.path.dirname(os.path.abspath(filename)))
            if vfs.f_bavail * vfs.f_frsize < 2 * max(vfs.f_bsize, 4096):
                cause = os.strerror(errno.ENOSPC)
    except OSError:
        pass
    if cause and cause.lower() not in text.lower():
        text = f"{cause}: {text}"
    return f"{shown_name}: cannot write: {text}"


# Formats whose colour is premultiplied by alpha by definition: straight colour
# must be premultiplied before it is written there (OpenImageIO does not).
_PREMULTIPLIED_FORMATS = ("openexr",)


def _premultiplied(px: NDArray, alpha_channel: int) -> NDArray:
    """Colour multiplied by alpha (0..1), in the pixels' own type."""
    x = to_unit(px)
    colour = [c for c in range(px.shape[2]) if c != alpha_channel]
    x[:, :, colour] *= x[:, :, alpha_channel : alpha_channel + 1]
    return from_unit(x, px.dtype)


class _Captured:
    """What C code wrote to stderr during a `_c_stderr` block (set on leaving it)."""

    text = ""


_CAPTURE_LOCK = threading.Lock()
_CAPTURE_MAX = 1 << 16


@contextlib.contextmanager
def _c_stderr():
    """Keep what C libraries write to file descriptor 2 off the terminal.

    libpng, for one, prints "libpng error: ..." itself before OpenImageIO
    reports the error; the CLI must show its one line only. The text is kept
    (``.text`` of the yielded object) to fold into an error message, and is
    dropped when the call succeeds. One block at a time: a block entered while
    another is open (another thread) does not redirect again.
    """
    said = _Captured()
    if not _CAPTURE_LOCK.acquire(blocking=False):
        yield said
        return
    sink = saved = None
    try:
        try:
            sink = _anonymous_file("warpcli-stderr")
            if sys.stderr is not None:
                sys.stderr.flush()
            saved = os.dup(2)
            os.dup2(sink.fileno(), 2)
        except (OSError, ValueError):
            if saved is not None:
                os.close(saved)
                saved = None
        yield said
    finally:
        try:
            if saved is not None:
                os.dup2(saved, 2)
                os.close(saved)
                sink.seek(0)
                said.text = sink.read(_CAPTURE_MAX).decode("utf-8", "replace")
            if sink is not None:
                sink.close()
        finally:
            _CAPTURE_LOCK.release()


def _anonymous_file(name: str):
    """A binary read-write file with no name on any disk."""
    fd = _memory_file(name) if hasattr(os, "memfd_create") else None
    if fd is not None:
        return os.fdopen(fd, "w+b")
    return tempfile.TemporaryFile()


# Prefixes the C libraries put on their own lines, ignored when comparing them
# with OpenImageIO's, which usually repeat them.
_LIB_PREFIX = re.compile(r"^(lib\w+|\w+ library)\s+(error|warning)\s*:\s*", re.I)


def _one_line(*texts: str | None, limit: int = 400, default: str = "unknown error") -> str:
    """Error texts (OpenImageIO's, several lines; what C code printed) on one
    line, without lines that only repeat another, or another but for numbers.

    >>> _one_line("Read error: end of file\\nPNG read error: IDAT: Read error: end of file", "libpng error: IDAT: Read error: end of file")
    'PNG read error: IDAT: Read error: end of file'
    >>> _one_line("Write error at 10\\nWrite error at 20\\nWrite error at 30")
    'Write error at 10 (and 2 more like it)'
    """
    lines: list[str] = []
    more: dict[str, int] = {}
    for text in texts:
        for line in (text or "").splitlines():
            line = " ".join(line.split())
            pattern = re.sub(r"\d+", "#", line)
            if pattern in more:
                more[pattern] += line not in lines
            elif line:
                lines.append(line)
                more[pattern] = 0
    kept: list[str] = []
    for line in sorted(lines, key=len, reverse=True):
        core = _LIB_PREFIX.sub("", line).lower()
        if not any(core in other.lower() for other in kept):
            kept.append(line)
    parts = []
    for line in lines:
        if line in kept:
            n = more[re.sub(r"\d+", "#", line)]
            parts.append(f"{line} (and {n} more like it)" if n else line)
    msg = "; ".join(parts) or default
    return msg if len(msg) <= limit else msg[: limit - 3] + "..."


def _oiio_error(oiio) -> str:
    """OpenImageIO's pending global error message, on one line."""
    return _one_line(oiio.geterror())


def _same_file(a: str, b: str) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.abspath(a) == os.path.abspath(b)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
