"""Stanford PLY surface patches: a strict reader of ASCII and binary files, and a writer with new vertex properties."""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from ..files import read_small_file
from .mesh import MAX_ELEMENTS, MAX_MESH_BYTES, MeshError, UVMesh

__all__ = ["PlyElement", "PlyFile", "PlyProperty", "read_ply"]

#: PLY's scalar types and their numpy codes (without byte order).
TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2", "ushort": "u2",
    "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4", "float": "f4", "float32": "f4",
    "double": "f8", "float64": "f8",
}  # fmt: skip
FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}
#: Largest header read, in bytes.
MAX_HEADER_BYTES = 1 << 16
#: Most entries of one list (a face's corners).
MAX_LIST = 1024
#: Texture coordinate property pairs, in the order they are looked for.
UV_NAMES = (("u", "v"), ("s", "t"), ("texture_u", "texture_v"), ("texture_s", "texture_t"))
#: Vertex properties that are geometry, not attributes to carry.
GEOMETRY = {"x", "y", "z", "nx", "ny", "nz"} | {n for pair in UV_NAMES for n in pair}


@dataclass(frozen=True)
class PlyProperty:
    """One property of an element: its name, scalar type, and for a list the type of its count."""

    name: str
    type: str
    count_type: str | None = None


@dataclass(frozen=True, eq=False)
class PlyElement:
    """An element (``vertex``, ``face``, ...) with its rows.

    ``data`` holds, per property name, an (N,) array for a scalar property, or
    for a list ``(counts, values)``: (N,) counts and their values flattened.
    """

    name: str
    count: int
    properties: tuple
    data: dict = field(repr=False)


@dataclass(frozen=True, eq=False)
class PlyFile:
    """A PLY file as read: its format, header comments and elements, and the mesh they make."""

    format: str
    comments: tuple
    elements: tuple
    mesh: UVMesh

    def element(self, name: str) -> PlyElement | None:
        return next((e for e in self.elements if e.name == name), None)

    def with_vertex_properties(self, values: dict, types: dict) -> bytes:
        """The file in its own format with vertex properties set (replaced, or added at the end of the vertex's).

        Parameters
        ----------
        values : dict of str to (V,) ndarray of float
        types : dict of str to str
            The PLY type of each new property (an existing one keeps its type).
            Integer types are rounded and clipped to their range.
        """
        elements = []
        for el in self.elements:
            if el.name == "vertex":
                props = list(el.properties)
                data = dict(el.data)
                have = {p.name for p in props}
                for key, v in values.items():
                    if key not in have:
                        props.append(PlyProperty(key, types[key]))
                    ptype = next(p.type for p in props if p.name == key)
                    data[key] = _cast(np.asarray(v, dtype=np.float64), ptype)
                el = replace(el, properties=tuple(props), data=data)
            elements.append(el)
        return _serialize(self.format, self.comments, elements)


def _cast(v: NDArray[np.float64], ptype: str) -> NDArray:
    dt = np.dtype(TYPES[ptype])
    if dt.kind in "iu":
        info = np.iinfo(dt)
        return np.clip(np.rint(v), info.min, info.max).astype(dt)
    return v.astype(dt)


def read_ply(path: str | os.PathLike[str]) -> PlyFile:
    """Read a PLY file (ASCII, binary little or big endian) with per-vertex texture coordinates.

    The vertex element must have ``u, v`` (or ``s, t``, ``texture_u,
    texture_v``), the face element a list ``vertex_indices`` (or
    ``vertex_index``); faces of more than three corners are split into fans.
    Every count is checked against the file's size before anything is
    allocated. A ``comment TextureFile NAME`` line names the texture.

    Raises
    ------
    MeshError
        Naming the file and the header line or element row at fault.
    """
    name = os.fspath(path)
    raw = read_small_file(name, "mesh file", MeshError, max_bytes=MAX_MESH_BYTES)
    fmt, comments, specs, start = _header(raw, name)
    body = memoryview(raw)[start:]
    elements = []
    if FORMATS[fmt] is None:
        tokens = bytes(body).split()
        pos = 0
        for el_name, count, props in specs:
            data, pos = _ascii_element(tokens, pos, el_name, count, props, name)
            elements.append(PlyElement(el_name, count, props, data))
    else:
        offset = 0
        for el_name, count, props in specs:
            data, offset = _binary_element(body, offset, FORMATS[fmt], el_name, count, props, name)
            elements.append(PlyElement(el_name, count, props, data))
    texture = None
    for line in comments:
        parts = line.split(None, 2)
        if len(parts) == 3 and parts[0] == "comment" and parts[1].lower() == "texturefile":
            texture = os.path.join(os.path.dirname(os.path.abspath(name)), parts[2].strip())
    mesh = _mesh(elements, name, texture)
    return PlyFile(fmt, tuple(comments), tuple(elements), mesh)


