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

import collections
import contextvars
import logging
import mmap
import os
import pickle
import signal
import struct
import sys
import threading
import warnings
import weakref
from collections.abc import Callable
from typing import Any

#: Environment variable: ``0`` builds on threads only.
FORK_ENV = "WARPCLI_FORK"

_log = logging.getLogger("warpcli")


class ChildDied(Exception):
    """The child ended without a result (killed by a signal, or crashed in C code)."""


def possible() -> bool:
    """Whether a child may be forked here at all: on Linux, and not turned off (``WARPCLI_FORK=0``).
    Enough for work kept apart from the process (a C library that may crash it)."""
    return sys.platform.startswith("linux") and hasattr(os, "fork") and os.environ.get(FORK_ENV, "1") != "0"


def available() -> bool:
    """Whether work may go to a forked child to run beside its parent: `possible`, with a
    core budget of more than one (`warpcli.cores`)."""
    from .cores import budget

    return possible() and budget() > 1


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
        _CHILDREN.add(pid)
        self._fd = read_end
        self._outcome: tuple | None = None
        brood = _BROOD.get()
        if brood is not None:
            brood.add(self)

    def result(self) -> Any:
        """Wait for the child; its return value, or the exception it raised (`ChildDied` if it died)."""
        if self._outcome is None:
            outcome = _receive(self._fd)
            os.close(self._fd)
            if outcome is None:
                self._outcome = ("died", _describe(self._reap()), [])
            else:
                # The whole result is here: the child only ends now (``os._exit``, which
                # unmaps its memory: 3-7 ms at 1 MP), and that is not waited for.
                self._reap_later()
                self._outcome = outcome
        kind, value, records = self._outcome
        self._outcome = (kind, value, [])  # records are logged once
        return _unpack(kind, value, records)

    def cancel(self) -> None:
        """Stop the child if it still runs (its result is no longer wanted): a `result`
        waiting for it, or called later, raises `ChildDied`."""
        pid = self._pid
        if pid is not None:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            _killed(pid)

    def _reap_later(self) -> None:
        """Reap the child when it has ended, on a thread of its own (it is ending: its result
        was read whole), so that its exit status is collected and no zombie stays behind."""
        pid, self._pid = self._pid, None
        if pid is None:
            return
        _CHILDREN.discard(pid)
        try:
            if os.waitpid(pid, os.WNOHANG)[0]:
                return  # ended already
        except ChildProcessError:
            return
        threading.Thread(target=_wait_for, args=(pid,), name="warp-reap", daemon=True).start()

    def _reap(self) -> int:
        pid, self._pid = self._pid, None
        if pid is None:
            return 0
        _CHILDREN.discard(pid)
        while True:
            try:
                return os.waitpid(pid, 0)[1]
            except InterruptedError:
                continue
            except ChildProcessError:
                return 0


def _killed(pid: int) -> None:
    """Child ``pid`` was killed: if it was compiling a kernel, it no longer is (`warpcli._native.compiling`)."""
    native = sys.modules.get("warpcli._native")
    if native is not None:
        native.process_gone(pid)


def _wait_for(pid: int) -> None:
    """Reap child ``pid`` once it ends (`Forked._reap_later`)."""
    while True:
        try:
            os.waitpid(pid, 0)
            return
        except InterruptedError:
            continue
        except ChildProcessError:
            return


class Brood:
    """The children `Forked` in a context (`watching`), to stop them all when their work is not wanted.

    A caller that starts work which may fork (a map built on a thread while
    the image is read: `warpcli.pipeline`) and may then find it unwanted (the
    image cannot be read, or its size is not the one guessed) kills the
    children with `cancel`, so that none computes on after the run has ended;
    a child forked after that is killed at once. Whoever waits for a child's
    result gets `ChildDied` (and reaps it), as for any killed child.
    """

    def __init__(self) -> None:
        self._lock = threading.Condition()
        self._children: list[Forked] = []
        self._forked = 0
        self.cancelled = False

    def add(self, child: Forked) -> None:
        with self._lock:
            self._forked += 1
            self._lock.notify_all()
            if not self.cancelled:
                self._children.append(child)
                return
        child.cancel()

    def wait(self, count: int, timeout: float) -> bool:
        """Wait until ``count`` children were forked, at most ``timeout`` seconds; whether they were."""
        with self._lock:
            return self._lock.wait_for(lambda: self._forked >= count, timeout)

    def cancel(self) -> None:
        """Kill every child forked so far; later ones are killed as they are forked."""
        with self._lock:
            self.cancelled = True
            children, self._children = self._children, []
        for child in children:
            child.cancel()


