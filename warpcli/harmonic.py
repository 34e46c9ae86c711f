"""Harmonic stage: cotangent Laplacian and the Dirichlet solve for a map onto Theta."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from .mesh import TriMesh, triangle_areas


@dataclass(frozen=True)
class HarmonicMap:
    """A discrete (piecewise-linear) harmonic map of a mesh onto Theta.

    Attributes
    ----------
    mesh : TriMesh
    values : (N, 2) ndarray of float
        Image in Theta of every mesh vertex.
    theta : (n, 2) ndarray of float
        The convex polygon the map goes onto.
    """

    mesh: TriMesh
    values: NDArray[np.float64]
    theta: NDArray[np.float64]

    def __post_init__(self) -> None:
        if self.values.shape != self.mesh.vertices.shape:
            raise ValueError(
                f"values has shape {self.values.shape} but the mesh has {self.mesh.vertices.shape}"
            )

    def flipped(self) -> NDArray[np.bool_]:
        """Per triangle: whether its image is degenerate or has the wrong orientation.

        A polygon oriented against Theta gives a mirror image, which is not
        counted as flipped.
        """
        return flipped_triangles(self.mesh, self.values, self.theta)


def flipped_triangles(
    mesh: TriMesh, values: NDArray[np.float64], theta: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """Triangles whose image under a map onto ``theta`` is flipped or degenerate.

    Mesh triangles are oriented like their polygon, and the boundary goes onto
    Theta's boundary in vertex order, so a one-to-one map gives every image
    triangle Theta's orientation, whichever way the polygon runs.
    """
    img = triangle_areas(values, mesh.triangles)
    return img * np.sign(_shoelace(theta)) <= 0


def _shoelace(p: NDArray[np.float64]) -> float:
    return 0.5 * float(np.dot(p[:, 0], np.roll(p[:, 1], -1)) - np.dot(np.roll(p[:, 0], -1), p[:, 1]))


def cotan_laplacian(vertices: NDArray[np.float64], triangles: NDArray[np.integer]) -> sp.csr_matrix:
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
    """
    n = len(vertices)
    tri = np.asarray(triangles)
    v = [vertices[tri[:, k]] for k in range(3)]
    rows = []
    cols = []
    vals = []
    double_area = np.abs(2.0 * triangle_areas(vertices, tri))
    for k in range(3):
        # The angle at corner k is opposite the edge (i, j).
        i, j = (k + 1) % 3, (k + 2) % 3
        u = v[i] - v[k]
        w = v[j] - v[k]
        cot = np.einsum("ij,ij->i", u, w) / double_area
        rows += [tri[:, i], tri[:, j]]
        cols += [tri[:, j], tri[:, i]]
        vals += [-0.5 * cot, -0.5 * cot]
    r = np.concatenate(rows)
    c = np.concatenate(cols)
    x = np.concatenate(vals)
    off = sp.coo_matrix((x, (r, c)), shape=(n, n)).tocsr()
    off.sum_duplicates()
    diag = -np.asarray(off.sum(axis=1)).ravel()
    return (off + sp.diags(diag)).tocsr()


def boundary_values(mesh: TriMesh, theta: NDArray[np.float64]) -> NDArray[np.float64]:
    """Piecewise-linear Dirichlet data: a node at parameter t on edge i goes to
    ``(1 - t) w_i + t w_{i+1}`` (Section 2, linear boundary behaviour)."""
    n = len(theta)
    e = mesh.boundary_edge
    t = mesh.boundary_t[:, None]
    return (1.0 - t) * theta[e] + t * theta[(e + 1) % n]


def solve_harmonic(mesh: TriMesh, theta: NDArray[np.float64]) -> HarmonicMap:
    """Solve the discrete Dirichlet problem for both coordinates (Section 3.1.1).

    Parameters
    ----------
    mesh : TriMesh
    theta : (n, 2) array of float
        Convex polygon with as many vertices as the meshed polygon.

    Returns
    -------
    HarmonicMap
    """
    from scipy.sparse.linalg import splu

    theta = np.asarray(theta, dtype=np.float64)
    nv = mesh.n_vertices
    values = np.zeros((nv, 2))
    values[mesh.boundary] = boundary_values(mesh, theta)
    is_b = np.zeros(nv, dtype=bool)
    is_b[mesh.boundary] = True
    interior = np.flatnonzero(~is_b)
    if interior.size:
        k = cotan_laplacian(mesh.vertices, mesh.triangles)
        k_ii = k[interior][:, interior].tocsc()
        rhs = -(k[interior][:, mesh.boundary] @ values[mesh.boundary])
        # K_II is a symmetric M-matrix: symmetric mode with a fill-reducing
        # ordering of A^T + A and no pivoting is both exact and the fastest
        # direct solve here (see bench/).
        lu = splu(
            k_ii,
            permc_spec="MMD_AT_PLUS_A",
            diag_pivot_thresh=0.0,
            options={"SymmetricMode": True},
        )
        values[interior] = lu.solve(np.ascontiguousarray(rhs))
    return HarmonicMap(mesh, values, theta)
