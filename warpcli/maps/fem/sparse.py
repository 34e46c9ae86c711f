"""FEM sparse algebra without scipy.sparse: the Dirichlet system of the cotangent Laplacian, and SuperLU.

Importing scipy.sparse and scipy.sparse.linalg (which imports scipy.linalg)
costs about 0.25 s per process, half of a whole 1-megapixel warp now, for a
matrix assembly and one factorization. This module builds the same system with
numpy and compiled passes over the mesh's edges and rows (`_sparse_kernels`:
placements of values, no arithmetic but an edge's one addition) and hands it
to SuperLU, the C extension that ``scipy.sparse.linalg.splu`` calls, loaded on
its own. It reproduces scipy's arithmetic operation by
operation, so the matrix, the right-hand side and the solution are bit for bit
those of the scipy route in `warpcli.maps.fem.solve` (tested):

- the stiffness matrix as ``coo_matrix((x, (r, c))).tocsr()`` sums it: the
  entries of one (row, column) added in pairs, which is exact in any order
  because each mesh edge has at most two triangles (more refuses this route);
- the diagonal as ``-off.sum(axis=1)``: ``np.add.reduceat`` over each row's
  entries, the very call scipy makes;
- ``off + diags(d)``, which drops entries that are exactly zero;
- the rows and columns of the unknowns, and the product with the boundary
  values as scipy's ``csr_matvecs`` forms it, entry after entry from zero.

Anything else (mean-value weights, natural boundary conditions, a SuperLU that
cannot be loaded this way) goes through scipy.sparse as before.
"""

from __future__ import annotations

import threading
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..._extensions import scipy_extension
from ...simplicial import corners
from .mesh import triangle_areas
from .topology import Edges, kernels, mesh_edges


class Unsupported(Exception):
    """This system or this scipy is not for this route; use scipy.sparse."""


class CSR(NamedTuple):
    """A compressed sparse row matrix: row i holds ``data[indptr[i]:indptr[i+1]]`` at ``indices``."""

    indptr: NDArray[np.int64]
    indices: NDArray[np.int64]
    data: NDArray[np.float64]
    shape: tuple[int, int]

    def rows(self) -> NDArray[np.int64]:
        """The row of every stored entry."""
        return np.repeat(np.arange(self.shape[0]), np.diff(self.indptr))

    def __matmul__(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """``self @ x`` for a dense (N,) or (N, k) ``x``, summed as scipy's ``csr_matvecs``:
        each row starts from zero and adds ``a * x[j]`` entry after entry."""
        x = np.asarray(x, dtype=np.float64)
        vec = x.ndim == 1
        x2 = x.reshape(len(x), -1)
        out = np.zeros((self.shape[0], x2.shape[1]))
        rows = self.rows()
        position = np.arange(len(self.indices)) - self.indptr[rows]
        for p in range(int(position.max(initial=-1)) + 1):
            at = position == p  # at most one entry per row: a plain fancy-indexed add
            r = rows[at]
            out[r] = out[r] + self.data[at, None] * x2[self.indices[at]]
        return out.ravel() if vec else out


def _corner_weights(vertices: NDArray[np.float64], triangles: NDArray[np.integer]) -> list[NDArray[np.float64]]:
    """``-(cot a) / 2`` for the angle a at each corner k of every triangle: a list of three (M,) arrays."""
    tri = np.asarray(triangles)
    v = corners(vertices, tri)
    double_area = np.abs(2.0 * triangle_areas(vertices, tri))
    out = []
    for k in range(3):
        # The angle at corner k is opposite the edge (k + 1, k + 2).
        u = v[(k + 1) % 3] - v[k]
        w = v[(k + 2) % 3] - v[k]
        cot = np.einsum("ij,ij->i", u, w) / double_area
        out.append(-0.5 * cot)
    return out


def cotan_terms(
    vertices: NDArray[np.float64], triangles: NDArray[np.integer]
) -> tuple[NDArray[np.integer], NDArray[np.integer], NDArray[np.float64]]:
    """The cotangent Laplacian's off-diagonal terms, (rows, columns, values), one per triangle corner and side.

    ``-(cot a) / 2`` for the edge opposite each corner's angle a, at (i, j) and
    (j, i); the terms of an edge shared by two triangles add up to
    ``K[i, j] = -(cot a_ij + cot b_ij) / 2``.
    """
    tri = np.asarray(triangles)
    rows, cols, vals = [], [], []
    for k, weight in enumerate(_corner_weights(vertices, tri)):
        i, j = (k + 1) % 3, (k + 2) % 3
        rows += [tri[:, i], tri[:, j]]
        cols += [tri[:, j], tri[:, i]]
        vals += [weight, weight]
    return np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)


