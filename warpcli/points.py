"""Points and UV layouts through the map (the paper's §4.2): JSON, CSV and text tables, and Wavefront OBJ texture coordinates.

``warp points --src A --dst B IN OUT`` carries points from the source
polygon's coordinates to the target's (``--inverse``: back). For an OBJ file
the ``vt`` lines are texture coordinates (u right, v up, 0..1) of a texture of
``texture_size`` pixels: they are taken to pixels (x = u W, y = (1 - v) H),
mapped, and written back, while every other line stays byte for byte. This
is the surface cross-parameterization of §4.2 as artists use it: a mesh's
UVs moved from one texture layout (polygon A) to another (B).

Tables (``.csv``: commas, semicolons or tabs; ``.txt``: whitespace) keep every
line and column but the two coordinates: x and y are the columns a header
names ``x`` and ``y``, else those given (``columns``), else the first two.
Coordinates are written rounded to `PRECISION` decimals (a millionth of a
pixel, below the accuracy of every method; ``precision`` changes it, 0 to
`MAX_PRECISION`), in the shortest form that reads back as that value.

Points outside the polygon have no image: they are left as they are with a
warning (``outside="keep"``), or refused (``outside="error"``).

A retouch (``within``, as ``warp --within``) maps points as it maps the image:
the cages move, the ring between them and the fixed outline follows, and every
point outside the outline stays where it is (it has an image: itself).
"""

from __future__ import annotations

import json
import logging
import os
import re
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .errors import InputError
from .options import MapOptions, outline_file
from .files import read_small_file
from .outputs import PendingOutputs, check_output_path, write_checked
from .keyframes import read_shape_at
from .maps.cage import map_between
from .polygon.partition import check_shapes
from .within import read_within_pair

log = logging.getLogger("warpcli")

#: What to do with points outside the polygon.
OUTSIDE = ("keep", "error")
#: Largest points file read, in bytes.
MAX_BYTES = 256 << 20
#: Decimals written by default: a millionth of a pixel. The map is not more
#: exact than that (the FEM maps' error is far larger, BEM's and MFS's too
#: near the polygon's corners), and 17 significant digits only show noise.
PRECISION = 6
#: Most decimals a caller may ask for: beyond 9, a pixel coordinate's decimals
#: are float64 rounding noise (2**-30 is about 1e-9 at a coordinate of 1000).
MAX_PRECISION = 9
#: The file kinds read, by extension.
KINDS = (".json", ".csv", ".txt", ".obj")

# A file's first line may start with a UTF-8 byte order mark (kept, byte for byte).
_VT = re.compile(rb"^((?:\xef\xbb\xbf)?\s*vt\s+)(\S+)(\s+)(\S+)(.*)$", re.S)


@dataclass(frozen=True)
class PointsResult:
    """What `map_points_file` did: how many points were mapped and how many were outside."""

    mapped: int
    outside: int


