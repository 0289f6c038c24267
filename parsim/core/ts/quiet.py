"""Quiet time steps: how many of the coming steps certainly change nothing but positions.

In the late stage of an aggregation a few slow clusters drift for thousands of time steps
before the next collision, and each step would pay a contact search over the whole box.
Over ``j`` steps of constant ``dt`` two spheres approach by at most ``j dt |V_i - V_j|``
(straight lines), so a pair with gap ``g`` cannot touch while ``j dt |V_i - V_j| < g``;
a cluster whose bounding box is inside the box reaches a wall after a number of steps
read off its velocity.  The stepper advances all those steps with one advection: the
steps still happen (time, histories, the dt law), only the searches that would have
found nothing are skipped.  Bounds are taken conservatively (round-off shortens them).
"""

import math

import numpy as np

from parsim.core.celllist import block_cells, build_cells, neighbour_offsets
from parsim.core.jit import jit

#: Relative safety margin on every bound, far above round-off.
MARGIN = 1e-9


@jit
def _steps_before(distance, closing):
    """Largest ``j >= 0`` with ``j closing < distance`` (less the margin); ``closing >= 0``."""
    if distance <= 0.0:
        return 0.0
    if closing <= 0.0:
        return math.inf
    return math.floor(distance * (1.0 - MARGIN) / closing)


@jit
def _steps_before_contact(X, V, R, cluster, queries, dt, fastest, horizon, side, k):
    """Steps during which no two spheres of different clusters can touch.

    Every pair of different clusters has an end in ``queries``.  Pairs with a gap up to
    ``horizon`` are examined one by one; every other pair is at least ``horizon`` apart
    and closes by at most ``2 fastest dt`` per step.  The grid (``k`` cells per side of
    length ``side >= 2 max R + horizon``) covers the points.  The scan is the one of
    :func:`parsim.core.ts.contacts._near_pairs`, reduced on the fly: with the horizon of
    a late-stage search, collecting the pairs first made the run several times slower.
    """
    n, d = X.shape
    steps = _steps_before(horizon, 2.0 * fastest * dt)
    head, nxt, _, cell_of, _ = build_cells(X, side, k)
    offsets = neighbour_offsets(d)
    coords = np.empty(d, dtype=np.int64)
    block = np.empty(offsets.shape[0], dtype=np.int64)
    for i in queries:
        nb = block_cells(cell_of[i], k, offsets, coords, block)
        for b in range(nb):
            j = head[block[b]]
            while j >= 0:
                if cluster[j] != cluster[i]:
                    s = 0.0
                    w = 0.0
                    for a in range(d):
                        dx = X[i, a] - X[j, a]
                        dv = V[i, a] - V[j, a]
                        s += dx * dx
                        w += dv * dv
                    gap = math.sqrt(s) - R[i] - R[j]
                    if gap <= horizon:
                        steps = min(steps, _steps_before(gap, math.sqrt(w) * dt))
                j = nxt[j]
    return steps


@jit
def _steps_before_wall(X, V, R, rows, box_length, dt):
    """Steps during which none of the spheres ``rows`` gets outside ``[0, L]^d`` (no reflection).
    Sphere by sphere: the minimum over a cluster's spheres is the cluster's bound."""
    steps = math.inf
    for i in rows:
        for a in range(X.shape[1]):
            if V[i, a] < 0.0:
                steps = min(steps, _steps_before(X[i, a] - R[i], -V[i, a] * dt))
            elif V[i, a] > 0.0:
                steps = min(steps, _steps_before(box_length - (X[i, a] + R[i]), V[i, a] * dt))
    return steps


def quiet_steps(X, V, R, cluster, n_owned, largest, box_length, dt, fastest, horizon, side, k):
    """How many of the next time steps of length ``dt`` can make no contact and no wall
    reflection (a float, possibly ``inf``) for the first ``n_owned`` rows; see the module
    docstring.  The other rows are ghosts (spheres of other processes within ``2 max R +
    horizon``), read as partners only; the caller takes the minimum over processes.

    ``fastest`` is ``max |V_i|`` over all spheres; ``horizon`` the gap up to which pairs are
    examined one by one; the cell grid (``k`` per side of length ``side``) must have
    ``side >= 2 max R + horizon``.  Every pair of different clusters has an end outside the
    ``largest`` cluster, so the pairs are searched from those spheres (in the late stage, a few).
    """
    owned = np.arange(n_owned)
    walls = _steps_before_wall(X, V, R, owned, box_length, dt)
    if walls == 0.0:
        return 0.0
    queries = np.flatnonzero(cluster[:n_owned] != largest)
    return min(walls, _steps_before_contact(X, V, R, cluster, queries, dt, fastest, horizon, side, k))
