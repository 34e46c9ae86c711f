"""Polygon files: plain JSON, labelme and GeoJSON, one polygon chosen by label or ``#N``."""

from __future__ import annotations

import json
import os

from ..errors import PolygonError
from ..files import read_small_file
from .messages import LongInteger, one_line, short_value
from .shape import Polygon

__all__ = ["MAX_FILE_BYTES", "parse_int", "parse_json", "points_of", "read_document", "read_polygon"]

#: Largest polygon file read, in bytes. A million vertices with full-precision
#: coordinates take 41 MB as a plain JSON array (55 MB indented), and a mesh
#: cannot use more boundary vertices than that anyway (see
#: ``maps.fem.mesh.AUTO_MAX_TRIANGLES``). Anything larger is not a polygon
#: (``/dev/zero``, a misnamed image or video) and would only exhaust memory:
#: parsed JSON takes 8 to 16 times the file's size.
MAX_FILE_BYTES = 64 * 1024 * 1024


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

    Only regular files of at most `MAX_FILE_BYTES` are read: a FIFO, a device
    such as ``/dev/zero`` or a directory is refused without reading from it
    (and without waiting for a FIFO's writer).

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
        If the file cannot be read, is not a regular file, is too large, is
        not JSON of one of these shapes, or the polygon is invalid. The
        message is one line and starts with the file's name.
    """
    name, doc = read_document(path)
    try:
        points = points_of(doc, name, label)
        return Polygon(points, name=name)
    except RecursionError as err:  # comparing or printing arrays nested ~1000 deep
        raise PolygonError(f"{name}: invalid polygon file: arrays nested too deeply") from err


def read_document(path: str | os.PathLike[str]) -> tuple[str, object]:
    """A polygon file's name and its parsed JSON: a regular file of at most
    `MAX_FILE_BYTES`, UTF-8 (a byte order mark allowed), every failure a
    one-line `PolygonError` naming the file."""
    name = os.fspath(path)
    raw = read_small_file(name, "polygon file", PolygonError, max_bytes=MAX_FILE_BYTES)
    try:
        # RFC 8259 lets a parser ignore a byte order mark; some editors write one.
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise PolygonError(f"{name}: not a JSON text file (invalid UTF-8 at byte {err.start})") from err
    return name, parse_json(text, name)


def parse_json(text: str, name: str) -> object:
    """json.loads, with every failure a one-line PolygonError.

    Integer literals too long for int() come back as `LongInteger` markers
    (see `parse_int`) instead of failing the whole file.

    Parameters
    ----------
    text : str
        The file's text.
    name : str
        Starts every message.

    Returns
    -------
    object
        What `json.loads` returns.

    Raises
    ------
    PolygonError
        If ``text`` is not JSON, or is nested too deeply.
    """
    try:
        try:
            return json.loads(text)
        except json.JSONDecodeError:
            raise
        except ValueError:
            # int() refused a literal of thousands of digits. Parse again,
            # keeping such literals as markers that Polygon will name
            # (they are far out of range) and other members may ignore.
            return json.loads(text, parse_int=parse_int)
    except json.JSONDecodeError as err:
        raise PolygonError(f"{name}: invalid JSON at line {err.lineno}, column {err.colno}: {err.msg}") from err
    except RecursionError as err:
        raise PolygonError(f"{name}: invalid JSON: nested too deeply") from err
    except ValueError as err:  # not expected after the second parse, but one line all the same
        raise PolygonError(f"{name}: invalid JSON: {one_line(str(err))}") from err


def parse_int(text: str) -> int | LongInteger:
    """The ``parse_int`` hook for `json.loads`: an int, or a `LongInteger` beyond a thousand digits.

    Parameters
    ----------
    text : str
        An integer literal from the JSON text.

    Returns
    -------
    int or LongInteger

    Examples
    --------
    >>> parse_int("-12"), parse_int("9" * 5000)
    (-12, <a 5000-digit integer>)
    """
    # A coordinate needs 10 digits at most (COORD_LIMIT); a thousand is
    # plenty for anything else and well inside int()'s limit.
    return int(text) if len(text) <= 1000 else LongInteger(text)


def points_of(doc: object, name: str, label: str | None) -> object:
    """The vertex list of a parsed polygon document (plain, labelme or GeoJSON).

    Parameters
    ----------
    doc : object
        The document, as `parse_json` returns it.
    name : str
        Starts every message.
    label : str or None
        Which polygon to take from a document holding several (see
        `read_polygon`).

    Returns
    -------
    object
        The vertex list as the document holds it, not yet checked: `Polygon`
        does that.

    Raises
    ------
    PolygonError
        If the document has no polygon, or not one chosen by ``label``.
    """
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


def with_points(doc: object, points: list, name: str) -> object:
    """``doc``, a parsed polygon document holding one polygon, with that polygon's vertices
    replaced by ``points``: everything else kept (a labelme file's other shapes, labels and image
    path; a GeoJSON feature's properties; other members of a ``{"points": ...}`` object).

    The writer's twin of `points_of` (without a label): a file saved over keeps what it held.

    Raises
    ------
    PolygonError
        If ``doc`` is not a document `points_of` reads one polygon from (as its messages say).
    """
    import copy

    points_of(doc, name, None)  # one polygon there, or the reader's message
    points = [list(map(float, p)) for p in points]
    if isinstance(doc, list):
        return points
    out = copy.deepcopy(doc)
    if "shapes" in out:
        shape = next(s for s in out["shapes"] if isinstance(s, dict) and s.get("shape_type", "polygon") == "polygon")
        shape["points"] = points
        return out
    if out.get("type") in ("Polygon", "Feature", "FeatureCollection", "MultiPolygon"):
        geometry = out
        if geometry.get("type") == "FeatureCollection":
            geometry = next(f for f in geometry["features"] if isinstance(f, dict))
        if geometry.get("type") == "Feature":
            geometry = geometry["geometry"]
        geometry["coordinates"] = [points + [points[0]]]
        return out
    out["points"] = points
    return out


def _unlabelled(points: object, name: str, label: str | None) -> object:
    if label is not None:
        raise PolygonError(f"{name}: holds a single polygon with no labels, but label {label!r} was asked for")
    return points


def _index_label(label: str) -> int | None:
    """``"#N"`` chooses the N-th polygon of a file (from 0) when no shape is labelled so.

    >>> _index_label("#2"), _index_label("mouth")
    (2, None)
    """
    text = str(label)
    return int(text[1:]) if text.startswith("#") and text[1:].isdigit() and len(text) < 12 else None


def _labelme_points(doc: dict, name: str, label: str | None) -> object:
    shapes = doc["shapes"]
    if not isinstance(shapes, list):
        raise PolygonError(f'{name}: labelme "shapes" must be an array')
    polys = [s for s in shapes if isinstance(s, dict) and s.get("shape_type", "polygon") == "polygon"]
    labels = _list_text([s.get("label") for s in polys])
    if label is not None:
        chosen = [s for s in polys if s.get("label") == label]
        index = _index_label(label)
        if not chosen and index is not None:
            if index >= len(polys):
                raise PolygonError(f"{name}: labelme file has {len(polys)} polygon(s), so there is no polygon {label}")
            chosen = [polys[index]]
        if len(chosen) != 1:
            what = "no" if not chosen else f"{len(chosen)}"
            raise PolygonError(
                f"{name}: labelme file has {what} polygon labelled {label!r} (labels: {labels or 'none'})"
            )
        polys = chosen
    if len(polys) != 1:
        if not polys:
            raise PolygonError(f"{name}: labelme file has no polygon shape")
        raise PolygonError(
            f"{name}: labelme file has {len(polys)} polygons ({labels}); choose one with a label option"
        )
    if "points" not in polys[0]:
        raise PolygonError(f'{name}: labelme shape has no "points"')
    return polys[0]["points"]


def _geojson_points(doc: dict, name: str, label: str | None) -> object:
    kind = doc.get("type")
    if kind == "FeatureCollection":
        features = doc.get("features") or []
        if not isinstance(features, list):
            raise PolygonError(f'{name}: GeoJSON FeatureCollection "features" must be an array')
        features = [f for f in features if isinstance(f, dict)]
        if label is not None:
            named = [f for f in features if label in _feature_names(f)]
            index = _index_label(label)
            if not named and index is not None:
                if index >= len(features):
                    raise PolygonError(f"{name}: GeoJSON FeatureCollection has {len(features)} feature(s), so there is no feature {label}")
                named = [features[index]]
            features = named
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
        raise PolygonError(f"{name}: GeoJSON geometry is a {_text(kind)}, not a Polygon")
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


def _text(value: object) -> str:
    """A value from a file, fit for a one-line message: short, printable text as is, else quoted and cut."""
    if isinstance(value, str) and value.isprintable() and len(value) <= 40:
        return value
    if value is None or isinstance(value, (bool, int, float)):
        return str(value)
    return short_value(value)


def _list_text(values: list) -> str:
    """Up to ten values, comma-separated, then how many more."""
    shown = ", ".join(_text(v) for v in values[:10])
    return shown + (f", ... ({len(values) - 10} more)" if len(values) > 10 else "")
