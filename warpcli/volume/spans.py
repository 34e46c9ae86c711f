"""Interior edges and faces whose image would lie in Theta's boundary: found and split before the solve.

A tetrahedral mesh may join boundary nodes by an interior edge (or three of
them by an interior face) whose images lie on one flat face of Theta: where
the cage bends and Theta does not, as a cage's faces bent convexly onto one
face of a box, or a bent cage edge onto one edge of Theta. The
piecewise-linear map then sends interior points of the solid into Theta's
boundary, and the tetrahedra around such an edge cannot all keep their
orientation (their images lie on one side of the face, but must turn a full
circle round the edge): some are flat or inverted whatever the free nodes
do, so the map is not one-to-one there. Splitting each such edge at its
midpoint (each such face at its centroid) makes a free node of it, which
the solve places inside Theta. Every tetrahedron round the simplex is split
with it, so the mesh stays conforming, and no new edge or face joins
boundary nodes alone.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..polygon.predicates import orient3d_sign
from .tetmesh import TetMesh, tet_volumes

#: The six edges of a tetrahedron, as pairs of its corners.
_EDGES = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))

#: Points of Theta this close to a plane (relative to its size and distance
#: from the origin) lie on it: the boundary nodes' images are barycentric
#: combinations of Theta's vertices, exact up to rounding.
ON_PLANE = 1e-9


def face_planes(vertices: NDArray[np.float64], triangles: NDArray[np.int64]) -> NDArray[np.int64]:
    """Theta's flat faces: for each triangle, the id of the edge-connected coplanar patch it belongs to."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    tol = _tolerance(vertices)
    n, d = _planes(vertices, triangles)
    sides = np.stack([triangles, np.roll(triangles, -1, axis=1)], axis=2).reshape(-1, 2)
    key = np.sort(sides, axis=1)
    order = np.lexsort((key[:, 1], key[:, 0]))
    k = key[order]
    same = np.flatnonzero((k[1:] == k[:-1]).all(axis=1))
    i, j = order[same] // 3, order[same + 1] // 3
    # Triangle j's corners on triangle i's plane and the other way round.
    flat = np.ones(len(i), dtype=bool)
    for a, b in ((i, j), (j, i)):
        off = np.einsum("mkd,md->mk", vertices[triangles[b]], n[a]) - d[a][:, None]
        flat &= (np.abs(off) <= tol).all(axis=1)
    graph = coo_matrix((np.ones(int(flat.sum())), (i[flat], j[flat])), shape=(len(triangles),) * 2)
    return connected_components(graph, directed=False)[1].astype(np.int64)


