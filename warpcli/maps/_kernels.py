"""Compiled (numba) helpers of the composition, whatever the method.

Called through `warpcli._native.Kernels` like every kernel of warpcli.
"""

from __future__ import annotations

from .._jit import njit


@njit(cache=True, nogil=True)
def scatter_products(a, b, index, out):
    """``out[index[k]] = a[k] @ b[k]`` for stacks of 2x2 matrices.

    Written out term by term, the same arithmetic as `warpcli.maps.base.matmul2`.
    """
    for k in range(index.shape[0]):
        i = index[k]
        for r in range(2):
            for c in range(2):
                out[i, r, c] = a[k, r, 0] * b[k, 0, c] + a[k, r, 1] * b[k, 1, c]
