"""Annotations carried by a warp's map: keypoints, boxes, masks and label images.

An image's annotations must move with its pixels: a keypoint stays on the
pixel it marks, a segmentation stays on its object. Everything here goes
through the one map an image is warped with (a `BijectiveMap`, or a
`WarpResult`, `SamplingPlan` or `PolygonTransform` holding it), in warpcli's
coordinates (pixel ``(r, c)`` has its centre at ``(c + 0.5, r + 0.5)``):

- points (`warp_points`) are mapped exactly, forward like the picture;
  a point without an image (outside the polygon) is NaN and flagged in a
  mask, never a sentinel value;
- boxes (`warp_boxes`) are polygons: their outlines are sampled along the
  edges and mapped, and the bounding box of the mapped outline is returned
  with it;
- masks and label images (`warp_labels`) are resampled with nearest, so no
  label is ever blended with another: every output value is an input value
  or the background (0 by default), for any integer (or bool) type, at the
  same source point as the image's pixel.
"""

from __future__ import annotations

import dataclasses
import os
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import InputError
from .maps.cage import map_between
from .maps.compose import BijectiveMap
from .options import MapOptions, check_size
from .polygon import Polygon
from .polygon.partition import Partition, read_shape

__all__ = ["WarpedBoxes", "WarpedPoints", "map_of", "warp_boxes", "warp_labels", "warp_points"]


class WarpedPoints(NamedTuple):
    """Points carried through a map.

    Attributes
    ----------
    points : (K, 2) ndarray of float
        The mapped points; NaN for a point without an image.
    inside : (K,) ndarray of bool
        Whether each point had an image (lay inside the polygon).
    """

    points: NDArray[np.float64]
    inside: NDArray[np.bool_]


class WarpedBoxes(NamedTuple):
    """Axis-aligned boxes carried through a map.

    Attributes
    ----------
    boxes : (K, 4) ndarray of float
        ``(xmin, ymin, xmax, ymax)`` of each mapped outline's points that
        have an image; NaN for a box none of whose outline has one.
    outlines : (K, 4 * samples, 2) ndarray of float
        Each box's outline, sampled along its edges (corners first on each
        edge, clockwise on screen from the top-left corner) and mapped; NaN
        where a sample has no image.
    inside : (K,) ndarray of bool
        Whether the whole outline had an image.
    """

    boxes: NDArray[np.float64]
    outlines: NDArray[np.float64]
    inside: NDArray[np.bool_]


def map_of(where: Any) -> BijectiveMap:
    """The `BijectiveMap` held by a map, a warp's result or a scikit-image transform.

    Parameters
    ----------
    where : BijectiveMap, WarpResult or PolygonTransform
        Anything with the map: itself, or its ``map`` attribute.

    Returns
    -------
    BijectiveMap

    Raises
    ------
    InputError
        If ``where`` holds no map.
    """
    fmap = getattr(where, "map", where)
    if not (callable(getattr(fmap, "forward", None)) and callable(getattr(fmap, "inverse", None))):
        raise InputError(f"expected a map (BijectiveMap, WarpResult or PolygonTransform), got {type(where).__name__}")
    return fmap


def _polygon(poly: Polygon | Partition | ArrayLike | str | os.PathLike[str], name: str) -> Polygon | Partition:
    if isinstance(poly, (Polygon, Partition)):
        return poly
    if isinstance(poly, (str, os.PathLike)):
        return read_shape(poly)  # a polygon file, or a cage mesh's
    return Polygon(np.asarray(poly, dtype=np.float64), name=name)


def _the_map(src, dst, fmap, options: MapOptions | None, changes: dict) -> BijectiveMap:
    if fmap is not None:
        if src is not None or dst is not None or options is not None or changes:
            raise InputError("give either a map (fmap=...) or the polygons src and dst with their options, not both")
        return map_of(fmap)
    if src is None or dst is None:
        raise InputError("give the polygons src and dst, or a map (fmap=...)")
    a, b = _polygon(src, "src"), _polygon(dst, "dst")
    if isinstance(a, Partition) or isinstance(b, Partition):
        opts = options or MapOptions()
        if changes:
            try:
                opts = dataclasses.replace(opts, **changes)
            except TypeError as err:
                raise InputError(f"unknown map option: {err}") from None
        return map_between(a, b, opts)  # type: ignore[return-value]
    return BijectiveMap.between(a, b, options, **changes)


def _as_points(points: ArrayLike, what: str, width: int) -> NDArray[np.float64]:
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != width:
        raise InputError(f"{what} must be a (K, {width}) array, got shape {pts.shape}")
    if not np.isfinite(pts).all():
        raise InputError(f"{what} must be finite numbers")
    return pts


