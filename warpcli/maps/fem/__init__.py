"""FEM (the paper's §3.1.1): piecewise-linear harmonic maps on graded constrained Delaunay meshes.

- `mesh`: graded quality meshes over `triangle`;
- `topology`: the mesh's edges and the triangles across them;
- `solve`: cotangent / mean-value Laplacians and the Dirichlet solve;
- `sparse`: the default Dirichlet system (numpy and `_sparse_kernels`) and SuperLU, without scipy.sparse;
- `locate`: point location (bucket grid, triangle neighbours);
- `_kernels`: compiled scan conversion and walks for pixel grids;
- `_sparse_kernels`: compiled passes over the mesh's edges and the Laplacian's rows.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..._cached import cached_property
from ..._native import Kernels
from ...boundary import nearest_edge
from ...options import MapOptions
from ...polygon import Polygon
from ...simplicial import PiecewiseLinear, corners
from ..base import Certificate, ForkedBuild, GridSample, Mapped, ThetaMap, as_points, inv2
from ..straight import IdentityMap, straight_boundary
from ..theta import TargetTheta, Theta
from . import sparse, topology
from .locate import TriangleLocator, affine_coefficients, triangle_neighbours
from .mesh import TriMesh, auto_max_area, centroids, mesh_polygon
from .solve import DirichletSolver, flipped_triangles, solve_dirichlet

log = logging.getLogger("warpcli")

#: The compiled scan conversion and walk (`_kernels`), loaded without numba;
#: they freeze locate.BARY_TOL when compiled.
_compiled = Kernels("warpcli.maps.fem._kernels", depends=("locate.py",))

__all__ = ["FEMMap", "build", "prepare", "triangle_jacobians"]


@dataclass(eq=False)
class FEMMap(ThetaMap):
    """A discrete (piecewise-linear) harmonic map of a triangle mesh onto Theta.

    Linear on every triangle of ``mesh``: vertex k goes to ``values[k]``.
    Build one with `build`.

    Parameters
    ----------
    polygon : Polygon
    theta : Theta
    mesh : TriMesh
        A mesh of ``polygon`` (triangles oriented like it).
    values : (N, 2) ndarray of float
        Image in Theta of every mesh vertex.
    weights : {"cotan", "positive"}
        The Laplacian's edge weights it was solved with.

    References
    ----------
    Schneider & Hormann, CAGD 2015, §3.1.1 (FEM) and §3.2 (inverting a
    piecewise-linear map).
    """

    mesh: TriMesh
    values: NDArray[np.float64]
    weights: str = "cotan"
    solver: DirichletSolver | None = field(default=None, repr=False, kw_only=True)
    conditions: str = field(default="dirichlet", kw_only=True)

    method = "fem"

    def __post_init__(self) -> None:
        if self.values.shape != self.mesh.vertices.shape:
            raise ValueError(f"values has shape {self.values.shape} but the mesh has {self.mesh.vertices.shape}")

    # Lookup tables, built on first use.

    @cached_property
    def _triangles(self) -> NDArray[np.int64]:
        return self.mesh.triangles.astype(np.int64)

    @cached_property
    def _domain_locator(self) -> TriangleLocator:
        return TriangleLocator(self.mesh.vertices, self.mesh.triangles)

    @cached_property
    def _image_locator(self) -> TriangleLocator:
        return TriangleLocator(self.values, self.mesh.triangles)

    @cached_property
    def _grid_table(self) -> NDArray[np.float64]:
        return _with_none_row(triangle_jacobians(self.mesh.vertices, self.values, self.mesh.triangles))

    @cached_property
    def _inverse_table(self) -> NDArray[np.float64]:
        return _with_none_row(triangle_jacobians(self.values, self.mesh.vertices, self.mesh.triangles))

    def flipped(self) -> NDArray[np.bool_]:
        """Per triangle: whether its image is degenerate or has the wrong orientation.

        A polygon oriented against Theta gives a mirror image, which is not
        counted as flipped.
        """
        return self._flipped

    @cached_property
    def _flipped(self) -> NDArray[np.bool_]:
        # Asked for by the repair and again by the certificate: computed once.
        # Every orientation is decided exactly, onto a convex Theta as onto a
        # target (--theta none, where the degree argument then needs no
        # tolerance, docs/proving.md): a float area can miss a fold.
        return flipped_triangles(self.mesh, self.values, self.theta.points)

    def precompute(self, side: str) -> None:
        """Build now the lookup tables one side of the composition will need.

        ``"grid"``: `evaluate_grid` (this map is evaluated on a pixel grid);
        ``"inverse"``: the coherent `inverse` (this map is inverted), both
        with Jacobians. `warpcli.maps.compose.build_map` calls this on the
        thread that built the map, so the tables are made on both cores while
        the other map is still solved, rather than one after the other later.
        """
        names = {
            "grid": ("_triangles", "_domain_coefficients", "_coherent_order", "_grid_table"),
            "inverse": ("_triangles", "_image_coefficients", "_neighbours", "_inverse_table"),
        }[side]
        for name in names:
            getattr(self, name)

    def certify(self) -> Certificate:
        """Exact for a piecewise-linear map: it is one-to-one iff no triangle flips."""
        return Certificate(int(self.flipped().sum()), self.mesh.n_triangles, "triangles")

    def describe(self) -> dict:
        return {"mesh": {"vertices": self.mesh.n_vertices, "triangles": self.mesh.n_triangles}}

    def to_theta_parameter(self, edge: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
        if self.conditions != "mixed":
            return super().to_theta_parameter(edge, t)
        return self._slide(edge, t, forward=True)

    def from_theta_parameter(self, edge: ArrayLike, s: ArrayLike) -> NDArray[np.float64]:
        if self.conditions != "mixed":
            return super().from_theta_parameter(edge, s)
        return self._slide(edge, s, forward=False)

    def _slide(self, edge: ArrayLike, u: ArrayLike, *, forward: bool) -> NDArray[np.float64]:
        """Natural boundary conditions let the boundary slide along Theta's edges: the
        parameter correspondence is the solution's, piecewise linear between nodes."""
        e = np.broadcast_to(np.asarray(edge, dtype=np.intp), np.shape(u))
        u = np.asarray(u, dtype=np.float64)
        out = np.empty(u.shape)
        for i, (t_nodes, s_nodes) in enumerate(self._edge_tables):
            on = e == i
            if on.any():
                out[on] = np.interp(u[on], t_nodes, s_nodes) if forward else np.interp(u[on], s_nodes, t_nodes)
        return out

    @cached_property
    def _edge_tables(self) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
        """Per polygon edge: the nodes' parameters along it and along Theta's edge (sorted)."""
        m = self.mesh
        w = self.theta.points
        n = len(w)
        tables = []
        for i in range(n):
            on = m.boundary_edge == i
            t = np.concatenate([m.boundary_t[on], [1.0]])
            a, d = w[i], w[(i + 1) % n] - w[i]
            img = np.concatenate([self.values[m.boundary[on]], w[(i + 1) % n][None]])
            s = np.clip((img - a) @ d / (d @ d), 0.0, 1.0)
            order = np.argsort(t, kind="stable")
            tables.append((t[order], np.maximum.accumulate(s[order])))
        return tables

    def retarget(self, theta: Theta) -> FEMMap:
        """The map of the same mesh onto another Theta: one back-substitution (§5.1)."""
        solver = self.solver or DirichletSolver(self.mesh, self.weights)
        new = FEMMap(
            self.polygon, theta, self.mesh, solver.solve(theta.points, self.boundary), self.weights,
            boundary=self.boundary, solver=solver, conditions=self.conditions,
        )  # fmt: skip
        # What depends on the mesh alone is shared.
        for name in ("_triangles", "_domain_locator", "_domain_coefficients", "_coherent_order", "_neighbours"):
            if name in self.__dict__:
                new.__dict__[name] = self.__dict__[name]
        return new

    def evaluate(self, points: ArrayLike, *, jacobian: bool = False) -> Mapped:
        out, tri = PiecewiseLinear(self.values, self.mesh.triangles, self._domain_locator).evaluate(as_points(points))
        return Mapped(out, self._gather("grid", tri) if jacobian else None)

    def inverse(self, points: ArrayLike, *, jacobian: bool = False, coherent: bool = False) -> Mapped:
        out, tri = self.inverse_cells(points, coherent=coherent)
        return Mapped(out, self._gather("inverse", tri) if jacobian else None)

    def inverse_cells(self, points: ArrayLike, *, coherent: bool = False) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """`inverse`'s points, and the triangle each one was found in (-1: none), whose
        Jacobian is the inverse's there: ``jacobian_table("inverse")[triangle]``.

        For `warpcli.maps.compose`, which multiplies the Jacobians of a pull-back as it
        scatters them (a gather of each band's quarter million Jacobians, twice, was
        20 % of a 12 MP pull-back's numpy)."""
        q = as_points(points)
        # The whole array's test first: the per-point one (``.all(axis=1)``, 2.5 ms per 130k
        # points, a reduction along an axis of 2) only where some point is not finite.
        all_finite = bool(np.isfinite(q).all())
        if coherent and all_finite:
            # One compiled walk through the image mesh from each point's
            # predecessor; the few walks that give up go to the bucket search.
            # Every point is written: by the walk, or (where it gave up) below.
            out = np.empty(q.shape)
            where = np.empty(len(q), dtype=np.int32)
            max_steps = len(self._triangles) + 64  # a safety net: the walk ends on its own
            _compiled.walk(
                np.ascontiguousarray(q), self._triangles, self._image_coefficients, self._neighbours,
                self.mesh.vertices, max_steps, out, where,
            )  # fmt: skip
            tri = where.astype(np.int64)
            lost = np.flatnonzero(where < 0)
        else:
            out = np.full(q.shape, np.nan)
            tri = np.full(len(q), -1, dtype=np.int64)
            lost = np.arange(len(q)) if all_finite else np.flatnonzero(np.isfinite(q).all(axis=1))
        if lost.size:
            out[lost], tri[lost] = self._inverse_located(q[lost])
        return out, tri

    def jacobian_table(self, side: str) -> NDArray[np.float64]:
        """(T + 1, 2, 2): the Jacobian on each triangle of the map (``"grid"``, as `evaluate_grid`
        gives it) or of its inverse (``"inverse"``), then a row of NaN, the row of triangle -1
        (none): the values `inverse` and `evaluate_grid` gather, NaN for none."""
        # One side's table only: a pull-back asks the target's map for "grid" and the source's for
        # "inverse" (both made in the child that built the map, `precompute`); a table of both
        # sides made the other one's Jacobians in the parent, twice on the pull-back's two threads
        # (7 ms each at 1 MP, measured).
        if side not in ("grid", "inverse"):
            raise ValueError(f"side must be 'grid' or 'inverse', not {side!r}")
        return self._grid_table if side == "grid" else self._inverse_table

    def _gather(self, side: str, tri: NDArray[np.integer]) -> NDArray[np.float64]:
        """The Jacobians of ``side`` on triangles ``tri``, NaN where it is -1: rows of
        `jacobian_table`, whose last row is that NaN (`numpy.take`: 0.6 ms per 262k pixels against
        4-5 ms for fancy indexing, twice per band of a pull-back)."""
        return np.take(self.jacobian_table(side), tri, axis=0)

    @cached_property
    def _image_coefficients(self) -> NDArray[np.float64]:
        return affine_coefficients(self.values, self._triangles)

    @cached_property
    def _neighbours(self) -> NDArray[np.int64]:
        try:  # from the edges the Laplacian found (the same table)
            return topology.neighbours(self.mesh.edges, self.mesh.n_triangles)
        except topology.NotManifold:
            return triangle_neighbours(self._triangles)

    def _inverse_located(self, q: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """phi^-1 by bucket search in the image mesh.

        A point of Theta's boundary can miss every image triangle by a
        rounding error; the boundary map is known exactly, so it is inverted
        there instead (triangle -1: no Jacobian).
        """
        out, tri = PiecewiseLinear(self.mesh.vertices, self.mesh.triangles, self._image_locator).evaluate(q)
        lost = np.flatnonzero((tri < 0) & np.isfinite(q).all(axis=1))
        if lost.size:
            edge, s, _ = nearest_edge(q[lost], self.theta.points)
            out[lost] = self.boundary_from_theta(edge, s)
        return out, tri

    def evaluate_grid(
        self, width: int, height: int, rows: tuple[int, int] | None = None, *, jacobian: bool = False
    ) -> GridSample:
        """phi at pixel centres by one compiled scan conversion of the mesh (see `_kernels.scan_grid`)."""
        sample, where = self.grid_cells(width, height, rows)
        return sample._replace(jacobian=self._gather("grid", where) if jacobian else None)

    def grid_cells(
        self, width: int, height: int, rows: tuple[int, int] | None = None
    ) -> tuple[GridSample, NDArray[np.int32]]:
        """`evaluate_grid` without Jacobians, and the triangle of each pixel, whose Jacobian is
        the map's there: ``jacobian_table("grid")[triangle]`` (see `inverse_cells`)."""
        r0, r1 = rows if rows is not None else (0, height)
        size = (r1 - r0) * width
        pixels = np.empty(size, dtype=np.int64)
        values = np.empty((size, 2))
        where = np.empty(size, dtype=np.int32)
        order = self._coherent_order if rows is None else self._order_within(r0, r1)
        count = _compiled.scan_grid(
            self.mesh.vertices, self._triangles, self._domain_coefficients, self.values, order,
            width, height, r0, r1, np.zeros(size, dtype=np.uint8), pixels, values, where,
        )  # fmt: skip
        return GridSample(pixels[:count], values[:count]), where[:count]

    def _order_within(self, r0: int, r1: int) -> NDArray[np.int64]:
        """`_coherent_order` restricted to the triangles that can reach rows r0 <= r < r1 (in the
        same order, so each pixel goes to the same triangle): a band scans its own triangles, not
        the whole mesh (which made strips of a tall image quadratic in its height)."""
        ymin_sorted, ymax, by_ymin, rank, tallest = self._row_index
        lo = np.searchsorted(ymin_sorted, r0 - 1.0 - tallest, side="left")
        hi = np.searchsorted(ymin_sorted, r1 + 1.0, side="right")
        near = by_ymin[lo:hi]
        near = near[ymax[near] >= r0 - 1.0]
        return self._coherent_order[np.sort(rank[near])]

    @cached_property
    def _row_index(self):
        """The triangles' ymin in increasing order, each one's ymax, the triangles by ymin, their
        ranks in `_coherent_order`, and the tallest's height."""
        # Each corner's y gathered from the y column, then the same np.minimum / np.maximum of
        # the three that min / max over an axis of (M, 3, 2) corners reduce with, in that order
        # (the same values, NaN and signed zeros alike): 9.7 -> 2.2 ms for 37k triangles at
        # 1 MP, on both threads of the pull-back's first bands (no lock: both make it).
        y = np.ascontiguousarray(self.mesh.vertices[:, 1])
        y0, y1, y2 = (np.take(y, self._triangles[:, k]) for k in range(3))
        ymin = np.minimum(np.minimum(y0, y1), y2)
        ymax = np.maximum(np.maximum(y0, y1), y2)
        rank = np.empty(len(ymin), dtype=np.int64)
        rank[self._coherent_order] = np.arange(len(ymin))
        tallest = float((ymax - ymin).max()) if len(ymin) else 0.0
        by_ymin = np.argsort(ymin, kind="stable")
        return ymin[by_ymin], ymax, by_ymin, rank, tallest

    @cached_property
    def _domain_coefficients(self) -> NDArray[np.float64]:
        return affine_coefficients(self.mesh.vertices, self._triangles)

    @cached_property
    def _coherent_order(self) -> NDArray[np.int64]:
        """Triangles in serpentine bands of 8 pixels: consecutive triangles are
        neighbours, so each pixel's walk in Theta starts next to its goal."""
        c = centroids(self.mesh.vertices, self._triangles)
        row = np.floor(c[:, 1] / 8.0)
        x = np.where(row % 2 == 0, c[:, 0], -c[:, 0])
        return np.lexsort((x, row)).astype(np.int64)


def triangle_jacobians(
    domain: NDArray[np.float64], image: NDArray[np.float64], triangles: NDArray[np.integer]
) -> NDArray[np.float64]:
    """(M, 2, 2): the constant Jacobian, per triangle, of the linear map taking
    ``domain`` vertices to ``image`` vertices.

    ``J = G @ inv(E)`` with ``E = [d_1 - d_0, d_2 - d_0]`` and
    ``G = [i_1 - i_0, i_2 - i_0]`` as columns; NaN or inf for a degenerate
    triangle. Swap the arguments for the inverse map's Jacobians.
    """
    t = triangles
    e, g = (_edge_columns(points, t) for points in (domain, image))
    return g @ inv2(e)


def _with_none_row(jacobians: NDArray[np.float64]) -> NDArray[np.float64]:
    """``jacobians`` (M, 2, 2) and a row of NaN after them, the row of triangle -1 (none)."""
    return np.concatenate([jacobians, np.full((1, 2, 2), np.nan)])


def _edge_columns(points: NDArray, t: NDArray[np.integer]) -> NDArray:
    """(M, 2, 2): per triangle, its edges from corner 0 to corners 1 and 2 as columns, in the
    type their difference has; written in place (``np.stack`` of the two copied them)."""
    first, second, third = corners(points, t)
    out = np.empty((len(t), 2, 2), dtype=np.subtract(first[:0], first[:0]).dtype)
    np.subtract(second, first, out=out[:, :, 0])
    np.subtract(third, first, out=out[:, :, 1])
    return out


def build(
    polygon: Polygon,
    theta: Theta,
    options: MapOptions,
    role: str = "source",
    region: tuple[float, float, float, float] | None = None,
) -> FEMMap:
    """Mesh ``polygon`` and solve the discrete harmonic map onto ``theta``.

    Parameters
    ----------
    polygon : Polygon
    theta : Theta
    options : MapOptions
        ``max_area``, ``grade`` and the boundary behaviour (for this ``role``),
        ``weights`` and ``check`` are used.
    role : {"source", "target"}
        Which of the pair ``polygon`` is (picks its ``max_area``).
    region : (xmin, ymin, xmax, ymax) or None
        Where the map will be evaluated (its image); a polygon reaching far
        beyond it is meshed graded from it (see `mesh.graded_from`).

    Returns
    -------
    FEMMap
        With ``options.check``: one that flips no triangle if a repair could
        make it so. A cotangent map that flips (the constrained Delaunay
        meshes should rule it out) is solved again with positive weights, with
        a warning; the caller certifies the result.

    Raises
    ------
    InputError
        If the mesh would be too large.
    MeshingError
        If `triangle` fails.
    """
    area = options.areas()[0 if role == "source" else 1]
    clock = time.perf_counter
    t0 = clock()
    boundary = options.src_boundary if role == "source" else options.dst_boundary
    straight = isinstance(theta, TargetTheta)
    if straight:
        # --theta none: the target goes onto itself (the identity, exact and
        # free); the source straight onto the target with the boundary
        # correspondence the two behaviours compose to.
        if role == "target":
            return IdentityMap(polygon, theta)
        boundary = straight_boundary(options)
    mesh = mesh_polygon(
        polygon, auto_max_area(polygon, region) if area is None else area, region=region, boundary=boundary,
        grade=options.grade,
    )
    t1 = clock()
    # Mixed conditions (§5.2; Theta the unit square): each coordinate is
    # prescribed on the two edges where it is constant (x on the vertical
    # edges 1 and 3, y on the horizontal edges 0 and 2) and slides freely
    # (zero normal derivative) along the other two.
    free = ((0, 2), (1, 3)) if options.conditions == "mixed" else ((), ())
    solver = DirichletSolver(mesh, options.weights, free)
    values = solver.solve(theta.points, boundary)
    phi = FEMMap(
        polygon, theta, mesh, values, options.weights, timings={"mesh": t1 - t0, "solve": clock() - t1},
        boundary=boundary, solver=solver, conditions=options.conditions,
    )  # fmt: skip
    if options.check and not straight:
        # No repair for the straight map: mean-value weights onto a non-convex
        # target are not one-to-one either, and it is the harmonic map that is
        # offered; the certificate refuses it (`warpcli.maps.compose.BijectiveMap`).
        phi = repaired(phi)
    return phi


def _built_to_send(
    polygon: Polygon, theta: Theta, options: MapOptions, role: str, region, side: str | None = None
) -> FEMMap:
    """`build`, in a forked child: the map without its solver (a factorization does not pickle;
    `FEMMap.with_theta` makes a new one if it is needed), with the lookup tables of ``side``
    (`FEMMap.precompute`) made there too: they cross the pipe with it (a few MB, out of band)
    rather than being made by the parent after the child ends (20-35 ms at 1-4 MP)."""
    built = build(polygon, theta, options, role, region)
    phi = dataclasses.replace(built, solver=None)
    # The repair's test of every triangle's orientation (`build`, with ``check``) is the
    # certificate's too: sent with the map, the parent does not decide it again (10-25 ms
    # of the parent's time between the children's end and the pull-back, at 1-12 MP).
    if "_flipped" in built.__dict__:
        phi.__dict__["_flipped"] = built.__dict__["_flipped"]
    if side is not None:
        phi.precompute(side)
    # The mesh's edge tables (four arrays of its edges: a fifth of what would cross the pipe,
    # 1.6-1.8 MB at 1 MP) served the Laplacian and `_neighbours`, made here: the parent's
    # warp asks for neither, and a later retarget makes them again.
    phi.mesh.__dict__.pop("edges", None)
    # Nor the int64 copy of the triangles (a sixth of the rest): the parent makes it again in
    # 0.1-0.3 ms where its sending took 1-1.5 ms.
    phi.__dict__.pop("_triangles", None)
    return phi


def forks(options: MapOptions) -> bool:
    """Whether `build_forked` builds maps with these options in a child, as soon as it is called."""
    from ..._fork import available

    return available() and options.conditions != "mixed"


def build_forked(
    polygon: Polygon, theta: Theta, options: MapOptions, role: str = "source", region=None, *,
    precompute: str | None = None,
) -> ForkedBuild | None:
    """`build` in a forked child process, so that it runs beside the other map's build
    (triangle and SuperLU hold the GIL, so threads take turns); None where that is
    not available (`warpcli._fork.available`) or not for these options (mixed
    conditions keep their solver). ``.result()`` is what `build` returns, bit for bit,
    with the lookup tables of `FEMMap.precompute` for side ``precompute`` (if given) made
    in the child."""
    if not forks(options):
        return None
    if role == "target" and isinstance(theta, TargetTheta):
        return None  # the identity (see `build`): nothing to build
    sparse.load_superlu()  # in the parent, so the child imports nothing
    try:
        return ForkedBuild(polygon.name, "meshing and solving", _built_to_send, polygon, theta, options, role, region, precompute)
    except OSError:  # no memory or processes left for a child: the caller builds on a thread
        return None


def repaired(phi: FEMMap) -> FEMMap:
    """phi itself if it flips no triangle, else phi solved with positive weights."""
    flips = int(phi.flipped().sum())
    if flips == 0 or phi.weights == "positive":
        return phi
    log.warning(
        "%s: the harmonic map flips %d triangle(s); solving with positive (mean-value) weights instead",
        phi.polygon.name,
        flips,
    )
    if phi.conditions == "mixed":
        return phi  # no repair for the experimental natural conditions: the certificate says so
    values = solve_dirichlet(phi.mesh, phi.theta.points, "positive", phi.boundary)
    return FEMMap(phi.polygon, phi.theta, phi.mesh, values, "positive", timings=phi.timings, boundary=phi.boundary)


def prepare() -> None:
    """Load the compiled kernels on tiny inputs, with the argument types of a warp.

    `warpcli.maps.compose.build_map` runs this on a thread of its own while
    the maps are built, so the first real call finds the kernels loaded; the
    first run on a machine compiles them here (see `warpcli._native`).
    """
    v = np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 2.0]])
    tri = np.array([[0, 1, 2]], dtype=np.int64)
    coef = np.array([[0.0, 0.0, 0.5, 0.0, 0.0, 0.5]])
    nbr = np.full((1, 3), -1, dtype=np.int64)
    order = np.zeros(1, dtype=np.int64)
    pixels = np.empty(4, dtype=np.int64)
    values = np.empty((4, 2))
    where = np.empty(4, dtype=np.int32)
    n = _compiled.scan_grid(v, tri, coef, v, order, 2, 2, 0, 2, np.zeros(4, dtype=np.uint8), pixels, values, where)
    _compiled.walk(values[:n], tri, coef, nbr, v, 8, np.empty((n, 2)), np.empty(n, dtype=np.int32))
