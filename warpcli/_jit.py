"""numba's ``@njit``, with its on-disk cache made safe for processes compiling at once.

The kernels are ``@njit(cache=True)``: numba keeps their machine code beside
the module. Its writes are atomic renames, but adding an entry reads the
index, takes the first free data-file number and writes both, so two
processes compiling two signatures of one kernel at once (a farm starting on
a fresh install, ``pytest -n``) can take the same number, and the index can
end up naming the other signature's machine code. Here that
read-modify-write holds a lock file beside the index (``fcntl.flock``; where
there is no ``fcntl``, numba's own behaviour). warpcli's own cache of machine
code (`warpcli._native`) has one file per kernel and signature, written by
atomic rename and checked by digest: it needs no lock.

Processes starting together on a fresh install also compiled the same kernel
each (BEM's kernels: about 15 s of CPU per process): here a process about to
compile a kernel another one is compiling waits for it (a second lock file
beside the index), then loads its machine code from the cache.

And a kernel calling another one compiles it once, for its arguments' plain
types. numba types a call while it is still inferring the caller's types,
so a counter started at ``0`` and carried through a loop (``ng = 0`` ...
``ng = _gather_far(..., ng)``) is first the literal ``0``: numba compiled the
callee for that literal, then again for int64 once the loop was typed, and
linked only the second (BEM's ``_far_to_local`` and ``_gather_far``: 2.2 s of
the 11 s that `bem_evaluate` took to compile; FEM's ``_bary``). Here calls
from one of warpcli's functions to another are typed with the arguments'
plain types (`numba.types.unliteral`), the types the linked code has anyway.
"""

from __future__ import annotations

import os

from numba import njit

__all__ = ["njit"]


def _serialize_cache_writes() -> None:
    try:
        import fcntl

        from numba.core import caching
    except ImportError:  # pragma: no cover - not on POSIX, or another numba
        return
    save = caching.IndexDataCacheFile.save
    if getattr(save, "serialized", False):
        return

    def serialized_save(self, key, data):
        path = getattr(self, "_index_path", None)
        if path is None:
            return save(self, key, data)
        with open(path + ".lock", "a") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            return save(self, key, data)

    serialized_save.serialized = True
    caching.IndexDataCacheFile.save = serialized_save


_serialize_cache_writes()


#: Index files whose compile lock this process holds (a kernel compiling itself, or another
#: kernel it calls, does not wait for itself). Read and written under numba's compiler lock.
_COMPILING: set[str] = set()


def _one_compile_across_processes() -> None:
    try:
        from numba.core.compiler_lock import global_compiler_lock
        from numba.core.dispatcher import Dispatcher
    except ImportError:  # pragma: no cover - another numba
        return
    from ._native import compiling_kernel, locked_file
    compile_ = Dispatcher.compile
    if getattr(compile_, "serialized", False):
        return

    def compile_once(self, sig):
        path = getattr(getattr(getattr(self, "_cache", None), "_cache_file", None), "_index_path", None)
        if path is None:  # not cached on disk: nothing to share
            return compile_(self, sig)
        with global_compiler_lock:  # one thread of this process at a time, as numba compiles
            if path in _COMPILING:
                return compile_(self, sig)
            try:
                os.makedirs(os.path.dirname(path), exist_ok=True)
                lock = locked_file(path + ".compiling")
            except OSError:  # a cache directory numba cannot write either
                return compile_(self, sig)
            with compiling_kernel(), lock:
                _COMPILING.add(path)
                try:
                    # Finds in the cache what another process compiled while this one waited.
                    return compile_(self, sig)
                finally:
                    _COMPILING.discard(path)

    compile_once.serialized = True
    Dispatcher.compile = compile_once


_one_compile_across_processes()


def _compile_callees_once() -> None:
    try:
        from numba.core import types
        from numba.core.dispatcher import Dispatcher
        from numba.core.errors import TypingError
    except ImportError:  # pragma: no cover - another numba
        return
    get_call_template = Dispatcher.get_call_template
    if getattr(get_call_template, "plain", False):
        return

    def plain_call_template(self, args, kws):
        # Only warpcli's functions (numba's own and other packages' keep numba's typing); a
        # function that needs a literal argument (none of warpcli's does) is typed as numba would.
        module = getattr(self.py_func, "__module__", None) or ""  # None for a function made by exec
        if any(isinstance(a, types.Literal) for a in args) and module.startswith("warpcli."):
            try:
                return get_call_template(self, tuple(types.unliteral(a) for a in args), kws)
            except TypingError:
                pass
        return get_call_template(self, args, kws)

    plain_call_template.plain = True
    Dispatcher.get_call_template = plain_call_template


_compile_callees_once()
