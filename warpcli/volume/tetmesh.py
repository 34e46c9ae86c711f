"""Tetrahedral meshing: a graded quality mesh of a polyhedron whose boundary is the cage's surface, refined, over TetGen."""

from __future__ import annotations

import contextlib
import math
import os
import tempfile
import threading
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..capture import terminal_saved
from ..errors import InputError, MeshingError
from ..polygon.predicates import orient3d_sign
from .surface import Surface, SurfaceError, reflex_edges

#: A box (lo, hi) of the surface's space: the region a map is used in.
Region = tuple[NDArray[np.float64], NDArray[np.float64]]

#: Refuse to build a mesh of more than this many tetrahedra.
MAX_TETS = 6_000_000

#: The default edge length is this times sqrt(size * voxel), with the size
#: the cube root of the polyhedron's volume, and never below one voxel (see
#: `auto_edge`): the P1 error in voxels grows like edge^2 / size, so this
#: keeps it alike at every volume size, as the 2D default does for pixels.
AUTO_EDGE_FACTOR = 0.6

#: Boundary edges shrink towards concave (reflex) edges, where the harmonic
#: map's gradient is singular as at a 2D reflex vertex: edge length
#: ``GRADE_SLOPE * distance``, at least ``GRADE_MIN`` times the nominal length.
GRADE_SLOPE = 0.5
GRADE_MIN = 0.3
#: An edge is graded towards when the solid is concave there by more than this (degrees).
GRADE_ANGLE = 40.0

#: Interior tetrahedra may be this many times the volume of a regular one of
#: the nominal edge: the harmonic map is smooth inside, and quality
#: refinement grades the interior from the boundary anyway.
INTERIOR_VOLUME = 3.0

#: TetGen's quality bounds: radius-edge ratio and minimum dihedral angle
#: (degrees), and the largest dihedral angle its mesh optimization aims for
#: (``-o/``). Obtuse dihedral angles make negative cotangent weights, where
#: the harmonic map can invert tetrahedra: on bench/volume.py's twisted bent
#: box, 1.5/15 with TetGen's default 177 left 19 inverted tetrahedra (4
#: after untangling: pinned faces), 1.4/16/140 leaves 2 (0 after), for 4%
#: more tetrahedra.
RADIUS_EDGE = 1.4
MIN_DIHEDRAL = 16.0
MAX_DIHEDRAL = 140.0

#: A cage that reaches further than this many times the size of its region
#: of interest (the box of the volume's voxels) beyond it is meshed graded
#: from the region, as in 2D (`warpcli.maps.fem.mesh.graded_from`): the
#: default edge follows the region's size, not the cage's, and edges grow by
#: `REGION_SLOPE` per unit of distance from the region, so the work follows
#: what touches the volume, not the cage's coordinates.
REGION_REACH = 0.5
REGION_SLOPE = 0.1
#: The lattice of interior points in the region is jittered by up to this
#: times the edge (see `_region_points`), differently on each of this many
#: tries before the mesh is made without it.
REGION_JITTER = 0.2
REGION_TRIES = 2

_TETGEN_LOCK = threading.Lock()


@dataclass(frozen=True, eq=False)
class TetMesh:
    """A tetrahedral mesh of a polyhedron, with each boundary node's place on the cage's surface.

    Attributes
    ----------
    vertices : (N, 3) ndarray of float
    tets : (M, 4) ndarray of int64
        Positively oriented: det[b - a, c - a, d - a] > 0.
    boundary : (B,) ndarray of int64
        The nodes on the surface.
    boundary_triangle : (B,) ndarray of int64
        The cage triangle each lies in (`Surface.triangles` row).
    boundary_bary : (B, 3) ndarray of float
        Its barycentric coordinates there: the boundary data of any map onto a
        Theta is ``bary @ theta[triangle]`` (piecewise linear on the cage's
        triangles).
    """

    vertices: NDArray[np.float64]
    tets: NDArray[np.int64]
    boundary: NDArray[np.int64]
    boundary_triangle: NDArray[np.int64]
    boundary_bary: NDArray[np.float64]

    def __post_init__(self) -> None:
        n = len(self.boundary)
        if len(self.boundary_triangle) != n or self.boundary_bary.shape != (n, 3):
            raise ValueError(
                f"{n} boundary nodes but {len(self.boundary_triangle)} triangles and {self.boundary_bary.shape} barycentrics"
            )

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def n_tets(self) -> int:
        return len(self.tets)

    @property
    def on_boundary(self) -> NDArray[np.bool_]:
        """(N,) bool: the nodes on the surface (the fixed nodes of every map of the mesh)."""
        out = np.zeros(self.n_vertices, dtype=bool)
        out[self.boundary] = True
        return out

    def boundary_values(self, theta: NDArray[np.float64], triangles: NDArray[np.int64]) -> NDArray[np.float64]:
        """The boundary data onto ``theta`` (vertex positions with the cage's ``triangles``)."""
        corners = theta[triangles[self.boundary_triangle]]  # (B, 3, 3)
        return np.einsum("bk,bkd->bd", self.boundary_bary, corners)