def cotan_stiffness(
    vertices: NDArray[np.float64], triangles: NDArray[np.integer], edges: Edges | None = None
) -> CSR:
    """The cotangent Laplacian of `warpcli.maps.fem.solve.cotan_laplacian`, as a `CSR`, bit for bit.

    Parameters
    ----------
    vertices : (N, 2) array of float
    triangles : (M, 3) array of int
    edges : Edges or None
        The mesh's `mesh_edges`, if already found.

    Raises
    ------
    warpcli.maps.fem.topology.NotManifold
        Without ``edges``: if some edge has more than two triangles (the terms'
        order would matter).
    """
    n = len(vertices)
    e = mesh_edges(triangles, n) if edges is None else _checked_edges(edges, n, 3 * len(triangles))
    # coo -> csr -> sum_duplicates: an edge's entries (i, j) and (j, i) both sum
    # its one or two corner terms; two terms add up alike in either order.
    weight = np.concatenate(_corner_weights(vertices, triangles))
    count = len(e.lo)
    # Each row: its entries below the diagonal (edges ending at it), then
    # those above (edges starting at it), columns ascending in both.
    indptr = np.empty(n + 1, dtype=np.int64)
    cols = np.empty(2 * count, dtype=np.int64)
    data = np.empty(2 * count)
    n_down = np.zeros(n, dtype=np.int64)
    kernels.laplacian_rows(
        n, count, *e, weight, n_down,
        np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64), indptr, cols, data,
    )  # fmt: skip
    # -off.sum(axis=1): scipy reduces each non-empty row with np.add.reduceat.
    diag = np.zeros(n)
    nonempty = np.flatnonzero(np.diff(indptr))
    if nonempty.size:
        diag[nonempty] = np.add.reduceat(data, indptr[nonempty])
    diag = -diag
    # off + diags(diag): the diagonal merged in after each row's entries below
    # it, and exact zeros dropped, as scipy's canonical sparse addition does (a
    # stored entry plus 0 is itself).
    out_indptr = np.empty(n + 1, dtype=np.int64)
    out_cols = np.empty(2 * count + n, dtype=np.int64)
    out_data = np.empty(2 * count + n)
    kept = kernels.with_diagonal(n, indptr, cols, data, n_down, diag, out_indptr, out_cols, out_data)
    return CSR(out_indptr, out_cols[:kept], out_data[:kept], (n, n))


def _checked_edges(edges: Edges, n: int, halves: int) -> Edges:
    """``edges`` as the compiled passes read them (int64, contiguous), if they can be the edges
    of a mesh of ``n`` vertices and ``halves`` half-edges; else ValueError (they index arrays
    of those sizes unchecked)."""
    lo, hi, first, second = (np.ascontiguousarray(a, dtype=np.int64) for a in edges)
    if not (lo.ndim == 1 and lo.shape == hi.shape == first.shape == second.shape):
        raise ValueError("edges: lo, hi, first and second must be 1-D arrays of one length")
    if lo.size and not (
        lo.min() >= 0 and hi.max() < n and (lo < hi).all() and first.min() >= 0 and first.max() < halves
        and second.min() >= -1 and second.max() < halves
    ):  # fmt: skip
        raise ValueError(f"edges: not those of a mesh of {n} vertices and {halves // 3} triangles")
    return Edges(lo, hi, first, second)