def _header(raw: bytes, name: str):
    end = raw.find(b"end_header", 0, MAX_HEADER_BYTES)
    if not raw.startswith(b"ply") or end < 0:
        raise MeshError(f"{name}: not a PLY file (it must start with 'ply' and have 'end_header' within 64 KiB)")
    nl = raw.find(b"\n", end)
    if nl < 0:
        raise MeshError(f"{name}: the header's end_header line has no line ending")
    try:
        lines = raw[:end].decode("ascii").splitlines()
    except UnicodeDecodeError:
        raise MeshError(f"{name}: the header is not ASCII text") from None
    fmt = None
    comments: list = []
    specs: list = []
    for k, line in enumerate(lines[1:], start=2):
        toks = line.split()
        if not toks:
            continue
        what = toks[0]
        if what == "format":
            if len(toks) != 3 or toks[1] not in FORMATS or toks[2] != "1.0":
                raise MeshError(f"{name}: line {k}: unknown format {' '.join(toks[1:])[:40]!r}")
            fmt = toks[1]
        elif what in ("comment", "obj_info"):
            comments.append(line.strip())
        elif what == "element":
            if len(toks) != 3 or not toks[2].isdigit():
                raise MeshError(f"{name}: line {k}: an element line needs a name and a count")
            count = int(toks[2])
            if count > MAX_ELEMENTS:
                raise MeshError(f"{name}: line {k}: {count} {toks[1]} elements (the limit is {MAX_ELEMENTS})")
            if any(s[0] == toks[1] for s in specs):
                raise MeshError(f"{name}: line {k}: element {toks[1]!r} is declared twice")
            specs.append((toks[1], count, []))
        elif what == "property":
            if not specs:
                raise MeshError(f"{name}: line {k}: a property before any element")
            if len(toks) == 5 and toks[1] == "list":
                if toks[2] not in TYPES or toks[3] not in TYPES or np.dtype(TYPES[toks[2]]).kind not in "iu":
                    raise MeshError(f"{name}: line {k}: bad list property types {toks[2]!r}, {toks[3]!r}")
                prop = PlyProperty(toks[4], toks[3], toks[2])
            elif len(toks) == 3 and toks[1] in TYPES:
                prop = PlyProperty(toks[2], toks[1])
            else:
                raise MeshError(f"{name}: line {k}: bad property line {line.strip()[:60]!r}")
            if any(p.name == prop.name for p in specs[-1][2]):
                raise MeshError(f"{name}: line {k}: property {prop.name!r} is declared twice")
            specs[-1][2].append(prop)
        else:
            raise MeshError(f"{name}: line {k}: unknown header keyword {what[:30]!r}")
    if fmt is None:
        raise MeshError(f"{name}: the header has no format line")
    return fmt, comments, [(n, c, tuple(p)) for n, c, p in specs], nl + 1


