"""The largest cluster's flights and wall reflections kept as a log, applied to a row when it is read.

In a late stage one cluster holds nearly every sphere and a few small clusters wander; the run
then makes tens of thousands of quiet stretches and wall reflections (N = 250 000, V_f 0.2:
22 million time steps, 21 800 reflections).  Each moves every sphere: a quiet stretch and the
step after it translate all rows (items i of section 3, ``X += duration V``), a reflection
shifts the whole cluster across the wall (item ii).  Done row by row that is three passes over
all spheres per reflection, nearly half of that run's time.

Between merges the cluster only translates, and all its spheres carry the same velocity
(eq. 2.9 gives every sphere of a cluster its momentum / mass; a reflection turns them alike).
Each row of the cluster therefore receives the same sequence of increments: ``duration * V_c``
for a flight, the shift for a reflection.  :class:`DeferredFlight` appends them to a log
instead, and brings a row up to date when it is read (the few rows that can reach a wall
first, those near a path of a small cluster) or all of them when the cluster is about to
change (a merge, the end of the run).  A row receives the increments in the order the eager
code would have added them, each rounded alike, so its position is the same bit for bit; the
one exception, ``-0.0 + 0.0``, is a centre exactly on a wall, which the reflections rule out.
Bringing every row up to date runs the log over blocks of rows held in registers: the same
additions without a pass over memory per increment.
"""

import numpy as np

from parsim.core.jit import jit

#: Rows brought up to date together (held in a small array while the log runs over them).
BLOCK_ROWS = 64

#: Increments kept at most; then every row is brought up to date and the log starts again.
MAX_INCREMENTS = 1 << 16


@jit
def catch_up(X, V, j, increments, applied, velocity):
    """Bring row ``j`` up to date: add the increments it has not received (``applied[j]`` is
    how many it has; rows outside the cluster hold ``len(increments)`` or more) and give it
    the cluster's ``velocity``."""
    count = increments.shape[0]
    if count == 0 or applied[j] >= count:
        return
    for k in range(applied[j], count):
        for a in range(X.shape[1]):
            X[j, a] += increments[k, a]
    for a in range(X.shape[1]):
        V[j, a] = velocity[a]
    applied[j] = count


@jit
def catch_up_rows(X, V, rows, increments, applied, velocity):
    """:func:`catch_up` of every row of ``rows``, ``BLOCK_ROWS`` at a time: the log runs once
    per block over the block's coordinates, held apart axis by axis so that the additions of a
    block run side by side (each row still adds its own increments, in order; a row that has
    one already adds 0)."""
    count = increments.shape[0]
    d = X.shape[1]
    block = np.empty((d, BLOCK_ROWS))
    since = np.empty(BLOCK_ROWS, dtype=np.int64)
    for start in range(0, rows.shape[0], BLOCK_ROWS):
        size = min(BLOCK_ROWS, rows.shape[0] - start)
        first = count
        for b in range(size):
            j = rows[start + b]
            since[b] = applied[j]
            first = min(first, since[b])
            for a in range(d):
                block[a, b] = X[j, a]
        for a in range(d):
            coordinates = block[a]
            for k in range(first, count):
                increment = increments[k, a]
                for b in range(size):
                    coordinates[b] += increment if since[b] <= k else 0.0
        for b in range(size):
            j = rows[start + b]
            if since[b] < count:
                for a in range(d):
                    X[j, a] = block[a, b]
                    V[j, a] = velocity[a]
                applied[j] = count


@jit
def translate_rows(X, V, duration, rows):
    """``X += duration V`` for the rows ``rows`` only (:func:`parsim.core.ts.clusters.translate`)."""
    for i in rows:
        for a in range(X.shape[1]):
            X[i, a] += duration * V[i, a]


class DeferredFlight:
    """The log of one cluster's increments, for its rows ``rows`` of ``X`` (``n`` rows, all of
    whose velocities are the cluster's, ``V[rows[0]]``)."""

    def __init__(self, X, V, rows):
        n, d = X.shape
        self.rows = rows
        self.velocity = V[rows[0]].copy()
        self._log = np.empty((64, d))
        self._count = 0
        self.applied = np.full(n, np.iinfo(np.int64).max, dtype=np.int64)  # rows outside: never behind
        self.applied[rows] = 0

    @property
    def increments(self):
        """The increments logged so far, oldest first, shape ``(count, d)``."""
        return self._log[:self._count]

    def log(self, V):
        """What the kernels that read rows of the cluster take to bring them up to date:
        ``(V, increments, applied, velocity)`` (:func:`catch_up`)."""
        return V, self.increments, self.applied, self.velocity

    def fly(self, X, V, duration):
        """The cluster's flight by ``duration`` at its velocity (``duration * V`` as the eager
        flight rounds it)."""
        self._append(X, V, duration * self.velocity)

    def reflect(self, X, V, axis, shift, sign):
        """A wall reflection of the cluster along ``axis``: shifted by ``shift``, the velocity
        component turned to the sign ``sign`` (:func:`parsim.core.ts.clusters.apply_reflections`)."""
        increment = np.zeros(X.shape[1])
        increment[axis] = shift
        self._append(X, V, increment)
        self.velocity[axis] = sign * abs(self.velocity[axis])

    def bring_up_to_date(self, X, V, rows):
        """Bring the rows ``rows`` up to date (any rows; those outside the cluster are)."""
        catch_up_rows(X, V, rows, self.increments, self.applied, self.velocity)

    def settle(self, X, V):
        """Bring every row of the cluster up to date; the log can then be dropped."""
        self.bring_up_to_date(X, V, self.rows)

    def _append(self, X, V, increment):
        if self._count == MAX_INCREMENTS:  # bound the log: apply it and start again
            self.settle(X, V)
            self._count = 0
            self.applied[self.rows] = 0
        if self._count == self._log.shape[0]:
            self._log = np.concatenate([self._log, np.empty_like(self._log)])
        self._log[self._count] = increment
        self._count += 1
