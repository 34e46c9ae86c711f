"""`warpcli.raster.pixels.fill`: one pixel value over an image, the values numpy's broadcast gives."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from warpcli.raster.pixels import fill


@settings(max_examples=25, deadline=None)
@given(
    shape=st.tuples(st.integers(0, 9), st.integers(0, 9), st.integers(1, 5)),
    dtype=st.sampled_from([np.uint8, np.uint16, np.int32, np.float16, np.float32, np.float64]),
    data=st.data(),
)
def test_fill_gives_every_pixel_the_value_as_numpy_broadcasting_does(shape, dtype, data):
    value = np.asarray(data.draw(st.lists(st.floats(0, 200, width=16), min_size=shape[2], max_size=shape[2])))
    expected = np.empty(shape, dtype=dtype)
    expected[:] = value.astype(dtype)
    got = np.full(shape, 7, dtype=dtype)
    fill(got, value.astype(dtype))
    assert got.tobytes() == expected.tobytes()
    # A view of a larger image (a window's rows and columns): only the view changes.
    big = np.zeros((shape[0] + 2, shape[1] + 3, shape[2]), dtype=dtype)
    fill(big[1 : 1 + shape[0], 2 : 2 + shape[1]], value.astype(dtype))
    assert big[1 : 1 + shape[0], 2 : 2 + shape[1]].tobytes() == expected.tobytes()
    assert not big[0].any() and not big[:, :2].any() and not big[1 + shape[0] :].any()
