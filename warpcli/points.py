"""Points and UV layouts through the map (the paper's §4.2): JSON, CSV, and Wavefront OBJ texture coordinates.

``warp points --src A --dst B IN OUT`` carries points from the source
polygon's coordinates to the target's (``--inverse``: back). For an OBJ file
the ``vt`` lines are texture coordinates (u right, v up, 0..1) of a texture of
``texture_size`` pixels: they are taken to pixels (x = u W, y = (1 - v) H),
mapped, and written back, while every other line stays byte for byte. This
is the surface cross-parameterization of §4.2 as artists use it: a mesh's
UVs moved from one texture layout (polygon A) to another (B).

Points outside the polygon have no image: they are left as they are with a
warning (``outside="keep"``), or refused (``outside="error"``).
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
from .maps.compose import BijectiveMap
from .options import MapOptions
from .files import read_small_file
from .outputs import PendingOutputs, write_checked
from .polygon import check_pair, read_polygon

log = logging.getLogger("warpcli")

#: What to do with points outside the polygon.
OUTSIDE = ("keep", "error")
#: Largest points file read, in bytes.
MAX_BYTES = 256 << 20

_VT = re.compile(rb"^(\s*vt\s+)(\S+)(\s+)(\S+)(.*)$", re.S)


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
) -> PointsResult:
    """Map the points of a JSON, CSV or OBJ file through the map between two polygons.

    Parameters
    ----------
    input_path, output_path : path-like
        ``.json`` (an array of [x, y], or ``{"points": [...]}``), ``.csv``
        (x,y per line, an optional header) or ``.obj`` (its ``vt`` lines);
        the output has the input's format.
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

    Returns
    -------
    PointsResult

    Raises
    ------
    InputError
        For unreadable or malformed files, an OBJ without ``texture_size``,
        or points outside with ``outside="error"``.

    References
    ----------
    Schneider & Hormann, CAGD 2015, §4.2.
    """
    if outside not in OUTSIDE:
        raise InputError(f"unknown choice for points outside {outside!r}; choose one of {', '.join(OUTSIDE)}")
    name = os.fspath(input_path)
    kind = os.path.splitext(name)[1].lower()
    if kind not in (".json", ".csv", ".obj"):
        raise InputError(f"{name}: points must be a .json, .csv or .obj file")
    if os.path.splitext(os.fspath(output_path))[1].lower() != kind:
        raise InputError(f"{os.fspath(output_path)}: the output must have the input's format ({kind})")
    if os.path.exists(output_path) and os.path.samefile(output_path, name):
        raise InputError(f"{os.fspath(output_path)}: output would overwrite the input {name}")
    if kind == ".obj" and texture_size is None:
        raise InputError(f"{name}: an OBJ file's UVs need the texture size (--texture-size WxH)")
    raw = _read(name)
    src = read_polygon(src_path, src_label)
    dst = read_polygon(dst_path, dst_label)
    check_pair(src, dst)
    if kind == ".json":
        pts, write = _json_points(raw, name)
    elif kind == ".csv":
        pts, write = _csv_points(raw, name)
    else:
        pts, write = _obj_points(raw, name, texture_size)  # type: ignore[arg-type]
    fmap = BijectiveMap.between(src, dst, options or MapOptions())
    moved = fmap.inverse(pts) if inverse else fmap.forward(pts)
    lost = ~np.isfinite(moved).all(axis=1)
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


def _json_points(raw: bytes, name: str):
    try:
        doc = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as err:
        raise InputError(f"{name}: invalid JSON: {err}") from None
    wrapped = isinstance(doc, dict)
    pts = _as_xy(doc.get("points") if wrapped else doc, name)

    def write(moved):
        out = moved.tolist()
        return (json.dumps({**doc, "points": out} if wrapped else out) + "\n").encode()

    return pts, write


def _csv_points(raw: bytes, name: str):
    lines = raw.decode("utf-8", errors="replace").splitlines()
    header = []
    if lines and not _numeric(lines[0]):
        header = [lines[0]]
        lines = lines[1:]
    rows = [ln for ln in lines if ln.strip()]
    try:
        pts = _as_xy([[float(v) for v in ln.split(",")[:2]] for ln in rows], name)
    except ValueError:
        raise InputError(f"{name}: every line must be x,y numbers") from None

    def write(moved):
        return ("\n".join(header + [f"{x:.17g},{y:.17g}" for x, y in moved]) + "\n").encode()

    return pts, write


def _numeric(line: str) -> bool:
    try:
        [float(v) for v in line.split(",")[:2]]
        return True
    except ValueError:
        return False


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
