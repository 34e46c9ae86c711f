"""warp edit without a browser: the server's refusals, the session's saves and exports, the warnings, the preview map."""

from __future__ import annotations

import http.client
import importlib
import json
import os
import pathlib
import socket
import sys
import threading

import numpy as np
import pytest
from edit_helpers import served, smooth_image, snapshot_dir, write_smooth_image
from helpers import l_shape, regular, star
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from warpcli.edit.preview import PreviewMapper, encode_png, preview_areas, preview_image
from warpcli.edit.server import MAX_BODY, EditServer
from warpcli.edit.session import EditPaths, EditSession, command_args, mirror_warning, rotated_start
from warpcli.errors import WarpError
from warpcli.maps.compose import BijectiveMap
from warpcli.options import MapOptions, WarpOptions
from warpcli.polygon import Polygon
from warpcli.raster.imageio import RasterImage, read_image

SECRET = b"do-not-serve-me"

# --- what the server opens: an audit hook records every file opened while `_watching` is set ---------

_watching = threading.Event()
_opened: list[str] = []


def _audit(event: str, args: tuple) -> None:
    if event == "open" and _watching.is_set() and isinstance(args[0], (str, bytes, os.PathLike)):
        _opened.append(os.fsdecode(args[0]))


sys.addaudithook(_audit)


@pytest.fixture()
def server(tmp_path):
    image = str(tmp_path / "picture.png")
    write_smooth_image(image, 64, 48)
    (tmp_path / "secret.txt").write_bytes(SECRET)
    (tmp_path / "a.json").write_text(json.dumps([[8, 8], [56, 8], [56, 40], [8, 40]]))
    with served(image, src=str(tmp_path / "a.json")) as s:
        yield s


def request(server, method, path, body=None, headers=None, host=None):
    """One request; ``host`` None: the server's own Host header."""
    conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=30)
    conn.putrequest(method, path, skip_host=True, skip_accept_encoding=True)
    conn.putheader("Host", host if host is not None else f"127.0.0.1:{server.port}")
    for key, value in (headers or {}).items():
        conn.putheader(key, value)
    data = b"" if body is None else body
    if body is not None and "Content-Length" not in (headers or {}):
        conn.putheader("Content-Length", str(len(data)))
    conn.endheaders(data if body is not None else None)
    response = conn.getresponse()
    out = response.status, response.read()
    conn.close()
    return out


def token(server):
    return {"X-Warp-Token": server.token}


def json_post(server, path, doc, **extra):
    headers = dict(token(server), **{"Content-Type": "application/json"})
    headers.update(extra.pop("headers", {}))
    return request(server, "POST", path, json.dumps(doc).encode(), headers, **extra)


SQUARE = [[8, 8], [56, 8], [56, 40], [8, 40]]
MOVED = [[8, 8], [60, 4], [56, 40], [8, 40]]


# --- the token, Host, Origin -----------------------------------------------------------------


def test_the_page_assets_and_image_with_the_token(server):
    status, body = request(server, "GET", f"/?token={server.token}")
    assert status == 200 and b"editor.js?token=" + server.token.encode() in body
    for path in ("/static/editor.js", "/static/editor.css", "/image.png", "/api/state"):
        status, body = request(server, "GET", f"{path}?token={server.token}")
        assert status == 200 and body, path
    status, body = request(server, "GET", "/image.png", headers=token(server))
    assert status == 200 and body.startswith(b"\x89PNG")


REFUSALS = [
    # (what, method, path template, headers, host) -> refused
    ("no token", "GET", "/", {}, None),
    ("no token", "GET", "/image.png", {}, None),
    ("no token", "GET", "/api/state", {}, None),
    ("wrong token", "GET", "/?token=wrong", {}, None),
    ("wrong token", "GET", "/image.png?token=x{token}", {}, None),
    ("wrong token header", "GET", "/api/state", {"X-Warp-Token": "nope"}, None),
    ("token prefix", "GET", "/?token={token_prefix}", {}, None),
    ("foreign Host", "GET", "/?token={token}", {}, "evil.example:{port}"),
    ("DNS rebinding", "GET", "/?token={token}", {}, "rebind.attacker.test:{port}"),
    ("other port", "GET", "/?token={token}", {}, "127.0.0.1:1"),
    ("no port", "GET", "/?token={token}", {}, "127.0.0.1"),
    ("empty Host", "GET", "/?token={token}", {}, ""),
    ("foreign Origin", "GET", "/api/state?token={token}", {"Origin": "http://evil.example"}, None),
    ("null Origin", "GET", "/api/state?token={token}", {"Origin": "null"}, None),
    ("https Origin", "GET", "/api/state?token={token}", {"Origin": "https://127.0.0.1:{port}"}, None),
    ("cross-site fetch", "GET", "/api/state?token={token}", {"Sec-Fetch-Site": "cross-site"}, None),
    ("same-site fetch", "GET", "/api/state?token={token}", {"Sec-Fetch-Site": "same-site"}, None),
    ("cross-site navigation to a call", "GET", "/api/state?token={token}", {"Sec-Fetch-Site": "cross-site",
     "Sec-Fetch-Mode": "navigate", "Sec-Fetch-Dest": "document"}, None),
    ("cross-site page in a frame", "GET", "/?token={token}", {"Sec-Fetch-Site": "cross-site", "Sec-Fetch-Mode": "navigate",
     "Sec-Fetch-Dest": "iframe"}, None),
    ("cross-site page fetched", "GET", "/?token={token}", {"Sec-Fetch-Site": "cross-site", "Sec-Fetch-Mode": "cors",
     "Sec-Fetch-Dest": "empty"}, None),
    ("cross-site navigation without the token", "GET", "/", {"Sec-Fetch-Site": "cross-site", "Sec-Fetch-Mode": "navigate",
     "Sec-Fetch-Dest": "document"}, None),
    ("traversal", "GET", "/static/../secret.txt?token={token}", {}, None),
    ("traversal", "GET", "/../secret.txt?token={token}", {}, None),
    ("traversal", "GET", "/static/%2e%2e/%2e%2e/secret.txt?token={token}", {}, None),
    ("traversal", "GET", "/static/..%2f..%2fsecret.txt?token={token}", {}, None),
    ("traversal", "GET", "//etc/passwd?token={token}", {}, None),
    ("traversal", "GET", "/image.png/../secret.txt?token={token}", {}, None),
    ("other file", "GET", "/secret.txt?token={token}", {}, None),
    ("other file", "GET", "/static/index.html?token={token}", {}, None),
    ("other file", "GET", "/static/?token={token}", {}, None),
    ("absolute URL", "GET", "http://evil.example/secret.txt?token={token}", {}, None),
    ("method", "PUT", "/?token={token}", {}, None),
    ("method", "DELETE", "/image.png?token={token}", {}, None),
    ("method", "OPTIONS", "/api/save?token={token}", {"Origin": "http://evil.example"}, None),
]


@pytest.mark.parametrize("what, method, path, headers, host", REFUSALS, ids=[r[0] for r in REFUSALS])
def test_refused_and_nothing_read_or_written(server, tmp_path, what, method, path, headers, host):
    fill = {"token": server.token, "token_prefix": server.token[:-1], "port": server.port}
    path = path.format(**fill)
    headers = {k: v.format(**fill) for k, v in headers.items()}
    before = snapshot_dir(str(tmp_path))
    _opened.clear()
    _watching.set()
    try:
        status, body = request(server, method, path, headers=headers, host=None if host is None else host.format(**fill))
    finally:
        _watching.clear()
    assert status in (403, 404, 405, 421), (status, body)
    assert SECRET not in body and b"warpEditor" not in body and not body.startswith(b"\x89PNG")
    assert b"root:" not in body
    assert _opened == [], _opened
    assert snapshot_dir(str(tmp_path)) == before


@pytest.mark.parametrize("path", ["/api/save", "/api/export", "/api/preview"])
def test_posts_refused_without_token_or_from_another_origin(server, tmp_path, path):
    doc = {"src": SQUARE, "dst": MOVED}
    before = snapshot_dir(str(tmp_path))
    cases = [
        {"Content-Type": "application/json"},  # no token
        {"Content-Type": "application/json", "X-Warp-Token": server.token + "x"},
        {"Content-Type": "application/json", "X-Warp-Token": server.token, "Origin": "http://evil.example"},
        {"Content-Type": "text/plain", "X-Warp-Token": server.token},  # a simple (CORS-free) request's type
    ]
    for headers in cases:
        status, _ = request(server, "POST", path, json.dumps(doc).encode(), headers)
        assert status in (403, 415), headers
    assert request(server, "POST", path, json.dumps(doc).encode(), {"Content-Type": "application/json",
                   "X-Warp-Token": server.token}, host="evil.example")[0] == 421  # fmt: skip
    assert snapshot_dir(str(tmp_path)) == before


