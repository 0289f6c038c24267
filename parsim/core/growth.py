"""Arrays that grow inside kernels: a copy with more rows."""

import numpy as np

from parsim.core.jit import jit

__all__ = ["with_rows", "with_rows_filled"]


@jit
def with_rows(array, rows, kept):
    """A new C-contiguous array of ``rows`` rows, with the trailing shape and dtype of ``array``,
    whose first ``kept`` rows are those of ``array``.  Copied element by element: a slice
    assignment compiles numba's broadcasting and its error messages, seconds of a first
    compilation."""
    grown = np.empty((rows,) + array.shape[1:], dtype=array.dtype)
    width = array.size // array.shape[0] if array.shape[0] > 0 else 0  # numbers per row
    old = array.reshape(-1)
    new = grown.reshape(-1)
    for i in range(kept * width):
        new[i] = old[i]
    return grown


@jit
def with_rows_filled(array, rows, kept, fill):
    """:func:`with_rows` whose rows after the first ``kept`` hold ``fill``."""
    grown = with_rows(array, rows, kept)
    flat = grown.reshape(-1)
    width = flat.size // rows if rows > 0 else 0
    for i in range(kept * width, flat.size):
        flat[i] = fill
    return grown
