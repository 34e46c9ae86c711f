"""FEM point location in triangle meshes: a uniform bucket grid, fully vectorized."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..._arrays import median
from ...simplicial import barycentric_combine, corners

#: A point counts as inside a triangle when all its barycentric coordinates
#: are at least -BARY_TOL: points on shared edges are found, and points on the
#: polygon's boundary are inside.
BARY_TOL = 1e-10

# Queries are processed in blocks of this many points to bound memory.
_BLOCK = 1 << 20



class TriangleLocator:
    """Find, for many points at once, the triangle containing each point (a `warpcli.simplicial.Locator`).

    Triangles are binned by bounding box into a uniform grid of about one cell
    per triangle (stored as CSR arrays). A query looks up its cell and tests
    that cell's triangles in turn, all queries advancing together, so the cost
    is a few vectorized passes, never a Python loop over points or triangles.
    Ties (a point on an edge shared by two triangles) go to the triangle with
    the smaller index, so results are deterministic.

    Parameters
    ----------
    vertices : (N, 2) array_like of float
    triangles : (M, 3) array_like of int
    """

    def __init__(self, vertices: ArrayLike, triangles: ArrayLike) -> None:
        v = np.asarray(vertices, dtype=np.float64)
        t = np.asarray(triangles, dtype=np.int64)
        self.vertices = v
        self.triangles = t
        self._coef = affine_coefficients(v, t)
        a, b, c = corners(v, t)
        tmin = np.minimum(np.minimum(a, b), c)
        tmax = np.maximum(np.maximum(a, b), c)
        lo = v.min(axis=0)
        hi = v.max(axis=0)
        span = np.maximum(hi - lo, 1e-300)
        # Cells shaped like a typical triangle's bounding box, about one cell
        # per triangle: a mesh of slivers (the harmonic image of a long thin
        # polygon) would otherwise put thousands of triangles in every cell.
        extent = np.maximum(median(tmax - tmin, axis=0), span * 1e-9)
        scale = math.sqrt(float(span[0] * span[1]) / (max(len(t), 1) * float(extent[0] * extent[1])))
        self._cell = np.maximum(scale * extent, span / 4096.0)
        self._lo = lo
        self._shape = (int(span[1] // self._cell[1]) + 1, int(span[0] // self._cell[0]) + 1)  # rows (y), cols (x)
        c0 = self._cell_xy(tmin)
        c1 = self._cell_xy(tmax)
        nx = c1[:, 0] - c0[:, 0] + 1
        ny = c1[:, 1] - c0[:, 1] + 1
        counts = nx * ny
        tri_rep = np.repeat(np.arange(len(t)), counts)
        start = np.cumsum(counts) - counts
        k = np.arange(tri_rep.size) - np.repeat(start, counts)
        nxr = nx[tri_rep]
        cx = c0[tri_rep, 0] + k % nxr
        cy = c0[tri_rep, 1] + k // nxr
        cell_id = cy * self._shape[1] + cx
        order = np.argsort(cell_id, kind="stable")  # stable: triangle order within a cell
        self._tri_ids = tri_rep[order]
        ncell = self._shape[0] * self._shape[1]
        self._indptr = np.zeros(ncell + 1, dtype=np.int64)
        np.cumsum(np.bincount(cell_id, minlength=ncell), out=self._indptr[1:])

    def _cell_xy(self, p: NDArray[np.float64]) -> NDArray[np.int64]:
        ij = np.floor((p - self._lo) / self._cell).astype(np.int64)
        ij[:, 0] = np.clip(ij[:, 0], 0, self._shape[1] - 1)
        ij[:, 1] = np.clip(ij[:, 1], 0, self._shape[0] - 1)
        return ij

    def locate(self, points: ArrayLike) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """Containing triangle and barycentric coordinates of each point.

        Parameters
        ----------
        points : (K, 2) array_like of float

        Returns
        -------
        tri : (K,) ndarray of int64
            Index of the containing triangle, -1 where none contains the point.
        bary : (K, 3) ndarray of float
            Barycentric coordinates in that triangle (NaN where ``tri`` is -1).
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        tri = np.full(len(p), -1, dtype=np.int64)
        bary = np.full((len(p), 3), np.nan)
        for s in range(0, len(p), _BLOCK):
            tri[s : s + _BLOCK], bary[s : s + _BLOCK] = self._locate_block(p[s : s + _BLOCK])
        return tri, bary

    def _locate_block(self, p: NDArray[np.float64]):
        tri = np.full(len(p), -1, dtype=np.int64)
        bary = np.full((len(p), 3), np.nan)
        # A point on the mesh's bounding box may sit an ulp outside it: points
        # within a small tolerance of the grid are clamped into it.
        g = (p - self._lo) / self._cell
        tol = 1e-9 * max(self._shape)
        ok = (
            np.isfinite(g).all(axis=1)
            & (g[:, 0] >= -tol)
            & (g[:, 1] >= -tol)
            & (g[:, 0] <= self._shape[1] + tol)
            & (g[:, 1] <= self._shape[0] + tol)
        )
        pending = np.flatnonzero(ok)
        ix = np.clip(np.floor(g[pending, 0]).astype(np.int64), 0, self._shape[1] - 1)
        iy = np.clip(np.floor(g[pending, 1]).astype(np.int64), 0, self._shape[0] - 1)
        cid = iy * self._shape[1] + ix
        first = self._indptr[cid]
        left = self._indptr[cid + 1] - first
        keep = left > 0
        pending, first, left = pending[keep], first[keep], left[keep]
        while pending.size:
            cand = self._tri_ids[first]
            co = self._coef[cand]
            dx = p[pending, 0] - co[:, 0]
            dy = p[pending, 1] - co[:, 1]
            l1 = dx * co[:, 2] + dy * co[:, 3]
            l2 = dx * co[:, 4] + dy * co[:, 5]
            l0 = 1.0 - l1 - l2
            inside = (l0 >= -BARY_TOL) & (l1 >= -BARY_TOL) & (l2 >= -BARY_TOL)
            hit = pending[inside]
            tri[hit] = cand[inside]
            bary[hit, 0] = l0[inside]
            bary[hit, 1] = l1[inside]
            bary[hit, 2] = l2[inside]
            more = ~inside & (left > 1)
            pending, first, left = pending[more], first[more] + 1, left[more] - 1
        return tri, bary

    def interpolate(self, values: ArrayLike, points: ArrayLike) -> NDArray[np.float64]:
        """Piecewise-linear interpolation of per-vertex ``values`` at ``points``.

        Returns
        -------
        (K, D) ndarray of float
            NaN rows for points outside every triangle.
        """
        vals = np.asarray(values, dtype=np.float64)
        tri, bary = self.locate(points)
        return barycentric_combine(vals, self.triangles, tri, bary)


