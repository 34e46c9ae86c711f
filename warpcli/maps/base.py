"""The map interface: a map of a polygon onto the convex polygon Theta, whatever the method.

Every method of the paper's §3.1 (FEM, and later BEM and MFS) implements
`ThetaMap`; `warpcli.maps.compose.BijectiveMap` composes two of them and never
looks inside. What crosses the seam is points and Jacobians, never mesh
triangles: `Mapped` and `Certificate` are `warpcli.mapping`'s, the same for
polygons and polyhedra (imported here, where the methods find them).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import ClassVar, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..boundary import edge_points, from_theta_parameter, to_theta_parameter
from ..errors import MeshingError
from ..grid import inside_polygon, pixel_centres
from ..mapping import Certificate, Mapped, as_points, matmul2
from ..polygon import Polygon
from .theta import Theta


class GridSample(NamedTuple):
    """A map evaluated at the pixel centres of a grid that lie in its domain.

    Attributes
    ----------
    pixels : (K,) ndarray of int64
        Flat (row-major) indices of those pixels in the whole grid, in the
        order they were visited (spatially coherent: consecutive pixels are
        neighbours, which makes a following `ThetaMap.inverse` with
        ``coherent=True`` fast).
    values : (K, 2) ndarray of float
        The map at each of those pixel centres.
    jacobian : (K, 2, 2) ndarray of float or None
        Its Jacobian there, if asked for.
    """

    pixels: NDArray[np.int64]
    values: NDArray[np.float64]
    jacobian: NDArray[np.float64] | None = None


@dataclass(eq=False)
class ThetaMap(ABC):
    """A map phi of a simple polygon onto a convex polygon Theta, with its inverse.

    phi takes the polygon's vertex i to Theta's vertex i and each edge onto the
    corresponding edge (linear boundary data, the paper's §2). Implementations
    approximate the harmonic map with those boundary values (§3.1) and are made
    by a method's ``build`` (see `warpcli.maps.registry.METHODS`).

    Attributes
    ----------
    polygon : Polygon
        The domain.
    theta : Theta
        The image.
    timings : dict of str to float
        Seconds spent building the map, per stage.
    boundary : {"linear", "quadratic"}
        The boundary behaviour (§5.2, `to_theta_parameter`).

    References
    ----------
    Schneider & Hormann, Smooth bijective maps between arbitrary planar
    polygons, CAGD 2015, §2-§3.
    """

    polygon: Polygon
    theta: Theta
    timings: dict[str, float] = field(default_factory=dict, kw_only=True)
    boundary: str = field(default="linear", kw_only=True)

    #: The method's registry name.
    method: ClassVar[str] = ""

    @abstractmethod
    def evaluate(self, points: ArrayLike, *, jacobian: bool = False) -> Mapped:
        """phi at points of the polygon.

        Parameters
        ----------
        points : (K, 2) array_like of float
            Points in the polygon's coordinates.
        jacobian : bool
            Also return the Jacobian of phi there.

        Returns
        -------
        Mapped
            Points of Theta; NaN for points outside the polygon.
        """

    @abstractmethod
    def inverse(self, points: ArrayLike, *, jacobian: bool = False, coherent: bool = False) -> Mapped:
        """phi^-1 at points of Theta.

        Parameters
        ----------
        points : (K, 2) array_like of float
            Points of Theta.
        jacobian : bool
            Also return the Jacobian of phi^-1 there.
        coherent : bool
            A hint that consecutive points are close together (as in a
            `GridSample`), which a method may use to search faster.

        Returns
        -------
        Mapped
            Points of the polygon; NaN for points outside Theta.
        """

    @abstractmethod
    def certify(self) -> Certificate:
        """Check that the map is one-to-one (see `Certificate`)."""

    def evaluate_grid(
        self, width: int, height: int, rows: tuple[int, int] | None = None, *, jacobian: bool = False
    ) -> GridSample:
        """phi at the pixel centres of a ``width`` x ``height`` grid that lie in the polygon.

        The fast path of the composition. This default evaluates the centres
        inside the polygon in row-major order; methods override it with
        something faster.

        Parameters
        ----------
        width, height : int
            Grid size in pixels (the polygon lives in this grid's coordinates).
        rows : (int, int) or None
            Only rows ``r0 <= r < r1``.
        jacobian : bool
            Also return the Jacobian of phi.

        Returns
        -------
        GridSample
        """
        r0, r1 = rows if rows is not None else (0, height)
        centres = pixel_centres(width, height, (r0, r1))
        inside = np.flatnonzero(self._inside_polygon(centres))
        mapped = self.evaluate(centres[inside], jacobian=jacobian)
        ok = np.isfinite(mapped.points[:, 0])
        pixels = (inside[ok] + r0 * width).astype(np.int64)
        jac = mapped.jacobian[ok] if mapped.jacobian is not None else None
        return GridSample(pixels, mapped.points[ok], jac)

    def _inside_polygon(self, points: NDArray[np.float64]) -> NDArray[np.bool_]:
        """`warpcli.grid.inside_polygon` against the polygon (a method may give the same booleans faster)."""
        return inside_polygon(points, self.polygon.points)

    def to_theta_parameter(self, edge: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
        """The boundary behaviour: the parameter along Theta's edge i of parameter t along the
        polygon's edge i (linear: t, the paper's default, §2; quadratic: t^2, §5.2; a map with
        natural boundary conditions slides along the edge as its solution says)."""
        return to_theta_parameter(t, self.boundary)

    def from_theta_parameter(self, edge: ArrayLike, s: ArrayLike) -> NDArray[np.float64]:
        """The inverse of `to_theta_parameter`."""
        return from_theta_parameter(s, self.boundary)

    def boundary_to_theta(self, edge: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
        """The boundary data: the image in Theta of the point at parameter t on polygon edge i."""
        return edge_points(self.theta.points, edge, self.to_theta_parameter(edge, t))

    def boundary_from_theta(self, edge: ArrayLike, s: ArrayLike) -> NDArray[np.float64]:
        """The inverse boundary data: the polygon point that goes to parameter s on Theta's edge i."""
        return edge_points(self.polygon.points, edge, self.from_theta_parameter(edge, s))

    def describe(self) -> dict:
        """What only this method knows, for the report (for FEM: the mesh's size)."""
        return {}

    def retarget(self, theta: Theta) -> ThetaMap | None:
        """The map of the same polygon onto another Theta, if the method can reuse its work
        (FEM: the factorization); None otherwise (then it is built anew)."""
        return None


def inv2(m: NDArray[np.float64]) -> NDArray[np.float64]:
    """Inverses of a stack of 2x2 matrices, in closed form (inf or NaN where singular)."""
    det = m[..., 0, 0] * m[..., 1, 1] - m[..., 0, 1] * m[..., 1, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.stack(
            [np.stack([m[..., 1, 1], -m[..., 0, 1]], axis=-1), np.stack([-m[..., 1, 0], m[..., 0, 0]], axis=-1)],
            axis=-2,
        ) / det[..., None, None]


#: Natural boundary conditions (§5.2): per edge, the polygon's parameters t and Theta's s, both increasing.
EdgeTables = list[tuple[NDArray[np.float64], NDArray[np.float64]]]


def sliding_tables(theta: NDArray[np.float64], edge: ArrayLike, t: ArrayLike, images: ArrayLike) -> EdgeTables:
    """The boundary correspondence of a map whose boundary slides along Theta's edges.

    Natural (Neumann) conditions leave the parameter along each edge to the
    solution: given boundary samples (polygon edge i, parameter t) and their
    images in Theta, each edge gets a table from t to the parameter s of the
    image's projection onto Theta's edge i, pinned at both vertices, and
    strictly increasing: the exact map is monotone along edges, but rounding
    and approximation may not be, and a sample whose s is not above every
    earlier one's (or not inside (0, 1)) is left out. (They were clipped and
    made non-decreasing: a fit's trace running back over a few pixels became
    a flat stretch, a run of up to 16 px of an edge sent to one point, and
    the warp no longer one-to-one along it.) Between the samples kept, the
    table is linear, so every edge goes onto Theta's one-to-one.

    Parameters
    ----------
    theta : (n, 2) ndarray of float
        Theta's vertices.
    edge : (K,) array_like of int
        Polygon edge of each sample.
    t : (K,) array_like of float
        Parameter along that edge, in [0, 1].
    images : (K, 2) array_like of float
        The map's value at each sample.

    Returns
    -------
    list of (t, s) pairs of 1-D arrays
        One per edge, for `slide`.
    """
    edge = np.asarray(edge, dtype=np.intp)
    t = np.asarray(t, dtype=np.float64)
    images = np.asarray(images, dtype=np.float64)
    n = len(theta)
    tables = []
    for i in range(n):  # loop over edges
        on = (edge == i) & (t > 0.0) & (t < 1.0)
        a, d = theta[i], theta[(i + 1) % n] - theta[i]
        order = np.argsort(t[on], kind="stable")
        tk, sk = t[on][order], ((images[on] - a) @ d / (d @ d))[order]
        # Kept: above every earlier s (and 0) and below 1, at a t above every earlier one's.
        floor_s = np.maximum.accumulate(np.concatenate([[0.0], sk[:-1]])) if sk.size else sk
        floor_t = np.concatenate([[0.0], tk[:-1]]) if tk.size else tk
        keep = (sk > floor_s) & (sk < 1.0) & (tk > floor_t)
        tables.append((np.concatenate([[0.0], tk[keep], [1.0]]), np.concatenate([[0.0], sk[keep], [1.0]])))
    return tables


class ForkedBuild:
    """A map being built in a forked child (`warpcli._fork.Forked`); `result` gives it.

    Parameters
    ----------
    name : str
        The polygon's name, for messages.
    doing : str
        What the child does, for a message if it dies (``"meshing and solving"``).
    fn, *args
        What the child runs; its result (the map) must pickle.

    Raises
    ------
    OSError
        If no child can be forked (no memory or processes left).
    """

    def __init__(self, name: str, doing: str, fn, *args) -> None:
        from .._fork import Forked

        self.name = name
        self._doing = doing
        self._child = Forked(fn, *args)

    def result(self) -> ThetaMap:
        """The map, or `MeshingError` naming the polygon if the child died."""
        from .._fork import ChildDied

        try:
            return self._child.result()
        except ChildDied as err:
            raise MeshingError(f"{self.name}: the process {self._doing} it {err}") from None

    def cancel(self) -> None:
        """Stop the child: its map is no longer wanted."""
        self._child.cancel()
