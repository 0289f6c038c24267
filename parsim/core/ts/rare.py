"""Kernels of the time stepping that a small run seldom reaches, run once on three spheres so that a
warm-up compiles them, or loads them from the cache, before any task is timed.

They are the refresh of candidate pairs inside a long minimisation (module
:mod:`~parsim.core.ts.daha`, "Candidate pairs"), which the warm-up's few spheres never drift far
enough to need, and the pairs with a ghost end, which only a run on several ranks has.  A task
that met them first would compile them inside its wall time (a few seconds).  The arrays have
the dtypes and layouts of the real calls, so the compiled versions are the ones those calls use.
"""

import numpy as np

from parsim.core.ts.contacts import BinnedRows, updated_candidate_pairs
from parsim.core.ts.daha.pairs import _carried, _rebase
from parsim.core.ts.problem import _cross_pairs


def compile_rare_kernels(dimension: int) -> None:
    """Three spheres in a row of ``dimension`` dimensions, two moving and the third a ghost: their pairs
    refreshed after the first has drifted, and their cross pairs found."""
    positions = np.zeros((3, dimension))
    positions[:, 0] = (0.0, 1.05, 2.1)
    radii = np.full(3, 0.5)
    reach = 0.1
    n_moving = first_ghost = 2
    pair_a, pair_b = np.array([0, 1]), np.array([1, 2])
    binned = BinnedRows(positions, radii, reach)
    built_at = positions.copy()
    positions[0, 0] -= 0.05
    moved = np.zeros(3, dtype=np.bool_)
    _rebase(positions, built_at, n_moving, first_ghost, 0.01, moved)
    fresh_a, fresh_b, source = updated_candidate_pairs(positions, radii, n_moving, reach, pair_a, pair_b, moved,
                                                       binned)
    _carried(source, np.zeros(2), np.zeros(2), positions, radii, fresh_a, fresh_b)
    moving_ghost = np.array([False, False, True])
    _cross_pairs(fresh_a, fresh_b, np.arange(3), moving_ghost)
