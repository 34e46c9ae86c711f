"""Safe output files: paths checked before any work, atomic renames, and a run's outputs renamed together.

Nothing is ever left half written at an output's path. One file is written
under a hidden temporary name beside it (`TEMP_NAME_PATTERN`, `atomic_path`),
flushed to the disk and renamed over it. A run that writes an image, a
report, pictures and maps either leaves all of them or none: each is written
under a pending name (``.NAME.warpcli-pending-XXXXXXXX.EXT``, `PendingOutputs`),
and only when every one has been written are they renamed into place. Both
names are on the output's file system, so the rename is atomic; a failure,
Ctrl-C or SIGTERM removes them, and only a SIGKILL or a power cut leaves
one behind, harmless and safe to delete.
"""

from __future__ import annotations

import contextlib
import errno
import os
import stat
from collections.abc import Iterable, Iterator
from types import TracebackType

from .errors import ImageInputError, ImageIOError, InputError, WarpError
from .files import file_kind, format_bytes

__all__ = [
    "PENDING_MARKER", "TEMP_NAME_GLOB", "TEMP_NAME_PATTERN", "PendingOutputs", "RunInputs", "atomic_path", "check_output_path",
    "check_room", "copy_from_memory", "end_when_consistent", "file_size_limit", "final_path", "memory_file", "output_mode",
    "remove_temporaries", "write_checked", "write_failure_message",
]  # fmt: skip

#: Name of the temporary file an output is written to before it is renamed over
#: the output: hidden, in the output's directory (the same file system, so the
#: rename is atomic), with the output's stem and extension (which picks the
#: format); XXXXXXXX is random. Only a run killed outright (SIGKILL, a power
#: cut) leaves one behind; it is harmless and can be deleted.
TEMP_NAME_PATTERN = ".{stem}.warpcli-tmp-XXXXXXXX{ext}"
#: A shell pattern matching the leftovers: ``find DIR -name '.*.warpcli-tmp-*' -delete``.
TEMP_NAME_GLOB = ".*.warpcli-tmp-*"
#: The marker in the names of pending outputs.
PENDING_MARKER = ".warpcli-pending-"

# Temporary and pending files that exist now, for `remove_temporaries` (a
# SIGTERM ends the process at once, without unwinding: see `warpcli.cli.run`).
_live: set[str] = set()
# Private directories of this process (emptied by the removals above), removed after them.
_live_dirs: set[str] = set()
# While a run's pending outputs are renamed into place (all or none), an end
# asked for by a signal waits until the renames are done.
_renaming = 0
_end_after_renames = None


# Pending paths handed out now, with the outputs they become.
_finals: dict[str, str] = {}


def final_path(path: str | os.PathLike[str]) -> str:
    """The output a pending path (`PendingOutputs.path`) becomes, for messages; any other path as it is.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    str
    """
    name = os.fspath(path)
    return _finals.get(name, name)


#: Names tried before giving up (tempfile.TMP_MAX).
_TMP_MAX = 10000


def _new_temporary(prefix: str, suffix: str, directory: str) -> tuple[int, str]:
    """``tempfile.mkstemp``, with the name in ``_live`` before the file exists (open, 0600).

    With mkstemp the file existed a few bytecodes before it was registered,
    and a SIGTERM handled there (`remove_temporaries`) left it behind. Here a
    signal either finds the name registered (its file then removed, or not
    created yet: the unlink fails harmlessly) or comes before it is chosen.
    """
    for _ in range(_TMP_MAX):
        # secrets.token_hex's bytes (os.urandom), without importing secrets: it imports hmac and
        # OpenSSL's hashlib (3-5 ms), before a warp's map could start.
        name = os.path.join(directory, f"{prefix}{os.urandom(4).hex()}{suffix}")
        _live.add(name)
        try:
            return os.open(name, os.O_RDWR | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o600), name
        except FileExistsError:
            _live.discard(name)  # another file's name: not ours to remove
        except BaseException:
            _live.discard(name)
            raise
    raise FileExistsError(errno.EEXIST, "no temporary name is free", directory)


def remove_temporaries() -> None:
    """Remove every temporary and pending file of this process that still exists.

    Safe in a signal handler: no lock, no allocation of note.
    """
    for names, remove in ((_live, os.unlink), (_live_dirs, os.rmdir)):  # the files first: that empties the folders
        for name in list(names):
            try:
                remove(name)
            except OSError:
                pass
        names.clear()


