"""The ring between a fixed outline and the cages inside it, cut into simple faces valid on both sides.

A retouch within an outline (``--within``) moves one or several cages and
keeps the outline fixed; the region between them (the *ring*) must be mapped
too, so that nothing is vacated and no edge is left behind. `cut_ring` cuts
that ring into a few simple polygons, *compatibly*: the same faces, by vertex
index, are simple polygons with one orientation in the source (cages at their
source positions) and in the target (cages moved), so that a cage-mesh map
that maps every face bijectively maps the whole outline bijectively.

How (design (a) of issue 21):

1. points are inserted along the outline (identical on both sides), so that
   every cage vertex sees outline points nearby;
2. the ring is triangulated without Steiner points (constrained Delaunay of
   the source ring, else of the target ring, else of rings in between), and
   every triangle's orientation is tested on both sides with exact
   predicates; edge flips repair the few that fold. A triangulation whose
   triangles all keep their orientation on both sides maps the ring
   bijectively (the degree of a map whose boundary goes once round the
   target ring is 1 inside it, and every triangle counts +1). Where no
   triangulation of the boundary's points alone does (a pocket of a cage
   changing shape), a quality mesh of the source ring with interior points
   is used, the points carried to the target by the harmonic extension of
   the cages' moves (mean-value weights), finer meshes until none folds
   (then the same from the target ring back to the source);
3. triangles are merged greedily into few, fat faces (the merge with the
   roundest result first: the isoperimetric quotient), a merge kept only if the union stays a disk (one boundary cycle,
   no vertex twice) that passes `validate_points` on both sides: a disk made
   of such triangles is a simple polygon on both sides.

Where no such cut exists without interior points (a cage vertex outside the
outline, cages overlapping, a cage crossing the outline, a vertex moved so far
that every triangulation folds), `PolygonError` names the cage and the vertex.

`outline_polygon` makes the outline of ``--within image|MARGIN|FILE.json``.
"""

from __future__ import annotations

import heapq
import math
import os
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._arrays import median
from .._switches import decimal
from ..errors import PolygonError
from ..options import outline_file
from .messages import format_number, format_point
from .predicates import orient_sign, orient_sign_one, point_segment_distance, segments_touch, signed_area
from .validate import clearance_floor, validate_points

__all__ = ["cut_ring", "outline_polygon"]

#: Points on the outline per cage vertex (at least `MIN_OUTLINE_POINTS` in all),
#: spread along it by length: enough for every cage vertex to see outline
#: points close by, few enough that the faces stay few.
OUTLINE_POINTS_PER_CAGE_VERTEX = 1.0
#: The fewest points the outline is given.
MIN_OUTLINE_POINTS = 12
#: Edge flips tried to repair a triangulation, per triangle.
FLIPS_PER_TRIANGLE = 8


def outline_polygon(
    within: str,
    image_size: tuple[int, int],
    cages: Sequence[ArrayLike],
    *,
    label: str | None = None,
) -> NDArray[np.float64]:
    """The fixed outline of ``--within``: the image, the cages' box grown by a margin, or a polygon file.

    Parameters
    ----------
    within : str
        ``"image"``: the image's rectangle; a number MARGIN > 0: the bounding
        box of all ``cages`` grown by MARGIN pixels on every side, clipped to
        the image; anything else: a polygon file (`warpcli.polygon.read_polygon`).
    image_size : (width, height)
    cages : sequence of (n, 2) array_like of float
        Every cage, source and target (the outline must hold them all).
    label : str or None
        Which polygon of a file holding several.

    Returns
    -------
    (m, 2) ndarray of float
        The outline's vertices, in the first cage's orientation for a
        rectangle, as the file gives them otherwise.

    Raises
    ------
    PolygonError
        If MARGIN is not positive and finite, or the file is not a polygon.

    Examples
    --------
    >>> outline_polygon("image", (4, 3), [[[1, 1], [2, 1], [2, 2]]]).tolist()
    [[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]]
    >>> outline_polygon("0.5", (4, 3), [[[1, 1], [2, 1], [2, 2]]]).tolist()
    [[0.5, 0.5], [2.5, 0.5], [2.5, 2.5], [0.5, 2.5]]
    """
    width, height = image_size
    orientation = 1.0
    if cages:
        orientation = math.copysign(1.0, signed_area(np.asarray(cages[0], dtype=np.float64)))
    text = str(within).strip()
    path = outline_file(within)
    if path is not None:
        from .formats import read_polygon

        return np.array(read_polygon(os.fspath(path), label).points)
    if text == "image":
        box = (0.0, 0.0, float(width), float(height))
    else:
        margin = float(text)
        if not (margin > 0 and math.isfinite(margin)):
            raise PolygonError(f"--within {within}: the margin must be a positive number of pixels")
        if not cages:
            raise PolygonError(f"--within {within}: a margin needs the cages it surrounds")
        pts = np.concatenate([np.asarray(c, dtype=np.float64).reshape(-1, 2) for c in cages])
        lo, hi = pts.min(axis=0) - margin, pts.max(axis=0) + margin
        box = (max(0.0, lo[0]), max(0.0, lo[1]), min(float(width), hi[0]), min(float(height), hi[1]))
        if not (box[0] < box[2] and box[1] < box[3]):
            raise PolygonError(f"--within {within}: the cages' box grown by {text} px misses the image")
    x0, y0, x1, y1 = box
    rect = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=np.float64)
    return rect if orientation > 0 else rect[::-1].copy()


