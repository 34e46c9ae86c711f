"""Compiled (numba) assembly of the FEM system: a mesh's edges, the Laplacian's rows, submatrices.

Integer work and placement of values, and one addition of an edge's two corner
terms (exact in either order): the matrices `warpcli.maps.fem.sparse` makes with
these are those its numpy passes made, entry for entry, bit for bit
scipy.sparse's (tests/test_fem_sparse.py); the edges are those numpy's sort of
the half-edges found, an edge's two half-edges now always in increasing order
(numpy's unstable sort gave either; every reader is symmetric in them). Called
through `warpcli._native.Kernels` like every kernel of warpcli; they allocate
nothing (the callers pass every array). `mesh_edges` checks every vertex index
it reads; the others index arrays by the edges and rows they are given, which
their callers check first (`warpcli.maps.fem.sparse`).
"""

from __future__ import annotations

from ..._jit import njit


@njit(cache=True, nogil=True)
def mesh_edges(tri, n, start, slot, upper, lo, hi, first, second):
    """The edges of a triangle mesh, sorted by (lo, hi), each with its one or two half-edges.

    Half-edge ``h = k * M + t`` is the side of triangle ``t`` opposite its
    corner ``k``, from corner ``(k + 1) % 3`` to corner ``(k + 2) % 3``.
    Writes edge ``e``'s vertices ``lo[e] < hi[e]``, its half-edges ``first[e]
    < second[e]`` (``second[e] = -1``: a boundary edge); ``start`` (n + 1
    zeros), ``slot`` and ``upper`` (3M each) are scratch.

    Returns
    -------
    int
        The number of edges; -1 if a triangle repeats a vertex, -2 if an edge
        has more than two triangles, -3 if a vertex index is not below ``n``.
    """
    m = tri.shape[0]
    for k in range(3):
        for t in range(m):
            a = tri[t, (k + 1) % 3]
            b = tri[t, (k + 2) % 3]
            if a < 0 or b < 0 or a >= n or b >= n:
                return -3
            if a == b:
                return -1
            start[min(a, b) + 1] += 1
    for v in range(n):
        start[v + 1] += start[v]
    # Half-edges by their lower vertex, in increasing h (a counting sort: stable), each with its
    # upper vertex; ``start[v]`` is vertex v's next free place meanwhile, then v + 1's first.
    for k in range(3):
        for t in range(m):
            a = tri[t, (k + 1) % 3]
            b = tri[t, (k + 2) % 3]
            v = min(a, b)
            at = start[v]
            slot[at] = k * m + t
            upper[at] = max(a, b)
            start[v] = at + 1
    count = 0
    s0 = 0
    for v in range(n):
        s1 = start[v]
        # A vertex's few half-edges by their upper vertex (insertion sort: stable, so h ascends
        # too; quadratic in a vertex's degree, which a quality mesh keeps small).
        for i in range(s0 + 1, s1):
            h = slot[i]
            key = upper[i]
            j = i - 1
            while j >= s0 and upper[j] > key:
                slot[j + 1] = slot[j]
                upper[j + 1] = upper[j]
                j -= 1
            slot[j + 1] = h
            upper[j + 1] = key
        i = s0
        while i < s1:
            w = upper[i]
            run = 1
            while i + run < s1 and upper[i + run] == w:
                run += 1
            if run > 2:
                return -2
            lo[count] = v
            hi[count] = w
            first[count] = slot[i]
            second[count] = slot[i + 1] if run == 2 else -1
            count += 1
            i += run
        s0 = s1
    return count


@njit(cache=True, nogil=True)
def laplacian_rows(n, count, lo, hi, first, second, weight, n_down, fill_down, fill_up, indptr, cols, data):
    """The off-diagonal entries of the cotangent Laplacian, row by row: edge ``e`` (of the first
    ``count``, sorted by (lo, hi)) gives ``weight[first[e]] + weight[second[e]]`` (its one term on
    the boundary) at (lo, hi) and (hi, lo). Each row holds its entries below the diagonal, then
    those above, columns ascending in both; writes ``indptr`` (n + 1), ``cols`` and ``data`` (2 *
    count each) and ``n_down`` (per row, its entries below the diagonal); ``fill_down`` and
    ``fill_up`` (n zeros each) are scratch."""
    for e in range(count):
        n_down[hi[e]] += 1
        fill_up[lo[e]] += 1
    indptr[0] = 0
    for v in range(n):
        indptr[v + 1] = indptr[v] + n_down[v] + fill_up[v]
        fill_up[v] = indptr[v] + n_down[v]
        fill_down[v] = indptr[v]
    # Edges come by ascending lo: each row's entries below the diagonal arrive in column order,
    # and (hi ascending within one lo) so do those above.
    for e in range(count):
        value = weight[first[e]]
        if second[e] >= 0:
            value = value + weight[second[e]]
        a = lo[e]
        b = hi[e]
        at = fill_up[a]
        cols[at] = b
        data[at] = value
        fill_up[a] = at + 1
        at = fill_down[b]
        cols[at] = a
        data[at] = value
        fill_down[b] = at + 1


@njit(cache=True, nogil=True)
def with_diagonal(n, indptr, cols, data, n_down, diag, out_indptr, out_cols, out_data):
    """Rows of ``(indptr, cols, data)`` with ``diag[i]`` placed after row i's ``n_down[i]``
    entries below the diagonal, every exact zero left out (as scipy's canonical sum of the
    off-diagonal matrix and a diagonal one drops them). Returns the entries written."""
    at = 0
    out_indptr[0] = 0
    for i in range(n):
        split = indptr[i] + n_down[i]
        for k in range(indptr[i], split):
            if data[k] != 0:
                out_cols[at] = cols[k]
                out_data[at] = data[k]
                at += 1
        if diag[i] != 0:
            out_cols[at] = i
            out_data[at] = diag[i]
            at += 1
        for k in range(split, indptr[i + 1]):
            if data[k] != 0:
                out_cols[at] = cols[k]
                out_data[at] = data[k]
                at += 1
        out_indptr[i + 1] = at
    return at


@njit(cache=True, nogil=True)
def submatrix(rows, indptr, indices, data, new_col, out_indptr, out_cols, out_data):
    """Rows ``rows`` (ascending) of a CSR matrix, their entries in columns with ``new_col >= 0``,
    renumbered: what fancy indexing ``k[rows][:, cols]`` keeps. Returns the entries written."""
    at = 0
    out_indptr[0] = 0
    for r in range(rows.shape[0]):
        i = rows[r]
        for k in range(indptr[i], indptr[i + 1]):
            c = new_col[indices[k]]
            if c >= 0:
                out_cols[at] = c
                out_data[at] = data[k]
                at += 1
        out_indptr[r + 1] = at
    return at
