"""Tests of warpcli.composite: polygon coverage by scanlines, and pasting a warp over its input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from helpers import comb, l_shape, simple_polygons, spiral, star, run_cli
from warpcli.composite import paste_over, polygon_coverage
from warpcli.grid import inside_polygon, pixel_centres


@given(st.integers(3, 30).flatmap(simple_polygons), st.floats(0.3, 1.2), st.floats(-40, 40), st.floats(-40, 40))
def test_scanline_coverage_agrees_with_the_point_test_and_sums_to_the_area(poly, scale, dx, dy):
    v = np.asarray(poly) * scale + [dx, dy]
    w, h = 150, 110
    cov = polygon_coverage(v, w, h)
    centres_in = inside_polygon(pixel_centres(w, h), v).reshape(h, w)
    # away from the boundary the coverage is the point test's answer
    edge = (cov > 0) & (cov < 1)
    np.testing.assert_array_equal(cov[~edge] == 1, centres_in[~edge])
    if v.min() > 2 and v[:, 0].max() < w - 2 and v[:, 1].max() < h - 2:  # wholly inside the grid
        area = 0.5 * abs(np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1]))
        perimeter = np.hypot(*(np.roll(v, -1, axis=0) - v).T).sum()
        assert abs(cov.sum() - area) < 0.1 * perimeter + 2 * len(v)  # corner effects only


@pytest.mark.parametrize("shape", [star(), l_shape(), comb(), spiral()])
def test_scanline_coverage_of_named_shapes(shape):
    cov = polygon_coverage(shape, 128, 128)
    inside = inside_polygon(pixel_centres(128, 128), shape).reshape(128, 128)
    edge = (cov > 0) & (cov < 1)
    np.testing.assert_array_equal(cov[~edge] == 1, inside[~edge])


def test_coverage_of_an_axis_aligned_rectangle_is_exact_and_far_polygons_cost_nothing():
    cov = polygon_coverage([[2, 3], [10, 3], [10, 7], [2, 7]], 12, 9)
    want = np.zeros((9, 12))
    want[3:7, 2:10] = 1
    np.testing.assert_array_equal(cov, want)
    assert not polygon_coverage([[1e9, 1e9], [2e9, 1e9], [2e9, 2e9]], 12, 9).any()
    huge = polygon_coverage([[-1e9, -1e9], [1e9, -1e9], [1e9, 1e9], [-1e9, 1e9]], 12, 9)
    assert (huge == 1).all()


def _image(alpha: bool, dtype=np.uint8):
    rng = np.random.default_rng(7)
    img = rng.integers(0, 256, (40, 50, 4 if alpha else 3)).astype(dtype)
    return img


@pytest.mark.parametrize("alpha", [False, True])
def test_a_transparent_warp_leaves_the_input_or_fills_the_vacated_source(alpha):
    img = _image(alpha)
    src = np.array([[5.0, 5.0], [30.0, 5.0], [30.0, 25.0], [5.0, 25.0]])
    nothing = lambda pixels, ai: np.zeros_like(pixels)  # noqa: E731
    kw = dict(src=src, background=[9, 8, 7, 255][: img.shape[2]], alpha_channel=3 if alpha else None, associated_alpha=False)
    kept = paste_over(img, nothing, vacated="keep", **kw)
    np.testing.assert_array_equal(kept, img)
    filled = paste_over(img, nothing, vacated="background", **kw)
    inside = np.zeros((40, 50), bool)
    inside[5:25, 5:30] = True
    np.testing.assert_array_equal(filled[~inside], img[~inside])
    assert (filled[inside] == np.array([9, 8, 7, 255][: img.shape[2]])).all()


@pytest.mark.parametrize("vacated", ["keep", "background"])
def test_an_opaque_warp_replaces_everything_it_covers(vacated):
    img = _image(False)
    rng = np.random.default_rng(3)
    other = rng.uniform(0, 255, (40, 50, 3)).astype(np.float32)
    cover = np.zeros((40, 50, 1), np.float32)
    cover[10:30, 10:40] = 1.0
    cover[10:30, 40] = 0.25  # an antialiased edge column

    def warp(pixels, ai):
        assert ai == 3 and pixels.shape == (40, 50, 4)
        out = np.concatenate([other * 255.0 / 255.0, np.full((40, 50, 1), 255.0, np.float32)], axis=2)
        return out * cover  # premultiplied: colour and alpha scaled by the coverage

    got = paste_over(img, warp, src=np.array([[0.0, 36.0], [4.0, 36.0], [0.0, 39.0]]), background=0, alpha_channel=None, associated_alpha=False, vacated=vacated)
    np.testing.assert_array_equal(got[10:30, 10:40], np.round(other[10:30, 10:40]).astype(np.uint8))
    blend = 0.25 * other[10:30, 40] + 0.75 * img[10:30, 40]
    np.testing.assert_array_equal(got[10:30, 40], np.round(blend).astype(np.uint8))
    np.testing.assert_array_equal(got[:10], img[:10])


def test_an_unknown_vacated_mode_is_refused():
    from warpcli import InputError

    with pytest.raises(InputError, match="vacated"):
        paste_over(_image(False), lambda p, a: p, src=np.zeros((3, 2)), background=0, alpha_channel=None, associated_alpha=False, vacated="x")



@pytest.mark.parametrize("alpha", [False, True])
def test_outside_input_with_identical_polygons_gives_the_input_back(tmp_path, alpha):
    from helpers import write_png, write_polygon

    rng = np.random.default_rng(11)
    px = rng.integers(0, 256, (96, 128, 4 if alpha else 3), dtype=np.uint8)
    if alpha:
        px[..., 3] = np.maximum(px[..., 3], 1)  # no fully transparent pixel: its colour is undefined
    img = write_png(tmp_path / "in.png", px)
    poly = write_polygon(tmp_path / "p.json", star(cx=60, cy=50, r_in=15, r_out=40))
    code, err = run_cli([img, tmp_path / "out.png", "--src", poly, "--dst", poly, "--outside", "input"])
    assert code == 0, err
    from warpcli.raster.imageio import read_image

    px = read_image(img).pixels.astype(int)  # as warpcli reads it (straight alpha)
    got = read_image(tmp_path / "out.png").pixels.astype(int)
    cov = polygon_coverage(star(cx=60, cy=50, r_in=15, r_out=40), 128, 96)
    assert (got[cov == 0] == px[cov == 0]).all()  # untouched, bit for bit
    assert np.abs(got - px)[cov == 1].max() <= 1  # the identity warp, to rounding
    # (edge pixels blend the input with the colour at the nearest boundary point, by coverage)


def test_outside_input_composites_the_warp_and_fills_the_vacated_source(tmp_path):
    from helpers import read_pixels, write_png, write_polygon

    px = np.full((100, 120, 3), 200, dtype=np.uint8)
    px[:, ::7] = 40  # stripes to move
    img = write_png(tmp_path / "in.png", px)
    src = np.array([[20.0, 20.0], [60.0, 20.0], [60.0, 80.0], [20.0, 80.0]])
    dst = src + [40.0, 0.0]  # moved right: the left 40 px of SRC are vacated
    s, d = write_polygon(tmp_path / "s.json", src), write_polygon(tmp_path / "d.json", dst)
    plain = tmp_path / "plain.png"
    assert run_cli([img, plain, "--src", s, "--dst", d])[0] == 0
    for vacated in ("keep", "background"):
        out = tmp_path / f"{vacated}.png"
        code, err = run_cli([img, out, "--src", s, "--dst", d, "--outside", "input", "--vacated", vacated, "--background", "0,0,1"])
        assert code == 0, err
        got = read_pixels(out)
        inside_dst = polygon_coverage(dst, 120, 100) == 1
        np.testing.assert_array_equal(got[inside_dst], read_pixels(plain)[inside_dst])  # the warp itself
        outside_both = (polygon_coverage(dst, 120, 100) == 0) & (polygon_coverage(src, 120, 100) == 0)
        np.testing.assert_array_equal(got[outside_both], px[outside_both])  # the input
        vac = (polygon_coverage(src, 120, 100) == 1) & (polygon_coverage(dst, 120, 100) == 0)
        want = px[vac] if vacated == "keep" else np.array([0, 0, 255], np.uint8)
        assert (got[vac] == want).all()


def test_outside_input_needs_the_input_size_and_leaves_nothing_behind(tmp_path):
    from helpers import write_png, write_polygon

    img = write_png(tmp_path / "in.png", np.zeros((64, 64, 3), dtype=np.uint8))
    poly = write_polygon(tmp_path / "p.json", star(cx=32, cy=32, r_in=8, r_out=20))
    code, err = run_cli([img, tmp_path / "out.png", "--src", poly, "--dst", poly, "--outside", "input", "--size", "32x32"])
    assert code == 2 and "must have its size 64x64" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.png", "p.json"]


# --- feathering (--feather) ---------------------------------------------------------------


def _distance_to_boundary(vertices, width, height):
    """Brute force: every pixel centre's distance to every edge, the least (an independent reference)."""
    v = np.asarray(vertices, dtype=float)
    p = pixel_centres(width, height)
    a, b = v, np.roll(v, -1, axis=0)
    d = b - a
    t = np.clip(((p[:, None, :] - a) * d).sum(axis=2) / (d * d).sum(axis=1), 0, 1)
    nearest = a + t[..., None] * d
    return np.hypot(*(p[:, None, :] - nearest).transpose(2, 0, 1)).min(axis=1).reshape(height, width)


