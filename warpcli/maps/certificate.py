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
  counted as they are (`CellCertificate.unproved`). With ``rigorous=True``
  (MFS maps' default) the cell is proved instead by `lower_bound`, a
  lower bound of det J over the whole cell from the closed form's
  structure (BEM: 1.5-5x the first-order test's time on the bench pairs,
  so opt-in; docs/proving.md).

Around a vertex where the boundary data themselves make the exact map's
det J tend to 0 (`degenerate_vertices`: a boundary behaviour with no slope
there, such as t^2; mixed conditions at a corner that is not a right
angle), the closed form's sign near the vertex is its approximation error,
not a fold of the exact map, so a ball may be left out there:

- the ball is the smallest around the vertex holding every cell whose
  sample fails, and only cells lying wholly within `vertex_ball` (5 % of
  the size) can be held; every cell reaching beyond is certified as
  anywhere else, so the ball's boundary arc is certified;
- it is left out only if its radius, or the diameter of its image (in the
  polygon's units), is within the band (`BAND`, 1 px): the image is bounded
  by the maximum principle (`_ball_image`), so whatever the closed form
  does inside, it does within a sub-pixel region of the source or of the
  target; otherwise the cells it holds count as failures.

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

__all__ = [
    "BAND", "BAND_RELATIVE", "GRID_CELLS", "MARGIN", "OUTSIDE", "CellCertificate", "Cover", "band_floor", "certify_cells",
    "cover", "degenerate_vertices", "lower_bound", "vertex_ball",
]  # fmt: skip

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
#: The largest ball (relative to the polygon's size) that may be left out around a vertex whose
#: boundary data force det J -> 0 there (`degenerate_vertices`); it is left out only if its radius,
#: or the diameter of its image (in the polygon's units), is within the band (`BAND`).
VERTEX_BALL = 0.05
#: Points sampled on the boundary of a left-out ball to bound the diameter of its image.
BALL_SAMPLES = 96
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


def vertex_ball(size: float) -> float:
    """The largest ball that may be left out around a degenerate vertex: `VERTEX_BALL` of the polygon's size.

    Parameters
    ----------
    size : float
        The longer side of the polygon's bounding box.

    Returns
    -------
    float
    """
    return VERTEX_BALL * size


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


@dataclass(frozen=True)
class CellCertificate:
    """What `certify_cells` found.

    Attributes
    ----------
    failed : int
        Samples where det J <= 0, is not finite, or the value leaves Theta
        (outside the excluded balls).
    checked : int
        Samples evaluated.
    excluded : tuple of (int, float)
        ``(vertex, radius)`` of each ball left out around a vertex whose
        boundary data force det J to 0 (see `certify_cells`'s ``balls``):
        the smallest radius outside which every cell was proved.
    unproved : int
        Cells whose sample passed but that were not proved at the smallest
        size (or when `MAX_SAMPLES` stopped the splitting): the first-order
        test and `lower_bound` leave these to their samples.
    """

    failed: int
    checked: int
    excluded: tuple[tuple[int, float], ...] = ()
    unproved: int = 0


def certify_cells(
    solution, vertices, theta, sign: float, near: float, balls=None, rigorous: bool = False
) -> CellCertificate:
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
    balls : (n,) array_like of float, optional
        Per vertex, the largest radius of a ball that may be left out (0:
        none). Only for vertices where the boundary data themselves make
        the exact map's det J tend to 0 (`degenerate_vertices`): there the
        closed form's sign is its approximation error. A cell lying wholly
        inside such a ball whose sample fails is held by the ball, not
        counted (yet) as a failure; the ball actually left out is the
        smallest around the vertex containing all such cells, reported in
        `CellCertificate.excluded`. Every cell reaching beyond the cap is
        certified as everywhere else.
    rigorous : bool
        Prove each cell with `lower_bound` (a bound of det J over the whole
        cell from the closed form's structure) instead of the first-order
        test; cells still unproved at the smallest size are counted in
        `CellCertificate.unproved`.

    Returns
    -------
    CellCertificate
    """
    v = np.asarray(vertices, dtype=np.float64)
    size = float(np.ptp(v, axis=0).max())
    floor = band_floor(size)
    band = min(BAND, BAND_RELATIVE * size)
    cells = cover(v, near)
    centres, half = cells.centres, cells.half
    caps = np.zeros(len(v)) if balls is None else np.asarray(balls, dtype=np.float64)
    ball_at = np.flatnonzero(caps > 0)
    radius = np.zeros(len(v))  # the balls actually left out
    held = np.zeros(len(v), dtype=np.int64)  # and the samples they hold
    w = theta.points
    d = np.roll(w, -1, axis=0) - w
    nd = d / np.hypot(d[:, 0], d[:, 1])[:, None]
    slack = OUTSIDE * float(np.ptp(w, axis=0).max())
    failed = checked = left = 0
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
            # Outside Theta by e_i beyond edge line i at distance delta from
            # the boundary: the point x0 would have to move by e_i / |J^T n_i|
            # (n_i the edge's outward normal; the level set of the harmonic
            # n_i . phi, to first order) for its value to be back on that
            # line, so the boundary seen through phi moves inward by about
            # delta + max_i e_i / |J^T n_i|. Within `BAND` that is the closed
            # form's boundary error (the warp clamps onto Theta's edge, a
            # sub-pixel shift); deeper, the map leaves Theta where the exact
            # one cannot. (sigma_min(J) <= |J^T n_i| would overstate it
            # where J is nearly singular, as at degenerate vertices, where
            # the value moves along the edge, not across it.)
            k = np.flatnonzero(out)
            shift = np.zeros(k.size)
            for i in range(len(w)):  # loop over Theta's edges
                cross = nd[i, 0] * (val[k, 1] - w[i, 1]) - nd[i, 1] * (val[k, 0] - w[i, 0])
                e = -cross * theta.orientation
                normal = np.array([nd[i, 1], -nd[i, 0]]) * theta.orientation  # outward
                across = np.hypot(*(np.einsum("kab,a->kb", j[k], normal)).T)  # |J^T n_i|
                with np.errstate(divide="ignore", invalid="ignore"):
                    shift = np.where(e > slack, np.fmax(shift, np.where(across > 0, e / across, np.inf)), shift)
            delta = nearest_edge(centres[k], v)[2]
            out[k] = ~(delta + shift <= band)
        bad = ~(det > 0) | out
        reach = half * math.sqrt(2.0)
        if rigorous:
            proved = lower_bound(solution, centres, reach, j, h, sign) > 0
        else:
            proved = det > MARGIN * np.hypot(grad[:, 0], grad[:, 1]) * reach
        unproved = bad | ~proved
        if ball_at.size:
            # A cell wholly inside a vertex's ball whose sample fails is left
            # out with the ball (its radius grows to cover the cell); cells
            # there that are not proved are split as anywhere else (and
            # count as their samples at the smallest size): the ball shrinks
            # to where the samples themselves fail.
            stuck = bad
            for i in ball_at:  # loop over the (few) degenerate vertices
                far = np.hypot(centres[:, 0] - v[i, 0], centres[:, 1] - v[i, 1]) + reach
                mine = stuck & (far <= caps[i])
                if mine.any():
                    radius[i] = max(radius[i], float(far[mine].max()))
                    held[i] += int(mine.sum())
                    bad &= ~mine
                    unproved &= ~mine
        failed += int(bad.sum())
        split = np.flatnonzero(unproved & ~bad & (half > floor))
        left += int((unproved & ~bad & ~(half > floor)).sum())
        # a failure decides the verdict: splitting further would only count more
        if failed or not split.size or checked + 4 * split.size > MAX_SAMPLES:
            if not failed and checked + 4 * split.size > MAX_SAMPLES:
                left += split.size
            break
        q = half[split] / 2
        corners = np.array([[-1.0, -1.0], [1.0, -1.0], [-1.0, 1.0], [1.0, 1.0]])
        kids = (centres[split, None, :] + corners[None] * q[:, None, None]).reshape(-1, 2)
        centres, half = _keep(kids, np.repeat(q, 4), v, near)
    excluded = []
    tsize = float(np.ptp(w, axis=0).max())
    for i in np.flatnonzero(radius > 0):  # loop over the balls left out (a few vertices)
        image = _ball_image(solution, v, i, radius[i], floor, near) * size / tsize
        checked += BALL_SAMPLES
        if min(radius[i], image) <= band:
            excluded.append((int(i), float(radius[i])))
        else:  # too large to leave out: what it holds fails
            failed += int(held[i])
    return CellCertificate(failed, checked, tuple(excluded), left)


def lower_bound(solution, centres, reach, j, h, sign: float) -> NDArray[np.float64]:
    """A lower bound of sign * det J over each disc (centre x0, radius r): positive proves the sign there.

    With f = u + i v, A = f_z and B = conj(f_zbar) analytic, det J = |A|^2 -
    |B|^2. Write A(x0 + h) = A0 + A1 h + R_A (A1 = A'(x0)) with |R_A| <=
    rho_A over the disc (`ClosedForm.derivative_bounds`), and the same for
    B. Then

        |A|^2 - |A0|^2 - 2 Re(A1 h conj(A0)) = |A1 h + R_A|^2 + 2 Re(R_A conj(A0)) >= -2 rho_A |A0|,
        |B|^2 - |B0|^2 - 2 Re(B1 h conj(B0)) <= (|B1| r + rho_B)^2 + 2 rho_B |B0|,

    and the first-order terms sum to grad det J(x0) . h, so over the disc

        det J >= det J(x0) - |grad det J(x0)| r - 2 rho_A |A0| - 2 rho_B |B0| - (|B1| r + rho_B)^2,

    less the effect of the evaluation error eta of A0 and B0 on det J(x0)
    (2 eta (|A0| + |B0| + eta)). For ``sign`` -1 (a map that should
    reverse orientation) the bound is that of -det J = |B|^2 - |A|^2: A
    and B swap roles. j and h are the Jacobian and Hessian at the centres
    (the caller's coordinates).

    Returns
    -------
    (K,) ndarray of float
    """
    bound = solution.derivative_bounds(centres, reach)
    eta, rho_a, rho_b = bound[:, 0], bound[:, 1], bound[:, 2]
    ux, uy, vx, vy = j[:, 0, 0], j[:, 0, 1], j[:, 1, 0], j[:, 1, 1]
    a0 = 0.5 * np.hypot(ux + vy, vx - uy)
    b0 = 0.5 * np.hypot(ux - vy, vx + uy)
    uxx, uxy, vxx, vxy = h[:, 0, 0, 0], h[:, 0, 0, 1], h[:, 1, 0, 0], h[:, 1, 0, 1]
    a1 = 0.5 * np.hypot(uxx + vxy, vxx - uxy)
    b1 = 0.5 * np.hypot(uxx - vxy, vxx + uxy)
    # sign * det J and its gradient at the centres
    det = sign * (ux * vy - uy * vx)
    grad = sign * (
        h[:, 0, 0, :] * vy[:, None] + ux[:, None] * h[:, 1, 1, :] - h[:, 0, 1, :] * vx[:, None] - uy[:, None] * h[:, 1, 0, :]
    )  # fmt: skip
    if sign < 0:  # -det J = |B|^2 - |A|^2
        a0, b0, a1, b1, rho_a, rho_b = b0, a0, b1, a1, rho_b, rho_a
    p0, prho, q0, q1, qrho = a0, rho_a, b0, b1, rho_b
    with np.errstate(invalid="ignore", over="ignore"):
        out = (
            det - np.hypot(grad[:, 0], grad[:, 1]) * reach
            - 2.0 * prho * p0 - 2.0 * qrho * q0 - (q1 * reach + qrho) ** 2
            - 2.0 * eta * (a0 + b0 + eta)
        )  # fmt: skip
    return np.where(np.isfinite(out), out, -np.inf)


def _ball_image(solution, v: NDArray[np.float64], i: int, r: float, floor: float, near: float) -> float:
    """An upper bound of the diameter of phi(P n B(v_i, r)), from phi on the ball's boundary.

    Each component of the closed form is harmonic in the polygon, so by
    the maximum principle (applied to every linear functional of phi) the
    image of P n B lies in the convex hull of the image of its boundary:
    the arc of radius r inside the polygon and the two edge segments from
    v_i (taken `floor` inside them, where the closed form is sampled
    anyway). The diameter of the samples' values plus the largest |J| times
    half their spacing bounds that of the hull (to first order in the
    spacing).
    """
    n = len(v)
    e_out = v[(i + 1) % n] - v[i]
    e_in = v[(i - 1) % n] - v[i]
    u_out, u_in = e_out / np.hypot(*e_out), e_in / np.hypot(*e_in)
    area2 = float(np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1]))
    sgn = math.copysign(1.0, area2)
    n_out = sgn * np.array([-u_out[1], u_out[0]])  # inward normals
    n_in = -sgn * np.array([-u_in[1], u_in[0]])
    a0 = math.atan2(u_out[1], u_out[0])
    wedge = math.atan2(u_out[0] * u_in[1] - u_out[1] * u_in[0], float(u_out @ u_in)) * sgn % (2 * math.pi)
    k = BALL_SAMPLES // 2
    ang = a0 + sgn * np.linspace(0.0, wedge, k)
    ring = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    s = np.linspace(0.0, r, BALL_SAMPLES // 4 + 1)
    sides = np.concatenate([v[i] + s[:, None] * u_out + floor * n_out, v[i] + s[:, None] * u_in + floor * n_in])
    # the arc of radius r, the two sides `floor` inside the edges, and the
    # arc of radius `floor` that closes them around a reflex corner (points
    # beyond the region only enlarge the hull)
    pts = np.concatenate([v[i] + r * ring, sides, v[i] + min(floor, r) * ring])
    pts, _ = _keep(pts, np.zeros(len(pts)), v, near)
    if not len(pts):
        return 0.0
    val, j = solution.value_and_jacobian(pts)
    if not (np.isfinite(val).all() and np.isfinite(j).all()):
        return math.inf
    diam = float(np.max(np.hypot(*(val[:, None, :] - val[None, :, :]).transpose(2, 0, 1))))
    spacing = max(r * wedge / (k - 1), r / (BALL_SAMPLES // 4))
    top = float(np.max(np.sqrt((j**2).sum(axis=(1, 2)))))  # Frobenius >= spectral norm
    return diam + top * spacing


def degenerate_vertices(vertices, theta_points, boundary_to_theta, mixed: bool = False) -> NDArray[np.bool_]:
    """The vertices where the boundary data alone make the exact map's det J tend to 0.

    Near a vertex v the exact harmonic map is, to leading order, the affine
    map taking the two edges' directions to the one-sided derivatives of
    the boundary data along them, plus singular terms r^(pi/alpha) of the
    corner's angle alpha. Its det J tends to 0 at v when:

    - a one-sided derivative of the data vanishes: the data leave the
      vertex slower than linearly along an incident edge (the quadratic
      behaviour t^2 at an edge's start, a boundary map that stalls there),
      or the edge's image is a point (a zero-length edge of Theta). Then
      the affine part has rank 1 or less, and every other term is o(r^0)
      in the gradient at a convex corner, o(1) in det J;
    - mixed conditions (each component prescribed on one incident edge and
      free on the other) at a corner of angle alpha < pi / 2: each
      component behaves as r^(pi / (2 alpha)), an exponent above 1, so
      both gradients tend to 0.

    The test of the first kind is numerical: the data's secant slope over
    1e-6 of each incident edge, against the edge's mean slope (|image| /
    |edge|, times the ratio of the polygons' sizes where Theta's edge is a
    point), below 1e-3: 1 for linear data, 1e-6 for t^2.

    Parameters
    ----------
    vertices : (n, 2) ndarray of float
        The polygon.
    theta_points : (n, 2) ndarray of float
        Theta.
    boundary_to_theta : callable
        ``(edge, t) -> (k, 2)`` points of Theta: the map's boundary data.
    mixed : bool
        Mixed conditions (§5.2): at every vertex one component is free on
        one incident edge and prescribed on the other.

    Returns
    -------
    (n,) ndarray of bool
    """
    v = np.asarray(vertices, dtype=np.float64)
    w = np.asarray(theta_points, dtype=np.float64)
    n = len(v)
    idx = np.arange(n)
    prev = (idx - 1) % n
    length = np.hypot(*(np.roll(v, -1, axis=0) - v).T)
    image = np.hypot(*(np.roll(w, -1, axis=0) - w).T)
    # the mean slope of the data along each edge; a point-like image of Theta
    # is measured against the polygons' sizes instead (its slope is ~0)
    mean = np.maximum(image, 1e-9 * float(np.ptp(w, axis=0).max())) / length
    scale = float(np.ptp(w, axis=0).max()) / float(np.ptp(v, axis=0).max())
    h = 1e-6
    out = np.hypot(*(boundary_to_theta(idx, np.full(n, h)) - boundary_to_theta(idx, np.zeros(n))).T) / (h * length)
    back = np.hypot(*(boundary_to_theta(prev, np.ones(n)) - boundary_to_theta(prev, np.full(n, 1 - h))).T) / (
        h * length[prev]
    )
    slow = (out < 1e-3 * np.minimum(mean, scale)) | (back < 1e-3 * np.minimum(mean[prev], scale))
    if mixed:
        e = np.roll(v, -1, axis=0) - v
        a, b = e, -e[prev]  # from the vertex along the outgoing and the incoming edge
        area2 = float(np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1]))
        turn = np.arctan2(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0], (a * b).sum(axis=1)) * math.copysign(1.0, area2)
        angle = np.mod(turn, 2 * np.pi)  # the interior angle at each vertex
        slow |= np.abs(angle - np.pi / 2) > 1e-9
    return slow