def test_oversized_and_unbounded_bodies_refused_unread(server, tmp_path):
    before = snapshot_dir(str(tmp_path))
    headers = dict(token(server), **{"Content-Type": "application/json"})
    # Only the headers are sent: the answer comes without the server waiting for (reading) the body.
    with socket.create_connection(("127.0.0.1", server.port), timeout=10) as sock:
        sock.sendall(
            f"POST /api/save HTTP/1.1\r\nHost: 127.0.0.1:{server.port}\r\nX-Warp-Token: {server.token}\r\n"
            f"Content-Type: application/json\r\nContent-Length: {MAX_BODY + 1}\r\n\r\n".encode()
        )
        answer = sock.recv(4096)
    assert answer.startswith(b"HTTP/1.1 413")
    with socket.create_connection(("127.0.0.1", server.port), timeout=10) as sock:
        sock.sendall(
            f"POST /api/save HTTP/1.1\r\nHost: 127.0.0.1:{server.port}\r\nX-Warp-Token: {server.token}\r\n"
            "Content-Type: application/json\r\nTransfer-Encoding: chunked\r\n\r\n".encode()
        )
        assert sock.recv(4096).startswith(b"HTTP/1.1 411")
    # A Content-Length is digits alone (int() would take a sign, underscores, spaces round it).
    for bad in ("-5", "x", "+2", "2_0", "1e1", "0x1"):
        assert request(server, "POST", "/api/save", b"{}", dict(headers, **{"Content-Length": bad}))[0] == 400, bad
    assert request(server, "POST", "/api/save", b"{}", dict(headers, **{"Content-Length": "9" * 40}))[0] == 413
    assert request(server, "POST", "/api/save", b"[" * 100_000, headers)[0] == 400
    assert request(server, "POST", "/api/save", b"[1, 2]", headers)[0] == 400
    # Over 1 MB of JSON: refused from its Content-Length alone, answered before the body is sent
    # (sending it would race with the server closing the connection).
    big = json.dumps({"src": [[1.0, 2.0]] * 100_000, "dst": SQUARE}).encode()
    assert len(big) > MAX_BODY
    with socket.create_connection(("127.0.0.1", server.port), timeout=10) as sock:
        sock.sendall(
            f"POST /api/save HTTP/1.1\r\nHost: 127.0.0.1:{server.port}\r\nX-Warp-Token: {server.token}\r\n"
            f"Content-Type: application/json\r\nContent-Length: {len(big)}\r\n\r\n".encode()
        )
        assert sock.recv(4096).startswith(b"HTTP/1.1 413")
    status, body = json_post(server, "/api/save", {"src": [[1.0, 2.0]] * 30_000, "dst": SQUARE})
    assert status == 200 and not json.loads(body)["ok"]  # under the size, over the vertex count
    assert snapshot_dir(str(tmp_path)) == before


# --- saving: only where the user says, never the input ----------------------------------------------------


@pytest.mark.parametrize(
    "name",
    [
        "../x.json", "/tmp/x.json", "sub/x.json", ".hidden.json", "x.png", "..", "a\\b.json", "x\n.json", "", 7,
        "x\x7f.json", "evil\u202egpj.json", " x.json", "x.json ", "a\u200bb.json", "x\x85.json",
    ],
)  # fmt: skip
def test_save_names_only_plain_json_files_in_the_image_directory(server, tmp_path, name):
    before = snapshot_dir(str(tmp_path))
    status, body = json_post(server, "/api/save", {"src": SQUARE, "dst": MOVED, "dst_name": name})
    result = json.loads(body)
    if name == "":  # the default: the path of the command line
        assert result["ok"]
        assert result["saved"] == [str(tmp_path / "a.json"), str(tmp_path / "picture.dst.json")]
        return
    assert status == 200 and not result["ok"] and result["error"]
    assert snapshot_dir(str(tmp_path)) == before
    assert not os.path.exists("/tmp/x.json") or name != "/tmp/x.json"


def test_save_writes_files_the_cli_reads(server, tmp_path):
    status, body = json_post(server, "/api/save", {"src": SQUARE, "dst": MOVED, "dst_name": "moved.json"})
    result = json.loads(body)
    assert result["ok"], result
    from warpcli.polygon import read_polygon

    np.testing.assert_array_equal(read_polygon(tmp_path / "a.json").points, SQUARE)
    np.testing.assert_array_equal(read_polygon(tmp_path / "moved.json").points, MOVED)
    assert f"--dst {tmp_path / 'moved.json'}" in result["command"]
    assert not [n for n in os.listdir(tmp_path) if "warpcli-" in n]  # no temporary left


def test_export_never_overwrites_the_input(server, tmp_path):
    before = snapshot_dir(str(tmp_path))
    status, body = json_post(server, "/api/export", {"src": SQUARE, "dst": MOVED, "output_name": "picture.png"})
    result = json.loads(body)
    assert not result["ok"] and "overwrite the input" in result["error"]
    assert snapshot_dir(str(tmp_path)) == before


def test_bad_polygons_get_the_cli_messages(server, tmp_path):
    bow_tie = [[8, 8], [56, 40], [56, 8], [8, 40]]
    for doc in ({"src": SQUARE, "dst": bow_tie}, {"src": SQUARE, "dst": SQUARE[:3]}, {"src": SQUARE, "dst": [[0, "a"]] * 4}):
        name = str(tmp_path / "picture.dst.json")
        with pytest.raises(Exception) as err:
            Polygon(doc["dst"], name=name)
            from warpcli.polygon import check_pair

            check_pair(Polygon(doc["src"], name=str(tmp_path / "a.json")), Polygon(doc["dst"], name=name))
        status, body = json_post(server, "/api/save", doc)
        assert json.loads(body) == {"ok": False, "error": str(err.value)}
        status, body = json_post(server, "/api/preview", doc)
        n = int.from_bytes(body[:4], "little")
        assert json.loads(body[4 : 4 + n])["error"] == str(err.value)


# --- the preview is the map ------------------------------------------------------------------------------


def assert_inverse(texcoords, positions, fmap, atol=1e-4):
    """``texcoords`` are f^-1 of ``positions``: where `BijectiveMap.inverse` answers (it may leave
    points on the target's edge out, as outside), and on the edge inside the source polygon's box."""
    want = fmap.inverse(positions)
    found = np.isfinite(want).all(axis=1)
    assert found.mean() > 0.8
    np.testing.assert_allclose(texcoords[found], want[found], atol=atol)
    x0, y0, x1, y1 = fmap.src.bounds
    edge = texcoords[~found]
    assert np.isfinite(edge).all() and (edge >= [x0 - 1e-3, y0 - 1e-3]).all() and (edge <= [x1 + 1e-3, y1 + 1e-3]).all()


def test_preview_map_is_build_map(server):
    """The kept-side builder gives the map `BijectiveMap.between` builds, value for value."""
    src, dst = Polygon(star(5), name="a"), Polygon(star(5, r_in=30, phase=0.1), name="b")
    opts = MapOptions(max_area=preview_areas(src, dst), grade=False)
    region = (0.0, 0.0, 128.0, 128.0)
    mapper = PreviewMapper()
    mesh = mapper.build(src, dst, opts, region)
    ref = BijectiveMap.between(src, dst, opts, regions=(region, region))
    np.testing.assert_array_equal(mesh.map.phi1.values, ref.phi1.values)
    np.testing.assert_array_equal(mesh.map.phi0.values, ref.phi0.values)
    assert_inverse(mesh.texcoords, mesh.positions, ref)
    # Only the target moves: the source map is kept, the target's rebuilt.
    dst2 = Polygon(star(5, r_in=33, phase=0.1), name="b")
    opts2 = MapOptions(max_area=preview_areas(src, dst2), grade=False)
    again = mapper.build(src, dst2, opts2, region)
    assert again.rebuilt == ("target",) and again.map.phi0 is mesh.map.phi0
    ref2 = BijectiveMap.between(src, dst2, opts2, regions=(region, region))
    np.testing.assert_array_equal(again.map.phi1.values, ref2.phi1.values)
    # Theta cyclic depends on both polygons: both are rebuilt.
    cyc = mapper.build(src, dst, MapOptions(theta="cyclic", max_area=preview_areas(src, dst)), region)
    assert cyc.rebuilt == ("source", "target")


