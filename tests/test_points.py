"""Tests of warpcli.points and `warp points`: points and OBJ UV layouts through the map (§4.2)."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from helpers import l_shape, regular, run_cli, write_polygon
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


# --- the image warp's map: every map option, and retouches within an outline -------------------


def _ramp(width, height):
    """An image whose pixel holds its own centre (x, y): bilinear sampling of it at s gives s exactly."""
    r, c = np.mgrid[0:height, 0:width]
    return np.stack([c + 0.5, r + 0.5], axis=2).astype(np.float64)


def _pulled_back(result, width, height, keep):
    """Output pixel centres p and the source points s the image warp sampled for them (read off the
    warped ramp, so through the resampler, not the map's own arrays), where ``keep`` and s lies
    where bilinear sampling is exact (half a pixel inside the image)."""
    s = result.pixels
    r, c = np.nonzero(keep & np.isfinite(s).all(axis=2))
    p = np.stack([c + 0.5, r + 0.5], axis=1)
    s = s[r, c]
    # Strictly inside: a point beyond the outer pixel centres reads as the clamped edge value.
    ok = (s[:, 0] > 0.501) & (s[:, 0] < width - 0.501) & (s[:, 1] > 0.501) & (s[:, 1] < height - 0.501)
    return p[ok], s[ok]


def _points_cli(tmp, pts, a, b, *options):
    (tmp / "s.json").write_text(json.dumps(np.asarray(pts).tolist()))
    assert main(["points", "--src", a, "--dst", b, *options, "-q", str(tmp / "s.json"), str(tmp / "p.json")]) == 0
    return np.array(json.loads((tmp / "p.json").read_text()))


@pytest.mark.parametrize(
    "options", [dict(method="fem", theta="cyclic"), dict(method="mfs", theta="cyclic", nodes=96), dict(method="fem", dst_boundary="quadratic")]
)
def test_points_go_where_the_image_warp_with_the_same_options_puts_them(tmp_path, options):
    """`warp points` takes every map option of `warp`: a point s that the image warp sampled for the
    output pixel centre p maps onto p (before, points had --method only, so --theta or --boundary
    gave points another map than the image's)."""
    from warpcli.grid import inside_polygon, pixel_centres
    from warpcli.pipeline import warp_image

    w = h = 120
    src, dst = SRC * 0.9, regular(6, r=50.0, phase=0.3) + 5.0
    a, b = write_polygon(tmp_path / "a.json", src), write_polygon(tmp_path / "b.json", dst)
    result = warp_image(_ramp(w, h), src, dst, interp="linear", antialias=False, **options)
    inside = inside_polygon(pixel_centres(w, h), dst).reshape(h, w)
    p, s = _pulled_back(result, w, h, inside)
    assert len(p) > 2000
    flags = [x for k, v in options.items() for x in ("--" + k.replace("_", "-"), str(v))]
    moved = _points_cli(tmp_path, s, a, b, *flags)
    assert np.abs(moved - p).max() <= 2e-5
    # A different Theta is a different map: the option really reaches the points.
    other = _points_cli(tmp_path, s, a, b, "--method", options["method"])
    assert np.abs(other - p).max() > 0.05


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture], phases=[Phase.explicit, Phase.generate])
@given(seed=st.integers(0, 10**6), within=st.sampled_from(["image", "6", "9.5"]), move=st.floats(0.05, 0.3))
def test_points_within_an_outline_follow_the_retouch_and_stay_outside_it(tmp_path, seed, within, move):
    """`warp points --within` maps points by the retouch's map: inside the outline onto where the
    image warp puts them, outside it (and anywhere off the image) exactly where they were."""
    from warpcli.errors import PolygonError
    from warpcli.grid import inside_polygon, pixel_centres
    from warpcli.pipeline import warp_image

    rng = np.random.default_rng(seed)
    w = h = 64
    angles = np.linspace(0, 2 * np.pi, 6, endpoint=False) + rng.uniform(0, 0.5, 6)
    radius = 13.0 * rng.uniform(0.6, 1.0, 6)
    src = np.stack([32 + radius * np.cos(angles), 32 + radius * np.sin(angles)], axis=1)
    dst = src + rng.uniform(-move, move, src.shape) * 13.0
    try:
        result = warp_image(_ramp(w, h), src, dst, within=within, interp="linear", antialias=False, method="fem", max_area=24.0)
    except PolygonError:
        return  # no fold-free cut of the ring for this cage: refused alike by both commands
    a, b = write_polygon(tmp_path / "a.json", src), write_polygon(tmp_path / "b.json", dst)
    options = ("--within", within, "--image-size", f"{w}x{h}", "--max-area", "24")
    inside = inside_polygon(pixel_centres(w, h), result.within.outline).reshape(h, w)
    p, s = _pulled_back(result, w, h, inside)
    assert np.abs(_points_cli(tmp_path, s, a, b, *options) - p).max() <= 2e-5
    assert np.abs(_points_cli(tmp_path, p, a, b, *options, "--inverse") - s).max() <= 2e-5
    # Outside the outline, and off the image: the identity (no warning needed, nothing lost).
    far = rng.uniform(-20, w + 20, (200, 2)).round(3)
    out = ~inside_polygon(far, result.within.outline)
    assert out.any()
    assert np.array_equal(_points_cli(tmp_path, far[out], a, b, *options), far[out])


def test_points_within_need_the_image_size(tmp_path, polys):
    (tmp_path / "p.json").write_text("[[20, 20]]")
    a, b = polys
    code, err = run_cli(["points", "--src", a, "--dst", b, "--within", "image", str(tmp_path / "p.json"), str(tmp_path / "q.json")])
    assert code == 2 and "--image-size" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "q.json").exists()
