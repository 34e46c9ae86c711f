"""FEM in 3D: the P1 (cotangent) Laplacian of a tetrahedral mesh and the Dirichlet solve for a harmonic map onto Theta (§5.3)."""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from ..errors import MeshingError
from .tetmesh import TetMesh

#: Relative residual at which the iterative solve stops. The map's values
#: are then correct to about this times Theta's size: far below a voxel.
SOLVE_TOL = 1e-10

#: Solvers by name (see `solve_dirichlet`).
SOLVERS = ("amg", "direct", "jacobi")

#: Below this many unknowns the direct solve is the fastest (measured in bench/volume.py).
DIRECT_BELOW = 4000


def gradients(vertices: NDArray[np.float64], tets: NDArray[np.integer]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Gradients of the four barycentric (hat) functions of each tetrahedron, and the volumes.

    Returns
    -------
    grads : (M, 4, 3) ndarray of float
    volumes : (M,) ndarray of float
        Signed (positive for positively oriented tetrahedra).
    """
    a = vertices[tets[:, 0]]
    e = np.stack([vertices[tets[:, k]] - a for k in (1, 2, 3)], axis=1)  # rows: edges from vertex 0
    det = np.linalg.det(e)
    inv = np.linalg.inv(e)  # columns: gradients of lambda_1..3
    g = np.empty((len(tets), 4, 3))
    g[:, 1:, :] = np.transpose(inv, (0, 2, 1))
    g[:, 0, :] = -g[:, 1:, :].sum(axis=1)
    return g, det / 6.0


def laplacian(vertices: NDArray[np.float64], tets: NDArray[np.integer]) -> sp.csr_matrix:
    """The P1 stiffness matrix of a tetrahedral mesh: the 3D cotangent Laplacian.

    ``K[i, j] = sum over tetrahedra T of vol(T) grad(l_i) . grad(l_j)``, which
    is ``-(1/6) sum l_kl cot(theta_kl)`` over the tetrahedra around edge ij
    (l_kl the length of the opposite edge and theta_kl its dihedral angle).
    Symmetric, positive semi-definite, zero row sums.

    Parameters
    ----------
    vertices : (N, 3) array of float
    tets : (M, 4) array of int

    Returns
    -------
    (N, N) scipy.sparse.csr_matrix
    """
    n = len(vertices)
    g, vol = gradients(vertices, tets)
    local = np.einsum("mid,mjd->mij", g, g) * np.abs(vol)[:, None, None]
    rows = np.repeat(tets[:, :, None], 4, axis=2).ravel()
    cols = np.repeat(tets[:, None, :], 4, axis=1).ravel()
    k = sp.coo_matrix((local.ravel(), (rows, cols)), shape=(n, n)).tocsr()
    k.sum_duplicates()
    return k


def solve_dirichlet(
    mesh: TetMesh, boundary_values: NDArray[np.float64], solver: str = "auto", start: NDArray[np.float64] | None = None
) -> tuple[NDArray[np.float64], dict]:
    """The discrete harmonic map: values at every node, given at the boundary nodes.

    Solves ``K_II x_I = -K_IB x_B`` for the three coordinates.

    Parameters
    ----------
    mesh : TetMesh
    boundary_values : (B, 3) ndarray of float
        At ``mesh.boundary``.
    solver : {"auto", "amg", "direct", "jacobi"}
        ``"jacobi"``: conjugate gradients with a diagonal preconditioner,
        the default from `DIRECT_BELOW` unknowns on (about 130 iterations
        on the default meshes, whose quality bounds keep the condition
        number low: 0.9 s for 18k unknowns, 2.3 s for 52k, against 2.1 s
        and 6.2 s with AMG, whose setup dominates, and 3.1 s and 7.7 s
        direct); ``"amg"``: conjugate gradients preconditioned by
        smoothed-aggregation algebraic multigrid (needs pyamg; fewer
        iterations, 13-16, for much larger meshes); ``"direct"``: a sparse
        LU factorization (SuperLU), fastest for small meshes, costly in
        memory for large ones (3D fill-in).

    Returns
    -------
    values : (N, 3) ndarray of float
    info : dict
        ``solver``, ``unknowns`` and ``iterations`` (the largest over the
        coordinates; 0 for the direct solve).

    Raises
    ------
    MeshingError
        If the iterative solve does not converge.
    """
    n = mesh.n_vertices
    k = laplacian(mesh.vertices, mesh.tets)
    is_free = np.ones(n, dtype=bool)
    is_free[mesh.boundary] = False
    free = np.flatnonzero(is_free)
    values = np.empty((n, 3))
    values[mesh.boundary] = boundary_values
    info = {"unknowns": int(len(free)), "iterations": 0}
    if len(free) == 0:
        info["solver"] = "none"
        return values, info
    k_ff = k[free][:, free].tocsr()
    rhs = -(k[free][:, mesh.boundary] @ boundary_values)
    if solver == "auto":
        solver = "direct" if len(free) < DIRECT_BELOW else "jacobi"
    info["solver"] = solver
    if solver == "direct":
        import scipy.sparse.linalg as spla

        lu = spla.splu(k_ff.tocsc())
        values[free] = lu.solve(np.ascontiguousarray(rhs))
        return values, info
    if solver == "amg":
        precondition = _amg_preconditioner(k_ff)
    elif solver == "jacobi":
        d = 1.0 / k_ff.diagonal()

        def precondition(r):
            return d * r
    else:
        raise ValueError(f"unknown solver {solver!r}; use one of {SOLVERS}")
    # Start from the mean of the boundary values (a harmonic map stays inside Theta's hull).
    for c in range(3):
        x0 = np.full(len(free), float(boundary_values[:, c].mean())) if start is None else start[free, c].copy()
        x, its = _pcg(k_ff, rhs[:, c], x0, precondition, SOLVE_TOL)
        if its < 0:
            raise MeshingError(f"the {solver} solve did not converge in {-its} iterations")
        info["iterations"] = max(info["iterations"], its)
        values[free, c] = x
    return values, info


def _has_pyamg() -> bool:
    try:
        import pyamg  # noqa: F401
    except ImportError:
        return False
    return True


def _amg_preconditioner(a: sp.csr_matrix):
    """One V-cycle of smoothed aggregation, built without random numbers.

    pyamg estimates spectral radii from a random start vector by default;
    the 'local' weighting of the prolongation smoother needs none, so the
    hierarchy (and the map's bytes) are the same on every run.
    """
    import pyamg

    ml = pyamg.smoothed_aggregation_solver(
        a, symmetry="symmetric", smooth=("jacobi", {"weighting": "local"}), max_coarse=500,
        presmoother=("gauss_seidel", {"sweep": "symmetric"}), postsmoother=("gauss_seidel", {"sweep": "symmetric"}),
        coarse_solver="splu",
    )  # fmt: skip
    m = ml.aspreconditioner(cycle="V")
    return lambda r: m @ r


def _pcg(a: sp.csr_matrix, b, x0, precondition, tol: float, maxiter: int | None = None):
    """Preconditioned conjugate gradients with serial reductions (the same bits whatever the threads).

    Returns (x, iterations), iterations negative when it did not converge.
    """
    from ._kernels import dot

    maxiter = maxiter or max(1000, 10 * int(math.sqrt(a.shape[0])) + 1000)
    x = x0.copy()
    r = b - a @ x
    norm_b = math.sqrt(dot(b, b)) or 1.0
    z = precondition(r)
    p = z.copy()
    rz = dot(r, z)
    for it in range(1, maxiter + 1):
        ap = a @ p
        alpha = rz / dot(p, ap)
        x += alpha * p
        r -= alpha * ap
        if math.sqrt(dot(r, r)) <= tol * norm_b:
            return x, it
        z = precondition(r)
        rz_new = dot(r, z)
        p *= rz_new / rz
        p += z
        rz = rz_new
    return x, -maxiter