def cut_ring(
    outline: ArrayLike,
    src_cages: Sequence[ArrayLike],
    dst_cages: Sequence[ArrayLike],
    *,
    name: str = "the outline",
    src_names: Sequence[str] | None = None,
    dst_names: Sequence[str] | None = None,
    min_convexity: float = 0.0,
) -> tuple[NDArray[np.float64], NDArray[np.float64], tuple[tuple[int, ...], ...]]:
    """Cut the region between a fixed outline and one or several cages into simple faces, compatibly.

    Parameters
    ----------
    outline : (m, 2) array_like of float
        The fixed outline: a simple polygon holding every cage, source and
        target, strictly inside.
    src_cages, dst_cages : sequence of (n_k, 2) array_like of float
        Each cage's source and target polygon (the same vertex count), all in
        one orientation.
    name : str
        How messages name the outline.
    src_names, dst_names : sequence of str or None
        How messages name each cage's source and target (default
        ``"source cage k"``, ``"target cage k"``).
    min_convexity : float
        Keep a merge of faces only if the merged face's area is at least this
        share of its convex hull's, on both sides (0: merge while the faces
        stay simple; then the ring around k cages has 2 faces, or a few more).

    Returns
    -------
    src_vertices, dst_vertices : (N, 2) ndarray of float
        The cage loops in order (cage 0's vertices, then cage 1's, ...), then
        the outline's points (its vertices, and the points inserted on its
        edges, in order along it), identical in both, then the interior
        points of the cut, if it needed any (each strictly inside the
        outline, at its own place on each side).
    faces : tuple of tuple of int
        The ring's faces (not the cages' interiors), each a simple polygon in
        both ``src_vertices`` and ``dst_vertices`` that passes
        `validate_points`, all with the orientation of the cage loops. With
        the cage interiors they tile the outline: every edge between two
        faces, or between a face and a cage, is used once in each direction,
        and every outline edge once.

    Raises
    ------
    PolygonError
        One line naming the cage and the vertex: a cage vertex outside the
        outline, a cage crossing the outline or another cage, a cage running
        the other way round, or a vertex moved so far that no triangulation
        of the ring keeps its orientation on both sides.

    Examples
    --------
    >>> square = [[0, 0], [10, 0], [10, 10], [0, 10]]
    >>> cage = [[4, 4], [6, 4], [6, 6], [4, 6]]
    >>> moved = [[4, 4], [6.5, 4.5], [6, 6], [4, 6]]
    >>> src, dst, faces = cut_ring(square, [cage], [moved])
    >>> bool((src[4:] == dst[4:]).all()), len(faces) >= 2
    (True, True)
    """
    out = np.asarray(outline, dtype=np.float64).reshape(-1, 2)
    validate_points(out, name)
    if len(src_cages) != len(dst_cages) or not src_cages:
        raise PolygonError(f"{name}: {len(src_cages)} source cages but {len(dst_cages)} target cages")
    k = len(src_cages)
    snames = list(src_names) if src_names is not None else [f"source cage {i}" for i in range(k)]
    dnames = list(dst_names) if dst_names is not None else [f"target cage {i}" for i in range(k)]
    src = [np.asarray(c, dtype=np.float64).reshape(-1, 2) for c in src_cages]
    dst = [np.asarray(c, dtype=np.float64).reshape(-1, 2) for c in dst_cages]
    for i in range(k):
        validate_points(src[i], snames[i])
        validate_points(dst[i], dnames[i])
        if len(src[i]) != len(dst[i]):
            raise PolygonError(f"{dnames[i]}: cage has {len(dst[i])} vertices but {snames[i]} has {len(src[i])}")
    sign = math.copysign(1.0, signed_area(src[0]))
    for i in range(k):
        for cage, label in ((src[i], snames[i]), (dst[i], dnames[i])):
            if math.copysign(1.0, signed_area(cage)) != sign:
                raise PolygonError(
                    f"{label}: vertex 0: the cage runs the other way round than {snames[0]}; reverse its vertex order"
                )
    for cages, names in ((src, snames), (dst, dnames)):
        _check_inside(out, cages, names, name)
        _check_apart(cages, names)
    sizes = [len(c) for c in src]
    starts = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
    cage_pts = (np.concatenate(src), np.concatenate(dst))
    segments = [np.stack([starts[i] + np.arange(n), starts[i] + (np.arange(n) + 1) % n], axis=1) for i, n in enumerate(sizes)]
    failure = None
    # Without interior points first (the faces' vertices are then the cages' and the outline's), then
    # with them: a quality mesh of the source ring, its interior points carried to the target by the
    # harmonic extension of the cages' moves (finer meshes follow a move more closely).
    for density, refine in ((1.0, 0), (3.0, 0), (1.0, 1), (1.0, 2), (1.0, 3), (1.0, -1), (1.0, -2), (1.0, -3)):
        ring_pts = _outline_points(out, density * max(MIN_OUTLINE_POINTS, OUTLINE_POINTS_PER_CAGE_VERTEX * sum(sizes)))
        m = len(ring_pts)
        base = int(starts[-1])
        seg = np.concatenate(segments + [np.stack([base + np.arange(m), base + (np.arange(m) + 1) % m], axis=1)])
        sv = np.concatenate([cage_pts[0], ring_pts])
        dv = np.concatenate([cage_pts[1], ring_pts])
        if refine > 0:  # a mesh of the source ring, carried to the target
            meshed = _steiner_triangles(sv, dv, seg, starts, refine)
            if meshed is None:
                continue
            sv, dv, tris = meshed
        elif refine < 0:  # a mesh of the target ring, carried back to the source
            meshed = _steiner_triangles(dv, sv, seg, starts, -refine)
            if meshed is None:
                continue
            dv, sv, tris = meshed
        else:
            tris = _compatible_triangles(sv, dv, seg, starts)
        bad = _folded(sv, dv, tris)
        if not bad.any():
            faces = _merge(sv, dv, tris, seg, min_convexity, name)
            for f in faces:  # the guarantee, in full, on the few faces left
                validate_points(sv[f], f"{name}: a face of the ring")
                validate_points(dv[f], f"{name}: a face of the ring")
            if sign < 0:
                faces = [f[::-1] for f in faces]
            return _drop_unused(sv, dv, faces, base + m)
        if failure is None:
            failure = (sv, dv, tris, bad)
    sv, dv, tris, bad = failure  # type: ignore[misc]
    raise PolygonError(_fold_message(sv, dv, tris[bad], starts, dnames, name))