def tet_volumes(vertices: NDArray[np.float64], tets: NDArray[np.integer]) -> NDArray[np.float64]:
    """Signed volumes of tetrahedra (positive for det[b - a, c - a, d - a] > 0)."""
    a = vertices[tets[:, 0]]
    return np.einsum("ij,ij->i", vertices[tets[:, 1]] - a, np.cross(vertices[tets[:, 2]] - a, vertices[tets[:, 3]] - a)) / 6.0


def auto_edge(surface: Surface, voxel: float = 1.0, region: Region | None = None) -> float:
    """The default nominal edge length: `AUTO_EDGE_FACTOR` * sqrt(size * voxel), at least ``voxel``.

    Parameters
    ----------
    surface : Surface
    voxel : float
        The size of a voxel in the surface's units (the finest the mesh needs to be).
    region : (lo, hi) pair of (3,) arrays, or None
        The box the map is used in. For a cage meshed graded from it
        (`graded_from`), the size is the region's where that is smaller: the
        far field's error reaches the region (bench/volume_region.py: at a
        cage 20 times the volume, 0.09 voxel against a finer mesh with the
        region's size, 0.19 with the cage's).
    """
    size = abs(surface.volume) ** (1.0 / 3.0)
    if graded_from(surface, region):
        lo, hi = (np.asarray(x, dtype=np.float64) for x in region)  # type: ignore[union-attr]
        size = min(size, float(np.prod(np.maximum(hi - lo, voxel))) ** (1.0 / 3.0))
    return max(AUTO_EDGE_FACTOR * math.sqrt(size * voxel), voxel)


def graded_from(surface: Surface, region: Region | None) -> bool:
    """Whether a cage reaches far enough beyond ``region`` (see `REGION_REACH`) to be meshed graded from it."""
    if region is None:
        return False
    lo, hi = (np.asarray(x, dtype=np.float64) for x in region)
    clo, chi = surface.bounds
    reach = REGION_REACH * max(float(np.max(hi - lo)), 0.0)
    return bool((clo < lo - reach).any() or (chi > hi + reach).any())


