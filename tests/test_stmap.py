"""Maps as files: STMaps written by --save-map, read by apply-map and by OpenImageIO."""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest

from helpers import read_pixels, regular, star, write_png, write_polygon
from warpcli.cli import main
from warpcli.grid import pixel_centres
from warpcli.errors import ImageInputError
from warpcli.raster.stmap import check_stmap_path, load_stmap, save_stmap


@pytest.fixture
def scene(tmp_path):
    rng = np.random.default_rng(11)
    # A smooth image, so filters that differ only at the border agree inside.
    y, x = np.mgrid[0:96, 0:112] / 96.0
    px = np.stack([0.5 + 0.4 * np.sin(5 * x), 0.5 + 0.4 * np.cos(4 * y), 0.3 + 0.5 * x * y], axis=2)
    px = np.round(px * 255 + rng.normal(0, 0.2, px.shape)).clip(0, 255).astype(np.uint8)
    return {
        "dir": tmp_path,
        "pixels": px,
        "image": write_png(tmp_path / "in.png", px),
        "src": write_polygon(tmp_path / "src.json", star(6, 56, 48, 20, 44)),
        "dst": write_polygon(tmp_path / "dst.json", regular(12, 56, 48, 44, 0.2)),
    }


@pytest.mark.parametrize("t_up", [False, True])
def test_save_and_load_round_trip(tmp_path, t_up):
    pts = np.stack(np.meshgrid(np.linspace(0.5, 40.5, 7), np.linspace(1.0, 30.0, 5)), axis=-1)
    pts[1, 2] = np.nan
    save_stmap(tmp_path / "m.exr", pts, (41, 31), t_up=t_up)
    back = load_stmap(tmp_path / "m.exr", (41, 31))  # the header says which way t runs
    assert np.array_equal(np.isnan(back), np.isnan(pts))
    np.testing.assert_allclose(back[np.isfinite(pts)], pts[np.isfinite(pts)], rtol=1e-6)


def test_stmap_convention_pixel_centres(tmp_path):
    # The identity map of a 4x2 image: s = (i + 0.5) / 4, t = (j + 0.5) / 2, t down.
    save_stmap(tmp_path / "id.exr", pixel_centres(4, 2).reshape(2, 4, 2), (4, 2))
    px = read_pixels(tmp_path / "id.exr")
    np.testing.assert_allclose(px[..., 0], [[0.125, 0.375, 0.625, 0.875]] * 2)
    np.testing.assert_allclose(px[..., 1], [[0.25] * 4, [0.75] * 4])
    assert (px[..., 3] == 1).all()


def test_apply_map_reproduces_the_warp_byte_for_byte(scene):
    d = scene["dir"]
    # An STMap has no Jacobians: apply-map samples once per pixel, like warp --no-antialias.
    assert main([scene["image"], str(d / "out.png"), "--src", scene["src"], "--dst", scene["dst"], "--save-map", str(d / "map.exr"), "--no-antialias"]) == 0
    assert main(["apply-map", str(d / "map.exr"), scene["image"], str(d / "again.png")]) == 0
    a = read_pixels(d / "out.png").astype(int)
    b = read_pixels(d / "again.png").astype(int)
    # float32 storage of s, t moves a sample by at most ~1e-5 px: at most one level.
    assert np.abs(a - b).max() <= 1
    assert (np.abs(a - b) > 0).mean() < 0.01


def test_openimageio_st_warp_agrees_with_warpcli(scene):
    d = scene["dir"]
    args = [scene["image"], str(d / "out.png"), "--src", scene["src"], "--dst", scene["dst"]]
    assert main([*args, "--save-map", str(d / "map.exr"), "--no-antialias"]) == 0
    src_buf = oiio.ImageBuf(scene["image"])
    st_buf = oiio.ImageBuf(str(d / "map.exr"))
    res = oiio.ImageBufAlgo.st_warp(src_buf, st_buf, filtername="triangle")
    assert not res.has_error, res.geterror()
    theirs = np.round(res.get_pixels(oiio.FLOAT)[..., :3] * 255)
    ours = read_pixels(d / "out.png").astype(float)
    inv = load_stmap(d / "map.exr", (112, 96))
    x, y = inv[..., 0], inv[..., 1]
    # Compare where both sample the image's interior (at the border OpenImageIO
    # blends with black, warpcli extends the edge pixels).
    inner = np.isfinite(x) & (x > 1.5) & (x < 110.5) & (y > 1.5) & (y < 94.5)
    assert inner.sum() > 3000
    diff = np.abs(theirs[inner] - ours[inner])
    assert diff.max() <= 1.0
    outside = ~np.isfinite(x)
    assert (theirs[outside] == 0).all() and (ours[outside] == 0).all()