def _drop_unused(
    sv: NDArray, dv: NDArray, faces: list[list[int]], keep: int
) -> tuple[NDArray[np.float64], NDArray[np.float64], tuple[tuple[int, ...], ...]]:
    """Interior points no face's boundary uses (inside merged faces) left out; the first ``keep`` points stay."""
    used = np.zeros(len(sv), dtype=bool)
    used[:keep] = True
    for f in faces:
        used[f] = True
    index = np.cumsum(used) - 1
    out = tuple(tuple(int(index[v]) for v in _canonical(f)) for f in faces)
    return sv[used], dv[used], out


def _steiner_triangles(
    sv: NDArray, dv: NDArray, seg: NDArray, starts: NDArray, level: int
) -> tuple[NDArray, NDArray, NDArray[np.intp]] | None:
    """A quality mesh of the source ring with interior points, carried to the target harmonically, flips repaired.

    The boundary keeps its points (no point is added on a cage's or the
    outline's edge: the cages are faces of their own). An interior point goes
    to its source position plus the harmonic extension of the boundary's
    moves (mean-value weights, positive, so an unmoved cage gives the
    identity), which follows the moves smoothly; ``level`` 1 is a quality
    mesh graded by the boundary alone, 2 and 3 bound the triangles' area by
    the median cage edge's square and a quarter of it.
    """
    import triangle as tr
    from scipy.sparse import coo_matrix
    from scipy.sparse.linalg import spsolve

    holes = np.array([_inner_point(sv[a:b]) for a, b in zip(starts[:-1], starts[1:])])
    n_cage = int(starts[-1])
    cage_edges = np.hypot(*(sv[seg[:, 1]] - sv[seg[:, 0]]).T)[: n_cage]
    # Level 1: a quality mesh alone (graded by the boundary: fine near the cages, coarse far off); then
    # triangles of at most the median cage edge's square, and a quarter of it.
    area = "" if level == 1 else f"a{decimal(median(cage_edges) ** 2 / 4.0 ** (level - 2))}"
    try:
        t = tr.triangulate({"vertices": sv, "segments": seg, "holes": holes}, f"pq25{area}YYQ")
    except Exception:  # triangle raises bare RuntimeErrors on geometry it cannot take
        return None
    v = np.asarray(t["vertices"], dtype=np.float64)
    tris = np.asarray(t["triangles"], dtype=np.intp)
    n_b = len(sv)
    if len(v) < n_b or not np.array_equal(v[:n_b], sv) or len(tris) == 0:
        return None
    n = len(v)
    # Mean-value weights: edge i->j of a triangle with angle theta at i adds tan(theta / 2) / |x_j - x_i|.
    rows, cols, vals = [], [], []
    for k in range(3):
        i, j, l = tris[:, k], tris[:, (k + 1) % 3], tris[:, (k + 2) % 3]
        e1, e2 = v[j] - v[i], v[l] - v[i]
        n1, n2 = np.hypot(*e1.T), np.hypot(*e2.T)
        cos = np.clip((e1 * e2).sum(axis=1) / (n1 * n2), -1.0, 1.0)
        half = np.tan(np.arccos(cos) / 2)
        rows += [i, i]
        cols += [j, l]
        vals += [half / n1, half / n2]
    r, c, w = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
    inner = r >= n_b
    r, c, w = r[inner], c[inner], w[inner]
    move = np.zeros((n, 2))
    move[:n_b] = dv - sv
    free = np.arange(n_b, n)
    if free.size:
        diag = np.bincount(r - n_b, weights=w, minlength=free.size)
        fixed = c < n_b
        lap = coo_matrix(
            (np.concatenate([diag, -w[~fixed]]), (np.concatenate([free - n_b, r[~fixed] - n_b]),
                                                   np.concatenate([free - n_b, c[~fixed] - n_b]))),
            shape=(free.size, free.size),
        ).tocsc()
        rhs = np.zeros((free.size, 2))
        np.add.at(rhs, r[fixed] - n_b, w[fixed, None] * move[c[fixed]])
        move[n_b:] = np.asarray(spsolve(lap, rhs)).reshape(free.size, 2)
    vd = v + move
    vd[:n_b] = dv  # exactly
    tris = _repair(v, vd, tris, seg)
    return v, vd, tris


