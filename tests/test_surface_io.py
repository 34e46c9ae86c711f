"""Surface mesh files: the OBJ and PLY readers (strict, hostile-input safe) and the writers of new vertex values."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from warpcli.surface import MeshError, read_mesh
from warpcli.surface.obj import read_obj
from warpcli.surface.ply import PlyFile, read_ply


def quad_obj(extra: str = "", faces: str = "f 1/1 2/2 3/3 4/4\n") -> str:
    return (
        "# a unit quad\nmtllib m.mtl\nusemtl skin\n"
        "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 1 1 0 0 0 1\nv 0 1 0 0.5 0.5 0.5\n"
        "vt 0.1 0.1\nvt 0.9 0.1\nvt 0.9 0.9\nvt 0.1 0.9\nvn 0 0 1\n" + extra + faces
    )


def test_obj_forms_fans_colours_and_material(tmp_path):
    (tmp_path / "m.mtl").write_text("newmtl other\nmap_Kd no.png\nnewmtl skin\nmap_Kd -s 1 1 1 tex.png\n")
    path = tmp_path / "q.obj"
    path.write_text(quad_obj(faces="f 1/1/1 2/2/1 3/3/1\nf -4/-4 -2/-2 -1/-1\n"))
    mesh = read_mesh(path)
    assert mesh.triangles_pos.tolist() == [[0, 1, 2], [0, 2, 3]]
    assert mesh.triangles_uv.tolist() == [[0, 1, 2], [0, 2, 3]]
    assert mesh.face_lines.tolist() == [13, 14]
    assert mesh.attributes["green"].tolist() == [0, 1, 0, 0.5]
    assert mesh.texture == str(tmp_path / "tex.png")
    # A quad is split into a fan of two triangles.
    path.write_text(quad_obj())
    assert read_mesh(path).triangles_uv.tolist() == [[0, 1, 2], [0, 2, 3]]


@pytest.mark.parametrize(
    "text, message",
    [
        (quad_obj(faces="f 1 2 3\n"), "line 13: face corner '1' has no texture coordinate"),
        (quad_obj(faces="f 1//1 2//1 3//1\n"), "line 13: face corner"),
        (quad_obj(faces="f 1/1 2/2 9/3\n"), "line 13: face refers to vertex 9, but 4 are defined"),
        (quad_obj(faces="f 1/1 2/2 0/3\n"), "line 13: face refers to vertex 0"),
        (quad_obj(faces="f 1/1 2/2\n"), "line 13: a face needs at least 3 corners"),
        (quad_obj(faces="f 1/1 2/2 x/3\n"), "line 13: a face's vertex index must be a whole number"),
        (quad_obj(extra="vt nan 0\n"), "line 13: texture coordinates must be finite"),
        (quad_obj(extra="v 1e999 0 0 1 1 1\n"), "line 13: vertex coordinates must be finite"),
        (quad_obj(extra="v 1 2\n"), "line 13: a v line needs x y z"),
        (quad_obj(extra="v 1 2 3\n"), "line 13: some vertices have colours"),
        ("v 0 0 0\nvt 0 0\n", "no faces"),
        ("", "no faces"),
        ("f " + "1/1 " * 2000 + "\n", "a face of 2000 corners"),
    ],
)
def test_obj_errors_name_the_file_and_line(tmp_path, text, message):
    path = tmp_path / "bad.obj"
    path.write_text(text)
    with pytest.raises(MeshError) as err:
        read_mesh(path)
    assert str(err.value).startswith(str(path)) and message in str(err.value)
    assert "\n" not in str(err.value)


def test_obj_colours_written_back_keep_every_other_line(tmp_path):
    path = tmp_path / "q.obj"
    text = quad_obj().replace("v 0 0 0 1 0 0\n", "v 0 0 0 1 0 0\r\n")
    path.write_bytes(text.encode())
    obj = read_obj(path)
    rgb = np.array([[0.25, 0.5, 1.0], [0, 0, 0], [2.0, -1, 0.125], [0.1, 0.2, 0.3]])
    out = obj.with_colours(rgb).decode()
    new, old = out.splitlines(keepends=True), text.splitlines(keepends=True)
    assert new[3] == "v 0 0 0 0.25 0.5 1\r\n" and new[5] == "v 1 1 0 1 0 0.125\n"  # clipped to 0..1
    assert [a for k, a in enumerate(new) if k not in (3, 4, 5, 6)] == [a for k, a in enumerate(old) if k not in (3, 4, 5, 6)]


def ply_text(fmt: str = "ascii") -> tuple[str, np.ndarray, list]:
    uv = np.array([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9], [0.5, 0.5]])
    faces = [[0, 1, 4], [1, 2, 4], [2, 3, 4, 0]]  # a triangle fan and a quad: lists of two lengths
    return fmt, uv, faces


def write_ply(path, fmt: str, uv, faces, *, order: str = "<", colours: bool = True, count_type: str = "uchar"):
    head = [
        "ply", f"format {fmt} 1.0", "comment TextureFile tex.png", f"element vertex {len(uv)}", "property float x",
        "property float y", "property float z", "property float s", "property float t",
    ]  # fmt: skip
    if colours:
        head += ["property uchar red", "property ushort quality"]
    head += [f"element face {len(faces)}", f"property list {count_type} int vertex_indices", "end_header"]
    xyz = np.column_stack([uv, np.zeros(len(uv))])
    if fmt == "ascii":
        rows = [
            " ".join(f"{v:.9g}" for v in [*xyz[k], *uv[k]]) + (f" {10 * k} {1000 * k}" if colours else "")
            for k in range(len(uv))
        ]
        rows += [" ".join(map(str, [len(f), *f])) for f in faces]
        path.write_bytes(("\n".join(head + rows) + "\n").encode())
        return
    body = b""
    for k in range(len(uv)):
        body += np.array([*xyz[k], *uv[k]], dtype=order + "f4").tobytes()
        if colours:
            body += np.array(10 * k, dtype="u1").tobytes() + np.array(1000 * k, dtype=order + "u2").tobytes()
    ct = {"uchar": "u1", "int": "i4"}[count_type]
    for f in faces:
        body += np.array(len(f), dtype=order + ct).tobytes() + np.array(f, dtype=order + "i4").tobytes()
    path.write_bytes(("\n".join(head) + "\n").encode() + body)


@pytest.mark.parametrize("fmt, order", [("ascii", "<"), ("binary_little_endian", "<"), ("binary_big_endian", ">")])
def test_ply_formats_read_alike_and_write_back(tmp_path, fmt, order):
    _, uv, faces = ply_text()
    path = tmp_path / "m.ply"
    write_ply(path, fmt, uv, faces, order=order)
    ply = read_ply(path)
    mesh = ply.mesh
    np.testing.assert_allclose(mesh.uv, uv, rtol=1e-7)
    assert mesh.triangles_uv.tolist() == [[0, 1, 4], [1, 2, 4], [2, 3, 4], [2, 4, 0]]
    assert mesh.attributes["red"].tolist() == [0, 10, 20, 30, 40]
    assert mesh.attribute_types == {"red": "uchar", "quality": "ushort"}
    assert mesh.texture == str(tmp_path / "tex.png")
    # Written back with a new property and a replaced one, in the same format; read again.
    data = ply.with_vertex_properties({"red": np.array([1.4, 300, -5, 7, 8]), "label": np.arange(5) / 2}, {"label": "float"})
    out = tmp_path / "out.ply"
    out.write_bytes(data)
    again = read_ply(out)
    assert again.format == fmt
    assert again.mesh.attributes["red"].tolist() == [1, 255, 0, 7, 8]  # rounded and clipped to uchar
    assert again.mesh.attributes["label"].tolist() == [0, 0.5, 1, 1.5, 2]
    assert again.mesh.attributes["quality"].tolist() == [0, 1000, 2000, 3000, 4000]
    assert again.mesh.triangles_uv.tolist() == mesh.triangles_uv.tolist()
    assert "comment TextureFile tex.png" in again.comments


def test_ply_binary_triangles_take_the_fast_path_and_agree(tmp_path):
    uv = np.random.default_rng(1).random((50, 2))
    faces = [[k, (k + 1) % 50, (k + 7) % 50] for k in range(40)]
    a, b = tmp_path / "a.ply", tmp_path / "b.ply"
    write_ply(a, "ascii", uv, faces, colours=False)
    write_ply(b, "binary_little_endian", uv, faces, colours=False, count_type="int")
    assert read_ply(a).mesh.triangles_uv.tolist() == read_ply(b).mesh.triangles_uv.tolist() == faces


def _binary(tmp_path, cut: int = 0, patch=None) -> str:
    _, uv, faces = ply_text()
    path = tmp_path / "m.ply"
    write_ply(path, "binary_little_endian", uv, faces)
    raw = path.read_bytes()
    if patch:
        raw = raw.replace(*patch)
    path.write_bytes(raw[: len(raw) - cut])
    return str(path)


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda p: _binary(p, cut=3), "the file ends inside face 2"),
        (lambda p: _binary(p, cut=60), "bytes but the file has"),
        (lambda p: _binary(p, patch=(b"element vertex 5", b"element vertex 99999999")), "(the limit is"),
        (lambda p: _binary(p, patch=(b"element vertex 5", b"element vertex 50000"), cut=0), "bytes but the file has"),
        (lambda p: _binary(p, patch=(b"format binary_little_endian", b"format binary_middle_endian")), "unknown format"),
        (lambda p: _binary(p, patch=(b"property float s\n", b"property float q\n")), "no texture coordinates"),
        (lambda p: _binary(p, patch=(b"property float x", b"property quux x")), "bad property line"),
        (lambda p: _binary(p, patch=(b"end_header", b"end_headr")), "not a PLY file"),
        (lambda p: _binary(p, patch=(b"property float y", b"property float x")), "declared twice"),
    ],
)
def test_ply_errors_name_the_file(tmp_path, make, message):
    path = make(tmp_path)
    with pytest.raises(MeshError) as err:
        read_mesh(path)
    assert str(err.value).startswith(path) and message in str(err.value), str(err.value)


@pytest.mark.parametrize(
    "rows, message",
    [
        ("0 0 0 0 0 1 1\n", "the vertex element needs 35 values but the file has 7 left"),
        ("0 0 0 0 0 1 1\n" * 5 + "3 0 1\n", "the file ends inside face 0"),
        ("0 0 0 0 0 1 1\n" * 5 + "3 0 1 9\n", "face 0 refers to vertex 9, but there are 5"),
        ("0 0 0 0 0 1 1\n" * 5 + "2 0 1\n", "face 0 has 2 corners"),
        ("0 0 0 0 0 300 1\n" * 5 + "3 0 1 2\n", "is uchar but holds 300"),
        ("0 0 0 nan 0 1 1\n" * 5 + "3 0 1 2\n", "not finite"),
        ("0 0 0 0 0 1 1\n" * 5 + "5000 0 1 2\n", "a list of 5000 entries"),
    ],
)
def test_ply_ascii_errors(tmp_path, rows, message):
    path = tmp_path / "m.ply"
    head = (
        "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\n"
        "property float u\nproperty float v\nproperty uchar red\nproperty uchar green\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
    )
    path.write_text(head + rows)
    with pytest.raises(MeshError, match=message):
        read_mesh(path)


def test_unknown_extension_and_unreadable_files(tmp_path):
    with pytest.raises(MeshError, match="must be an .obj, .ply, .gltf or .glb"):
        read_mesh(tmp_path / "m.stl")
    with pytest.raises(MeshError, match="no such file"):
        read_mesh(tmp_path / "missing.obj")
    (tmp_path / "d.obj").mkdir()
    with pytest.raises(MeshError, match="directory"):
        read_mesh(tmp_path / "d.obj")
    assert isinstance(PlyFile, type)


def _valid_files(tmp_path) -> dict:
    _, uv, faces = ply_text()
    out = {}
    for fmt in ("ascii", "binary_little_endian"):
        p = tmp_path / f"{fmt}.ply"
        write_ply(p, fmt, uv, faces)
        out[fmt] = p.read_bytes()
    out["obj"] = quad_obj().encode()
    doc, blob = _gltf_doc(uv, [f[:3] for f in faces], np.zeros((len(uv), 3)))
    del doc["buffers"][0]["uri"]
    out["glb"] = _glb(doc, blob)
    return out


@settings(max_examples=25)
@given(kind=st.sampled_from(["ascii", "binary_little_endian", "obj", "glb"]), data=st.data())
def test_damaged_files_are_read_or_refused_with_a_mesh_error(tmp_path_factory, kind, data):
    """Bytes overwritten, or the file cut short: a `MeshError` (or a mesh), never another exception."""
    tmp = tmp_path_factory.mktemp("damaged")
    raw = bytearray(_valid_files(tmp)[kind])
    for _ in range(data.draw(st.integers(1, 4))):
        raw[data.draw(st.integers(0, len(raw) - 1))] = data.draw(st.integers(0, 255))
    raw = raw[: data.draw(st.integers(len(raw) // 2, len(raw)))]
    path = tmp / {"obj": "m.obj", "glb": "m.glb"}.get(kind, "m.ply")
    path.write_bytes(bytes(raw))
    try:
        mesh = read_mesh(path)
    except MeshError as err:
        assert str(err).startswith(str(path)) and "\n" not in str(err)
    else:
        assert np.isfinite(mesh.uv).all() and mesh.triangles_uv.min() >= 0


# --- glTF ---------------------------------------------------------------------------------


def _gltf_doc(uv, tris, colours=None, uri="data"):
    """A glTF 2.0 document of one primitive, and its binary buffer."""
    import base64

    pos = np.column_stack([uv, np.zeros(len(uv))]).astype("<f4")
    tex = np.column_stack([uv[:, 0], 1 - uv[:, 1]]).astype("<f4")  # glTF's v runs down
    idx = np.asarray(tris, dtype="<u2").ravel()
    parts = [pos.tobytes(), tex.tobytes(), idx.tobytes() + b"\0" * (-idx.nbytes % 4)]
    if colours is not None:
        parts.append(np.asarray(colours, dtype="u1").tobytes())
    offsets = np.cumsum([0] + [len(p) for p in parts])
    blob = b"".join(parts)
    views = [{"buffer": 0, "byteOffset": int(offsets[k]), "byteLength": len(p)} for k, p in enumerate(parts)]
    accessors = [
        {"bufferView": 0, "componentType": 5126, "count": len(uv), "type": "VEC3"},
        {"bufferView": 1, "componentType": 5126, "count": len(uv), "type": "VEC2"},
        {"bufferView": 2, "componentType": 5123, "count": idx.size, "type": "SCALAR"},
    ]
    attrs = {"POSITION": 0, "TEXCOORD_0": 1}
    if colours is not None:
        accessors.append({"bufferView": 3, "componentType": 5121, "normalized": True, "count": len(uv), "type": "VEC3"})
        attrs["COLOR_0"] = 3
    buffer = {"byteLength": len(blob)}
    if uri == "data":
        buffer["uri"] = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
    doc = {
        "asset": {"version": "2.0"}, "buffers": [buffer], "bufferViews": views, "accessors": accessors,
        "meshes": [{"primitives": [{"attributes": attrs, "indices": 2}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
        "textures": [{"source": 0}], "images": [{"uri": "tex%20a.png"}],
    }  # fmt: skip
    doc["meshes"][0]["primitives"][0]["material"] = 0
    return doc, blob


def _glb(doc, blob) -> bytes:
    import json
    import struct

    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    blob += b"\0" * (-len(blob) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(blob), 0x004E4942) + blob
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body


def test_gltf_and_glb_read_like_the_mesh_they_hold(tmp_path):
    import json

    uv = np.array([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9], [0.5, 0.5]])
    tris = [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]
    colours = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [51, 102, 153], [0, 0, 0]])
    doc, blob = _gltf_doc(uv, tris, colours)
    (tmp_path / "m.gltf").write_text(json.dumps(doc))
    doc2 = json.loads(json.dumps(doc))
    del doc2["buffers"][0]["uri"]
    (tmp_path / "m.glb").write_bytes(_glb(doc2, blob))
    for name in ("m.gltf", "m.glb"):
        mesh = read_mesh(tmp_path / name)
        np.testing.assert_allclose(mesh.uv, uv, atol=1e-7)  # v flipped back to run up
        assert mesh.triangles_uv.tolist() == tris
        np.testing.assert_allclose(mesh.attributes["blue"], colours[:, 2] / 255)
        assert mesh.texture == str(tmp_path / "tex a.png")


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda d: d["accessors"][1].update(count=500), "reaches beyond its buffer view"),
        (lambda d: d["asset"].update(version="1.0"), "only glTF 2 is read"),
        (lambda d: d["accessors"][2].update(count=2), "2 indices are not whole triangles"),
        (lambda d: d["meshes"][0]["primitives"][0]["attributes"].pop("TEXCOORD_0"), "no texture coordinates"),
        (lambda d: d["meshes"][0]["primitives"][0].update(indices=9), "accessors[9] does not exist"),
        (lambda d: d["buffers"][0].update(uri="data:,%%%"), "not base64"),
        (lambda d: d["buffers"][0].update(uri="missing.bin"), "missing.bin: no such file"),
    ],
)
def test_gltf_errors_name_the_file(tmp_path, change, message):
    import json

    doc, _ = _gltf_doc(np.array([[0.1, 0.1], [0.9, 0.1], [0.5, 0.9]]), [[0, 1, 2]])
    change(doc)
    path = tmp_path / "bad.gltf"
    path.write_text(json.dumps(doc))
    with pytest.raises(MeshError, match=message.replace("[", "\\[").replace("]", "\\]")):
        read_mesh(path)


@pytest.mark.parametrize("index, ok", [("0.9", False), ("2.5", False), ("2.0", True)])
def test_ply_float_face_indices_must_be_whole(tmp_path, index, ok):
    # A face list declared float: 0.9 was read as vertex 0; a whole float is the vertex it names.
    path = tmp_path / "m.ply"
    head = (
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
        "property float u\nproperty float v\nelement face 2\nproperty list uchar float vertex_indices\nend_header\n"
    )
    rows = "0 0 0 0 0\n1 0 0 1 0\n1 1 0 1 1\n0 1 0 0 1\n" + f"3 0 1 {index}\n3 0 2 3\n"
    path.write_text(head + rows)
    if ok:
        assert read_mesh(path).triangles_pos.tolist()[0] == [0, 1, 2]
    else:
        with pytest.raises(MeshError, match="face 0 has a vertex index that is not a whole number"):
            read_mesh(path)
