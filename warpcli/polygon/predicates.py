"""Exact orientation predicates, segment tests and the signed area of vertex arrays."""

from __future__ import annotations

import math
from collections.abc import Sequence
from fractions import Fraction

import numpy as np
from numpy.typing import NDArray

from ..simplicial import corners

__all__ = [
    "intersection_point", "orient", "orient3d_sign", "orient_sign", "orient_sign_one", "orientations",
    "point_segment_distance", "segments_touch", "signed_area",
]  # fmt: skip


def signed_area(points: NDArray[np.float64]) -> float:
    """Shoelace formula; the sign gives the orientation.

    Coordinates are taken relative to the first vertex, so that a small
    polygon far from the origin (at 1e9, say) keeps its area's digits.

    Parameters
    ----------
    points : (n, 2) array_like of float
        Vertices in order; the polygon closes itself.

    Returns
    -------
    float
        Positive when the vertices run clockwise on screen (y down), 0.0 for
        no vertices.

    Examples
    --------
    >>> signed_area(np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 1.0]]))
    1.0
    """
    points = np.asarray(points, dtype=np.float64)
    if not len(points):
        return 0.0
    x = points[:, 0] - points[0, 0]
    y = points[:, 1] - points[0, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


# Shewchuk's bound on the rounding error of the orientation determinant
# computed in doubles ("Adaptive precision floating-point arithmetic and fast
# robust geometric predicates", 1997, ccwerrboundA): if |det| exceeds it, the
# sign of the computed det is the sign of the exact one.
# The bound assumes no underflow: a product below the normal range has an
# absolute error of up to 2**-1075 instead (in 1e-155 coordinates, a float
# determinant of one subnormal unit had the wrong sign in 1 case of 7 found
# near a line), hence `_UNDERFLOW2` on top.
_EPS = 2.0**-53
_ORIENT_BOUND = (3.0 + 16.0 * _EPS) * _EPS
_UNDERFLOW2 = 2.0**-1072


def orient(ax, ay, bx, by, cx, cy):
    """(b - a) x (c - a) in doubles, and a bound on its rounding error (vectorized).

    Where ``abs(det) > bound`` the sign of ``det`` is exact; elsewhere ask
    `orient_sign`. A cheap filter for tests that only need the certain cases.

    Parameters
    ----------
    ax, ay, bx, by, cx, cy : (m,) ndarray of float
        The coordinates of the points a, b and c.

    Returns
    -------
    det : (m,) ndarray of float
        The determinant computed in doubles.
    bound : (m,) ndarray of float
        A bound on its rounding error (Shewchuk's ccwerrboundA, plus the
        error of products that underflow).
    """
    left = (bx - ax) * (cy - ay)
    right = (by - ay) * (cx - ax)
    return left - right, _ORIENT_BOUND * (np.abs(left) + np.abs(right)) + _UNDERFLOW2


def orient_sign(ax, ay, bx, by, cx, cy) -> NDArray[np.float64]:
    """The exact sign (1, 0 or -1) of (b - a) x (c - a) for double coordinates (vectorized).

    Positive when c is to the left of the line from a to b (y up).

    Parameters
    ----------
    ax, ay, bx, by, cx, cy : (m,) ndarray of float
        The coordinates of the points a, b and c.

    Returns
    -------
    (m,) ndarray of float
        1.0, 0.0 or -1.0: the sign of the exact determinant of the doubles
        given, at any distance from the origin.

    Examples
    --------
    >>> float(orient_sign(*(np.array([v]) for v in (0.0, 0.0, 3.0, 1.0, 6.0, 2.0)))[0])
    0.0
    """
    det, bound = orient(ax, ay, bx, by, cx, cy)
    sign = np.sign(det)
    unsure = np.flatnonzero(~(np.abs(det) > bound))
    if unsure.size:
        ax, ay, bx, by, cx, cy = (np.asarray(v)[unsure] for v in (ax, ay, bx, by, cx, cy))
        # Most undecided determinants are exact zeros of axis-parallel points (the points along a
        # rectangle's side, the outline of ``--within``): when a factor of each product is a
        # difference of equal coordinates, both products are exactly 0. Compared as coordinates, not
        # as differences, this needs no reasoning about rounding; the rest get the exact expansion.
        zero = ((bx == ax) | (cy == ay)) & ((by == ay) | (cx == ax))
        exact = np.zeros(len(unsure))
        hard = np.flatnonzero(~zero)
        if hard.size:
            exact[hard] = _orient_sign_exact(ax[hard], ay[hard], bx[hard], by[hard], cx[hard], cy[hard])
        sign[unsure] = exact
    return sign


def orient_sign_one(a: Sequence[float], b: Sequence[float], c: Sequence[float]) -> int:
    """`orient_sign` of one triple of points given as Python floats: 1, 0 or -1, exactly.

    The same filter in the same double arithmetic (Python's floats are
    IEEE doubles, as numpy's), then rational arithmetic for what it leaves
    undecided: for code that tests triangles one at a time (edge flips),
    where a numpy call per triangle costs a hundred times the arithmetic.

    Parameters
    ----------
    a, b, c : (x, y) pairs of float

    Examples
    --------
    >>> orient_sign_one((0.0, 0.0), (3.0, 1.0), (6.0, 2.0)), orient_sign_one((0.0, 0.0), (1.0, 0.0), (0.0, 1.0))
    (0, 1)
    """
    ax, ay = a
    left = (b[0] - ax) * (c[1] - ay)
    right = (b[1] - ay) * (c[0] - ax)
    det = left - right
    bound = _ORIENT_BOUND * (abs(left) + abs(right)) + _UNDERFLOW2  # as `orient`: products that underflow
    if det > bound:
        return 1
    if -det > bound:
        return -1
    fx = [Fraction(float(v)) for v in (ax, ay, b[0], b[1], c[0], c[1])]
    d = (fx[2] - fx[0]) * (fx[5] - fx[1]) - (fx[3] - fx[1]) * (fx[4] - fx[0])
    return (d > 0) - (d < 0)


def _orient_sign_exact(ax, ay, bx, by, cx, cy) -> NDArray[np.float64]:
    """Exact signs for the few determinants too close to 0 for the error bound (vectorized).

    Each difference is an exact sum of two doubles (Knuth's two-difference),
    each product of those an exact sum of two (Dekker's product), and the
    sixteen terms are added exactly into a non-overlapping expansion
    (Shewchuk's grow-expansion), whose largest non-zero term has the sign of
    the whole. Values so tiny that products could underflow go to rational
    arithmetic instead.
    """
    dx1, dy2, dy1, dx2 = (_two_diff(u, v) for u, v in ((bx, ax), (cy, ay), (by, ay), (cx, ax)))
    terms = []
    for (p, q), sign in (((dx1, dy2), 1.0), ((dy1, dx2), -1.0)):
        for u in p:
            for v in q:
                x, err = _two_product(u, v)
                terms += [sign * x, sign * err]
    expansion: list = []
    for t in terms:
        grown = []
        for h in expansion:
            t, err = _two_sum(t, h)
            grown.append(err)
        expansion = grown + [t]
    sign = np.zeros(len(ax))
    for h in expansion:  # increasing magnitude: the last non-zero term decides
        sign = np.where(h != 0, np.sign(h), sign)
    tiny = np.zeros(len(ax), dtype=bool)
    for v in (*dx1, *dy2, *dy1, *dx2):
        tiny |= (v != 0) & (np.abs(v) < 2.0**-450)
    for i in np.flatnonzero(tiny):
        fx = [Fraction(float(v[i])) for v in (ax, ay, bx, by, cx, cy)]
        d = (fx[2] - fx[0]) * (fx[5] - fx[1]) - (fx[3] - fx[1]) * (fx[4] - fx[0])
        sign[i] = (d > 0) - (d < 0)
    return sign


def _two_sum(a, b):
    """(x, err) with x = fl(a + b) and a + b = x + err exactly (Knuth)."""
    x = a + b
    bv = x - a
    av = x - bv
    return x, (a - av) + (b - bv)


def _two_diff(a, b):
    """(x, err) with x = fl(a - b) and a - b = x + err exactly (Knuth)."""
    x = a - b
    bv = a - x
    av = x + bv
    return x, (a - av) + (bv - b)


def _two_product(a, b):
    """(x, err) with x = fl(a b) and a b = x + err exactly (Dekker, with Veltkamp's split)."""
    x = a * b
    ah, al = _split(a)
    bh, bl = _split(b)
    return x, al * bl - (((x - ah * bh) - al * bh) - ah * bl)


def _split(a):
    c = 134217729.0 * a  # 2**27 + 1
    hi = c - (c - a)
    return hi, a - hi


def orientations(vertices: NDArray[np.float64], triangles: NDArray[np.integer]) -> NDArray[np.float64]:
    """The exact orientation (1, 0 or -1) of each triangle of a mesh, with `signed_area`'s sign convention.

    Parameters
    ----------
    vertices : (N, 2) ndarray of float
    triangles : (M, 3) ndarray of int

    Returns
    -------
    (M,) ndarray of float
        The sign of each triangle's exact signed area (positive when
        clockwise on screen, y down); 0.0 for a degenerate one; NaN where a
        corner is not finite.

    Examples
    --------
    >>> v = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [2.0, 0.0]])
    >>> orientations(v, np.array([[0, 1, 2], [0, 2, 1], [0, 1, 3]])).tolist()
    [1.0, -1.0, 0.0]
    """
    a, b, c = corners(vertices, triangles)
    return orient_sign(a[:, 0], a[:, 1], b[:, 0], b[:, 1], c[:, 0], c[:, 1])


# Shewchuk's o3derrboundA: the bound on the rounding error of the 3 x 3
# determinant of differences computed in doubles, relative to its permanent.
# It assumes no underflow: a product that lands below the normal range has an
# absolute error of up to 2**-1075 instead, carried through the last products
# by the differences it is multiplied with, hence `_UNDERFLOW` * (1 + sum |u|)
# on top. (Overflow needs nothing: the permanent is then infinite and no
# determinant passes the test.)
_ORIENT3D_BOUND = (7.0 + 56.0 * _EPS) * _EPS
_UNDERFLOW = 2.0**-1070


def orient3d_sign(a, b, c, d) -> NDArray[np.float64]:
    """The exact sign (1, 0 or -1) of det[b - a, c - a, d - a] for double coordinates (vectorized).

    Positive when the tetrahedron a, b, c, d is positively oriented (the sign
    of `warpcli.volume.tetmesh.tet_volumes`): d is on the side of the plane
    abc that (b - a) x (c - a) points to. The determinant is computed in
    doubles and its sign kept where it exceeds Shewchuk's error bound
    (o3derrboundA); the few others (near-flat tetrahedra) are decided in
    exact integer arithmetic.

    Parameters
    ----------
    a, b, c, d : (m, 3) ndarray of float
        The corners.

    Returns
    -------
    (m,) ndarray of float
        1.0, 0.0 or -1.0: the sign of the exact determinant of the doubles
        given, at any scale; NaN where a coordinate is not finite.

    Examples
    --------
    >>> o = np.zeros((1, 3))
    >>> x, y, z = np.eye(3)[:, None, :]
    >>> float(orient3d_sign(o, x, y, z)[0]), float(orient3d_sign(o, y, x, z)[0]), float(orient3d_sign(o, x, y, x + y)[0])
    (1.0, -1.0, 0.0)
    """
    a, b, c, d = (np.asarray(p, dtype=np.float64) for p in (a, b, c, d))
    with np.errstate(over="ignore", invalid="ignore", under="ignore"):
        u, v, w = b - a, c - a, d - a
        vw0, vw1, vw2 = v[:, 1] * w[:, 2], v[:, 2] * w[:, 1], v[:, 2] * w[:, 0]
        vw3, vw4, vw5 = v[:, 0] * w[:, 2], v[:, 0] * w[:, 1], v[:, 1] * w[:, 0]
        det = u[:, 0] * (vw0 - vw1) + u[:, 1] * (vw2 - vw3) + u[:, 2] * (vw4 - vw5)
        u0, u1, u2 = np.abs(u[:, 0]), np.abs(u[:, 1]), np.abs(u[:, 2])
        permanent = (
            u0 * (np.abs(vw0) + np.abs(vw1)) + u1 * (np.abs(vw2) + np.abs(vw3)) + u2 * (np.abs(vw4) + np.abs(vw5))
        )
        bound = _ORIENT3D_BOUND * permanent + _UNDERFLOW * (1.0 + u0 + u1 + u2)
        unsure = ~(np.abs(det) > bound)
    sign = np.sign(det)
    for i in np.flatnonzero(unsure):
        sign[i] = _orient3d_exact(a[i], b[i], c[i], d[i])
    return sign


def _orient3d_exact(a, b, c, d) -> float:
    """The exact sign for one tetrahedron: doubles are dyadic rationals, so scaled by a common
    power of two they are integers, whose determinant Python computes exactly."""
    coords = [float(x) for p in (a, b, c, d) for x in p]
    if not all(math.isfinite(x) for x in coords):
        return math.nan
    ratios = [x.as_integer_ratio() for x in coords]  # denominators are powers of two
    den = max(q for _, q in ratios)
    n = [p * (den // q) for p, q in ratios]
    u0, u1, u2 = (n[3 + k] - n[k] for k in range(3))
    v0, v1, v2 = (n[6 + k] - n[k] for k in range(3))
    w0, w1, w2 = (n[9 + k] - n[k] for k in range(3))
    det = u0 * (v1 * w2 - v2 * w1) + u1 * (v2 * w0 - v0 * w2) + u2 * (v0 * w1 - v1 * w0)
    return float((det > 0) - (det < 0))


def point_segment_distance(p, a, b) -> NDArray[np.float64]:
    """Distance from each point p to the segment ab (vectorized).

    Parameters
    ----------
    p, a, b : (m, 2) ndarray of float
        The points, and the segments' ends.

    Returns
    -------
    (m,) ndarray of float
    """
    d = b - a
    dd = np.einsum("ij,ij->i", d, d)
    t = np.einsum("ij,ij->i", p - a, d)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(dd > 0, np.clip(t / dd, 0.0, 1.0), 0.0)
    c = a + t[:, None] * d
    return np.hypot(p[:, 0] - c[:, 0], p[:, 1] - c[:, 1])


def segments_touch(p1, p2, q1, q2) -> NDArray[np.bool_]:
    """Whether closed segments p1p2 and q1q2 share at least one point (vectorized, exact).

    Parameters
    ----------
    p1, p2, q1, q2 : (m, 2) ndarray of float
        The ends of the segments p (p1 to p2) and q (q1 to q2).

    Returns
    -------
    (m,) ndarray of bool
        Decided by `orient_sign`, so touching at one point counts, exactly.
    """
    o1 = orient_sign(p1[:, 0], p1[:, 1], p2[:, 0], p2[:, 1], q1[:, 0], q1[:, 1])
    o2 = orient_sign(p1[:, 0], p1[:, 1], p2[:, 0], p2[:, 1], q2[:, 0], q2[:, 1])
    o3 = orient_sign(q1[:, 0], q1[:, 1], q2[:, 0], q2[:, 1], p1[:, 0], p1[:, 1])
    o4 = orient_sign(q1[:, 0], q1[:, 1], q2[:, 0], q2[:, 1], p2[:, 0], p2[:, 1])
    proper = (o1 * o2 < 0) & (o3 * o4 < 0)
    touch = (
        ((o1 == 0) & _on_box(p1, p2, q1))
        | ((o2 == 0) & _on_box(p1, p2, q2))
        | ((o3 == 0) & _on_box(q1, q2, p1))
        | ((o4 == 0) & _on_box(q1, q2, p2))
    )
    return proper | touch


def _on_box(a, b, c) -> NDArray[np.bool_]:
    """For c collinear with segment ab: whether c lies on the segment."""
    lo = np.minimum(a, b)
    hi = np.maximum(a, b)
    return ((c >= lo) & (c <= hi)).all(axis=1)


def intersection_point(p1, p2, q1, q2) -> NDArray[np.float64]:
    """A point where segments p1p2 and q1q2 meet, for a message (in doubles, not exact).

    Parameters
    ----------
    p1, p2, q1, q2 : (2,) ndarray of float
        The ends of two segments that touch (see `segments_touch`).

    Returns
    -------
    (2,) ndarray of float
        Where their lines cross or, for collinear segments that overlap, an
        end of one that lies on the other.
    """
    d1 = p2 - p1
    d2 = q2 - q1
    den = d1[0] * d2[1] - d1[1] * d2[0]
    if den == 0:
        # Collinear overlap: report an endpoint that lies on the other segment.
        for c, (a, b) in ((q1, (p1, p2)), (q2, (p1, p2)), (p1, (q1, q2)), (p2, (q1, q2))):
            if _on_box(a[None], b[None], c[None])[0]:
                return c
        return p1
    t = ((q1[0] - p1[0]) * d2[1] - (q1[1] - p1[1]) * d2[0]) / den
    return p1 + t * d1