#: The `Brood` that children forked in this context join (None: none).
_BROOD: contextvars.ContextVar[Brood | None] = contextvars.ContextVar("warpcli_brood", default=None)


def watching(brood: Brood) -> contextvars.Context:
    """A copy of the current context in which every `Forked` child joins ``brood``
    (run work in it with ``context.run``; threads it starts with `warpcli.maps.compose.Task` inherit it)."""
    context = contextvars.copy_context()
    context.run(_BROOD.set, brood)
    return context


def _receive(fd: int, shared: SharedMemory | None = None, region: int | None = None) -> tuple | None:
    """What `_respond` wrote to ``fd`` (and to ``shared``'s ``region``): (kind, value, records),
    or None if the writer ended first."""
    try:
        sizes, places = _read_header(fd)
        parts: list[Any] = []
        block = _Block(sizes[1:], places[1:])
        for k, (n, place) in enumerate(zip(sizes, places)):
            if place == _IN_PIPE:
                # The arrays' memory: each part is read once, in place.
                parts.append(bytearray(n) if k == 0 else block.take(n))
                _read_into(fd, parts[-1])
            elif shared is None or region is None:
                raise ValueError("a part in shared memory that was not lent")
            else:  # the arrays' memory is the region's: no copy
                parts.append(shared.view(region, place, n))
        return pickle.loads(parts[0], buffers=parts[1:])
    except Exception:
        return None


