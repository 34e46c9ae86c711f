"""Work in a forked child process, for C code that holds the GIL.

The two maps of a warp are independent, but the C code that builds an FEM
map (triangle's meshing, SuperLU's factorization) holds Python's GIL: on
threads the two builds take turns, measured as long as one after the other
(two factorizations of 48k unknowns: 0.44 s serial, 0.47 s on two threads).
A forked child has a GIL of its own, so `Forked` runs one build there while
the parent builds the other: both cores work. The child inherits everything
(modules, data) at no cost, runs one function, sends back its pickled
result and ends with ``os._exit``; what it logs comes back with it and is
logged by the parent when the result is taken, as if logged there.

A child only runs the code it is given: meshing, numpy and SuperLU, which
take no lock another thread of the parent could hold at the fork (the
allocator's locks are reset by the C library, the logging module's by
Python). If it dies (a crash in the C code), the parent gets `ChildDied`
instead of crashing itself.

Used only on Linux, where ``fork`` is cheap and safe for this; ``WARPCLI_FORK=0``
turns it off (the work then runs on a thread, with the same result).
"""

from __future__ import annotations

import logging
import os
import pickle
import signal
import sys
import warnings
from collections.abc import Callable
from typing import Any

#: Environment variable: ``0`` builds on threads only.
FORK_ENV = "WARPCLI_FORK"

_log = logging.getLogger("warpcli")


class ChildDied(Exception):
    """The child ended without a result (killed by a signal, or crashed in C code)."""


def available() -> bool:
    """Whether work may go to a forked child here."""
    return sys.platform.startswith("linux") and hasattr(os, "fork") and os.environ.get(FORK_ENV, "1") != "0"


class Forked:
    """``fn(*args)`` in a forked child; `result` returns or raises what it did.

    ``fn``'s result and any exception it raises must pickle.
    """

    def __init__(self, fn: Callable[..., Any], *args: Any) -> None:
        read_end, write_end = os.pipe()
        with warnings.catch_warnings():
            # Python 3.12 warns of forking a process with threads: the child
            # here touches nothing they could have locked (see the module).
            warnings.simplefilter("ignore", DeprecationWarning)
            try:
                pid = os.fork()
            except OSError:
                os.close(read_end)
                os.close(write_end)
                raise
        if pid == 0:  # the child: never returns
            os.close(read_end)
            _child(fn, args, write_end)
        os.close(write_end)
        self._pid: int | None = pid
        self._fd = read_end
        self._outcome: tuple | None = None

    def result(self) -> Any:
        """Wait for the child; its return value, or the exception it raised (`ChildDied` if it died)."""
        if self._outcome is None:
            chunks = []
            while True:
                data = os.read(self._fd, 1 << 20)  # releases the GIL while it waits
                if not data:
                    break
                chunks.append(data)
            os.close(self._fd)
            status = self._reap()
            try:
                self._outcome = pickle.loads(b"".join(chunks))
            except Exception:
                self._outcome = ("died", _describe(status), [])
        kind, value, records = self._outcome
        self._outcome = (kind, value, [])  # records are logged once
        replay(records)
        if kind == "died":
            raise ChildDied(value)
        if kind == "error":
            raise value
        return value

    def cancel(self) -> None:
        """Stop the child if it still runs (its result is no longer wanted): a `result`
        waiting for it, or called later, raises `ChildDied`."""
        pid = self._pid
        if pid is not None:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass

    def _reap(self) -> int:
        pid, self._pid = self._pid, None
        if pid is None:
            return 0
        while True:
            try:
                return os.waitpid(pid, 0)[1]
            except InterruptedError:
                continue
            except ChildProcessError:
                return 0


def _describe(status: int) -> str:
    if os.WIFSIGNALED(status):
        sig = os.WTERMSIG(status)
        try:
            name = signal.Signals(sig).name
        except ValueError:
            name = f"signal {sig}"
        return f"killed by {name}"
    return f"ended with status {os.WEXITSTATUS(status)} without a result"


class KeptRecords(logging.Handler):
    """Keeps a process's log records as dicts, to be logged by another (`replay`): a
    forked child's, or a worker process's of a pool (`warpcli.batch`)."""

    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.records: list[dict] = []

    def emit(self, record: logging.LogRecord) -> None:
        d = dict(record.__dict__)
        d.update(msg=record.getMessage(), args=None, exc_info=None, exc_text=None)
        self.records.append(d)


def replay(records: list[dict]) -> None:
    """Log, here, records a `KeptRecords` kept in another process, as if logged here."""
    for record in records:
        _log.handle(logging.makeLogRecord(record))


def _child(fn: Callable[..., Any], args: tuple, fd: int) -> None:
    code = 0
    try:
        if "faulthandler" in sys.modules:
            # A crash here is the parent's to report (`ChildDied`), in one line.
            sys.modules["faulthandler"].disable()
        keep = KeptRecords()
        # Records go to the parent, not to the inherited stderr.
        _log.handlers[:] = [keep]
        _log.filters[:] = []
        _log.propagate = False
        try:
            payload = pickle.dumps(("ok", fn(*args), keep.records), protocol=pickle.HIGHEST_PROTOCOL)
        except BaseException as err:  # handed to the parent
            try:
                payload = pickle.dumps(("error", err, keep.records), protocol=pickle.HIGHEST_PROTOCOL)
            except Exception:
                payload = pickle.dumps(("error", RuntimeError(f"{type(err).__name__}: {err}"), keep.records))
        view = memoryview(payload)
        while view:
            view = view[os.write(fd, view) :]
    except BaseException:
        code = 70
    finally:
        os._exit(code)
