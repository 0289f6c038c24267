"""The candidate pairs searched again during a minimisation (:mod:`parsim.core.ts.daha`, "Candidate pairs").

Which rows drifted far enough from where their pairs were searched, and the multiplier and
constraint value each pair carries into the refreshed lists.
"""

import math

import numpy as np

from parsim.core.jit import jit
from parsim.core.ts.contacts import _distance_sq
from parsim.core.ts.daha.scheme import _phi


@jit
def _carried(source, lam, phi, P, R, pair_a, pair_b):
    """Multiplier and constraint value of each pair after a refresh of the candidate pairs:
    those of the same pair before (``source``; ``phi`` is kept current by the multiplier
    updates), and 0 and (3.4) for a new pair."""
    new_lam = np.zeros(source.shape[0])
    new_phi = np.empty(source.shape[0])
    for p in range(source.shape[0]):
        if source[p] >= 0:
            new_lam[p] = lam[source[p]]
            new_phi[p] = phi[source[p]]
        else:
            new_phi[p] = _phi(P, R, pair_a[p], pair_b[p])
    return new_lam, new_phi


@jit
def _rebase(P, built_at, n_moving, first_ghost, far, moved):
    """Flag in ``moved`` the moving spheres (rows below ``n_moving``) and the ghost rows (from
    ``first_ghost`` on) more than ``far`` from ``built_at``, where their pairs are to be searched
    again, and move their ``built_at`` to ``P``; returns how far the other moving spheres are
    from theirs at most.  A ghost row holds its owner's positions, from the same start, and is
    rebased at the same iterations: it is flagged as its owner flags it, with no exchange."""
    largest = 0.0
    for i in range(n_moving):
        distance_sq = _distance_sq(P, i, built_at, i)
        if not _flag_moved(P, built_at, i, distance_sq > far * far, moved):
            largest = max(largest, distance_sq)
    for i in range(first_ghost, P.shape[0]):
        _flag_moved(P, built_at, i, _distance_sq(P, i, built_at, i) > far * far, moved)
    return math.sqrt(largest)


@jit
def _flag_moved(P, built_at, i, far_off, moved):
    """``moved[i] = far_off``, and a row far off is rebased at ``P``; returns ``far_off``."""
    moved[i] = far_off
    if far_off:
        for k in range(P.shape[1]):
            built_at[i, k] = P[i, k]
    return far_off