def submatrix(k: CSR, rows: NDArray[np.integer], cols: NDArray[np.integer]) -> CSR:
    """``k[rows][:, cols]`` for sorted, distinct ``rows`` and ``cols`` (scipy's fancy indexing keeps the values)."""
    n_rows, n_cols = k.shape
    rows = np.asarray(rows, dtype=np.int64)
    cols = np.asarray(cols, dtype=np.int64)
    for idx, size in ((rows, n_rows), (cols, n_cols)):
        if idx.size and (np.any(np.diff(idx) <= 0) or idx[0] < 0 or idx[-1] >= size):
            raise Unsupported("indices not sorted and distinct")
    k_indptr, k_indices = (np.ascontiguousarray(a, dtype=np.int64) for a in (k.indptr, k.indices))
    k_data = np.ascontiguousarray(k.data, dtype=np.float64)
    if not (
        k_indptr.shape == (n_rows + 1,) and k_indices.shape == k_data.shape and k_indptr[0] == 0
        and k_indptr[-1] == len(k_indices) and (np.diff(k_indptr) >= 0).all()
        and (not k_indices.size or (k_indices.min() >= 0 and k_indices.max() < n_cols))
    ):  # fmt: skip
        raise ValueError(f"not a CSR matrix of shape {k.shape}")  # the compiled pass indexes it unchecked
    new_col = np.full(n_cols, -1, dtype=np.int64)
    new_col[cols] = np.arange(len(cols))
    indptr = np.empty(len(rows) + 1, dtype=np.int64)
    most = int(np.diff(k_indptr)[rows].sum()) if rows.size else 0
    c = np.empty(most, dtype=np.int64)
    d = np.empty(most)
    kept = kernels.submatrix(np.ascontiguousarray(rows), k_indptr, k_indices, k_data, new_col, indptr, c, d)
    return CSR(indptr, c[:kept], d[:kept], (len(rows), len(cols)))


def to_csc(a: CSR) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """``(indptr, row indices, data)`` of ``a`` in compressed sparse columns, rows ascending in each column."""
    order = np.argsort(a.indices, kind="stable")
    indptr = np.zeros(a.shape[1] + 1, dtype=np.int64)
    np.cumsum(np.bincount(a.indices, minlength=a.shape[1]), out=indptr[1:])
    return indptr, a.rows()[order], a.data[order]


_SUPERLU: Any = None
_SUPERLU_LOCK = threading.Lock()
_SUPERLU_NAME = "scipy.sparse.linalg._dsolve._superlu"


def _superlu():
    """scipy's SuperLU extension module, loaded without importing scipy.sparse.linalg
    (`warpcli._extensions.scipy_extension`)."""
    global _SUPERLU
    with _SUPERLU_LOCK:
        if _SUPERLU is None:
            try:
                module = scipy_extension(_SUPERLU_NAME)
            except ImportError as err:
                raise Unsupported(str(err)) from err
            if not hasattr(module, "gstrf"):
                raise Unsupported("SuperLU extension without gstrf")
            _SUPERLU = module
        return _SUPERLU


def load_superlu() -> None:
    """Load SuperLU now if it can be (a forked child then finds it loaded)."""
    try:
        _superlu()
    except Unsupported:
        pass


def _csc_array(*args, **kwargs):
    """What SuperLU builds its L and U with, when asked for them (imports scipy.sparse then)."""
    from scipy.sparse import csc_array

    return csc_array(*args, **kwargs)


def splu(a: CSR, symmetric: bool = False):
    """SuperLU of ``a`` exactly as `warpcli.maps.fem.solve._factorize` makes it with ``splu``.

    The same call ``scipy.sparse.linalg.splu(A, permc_spec="MMD_AT_PLUS_A",
    diag_pivot_thresh=0.0, options={"SymmetricMode": symmetric})`` makes of
    the extension, with the matrix in compressed sparse columns. ``symmetric``
    also says that ``a`` is exactly symmetric (the cotangent Laplacian is, term
    by term: both entries of an edge add the same two values), so that its rows
    serve as its columns.

    Raises
    ------
    Unsupported
        If the extension cannot be loaded or called this way.
    """
    module = _superlu()
    # A symmetric matrix's compressed columns are its compressed rows.
    indptr, indices, data = (a.indptr, a.indices, a.data) if symmetric else to_csc(a)
    n = a.shape[0]
    if a.shape[1] != n or len(data) > np.iinfo(np.intc).max:
        raise Unsupported("not a square matrix with int32 indices")
    options = {"DiagPivotThresh": 0.0, "ColPerm": "MMD_AT_PLUS_A", "PanelSize": None, "Relax": None}
    options["SymmetricMode"] = symmetric
    try:
        return module.gstrf(
            n, len(data), np.ascontiguousarray(data, dtype=np.float64), indices.astype(np.intc),
            indptr.astype(np.intc), csc_construct_func=_csc_array, ilu=False, options=options,
        )  # fmt: skip
    except TypeError as err:  # another scipy's calling convention
        raise Unsupported(f"SuperLU: {err}") from err