def warp_points(
    points: ArrayLike,
    src: Polygon | ArrayLike | str | os.PathLike[str] | None = None,
    dst: Polygon | ArrayLike | str | os.PathLike[str] | None = None,
    *,
    fmap: Any = None,
    inverse: bool = False,
    options: MapOptions | None = None,
    **changes: Any,
) -> WarpedPoints:
    """Carry points (keypoints, landmarks) of the source image to the warped image.

    Parameters
    ----------
    points : (K, 2) array_like of float
        ``(x, y)`` in warpcli's pixel coordinates (pixel centres at +0.5;
        add 0.5 to scikit-image's or OpenCV's integer centres).
    src, dst : Polygon, Partition, (n, 2) array_like or path-like, optional
        The polygons of the warp (vertex i of ``src`` onto vertex i of
        ``dst``), or two cage meshes; a path is read as a polygon file (or a
        cage mesh's, `warpcli.polygon.partition.read_shape`).
    fmap : BijectiveMap, WarpResult or PolygonTransform, optional
        The map an image was warped with, instead of ``src`` and ``dst``:
        the points then move exactly as that image's pixels did (a
        retouch's result, ``within=``: points outside its outline stay where
        they are, as the image does there, and count as inside).
    inverse : bool
        Map points of the warped image back to the source.
    options : MapOptions or None
        How the map is built from ``src`` and ``dst``; ``**changes`` change
        its fields (``method="bem"``).

    Returns
    -------
    WarpedPoints
        The mapped points (NaN for points outside the polygon) and a mask of
        those that had an image.

    Raises
    ------
    InputError
        For points that are not a finite (K, 2) array, or neither polygons
        nor a map (or both).

    Examples
    --------
    >>> square = [[0, 0], [100, 0], [100, 100], [0, 100]]
    >>> kite = [[0, 0], [120, 10], [100, 100], [-10, 90]]
    >>> moved = warp_points([[0, 0], [50, 50], [500, 5]], square, kite)
    >>> moved.inside
    array([ True,  True, False])
    >>> bool(np.abs(moved.points[0]).max() < 1e-9)  # a vertex goes onto its vertex
    True
    """
    fm = _the_map(src, dst, fmap, options, changes)
    pts = _as_points(points, "points", 2)
    out = fm.inverse(pts) if inverse else fm.forward(pts)
    inside = np.isfinite(out).all(axis=1)
    if getattr(fmap, "within", None) is not None:
        # A retouch's result: outside the outline the image is the input's own, and so are the
        # points (as `warp points --within`).
        out[~inside] = pts[~inside]
        return WarpedPoints(out, np.ones(len(pts), dtype=bool))
    out[~inside] = np.nan
    return WarpedPoints(out, inside)


def box_outlines(boxes: ArrayLike, samples: int = 16) -> NDArray[np.float64]:
    """Points along the edges of axis-aligned boxes.

    Parameters
    ----------
    boxes : (K, 4) array_like of float
        ``(xmin, ymin, xmax, ymax)``.
    samples : int
        Points per edge (the corner it starts at included), at least 1.

    Returns
    -------
    (K, 4 * samples, 2) ndarray of float
        Top edge left to right, right edge down, bottom edge right to left,
        left edge up.
    """
    b = _as_points(boxes, "boxes", 4)
    if samples < 1:
        raise InputError(f"samples must be at least 1, got {samples}")
    x0, y0, x1, y1 = (b[:, k : k + 1] for k in range(4))
    t = np.arange(samples) / samples
    edges = [
        (x0 + (x1 - x0) * t, np.broadcast_to(y0, (len(b), samples))),
        (np.broadcast_to(x1, (len(b), samples)), y0 + (y1 - y0) * t),
        (x1 + (x0 - x1) * t, np.broadcast_to(y1, (len(b), samples))),
        (np.broadcast_to(x0, (len(b), samples)), y1 + (y0 - y1) * t),
    ]
    xs = np.concatenate([e[0] for e in edges], axis=1)
    ys = np.concatenate([e[1] for e in edges], axis=1)
    return np.stack([xs, ys], axis=2)


