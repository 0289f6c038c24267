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

``jit(inline="always")`` inlines a kernel into its callers in numba's IR, a copy at every call
site: it is kept for small functions on the paths of every event, where a call through numba's
calling convention cost up to 25 % of a deposition's time.  Functions called once per particle
in the serial deposition, and the event window's compaction, are plain calls: inlined, they
make the first deposition's compilation some 8 s longer for no measurable speed.

While numba compiles a kernel of :mod:`parsim.core`, Python's cyclic garbage collector runs
less often (:class:`CompilationCollector`): numba's compiler keeps millions of Python objects
alive, and the collector's passes over them, most of them full passes, would take over a quarter
of the CPU time of the first deposition's compilation.  The process's own thresholds are back in
place when the compilation ends.
"""

import gc
from pathlib import Path

import numba
from numba.core import event

from parsim.core import cache

cache.install()

JIT_OPTIONS = {"cache": True, "nogil": True, "fastmath": False}

#: The collector's thresholds while a kernel compiles (Python's defaults: 700, 10, 10).  A young
#: collection every 100 000 allocations and a middle one every 100 of those let the compiler's
#: short-lived reference cycles die before they reach the oldest generation, whose full passes
#: are what cost; threshold 1000 makes those passes rare, at the same peak memory.  Young
#: thresholds of 10 000 or 20 000 let the cycles reach the oldest generation (a third more peak
#: memory), larger ones than 100 000 save no more time for more memory, and no collection at all
#: costs over a GiB more.
COMPILATION_GC_THRESHOLD = (100_000, 100, 1000)


def jit(function=None, **overrides):
    """``numba.njit`` with parsim's options; usable as ``@jit`` or ``@jit(...)``."""
    options = {**JIT_OPTIONS, **overrides}
    if options["cache"] and not cache.cache_usable():
        options["cache"] = False
    if function is None:
        return numba.njit(**options)
    return numba.njit(**options)(function)


def defined_in_core(dispatcher):
    """Whether the function that ``dispatcher`` compiles is one of :mod:`parsim.core`'s kernels."""
    try:
        return Path(dispatcher.py_func.__code__.co_filename).resolve().is_relative_to(cache.CORE)
    except (AttributeError, OSError, ValueError):
        return False


class CompilationCollector(event.Listener):
    """Sets :data:`COMPILATION_GC_THRESHOLD` while numba compiles a kernel of :mod:`parsim.core`.

    Numba announces every compilation with a ``"numba:compile"`` event, nested ones (the
    kernels a kernel calls) within the outer one, and always ends it, also when it fails.
    The thresholds change when the outermost compilation of a parsim kernel starts and are
    restored when it ends, unless something else changed them meanwhile (the process's setting
    then stands).  Compilations hold numba's global compiler lock, so one thread compiles at a
    time and the depth counts that thread's nesting.
    """

    def __init__(self):
        self.depth = 0
        self.saved = None

    def on_start(self, ev):
        if self.depth == 0:
            if not defined_in_core((ev.data or {}).get("dispatcher")):
                return
            self.saved = gc.get_threshold()
            gc.set_threshold(*COMPILATION_GC_THRESHOLD)
        self.depth += 1

    def on_end(self, ev):
        if self.depth == 0:
            return  # the end of a compilation that is not parsim's
        self.depth -= 1
        if self.depth == 0 and gc.get_threshold() == COMPILATION_GC_THRESHOLD:
            gc.set_threshold(*self.saved)


event.register("numba:compile", CompilationCollector())
