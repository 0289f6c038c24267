"""A binary min-heap of events held in plain arrays, for numba kernels.

An event is a time ``t`` (float64), an insertion sequence number ``seq`` (int64, unique
and increasing) and ``NFIELDS`` int64 payload fields.  Events are ordered by
``(t, seq)``: equal times come out in insertion order, which makes event-driven runs
deterministic.

Storage is three arrays of the same length (the capacity): ``times (cap,)``,
``seqs (cap,)`` and ``data (cap, NFIELDS)``; the heap occupies the first ``size`` rows.
Only :func:`heap_new` and :func:`heap_grow` allocate; the caller keeps the capacity
(see :func:`heap_filter`, used to drop stale events).
"""

import numpy as np

from parsim.core.jit import jit

__all__ = ["NFIELDS", "heap_new", "heap_push", "heap_pop", "heap_filter", "heap_grow"]

#: Number of int64 payload fields per event.
NFIELDS = 5
#: The heap's first row.  A numpy integer, not a Python int: numba types a Python int constant
#: passed to a kernel as a literal and compiles a separate copy of the callee for each value.
_ROOT = np.int64(0)


@jit
def heap_new(capacity):
    """Empty heap arrays ``times, seqs, data`` of the given capacity."""
    return (
        np.empty(capacity, dtype=np.float64),
        np.empty(capacity, dtype=np.int64),
        np.empty((capacity, NFIELDS), dtype=np.int64),
    )


@jit
def _before(t1, s1, t2, s2):
    return t1 < t2 or (t1 == t2 and s1 < s2)


@jit
def _move(times, seqs, data, src, dst):
    """Copy the event in row ``src`` to row ``dst``."""
    times[dst] = times[src]
    seqs[dst] = seqs[src]
    for f in range(NFIELDS):
        data[dst, f] = data[src, f]


@jit
def _place(times, seqs, data, k, t, seq, f0, f1, f2, f3, f4):
    """Write the event ``(t, seq, f0..f4)`` into row ``k``."""
    times[k] = t
    seqs[k] = seq
    data[k, 0] = f0
    data[k, 1] = f1
    data[k, 2] = f2
    data[k, 3] = f3
    data[k, 4] = f4


@jit
def heap_push(times, seqs, data, size, t, seq, f0, f1, f2, f3, f4):
    """Insert an event (capacity must exceed ``size``); returns the new size."""
    k = size
    while k > 0:
        p = (k - 1) >> 1
        if _before(times[p], seqs[p], t, seq):
            break
        _move(times, seqs, data, p, k)
        k = p
    _place(times, seqs, data, k, t, seq, f0, f1, f2, f3, f4)
    return size + 1


@jit
def _sift_down(times, seqs, data, size, k, t, seq, f0, f1, f2, f3, f4):
    """Place the event ``(t, seq, f0..f4)`` at hole ``k`` and sift it down."""
    while True:
        c = 2 * k + 1
        if c >= size:
            break
        if c + 1 < size and _before(times[c + 1], seqs[c + 1], times[c], seqs[c]):
            c += 1
        if not _before(times[c], seqs[c], t, seq):
            break
        _move(times, seqs, data, c, k)
        k = c
    _place(times, seqs, data, k, t, seq, f0, f1, f2, f3, f4)


@jit
def heap_pop(times, seqs, data, size, out):
    """Remove the first event; its payload goes to ``out`` (NFIELDS,).

    Returns ``(t, seq, new_size)``.  ``size`` must be > 0.
    """
    t = times[0]
    seq = seqs[0]
    for f in range(NFIELDS):
        out[f] = data[0, f]
    size -= 1
    if size > 0:
        _sift_down(times, seqs, data, size, _ROOT, times[size], seqs[size],
                   data[size, 0], data[size, 1], data[size, 2], data[size, 3], data[size, 4])
    return t, seq, size


@jit
def heap_filter(times, seqs, data, size, keep):
    """Keep the events whose ``keep[k]`` is true and rebuild the heap; returns the new size."""
    m = np.int64(0)  # not the literal 0, which would compile a second _sift_down (see _ROOT)
    for k in range(size):
        if keep[k]:
            _move(times, seqs, data, k, m)
            m += 1
    for k in range((m - 2) // 2, -1, -1):
        _sift_down(times, seqs, data, m, k, times[k], seqs[k],
                   data[k, 0], data[k, 1], data[k, 2], data[k, 3], data[k, 4])
    return m


@jit
def heap_grow(times, seqs, data, size, capacity):
    """Copies of the heap arrays with a larger capacity."""
    t2, s2, d2 = heap_new(capacity)
    # Element by element: slice assignments (``t2[:size] = times[:size]``) compile numba's
    # broadcasting and its error messages, some 40 kernels and 40 % more CPU time in the
    # first aggregation's compilation.
    for k in range(size):
        t2[k] = times[k]
        s2[k] = seqs[k]
        for f in range(NFIELDS):
            d2[k, f] = data[k, f]
    return t2, s2, d2
