"""What C libraries print on stderr: kept off the terminal and folded, with their error texts, into one line."""

from __future__ import annotations

import contextlib
import io
import os
import re
import sys
import threading
from collections.abc import Iterator

__all__ = ["Captured", "c_stderr", "one_line", "stderr_apart", "stderr_fd", "terminal_saved"]


class Captured:
    """What C code wrote to stderr during a `c_stderr` block (set on leaving it).

    Attributes
    ----------
    text : str
        At most 64 KiB of it, decoded as UTF-8 ("" while the block runs).
    """

    text = ""


_CAPTURE_LOCK = threading.Lock()
_CAPTURE_MAX = 1 << 16

#: Copies of the real file descriptor 2 kept while it points elsewhere (the
#: innermost last): a signal handler that ends the process writes its line
#: there, or it would land in the capture and be lost (`stderr_fd`).
_TERMINAL: list[int] = []


def stderr_fd() -> int:
    """The file descriptor of the real stderr: 2, or its saved copy while C output is captured.

    For a line written with ``os.write`` from a signal handler (SIGTERM ends
    the run at once, `warpcli.cli.run`): a `c_stderr` block or TetGen's quiet
    run may have file descriptor 2 pointing into a capture at that moment.
    """
    return _TERMINAL[-1] if _TERMINAL else 2


def stderr_apart() -> None:
    """Give Python's ``sys.stderr`` a file descriptor of its own: a duplicate of 2 (the ``warp`` command's set-up).

    `c_stderr` points file descriptor 2 into a capture while a C library reads
    or writes an image, on whichever thread does so. A line Python wrote to
    stderr meanwhile from another thread (a batch's error for one input while a
    worker writes the next output) landed in that capture and was lost: 40 %
    of the runs of a batch with one bad input said nothing about it. On its
    own descriptor, Python's stderr reaches the terminal whatever 2 points to;
    what C code prints on 2 is still captured. `stderr_fd` names the duplicate
    too. A library user's process is not changed: only the command calls this.
    Nothing happens if stderr is not file descriptor 2 (redirected in-process,
    closed, or None).
    """
    old = sys.stderr
    try:
        if old is None or old.fileno() != 2:
            return
        old.flush()
        fd = os.dup(2)
    except (OSError, ValueError, AttributeError, io.UnsupportedOperation):
        return
    sys.stderr = io.TextIOWrapper(
        io.FileIO(fd, "w"), encoding=old.encoding, errors=old.errors, line_buffering=True, write_through=True
    )
    _TERMINAL.insert(0, fd)


@contextlib.contextmanager
def terminal_saved(copy: int) -> Iterator[None]:
    """Within the block, `stderr_fd` is ``copy``: a duplicate of the real file descriptor 2
    made before 2 was pointed elsewhere (close ``copy`` only after the block)."""
    _TERMINAL.append(copy)
    try:
        yield
    finally:
        _TERMINAL.remove(copy)


@contextlib.contextmanager
def c_stderr() -> Iterator[Captured]:
    """Keep what C libraries write to file descriptor 2 off the terminal.

    libpng, for one, prints "libpng error: ..." itself before OpenImageIO
    reports the error; the CLI must show its one line only. The text is kept
    (``.text`` of the yielded object) to fold into an error message, and is
    dropped when the call succeeds. One block at a time: a block entered while
    another is open (another thread) does not redirect again.

    Yields
    ------
    Captured
        Whose ``text`` is set when the block ends.
    """
    said = Captured()
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
            _TERMINAL.append(saved)
            os.dup2(sink.fileno(), 2)
        except (OSError, ValueError):
            if saved is not None:
                _TERMINAL.remove(saved)
                os.close(saved)
                saved = None
        yield said
    finally:
        try:
            if saved is not None:
                os.dup2(saved, 2)
                _TERMINAL.remove(saved)
                os.close(saved)
                sink.seek(0)
                said.text = sink.read(_CAPTURE_MAX).decode("utf-8", "replace")
            if sink is not None:
                sink.close()
        finally:
            _CAPTURE_LOCK.release()


def _anonymous_file(name: str):
    """A binary read-write file with no name on any disk (in memory where the system can)."""
    if hasattr(os, "memfd_create"):
        try:
            return os.fdopen(os.memfd_create(name, os.MFD_CLOEXEC), "w+b")
        except OSError:
            pass
    import tempfile  # (shutil, random, bz2, lzma: 5 ms, for systems without memfd only)

    return tempfile.TemporaryFile()


# Prefixes the C libraries put on their own lines, ignored when comparing them
# with OpenImageIO's, which usually repeat them.
_LIB_PREFIX = re.compile(r"^(lib\w+|\w+ library)\s+(error|warning)\s*:\s*", re.I)


def one_line(*texts: str | None, limit: int = 400, default: str = "unknown error") -> str:
    """Error texts (OpenImageIO's, several lines; what C code printed) on one
    line, without lines that only repeat another, or another but for numbers.

    Parameters
    ----------
    *texts : str or None
        Joined in this order; None and "" are skipped.
    limit : int
        The most characters returned (a longer text ends in "...").
    default : str
        What to return when every text is empty.

    Returns
    -------
    str

    Examples
    --------
    >>> one_line("Read error: end of file\\nPNG read error: IDAT: Read error: end of file", "libpng error: IDAT: Read error: end of file")
    'PNG read error: IDAT: Read error: end of file'
    >>> one_line("Write error at 10\\nWrite error at 20\\nWrite error at 30")
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
