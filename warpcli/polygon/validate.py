"""Validating simple polygons: vertices, area, crossings and clearance, with an n log n pair scan."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._arrays import median
from ..errors import PolygonError
from .messages import format_number, format_point
from .predicates import intersection_point, orient, orient_sign, point_segment_distance, segments_touch, signed_area

__all__ = ["MIN_CLEARANCE", "MIN_CLEARANCE_RELATIVE", "check_edges", "clearance_floor", "validate_points"]

#: Smallest clearance accepted, in pixels: every vertex must be at least this
#: far from every edge that does not end at it (so edges are at least this
#: long, and non-adjacent edges at least this far apart). A thousandth of a
#: pixel is below anything an image shows (moving an edge that far changes a
#: pixel's coverage by 0.001, a quarter of an 8-bit level), so a narrower part
#: of a polygon is a mistake, not a feature: a sliver, a needle, a slit that
#: was meant to be closed. It also keeps the later stages working: the mesher
#: needs triangles no wider than the narrowest part, so a part 1e-3 px wide and
#: 1000 px long already costs a million triangles, and a 1e-12 px slit crashed
#: it. Even at ``COORD_LIMIT`` a thousandth of a pixel is 8000 units in the last
#: place of a double, far from rounding. A gap of 0.05 px between two arms is
#: thin but deliberate (sub-pixel annotation) and is accepted.
MIN_CLEARANCE = 1e-3

#: Smallest clearance accepted relative to the polygon's size (the diagonal of
#: its bounding box), for polygons over 1000 px across, where this exceeds
#: ``MIN_CLEARANCE``. The mesher needs triangles no wider than a part of the
#: polygon all along it: a strip L long and w wide costs about L / w
#: triangles, a needle with a tip angle t about 1 / t (measured with
#: `triangle`). So no part may be narrower than a millionth of the polygon's
#: size: then a thin part costs at most about a million triangles (the
#: automatic mesh's budget), the largest triangle is at most about 1e6 times
#: the smallest (the FEM system's condition number, which grows like the
#: square of that ratio, stays below about 1e12), and no needle's tip is
#: sharper than about 1e-6 rad. A needle 1e8 px long and 26 px wide
#: (2.6e-7 rad) crashed `triangle`.
MIN_CLEARANCE_RELATIVE = 1e-6

# Polygons with at most this many vertices are checked pair by pair; larger
# ones through a grid of cells (see _grid_scan).
_BRUTE_FORCE_MAX = 64

# A grid cell holding more than this many edges is split in _SPLIT x _SPLIT.
_CROWD = 16
_SPLIT = 2

# A cell that cannot be split further (under 4 clearances wide) holding more
# edges than this proves the polygon invalid: in a valid polygon, vertices are
# a clearance apart and edges passing by a clearance apart, so at most about
# 130 edges come within a clearance of such a cell.
_CROWD_FINAL = 512

# Work limits of the grid: cell entries and edge pairs tested, in all, per
# edge and in addition. Only long edges running side by side, close together
# over much of a polygon, reach them (see _grid_scan).
_ENTRIES_PER_EDGE = 16
_ENTRIES_EXTRA = 1 << 21
_PAIRS_PER_EDGE = 64
_PAIRS_EXTRA = 1 << 23

# Edge pairs are tested in blocks of this many, to keep memory small.
_PAIR_BLOCK = 1 << 18

# Edges are put into cells in blocks of this many (edges, columns, cells).
_BLOCK = 1 << 16


def clearance_floor(points: ArrayLike) -> float:
    """The smallest clearance `validate_points` accepts for a polygon with these vertices.

    ``max(MIN_CLEARANCE, MIN_CLEARANCE_RELATIVE * d)`` pixels, where ``d`` is
    the diagonal of the vertices' bounding box.

    Parameters
    ----------
    points : (n, 2) array_like of float

    Returns
    -------
    float

    >>> clearance_floor([[0, 0], [300, 0], [300, 400]])
    0.001
    >>> clearance_floor([[0, 0], [3e5, 0], [3e5, 4e5]])
    0.5
    """
    pts = np.asarray(points, dtype=np.float64)
    w, h = np.ptp(pts, axis=0)
    return max(MIN_CLEARANCE, MIN_CLEARANCE_RELATIVE * math.hypot(float(w), float(h)))


def validate_points(pts: NDArray[np.float64], name: str) -> None:
    """Raise PolygonError unless ``pts`` is a simple polygon with non-zero area and enough clearance.

    The checks, in order (the message names the first that fails):

    1. at least 3 vertices, no vertex repeated;
    2. non-zero area (all vertices on one line have none);
    3. simple: adjacent edges do not overlap (the boundary does not double
       back), and no two other edges cross or touch, not even at one point;
    4. clearance: every vertex is at least `clearance_floor` away from every
       edge that does not end at it (the *minimum clearance* of GEOS and
       shapely). This refuses short edges, slivers and needles (a triangle
       1e-4 px high), slits (two edges 1e-12 px apart) and near-touching
       parts; see `MIN_CLEARANCE` for the floor's reasons. The area is not
       compared with the perimeter: clearance bounds the width of every part
       from below, which is what meshing needs, and a long, narrow but real
       shape (a road, a crack 1 px wide) has a tiny area for its perimeter.

    Checks 3 and 4 put the edges into a grid of cells (a finer one where
    edges crowd) and test only edges sharing a cell, so a polygon with a
    million vertices takes about a second, not days. The crossing test has no
    tolerance: it uses the exact signs of orientation determinants (a
    floating-point filter with Shewchuk's error bound, then exact arithmetic
    for the rare cases it cannot decide), so touching is decided exactly for
    the coordinates given, at any distance from the origin. Among several
    crossing pairs the message names the pair ``(i, j)``, ``i < j``, that
    comes first; among too-close pairs, the closest. (Where more than 16
    edges crowd into a grid cell only a few clearances wide, the search there
    stops at the first fault it finds, which may then be another.)

    The work is bounded: a polygon whose long edges run side by side, close
    together, over much of its area (a comb of 20 000 teeth 100 px long and
    0.05 px wide, or of 60 teeth 100 px long and 0.0015 px wide) would need
    more than about 16 n grid entries or 64 n pair tests (plus a few
    million); it is refused as too intricate, within seconds (some 10 s for
    a million vertices). Its mesh would need millions of triangles anyway,
    more than the mesher allows.

    Parameters
    ----------
    pts : (n, 2) ndarray of float
        Finite vertices, as `Polygon` takes them.
    name : str
        Starts every message.

    Raises
    ------
    PolygonError
    """
    n = len(pts)
    if n < 3:
        raise PolygonError(f"{name}: a polygon needs at least 3 vertices, got {n}")
    _check_repeats(pts, name)
    area = signed_area(pts)
    span = float(np.ptp(pts, axis=0).max())
    if abs(area) <= 1e-12 * span * span:
        # Collinear vertices have zero area; so do the equal and opposite
        # lobes of a symmetric bow-tie, which is better named by its crossing.
        if not _collinear(pts):
            check_edges(pts, name, clearance=False)
        raise PolygonError(f"{name}: polygon has zero area")
    check_edges(pts, name, clearance=True)


def _check_repeats(pts: NDArray[np.float64], name: str) -> None:
    order = np.lexsort((pts[:, 1], pts[:, 0]))
    s = pts[order]
    same = np.flatnonzero((s[1:] == s[:-1]).all(axis=1))
    if same.size:
        i, j = sorted((int(order[same[0]]), int(order[same[0] + 1])))
        hint = " (list each vertex once; the polygon closes itself)" if (i, j) == (0, len(pts) - 1) else ""
        raise PolygonError(
            f"{name}: vertices {i} and {j} are repeated at {format_point(pts[i])}{hint}"
        )


def _collinear(pts: NDArray[np.float64]) -> bool:
    """Whether all points lie on one line (up to rounding)."""
    d = pts - pts[0]
    far = d[np.argmax(np.hypot(d[:, 0], d[:, 1]))]
    cross = np.abs(d[:, 0] * far[1] - d[:, 1] * far[0])
    return bool(cross.max() <= 1e-12 * float(far @ far))


def check_edges(pts: NDArray[np.float64], name: str, *, clearance: bool, grid: bool | None = None) -> int:
    """Checks 3 (simple) and, if ``clearance``, 4 of `validate_points`; return how many edge pairs were tested.

    `validate_points` runs checks 1 and 2 first; this is the part whose work
    grows with the polygon, open to tests and benchmarks that compare the grid
    with all pairs or count the pairs tested.

    Parameters
    ----------
    pts : (n, 2) ndarray of float
        Finite vertices, none repeated.
    name : str
        Starts every message.
    clearance : bool
        Whether to check the clearance (check 4) too.
    grid : bool or None
        Forces (True) or avoids (False) the grid of cells; by default it is
        used above 64 vertices, and all pairs are tested below.

    Returns
    -------
    int
        How many pairs of non-adjacent edges were tested.

    Raises
    ------
    PolygonError
        Naming the first fault, as `validate_points` does.
    """
    n = len(pts)
    a = pts
    b = np.roll(pts, -1, axis=0)
    prev = np.roll(pts, 1, axis=0)
    # Adjacent edges share a vertex; they only overlap if the boundary doubles
    # back on itself (a zero-angle spike). For collinear points the dot
    # product adds two terms of one sign: its sign is exact too.
    turn = orient_sign(prev[:, 0], prev[:, 1], a[:, 0], a[:, 1], b[:, 0], b[:, 1])
    back = np.einsum("ij,ij->i", prev - a, b - a) > 0
    spikes = np.flatnonzero((turn == 0) & back)
    del turn, back
    if spikes.size:
        i = int(spikes[0])
        raise PolygonError(
            f"{name}: edges {(i - 1) % n} and {i} overlap (the boundary doubles back at vertex {i}, "
            f"{format_point(pts[i])})"
        )
    floor = clearance_floor(pts)
    scan = _PairScan(a, b, floor, clearance)
    if clearance:
        # A vertex against the edges adjacent to its own (the edge after next
        # and the edge before last): in a triangle these are the heights.
        idx = np.arange(n)
        scan.near_candidates(point_segment_distance(prev, a, b), (idx - 1) % n, idx)
        scan.near_candidates(point_segment_distance(b, prev, a), (idx + 1) % n, (idx - 1) % n)
        del idx
    del prev
    if n >= 4:
        use_grid = n > _BRUTE_FORCE_MAX if grid is None else grid
        if use_grid:
            origin = pts.min(axis=0)
            _grid_scan(pts - origin, floor, scan, name, origin)
        else:
            i, j = np.triu_indices(n, 2)
            keep = ~((i == 0) & (j == n - 1))
            scan.test(i[keep], j[keep])
    if scan.cross is not None:
        e, f = scan.cross
        where = intersection_point(pts[e], pts[(e + 1) % n], pts[f], pts[(f + 1) % n])
        raise PolygonError(
            f"{name}: polygon is self-intersecting: edges {e} and {f} cross at {format_point(where)}"
        )
    if not clearance:
        return scan.tested
    length = np.hypot(b[:, 0] - a[:, 0], b[:, 1] - a[:, 1])
    short = np.flatnonzero(length < floor)
    if short.size:
        i = int(short[np.argmin(length[short])])
        j = (i + 1) % n
        value, limit = _apart(length[i], floor)
        raise PolygonError(
            f"{name}: edge {i} is too short: {value} px from vertex {i} "
            f"{format_point(pts[i])} to vertex {j} {format_point(pts[j])} (the minimum is {_floor_note(floor, limit)})"
        )
    if scan.near is not None:
        d, v, e = scan.near
        value, limit = _apart(d, floor)
        raise PolygonError(
            f"{name}: polygon is too thin: vertex {v} {format_point(pts[v])} is {value} px from "
            f"edge {e} (the minimum clearance is {_floor_note(floor, limit)})"
        )
    return scan.tested


def _apart(value: float, floor: float) -> tuple[str, str]:
    """``value`` (< ``floor``) and ``floor`` written with enough digits to show the one below
    the other: a 1.0 px edge under a floor of 1.0000003 px is not "1.0 px, the minimum is 1.0 px".

    >>> _apart(1.0, 1.0000003)
    ('1.0', '1.0000003')
    >>> _apart(0.0005, 0.001)
    ('0.0005', '0.001')
    """
    for digits in (6, 9, 12, 17):
        a, b = f"{float(value):.{digits}g}", f"{float(floor):.{digits}g}"
        if float(a) < float(b):
            break
    return tuple(t if any(ch in t for ch in ".en") else t + ".0" for t in (a, b))  # type: ignore[return-value]


def _floor_note(floor: float, shown: str | None = None) -> str:
    shown = shown or format_number(floor)
    if format_number(floor) != format_number(MIN_CLEARANCE):
        return f"{shown} px for a polygon this large: {MIN_CLEARANCE_RELATIVE:g} of its bounding box's diagonal"
    return f"{shown} px"


class _PairScan:
    """Tests pairs of non-adjacent edges; keeps the first crossing pair and the closest pair.

    ``a`` and ``b`` are the edges' start and end points, (n, 2); ``floor`` the
    clearance; ``clearance`` whether to look for pairs closer than it.
    """

    def __init__(self, a, b, floor: float, clearance: bool) -> None:
        self.a = a
        self.b = b
        self.n = len(a)
        self.floor = floor
        self.clearance = clearance
        self.cross: tuple[int, int] | None = None
        self.near: tuple[float, int, int] | None = None
        self.tested = 0
        self.budget = math.inf  # pairs to test before raising _OverBudget

    def faulty(self) -> bool:
        return self.cross is not None or self.near is not None

    def test(self, e: NDArray[np.intp], f: NDArray[np.intp]) -> bool:
        """Test edge pairs (e < f, not adjacent); return whether any is at fault."""
        self.tested += len(e)
        if self.tested > self.budget:
            raise _OverBudget
        if not len(e):
            return False
        a, b = self.a, self.b
        ae, be, af, bf = a[e], b[e], a[f], b[f]
        # Most pairs lie far apart, one edge wholly on one side of the other's
        # line, at least the reach away: they neither touch nor come near.
        # Only the others get the full tests. (All four signs certain, so that
        # segments_touch would say no.)
        o1, e1 = orient(ae[:, 0], ae[:, 1], be[:, 0], be[:, 1], af[:, 0], af[:, 1])
        o2, e2 = orient(ae[:, 0], ae[:, 1], be[:, 0], be[:, 1], bf[:, 0], bf[:, 1])
        o3, e3 = orient(af[:, 0], af[:, 1], bf[:, 0], bf[:, 1], ae[:, 0], ae[:, 1])
        o4, e4 = orient(af[:, 0], af[:, 1], bf[:, 0], bf[:, 1], be[:, 0], be[:, 1])
        reach = self.floor if self.clearance else 0.0
        de = be - ae
        df = bf - af
        m12 = np.minimum(np.abs(o1), np.abs(o2))
        m34 = np.minimum(np.abs(o3), np.abs(o4))
        far = (np.abs(o1) > e1) & (np.abs(o2) > e2) & (np.abs(o3) > e3) & (np.abs(o4) > e4)
        far &= ((o1 * o2 > 0) & (m12 >= reach * np.hypot(de[:, 0], de[:, 1]))) | (
            (o3 * o4 > 0) & (m34 >= reach * np.hypot(df[:, 0], df[:, 1]))
        )
        keep = np.flatnonzero(~far)
        if not keep.size:
            return False
        e, f, ae, be, af, bf = e[keep], f[keep], ae[keep], be[keep], af[keep], bf[keep]
        touch = segments_touch(ae, be, af, bf)
        found = False
        if touch.any():
            key = e[touch].astype(np.int64) * self.n + f[touch]
            k = int(key.min())
            pair = (k // self.n, k % self.n)
            if self.cross is None or pair < self.cross:
                self.cross = pair
            found = True
        if self.clearance and self.cross is None:
            n = self.n
            dist = np.stack(
                [
                    point_segment_distance(ae, af, bf),
                    point_segment_distance(be, af, bf),
                    point_segment_distance(af, ae, be),
                    point_segment_distance(bf, ae, be),
                ]
            )
            which = np.argmin(dist, axis=0)
            d = np.take_along_axis(dist, which[None], axis=0)[0]
            vertex = np.choose(which, [e, (e + 1) % n, f, (f + 1) % n])
            edge = np.where(which < 2, f, e)
            found |= self.near_candidates(d, vertex, edge)
        return found

    def near_candidates(self, d, vertex, edge) -> bool:
        """Keep the closest (vertex, edge) pair nearer than the floor; return whether there is one."""
        near = np.flatnonzero(d < self.floor)
        if not near.size:
            return False
        # Closest first, then the smallest vertex and edge numbers.
        k = near[np.lexsort((edge[near], vertex[near], d[near]))[0]]
        cand = (float(d[k]), int(vertex[k]), int(edge[k]))
        if self.near is None or cand < self.near:
            self.near = cand
        return True


def _grid_scan(q: NDArray[np.float64], reach: float, scan: _PairScan, name: str, origin) -> None:
    """Test every pair of non-adjacent edges that come within ``reach`` of each other.

    A uniform grid of square cells, sized from the edge lengths, records the
    cells each edge passes within ``reach`` of (the cells along the segment,
    not its bounding box, so a long diagonal edge costs its length in cells,
    not its square). Only edges sharing a cell are tested. A cell holding more
    than _CROWD edges is split into _SPLIT x _SPLIT smaller ones, again and
    again down to a few ``reach`` wide, so a polygon that is detailed in one
    place and coarse elsewhere still costs O(n log n).

    Once a crossing is known, only crowded cells that could hold one with
    smaller edge numbers are split further. Crowded cells that cannot be split
    (a few ``reach`` wide) are tested until the first fault (see
    _test_crowded_cells), so the fault named is then not always the first.

    ``q`` are the vertices relative to their bounding box's corner
    ``origin`` (so all >= 0).

    Raises
    ------
    PolygonError
        If the work would exceed about 16 n cell entries or 64 n pair tests
        (plus a few million of each), with no fault found on the way. Only
        long edges running side by side, close together over much of the
        polygon, need that much; meshing such a polygon would need millions
        of triangles.
    """
    n = len(q)
    r = np.roll(q, -1, axis=0)
    xa, ya, xb, yb = q[:, 0], q[:, 1], r[:, 0], r[:, 1]
    span = float(q.max())
    # Cells are found in floating point: widen the reach well beyond rounding.
    d = reach * (1.0 + 1e-9) + 64.0 * np.finfo(np.float64).eps * span
    length = np.hypot(xb - xa, yb - ya)
    taxicab = float(np.abs(xb - xa).sum() + np.abs(yb - ya).sum())
    # Cells about as long as a typical edge, but long enough that all edges
    # together pass through at most about 7 n cells.
    h = max(median(length), taxicab / (4.0 * n), 4.0 * d)
    del r, length
    budget = _ENTRIES_PER_EDGE * n + _ENTRIES_EXTRA
    scan.budget = scan.tested + _PAIRS_PER_EDGE * n + _PAIRS_EXTRA
    ids = np.arange(n, dtype=np.int32)
    clip = None
    crowd = None  # the most crowded cell of the first level: (centre, width, edges)
    try:
        while True:
            try:
                key, eid, rows = _cells(xa, ya, xb, yb, ids, h, d, clip, span, budget)
            except _OverBudget:
                if clip is not None:
                    raise
                h *= 2.0  # first level: larger cells, fewer entries
                continue
            budget -= len(key)
            order = np.argsort(key, kind="stable")
            key = key[order]
            eid = eid[order]
            del order
            starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
            sizes = np.diff(np.r_[starts, len(key)])
            crowded = sizes > _CROWD
            for e, f in _group_pairs(eid, starts[~crowded], sizes[~crowded], n):
                scan.test(e, f)
            if scan.cross is not None:
                # Only a crossing with smaller edge numbers matters now: it
                # needs an edge numbered at most the found pair's first.
                crowded &= np.minimum.reduceat(eid, starts) <= scan.cross[0]
            if not crowded.any():
                return
            if h / _SPLIT < 2.0 * d:
                _test_crowded_cells(eid, starts[crowded], sizes[crowded], n, scan)
                return
            if crowd is None:
                big = int(np.argmax(sizes))
                c, rw = divmod(int(key[starts[big]]), rows)
                crowd = (np.array([(c - 0.5) * h, (rw - 0.5) * h]) + origin, h, int(sizes[big]))
            # A cell is often crowded because of a fault (many edges crossing
            # at one point): test some of its pairs before splitting it.
            for e, f in _group_pairs(eid, starts[crowded], np.minimum(sizes[crowded], _CROWD + 1), n):
                scan.test(e, f)
            # Split the crowded cells: their edges again, into cells _SPLIT
            # times smaller, but only within the crowded cell.
            member = np.repeat(crowded, sizes)
            ids = eid[member]
            col, row = np.divmod(key[member], rows)
            del key, eid, member, starts, sizes, crowded
            col = ((col - 1) * _SPLIT).astype(np.int32)
            row = ((row - 1) * _SPLIT).astype(np.int32)
            clip = (col, col + (_SPLIT - 1), row, row + (_SPLIT - 1))
            del col, row
            h /= _SPLIT
    except _OverBudget:
        if scan.faulty():
            return  # the caller names the fault found on the way
        where = (
            f" (for one, {crowd[2]:,} edges pass through the square {format_number(crowd[1])} px wide "
            f"centred at {format_point(crowd[0])})"
            if crowd
            else ""
        )
        raise PolygonError(
            f"{name}: polygon is too intricate to check in reasonable time: long edges run close "
            f"together over much of it{where}; simplify it"
        ) from None


def _cells(xa, ya, xb, yb, ids, h, d, clip, span, budget):
    """Cells (as keys) that edges ``ids`` pass within ``d`` of, for cells of size ``h``.

    Cell (col, row) is [col h, (col + 1) h) x [row h, (row + 1) h); its key
    is (col + 1) * rows + row + 1. ``clip`` is None or per-edge inclusive
    bounds (col_lo, col_hi, row_lo, row_hi). Returns (keys, edge ids, rows).
    Raises _OverBudget beyond ``budget`` entries.
    """
    rows = int(math.floor((span + d) / h)) + 3
    keys = [np.empty(0, np.int64)]
    eids = [np.empty(0, ids.dtype)]
    total = 0
    for s in range(0, len(ids), _BLOCK):
        sl = slice(s, s + _BLOCK)
        e = ids[sl]
        x0, y0, x1, y1 = xa[e], ya[e], xb[e], yb[e]
        xlo = np.minimum(x0, x1)
        xhi = np.maximum(x0, x1)
        c0 = np.floor((xlo - d) / h).astype(np.int64)
        c1 = np.floor((xhi + d) / h).astype(np.int64)
        if clip is not None:
            c0 = np.maximum(c0, clip[0][sl])
            c1 = np.minimum(c1, clip[1][sl])
        ncol = np.maximum(c1 - c0 + 1, 0)
        if total + int(ncol.sum()) > budget:
            raise _OverBudget
        for k, col in _runs(c0, ncol):
            # One entry per (edge, column): the part of the edge within d of
            # the column's slab of x, and so the rows it passes within d of.
            sx0 = np.maximum(col * h - d, xlo[k])
            sx1 = np.minimum((col + 1) * h + d, xhi[k])
            dx = x1[k] - x0[k]
            with np.errstate(divide="ignore", invalid="ignore"):
                t0 = np.where(dx != 0, np.clip((sx0 - x0[k]) / dx, 0.0, 1.0), 0.0)
                t1 = np.where(dx != 0, np.clip((sx1 - x0[k]) / dx, 0.0, 1.0), 1.0)
            dy = y1[k] - y0[k]
            y_0 = y0[k] + t0 * dy
            y_1 = y0[k] + t1 * dy
            r0 = np.floor((np.minimum(y_0, y_1) - d) / h).astype(np.int64)
            r1 = np.floor((np.maximum(y_0, y_1) + d) / h).astype(np.int64)
            if clip is not None:
                r0 = np.maximum(r0, clip[2][sl][k])
                r1 = np.minimum(r1, clip[3][sl][k])
            nrow = np.maximum(r1 - r0 + 1, 0)
            total += int(nrow.sum())
            if total > budget:
                raise _OverBudget
            for j, row in _runs(r0, nrow):
                keys.append((col[j] + 1) * rows + (row + 1))
                eids.append(e[k[j]])
    return np.concatenate(keys), np.concatenate(eids), rows


def _blocks(count, block: int) -> Iterator[slice]:
    """Consecutive slices of ``count`` whose sums are about ``block`` (at least one element each)."""
    cum = np.cumsum(count)
    u = 0
    while u < len(count):
        done = int(cum[u - 1]) if u else 0
        v = max(int(np.searchsorted(cum, done + block, side="right")), u + 1)
        yield slice(u, v)
        u = v


def _runs(start, count, block: int = _BLOCK) -> Iterator[tuple[NDArray[np.intp], NDArray[np.int64]]]:
    """``(i, start[i] + m)`` for m in range(count[i]), for every i, in blocks of about ``block``."""
    for sl in _blocks(count, block):
        c = count[sl]
        i = np.repeat(np.arange(sl.start, sl.stop), c)
        yield i, start[i] + (np.arange(len(i)) - np.repeat(np.cumsum(c) - c, c))


def _group_pairs(eid, starts, sizes, n) -> Iterator[tuple[NDArray[np.intp], NDArray[np.intp]]]:
    """All pairs of non-adjacent edges within each group, in blocks: (e, f), e < f.

    Group g is ``eid[starts[g]:starts[g] + sizes[g]]``.
    """
    keep = sizes > 1
    starts = starts[keep]
    sizes = sizes[keep]
    for g in _blocks(sizes, _BLOCK):
        # Groups g, about _BLOCK entries in all. Entry p of a group pairs with
        # the entries after it in the same group.
        st = starts[g]
        sz = sizes[g]
        pos = np.repeat(st - (np.cumsum(sz) - sz), sz) + np.arange(int(sz.sum()))
        count = np.repeat(st + sz, sz) - pos - 1
        for k, second in _runs(pos + 1, count, block=_PAIR_BLOCK):
            e = eid[pos[k]]
            f = eid[second]
            lo = np.minimum(e, f)
            hi = np.maximum(e, f)
            gap = hi - lo
            ok = (gap > 1) & (gap != n - 1)
            yield lo[ok], hi[ok]


def _test_crowded_cells(eid, starts, sizes, n, scan: _PairScan) -> None:
    """Cells too small to split that hold more than _CROWD edges; stop at the first fault.

    A valid polygon has no cell of more than _CROWD_FINAL edges (see there),
    so among a cell's first _CROWD_FINAL + 1 edges there is a fault, or the
    adjacent-edge checks found one. Only if neither (and the clearance is
    being checked, so the polygon is not about to be refused for zero area)
    are all pairs of such a cell tested.
    """
    for e, f in _group_pairs(eid, starts, np.minimum(sizes, _CROWD_FINAL + 1), n):
        if scan.test(e, f):
            return
    big = sizes > _CROWD_FINAL
    if not big.any() or scan.faulty() or not scan.clearance:
        return
    for e, f in _group_pairs(eid, starts[big], sizes[big], n):
        if scan.test(e, f):
            return


class _OverBudget(Exception):
    """The grid would need more cell entries than the budget."""
