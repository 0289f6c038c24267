"""One cluster's spheres binned in the cluster's own frame, for the watch's searches of a late
stage (:mod:`parsim.core.ts.quiet`).

Between merges a cluster only translates: free flight moves all its spheres by the same
vector, and a wall reflection shifts it as a whole (items i and ii of section 3).  Its
spheres, binned once into cells, therefore stay binned if every lookup is made in the frame
that moves with the cluster: a point ``x`` is looked up at ``x - s``, with ``s`` how far
the cluster's reference sphere has moved since the binning.

In a late stage one large cluster holds nearly every sphere, and the watch is renewed from
the few spheres outside it every hundred steps or so.  A renewal that sorted every sphere
into cells again cost O(N) each time; with the large cluster
binned in its frame it costs what the cells around the few queries hold.  With fewer
still outside, the stepper follows their straight paths through the frame to the first
possible contact (:meth:`ClusterFrame.first_contact`) and keeps no watch at all.
"""

import math
from typing import NamedTuple

import numpy as np

from parsim.core.celllist import cells_over, grid_size
from parsim.core.jit import jit
from parsim.core.ts.contacts import _distance_sq, _sorted_by_cell, _with_pair
from parsim.core.ts.deferred import catch_up
from parsim.core.ts.quiet import time_to_contact

#: The search looks this much farther, relatively: the spheres' positions are rounded at
#: every flight, so the frame's shift matches each sphere's own only to within round-off.
ROUNDING_PAD = 1e-6

#: Cells per search distance: a query scans the cells within that distance of its own, about
#: ``(2 + 1/4)^d`` times the search distance to the ``d``, against ``3^d`` with cells one
#: search distance wide.
CELLS_PER_CUTOFF = 4

#: The cells a frame is binned into, at most, per sphere (as the whole-box searches).
CELLS_PER_SPHERE = 4


class BinnedFrame(NamedTuple):
    """Rows of ``X`` binned where they were, in ``k^d`` cells of side ``side``, sorted cell by
    cell: those of cell ``c`` are ``rows[first[c]:first[c + 1]]``, the ``s``-th of them binned at
    ``X[s]`` with radius ``R[s]``, none larger than ``largest``."""

    rows: np.ndarray  #: (n,) the rows, cell by cell
    X: np.ndarray  #: (n, d) their positions when binned
    R: np.ndarray  #: (n,) their radii
    largest: float  #: the largest radius, 0 if none
    first: np.ndarray  #: (k^d + 1,) each cell's first place in ``rows``
    side: float  #: the cells' side
    k: int  #: cells per side


@jit
def _pairs_in_frame(X, R, queries, reach, shift, binned, log):
    """Pairs ``(q, j)``, ``q`` in ``queries``, ``j`` in the :class:`BinnedFrame` ``binned``, with
    a gap ``|X_q - X_j| - R_q - R_j <= reach``.  Each query scans the cells within its search
    distance of ``X_q - shift``; the frame's positions select the candidates, within a padded
    distance, and the pairs are decided on ``X``, by the test of the whole-box searches, each
    candidate first brought up to date from the ``log`` of deferred flights
    (:mod:`parsim.core.ts.deferred`)."""
    binned_rows, binned_X, binned_R, first = binned.rows, binned.X, binned.R, binned.first
    d = X.shape[1]
    y = np.empty(d)
    pairs = np.empty((16, 2), dtype=np.int64)
    count = 0
    for q in queries:
        cutoff = (R[q] + binned.largest + reach) * (1.0 + ROUNDING_PAD)
        for a in range(d):
            y[a] = X[q, a] - shift[a]
        for c in cells_over(y - cutoff, y + cutoff, binned.side, binned.k):
            for s in range(first[c], first[c + 1]):
                padded = (R[q] + binned_R[s] + reach) * (1.0 + ROUNDING_PAD)
                far = 0.0
                for a in range(d):
                    far += (binned_X[s, a] - y[a]) ** 2
                if far > padded * padded:
                    continue
                j = binned_rows[s]
                catch_up(X, log[0], j, log[1], log[2], log[3])
                limit = R[q] + R[j] + reach
                if _distance_sq(X, q, X, j) <= limit * limit:
                    pairs = _with_pair(pairs, count, q, j)
                    count += 1
    return pairs[:count].copy()


@jit
def _segment_distance_sq(P, s, a, b):
    """Squared distance from row ``s`` of ``P`` to the segment from ``a`` to ``b``."""
    d = P.shape[1]
    along = norm = 0.0
    for k in range(d):
        along += (P[s, k] - a[k]) * (b[k] - a[k])
        norm += (b[k] - a[k]) ** 2
    f = min(max(along / norm, 0.0), 1.0) if norm > 0.0 else 0.0
    distance_sq = 0.0
    for k in range(d):
        distance_sq += (P[s, k] - a[k] - f * (b[k] - a[k])) ** 2
    return distance_sq