def map_points_file(
    input_path: str | os.PathLike[str],
    output_path: str | os.PathLike[str],
    src_path: str | os.PathLike[str],
    dst_path: str | os.PathLike[str],
    options: MapOptions | None = None,
    *,
    inverse: bool = False,
    texture_size: tuple[int, int] | None = None,
    outside: str = "keep",
    src_label: str | None = None,
    dst_label: str | None = None,
    frame: int | None = None,
    precision: int = PRECISION,
    columns: tuple[str, str] | None = None,
    within: str | None = None,
    image_size: tuple[int, int] | None = None,
) -> PointsResult:
    """Map the points of a JSON, CSV or OBJ file through the map between two polygons.

    Parameters
    ----------
    input_path, output_path : path-like
        ``.json`` (an array of [x, y], or ``{"points": [...]}``), ``.csv``
        (a table separated by commas, semicolons or tabs, with an optional
        header; semicolon and tab tables may use decimal commas), ``.txt`` (a
        table separated by whitespace) or ``.obj`` (its ``vt`` lines); the
        output has the input's format, and a table keeps its other columns,
        its lines, separators and byte order mark.
    src_path, dst_path : path-like
        Polygon files.
    options : MapOptions or None
        The method and its options (``bem`` and ``mfs`` give smooth maps).
    inverse : bool
        Map target points back to the source.
    texture_size : (width, height) or None
        OBJ: the texture's size in pixels, the units of the polygons.
    outside : {"keep", "error"}
        Points outside the polygon: left as they are (with a warning) or an error.
    src_label, dst_label : str or None
        Which polygon of a file holding several.
    frame : int or None
        The frame of keyframed polygon files (`warpcli.keyframes.read_polygon_at`).
    precision : int
        Decimals of the coordinates written to JSON and tables (0 to
        `MAX_PRECISION`); OBJ texture coordinates keep 9 significant digits.
    columns : (str, str) or None
        A table's x and y columns: header names, or 1-based numbers as
        strings (``("2", "3")``). None: the columns a header names ``x`` and
        ``y`` (any case), else the first two.
    within : str or None
        A retouch within a fixed outline, as ``warp --within``
        (`warpcli.within.within_pair`): ``"image"``, a margin in pixels, or a
        polygon file; the source and target files may hold several cages.
        Points outside the outline stay as they are.
    image_size : (width, height) or None
        The image's size, which ``within`` needs (an OBJ's ``texture_size``
        when not given).

    Returns
    -------
    PointsResult

    Raises
    ------
    InputError
        For unreadable or malformed files, an OBJ without ``texture_size``,
        ``within`` without an image size, or points outside with
        ``outside="error"``.

    References
    ----------
    Schneider & Hormann, CAGD 2015, §4.2.
    """
    if outside not in OUTSIDE:
        raise InputError(f"unknown choice for points outside {outside!r}; choose one of {', '.join(OUTSIDE)}")
    if isinstance(precision, bool) or not isinstance(precision, int) or not 0 <= precision <= MAX_PRECISION:
        raise InputError(f"precision must be a whole number of decimals from 0 to {MAX_PRECISION}, got {precision!r}")
    name = os.fspath(input_path)
    kind = os.path.splitext(name)[1].lower()
    if kind not in KINDS:
        raise InputError(f"{name}: points must be a .json, .csv, .txt or .obj file")
    if os.path.splitext(os.fspath(output_path))[1].lower() != kind:
        raise InputError(f"{os.fspath(output_path)}: the output must have the input's format ({kind})")
    theta_file = (options or MapOptions()).theta_file
    sources = (name, src_path, dst_path, theta_file, outline_file(within))
    check_output_path(output_path, inputs=tuple(p for p in sources if p is not None))
    if kind == ".obj" and texture_size is None:
        raise InputError(f"{name}: an OBJ file's UVs need the texture size (--texture-size WxH)")
    size = image_size if image_size is not None else texture_size
    if within is not None and size is None:
        raise InputError(f"{name}: --within needs the image's size (--image-size WxH)")
    raw = _read(name)
    if within is not None:
        pair = read_within_pair(src_path, dst_path, within, size, src_label=src_label, dst_label=dst_label, frame=frame)  # type: ignore[arg-type]
        src, dst = pair.src, pair.dst
    else:
        src = read_shape_at(src_path, src_label, frame)
        dst = read_shape_at(dst_path, dst_label, frame)
    check_shapes(src, dst)
    if kind == ".json":
        pts, write = _json_points(raw, name, precision)
    elif kind in (".csv", ".txt"):
        pts, write = _table_points(raw, name, kind, columns, precision)
    else:
        pts, write = _obj_points(raw, name, texture_size)  # type: ignore[arg-type]
    fmap = map_between(src, dst, options or MapOptions())
    moved = fmap.inverse(pts) if inverse else fmap.forward(pts)
    lost = ~np.isfinite(moved).all(axis=1)
    if within is not None:  # outside the outline the retouch is the identity, as for the image
        moved[lost] = pts[lost]
        lost[:] = False
    if lost.any():
        poly = dst if inverse else src
        if outside == "error":
            k = int(np.flatnonzero(lost)[0])
            raise InputError(
                f"{name}: {int(lost.sum())} point(s) lie outside {poly.name}, the first is point {k} "
                f"({pts[k, 0]:.6g}, {pts[k, 1]:.6g})"
            )
        log.warning("%s: %d point(s) lie outside %s and are left as they are", name, int(lost.sum()), poly.name)
        moved[lost] = pts[lost]
    with PendingOutputs() as pending:
        write_checked(pending.path(output_path), write(moved), output_path)
    return PointsResult(int((~lost).sum()), int(lost.sum()))


