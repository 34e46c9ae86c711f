"""The sampling plan: one object per output window, whatever made the map and whoever renders it."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.ndimage import map_coordinates

from helpers import similarity, star
from warpcli import BijectiveMap, ImageIOError, InputError, SamplingPlan, resample, warp_image
from warpcli.batch import PlanCache
from warpcli.options import MapOptions, WarpOptions
from warpcli.polygon import Polygon
from warpcli.plan import plan_for

TRI_SRC = np.array([[10.0, 12.0], [110.0, 20.0], [30.0, 100.0]])
# An affine image of TRI_SRC: x -> A x + b.
A = np.array([[0.8, 0.25], [-0.15, 1.1]])
B = np.array([7.0, -3.0])
TRI_DST = TRI_SRC @ A.T + B


def _map(src, dst, opts: MapOptions | None = None) -> BijectiveMap:
    return BijectiveMap.between(Polygon(src, name="src"), Polygon(dst, name="dst"), opts or MapOptions())


def _image(h=120, w=130, c=3, seed=1):
    return np.random.default_rng(seed).integers(0, 256, (h, w, c), dtype=np.uint8)


def test_a_plan_of_an_affine_map_samples_where_the_affine_inverse_says():
    """Exact mathematics: between two triangles the map is the affine map, so the plan's source points
    are A^-1 (y - b) at every output pixel centre inside the target, and NaN outside."""
    fmap = _map(TRI_SRC, TRI_DST)
    plan = SamplingPlan.from_map(fmap, 130, 120, antialias=False)
    pts = plan.pull.full_points()
    inside = np.isfinite(pts[..., 0])
    rows, cols = np.nonzero(inside)
    centres = np.stack([cols + 0.5, rows + 0.5], axis=1)
    expected = (centres - B) @ np.linalg.inv(A).T
    assert inside.sum() > 3000
    np.testing.assert_allclose(pts[inside], expected, atol=1e-9)


def test_rendering_a_plan_is_bilinear_resampling_at_its_points():
    """Independent reference: scipy's map_coordinates (order 1) at the plan's points (centres at +0.5)."""
    img = _image(c=1).astype(np.float64)
    fmap = _map(TRI_SRC, TRI_DST)
    plan = SamplingPlan.from_map(fmap, 130, 120, antialias=False, background=0.0)
    out = plan.render(img)[..., 0]
    pts = plan.pull.full_points()
    inside = np.isfinite(pts[..., 0])
    ref = map_coordinates(img[..., 0], [pts[inside][:, 1] - 0.5, pts[inside][:, 0] - 0.5], order=1, mode="nearest")
    # Away from the input's border (where the resampler covers rather than clamps).
    far = (pts[inside] > 1.0).all(axis=1) & (pts[inside][:, 0] < 129) & (pts[inside][:, 1] < 119)
    np.testing.assert_allclose(out[inside][far], ref[far], atol=1e-9)
    assert (out[~inside] == 0).all()


@settings(max_examples=12)
@given(
    scale=st.floats(0.6, 1.3), angle=st.floats(-0.6, 0.6), interp=st.sampled_from(["nearest", "linear", "cubic"]),
    antialias=st.booleans(), cuts=st.tuples(st.integers(1, 60), st.integers(1, 60)),
)
def test_crops_of_a_plan_render_the_whole_plan_bit_for_bit(scale, angle, interp, antialias, cuts):
    """A strip or chunk of a plan (`crop`) gives its pixels exactly what the whole plan gives them,
    edge coverage included: the property strips of images larger than memory rely on."""
    src = star(5, 64, 60, 22, 50)
    dst = similarity(src, scale, angle, (3.0, -2.0), (64.0, 60.0))
    img = _image(128, 128, 4, seed=3)
    fmap = _map(src, dst)
    plan = SamplingPlan.from_map(fmap, 128, 128, interp=interp, antialias=antialias, background=(0.2, 0.4, 0.6, 1.0))
    whole = plan.sample_window(img, alpha_channel=3)
    h, w = plan.pull.points.shape[:2]
    r, c = min(cuts[0], h), min(cuts[1], w)
    pieces = [
        [plan.crop(rows, cols).sample_window(img, alpha_channel=3) for cols in ((0, c), (c, w))]
        for rows in ((0, r), (r, h))
    ]
    assembled = np.concatenate([np.concatenate(row, axis=1) for row in pieces], axis=0)
    assert np.array_equal(assembled, whole)


def test_a_plan_for_rows_is_the_whole_plan_cropped_to_them():
    src, dst = star(6, 64, 64, 25, 56), star(6, 64, 64, 20, 58, 0.3)
    fmap = _map(src, dst)
    whole = SamplingPlan.from_map(fmap, 128, 128)
    strip = SamplingPlan.from_map(fmap, 128, 128, rows=(40, 70))
    r0 = whole.pull.origin[0]
    cropped = whole.crop((40 - r0, 70 - r0), (0, whole.pull.points.shape[1]))
    assert strip.pull.origin == cropped.pull.origin
    assert np.array_equal(strip.pull.points, cropped.pull.points, equal_nan=True)
    assert np.array_equal(strip.pull.jacobian, cropped.pull.jacobian, equal_nan=True)
    for name in ("pixels", "fraction", "edge", "t", "source_points"):
        assert np.array_equal(getattr(strip.coverage, name), getattr(cropped.coverage, name)), name


def test_warp_image_renders_through_its_plan():
    """The whole-image route is the plan's: same bytes as rendering a plan of the same map."""
    src, dst = star(6, 64, 64, 25, 56), star(6, 64, 64, 20, 58, 0.3)
    img = _image(128, 128, 3, seed=4)
    res = warp_image(img, src, dst, interp="cubic", background=0.5)
    plan = plan_for(res.map, 128, 128, WarpOptions(interp="cubic", background=0.5))
    assert np.array_equal(plan.render(img), res.pixels)
    # The result's own plan warps another image of that size the same way.
    other = _image(128, 128, 3, seed=7)
    assert np.array_equal(res.plan.render(other), warp_image(other, src, dst, interp="cubic", background=0.5).pixels)


