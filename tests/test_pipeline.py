"""End-to-end properties of warp_image / warp_file against exact mathematics."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import map_coordinates

from helpers import l_shape, read_pixels, regular, similarity, star, write_png, write_polygon
from warpcli import Polygon, warp_file, warp_image
from warpcli.grid import pixel_centres


def test_pixel_centres_follow_the_convention():
    c = pixel_centres(3, 2).reshape(2, 3, 2)
    assert c[1, 2].tolist() == [2.5, 1.5]  # row 1, column 2 -> (c + 0.5, r + 0.5)


def test_identical_polygons_leave_the_image_unchanged_inside():
    from warpcli.boundary import edge_points
    from warpcli.raster.resample import edge_coverage

    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, (64, 64, 3), dtype=np.uint8)
    poly = star(cx=32, cy=32, r_in=12, r_out=30)
    res = warp_image(img, poly, poly, background=0)
    inside = np.isfinite(res.inverse_map[..., 0])
    edge = edge_coverage(poly, inside)
    on_edge = np.zeros(64 * 64, bool)
    on_edge[edge.pixels] = True
    on_edge = on_edge.reshape(64, 64)
    assert (inside & ~on_edge).sum() > 800
    np.testing.assert_array_equal(res.pixels[inside & ~on_edge], img[inside & ~on_edge])
    assert (res.pixels[~inside & ~on_edge] == 0).all()
    # Edge pixels: the image weighted by the share of the pixel inside the
    # polygon; a pixel whose centre is outside takes the colour at the
    # nearest boundary point (bilinear there).
    flat = res.pixels.reshape(-1, 3).astype(float)
    centre_inside = inside.ravel()[edge.pixels]
    colour = img.reshape(-1, 3)[edge.pixels].astype(float)
    p = edge_points(poly, edge.edge, edge.t)[~centre_inside]  # identity: the boundary point itself
    colour[~centre_inside] = np.stack(
        [map_coordinates(img[:, :, ch].astype(float), [p[:, 1] - 0.5, p[:, 0] - 0.5], order=1, mode="nearest") for ch in range(3)],
        axis=1,
    )
    expected = edge.fraction[:, None] * colour
    assert np.abs(flat[edge.pixels] - expected).max() <= 0.5 + 1e-6


def test_triangle_warp_equals_an_independent_affine_warp():
    rng = np.random.default_rng(4)
    img = rng.random((80, 90, 2)).astype(np.float32)
    src = np.array([[3.0, 4.0], [86.0, 10.0], [20.0, 77.0]])
    dst = np.array([[60.0, 2.0], [88.0, 70.0], [2.0, 40.0]])
    res = warp_image(img, src, dst, interp="linear", antialias=False)
    # The exact inverse: the affine map taking dst onto src.
    m = np.linalg.solve(np.hstack([dst, np.ones((3, 1))]), src)
    q = pixel_centres(90, 80)
    pre = (np.hstack([q, np.ones((len(q), 1))]) @ m).reshape(80, 90, 2)
    inside = np.isfinite(res.inverse_map[..., 0])
    np.testing.assert_allclose(res.inverse_map[inside], pre[inside], atol=1e-6)
    for ch in range(2):
        ref = map_coordinates(img[:, :, ch].astype(np.float64), [pre[..., 1] - 0.5, pre[..., 0] - 0.5], order=1, mode="nearest")
        np.testing.assert_allclose(res.pixels[inside, ch], ref[inside], atol=1e-5)


def test_linear_image_data_is_reproduced_through_the_whole_warp():
    h, w = 96, 96
    r, c = np.mgrid[0:h, 0:w]
    img = np.stack([0.25 * c + 0.5 * r, -0.75 * c + 3.0], axis=2).astype(np.float32)
    for antialias, margin in ((False, 0.5), (True, 4.0)):
        res = warp_image(
            img, l_shape(size=80), star(cx=48, cy=48, r_in=20, r_out=44)[::2], interp="linear", antialias=antialias
        )
        x, y = res.inverse_map[..., 0], res.inverse_map[..., 1]
        # Away from the image border (where samples are clamped) and, with
        # antialiasing, away from the polygon's edge (blended with the background):
        ok = (x >= margin) & (x <= w - margin) & (y >= margin) & (y <= h - margin)
        if antialias:
            from warpcli.raster.resample import edge_coverage

            edge = np.zeros(h * w, bool)
            edge[edge_coverage(star(cx=48, cy=48, r_in=20, r_out=44)[::2], np.isfinite(x)).pixels] = True
            ok &= ~edge.reshape(h, w)
        expected0 = 0.25 * (x - 0.5) + 0.5 * (y - 0.5)
        expected1 = -0.75 * (x - 0.5) + 3.0
        # A symmetric average of a linear function is its centre value: exact.
        np.testing.assert_allclose(res.pixels[ok, 0], expected0[ok], atol=1e-4)
        np.testing.assert_allclose(res.pixels[ok, 1], expected1[ok], atol=1e-4)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float16, np.float32])
@pytest.mark.parametrize("channels", [1, 2, 4])
def test_pixel_type_and_channels_are_kept(dtype, channels):
    img = (np.random.default_rng(5).random((40, 50, channels)) * 100).astype(dtype)
    res = warp_image(img, regular(5, 25, 20, 18), regular(5, 25, 20, 15, phase=0.4), size=(60, 45))
    assert res.pixels.dtype == img.dtype
    assert res.pixels.shape == (45, 60, channels)


def test_background_is_normalized_for_integer_types():
    img = np.zeros((30, 30, 3), dtype=np.uint16)
    tri = [[5.0, 5.0], [25.0, 5.0], [5.0, 25.0]]
    out = warp_image(img, tri, tri, background=[1.0, 0.5, 0.0]).pixels
    assert out[28, 28].tolist() == [65535, 32768, 0]
    fl = warp_image(img.astype(np.float32), tri, tri, background=[2.5, -1.0, 0.0]).pixels
    assert fl[28, 28].tolist() == [2.5, -1.0, 0.0]


def test_similarity_warp_matches_the_similarity():
    img = np.random.default_rng(6).random((128, 128, 1)).astype(np.float32)
    src = Polygon(star())
    dst = Polygon(similarity(src.points, 0.8, 0.5, (4.0, -3.0)))
    res = warp_image(img, src, dst)
    inside = np.isfinite(res.inverse_map[..., 0])
    q = pixel_centres(128, 128).reshape(128, 128, 2)[inside]
    # Inverse similarity: x = R^-1 (q - c - shift) / s + c.
    exact = similarity(q - [4.0, -3.0], 1 / 0.8, -0.5, (0.0, 0.0))
    err = np.hypot(*(res.inverse_map[inside] - exact).T)
    assert err.mean() < 0.02 and err.max() < 0.3


def test_warp_file_is_deterministic_and_keeps_metadata(tmp_path):
    img = (np.random.default_rng(7).random((48, 48, 3)) * 255).astype(np.uint8)
    inp = write_png(tmp_path / "in.png", img)
    a = write_polygon(tmp_path / "a.json", regular(6, 24, 24, 20))
    b = write_polygon(tmp_path / "b.json", star(3, 24, 24, 10, 22))
    warp_file(inp, tmp_path / "o1.png", a, b)
    warp_file(inp, tmp_path / "o2.png", a, b)
    assert (tmp_path / "o1.png").read_bytes() == (tmp_path / "o2.png").read_bytes()
    assert read_pixels(tmp_path / "o1.png").shape == (48, 48, 3)


def test_antialiased_affine_warp_averages_the_footprint():
    """An independent computation: a shrinking affine map averages k x k bilinear
    samples over each pixel's parallelogram footprint, k = ceil(|J column| - 0.3)."""
    rng = np.random.default_rng(14)
    img = rng.random((90, 90, 1)).astype(np.float64)
    src = np.array([[2.0, 2.0], [88.0, 4.0], [6.0, 88.0]])
    dst = np.array([[20.0, 20.0], [50.0, 24.0], [22.0, 52.0]])  # about a third of the size
    res = warp_image(img, src, dst, interp="linear", antialias=True)
    m = np.linalg.solve(np.hstack([dst, np.ones((3, 1))]), src)
    j = m[:2].T  # source point = j @ q + offset
    ku = int(np.ceil(np.hypot(*j[:, 0]) - 0.3))
    kv = int(np.ceil(np.hypot(*j[:, 1]) - 0.3))
    assert ku >= 2 and kv >= 2
    q = pixel_centres(90, 90)
    centre = np.hstack([q, np.ones((len(q), 1))]) @ m
    acc = np.zeros(len(q))
    for i in range(ku):
        for k in range(kv):
            off = j @ np.array([(i + 0.5) / ku - 0.5, (k + 0.5) / kv - 0.5])
            p = centre + off
            acc += map_coordinates(img[:, :, 0], [p[:, 1] - 0.5, p[:, 0] - 0.5], order=1, mode="nearest")
    expected = (acc / (ku * kv)).reshape(90, 90)
    from warpcli.raster.resample import edge_coverage

    edge = np.zeros(90 * 90, bool)
    edge[edge_coverage(dst, np.isfinite(res.inverse_map[..., 0])).pixels] = True
    ok = np.isfinite(res.inverse_map[..., 0]) & ~edge.reshape(90, 90)
    np.testing.assert_allclose(res.pixels[ok, 0], expected[ok], atol=1e-9)


