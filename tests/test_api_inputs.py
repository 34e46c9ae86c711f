"""The Python API takes what its siblings take, and refuses the rest with an InputError (found by a review of the API)."""

from __future__ import annotations

import numpy as np
import pytest

from warpcli import BijectiveMap, InputError, SamplingPlan, warp_image, warp_labels

SQUARE = [[0.0, 0.0], [40.0, 0.0], [40.0, 30.0], [0.0, 30.0]]
KITE = [[2.0, 1.0], [41.0, 3.0], [37.0, 29.0], [-1.0, 27.0]]


@pytest.fixture(scope="module")
def fmap():
    return BijectiveMap.between(SQUARE, KITE)  # lists, as warp_image and warp_points take them


def test_maps_are_built_from_arrays_and_lists(fmap):
    again = BijectiveMap.between(np.array(SQUARE), np.array(KITE, dtype=np.float32))
    p = np.array([[10.0, 10.0], [30.5, 20.25]])
    assert np.array_equal(fmap.forward(p), again.forward(p))


@pytest.mark.parametrize("size", [(0, 10), (10, 0), (-5, 10), (10.5, 10), (np.nan, 3), "40x30", (1, 2, 3)])
def test_sizes_that_are_not_positive_whole_numbers_are_refused(fmap, size):
    labels = np.ones((30, 40), dtype=np.uint8)
    calls = [lambda: warp_labels(labels, fmap, size=size)]
    if isinstance(size, tuple) and len(size) == 2:
        w, h = size
        calls += [
            lambda: fmap.pull_back(w, h), lambda: fmap.inverse_grid(w, h), lambda: fmap.forward_grid(w, h),
            lambda: SamplingPlan.from_map(fmap, w, h),
        ]  # fmt: skip
    for call in calls:
        with pytest.raises(InputError, match="size"):
            call()


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_a_plan_renders_a_two_dimensional_image_as_warp_image_does(dtype):
    rng = np.random.default_rng(3)
    img = (rng.random((30, 40)) * 200).astype(dtype)
    result = warp_image(img, SQUARE, KITE)
    for pixels in (img, img.tolist()):
        again = result.plan.render(np.asarray(pixels, dtype=dtype) if isinstance(pixels, list) else pixels)
        assert again.shape == (30, 40, 1) and np.array_equal(again, result.pixels)
    with pytest.raises(InputError, match="image"):
        result.plan.render(np.zeros((30,)))
