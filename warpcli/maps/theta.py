"""Theta: the convex intermediate polygon both harmonic maps go onto, and the strategies that choose it."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError
from ..polygon import Polygon, signed_area


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

    def __post_init__(self) -> None:
        pts = np.array(self.points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3:
            raise InputError(f"{self.name}: Theta needs at least 3 [x, y] vertices, got shape {pts.shape}")
        if not np.isfinite(pts).all():
            raise InputError(f"{self.name}: Theta has a non-finite coordinate")
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

    def same_as(self, other: Theta) -> bool:
        """Whether two Thetas are the same polygon, vertex for vertex."""
        return self.points.shape == other.points.shape and bool(np.array_equal(self.points, other.points))


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
    """Strategy ``regular``: the regular n-gon (the paper's default, §2)."""
    return Theta(regular_polygon(src.n), name="regular")


