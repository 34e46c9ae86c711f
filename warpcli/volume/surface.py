"""Polyhedra: reading closed surface meshes (OBJ, OFF, PLY) and checking that they bound a genus-0 solid."""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray
from scipy.sparse.csgraph import connected_components

from ..errors import InputError
from ..files import read_small_file

#: Surface formats read by extension.
SURFACE_EXTENSIONS = (".obj", ".off", ".ply")

#: Largest cage coordinate magnitude: the cube of twice it (volumes) stays finite.
CAGE_COORD_LIMIT = 1e100
#: A triangle whose area is below this fraction of the squared diameter is degenerate.
DEGENERATE_AREA = 1e-14

#: Largest surface mesh file read, in bytes.
MAX_FILE_BYTES = 256 << 20


class SurfaceError(InputError):
    """A surface mesh file is missing, malformed, or does not bound a genus-0 solid."""


@dataclass(frozen=True, eq=False)
class Surface:
    """A closed, oriented, genus-0 triangle surface: the boundary of a polyhedron.

    Polygonal faces (quadrilaterals, as in the paper's Fig. 17) are kept as
    triangles, each face a fan from its smallest vertex index, so that two
    surfaces with the same faces get the same triangles whatever the order
    their files list the vertices of a face in.

    Parameters
    ----------
    vertices : (N, 3) array_like of float
    triangles : (T, 3) array_like of int
        Counter-clockwise seen from outside (outward normals).
    face_of : (T,) array_like of int
        The polygonal face of the file each triangle comes from.
    name : str
        Where it came from, for messages.

    Attributes
    ----------
    n_faces : int
        Faces in the file (before triangulation).
    """

    vertices: NDArray[np.float64]
    triangles: NDArray[np.int64]
    face_of: NDArray[np.int64] = field(default=None, repr=False)  # type: ignore[assignment]
    name: str = "surface"
    n_faces: int = field(default=-1, repr=False)

    def __post_init__(self) -> None:
        v = np.ascontiguousarray(self.vertices, dtype=np.float64)
        t = np.ascontiguousarray(self.triangles, dtype=np.int64)
        if v.ndim != 2 or v.shape[1] != 3:
            raise SurfaceError(f"{self.name}: vertices must be (N, 3), got shape {v.shape}")
        if t.ndim != 2 or t.shape[1] != 3:
            raise SurfaceError(f"{self.name}: triangles must be (T, 3), got shape {t.shape}")
        f = np.arange(len(t), dtype=np.int64) if self.face_of is None else np.asarray(self.face_of, dtype=np.int64)
        if f.shape != (len(t),):
            raise SurfaceError(f"{self.name}: face_of has {f.size} entries for {len(t)} triangles")
        for a in (v, t, f):
            a.setflags(write=False)
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "triangles", t)
        object.__setattr__(self, "face_of", f)
        if self.n_faces < 0:
            object.__setattr__(self, "n_faces", int(f.max()) + 1 if f.size else 0)

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Lowest and highest corners of the bounding box."""
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    @property
    def diameter(self) -> float:
        """Length of the bounding box's diagonal."""
        lo, hi = self.bounds
        return float(np.linalg.norm(hi - lo))

    @property
    def volume(self) -> float:
        """Signed volume enclosed (positive for outward normals)."""
        return float(signed_volume(self.vertices, self.triangles))

    def with_vertices(self, vertices: ArrayLike, name: str | None = None) -> Surface:
        """The same connectivity at other vertex positions."""
        return Surface(vertices, self.triangles, self.face_of, name or self.name, self.n_faces)


def signed_volume(vertices: NDArray[np.float64], triangles: NDArray[np.integer]) -> float:
    """Volume enclosed by a closed triangle surface, positive when its normals point outwards.

    >>> from warpcli.volume.examples import tetrahedron
    >>> round(signed_volume(*tetrahedron()), 6)
    0.166667
    """
    a, b, c = (vertices[triangles[:, k]] - vertices[triangles[0, 0]] for k in range(3))
    return float(np.einsum("ij,ij->", a, np.cross(b, c)) / 6.0)


