"""Wavefront OBJ surface patches: a strict reader of v, vt, f, mtllib and usemtl, and vertex colours written back."""

from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..files import read_small_file
from .mesh import MAX_ELEMENTS, MAX_MESH_BYTES, MeshError, UVMesh

__all__ = ["ObjFile", "read_obj"]

log = logging.getLogger("warpcli")

#: Most corners of one face.
MAX_FACE_CORNERS = 1024
#: Largest material library read, in bytes.
MAX_MTL_BYTES = 16 << 20
#: The names OBJ vertex colours (``v x y z r g b``) get as attributes.
COLOURS = ("red", "green", "blue")


@dataclass(frozen=True, eq=False)
class ObjFile:
    """An OBJ file as read: the mesh, and its lines to write back with new vertex colours.

    Attributes
    ----------
    mesh : UVMesh
    lines : list of bytes
        The file's lines with their endings.
    vertex_lines : (V,) ndarray of int
        Which line (0-based) holds each ``v``.
    """

    mesh: UVMesh
    lines: list
    vertex_lines: NDArray[np.int64]

    def with_colours(self, colours: NDArray[np.float64]) -> bytes:
        """The file with ``v x y z r g b`` for every vertex, every other line byte for byte.

        Parameters
        ----------
        colours : (V, 3) ndarray of float
            Red, green, blue in 0..1 (clipped there), written with 6 significant digits.
        """
        out = list(self.lines)
        rgb = np.clip(np.asarray(colours, dtype=np.float64), 0.0, 1.0)
        for k, c in zip(self.vertex_lines, rgb):
            raw = self.lines[k]
            body = raw.rstrip(b"\r\n")
            ending = raw[len(body) :]
            toks = body.split(b"#", 1)[0].split()
            out[k] = b" ".join([b"v", *toks[1:4], *(f"{x:.6g}".encode() for x in c)]) + ending
        return b"".join(out)


def _number(tok: bytes, name: str, line: int, what: str) -> float:
    try:
        value = float(tok)
    except ValueError:
        raise MeshError(f"{name}: line {line}: {what} must be numbers, got {tok[:20].decode('latin-1')!r}") from None
    if not math.isfinite(value):
        raise MeshError(f"{name}: line {line}: {what} must be finite, got {tok[:20].decode('latin-1')!r}")
    return value


def _index(tok: bytes, count: int, name: str, line: int, what: str) -> int:
    """A 1-based (or negative, relative) OBJ index as a 0-based one."""
    try:
        i = int(tok)
    except ValueError:
        raise MeshError(f"{name}: line {line}: a face's {what} index must be a whole number, got {tok[:20].decode('latin-1')!r}") from None
    k = i - 1 if i > 0 else count + i
    if i == 0 or not 0 <= k < count:
        raise MeshError(f"{name}: line {line}: face refers to {what} {i}, but {count} are defined before it")
    return k


