"""PolygonTransform: a warpcli map used as scikit-image transforms are, checked against warpcli's own warp."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import similarity, star
from warpcli import InputError, PolygonTransform, warp_image
from warpcli.transform import FAR

transform = pytest.importorskip("skimage.transform")


def _pair(scale=0.9, angle=0.3):
    src = star(6, 64, 60, 24, 54)
    return src, similarity(src, scale, angle, (4.0, -3.0), (64.0, 60.0))


@settings(max_examples=6)
@given(scale=st.floats(0.7, 1.2), angle=st.floats(-0.8, 0.8), seed=st.integers(0, 100))
def test_skimage_warp_with_the_inverse_is_warpclis_warp(scale, angle, seed):
    """Both resample bilinearly at the same source points once the half-pixel convention is handled:
    inside the target (away from the input's border, where warpcli covers instead of clamping) the
    values agree to rounding; outside it scikit-image gives cval, as warpcli gives the background."""
    src, dst = _pair(scale, angle)
    img = np.random.default_rng(seed).random((128, 128))
    res = warp_image(img, src, dst, interp="linear", antialias=False, background=0.25)
    ours = res.pixels[..., 0]
    tf = PolygonTransform(src, dst, vertices="warpcli")  # the same polygons as warp_image's
    theirs = transform.warp(img, tf.inverse, order=1, cval=0.25, preserve_range=True)
    pts = res.inverse_map  # the source point of each output pixel (the map's, whatever the background)
    inside = np.isfinite(pts[..., 0])
    away = inside & (pts > 1.0).all(axis=-1) & (pts < 127.0).all(axis=-1)
    assert away.sum() > 1000
    np.testing.assert_allclose(theirs[away], ours[away], atol=1e-9)
    assert np.array_equal(theirs[~inside], np.full((~inside).sum(), 0.25))


def test_skimage_coordinates_are_warpclis_minus_half_a_pixel():
    src, dst = _pair()
    tf_sk = PolygonTransform(src - 0.5, dst - 0.5, outside="nan")  # vertices in scikit-image's convention
    tf_wc = PolygonTransform(src, dst, vertices="warpcli", outside="nan")
    p = np.array([[60.0, 55.0], [70.5, 64.25], [40.0, 61.0]])
    np.testing.assert_allclose(tf_sk(p), tf_wc(p), atol=1e-9)
    np.testing.assert_allclose(tf_sk(p), tf_sk.map.forward(p + 0.5) - 0.5, atol=1e-9)
    np.testing.assert_allclose(tf_sk.inverse(p), tf_sk.map.inverse(p + 0.5) - 0.5, atol=1e-9)


def test_inverse_undoes_forward_and_residuals_measure_it():
    src, dst = _pair()
    tf = PolygonTransform(src, dst)
    p = np.random.default_rng(3).uniform(45, 80, (200, 2))
    fwd = tf(p)
    ok = fwd[:, 0] != FAR
    assert ok.sum() > 100
    np.testing.assert_allclose(tf.inverse(fwd[ok]), p[ok], atol=1e-7)
    assert tf.inverse.inverse is tf
    np.testing.assert_allclose(tf.residuals(p[ok], fwd[ok]), 0.0, atol=1e-12)


def test_points_outside_go_far_or_nan():
    src, dst = _pair()
    far = PolygonTransform(src, dst)([[0.0, 0.0]])
    assert np.array_equal(far, [[FAR, FAR]])
    nan = PolygonTransform(src, dst, outside="nan").inverse([[0.0, 0.0]])
    assert np.isnan(nan).all()
    with pytest.raises(InputError, match="vertices"):
        PolygonTransform(src, dst, vertices="opencv")
    with pytest.raises(InputError, match=r"\(K, 2\)"):
        PolygonTransform(src, dst)(np.zeros(3))


def test_map_options_pass_through():
    src, dst = _pair()
    tf = PolygonTransform(src, dst, method="mfs")
    assert tf.map.phi0.method == "mfs"
