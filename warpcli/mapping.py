"""Mapping stage: the composed bijection f = phi1^-1 o phi0 and its inverse."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import FoldOverError
from .harmonic import HarmonicMap, solve_harmonic
from .locate import TriangleLocator, _affine_coefficients, barycentric_combine, triangle_neighbours
from .mesh import auto_max_area, mesh_polygon
from .polygon import Polygon, check_pair
from .theta import regular_polygon

log = logging.getLogger("warpcli")

@dataclass(frozen=True)
class GridPullBack:
    """The inverse map at output pixel centres, with the triangles it went through.

    Attributes
    ----------
    inverse_map : (H, W, 2) ndarray of float
        Source point of each output pixel centre, NaN outside the target.
    source_triangle, target_triangle : (H, W) ndarray of int32
        Triangle of the source mesh containing the source point and of the
        target mesh containing the pixel centre (-1 outside, or for the source
        triangle of a pixel on the boundary resolved through Theta's boundary).
    """

    inverse_map: NDArray[np.float64]
    source_triangle: NDArray[np.int32]
    target_triangle: NDArray[np.int32]


class BijectiveMap:
    """The smooth bijective map between two polygons, discretized by FEM.

    ``forward`` takes source points to the target, ``inverse`` takes target
    points back to the source (eq. (2): f = phi1^-1 o phi0, and
    f^-1 = phi0^-1 o phi1). Both are piecewise-linear compositions of the
    two discrete harmonic maps onto the convex polygon Theta.

    Build one with `BijectiveMap.between`.

    Parameters
    ----------
    src, dst : Polygon
    phi0 : HarmonicMap
        Source mesh onto Theta.
    phi1 : HarmonicMap
        Target mesh onto Theta.
    """

    def __init__(self, src: Polygon, dst: Polygon, phi0: HarmonicMap, phi1: HarmonicMap) -> None:
        check_pair(src, dst)
        self.src = src
        self.dst = dst
        self.phi0 = phi0
        self.phi1 = phi1
        self.theta = phi0.theta

    @classmethod
    def between(
        cls,
        src: Polygon,
        dst: Polygon,
        *,
        max_area: float | tuple[float, float] | None = None,
        weights: str = "cotan",
        check: bool = True,
        timings: dict[str, float] | None = None,
    ) -> BijectiveMap:
        """Mesh both polygons, solve both harmonic maps onto a regular n-gon.

        Parameters
        ----------
        src, dst : Polygon
            Corresponding polygons (vertex i of ``src`` goes to vertex i of ``dst``).
        max_area : float, (float, float) or None
            Largest triangle area of both meshes, or of the source and the
            target mesh, in square pixels of the image each polygon lives in;
            None picks `auto_max_area` for each.
        weights : {"cotan", "positive"}
            ``cotan`` solves the harmonic maps (FEM); ``positive`` uses
            mean-value weights, one-to-one on any mesh but no longer harmonic.
        check : bool
            Make sure neither discrete map flips a triangle: a cotangent map
            that does (which the constrained Delaunay meshes should rule out)
            is solved again with positive weights, with a warning; if a flip
            remains, raise `FoldOverError`. Never hand back a folding map.
        timings : dict or None
            If given, receives the seconds spent in ``"mesh"`` and ``"solve"``.

        Returns
        -------
        BijectiveMap
        """
        check_pair(src, dst)
        theta = regular_polygon(src.n)
        areas = (max_area, max_area) if max_area is None or np.isscalar(max_area) else max_area
        area0, area1 = (auto_max_area(p) if a is None else float(a) for p, a in zip((src, dst), areas))
        clock = time.perf_counter
        t0 = clock()
        # SuperLU releases the GIL and triangle does not: the source map is
        # solved on a second core while the target is meshed, then both
        # solves run at once. Each solve is independent, so the results do
        # not depend on the scheduling.
        with ThreadPoolExecutor(max_workers=3) as pool:
            solve0 = pool.submit(solve_harmonic, mesh_polygon(src, area0), theta, weights)
            # Loading the compiled kernels costs ~0.3 s of GIL-bound work in a
            # fresh process; the solves release the GIL, so do it meanwhile.
            pool.submit(_load_kernels)
            mesh1 = mesh_polygon(dst, area1)
            t1 = clock()
            solve1 = pool.submit(solve_harmonic, mesh1, theta, weights)
            phi0, phi1 = solve0.result(), solve1.result()
        if check:
            phi0, phi1 = (_repaired(phi, poly) for phi, poly in ((phi0, src), (phi1, dst)))
        if timings is not None:
            timings["mesh"] = t1 - t0
            timings["solve"] = clock() - t1
        result = cls(src, dst, phi0, phi1)
        if check:
            result.check_bijective()
        return result

    def flipped_triangles(self) -> int:
        """Number of triangles flipped or degenerate in either discrete map."""
        return int(self.phi0.flipped().sum() + self.phi1.flipped().sum())

    def check_bijective(self) -> None:
        """Raise `FoldOverError` unless both discrete maps are one-to-one."""
        f0 = int(self.phi0.flipped().sum())
        f1 = int(self.phi1.flipped().sum())
        if f0 or f1:
            raise FoldOverError(
                f"the discrete harmonic maps flip {f0} triangle(s) of the {self.src.name} mesh and "
                f"{f1} of the {self.dst.name} mesh; the warp would fold the image over itself"
            )

    @property
    def orientation_preserving(self) -> bool:
        """False when the polygons run in opposite directions: f is then a mirror image."""
        return (self.src.signed_area > 0) == (self.dst.signed_area > 0)

    @cached_property
    def _src_locator(self) -> TriangleLocator:
        return TriangleLocator(self.phi0.mesh.vertices, self.phi0.mesh.triangles)

    @cached_property
    def _dst_locator(self) -> TriangleLocator:
        return TriangleLocator(self.phi1.mesh.vertices, self.phi1.mesh.triangles)

    @cached_property
    def _theta0_locator(self) -> TriangleLocator:
        return TriangleLocator(self.phi0.values, self.phi0.mesh.triangles)

    @cached_property
    def _theta1_locator(self) -> TriangleLocator:
        return TriangleLocator(self.phi1.values, self.phi1.mesh.triangles)

    def forward(self, points: ArrayLike) -> NDArray[np.float64]:
        """Map source points to the target.

        Parameters
        ----------
        points : (K, 2) array_like of float
            Points in the source image's coordinates.

        Returns
        -------
        (K, 2) ndarray of float
            Their images in the target's coordinates; NaN for points outside
            the source polygon.
        """
        theta = self.to_theta_src(points)
        return _from_theta(theta, self._theta1_locator, self.phi1, self.dst)[0]

    def inverse(self, points: ArrayLike) -> NDArray[np.float64]:
        """Map target points back to the source.

        Parameters
        ----------
        points : (K, 2) array_like of float
            Points in the target (output) image's coordinates.

        Returns
        -------
        (K, 2) ndarray of float
            Their pre-images in the source's coordinates; NaN for points
            outside the target polygon.
        """
        theta = self.to_theta_dst(points)
        return _from_theta(theta, self._theta0_locator, self.phi0, self.src)[0]

    def inverse_grid(self, width: int, height: int) -> NDArray[np.float64]:
        """`inverse` at every pixel centre of a ``width`` x ``height`` output image.

        The same values as ``inverse(pixel_centres(width, height))`` (up to
        rounding on shared edges), computed by one compiled pass: the target
        mesh is scan-converted onto the pixel grid, and each pixel's search in
        Theta walks from the previous pixel's triangle.

        Returns
        -------
        (height, width, 2) ndarray of float
            Source point of each output pixel centre; NaN outside the target.
        """
        return self.pull_back_grid(width, height).inverse_map

    def pull_back_grid(self, width: int, height: int) -> GridPullBack:
        """`inverse_grid` together with the triangles each pixel went through."""
        return _through_theta(self.phi1, self.phi0, lambda: self._theta0_locator, self.src, width, height)

    def forward_grid(self, width: int, height: int) -> NDArray[np.float64]:
        """`forward` at every pixel centre of a ``width`` x ``height`` source image.

        Returns
        -------
        (height, width, 2) ndarray of float
            Target point of each source pixel centre; NaN outside the source.
        """
        grid = _through_theta(self.phi0, self.phi1, lambda: self._theta1_locator, self.dst, width, height)
        return grid.inverse_map

    def to_theta_src(self, points: ArrayLike) -> NDArray[np.float64]:
        """phi0: source points to Theta (NaN outside the source polygon)."""
        return self._src_locator.interpolate(self.phi0.values, _points(points))

    def to_theta_dst(self, points: ArrayLike) -> NDArray[np.float64]:
        """phi1: target points to Theta (NaN outside the target polygon)."""
        return self._dst_locator.interpolate(self.phi1.values, _points(points))

def _from_theta(
    theta: NDArray[np.float64], locator: TriangleLocator, phi: HarmonicMap, poly: Polygon
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """phi^-1 at points of Theta: the polygon's points, and the mesh triangle of each.

    Each point is located in phi's image mesh and interpolated in the mesh. A
    point of Theta's boundary can miss every image triangle by a rounding
    error; the boundary map is known exactly, so it is inverted there instead
    (triangle -1).
    """
    tri, bary = locator.locate(theta)
    out = barycentric_combine(phi.mesh.vertices, phi.mesh.triangles, tri, bary)
    lost = np.flatnonzero((tri < 0) & np.isfinite(theta).all(axis=1))
    if lost.size:
        out[lost] = theta_boundary_to_polygon(theta[lost], phi.theta, poly.points)
    return out, tri


def _through_theta(
    phi_grid: HarmonicMap,
    phi_other: HarmonicMap,
    other_locator: Callable[[], TriangleLocator],
    other_poly: Polygon,
    width: int,
    height: int,
) -> GridPullBack:
    """phi_other^-1 o phi_grid at every pixel centre of the grid phi_grid's polygon lives on.

    One compiled pass (warpcli._kernels.compose_grid): phi_grid's mesh is
    scan-converted onto the pixel grid, and each pixel's image in Theta is
    located in phi_other's image mesh by a walk from the previous pixel's.
    ``other_locator`` builds the bucket locator of that image mesh, needed
    only for the rare walks that give up (slivers make it expensive to build).
    """
    from . import _kernels

    mesh = phi_grid.mesh
    tri = mesh.triangles.astype(np.int64)
    other_tri = phi_other.mesh.triangles.astype(np.int64)
    out = np.empty((height * width, 2))
    status = np.zeros(height * width, dtype=np.int8)
    where_other = np.full(height * width, -1, dtype=np.int32)
    where_grid = np.full(height * width, -1, dtype=np.int32)
    # A safety net only: the stochastic walk terminates on its own.
    max_steps = len(other_tri) + 64
    _kernels.compose_grid(
        mesh.vertices, tri, _affine_coefficients(mesh.vertices, tri), phi_grid.values, _coherent_order(mesh.vertices, tri),
        other_tri, _affine_coefficients(phi_other.values, other_tri), triangle_neighbours(other_tri),
        phi_other.mesh.vertices, max_steps, width, height, out, status, where_other, where_grid,
    )  # fmt: skip
    out[status == _kernels.OUTSIDE] = np.nan
    lost = np.flatnonzero(status == _kernels.LOST)
    if lost.size:
        # Rare: the bucket search (built only now) for the walks that gave up,
        # and Theta's exact boundary map for points a rounding error outside.
        out[lost], where_other[lost] = _from_theta(out[lost], other_locator(), phi_other, other_poly)
    shape = (height, width)
    return GridPullBack(out.reshape(height, width, 2), where_other.reshape(shape), where_grid.reshape(shape))


def _coherent_order(vertices: NDArray[np.float64], triangles: NDArray[np.int64], band: float = 8.0) -> NDArray[np.int64]:
    """Triangles in serpentine bands of ``band`` pixels: consecutive triangles are
    neighbours, so each pixel's walk in Theta starts next to its goal."""
    c = vertices[triangles].mean(axis=1)
    row = np.floor(c[:, 1] / band)
    x = np.where(row % 2 == 0, c[:, 0], -c[:, 0])
    return np.lexsort((x, row)).astype(np.int64)


def _load_kernels() -> None:
    """Load the compiled kernels (see warpcli._kernels.warm_up) before they are needed."""
    from . import _kernels

    _kernels.warm_up()


def _repaired(phi: HarmonicMap, poly: Polygon) -> HarmonicMap:
    """phi itself if it flips no triangle, else phi solved with positive weights."""
    flips = int(phi.flipped().sum())
    if flips == 0 or phi.weights == "positive":
        return phi
    log.warning(
        "%s: the harmonic map flips %d triangle(s); solving with positive (mean-value) weights instead",
        poly.name,
        flips,
    )
    return solve_harmonic(phi.mesh, phi.theta, "positive")


def theta_boundary_to_polygon(
    q: NDArray[np.float64], theta: NDArray[np.float64], poly: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Project points onto Theta's boundary and carry them to the polygon's boundary.

    The boundary data is piecewise linear, so the point at parameter t of
    Theta's edge i goes to the point at parameter t of the polygon's edge i.
    """
    n = len(theta)
    a = theta
    d = np.roll(theta, -1, axis=0) - theta
    rel = q[:, None, :] - a[None, :, :]
    t = np.clip(np.einsum("kij,ij->ki", rel, d) / np.einsum("ij,ij->i", d, d), 0.0, 1.0)
    near = a[None] + t[..., None] * d[None]
    dist = ((q[:, None, :] - near) ** 2).sum(axis=2)
    e = np.argmin(dist, axis=1)
    te = t[np.arange(len(q)), e][:, None]
    return (1.0 - te) * poly[e] + te * poly[(e + 1) % n]


def _points(points: ArrayLike) -> NDArray[np.float64]:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"points must be a (K, 2) array, got shape {p.shape}")
    return p