def node_planes(
    mesh: TetMesh, vertices: NDArray[np.float64], triangles: NDArray[np.int64]
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Which flat faces of Theta (`face_planes`) each boundary node's image lies on.

    A node lies on its own triangle's face, and on a neighbour's where it is
    on their common edge or vertex: every face of a triangle sharing a vertex
    with its own is tried.

    Returns
    -------
    nodes, planes : (K,) ndarray of int64
        Pairs (mesh node, plane id), sorted by node then plane.
    """
    groups = face_planes(vertices, triangles)
    n, d = _planes(vertices, triangles)
    tol = _tolerance(vertices)
    # Each cage vertex's faces (unique), as a CSR list.
    vt = np.unique(np.column_stack([triangles.ravel(), np.repeat(groups, 3)]), axis=0)
    start = np.searchsorted(vt[:, 0], np.arange(len(vertices) + 1))
    corners = triangles[mesh.boundary_triangle]  # (B, 3)
    lo, hi = start[corners], start[corners + 1]
    counts = (hi - lo).ravel()
    which = np.repeat(np.arange(corners.size), counts)
    offset = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    cand_node = np.repeat(np.arange(len(mesh.boundary)), 3)[which]
    cand_plane = vt[lo.ravel()[which] + offset, 1]
    # The representative triangle of each plane: the first of its group.
    first = np.full(int(groups.max()) + 1, -1, dtype=np.int64)
    first[groups[::-1]] = np.arange(len(groups))[::-1]
    y = mesh.boundary_values(vertices, triangles)
    rep = first[cand_plane]
    on = np.abs(np.einsum("kd,kd->k", y[cand_node], n[rep]) - d[rep]) <= tol
    pairs = np.unique(np.column_stack([mesh.boundary[cand_node[on]], cand_plane[on]]), axis=0)
    return pairs[:, 0], pairs[:, 1]


def flat_spans(mesh: TetMesh, nodes: NDArray[np.int64], planes: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Interior edges (E, 2) and interior faces (F, 3) whose nodes all lie on one flat face of Theta.

    ``nodes``, ``planes``: `node_planes`' pairs. An edge or face is interior
    when it is not on the mesh's boundary surface.
    """
    tets = mesh.tets
    on_boundary = mesh.on_boundary
    keys = np.unique(nodes * (int(planes.max(initial=0)) + 1) + planes)
    width = int(planes.max(initial=0)) + 1
    start = np.searchsorted(nodes, np.arange(mesh.n_vertices + 1))

    def shared(simplices: NDArray[np.int64]) -> NDArray[np.bool_]:
        """Whether the first node's planes include one every other node is on too."""
        a = simplices[:, 0]
        counts = start[a + 1] - start[a]
        which = np.repeat(np.arange(len(simplices)), counts)
        offset = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
        plane = planes[start[a][which] + offset]
        ok = np.ones(len(which), dtype=bool)
        for k in range(1, simplices.shape[1]):
            key = simplices[which, k] * width + plane
            ok &= np.isin(key, keys)
        out = np.zeros(len(simplices), dtype=bool)
        out[which[ok]] = True
        return out

    surface, tris = _skin(mesh, on_boundary)
    surface_edges = _edges_of(surface)
    pairs = np.concatenate([tets[:, [i, j]] for i, j in _EDGES])
    edges = _unique_rows(np.sort(pairs[on_boundary[pairs].all(axis=1)], axis=1), mesh.n_vertices)
    if len(edges):
        code = edges[:, 0] * mesh.n_vertices + edges[:, 1]
        edges = edges[~np.isin(code, surface_edges[:, 0] * mesh.n_vertices + surface_edges[:, 1])]
        edges = edges[shared(edges)]
    if len(tris):
        tris = tris[shared(tris)]
    return edges.astype(np.int64), tris.astype(np.int64)


def split_simplices(mesh: TetMesh, simplices: list[NDArray[np.int64]], applied: list[bool] | None = None) -> TetMesh:
    """Split each interior simplex (an edge or face, in order) at its barycentre, with every tetrahedron round it.

    A tetrahedron containing the simplex becomes one tetrahedron per node of
    the simplex, the node replaced by the new one; the pieces keep the
    orientation (the new node lies in the simplex), checked exactly: a split
    whose rounded barycentre would leave a piece flat (a sliver) is left out
    (``applied``, if given, is extended with whether each simplex was split).
    The new nodes are interior nodes, numbered after the mesh's, in the order
    of the simplices split; the boundary is unchanged.
    """
    if not simplices:
        return mesh
    tets = mesh.tets
    m = len(tets)
    involved = np.unique(np.concatenate([np.asarray(s).ravel() for s in simplices]))
    rows, cols = np.nonzero(np.isin(tets, involved))
    incident: dict[int, set[int]] = {int(v): set() for v in involved}
    for r, c in zip(rows.tolist(), tets[rows, cols].tolist()):
        incident[c].add(r)
    changed: dict[int, list[int]] = {}
    added: list[list[int]] = []
    points = []
    n = mesh.n_vertices

    def row(t: int) -> list[int]:
        return added[t - m] if t >= m else changed.get(t) or tets[t].tolist()

    def vertex(i: int) -> NDArray[np.float64]:
        return mesh.vertices[i] if i < n else points[i - n]

    for s in simplices:
        s = [int(x) for x in s]
        new = n + len(points)
        point = mesh.vertices[s].mean(axis=0)
        around = sorted(set.intersection(*(incident[x] for x in s)))
        # Each piece keeps the orientation in exact arithmetic; the barycentre is rounded, and on a
        # sliver a piece can come out flat or inverted (a singular element). Such a split is left out.
        # One piece per node of the simplex for each tetrahedron round it, that node replaced.
        split = [[[new if x == v else x for x in row(t)] for v in s] for t in around]
        corners = [np.array([point if x == new else vertex(x) for x in piece]) for pieces in split for piece in pieces]
        if corners:
            stack = np.stack(corners)
            if not (orient3d_sign(stack[:, 0], stack[:, 1], stack[:, 2], stack[:, 3]) > 0).all():
                if applied is not None:
                    applied.append(False)
                continue
        if applied is not None:
            applied.append(True)
        points.append(point)
        for t, pieces in zip(around, split):
            if t >= m:
                added[t - m] = pieces[0]
            else:
                changed[t] = pieces[0]
            incident[s[0]].discard(t)
            for v, piece in zip(s[1:], pieces[1:]):
                added.append(piece)
                for x in piece:
                    if x in incident and x != v:
                        incident[x].add(m + len(added) - 1)
    out = tets.copy()
    for t, r in changed.items():
        out[t] = r
    out = np.concatenate([out, np.array(added, dtype=np.int64).reshape(-1, 4)])
    return TetMesh(
        np.concatenate([mesh.vertices, np.array(points, dtype=np.float64).reshape(-1, 3)]), out, mesh.boundary,
        mesh.boundary_triangle, mesh.boundary_bary,
    )


def repair_edges(mesh: TetMesh, bad: NDArray[np.bool_]) -> NDArray[np.int64]:
    """An edge to split for each tetrahedron in ``bad`` (one untangling could not mend), (E, 2) unique.

    The longest of its interior edges that join two boundary nodes: the new
    free node gives the tetrahedron room that its fixed nodes deny it; else
    its longest interior edge, whose new node gives its free neighbours more
    room. A tetrahedron with no interior edge gives none.
    """
    tets = mesh.tets[bad]
    if not len(tets):
        return np.zeros((0, 2), dtype=np.int64)
    on_boundary = mesh.on_boundary
    n = mesh.n_vertices
    surface = _edges_of(_skin(mesh, on_boundary)[0])
    surface_codes = surface[:, 0] * n + surface[:, 1]
    pick = []
    for t in tets:
        edges = np.sort(t[list(_EDGES)], axis=1)
        interior = ~np.isin(edges[:, 0] * n + edges[:, 1], surface_codes)
        if not interior.any():
            continue
        length = np.linalg.norm(mesh.vertices[edges[:, 0]] - mesh.vertices[edges[:, 1]], axis=1)
        both = on_boundary[edges].all(axis=1)
        rank = np.where(interior, length + np.where(both, length.max() + 1.0, 0.0), -1.0)
        pick.append(edges[int(np.argmax(rank))])
    if not pick:
        return np.zeros((0, 2), dtype=np.int64)
    return np.unique(np.array(pick, dtype=np.int64), axis=0)


def split_flat_spans(mesh: TetMesh, vertices: NDArray[np.float64], triangles: NDArray[np.int64]) -> tuple[TetMesh, dict]:
    """The mesh with every interior edge, then every interior face, on one flat face of Theta split;
    then an edge of each tetrahedron of boundary nodes alone whose image is not positively oriented.

    The last are known before any solve (their nodes' images are the
    boundary data): tetrahedra near a corner of Theta whose four nodes, on
    three of its faces, happen to lie on one plane, or go round the wrong
    way. `repair_edges` chooses the edge.

    Parameters
    ----------
    mesh : TetMesh
    vertices, triangles : ndarray
        Theta: its vertices, with the cage's triangles.

    Returns
    -------
    TetMesh
    dict
        ``split_edges``, ``split_faces``: how many were split.
    """
    nodes, planes = node_planes(mesh, vertices, triangles)
    edges, _ = flat_spans(mesh, nodes, planes)
    edges_done: list[bool] = []
    faces_done: list[bool] = []
    mesh = split_simplices(mesh, list(edges), edges_done)
    # Splitting edges removes every face on them; the faces left are those whose edges are all on the surface.
    _, faces = flat_spans(mesh, nodes, planes)
    mesh = split_simplices(mesh, list(faces), faces_done)
    images = np.zeros((mesh.n_vertices, 3))
    images[mesh.boundary] = mesh.boundary_values(vertices, triangles)
    mesh = split_simplices(mesh, list(repair_edges(mesh, pinned_flat_or_inverted(mesh, images))), edges_done)
    # (A split left out would leave its span: the certificate counts what it flattens.)
    return mesh, {"split_edges": int(sum(edges_done)), "split_faces": int(sum(faces_done))}


#: A tetrahedron of boundary nodes alone whose image's volume is below this times the cube of its
#: longest image edge is flat: its nodes' images are rounded barycentric combinations of Theta's
#: vertices, and four that are coplanar in exact arithmetic (on three faces round a corner of
#: Theta) come out of the rounding on either side of their plane, half of them "positive".
PINNED_FLAT = 1e-9


def pinned_flat_or_inverted(mesh: TetMesh, values: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Tetrahedra of boundary nodes alone whose image is inverted, or flat up to the rounding of
    the boundary data (`PINNED_FLAT`): no solve or untangling can move them, and a flat one sends
    a solid sliver onto a triangle."""
    from .untangle import inverted

    pinned = np.flatnonzero(mesh.on_boundary[mesh.tets].all(axis=1))
    out = np.zeros(mesh.n_tets, dtype=bool)
    if not len(pinned):
        return out
    t = mesh.tets[pinned]
    p = values[t]
    longest = np.zeros(len(t))
    for i, j in _EDGES:
        longest = np.maximum(longest, ((p[:, i] - p[:, j]) ** 2).sum(axis=1))
    out[pinned] = inverted(values, t) | (np.abs(tet_volumes(values, t)) <= PINNED_FLAT * longest**1.5)
    return out


def folded(mesh: TetMesh, values: NDArray[np.float64]) -> NDArray[np.bool_]:
    """The tetrahedra a map with ``values`` at the nodes does not take one-to-one: inverted or flat
    (`warpcli.volume.untangle.inverted`, exact), or of boundary nodes alone and flat up to the
    rounding of the boundary data (`pinned_flat_or_inverted`). The certificate's count
    (`warpcli.volume.compose.TetMap.flipped`) and what the repair rounds mend."""
    from .untangle import inverted

    return inverted(values, mesh.tets) | pinned_flat_or_inverted(mesh, values)


def _skin(mesh: TetMesh, on_boundary: NDArray[np.bool_]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The faces of boundary nodes alone, sorted: those on the surface (one tetrahedron) and the interior ones (two).

    Only faces of boundary nodes can be on the surface, so only they are
    sorted out (a few per boundary node, not four per tetrahedron).
    """
    t = mesh.tets
    tris = np.concatenate([t[:, [1, 2, 3]], t[:, [0, 2, 3]], t[:, [0, 1, 3]], t[:, [0, 1, 2]]])
    tris, counts = _unique_rows(np.sort(tris[on_boundary[tris].all(axis=1)], axis=1), mesh.n_vertices, counts=True)
    return tris[counts == 1].astype(np.int64), tris[counts == 2].astype(np.int64)


def _edges_of(tris: NDArray[np.int64]) -> NDArray[np.int64]:
    """The unique edges of triangles, each sorted."""
    e = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    return _unique_rows(e, int(tris.max(initial=0)) + 1)


def _unique_rows(rows: NDArray[np.int64], n: int, counts: bool = False):
    """``np.unique(rows, axis=0)`` (with counts) for rows of node numbers below ``n``: by one integer
    code per row where it fits in 63 bits, several times faster than sorting rows."""
    k = rows.shape[1]
    if float(n) ** k >= 2.0**62:
        return np.unique(rows, axis=0, return_counts=counts)
    code = np.zeros(len(rows), dtype=np.int64)
    for j in range(k):
        code = code * n + rows[:, j]
    out = np.unique(code, return_counts=counts)
    u = out[0] if counts else out
    cols = []
    for _ in range(k):
        cols.append(u % n)
        u = u // n
    table = np.column_stack(cols[::-1]).astype(np.int64)
    return (table, out[1]) if counts else table


def _planes(vertices: NDArray[np.float64], triangles: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1)[:, None]
    return n, np.einsum("md,md->m", n, a)


def _tolerance(vertices: NDArray[np.float64]) -> float:
    span = float(np.ptp(vertices, axis=0).max())
    return ON_PLANE * max(span, float(np.abs(vertices).max()))
