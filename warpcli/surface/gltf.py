"""glTF 2.0 surface patches (.gltf with its buffers, or .glb): the first triangle primitive, read strictly."""

from __future__ import annotations

import base64
import json
import os
import struct

import numpy as np
from numpy.typing import NDArray

from ..files import read_small_file
from .mesh import MAX_ELEMENTS, MAX_MESH_BYTES, MeshError, UVMesh

__all__ = ["read_gltf"]

#: glTF's accessor component types: numpy type and the divisor of a normalized integer.
COMPONENTS = {5120: ("i1", 127.0), 5121: ("u1", 255.0), 5122: ("i2", 32767.0), 5123: ("u2", 65535.0),
              5125: ("u4", None), 5126: ("f4", None)}  # fmt: skip
WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}
TRIANGLES = 4


def read_gltf(path: str | os.PathLike[str]) -> UVMesh:
    """Read the first triangle primitive of a glTF 2.0 file's first mesh.

    Its ``POSITION``, ``TEXCOORD_0`` (glTF's v runs down the texture: it is
    stored as 1 - v, so that every `UVMesh` has v up) and ``COLOR_0``
    (attributes ``red``, ``green``, ``blue`` and ``alpha`` in 0..1), and its
    ``indices``. Buffers are embedded (``data:`` URIs, a .glb's binary chunk)
    or files beside it. The texture is the material's base colour image, when
    it is a file.

    Raises
    ------
    MeshError
        Naming the file and what is wrong (an accessor beyond its buffer, ...).
    """
    name = os.fspath(path)
    raw = read_small_file(name, "mesh file", MeshError, max_bytes=MAX_MESH_BYTES)
    doc, glb_bin = _container(raw, name)
    base = os.path.dirname(os.path.abspath(name))
    buffers: dict = {}

    def buffer(i: int) -> bytes:
        if i not in buffers:
            spec = _item(doc, "buffers", i, name)
            uri = spec.get("uri")
            if uri is None:
                if glb_bin is None or i != 0:
                    raise MeshError(f"{name}: buffer {i} has no data")
                data = glb_bin
            elif isinstance(uri, str) and uri.startswith("data:"):
                try:
                    data = base64.b64decode(uri.split(",", 1)[1], validate=True)
                except (IndexError, ValueError):
                    raise MeshError(f"{name}: buffer {i}: its data URI is not base64") from None
            elif isinstance(uri, str):
                data = read_small_file(os.path.join(base, uri), "glTF buffer", MeshError, max_bytes=MAX_MESH_BYTES)
            else:
                raise MeshError(f"{name}: buffer {i}: uri must be a string")
            buffers[i] = data
        return buffers[i]

    def accessor(i: object, what: str, types: tuple) -> NDArray:
        acc = _item(doc, "accessors", i, name)
        kind = acc.get("type")
        comp = acc.get("componentType")
        count = acc.get("count")
        if kind not in types or comp not in COMPONENTS or not isinstance(count, int) or not 0 < count <= MAX_ELEMENTS:
            raise MeshError(f"{name}: accessor {i} ({what}): unsupported type {kind!r}/{comp!r} or count {count!r}")
        if "sparse" in acc or "bufferView" not in acc:
            raise MeshError(f"{name}: accessor {i} ({what}): sparse or empty accessors are not read")
        view = _item(doc, "bufferViews", acc["bufferView"], name)
        data = buffer(_int(view.get("buffer"), name, "bufferView.buffer"))
        start = _int(view.get("byteOffset", 0), name, "byteOffset") + _int(acc.get("byteOffset", 0), name, "byteOffset")
        dtype = np.dtype("<" + COMPONENTS[comp][0])
        width = WIDTHS[kind]
        stride = _int(view.get("byteStride", width * dtype.itemsize), name, "byteStride")
        end = _int(view.get("byteOffset", 0), name, "byteOffset") + _int(view.get("byteLength", 0), name, "byteLength")
        need = start + (count - 1) * stride + width * dtype.itemsize
        if stride < width * dtype.itemsize or need > min(end, len(data)):
            raise MeshError(f"{name}: accessor {i} ({what}) reaches beyond its buffer view")
        values = np.ndarray((count, width), dtype=dtype, buffer=data, offset=start, strides=(stride, dtype.itemsize))
        out = values.astype(np.float64) if dtype.kind == "f" else values.astype(np.int64)
        norm = COMPONENTS[comp][1]
        if acc.get("normalized") and norm is not None:
            out = np.maximum(out / norm, -1.0)
        if out.dtype.kind == "f" and not np.isfinite(out).all():
            raise MeshError(f"{name}: accessor {i} ({what}) holds a value that is not finite")
        return out

    meshes = doc.get("meshes")
    if not isinstance(meshes, list) or not meshes or not isinstance(meshes[0], dict):
        raise MeshError(f"{name}: no meshes")
    prims = [p for p in meshes[0].get("primitives", []) if isinstance(p, dict) and p.get("mode", TRIANGLES) == TRIANGLES]
    if not prims:
        raise MeshError(f"{name}: the first mesh has no triangle primitive")
    prim = prims[0]
    attrs = prim.get("attributes")
    if not isinstance(attrs, dict) or "TEXCOORD_0" not in attrs:
        raise MeshError(f"{name}: the primitive has no texture coordinates (TEXCOORD_0)")
    uv = accessor(attrs["TEXCOORD_0"], "TEXCOORD_0", ("VEC2",)).astype(np.float64)
    uv[:, 1] = 1.0 - uv[:, 1]  # glTF's v runs down; a UVMesh's up
    n = len(uv)
    pos = accessor(attrs["POSITION"], "POSITION", ("VEC3",)) if "POSITION" in attrs else np.zeros((n, 3))
    if len(pos) != n:
        raise MeshError(f"{name}: POSITION has {len(pos)} entries but TEXCOORD_0 has {n}")
    if "indices" in prim:
        flat = accessor(prim["indices"], "indices", ("SCALAR",)).ravel()
    else:
        flat = np.arange(n)
    if flat.size % 3 or flat.size == 0:
        raise MeshError(f"{name}: {flat.size} indices are not whole triangles")
    if flat.dtype.kind != "i" or flat.min() < 0 or flat.max() >= n:
        raise MeshError(f"{name}: an index refers to a vertex that does not exist (there are {n})")
    tris = flat.reshape(-1, 3).astype(np.int64)
    attributes, types = {}, {}
    if "COLOR_0" in attrs:
        colour = accessor(attrs["COLOR_0"], "COLOR_0", ("VEC3", "VEC4")).astype(np.float64)
        if len(colour) != n:
            raise MeshError(f"{name}: COLOR_0 has {len(colour)} entries but TEXCOORD_0 has {n}")
        for c, key in enumerate(("red", "green", "blue", "alpha")[: colour.shape[1]]):
            attributes[key] = colour[:, c]
            types[key] = "float"
    texture = _texture(doc, prim, base)
    return UVMesh(pos.astype(np.float64), uv, tris, tris, attributes, types, name, texture, None, "triangle")


