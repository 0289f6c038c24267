"""Borrowed views: the deposition kernel's arrays without reference counting.

numba counts the references to every array it manages: reading an array out of a bundle
(:mod:`.bundles`) takes a reference and drops it again, an atomic increment and decrement of
the array's count.  The kernel would do that about 230 times per decide-and-move step of a
sphere, and the atomic operations would take some 40 % of its time.

A borrowed view is the same array without its memory-info pointer: numba's reference counting
returns at once on it, with no atomic operation.  It does not keep its memory alive, so every
bundle that holds borrowed views also holds the arrays they borrow from (its ``memory``
field), and a borrowed view is never handed back to Python.
"""

from numba.core import cgutils
from numba.extending import intrinsic

from parsim.core.jit import jit

__all__ = ["borrowed", "carve", "carve_rows"]


@intrinsic
def borrowed(typingctx, array):
    """A view of ``array`` (same data, shape and type) that numba does not reference-count."""
    def codegen(context, builder, signature, args):
        view = context.make_array(array)(context, builder, value=args[0])
        view.meminfo = cgutils.get_null_value(view.meminfo.type)
        view.parent = cgutils.get_null_value(view.parent.type)
        return view._getvalue()

    return array(array), codegen


@jit(inline="always")
def carve(memory, start, size):
    """The borrowed 1-D view of ``size`` elements of the 1-D array ``memory`` from ``start`` on;
    returns it and the next free position."""
    return borrowed(memory[start:start + size]), start + size


@jit(inline="always")
def carve_rows(memory, start, rows, columns):
    """The borrowed ``rows x columns`` view of the 1-D array ``memory`` from ``start`` on; returns it
    and the next free position."""
    return borrowed(memory[start:start + rows * columns].reshape((rows, columns))), start + rows * columns
