"""`cached_property` without a lock, as Python 3.12 has it: safe to fork beside.

Python 3.11's `functools.cached_property` holds one `threading.RLock` per
property (shared by every instance of the class) while it computes a value.
warpcli forks map builders (`warpcli._fork`) while other threads of the
parent work; a fork while some thread computes any instance's property of
that class leaves the lock held forever in the child, which then waits on
it at its first read of that property (seen: a forked FEM builder blocked in
`rlock_acquire` under a cached property, the suite hung). Python 3.12
dropped the lock (two threads may compute the same value; the last one is
kept), and so does this subclass: every property here is a pure function of
its instance.
"""

from __future__ import annotations

import functools
from typing import Any

__all__ = ["cached_property"]

_MISSING = object()


class cached_property(functools.cached_property):
    """`functools.cached_property` without its lock (Python 3.12's behaviour)."""

    def __get__(self, instance: Any, owner: type | None = None) -> Any:
        if instance is None:
            return self
        if self.attrname is None:
            raise TypeError("Cannot use cached_property instance without calling __set_name__ on it.")
        cache = instance.__dict__
        value = cache.get(self.attrname, _MISSING)
        if value is _MISSING:
            value = self.func(instance)
            cache[self.attrname] = value
        return value