def _decoded(data: bytes):
    n = int.from_bytes(data[:4], "little")
    header = json.loads(data[4 : 4 + n])
    if not header["ok"]:
        return header, None
    v = header["vertices"]
    xyuv = np.frombuffer(data, "<f4", 4 * v, 4 + n).reshape(v, 4)
    return header, xyuv


@pytest.mark.parametrize("factor", [1, 2])
def test_a_drag_rebuilds_only_its_side_at_the_drag_density_and_the_release_at_the_full_one(tmp_path, factor):
    from warpcli.edit.preview import PREVIEW_DRAG_TRIANGLES, with_preview_density

    image = str(tmp_path / "i.png")
    write_smooth_image(image, 128 * factor, 128 * factor)
    session = EditSession(EditPaths.defaults(image))
    session.preview = preview_image(read_image(image), side=128)  # a factor whatever PREVIEW_SIDE is
    assert session.preview.factor == factor
    src = star(5) * factor
    region = (0.0, 0.0, 128.0, 128.0)
    steps = [(None, star(5, r_in=30)), ("dst", star(5, r_in=31)), ("dst", star(5, r_in=32)), (None, star(5, r_in=32)),
             ("src", star(5, r_in=32))]  # fmt: skip
    expected_rebuilt = [["source", "target"], ["target"], ["target"], ["target"], ["source"]]
    for (drag, dst), rebuilt in zip(steps, expected_rebuilt):
        if drag == "src":
            src = star(5, r_out=56) * factor
        header, xyuv = _decoded(session.preview_map({"src": src.tolist(), "dst": (dst * factor).tolist(), "drag": drag}))
        assert header["rebuilt"] == rebuilt
        psrc, pdst = Polygon(src / factor), Polygon(dst)
        full = preview_areas(psrc, pdst)
        coarse = preview_areas(psrc, pdst, PREVIEW_DRAG_TRIANGLES)
        side = {"src": 0, "dst": 1}.get(drag)
        assert header["max_area"] == [coarse[i] if i == side else full[i] for i in (0, 1)]
        # The real map at that density: what BijectiveMap.between builds from the same options.
        ref = BijectiveMap.between(psrc, pdst, with_preview_density(MapOptions(), psrc, pdst, drag), regions=(region, region))
        np.testing.assert_array_equal(xyuv[:, :2], ref.phi1.mesh.vertices.astype(np.float32))
        assert_inverse(xyuv[:, 2:].astype(float), xyuv[:, :2].astype(float), ref, atol=1e-3)
    header, _ = _decoded(session.preview_map({"src": src.tolist(), "dst": (dst * factor).tolist(), "drag": "both"}))
    assert not header["ok"] and "drag must be" in header["error"]


@pytest.mark.parametrize("method", ["bem", "mfs"])
def test_preview_of_meshless_methods(method):
    src, dst = Polygon(l_shape(), name="a"), Polygon(l_shape(notch=0.4), name="b")
    mesh = PreviewMapper().build(src, dst, MapOptions(method=method, max_area=preview_areas(src, dst)), (0, 0, 128, 128))
    # Near the edge the meshless inverse (Newton's method) stops within its tolerance: a thousandth of a pixel.
    assert_inverse(mesh.texcoords, mesh.positions, mesh.map, atol=5e-3)


def test_session_preview_is_scaled_by_a_whole_factor(tmp_path):
    image = str(tmp_path / "big.png")
    write_smooth_image(image, 2100, 900)
    session = EditSession(EditPaths.defaults(image))
    assert session.preview.factor == 3 and session.preview.preview_size == (700, 300)
    px = read_image(image).pixels.astype(float) / 255
    block = px[:3, 6:9].mean(axis=(0, 1))
    np.testing.assert_allclose(session.preview.pixels[0, 2, :3], np.round(block * 255), atol=1)


def test_encode_png_round_trips(tmp_path):
    rgba = np.concatenate([smooth_image(37, 23), np.full((23, 37, 1), 200, np.uint8)], axis=2)
    path = tmp_path / "x.png"
    path.write_bytes(encode_png(rgba))
    np.testing.assert_array_equal(read_image(path).pixels, rgba)


def test_preview_image_of_grey_alpha_and_float():
    grey = RasterImage(np.linspace(0, 1, 12, dtype=np.float32).reshape(3, 4, 1), ("Y",))
    out = preview_image(grey).pixels
    assert out.shape == (3, 4, 4) and (out[..., 0] == out[..., 1]).all() and (out[..., 3] == 255).all()
    la = RasterImage(np.full((2, 2, 2), 128, np.uint8), ("Y", "A"), alpha_channel=1, associated_alpha=False)
    assert preview_image(la).pixels[0, 0].tolist() == [128, 128, 128, 128]


# --- warnings -----------------------------------------------------------------------------------------