def _smoothstep(s):
    s = np.clip(s, 0, 1)
    return s * s * (3 - 2 * s)


@pytest.mark.parametrize("band", [0.7, 3.0, 9.5])
@pytest.mark.parametrize("shape", [star(cx=40, cy=30, r_in=8, r_out=26), l_shape(2.5, -3.0, 60.0)])
def test_feather_weights_are_the_smoothstep_of_the_exact_distance(shape, band):
    from warpcli.composite import feather_weights

    w, h = 70, 56
    got = feather_weights(shape, w, h, band)
    inside = inside_polygon(pixel_centres(w, h), shape).reshape(h, w)
    want = np.where(inside, _smoothstep(_distance_to_boundary(shape, w, h) / band), 0.0)
    np.testing.assert_allclose(got, want, atol=2e-7)
    # A strip's rows are the whole grid's.
    np.testing.assert_array_equal(feather_weights(shape, w, h, band, rows=(9, 31)), got[9:31])


def _ramp_scene():
    """A float ramp image (smooth: a seam shows as a jump of many steps) and a cage moved and turned."""
    y, x = np.mgrid[0:64, 0:80].astype(np.float32)
    img = np.stack([x / 80, y / 64, (x + y) / 144], axis=2).astype(np.float32)
    src = np.array([[20.0, 18.0], [52.0, 16.0], [56.0, 44.0], [24.0, 48.0]])
    dst = np.array([[26.0, 14.0], [58.0, 20.0], [52.0, 50.0], [18.0, 42.0]])
    return img, src, dst


