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


@njit(cache=True, nogil=True)
def _window_pixel(p, width, r0, c0, ww, start, stop):
    """The window index of grid pixel ``p`` (flat, in a grid ``width`` wide; its column at least
    ``c0``) if its row is ``start <= row < stop``, else -1."""
    row = p // width
    if row < start or row >= stop:
        return -1
    return (row - r0) * ww + (p - row * width - c0)


@njit(cache=True, nogil=True)
def scatter_band(pixels, width, r0, c0, ww, start, stop, found, a, b, with_jac, points, out):
    """A band's values into the window: for each grid pixel ``pixels[k]`` (flat index in a
    grid ``width`` wide) of a row ``start <= row < stop``, window pixel
    ``i = (row - r0) * ww + (col - c0)`` gets ``points[i] = found[k]`` and, with
    ``with_jac``, ``out[i] = a[k] @ b[k]`` (as `scatter_products`); later pixels win.

    `warpcli.maps.compose._through_theta`'s scatter in one pass, where numpy made
    the rows and columns (divmod), a mask of the rows, the indices and a fancy
    assignment, each over the band's quarter million pixels.
    """
    for k in range(pixels.shape[0]):
        i = _window_pixel(pixels[k], width, r0, c0, ww, start, stop)
        if i < 0:
            continue
        points[i, 0] = found[k, 0]
        points[i, 1] = found[k, 1]
        if with_jac:
            for r in range(2):
                for c in range(2):
                    out[i, r, c] = a[k, r, 0] * b[k, 0, c] + a[k, r, 1] * b[k, 1, c]


@njit(cache=True, nogil=True)
def scatter_band_cells(pixels, width, r0, c0, ww, start, stop, found, ta, ca, tb, cb, points, out):
    """`scatter_band` of Jacobians constant per cell: ``a[k] = ta[ca[k]]`` and
    ``b[k] = tb[cb[k]]``, the tables' last row for a cell below 0 (none; a row of
    NaN, as a gather gives it). The same products of the same values, without
    gathering each band's Jacobians into two arrays first."""
    na = ta.shape[0] - 1
    nb = tb.shape[0] - 1
    for k in range(pixels.shape[0]):
        i = _window_pixel(pixels[k], width, r0, c0, ww, start, stop)
        if i < 0:
            continue
        points[i, 0] = found[k, 0]
        points[i, 1] = found[k, 1]
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