def warp_boxes(
    boxes: ArrayLike,
    src: Polygon | ArrayLike | str | os.PathLike[str] | None = None,
    dst: Polygon | ArrayLike | str | os.PathLike[str] | None = None,
    *,
    fmap: Any = None,
    inverse: bool = False,
    samples: int = 16,
    options: MapOptions | None = None,
    **changes: Any,
) -> WarpedBoxes:
    """Carry axis-aligned boxes (detections) through the map, as polygons.

    A box's image under a smooth map is a curved quadrilateral: its outline
    is sampled with ``samples`` points per edge and mapped, and the box
    returned is the bounding box of the mapped outline. (Mapping the corners
    alone would miss where an edge bulges.)

    Parameters
    ----------
    boxes : (K, 4) array_like of float
        ``(xmin, ymin, xmax, ymax)`` in warpcli's pixel coordinates.
    src, dst, fmap, inverse, options, **changes
        As for `warp_points`.
    samples : int
        Points per edge of the outline.

    Returns
    -------
    WarpedBoxes
        The bounding boxes, the mapped outlines, and which boxes lay wholly
        inside the polygon. A box partly outside gets the bounding box of
        the image of its part inside the polygon: its outline there, and the
        polygon's edges inside the box, which go exactly onto the other
        polygon's edges (a box round the whole polygon gets the other
        polygon's bounding box; a cage mesh's map: the outline's part alone).
        A box with no point in the polygon is NaN.

    Examples
    --------
    >>> square = [[0, 0], [100, 0], [100, 100], [0, 100]]
    >>> out = warp_boxes([[0, 0, 100, 100]], square, square)
    >>> bool(np.allclose(out.boxes, [[0, 0, 100, 100]], rtol=0, atol=1e-9))
    True
    """
    fm = _the_map(src, dst, fmap, options, changes)
    outline = box_outlines(boxes, samples)
    k, n, _ = outline.shape
    moved = warp_points(outline.reshape(-1, 2), fmap=fm, inverse=inverse).points.reshape(k, n, 2)
    ok = np.isfinite(moved[..., 0])
    lo = np.where(ok[..., None], moved, np.inf).min(axis=1)
    hi = np.where(ok[..., None], moved, -np.inf).max(axis=1)
    edge_lo, edge_hi = _boundary_in_boxes(fm, _as_points(boxes, "boxes", 4), inverse)
    lo, hi = np.minimum(lo, edge_lo), np.maximum(hi, edge_hi)
    out = np.concatenate([lo, hi], axis=1)
    out[~np.isfinite(out).all(axis=1)] = np.nan
    return WarpedBoxes(out, moved, ok.all(axis=1))


def _boundary_in_boxes(fm: Any, boxes: NDArray[np.float64], inverse: bool) -> tuple[NDArray, NDArray]:
    """The bounding boxes (lo, hi: (K, 2), inf where none) of the images of the parts of the
    polygon's edges inside each box.

    The image of a box is that of its part inside the polygon, whose outline is the box's outline
    inside the polygon (sampled by `warp_boxes`) and the polygon's edges inside the box. An edge
    goes onto the other polygon's edge, a straight segment, monotonically: the image of the part
    from t0 to t1 is the segment between the images of t0 and t1, exact. (Cage meshes: none.)
    """
    k = len(boxes)
    lo, hi = np.full((k, 2), np.inf), np.full((k, 2), -np.inf)
    poly = getattr(fm, "dst" if inverse else "src", None)
    along = getattr(fm, "inverse_boundary" if inverse else "forward_boundary", None)
    if not isinstance(poly, Polygon) or along is None:
        return lo, hi
    a = poly.points
    d = np.roll(a, -1, axis=0) - a
    edge = np.arange(len(a))
    for b in range(k):
        x0, y0, x1, y1 = boxes[b]
        # Liang-Barsky: each edge's parameters inside the box.
        enter, leave = np.zeros(len(a)), np.ones(len(a))
        keep = np.ones(len(a), dtype=bool)
        for p, q in ((-d[:, 0], a[:, 0] - x0), (d[:, 0], x1 - a[:, 0]), (-d[:, 1], a[:, 1] - y0), (d[:, 1], y1 - a[:, 1])):
            with np.errstate(divide="ignore", invalid="ignore"):
                r = q / p
            keep &= ~((p == 0) & (q < 0))
            enter = np.where(p < 0, np.maximum(enter, r), enter)
            leave = np.where(p > 0, np.minimum(leave, r), leave)
        keep &= enter <= leave
        if not keep.any():
            continue
        e = edge[keep]
        ends = along(np.concatenate([e, e]), np.concatenate([enter[keep], leave[keep]]))
        ends = ends[np.isfinite(ends).all(axis=1)]
        if len(ends):
            lo[b], hi[b] = ends.min(axis=0), ends.max(axis=0)
    return lo, hi