def test_a_plan_from_points_is_plain_resampling():
    """A loaded STMap has only points: its plan renders what `resample` gives for them."""
    img = _image(40, 50, 3, seed=5)
    yy, xx = np.mgrid[0:30, 0:35] + 0.5
    pts = np.stack([xx * 1.3 + 0.2, yy * 1.1 - 0.4], axis=-1)
    pts[:3, :3] = np.nan
    plan = SamplingPlan.from_points(pts, interp="linear", background=1.0)
    expected = resample(img, pts, interp="linear", background=255.0)
    assert np.array_equal(plan.render(img), expected)
    with pytest.raises(InputError, match=r"\(H, W, 2\)"):
        SamplingPlan.from_points(np.zeros((4, 4)))


def test_the_background_must_fit_the_image():
    plan = SamplingPlan.from_points(np.full((2, 2, 2), np.nan), background=(0.1, 0.2))
    with pytest.raises(InputError, match="background has 2 values but the image has 3 channels"):
        plan.render(_image(2, 2, 3))
    with pytest.raises(InputError, match="outside"):
        SamplingPlan(plan.pull, outside="elsewhere")


def test_a_shipped_plan_cache_renders_the_same_bytes_and_makes_no_new_plans():
    """What Dask workers get: the plans, pickled, without the map."""
    src, dst = star(6, 64, 64, 25, 56), star(6, 64, 64, 20, 58, 0.3)
    opts = WarpOptions()
    cache = PlanCache(_map(src, dst), opts)
    assert cache.get((128, 128)) is cache.get((128, 128))
    shipped = pickle.loads(pickle.dumps(cache))
    assert shipped.fmap is None
    img = _image(128, 128, 3, seed=6)
    assert np.array_equal(shipped.get((128, 128)).render(img), cache.get((128, 128)).render(img))
    with pytest.raises(ImageIOError, match="no sampling plan was made for an output of 64x64"):
        shipped.get((64, 64))


@pytest.mark.parametrize("alpha, associated, copies", [(3, False, 1), (3, True, 0), (None, False, 0)])
def test_rendering_band_by_band_copies_the_image_at_most_once(monkeypatch, alpha, associated, copies):
    """`SamplingPlan.render_rows` samples the image band by band: straight colour is premultiplied
    into one working copy for all of them (each band's `resample` copied the whole image again),
    and the bands give `render`'s bytes."""
    import warpcli.plan as plan_module
    import warpcli.raster.resample as resample_module

    made = []
    real = resample_module.working_copy

    def counted(*args, **kwargs):
        out = real(*args, **kwargs)
        made.append(out is not None and out.shape[:2] == img.shape[:2])  # copies of the whole image
        return out

    monkeypatch.setattr(plan_module, "working_copy", counted)
    monkeypatch.setattr(resample_module, "working_copy", counted)
    img = _image(c=4)
    img[..., 3] = np.random.default_rng(3).integers(0, 256, img.shape[:2])
    plan = SamplingPlan.from_map(_map(star(6, 65, 60, 25, 55), star(6, 65, 60, 22, 50, 0.2)), 130, 120)
    out = np.empty_like(img)
    bands = list(plan.render_rows(img, out, alpha_channel=alpha, associated_alpha=associated, band=16))
    assert len(bands) > 4 and sum(made) == copies
    assert out.tobytes() == plan.render(img, alpha_channel=alpha, associated_alpha=associated).tobytes()