def _ascii_element(tokens, pos, el_name, count, props, name):
    data: dict = {}
    if all(p.count_type is None for p in props):
        width = len(props)
        need = count * width
        if pos + need > len(tokens):
            raise MeshError(f"{name}: the {el_name} element needs {need} values but the file has {len(tokens) - pos} left")
        try:
            table = np.array(tokens[pos : pos + need], dtype=np.float64).reshape(count, width)
        except ValueError:
            raise MeshError(f"{name}: {el_name} rows must hold numbers") from None
        for j, p in enumerate(props):
            data[p.name] = _checked(table[:, j], p.type, name, el_name, p.name)
        return data, pos + need
    cols: dict = {p.name: [] for p in props}
    counts: dict = {p.name: [] for p in props if p.count_type is not None}
    for row in range(count):
        for p in props:
            try:
                if p.count_type is None:
                    cols[p.name].append(float(tokens[pos]))
                    pos += 1
                else:
                    c = int(tokens[pos])
                    if not 0 <= c <= MAX_LIST:
                        raise MeshError(f"{name}: {el_name} {row}: a list of {c} entries (the limit is {MAX_LIST})")
                    counts[p.name].append(c)
                    cols[p.name].extend(float(t) for t in tokens[pos + 1 : pos + 1 + c])
                    if pos + 1 + c > len(tokens):
                        raise IndexError
                    pos += 1 + c
            except MeshError:
                raise
            except IndexError:
                raise MeshError(f"{name}: the file ends inside {el_name} {row}") from None
            except ValueError:
                raise MeshError(f"{name}: {el_name} {row}: property {p.name!r} must be a number") from None
    for p in props:
        values = _checked(np.array(cols[p.name], dtype=np.float64), p.type, name, el_name, p.name)
        data[p.name] = values if p.count_type is None else (np.array(counts[p.name], dtype=np.int64), values)
    return data, pos


def _checked(values: NDArray[np.float64], ptype: str, name: str, el_name: str, prop: str) -> NDArray:
    dt = np.dtype(TYPES[ptype])
    if dt.kind in "iu":
        info = np.iinfo(dt)
        bad = ~((values == np.floor(values)) & (values >= info.min) & (values <= info.max))
        if bad.any():
            raise MeshError(f"{name}: {el_name} property {prop!r} is {ptype} but holds {float(values[np.argmax(bad)]):.10g}")
    elif not np.isfinite(values).all():
        raise MeshError(f"{name}: {el_name} property {prop!r} holds a value that is not finite")
    return values.astype(dt)


def _binary_element(body, offset, order, el_name, count, props, name):
    rest = len(body) - offset

    def row_dtype(list_len: int | None) -> np.dtype:
        fields = []
        for p in props:
            if p.count_type is None:
                fields.append((p.name, order + TYPES[p.type]))
            else:
                fields.append((f"{p.name}\0count", order + TYPES[p.count_type]))
                fields.append((p.name, order + TYPES[p.type], (list_len,)))
        return np.dtype(fields)

    lists = [p for p in props if p.count_type is not None]
    if not lists:
        dt = row_dtype(None)
        if count * dt.itemsize > rest:
            raise MeshError(f"{name}: the {el_name} element needs {count * dt.itemsize} bytes but the file has {rest} left")
        rows = np.frombuffer(body, dtype=dt, count=count, offset=offset)
        data = {p.name: _finite(rows[p.name].astype(TYPES[p.type]), name, el_name, p.name) for p in props}
        return data, offset + count * dt.itemsize
    if count == 0:
        return {p.name: (np.zeros(0, np.int64), np.zeros(0, TYPES[p.type])) if p.count_type else np.zeros(0) for p in props}, offset
    # Usually every list has the same length (triangles): read all rows at once and check.
    first = _list_lengths(body, offset, order, props, name, el_name)
    if first is not None:
        dt = row_dtype(first)
        if count * dt.itemsize <= rest:
            rows = np.frombuffer(body, dtype=dt, count=count, offset=offset)
            if all((rows[f"{p.name}\0count"] == first).all() for p in lists):
                data = {}
                for p in props:
                    if p.count_type is None:
                        data[p.name] = _finite(rows[p.name].astype(TYPES[p.type]), name, el_name, p.name)
                    else:
                        vals = rows[p.name].reshape(-1).astype(TYPES[p.type])
                        data[p.name] = (np.full(count, first, dtype=np.int64), _finite(vals, name, el_name, p.name))
                return data, offset + count * dt.itemsize
    # Lists of several lengths: row by row.
    cols: dict = {p.name: [] for p in props}
    counts: dict = {p.name: [] for p in lists}
    for row in range(count):
        for p in props:
            if p.count_type is None:
                dt = np.dtype(order + TYPES[p.type])
                if offset + dt.itemsize > len(body):
                    raise MeshError(f"{name}: the file ends inside {el_name} {row}")
                cols[p.name].append(np.frombuffer(body, dtype=dt, count=1, offset=offset)[0])
                offset += dt.itemsize
            else:
                ct = np.dtype(order + TYPES[p.count_type])
                vt = np.dtype(order + TYPES[p.type])
                if offset + ct.itemsize > len(body):
                    raise MeshError(f"{name}: the file ends inside {el_name} {row}")
                c = int(np.frombuffer(body, dtype=ct, count=1, offset=offset)[0])
                offset += ct.itemsize
                if not 0 <= c <= MAX_LIST:
                    raise MeshError(f"{name}: {el_name} {row}: a list of {c} entries (the limit is {MAX_LIST})")
                if offset + c * vt.itemsize > len(body):
                    raise MeshError(f"{name}: the file ends inside {el_name} {row}")
                counts[p.name].append(c)
                cols[p.name].append(np.frombuffer(body, dtype=vt, count=c, offset=offset))
                offset += c * vt.itemsize
    data = {}
    for p in props:
        if p.count_type is None:
            data[p.name] = _finite(np.array(cols[p.name]).astype(TYPES[p.type]), name, el_name, p.name)
        else:
            vals = np.concatenate(cols[p.name]) if cols[p.name] else np.zeros(0)
            data[p.name] = (np.array(counts[p.name], dtype=np.int64), _finite(vals.astype(TYPES[p.type]), name, el_name, p.name))
    return data, offset