def _container(raw: bytes, name: str) -> tuple[dict, bytes | None]:
    """The JSON document, and a .glb's binary chunk."""
    glb_bin = None
    if raw[:4] == b"glTF":
        if len(raw) < 20:
            raise MeshError(f"{name}: a .glb file shorter than its header")
        version, length = struct.unpack_from("<II", raw, 4)
        if version != 2 or length > len(raw):
            raise MeshError(f"{name}: a glTF {version} binary of {length} bytes in a file of {len(raw)}: only glTF 2 is read")
        chunks, offset = {}, 12
        while offset + 8 <= length:
            size, kind = struct.unpack_from("<II", raw, offset)
            if offset + 8 + size > length:
                raise MeshError(f"{name}: a .glb chunk reaches beyond the file")
            chunks.setdefault(kind, raw[offset + 8 : offset + 8 + size])
            offset += 8 + size + (-size % 4)
        text = chunks.get(0x4E4F534A)
        glb_bin = chunks.get(0x004E4942)
        if text is None:
            raise MeshError(f"{name}: a .glb without a JSON chunk")
    else:
        text = raw
    try:
        doc = json.loads(text.decode("utf-8-sig"))
    except (UnicodeDecodeError, ValueError, RecursionError) as err:
        raise MeshError(f"{name}: invalid glTF JSON: {str(err)[:80]}") from None
    if not isinstance(doc, dict):
        raise MeshError(f"{name}: a glTF document is a JSON object")
    version = str((doc.get("asset") or {}).get("version", ""))
    if not version.startswith("2"):
        raise MeshError(f"{name}: glTF version {version[:10] or 'missing'}: only glTF 2 is read")
    return doc, glb_bin


def _int(value: object, name: str, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise MeshError(f"{name}: {what} must be a whole number, got {str(value)[:20]}")
    return value


def _item(doc: dict, key: str, index: object, name: str) -> dict:
    items = doc.get(key)
    i = _int(index, name, f"an index into {key}")
    if not isinstance(items, list) or i >= len(items) or not isinstance(items[i], dict):
        raise MeshError(f"{name}: {key}[{i}] does not exist")
    return items[i]


def _texture(doc: dict, prim: dict, base: str) -> str | None:
    """The base colour texture's file, if the material names one (an embedded image: None)."""
    try:
        material = doc["materials"][prim["material"]]
        tex = doc["textures"][material["pbrMetallicRoughness"]["baseColorTexture"]["index"]]
        uri = doc["images"][tex["source"]]["uri"]
    except (KeyError, IndexError, TypeError):
        return None
    if not isinstance(uri, str) or uri.startswith("data:"):
        return None
    from urllib.parse import unquote

    return os.path.join(base, unquote(uri))