def mesh_polyhedron(surface: Surface, edge: float, *, grade: bool = True, region: Region | None = None) -> TetMesh:
    """Mesh the solid a checked cage bounds with quality tetrahedra.

    The surface is first refined (edges split at their midpoints, so every
    new boundary node lies on a cage triangle) to edges of at most ``edge``,
    shorter towards concave edges when ``grade``; TetGen then fills the solid
    without adding boundary points (``-Y``), with quality bounds
    (`RADIUS_EDGE`, `MIN_DIHEDRAL`) and tetrahedra of at most the volume of
    a regular one of edge ``edge``, so the interior grades from the boundary.

    A cage that reaches far beyond ``region`` (`graded_from`) is meshed
    graded from it instead: boundary edges of ``edge`` at the region,
    growing by `REGION_SLOPE` per unit of distance from it; inside the
    region, a lattice of points ``edge`` apart that TetGen keeps; and no
    volume bound, so the quality bounds grade the rest. The mesh's size then
    follows the region's, whatever the cage's.

    Parameters
    ----------
    surface : Surface
    edge : float
        Nominal edge length, in the surface's units.
    grade : bool
    region : (lo, hi) pair of (3,) arrays, or None
        The box the map is used in (a volume's voxels).

    Returns
    -------
    TetMesh

    Raises
    ------
    InputError
        If ``edge`` is not positive, or the mesh would exceed `MAX_TETS`.
    MeshingError
        If TetGen is not installed or fails.
    """
    if not (edge > 0 and math.isfinite(edge)):
        raise InputError(f"{surface.name}: the mesh edge length must be positive and finite, got {edge}")
    size = abs(surface.volume) ** (1.0 / 3.0)
    if not (1e-6 * size <= edge <= 1e6 * size):  # (1e-300 divided by zero; 1e300 overflowed)
        raise InputError(f"{surface.name}: a mesh edge length of {edge:g} is out of all proportion to the cage (size {size:g})")
    regular = edge**3 / (6.0 * math.sqrt(2.0))
    graded = graded_from(surface, region)
    solid = abs(surface.volume)
    if graded:
        lo, hi = region  # type: ignore[misc]
        solid = min(solid, float(np.prod(np.asarray(hi) - np.asarray(lo) + 2.0 * edge)))
    estimate = 1.3 * solid / regular
    if estimate > MAX_TETS:
        raise InputError(
            f"{surface.name}: meshing with edges of {edge:g} would need about {estimate:.3g} tetrahedra, more than "
            f"the limit of {MAX_TETS:,}; use a longer edge"
        )
    size_fn = _size_function(surface, edge, grade, region if graded else None)
    v, tri, owner = refine_surface(surface.vertices, surface.triangles, size_fn)
    if graded:
        # TetGen can fail on a graded input (an internal error in boundary recovery, 12 of 864 cages
        # a review tried): each try jitters the lattice differently, and then the cage is meshed
        # as it would be without a region (slower for a large cage, as accurate; a graded mesh
        # without the lattice lost the volume's accuracy: 1 tetrahedron in it, 0.58 voxel).
        for attempt in range(REGION_TRIES):
            inner = _region_points(surface, region, edge, v, tri, size_fn, attempt)  # type: ignore[arg-type]
            try:
                nodes, tets = _tetgen(v, tri, None, surface.name, inner)
                break
            except MeshingError:
                continue
        else:
            return mesh_polyhedron(surface, edge, grade=grade)
    else:
        nodes, tets = _tetgen(v, tri, INTERIOR_VOLUME * regular, surface.name)
    # Exact signs (a float volume can be wrong on a sliver): the maps' certificates trust these.
    sign = orient3d_sign(*(nodes[tets[:, k]] for k in range(4)))
    if (sign < 0).sum() > len(sign) // 2:
        tets = tets[:, [0, 2, 1, 3]]
        sign = -sign
    if not (sign > 0).all():
        raise MeshingError(f"{surface.name}: TetGen made {int((~(sign > 0)).sum())} degenerate tetrahedra")
    nb = len(v)
    if len(nodes) < nb or not np.array_equal(nodes[:nb], v):
        raise SurfaceError(
            f"{surface.name}: TetGen moved or merged the boundary nodes; the surface probably touches itself "
            "where the checks could not tell (a vertex exactly on another face)"
        )
    tri_of, bary = _boundary_places(surface, v, tri, owner)
    on_boundary = np.unique(boundary_faces(tets))
    extra = on_boundary[on_boundary >= nb]
    if len(extra):
        # TetGen may still split a boundary face to recover it (-Y is a wish, not a promise):
        # place those nodes on the refined triangle they lie in.
        e_tri, e_bary = _place_on(surface, nodes[extra], v, tri, owner)
        tri_of = np.concatenate([tri_of, e_tri])
        bary = np.concatenate([bary, e_bary])
    return TetMesh(
        np.ascontiguousarray(nodes), np.ascontiguousarray(tets, dtype=np.int64),
        np.concatenate([np.arange(nb, dtype=np.int64), extra]), tri_of, bary,
    )  # fmt: skip


def boundary_faces(tets: NDArray[np.integer]) -> NDArray[np.int64]:
    """The faces that belong to one tetrahedron only (the mesh's boundary), (F, 3)."""
    faces = np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 3, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 1]]])
    key = np.sort(faces, axis=1)
    _, idx, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    return faces[idx[counts == 1]].astype(np.int64)