def triangle_normals(vertices: NDArray[np.float64], triangles: NDArray[np.integer]) -> NDArray[np.float64]:
    """Cross products (b - a) x (c - a): normals of length twice the area."""
    a = vertices[triangles[:, 0]]
    return np.cross(vertices[triangles[:, 1]] - a, vertices[triangles[:, 2]] - a)


# --- reading -----------------------------------------------------------------


def read_surface(path: str | os.PathLike[str], *, check: bool = True) -> Surface:
    """Read a closed surface mesh and check it (see `check_surface`).

    Parameters
    ----------
    path : path-like
        Wavefront OBJ (``v`` and ``f`` lines; texture and normal indices and
        negative indices accepted, everything else ignored), OFF, or PLY
        (ASCII or binary; a ``vertex`` element with x, y, z and a ``face``
        element with a vertex index list).
    check : bool
        Check that it bounds a genus-0 solid.

    Returns
    -------
    Surface

    Raises
    ------
    SurfaceError
        Naming the file and the problem: missing, unreadable, malformed,
        or not the boundary of a genus-0 solid.
    """
    name = os.fspath(path)
    ext = os.path.splitext(name)[1].lower()
    if ext not in SURFACE_EXTENSIONS:
        raise SurfaceError(
            f"{name}: unknown surface mesh format {ext or '(no extension)'}; use one of {', '.join(SURFACE_EXTENSIONS)}"
        )
    data = read_small_file(name, "surface mesh", SurfaceError, max_bytes=MAX_FILE_BYTES)
    reader = {".obj": _parse_obj, ".off": _parse_off, ".ply": _parse_ply}[ext]
    vertices, faces = reader(data, name)
    surface = from_faces(vertices, faces, name)
    if check:
        check_surface(surface)
    return surface


def from_faces(vertices: ArrayLike, faces, name: str = "surface") -> Surface:
    """A `Surface` from vertices and polygonal faces (each a sequence of at least 3 indices).

    Faces are triangulated as fans from their smallest vertex index, after
    checking the indices. Nothing else is checked (see `check_surface`).

    Raises
    ------
    SurfaceError
        If an index is out of range, a face has fewer than 3 vertices or
        repeats one, or a coordinate is not finite.
    """
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise SurfaceError(f"{name}: vertices must be (N, 3), got shape {v.shape}")
    if not np.isfinite(v).all():
        bad = int(np.flatnonzero(~np.isfinite(v).all(axis=1))[0])
        raise SurfaceError(f"{name}: vertex {bad} has a non-finite coordinate")
    if v.size and np.abs(v).max() > CAGE_COORD_LIMIT:
        # Areas and volumes (products of up to three differences) would overflow: say so, not "degenerate face".
        bad = int(np.argmax(np.abs(v).max(axis=1)))
        raise SurfaceError(
            f"{name}: vertex {bad} is too far out ({np.abs(v[bad]).max():.3g}; the limit is {CAGE_COORD_LIMIT:g}): "
            "scale the cage down"
        )
    if isinstance(faces, np.ndarray) and faces.ndim == 2:
        groups = {faces.shape[1]: (np.arange(len(faces)), _indices(faces, np.arange(len(faces)), name))}
    else:
        by_size: dict[int, list[int]] = {}
        for k, face in enumerate(faces):
            by_size.setdefault(len(face), []).append(k)
        groups = {}
        for size, ks in by_size.items():
            ids = np.array(ks, dtype=np.int64)
            try:
                given = np.array([faces[k] for k in ks])
            except (OverflowError, ValueError, TypeError):
                raise SurfaceError(f"{name}: a face's vertex indices are not whole numbers in range") from None
            groups[size] = (ids, _indices(given, ids, name))
    if not groups:
        raise SurfaceError(f"{name}: has no faces")
    tris, owner = [], []
    for size, (ids, f) in sorted(groups.items()):
        if size < 3:
            raise SurfaceError(f"{name}: face {int(ids[0])} has {size} vertices; a face needs at least 3")
        bad = (f < 0) | (f >= len(v))
        if bad.any():
            k = int(np.flatnonzero(bad.any(axis=1))[0])
            raise SurfaceError(
                f"{name}: face {int(ids[k])} refers to vertex {int(f[k][bad[k]][0])}, but there are {len(v)} vertices"
            )
        s = np.sort(f, axis=1)
        rep = (s[:, 1:] == s[:, :-1]).any(axis=1)
        if rep.any():
            k = int(np.flatnonzero(rep)[0])
            raise SurfaceError(f"{name}: face {int(ids[k])} repeats a vertex: {f[k].tolist()}")
        # Canonical rotation: smallest index first (the same cycle gives the same fan).
        start = np.argmin(f, axis=1)
        f = np.take_along_axis(f, (start[:, None] + np.arange(size)) % size, axis=1)
        for j in range(1, size - 1):
            tris.append(f[:, [0, j, j + 1]])
            owner.append(ids)
    tri = np.concatenate(tris)
    face_of = np.concatenate(owner)
    order = np.lexsort((np.repeat(np.arange(len(tris)), [len(x) for x in tris]), face_of))
    n_faces = sum(len(ids) for ids, _ in groups.values())
    return Surface(v, tri[order], face_of[order], name, n_faces)


