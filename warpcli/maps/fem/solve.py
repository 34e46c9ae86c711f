"""FEM solve: the cotangent (or mean-value) Laplacian and the Dirichlet solve for a map onto Theta (§3.1.1)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ...boundary import edge_points, to_theta_parameter
from ...errors import InputError
from ...options import WEIGHTS
from ...polygon import signed_area
from ...polygon.predicates import orientations
from . import sparse
from .mesh import TriMesh
from .sparse import cotan_terms
from .topology import NotManifold


def flipped_triangles(
    mesh: TriMesh, values: NDArray[np.float64], theta: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """Triangles whose image under a map onto ``theta`` is flipped or degenerate, decided exactly.

    Mesh triangles are oriented like their polygon, and the boundary goes onto
    Theta's boundary in vertex order, so a one-to-one map gives every image
    triangle Theta's orientation, whichever way the polygon runs. Each image
    triangle's orientation is the exact sign of its area for the doubles
    given (`warpcli.polygon.predicates.orientations`: a float area can have
    the wrong sign on a sliver, and a certificate that can miss a fold is no
    certificate); a triangle counts as flipped unless that sign is strictly
    Theta's, so degenerate images and corners that are not finite are flipped.
    """
    sign = orientations(values, mesh.triangles)
    return ~(sign * np.sign(signed_area(theta)) > 0)


def flipped_exactly(
    mesh: TriMesh, values: NDArray[np.float64], target: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """`flipped_triangles` onto a target polygon (``--theta none``): the same exact test."""
    return flipped_triangles(mesh, values, target)


def cotan_laplacian(vertices: NDArray[np.float64], triangles: NDArray[np.integer]):
    """The P1 stiffness matrix (cotangent Laplacian) of a triangle mesh.

    ``K[i, j] = -(cot a_ij + cot b_ij) / 2`` for an edge ij with opposite angles
    a_ij and b_ij, and ``K[i, i] = -sum_j K[i, j]``: symmetric, positive
    semi-definite, zero row sums (constants are harmonic).

    Parameters
    ----------
    vertices : (N, 2) array of float
    triangles : (M, 3) array of int

    Returns
    -------
    (N, N) scipy.sparse.csr_matrix
        The Dirichlet solve itself builds the same matrix without scipy.sparse
        (`warpcli.maps.fem.sparse.cotan_stiffness`).
    """
    import scipy.sparse as sp

    n = len(vertices)
    r, c, x = cotan_terms(vertices, triangles)
    off = sp.coo_matrix((x, (r, c)), shape=(n, n)).tocsr()
    off.sum_duplicates()
    diag = -np.asarray(off.sum(axis=1)).ravel()
    return (off + sp.diags(diag)).tocsr()


def mean_value_laplacian(vertices: NDArray[np.float64], triangles: NDArray[np.integer]):
    """Floater's mean-value weights as a Laplacian (the paper's Section 3.1.4).

    ``w_ij = (tan(a_ij / 2) + tan(b_ij / 2)) / |v_i - v_j|`` with a_ij and b_ij
    the angles at v_i of the two triangles beside edge ij: positive for every
    triangle mesh, so the discrete map onto a convex polygon is a
    convex-combination map and one-to-one whatever the mesh. Not symmetric,
    and not the harmonic map: the price of the guarantee is a different
    (still smooth-looking) interpolant. Rows: ``L[i, i] = sum_j w_ij``,
    ``L[i, j] = -w_ij``.
    """
    import scipy.sparse as sp

    n = len(vertices)
    t = np.asarray(triangles)
    rows = []
    cols = []
    vals = []
    for k in range(3):
        i, j, m = t[:, k], t[:, (k + 1) % 3], t[:, (k + 2) % 3]
        u = vertices[j] - vertices[i]
        w = vertices[m] - vertices[i]
        lu = np.hypot(u[:, 0], u[:, 1])
        lw = np.hypot(w[:, 0], w[:, 1])
        # tan(angle / 2) = sin / (1 + cos) = |u x w| / (|u| |w| + u . w)
        half = np.abs(u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0]) / (lu * lw + np.einsum("ij,ij->i", u, w))
        rows += [i, i]
        cols += [j, m]
        vals += [half / lu, half / lw]
    w_mat = sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)).tocsr()
    w_mat.sum_duplicates()
    return (sp.diags(np.asarray(w_mat.sum(axis=1)).ravel()) - w_mat).tocsr()


def boundary_values(mesh: TriMesh, theta: NDArray[np.float64], boundary: str = "linear") -> NDArray[np.float64]:
    """Dirichlet data: a node at parameter t on edge i goes to ``(1 - s) w_i + s w_{i+1}``,
    s = t (linear boundary behaviour, §2) or t^2 (quadratic, §5.2)."""
    return edge_points(theta, mesh.boundary_edge, to_theta_parameter(mesh.boundary_t, boundary))


def solve_dirichlet(
    mesh: TriMesh, theta: NDArray[np.float64], weights: str = "cotan", boundary: str = "linear"
) -> NDArray[np.float64]:
    """Solve the discrete Dirichlet problem for both coordinates (Section 3.1.1).

    Parameters
    ----------
    mesh : TriMesh
    theta : (n, 2) array of float
        Convex polygon with as many vertices as the meshed polygon.
    weights : {"cotan", "positive"}
        ``cotan``: the FEM (cotangent) Laplacian, the harmonic map;
        ``positive``: mean-value weights, one-to-one on any mesh (Section 3.1.4).
    boundary : {"linear", "quadratic"}
        The boundary behaviour (`boundary_values`).

    Returns
    -------
    (N, 2) ndarray of float
        The image in Theta of every mesh vertex.
    """
    return DirichletSolver(mesh, weights).solve(theta, boundary)


class DirichletSolver:
    """The Dirichlet problem on one mesh, factorized once, for any boundary data.

    The Laplacian depends on the mesh and the weights only; Theta and the
    boundary behaviour enter through the right-hand side. So maps of one mesh
    onto many Thetas (the optimization of §5.1) cost one factorization and a
    back-substitution each.

    Parameters
    ----------
    mesh : TriMesh
    weights : {"cotan", "positive"}
    free_edges : (edges, edges)
        Natural boundary conditions (§5.2): for each coordinate, the polygon
        edges along which it is free (zero normal derivative) instead of
        prescribed; their nodes, but not the polygon's vertices, are then
        unknowns of that coordinate's system. Empty (the default): Dirichlet
        everywhere, one factorization for both coordinates.
    """

    def __init__(self, mesh: TriMesh, weights: str = "cotan", free_edges: tuple = ((), ())) -> None:
        if weights not in WEIGHTS:
            raise InputError(f"unknown weights {weights!r}; choose one of {', '.join(WEIGHTS)}")
        self.mesh = mesh
        self.weights = weights
        k = None
        parts = []
        groups = [((0, 1), tuple(free_edges[0]))] if tuple(free_edges[0]) == tuple(free_edges[1]) else [
            ((0,), tuple(free_edges[0])), ((1,), tuple(free_edges[1]))
        ]  # fmt: skip
        for coords, free in groups:
            fixed = np.zeros(mesh.n_vertices, dtype=bool)
            fixed[mesh.boundary] = True
            if free:
                sliding = (mesh.boundary_t > 0) & np.isin(mesh.boundary_edge, free)
                fixed[mesh.boundary[sliding]] = False
            unknown = np.flatnonzero(~fixed)
            known = mesh.boundary if not free else np.flatnonzero(fixed)
            if unknown.size == 0:
                parts.append((coords, unknown, known, None, None))
                continue
            if weights == "cotan" and not free:
                # The default system, built by `sparse` and factorized by SuperLU
                # without importing scipy.sparse (see `sparse`): the same bits.
                try:
                    parts.append((coords, unknown, known, *_cotan_system(mesh, unknown, known)))
                    continue
                except (sparse.Unsupported, NotManifold):
                    pass
            if k is None:
                k = cotan_laplacian(mesh.vertices, mesh.triangles) if weights == "cotan" else mean_value_laplacian(
                    mesh.vertices, mesh.triangles
                )  # fmt: skip
            k_u = k[unknown]
            parts.append((coords, unknown, known, _factorize(k_u[:, unknown].tocsc(), weights), k_u[:, known]))
        self._parts = parts

    def solve(self, theta: NDArray[np.float64], boundary: str = "linear") -> NDArray[np.float64]:
        """The image in Theta of every mesh vertex, (N, 2), for boundary data onto ``theta``."""
        theta = np.asarray(theta, dtype=np.float64)
        values = np.zeros((self.mesh.n_vertices, 2))
        values[self.mesh.boundary] = boundary_values(self.mesh, theta, boundary)
        for coords, unknown, known, lu, k_uk in self._parts:
            if lu is None:
                continue
            c = list(coords)
            rhs = -(k_uk @ (values[known] if len(c) == 2 else values[known][:, c]))
            values[np.ix_(unknown, c)] = lu.solve(np.ascontiguousarray(rhs)).reshape(len(unknown), len(c))
        return values


def _cotan_system(mesh: TriMesh, unknown: NDArray[np.intp], known: NDArray[np.intp]):
    """SuperLU of K_UU and the matrix K_UK, for the cotangent Laplacian, without scipy.sparse.

    Raises
    ------
    sparse.Unsupported, NotManifold
        When the scipy route must be taken instead.
    """
    k = sparse.cotan_stiffness(mesh.vertices, mesh.triangles, mesh.edges)
    return sparse.splu(sparse.submatrix(k, unknown, unknown), symmetric=True), sparse.submatrix(k, unknown, known)


def _factorize(k_uu, weights: str):
    """SuperLU of the system matrix.

    K_UU is an M-matrix (diagonally dominant, non-positive off-diagonal): a
    fill-reducing ordering of A^T + A without pivoting is exact and the fastest
    direct solve here; the cotangent matrix is also symmetric.
    """
    from scipy.sparse.linalg import splu

    return splu(k_uu, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": weights == "cotan"})
