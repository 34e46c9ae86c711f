"""Polygon stage: reading polygon files and validating simple polygons."""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import PolygonError

#: Largest coordinate magnitude accepted, in pixels: far beyond any image, and
#: small enough that areas and orientation tests cannot overflow.
COORD_LIMIT = 1e9

# Pairs of edges are tested in blocks of this many, so that the O(n^2) test of
# a polygon with thousands of vertices stays within a few tens of megabytes.
_PAIR_BLOCK = 1 << 20


@dataclass(frozen=True)
class Polygon:
    """A simple polygon in continuous image coordinates.

    Parameters
    ----------
    points : (n, 2) array_like of float
        Vertices in order, x to the right and y down, the top-left corner of
        the top-left pixel at the origin. The polygon closes itself: do not
        repeat the first vertex at the end. Edge ``i`` runs from vertex ``i``
        to vertex ``i + 1`` (mod n).
    name : str
        How error messages refer to the polygon, usually its file name.

    Raises
    ------
    PolygonError
        If the points do not form a simple polygon with non-zero area.
    """

    points: NDArray[np.float64]
    name: str = field(default="polygon")

    def __post_init__(self) -> None:
        pts = _as_points(self.points, self.name)
        validate_points(pts, self.name)
        pts.setflags(write=False)
        object.__setattr__(self, "points", pts)

    @property
    def n(self) -> int:
        """Number of vertices."""
        return len(self.points)

    @property
    def signed_area(self) -> float:
        """Shoelace area: positive when the vertices run clockwise on screen (y down)."""
        return signed_area(self.points)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)``."""
        lo = self.points.min(axis=0)
        hi = self.points.max(axis=0)
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])

    def reflex_vertices(self) -> NDArray[np.intp]:
        """Indices of the vertices whose interior angle exceeds pi."""
        p = self.points
        a = p - np.roll(p, 1, axis=0)
        b = np.roll(p, -1, axis=0) - p
        turn = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
        return np.flatnonzero(turn * math.copysign(1.0, self.signed_area) < 0)


def signed_area(points: NDArray[np.float64]) -> float:
    """Shoelace formula; the sign gives the orientation.

    >>> signed_area(np.array([[0.0, 0.0], [2.0, 0.0], [0.0, 1.0]]))
    1.0
    """
    x = points[:, 0]
    y = points[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def read_polygon(path: str | os.PathLike[str], label: str | None = None) -> Polygon:
    """Read a polygon from a JSON file, recognising the format by its content.

    - plain: an array of ``[x, y]`` pairs, or an object whose ``"points"``
      member is one;
    - labelme: an object with ``"shapes"``; the one polygon shape, or the
      polygon shape whose ``"label"`` is ``label``;
    - GeoJSON: a ``Polygon`` geometry, a ``Feature`` holding one, or a
      ``FeatureCollection`` with exactly one (or, given ``label``, the one whose
      ``properties.label`` or ``properties.name`` is ``label``); the exterior
      ring ends with its first vertex again, which is not a vertex of its own.

    Coordinates are taken as they are: continuous image coordinates, x right,
    y down, origin at the image's top-left corner.

    Parameters
    ----------
    path : path-like
        The polygon file.
    label : str or None
        Which polygon to take from a file holding several.

    Returns
    -------
    Polygon

    Raises
    ------
    PolygonError
        If the file cannot be read, is not JSON of one of these shapes, or the
        polygon is invalid. The message starts with the file's name.
    """
    name = os.fspath(path)
    try:
        with open(name, "rb") as fh:
            raw = fh.read()
    except OSError as err:
        raise PolygonError(f"{name}: cannot read polygon file: {err.strerror or err}") from err
    try:
        doc = json.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as err:
        raise PolygonError(f"{name}: not a JSON text file (invalid UTF-8 at byte {err.start})") from err
    except json.JSONDecodeError as err:
        raise PolygonError(
            f"{name}: invalid JSON at line {err.lineno}, column {err.colno}: {err.msg}"
        ) from err
    except RecursionError as err:
        raise PolygonError(f"{name}: invalid JSON: nested too deeply") from err
    return Polygon(_points_of(doc, name, label), name=name)


def _points_of(doc: object, name: str, label: str | None) -> object:
    """The vertex list of a parsed polygon document (plain, labelme or GeoJSON)."""
    if isinstance(doc, list):
        return _unlabelled(doc, name, label)
    if not isinstance(doc, dict):
        raise PolygonError(f"{name}: expected an array of [x, y] pairs")
    if "shapes" in doc:
        return _labelme_points(doc, name, label)
    if doc.get("type") in ("Polygon", "Feature", "FeatureCollection", "MultiPolygon"):
        return _geojson_points(doc, name, label)
    if "points" in doc:
        return _unlabelled(doc["points"], name, label)
    raise PolygonError(
        f'{name}: JSON object has no "points" member (and is neither a labelme file nor GeoJSON)'
    )


def _unlabelled(points: object, name: str, label: str | None) -> object:
    if label is not None:
        raise PolygonError(f"{name}: holds a single polygon with no labels, but label {label!r} was asked for")
    return points


def _labelme_points(doc: dict, name: str, label: str | None) -> object:
    shapes = doc["shapes"]
    if not isinstance(shapes, list):
        raise PolygonError(f'{name}: labelme "shapes" must be an array')
    polys = [s for s in shapes if isinstance(s, dict) and s.get("shape_type", "polygon") == "polygon"]
    labels = [str(s.get("label")) for s in polys]
    if label is not None:
        chosen = [s for s in polys if s.get("label") == label]
        if len(chosen) != 1:
            what = "no" if not chosen else f"{len(chosen)}"
            raise PolygonError(
                f"{name}: labelme file has {what} polygon labelled {label!r} (labels: {', '.join(labels) or 'none'})"
            )
        polys = chosen
    if len(polys) != 1:
        if not polys:
            raise PolygonError(f"{name}: labelme file has no polygon shape")
        raise PolygonError(
            f"{name}: labelme file has {len(polys)} polygons ({', '.join(labels)}); choose one with a label option"
        )
    if "points" not in polys[0]:
        raise PolygonError(f'{name}: labelme shape has no "points"')
    return polys[0]["points"]


def _geojson_points(doc: dict, name: str, label: str | None) -> object:
    kind = doc.get("type")
    if kind == "FeatureCollection":
        features = [f for f in doc.get("features") or [] if isinstance(f, dict)]
        if label is not None:
            features = [f for f in features if label in _feature_names(f)]
        if len(features) != 1:
            which = f" labelled {label!r}" if label is not None else ""
            raise PolygonError(
                f"{name}: GeoJSON FeatureCollection has {len(features)} features{which}; it must have exactly one"
                + ("" if label is not None else " (or choose one with a label option)")
            )
        doc = features[0]
        kind = doc.get("type")
    elif label is not None and kind == "Feature" and label not in _feature_names(doc):
        raise PolygonError(f"{name}: the GeoJSON feature is not labelled {label!r}")
    elif label is not None and kind != "Feature":
        raise PolygonError(f"{name}: a GeoJSON geometry has no label, but label {label!r} was asked for")
    if kind == "Feature":
        doc = doc.get("geometry")
        if not isinstance(doc, dict):
            raise PolygonError(f"{name}: GeoJSON feature has no geometry")
        kind = doc.get("type")
    if kind != "Polygon":
        raise PolygonError(f"{name}: GeoJSON geometry is a {kind}, not a Polygon")
    rings = doc.get("coordinates")
    if not isinstance(rings, list) or not rings:
        raise PolygonError(f"{name}: GeoJSON Polygon has no coordinates")
    if len(rings) > 1:
        raise PolygonError(f"{name}: GeoJSON Polygon has {len(rings) - 1} hole(s); polygons with holes are not supported")
    ring = rings[0]
    if not isinstance(ring, list) or len(ring) < 2 or ring[0] != ring[-1]:
        raise PolygonError(f"{name}: GeoJSON ring must end with its first vertex (a closed linear ring)")
    return ring[:-1]


def _feature_names(feature: dict) -> tuple:
    props = feature.get("properties") or {}
    return tuple(props.get(k) for k in ("label", "name") if isinstance(props, dict) and k in props)


def check_pair(src: Polygon, dst: Polygon) -> None:
    """Check that two polygons can be mapped onto each other vertex by vertex.

    Raises
    ------
    PolygonError
        If the vertex counts differ.
    """
    if src.n != dst.n:
        raise PolygonError(
            f"{dst.name}: polygon has {dst.n} vertices but {src.name} has {src.n}"
        )


def _as_points(data: ArrayLike, name: str) -> NDArray[np.float64]:
    """Turn parsed JSON (or any array-like) into an (n, 2) float array, strictly."""
    if isinstance(data, np.ndarray):
        if data.ndim != 2 or data.shape[1] != 2 or data.dtype.kind not in "iuf":
            raise PolygonError(f"{name}: points must be an (n, 2) array of numbers")
        pts = np.array(data, dtype=np.float64)
    else:
        if not isinstance(data, (list, tuple)):
            raise PolygonError(f"{name}: expected an array of [x, y] pairs")
        for i, pair in enumerate(data):
            if not isinstance(pair, (list, tuple)) or len(pair) != 2:
                raise PolygonError(f"{name}: vertex {i} is not an [x, y] pair: {_short(pair)}")
            for value in pair:
                # bool is an int subclass in Python; true/false are not coordinates.
                if isinstance(value, bool) or not isinstance(value, (int, float)):
                    raise PolygonError(
                        f"{name}: vertex {i} has a non-numeric coordinate: {_short(value)}"
                    )
                # JSON integers are unbounded; one beyond a float's range
                # would overflow the conversion below.
                if isinstance(value, int) and abs(value) > COORD_LIMIT:
                    raise PolygonError(_out_of_range(name, i, value))
        pts = np.array(data, dtype=np.float64).reshape(-1, 2)
    bad = np.flatnonzero(~np.isfinite(pts).all(axis=1))
    if bad.size:
        i = int(bad[0])
        raise PolygonError(f"{name}: vertex {i} has a non-finite coordinate: {pts[i].tolist()}")
    big = np.flatnonzero((np.abs(pts) > COORD_LIMIT).any(axis=1))
    if big.size:
        i = int(big[0])
        raise PolygonError(_out_of_range(name, i, float(pts[i][np.argmax(np.abs(pts[i]))])))
    return pts


def _out_of_range(name: str, i: int, value: float) -> str:
    return (
        f"{name}: vertex {i} has a coordinate out of range: {_short(value)} "
        f"(coordinates must be within +-{COORD_LIMIT:.0e} pixels)"
    )


def validate_points(pts: NDArray[np.float64], name: str) -> None:
    """Raise PolygonError unless ``pts`` is a simple polygon with non-zero area."""
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
            _check_crossings(pts, name)
        raise PolygonError(f"{name}: polygon has zero area")
    _check_crossings(pts, name)


def _check_repeats(pts: NDArray[np.float64], name: str) -> None:
    order = np.lexsort((pts[:, 1], pts[:, 0]))
    s = pts[order]
    same = np.flatnonzero((s[1:] == s[:-1]).all(axis=1))
    if same.size:
        i, j = sorted((int(order[same[0]]), int(order[same[0] + 1])))
        hint = " (list each vertex once; the polygon closes itself)" if (i, j) == (0, len(pts) - 1) else ""
        raise PolygonError(
            f"{name}: vertices {i} and {j} are repeated at {_fmt_point(pts[i])}{hint}"
        )


def _collinear(pts: NDArray[np.float64]) -> bool:
    """Whether all points lie on one line (up to rounding)."""
    d = pts - pts[0]
    far = d[np.argmax(np.hypot(d[:, 0], d[:, 1]))]
    cross = np.abs(d[:, 0] * far[1] - d[:, 1] * far[0])
    return bool(cross.max() <= 1e-12 * float(far @ far))


def _orient(ax, ay, bx, by, cx, cy):
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


def _check_crossings(pts: NDArray[np.float64], name: str) -> None:
    """Find the first pair of edges that touch other than at a shared vertex."""
    n = len(pts)
    a = pts
    b = np.roll(pts, -1, axis=0)
    # Adjacent edges share a vertex; they only overlap if the boundary doubles
    # back on itself (a zero-angle spike).
    prev = np.roll(pts, 1, axis=0)
    turn = _orient(prev[:, 0], prev[:, 1], a[:, 0], a[:, 1], b[:, 0], b[:, 1])
    back = np.einsum("ij,ij->i", prev - a, b - a) > 0
    spikes = np.flatnonzero((turn == 0) & back)
    if spikes.size:
        i = int(spikes[0])
        raise PolygonError(
            f"{name}: edges {(i - 1) % n} and {i} overlap (the boundary doubles back at vertex {i}, "
            f"{_fmt_point(pts[i])})"
        )
    if n < 4:
        return
    # Non-adjacent pairs (i, j), i < j, j - i >= 2, excluding (0, n - 1).
    rows_per_block = max(1, _PAIR_BLOCK // n)
    for i0 in range(0, n - 2, rows_per_block):
        i = np.arange(i0, min(i0 + rows_per_block, n - 2))
        ii, jj = np.meshgrid(i, np.arange(n), indexing="ij")
        keep = (jj >= ii + 2) & ~((ii == 0) & (jj == n - 1))
        ii = ii[keep]
        jj = jj[keep]
        if ii.size == 0:
            continue
        hit = _segments_touch(a[ii], b[ii], a[jj], b[jj])
        if hit.any():
            k = int(np.flatnonzero(hit)[0])
            e, f = int(ii[k]), int(jj[k])
            where = _intersection_point(a[e], b[e], a[f], b[f])
            raise PolygonError(
                f"{name}: polygon is self-intersecting: edges {e} and {f} cross at {_fmt_point(where)}"
            )


def _segments_touch(p1, p2, q1, q2) -> NDArray[np.bool_]:
    """Whether closed segments p1p2 and q1q2 share at least one point (vectorized)."""
    o1 = _orient(p1[:, 0], p1[:, 1], p2[:, 0], p2[:, 1], q1[:, 0], q1[:, 1])
    o2 = _orient(p1[:, 0], p1[:, 1], p2[:, 0], p2[:, 1], q2[:, 0], q2[:, 1])
    o3 = _orient(q1[:, 0], q1[:, 1], q2[:, 0], q2[:, 1], p1[:, 0], p1[:, 1])
    o4 = _orient(q1[:, 0], q1[:, 1], q2[:, 0], q2[:, 1], p2[:, 0], p2[:, 1])
    proper = (np.sign(o1) * np.sign(o2) < 0) & (np.sign(o3) * np.sign(o4) < 0)
    touch = (
        ((o1 == 0) & _on_box(p1, p2, q1))
        | ((o2 == 0) & _on_box(p1, p2, q2))
        | ((o3 == 0) & _on_box(q1, q2, p1))
        | ((o4 == 0) & _on_box(q1, q2, p2))
    )
    return proper | touch


def _on_box(a, b, c) -> NDArray[np.bool_]:
    """For c collinear with segment ab: whether c lies on the segment."""
    lo = np.minimum(a, b)
    hi = np.maximum(a, b)
    return ((c >= lo) & (c <= hi)).all(axis=1)


def _intersection_point(p1, p2, q1, q2) -> NDArray[np.float64]:
    d1 = p2 - p1
    d2 = q2 - q1
    den = d1[0] * d2[1] - d1[1] * d2[0]
    if den == 0:
        # Collinear overlap: report an endpoint that lies on the other segment.
        for c, (a, b) in ((q1, (p1, p2)), (q2, (p1, p2)), (p1, (q1, q2)), (p2, (q1, q2))):
            if _on_box(a[None], b[None], c[None])[0]:
                return c
        return p1
    t = ((q1[0] - p1[0]) * d2[1] - (q1[1] - p1[1]) * d2[0]) / den
    return p1 + t * d1


def _fmt_point(p) -> str:
    return f"({_fmt_num(p[0])}, {_fmt_num(p[1])})"


def _fmt_num(v: float) -> str:
    """Six significant digits, always with a decimal point or exponent: 2.0, 0.666667, 1e+08."""
    text = f"{float(v):.6g}"
    return text if any(ch in text for ch in ".en") else text + ".0"


def _short(value: object) -> str:
    text = repr(value) if isinstance(value, float) else json.dumps(value)
    return text if len(text) <= 40 else text[:37] + "..."