def read_obj(path: str | os.PathLike[str]) -> ObjFile:
    """Read an OBJ file: positions (with optional ``r g b`` colours), texture coordinates and faces.

    Faces take the forms ``v/vt`` and ``v/vt/vn`` (indices from 1, or
    negative: counted back from the last defined); every corner must have a
    texture coordinate. Faces of more than three corners are split into fans.
    Other statements (``vn``, ``g``, ``o``, ``s``, ``l``, comments) are read
    past. The texture is the ``map_Kd`` of the first face's material
    (``usemtl``) in the ``mtllib`` files.

    Raises
    ------
    MeshError
        Naming the file and the line.
    """
    name = os.fspath(path)
    raw = read_small_file(name, "mesh file", MeshError, max_bytes=MAX_MESH_BYTES)
    lines = raw.splitlines(keepends=True)
    pos: list = []
    colours: list = []
    vlines: list = []
    uv: list = []
    tri_p: list = []
    tri_t: list = []
    face_line: list = []
    libraries: list = []
    material = None
    face_material = None
    no_colour_line = None
    for k, line in enumerate(lines):
        n = k + 1
        body = line.split(b"#", 1)[0]
        toks = body.split()
        if not toks:
            continue
        key = toks[0]
        if key == b"v":
            if len(toks) not in (4, 5, 7):
                raise MeshError(f"{name}: line {n}: a v line needs x y z (and optionally w, or r g b), got {len(toks) - 1} values")
            vals = [_number(t, name, n, "vertex coordinates") for t in toks[1:]]
            pos.append(vals[:3])
            vlines.append(k)
            if len(vals) == 6:
                colours.append(vals[3:])
            elif no_colour_line is None:
                no_colour_line = n
            if len(pos) > MAX_ELEMENTS:
                raise MeshError(f"{name}: more than {MAX_ELEMENTS} vertices")
        elif key == b"vt":
            if not 2 <= len(toks) <= 4:
                raise MeshError(f"{name}: line {n}: a vt line needs u and v, got {len(toks) - 1} values")
            vals = [_number(t, name, n, "texture coordinates") for t in toks[1:3]]
            uv.append(vals if len(vals) == 2 else [vals[0], 0.0])
            if len(uv) > MAX_ELEMENTS:
                raise MeshError(f"{name}: more than {MAX_ELEMENTS} texture coordinates")
        elif key == b"f":
            corners = toks[1:]
            if len(corners) < 3:
                raise MeshError(f"{name}: line {n}: a face needs at least 3 corners, got {len(corners)}")
            if len(corners) > MAX_FACE_CORNERS:
                raise MeshError(f"{name}: line {n}: a face of {len(corners)} corners (the limit is {MAX_FACE_CORNERS})")
            ip, it = [], []
            for c in corners:
                parts = c.split(b"/")
                if len(parts) > 3 or len(parts) < 2 or not parts[1]:
                    raise MeshError(
                        f"{name}: line {n}: face corner {c[:30].decode('latin-1')!r} has no texture coordinate "
                        "(write v/vt or v/vt/vn)"
                    )
                ip.append(_index(parts[0], len(pos), name, n, "vertex"))
                it.append(_index(parts[1], len(uv), name, n, "texture coordinate"))
            for j in range(1, len(ip) - 1):  # a fan
                tri_p.append((ip[0], ip[j], ip[j + 1]))
                tri_t.append((it[0], it[j], it[j + 1]))
                face_line.append(n)
            if len(tri_p) > MAX_ELEMENTS:
                raise MeshError(f"{name}: more than {MAX_ELEMENTS} triangles")
            if face_material is None:
                face_material = material
        elif key == b"mtllib":
            libraries.extend(t.decode("utf-8", "replace") for t in toks[1:])
        elif key == b"usemtl":
            material = body.split(None, 1)[1].strip().decode("utf-8", "replace") if len(toks) > 1 else None
    if not tri_p:
        raise MeshError(f"{name}: no faces")
    attributes, types = {}, {}
    if colours:
        if len(colours) != len(pos):
            raise MeshError(f"{name}: line {no_colour_line}: some vertices have colours (v x y z r g b) and this one has none")
        rgb = np.array(colours, dtype=np.float64)
        for c, key in enumerate(COLOURS):
            attributes[key] = rgb[:, c]
            types[key] = "float"
    texture = _texture(name, libraries, face_material)
    mesh = UVMesh(
        np.array(pos, dtype=np.float64).reshape(-1, 3), np.array(uv, dtype=np.float64).reshape(-1, 2),
        np.array(tri_p, dtype=np.int64), np.array(tri_t, dtype=np.int64), attributes, types, name, texture,
        np.array(face_line, dtype=np.int64), "line",
    )  # fmt: skip
    return ObjFile(mesh, lines, np.array(vlines, dtype=np.int64))


def _texture(name: str, libraries: list, material: str | None) -> str | None:
    """The ``map_Kd`` file of ``material`` in the material libraries, or None (with the reason logged)."""
    if material is None or not libraries:
        return None
    base = os.path.dirname(os.path.abspath(name))
    for lib in libraries:
        path = os.path.join(base, lib)
        try:
            text = read_small_file(path, "material library", MeshError, max_bytes=MAX_MTL_BYTES)
        except MeshError as err:
            log.info("%s", err)
            continue
        current = None
        for line in text.decode("utf-8", "replace").splitlines():
            toks = line.split("#", 1)[0].split()
            if not toks:
                continue
            if toks[0] == "newmtl":
                current = " ".join(toks[1:])
            elif toks[0] == "map_Kd" and current == material and len(toks) > 1:
                # Options (-s 1 1 1, -clamp on, ...) come first: the file name is the last word.
                return os.path.join(os.path.dirname(path), toks[-1])
    return None
