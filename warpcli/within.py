"""A retouch within a fixed outline (``--within``): the cages and the ring around them as one cage mesh.

A retouch pasted over its image (``--outside input``) leaves a seam where the
target's edge moved and a ghost where the source was vacated. Within a fixed
outline (the image's rectangle, the cages' box grown by a margin, or a
polygon) the picture moves as one piece instead: the cages move, the outline
stays, and the ring between them is mapped too. `within_pair` makes that one
cage mesh per side:

- the faces of the cages: a polygon is one face, a cage mesh
  (`warpcli.polygon.partition.Partition`) keeps its faces;
- the faces of the ring, cut compatibly on both sides by
  `warpcli.polygon.outline.cut_ring` (design (a) of issue 21).

`warpcli.maps.cage.build_cage_map` maps it like any cage mesh: continuous
across every cage edge and cut (exactly for FEM), bijective and certified
when every face map is, the identity on the outline. Outside the outline the
output is the input's own pixels (the retouch's paste, ``outside="input"``).

Several cages go into one outline (both eyes at once): give a sequence of
shapes, or a file read by `read_cages` (a labelme or GeoJSON file with
several polygons that do not form one mesh, or ``{"cages": [SHAPE, ...]}``).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import PolygonError
from .polygon import Polygon
from .polygon.formats import points_of, read_document
from .polygon.outline import cut_ring, outline_polygon
from .polygon.partition import WELD_TOLERANCE, Cages, Partition, cages_of, welded
from .report.seam import crossing_pairs

__all__ = ["WithinPair", "read_cages", "read_within_pair", "within_pair", "within_seams"]

Shape = Polygon | Partition


@dataclass(frozen=True)
class WithinPair:
    """The cage mesh of a retouch within an outline, on both sides.

    Attributes
    ----------
    src, dst : Partition
        The same faces on both sides: the cages' faces first (face ``k`` for
        ``k < cage_faces``), then the ring's. The outline's points are the
        same on both sides.
    outline : (m, 2) ndarray of float
        The fixed outline.
    cage_faces : int
        How many faces the cages have (the first ones).
    cage_loops : tuple of tuple of int
        Each cage's outline as vertex indices, in order.
    cuts : tuple of (int, int)
        The edges between two ring faces (the cuts of the ring), as vertex
        index pairs.
    """

    src: Partition
    dst: Partition
    outline: NDArray[np.float64]
    cage_faces: int
    cage_loops: tuple[tuple[int, ...], ...]
    cuts: tuple[tuple[int, int], ...]


def _as_cages(shapes: Shape | Cages | Sequence[Shape]) -> list[Shape]:
    if isinstance(shapes, (Polygon, Partition)):
        return [shapes]
    if isinstance(shapes, Cages):
        return list(shapes.shapes)
    return list(shapes)


def _loop_and_faces(shape: Shape) -> tuple[NDArray[np.intp], NDArray[np.float64], tuple[tuple[int, ...], ...]]:
    """A cage's outline (vertex indices into its own vertices), its vertices and its faces."""
    if isinstance(shape, Partition):
        return shape.loops[0], shape.vertices, shape.faces
    n = len(shape.points)
    return np.arange(n), shape.points, (tuple(range(n)),)