def _list_lengths(body, offset, order, props, name, el_name) -> int | None:
    """The length of the first row's lists if they all have one length, else None."""
    lengths = set()
    for p in props:
        dt = np.dtype(order + TYPES[p.type] if p.count_type is None else order + TYPES[p.count_type])
        if offset + dt.itemsize > len(body):
            raise MeshError(f"{name}: the file ends inside {el_name} 0")
        if p.count_type is None:
            offset += dt.itemsize
            continue
        c = int(np.frombuffer(body, dtype=dt, count=1, offset=offset)[0])
        if not 0 <= c <= MAX_LIST:
            raise MeshError(f"{name}: {el_name} 0: a list of {c} entries (the limit is {MAX_LIST})")
        lengths.add(c)
        offset += dt.itemsize + c * np.dtype(TYPES[p.type]).itemsize
    return lengths.pop() if len(lengths) == 1 else None


def _finite(values: NDArray, name: str, el_name: str, prop: str) -> NDArray:
    if values.dtype.kind == "f" and not np.isfinite(values).all():
        raise MeshError(f"{name}: {el_name} property {prop!r} holds a value that is not finite")
    return values


def _mesh(elements, name: str, texture: str | None) -> UVMesh:
    vertex = next((e for e in elements if e.name == "vertex"), None)
    face = next((e for e in elements if e.name == "face"), None)
    if vertex is None or face is None:
        raise MeshError(f"{name}: a PLY mesh needs a vertex and a face element")
    scalars = {p.name: vertex.data[p.name] for p in vertex.properties if p.count_type is None}
    pair = next((pr for pr in UV_NAMES if pr[0] in scalars and pr[1] in scalars), None)
    if pair is None:
        raise MeshError(f"{name}: the vertices have no texture coordinates (properties u, v or s, t)")
    uv = np.stack([scalars[pair[0]], scalars[pair[1]]], axis=1).astype(np.float64)
    xyz = [scalars.get(k) for k in ("x", "y", "z")]
    n = vertex.count
    positions = np.stack([np.zeros(n) if c is None else c.astype(np.float64) for c in xyz], axis=1)
    key = next((k for k in ("vertex_indices", "vertex_index") if k in face.data), None)
    if key is None or not isinstance(face.data[key], tuple):
        raise MeshError(f"{name}: the face element has no list vertex_indices")
    counts, flat = face.data[key]
    if (counts < 3).any():
        row = int(np.argmax(counts < 3))
        raise MeshError(f"{name}: face {row} has {int(counts[row])} corners, fewer than 3")
    if flat.dtype.kind == "f" and flat.size and not (flat == np.round(flat)).all():  # 0.9 is not vertex 0
        bad = int(np.argmax(flat != np.round(flat)))
        row = int(np.searchsorted(np.cumsum(counts), bad, side="right"))
        raise MeshError(f"{name}: face {row} has a vertex index that is not a whole number: {float(flat[bad])!r}")
    flat = flat.astype(np.int64)
    if flat.size and (flat.min() < 0 or flat.max() >= n):
        bad = int(np.argmax((flat < 0) | (flat >= n)))
        row = int(np.searchsorted(np.cumsum(counts), bad, side="right"))
        raise MeshError(f"{name}: face {row} refers to vertex {int(flat[bad])}, but there are {n}")
    starts = np.cumsum(counts) - counts
    fans = counts - 2
    if int(fans.sum()) > MAX_ELEMENTS:
        raise MeshError(f"{name}: more than {MAX_ELEMENTS} triangles")
    face_of = np.repeat(np.arange(len(counts)), fans)
    j = np.arange(fans.sum()) - np.repeat(np.cumsum(fans) - fans, fans)
    tris = np.stack([flat[starts[face_of]], flat[starts[face_of] + j + 1], flat[starts[face_of] + j + 2]], axis=1)
    attributes = {k: v.astype(np.float64) for k, v in scalars.items() if k not in GEOMETRY}
    types = {p.name: p.type for p in vertex.properties if p.name in attributes}
    return UVMesh(positions, uv, tris, tris, attributes, types, name, texture, face_of, "face")