def _indices(given: np.ndarray, ids: np.ndarray, name: str) -> np.ndarray:
    """Faces' vertex indices as int64: whole numbers only (a PLY may declare them float; 0.9 is not
    vertex 0), within int64 (larger ones are out of range anyway)."""
    if given.dtype.kind in "iu" and np.can_cast(given.dtype, np.int64):
        return given.astype(np.int64)
    try:
        values = given.astype(np.float64)
    except (OverflowError, ValueError, TypeError):
        raise SurfaceError(f"{name}: a face's vertex indices are not whole numbers in range") from None
    whole = np.isfinite(values) & (values == np.round(values)) & (np.abs(values) < 2.0**53)
    if not whole.all():
        k = int(np.flatnonzero(~whole.all(axis=1))[0])
        raise SurfaceError(f"{name}: face {int(ids[k])} has a vertex index that is not a whole number in range: {given[k].tolist()}")
    return values.astype(np.int64)


def _parse_obj(data: bytes, name: str):
    verts: list[list[float]] = []
    faces: list[list[int]] = []
    for lineno, raw in enumerate(data.decode("utf-8", "replace").splitlines(), 1):
        parts = raw.split("#", 1)[0].split()
        if not parts:
            continue
        if parts[0] == "v":
            try:
                verts.append([float(x) for x in parts[1:4]])
            except ValueError:
                raise SurfaceError(f"{name}: line {lineno}: bad vertex {raw.strip()!r}") from None
            if len(verts[-1]) != 3:
                raise SurfaceError(f"{name}: line {lineno}: a vertex needs 3 coordinates: {raw.strip()!r}")
        elif parts[0] == "f":
            face = []
            for tok in parts[1:]:
                try:
                    k = int(tok.split("/", 1)[0])
                except ValueError:
                    raise SurfaceError(f"{name}: line {lineno}: bad face index {tok!r}") from None
                if k == 0:
                    raise SurfaceError(f"{name}: line {lineno}: face index 0 (OBJ counts from 1)")
                # Negative indices count back from the last vertex read.
                face.append(k - 1 if k > 0 else len(verts) + k)
            faces.append(face)
    if not verts:
        raise SurfaceError(f"{name}: no vertices ('v' lines): not an OBJ surface")
    return np.array(verts), faces


def _parse_off(data: bytes, name: str):
    words = []
    for raw in data.decode("utf-8", "replace").splitlines():
        words += raw.split("#", 1)[0].split()
    if not words or not words[0].endswith("OFF"):
        raise SurfaceError(f"{name}: not an OFF file (no OFF header)")
    if words[0] != "OFF":
        raise SurfaceError(f"{name}: {words[0]} files are not supported, only plain OFF")
    try:
        nv, nf = int(words[1]), int(words[2])
        pos = 4
        verts = np.array(words[pos : pos + 3 * nv], dtype=np.float64).reshape(nv, 3)
        pos += 3 * nv
        faces = []
        for _ in range(nf):
            k = int(words[pos])
            faces.append([int(x) for x in words[pos + 1 : pos + 1 + k]])
            if len(faces[-1]) != k:
                raise ValueError
            pos += 1 + k  # colours after the indices are not supported
    except (ValueError, IndexError):
        raise SurfaceError(f"{name}: malformed or truncated OFF file") from None
    return verts, faces


