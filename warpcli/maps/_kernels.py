"""Compiled (numba) helpers of the composition, whatever the method.

Called through `warpcli._native.Kernels` like every kernel of warpcli.
"""

from __future__ import annotations

from .._jit import njit


@njit(cache=True, nogil=True)
def scatter_band(pixels, width, r0, c0, ww, start, stop, found, ta, ca, tb, cb, with_jac, points, out):
    """A band's values into the window: for each grid pixel ``pixels[k]`` (flat index in a
    grid ``width`` wide, its column at least ``c0``) of a row ``start <= row < stop``, window
    pixel ``i = (row - r0) * ww + (col - c0)`` gets ``points[i] = found[k]`` and, with
    ``with_jac``, ``out[i] = ta[ca[k]] @ tb[cb[k]]`` (written out term by term, the
    arithmetic of `warpcli.maps.base.matmul2`), a table's last row for an index below 0;
    later pixels win.

    The tables are per cell (FEM's Jacobians on each triangle, a last row of NaN for
    none: no band's Jacobians gathered into arrays first) or per pixel (indices
    ``0..n-1``). `warpcli.maps.compose._through_theta`'s scatter in one pass, where
    numpy made the rows and columns (divmod), a mask of the rows, the indices and a
    fancy assignment, each over the band's quarter million pixels.
    """
    na = ta.shape[0] - 1
    nb = tb.shape[0] - 1
    for k in range(pixels.shape[0]):
        p = pixels[k]
        row = p // width
        if row < start or row >= stop:
            continue
        i = (row - r0) * ww + (p - row * width - c0)
        points[i, 0] = found[k, 0]
        points[i, 1] = found[k, 1]
        if with_jac:
            ia = ca[k]
            if ia < 0:
                ia = na
            ib = cb[k]
            if ib < 0:
                ib = nb
            for r in range(2):
                for c in range(2):
                    out[i, r, c] = ta[ia, r, 0] * tb[ib, 0, c] + ta[ia, r, 1] * tb[ib, 1, c]


@njit(cache=True, nogil=True)
def outside_columns(pixels, width, c0, c1):
    """How many of the grid pixels ``pixels`` (flat indices, ``width`` wide) lie outside the columns ``c0 <= col < c1``."""
    n = 0
    for k in range(pixels.shape[0]):
        col = pixels[k] % width
        if col < c0 or col >= c1:
            n += 1
    return n