def check_distinct(outputs: Iterable[tuple[str, str | os.PathLike[str] | None]]) -> None:
    """Refuse two outputs of one run that are one file: the same path however written (``./a`` and
    ``a``, a link to a folder, a ``#`` and a ``%04d`` pattern's same frame), or two names of one
    existing file (a hard link). ``outputs``: (what, path) pairs; None paths are skipped.

    Raises
    ------
    InputError
        Naming the second path, what it is, and the first.
    """
    seen: dict[str, tuple[str, str]] = {}
    files: dict[tuple[int, int], tuple[str, str]] = {}
    for what, path in outputs:
        if path is None or os.fspath(path) == "-":
            continue
        name = os.fspath(path)
        key = os.path.normcase(os.path.realpath(name))
        first = seen.get(key)
        if first is None:
            try:
                st = os.stat(name)
            except OSError:
                st = None
            first = files.get((st.st_dev, st.st_ino)) if st is not None else None
            if st is not None and first is None:
                files[(st.st_dev, st.st_ino)] = (what, name)
        if first is not None:
            raise InputError(f"{name}: the {what} is the same file as the {first[0]} {first[1]}; one would overwrite the other")
        seen[key] = (what, name)


def track_temporary(path: str, *, directory: bool = False, keep: bool = True) -> None:
    """Have `remove_temporaries` remove ``path`` (a file, or an emptied ``directory``) if the process
    ends at once (SIGTERM); ``keep=False``: not any more (the caller removed it)."""
    where = _live_dirs if directory else _live
    if keep:
        where.add(path)
    else:
        where.discard(path)


def end_when_consistent(end) -> None:
    """Call ``end()`` now, or, while pending outputs are being renamed into
    place, as soon as they all are (a run's outputs are all there or none)."""
    global _end_after_renames
    if _renaming:
        _end_after_renames = end
    else:
        end()


def check_output_path(path: str | os.PathLike[str], inputs: tuple[str | os.PathLike[str], ...] | RunInputs = ()) -> None:
    """Check before any work that an output can be written at ``path``.

    Whether its format is one the writer knows is the writer's to check
    (`warpcli.raster.imageio.check_image_output` for images).

    Parameters
    ----------
    path : path-like
    inputs : tuple of path-like, or RunInputs
        Paths that must not be overwritten (a `RunInputs` for many).

    Raises
    ------
    ImageInputError
        If the directory is missing or cannot be written in (read-only, no
        permission), ``path`` exists and is not a regular file (a device, a
        FIFO: it would be replaced), or ``path`` is one of ``inputs`` (an
        input is never overwritten).
    """
    name = os.fspath(path)
    (inputs if isinstance(inputs, RunInputs) else RunInputs(inputs)).check(name)
    directory = os.path.dirname(os.path.abspath(name))
    if not os.path.isdir(directory):
        raise ImageInputError(f"{name}: output directory {directory} does not exist")
    if os.path.isdir(name):
        raise ImageInputError(f"{name}: is a directory")
    _check_replaceable(name)
    if not os.access(directory, os.W_OK | os.X_OK):
        raise ImageInputError(f"{name}: cannot write in {directory}: {_why_unwritable(directory)}")


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[str]:
    """Yield a temporary path beside ``path`` (same extension); on success rename it
    over ``path``, on any failure remove it. Readers never see a partial file.

    The temporary file is named after `TEMP_NAME_PATTERN`. What the body wrote is
    flushed to the disk (fsync) before the rename, and an `OSError` raised by the
    body or by these steps becomes an `ImageIOError` naming ``path`` and the OS's
    reason (an `ImageInputError` when ``path`` cannot be written at all: no
    permission, a read-only file system).

    Parameters
    ----------
    path : path-like
        The output.

    Yields
    ------
    str
        The temporary path to write to, created empty with mode 0600 (given
        `output_mode`'s permissions when renamed: those of the file it
        replaces, else the umask's).

    Raises
    ------
    ImageInputError
        If ``path`` exists and is not a regular file, or cannot be written at all.
    ImageIOError
        If writing, flushing or renaming fails.

    Examples
    --------
    >>> import os, tempfile
    >>> out = os.path.join(tempfile.mkdtemp(), "a.txt")
    >>> with atomic_path(out) as tmp:
    ...     with open(tmp, "w") as fh:
    ...         _ = fh.write("done")
    >>> open(out).read()
    'done'
    """
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    _check_replaceable(path)
    prefix, suffix = _temp_affixes(path, directory)
    try:
        fd, tmp = _new_temporary(prefix, suffix, directory)
        os.close(fd)
    except OSError as err:
        raise _write_error(path, err) from err
    try:
        yield tmp
        _sync_file(tmp)
        os.chmod(tmp, output_mode(path))
        os.replace(tmp, path)
        _live.discard(tmp)
    except BaseException as err:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        _live.discard(tmp)
        if isinstance(err, OSError) and not isinstance(err, WarpError):
            raise _write_error(path, err) from err
        raise
    _sync_directory(directory)