_PLY_TYPES = {
    "char": "b", "int8": "b", "uchar": "B", "uint8": "B", "short": "h", "int16": "h", "ushort": "H",
    "uint16": "H", "int": "i", "int32": "i", "uint": "I", "uint32": "I", "float": "f", "float32": "f",
    "double": "d", "float64": "d",
}  # fmt: skip


def _parse_ply(data: bytes, name: str):
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise SurfaceError(f"{name}: not a PLY file (no ply header)")
    header = data[:end].decode("ascii", "replace").splitlines()
    fmt = None
    elements: list[list] = []  # [name, count, [(prop, type, list_count_type)]]
    try:
        body = data[data.index(b"\n", end) + 1 :]
        for line in header:
            w = line.split()
            if not w:
                continue
            if w[0] == "format":
                fmt = w[1]
            elif w[0] == "element":
                elements.append([w[1], int(w[2]), []])
            elif w[0] == "property" and elements:
                if w[1] == "list":
                    elements[-1][2].append((w[4], w[3], w[2]))
                else:
                    elements[-1][2].append((w[2], w[1], None))
    except (ValueError, IndexError):
        raise SurfaceError(f"{name}: malformed PLY header") from None
    try:
        if fmt == "ascii":
            return _ply_ascii(body, elements, name)
        if fmt in ("binary_little_endian", "binary_big_endian"):
            return _ply_binary(body, elements, "<" if fmt == "binary_little_endian" else ">", name)
    except (ValueError, IndexError, KeyError, struct.error):
        raise SurfaceError(f"{name}: malformed or truncated PLY file") from None
    raise SurfaceError(f"{name}: unknown PLY format {fmt!r}")


def _ply_result(values: dict, name: str):
    if "vertex" not in values or "face" not in values:
        raise SurfaceError(f"{name}: a PLY surface needs 'vertex' and 'face' elements")
    vx = values["vertex"]
    verts = np.array([[row["x"], row["y"], row["z"]] for row in vx], dtype=np.float64)
    key = next((k for k in ("vertex_indices", "vertex_index") if values["face"] and k in values["face"][0]), None)
    if key is None and values["face"]:
        raise SurfaceError(f"{name}: PLY faces have no vertex_indices list")
    return verts, [list(row[key]) for row in values["face"]]


def _ply_ascii(body: bytes, elements, name: str):
    words = body.decode("ascii", "replace").split()
    pos = 0
    values: dict = {}
    for el, count, props in elements:
        rows = []
        for _ in range(count):
            row = {}
            for prop, _typ, list_type in props:
                if list_type is not None:
                    k = int(words[pos])
                    # As written: `from_faces` refuses an index that is not whole (int(float("0.9")) was vertex 0).
                    row[prop] = [_number(x) for x in words[pos + 1 : pos + 1 + k]]
                    pos += 1 + k
                else:
                    row[prop] = float(words[pos])
                    pos += 1
            rows.append(row)
        values[el] = rows
    return _ply_result(values, name)


def _number(word: str) -> int | float:
    """A PLY list value: an int if it is written as one (exactly, however large), else a float."""
    try:
        return int(word)
    except ValueError:
        return float(word)


def _ply_binary(body: bytes, elements, order: str, name: str):
    pos = 0
    values: dict = {}
    for el, count, props in elements:
        rows = []
        if all(lt is None for _, _, lt in props):
            dtype = np.dtype([(p, order + _PLY_TYPES[t]) for p, t, _ in props])
            arr = np.frombuffer(body, dtype=dtype, count=count, offset=pos)
            pos += dtype.itemsize * count
            values[el] = [dict(zip(arr.dtype.names, r)) for r in arr.tolist()]
            continue
        for _ in range(count):
            row = {}
            for prop, typ, list_type in props:
                if list_type is not None:
                    (k,) = struct.unpack_from(order + _PLY_TYPES[list_type], body, pos)
                    pos += struct.calcsize(_PLY_TYPES[list_type])
                    code = _PLY_TYPES[typ]
                    row[prop] = list(struct.unpack_from(f"{order}{k}{code}", body, pos))
                    pos += k * struct.calcsize(code)
                else:
                    code = _PLY_TYPES[typ]
                    (row[prop],) = struct.unpack_from(order + code, body, pos)
                    pos += struct.calcsize(code)
            rows.append(row)
        values[el] = rows
    return _ply_result(values, name)