def test_feather_blends_warp_and_input_by_the_documented_weights_and_nothing_else():
    from warpcli import warp_image

    img, src, dst = _ramp_scene()
    band = 6.0
    plain = warp_image(img, src, dst, outside="input").pixels
    assert np.array_equal(warp_image(img, src, dst, outside="input", feather=0).pixels, plain)
    got = warp_image(img, src, dst, outside="input", feather=band).pixels
    h, w = img.shape[:2]
    cov = polygon_coverage(dst, w, h)
    weight = _smoothstep(_distance_to_boundary(dst, w, h) / band)
    inner = cov == 1  # fully inside the target: plain holds the warp itself
    want = weight[..., None] * plain + (1 - weight[..., None]) * img
    np.testing.assert_allclose(got[inner], want[inner], atol=1e-5)
    far = inner & (_distance_to_boundary(dst, w, h) >= band + 1e-9)
    np.testing.assert_array_equal(got[far], plain[far])  # beyond the band: unchanged, bit for bit
    outside = cov == 0
    np.testing.assert_array_equal(got[outside], plain[outside])  # the input, as without feather


def test_feather_lowers_the_seam_on_a_smooth_ramp():
    from warpcli import warp_image
    from warpcli.report.seam import seam_jump

    img, src, dst = _ramp_scene()
    step = 1 / 80
    hard = seam_jump(warp_image(img, src, dst, outside="input").pixels, dst)
    soft = seam_jump(warp_image(img, src, dst, outside="input", feather=8.0).pixels, dst)
    assert hard.across_max > 4 * step  # the seam: several ramp steps at once
    assert soft.across_max < 0.25 * hard.across_max


def test_feather_needs_outside_input_and_a_sane_width():
    from warpcli.errors import InputError
    from warpcli.options import WarpOptions

    with pytest.raises(InputError, match="needs --outside input"):
        WarpOptions(feather=3)
    for bad in (-1, float("nan"), float("inf"), "x"):
        with pytest.raises(InputError, match="feather"):
            WarpOptions(outside="input", feather=bad)
    assert WarpOptions(outside="input", feather=2).feather == 2.0


def test_feather_through_the_cli_and_batches(tmp_path):
    from helpers import read_pixels, write_png, write_polygon

    img, src, dst = _ramp_scene()
    px = np.round(img * 255).astype(np.uint8)
    a = write_png(tmp_path / "a.png", px)
    b = write_png(tmp_path / "b.png", px[::-1].copy())
    s, d = write_polygon(tmp_path / "s.json", src), write_polygon(tmp_path / "d.json", dst)
    common = ["--src", s, "--dst", d, "--outside", "input"]
    assert run_cli([a, tmp_path / "zero.png", *common, "--feather", "0"])[0] == 0
    assert run_cli([a, tmp_path / "none.png", *common])[0] == 0
    assert read_pixels(tmp_path / "zero.png").tobytes() == read_pixels(tmp_path / "none.png").tobytes()
    assert run_cli([a, tmp_path / "one.png", *common, "--feather", "5"])[0] == 0
    (tmp_path / "out").mkdir()
    code, err = run_cli([a, b, "--out-dir", tmp_path / "out", *common, "--feather", "5", "--jobs", "2"])
    assert code == 0, err
    np.testing.assert_array_equal(read_pixels(tmp_path / "out" / "a.png"), read_pixels(tmp_path / "one.png"))
    code, err = run_cli([a, tmp_path / "bad.png", "--src", s, "--dst", d, "--feather", "5"])
    assert code == 2 and "needs --outside input" in err and not (tmp_path / "bad.png").exists()
