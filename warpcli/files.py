"""Input files: one regular-file check, bounded reads, and one byte formatter for every reader.

Every reader of a user's file (polygons, keyframes, Theta files, points,
surface meshes, images, volumes) looks before it opens: a FIFO blocks until a
writer comes, ``/dev/zero`` never ends, a directory is not a file. The
message names the file and what it is, through the caller's own error type.
"""

from __future__ import annotations

import os
import stat

from .errors import InputError

__all__ = ["check_regular_file", "file_kind", "format_bytes", "read_small_file"]


def format_bytes(n: float) -> str:
    """A byte count for people, in binary units.

    Examples
    --------
    >>> format_bytes(900), format_bytes(64 << 20), format_bytes(7.5 * 2**30), format_bytes(20 * 2**30)
    ('900 bytes', '64 MiB', '7.5 GiB', '20 GiB')
    """
    for unit, size in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= size:
            return f"{n / size:.1f} {unit}" if n < 10 * size else f"{n / size:.0f} {unit}"
    return f"{int(n)} bytes"


def file_kind(mode: int) -> str:
    """What a file of this ``st_mode`` is, for a message: 'a directory', 'a FIFO (named pipe)', ..."""
    for test, kind in (
        (stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"), (stat.S_ISREG, "a regular file"),
    ):  # fmt: skip
        if test(mode):
            return kind
    return "a special file"


def _check_stat(name: str, st: os.stat_result, what: str, error: type[InputError], max_bytes: int | None) -> None:
    if not stat.S_ISREG(st.st_mode):
        raise error(f"{name}: cannot read {what}: it is {file_kind(st.st_mode)}, not a regular file")
    if max_bytes is not None and st.st_size > max_bytes:
        raise error(
            f"{name}: {what} is too large: {format_bytes(st.st_size)}, more than the limit of {format_bytes(max_bytes)}"
        )


def _refuse(name: str, what: str, error: type[InputError], err: OSError) -> InputError:
    if isinstance(err, FileNotFoundError):
        return error(f"{name}: no such file")
    return error(f"{name}: cannot read {what}: {err.strerror or err}")


def check_regular_file(
    path: str | os.PathLike[str], what: str, error: type[InputError] = InputError, *, max_bytes: int | None = None
) -> int:
    """Refuse, before anything opens it, a path that is not a regular file (or is larger than ``max_bytes``).

    For readers that open the file themselves (OpenImageIO, nibabel,
    tifffile); `read_small_file` also checks the file it has opened.

    Parameters
    ----------
    path : path-like
    what : str
        What the file should be, for the message ("image", "polygon file").
    error : subclass of InputError
        The error to raise (`PolygonError`, `ImageInputError`, ...).
    max_bytes : int or None
        The largest size accepted.

    Returns
    -------
    int
        The file's size in bytes.

    Raises
    ------
    InputError
        Of type ``error``, naming the file: missing, unreadable, not a
        regular file (saying what it is), or too large.
    """
    name = os.fspath(path)
    if "\0" in name:  # os.stat would raise a ValueError
        raise error(f"{name!r}: cannot read {what}: embedded null byte")
    try:
        st = os.stat(name)
    except OSError as err:
        raise _refuse(name, what, error, err) from None
    _check_stat(name, st, what, error, max_bytes)
    return st.st_size


def read_small_file(
    path: str | os.PathLike[str], what: str, error: type[InputError] = InputError, *, max_bytes: int
) -> bytes:
    """The bytes of a regular file of at most ``max_bytes``, without blocking on anything else.

    Parameters
    ----------
    path : path-like
    what : str
        What the file should be, for messages ("polygon file").
    error : subclass of InputError
        The error to raise.
    max_bytes : int
        The largest size read; a file that grows past it while read is refused too.

    Returns
    -------
    bytes

    Raises
    ------
    InputError
        Of type ``error``, as `check_regular_file` says, or if reading fails.
    """
    name = os.fspath(path)
    check_regular_file(name, what, error, max_bytes=max_bytes)
    try:
        # O_NONBLOCK in case the path became a FIFO since the look: open then
        # returns at once (it changes nothing for a regular file).
        fd = os.open(name, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0))
    except OSError as err:
        raise _refuse(name, what, error, err) from None
    try:
        _check_stat(name, os.fstat(fd), what, error, max_bytes)
        chunks = []
        size = 0
        while size <= max_bytes:
            chunk = os.read(fd, min(1 << 24, max_bytes + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as err:
        raise _refuse(name, what, error, err) from None
    finally:
        os.close(fd)
    if size > max_bytes:  # it grew since fstat
        raise error(f"{name}: {what} is too large: over {format_bytes(max_bytes)}")
    return b"".join(chunks)