@jit
def _first_contact_in_frame(X, V, R, queries, duration, reference, shift, binned, log):
    """The earliest time within ``duration`` at which a query, flying straight at ``V_q``,
    touches a row of the :class:`BinnedFrame` ``binned``, all of which fly at the velocity of row
    ``reference``; ``inf`` if none does.  Each query's path in the frame is cut into pieces at
    most a cell long, and the cells around each piece are scanned: a row the path touches lies
    within ``R_q + R_j`` of it.  The frame's positions select the candidates, the times come
    from ``X`` and ``V`` (:func:`parsim.core.ts.quiet.time_to_contact`), each candidate first
    brought up to date from the ``log`` of deferred flights."""
    binned_rows, binned_X, binned_R, first, side = binned.rows, binned.X, binned.R, binned.first, binned.side
    d = X.shape[1]
    start = np.empty(d)
    end = np.empty(d)
    earliest = math.inf
    for q in queries:
        length = 0.0
        for a in range(d):
            length += (V[q, a] - V[reference, a]) ** 2
        length = math.sqrt(length) * duration
        pieces = max(1, int(math.ceil(length / side)))
        reach = (R[q] + binned.largest) * (1.0 + ROUNDING_PAD)
        for piece in range(pieces):
            for a in range(d):
                u = V[q, a] - V[reference, a]
                start[a] = X[q, a] - shift[a] + u * duration * piece / pieces
                end[a] = X[q, a] - shift[a] + u * duration * (piece + 1) / pieces
            for c in cells_over(np.minimum(start, end) - reach, np.maximum(start, end) + reach, side, binned.k):
                for s in range(first[c], first[c + 1]):
                    padded = (R[q] + binned_R[s]) * (1.0 + ROUNDING_PAD)
                    if _segment_distance_sq(binned_X, s, start, end) <= padded * padded:
                        catch_up(X, log[0], binned_rows[s], log[1], log[2], log[3])
                        earliest = min(earliest, time_to_contact(X, V, R, q, binned_rows[s]))
    return earliest


class ClusterFrame:
    """The rows ``rows`` of ``X`` (one cluster's spheres, radii ``R``), binned where they are
    now over the box ``[0, box_length]^d``, in cells sized for searches up to ``cutoff``
    (``2 max R`` plus the gap searched; a search of any gap is right, one of about that gap
    fast).

    Valid while the rows move together by translations; the caller renews it after a merge
    or when rows change places.
    """

    def __init__(self, X, R, rows, cutoff, box_length):
        self.rows = rows
        self.cutoff = cutoff
        self.k, self.side = grid_size(box_length, cutoff / CELLS_PER_CUTOFF, X.shape[1], max(rows.size, 1),
                                      CELLS_PER_SPHERE)
        self._origin = X[rows[:1]].copy()  # where the reference sphere (the first row) was binned
        order, first, _ = _sorted_by_cell(X[rows], self.side, self.k)
        binned_rows = rows[order]
        binned_R = R[binned_rows]
        self._binned = BinnedFrame(binned_rows, X[binned_rows], binned_R, float(binned_R.max(initial=0.0)), first,
                                   self.side, self.k)

    def pairs_near(self, X, R, queries, reach, log=None):
        """Pairs ``(q, j)`` of rows, ``q`` in ``queries``, ``j`` in the frame, with a gap of at
        most ``reach`` (``X``: the rows' positions now, ``R``: their radii; ``log``: the
        deferred flights of the frame's rows, :meth:`parsim.core.ts.deferred.DeferredFlight.log`)."""
        if self.rows.size == 0:
            return np.empty((0, 2), dtype=np.int64)
        log = no_log(X.shape[1]) if log is None else log
        return _pairs_in_frame(X, R, queries, reach, self._shift(X, log), self._binned, log)

    def first_contact(self, X, V, R, queries, duration, log=None):
        """The earliest time within ``duration`` at which one of the rows ``queries`` touches a
        row of the frame, every row flying straight (the frame's rows at one velocity); ``inf``
        if none does; ``log`` as for :meth:`pairs_near`."""
        if self.rows.size == 0:
            return math.inf
        log = no_log(X.shape[1]) if log is None else log
        return _first_contact_in_frame(X, V, R, queries, duration, self.rows[0], self._shift(X, log), self._binned,
                                       log)

    def _shift(self, X, log):
        """How far the frame's rows have moved since they were binned (its reference row brought
        up to date first)."""
        catch_up(X, log[0], self.rows[0], log[1], log[2], log[3])
        return X[self.rows[0]] - self._origin[0]


def no_log(dimension):
    """The ``log`` of rows that are all up to date (no deferred flight)."""
    return (np.empty((0, dimension)), np.empty((0, dimension)), np.empty(0, dtype=np.int64), np.zeros(dimension))
