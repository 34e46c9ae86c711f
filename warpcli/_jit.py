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
"""

from __future__ import annotations

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