def test_forward_map_inverts_the_inverse_map(scene):
    d = scene["dir"]
    args = [scene["image"], str(d / "out.png"), "--src", scene["src"], "--dst", scene["dst"]]
    assert main([*args, "--save-map", str(d / "inv.exr"), "--save-forward-map", str(d / "fwd.exr")]) == 0
    inv = load_stmap(d / "inv.exr", (112, 96))  # output pixel -> input point
    fwd = load_stmap(d / "fwd.exr", (112, 96), kind="forward")  # input pixel -> output point
    # Following the inverse map from an output pixel, then the forward map from
    # the input pixel nearest to it, lands back within about a pixel.
    ok = np.isfinite(inv[..., 0])
    r, c = np.nonzero(ok)
    src_pt = inv[r, c]
    i = np.clip(np.floor(src_pt[:, 1]).astype(int), 0, 95)
    j = np.clip(np.floor(src_pt[:, 0]).astype(int), 0, 111)
    there = fwd[i, j]
    good = np.isfinite(there[:, 0])
    back = there[good]
    start = pixel_centres(112, 96).reshape(96, 112, 2)[r, c][good]
    assert np.median(np.hypot(*(back - start).T)) < 1.0


def test_nuke_orientation_is_flipped_t(scene):
    d = scene["dir"]
    args = [scene["image"], str(d / "o.png"), "--src", scene["src"], "--dst", scene["dst"], "--no-antialias"]
    assert main([*args, "--save-map", str(d / "down.exr")]) == 0
    assert main([*args[:1], str(d / "o2.png"), *args[2:], "--save-map", str(d / "up.exr"), "--stmap-t", "up"]) == 0
    down = read_pixels(d / "down.exr")
    up = read_pixels(d / "up.exr")
    inside = down[..., 3] > 0
    np.testing.assert_allclose(up[..., 1][inside], 1.0 - down[..., 1][inside], atol=1e-6)
    # apply-map reads the orientation from the header, or as told.
    assert main(["apply-map", str(d / "up.exr"), scene["image"], str(d / "a.png")]) == 0
    assert main(["apply-map", str(d / "up.exr"), scene["image"], str(d / "b.png"), "--stmap-t", "down"]) == 0
    assert np.abs(read_pixels(d / "a.png").astype(int) - read_pixels(d / "o.png").astype(int)).max() <= 1
    assert not np.array_equal(read_pixels(d / "b.png"), read_pixels(d / "o.png"))


def test_apply_map_bad_input(scene, capsys):
    d = scene["dir"]
    grey = write_png(d / "grey.png", np.zeros((8, 8), dtype=np.uint8))
    before = sorted(p.name for p in d.iterdir())
    assert main(["apply-map", str(d / "missing.exr"), scene["image"], str(d / "x.png")]) == 2
    assert main(["apply-map", grey, scene["image"], str(d / "x.png")]) == 2
    assert main(["apply-map", grey, scene["image"], scene["image"]]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3
    assert "missing.exr" in err[0] and "no such file" in err[0]
    assert "grey.png" in err[1] and "two channels" in err[1]
    assert "overwrite" in err[2]
    assert sorted(p.name for p in d.iterdir()) == before


def test_integer_stmaps_are_normalized(tmp_path):
    # A 16-bit STMap (s, t in 0..65535): the identity of a 2x1 image.
    px = np.array([[[16384, 32768, 0], [49151, 32768, 0]]], dtype=np.uint16)
    write_png(tmp_path / "m.png", px)
    back = load_stmap(tmp_path / "m.png", (2, 1))
    np.testing.assert_allclose(back, [[[0.5, 0.5], [1.5, 0.5]]], atol=1e-4)


def test_oiiotool_st_warp_agrees_with_warpcli(scene):
    import os
    import shutil
    import subprocess
    import sys

    oiiotool = shutil.which("oiiotool", path=os.path.dirname(sys.executable)) or shutil.which("oiiotool")
    if oiiotool is None:
        pytest.skip("oiiotool is not installed")
    d = scene["dir"]
    args = [scene["image"], str(d / "out.png"), "--src", scene["src"], "--dst", scene["dst"], "--no-antialias"]
    assert main([*args, "--save-map", str(d / "map.exr")]) == 0
    subprocess.run(
        [oiiotool, scene["image"], str(d / "map.exr"), "--st_warp:filter=triangle", "-d", "uint8", "-o", str(d / "oiio.png")],
        check=True,
    )
    theirs = read_pixels(d / "oiio.png")[..., :3].astype(int)
    ours = read_pixels(d / "out.png").astype(int)
    inv = load_stmap(d / "map.exr", (112, 96))
    x, y = inv[..., 0], inv[..., 1]
    inner = np.isfinite(x) & (x > 1.5) & (x < 110.5) & (y > 1.5) & (y < 94.5)
    assert np.abs(theirs[inner] - ours[inner]).max() <= 1


def grid_points(w, h):
    """The identity map of a w x h image, with one undefined pixel."""
    pts = pixel_centres(w, h).reshape(h, w, 2).copy()
    pts[1, 2] = np.nan
    return pts


@pytest.mark.parametrize("name", ["m.png", "m.jpg", "m.PNG", "m.bmp", "m.webp", "m"])
def test_stmaps_are_never_written_in_8_bits(tmp_path, name):
    # An 8-bit map would quantize s and t to 1/255 of the image: a blocky warp.
    with pytest.raises(ImageInputError) as info:
        save_stmap(tmp_path / name, grid_points(5, 4), (5, 4))
    assert str(info.value) == f"{tmp_path / name}: an STMap must be float OpenEXR (.exr) or TIFF (.tif, .tiff)"
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ImageInputError, match="must be float OpenEXR"):
        check_stmap_path(name)


