"""Image I/O: OpenImageIO read/write keeping pixel type, channels and metadata."""

from __future__ import annotations

import contextlib
import os
import tempfile
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..errors import ImageInputError, ImageIOError
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

    Parameters
    ----------
    path : path-like
        Any format OpenImageIO reads. The EXIF orientation is applied, so the
        pixels are the image as displayed.

    Returns
    -------
    RasterImage
        Pixels (H, W, C) in the file's type, channel names, alpha, metadata.

    Raises
    ------
    ImageInputError
        If the file is missing or is not an image OpenImageIO can read.
    """
    import OpenImageIO as oiio

    name = os.fspath(path)
    if not os.path.exists(name):
        raise ImageInputError(f"{name}: no such file")
    if os.path.isdir(name):
        raise ImageInputError(f"{name}: is a directory, not an image")
    # Ask for straight colour where the file stores it so (PNG): OpenImageIO
    # would otherwise premultiply it in 8 bits, losing the colour of
    # transparent pixels and precision at low alpha.
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(name, config)
    if inp is None:
        raise ImageInputError(f"{name}: cannot read image: {_oiio_error(oiio)}")
    try:
        spec = inp.spec()
        pixels = inp.read_image(oiio.UNKNOWN)
        if pixels is None:
            raise ImageInputError(f"{name}: cannot read image: {inp.geterror() or _oiio_error(oiio)}")
    finally:
        inp.close()
    pixels = np.asarray(pixels)
    if spec.get_int_attribute("Orientation", 1) != 1:
        # Polygons are drawn on the image as displayed (labelme, for one,
        # applies the orientation), so apply it and write the result upright.
        buf = oiio.ImageBufAlgo.reorient(oiio.ImageBuf(name))
        pixels = np.asarray(buf.get_pixels(oiio.TypeDesc(_OIIO_TYPES.get(pixels.dtype, "float"))))
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    attrs = tuple(
        (a.name, str(a.type), a.value)
        for a in spec.extra_attribs
        if a.name in _KEEP or not a.name.startswith(_DROP_PREFIXES)
    )
    alpha = spec.alpha_channel if spec.alpha_channel >= 0 else None
    associated = spec.get_int_attribute("oiio:UnassociatedAlpha", 0) != 1
    return RasterImage(np.ascontiguousarray(pixels), tuple(spec.channelnames), alpha, attrs, associated)


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
        If the format is unknown, the directory is missing, or ``path`` is one
        of ``inputs`` (an input is never overwritten).
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
    if not image:
        return
    out = oiio.ImageOutput.create(name)
    if out is None:
        _oiio_error(oiio)
        ext = os.path.splitext(name)[1] or "(none)"
        raise ImageInputError(f"{name}: unknown output image format for extension {ext}")


def write_image(path: str | os.PathLike[str], image: RasterImage) -> None:
    """Write an image atomically: to a temporary file beside ``path``, then rename.

    An interrupted or failed write leaves no partial file at ``path``.

    Parameters
    ----------
    path : path-like
        The output; its extension picks the format.
    image : RasterImage
        Pixels (H, W, C) and what to carry over (channel names, alpha, its
        convention, metadata).

    Raises
    ------
    ImageIOError
        If OpenImageIO cannot write the file.
    """
    import OpenImageIO as oiio

    name = os.fspath(path)
    check_output_path(name)
    with atomic_path(name) as tmp:
        _write(oiio, tmp, image, shown_name=name)


@contextlib.contextmanager
def atomic_path(path: str):
    """Yield a temporary path beside ``path`` (same extension); on success rename it
    over ``path``, on any failure remove it. Readers never see a partial file."""
    directory = os.path.dirname(os.path.abspath(path))
    base, ext = os.path.splitext(os.path.basename(path))
    fd, tmp = tempfile.mkstemp(prefix=f".{base}.", suffix=f".tmp{ext}", dir=directory)
    os.close(fd)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


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
    spec = oiio.ImageSpec(w, h, nc, type_name)
    if image.channel_names:
        spec.channelnames = tuple(image.channel_names)
    spec.alpha_channel = -1 if image.alpha_channel is None else int(image.alpha_channel)
    if image.alpha_channel is not None and not image.associated_alpha:
        if out.format_name() in _PREMULTIPLIED_FORMATS:
            px = _premultiplied(px, image.alpha_channel)
        else:
            spec.attribute("oiio:UnassociatedAlpha", 1)  # store the straight colour as it is
    for attr_name, attr_type, value in image.attributes:
        try:
            spec.attribute(attr_name, oiio.TypeDesc(attr_type), value)
        except (TypeError, ValueError, RuntimeError):
            continue  # metadata OpenImageIO cannot round-trip is dropped, not fatal
    try:
        if not out.open(filename, spec):
            raise ImageIOError(f"{shown_name}: cannot write: {out.geterror() or _oiio_error(oiio)}")
        if not out.write_image(px):
            raise ImageIOError(f"{shown_name}: cannot write: {out.geterror() or _oiio_error(oiio)}")
    finally:
        out.close()


# Formats whose colour is premultiplied by alpha by definition: straight colour
# must be premultiplied before it is written there (OpenImageIO does not).
_PREMULTIPLIED_FORMATS = ("openexr",)


def _premultiplied(px: NDArray, alpha_channel: int) -> NDArray:
    """Colour multiplied by alpha (0..1), in the pixels' own type."""
    x = to_unit(px)
    colour = [c for c in range(px.shape[2]) if c != alpha_channel]
    x[:, :, colour] *= x[:, :, alpha_channel : alpha_channel + 1]
    return from_unit(x, px.dtype)


def _oiio_error(oiio) -> str:
    """OpenImageIO's pending global error message, on one line."""
    msg = oiio.geterror() or "unknown error"
    return " ".join(msg.split())


def _same_file(a: str, b: str) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.abspath(a) == os.path.abspath(b)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
