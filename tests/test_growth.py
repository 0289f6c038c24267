"""Arrays grown inside kernels (parsim.core.growth) keep their rows."""

import numpy as np

from parsim.core.growth import with_rows


def test_grown_arrays_keep_their_first_rows_shape_and_dtype():
    rows = np.arange(12, dtype=np.int64)
    grown = with_rows(rows, 30, 12)
    assert grown.shape == (30,) and grown.dtype == np.int64
    np.testing.assert_array_equal(grown[:12], rows)
    table = np.random.default_rng(1).random((5, 3))
    grown = with_rows(table, 10, 4)
    assert grown.shape == (10, 3) and grown.dtype == np.float64
    np.testing.assert_array_equal(grown[:4], table[:4])
