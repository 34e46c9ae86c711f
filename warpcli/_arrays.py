"""``np.unique`` and ``np.median`` as they compute them, without their test for masked arrays.

``np.unique`` and ``np.median`` check whether their input is a masked array,
and that check imports numpy.ma: 10-20 ms (quiet) in every process that
calls them, on a warp's critical path and in each forked builder. These give
the same values (and first indices) by the same stable sort.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["sorted_unique", "first_of_each", "first_and_inverse", "median"]


def sorted_unique(values: ArrayLike) -> NDArray:
    """``np.unique(values)``: the values sorted, each once (integers or finite floats).

    >>> sorted_unique([3, 1, 3, 2]).tolist()
    [1, 2, 3]
    """
    v = np.sort(np.ravel(values))
    return v[np.r_[True, v[1:] != v[:-1]]] if v.size else v


def first_of_each(values: ArrayLike) -> NDArray[np.intp]:
    """``np.unique(values, return_index=True)[1]``: the index of each distinct value's first
    occurrence, in the order of the sorted values.

    >>> first_of_each([3, 1, 3, 2]).tolist()
    [1, 3, 0]
    """
    order, new = _runs(values)
    return order[new]


def first_and_inverse(values: ArrayLike) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """``np.unique(values, return_index=True, return_inverse=True)[1:]``: `first_of_each`, and
    for each value the rank of its distinct value among them.

    >>> [a.tolist() for a in first_and_inverse([3, 1, 3, 2])]
    [[1, 3, 0], [2, 0, 2, 1]]
    """
    order, new = _runs(values)
    inverse = np.empty(len(order), dtype=np.intp)
    inverse[order] = np.cumsum(new) - 1
    return order[new], inverse


def median(values: ArrayLike, axis: int | None = None) -> NDArray[np.float64] | float:
    """``np.median(values, axis)`` of finite floats, the same bits: the middle of the sorted values, or
    the mean of the two middle ones (at least one value along ``axis``).

    >>> median([3.0, 1.0, 2.0, 10.0])
    2.5
    """
    ax = 0 if axis is None else axis
    s = np.sort(np.ravel(values) if axis is None else np.asarray(values), axis=ax)
    h = s.shape[ax] // 2
    mid = np.take(s, h, axis=ax)
    if s.shape[ax] % 2 == 0:
        mid = (np.take(s, h - 1, axis=ax) + mid) / 2.0
    return float(mid) if axis is None else mid


def _runs(values: ArrayLike) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
    """The stable sorting order of the values, and where each run of equal ones starts in it."""
    v = np.ravel(values)
    order = np.argsort(v, kind="stable")
    ranked = v[order]
    return order, np.r_[True, ranked[1:] != ranked[:-1]] if v.size else np.zeros(0, dtype=bool)