def _serialize(fmt: str, comments, elements) -> bytes:
    head = ["ply", f"format {fmt} 1.0", *comments]
    for el in elements:
        head.append(f"element {el.name} {el.count}")
        for p in el.properties:
            head.append(f"property list {p.count_type} {p.type} {p.name}" if p.count_type else f"property {p.type} {p.name}")
    head.append("end_header")
    out = ["\n".join(head).encode("ascii") + b"\n"]
    order = FORMATS[fmt]
    for el in elements:
        if order is None:
            out.append(_ascii_rows(el))
        else:
            out.append(_binary_rows(el, order))
    return b"".join(out)


def _text(values: NDArray) -> list:
    """ASCII values: integers as they are, floats in the shortest form that reads back as the
    same value of their type (a float property written as 0.939693 stays 0.939693)."""
    if values.dtype.kind in "iu":
        return [str(int(v)) for v in values]
    return [np.format_float_positional(v, unique=True, trim="-") if 1e-4 <= abs(v) < 1e16 or v == 0
            else np.format_float_scientific(v, unique=True, trim="-") for v in values]  # fmt: skip


def _ascii_rows(el: PlyElement) -> bytes:
    columns = []
    for p in el.properties:
        d = el.data[p.name]
        if p.count_type is None:
            columns.append(_text(d))
        else:
            counts, flat = d
            words = _text(flat)
            ends = np.cumsum(counts)
            columns.append([" ".join([str(int(c)), *words[e - c : e]]) for c, e in zip(counts, ends)])
    return "".join(" ".join(row) + "\n" for row in zip(*columns)).encode("ascii") if columns else b""


def _binary_rows(el: PlyElement, order: str) -> bytes:
    lists = [p for p in el.properties if p.count_type is not None]
    lengths = {int(c) for p in lists for c in np.unique(el.data[p.name][0])}
    if len(lengths) <= 1:
        k = lengths.pop() if lengths else 0
        fields = []
        for p in el.properties:
            if p.count_type is None:
                fields.append((p.name, order + TYPES[p.type]))
            else:
                fields.append((f"{p.name}\0count", order + TYPES[p.count_type]))
                fields.append((p.name, order + TYPES[p.type], (k,)))
        rows = np.zeros(el.count, dtype=np.dtype(fields))
        for p in el.properties:
            if p.count_type is None:
                rows[p.name] = el.data[p.name]
            else:
                rows[f"{p.name}\0count"] = k
                rows[p.name] = el.data[p.name][1].reshape(el.count, k)
        return rows.tobytes()
    parts = []
    offsets = {p.name: np.cumsum(el.data[p.name][0]) - el.data[p.name][0] for p in lists}
    for row in range(el.count):
        for p in el.properties:
            if p.count_type is None:
                parts.append(np.asarray(el.data[p.name][row], dtype=order + TYPES[p.type]).tobytes())
            else:
                counts, flat = el.data[p.name]
                c, o = int(counts[row]), int(offsets[p.name][row])
                parts.append(np.asarray(c, dtype=order + TYPES[p.count_type]).tobytes())
                parts.append(np.asarray(flat[o : o + c], dtype=order + TYPES[p.type]).tobytes())
    return b"".join(parts)
