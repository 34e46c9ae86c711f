"""Tests of warpcli.points and `warp points`: points and OBJ UV layouts through the map (§4.2)."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from helpers import l_shape, regular, write_polygon
from warpcli import BijectiveMap, MapOptions, Polygon
from warpcli.cli import main

SRC = l_shape()
DST = regular(6, r=55.0, phase=0.3)


@pytest.fixture
def polys(tmp_path):
    return write_polygon(tmp_path / "a.json", SRC), write_polygon(tmp_path / "b.json", DST)


@pytest.mark.parametrize("method", ["fem", "mfs"])
def test_json_points_round_trip(tmp_path, polys, method):
    pts = [[20.0, 20.0], [30.0, 100.0], [100.0, 100.0], [40.5, 60.25]]
    (tmp_path / "p.json").write_text(json.dumps(pts))
    a, b = polys
    assert main(["points", "--src", a, "--dst", b, "--method", method, str(tmp_path / "p.json"), str(tmp_path / "q.json")]) == 0
    moved = json.loads((tmp_path / "q.json").read_text())
    f = BijectiveMap.between(Polygon(SRC), Polygon(DST), MapOptions(method=method))
    np.testing.assert_allclose(moved, f.forward(pts), atol=1e-12)
    assert main(["points", "--src", a, "--dst", b, "--method", method, "--inverse", str(tmp_path / "q.json"), str(tmp_path / "r.json")]) == 0
    np.testing.assert_allclose(json.loads((tmp_path / "r.json").read_text()), pts, atol=1e-7)


def test_csv_keeps_its_header(tmp_path, polys):
    (tmp_path / "p.csv").write_text("x,y\n20,20\n30,100\n")
    a, b = polys
    assert main(["points", "--src", a, "--dst", b, str(tmp_path / "p.csv"), str(tmp_path / "q.csv")]) == 0
    lines = (tmp_path / "q.csv").read_text().splitlines()
    assert lines[0] == "x,y" and len(lines) == 3


def test_obj_uvs_move_and_every_other_line_stays_byte_for_byte(tmp_path, polys):
    """A 128 px texture: vt (u, v) is pixel (128 u, 128 (1 - v))."""
    obj = (
        b"# a quad\r\nmtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\n"
        b"vt 0.25 0.75\nvt   0.5 0.5 0.0\nvt 0.9 0.9\nf 1/1 2/2 3/3\n"
    )
    (tmp_path / "m.obj").write_bytes(obj)
    a, b = polys
    assert main(["points", "--src", a, "--dst", b, "--texture-size", "128x128", str(tmp_path / "m.obj"), str(tmp_path / "n.obj")]) == 0
    out = (tmp_path / "n.obj").read_bytes().splitlines(keepends=True)
    src_lines = obj.splitlines(keepends=True)
    for old, new in zip(src_lines, out):
        if not old.startswith(b"vt"):
            assert old == new
    assert len(out) == len(src_lines)
    f = BijectiveMap.between(Polygon(SRC), Polygon(DST))
    u, v = (float(x) for x in out[5].split()[1:3])
    np.testing.assert_allclose([u * 128, (1 - v) * 128], f.forward([[32.0, 32.0]])[0], atol=1e-6)
    assert out[6].startswith(b"vt   ") and out[6].rstrip().endswith(b" 0.0")  # spacing and w kept
    # (0.9, 0.9) is pixel (115.2, 12.8): outside the L (its notch), left as it is.
    assert out[7] == src_lines[7]


def test_points_outside_warn_or_fail(tmp_path, polys, capsys):
    (tmp_path / "p.json").write_text(json.dumps([[20.0, 20.0], [115.0, 12.0]]))
    a, b = polys
    assert main(["points", "--src", a, "--dst", b, str(tmp_path / "p.json"), str(tmp_path / "q.json")]) == 0
    assert "1 point(s) lie outside" in capsys.readouterr().err
    assert json.loads((tmp_path / "q.json").read_text())[1] == [115.0, 12.0]
    assert main(["points", "--src", a, "--dst", b, "--outside", "error", str(tmp_path / "p.json"), str(tmp_path / "r.json")]) == 2
    assert not os.path.exists(tmp_path / "r.json")


@pytest.mark.parametrize(
    "name, content, extra, match",
    [
        ("p.dat", "1,2", [], "must be a .json, .csv, .txt or .obj"),
        ("p.json", "[[1, 2], [3]]", [], "pairs"),
        ("p.csv", "1,2\nx,y\n", [], "must be numbers"),
        ("m.obj", "v 0 0 0\n", ["--texture-size", "64x64"], "no texture coordinates"),
        ("m.obj", "vt 0 0\n", [], "texture size"),
    ],
)
def test_bad_points_files_are_one_line(tmp_path, polys, capsys, name, content, extra, match):
    (tmp_path / name).write_text(content)
    a, b = polys
    out = tmp_path / ("out" + os.path.splitext(name)[1])
    assert main(["points", "--src", a, "--dst", b, *extra, str(tmp_path / name), str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and match in err
    assert not out.exists()


@pytest.mark.parametrize("digits", [310, 311, 401, 1000])
@pytest.mark.parametrize("where", ["points", "theta"])
@pytest.mark.parametrize("sign", ["", "-"])
def test_integers_beyond_floating_point_are_one_line_exit_2(tmp_path, digits, where, sign):
    # 10**309 and beyond overflow a float: numpy raised OverflowError (a traceback).
    from helpers import run_cli, write_png

    big = sign + "1" + "0" * (digits - 1)
    src = write_polygon(tmp_path / "s.json", regular(5, cx=8, cy=8, r=6))
    pts = tmp_path / "p.json"
    pts.write_text(f"[[1, 2], [{big}, 3]]" if where == "points" else "[[1, 2]]")
    theta = tmp_path / "t.json"
    theta.write_text(f"[[0, 0], [1, 0], [1, 1], [0, 1], [{big}, 0.5]]")
    if where == "points":
        code, err = run_cli(["points", pts, tmp_path / "o.json", "--src", src, "--dst", src])
        named = "p.json"
    else:
        img = write_png(tmp_path / "in.png", np.zeros((16, 16, 3), dtype=np.uint8))
        code, err = run_cli([img, tmp_path / "o.png", "--src", src, "--dst", src, "--theta", theta])
        named = "t.json"
    assert code == 2 and err.count("\n") == 1 and named in err and "floating-point range" in err, err


@pytest.mark.parametrize("size", ["3000000000x1", "1x3000000000", "2147483648x2", f"{10**400}x1", f"5x{2**63}"])
def test_sizes_beyond_openimageio_are_one_line_exit_2(tmp_path, size):
    from helpers import run_cli, write_png

    from warpcli.errors import InputError
    from warpcli.options import MAX_SIDE, check_size

    img = write_png(tmp_path / "in.png", np.zeros((16, 16, 3), dtype=np.uint8))
    src = write_polygon(tmp_path / "s.json", regular(5))
    code, err = run_cli([img, tmp_path / "o.png", "--src", src, "--dst", src, "--size", size])
    assert code == 2 and err.count("\n") == 1 and "--size" in err, err
    assert not any(p.name.startswith(".") for p in tmp_path.iterdir())
    w, h = (int(v) for v in size.split("x"))
    with pytest.raises(InputError, match="OpenImageIO"):
        check_size((w, h))
    assert check_size((MAX_SIDE, 1)) == (MAX_SIDE, 1)
