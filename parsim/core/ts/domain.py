"""Where the spheres of a time-stepping run live: the stepper's one interface to other processes.

The stepper (:mod:`parsim.core.ts.stepper`) keeps the rows of the spheres its process owns,
named by their global ids, and calls the members of a *domain* wherever a step needs spheres
or sums of other processes.  :class:`SerialDomain` owns every sphere and exchanges nothing;
:class:`parsim.aggregation.tiled.DecomposedDomain` shares the box out among MPI ranks with the
same members, so the same stepper runs serially and decomposed (see docs/architecture.md).

Members:

- ``distribute(X, V, tile_side)`` -> ``(global_id, X, V)`` of the spheres owned here, at the
  start; ``tile_side`` is the least width of the tiles ranks own (the halo width);
- ``redistribute(global_id, X, V)``: the same after the spheres moved (migration, balance);
- ``hold_everything(global_id, X, V)``: from then on every process holds every sphere (the rows
  of all, by global id) and runs alone, ``size`` 1;
- ``ghosts(X, global_id, width)``: a halo of the spheres of other processes within ``width``
  of this one's sub-box: ``n_ghost``, ``ghost_global_id`` and ``exchange(values)`` (the
  ghosts' rows of per-owned-sphere ``values``); ``max_halo_width`` bounds ``width``;
- ``problem_exchange(halo, margin)``: the minimiser's exchange (:class:`SerialExchange`),
  which stops a minimisation when a sphere moves farther than ``margin``;
- ``sum``, ``max``, ``min`` of a float, ``sum_array`` elementwise, ``gather(rows)`` the
  concatenation of every process's rows in rank order, ``imbalance(work)`` max / mean;
- ``close()`` at the end of the run (a domain serves one run).
"""

import math

import numpy as np

from parsim.core.ts.daha import SerialExchange


class _NoHalo:
    """The halo of a process that owns the whole box: no ghosts."""

    n_ghost = 0
    ghost_global_id = np.empty(0, dtype=np.int64)

    def exchange(self, values):
        values = np.asarray(values)
        return np.empty((0, *values.shape[1:]), dtype=np.float64)


class SerialDomain:
    """Every sphere on this process; every exchange is empty and every reduction the identity."""

    size = 1
    max_halo_width = math.inf

    def distribute(self, X, V, tile_side):
        return np.arange(X.shape[0], dtype=np.int64), X, V

    def redistribute(self, global_id, X, V):
        return global_id, X, V

    def hold_everything(self, global_id, X, V):
        return global_id, X, V

    def ghosts(self, X, global_id, width):
        return _NoHalo()

    def problem_exchange(self, halo, margin):
        return SerialExchange()

    def sum(self, value):
        return value

    def max(self, value):
        return value

    def min(self, value):
        return value

    def sum_array(self, values):
        return values

    def gather(self, rows):
        return rows

    def imbalance(self, work):
        return 1.0

    def close(self):
        return None
