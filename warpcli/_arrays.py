"""``np.unique`` as it computes it, without its test for masked arrays.

``np.unique`` checks whether its input is a masked array, and that check
imports numpy.ma: 10-20 ms (quiet) in every process that calls it, on a
warp's critical path and in each forked builder. These give the same
values (and first indices) by the same stable sort.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["sorted_unique", "first_of_each", "first_and_inverse"]


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


def _runs(values: ArrayLike) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
    """The stable sorting order of the values, and where each run of equal ones starts in it."""
    v = np.ravel(values)
    order = np.argsort(v, kind="stable")
    ranked = v[order]
    return order, np.r_[True, ranked[1:] != ranked[:-1]] if v.size else np.zeros(0, dtype=bool)
