"""warpcli.grid.pixel_centres against the convention written out with numpy's own grid."""

from __future__ import annotations

import numpy as np
import pytest

from warpcli.grid import pixel_centres


@pytest.mark.parametrize("seed", range(6))
def test_pixel_centres_are_the_centres_row_by_row(seed):
    """Pixel (row r, column c) has its centre at (c + 0.5, r + 0.5), rows in order, for generated
    sizes and row ranges (empty ones too): numpy's mgrid says the same, value for value."""
    rng = np.random.default_rng(seed)
    width, height = (int(v) for v in rng.integers(0, 40, 2))
    r0 = int(rng.integers(0, height + 1))
    r1 = int(rng.integers(r0, height + 1))
    for rows in (None, (r0, r1)):
        a, b = rows or (0, height)
        yy, xx = np.mgrid[a:b, 0:width]
        want = np.stack([xx.ravel() + 0.5, yy.ravel() + 0.5], axis=1).astype(np.float64)
        got = pixel_centres(width, height, rows)
        assert got.dtype == np.float64 and got.flags.c_contiguous and got.shape == want.shape
        assert np.array_equal(got, want)