def triangle_neighbours(triangles: ArrayLike) -> NDArray[np.int64]:
    """For each triangle and corner k, the triangle sharing the edge opposite k (-1 if none).

    >>> triangle_neighbours([[0, 1, 2], [2, 1, 3]]).tolist()
    [[1, -1, -1], [-1, -1, 0]]
    """
    t = np.asarray(triangles, dtype=np.int64)
    m = len(t)
    # Half-edge opposite corner k of triangle i: (t[i, k+1], t[i, k+2]).
    a = np.concatenate([t[:, 1], t[:, 2], t[:, 0]])
    b = np.concatenate([t[:, 2], t[:, 0], t[:, 1]])
    key = np.minimum(a, b) * (int(t.max(initial=0)) + 1) + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    ks = key[order]
    same = np.flatnonzero(ks[1:] == ks[:-1])
    out = np.full(3 * m, -1, dtype=np.int64)
    h1 = order[same]
    h2 = order[same + 1]
    out[h1] = h2 % m
    out[h2] = h1 % m
    # Half-edge j = k * m + i  ->  (i, k).
    return out.reshape(3, m).T.copy()


def affine_coefficients(v: NDArray[np.float64], t: NDArray[np.int64]) -> NDArray[np.float64]:
    """Per triangle ``(ax, ay, k0, k1, k2, k3)``: l1 = dx*k0 + dy*k1, l2 = dx*k2 + dy*k3.

    (dx, dy) = p - a; degenerate triangles get NaN coefficients, so no point
    is ever inside them.
    """
    a, b, c = corners(v, t)
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(det != 0, 1.0 / det, np.nan)
    return np.stack(
        [
            a[:, 0],
            a[:, 1],
            (c[:, 1] - a[:, 1]) * inv,
            -(c[:, 0] - a[:, 0]) * inv,
            -(b[:, 1] - a[:, 1]) * inv,
            (b[:, 0] - a[:, 0]) * inv,
        ],
        axis=1,
    )
