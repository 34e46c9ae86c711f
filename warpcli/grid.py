"""Pixel grids: the coordinate convention, pixel centres, and which centres a polygon covers.

Coordinates are continuous image coordinates: x right, y down, the origin at
the top-left corner of the top-left pixel, so pixel (row r, column c) covers
``[c, c+1] x [r, r+1]`` and has its centre at ``(c + 0.5, r + 0.5)``. Sizes are
``(width, height)``; arrays of pixels have shape ``(height, width, ...)``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray


def pixel_centres(width: int, height: int, rows: tuple[int, int] | None = None) -> NDArray[np.float64]:
    """Centres of a ``width`` x ``height`` pixel grid, row by row, as (K, 2) points.

    Parameters
    ----------
    width, height : int
        Grid size in pixels.
    rows : (int, int) or None
        Only rows ``r0 <= r < r1``.

    Returns
    -------
    (K, 2) ndarray of float
        K = width * (number of rows).

    Examples
    --------
    >>> pixel_centres(2, 1).tolist()
    [[0.5, 0.5], [1.5, 0.5]]
    """
    r0, r1 = rows if rows is not None else (0, height)
    # Written in place, one pass (meshgrid's copies and stack's: 14 ms against 2.5 ms at 1 MP).
    out = np.empty((max(r1 - r0, 0), width, 2))
    out[:, :, 0] = np.arange(width, dtype=np.float64) + 0.5
    out[:, :, 1] = (np.arange(r0, r1, dtype=np.float64) + 0.5)[:, None]
    return out.reshape(-1, 2)


def window(bounds: tuple[float, float, float, float], width: int, height: int, margin: int = 2) -> tuple[int, int, int, int]:
    """The pixels ``(r0, r1, c0, c1)`` of a grid whose centres can lie in a box, plus a margin.

    Rows ``r0 <= r < r1`` and columns ``c0 <= c < c1`` of a ``width`` x
    ``height`` grid around the box ``(xmin, ymin, xmax, ymax)``, ``margin``
    pixels wider each side (a polygon's antialiased edge reaches a pixel
    beyond its bounding box), clipped to the grid; empty (r0 == r1 or
    c0 == c1) when the box misses the grid.

    >>> window((10.2, 3.0, 20.0, 4.5), 100, 50)
    (1, 7, 8, 22)
    >>> window((200.0, 3.0, 300.0, 4.5), 100, 50)[2:]
    (100, 100)
    """
    xmin, ymin, xmax, ymax = bounds
    r0 = min(max(0, math.ceil(ymin - 0.5) - margin), height)
    r1 = max(r0, min(height, math.floor(ymax - 0.5) + 1 + margin))
    c0 = min(max(0, math.ceil(xmin - 0.5) - margin), width)
    c1 = max(c0, min(width, math.floor(xmax - 0.5) + 1 + margin))
    return r0, r1, c0, c1


def inside_polygon(points: ArrayLike, vertices: ArrayLike) -> NDArray[np.bool_]:
    """Whether each point lies inside a polygon (even-odd rule; points on the boundary vary).

    Parameters
    ----------
    points : (K, 2) array_like of float
    vertices : (n, 2) array_like of float

    Returns
    -------
    (K,) ndarray of bool
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    v = np.asarray(vertices, dtype=np.float64)
    x, y = p[:, 0], p[:, 1]
    inside = np.zeros(len(p), dtype=bool)
    for i in range(len(v)):  # a loop over edges, vectorized over points: memory O(K)
        x0, y0 = v[i]
        x1, y1 = v[(i + 1) % len(v)]
        crosses = (y0 > y) != (y1 > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xc = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
        inside ^= crosses & (x < xc)
    return inside


def clip_segments(
    a: NDArray[np.float64], d: NDArray[np.float64], box: tuple[float, float, float, float]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Parameter range ``[t_lo, t_hi]`` of the segments ``a + t d``, t in [0, 1], inside a box
    ``(xmin, ymin, xmax, ymax)`` (Liang-Barsky); ``t_lo > t_hi`` where a segment misses it.

    >>> lo, hi = clip_segments(np.array([[-10.0, 5.0]]), np.array([[40.0, 0.0]]), (0.0, 0.0, 20.0, 10.0))
    >>> lo.tolist(), hi.tolist()
    ([0.25], [0.75])
    """
    t_lo = np.zeros(len(a))
    t_hi = np.ones(len(a))
    lo = np.array(box[:2])
    hi = np.array(box[2:])
    with np.errstate(divide="ignore", invalid="ignore"):
        for k in range(2):
            p, q = d[:, k], a[:, k]
            t1 = (lo[k] - q) / p
            t2 = (hi[k] - q) / p
            enter = np.where(p != 0, np.minimum(t1, t2), np.where((q >= lo[k]) & (q <= hi[k]), -np.inf, np.inf))
            leave = np.where(p != 0, np.maximum(t1, t2), np.where((q >= lo[k]) & (q <= hi[k]), np.inf, -np.inf))
            t_lo = np.maximum(t_lo, enter)
            t_hi = np.minimum(t_hi, leave)
    return t_lo, t_hi