def _check_inside(outline: NDArray, cages: list[NDArray], names: list[str], name: str) -> None:
    """Every cage strictly inside the outline: vertices inside, no edge touching it."""
    oa, ob = outline, np.roll(outline, -1, axis=0)
    for cage, label in zip(cages, names):
        inside = _inside(cage, outline)
        if not inside.all():
            i = int(np.flatnonzero(~inside)[0])
            raise PolygonError(f"{label}: vertex {i} at {format_point(cage[i])} lies outside {name}")
        ca, cb = cage, np.roll(cage, -1, axis=0)
        n, m = len(ca), len(oa)
        touch = segments_touch(
            np.repeat(ca, m, axis=0), np.repeat(cb, m, axis=0), np.tile(oa, (n, 1)), np.tile(ob, (n, 1))
        ).reshape(n, m)
        if touch.any():
            i, j = (int(v) for v in np.argwhere(touch)[0])
            raise PolygonError(
                f"{label}: vertex {i}: the edge from it to vertex {(i + 1) % n} crosses {name} (its edge {j}); "
                "the outline must hold the cage strictly inside"
            )


def _check_apart(cages: list[NDArray], names: list[str]) -> None:
    """No two cages cross, touch or nest."""
    for a in range(len(cages)):
        for b in range(a + 1, len(cages)):
            p, q = cages[a], cages[b]
            pa, pb, qa, qb = p, np.roll(p, -1, axis=0), q, np.roll(q, -1, axis=0)
            n, m = len(p), len(q)
            touch = segments_touch(
                np.repeat(pa, m, axis=0), np.repeat(pb, m, axis=0), np.tile(qa, (n, 1)), np.tile(qb, (n, 1))
            ).reshape(n, m)
            if touch.any():
                i, j = (int(v) for v in np.argwhere(touch)[0])
                raise PolygonError(f"{names[b]}: vertex {j}: its edge to vertex {(j + 1) % m} crosses {names[a]}")
            if _inside(q[:1], p)[0]:
                raise PolygonError(f"{names[b]}: vertex 0 at {format_point(q[0])} lies inside {names[a]}")
            if _inside(p[:1], q)[0]:
                raise PolygonError(f"{names[a]}: vertex 0 at {format_point(p[0])} lies inside {names[b]}")


