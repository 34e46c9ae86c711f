"""Outputs of one run: written under hidden pending names, renamed into place together.

A run that writes an image, a report, pictures and maps either leaves all of
them or none: each is written to a temporary file beside its destination
(``.NAME.warpcli-pending-XXXXXXXX.EXT``, hidden, on the same file system so the
rename is atomic), and only when every one has been written are they renamed
into place. A failure, Ctrl-C or SIGTERM removes them; after a SIGKILL, files
matching that pattern are leftovers and can be deleted.
"""

from __future__ import annotations

import os
import tempfile
from types import TracebackType

from .errors import ImageIOError, WarpError

#: The marker in the names of pending outputs.
PENDING_MARKER = ".warpcli-pending-"


class PendingOutputs:
    """A context manager handing out pending paths for a run's outputs.

    Examples
    --------
    >>> import os, tempfile
    >>> d = tempfile.mkdtemp()
    >>> with PendingOutputs() as out:
    ...     with open(out.path(os.path.join(d, "a.txt")), "w") as fh:
    ...         _ = fh.write("done")
    >>> sorted(os.listdir(d))
    ['a.txt']
    """

    def __init__(self) -> None:
        self._pending: list[tuple[str, str]] = []

    def __enter__(self) -> PendingOutputs:
        return self

    def path(self, final: str | os.PathLike[str]) -> str:
        """A pending path for ``final`` (same directory and extension), created empty.

        Parameters
        ----------
        final : path-like
            Where the output goes when the run succeeds.

        Returns
        -------
        str
            The path to write it to now.
        """
        name = os.path.abspath(os.fspath(final))
        directory, base = os.path.split(name)
        stem, ext = os.path.splitext(base)
        fd, tmp = tempfile.mkstemp(prefix=f".{stem}{PENDING_MARKER}", suffix=ext, dir=directory)
        os.close(fd)
        self._pending.append((tmp, name))
        return tmp

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        pending, self._pending = self._pending, []
        if exc_type is None:
            try:
                for k, (tmp, final) in enumerate(pending):
                    os.replace(tmp, final)
            except OSError as err:
                _remove(tmp for tmp, _ in pending[k:])
                raise ImageIOError(f"{final}: cannot move the output into place: {err.strerror or err}") from err
        else:
            _remove(tmp for tmp, _ in pending)
            # Messages name the user's paths, not the pending ones.
            text = str(exc)
            renamed = text
            for tmp, final in pending:
                renamed = renamed.replace(tmp, final)
            if renamed != text and isinstance(exc, WarpError):
                raise type(exc)(renamed) from exc


def _remove(paths) -> None:
    for tmp in paths:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass


def write_checked(path: str, data: bytes, shown_name: str | os.PathLike[str] | None = None) -> None:
    """Write bytes and make sure they reached the disk (a full disk is an error, not a success).

    Raises
    ------
    ImageIOError
        Naming ``shown_name`` (else ``path``) and the system's reason.
    """
    try:
        with open(path, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
    except OSError as err:
        raise ImageIOError(f"{os.fspath(shown_name or path)}: cannot write: {err.strerror or err}") from err
