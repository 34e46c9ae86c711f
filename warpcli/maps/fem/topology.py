"""FEM mesh topology: a triangle mesh's edges, the half-edges on them, and the triangles across them.

Found once per mesh (`warpcli.maps.fem.mesh.TriMesh.edges`) and read by the
Laplacian's assembly (`warpcli.maps.fem.sparse`) and by point location (the
neighbour table); it knows nothing of either.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray


class NotManifold(Exception):
    """A mesh with an edge of more than two triangles, or a triangle with a repeated vertex.

    Meshes made here never are; a `TriMesh` built by hand can be, and then the
    callers take the routes that need no `Edges` (scipy.sparse, `triangle_neighbours`).
    """


class Edges(NamedTuple):
    """The edges of a triangle mesh, each with the one or two half-edges on it.

    Half-edge ``h = k * M + t`` is the side of triangle t opposite its corner
    k. Edges are sorted by (lo, hi), their vertices lo < hi; ``second`` is -1
    on the boundary.
    """

    lo: NDArray[np.int64]
    hi: NDArray[np.int64]
    first: NDArray[np.int64]
    second: NDArray[np.int64]


def mesh_edges(triangles: NDArray[np.integer], n_vertices: int) -> Edges:
    """The `Edges` of a mesh: one sort of its half-edges.

    Raises
    ------
    NotManifold
        If an edge has more than two triangles, or a triangle a repeated vertex.
    """
    tri = np.asarray(triangles, dtype=np.int64)
    a = np.concatenate([tri[:, 1], tri[:, 2], tri[:, 0]])
    b = np.concatenate([tri[:, 2], tri[:, 0], tri[:, 1]])
    if (a == b).any():
        raise NotManifold("a triangle with a repeated vertex")
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * n_vertices + hi
    order = np.argsort(key)
    key = key[order]
    head = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    runs = np.diff(np.r_[head, len(key)])
    if runs.size and runs.max() > 2:
        raise NotManifold("an edge with more than two triangles")
    second = np.full(len(head), -1, dtype=np.int64)
    pair = runs == 2
    second[pair] = order[head[pair] + 1]
    first = order[head]
    return Edges(lo[first], hi[first], first, second)


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
