"""The certificate of a smooth map onto Theta (BEM, MFS): det J > 0 and values in Theta, cell by cell.

A smooth map has no triangles whose orientation could be checked; its
Jacobian determinant is a smooth function inside the polygon. The polygon is
covered by square cells, each with a sample at its centre x0 and a half-side
s (reach r = s sqrt 2):

- where the closed form has its largest errors and folds live, the cells
  are small: a uniform grid of `GRID_CELLS` cells over the interior, layers
  of cells along every edge at distances halving from the grid's step down
  to `band_floor` (0.01 px for a polygon of 1000 px or more, 1e-5 of its
  size below), and polar grids of cells around every vertex from
  `band_floor` to the grid's step;
- at each sample the closed form gives phi, J and the Hessian, hence det J
  and its gradient exactly (``d det J / dx_c`` from J and d J / dx_c);
- a sample fails when det J <= 0 (relative to the orientations) or is not
  finite, or when phi(x0) lies outside Theta by more than `OUTSIDE`
  (relative to Theta's size): the exact map takes the polygon into Theta,
  and the composition would clamp such a value onto Theta's boundary;
- a cell is proved when det J(x0) > `MARGIN` |grad det J(x0)| r: to first
  order det J stays positive over the whole cell (the factor covers the
  change of the gradient across it). A cell that is not proved is split in
  four, down to cells of half-side `band_floor`; the samples of those are
  counted as they are.

Failures are counted (`Certificate.flipped`: at least one for a map that
is not certified; cells are not split further once one sample failed);
every sample is counted in `Certificate.checked`. Points within `ON_BOUNDARY` of the polygon's size of
its boundary are not the closed form's (the maps take the exact boundary
data there), so cells are not sampled there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..boundary import nearest_edge, on_boundary
from ..grid import inside_polygon

__all__ = ["BAND", "BAND_RELATIVE", "GRID_CELLS", "MARGIN", "OUTSIDE", "Cover", "band_floor", "certify_cells", "cover"]

#: Cells of the uniform grid over the polygon's interior (its step: sqrt(area / GRID_CELLS)).
GRID_CELLS = 40_000
#: A cell is proved when det J(x0) > MARGIN |grad det J(x0)| r (first order, with room for the gradient to grow).
MARGIN = 2.0
#: A value further outside Theta than this (times Theta's size) is a failure: beyond rounding.
OUTSIDE = 1e-9
#: Values outside Theta are the closed form's boundary error when they move the boundary by less
#: than ``min(BAND, BAND_RELATIVE * size)``: a pixel (the boundary deviations BEM and MFS have at
#: 1 MP, bench/methods_table.py), 0.4 % of the size for polygons under 250 px.
BAND = 1.0
BAND_RELATIVE = 4e-3
#: Along edges, cells are no longer than this fraction of the polygon's size.
ALONG = 5e-4
#: Rounds of splitting at most (each halves the cells).
MAX_ROUNDS = 24
#: Samples at most in one certificate; beyond, unproved cells count as their samples.
MAX_SAMPLES = 2_000_000


def band_floor(size: float) -> float:
    """The smallest cells and the nearest band to the boundary: 0.01 (px) or 1e-5 of the size if smaller.

    Parameters
    ----------
    size : float
        The longer side of the polygon's bounding box.

    Returns
    -------
    float
    """
    return min(0.01, 1e-5 * size)


@dataclass(frozen=True)
class Cover:
    """Square cells covering a polygon: centres and half-sides."""

    centres: NDArray[np.float64]
    half: NDArray[np.float64]


def _keep(centres, half, vertices, near):
    """The cells whose centre lies inside, farther than ``near`` from the boundary."""
    if not len(centres):
        return centres, half
    ok = inside_polygon(centres, vertices)
    idx = np.flatnonzero(ok)
    close = on_boundary(centres[idx], vertices, near)[0]
    ok[idx[close]] = False
    return centres[ok], half[ok]


def cover(vertices: NDArray[np.float64], near: float) -> Cover:
    """The starting cells of a polygon's certificate: interior grid, edge bands, corner polar grids.

    Parameters
    ----------
    vertices : (n, 2) ndarray of float
        The polygon, either orientation.
    near : float
        Cells whose centre is this close to the boundary are left out.

    Returns
    -------
    Cover
    """
    v = np.asarray(vertices, dtype=np.float64)
    n = len(v)
    xmin, ymin = v.min(axis=0)
    xmax, ymax = v.max(axis=0)
    size = float(max(xmax - xmin, ymax - ymin))
    area2 = float(np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1]))
    step = math.sqrt(abs(area2) / 2 / GRID_CELLS)
    floor = band_floor(size)
    # the grid of the former certificate (its samples are still checked)
    xs = np.arange(xmin + step / 2, xmax, step)
    ys = np.arange(ymin + step / 2, ymax, step)
    centres = [np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)]
    half = [np.full(len(centres[0]), step / 2)]
    # bands: layers at distances step/2, step/4, ... down to the floor
    e = np.roll(v, -1, axis=0) - v
    length = np.hypot(e[:, 0], e[:, 1])
    inward = np.stack([-e[:, 1], e[:, 0]], axis=1) / length[:, None] * math.copysign(1.0, area2)
    dist = []
    d = step / 2
    while d > floor:
        dist.append(d)
        d /= 2
    dist.append(floor)
    for d in dist:  # loop over layers (a few dozen), vectorised over edges
        along = min(max(2 * d, ALONG * size), step)
        count = np.maximum(1, np.ceil(length / along)).astype(np.int64)
        edge = np.repeat(np.arange(n), count)
        first = np.concatenate([[0], np.cumsum(count)[:-1]])
        t = (np.arange(int(count.sum())) - np.repeat(first, count) + 0.5) / count[edge]
        centres.append(v[edge] + t[:, None] * e[edge] + d * inward[edge])
        half.append(np.maximum(0.5 * length[edge] / count[edge], 0.5 * d))
    # polar grids in each corner's wedge: radii from the floor to the step, by factors of 1.5
    radii = floor * 1.5 ** np.arange(max(1, math.ceil(math.log(step / floor) / math.log(1.5)) + 1))
    start = np.arctan2(e[:, 1], e[:, 0])  # the outgoing edge's direction
    back = -np.roll(e, 1, axis=0)  # the incoming edge, from the vertex
    wedge = np.mod(np.arctan2(back[:, 1], back[:, 0]) - start, 2 * np.pi)
    if area2 < 0:  # the interior is clockwise from the outgoing edge
        start, wedge = start - (2 * np.pi - wedge), 2 * np.pi - wedge
    for i in range(n):  # loop over vertices
        k = max(3, math.ceil(wedge[i] / 0.3))
        ang = start[i] + (np.arange(k) + 0.5) / k * wedge[i]
        ring = np.stack([np.cos(ang), np.sin(ang)], axis=1)
        centres.append((v[i] + radii[:, None, None] * ring[None]).reshape(-1, 2))
        half.append(np.repeat(radii * max(0.5 * wedge[i] / k, 0.25), k))
    c, h = _keep(np.concatenate(centres), np.concatenate(half), v, near)
    return Cover(c, h)


def certify_cells(solution, vertices, theta, sign: float, near: float) -> tuple[int, int]:
    """Check a smooth map cell by cell (see the module's docstring).

    Parameters
    ----------
    solution : ClosedForm
        ``value_jacobian_hessian(points)`` of the map.
    vertices : (n, 2) ndarray of float
        Its polygon.
    theta : Theta
        Where its values must lie.
    sign : float
        +1 or -1: the sign det J has when the map preserves the orientation
        it should (Theta's orientation times the polygon's).
    near : float
        No samples this close to the boundary.

    Returns
    -------
    failed : int
        Samples where det J <= 0, is not finite, or the value leaves Theta.
    checked : int
        Samples evaluated.
    """
    v = np.asarray(vertices, dtype=np.float64)
    size = float(np.ptp(v, axis=0).max())
    floor = band_floor(size)
    band = min(BAND, BAND_RELATIVE * size)
    cells = cover(v, near)
    centres, half = cells.centres, cells.half
    w = theta.points
    d = np.roll(w, -1, axis=0) - w
    nd = d / np.hypot(d[:, 0], d[:, 1])[:, None]
    slack = OUTSIDE * float(np.ptp(w, axis=0).max())
    failed = checked = 0
    for _ in range(MAX_ROUNDS):  # each round splits the cells it could not prove
        if not len(centres):
            break
        val, j, h = solution.value_jacobian_hessian(centres)
        checked += len(centres)
        det = sign * (j[:, 0, 0] * j[:, 1, 1] - j[:, 0, 1] * j[:, 1, 0])
        # d det J / dx_c = dJ00/dx_c J11 + J00 dJ11/dx_c - dJ01/dx_c J10 - J01 dJ10/dx_c
        grad = sign * (
            h[:, 0, 0, :] * j[:, 1, 1, None] + j[:, 0, 0, None] * h[:, 1, 1, :]
            - h[:, 0, 1, :] * j[:, 1, 0, None] - j[:, 0, 1, None] * h[:, 1, 0, :]
        )  # fmt: skip
        beyond = np.zeros(len(val))
        for i in range(len(w)):  # convex Theta: how far beyond its farthest edge line
            cross = nd[i, 0] * (val[:, 1] - w[i, 1]) - nd[i, 1] * (val[:, 0] - w[i, 0])
            beyond = np.maximum(beyond, -cross * theta.orientation)
        out = beyond > slack
        if out.any():
            # Outside Theta by e at distance delta from the boundary: the
            # boundary seen through phi moves inward by about delta + e /
            # sigma_min(J). Within `BAND` that is the closed form's boundary
            # error (the warp clamps onto Theta's edge, a sub-pixel shift);
            # deeper, the map leaves Theta where the exact one cannot.
            k = np.flatnonzero(out)
            sigma = _smallest_singular_value(j[k])
            delta = nearest_edge(centres[k], v)[2]
            with np.errstate(divide="ignore", invalid="ignore"):
                out[k] = ~(delta + beyond[k] / sigma <= band)
        bad = ~(det > 0) | out
        failed += int(bad.sum())
        reach = np.hypot(grad[:, 0], grad[:, 1]) * half * math.sqrt(2.0)
        split = np.flatnonzero(~bad & ~(det > MARGIN * reach) & (half > floor))
        # a failure decides the verdict: splitting further would only count more
        if failed or not split.size or checked + 4 * split.size > MAX_SAMPLES:
            break
        q = half[split] / 2
        corners = np.array([[-1.0, -1.0], [1.0, -1.0], [-1.0, 1.0], [1.0, 1.0]])
        kids = (centres[split, None, :] + corners[None] * q[:, None, None]).reshape(-1, 2)
        centres, half = _keep(kids, np.repeat(q, 4), v, near)
    return failed, checked


def _smallest_singular_value(j: NDArray[np.float64]) -> NDArray[np.float64]:
    """sigma_min of stacked 2x2 matrices: |det| / sigma_max, sigma_max = (sqrt(s + 2|det|) + sqrt(s - 2|det|)) / 2."""
    a, b, c, d = j[:, 0, 0], j[:, 0, 1], j[:, 1, 0], j[:, 1, 1]
    s = a * a + b * b + c * c + d * d
    det = np.abs(a * d - b * c)
    top = 0.5 * (np.sqrt(s + 2 * det) + np.sqrt(np.maximum(s - 2 * det, 0.0)))
    return det / top