def _inside(points: NDArray, polygon: NDArray) -> NDArray[np.bool_]:
    """Whether each point lies inside the polygon (even-odd; exact signs, points on an edge count as outside)."""
    a, b = polygon, np.roll(polygon, -1, axis=0)
    n, m = len(points), len(a)
    px, py = np.repeat(points[:, 0], m), np.repeat(points[:, 1], m)
    ax, ay, bx, by = (np.tile(v, n) for v in (a[:, 0], a[:, 1], b[:, 0], b[:, 1]))
    # Edge straddles the horizontal through p (half-open), and p lies left of it (exact sign).
    up = (ay <= py) & (by > py)
    down = (by <= py) & (ay > py)
    side = orient_sign(ax, ay, bx, by, px, py)
    crossing = (up & (side > 0)) | (down & (side < 0))
    on_edge = (side == 0) & (np.minimum(ax, bx) <= px) & (px <= np.maximum(ax, bx)) & (np.minimum(ay, by) <= py) & (
        py <= np.maximum(ay, by)
    )
    odd = (crossing.reshape(n, m).sum(axis=1) % 2) == 1
    return odd & ~on_edge.reshape(n, m).any(axis=1)


def _inner_point(cage: NDArray) -> NDArray[np.float64]:
    """A point strictly inside a simple polygon (the centroid of an ear of its triangulation)."""
    import triangle as tr

    n = len(cage)
    seg = np.stack([np.arange(n), (np.arange(n) + 1) % n], axis=1)
    try:
        t = tr.triangulate({"vertices": cage, "segments": seg}, "pQ")
    except Exception:  # an in-between cage that crosses itself: no ring there
        return cage.mean(axis=0)
    tri = t["triangles"]
    area = np.abs(_areas(t["vertices"], tri))
    return t["vertices"][tri[int(np.argmax(area))]].mean(axis=0)


def _outline_points(outline: NDArray, count: float) -> NDArray[np.float64]:
    """The outline's vertices with points inserted along its edges, about ``count`` in all, spread by length."""
    b = np.roll(outline, -1, axis=0)
    length = np.hypot(*(b - outline).T)
    per = max(count, len(outline)) / float(length.sum())
    pieces = np.maximum(1, np.round(length * per).astype(int))
    parts = []
    for a, e, p in zip(outline, b, pieces):
        t = np.arange(p)[:, None] / p
        parts.append(a + t * (e - a))
    return np.concatenate(parts)


def _areas(v: NDArray, tri: NDArray) -> NDArray[np.float64]:
    a, b, c = v[tri[:, 0]], v[tri[:, 1]], v[tri[:, 2]]
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))


def _signs(v: NDArray, tri: NDArray) -> NDArray[np.float64]:
    a, b, c = v[tri[:, 0]], v[tri[:, 1]], v[tri[:, 2]]
    return orient_sign(a[:, 0], a[:, 1], b[:, 0], b[:, 1], c[:, 0], c[:, 1])


def _folded(sv: NDArray, dv: NDArray, tris: NDArray) -> NDArray[np.bool_]:
    """Triangles that are not positively oriented on both sides."""
    return (_signs(sv, tris) <= 0) | (_signs(dv, tris) <= 0)


