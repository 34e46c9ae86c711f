"""FEM meshing: graded quality constrained Delaunay meshes of a polygon, over `triangle`."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..._arrays import sorted_unique
from ..._cached import cached_property
from ..._switches import decimal
from ...errors import InputError, MeshingError, PolygonError
from ...polygon import Polygon
from ...simplicial import corners
from .topology import mesh_edges

#: Refuse to build a mesh of more than this many triangles when the user sets
#: the density: its direct solve would take many minutes and several GB.
MAX_TRIANGLES = 4_000_000

#: A polygon reaching far beyond the image (`graded_from`) is meshed with at most
#: this many times the triangles its part near the image needs (and at least
#: ``AUTO_MAX_TRIANGLES``): its far parts get triangles growing with the distance,
#: so a square of 1e7 px round a 200 px image takes 5.9 times, and only a part
#: far away that is thin for its length (a needle to x = 9e8, 2,200 px wide: 5
#: million triangles, 40 s and 2 GB) needs more. That is refused instead.
GRADED_BUDGET = 8

#: The automatic density never asks for more triangles than this per mesh; a
#: polygon far larger than any image gets a coarser mesh instead (its harmonic
#: map is correspondingly smooth at the scale of a pixel).
AUTO_MAX_TRIANGLES = 1_000_000

#: The default mesh density: the largest triangle area is the polygon's size
#: sqrt(area) divided by this, but never below one square pixel. The FEM error
#: in pixels grows like area bound / size, so this keeps the map's mean error
#: against a 4x finer mesh near 0.015-0.02 px at every image size, a third of
#: the 0.05 px we allow (measured by the accuracy table of bench/run.py);
#: ``max_area=1`` is the paper's pixel density.
AUTO_AREA_DIVISOR = 35.0

#: Triangle's minimum-angle bound (degrees) for quality meshing.
MIN_ANGLE = 30.0

#: Quadratic boundary data: nodes per edge, evenly spaced in Theta's parameter.
QUADRATIC_NODES = 16

#: A polygon that reaches further than this many times the size of its region
#: of interest (the image the map is evaluated on) beyond that region is meshed
#: graded from it: the automatic density follows the region's size, and edge
#: lengths grow by _REGION_SLOPE per pixel of distance from it. The triangle
#: count then grows with the logarithm of the polygon's size (for a square
#: around a 64 x 48 image, by its half-side: 72k triangles at 1e3 px, 135k at
#: 1e4, 262k at 1e6, 435k at 5e8, about 65k more per factor of 10, against the
#: 1M cap of a uniform mesh), and the map stays accurate where it is used:
#: the harmonic map at the image depends on the whole polygon, and a gentle
#: slope keeps the far field's error from polluting it (a 1e7 px pair:
#: 0.07-0.15 px at a 64 px image in about 5 s, against 0.05 px in 17 s
#: uniform; slope 0.3 gave 4.9 px).
REGION_REACH = 0.5
_REGION_SLOPE = 0.03
# Each refinement pass divides a triangle's area by at most _REGION_SPLIT, so that triangle
# (whose new triangles inherit their parent's area bound) never refines a huge
# triangle down to the region's density everywhere.
_REGION_PASSES = 40
_REGION_SPLIT = 16.0

# Near a reflex (re-entrant) vertex the harmonic map's gradient is singular and
# the FEM error concentrates there. Boundary points are placed at geometric
# distances from such a vertex, from _GRADE_MIN pixels up to _GRADE_REACH times
# the nominal edge length, and Triangle's quality refinement grades the
# interior to match.
_GRADE_MIN = 0.1
_GRADE_RATIO = 1.4
_GRADE_REACH = 6.0
_GRADE_SLOPE = 0.25


@dataclass(frozen=True)
class TriMesh:
    """A triangle mesh of a polygon, with each boundary node's place on the polygon.

    Attributes
    ----------
    vertices : (N, 2) ndarray of float
    triangles : (M, 3) ndarray of int32
        Vertex indices, all oriented like the polygon.
    boundary : (B,) ndarray of int
        Indices of the nodes on the polygon's boundary.
    boundary_edge : (B,) ndarray of int
        Polygon edge each boundary node lies on (a vertex ``i`` lies on edge ``i``).
    boundary_t : (B,) ndarray of float
        Parameter in [0, 1) of the node along its edge.
    """

    vertices: NDArray[np.float64]
    triangles: NDArray[np.int32]
    boundary: NDArray[np.intp]
    boundary_edge: NDArray[np.intp]
    boundary_t: NDArray[np.float64]

    def __post_init__(self) -> None:
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 2:
            raise ValueError(f"vertices must be (N, 2), got {self.vertices.shape}")
        if self.triangles.ndim != 2 or self.triangles.shape[1] != 3:
            raise ValueError(f"triangles must be (M, 3), got {self.triangles.shape}")
        if not (len(self.boundary) == len(self.boundary_edge) == len(self.boundary_t)):
            raise ValueError(
                "boundary, boundary_edge and boundary_t differ in length: "
                f"{len(self.boundary)}, {len(self.boundary_edge)}, {len(self.boundary_t)}"
            )

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def n_triangles(self) -> int:
        return len(self.triangles)

    @cached_property
    def edges(self):
        """The mesh's edges and the half-edges on them (`warpcli.maps.fem.topology.Edges`), found once
        for the Laplacian and the triangles' neighbours.

        Raises
        ------
        warpcli.maps.fem.topology.NotManifold
            For a mesh with an edge of more than two triangles (never made here).
        ValueError
            For triangles naming a vertex the mesh does not have.
        """
        return mesh_edges(self.triangles, self.n_vertices)


def centroids(vertices: NDArray[np.float64], triangles: NDArray[np.integer]) -> NDArray[np.float64]:
    """Each triangle's centroid, as ``vertices[triangles].mean(axis=1)`` makes it, bit for bit: the
    corners summed from 0.0 (which turns -0.0 into 0.0) one after the other, over 3; without the
    (M, 3, 2) gather and the reduction along an axis of 3 (4-7 ms for 37k triangles)."""
    c0, c1, c2 = corners(vertices, triangles)
    out = c0 + 0.0
    out += c1
    out += c2
    out /= 3.0
    return out


def triangle_areas(vertices: NDArray[np.float64], triangles: NDArray[np.integer]) -> NDArray[np.float64]:
    """Signed areas of triangles (positive when clockwise on screen, like `signed_area`)."""
    a, b, c = corners(vertices, triangles)
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))


def graded_from(polygon: Polygon, region: tuple[float, float, float, float] | None) -> bool:
    """Whether ``polygon`` reaches far enough beyond ``region`` to be meshed graded from it."""
    if region is None:
        return False
    xmin, ymin, xmax, ymax = polygon.bounds
    rx0, ry0, rx1, ry1 = region
    reach = REGION_REACH * max(rx1 - rx0, ry1 - ry0, 1.0)
    return xmin < rx0 - reach or ymin < ry0 - reach or xmax > rx1 + reach or ymax > ry1 + reach


def auto_max_area(polygon: Polygon, region: tuple[float, float, float, float] | None = None) -> float:
    """The default largest triangle area for ``polygon``, in square pixels.

    ``sqrt(area) / AUTO_AREA_DIVISOR``, at least 1, and large enough that the
    mesh stays within ``AUTO_MAX_TRIANGLES``; for a polygon that reaches far
    beyond its ``region`` of interest (see `graded_from`), the area is that of
    the region, the mesh's density there.
    """
    area = abs(polygon.signed_area)
    if graded_from(polygon, region):
        rx0, ry0, rx1, ry1 = region  # type: ignore[misc]
        area = min(area, (rx1 - rx0) * (ry1 - ry0))
    return max(1.0, math.sqrt(area) / AUTO_AREA_DIVISOR, 2.0 * area / AUTO_MAX_TRIANGLES)


def mesh_polygon(
    polygon: Polygon,
    max_area: float,
    *,
    grade: bool = True,
    region: tuple[float, float, float, float] | None = None,
    boundary: str = "linear",
) -> TriMesh:
    """Mesh a polygon with a quality constrained Delaunay triangulation.

    Every triangle has area at most ``max_area`` and angles of at least
    ``MIN_ANGLE`` degrees (except where an input angle is smaller). The mesh has
    no interior constraints, so every interior edge is locally Delaunay: its
    two opposite angles sum to at most pi and its cotangent weight is
    non-negative, which makes a discrete harmonic map onto a convex polygon a
    convex-combination map.

    Parameters
    ----------
    polygon : Polygon
    max_area : float
        Largest triangle area, in square units of the polygon's coordinates
        (pixels).
    grade : bool
        Refine geometrically towards reflex vertices.
    region : (xmin, ymin, xmax, ymax) or None
        Where the map will be evaluated (the image). A polygon reaching far
        beyond it (see `graded_from`) gets ``max_area`` near the region and
        triangles growing with the distance from it.
    boundary : {"linear", "quadratic"}
        The boundary behaviour the mesh will carry: quadratic data (t goes to
        t^2 of Theta's edge) gets nodes at ``t = sqrt(k / QUADRATIC_NODES)`` on
        every edge, evenly spaced in Theta, so that the piecewise-linear data
        follows the parabola on short edges too.

    Returns
    -------
    TriMesh
        Triangles are oriented like ``polygon``.

    Raises
    ------
    InputError
        If ``max_area`` is not positive, or the mesh would exceed
        ``MAX_TRIANGLES`` triangles (a `PolygonError`).
    MeshingError
        If `triangle` fails.
    """
    import triangle as tr

    if not (max_area > 0 and math.isfinite(max_area)):
        raise InputError(f"{polygon.name}: maximum triangle area must be positive and finite, got {max_area}")
    area = abs(polygon.signed_area)
    graded = graded_from(polygon, region)
    if graded:
        rx0, ry0, rx1, ry1 = region  # type: ignore[misc]
        reach = REGION_REACH * max(rx1 - rx0, ry1 - ry0, 1.0)
        area = min(area, (rx1 - rx0 + 2 * reach) * (ry1 - ry0 + 2 * reach))
    # A quality mesh with area bound A has triangles of about A/2 on average.
    estimate = 2.0 * area / max_area
    if estimate > MAX_TRIANGLES:
        raise PolygonError(
            f"{polygon.name}: meshing this polygon (area {area:.4g} px^2) with triangles of at most "
            f"{max_area:g} px^2 would need about {estimate:.3g} triangles, more than the limit of "
            f"{MAX_TRIANGLES:,}; use a larger maximum triangle area"
        )
    tri_in = triangle_input(polygon, max_area, grade, boundary == "quadratic")
    if graded:
        most = min(MAX_TRIANGLES, max(AUTO_MAX_TRIANGLES, round(GRADED_BUDGET * estimate)))
        too_many = (
            f"{polygon.name}: this polygon reaches far beyond the image (to {_far_corner(polygon.bounds, region)}) "
            f"through a part too thin for its length: meshing it would need more than {most:,} triangles; "
            "bring its far vertices closer, or widen that part"
        )
    else:
        most = MAX_TRIANGLES
        too_many = (
            f"{polygon.name}: meshing this polygon would need more than {most:,} triangles: a part of it is too "
            "thin for its length; widen that part or shorten it"
        )
    triangulate = functools.partial(_bounded_triangulate, tr, most=most, message=too_many)
    try:
        reflex = polygon.points[polygon.reflex_vertices()] if grade else np.empty((0, 2))
        if graded:
            out = _region_graded(triangulate, tri_in, polygon, max_area, reflex, region)  # type: ignore[arg-type]
        else:
            out = triangulate(tri_in, f"pq{MIN_ANGLE:g}a{decimal(max_area)}Q")
        if len(reflex) and not graded:
            # Size field: edge length growing linearly with the distance to the
            # nearest reflex vertex, from _GRADE_MIN up to the nominal length.
            centroid = centroids(out["vertices"], out["triangles"])
            dist = _nearest_distance(centroid, reflex)
            h = math.sqrt(4.0 * max_area / math.sqrt(3.0))
            edge = np.clip(_GRADE_SLOPE * dist, _GRADE_MIN, h)
            out["triangle_max_area"] = (math.sqrt(3.0) / 4.0 * edge * edge).reshape(-1, 1)
            out = triangulate(out, f"rpq{MIN_ANGLE:g}aQ")
    except PolygonError:
        raise
    except Exception as err:  # triangle raises bare RuntimeErrors; say which polygon.
        raise MeshingError(f"{polygon.name}: triangle failed to mesh the polygon: {err}") from err
    return mesh_from_triangle(polygon, out)


def _bounded_triangulate(tr, data: dict, switches: str, *, most: int, message: str) -> dict:
    """`triangle.triangulate`, refused with ``message`` (a `PolygonError`) if the mesh has more than ``most`` triangles.

    The work is bounded before it is done: Triangle's ``S`` switch stops it
    once the mesh has ``most`` vertices. A triangulation of V vertices, B of
    them on the boundary, has 2V - B - 2 triangles: about 2V for a mesh of
    an area, about V for one of a thin part (its boundary split all along),
    so the vertices bound the triangles to 2 ``most``, and a polygon that
    needs more than ``most`` (a part too thin for its length) is refused.
    """
    room = most - len(data["vertices"])
    if room <= 0:
        raise PolygonError(message)
    out = tr.triangulate(data, f"{switches}S{room}")
    if len(out["vertices"]) >= most or len(out["triangles"]) > most:
        raise PolygonError(message)
    return out


def _far_corner(bounds, region) -> str:
    """The corner of the polygon's bounding box farthest from the region, for a message."""
    xmin, ymin, xmax, ymax = bounds
    rx0, ry0, rx1, ry1 = region
    x = xmin if rx0 - xmin > xmax - rx1 else xmax
    y = ymin if ry0 - ymin > ymax - ry1 else ymax
    return f"x = {x:.4g}, y = {y:.4g}"


def triangle_input(polygon: Polygon, max_area: float, grade: bool = True, quadratic: bool = False) -> dict:
    """What `triangle.triangulate` is given for ``polygon``: its boundary points and segments, marked.

    Marker of a boundary point: 2 + i for polygon vertex i, 2 + n + i for a
    point inside edge i (Triangle gives points it adds on a segment that
    segment's marker). 0 marks interior nodes, 1 is Triangle's default.
    """
    n = polygon.n
    pts, markers = _boundary_points(polygon, max_area, grade, quadratic)
    m = len(pts)
    seg = np.stack([np.arange(m), (np.arange(m) + 1) % m], axis=1)
    seg_markers = np.where(markers < 2 + n, markers + n, markers)
    return {
        "vertices": pts,
        "vertex_markers": markers.reshape(-1, 1),
        "segments": seg,
        "segment_markers": seg_markers.reshape(-1, 1),
    }


def mesh_from_triangle(polygon: Polygon, out: dict) -> TriMesh:
    """The `TriMesh` of what `triangle.triangulate` made of `triangle_input`'s ``polygon``."""
    n = polygon.n
    verts = np.ascontiguousarray(out["vertices"], dtype=np.float64)
    tris = np.ascontiguousarray(out["triangles"], dtype=np.int32)
    vmark = out["vertex_markers"].ravel()
    if len(tris) == 0:
        raise MeshingError(f"{polygon.name}: triangle produced no triangles")
    # Triangle returns counter-clockwise triangles in its own y-up sense, which
    # is a positive shoelace area; make them match the polygon's orientation.
    if polygon.signed_area < 0:
        tris = tris[:, ::-1].copy()
    boundary = np.flatnonzero(vmark >= 2)
    mk = vmark[boundary]
    edge = np.where(mk < 2 + n, mk - 2, mk - 2 - n).astype(np.intp)
    a = polygon.points[edge]
    b = polygon.points[(edge + 1) % n]
    d = b - a
    t = np.einsum("ij,ij->i", verts[boundary] - a, d) / np.einsum("ij,ij->i", d, d)
    t = np.where(mk < 2 + n, 0.0, np.clip(t, 0.0, 1.0))
    return TriMesh(verts, tris, boundary, edge, t)


def _region_graded(triangulate, tri_in: dict, polygon: Polygon, max_area: float, reflex, region) -> dict:
    """A mesh with ``max_area`` at the region, growing away from it (and graded at reflex vertices).

    Starts from a coarse mesh and refines in passes; each pass asks of every
    triangle that is still too large at most a quarter of its area, so the
    mesh grows only where the size field asks for it.
    """
    h = math.sqrt(4.0 * max_area / math.sqrt(3.0))
    coarse = max(max_area, abs(polygon.signed_area) / 2000.0)
    out = triangulate(tri_in, f"pq{MIN_ANGLE:g}a{decimal(coarse)}Q")
    lo = np.array(region[:2])
    hi = np.array(region[2:])
    for _ in range(_REGION_PASSES):
        box = out["vertices"][out["triangles"]]  # (M, 3, 2): each triangle's corners
        # Distance from the region to each triangle's bounding box (0 where they overlap).
        gap = np.maximum(np.maximum(lo - box.max(axis=1), box.min(axis=1) - hi), 0.0)
        edge = h + _REGION_SLOPE * np.hypot(gap[:, 0], gap[:, 1])
        if len(reflex):
            near = np.maximum(_GRADE_SLOPE * _nearest_distance(centroids(out["vertices"], out["triangles"]), reflex), _GRADE_MIN)
            edge = np.minimum(edge, near)
        target = math.sqrt(3.0) / 4.0 * edge * edge
        area = np.abs(triangle_areas(out["vertices"], out["triangles"]))
        big = area > target
        if not big.any():
            break
        out["triangle_max_area"] = np.where(big, np.maximum(target, area / _REGION_SPLIT), -1.0).reshape(-1, 1)
        out = triangulate(out, f"rpq{MIN_ANGLE:g}aQ")
    return out


def _nearest_distance(points: NDArray[np.float64], sites: NDArray[np.float64]) -> NDArray[np.float64]:
    """Distance from each point to the nearest site (sites are few: polygon vertices)."""
    best = np.full(len(points), np.inf)
    for s in sites:
        np.minimum(best, np.hypot(points[:, 0] - s[0], points[:, 1] - s[1]), out=best)
    return best


def _boundary_points(polygon: Polygon, max_area: float, grade: bool, quadratic: bool = False):
    """Boundary points in order, with Triangle markers; graded towards reflex vertices."""
    p = polygon.points
    n = polygon.n
    # Edge length of an equilateral triangle of area max_area.
    h = math.sqrt(4.0 * max_area / math.sqrt(3.0))
    reflex = np.zeros(n, dtype=bool)
    if grade:
        reflex[polygon.reflex_vertices()] = True
    if not quadratic and not reflex.any():  # each edge gives its first vertex alone (`_edge_params`)
        return p.copy(), np.arange(2, 2 + n, dtype=np.int32)
    pieces = []
    marks = []
    for i in range(n):
        a = p[i]
        b = p[(i + 1) % n]
        length = float(np.hypot(*(b - a)))
        t = _edge_params(length, h, bool(reflex[i]), bool(reflex[(i + 1) % n]))
        if quadratic:
            t = sorted_unique(np.concatenate([t, np.sqrt(np.arange(1, QUADRATIC_NODES) / QUADRATIC_NODES)]))
        pieces.append(a + t[:, None] * (b - a))
        mk = np.full(len(t), 2 + n + i, dtype=np.int32)
        mk[0] = 2 + i
        marks.append(mk)
    return np.concatenate(pieces), np.concatenate(marks)


def _edge_params(length: float, h: float, grade_start: bool, grade_end: bool) -> NDArray[np.float64]:
    """Parameters in [0, 1) of the points on one edge, starting with 0 (the vertex).

    Only graded ends get points here; Triangle's own refinement subdivides the
    rest of the edge to the area bound.
    """
    if not (grade_start or grade_end) or length <= 0:
        return np.zeros(1)
    # Distances from a graded end: _GRADE_MIN px, then each step at most
    # _GRADE_RATIO - 1 times the distance (so segments grow geometrically) and
    # at most the nominal length h, out to _GRADE_REACH * h; capped at a third
    # of the edge each side.
    radii = [min(_GRADE_MIN, h)]
    while radii[-1] < _GRADE_REACH * h:
        radii.append(radii[-1] + min(h, radii[-1] * (_GRADE_RATIO - 1.0)))
    r = np.array(radii)
    cap = length / 3.0 if (grade_start and grade_end) else length / 1.5
    r = r[r < cap]
    ts = [np.zeros(1)]
    if grade_start:
        ts.append(r / length)
    if grade_end:
        ts.append(1.0 - r[::-1] / length)
    return sorted_unique(np.concatenate(ts))