def within_pair(
    src: Shape | Sequence[Shape],
    dst: Shape | Sequence[Shape],
    within: str,
    image_size: tuple[int, int],
    *,
    label: str | None = None,
) -> WithinPair:
    """The cages and the ring between them and a fixed outline, as one cage mesh on each side.

    Parameters
    ----------
    src, dst : Polygon, Partition, or sequence of them
        The cages, source and target: cage ``k`` of ``src`` moves onto cage
        ``k`` of ``dst`` (same vertex count, a mesh with the same faces).
    within : str
        ``"image"``, a margin in pixels, or a polygon file
        (`warpcli.polygon.outline.outline_polygon`).
    image_size : (width, height)
        The image's size (the output's: a retouch keeps it).
    label : str or None
        Which polygon of an outline file holding several.

    Returns
    -------
    WithinPair

    Raises
    ------
    PolygonError
        One line naming the cage and the vertex where no fold-free cut of
        the ring exists (a cage outside the outline or crossing another, a
        vertex moved too far), or the cages do not correspond.

    Examples
    --------
    >>> cage = Polygon([[4, 4], [6, 4], [6, 6], [4, 6]])
    >>> moved = Polygon([[4, 4], [6.5, 4.5], [6, 6], [4, 6]])
    >>> pair = within_pair(cage, moved, "image", (10, 10))
    >>> pair.cage_faces, pair.src.outline.points.tolist() == pair.dst.outline.points.tolist()
    (1, True)
    """
    srcs, dsts = _as_cages(src), _as_cages(dst)
    if not srcs or len(srcs) != len(dsts):
        raise PolygonError(f"--within: {len(srcs)} source cage(s) but {len(dsts)} target cage(s)")
    loops, src_loops, dst_loops, src_names, dst_names = [], [], [], [], []
    sign = 0.0
    for k, (a, b) in enumerate(zip(srcs, dsts)):
        if isinstance(a, Partition) != isinstance(b, Partition):
            raise PolygonError(f"{b.name}: cage {k} is a cage mesh on one side and a polygon on the other")
        if isinstance(a, Partition):
            assert isinstance(b, Partition)
            if a.faces != b.faces:
                raise PolygonError(f"{b.name}: cage {k}'s faces differ from {a.name}'s")
        elif len(a.points) != len(b.points):
            raise PolygonError(f"{b.name}: cage {k} has {len(b.points)} vertices but {a.name} has {len(a.points)}")
        loop, _, _ = _loop_and_faces(a)
        area = a.signed_area
        if k == 0:
            sign = math.copysign(1.0, area)
        reverse = math.copysign(1.0, area) != sign  # cut_ring takes every cage one way round: turn a polygon over
        if reverse and isinstance(a, Partition):
            raise PolygonError(f"{a.name}: cage {k} runs the other way round than cage 0; reverse its faces")
        loop = loop[::-1] if reverse else loop
        loops.append((loop, reverse))
        src_loops.append(_loop_and_faces(a)[1][loop])
        dst_loops.append(_loop_and_faces(b)[1][loop])
        src_names.append(a.name if len(srcs) == 1 else f"{a.name} cage {k}")
        dst_names.append(b.name if len(dsts) == 1 else f"{b.name} cage {k}")
    outline = outline_polygon(within, image_size, src_loops + dst_loops, label=label)
    name = "the image's outline" if str(within).strip() == "image" else f"--within {within}"
    sv, dv, ring = cut_ring(outline, src_loops, dst_loops, name=name, src_names=src_names, dst_names=dst_names)
    # The cages' vertices off their outlines (a mesh's inner vertices) come after cut_ring's.
    extra_src, extra_dst = [], []
    faces: list[tuple[int, ...]] = []
    cage_loops = []
    start, n_all = 0, len(sv)
    for (a, b), (loop, reverse) in zip(zip(srcs, dsts), loops):
        _, va, own_faces = _loop_and_faces(a)
        vb = _loop_and_faces(b)[1]
        index = np.full(len(va), -1, dtype=np.intp)
        index[loop] = start + np.arange(len(loop))
        cage_loops.append(tuple(int(i) for i in index[loop]))
        start += len(loop)
        inner = np.flatnonzero(index < 0)
        index[inner] = n_all + np.arange(len(inner))
        n_all += len(inner)
        extra_src.append(va[inner])
        extra_dst.append(vb[inner])
        for f in own_faces:
            face = tuple(int(index[v]) for v in f)
            faces.append(face[::-1] if reverse else face)
    cage_faces = len(faces)
    faces.extend(ring)
    src_v = np.concatenate([sv, *extra_src])
    dst_v = np.concatenate([dv, *extra_dst])
    cuts = _cuts(ring)
    src_mesh = Partition(src_v, faces, f"{srcs[0].name} within {name}")
    dst_mesh = Partition(dst_v, faces, f"{dsts[0].name} within {name}")
    return WithinPair(src_mesh, dst_mesh, outline, cage_faces, tuple(cage_loops), cuts)


def _cuts(ring: Sequence[Sequence[int]]) -> tuple[tuple[int, int], ...]:
    """Edges used by two ring faces (once each way)."""
    directed = set()
    for f in ring:
        for j in range(len(f)):
            directed.add((int(f[j]), int(f[(j + 1) % len(f)])))
    return tuple(sorted((a, b) for a, b in directed if a < b and (b, a) in directed))


