"""warpcli._arrays: np.unique's results without np.unique (whose masked-array test imports numpy.ma)."""

from __future__ import annotations

import numpy as np
import pytest

from warpcli._arrays import first_and_inverse, first_of_each, sorted_unique


@pytest.mark.parametrize("seed", range(6))
def test_sorted_unique_of_integer_keys_is_numpys(seed):
    rng = np.random.default_rng(seed)
    keys = rng.integers(0, 50, size=int(rng.integers(0, 80)), dtype=np.int64)
    assert sorted_unique(keys).tobytes() == np.unique(keys).tobytes()


@pytest.mark.parametrize("seed", range(6))
def test_sorted_unique_of_edge_parameters_is_numpys(seed):
    rng = np.random.default_rng(seed)
    t = rng.choice(rng.random(20), size=int(rng.integers(1, 60)))  # floats: repeats, unsorted
    assert sorted_unique(t.copy()).tobytes() == np.unique(t).tobytes()


@pytest.mark.parametrize("seed", range(6))
def test_first_of_each_is_numpys_return_index(seed):
    rng = np.random.default_rng(seed)
    keys = rng.integers(0, 12, size=int(rng.integers(0, 60)))
    assert np.array_equal(first_of_each(keys), np.unique(keys, return_index=True)[1])


@pytest.mark.parametrize("seed", range(6))
def test_first_and_inverse_are_numpys_return_index_and_inverse(seed):
    rng = np.random.default_rng(seed)
    keys = rng.integers(0, 12, size=int(rng.integers(0, 60)))
    _, index, inverse = np.unique(keys, return_index=True, return_inverse=True)
    first, which = first_and_inverse(keys)
    assert np.array_equal(first, index) and np.array_equal(which, inverse.ravel())


@pytest.mark.parametrize("seed", range(8))
def test_median_is_numpys(seed):
    """`median` against np.median, bit for bit: odd and even counts, whole arrays and along axis 0 and 1."""
    from warpcli._arrays import median

    rng = np.random.default_rng(seed)
    a = rng.random(([1, 2, 3, 16, 255, 256][seed % 6], 3)) * 10.0 ** rng.integers(-3, 4)
    assert median(a) == float(np.median(a)) and isinstance(median(a), float)
    for axis in (0, 1):
        assert median(a, axis=axis).tobytes() == np.median(a, axis=axis).tobytes()
