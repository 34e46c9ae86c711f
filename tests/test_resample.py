"""Tests of warpcli.resample: filters, background, alpha, pixel types."""

from __future__ import annotations

import numpy as np
import pytest

from warpcli.grid import pixel_centres
from warpcli.raster.resample import footprint_bounds, resample


def identity_map(w: int, h: int) -> np.ndarray:
    return pixel_centres(w, h).reshape(h, w, 2)


@pytest.mark.parametrize("interp", ["nearest", "linear", "cubic"])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float16, np.float32])
def test_identity_map_reproduces_the_image_exactly(interp, dtype):
    rng = np.random.default_rng(1)
    img = (rng.random((9, 11, 3)) * 200).astype(dtype)
    out = resample(img, identity_map(11, 9), interp=interp)
    assert out.dtype == img.dtype
    np.testing.assert_array_equal(out, img) if interp != "cubic" else np.testing.assert_allclose(
        out.astype(float), img.astype(float), atol=1e-3 if dtype in (np.float32, np.float16) else 0
    )


def test_linear_reproduces_linear_data_exactly():
    h, w = 20, 30
    r, c = np.mgrid[0:h, 0:w]
    img = (0.7 * c - 0.3 * r + 5.0).astype(np.float64)[:, :, None]
    rng = np.random.default_rng(2)
    # Arbitrary positions inside the span of pixel centres.
    xy = np.stack([rng.uniform(0.5, w - 0.5, (7, 9)), rng.uniform(0.5, h - 0.5, (7, 9))], axis=2)
    out = resample(img, xy, interp="linear")[:, :, 0]
    expected = 0.7 * (xy[..., 0] - 0.5) - 0.3 * (xy[..., 1] - 0.5) + 5.0
    np.testing.assert_allclose(out, expected, atol=1e-12)


def test_nearest_takes_the_pixel_the_point_falls_in():
    img = np.arange(12, dtype=np.float32).reshape(3, 4, 1)
    pts = np.array([[[0.01, 0.01], [3.99, 2.99], [1.2, 1.7]]])
    out = resample(img, pts, interp="nearest")[0, :, 0]
    assert out.tolist() == [img[0, 0, 0], img[2, 3, 0], img[1, 1, 0]]


def test_background_for_nan_and_for_pre_images_outside_the_input():
    img = np.full((4, 4, 2), 100, dtype=np.uint8)
    pts = np.array([[[np.nan, np.nan], [-0.1, 2.0], [2.0, 4.2], [0.0, 0.0], [4.0, 4.0]]])
    out = resample(img, pts, background=[7, 9])[0]
    assert out.tolist() == [[7, 9], [7, 9], [7, 9], [100, 100], [100, 100]]


def test_float_data_is_neither_clamped_nor_quantized():
    img = np.array([[[-2.5], [1e6]], [[0.123456789], [3.0]]], dtype=np.float32)
    out = resample(img, identity_map(2, 2), interp="linear")
    assert out.dtype == np.float32
    np.testing.assert_array_equal(out, img)
    mid = resample(img, np.array([[[1.0, 0.5]]]), interp="linear")
    assert mid[0, 0, 0] == np.float32((-2.5 + 1e6) / 2)


def test_integer_results_are_rounded_and_clipped():
    img = np.array([[[0], [255]]], dtype=np.uint8)
    mid = resample(img, np.array([[[1.0, 0.5]]]), interp="linear")
    assert mid[0, 0, 0] == 128  # 127.5 rounds to even
    ring = np.zeros((1, 8, 1), dtype=np.uint8)
    ring[0, 4] = 255
    cub = resample(ring, np.array([[[4.1, 0.5], [3.5, 0.5]]]), interp="cubic")
    assert cub.dtype == np.uint8 and cub.max() <= 255  # cubic overshoot clipped


