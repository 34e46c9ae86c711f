"""Exact orientation predicates, segment tests and the signed area of vertex arrays."""

from __future__ import annotations

from collections.abc import Sequence
from fractions import Fraction

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "intersection_point", "orient", "orient_sign", "orient_sign_one", "point_segment_distance", "segments_touch", "signed_area",
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
_EPS = 2.0**-53
_ORIENT_BOUND = (3.0 + 16.0 * _EPS) * _EPS


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
        A bound on its rounding error (Shewchuk's ccwerrboundA).
    """
    left = (bx - ax) * (cy - ay)
    right = (by - ay) * (cx - ax)
    return left - right, _ORIENT_BOUND * (np.abs(left) + np.abs(right))


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
    bound = _ORIENT_BOUND * (abs(left) + abs(right))
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
