"""An image's size from the first bytes of its file, without OpenImageIO: a guess to start work early.

``warp`` builds its map from the image's size alone, in forked children
(`warpcli.pipeline`). OpenImageIO takes 25-40 ms to import, and only then
could its header be read and the children be forked; a PNG states its size
at a fixed place (the IHDR chunk, the first, bytes 16-24), so the children
can start first and mesh and solve while OpenImageIO loads and decodes.

What this returns is only a guess: the caller checks it against
OpenImageIO's own header (`warpcli.raster.imageio.read_header`) and throws
the work away if they differ (an EXIF orientation turns the picture; a file
damaged past its header is refused there, with OpenImageIO's message).
Anything this does not read as a well-formed PNG header (another format, a
short or damaged file, a size libpng refuses) gives None: no guess.
"""

from __future__ import annotations

import os
import struct
import zlib

__all__ = ["PNG_SIGNATURE", "parse_png_header", "png_size"]

#: The 8 bytes every PNG file starts with.
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

#: Colour type -> bit depths the PNG specification allows with it (§11.2.2).
_DEPTHS = {0: (1, 2, 4, 8, 16), 2: (8, 16), 3: (1, 2, 4, 8), 4: (8, 16), 6: (8, 16)}

#: Colour type -> channels.
_CHANNELS = {0: 1, 2: 3, 3: 3, 4: 2, 6: 4}

#: libpng's default limit on width and height (PNG_USER_WIDTH_MAX, PNG_USER_HEIGHT_MAX).
_LIBPNG_MAX_SIDE = 1_000_000


def png_size(path: str | os.PathLike[str]) -> tuple[int, int, int] | None:
    """``(width, height, channels)`` a PNG file's header states, or None if ``path`` does not start like a valid PNG.

    ``channels`` is what the colour type gives (grey 1, grey and alpha 2,
    RGB and palette 3, RGBA 4); a tRNS chunk further on adds an alpha channel
    when OpenImageIO reads it.

    Reads 33 bytes of a regular file (a FIFO or a device is not opened: it
    could block or never end): the signature, then an IHDR chunk of 13 bytes
    whose CRC matches, with a size of 1 to 1,000,000 pixels a side (libpng's
    default limits), a valid colour type and bit depth for it, and the only
    compression, filter and interlace methods the specification defines.

    Examples
    --------
    >>> import io, struct, zlib
    >>> body = b"IHDR" + struct.pack(">IIBBBBB", 640, 480, 8, 2, 0, 0, 0)
    >>> head = PNG_SIGNATURE + struct.pack(">I", 13) + body + struct.pack(">I", zlib.crc32(body))
    >>> parse_png_header(head)
    (640, 480, 3)
    """
    import stat

    name = os.fspath(path)
    try:
        fd = os.open(name, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except (OSError, ValueError):
        return None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return None
        head = os.pread(fd, 33, 0) if hasattr(os, "pread") else os.read(fd, 33)
    except OSError:
        return None
    finally:
        os.close(fd)
    return parse_png_header(head)


def parse_png_header(head: bytes) -> tuple[int, int, int] | None:
    """`png_size` of the first bytes of a file (at least 33 for a size)."""
    if len(head) < 33 or head[:8] != PNG_SIGNATURE:
        return None
    length, kind = struct.unpack(">I4s", head[8:16])
    if length != 13 or kind != b"IHDR":
        return None
    body = head[12:29]
    if zlib.crc32(body) != struct.unpack(">I", head[29:33])[0]:
        return None
    width, height, depth, colour, compression, filtering, interlace = struct.unpack(">IIBBBBB", head[16:29])
    if not (0 < width <= _LIBPNG_MAX_SIDE and 0 < height <= _LIBPNG_MAX_SIDE):
        return None
    if depth not in _DEPTHS.get(colour, ()) or compression != 0 or filtering != 0 or interlace not in (0, 1):
        return None
    return width, height, _CHANNELS[colour]
