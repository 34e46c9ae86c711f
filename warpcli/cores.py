"""The run's core budget: how many cores a run may keep busy (``--jobs N``).

Farms and batch scripts give a job N cores and expect it to keep at most N
busy. Every parallel path of warpcli reads the budget here, and nowhere
else: the kernels' threads (`warpcli._native.parallel`), the forked child
that builds one of a warp's two maps beside the other
(`warpcli._fork.available`) and the thread that builds it otherwise
(`warpcli.maps.compose.Task`), the threads of a batch and the processes of
an animated sequence (`warpcli.batch`). So do the libraries' own thread
pools: OpenImageIO's and OpenEXR's (``OPENIMAGEIO_OPTIONS`` before it is
imported, ``OpenImageIO.attribute`` after), BLAS's (threadpoolctl, and
``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS``, ``MKL_NUM_THREADS`` for
libraries loaded later) and numba's (``NUMBA_NUM_THREADS``).

The default is the cores this process may run on (`available`: the CPU
affinity, so ``taskset`` and a batch system's cgroup are honoured), and
leaves the libraries' settings as they are. A budget of 1 is strictly one
core: no thread or child process does work beside the caller's, and the
libraries run on the calling thread. N > 1 keeps every parallel path, each
capped at N threads or processes. Output bytes and messages do not depend
on the budget.

The budget belongs to the process (threads and forked children share it,
spawned workers are given it): set it with `set_jobs`, or for a block with
``with jobs(N):``. The library's ``jobs=`` parameters (`warpcli.warp_batch`,
`warpcli.warp_sequence`) set it for their call; calls from several threads
with different budgets at once are not supported (the last one set wins).
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
from collections.abc import Iterator

__all__ = ["available", "budget", "jobs", "set_jobs"]

#: Environment variables read by thread pools when their library is loaded.
_THREAD_ENV = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")
_OIIO_ENV = "OPENIMAGEIO_OPTIONS"

_lock = threading.RLock()
_budget: int | None = None  # None: `available`
# What `set_jobs` changed, to put back when the default returns: the environment's
# values, OpenImageIO's attributes, threadpoolctl's limiter.
_saved_env: dict[str, str | None] | None = None
_saved_oiio: tuple[int, int] | None = None
_blas_limiter = None
_applied = False  # OpenImageIO's options were in the environment since the default was last in force


def available() -> int:
    """The CPU cores this process may run on (its affinity; at least 1)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def budget() -> int:
    """The cores this run may keep busy: `set_jobs`'s value, else `available`."""
    n = _budget
    return available() if n is None else n


def explicit() -> int | None:
    """The budget `set_jobs` set, or None for the default."""
    return _budget


def check_jobs(n: object) -> int | None:
    """``n`` if it is None or a whole number of at least 1.

    Raises
    ------
    InputError
        Otherwise, in one line.
    """
    if n is None or (isinstance(n, int) and not isinstance(n, bool) and n >= 1):
        return n  # type: ignore[return-value]
    from .errors import InputError

    raise InputError(f"jobs must be a whole number of at least 1, got {n!r}")


def set_jobs(n: int | None, *, pools: bool = True) -> None:
    """Let this process keep at most ``n`` cores busy from now on; None: the default (`available`).

    Parameters
    ----------
    n : int or None
        At least 1; 1 is strictly one core (no threads, no child processes,
        the libraries' pools on one thread).
    pools : bool
        Also size the libraries' thread pools (OpenImageIO, OpenEXR, BLAS).
        False in a forked child, whose copies of those pools must not be
        touched (their threads were not forked).

    Raises
    ------
    InputError
        If ``n`` is not None or a whole number of at least 1.

    Examples
    --------
    >>> import warpcli
    >>> warpcli.set_jobs(1)     # from here on: one core, as ``warp --jobs 1``
    >>> warpcli.set_jobs(None)  # every core the process may use again
    """
    global _budget
    n = check_jobs(n)
    with _lock:
        if n == _budget:
            return
        _budget = n
        if pools:
            _apply_libraries(n)


@contextlib.contextmanager
def jobs(n: int | None) -> Iterator[int]:
    """``with jobs(n):`` the budget is ``n`` in the block, the previous one after.

    Parameters
    ----------
    n : int or None
        At least 1 (1: strictly one core); None leaves the budget as it is.

    Returns
    -------
    context manager
        Entered, it gives the budget in the block (an int).

    Examples
    --------
    >>> import warpcli
    >>> with warpcli.jobs(1):  # one core: no threads, no child processes
    ...     pass               # warp_image(...), warp_file(...), build_map(...)
    """
    n = check_jobs(n)
    if n is None or n == _budget:
        yield budget()
        return
    before = _budget
    set_jobs(n)
    try:
        yield n
    finally:
        set_jobs(before)


def _apply_libraries(n: int | None) -> None:
    """The libraries' thread pools to ``n`` threads (None: as they were before the first budget)."""
    global _saved_env, _saved_oiio, _blas_limiter, _applied
    if n is not None and _saved_env is None:
        _saved_env = {name: os.environ.get(name) for name in (*_THREAD_ENV, _OIIO_ENV)}
    if _saved_env is not None:
        for name, value in _saved_env.items():
            if n is not None and name in _THREAD_ENV:
                value = str(n)
            elif n is not None:  # OpenImageIO's options, read when it is imported
                value = ",".join(filter(None, (value, *_oiio_options(n))))
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
        if n is None:
            _saved_env = None
    oiio = sys.modules.get("OpenImageIO")
    if oiio is not None:  # already imported: its attributes
        if n is not None and _saved_oiio is None and not _applied:  # its own settings, not a budget's
            _saved_oiio = (oiio.get_int_attribute("threads"), oiio.get_int_attribute("exr_threads"))
        if n is not None:
            for option in _oiio_options(n):
                name, value = option.split("=")
                oiio.attribute(name, int(value))
        elif _saved_oiio is not None or _applied:
            # Imported after a budget was set: from its options; 0 is OpenImageIO's default for both.
            threads, exr = _saved_oiio if _saved_oiio is not None else (0, 0)
            oiio.attribute("threads", threads)
            oiio.attribute("exr_threads", exr)
            _saved_oiio = None
    _applied = n is not None
    if _blas_limiter is not None:
        _blas_limiter.restore_original_limits()
        _blas_limiter = None
    # BLAS libraries loaded already; one loaded while a budget was in force took its
    # thread count from the environment then, and keeps it (its default is not known here).
    if n is not None and "numpy" in sys.modules:
        from threadpoolctl import threadpool_limits

        _blas_limiter = threadpool_limits(limits=n)


def _oiio_options(n: int) -> tuple[str, str]:
    # exr_threads -1: OpenEXR without its pool (0 would give it `threads`' count).
    return f"threads={n}", f"exr_threads={-1 if n == 1 else n}"
