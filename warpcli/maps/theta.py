"""Theta: the convex intermediate polygon both harmonic maps go onto, and the strategies that choose it."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError
from ..files import read_small_file
from ..polygon import Polygon, signed_area

#: Largest Theta file read, in bytes (n vertices as JSON).
MAX_THETA_BYTES = 1 << 20


@dataclass(frozen=True, eq=False)
class Theta:
    """A strictly convex polygon: the common image of both harmonic maps.

    Harmonic maps onto a convex domain are bijective (Radó-Kneser-Choquet,
    the paper's §2), which is why Theta must be convex.

    Parameters
    ----------
    points : (n, 2) array_like of float
        Vertices in order, either orientation.
    name : str
        Where it came from (a strategy's name or a file), for messages and reports.
    notes : dict
        What the strategy reports about it (the optimization's energies).

    Raises
    ------
    InputError
        If the polygon has fewer than 3 vertices or is not strictly convex.

    References
    ----------
    Schneider & Hormann, Smooth bijective maps between arbitrary planar
    polygons, CAGD 2015, §2 and §5.1.
    """

    points: NDArray[np.float64]
    name: str = field(default="theta")
    notes: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        pts = np.array(self.points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3:
            raise InputError(f"{self.name}: Theta needs at least 3 [x, y] vertices, got shape {pts.shape}")
        if not np.isfinite(pts).all():
            raise InputError(f"{self.name}: Theta has a non-finite coordinate")
        big = float(np.abs(pts).max())
        if big > THETA_COORD_LIMIT:
            # Beyond it, the products of the convexity test overflow: say so, not "not convex".
            raise InputError(
                f"{self.name}: Theta's coordinates are too large ({big:.3g}; the limit is {THETA_COORD_LIMIT:g}): "
                "scale it down, the map does not depend on Theta's size"
            )
        bad = _not_strictly_convex(pts)
        if bad is not None:
            raise InputError(f"{self.name}: Theta must be strictly convex, but it is not at vertex {bad}")
        pts.setflags(write=False)
        object.__setattr__(self, "points", pts)

    @property
    def n(self) -> int:
        """Number of vertices."""
        return len(self.points)

    @property
    def orientation(self) -> float:
        """+1 or -1: the sign of the shoelace area."""
        return float(np.sign(signed_area(self.points)))

    def clamp(self, points: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Move points outside Theta onto its nearest boundary point, in place.

        The exact harmonic map takes the polygon into Theta (its values are
        convex combinations of the boundary data); an approximation can land
        just outside near the boundary, where its error is largest.

        Parameters
        ----------
        points : (K, 2) ndarray of float
            Changed in place.

        Returns
        -------
        (K,) ndarray of bool
            Which points were moved.
        """
        from ..boundary import edge_points, nearest_edge

        w = self.points
        d = np.roll(w, -1, axis=0) - w
        outside = np.zeros(len(points), dtype=bool)
        for i in range(len(w)):  # convex: outside iff on the wrong side of some edge
            cross = d[i, 0] * (points[:, 1] - w[i, 1]) - d[i, 1] * (points[:, 0] - w[i, 0])
            outside |= cross * self.orientation < 0.0
        if outside.any():
            edge, t, _ = nearest_edge(points[outside], w)
            points[outside] = edge_points(w, edge, t)
        return outside

    def same_as(self, other: Theta) -> bool:
        """Whether two Thetas are the same polygon, vertex for vertex."""
        return self.points.shape == other.points.shape and bool(np.array_equal(self.points, other.points))


@dataclass(frozen=True, eq=False)
class TargetTheta(Theta):
    """The target polygon itself in Theta's place (``--theta none``): no intermediate polygon.

    The source's harmonic map then goes straight onto the target, and the
    target's map is the identity (`warpcli.maps.straight`). The target is
    not convex in general, so nothing guarantees that the straight map is
    one-to-one: it is certified after it is built (every image triangle
    oriented like the target, exactly) and refused where it folds.

    Parameters
    ----------
    points : (n, 2) array_like of float
        The target polygon's vertices (validated as a simple polygon already).
    name : str
    notes : dict

    Raises
    ------
    InputError
        If there are fewer than 3 vertices or a coordinate is not finite.
    """

    def __post_init__(self) -> None:
        pts = np.array(self.points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3:
            raise InputError(f"{self.name}: the target needs at least 3 [x, y] vertices, got shape {pts.shape}")
        if not np.isfinite(pts).all():
            raise InputError(f"{self.name}: the target has a non-finite coordinate")
        pts.setflags(write=False)
        object.__setattr__(self, "points", pts)

    def clamp(self, points: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Move points outside the (not necessarily convex) polygon onto its nearest boundary point, in place."""
        from ..boundary import edge_points, nearest_edge
        from ..grid import inside_polygon

        outside = ~inside_polygon(points, self.points)
        if outside.any():
            edge, t, _ = nearest_edge(points[outside], self.points)
            points[outside] = edge_points(self.points, edge, t)
        return outside


def _not_strictly_convex(pts: NDArray[np.float64]) -> int | None:
    """The first vertex where the polygon turns the wrong way or not at all, or None."""
    a = pts - np.roll(pts, 1, axis=0)
    b = np.roll(pts, -1, axis=0) - pts
    turn = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    sign = np.sign(signed_area(pts))
    scale = np.hypot(a[:, 0], a[:, 1]) * np.hypot(b[:, 0], b[:, 1])
    bad = np.flatnonzero(~(turn * sign > 1e-12 * scale))
    if bad.size or sign == 0:
        return int(bad[0]) if bad.size else 0
    # Turning the same way at every vertex is not enough: the boundary must
    # also wind around once (a pentagram turns one way but winds twice).
    angle = np.arctan2(turn, np.einsum("ij,ij->i", a, b))
    if abs(angle.sum()) > 2.0 * np.pi + 1e-6:
        return 0
    return None


def regular_polygon(n: int) -> NDArray[np.float64]:
    """The regular n-gon inscribed in the unit circle, positive shoelace area.

    Vertex 0 is at angle 0 and the angles increase, so with y down the
    vertices run clockwise on screen, like `Polygon.signed_area` > 0.

    >>> regular_polygon(4).round(12).tolist()
    [[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [-0.0, -1.0]]
    """
    if n < 3:
        raise InputError(f"Theta needs at least 3 vertices, got {n}")
    angle = 2.0 * np.pi * np.arange(n) / n
    return np.stack([np.cos(angle), np.sin(angle)], axis=1)


def regular(src: Polygon, dst: Polygon, options: object = None) -> Theta:
    """Strategy ``regular``: the regular n-gon (the paper's default, §2).

    Parameters
    ----------
    src, dst : Polygon
        The polygons (only their vertex count is used).
    options : MapOptions or None

    Returns
    -------
    Theta
    """
    return Theta(regular_polygon(src.n), name="regular")


def cyclic(src: Polygon, dst: Polygon, options: object = None) -> Theta:
    """Strategy ``cyclic``: inscribed in a circle, edge lengths proportional to the mean
    length of the corresponding source and target edges (the paper's Fig. 11).

    Parameters
    ----------
    src, dst : Polygon
    options : MapOptions or None

    Returns
    -------
    Theta
        Inscribed in the unit circle, vertex 0 at angle 0, positive shoelace area.
    """
    lengths = 0.5 * (_edge_lengths(src.points) + _edge_lengths(dst.points))
    return Theta(cyclic_polygon(lengths), name="cyclic")


def _edge_lengths(points: NDArray[np.float64]) -> NDArray[np.float64]:
    d = np.roll(points, -1, axis=0) - points
    return np.hypot(d[:, 0], d[:, 1])


def cyclic_polygon(lengths: ArrayLike) -> NDArray[np.float64]:
    """The polygon inscribed in the unit circle whose edge lengths are proportional to ``lengths``.

    Edge i subtends the central angle ``2 asin(l_i / 2R)`` for the circumradius
    R that makes the angles sum to 2 pi; when even ``R = max(l) / 2`` leaves
    them short of 2 pi, the longest edge is the one whose arc holds the
    centre (angle ``2 pi - 2 asin(l / 2R)``). A solution exists when every
    length is shorter than the sum of the others (a polygon inequality, which
    the edges of any polygon satisfy).

    Parameters
    ----------
    lengths : (n,) array_like of float
        Positive.

    Returns
    -------
    (n, 2) ndarray of float

    Raises
    ------
    InputError
        If no cyclic polygon has these edge lengths.

    Examples
    --------
    >>> p = cyclic_polygon([1.0, 1.0, 1.0, 1.0])
    >>> np.allclose(p, regular_polygon(4))
    True
    """
    lengths = np.asarray(lengths, dtype=np.float64)
    n = len(lengths)
    if n < 3 or not np.all(lengths > 0) or not np.isfinite(lengths).all():
        raise InputError(f"a cyclic Theta needs at least 3 positive edge lengths, got {lengths.tolist()}")
    longest = int(np.argmax(lengths))
    if lengths[longest] >= lengths.sum() - lengths[longest]:
        raise InputError("no cyclic polygon has these edge lengths: one is as long as all the others together")
    half = lengths / lengths[longest]  # l_i / l_max, so that R >= 1/2
    lo = 0.5

    def angles(r: float, centre_inside: bool) -> NDArray[np.float64]:
        a = 2.0 * np.arcsin(np.minimum(half / (2.0 * r), 1.0))
        if not centre_inside:
            a[longest] = 2.0 * np.pi - a[longest]
        return a

    # Centre inside (every edge subtends less than pi): the angle sum falls as
    # R grows from l_max / 2; if it is already below 2 pi there, the centre
    # lies outside, across the longest edge, and the sum then grows with R.
    centre_inside = angles(lo, True).sum() >= 2.0 * np.pi
    hi = 1.0
    while (angles(hi, centre_inside).sum() - 2.0 * np.pi) * (1 if centre_inside else -1) > 0:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        excess = angles(mid, centre_inside).sum() - 2.0 * np.pi
        if (excess > 0) == centre_inside:
            lo = mid
        else:
            hi = mid
    a = angles(0.5 * (lo + hi), centre_inside)
    at = np.concatenate([[0.0], np.cumsum(a)[:-1]])
    return np.stack([np.cos(at), np.sin(at)], axis=1)


def from_file(path: str, n: int) -> Theta:
    """A user's Theta from a JSON file: n vertices, strictly convex, either orientation.

    The file holds an array of ``[x, y]`` pairs, or an object with a
    ``"points"`` member holding one (as written by ``--save-theta``).

    Parameters
    ----------
    path : str
    n : int
        The polygons' vertex count.

    Returns
    -------
    Theta

    Raises
    ------
    InputError
        If the file cannot be read, is not such an array, has another vertex
        count, or is not strictly convex; the message names the file.
    """
    import json

    raw = read_small_file(path, "Theta file", InputError, max_bytes=MAX_THETA_BYTES)
    try:
        doc = json.loads(raw.decode("utf-8-sig"))
    except (ValueError, RecursionError) as err:
        raise InputError(f"{path}: cannot read Theta: {getattr(err, 'strerror', None) or err}") from None
    pts = doc.get("points") if isinstance(doc, dict) else doc
    try:
        arr = np.array(pts, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{path}: Theta must be an array of [x, y] pairs") from None
    except OverflowError:  # an integer of hundreds of digits
        raise InputError(f"{path}: Theta has a coordinate beyond the floating-point range (1.8e308)") from None
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise InputError(f"{path}: Theta must be an array of [x, y] pairs")
    if len(arr) != n:
        raise InputError(f"{path}: Theta has {len(arr)} vertices but the polygons have {n}")
    return Theta(arr, name=path)


#: Largest Theta coordinate magnitude: the convexity test's cross products
#: (up to (2 x)^2) stay finite below about 6.7e153.
THETA_COORD_LIMIT = 1e150
#: Largest ratio of a user Theta's principal axes that BEM and MFS take. The
#: composed map does not depend on an affine change of Theta (FEM's does not
#: to 4e-14 px up to 1e9:1), but BEM's and MFS's fits do once Theta is very
#: flat: for a regular 7-gon stretched s times in x, their maps agree with
#: s = 1 to 4e-13 px up to s = 1e6, then differ by 0.8 px at 1e7, 8.4 px at
#: 1e8 and 43 px at 1e9 (a folded, collapsed map the certificate passes).
SMOOTH_MAX_ASPECT = 1e6


def aspect_ratio(points: NDArray[np.float64]) -> float:
    """The ratio of the principal axes of a polygon's vertices (1 for a regular polygon).

    >>> round(aspect_ratio(np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 1.0], [0.0, 1.0]])), 6)
    4.0
    """
    centred = points - points.mean(axis=0)
    ev = np.linalg.eigvalsh(centred.T @ centred)
    return float(np.sqrt(ev[1] / ev[0])) if ev[0] > 0 else math.inf