class _Block:
    """One allocation for the arrays of a result that come through the pipe, cut in parts.

    Each in a bytearray of its own, the 7-8 MB of a 1 MP map took one page fault
    per 4 KiB as they were read (10-14 ms in a fresh process, 2.5 ms warm); in
    one numpy array of 4 MiB or more, which numpy asks the kernel to back with
    huge pages (``madvise``), 1.5 ms: between the last child's end and the pull-back.
    """

    def __init__(self, sizes: list[int], places: list[int]) -> None:
        import numpy as np

        total = sum(-(-n // _ALIGN) * _ALIGN for n, place in zip(sizes, places) if place == _IN_PIPE)
        self._memory = np.empty(total, dtype=np.uint8)
        self._used = 0

    def take(self, n: int) -> Any:
        """The next ``n`` bytes (at a multiple of `_ALIGN`)."""
        part = self._memory[self._used : self._used + n]
        self._used += -(-n // _ALIGN) * _ALIGN
        return part


def _unpack(kind: str, value: Any, records: list[dict]) -> Any:
    replay(records)
    if kind == "died":
        raise ChildDied(value)
    if kind == "error":
        raise value
    return value


#: The parent's ends of its workers' pipes: a child forked later closes its copies, else a
#: worker would never see the end of its requests (a copy of their write end lives on).
_WORKER_FDS: set[int] = set()


#: The pids of this process's children not yet reaped (`Forked`, `Worker`): `kill_children`'s.
_CHILDREN: set[int] = set()


def kill_children() -> None:
    """Kill every child this process forked and has not reaped: for a run that ends at once.

    `warpcli.cli.run`'s SIGTERM handler ends the process without unwinding;
    a SIGTERM sent to the process alone (``kill PID``) does not reach its
    children, which would otherwise compute on, a map or a frame, after the
    run has ended. Safe in a signal handler: no lock.
    """
    for pid in list(_CHILDREN):
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass


def _close_inherited() -> None:
    for fd in list(_WORKER_FDS):
        try:
            os.close(fd)
        except OSError:
            pass
    _WORKER_FDS.clear()
    _CHILDREN.clear()  # the parent's children are not this child's


class SharedMemory:
    """Memory shared by the parent and its `Worker` children, for results too large for a pipe.

    A few regions of ``capacity`` bytes each, anonymous shared mappings made
    before the workers are forked (the children inherit them; they have no
    name, so nothing is left behind however the processes end, and a page
    takes memory only once written). A call's result lends one region (`lend`):
    the child copies the result's large arrays into it and sends only their
    places through the pipe, and the parent's arrays are views of that
    memory, with no copy made there (a 1280x720 sampling plan, 20 MB: its
    read from the pipe took 8 ms of the parent's CPU, its write 5 ms of the
    child's). A region is lent again only once no array of the last result
    placed in it is alive (weak references tell), so a result kept by the
    caller is never written over; with no region free, or an array that does
    not fit, it goes through the pipe as before.

    Parameters
    ----------
    count : int
        Regions: as many results as may be alive or under way at once
        (results in flight, one per worker, and the ones the parent holds).
    capacity : int
        Bytes per region: at least the large arrays of one result.
    """

    def __init__(self, count: int, capacity: int) -> None:
        self.capacity = int(capacity)
        self._maps = [mmap.mmap(-1, self.capacity, flags=mmap.MAP_SHARED) for _ in range(count)]
        self._views: list[list[weakref.ref]] = [[] for _ in range(count)]
        self._lent: set[int] = set()

    def lend(self) -> int | None:
        """A region no worker writes and no live result uses, now lent; None if there is none."""
        for k in range(len(self._maps)):
            if k not in self._lent and all(ref() is None for ref in self._views[k]):
                self._views[k] = []
                self._lent.add(k)
                return k
        return None

    def give_back(self, k: int | None) -> None:
        """Region ``k``'s writer is done with it (the arrays made from it keep it from `lend`)."""
        self._lent.discard(k)  # type: ignore[arg-type]

    def region(self, k: int) -> mmap.mmap:
        """Region ``k``'s memory (in a child: the same pages as the parent's)."""
        return self._maps[k]

    def view(self, k: int, offset: int, nbytes: int) -> Any:
        """``nbytes`` bytes of region ``k`` from ``offset``, as an array the result's arrays are made over."""
        import numpy as np

        if not 0 <= offset <= offset + nbytes <= self.capacity:
            raise ValueError("a part outside its region")
        part = np.frombuffer(self._maps[k], dtype=np.uint8, count=nbytes, offset=offset)
        self._views[k].append(weakref.ref(part))
        return part


#: The place of a part sent through the pipe, not placed in shared memory.
_IN_PIPE = (1 << 64) - 1
#: Arrays are placed in a region at multiples of this (cache lines; the kernels want aligned arrays).
_ALIGN = 64


class Worker:
    """A forked child that runs ``fn(*args)`` for each `submit`, one call at a time, in the
    order submitted; `result` returns or raises what the oldest call not yet taken did, as
    `Forked` does.

    For many calls of one function (the maps of an animated sequence): the
    process is forked once, not once per call, so the parent's pages are
    copied on write once, not after every fork. ``fn`` is the child's from
    the fork on; the arguments and results must pickle. With ``shared`` (made
    before the worker), a result's large arrays come back through shared
    memory instead of the pipe (`SharedMemory`). Calls may be submitted
    before the earlier ones' results are taken (`pending`): the child starts
    the next as soon as it has written a result, without waiting for the
    parent to take it.
    """

    def __init__(self, fn: Callable[..., Any], shared: SharedMemory | None = None) -> None:
        requests = os.pipe()
        answers = os.pipe()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)  # as in Forked
            try:
                pid = os.fork()
            except OSError:
                for fd in (*requests, *answers):
                    os.close(fd)
                raise
        if pid == 0:  # the child: never returns
            os.close(requests[1])
            os.close(answers[0])
            _serve(fn, requests[0], answers[1], shared)
        os.close(requests[0])
        os.close(answers[1])
        self._pid: int | None = pid
        _CHILDREN.add(pid)
        self._to, self._from = requests[1], answers[0]
        _WORKER_FDS.update((self._to, self._from))
        self._shared = shared
        self._regions: collections.deque[int | None] = collections.deque()  # of the calls not yet taken, in order
        self._died: str | None = None

    @property
    def pending(self) -> int:
        """Calls submitted whose result has not been taken."""
        return len(self._regions)

    @property
    def busy(self) -> bool:
        """Whether a call's result is still to be taken."""
        return bool(self._regions)

    def submit(self, *args: Any) -> None:
        """Queue ``fn(*args)`` after the calls submitted before; `ChildDied` if the child has ended."""
        if self._died is not None:
            raise ChildDied(self._died)
        if self._to < 0:
            raise RuntimeError("a worker takes no call after finish or close")
        region = None if self._shared is None else self._shared.lend()
        data = pickle.dumps((region, args), protocol=pickle.HIGHEST_PROTOCOL)
        try:
            _write_all(self._to, struct.pack("<Q", len(data)) + data)
        except OSError as err:  # a broken pipe: the child is gone
            if self._shared is not None:
                self._shared.give_back(region)
            raise ChildDied(self._gone()) from err
        self._regions.append(region)

    def result(self) -> Any:
        """Wait for the oldest call not yet taken: its return value or exception (`ChildDied`
        if the child died; then every call still pending raises it too)."""
        region = self._regions.popleft()
        if self._died is not None:
            raise ChildDied(self._died)
        try:
            outcome = _receive(self._from, self._shared, region)
        finally:  # the child has written the region (or is gone)
            if self._shared is not None:
                self._shared.give_back(region)
        if outcome is None:  # its end of the pipe closed: the child is gone
            raise ChildDied(self._gone())
        return _unpack(*outcome)

    def _gone(self) -> str:
        """The child has ended: reaped, the pipes closed, the regions of its pending calls given back."""
        self._died = _describe(self._reap())
        if self._shared is not None:
            for region in self._regions:
                self._shared.give_back(region)
        self.close()
        return self._died

    def finish(self) -> None:
        """No more calls: the child ends once it has answered those submitted (their results are
        still to be taken), in the background; `close` then only reaps it."""
        if self._to >= 0:
            _WORKER_FDS.discard(self._to)
            os.close(self._to)
            self._to = -1

    def close(self, kill: bool = False) -> None:
        """End the child: at once with ``kill``, else when it has finished the call it runs (the
        calls queued behind that one are not run)."""
        if kill and self._pid is not None:
            try:
                os.kill(self._pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            _killed(self._pid)
        for fd in (self._to, self._from):
            if fd >= 0:
                _WORKER_FDS.discard(fd)
                os.close(fd)
        self._to = self._from = -1
        self._reap()

    def _reap(self) -> int:
        return Forked._reap(self)  # type: ignore[arg-type]


def _serve(fn: Callable[..., Any], requests: int, answers: int, shared: SharedMemory | None) -> None:
    code = 0
    try:
        keep = _child_setup()
        _keep_freed_memory()
        while True:
            head = bytearray(8)
            try:
                _read_into(requests, head)
            except EOFError:  # the parent is done with this worker
                break
            data = bytearray(struct.unpack("<Q", head)[0])
            _read_into(requests, data)
            region, args = pickle.loads(data)
            _respond(fn, args, answers, keep, None if region is None else shared.region(region))  # type: ignore[union-attr]
    except BaseException:
        code = 70
    finally:
        os._exit(code)


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view) :]


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
        keep = _child_setup()
        _respond(fn, args, fd, keep)
    except BaseException:
        code = 70
    finally:
        os._exit(code)


def die_with_parent(parent: int | None = None) -> None:
    """Have the kernel kill this process when its parent ends (Linux: ``PR_SET_PDEATHSIG``).

    A parent ended at once (SIGTERM's end, `kill -9`, a closed terminal)
    kills the children it knows of (`kill_children`), but not those of its
    children, nor the workers a process pool spawned; orphaned, they went on
    writing frames and then waited for ever, holding the run's stderr open.
    ``parent``: the pid the parent had when it started this process (if it
    ended before the request took effect, this process ends now). Elsewhere
    than Linux: nothing.
    """
    if not sys.platform.startswith("linux"):
        return
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if parent is not None and os.getppid() != parent:
        os._exit(0)


def _child_setup() -> KeptRecords:
    _close_inherited()
    # The parent's SIGTERM handler (`warpcli.cli.run`) removes the parent's temporary files and
    # says "terminated": not a child's to do when a job's whole process group is sent SIGTERM
    # (a scheduler, systemd). A child just ends; its parent, sent the same signal, does the rest.
    try:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
    except ValueError:  # not the main thread: cannot be after a fork (it makes the forking thread the main one)
        pass
    if "faulthandler" in sys.modules:
        # A crash here is the parent's to report (`ChildDied`), in one line.
        sys.modules["faulthandler"].disable()
    keep = KeptRecords()
    # Records go to the parent, not to the inherited stderr.
    _log.handlers[:] = [keep]
    _log.filters[:] = []
    _log.propagate = False
    return keep


def _keep_freed_memory() -> None:
    """A worker's C library keeps the memory its calls free, for the next call.

    glibc hands large blocks back to the system when they are freed (blocks
    from their own mapping, the free top of the heap past 2x the mapping
    threshold), and the next call takes them again, one page fault per 4 KiB:
    a worker building 1280x720 sampling plans took 8000 faults a frame, 3000
    more than the same builds in the main process, whose heap was grown by
    its images already (about 25 ms of system time per frame). Here blocks
    up to 32 MiB (glibc's most) come from the heap, and up to 256 MiB of its
    free top is kept: about what one call takes at its peak, which the next
    call of the same size takes again. Only glibc has ``mallopt``; elsewhere
    nothing changes.
    """
    try:
        import ctypes

        libc = ctypes.CDLL(None)
        mallopt = libc.mallopt
        libc.gnu_get_libc_version  # glibc's, not another C library's
    except (OSError, AttributeError):
        return
    m_trim_threshold, m_mmap_threshold = -1, -3
    mallopt(m_mmap_threshold, 32 << 20)
    mallopt(m_trim_threshold, 256 << 20)


class _Lent:
    """The region lent to the call a worker runs now, from which `empty` makes arrays."""

    def __init__(self, region: mmap.mmap) -> None:
        import numpy as np

        self.bytes = np.frombuffer(region, dtype=np.uint8)
        self.start = self.bytes.ctypes.data
        self.used = 0

    def offset(self, part: memoryview) -> int | None:
        """Where ``part`` lies in the region, or None if it lies elsewhere."""
        import numpy as np

        if not part.nbytes:
            return None
        at = np.frombuffer(part, dtype=np.uint8).ctypes.data - self.start
        return at if 0 <= at and at + part.nbytes <= self.bytes.size else None


#: The region of the call a worker runs now (`_respond`); None elsewhere.
_LENT: _Lent | None = None


def empty(shape: int | tuple[int, ...], dtype: Any = float) -> Any:
    """``numpy.empty(shape, dtype)``; in a `Worker`'s call with shared memory lent to it, a large
    array is made in that memory, where the result it is part of is sent from without a copy.

    For the large arrays of a worker's result (a sampling plan's points and
    Jacobians, made by `warpcli.maps.compose.BijectiveMap.pull_back`): made
    anywhere else, they are copied into the region when the call returns
    (20 MB a 1280x720 plan). An array of less than 64 KiB (sent in the
    pickle), or one that does not fit in what is left of the region, is
    numpy's.
    """
    import numpy as np

    lent = _LENT
    if lent is not None:
        dt = np.dtype(dtype)
        dims = (shape,) if isinstance(shape, int) else tuple(shape)
        n = dt.itemsize * int(np.prod(dims, dtype=np.int64))
        start = -(-lent.used // _ALIGN) * _ALIGN
        if n >= 1 << 16 and start + n <= lent.bytes.size:
            lent.used = start + n
            return lent.bytes[start : start + n].view(dt).reshape(dims)
    return np.empty(shape, dtype)


def _respond(fn: Callable[..., Any], args: tuple, fd: int, keep: KeptRecords, region: mmap.mmap | None = None) -> None:
    """``fn(*args)``'s outcome and log records, written to ``fd`` for `_receive`; with ``region``,
    the large arrays that fit written there (`SharedMemory`; those `empty` made there already
    are not copied), their places through ``fd``."""
    global _LENT
    keep.records = []
    buffers: list[memoryview] = []
    lent = _LENT = None if region is None else _Lent(region)
    try:
        payload = _dumps(("ok", fn(*args), keep.records), buffers)
    except BaseException as err:  # handed to the parent
        buffers.clear()
        try:
            payload = _dumps(("error", err, keep.records), buffers)
        except Exception:
            buffers.clear()
            payload = _dumps(("error", RuntimeError(f"{type(err).__name__}: {err}"), keep.records), buffers)
    finally:
        _LENT = None
    parts = [memoryview(payload), *buffers]
    places = [_IN_PIPE] * len(parts)
    end = 0 if lent is None else lent.used  # the arrays made in the region end here
    for k, part in enumerate(parts[1:], 1):
        at = None if lent is None else lent.offset(part)
        if at is not None:  # made there by `empty`: no copy
            places[k] = at
            continue
        start = -(-end // _ALIGN) * _ALIGN
        if region is not None and start + part.nbytes <= len(region):
            region[start : start + part.nbytes] = part
            places[k], end = start, start + part.nbytes
    piped = [part for part, place in zip(parts, places) if place == _IN_PIPE]
    if sum(p.nbytes for p in piped) > 1 << 16:
        _widen(fd)
    header = struct.pack(f"<Q{2 * len(parts)}Q", len(parts), *(p.nbytes for p in parts), *places)
    for part in (memoryview(header), *piped):
        view = part
        while view:
            view = view[os.write(fd, view) :]


# The result crosses the pipe as pickle protocol 5 with its large arrays out of
# band: they are written from their own memory and read into theirs, without
# the two copies (and the pickling time) of a pickle holding them (a sampling
# plan for 1280x720 is 20 MB: 25 ms of pickling per frame saved).


def _dumps(obj: Any, buffers: list[memoryview]) -> bytes:
    def out_of_band(buf: pickle.PickleBuffer) -> bool:
        try:
            raw = buf.raw()
        except BufferError:  # not contiguous: in the pickle
            return True
        if raw.nbytes < 1 << 16:
            return True  # small: not worth a read of its own
        buffers.append(raw)
        return False

    return pickle.dumps(obj, protocol=5, buffer_callback=out_of_band)


def _widen(fd: int) -> None:
    """A larger pipe (1 MiB, Linux's default limit), for fewer switches between the two processes."""
    try:
        import fcntl

        fcntl.fcntl(fd, getattr(fcntl, "F_SETPIPE_SZ", 1031), 1 << 20)
    except OSError:
        pass


def _read_header(fd: int) -> tuple[list[int], list[int]]:
    """The parts' sizes, and their places in shared memory (`_IN_PIPE`: in the pipe)."""
    count = bytearray(8)
    _read_into(fd, count)
    (n,) = struct.unpack("<Q", count)
    if not 1 <= n <= 1 << 20:
        raise ValueError("bad header")
    sizes = bytearray(16 * n)
    _read_into(fd, sizes)
    values = list(struct.unpack(f"<{2 * n}Q", sizes))
    if values[n] != _IN_PIPE:
        raise ValueError("bad header")  # the pickle itself always comes through the pipe
    return values[:n], values[n:]


def _read_into(fd: int, buf: bytearray) -> None:
    """Fill ``buf`` from ``fd`` (the GIL released while waiting); EOFError if the writer ended first."""
    view = memoryview(buf)
    while view:
        got = os.readv(fd, [view])
        if got == 0:
            raise EOFError
        view = view[got:]