#: Name of a pending output (`PendingOutputs`), as `TEMP_NAME_PATTERN`.
PENDING_NAME_PATTERN = ".{stem}" + PENDING_MARKER + "XXXXXXXX{ext}"


def _temp_affixes(path: str, directory: str, pattern: str = TEMP_NAME_PATTERN) -> tuple[str, str]:
    """mkstemp's prefix and suffix for ``pattern`` (`TEMP_NAME_PATTERN`, `PENDING_NAME_PATTERN`),
    the stem shortened if the name would be too long for the file system: an output's own
    name may be as long as the file system allows."""
    stem, ext = os.path.splitext(os.path.basename(path))
    head, tail = pattern.split("XXXXXXXX")
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


class RunInputs:
    """Every input file of a run, to refuse an output that is any of them.

    A sequence's output frame can be another of its input frames
    (``f.@.png`` -> ``f.1@.png`` with frames 1 and 11); a batch's output
    another of its images; a report the Theta file. Files are compared by
    identity (device and inode: hard links, symbolic links) and by resolved
    path (an input that does not exist yet, a missing frame), in a set, so
    a run of many frames costs one look-up per output.

    Parameters
    ----------
    paths : iterable of path-like
        The run's inputs (images, polygon files, a Theta file, a map).

    Examples
    --------
    >>> import os, tempfile
    >>> d = tempfile.mkdtemp()
    >>> a = os.path.join(d, "a.png"); open(a, "w").close()
    >>> inputs = RunInputs([a, os.path.join(d, "b.png")])
    >>> inputs.find(os.path.join(d, ".", "a.png")) == a
    True
    >>> inputs.find(os.path.join(d, "c.png")) is None
    True
    """

    def __init__(self, paths=()) -> None:
        self._ids: dict[tuple[int, int], str] = {}
        self._paths: dict[str, str] = {}
        for p in paths:
            self.add(p)

    def add(self, path: str | os.PathLike[str]) -> None:
        """Count ``path`` among the inputs."""
        name = os.fspath(path)
        self._paths.setdefault(os.path.realpath(name), name)
        try:
            st = os.stat(name)
        except (OSError, ValueError):
            return
        self._ids.setdefault((st.st_dev, st.st_ino), name)

    def find(self, path: str | os.PathLike[str]) -> str | None:
        """The input that ``path`` is (as the user named it), or None."""
        name = os.fspath(path)
        try:
            st = os.stat(name)
        except (OSError, ValueError):
            pass
        else:
            if (st.st_dev, st.st_ino) in self._ids:
                return self._ids[(st.st_dev, st.st_ino)]
        return self._paths.get(os.path.realpath(name))

    def check(self, path: str | os.PathLike[str]) -> None:
        """Refuse ``path`` as an output if it is one of the inputs.

        Raises
        ------
        ImageInputError
            ``"OUT: output would overwrite the input IN"``.
        """
        other = self.find(path)
        if other is not None:
            raise ImageInputError(f"{os.fspath(path)}: output would overwrite the input {other}")


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def output_mode(path: str | os.PathLike[str]) -> int:
    """The permissions a file written at ``path`` gets, as an ordinary ``open`` would give it.

    mkstemp creates its files 0600; an output renamed from one would stay
    private. A new file gets ``0666 & ~umask``; a file replaced keeps its
    own permissions (as an editor saving it does).

    Parameters
    ----------
    path : path-like
        The output's final path.

    Returns
    -------
    int
        The permission bits.

    Examples
    --------
    >>> import os, tempfile
    >>> out = os.path.join(tempfile.mkdtemp(), "a.txt")
    >>> output_mode(out) == 0o666 & ~_umask()
    True
    >>> open(out, "w").close(); os.chmod(out, 0o640)
    >>> oct(output_mode(out))
    '0o640'
    """
    try:
        st = os.stat(path)
    except OSError:
        return 0o666 & ~_umask()
    if stat.S_ISREG(st.st_mode):
        return stat.S_IMODE(st.st_mode)
    return 0o666 & ~_umask()


def file_size_limit() -> int | None:
    """The largest file this process may write (``ulimit -f``), in bytes, or None if unlimited."""
    try:
        import resource
    except ImportError:
        return None
    soft = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    return None if soft == resource.RLIM_INFINITY else soft