def _read(name: str) -> bytes:
    return read_small_file(name, "points file", InputError, max_bytes=MAX_BYTES)


def _as_xy(values, name: str) -> NDArray[np.float64]:
    try:
        pts = np.array(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name}: points must be [x, y] pairs of numbers") from None
    except OverflowError:  # an integer of hundreds of digits
        raise InputError(f"{name}: a coordinate is beyond the floating-point range (1.8e308)") from None
    if pts.ndim != 2 or pts.shape[1] != 2 or not np.isfinite(pts).all():
        raise InputError(f"{name}: points must be finite [x, y] pairs")
    return pts


def _json_points(raw: bytes, name: str, precision: int):
    try:
        doc = json.loads(raw.decode("utf-8-sig"))
    except (UnicodeDecodeError, ValueError, RecursionError) as err:
        raise InputError(f"{name}: invalid JSON: {err}") from None
    wrapped = isinstance(doc, dict)
    pts = _as_xy(doc.get("points") if wrapped else doc, name)

    def write(moved):
        out = [[_rounded(x, precision), _rounded(y, precision)] for x, y in moved]
        return (json.dumps({**doc, "points": out} if wrapped else out) + "\n").encode()

    return pts, write


def _rounded(value: float, precision: int) -> float:
    """``value`` to ``precision`` decimals; its repr is the shortest text that reads back as it."""
    out = round(float(value), precision)
    return 0.0 if out == 0 else out  # not -0.0


def format_coordinate(value: float, precision: int = PRECISION) -> str:
    """A coordinate as `map_points_file` writes it: rounded to ``precision`` decimals, shortest form.

    Examples
    --------
    >>> format_coordinate(500.29558820679409), format_coordinate(12.0), format_coordinate(-1e-9)
    ('500.295588', '12.0', '0.0')
    >>> format_coordinate(2 / 3, 9)
    '0.666666667'
    """
    return repr(_rounded(value, precision))


_SEPARATORS = ("\t", ";", ",")


def _table_points(raw: bytes, name: str, kind: str, columns: tuple[str, str] | None, precision: int):
    """A table's points, and a writer giving the table back with them replaced.

    Every line keeps its other fields and separators, and its line ending;
    a line with quotes is read and written by the csv module.
    """
    bom = raw.startswith(b"\xef\xbb\xbf")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise InputError(f"{name}: not a UTF-8 text file (invalid byte at {err.start})") from None
    lines = text.splitlines(keepends=True)
    rows = [k for k, ln in enumerate(lines) if ln.strip()]
    if not rows:
        raise InputError(f"{name}: no points")
    sep = None if kind == ".txt" else _separator(lines[rows[0]])
    split = [_fields(lines[k], sep) for k in rows]
    decimal_comma = sep in (";", "\t") and any("," in f for fields in split for f in fields) and not any(
        "." in f for fields in split for f in fields
    )
    ix, iy, named = _xy_columns(split[0], columns, name)
    # The first line is a header when it names the columns, or its x and y are not numbers.
    numeric = all(i < len(split[0]) and _number(split[0][i], decimal_comma) is not None for i in (ix, iy))
    header = split[0] if named or not numeric else None
    body = rows[1:] if header is not None else rows
    fields_of = split[1:] if header is not None else split
    pts = []
    for k, fields in zip(body, fields_of):
        if max(ix, iy) >= len(fields):
            raise InputError(f"{name}: line {k + 1} has {len(fields)} field(s), not the x and y of columns {ix + 1} and {iy + 1}")
        x, y = _number(fields[ix], decimal_comma), _number(fields[iy], decimal_comma)
        if x is None or y is None:
            raise InputError(f"{name}: line {k + 1}: x and y (columns {ix + 1} and {iy + 1}) must be numbers, got {fields[ix][:20]!r} and {fields[iy][:20]!r}")
        pts.append((x, y))

    def write(moved):
        out = list(lines)
        for k, fields, (x, y) in zip(body, fields_of, moved):
            fields = list(fields)
            for i, v in ((ix, x), (iy, y)):
                text_v = format_coordinate(v, precision)
                fields[i] = text_v.replace(".", ",") if decimal_comma else text_v
            out[k] = _joined(lines[k], fields, sep)
        return ("\ufeff" if bom else "").encode() + "".join(out).encode()

    return _as_xy(pts, name), write


