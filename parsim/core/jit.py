"""The one place where parsim's numba options are set.

Every kernel in :mod:`parsim.core` is decorated with :func:`jit`, so caching,
GIL release and the floating-point model are decided here once:

- ``cache=True``: compiled machine code is kept on disk, so only the first run
  on a machine pays the compilation time; it lives in a per-user folder, not in the
  installed package (see :mod:`parsim.core.cache`, imported here so that its locator is
  in place before any kernel is decorated);
- ``nogil=True``: kernels release the GIL, which lets the MPI task server thread
  of rank 0 answer other ranks while rank 0 computes;
- ``fastmath=False``: results are IEEE-exact and reproducible between runs, a
  requirement for identical datasets on 1 and 2 ranks.
"""

import numba

from parsim.core import cache

cache.install()

JIT_OPTIONS = {"cache": True, "nogil": True, "fastmath": False}


def jit(function=None, **overrides):
    """``numba.njit`` with parsim's options; usable as ``@jit`` or ``@jit(...)``."""
    options = {**JIT_OPTIONS, **overrides}
    if options["cache"] and not cache.cache_usable():
        options["cache"] = False
    if function is None:
        return numba.njit(**options)
    return numba.njit(**options)(function)