def _size_function(surface: Surface, edge: float, grade: bool, region: Region | None = None):
    """Target boundary edge length at points: ``edge``, shorter near concave edges.

    With a ``region``: ``edge`` there, growing by `REGION_SLOPE` per unit of
    distance from it, and near concave edges down to `GRADE_MIN` times that.
    """
    if region is None:
        def nominal(p: NDArray[np.float64]) -> NDArray[np.float64]:
            return np.full(len(p), edge)
    else:
        lo, hi = (np.asarray(x, dtype=np.float64) for x in region)

        def nominal(p: NDArray[np.float64]) -> NDArray[np.float64]:
            gap = np.maximum(np.maximum(lo - p, p - hi), 0.0)
            return edge + REGION_SLOPE * np.sqrt((gap * gap).sum(axis=1))

    reflex = reflex_edges(surface, GRADE_ANGLE) if grade else np.zeros((0, 2), dtype=np.int64)
    if len(reflex) == 0:
        return nominal
    from scipy.spatial import cKDTree

    hmin = GRADE_MIN * edge
    a = surface.vertices[reflex[:, 0]]
    b = surface.vertices[reflex[:, 1]]
    length = np.linalg.norm(b - a, axis=1)
    # Sample the concave edges at half the floor of the grading there (hmin without a region): the
    # nearest sample is within a quarter of it of the nearest point.
    floor = np.full(len(reflex), hmin)
    if region is not None:  # the smallest nominal length along each edge (17 points: distance to a box is convex)
        u = np.linspace(0.0, 1.0, 17)
        along = (a[:, None, :] + u[None, :, None] * (b - a)[:, None, :]).reshape(-1, 3)
        floor = GRADE_MIN * nominal(along).reshape(len(reflex), -1).min(axis=1)
    counts = np.maximum(np.ceil(length / (0.5 * floor)).astype(np.int64), 1)
    t = np.concatenate([np.arange(c + 1) / c for c in counts])
    which = np.repeat(np.arange(len(reflex)), counts + 1)
    tree = cKDTree(a[which] + t[:, None] * (b - a)[which])

    def size(p: NDArray[np.float64]) -> NDArray[np.float64]:
        d, _ = tree.query(p)
        h = nominal(p)
        return np.clip(GRADE_SLOPE * d, GRADE_MIN * h, h)

    return size


def _region_points(
    surface: Surface, region: Region, edge: float, v: NDArray[np.float64], tri, size_fn, seed: int = 0
) -> NDArray[np.float64]:
    """A lattice ``edge`` apart over the region (and one edge round it), inside the cage and half the
    local edge length or more from its refined surface (v, tri): interior nodes TetGen keeps.

    Each point is moved by up to `REGION_JITTER` times ``edge`` in each coordinate (seeded by
    ``seed``): a regular lattice is a degenerate input for Delaunay meshing (points by the dozen on
    one sphere), on which TetGen can fail.
    """
    from scipy.spatial import cKDTree

    from ._kernels import winding

    lo, hi = (np.asarray(x, dtype=np.float64) for x in region)
    clo, chi = surface.bounds
    lo, hi = np.maximum(lo - edge, clo), np.minimum(hi + edge, chi)
    if (hi <= lo).any():
        return np.zeros((0, 3))
    axes = [lo[k] + edge * np.arange(int((hi[k] - lo[k]) / edge) + 1) for k in range(3)]
    p = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    p = p + (np.random.default_rng(seed).random(p.shape) - 0.5) * (2.0 * REGION_JITTER * edge)
    p = p[winding(p, surface.vertices, surface.triangles) > 0.5]
    if len(p):
        # The refined triangles' corners, edge midpoints and centroids are within 0.45 of the local
        # edge length of every point of the surface (edges at most 1.4 of it): a point that far
        # from all of them is at least half an edge length inside.
        corners = v[tri]
        samples = np.concatenate([v, 0.5 * (corners + np.roll(corners, -1, axis=1)).reshape(-1, 3), corners.mean(axis=1)])
        d, _ = cKDTree(samples).query(p)
        p = p[d > size_fn(p)]
    return p


#: An edge is split when longer than this times the target length: its halves
#: are then at least 0.7 times it (splitting at 1x would halve edges just over
#: the target, and double the boundary nodes).
SPLIT_RATIO = 1.4