def _triangulate(v: NDArray, seg: NDArray, holes: NDArray) -> NDArray[np.intp] | None:
    """The constrained Delaunay triangulation of the ring (no Steiner points), or None if `triangle` adds any."""
    import triangle as tr

    try:
        t = tr.triangulate({"vertices": v, "segments": seg, "holes": holes}, "pYYQ")
    except Exception:  # triangle raises bare RuntimeErrors on geometry it cannot take
        return None
    if len(t["vertices"]) != len(v) or "triangles" not in t:
        return None
    return np.asarray(t["triangles"], dtype=np.intp)


def _compatible_triangles(sv: NDArray, dv: NDArray, seg: NDArray, starts: NDArray) -> NDArray[np.intp]:
    """A triangulation of the ring with as few triangles folded on either side as found.

    Candidates: the constrained Delaunay triangulations of the source ring,
    of the target ring and of rings in between (where those are rings), each
    repaired by edge flips; the first with no fold wins.
    """
    best = None
    for t in (0.0, 1.0, 0.5, 0.25, 0.75):
        v = sv + t * (dv - sv)
        cages = [v[a:b] for a, b in zip(starts[:-1], starts[1:])]
        if 0.0 < t < 1.0 and not _is_ring(v[int(starts[-1]):], cages):
            continue  # `triangle` may crash on a ring that crosses itself (repeated points: a segfault)
        holes = np.array([_inner_point(c) for c in cages])
        tris = _triangulate(v, seg, holes)
        if tris is None or len(tris) == 0:
            continue
        tris = _repair(sv, dv, tris, seg)
        folds = int(_folded(sv, dv, tris).sum())
        if best is None or folds < best[0]:
            best = (folds, tris)
        if folds == 0:
            break
    if best is None:
        raise PolygonError("the ring between the outline and the cages could not be triangulated")
    return best[1]


def _is_ring(outline: NDArray, cages: list[NDArray]) -> bool:
    """Whether cages inside an outline make a valid ring (each simple, inside, apart)."""
    names = [f"cage {i}" for i in range(len(cages))]
    try:
        for cage, label in zip(cages, names):
            validate_points(cage, label)
        _check_inside(outline, cages, names, "outline")
        _check_apart(cages, names)
    except PolygonError:
        return False
    return True


def _repair(sv: NDArray, dv: NDArray, tris: NDArray, seg: NDArray) -> NDArray[np.intp]:
    """Flip interior edges of folded triangles while that lowers the count of folds (on either side)."""
    arr = np.asarray(tris, dtype=np.intp).reshape(-1, 3)
    tris = arr.tolist()
    fixed = {frozenset((int(a), int(b))) for a, b in seg}
    # A triangle's folds are tested one at a time, exactly, in Python floats (`orient_sign_one`: a numpy
    # call per triangle cost 50 times more), and remembered: flips test the same triangles again and again.
    sides = (sv.tolist(), dv.tolist())
    memo: dict[tuple[int, int, int], int] = {}

    def badness(t) -> int:
        key = (t[0], t[1], t[2])
        bad = memo.get(key)
        if bad is None:
            bad = memo[key] = sum(orient_sign_one(p[key[0]], p[key[1]], p[key[2]]) <= 0 for p in sides)
        return bad

    def edge_owners() -> dict[tuple[int, int], int]:
        edges: dict[tuple[int, int], int] = {}
        for i, t in enumerate(tris):
            for j in range(3):
                edges[(t[j], t[(j + 1) % 3])] = i
        return edges

    # The directed edges and the folded triangles are kept up to date flip by flip (a flip changes two
    # triangles), not found again over all triangles after each flip; should a flip make an edge that
    # is there already (a flip across a quadrilateral that is not convex can), they are found again
    # after every flip, as the last triangle holding an edge owns it.
    edges = edge_owners()
    folded = set(np.flatnonzero(_folded(sv, dv, arr)).tolist())  # folded on either side, as badness says
    rebuild = False
    for _ in range(FLIPS_PER_TRIANGLE * len(tris)):
        if rebuild:
            edges = edge_owners()
        if not folded:
            break
        flipped = False
        for i in sorted(folded):
            t = tris[i]
            for j in range(3):
                a, b, c = t[j], t[(j + 1) % 3], t[(j + 2) % 3]
                other = edges.get((b, a))
                if other is None or frozenset((a, b)) in fixed:
                    continue
                u = tris[other]
                d = u[(u.index(a) + 1) % 3]  # u = (b, a, d) rotated
                new = ([c, a, d], [d, b, c])
                before = badness(t) + badness(u)
                after = badness(new[0]) + badness(new[1])
                if after < before:
                    for k, tri in ((i, t), (other, u)):
                        for m in range(3):
                            edge = (tri[m], tri[(m + 1) % 3])
                            if edges.get(edge) == k:
                                del edges[edge]
                    rebuild = rebuild or (c, d) in edges or (d, c) in edges
                    tris[i], tris[other] = new
                    for k in (i, other):
                        tri = tris[k]
                        for m in range(3):
                            edges[(tri[m], tri[(m + 1) % 3])] = k
                        if badness(tri):
                            folded.add(k)
                        else:
                            folded.discard(k)
                    flipped = True
                    break
            if flipped:
                break
        if not flipped:
            break
    return np.array(tris, dtype=np.intp)