def within_seams(values: ArrayLike, jacobian: ArrayLike | None, pair: WithinPair) -> dict:
    """The jumps of neighbouring output values (and of the map's Jacobian) across cage edges and cuts, and elsewhere.

    For every pair of 4-neighbouring output pixels, the largest difference of
    their values over the channels (`warpcli.report.seam.seam_jump`'s
    measure): pairs on either side of a cage's target edge are *cage_edges*,
    on either side of a cut of the ring *cuts*, on either side of the outline
    *outline*, the other pairs inside the outline's box *elsewhere*. A seam
    shows as an across maximum far above the elsewhere one.

    Parameters
    ----------
    values : (H, W) or (H, W, C) array_like of float
        The output image.
    jacobian : (H, W, 2, 2) array_like of float or None
        The inverse map's Jacobian at every output pixel (NaN outside the
        outline: taken there as the identity, the input's own), or None.
    pair : WithinPair

    Returns
    -------
    dict
        ``{"values": {...}, "jacobian": {...}}``, each with the maximum and
        mean jump per kind of line and the 99th percentile elsewhere.
    """
    v = np.asarray(values, dtype=np.float64)
    if v.ndim == 2:
        v = v[:, :, None]
    h, w = v.shape[:2]
    verts = pair.dst.vertices
    lines = {
        "cage_edges": [(verts[list(loop)], True) for loop in pair.cage_loops],
        "cuts": [(verts[[a, b]], False) for a, b in pair.cuts],
        "outline": [(pair.outline, True)],
    }
    masks = {}
    for kind, polylines in lines.items():
        hor = np.zeros((h, max(w - 1, 0)), dtype=bool)
        ver = np.zeros((max(h - 1, 0), w), dtype=bool)
        for poly, closed in polylines:
            a, b = crossing_pairs(poly, w, h, closed=closed)
            hor |= a
            ver |= b
        masks[kind] = (hor, ver)
    # Elsewhere: inside the outline's box, so that the untouched input beyond does not dilute it.
    x0, y0 = np.floor(pair.outline.min(axis=0)).astype(int)
    x1, y1 = np.ceil(pair.outline.max(axis=0)).astype(int)
    box = np.zeros((h, w), dtype=bool)
    box[max(y0, 0) : max(y1, 0), max(x0, 0) : max(x1, 0)] = True
    out = {}
    fields = {"values": v}
    if jacobian is not None:
        jac = np.asarray(jacobian, dtype=np.float64).reshape(h, w, 4)
        # Outside the outline the output is the input: the map's Jacobian there is the identity.
        fields["jacobian"] = np.where(np.isfinite(jac), jac, np.array([1.0, 0.0, 0.0, 1.0]))
    for field, data in fields.items():
        diffs = ((data[:, 1:] - data[:, :-1], 0, box[:, 1:] & box[:, :-1]), (data[1:] - data[:-1], 1, box[1:] & box[:-1]))
        doc: dict[str, float | int] = {}
        for kind in lines:
            jumps = []
            for diff, axis, _ in diffs:
                jump = np.abs(diff).max(axis=2)
                jumps.append(jump[masks[kind][axis] & np.isfinite(jump)])
            j = np.concatenate(jumps)
            doc[f"{kind}_max"] = float(j.max()) if j.size else 0.0
            doc[f"{kind}_mean"] = float(j.mean()) if j.size else 0.0
            doc[f"{kind}_pairs"] = int(j.size)
        rest = []
        for diff, axis, inbox in diffs:
            jump = np.abs(diff).max(axis=2)
            crossing = np.zeros_like(inbox)
            for kind in lines:
                crossing |= masks[kind][axis]
            rest.append(jump[inbox & ~crossing & np.isfinite(jump)])
        r = np.concatenate(rest)
        doc["elsewhere_max"] = float(r.max()) if r.size else 0.0
        doc["elsewhere_p99"] = float(np.percentile(r, 99)) if r.size else 0.0
        doc["elsewhere_mean"] = float(r.mean()) if r.size else 0.0
        out[field] = doc
    return out


