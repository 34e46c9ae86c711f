"""FEM mesh topology: a triangle mesh's edges, the half-edges on them, and the triangles across them.

Found once per mesh (`warpcli.maps.fem.mesh.TriMesh.edges`) and read by the
Laplacian's assembly (`warpcli.maps.fem.sparse`) and by point location (the
neighbour table); it knows nothing of either.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..._native import Kernels

#: The compiled passes of the mesh's edges and of the Laplacian's rows (`warpcli.maps.fem.sparse` calls them too).
kernels = Kernels("warpcli.maps.fem._sparse_kernels")


class NotManifold(Exception):
    """A mesh with an edge of more than two triangles, or a triangle with a repeated vertex.

    Meshes made here never are; a `TriMesh` built by hand can be, and then the
    callers take the routes that need no `Edges` (scipy.sparse, `triangle_neighbours`).
    """


class Edges(NamedTuple):
    """The edges of a triangle mesh, each with the one or two half-edges on it.

    Half-edge ``h = k * M + t`` is the side of triangle t opposite its corner
    k. Edges are sorted by (lo, hi), their vertices lo < hi, their half-edges
    first < second; ``second`` is -1 on the boundary.
    """

    lo: NDArray[np.int64]
    hi: NDArray[np.int64]
    first: NDArray[np.int64]
    second: NDArray[np.int64]


def mesh_edges(triangles: NDArray[np.integer], n_vertices: int) -> Edges:
    """The `Edges` of a mesh: its half-edges sorted by vertex, in one compiled pass
    (`warpcli.maps.fem._sparse_kernels.mesh_edges`: 0.4 ms for the 37k triangles of a
    1 MP map, against 2.8 ms for numpy's sort of them).

    Raises
    ------
    NotManifold
        If an edge has more than two triangles, or a triangle a repeated vertex.
    ValueError
        If ``triangles`` is not (M, 3), or a triangle names a vertex that is
        not one of the ``n_vertices``.
    """
    tri = np.ascontiguousarray(triangles, dtype=np.int64)
    if tri.size == 0:
        tri = tri.reshape(0, 3)
    if tri.ndim != 2 or tri.shape[1] != 3:
        raise ValueError(f"triangles must be an (M, 3) array, got shape {tri.shape}")
    n = int(n_vertices)
    halves = 3 * len(tri)
    lo, hi, first, second = (np.empty(halves, dtype=np.int64) for _ in range(4))
    count = kernels.mesh_edges(
        tri, n, np.zeros(n + 1, dtype=np.int64), np.empty(halves, dtype=np.int64), np.empty(halves, dtype=np.int64),
        lo, hi, first, second,
    )  # fmt: skip
    if count == -1:
        raise NotManifold("a triangle with a repeated vertex")
    if count == -2:
        raise NotManifold("an edge with more than two triangles")
    if count < 0:
        raise ValueError(f"a triangle names a vertex outside the mesh's {n}")
    return Edges(lo[:count], hi[:count], first[:count], second[:count])


def neighbours(edges: Edges, n_triangles: int) -> NDArray[np.int64]:
    """For each triangle and corner k, the triangle across the side opposite k (-1 on the boundary).

    The same table as `warpcli.maps.fem.locate.triangle_neighbours`, from edges already found.
    """
    out = np.full(3 * n_triangles, -1, dtype=np.int64)
    inner = edges.second >= 0
    h1, h2 = edges.first[inner], edges.second[inner]
    out[h1] = h2 % n_triangles
    out[h2] = h1 % n_triangles
    return out.reshape(3, n_triangles).T.copy()