def _fold_message(sv: NDArray, dv: NDArray, bad: NDArray, starts: NDArray, names: list[str], name: str) -> str:
    """One line naming the cage vertex of a folded triangle that moved the most."""
    cage_count = int(starts[-1])
    verts = sorted({int(v) for v in bad.ravel() if v < cage_count}, key=lambda v: -float(np.hypot(*(dv[v] - sv[v]))))
    if not verts:
        return f"{name}: the ring between it and the cages cannot be cut without folding"
    v = verts[0]
    k = int(np.searchsorted(starts, v, side="right")) - 1
    moved = float(np.hypot(*(dv[v] - sv[v])))
    return (
        f"{names[k]}: vertex {v - int(starts[k])} at {format_point(dv[v])} moved {format_number(moved)} px, too far "
        f"for a fold-free cut of the ring within {name}; move it less or give the outline more room"
    )


def _canonical(face: list[int]) -> list[int]:
    """The cycle rotated to start at its smallest index."""
    i = int(np.argmin(face))
    return face[i:] + face[:i]


def _convexity(points: NDArray) -> float:
    """Area over the area of the convex hull (1 for a convex polygon)."""
    hull = _hull(points)
    h = abs(signed_area(hull))
    return abs(signed_area(points)) / h if h > 0 else 0.0


def _hull(points: NDArray) -> NDArray[np.float64]:
    """The convex hull (Andrew's monotone chain)."""
    pts = sorted(map(tuple, points))
    if len(pts) < 3:
        return np.array(pts)

    def cross(o, a, b) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    upper: list = []
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


def _join(a: list[int], b: list[int], u: int, v: int) -> list[int] | None:
    """The boundary of the union of faces ``a`` (holding edge u->v) and ``b`` (holding v->u), or None if not a disk."""
    i = a.index(v)
    a_rot = a[i:] + a[:i]  # v ... u
    j = b.index(u)
    b_rot = b[j:] + b[:j]  # u ... v
    cycle = a_rot + b_rot[1:-1]  # v ... u ... (before v)
    # Faces sharing a chain of edges leave spikes x, y, x: fold them away.
    changed = True
    while changed and len(cycle) >= 3:
        changed = False
        n = len(cycle)
        for s in range(n):
            if cycle[s] == cycle[(s + 2) % n]:
                drop = {(s + 1) % n, (s + 2) % n}
                cycle = [c for idx, c in enumerate(cycle) if idx not in drop]
                changed = True
                break
    if len(cycle) < 3 or len(set(cycle)) != len(cycle):
        return None
    return cycle


