"""Test configuration: one copy of warpcli under test, and derandomized hypothesis."""

from __future__ import annotations

import os

import pytest
from hypothesis import settings

import warpcli

#: The checkout these tests belong to.
REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# Exactly one copy of the code is tested: the one in this checkout. A copy
# installed elsewhere (pip install . without -e) would be tested by the CLI
# subprocesses while the working tree was tested in-process; refuse to run.
_here = os.path.dirname(os.path.abspath(warpcli.__file__))
if _here != os.path.join(REPO, "warpcli"):
    raise pytest.UsageError(
        f"the tests import warpcli from {_here}, not from this checkout ({REPO}); "
        "install it in editable mode: pip install -e '.[test]'"
    )

# No unseeded randomness anywhere, tests included: the same examples every run.
settings.register_profile("warpcli", derandomize=True, deadline=None, max_examples=40)
# Longer local fuzzing: WARPCLI_FUZZ=long python -m pytest tests/test_fuzz.py (random, many examples).
settings.register_profile("long", derandomize=False, deadline=None, max_examples=2000)
settings.load_profile("long" if os.environ.get("WARPCLI_FUZZ") == "long" else "warpcli")


def _serialize_numba_cache_writes() -> None:
    """One process at a time adds a compiled function to numba's on-disk cache.

    The volume kernels (``@njit(cache=True)``) are cached by numba itself, beside
    their module. Its writes are atomic renames, but adding an entry reads the
    index, takes the first free data-file number, and writes both: two test
    workers (``pytest -n``) compiling two signatures of one kernel at once can
    take the same number, and the index can end up naming the other
    signature's machine code. A lock file beside the index serializes that
    read-modify-write. (warpcli's own cache, `warpcli._native`, has one file
    per kernel and signature, written by atomic rename and checked by digest
    on reading: concurrent writers are safe there.)
    """
    try:
        import fcntl

        from numba.core import caching
    except ImportError:
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


_serialize_numba_cache_writes()
