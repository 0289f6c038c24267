"""A quick, conservative test of whether an interval of x meets any of a few boxes.

The checks between a rank's rows and the footprints of other ranks' particles compare every row
with every footprint; nearly all of them are far apart (the footprints gather at the block's
borders).  :func:`mark_strips` marks the strips of x that the boxes' x-intervals cover, padded by
one strip on each side so that round-off in the strip index never drops a meeting pair;
:func:`meets_strips` tells whether an interval touches a marked strip.  A row that touches none
meets no box, and skips the exact comparison (:func:`.blocks.box_meets`).
"""

import math

import numpy as np

from parsim.core.jit import jit

N_STRIPS = 256


@jit
def mark_strips(boxes, n, margin, length, periodic):
    """The strips of x (``N_STRIPS`` of them) covered by the x-intervals of ``boxes[:n]`` (x_low,
    x_high, ...) widened by ``margin``: ``(marked, origin, width)``.  Periodic strips tile one period
    from 0; others tile the boxes' hull.  Empty intervals (x_low > x_high: a particle with no
    spheres) mark nothing; unbounded ones mark every strip."""
    marked = np.zeros(N_STRIPS, dtype=np.bool_)
    low, high = np.inf, -np.inf
    for k in range(n):
        if boxes[k, 0] <= boxes[k, 1]:
            low = min(low, boxes[k, 0] - margin)
            high = max(high, boxes[k, 1] + margin)
    if low > high:
        return marked, 0.0, 1.0
    if not (math.isfinite(low) and math.isfinite(high)):
        marked[:] = True
        return marked, 0.0, 1.0
    if periodic:
        origin, width = 0.0, length / N_STRIPS
    else:
        origin, width = low, (high - low) / N_STRIPS if high > low else 1.0
    for k in range(n):
        if boxes[k, 0] > boxes[k, 1]:
            continue
        first, last = _strip_range(boxes[k, 0] - margin, boxes[k, 1] + margin, origin, width, periodic)
        if last - first >= N_STRIPS - 1:
            marked[:] = True
            break
        for s in range(first - 1, last + 2):
            if periodic:
                marked[s % N_STRIPS] = True
            elif 0 <= s < N_STRIPS:
                marked[s] = True
    return marked, origin, width


@jit(inline="always")
def meets_strips(x_low, x_high, marked, origin, width, periodic):
    """Whether ``[x_low, x_high]`` touches a strip that :func:`mark_strips` marked (an empty
    interval touches none, an unbounded one every strip)."""
    if x_low > x_high:
        return False
    if not (math.isfinite(x_low) and math.isfinite(x_high)):
        return True
    first, last = _strip_range(x_low, x_high, origin, width, periodic)
    if not periodic:
        first, last = max(first, 0), min(last, N_STRIPS - 1)
    if last - first >= N_STRIPS:
        last = first + N_STRIPS - 1
    for s in range(first, last + 1):
        if marked[s % N_STRIPS]:
            return True
    return False


@jit(inline="always")
def _strip_range(x_low, x_high, origin, width, periodic):
    """The first and last strip index of ``[x_low, x_high]`` (unwrapped, periodic: may leave
    ``0 .. N_STRIPS - 1``; otherwise clamped to ``-1 .. N_STRIPS``, outside the strips)."""
    first = math.floor((x_low - origin) / width)
    last = math.floor((x_high - origin) / width)
    if periodic:
        if last - first >= N_STRIPS:
            last = first + N_STRIPS - 1
    else:
        first = min(max(first, -1.0), float(N_STRIPS))
        last = min(max(last, -1.0), float(N_STRIPS))
    return int(first), int(last)