def _merge(sv: NDArray, dv: NDArray, tris: NDArray, seg: NDArray, min_convexity: float, name: str) -> list[list[int]]:
    """Triangles merged greedily into few faces, fattest merge first, each simple on both sides.

    A merge's score is the isoperimetric quotient ``4 pi area / perimeter^2``
    of the merged face (1 for a disc, small for a sliver or a long snake),
    the lesser of source and target, kept per face so that a score costs
    O(1); a merge is done only if the union is a disk with clearance on both
    sides (and, with ``min_convexity``, convex enough).
    """
    fixed = {frozenset((int(a), int(b))) for a, b in seg}
    faces: dict[int, list[int]] = {i: [int(x) for x in t] for i, t in enumerate(tris)}
    area = {i: (abs(float(a)), abs(float(b))) for i, (a, b) in enumerate(zip(_areas(sv, tris), _areas(dv, tris)))}
    perimeter = {}
    for i, t in enumerate(tris):
        perimeter[i] = tuple(float(sum(np.hypot(*(side[t[(j + 1) % 3]] - side[t[j]])) for j in range(3))) for side in (sv, dv))
    version: dict[int, int] = dict.fromkeys(faces, 0)
    owner: dict[tuple[int, int], int] = {}
    for f, cyc in faces.items():
        for j in range(len(cyc)):
            owner[(cyc[j], cyc[(j + 1) % len(cyc)])] = f
    next_id = len(faces)
    heap: list = []

    def candidates(f: int) -> None:
        cyc = faces[f]
        common: dict[int, list[float]] = {}
        first: dict[int, tuple[int, int]] = {}
        for j in range(len(cyc)):
            u, v = cyc[j], cyc[(j + 1) % len(cyc)]
            g = owner.get((v, u))
            if g is None or g not in faces or g == f or frozenset((u, v)) in fixed:
                continue
            length = common.setdefault(g, [0.0, 0.0])
            length[0] += float(np.hypot(*(sv[v] - sv[u])))
            length[1] += float(np.hypot(*(dv[v] - dv[u])))
            first.setdefault(g, (u, v))
        for g, (ls, ld) in common.items():
            score = min(
                4 * math.pi * (area[f][k] + area[g][k]) / max(perimeter[f][k] + perimeter[g][k] - 2 * c, 1e-300) ** 2
                for k, c in ((0, ls), (1, ld))
            )
            u, v = first[g]
            heapq.heappush(heap, (-score, f, version[f], g, version[g], u, v, (ls, ld)))

    for f in list(faces):
        candidates(f)
    while heap:
        _, f, vf, g, vg, u, v, common = heapq.heappop(heap)
        if f not in faces or g not in faces or version[f] != vf or version[g] != vg:
            continue
        joined = _join(faces[f], faces[g], u, v)
        if joined is None or not _valid_join(sv, dv, faces[f], faces[g], joined):
            continue
        if min_convexity > 0 and min(_convexity(sv[joined]), _convexity(dv[joined])) < min_convexity:
            continue
        h = next_id
        next_id += 1
        area[h] = (area[f][0] + area[g][0], area[f][1] + area[g][1])
        perimeter[h] = (perimeter[f][0] + perimeter[g][0] - 2 * common[0], perimeter[f][1] + perimeter[g][1] - 2 * common[1])
        del faces[f], faces[g]
        faces[h] = joined
        version[h] = 0
        for j in range(len(joined)):
            owner[(joined[j], joined[(j + 1) % len(joined)])] = h
        candidates(h)
    return list(faces.values())


def _valid_join(sv: NDArray, dv: NDArray, a: list[int], b: list[int], joined: list[int]) -> bool:
    """Whether the union ``joined`` of faces ``a`` and ``b`` has `validate_points`' clearance on both sides.

    A disk made of triangles that keep their orientation on both sides is
    simple on both; what may fail is the clearance (a vertex of one face
    close to an edge of the other that does not end at it): only those pairs
    are tested (each face has its clearance already), in numpy, with the
    floor of `validate_points` for the joined face.
    """
    if len(a) < len(b):
        a, b = b, a
    idx = np.array(joined)
    n = len(idx)
    in_b = np.zeros(len(sv), dtype=bool)
    in_b[b] = True
    verts_b = in_b[idx]
    from_b = verts_b & np.roll(verts_b, -1)  # edges between two of b's vertices (b's, and maybe a chord: tested too)
    vi = np.concatenate([np.repeat(np.arange(n), from_b.sum()), np.repeat(np.flatnonzero(verts_b), n)])
    ei = np.concatenate([np.tile(np.flatnonzero(from_b), n), np.tile(np.arange(n), verts_b.sum())])
    keep = (vi != ei) & (vi != (ei + 1) % n)
    vi, ei = vi[keep], ei[keep]
    # Both sides in one call (the same arithmetic per pair): source pairs first, then target pairs.
    m = len(vi)
    pts = (sv[idx], dv[idx])
    both = np.concatenate(pts)
    vj, ej, fj = np.r_[vi, vi + n], np.r_[ei, ei + n], np.r_[(ei + 1) % n, (ei + 1) % n + n]
    d = point_segment_distance(both[vj], both[ej], both[fj])
    return not ((d[:m] < clearance_floor(pts[0])).any() or (d[m:] < clearance_floor(pts[1])).any())