def read_within_pair(
    src_path: str | os.PathLike[str],
    dst_path: str | os.PathLike[str],
    within: str,
    image_size: tuple[int, int],
    *,
    src_label: str | None = None,
    dst_label: str | None = None,
    frame: int | None = None,
) -> WithinPair:
    """`within_pair` of the cages two files hold: `read_cages`, or at ``frame`` of keyframed files
    (`warpcli.keyframes.read_shape_at`), as every run from files reads a retouch (the warp and points).

    Raises
    ------
    PolygonError
        As `read_cages`, `read_shape_at` and `within_pair`.
    """
    from .keyframes import read_shape_at

    if frame is None:
        src, dst = read_cages(src_path, src_label), read_cages(dst_path, dst_label)
    else:
        src, dst = read_shape_at(src_path, src_label, frame), read_shape_at(dst_path, dst_label, frame)
    return within_pair(src, dst, within, image_size)


def read_cages(path: str | os.PathLike[str], label: str | None = None) -> tuple[Shape, ...]:
    """Read one or several cages from a polygon file.

    Several cages (both eyes at once) are given as a labelme or GeoJSON file
    with several polygons read without ``label``: polygons sharing vertices
    (welded within `WELD_TOLERANCE`) form one cage mesh, and the separate
    pieces are separate cages, in order of their first polygon; or as a JSON
    object ``{"cages": [SHAPE, ...]}`` whose items are polygons (a list of
    points or ``{"points": ...}``) or cage meshes (``{"vertices", "faces"}``).
    Anything else is one cage, as `warpcli.polygon.partition.read_shape`
    reads it.

    Parameters
    ----------
    path : path-like
    label : str or None
        Which polygon of a labelme or GeoJSON file holding several (then one cage).

    Returns
    -------
    tuple of Polygon or Partition

    Raises
    ------
    PolygonError
        One line naming the file and the problem.
    """
    name, doc = read_document(path)
    found = cages_of(doc, name)
    if found is not None:
        return found.shapes
    count = _polygon_count(doc) if label is None else 1
    if count <= 1:
        from .polygon.partition import read_shape

        return (read_shape(name, label),)
    rings = [points_of(doc, name, f"#{i}") for i in range(count)]
    try:
        return (welded(rings, name),)
    except PolygonError:
        pass  # separate pieces: a cage each
    return tuple(
        welded([rings[i] for i in group], name) if len(group) > 1 else Polygon(rings[group[0]], name=f"{name} #{group[0]}")
        for group in _pieces(rings)
    )


def _polygon_count(doc: object) -> int:
    """How many polygons a labelme or GeoJSON document holds (1 for anything else)."""
    if not isinstance(doc, dict):
        return 1
    if isinstance(doc.get("shapes"), list):
        return sum(1 for s in doc["shapes"] if isinstance(s, dict) and s.get("shape_type", "polygon") == "polygon")
    geometry = doc.get("geometry") if doc.get("type") == "Feature" else doc
    if doc.get("type") == "FeatureCollection" and isinstance(doc.get("features"), list):
        return sum(
            len(f["geometry"].get("coordinates") or ()) if isinstance(f, dict) and isinstance(f.get("geometry"), dict)
            and f["geometry"].get("type") == "MultiPolygon" else 1
            for f in doc["features"]
        )
    if isinstance(geometry, dict) and geometry.get("type") == "MultiPolygon":
        return len(geometry.get("coordinates") or ())
    return 1


def _pieces(rings: list) -> list[list[int]]:
    """The rings grouped into pieces: rings with a vertex within `WELD_TOLERANCE` of each other's are one piece."""
    pts = [np.asarray(r, dtype=np.float64).reshape(-1, 2) for r in rings]
    parent = list(range(len(rings)))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i in range(len(pts)):
        for j in range(i + 1, len(pts)):
            d = np.hypot(*(pts[i][:, None, :] - pts[j][None, :, :]).transpose(2, 0, 1))
            if (d <= WELD_TOLERANCE).any():
                parent[root(j)] = root(i)
    groups: dict[int, list[int]] = {}
    for i in range(len(pts)):
        groups.setdefault(root(i), []).append(i)
    return list(groups.values())
