"""The boundary correspondence of two charts: loops in order from a start, or corners with arclength between them."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .mesh import MeshError

__all__ = ["MERGE_PIXELS", "STRAIGHT", "LoopPair", "corresponding_loops"]

#: Boundary points of the two sides closer than this (pixels, along either side) are
#: one vertex of the polygons: a hundredth of a pixel is far below what a texture
#: shows, and inserting both would leave edges shorter than the polygons' clearance.
MERGE_PIXELS = 0.01
#: A vertex is left out of the polygons when it lies within this fraction of the chord's
#: length from the chord between its kept neighbours, on both sides, at fractions along
#: them that agree within it: texture coordinates are usually written with 6 decimals,
#: which puts the vertices of a straight side up to ~1e-5 of an edge off their line.
STRAIGHT = 1e-4


@dataclass(frozen=True, eq=False)
class LoopPair:
    """Two polygons with vertex i of one going to vertex i of the other, made from two boundary loops.

    Attributes
    ----------
    src, dst : (n, 2) ndarray of float
        The polygons (pixel coordinates). Every boundary vertex of each loop
        lies on its polygon (a vertex of it, or on an edge where the loop is
        straight and the map linear across it).
    corners : (n,) ndarray of bool
        Which polygon vertices are corners (or the start, without corners).
    """

    src: NDArray[np.float64]
    dst: NDArray[np.float64]
    corners: NDArray[np.bool_]


def _place(ids: NDArray[np.int64], vertex: int, side: str, name: str) -> int:
    where = np.flatnonzero(ids == vertex)
    if where.size == 0:
        raise MeshError(f"{name}: vertex {vertex} ({side}) is not on the chart's boundary")
    if where.size > 1:
        raise MeshError(f"{name}: vertex {vertex} ({side}) is on the boundary {where.size} times (a seam); name another")
    return int(where[0])


def corresponding_loops(
    src: NDArray[np.float64],
    dst: NDArray[np.float64],
    src_ids: NDArray[np.int64],
    dst_ids: NDArray[np.int64],
    *,
    src_name: str = "src",
    dst_name: str = "dst",
    src_start: int | None = None,
    dst_start: int | None = None,
    src_corners: Sequence[int] | None = None,
    dst_corners: Sequence[int] | None = None,
) -> LoopPair:
    """Pair two boundary loops into polygons of one vertex count.

    Without corners the loops must have one length: boundary vertex k of each,
    counted from its start along the loop, go to each other (the start is
    the boundary vertex of smallest index, or ``src_start``/``dst_start``).
    With corners (as many on each side, in the loops' order), corner k goes
    to corner k and the boundary between two corners goes to the boundary
    between their partners by arclength: each side's vertices are inserted
    into the other side's polyline at the same fraction of its length, so
    both polygons have all the vertices of both loops and the map along the
    boundary is linear on every piece. Vertices straight on both sides, where
    the map is linear across them anyway, are left out of the polygons (a
    grid chart's sides become single edges).

    Parameters
    ----------
    src, dst : (L, 2) ndarray of float
        The loops' points, in loop order.
    src_ids, dst_ids : (L,) ndarray of int
        The vertex number of each loop point (what starts and corners name).

    Returns
    -------
    LoopPair

    Raises
    ------
    MeshError
        If the counts differ without corners, or a start or corner is not on
        its boundary, or the corners are not in loop order.
    """
    if (src_corners is None) != (dst_corners is None):
        raise MeshError(f"{src_name if src_corners is None else dst_name}: corners are given for one side only; name them on both")
    if src_corners is None:
        if len(src) != len(dst):
            raise MeshError(
                f"{dst_name}: the chart's boundary has {len(dst)} vertices but {src_name}'s has {len(src)}: "
                "name corresponding corners on both (--src-corners, --dst-corners)"
            )
        i0 = int(np.argmin(src_ids)) if src_start is None else _place(src_ids, src_start, "start", src_name)
        j0 = int(np.argmin(dst_ids)) if dst_start is None else _place(dst_ids, dst_start, "start", dst_name)
        a = np.roll(src, -i0, axis=0)
        b = np.roll(dst, -j0, axis=0)
        corners = np.zeros(len(a), dtype=bool)
        corners[0] = True
        return _simplified(a, b, corners)
    if len(src_corners) != len(dst_corners):
        raise MeshError(f"{dst_name}: {len(dst_corners)} corners, but {src_name} has {len(src_corners)}")
    if len(src_corners) < 1:
        raise MeshError(f"{src_name}: name at least one corner")
    si = [_place(src_ids, int(c), "corner", src_name) for c in src_corners]
    di = [_place(dst_ids, int(c), "corner", dst_name) for c in dst_corners]
    pieces_a, pieces_b, marks = [], [], []
    sa, sb = _sides(src, si, src_name), _sides(dst, di, dst_name)
    for pa, pb in zip(sa, sb):
        a, b = _merged_side(pa, pb)
        pieces_a.append(a[:-1])
        pieces_b.append(b[:-1])
        m = np.zeros(len(a) - 1, dtype=bool)
        m[0] = True
        marks.append(m)
    return _simplified(np.concatenate(pieces_a), np.concatenate(pieces_b), np.concatenate(marks))


def _sides(points: NDArray[np.float64], idx: list, name: str) -> list:
    """The polylines from each corner to the next (both ends included), checking loop order."""
    n = len(points)
    rel = [(i - idx[0]) % n for i in idx]
    if len(set(rel)) != len(rel):
        raise MeshError(f"{name}: a corner is named twice")
    if rel != sorted(rel):
        raise MeshError(
            f"{name}: the corners are not in the order of the boundary loop (list them the way the faces run along it)"
        )
    out = []
    for k in range(len(idx)):
        a = idx[k]
        length = (idx[(k + 1) % len(idx)] - a) % n or n
        out.append(points[(a + np.arange(length + 1)) % n])
    return out


def _arclength(poly: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
    seg = np.hypot(*np.diff(poly, axis=0).T)
    total = float(seg.sum())
    s = np.concatenate([[0.0], np.cumsum(seg)]) / total
    s[-1] = 1.0  # the ends of two sides must meet exactly (cumsum and sum round differently)
    return s, total


def _at(poly: NDArray[np.float64], s: NDArray[np.float64], t: float) -> NDArray[np.float64]:
    """The point at arclength fraction t of a polyline with vertex fractions s."""
    k = int(np.clip(np.searchsorted(s, t, side="right") - 1, 0, len(s) - 2))
    span = s[k + 1] - s[k]
    w = 0.0 if span <= 0 else (t - s[k]) / span
    return (1.0 - w) * poly[k] + w * poly[k + 1]


def _merged_side(pa: NDArray[np.float64], pb: NDArray[np.float64]):
    """Both polylines with each other's vertices inserted at the same arclength fractions.

    A vertex of one side within `MERGE_PIXELS` (along either side) of a
    vertex of the other is paired with it instead: each keeps its place.
    """
    sa, la = _arclength(pa)
    sb, lb = _arclength(pb)
    tol = MERGE_PIXELS / max(min(la, lb), 1e-300)
    events = sorted([(float(t), 0, i) for i, t in enumerate(sa)] + [(float(t), 1, j) for j, t in enumerate(sb)])
    groups: list = []
    for t, side, i in events:
        g = groups[-1] if groups else None
        if g is not None and side not in g["own"] and t - g["t"] <= tol:
            g["own"][side] = i
        else:
            groups.append({"t": t, "own": {side: i}})
    # The ends are shared: the first and last groups hold both polylines' ends.
    out_a, out_b = [], []
    for g in groups:
        own = g["own"]
        out_a.append(pa[own[0]] if 0 in own else _at(pa, sa, g["t"]))
        out_b.append(pb[own[1]] if 1 in own else _at(pb, sb, g["t"]))
    return np.array(out_a), np.array(out_b)


def _straight(prev: NDArray[np.float64], here: NDArray[np.float64], nxt: NDArray[np.float64]) -> tuple[bool, float]:
    """Whether ``here`` lies on the segment from ``prev`` to ``nxt``, and its fraction along it."""
    d = nxt - prev
    e = here - prev
    dd = float(d @ d)
    if dd <= 0:
        return False, 0.0
    cross = abs(float(d[0] * e[1] - d[1] * e[0]))
    t = float(d @ e) / dd
    return cross <= STRAIGHT * dd and 0.0 < t < 1.0, t


def _simplified(a: NDArray[np.float64], b: NDArray[np.float64], corners: NDArray[np.bool_]) -> LoopPair:
    """Leave out vertices straight in both polygons at the same fraction (the map is linear across them)."""
    n = len(a)
    keep = [0]
    for i in range(1, n):
        j = (i + 1) % n
        p = keep[-1]
        sa, ta = _straight(a[p], a[i], a[j])
        sb, tb = _straight(b[p], b[i], b[j])
        if sa and sb and abs(ta - tb) <= STRAIGHT and n - (i - len(keep) + 1) >= 3:
            continue
        keep.append(i)
    k = np.array(keep)
    return LoopPair(a[k], b[k], corners[k])