@pytest.mark.parametrize("ext", ["exr", "tif", "tiff", "EXR", "TIF"])
@pytest.mark.parametrize("kind", ["inverse", "forward"])
@pytest.mark.parametrize("t_up", [False, True])
def test_float_stmaps_round_trip_with_their_header(tmp_path, ext, kind, t_up):
    # TIFF keeps no attribute of warpcli's: the header travels in the
    # ImageDescription, so the kind and the way t runs survive in both formats.
    pts = grid_points(7, 5) * 3.0
    path = tmp_path / f"m.{ext}"
    check_stmap_path(path)
    save_stmap(path, pts, (21, 15), kind=kind, t_up=t_up)
    assert read_pixels(path).dtype == np.float32
    back = load_stmap(path, (21, 15), kind=kind)  # the header says which way t runs
    assert np.array_equal(np.isnan(back), np.isnan(pts))
    np.testing.assert_allclose(back[np.isfinite(pts)], pts[np.isfinite(pts)], rtol=1e-6)


@pytest.mark.parametrize("ext", ["exr", "tif"])
def test_a_map_of_the_other_kind_is_refused(tmp_path, ext):
    save_stmap(tmp_path / f"fwd.{ext}", grid_points(4, 3), (4, 3), kind="forward")
    save_stmap(tmp_path / f"inv.{ext}", grid_points(4, 3), (4, 3), kind="inverse")
    with pytest.raises(ImageInputError) as forward:
        load_stmap(tmp_path / f"fwd.{ext}", (4, 3))  # apply-map's default: the inverse map
    with pytest.raises(ImageInputError) as inverse:
        load_stmap(tmp_path / f"inv.{ext}", (4, 3), kind="forward")
    msg = str(forward.value)
    assert msg.startswith(f"{tmp_path / f'fwd.{ext}'}: ") and "\n" not in msg
    assert "forward map" in msg and "inverse map" in msg and "--save-map" in msg
    assert "inverse map" in str(inverse.value) and "not a forward map" in str(inverse.value)
    # Asked for explicitly, each kind loads.
    assert np.isfinite(load_stmap(tmp_path / f"fwd.{ext}", (4, 3), kind="forward")).sum() == 22
    assert np.isfinite(load_stmap(tmp_path / f"inv.{ext}", (4, 3))).sum() == 22


def test_a_map_without_a_header_is_taken_as_asked(tmp_path):
    # A float STMap from elsewhere (Nuke, oiiotool) has no warpcli header.
    px = np.zeros((2, 2, 3), dtype=np.float32)
    px[..., 0], px[..., 1] = [[0.25, 0.75]] * 2, [[0.25] * 2, [0.75] * 2]
    spec = oiio.ImageSpec(2, 2, 3, "float")
    out = oiio.ImageOutput.create(str(tmp_path / "m.exr"))
    assert out.open(str(tmp_path / "m.exr"), spec) and out.write_image(px)
    out.close()
    for kind in ("inverse", "forward"):
        np.testing.assert_allclose(load_stmap(tmp_path / "m.exr", (2, 2), kind=kind), [[[0.5, 0.5], [1.5, 0.5]], [[0.5, 1.5], [1.5, 1.5]]])