def _separator(line: str) -> str:
    """The field separator of a CSV line: a tab or semicolon if it has one, else a comma."""
    for sep in _SEPARATORS:
        if sep in line:
            return sep
    return ","


def _fields(line: str, sep: str | None) -> list[str]:
    body = line.rstrip("\r\n")
    if sep is None:
        return body.split()
    if '"' in body:
        import csv

        return next(csv.reader([body], delimiter=sep))
    return body.split(sep)


def _joined(line: str, fields: list[str], sep: str | None) -> str:
    """The line with its fields replaced: separators, spacing and line ending as they were."""
    body = line.rstrip("\r\n")
    ending = line[len(body) :]
    if sep is None:  # whitespace: keep each run of it
        parts = re.split(r"(\s+)", body)  # tokens at the even places (empty at a leading or trailing space)
        values = iter(fields)
        return "".join(next(values) if k % 2 == 0 and p else p for k, p in enumerate(parts)) + ending
    if '"' in body:
        import csv
        import io

        buf = io.StringIO()
        csv.writer(buf, delimiter=sep, lineterminator="").writerow(fields)
        return buf.getvalue() + ending
    return sep.join(fields) + ending


def _number(field: str, decimal_comma: bool) -> float | None:
    text = field.strip().strip('"').strip()
    if decimal_comma:
        text = text.replace(",", ".")
    try:
        return float(text)
    except ValueError:
        return None


def _xy_columns(first: list[str], columns: tuple[str, str] | None, name: str) -> tuple[int, int, bool]:
    """The 0-based x and y columns, and whether the first line names them (a header): as given
    (names or numbers from 1), else the columns the first line names x and y, else the first two."""
    names = [h.strip().strip('"').strip().lower() for h in first]
    if columns is not None:
        picked, named = [], False
        for col in columns:
            key = str(col).strip()
            if key.isdigit() and int(key) >= 1:
                picked.append(int(key) - 1)
            elif key.lower() in names:
                picked.append(names.index(key.lower()))
                named = True
            else:
                raise InputError(
                    f"{name}: no column {key!r} (the first line has {', '.join(first)[:60]}); give header names or numbers from 1"
                )
        if picked[0] == picked[1]:
            raise InputError(f"{name}: x and y are the same column ({picked[0] + 1})")
        return picked[0], picked[1], named
    if "x" in names and "y" in names:
        return names.index("x"), names.index("y"), True
    return 0, 1, False


def _obj_points(raw: bytes, name: str, size: tuple[int, int]):
    w, h = size
    lines = raw.splitlines(keepends=True)
    where, uv = [], []
    for k, ln in enumerate(lines):
        m = _VT.match(ln)
        if m:
            try:
                uv.append((float(m.group(2)), float(m.group(4))))
            except ValueError:
                raise InputError(f"{name}: line {k + 1}: a vt line needs two numbers") from None
            where.append(k)
    if not uv:
        raise InputError(f"{name}: no texture coordinates (vt lines)")
    uv_arr = np.array(uv)
    pts = np.stack([uv_arr[:, 0] * w, (1.0 - uv_arr[:, 1]) * h], axis=1)

    def write(moved):
        out = list(lines)
        for k, (x, y) in zip(where, moved):
            m = _VT.match(lines[k])
            u, v = x / w, 1.0 - y / h
            out[k] = m.group(1) + f"{u:.9g}".encode() + m.group(3) + f"{v:.9g}".encode() + m.group(5)
        return b"".join(out)

    return _as_xy(pts, name), write