def refine_surface(vertices: NDArray[np.float64], triangles: NDArray[np.int64], size_fn, max_passes: int = 40):
    """Split edges longer than ``size_fn`` at their midpoints until none is.

    Returns
    -------
    vertices : (N', 3) ndarray of float
        The original vertices first, in order.
    triangles : (T', 3) ndarray of int
    owner : (T',) ndarray of int
        The original triangle each new one lies in.
    """
    from ._kernels import split_triangles

    v = np.asarray(vertices, dtype=np.float64)
    # A writable copy, as split_triangles' own output is: numba compiles read-only arrays as
    # another type, and a cage's frozen triangles cost a second compile (1.8 s) of the kernel.
    t = np.array(triangles, dtype=np.int64)
    owner = np.arange(len(t), dtype=np.int64)
    for _ in range(max_passes):
        sides = np.stack([t, np.roll(t, -1, axis=1)], axis=2).reshape(-1, 2)
        key = np.sort(sides, axis=1)
        edges, side_edge = np.unique(key, axis=0, return_inverse=True)
        side_edge = side_edge.reshape(-1, 3)
        mid = 0.5 * (v[edges[:, 0]] + v[edges[:, 1]])
        length = np.linalg.norm(v[edges[:, 1]] - v[edges[:, 0]], axis=1)
        split = length > SPLIT_RATIO * size_fn(mid)
        if not split.any():
            break
        new_id = np.full(len(edges), -1, dtype=np.int64)
        new_id[split] = len(v) + np.arange(int(split.sum()))
        v = np.concatenate([v, mid[split]])
        t, parent = split_triangles(t, side_edge, new_id, v)
        owner = owner[parent]
    return v, t, owner


def _place_on(surface: Surface, points, v, tri, owner):
    """The cage triangle and barycentrics of points lying on the refined surface (v, tri)."""
    from scipy.spatial import cKDTree

    centroid = v[tri].mean(axis=1)
    k = min(16, len(tri))
    _, cand = cKDTree(centroid).query(points, k=k)
    cand = cand.reshape(len(points), k)
    best = np.full(len(points), np.inf)
    which = np.zeros(len(points), dtype=np.int64)
    for j in range(k):
        c = tri[cand[:, j]]
        a, b, d = v[c[:, 0]], v[c[:, 1]], v[c[:, 2]]
        lam = _bary_in_plane(points, a, b, d)
        dist = np.linalg.norm(points - (lam[:, :1] * a + lam[:, 1:2] * b + lam[:, 2:] * d), axis=1)
        dist += np.maximum(-lam.min(axis=1), 0.0) * np.linalg.norm(b - a, axis=1)
        better = dist < best
        best[better] = dist[better]
        which[better] = cand[better, j]
    tri_of = owner[which]
    corners = surface.vertices[surface.triangles[tri_of]]
    return tri_of, _bary_in_plane(points, corners[:, 0], corners[:, 1], corners[:, 2])


def _bary_in_plane(p, a, b, c):
    """Barycentric coordinates of the projections of points p onto triangles abc (least squares)."""
    e1, e2, d = b - a, c - a, p - a
    g11 = np.einsum("ij,ij->i", e1, e1)
    g12 = np.einsum("ij,ij->i", e1, e2)
    g22 = np.einsum("ij,ij->i", e2, e2)
    r1 = np.einsum("ij,ij->i", d, e1)
    r2 = np.einsum("ij,ij->i", d, e2)
    det = g11 * g22 - g12 * g12
    l1 = (g22 * r1 - g12 * r2) / det
    l2 = (g11 * r2 - g12 * r1) / det
    return np.column_stack([1.0 - l1 - l2, l1, l2])


def _boundary_places(surface: Surface, v, tri, owner):
    """Each refined boundary node's cage triangle and barycentric coordinates."""
    n = len(v)
    tri_of = np.empty(n, dtype=np.int64)
    tri_of[tri.ravel()] = np.repeat(owner, 3)
    corners = surface.vertices[surface.triangles[tri_of]]  # (n, 3, 3)
    # The node lies in the triangle's plane up to rounding.
    bary = _bary_in_plane(v, corners[:, 0], corners[:, 1], corners[:, 2])
    # Original vertices exactly.
    m = surface.n_vertices
    for k in range(3):
        at = surface.triangles[tri_of[:m], k] == np.arange(m)
        bary[:m][at] = np.eye(3)[k]
    return tri_of, bary