# --- checking ----------------------------------------------------------------


def check_surface(surface: Surface, *, intersections: bool = True) -> None:
    """Check that a surface bounds a solid ball: closed, manifold, genus 0, outward, not self-intersecting.

    Parameters
    ----------
    surface : Surface
    intersections : bool
        Also look for faces crossing each other (a grid of boxes and an exact
        segment-triangle test for every nearby pair; coplanar overlaps are not
        detected).

    Raises
    ------
    SurfaceError
        With one line naming the file and the first problem found: fewer than
        4 vertices, a vertex no face uses, an edge with one face (not closed)
        or more than two (not manifold), two faces running the same way along
        an edge (inconsistent orientation), a vertex where two sheets touch,
        several parts, a genus other than 0 (Euler characteristic), a
        degenerate face, inward orientation (negative volume), two vertices
        at one point (touching), or two faces that cross.
    """
    name = surface.name
    v, t = surface.vertices, surface.triangles
    n = len(v)
    if n < 4 or len(t) < 4:
        raise SurfaceError(f"{name}: a closed surface needs at least 4 vertices and 4 triangles, got {n} and {len(t)}")
    used = np.zeros(n, dtype=bool)
    used[t.ravel()] = True
    if not used.all():
        raise SurfaceError(f"{name}: vertex {int(np.flatnonzero(~used)[0])} is used by no face")
    edges, _ = _check_edges(surface)
    _check_vertex_fans(surface)
    parts, _ = connected_components(
        sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n)), directed=False
    )
    if parts != 1:
        raise SurfaceError(f"{name}: has {parts} separate parts; one closed surface is needed")
    chi = n - len(edges) + len(t)
    if chi != 2:
        genus = (2 - chi) // 2
        raise SurfaceError(
            f"{name}: has genus {genus} (Euler characteristic V - E + F = {chi}); only genus-0 (sphere-like) "
            "surfaces bound the solids that can be mapped"
        )
    normals = triangle_normals(v, t)
    area2 = np.linalg.norm(normals, axis=1)
    diam = surface.diameter
    tiny = area2 <= 2 * DEGENERATE_AREA * diam * diam
    if tiny.any():
        k = int(np.flatnonzero(tiny)[0])
        raise SurfaceError(f"{name}: face {int(surface.face_of[k])} is degenerate (zero area): vertices {t[k].tolist()}")
    _check_polygon_fans(surface, normals)
    vol = surface.volume
    if vol <= 0:
        raise SurfaceError(
            f"{name}: its faces point inwards (enclosed volume {vol:.6g} is negative): the orientation is inverted; "
            "reverse the vertex order of every face"
        )
    if intersections:
        _check_coincident(surface)
        from ._kernels import first_intersection

        pair = first_intersection(v, t)
        if pair is not None:
            i, j = pair
            where = v[t[i]].mean(axis=0)
            raise SurfaceError(
                f"{name}: faces {int(surface.face_of[i])} and {int(surface.face_of[j])} intersect near "
                f"({where[0]:.6g}, {where[1]:.6g}, {where[2]:.6g}); the surface must not cross itself"
            )


def _check_coincident(surface: Surface) -> None:
    """Two vertices at one point: the surface touches itself there (a crossing that only touches,
    which the float crossing test does not see, and on which TetGen merges the points)."""
    v = surface.vertices
    order = np.lexsort(v.T[::-1])
    same = np.flatnonzero((v[order[1:]] == v[order[:-1]]).all(axis=1))
    if len(same):
        i, j = sorted((int(order[same[0]]), int(order[same[0] + 1])))
        p = v[i]
        raise SurfaceError(
            f"{surface.name}: vertices {i} and {j} are at the same point ({p[0]:.6g}, {p[1]:.6g}, {p[2]:.6g}); "
            "the surface must not touch itself"
        )