def check_room(filename: str, shown_name: str, nbytes: int, what: str, *, disk: bool = True) -> None:
    """Refuse beforehand a file of up to ``nbytes`` that there may be no room for.

    For writers that cannot report a full disk themselves (libjpeg ends the
    process instead).

    Parameters
    ----------
    filename : str
        Where the file will be written (its file system's free space counts).
    shown_name : str
        The name given in messages (the user's path).
    nbytes : int
        The most the file may take.
    what : str
        The file and its bound, for the message ("a JPEG of 640 x 480 may take up to 1.2 MiB").
    disk : bool
        Whether to check the free space too (not when the file is first
        written to memory, whose copy to the disk reports a full disk).

    Raises
    ------
    ImageIOError
        If ``nbytes`` is over the file size limit (`file_size_limit`) or, with
        ``disk``, over the free space.
    """
    soft = file_size_limit()
    if soft is not None and nbytes > soft:
        raise ImageIOError(
            f"{shown_name}: cannot write: {os.strerror(errno.EFBIG)}: {what}, "
            f"the file size limit (ulimit -f) is {format_bytes(soft)}"
        )
    if not disk:
        return
    try:
        vfs = os.statvfs(os.path.dirname(os.path.abspath(filename)))
    except OSError:
        return
    free = vfs.f_bavail * vfs.f_frsize
    if free < nbytes:
        raise ImageIOError(f"{shown_name}: cannot write: {os.strerror(errno.ENOSPC)}: {what}, {format_bytes(free)} free")


def write_failure_message(shown_name: str, text: str, written: str, filename: str, on_disk: bool) -> str:
    """The message for a failed write: temporary names replaced by the output's,
    and the OS's likely reason added when the library that failed did not give
    one (libpng, libtiff and OpenEXR report no errno).

    Parameters
    ----------
    shown_name : str
        The output's name for the user.
    text : str
        What the writer said.
    written : str
        The file the library wrote (the temporary file, or the in-memory one).
    filename : str
        The temporary file on the output's file system.
    on_disk : bool
        Whether ``written`` is on the output's file system (else in memory).

    Returns
    -------
    str
        ``"{shown_name}: cannot write: ..."``.
    """
    text = text.replace(written, shown_name).replace(filename, shown_name)
    cause = ""
    try:
        limit = file_size_limit()
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


def memory_file(name: str) -> int | None:
    """An anonymous in-memory file that a C library can open by a path
    (``/proc/self/fd/N``), or None where the system has none.

    Parameters
    ----------
    name : str
        A name for debugging (``/proc/self/fd/N`` links to ``/memfd:NAME``).

    Returns
    -------
    int or None
        Its file descriptor (close-on-exec), for the caller to close.
    """
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


def copy_from_memory(src_fd: int, filename: str, shown_name: str) -> int:
    """Copy a file encoded in memory (`memory_file`) to ``filename``, flushed to the disk.

    Written by Python rather than by the C library that encoded it, so that
    every OS error ("No space left on device" first) is an exception.

    Returns
    -------
    int
        The bytes copied.

    Raises
    ------
    ImageIOError
        Naming ``shown_name`` and the OS's reason.
    """
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
        self._pending: list[tuple[str, str, str]] = []  # (pending, final, the user's name for it)

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

        Raises
        ------
        ImageInputError
            If it cannot be created where ``final`` goes (no such directory, no permission).
        ImageIOError
            If creating it fails otherwise.
        """
        name = os.path.abspath(os.fspath(final))
        directory = os.path.dirname(name)
        try:
            fd, tmp = _new_temporary(*_temp_affixes(name, directory, PENDING_NAME_PATTERN), directory)
            os.close(fd)
        except OSError as err:
            raise _write_error(os.fspath(final), err) from err
        _finals[tmp] = os.fspath(final)
        self._pending.append((tmp, name, os.fspath(final)))
        return tmp

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        global _renaming, _end_after_renames
        pending, self._pending = self._pending, []
        for tmp, _, _ in pending:
            _finals.pop(tmp, None)
        if exc_type is None:
            _renaming += 1
            try:
                for k, (tmp, final, shown) in enumerate(pending):
                    os.chmod(tmp, output_mode(final))
                    os.replace(tmp, final)
                    _live.discard(tmp)
            except OSError as err:
                _remove(tmp for tmp, _, _ in pending[k:])
                raise ImageIOError(f"{shown}: cannot move the output into place: {err.strerror or err}") from err
            finally:
                _renaming -= 1
                end, _end_after_renames = _end_after_renames, None
                if end is not None and not _renaming:
                    end()
        else:
            _remove(tmp for tmp, _, _ in pending)
            # Messages name the user's paths, not the pending ones.
            text = str(exc)
            renamed = text
            for tmp, _, shown in pending:
                renamed = renamed.replace(tmp, shown)
            if renamed != text and isinstance(exc, WarpError):
                raise type(exc)(renamed) from exc


def _remove(paths) -> None:
    for tmp in paths:
        _live.discard(tmp)
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