@given(n=st.integers(3, 40), shift=st.integers(1, 39), scale=st.floats(0.3, 3.0), dx=st.floats(-50, 50))
def test_rotated_start_found_for_any_shift(n, shift, scale, dx):
    shift %= n
    pts = regular(n, phase=0.3) if n % 2 else star(n // 2 + 2)
    src = Polygon(pts, name="a")
    moved = np.roll(pts * scale + dx, shift, axis=0)
    assert rotated_start(src, Polygon(moved, name="b")) == shift
    assert rotated_start(src, Polygon(pts * scale + dx, name="b")) == 0


def test_no_rotated_start_for_ordinary_edits():
    src = Polygon(star(6), name="a")
    rng = np.random.default_rng(1)
    for _ in range(20):
        pts = star(6) + rng.normal(0, 3, (12, 2))
        assert rotated_start(src, Polygon(pts, name="b")) == 0


def test_mirror_warning_is_the_cli_one():
    a = Polygon(regular(6), name="a.json")
    assert mirror_warning(a, Polygon(regular(6) * 2, name="b.json")) is None
    text = mirror_warning(a, Polygon(regular(6)[::-1], name="b.json"))
    assert text.startswith("a.json and b.json run in opposite directions: the warp mirrors the image")


# --- the command line -----------------------------------------------------------------------------------


def test_command_line_parses_back_to_the_options(monkeypatch):
    """Every option of the printed command reaches ``warp`` as the session's options."""
    from warpcli.cli import main

    # The module (the package's name ``warp`` is the command); imported here, since the group
    # imports a command's module only when the command runs.
    warp_command = importlib.import_module("warpcli.cli.warp")

    opts = WarpOptions(map=MapOptions(method="bem", theta="cyclic", dst_boundary="quadratic", max_area=4.0), interp="cubic",
                       outside="input", antialias=False, background=(1.0, 0.5, 0.25))  # fmt: skip
    seen = []
    monkeypatch.setattr(warp_command, "_single", lambda *args: seen.append(args))
    args = command_args(opts, "in.png", "a.json", "b.json", "out.png")
    assert main(args[1:]) == 0
    assert seen[0][:2] == ("in.png", "out.png") and seen[0][3] == opts
    assert command_args(WarpOptions(), "in.png", "a.json", "b.json", "out.png") == [
        "warp", "in.png", "--src", "a.json", "--dst", "b.json", "out.png"]  # fmt: skip


@pytest.mark.parametrize("when", ["serving", "before the loop starts", "twice"])
def test_shutdown_ends_the_serving_thread_and_frees_the_port(tmp_path, when):
    """`EditServer.shutdown` wakes the serving loop (it sleeps in select, it does not poll), waits
    for it to end and closes the port; called before the loop runs, the loop never serves."""
    from warpcli.edit.server import EditServer

    image = str(tmp_path / "picture.png")
    write_smooth_image(image, 16, 12)
    server = EditServer(EditSession(EditPaths.defaults(image)))
    if when == "before the loop starts":
        server.shutdown()
        thread = server.start()
    else:
        thread = server.start()
        assert request(server, "GET", f"/?token={server.token}")[0] == 200  # it serves
        server.shutdown()
        if when == "twice":
            server.shutdown()
    thread.join(timeout=30)
    assert not thread.is_alive()
    with pytest.raises(OSError):
        socket.create_connection(("127.0.0.1", server.port), timeout=5).close()


# --- the command ------------------------------------------------------------------------------------------


def test_warp_edit_prints_the_address_serves_and_stops_on_ctrl_c(tmp_path):
    import signal
    import subprocess
    import urllib.request

    image = str(tmp_path / "picture.png")
    write_smooth_image(image, 64, 48)
    env = dict(os.environ, PYTHONPATH=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

    def default_sigint() -> None:
        # Run as a user's shell runs it: SIGINT delivered and not ignored. A child inherits an
        # ignored or blocked SIGINT from its parent, and earlier tests in this test worker (a
        # Dask cluster, threads of other libraries) may leave the worker so.
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
        signal.signal(signal.SIGINT, signal.SIG_DFL)

    proc = subprocess.Popen(
        [sys.executable, "-m", "warpcli", "edit", image, "--no-browser"], stderr=subprocess.PIPE, text=True, env=env,
        preexec_fn=default_sigint,
    )  # fmt: skip
    try:
        line = proc.stderr.readline()
        assert line.startswith(f"warp edit: {image} at http://127.0.0.1:") and "?token=" in line
        url = line.split(" at ")[1].split()[0]
        with urllib.request.urlopen(url, timeout=30) as response:
            assert b"warp edit" in response.read()
        proc.send_signal(signal.SIGINT)
        # communicate, not wait: it drains stderr while waiting, so that a child that writes
        # more than a pipe holds cannot block on the write (see subprocess.Popen.wait).
        _, rest = proc.communicate(timeout=60)
        assert proc.returncode == 0, rest
        assert rest.strip() == "warp edit: stopped"
    finally:
        if proc.poll() is None:
            proc.kill()
    assert sorted(os.listdir(tmp_path)) == ["picture.png"]


@pytest.mark.parametrize("case", ["missing", "not an image", "bad polygon"])
def test_warp_edit_bad_input_is_one_line_and_exit_2(tmp_path, case, capsys):
    from warpcli.cli import main

    image = tmp_path / "picture.png"
    args = [str(image)]
    if case == "not an image":
        image.write_text("hello")
    elif case == "bad polygon":
        write_smooth_image(str(image), 32, 32)
        (tmp_path / "a.json").write_text("[[0, 0], [1, 1]]")
        args += ["--src", str(tmp_path / "a.json")]
    assert main(["edit", *args, "--no-browser"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("warp: error: ") and str(tmp_path) in err


def test_load_reads_what_the_cli_reads(server, tmp_path):
    """A file chosen on the page (its text) is parsed as `read_polygon` parses the file; nothing is read from disk."""
    from warpcli.polygon import read_polygon

    docs = {
        "plain.json": SQUARE,
        "points.json": {"points": MOVED},
        "labelme.json": {"shapes": [{"label": "eye", "shape_type": "polygon", "points": MOVED}]},
        "geo.json": {"type": "Polygon", "coordinates": [SQUARE + [SQUARE[0]]]},
    }
    for name, doc in docs.items():
        path = tmp_path / name
        path.write_text(json.dumps(doc))
        text = path.read_text()
        _opened.clear()
        _watching.set()
        try:
            status, body = json_post(server, "/api/load", {"name": name, "text": text})
        finally:
            _watching.clear()
        assert _opened == []
        assert json.loads(body) == {"ok": True, "points": read_polygon(path).points.tolist()}
    for text in ("[[0, 0], [1, 1]]", "{", '{"shapes": []}', '{"points": [[0, 0], [1, 0], [0, 1], [1, 1]]}'):
        path = tmp_path / "bad.json"
        path.write_text(text)
        with pytest.raises(Exception) as err:
            read_polygon(path)
        status, body = json_post(server, "/api/load", {"name": "/somewhere/bad.json", "text": text})
        assert json.loads(body) == {"ok": False, "error": str(err.value).replace(str(path), "bad.json")}


def test_warp_edit_on_a_taken_port_is_bad_input(tmp_path, capsys):
    from warpcli.cli import main

    image = str(tmp_path / "picture.png")
    write_smooth_image(image, 16, 16)
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        assert main(["edit", image, "--no-browser", "--port", str(port)]) == 2
    err = capsys.readouterr().err
    assert err == f"warp: error: 127.0.0.1:{port}: cannot listen there: Address already in use\n"


def test_preview_density_coarsens_the_grading_not_the_map():
    """Ungraded preview meshes have several times fewer vertices, and the map stays within a tenth of a pixel."""
    src, dst = Polygon(star(6), name="a"), Polygon(star(6, r_in=30, phase=0.2), name="b")
    region = (0.0, 0.0, 128.0, 128.0)
    from warpcli.edit.preview import with_preview_density

    preview = BijectiveMap.between(src, dst, with_preview_density(MapOptions(), src, dst), regions=(region, region))
    graded = BijectiveMap.between(src, dst, MapOptions(max_area=preview_areas(src, dst)), regions=(region, region))
    fine = BijectiveMap.between(src, dst, regions=(region, region))
    assert len(graded.phi1.mesh.vertices) > 3 * len(preview.phi1.mesh.vertices)
    y, x = np.mgrid[20:108:3, 20:108:3] + 0.5
    q = np.stack([x.ravel(), y.ravel()], axis=1)
    a, b = preview.inverse(q), fine.inverse(q)
    ok = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
    assert ok.sum() > 200
    assert np.percentile(np.hypot(*(a[ok] - b[ok]).T), 95) < 0.1
    with pytest.raises(ValueError, match="grade must be True or False"):
        MapOptions(grade="no")


# --- within a fixed outline (--within) --------------------------------------------------------------------

WITHIN_CAGE = np.array([[40.0, 30.0], [80.0, 30.0], [88.0, 50.0], [80.0, 66.0], [40.0, 66.0], [32.0, 48.0]])


def _within_target(seed: int) -> np.ndarray:
    """The cage with its vertices moved a few pixels at random (generated cases)."""
    return WITHIN_CAGE + np.random.default_rng(seed).uniform(-6, 6, WITHIN_CAGE.shape).round(2)


@pytest.fixture(scope="module")
def within_session(tmp_path_factory):
    image = str(tmp_path_factory.mktemp("within") / "picture.png")
    write_smooth_image(image, 128, 96)
    return EditSession(EditPaths.defaults(image))


@pytest.mark.parametrize("within, seed, method, factor", [("image", 0, "fem", 1), ("12", 1, "fem", 1), ("image", 2, "fem", 2)])
def test_within_preview_is_the_within_warp_at_preview_density(within_session, within, seed, method, factor):
    """The preview with within is warp_image(..., within=...)'s cage map at the density the header names (in the
    image's pixels), value for value, shown shrunk by the preview's factor."""
    from warpcli.pipeline import warp_image

    session = within_session
    session.preview = preview_image(read_image(session.paths.image), side=128 // factor)
    assert session.preview.factor == factor
    dst = _within_target(seed)
    header, xyuv = _decoded(session.preview_map({"src": WITHIN_CAGE.tolist(), "dst": dst.tolist(),
                                                 "options": {"within": within, "method": method}}))  # fmt: skip
    assert header["ok"], header
    assert header["command"].endswith(f"--within {within}") and "--outside" not in header["command"]
    pixels = read_image(session.paths.image).pixels
    ref = warp_image(pixels, WITHIN_CAGE, dst, WarpOptions(within=within, antialias=False),
                     method=method, max_area=tuple(header["max_area"]), grade=False)  # fmt: skip
    cage = ref.map
    assert len(cage.face_maps) > 1  # the cage and the ring's faces
    positions, tex = xyuv[:, :2].astype(float) * factor, xyuv[:, 2:].astype(float) * factor
    if method == "fem":  # the same meshes, vertex for vertex, and the same harmonic values
        want = np.concatenate([m.phi1.mesh.vertices for m in cage.face_maps])
        np.testing.assert_array_equal(xyuv[:, :2], (want / factor).astype(np.float32))
    # The preview's texture coordinates are f^-1 of its vertices, f the within warp's map.
    want = cage.inverse(positions)
    found = np.isfinite(want).all(axis=1)
    assert found.mean() > 0.95
    np.testing.assert_allclose(tex[found], want[found], atol=5e-3 if method == "bem" else 1e-3)
    # The mesh covers the whole outline (the cage and the ring): its area is the outline's.
    tris = np.frombuffer(session.preview_map({"src": WITHIN_CAGE.tolist(), "dst": dst.tolist(),
                         "options": {"within": within, "method": method}}), "<u4")[-3 * header["triangles"]:].reshape(-1, 3)  # fmt: skip
    a, b, c = (positions.astype(np.float32)[tris[:, i]].astype(float) for i in range(3))
    area = 0.5 * np.abs((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]).sum()
    x0, y0 = ref.within.outline.min(axis=0)
    x1, y1 = ref.within.outline.max(axis=0)
    assert area == pytest.approx((x1 - x0) * (y1 - y0), rel=1e-6)


@pytest.mark.parametrize("within", ["image", "8"])
def test_within_export_is_the_command_byte_for_byte(tmp_path, within):
    """Export with within writes what the page's command line writes (``warp ... --within``), byte for byte."""
    import shlex

    from warpcli.cli import main

    image = str(tmp_path / "picture.png")
    write_smooth_image(image, 128, 96)
    session = EditSession(EditPaths.defaults(image))
    result = session.export({"src": WITHIN_CAGE.tolist(), "dst": _within_target(3).tolist(),
                             "options": {"within": within, "interp": "cubic"}})  # fmt: skip
    args = shlex.split(result["command"])
    assert args[-2:] == ["--within", within] and "--interp" in args
    again = str(tmp_path / "again.png")
    args[args.index(result["output"])] = again
    assert main(args[1:]) == 0
    with open(result["output"], "rb") as a, open(again, "rb") as b:
        assert a.read() == b.read()
    # Outside the outline, the input's own pixels.
    if within != "image":
        out, src = read_image(result["output"]).pixels, read_image(image).pixels
        assert (out[:, :10] == src[:, :10]).all()


@given(vertex=st.integers(0, 5), dx=st.floats(-200, 200), dy=st.floats(-200, 200), within=st.sampled_from(["image", "5"]))
@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_within_ring_errors_are_one_line_the_clis(within_session, vertex, dx, dy, within):
    """A vertex moved anywhere: a preview or the CLI's one-line message (within_pair's), never a server error."""
    from warpcli.errors import WarpError
    from warpcli.within import within_pair

    session = within_session
    dst = WITHIN_CAGE.copy()
    dst[vertex] += [dx, dy]
    header, _ = _decoded(session.preview_map({"src": WITHIN_CAGE.tolist(), "dst": dst.tolist(), "options": {"within": within}}))
    try:
        src_p, dst_p = Polygon(WITHIN_CAGE, name=session.paths.src), Polygon(dst, name=session.paths.dst)
        from warpcli.polygon import check_pair

        check_pair(src_p, dst_p)
        within_pair(src_p, dst_p, within, session.image_size)
    except WarpError as err:
        assert header == {"ok": False, "error": str(err), "command": None}
        assert "\n" not in header["error"]
        return
    assert header["ok"] or ("\n" not in header["error"] and header["error"])  # a map that folds: its message


@pytest.mark.parametrize(
    "value",
    ["/etc/passwd", "../a.json", "a.json", "0", "-5", "nan", "inf", "", " ", "1e400", 5, ["image"], {"x": 1}, "9" * 300],
)
def test_within_from_the_page_is_image_or_a_margin_and_never_a_file(server, tmp_path, value):
    before = snapshot_dir(str(tmp_path))
    _opened.clear()
    _watching.set()
    try:
        for path in ("/api/preview", "/api/save", "/api/export"):
            status, body = json_post(server, path, {"src": SQUARE, "dst": MOVED, "options": {"within": value}})
            assert status == 200
            if path == "/api/preview":
                n = int.from_bytes(body[:4], "little")
                body = body[4 : 4 + n]
            result = json.loads(body)
            assert not result["ok"] and "within" in result["error"] and "\n" not in result["error"]
    finally:
        _watching.clear()
    assert _opened == [], _opened
    assert snapshot_dir(str(tmp_path)) == before


def test_within_file_of_the_command_line_and_the_cli_checks(tmp_path, capsys):
    """``warp edit --within FILE``: the page may choose it back (and none); bad values are one line and exit 2."""
    from warpcli.cli import main

    image = str(tmp_path / "picture.png")
    write_smooth_image(image, 128, 96)
    outline = tmp_path / "outline.json"
    outline.write_text(json.dumps([[20, 16], [110, 16], [110, 84], [20, 84]]))
    session = EditSession(EditPaths.defaults(image), WarpOptions(within=str(outline)))
    assert session.state()["options"]["within"] == str(outline)
    doc = {"src": WITHIN_CAGE.tolist(), "dst": _within_target(4).tolist()}
    header, _ = _decoded(session.preview_map(dict(doc, options={"within": str(outline)})))
    assert header["ok"] and header["command"].endswith(f"--within {outline}")
    header, _ = _decoded(session.preview_map(dict(doc, options={"within": None, "outside": "background"})))
    assert header["ok"] and "--within" not in header["command"] and "--outside" not in header["command"]
    header, _ = _decoded(session.preview_map(dict(doc, options={"within": str(tmp_path / "other.json")})))
    assert not header["ok"] and "a polygon file only from the command line" in header["error"]
    for value, needle in (("0", "positive number"), (str(tmp_path / "missing.json"), "missing.json")):
        assert main(["edit", image, "--within", value, "--no-browser"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("warp: error: ") and needle in err
    assert main(["edit", image, "--within", "image", "--outside", "background", "--no-browser"]) == 2
    assert "takes no --outside background" in capsys.readouterr().err


def test_within_command_line_parses_back(monkeypatch):
    from warpcli.cli import main

    warp_command = importlib.import_module("warpcli.cli.warp")  # the module, imported on demand
    seen = []
    monkeypatch.setattr(warp_command, "_single", lambda *args: seen.append(args))
    for within in ("image", "7.5"):
        opts = WarpOptions(map=MapOptions(method="bem"), interp="cubic", within=within)
        args = command_args(opts, "in.png", "a.json", "b.json", "out.png")
        assert "--outside" not in args and args[-2:] == ["--within", within]
        assert main(args[1:]) == 0
        assert seen[-1][3] == opts


# --- a save or an export checks everything before it writes anything ---------------------------------------


def _contents(directory) -> dict:
    """Every file in ``directory`` (following links) with its bytes, and its size and modification time."""
    return {p.name: p.read_bytes() for p in sorted(pathlib.Path(directory).iterdir()) if p.is_file()}, snapshot_dir(str(directory))


BAD_SAVES = [
    # (what, the document's changes): each alone is refused, with the last save's files in place
    ("gif output", {"output_name": "nope.gif"}),
    ("output with a directory", {"output_name": "../out.png"}),
    ("hidden output", {"output_name": ".out.png"}),
    ("output not a name", {"output_name": 5}),
    ("output too long", {"output_name": "x" * 300 + ".png"}),
    ("output over the image", {"output_name": "picture.png"}),  # export only: a save writes no output
    ("txt source", {"src_name": "a.txt"}),
    ("target with a directory", {"dst_name": "sub/b.json"}),
    ("one file for both", {"src_name": "same.json", "dst_name": "same.json"}),
    ("unknown method", {"options": {"method": "nope"}}),
    ("unknown option", {"options": {"colour": "red"}}),
    ("bad margin", {"options": {"within": "0"}}),
    ("bad target", {"dst": [[0, "a"]] * 4}),
    ("too few vertices", {"dst": SQUARE[:3]}),
]


#: (route, what, change): every bad save for both routes, but an output over the image for an
#: export only (a save writes no output, so that name is no harm to it).
_BAD_CALLS = [(path, what, change) for path in ("/api/save", "/api/export") for what, change in BAD_SAVES
              if not (what == "output over the image" and path == "/api/save")]  # fmt: skip


@pytest.mark.parametrize("path, what, change", _BAD_CALLS, ids=[f"{p[5:]}-{w}" for p, w, _ in _BAD_CALLS])
def test_a_bad_name_or_value_writes_nothing(server, tmp_path, path, what, change):
    """Every name and value is checked first: a save or an export refused for any of them leaves every file as it was
    (the output's name was checked after the polygons were written)."""
    assert json.loads(json_post(server, "/api/save", {"src": SQUARE, "dst": MOVED})[1])["ok"]
    (tmp_path / "sub").mkdir()
    before = _contents(tmp_path)
    status, body = json_post(server, path, dict({"src": MOVED, "dst": SQUARE}, **change))
    result = json.loads(body)
    assert status == 200 and not result["ok"] and result["error"] and "\n" not in result["error"]
    assert _contents(tmp_path) == before


def test_a_failed_write_replaces_neither_polygon_file(server, tmp_path, monkeypatch):
    """The two files are renamed into place together: the second failing (a full disk) leaves the first as it was."""
    from warpcli.edit import session as session_module
    from warpcli.errors import ImageIOError

    assert json.loads(json_post(server, "/api/save", {"src": SQUARE, "dst": MOVED})[1])["ok"]
    before = _contents(tmp_path)
    real = session_module.write_checked

    def full_disk(path, data, shown=None):
        if str(shown).endswith("dst.json"):
            raise ImageIOError(f"{shown}: cannot write: No space left on device")
        real(path, data, shown)

    monkeypatch.setattr(session_module, "write_checked", full_disk)
    result = json.loads(json_post(server, "/api/save", {"src": MOVED, "dst": SQUARE})[1])
    assert not result["ok"] and "No space left" in result["error"]
    assert _contents(tmp_path) == before


# --- a save never replaces an input of the session -------------------------------------------------------


def _protected_session(tmp_path, src="a.json"):
    """A session with every kind of input: the image, --within FILE, --theta FILE, and two polygon files it read."""
    image = tmp_path / "picture.png"
    write_smooth_image(str(image), 64, 48)
    (tmp_path / "outline.json").write_text(json.dumps([[2, 2], [62, 2], [62, 46], [2, 46]]))
    (tmp_path / "theta.json").write_text(json.dumps(regular(4).tolist()))
    (tmp_path / "a.json").write_text(json.dumps(SQUARE))
    (tmp_path / "b.json").write_text(json.dumps(MOVED))
    options = WarpOptions(map=MapOptions(theta=str(tmp_path / "theta.json")), within=str(tmp_path / "outline.json"))
    return EditSession(EditPaths.defaults(str(image), src=str(tmp_path / src), dst=str(tmp_path / "b.json")), options)


PROTECTED = [
    (target, how, side)
    for target in ("picture.png", "outline.json", "theta.json")
    for how in ("name", "symlink", "hardlink")
    for side in ("src_name", "dst_name")
    if not (target == "picture.png" and how == "name")  # a .json name cannot be the image's own
] + [("b.json", "name", "src_name"), ("a.json", "name", "dst_name"), ("b.json", "symlink", "src_name"),
     ("a.json", "hardlink", "dst_name")]  # fmt: skip


@pytest.mark.parametrize("target, how, side", PROTECTED, ids=["-".join(p) for p in PROTECTED])
def test_save_never_replaces_an_input_of_the_session(tmp_path, target, how, side):
    """Not the image, the --within file, the --theta file, nor the other polygon's file as the session read it, by name
    or through a symbolic or hard link: refused, and nothing written (a save replaced the --within file)."""
    session = _protected_session(tmp_path)
    name = target
    if how != "name":
        name = f"{how}-{target.split('.')[0]}.json"
        (os.symlink if how == "symlink" else os.link)(tmp_path / target, tmp_path / name)
    other = {"src_name": "dst_name", "dst_name": "src_name"}[side]
    before = _contents(tmp_path)
    for call in (session.save, session.export):
        with pytest.raises(WarpError) as err:
            call({"src": SQUARE, "dst": MOVED, side: name, other: "new.json"})
        assert "overwrite" in str(err.value) and "\n" not in str(err.value)
        assert _contents(tmp_path) == before


def test_save_replaces_its_own_files_and_new_ones(tmp_path):
    session = _protected_session(tmp_path)
    assert session.save({"src": MOVED, "dst": SQUARE})["saved"] == [str(tmp_path / "a.json"), str(tmp_path / "b.json")]
    assert session.save({"src": MOVED, "dst": SQUARE, "src_name": "c.json", "dst_name": "d.json"})["saved"][1].endswith("d.json")


def test_a_polygon_file_that_is_an_input_is_not_saved_over(tmp_path):
    """``warp edit IMG --src outline.json --within outline.json``: even the command line's polygon path is refused."""
    session = _protected_session(tmp_path, src="outline.json")
    before = _contents(tmp_path)
    with pytest.raises(WarpError, match="overwrite the input"):
        session.save({"src": SQUARE, "dst": MOVED})
    assert _contents(tmp_path) == before


def test_save_over_the_within_file_is_refused_through_the_server(tmp_path):
    session = _protected_session(tmp_path)
    before = _contents(tmp_path)
    server = EditServer(session)
    server.start()
    try:
        for side in ("src_name", "dst_name"):
            status, body = json_post(server, "/api/save", {"src": SQUARE, "dst": MOVED, side: "outline.json"})
            result = json.loads(body)
            assert status == 200 and not result["ok"] and "overwrite the input" in result["error"]
    finally:
        server.shutdown()
    assert _contents(tmp_path) == before


# --- an unexpected error is a 500 with a JSON error, one line on stderr, and the server goes on ---------------


class _Exploding:
    """A session whose every attribute raises ``error``."""

    def __init__(self, error: BaseException) -> None:
        self.error = error

    def __getattr__(self, name):
        raise self.error


ROUTES = [("GET", "/"), ("GET", "/static/editor.js"), ("GET", "/static/editor.css"), ("GET", "/image.png"),
          ("GET", "/api/state"), ("HEAD", "/api/state"), ("POST", "/api/preview"), ("POST", "/api/load"),
          ("POST", "/api/save"), ("POST", "/api/export")]  # fmt: skip
ERRORS = [MemoryError(), RuntimeError("a bug\non two lines"), KeyError("x"), RecursionError("deep")]


@pytest.fixture()
def warpcli_log():
    """The records of the ``warpcli`` logger (whatever an earlier test's CLI run made of its handlers)."""
    import logging

    records: list[logging.LogRecord] = []

    class Keep(logging.Handler):
        def emit(self, record):
            records.append(record)

    logger = logging.getLogger("warpcli")
    handler, level = Keep(logging.DEBUG), logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.DEBUG)
    yield records
    logger.removeHandler(handler)
    logger.setLevel(level)


@pytest.mark.parametrize("error", ERRORS, ids=[type(e).__name__ for e in ERRORS])
@pytest.mark.parametrize("method, path", ROUTES, ids=[f"{m} {p}" for m, p in ROUTES])
def test_an_unexpected_error_is_answered_500_and_the_server_goes_on(server, monkeypatch, warpcli_log, method, path, error):
    import logging

    session = server.session

    def boom(*args):
        raise error

    monkeypatch.setattr(server, "asset", boom)
    server.session = _Exploding(error)
    if method == "POST":
        status, body = json_post(server, path, {"src": SQUARE, "dst": MOVED, "name": "a.json", "text": "[]"})
    else:
        status, body = request(server, method, f"{path}?token={server.token}")
    assert status == 500
    if method != "HEAD":
        message = json.loads(body)["error"]
        assert message.startswith("internal error (") and type(error).__name__ in message and "\n" not in message
    errors = [r for r in warpcli_log if r.levelno >= logging.ERROR]
    assert len(errors) == 1 and errors[0].exc_info is None
    line = errors[0].getMessage()
    assert "\n" not in line and type(error).__name__ in line and server.token not in line
    # The server goes on serving, the session's lock free again.
    server.session = session
    monkeypatch.undo()
    assert request(server, "GET", f"/api/state?token={server.token}")[0] == 200
    status, body = json_post(server, "/api/preview", {"src": SQUARE, "dst": MOVED})
    assert status == 200 and _decoded(body)[0]["ok"]


# --- connections: timed out, bounded, and no busy loop out of file descriptors -------------------------------


def _closed_within(sock, seconds: float) -> bool:
    """Whether the server closes ``sock`` within ``seconds`` (whatever it answered first)."""
    import time

    end = time.monotonic() + seconds
    try:
        while time.monotonic() < end:
            sock.settimeout(max(0.01, end - time.monotonic()))
            if not sock.recv(65536):
                return True
    except (ConnectionError, TimeoutError):
        return isinstance(sys.exc_info()[1], ConnectionError)
    return False


SLOW_REQUESTS = ["nothing", "half a request line", "headers never ended", "a byte at a time", "half a body",
                 "idle after a request"]  # fmt: skip


@pytest.mark.parametrize("how", SLOW_REQUESTS)
def test_a_request_that_does_not_arrive_in_time_is_closed(server, monkeypatch, how):
    """Each connection has REQUEST_TIMEOUT seconds for its request to arrive whole, however it trickles in (a thread
    was held for ever by a connection that sent nothing); the server goes on serving."""
    import time

    from warpcli.edit import server as server_module

    monkeypatch.setattr(server_module, "REQUEST_TIMEOUT", 0.5)
    head = (f"POST /api/save HTTP/1.1\r\nHost: 127.0.0.1:{server.port}\r\nX-Warp-Token: {server.token}\r\n"
            "Content-Type: application/json\r\nContent-Length: 100\r\n\r\n").encode()  # fmt: skip
    t0 = time.monotonic()
    with socket.create_connection(("127.0.0.1", server.port), timeout=10) as sock:
        if how == "half a request line":
            sock.sendall(b"GET /api/st")
        elif how == "headers never ended":
            sock.sendall(head[:60])
        elif how == "half a body":
            sock.sendall(head + b'{"src": ')
        elif how == "idle after a request":
            sock.sendall(f"GET /api/state?token={server.token} HTTP/1.1\r\nHost: 127.0.0.1:{server.port}\r\n\r\n".encode())
        elif how == "a byte at a time":
            try:
                for byte in head:  # 4 bytes a second: 40 s for the headers
                    sock.sendall(bytes([byte]))
                    time.sleep(0.25)
                    if time.monotonic() - t0 > 3:
                        break
            except OSError:  # closed meanwhile
                pass
        assert _closed_within(sock, 5)
    assert time.monotonic() - t0 < 4
    assert request(server, "GET", f"/api/state?token={server.token}")[0] == 200


def _state_answered(server) -> bool:
    try:
        return request(server, "GET", f"/api/state?token={server.token}")[0] == 200
    except (ConnectionError, http.client.HTTPException):
        return False


def test_connections_beyond_the_limit_make_room_or_are_closed(tmp_path, monkeypatch):
    """At most MAX_CONNECTIONS threads: beyond them the connection idle longest is closed to make room for the new one
    (idle connections cannot lock the page out), and with every thread in a call the new connection is closed at once."""
    import time

    from warpcli.edit import server as server_module

    monkeypatch.setattr(server_module, "MAX_CONNECTIONS", 3)
    image = str(tmp_path / "picture.png")
    write_smooth_image(image, 16, 12)
    with served(image) as server:
        assert server.httpd.request_queue_size >= 64  # was 5: a burst of the page's requests was refused
        idle = []
        for _ in range(3):  # REQUEST_TIMEOUT is 30 s: any close here is for the limit
            idle.append(socket.create_connection(("127.0.0.1", server.port), timeout=10))
            time.sleep(0.05)  # oldest first
        assert _state_answered(server)  # at once
        assert _closed_within(idle[0], 3)  # the oldest idle one made room
        assert not _closed_within(idle[1], 0.3) and not _closed_within(idle[2], 0.3)
        for sock in idle:
            sock.close()
        # Every thread in a call (saves waiting for the session): nothing to make room with.
        server.calls.acquire()
        savers = [threading.Thread(target=json_post, args=(server, "/api/save", {"src": SQUARE, "dst": MOVED}))
                  for _ in range(3)]  # fmt: skip
        for t in savers:
            t.start()
        time.sleep(0.5)
        with socket.create_connection(("127.0.0.1", server.port), timeout=10) as extra:
            t0 = time.monotonic()
            assert _closed_within(extra, 5) and time.monotonic() - t0 < 3
        server.calls.release()
        for t in savers:
            t.join(30)
        assert _state_answered(server)


def test_out_of_file_descriptors_pauses_accepting_instead_of_spinning(tmp_path, monkeypatch, warpcli_log):
    """accept() failing with EMFILE leaves the connection queued: the loop pauses ACCEPT_BACKOFF between tries (it
    tried thousands of times a second), warns once, and serves the connection once descriptors are free."""
    import errno
    import time

    from warpcli.edit.server import ACCEPT_BACKOFF

    image = str(tmp_path / "picture.png")
    write_smooth_image(image, 16, 12)
    tries = []
    real_accept = socket.socket.accept

    def out_of_files(self):
        tries.append(time.monotonic())
        raise OSError(errno.EMFILE, "Too many open files")

    with served(image) as server:
        monkeypatch.setattr(socket.socket, "accept", out_of_files)
        with socket.create_connection(("127.0.0.1", server.port), timeout=10) as sock:
            time.sleep(1.0)
            assert 2 <= len(tries) <= 1.0 / ACCEPT_BACKOFF + 3
            monkeypatch.setattr(socket.socket, "accept", real_accept)
            sock.sendall(f"GET /api/state?token={server.token} HTTP/1.1\r\nHost: 127.0.0.1:{server.port}\r\n\r\n".encode())
            assert sock.recv(64).startswith(b"HTTP/1.1 200")
    warnings = [r.getMessage() for r in warpcli_log if "file descriptors" in r.getMessage()]
    assert len(warnings) == 1


# --- one preview at a time: another is refused at once, its body unparsed; a save waits its turn ----------------


def test_a_preview_while_another_runs_is_answered_busy_at_once(server, tmp_path, monkeypatch):
    """Bodies were parsed (24 times their size) while waiting behind a long preview, and a small preview waited 20 s."""
    import time

    started, release = threading.Event(), threading.Event()
    real = server.session.preview_map

    def long_preview(doc):
        started.set()
        assert release.wait(30)
        return real(doc)

    monkeypatch.setattr(server.session, "preview_map", long_preview)
    results = {}

    def post(key, path, doc):
        results[key] = json_post(server, path, doc)

    holder = threading.Thread(target=post, args=("holder", "/api/preview", {"src": SQUARE, "dst": MOVED}))
    holder.start()
    assert started.wait(30)
    parsed = []
    real_loads = json.loads
    monkeypatch.setattr(json, "loads", lambda text, *a, **k: (parsed.append(len(text)), real_loads(text, *a, **k))[1])
    big = {"x": [{}] * ((MAX_BODY - 200) // 4), "src": SQUARE, "dst": MOVED}
    assert MAX_BODY // 2 < len(json.dumps(big)) <= MAX_BODY
    t0 = time.monotonic()
    flood = [threading.Thread(target=post, args=(i, "/api/preview", big)) for i in range(12)]
    for t in flood:
        t.start()
    for t in flood:
        t.join(30)
    assert time.monotonic() - t0 < 10
    for i in range(12):
        status, body = results[i]
        assert status == 503 and json.loads(body)["error"].startswith("busy")
    assert not [n for n in parsed if n > 1000]  # none of the big bodies was parsed
    saver = threading.Thread(target=post, args=("save", "/api/save", {"src": SQUARE, "dst": MOVED}))
    saver.start()
    saver.join(0.3)
    assert saver.is_alive()  # a save waits for the preview
    release.set()
    holder.join(30)
    saver.join(30)
    assert results["holder"][0] == 200 and _decoded(results["holder"][1])[0]["ok"]
    assert results["save"][0] == 200 and json.loads(results["save"][1])["ok"]
    status, body = json_post(server, "/api/preview", {"src": SQUARE, "dst": MOVED})
    assert status == 200 and _decoded(body)[0]["ok"]


def test_the_page_asks_again_when_the_server_is_busy():
    """The page's preview loop: a 503 keeps the state wanted and asks again after BUSY_RETRY_MS (and stays not idle)."""
    from importlib import resources

    js = resources.files("warpcli.edit").joinpath("static", "editor.js").read_text()
    assert "err.status === 503" in js and "setTimeout(next, BUSY_RETRY_MS)" in js


# --- the browser is opened on a private file, never with the token on its command line ----------------------


@pytest.mark.parametrize("stop", ["ctrl-c", "returns"])
def test_the_browser_opens_a_private_redirect_file(tmp_path, monkeypatch, stop):
    import stat
    import webbrowser

    from warpcli import edit

    image = str(tmp_path / "picture.png")
    write_smooth_image(image, 16, 12)
    seen = {}

    def fake_open(url, *args, **kwargs):
        seen["url"] = url
        path = url.removeprefix("file://")
        seen["path"] = path
        seen["file_mode"] = stat.S_IMODE(os.stat(path).st_mode)
        seen["dir_mode"] = stat.S_IMODE(os.stat(os.path.dirname(path)).st_mode)
        with open(path, encoding="utf-8") as fh:
            seen["text"] = fh.read()
        return True

    def serve_forever(self):
        seen["token"], seen["address"] = self.token, self.url
        if stop == "ctrl-c":
            raise KeyboardInterrupt

    monkeypatch.setattr(webbrowser, "open", fake_open)
    monkeypatch.setattr(edit.EditServer, "serve_forever", serve_forever)
    announced = []
    if stop == "ctrl-c":
        with pytest.raises(KeyboardInterrupt):
            edit.serve(image, announce=announced.append)
    else:
        edit.serve(image, announce=announced.append)
    assert announced == [seen["address"]]  # the user's terminal still gets the address
    assert seen["url"].startswith("file:///") and seen["token"] not in seen["url"]
    assert seen["file_mode"] == 0o600 and seen["dir_mode"] == 0o700
    assert f'content="0;url={seen["address"]}"' in seen["text"] and f'href="{seen["address"]}"' in seen["text"]
    assert not os.path.exists(os.path.dirname(seen["path"]))  # removed when the server stopped


def test_the_redirect_file_opens_the_page(server):
    """The browser's navigation from the redirect file (a file: page) is cross-site: the page itself is let through
    (a top-level navigation to / with the token, as Chromium sends it), nothing else."""
    headers = {"Sec-Fetch-Site": "cross-site", "Sec-Fetch-Mode": "navigate", "Sec-Fetch-Dest": "document",
               "Upgrade-Insecure-Requests": "1"}  # fmt: skip
    status, body = request(server, "GET", f"/?token={server.token}", headers=headers)
    assert status == 200 and b"editor.js?token=" in body


@pytest.mark.parametrize(("signame", "code", "said"), [("SIGTERM", 143, "terminated"), ("SIGHUP", 129, "hung up")])
def test_sigterm_removes_the_redirect_file(tmp_path, signame, code, said):
    # A SIGTERM ends `warp edit` at once (no unwinding, warpcli.cli.run): the private page with the
    # token stayed in the temporary directory. $BROWSER=true stands in for the browser.
    import signal
    import subprocess
    import sys
    import time

    image = str(tmp_path / "picture.png")
    write_smooth_image(image, 16, 12)
    temp = tmp_path / "tmp"
    temp.mkdir()
    env = {**os.environ, "TMPDIR": str(temp), "BROWSER": "true"}
    proc = subprocess.Popen([sys.executable, "-m", "warpcli", "edit", image], env=env, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while not list(temp.glob("warp-edit-*/open.html")) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert list(temp.glob("warp-edit-*/open.html")), "the page was never written"
        proc.send_signal(getattr(signal, signame))
        _, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == code and said in err, err
    assert not list(temp.glob("warp-edit-*")), "the redirect page was left behind"


@pytest.mark.parametrize("method", ["TRACE", "CONNECT", "BREW"])
def test_methods_the_server_has_no_use_for_get_json_with_the_security_headers(server, method):
    # TRACE had the standard library's 501 HTML page, without the security headers.
    from warpcli.edit.server import SECURITY_HEADERS

    conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=30)
    conn.putrequest(method, "/", skip_host=True, skip_accept_encoding=True)
    conn.putheader("Host", f"127.0.0.1:{server.port}")
    conn.endheaders()
    response = conn.getresponse()
    body = response.read()
    conn.close()
    assert response.status in (405, 501)
    assert response.getheader("Content-Type") == "application/json" and "error" in json.loads(body)
    for key, value in SECURITY_HEADERS.items():
        assert response.getheader(key) == value, key


# --- the polygon files the page starts from, and what a save keeps of them --------------------------------


def test_a_target_file_the_page_cannot_show_is_refused_at_start(tmp_path):
    # It used to be ignored (no source file: the page started empty) or replaced by a copy of the
    # source (another vertex count), and a save then overwrote it unseen.
    image = str(tmp_path / "picture.png")
    write_smooth_image(image, 64, 48)
    dst = tmp_path / "picture.dst.json"
    dst.write_text(json.dumps(SQUARE))
    with pytest.raises(WarpError, match="exists, but .*picture.src.json does not"):
        EditSession(EditPaths.defaults(image))
    (tmp_path / "picture.src.json").write_text(json.dumps([[8, 8], [56, 8], [56, 40], [32, 46], [8, 40]]))
    with pytest.raises(WarpError, match="has 4 vertices, but .* has 5"):
        EditSession(EditPaths.defaults(image))
    assert json.loads(dst.read_text()) == SQUARE
    (tmp_path / "picture.src.json").write_text(json.dumps(MOVED))
    assert EditSession(EditPaths.defaults(image)).state()["dst"] == SQUARE


def test_a_save_keeps_everything_a_labelme_or_geojson_file_held(tmp_path):
    image = str(tmp_path / "picture.png")
    write_smooth_image(image, 64, 48)
    labelme = {
        "version": "5.2.1", "imagePath": "picture.png", "flags": {"x": True},
        "shapes": [
            {"label": "box", "shape_type": "rectangle", "points": [[1, 1], [5, 5]]},
            {"label": "face", "shape_type": "polygon", "points": SQUARE, "group_id": 3},
            {"label": "eye", "shape_type": "point", "points": [[9, 9]]},
        ],
    }  # fmt: skip
    geojson = {"type": "Feature", "properties": {"name": "face", "id": 7},
               "geometry": {"type": "Polygon", "coordinates": [SQUARE + [SQUARE[0]]]}}  # fmt: skip
    (tmp_path / "a.json").write_text(json.dumps(labelme))
    (tmp_path / "b.json").write_text(json.dumps(geojson))
    session = EditSession(EditPaths.defaults(image, src=str(tmp_path / "a.json"), dst=str(tmp_path / "b.json")))
    session.save({"src": MOVED, "dst": MOVED})
    a = json.loads((tmp_path / "a.json").read_text())
    b = json.loads((tmp_path / "b.json").read_text())
    want = dict(labelme, shapes=[labelme["shapes"][0], dict(labelme["shapes"][1], points=MOVED), labelme["shapes"][2]])
    assert a == json.loads(json.dumps(want))
    assert b == dict(geojson, geometry={"type": "Polygon", "coordinates": [MOVED + [MOVED[0]]]})
    from warpcli.polygon.formats import read_polygon

    assert read_polygon(tmp_path / "a.json").points.tolist() == MOVED
    # A file there that holds no one polygon is not replaced.
    (tmp_path / "notes.json").write_text('{"todo": "keep me"}')
    with pytest.raises(WarpError, match="holds no one polygon a save can update"):
        session.save({"src": MOVED, "dst": MOVED, "dst_name": "notes.json"})
    assert json.loads((tmp_path / "notes.json").read_text()) == {"todo": "keep me"}


def test_ctrl_c_during_an_export_leaves_no_pending_file(tmp_path, monkeypatch):
    # Ctrl-C stops the server while a request's thread still writes an export: the thread dies
    # with the process, and its pending files stayed beside the image. serve() removes every
    # file warpcli.outputs tracks when it stops.
    from warpcli import edit
    from warpcli.outputs import PendingOutputs

    image = str(tmp_path / "picture.png")
    write_smooth_image(image, 16, 12)
    seen = {}

    def serve_forever(self):
        pending = PendingOutputs().__enter__()  # an export in the middle of its writes
        path = pending.path(str(tmp_path / "picture.warped.png"))
        with open(path, "wb") as fh:
            fh.write(b"half an image")
        seen["path"] = path
        raise KeyboardInterrupt

    monkeypatch.setattr(edit.EditServer, "serve_forever", serve_forever)
    with pytest.raises(KeyboardInterrupt):
        edit.serve(image, browser=False)
    assert os.path.basename(seen["path"]).startswith(".") and not os.path.exists(seen["path"])
    assert sorted(os.listdir(tmp_path)) == ["picture.png"]