def _source_points(where: Any, size: tuple[int, int] | None) -> NDArray[np.float64]:
    """(H, W, 2): the source point of every output pixel centre of a plan, result, map or array."""
    from .plan import SamplingPlan

    if isinstance(where, np.ndarray) or isinstance(where, (list, tuple)):
        pts = np.asarray(where, dtype=np.float64)
        if pts.ndim != 3 or pts.shape[2] != 2:
            raise InputError(f"source points must be an (H, W, 2) array, got shape {pts.shape}")
        return pts
    if isinstance(where, SamplingPlan):
        return where.pull.full_points()
    pull = getattr(where, "pull", None)
    if pull is not None and hasattr(pull, "full_points") and size is None:
        pts = pull.full_points()  # a WarpResult: the output it was rendered at
        if getattr(where, "within", None) is not None:
            # A retouch: outside its outline the output is the input's own pixel (the same size).
            none = np.isnan(pts[..., 0])
            j, i = np.nonzero(none)
            pts[j, i, 0] = i + 0.5
            pts[j, i, 1] = j + 0.5
        return pts
    fm = map_of(where)
    if size is None:
        raise InputError("warping labels through a map needs the output size (size=(width, height))")
    width, height = check_size(size)
    return fm.pull_back(width, height, jacobian=False).full_points()


def warp_labels(
    labels: ArrayLike,
    where: Any,
    size: tuple[int, int] | None = None,
    *,
    background: int | float | bool = 0,
) -> NDArray:
    """Resample a mask or label image with nearest: labels are carried, never blended.

    Each output pixel takes the label of the input pixel its centre's source
    point falls in, exactly as ``interp="nearest"`` takes an image's pixel
    (`warpcli.resample`: the border belongs to the edge pixels), so a mask
    and an image warped through one map agree pixel for pixel. Values are
    copied, not converted: any integer type (int64 IDs beyond 2**24
    included), bool masks, or floats.

    Parameters
    ----------
    labels : (H, W) or (H, W, C) array_like
        The mask or label image, the size of the image it annotates.
    where : SamplingPlan, WarpResult, BijectiveMap, PolygonTransform or (H2, W2, 2) ndarray
        The warp: a plan or a result (the output size is theirs), a map
        (give ``size``), or the source point of every output pixel centre
        (NaN: none), as ``WarpResult.inverse_map``.
    size : (width, height) or None
        The output size, for a map; by default (a map) the input's.
    background : scalar
        The label of pixels without a pre-image (0: background), also where a
        warp with ``outside="input"`` pasted the warp over its input (the
        labels are not pasted: the input's labels would stay where the
        polygon moved from; ``warp --labels`` refuses that option). A
        retouch's result (``within=``) is the exception: its map covers the
        whole outline, and outside it each pixel keeps its own label, as the
        image does.

    Returns
    -------
    (H2, W2) or (H2, W2, C) ndarray of the labels' dtype

    Raises
    ------
    InputError
        For labels that are not 2 or 3 dimensional, or a background the
        labels' type cannot hold.

    Examples
    --------
    >>> square = [[0, 0], [4, 0], [4, 4], [0, 4]]
    >>> fmap = BijectiveMap.between(Polygon(square), Polygon(square))
    >>> seg = np.arange(16, dtype=np.int64).reshape(4, 4) + 2**40
    >>> bool((warp_labels(seg, fmap) == seg).all())
    True
    """
    lab = np.asarray(labels)
    if lab.ndim not in (2, 3) or lab.size == 0:
        raise InputError(f"labels must be an (H, W) or (H, W, C) array, got shape {lab.shape}")
    h, w = lab.shape[:2]
    if size is None and not isinstance(where, np.ndarray) and getattr(where, "pull", None) is None:
        from .plan import SamplingPlan

        if not isinstance(where, SamplingPlan):
            size = (w, h)
    pts = _source_points(where, size)
    try:
        bg = np.asarray(background, dtype=lab.dtype)
    except (OverflowError, TypeError, ValueError):
        bg = None
    if bg is None or bg.item() != background:
        raise InputError(f"background {background!r} does not fit labels of type {lab.dtype}")
    x = pts[..., 0]
    y = pts[..., 1]
    # The rule of warpcli.raster._kernels.sample_nearest: inside [0, W] x [0, H]
    # (NaN is not), the pixel the point falls in, the far border to the edge pixel.
    with np.errstate(invalid="ignore"):
        ok = (x >= 0) & (x <= w) & (y >= 0) & (y <= h)
    i = np.minimum(np.where(ok, x, 0).astype(np.int64), w - 1)
    j = np.minimum(np.where(ok, y, 0).astype(np.int64), h - 1)
    out = lab[j, i]
    out[~ok] = bg
    return out