def test_alpha_is_premultiplied_so_transparent_colour_never_bleeds():
    # Left pixel: transparent red; right pixel: opaque blue.
    img = np.array([[[255, 0, 0, 0], [0, 0, 255, 255]]], dtype=np.uint8)
    out = resample(img, np.array([[[1.0, 0.5]]]), interp="linear", alpha_channel=3)[0, 0]
    assert out.tolist() == [0, 0, 255, 128]


def test_unknown_filter_is_rejected():
    with pytest.raises(ValueError, match="interp"):
        resample(np.zeros((2, 2, 1)), identity_map(2, 2), interp="lanczos")


@pytest.mark.parametrize("seed", range(4))
def test_border_coverage_of_a_patch_is_that_of_the_patched_points(seed):
    # A patch (pixels ascending, their points replaced) is the same as the points with the patch written in.
    from warpcli.raster import resample as rs

    rng = np.random.default_rng(seed)
    w, h = 12, 9
    points = rng.uniform(-1.5, [w + 1.5, h + 1.5], size=(w * h, 2))
    jac = np.broadcast_to(np.eye(2), (w * h, 2, 2)).copy()
    patch = np.sort(rng.choice(w * h, size=int(rng.integers(1, 30)), replace=False)).astype(np.int64)
    patch_xy = rng.uniform(-1.5, [w + 1.5, h + 1.5], size=(len(patch), 2))
    written = points.copy()
    written[patch] = patch_xy
    got = rs._border_coverage(points, jac, w, h, patch, patch_xy)
    want = rs._border_coverage(written, jac, w, h)
    assert (got is None) == (want is None)
    if got is not None:
        assert got[0].tobytes() == want[0].tobytes() and got[1].tobytes() == want[1].tobytes()


def _bounds_by_numpy(points, jac, limits):
    """footprint_bounds' definition, written with numpy's whole-array operations."""
    xy = points.reshape(-1, 2)
    ex = ey = 0.0
    if jac is not None:
        j = np.abs(jac.reshape(-1, 2, 2))
        with np.errstate(invalid="ignore"):
            ex = np.nan_to_num(0.5 * (j[:, 0, 0] + j[:, 0, 1]), nan=0.0, posinf=np.inf)
            ey = np.nan_to_num(0.5 * (j[:, 1, 0] + j[:, 1, 1]), nan=0.0, posinf=np.inf)
    finite = np.isfinite(xy).all(axis=1)
    if not finite.any():
        return None
    with np.errstate(invalid="ignore"):
        xs = [np.clip((xy[:, 0] + s * ex)[finite], limits[0], limits[1]) for s in (-1, 1)]
        ys = [np.clip((xy[:, 1] + s * ey)[finite], limits[2], limits[3]) for s in (-1, 1)]
    return xs[0].min(), xs[1].max(), ys[0].min(), ys[1].max()


@pytest.mark.parametrize("seed", range(40))
def test_footprint_bounds_are_numpys_bounds_exactly(seed):
    # Points inside, beyond and far beyond the limits, some NaN or infinite; Jacobians from
    # magnifying to huge, some NaN or infinite entries; with and without Jacobians.
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 300))
    scale = 10.0 ** rng.uniform(-2, 12)
    pts = rng.normal(50, scale, (n, 2))
    jac = rng.normal(0, 10.0 ** rng.uniform(-3, 8), (n, 2, 2))
    for arr, specials in ((pts, (np.nan, np.inf, -np.inf)), (jac, (np.nan, np.inf, -np.inf))):
        flat = arr.reshape(-1)
        hit = rng.random(flat.size) < rng.choice([0.0, 0.05, 0.5, 1.0])
        flat[hit] = rng.choice(specials, int(hit.sum()))
    limits = (-2.0, 100.0 + 2.0, -2.0, 70.0 + 2.0)
    for j in (jac, None):
        want = _bounds_by_numpy(pts, j, limits)
        got = footprint_bounds(pts.reshape(n, 1, 2), None if j is None else j.reshape(n, 1, 2, 2), limits)
        assert got == want if want is None else np.array_equal(np.array(got), np.array(want))
