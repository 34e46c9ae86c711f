"""Cage meshes: planar partitions of a region into polygon faces that share vertices and edges.

A cage mesh is what one polygon is for a single warp, for several at once:
faces listed by vertex index, each face mapped by the chosen method
(`warpcli.maps.cage`). The map of the whole is continuous because
neighbouring faces share their edge, and one-to-one when the faces of both
sides form a partition with the same combinatorics and orientation, which is
what `Partition` and `validate_pair` check, exactly:

- every face is a simple polygon (`Polygon`'s checks) and all run the same way
  round as the mesh's outline;
- every interior edge is used by exactly two faces, in opposite directions;
  the remaining (boundary) edges form one simple closed loop, the outline, and
  the faces form one piece without holes (Euler characteristic 1);
- the faces' angles at every interior vertex sum to 2 pi (they wind round it
  once), and at every vertex of the outline to the outline's angle there.

With these the mesh is an immersed disk whose boundary is simple, hence
embedded: its faces do not overlap and cover the region inside the outline.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._cached import cached_property
from ..errors import PolygonError
from .formats import points_of, read_document
from .messages import LongInteger, format_point, short_value
from .shape import COORD_LIMIT, Polygon, check_pair

__all__ = [
    "WELD_TOLERANCE", "Cages", "Partition", "cages_of", "check_shapes", "is_partition_document", "partition_of",
    "read_partition", "read_shape", "validate_pair",
]  # fmt: skip

#: Vertices of different polygons of a labelme or GeoJSON file closer than this
#: (in pixels) are one vertex of the cage mesh. GIS tools that snap write equal
#: coordinates; files written with two decimals differ by at most 0.01 px; no
#: warp resolves less.
WELD_TOLERANCE = 0.01


@dataclass(frozen=True, eq=False)
class Partition:
    """A planar partition: polygon faces sharing vertices and edges.

    Validated on construction (see the module's docstring): a valid
    partition's faces do not overlap and cover the region inside its outline.

    Parameters
    ----------
    vertices : (N, 2) array_like of float
        Vertex coordinates, x right and y down (pixels).
    faces : sequence of sequence of int
        Vertex indices per face, in order round the face; one orientation for
        all faces. A face closes itself: do not repeat its first vertex.
    name : str
        How error messages refer to the mesh, usually its file name.

    Raises
    ------
    PolygonError
        One line naming the face or vertex at fault.
    """

    vertices: NDArray[np.float64]
    faces: tuple[tuple[int, ...], ...]
    name: str = field(default="cage mesh")

    def __post_init__(self) -> None:
        verts = _as_vertices(self.vertices, self.name)
        faces = _as_faces(self.faces, len(verts), self.name)
        verts.setflags(write=False)
        object.__setattr__(self, "vertices", verts)
        object.__setattr__(self, "faces", faces)
        loop = _topology(faces, len(verts), self.name)
        object.__setattr__(self, "_loop", loop)
        # The outline and the faces as the checks made them (checked once: `outline` and `face_polygon` rename them).
        object.__setattr__(self, "_polygons", _geometry(verts, faces, loop, self.name))

    @property
    def points(self) -> NDArray[np.float64]:
        """The vertices (as `Polygon.points`: what keyframes blend and compare)."""
        return self.vertices

    @property
    def n_faces(self) -> int:
        """Number of faces."""
        return len(self.faces)

    @property
    def n(self) -> int:
        """Number of vertices."""
        return len(self.vertices)

    @property
    def loops(self) -> tuple[NDArray[np.intp], ...]:
        """The outer boundary loop(s) as vertex indices, in the faces' direction (one for a valid mesh)."""
        return (self._loop,)  # type: ignore[attr-defined]

    @cached_property
    def outline(self) -> Polygon:
        """The outer boundary as a `Polygon`, running the faces' way round."""
        return self._polygons[0].renamed(self.name)  # type: ignore[attr-defined]

    @cached_property
    def outline_edges(self) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """For each edge of `outline`: the face it belongs to and that face's edge index."""
        where = {}
        for k, f in enumerate(self.faces):
            for j in range(len(f)):
                where[(f[j], f[(j + 1) % len(f)])] = (k, j)
        loop = self._loop  # type: ignore[attr-defined]
        pairs = [where[(int(loop[i]), int(loop[(i + 1) % len(loop)]))] for i in range(len(loop))]
        arr = np.array(pairs, dtype=np.intp).reshape(-1, 2)
        return arr[:, 0], arr[:, 1]

    def face_points(self, k: int) -> NDArray[np.float64]:
        """The vertices of face ``k`` in order, (n_k, 2)."""
        return self.vertices[list(self.faces[k])]

    def face_polygon(self, k: int) -> Polygon:
        """Face ``k`` as a `Polygon`, named ``"NAME face k"``."""
        return self._polygons[1][k].renamed(f"{self.name} face {k}")  # type: ignore[attr-defined]

    def face_polygons(self) -> tuple[Polygon, ...]:
        """Every face as a `Polygon` (see `face_polygon`)."""
        return tuple(self.face_polygon(k) for k in range(self.n_faces))

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` of the vertices."""
        lo = self.vertices.min(axis=0)
        hi = self.vertices.max(axis=0)
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])

    @property
    def signed_area(self) -> float:
        """The outline's signed area: positive when the faces run clockwise on screen (y down)."""
        return self.outline.signed_area

    def moved(self, vertices: ArrayLike, name: str | None = None) -> Partition:
        """The same faces on other vertex positions (validated again).

        All of `Partition`'s checks, with what cannot have changed taken from
        this mesh: the faces' combinatorics (the same faces), and a face's own
        polygon checks where none of its vertices moved (they depend on its
        points alone). The orientation and angle checks run on every face.
        A drag in the editor moves the faces at one vertex.

        Raises
        ------
        PolygonError
            As `Partition`, with the same messages.
        """
        label = self.name if name is None else name
        verts = _as_vertices(np.asarray(vertices, dtype=np.float64), label)
        if verts.shape != self.vertices.shape:
            return Partition(verts, self.faces, label)
        verts.setflags(write=False)
        moved = object.__new__(Partition)
        for key, value in (("vertices", verts), ("faces", self.faces), ("name", label), ("_loop", self._loop)):  # type: ignore[attr-defined]
            object.__setattr__(moved, key, value)
        kept = (self.vertices, self._polygons)  # type: ignore[attr-defined]
        object.__setattr__(moved, "_polygons", _geometry(verts, self.faces, self._loop, label, kept))  # type: ignore[attr-defined]
        return moved


@dataclass(frozen=True, eq=False)
class Cages:
    """Several separate cages (polygons or cage meshes) that move together: one keyframe of
    ``{"cages": [...]}``, warped with ``--within`` (`warpcli.within.within_pair`).

    Its vertices are the cages' vertices, cage after cage, so that keyframes
    blend them as they blend one polygon's (`warpcli.keyframes.Keyframes`).

    Parameters
    ----------
    shapes : tuple of Polygon or Partition
    name : str
    """

    shapes: tuple[Polygon | Partition, ...]
    name: str = "cages"

    @property
    def points(self) -> NDArray[np.float64]:
        """(N, 2): every cage's vertices, cage after cage."""
        return np.concatenate([s.points for s in self.shapes])

    @property
    def n(self) -> int:
        """The number of vertices of all cages."""
        return sum(s.n for s in self.shapes)

    @property
    def structure(self) -> tuple:
        """What must not change from keyframe to keyframe: each cage's vertex count and faces."""
        return tuple((s.n, getattr(s, "faces", None)) for s in self.shapes)

    @property
    def turns(self) -> tuple[bool, ...]:
        """Which way round each cage runs (its signed area's sign)."""
        return tuple(s.signed_area > 0 for s in self.shapes)

    def moved(self, vertices: ArrayLike, name: str | None = None) -> Cages:
        """The same cages on other vertex positions (each validated again)."""
        v = np.asarray(vertices, dtype=np.float64)
        out, start = [], 0
        label = self.name if name is None else name
        for k, s in enumerate(self.shapes):
            part = v[start : start + s.n]
            start += s.n
            where = f"{label}: cage {k}"
            out.append(s.moved(part, where) if isinstance(s, Partition) else Polygon(part, name=where))
        return Cages(tuple(out), label)


def cages_of(doc: object, name: str) -> Cages | None:
    """The cages of a document ``{"cages": [SHAPE, ...]}`` (each a polygon, as a list of points or
    ``{"points": ...}``, or a cage mesh ``{"vertices", "faces"}``); None for any other document.

    Raises
    ------
    PolygonError
        One line naming the file (and the cage) and the problem.
    """
    if not (isinstance(doc, dict) and "cages" in doc):
        return None
    items = doc["cages"]
    if not isinstance(items, list) or not items:
        raise PolygonError(f'{name}: "cages" must be a non-empty list of polygons or cage meshes')
    cages: list[Polygon | Partition] = []
    for k, item in enumerate(items):
        where = f"{name}: cage {k}"
        mesh = partition_of(item, where)
        cages.append(mesh if mesh is not None else Polygon(points_of(item, where, None), name=where))
    return Cages(tuple(cages), name)


def validate_pair(src: Partition, dst: Partition, src_name: str | None = None, dst_name: str | None = None) -> None:
    """Check that two cage meshes correspond: the same vertex count and the same faces.

    Each is a valid partition already (checked on construction); with the same
    faces, they have the same combinatorics, and both run as their outlines
    do, so the map of every face goes the same way round.

    Parameters
    ----------
    src, dst : Partition
    src_name, dst_name : str or None
        How messages name them (default: their ``name``).

    Raises
    ------
    PolygonError
        One line naming the target's file and the face at fault.
    """
    sname = src.name if src_name is None else src_name
    dname = dst.name if dst_name is None else dst_name
    if dst.n != src.n:
        raise PolygonError(f"{dname}: cage mesh has {dst.n} vertices but {sname} has {src.n}")
    if dst.n_faces != src.n_faces:
        raise PolygonError(f"{dname}: cage mesh has {dst.n_faces} faces but {sname} has {src.n_faces}")
    for k, (a, b) in enumerate(zip(src.faces, dst.faces)):
        if a != b:
            flipped = sorted(a) == sorted(b) and _cyclic_equal(a, b[::-1])
            why = (
                "runs the other way round (the face is flipped over: the mesh folds there)" if flipped
                else f"is {list(b)} but {sname}'s face {k} is {list(a)}; both need the same faces"
            )  # fmt: skip
            raise PolygonError(f"{dname}: face {k} {why}")


def check_shapes(src: Polygon | Partition, dst: Polygon | Partition) -> None:
    """`check_pair` for two polygons, `validate_pair` for two cage meshes; a polygon and a mesh are refused.

    Raises
    ------
    PolygonError
        One line naming the target's file.
    """
    for shape in (src, dst):
        if isinstance(shape, Cages):
            raise PolygonError(
                f"{shape.name}: holds {len(shape.shapes)} separate cages: warp them with --within (an outline round "
                "them), or give one polygon or one cage mesh"
            )
    if isinstance(src, Partition) and isinstance(dst, Partition):
        validate_pair(src, dst)
    elif isinstance(src, Partition) or isinstance(dst, Partition):
        mesh, poly = (src, dst) if isinstance(src, Partition) else (dst, src)
        raise PolygonError(
            f"{poly.name}: holds one polygon but {mesh.name} is a cage mesh ({mesh.n_faces} faces); "
            "give both as cage meshes with the same faces, or both as polygons"
        )
    else:
        check_pair(src, dst)


def _cyclic_equal(a: tuple[int, ...], b: tuple[int, ...]) -> bool:
    if len(a) != len(b):
        return False
    doubled = tuple(b) + tuple(b)
    return any(doubled[i : i + len(a)] == tuple(a) for i in range(len(b)))


def _as_vertices(data: ArrayLike, name: str) -> NDArray[np.float64]:
    if isinstance(data, np.ndarray):
        if data.ndim != 2 or data.shape[1] != 2 or data.dtype.kind not in "iuf":
            raise PolygonError(f"{name}: vertices must be an (N, 2) array of numbers")
        pts = np.array(data, dtype=np.float64)
    else:
        if not isinstance(data, (list, tuple)):
            raise PolygonError(f'{name}: "vertices" must be an array of [x, y] pairs')
        for i, pair in enumerate(data):
            if not isinstance(pair, (list, tuple)) or len(pair) != 2:
                raise PolygonError(f"{name}: vertex {i} is not an [x, y] pair: {short_value(pair)}")
            for value in pair:
                if isinstance(value, LongInteger) or (
                    isinstance(value, int) and not isinstance(value, bool) and abs(value) > COORD_LIMIT
                ):
                    raise PolygonError(f"{name}: vertex {i} has a coordinate out of range: {short_value(value)}")
                if isinstance(value, bool) or not isinstance(value, (int, float)):
                    raise PolygonError(f"{name}: vertex {i} has a non-numeric coordinate: {short_value(value)}")
        pts = np.array(data, dtype=np.float64).reshape(-1, 2)
    bad = np.flatnonzero(~np.isfinite(pts).all(axis=1) | (np.abs(pts) > COORD_LIMIT).any(axis=1))
    if bad.size:
        i = int(bad[0])
        raise PolygonError(
            f"{name}: vertex {i} has a coordinate out of range: {pts[i].tolist()} "
            f"(coordinates must be finite and within +-{COORD_LIMIT:.0e} pixels)"
        )
    return pts


def _as_faces(data: object, n: int, name: str) -> tuple[tuple[int, ...], ...]:
    if isinstance(data, np.ndarray):
        data = data.tolist()
    if not isinstance(data, (list, tuple)) or not data:
        raise PolygonError(f'{name}: "faces" must be a non-empty array of arrays of vertex indices')
    out = []
    for k, face in enumerate(data):
        if isinstance(face, np.ndarray):
            face = face.tolist()
        if not isinstance(face, (list, tuple)):
            raise PolygonError(f"{name}: face {k} is not an array of vertex indices: {short_value(face)}")
        if len(face) < 3:
            raise PolygonError(f"{name}: face {k} has {len(face)} vertices; a face needs at least 3")
        idx = []
        for v in face:
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or not 0 <= v < n:
                raise PolygonError(
                    f"{name}: face {k} names vertex {short_value(v)}, but the vertices are numbered 0 to {n - 1}"
                )
            idx.append(int(v))
        if len(set(idx)) != len(idx):
            dup = next(v for v in idx if idx.count(v) > 1)
            raise PolygonError(f"{name}: face {k} passes through vertex {dup} twice; a face must be a simple polygon")
        out.append(tuple(idx))
    return tuple(out)


def _topology(faces: tuple[tuple[int, ...], ...], n: int, name: str) -> NDArray[np.intp]:
    """The combinatorial checks; the outline's vertex indices, in the faces' direction."""
    directed: dict[tuple[int, int], int] = {}
    for k, f in enumerate(faces):
        for j in range(len(f)):
            e = (f[j], f[(j + 1) % len(f)])
            if e in directed:
                raise PolygonError(
                    f"{name}: faces {directed[e]} and {k} both run along the edge from vertex {e[0]} to vertex "
                    f"{e[1]}; neighbouring faces run along their shared edge in opposite directions "
                    "(list every face the same way round), and faces must not overlap"
                )
            directed[e] = k
    used = np.zeros(n, dtype=bool)
    used[[v for f in faces for v in f]] = True
    if not used.all():
        raise PolygonError(f"{name}: vertex {int(np.flatnonzero(~used)[0])} belongs to no face")
    nxt: dict[int, int] = {}
    for a, b in directed:
        if (b, a) not in directed:
            if a in nxt:
                raise PolygonError(
                    f"{name}: the mesh's outline passes through vertex {a} twice (faces meet there at a single "
                    "point); faces must share whole edges"
                )
            nxt[a] = b
    # One piece: faces joined through shared edges.
    parent = list(range(len(faces)))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for (a, b), k in directed.items():
        other = directed.get((b, a))
        if other is not None:
            parent[root(k)] = root(other)
    pieces = {root(k) for k in range(len(faces))}
    if len(pieces) > 1:
        lone = next(k for k in range(len(faces)) if root(k) != root(0))
        raise PolygonError(
            f"{name}: the faces form {len(pieces)} separate pieces (face {lone} shares no edge with face 0's "
            "piece); a cage mesh is one piece: join them with faces between them"
        )
    if not nxt:
        raise PolygonError(f"{name}: the faces close up on themselves and have no outline")
    loops = []
    left = dict(nxt)
    while left:
        start = min(left)
        loop = [start]
        v = left.pop(start)
        while v != start:
            if v not in left:  # cannot happen: every boundary vertex has one edge in and one out
                raise PolygonError(f"{name}: the mesh's outline is broken at vertex {v}")
            loop.append(v)
            v = left.pop(v)
        loops.append(loop)
    edges = len(directed) - (len(directed) - len(nxt)) // 2
    euler = n - edges + len(faces)
    if len(loops) != 1 or euler != 1:
        raise PolygonError(
            f"{name}: the faces leave {len(loops) - 1 if len(loops) > 1 else 'a'} hole(s) (the outline has "
            f"{len(loops)} loops, Euler characteristic {euler}); a cage mesh covers a region without holes: "
            "fill each hole with a face"
        )
    return np.array(loops[0], dtype=np.intp)


def _turn(area: float) -> str:
    return "clockwise" if area > 0 else "counter-clockwise"


def _corner_angles(points: NDArray[np.float64], positive: bool) -> NDArray[np.float64]:
    """Interior angle at each vertex of a simple polygon running ``positive``-ly (signed area > 0), in (0, 2 pi)."""
    u = np.roll(points, 1, axis=0) - points  # towards the previous vertex
    w = np.roll(points, -1, axis=0) - points  # towards the next
    cross = w[:, 0] * u[:, 1] - w[:, 1] * u[:, 0]
    dot = (w * u).sum(axis=1)
    ang = np.arctan2(cross if positive else -cross, dot)
    return np.mod(ang, 2 * np.pi)


def _geometry(
    verts: NDArray[np.float64],
    faces: tuple[tuple[int, ...], ...],
    loop: NDArray[np.intp],
    name: str,
    kept: tuple[NDArray[np.float64], tuple[Polygon, tuple[Polygon, ...]]] | None = None,
) -> tuple[Polygon, tuple[Polygon, ...]]:
    """The geometric checks of one side (see the module's docstring); the outline and the faces, checked.

    ``kept``: the vertices and polygons of the same faces checked before; a
    polygon whose points are the same is taken from there (renamed), not
    checked again.
    """

    def polygon(index: NDArray[np.intp] | list[int], label: str, old: Polygon | None) -> Polygon:
        points = verts[index]
        if old is not None and kept is not None and np.array_equal(kept[0][index], points):
            return old.renamed(label)
        return Polygon(points, name=label)

    outline = polygon(loop, f"{name} (the cage mesh's outline)", kept[1][0] if kept else None)
    positive = outline.signed_area > 0
    total = np.zeros(len(verts))
    polygons = []
    for k, f in enumerate(faces):
        poly = polygon(list(f), f"{name}: face {k}", kept[1][1][k] if kept else None)
        polygons.append(poly)
        if (poly.signed_area > 0) != positive:
            raise PolygonError(
                f"{name}: face {k} runs {_turn(poly.signed_area)} but the mesh's outline runs "
                f"{_turn(outline.signed_area)}: face {k} is flipped over (the mesh folds there)"
            )
        np.add.at(total, list(f), _corner_angles(poly.points, positive))
    expected = np.full(len(verts), 2 * np.pi)
    expected[loop] = _corner_angles(verts[loop], positive)
    winding = np.rint((total - expected) / (2 * np.pi)).astype(np.int64)
    bad = np.flatnonzero(winding != 0)
    if bad.size:
        v = int(bad[0])
        where = "at" if v in set(loop.tolist()) else "round"
        raise PolygonError(
            f"{name}: the faces {where} vertex {v} {format_point(verts[v])} overlap: their angles there sum to "
            f"{math.degrees(total[v]):.6g} degrees, not {math.degrees(expected[v]):.6g}"
        )
    return outline, tuple(polygons)


# ---------------------------------------------------------------- files


def is_partition_document(doc: object, label: str | None = None) -> bool:
    """Whether a parsed polygon file holds a cage mesh rather than one polygon.

    A plain object with a ``"faces"`` member, a labelme file with several
    polygon shapes, a GeoJSON ``FeatureCollection`` with several polygon
    features or a ``MultiPolygon`` (without ``label``: a label chooses one
    polygon, as before).
    """
    if not isinstance(doc, dict):
        return False
    if "faces" in doc:
        return True
    if label is not None:
        return False
    if "shapes" in doc and isinstance(doc["shapes"], list):
        return len(_labelme_polygons(doc)) > 1
    kind = doc.get("type")
    if kind == "FeatureCollection" and isinstance(doc.get("features"), list):
        return len([f for f in doc["features"] if isinstance(f, dict)]) > 1
    if kind == "MultiPolygon":
        return True
    geometry = doc.get("geometry") if kind == "Feature" else None
    return isinstance(geometry, dict) and geometry.get("type") == "MultiPolygon"


def _labelme_polygons(doc: dict) -> list:
    return [s for s in doc["shapes"] if isinstance(s, dict) and s.get("shape_type", "polygon") == "polygon"]


def partition_of(doc: object, name: str, label: str | None = None) -> Partition | None:
    """The cage mesh of a parsed polygon file, or None if it holds one polygon (`is_partition_document`).

    Raises
    ------
    PolygonError
        If the mesh is invalid; one line starting with ``name``.
    """
    if not is_partition_document(doc, label):
        return None
    assert isinstance(doc, dict)
    if "faces" in doc:
        if label is not None:
            raise PolygonError(f"{name}: a cage mesh has no labels, but label {label!r} was asked for")
        if "vertices" not in doc:
            raise PolygonError(f'{name}: a cage mesh has "faces" but no "vertices"')
        return Partition(doc["vertices"], doc["faces"], name)
    if "shapes" in doc:
        shapes = _labelme_polygons(doc)
        rings = [s.get("points") for s in shapes]
        what, labels = "labelme", [s.get("label") for s in shapes]
    else:
        rings = _geojson_rings(doc, name)
        what, labels = "GeoJSON", []
    try:
        return welded(rings, name, f"{what} polygon")
    except PolygonError as err:
        # Several polygons meant as one of them, with the label forgotten, must
        # read as before: name both readings.
        reason = str(err).removeprefix(f"{name}: ")
        text = [v if isinstance(v, str) and v.isprintable() and len(v) <= 40 else short_value(v) for v in labels[:10]]
        shown = f" ({', '.join(text)}{', ...' if len(labels) > 10 else ''})" if labels else ""
        raise PolygonError(
            f"{name}: {what} file has {len(rings)} polygons{shown}, which do not form a cage mesh ({reason}); "
            "choose one with a label option"
        ) from None


def _geojson_rings(doc: dict, name: str) -> list:
    geometries = []
    if doc.get("type") == "FeatureCollection":
        for feature in doc["features"]:
            if isinstance(feature, dict):
                geometries.append(feature.get("geometry") if feature.get("type") == "Feature" else feature)
    elif doc.get("type") == "Feature":
        geometries.append(doc.get("geometry"))
    else:
        geometries.append(doc)
    rings = []
    for g in geometries:
        if not isinstance(g, dict) or g.get("type") not in ("Polygon", "MultiPolygon"):
            raise PolygonError(f"{name}: GeoJSON feature {len(rings)} is not a Polygon")
        polys = [g.get("coordinates")] if g["type"] == "Polygon" else g.get("coordinates")
        if not isinstance(polys, list):
            raise PolygonError(f"{name}: GeoJSON {g['type']} has no coordinates")
        for p in polys:
            if not isinstance(p, list) or not p:
                raise PolygonError(f"{name}: GeoJSON polygon {len(rings)} has no coordinates")
            if len(p) > 1:
                raise PolygonError(f"{name}: GeoJSON polygon {len(rings)} has holes; cage mesh faces have none")
            ring = p[0]
            if not isinstance(ring, list) or len(ring) < 2 or ring[0] != ring[-1]:
                raise PolygonError(f"{name}: GeoJSON ring {len(rings)} must end with its first vertex")
            rings.append(ring[:-1])
    return rings


def welded(rings: list, name: str, what: str = "polygon", tolerance: float = WELD_TOLERANCE) -> Partition:
    """A cage mesh from several polygons, their vertices welded within ``tolerance`` pixels.

    Vertices are numbered in order of first appearance; a vertex closer than
    ``tolerance`` to one already numbered is that vertex (its first
    coordinates are kept). Every polygon is turned to run as the first one
    does, so that files drawn in either direction read alike; a target face
    flipped over then differs from the source's (`validate_pair` says so).

    Parameters
    ----------
    rings : list of (n_k, 2) array_like
        The polygons' vertices.
    name : str
    what : str
        What a ring is called in messages.
    tolerance : float

    Raises
    ------
    PolygonError
        If a polygon is invalid, has two vertices welded into one, or the
        faces do not form a cage mesh.
    """
    points: list[list[float]] = []
    buckets: dict[tuple[int, int], list[int]] = {}
    faces = []
    sign = 0.0
    cell = max(tolerance, 1e-300)
    for k, ring in enumerate(rings):
        poly = Polygon(ring, name=f"{name}: {what} {k}")
        face = []
        for p in poly.points:
            cx, cy = math.floor(p[0] / cell), math.floor(p[1] / cell)
            found = None
            for dx in (-1, 0, 1):
                for dy in (-1, 0, 1):
                    for i in buckets.get((cx + dx, cy + dy), ()):
                        if math.hypot(points[i][0] - p[0], points[i][1] - p[1]) <= tolerance:
                            found = i if found is None else min(found, i)
            if found is None:
                found = len(points)
                points.append([float(p[0]), float(p[1])])
                buckets.setdefault((cx, cy), []).append(found)
            if found in face:
                raise PolygonError(
                    f"{name}: {what} {k} has two vertices within {tolerance:g} px of vertex {found} "
                    f"{format_point(points[found])}, which would weld into one"
                )
            face.append(found)
        if k == 0:
            sign = poly.signed_area
        elif (poly.signed_area > 0) != (sign > 0):
            face = [face[0], *face[:0:-1]]
        faces.append(face)
    return Partition(np.array(points, dtype=np.float64).reshape(-1, 2), faces, name)


def read_shape(path: str | os.PathLike[str], label: str | None = None) -> Polygon | Partition:
    """Read a polygon file holding one polygon (a `Polygon`) or a cage mesh (a `Partition`).

    A cage mesh is a JSON object ``{"vertices": [[x, y], ...], "faces": [[i,
    j, k, ...], ...]}``, or a labelme or GeoJSON file with several polygons
    (welded within `WELD_TOLERANCE`), read without a label; anything else is
    read as `warpcli.polygon.read_polygon` reads it.

    Parameters
    ----------
    path : path-like
        The polygon file.
    label : str or None
        Which polygon of a labelme or GeoJSON file holding several: then one
        polygon is read, as `warpcli.polygon.read_polygon` reads it.

    Returns
    -------
    Polygon or Partition

    Examples
    --------
    >>> import json, os, tempfile
    >>> path = os.path.join(tempfile.mkdtemp(), "cage.json")
    >>> square = [[0, 0], [10, 0], [20, 0], [20, 10], [10, 10], [0, 10]]
    >>> with open(path, "w") as fh:
    ...     json.dump({"vertices": square, "faces": [[0, 1, 4, 5], [1, 2, 3, 4]]}, fh)
    >>> mesh = read_shape(path)
    >>> mesh.n_faces, mesh.outline.points.tolist()
    (2, [[0.0, 0.0], [10.0, 0.0], [20.0, 0.0], [20.0, 10.0], [10.0, 10.0], [0.0, 10.0]])

    Raises
    ------
    PolygonError
        As `warpcli.polygon.read_polygon`, and for an invalid cage mesh.
    """
    name, doc = read_document(path)
    try:
        found = partition_of(doc, name, label)
        return found if found is not None else Polygon(points_of(doc, name, label), name=name)
    except RecursionError as err:
        raise PolygonError(f"{name}: invalid polygon file: arrays nested too deeply") from err


def read_partition(path: str | os.PathLike[str]) -> Partition:
    """Read a cage mesh file (see `read_shape`).

    Parameters
    ----------
    path : path-like
        A JSON cage mesh, or a labelme or GeoJSON file with several polygons.

    Returns
    -------
    Partition

    Raises
    ------
    PolygonError
        If the file holds one polygon, or an invalid cage mesh.
    """
    shape = read_shape(path)
    if not isinstance(shape, Partition):
        raise PolygonError(f"{os.fspath(path)}: holds one polygon, not a cage mesh (no \"faces\", not several polygons)")
    return shape
