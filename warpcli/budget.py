"""The memory budget: how many bytes of pixels warpcli may hold, and refusing more before allocating it."""

from __future__ import annotations

import math
import os
import sys

from .errors import ImageInputError
from .files import format_bytes

__all__ = [
    "MAX_COMPRESSION", "MAX_IMAGE_BYTES_ENV", "MEMORY_FRACTION", "check_declared_size", "check_fits", "max_image_bytes",
]  # fmt: skip

#: Environment variable: the most bytes of pixels warpcli will hold for one
#: image (read, or made with ``--size``), overriding the default limit.
MAX_IMAGE_BYTES_ENV = "WARPCLI_MAX_IMAGE_BYTES"
#: The default limit: this share of the memory available (Linux's MemAvailable,
#: within a cgroup's limit; elsewhere the free physical memory), leaving the
#: rest for the warp's working arrays.
MEMORY_FRACTION = 0.5
#: The most decoded bytes per byte of file a compressed image may declare:
#: zlib (PNG, TIFF, OpenEXR, .nii.gz) compresses at most about 1032 to 1.
MAX_COMPRESSION = 1100


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


def check_fits(
    width: int, height: int, channels: int, bytes_per_value: int, what: str, *, copies: int = 1, why: str = ""
) -> None:
    """Refuse, before allocating it, an image too large for this machine's memory.

    Parameters
    ----------
    width, height, channels : int
    bytes_per_value : int
        1 for uint8, 2 for uint16 and half, 4 for float, ...
    what : str
        What the size comes from: a file name, or an option such as
        ``"--size 100000x100000"``. The message starts with it.
    copies : int
        How many copies of the image are held at once.
    why : str
        Why there are several copies, for the message ("to apply the orientation").

    Raises
    ------
    ImageInputError
        If ``width * height * channels * bytes_per_value * copies`` is more
        than `max_image_bytes` (``WARPCLI_MAX_IMAGE_BYTES``, else half the
        available memory), with the size and the memory it needs; or if a
        size is negative.

    Examples
    --------
    >>> check_fits(640, 480, 3, 1, "in.png")  # 0.9 MB: fits
    """
    width, height, channels, nbytes = (int(d) for d in (width, height, channels, bytes_per_value))
    if min(width, height, channels, nbytes) < 0:
        raise ImageInputError(f"{what}: invalid image size {width} x {height} x {channels} channels")
    need = math.prod((width, height, channels, nbytes, copies))
    limit = max_image_bytes()
    if need > limit:
        unit = "byte" if nbytes == 1 else "bytes"
        several = f" ({copies} copies{', ' + why if why else ''})" if copies > 1 else ""
        source = MAX_IMAGE_BYTES_ENV if os.environ.get(MAX_IMAGE_BYTES_ENV, "").strip() else (
            f"{MEMORY_FRACTION:.0%} of the available memory; set {MAX_IMAGE_BYTES_ENV} to change it"
        )
        shown_need, shown_limit = format_bytes(need), format_bytes(limit)
        if shown_need == shown_limit:  # rounded alike: give them exactly
            shown_need, shown_limit = f"{need} bytes", f"{limit} bytes"
        raise ImageInputError(
            f"{what}: a {width} x {height} image of {channels} channel(s) x {nbytes} {unit} needs "
            f"{shown_need} of memory{several}, more than the {shown_limit} warpcli may use ({source})"
        )


def check_declared_size(path: str | os.PathLike[str], decoded: int, what: str, *, ratio: float = MAX_COMPRESSION) -> None:
    """Refuse, from its header and before decoding it, a file that declares far
    more data than it could hold (a decompression bomb or a corrupt header).

    Parameters
    ----------
    path : path-like
        The file; its size on disk is what the header is checked against.
    decoded : int
        The bytes of data its header declares.
    what : str
        What is declared, for the message ("16 x 16 x 4096 voxels of float32").
    ratio : float
        The most decoded bytes per byte of file: `MAX_COMPRESSION` for a
        compressed file, 1 for one stored raw.

    Raises
    ------
    ImageInputError
        If ``decoded`` is more than ``ratio`` times the file's size.
    """
    size = max(os.stat(path).st_size, 1)
    if decoded > ratio * size:
        how = "more than any compression gives" if ratio > 1 else "more than the file holds"
        raise ImageInputError(
            f"{os.fspath(path)}: declares {what} ({format_bytes(decoded)}) in a file of {format_bytes(size)}, "
            f"{how}: refused before reading (truncated, corrupt or a decompression bomb)"
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