def test_apply_map_refuses_a_forward_map(scene, capsys):
    d = scene["dir"]
    save_stmap(d / "fwd.exr", grid_points(112, 96), (112, 96), kind="forward")
    assert main(["apply-map", str(d / "fwd.exr"), scene["image"], str(d / "x.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"warp: error: {d / 'fwd.exr'}: this is a forward map")
    assert not (d / "x.png").exists()


def test_a_map_of_an_unknown_kind_is_refused(tmp_path):
    px = np.zeros((2, 2, 4), dtype=np.float32)
    spec = oiio.ImageSpec(2, 2, 4, "float")
    spec.attribute("warpcli:map", "sideways")
    out = oiio.ImageOutput.create(str(tmp_path / "m.exr"))
    assert out.open(str(tmp_path / "m.exr"), spec) and out.write_image(px)
    out.close()
    with pytest.raises(ImageInputError, match="unknown kind warpcli:map='sideways', not 'inverse'"):
        load_stmap(tmp_path / "m.exr", (2, 2))


def test_unknown_kinds_are_refused(tmp_path):
    with pytest.raises(ValueError, match="unknown map kind"):
        save_stmap(tmp_path / "m.exr", grid_points(4, 3), (4, 3), kind="backward")
    with pytest.raises(ValueError, match="unknown map kind"):
        load_stmap(tmp_path / "m.exr", (4, 3), kind="backward")
    assert list(tmp_path.iterdir()) == []


# -- an STMap whose warp does not fit in memory is refused from its header (issue 27) --


def _stmap_file(path, w, h, channels, fmt):
    s, t = np.meshgrid((np.arange(w) + 0.5) / w, (np.arange(h) + 0.5) / h)
    px = np.dstack([s, t] + [np.ones_like(s)] * (channels - 2)).astype(np.float32)
    out = oiio.ImageOutput.create(str(path))
    spec = oiio.ImageSpec(w, h, channels, fmt)
    spec.attribute("compression", "zip")
    assert out.open(str(path), spec) and out.write_image(px if fmt != "uint16" else (px * 65535).astype(np.uint16))
    out.close()
    return str(path)


@pytest.mark.parametrize("fmt", ["half", "float", "uint16"])
@pytest.mark.parametrize("channels", [2, 3, 4])
@pytest.mark.parametrize("size", [(64, 48), (300, 7)])
def test_an_stmap_beyond_the_memory_budget_is_refused_before_decoding(tmp_path, monkeypatch, fmt, channels, size):
    from helpers import run_cli
    from warpcli import pipeline

    w, h = size
    stmap = _stmap_file(tmp_path / "map.exr" if fmt != "uint16" else tmp_path / "map.tif", w, h, channels, fmt)
    img = write_png(tmp_path / "in.png", np.zeros((20, 30, 3), dtype=np.uint8))
    decoded = w * h * channels * {"half": 2, "float": 4, "uint16": 2}[fmt]
    # Just under what the map alone decodes to: refused, and nothing decoded.
    monkeypatch.setenv("WARPCLI_MAX_IMAGE_BYTES", str(decoded * 2))
    real = pipeline.read_image
    monkeypatch.setattr(pipeline, "read_image", lambda *a, **k: pytest.fail("decoded"))
    code, err = run_cli(["apply-map", stmap, img, tmp_path / "out.png"])
    assert code == 2 and err.count("\n") == 1 and "more than the" in err and "map." in err, err
    assert not (tmp_path / "out.png").exists()
    # With room for every copy it is applied (stretched: the map is not of the image's size).
    monkeypatch.setattr(pipeline, "read_image", real)
    monkeypatch.setenv("WARPCLI_MAX_IMAGE_BYTES", str(decoded * 64 + 10**6))
    code, err = run_cli(["apply-map", stmap, img, tmp_path / "out.png", "--map-scale", "stretch"])
    assert code == 0, err


# --- maps of a retouch (--outside input) and maps of another size ----------------------------


@pytest.mark.parametrize("antialias", [False, True])
def test_the_map_of_a_retouch_covers_the_whole_image_and_apply_map_reproduces_it(scene, antialias):
    from warpcli.composite import polygon_coverage

    d = scene["dir"]
    src = np.asarray(star(6, 56, 48, 14, 30))
    dst = src + [6.0, -3.0]
    s, t = write_polygon(d / "s.json", src), write_polygon(d / "t.json", dst)
    flags = [] if antialias else ["--no-antialias"]
    assert main([scene["image"], str(d / "out.png"), "--src", s, "--dst", t, "--outside", "input",
                 "--save-map", str(d / "map.exr"), *flags]) == 0  # fmt: skip
    points = load_stmap(d / "map.exr", (112, 96))
    assert np.isfinite(points).all()  # the whole image, no black frame
    cov = polygon_coverage(dst, 112, 96)
    centres = pixel_centres(112, 96).reshape(96, 112, 2)
    np.testing.assert_allclose(points[cov == 0], centres[cov == 0], atol=1e-4)  # identity outside the target
    assert main(["apply-map", str(d / "map.exr"), scene["image"], str(d / "again.png")]) == 0
    a = read_pixels(d / "out.png").astype(int)
    b = read_pixels(d / "again.png").astype(int)
    assert (a[cov == 0] == scene["pixels"][cov == 0]).all() and (b[cov == 0] == a[cov == 0]).all()  # exact
    inner = cov == 1 if antialias else np.ones(cov.shape, bool)
    # Within interpolation tolerance: float32 s, t (and, antialiased, the footprints apply-map has not).
    assert np.abs(a - b)[inner].max() <= (3 if antialias else 1)


def test_the_map_of_a_retouch_leaves_the_vacated_source_to_the_background(scene):
    from warpcli.composite import polygon_coverage

    d = scene["dir"]
    src = np.array([[20.0, 20.0], [50.0, 20.0], [50.0, 70.0], [20.0, 70.0]])
    dst = src + [30.0, 0.0]
    s, t = write_polygon(d / "s.json", src), write_polygon(d / "t.json", dst)
    assert main([scene["image"], str(d / "out.png"), "--src", s, "--dst", t, "--outside", "input", "--vacated",
                 "background", "--background", "1", "--save-map", str(d / "map.exr"), "--no-antialias"]) == 0  # fmt: skip
    assert main(["apply-map", str(d / "map.exr"), scene["image"], str(d / "again.png"), "--background", "1"]) == 0
    vacated = (polygon_coverage(src, 112, 96) == 1) & (polygon_coverage(dst, 112, 96) == 0)
    assert (read_pixels(d / "again.png")[vacated] == 255).all()
    assert (read_pixels(d / "out.png")[vacated] == 255).all()


def test_apply_map_refuses_an_image_of_another_size_unless_stretched(scene, capsys):
    d = scene["dir"]
    assert main([scene["image"], str(d / "out.png"), "--src", scene["src"], "--dst", scene["dst"],
                 "--save-map", str(d / "map.exr")]) == 0  # fmt: skip
    small = write_png(d / "small.png", scene["pixels"][::2, ::2].copy())  # 56 x 48
    capsys.readouterr()
    assert main(["apply-map", str(d / "map.exr"), small, str(d / "x.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "112x96" in err[0] and "56x48" in err[0] and "--map-scale stretch" in err[0]
    assert not (d / "x.png").exists()
    assert main(["apply-map", str(d / "map.exr"), small, str(d / "x.png"), "--map-scale", "stretch"]) == 0
    assert read_pixels(d / "x.png").shape[:2] == (96, 112)  # the map's size, sampling the small image


def test_a_map_of_a_resized_warp_records_its_source_size(scene):
    d = scene["dir"]
    assert main([scene["image"], str(d / "out.png"), "--src", scene["src"], "--dst", scene["dst"], "--size", "80x60",
                 "--save-map", str(d / "map.tif")]) == 0  # fmt: skip
    # The map is 80x60 but made for the 112x96 input: accepted for it (the header says so, TIFF too).
    assert main(["apply-map", str(d / "map.tif"), scene["image"], str(d / "again.png")]) == 0
    assert read_pixels(d / "again.png").shape[:2] == (60, 80)
    assert main(["apply-map", str(d / "map.tif"), write_png(d / "o.png", np.zeros((60, 80), np.uint8)),
                 str(d / "x.png")]) == 2  # fmt: skip
    # A map of the input's own size says nothing more: its bytes are those of before.
    save_stmap(d / "own.exr", pixel_centres(4, 3).reshape(3, 4, 2), (4, 3))
    names = {a.name for a in oiio.ImageInput.open(str(d / "own.exr")).spec().extra_attribs}
    assert "warpcli:source" not in names and "warpcli:map" in names