@contextlib.contextmanager
def _quiet_fds():
    """Keep what TetGen prints to file descriptors 1 and 2 off the terminal; the text is kept for errors."""
    sink = tempfile.TemporaryFile()
    saved = []
    said = {"text": ""}
    keep = contextlib.ExitStack()
    try:
        for fd in (1, 2):
            try:
                os.fsync(fd)
            except OSError:
                pass
            saved.append((fd, os.dup(fd)))
            if fd == 2:
                keep.enter_context(terminal_saved(saved[-1][1]))  # a SIGTERM's line goes to the terminal
            os.dup2(sink.fileno(), fd)
        yield said
    finally:
        for fd, old in saved:
            os.dup2(old, fd)
        keep.close()
        for fd, old in saved:
            os.close(old)
        sink.seek(0)
        said["text"] = sink.read().decode("utf-8", "replace")
        sink.close()


def _tetgen(v: NDArray[np.float64], tri: NDArray[np.int64], max_volume: float | None, name: str, inner=None):
    """TetGen's mesh of the closed surface (v, tri): in a forked child where the system can fork.

    TetGen ends the process (abort) on some inputs the surface checks let
    through (a cage vertex pushed exactly through an edge of a face: a
    crossing that only touches, which the checks' floating-point tests take
    for no crossing), and writes files of its own ("tetgen-tmpfile_*") into
    the working directory as it does. In a child that works in a private
    directory, removed after, such a crash is a `SurfaceError` (bad input,
    exit 2) naming the surface; nothing is left behind.
    """
    try:
        import tetgen  # noqa: F401  (said here, in the parent: the child's failure would be a crash)
    except ImportError as err:
        raise MeshingError(
            "meshing a polyhedron needs the tetgen package (pip install 'warpcli[volume]'); "
            f"it could not be imported: {err}"
        ) from None
    from .. import _fork

    if not _fork.possible():
        return _tetgen_here(v, tri, max_volume, name, inner)
    import shutil

    private = tempfile.mkdtemp(prefix="warpcli-tetgen-")
    try:
        try:
            return _fork.Forked(_tetgen_in, private, v, tri, max_volume, name, inner).result()
        except _fork.ChildDied as err:
            raise SurfaceError(
                f"{name}: TetGen crashed meshing the polyhedron ({err}); the surface probably touches or crosses "
                "itself where the checks could not tell (a vertex exactly on another face's edge)"
            ) from None
    finally:
        shutil.rmtree(private, ignore_errors=True)


def _tetgen_in(directory: str, v, tri, max_volume: float | None, name: str, inner=None):
    """`_tetgen_here` with ``directory`` as the working directory (in a forked child)."""
    os.chdir(directory)
    return _tetgen_here(v, tri, max_volume, name, inner)


def _tetgen_here(v: NDArray[np.float64], tri: NDArray[np.int64], max_volume: float | None, name: str, inner=None):
    """TetGen's quality mesh of the surface (v, tri), tetrahedra of at most ``max_volume`` (None: no
    bound), with the points ``inner`` (inside, off the surface) among its nodes, after v's."""
    import tetgen

    volume = "" if max_volume is None else f"a{max_volume:.10g}"
    switches = f"pq{RADIUS_EDGE:g}/{MIN_DIHEDRAL:g}{volume}o/{MAX_DIHEDRAL:g}YQ"
    if inner is not None and len(inner):
        v = np.concatenate([v, inner])
    with _TETGEN_LOCK:
        with _quiet_fds() as said:
            try:
                gen = tetgen.TetGen(np.ascontiguousarray(v), np.ascontiguousarray(tri, dtype=np.int32))
                nodes, tets, *_ = gen.tetrahedralize(switches=switches)
                err = None
            except (RuntimeError, ValueError) as exc:  # TetGen's failures come back as these
                err = exc
    if err is not None or len(tets) == 0:
        detail = " ".join(said["text"].split())[-300:]
        raise MeshingError(f"{name}: TetGen failed to mesh the polyhedron: {err or 'no tetrahedra'} {detail}".rstrip())
    return np.asarray(nodes, dtype=np.float64), np.asarray(tets, dtype=np.int64)