def test_edge_coverage_sums_to_the_polygon_area():
    from warpcli.raster.resample import edge_coverage

    poly = star(cx=64, cy=64, r_in=25, r_out=58, phase=0.37)
    res = warp_image(np.zeros((128, 128, 1), np.float32), poly, poly, antialias=False)
    edge = edge_coverage(poly, np.isfinite(res.inverse_map[..., 0]))
    full = np.isfinite(res.inverse_map[..., 0]).ravel()
    full[edge.pixels] = False  # interior pixels count 1, edge pixels their share
    area = full.sum() + edge.fraction.sum()
    assert area == pytest.approx(abs(Polygon(poly).signed_area), rel=0.002)


def test_antialiasing_follows_the_map_where_it_shrinks():
    """A fine checkerboard squeezed to a third: close to a 4x supersampled reference."""
    import math

    from warpcli.raster.resample import edge_coverage

    size = 150
    r, c = np.mgrid[0:size, 0:size]
    img = (((r // 3) + (c // 3)) % 2 * 255).astype(np.float32)[:, :, None]
    a = 2 * math.pi * np.arange(6) / 6
    src = np.stack([75 + 70 * np.cos(a), 75 + 70 * np.sin(a)], axis=1)
    dst = np.stack([75 + 23 * np.cos(a + 0.2), 75 + 23 * np.sin(a + 0.2)], axis=1)
    big = warp_image(img, src, dst * 4, size=(4 * size, 4 * size), antialias=False).pixels[:, :, 0]
    reference = big.astype(float).reshape(size, 4, size, 4).mean(axis=(1, 3))
    plain = warp_image(img, src, dst, antialias=False)
    smooth = warp_image(img, src, dst, antialias=True)
    centre_in = np.isfinite(plain.inverse_map[..., 0])
    inside = centre_in.ravel()
    inside[edge_coverage(dst, centre_in).pixels] = False
    inside = inside.reshape(size, size)

    def rmse(x):
        d = (x[:, :, 0].astype(float) - reference)[inside]
        return float(np.sqrt((d * d).mean()))

    assert rmse(plain.pixels) > 40  # aliasing: the unfiltered warp is far off
    assert rmse(smooth.pixels) < 0.15 * rmse(plain.pixels)
    assert rmse(smooth.pixels) < 8


@pytest.mark.parametrize(
    "dst, size",
    [
        ([[-100.0, -100.0], [500.0, -100.0], [500.0, 500.0], [-100.0, 500.0]], (64, 48)),  # covers the image
        ([[1000.0, 1000.0], [1100.0, 1000.0], [1100.0, 1100.0], [1000.0, 1100.0]], (64, 48)),  # misses it
        ([[0.0, 0.0], [1.0e7, 0.0], [1.0e7, 1.0e7], [0.0, 1.0e7]], (64, 48)),  # far larger than the image
        ([[0.2, 0.2], [0.9, 0.3], [0.5, 0.9]], (1, 1)),  # a 1 x 1 output
        ([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], (1, 1)),
    ],
)
def test_targets_covering_missing_or_dwarfing_the_output(dst, size):
    img = np.full((40, 50, 3), 200, dtype=np.uint8)
    src = [[5.0, 5.0], [45.0, 5.0], [45.0, 35.0], [5.0, 35.0]][: len(dst)] if len(dst) == 4 else [[5, 5], [45, 5], [20, 35]]
    res = warp_image(img, src, dst, size=size, max_area=1e12 if max(np.ravel(dst)) > 1e6 else None)
    assert res.pixels.shape == (size[1], size[0], 3)
    r, c = res.pull.origin
    h, w = res.pull.points.shape[:2]
    assert 0 <= r <= r + h <= size[1] and 0 <= c <= c + w <= size[0]


def test_only_the_target_window_costs_map_work():
    """A 10 x 10 target on a large output: the pull-back covers its bounding box and a margin."""
    img = np.zeros((3000, 4000, 1), dtype=np.uint8)
    dst = [[2000.0, 1500.0], [2010.0, 1500.0], [2010.0, 1510.0], [2000.0, 1510.0]]
    res = warp_image(img, [[0, 0], [4000, 0], [4000, 3000], [0, 3000]], dst)
    assert res.pull.points.shape[:2] == (14, 14)
    assert res.pull.origin == (1498, 1998)
    assert res.inverse_map.shape == (3000, 4000, 2)
    assert np.isfinite(res.inverse_map[..., 0]).sum() == 100


def test_edge_coverage_of_a_huge_polygon_costs_only_its_visible_boundary():
    from warpcli.raster.resample import edge_coverage

    big = np.array([[-5.0e8, -5.0e8], [5.0e8, -5.0e8], [5.0e8, 20.5], [-5.0e8, 20.5]])
    inside = np.zeros((30, 40), dtype=bool)
    inside[:20] = True
    cov = edge_coverage(big, inside)
    # The one visible edge (y = 20.5) crosses row 20: half of each pixel there is inside.
    assert set(cov.pixels // 40) == {20}
    np.testing.assert_allclose(cov.fraction, 0.5)


@pytest.mark.parametrize("pattern", ["../x.png", "{name.__class__}", "{name!r}", "{name:>20}", "{0}", "", "sub/{name}", ".."])
def test_output_names_stay_inside_the_output_directory(pattern):
    from warpcli.errors import InputError
    from warpcli.batch import output_name

    with pytest.raises(InputError):
        output_name("shots/a.png", pattern)


def test_out_of_range_backgrounds_are_clipped_without_warnings():
    import warnings

    img = np.full((20, 20, 3), 50, dtype=np.uint8)
    tri = [[2.0, 2.0], [18.0, 2.0], [2.0, 18.0]]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = warp_image(img, tri, tri, background=1e308).pixels
        assert out[19, 19].tolist() == [255, 255, 255]
        out = warp_image(img.astype(np.float32), tri, tri, background=-1e308).pixels
        assert np.isfinite(out).all()


def test_cubic_with_alpha_prints_no_warnings():
    import warnings

    rng = np.random.default_rng(5)
    img = rng.integers(0, 256, (40, 40, 4), dtype=np.uint8)
    img[::3, :, 3] = 0  # transparent stripes: the spline rings around alpha 0
    src = star(cx=20, cy=20, r_in=8, r_out=18)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = warp_image(img, src, star(cx=20, cy=20, r_in=6, r_out=19, phase=0.3), interp="cubic", alpha_channel=3)
    assert res.pixels.dtype == np.uint8


def test_huge_similar_polygons_warp_accurately_where_the_image_is():
    """Both polygons 1e6 px (15,000 times the image): the map is the similarity to FEM accuracy
    over the image (the meshes are graded from the image, so the cost does not grow with the
    polygons)."""
    from warpcli.grid import pixel_centres

    # 1e6 px, not 1e7: the same class (graded meshes, every triangle count below the uniform
    # cap's), 490k triangles against 610k and 60 % of the CPU; the accuracy is held to 0.1 px.
    big = np.array([[-5.0e5, -4.0e5], [6.0e5, -5.0e5], [5.0e5, 5.0e5], [-4.0e5, 6.0e5]])
    moved = similarity(big, 1.02, 0.01, (3.0, -2.0), center=(32.0, 24.0))
    img = np.zeros((48, 64, 1), dtype=np.float32)
    res = warp_image(img, big, moved)
    assert sum(v["triangles"] for v in res.map.describe().values()) < 800_000  # uniform: 1.6 M
    q = pixel_centres(64, 48)
    c, t = np.array([32.0, 24.0]), np.array([3.0, -2.0])
    rot = np.array([[np.cos(0.01), -np.sin(0.01)], [np.sin(0.01), np.cos(0.01)]])
    exact = ((q - c - t) @ rot) / 1.02 + c  # the inverse of y = 1.02 R (x - c) + c + t
    err = np.hypot(*(res.inverse_map.reshape(-1, 2) - exact).T)
    # The harmonic map at the image depends on the whole polygon: a relative accuracy of a few
    # 1e-8 of its size (measured: 0.025 px at 1e6 px, 0.14 px at 1e7 px).
    assert err.max() < 0.1, err.max()


@pytest.mark.parametrize("interp", ["linear", "cubic"])
def test_the_input_border_is_antialiased_where_the_source_runs_past_it(interp):
    """A white image, a source square past its right border, rotated and magnified: the
    output along the border's pre-image matches a 4x supersampled rendering of it."""
    w = h = 40
    img = np.ones((h, w, 1), dtype=np.float32)
    src = np.array([[10.0, 5.0], [60.0, 5.0], [60.0, 35.0], [10.0, 35.0]])  # past x = 40
    dst = similarity(src, 1.6, 0.3, (-20.0, 8.0), center=(35.0, 20.0))
    res = warp_image(img, src, dst, interp=interp, size=(90, 80))
    # The exact share of each output pixel whose pre-image lies in the input
    # image: 4x4 samples of the inverse similarity (inside the target).
    sub = (np.arange(4) + 0.5) / 4
    ys, xs = np.mgrid[0:80, 0:90]
    acc = np.zeros((80, 90))
    c, t = np.array([35.0, 20.0]), np.array([-20.0, 8.0])
    rot = np.array([[np.cos(0.3), -np.sin(0.3)], [np.sin(0.3), np.cos(0.3)]])
    for dy in sub:
        for dx in sub:
            q = np.stack([xs + dx, ys + dy], axis=-1).reshape(-1, 2)
            p = ((q - c - t) @ rot) / 1.6 + c
            acc += ((p[:, 0] >= 0) & (p[:, 0] <= w) & (p[:, 1] >= 0) & (p[:, 1] <= h)).reshape(80, 90)
    ref = acc / 16
    # Pixels the image border crosses, away from the target polygon's own edge.
    from warpcli.raster.resample import edge_coverage

    inside = np.isfinite(res.inverse_map[..., 0])
    poly_edge = np.zeros(80 * 90, bool)
    poly_edge[edge_coverage(dst, inside).pixels] = True
    band = (ref > 0) & (ref < 1) & inside & ~poly_edge.reshape(80, 90)
    assert band.sum() > 30
    err = np.abs(res.pixels[..., 0] - ref)[band]
    hard = np.abs(np.round(ref) - ref)[band]  # a staircase (no antialiasing) is this far off
    assert err.mean() < 0.06 and err.mean() < 0.4 * hard.mean(), (err.mean(), hard.mean())