def _check_edges(surface: Surface) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Every edge in exactly two triangles, once each way. Returns the edges (E, 2), sorted,
    and for each half-edge (3T) the index of its edge."""
    name = surface.name
    t = surface.triangles
    half = np.stack([t, np.roll(t, -1, axis=1)], axis=2).reshape(-1, 2)  # (3T, 2): a -> b
    key = np.sort(half, axis=1)
    edges, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    if (counts == 1).any():
        e = edges[np.flatnonzero(counts == 1)[0]]
        tri = int(np.flatnonzero((key == e).all(axis=1))[0]) // 3
        raise SurfaceError(
            f"{name}: is not closed: edge {e[0]}-{e[1]} borders only face {int(surface.face_of[tri])} (a hole)"
        )
    if (counts > 2).any():
        e = edges[np.flatnonzero(counts > 2)[0]]
        raise SurfaceError(
            f"{name}: is not manifold: edge {e[0]}-{e[1]} is shared by {int(counts.max())} faces"
        )
    forward = half[:, 0] < half[:, 1]
    ways = np.bincount(inverse, weights=forward, minlength=len(edges))
    if (ways != 1).any():
        k = int(np.flatnonzero(ways != 1)[0])
        e = edges[k]
        faces = sorted({int(surface.face_of[h // 3]) for h in np.flatnonzero(inverse == k)})
        raise SurfaceError(
            f"{name}: faces {faces[0]} and {faces[-1]} run the same way along edge {e[0]}-{e[1]}: the faces are "
            "not consistently oriented (one is flipped, or the surface is not orientable)"
        )
    return edges, inverse


def _check_vertex_fans(surface: Surface) -> None:
    """The triangles around each vertex form one fan (no two sheets touching at a vertex)."""
    t = surface.triangles
    n = surface.n_vertices
    m = len(t)
    # Corner (triangle i, position k) at vertex a = t[i, k]; the half-edge a -> b = t[i, k+1]
    # has its twin b -> a in triangle j, where a sits at corner (j, position of a). Going from
    # corner to corner this way turns once around a; each vertex must be one cycle.
    half = np.stack([t, np.roll(t, -1, axis=1)], axis=2).reshape(-1, 2)
    code = half[:, 0] * n + half[:, 1]
    twin_code = half[:, 1] * n + half[:, 0]
    order = np.argsort(code, kind="stable")
    pos = np.searchsorted(code[order], twin_code)
    twin = order[pos]  # twin half-edge (b -> a), which ends at a: the corner of a is the next one
    corner_next = (twin // 3) * 3 + (twin % 3 + 1) % 3
    g = sp.coo_matrix((np.ones(3 * m), (np.arange(3 * m), corner_next)), shape=(3 * m, 3 * m))
    cycles, label = connected_components(g, directed=True, connection="weak")
    if cycles != n:
        per_vertex = np.zeros(n, dtype=np.int64)
        first = np.unique(label, return_index=True)[1]
        np.add.at(per_vertex, t.ravel()[first], 1)
        bad = int(np.flatnonzero(per_vertex > 1)[0])
        raise SurfaceError(
            f"{surface.name}: is not manifold at vertex {bad}: {int(per_vertex[bad])} separate sheets of faces meet there"
        )


def _check_polygon_fans(surface: Surface, normals: NDArray[np.float64]) -> None:
    """The triangles of one polygonal face turn the same way (a fan of a non-convex face may not)."""
    f = surface.face_of
    multi = np.flatnonzero(np.bincount(f) > 1)
    if multi.size == 0:
        return
    total = np.zeros((surface.n_faces, 3))
    np.add.at(total, f, normals)
    dots = np.einsum("ij,ij->i", normals, total[f])
    bad = dots <= 0
    if bad.any():
        k = int(f[np.flatnonzero(bad)[0]])
        raise SurfaceError(
            f"{surface.name}: face {k} folds over itself when split into triangles from its first vertex "
            "(a non-convex or twisted polygon); split it into triangles in the file"
        )


def check_pair(a: Surface, b: Surface) -> None:
    """Check that two surfaces have the same connectivity: vertex i of one corresponds to vertex i of the other.

    Raises
    ------
    SurfaceError
        If the vertex counts, face counts or faces differ, naming both files
        and the first difference.
    """
    if a.n_vertices != b.n_vertices:
        raise SurfaceError(f"{b.name}: has {b.n_vertices} vertices but {a.name} has {a.n_vertices}")
    if len(a.triangles) != len(b.triangles):
        raise SurfaceError(
            f"{b.name}: has {b.n_faces} faces ({len(b.triangles)} triangles) but {a.name} has "
            f"{a.n_faces} faces ({len(a.triangles)} triangles): not the same connectivity"
        )
    if np.array_equal(a.triangles, b.triangles):
        return
    ka = _canonical(a.triangles)
    kb = _canonical(b.triangles)
    if not np.array_equal(ka, kb):
        missing = np.setdiff1d(ka, kb)
        tri = a.triangles[np.flatnonzero(np.isin(_tri_codes(a.triangles), missing))[0]]
        raise SurfaceError(
            f"{b.name}: does not have the same connectivity as {a.name}: {a.name} has a face through vertices "
            f"{tri.tolist()} that {b.name} does not (vertex i of one must correspond to vertex i of the other)"
        )


def _tri_codes(t: NDArray[np.int64]) -> NDArray[np.int64]:
    """One integer per oriented triangle, the same for any rotation of it."""
    start = np.argmin(t, axis=1)
    r = np.take_along_axis(t, (start[:, None] + np.arange(3)) % 3, axis=1)
    n = int(t.max()) + 1
    return (r[:, 0] * n + r[:, 1]) * n + r[:, 2]


def _canonical(t: NDArray[np.int64]) -> NDArray[np.int64]:
    return np.sort(_tri_codes(t))


def reflex_edges(surface: Surface, min_angle_deg: float = 20.0) -> NDArray[np.int64]:
    """Edges where the solid is concave by more than ``min_angle_deg`` (dihedral above 180 + that).

    The harmonic map's gradient is singular along such edges, like at a 2D
    polygon's reflex vertex, and the FEM mesh is graded towards them.

    Returns
    -------
    (R, 2) ndarray of int
        Vertex pairs.
    """
    v, t = surface.vertices, surface.triangles
    half = np.stack([t, np.roll(t, -1, axis=1)], axis=2).reshape(-1, 2)
    tri = np.repeat(np.arange(len(t)), 3)
    opposite = np.roll(t, 1, axis=1).ravel()  # the third vertex of each half-edge's triangle
    fwd = half[:, 0] < half[:, 1]
    key = np.where(fwd, half[:, 0] * len(v) + half[:, 1], half[:, 1] * len(v) + half[:, 0])
    order = np.lexsort((~fwd, key))
    a, b = order[0::2], order[1::2]  # the forward half-edge, then its twin
    n = triangle_normals(v, t)
    n /= np.linalg.norm(n, axis=1)[:, None]
    e = half[a]
    # Concave when the twin triangle's far vertex lies above this triangle's plane.
    d = v[opposite[b]] - v[e[:, 0]]
    height = np.einsum("ij,ij->i", d, n[tri[a]])
    cosang = np.clip(np.einsum("ij,ij->i", n[tri[a]], n[tri[b]]), -1.0, 1.0)
    bend = np.degrees(np.arccos(cosang))
    return e[(height > 0) & (bend > min_angle_deg)]


def is_convex(surface: Surface, rel_tol: float = 1e-9) -> bool:
    """Whether the solid is convex: no edge is concave beyond ``rel_tol`` times the diameter.

    Coplanar neighbours (a square side split into triangles) count as convex.
    A closed, embedded surface that is convex along every edge bounds a convex
    solid.
    """
    v, t = surface.vertices, surface.triangles
    half = np.stack([t, np.roll(t, -1, axis=1)], axis=2).reshape(-1, 2)
    n_v = len(v)
    fwd = half[:, 0] < half[:, 1]
    key = np.where(fwd, half[:, 0] * n_v + half[:, 1], half[:, 1] * n_v + half[:, 0])
    order = np.lexsort((~fwd, key))
    a, b = order[0::2], order[1::2]
    opposite = np.roll(t, 1, axis=1).ravel()
    n = triangle_normals(v, t)
    n /= np.linalg.norm(n, axis=1)[:, None]
    d = v[opposite[b]] - v[half[a, 0]]
    height = np.einsum("ij,ij->i", d, n[a // 3])
    return bool((height <= rel_tol * surface.diameter).all())


def surface_from_arrays(vertices: ArrayLike, faces: ArrayLike, name: str = "surface", *, check: bool = True) -> Surface:
    """A checked `Surface` from arrays (polygonal faces of one size), as `read_surface` makes from a file."""
    s = from_faces(vertices, np.asarray(faces), name)
    if check:
        check_surface(s)
    return s
