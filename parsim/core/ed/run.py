"""The event loop of an event-driven run, from the initial events to the final state."""

from typing import NamedTuple

import numpy as np

from parsim.core.ed.collisions import merge, new_record, reflect
from parsim.core.ed.events import PAIR, WALL, initial_events, next_event, predict_cluster
from parsim.core.ed.frames import new_clusters, position, restamp
from parsim.core.ed.neighbours import new_grid, new_lists, rebin_cluster
from parsim.core.eventqueue import NFIELDS
from parsim.core.jit import jit

#: A cluster is re-binned when it has moved (1 - REBIN_MARGIN) * skin / 2 since binning,
#: so the guaranteed gap of unlisted pairs, skin * REBIN_MARGIN, dwarfs round-off in the
#: lazily evaluated positions (~1e-16 L).
REBIN_MARGIN = 1e-6

STOP_REASONS = ("single_cluster", "max_time", "max_events")
SINGLE, MAX_TIME, MAX_EVENTS = 0, 1, 2


class RunOutcome(NamedTuple):
    """What :func:`simulate` returns; ``reason`` indexes ``STOP_REASONS``."""

    positions: np.ndarray
    velocities: np.ndarray
    cluster: np.ndarray  #: (n,) raw cluster labels (the surviving cluster numbers)
    links: np.ndarray
    merge_times: np.ndarray
    time: float
    n_events: int
    n_collisions: int
    n_wall_reflections: int
    n_rebins: int
    reason: int
    momentum_before: np.ndarray
    momentum_after: np.ndarray


@jit
def final_state(t, clusters, x):
    """Every sphere's centre and velocity at ``t``: ``(positions, velocities)``."""
    n, d = clusters.P.shape
    positions = np.empty((n, d))
    velocities = np.empty((n, d))
    for i in range(n):
        position(i, t, clusters, x)
        for a in range(d):
            positions[i, a] = x[a]
            velocities[i, a] = clusters.V[clusters.cl[i], a]
    return positions, velocities


@jit
def simulate(X0, V0, R, m, L, max_time, max_events, skin, k_side, side, momenta):
    """Run the events from t = 0 until one cluster remains, ``max_time`` or ``max_events``.

    A popped pair event merges two clusters (eq. 2.9), a wall event reflects one (eq. 2.2), a
    re-bin event rebuilds one's neighbour lists; the cluster changed then gets its events
    predicted anew.  Returns a :class:`RunOutcome`.
    """
    n, d = X0.shape
    h = 0.5 * skin * (1.0 - REBIN_MARGIN)
    clusters = new_clusters(X0, V0, R, m, h)
    grid = new_grid(X0, side, k_side)
    lists, nbr = new_lists(clusters, grid, skin)
    queue = initial_events(clusters, lists, nbr, max_time, L)
    record = new_record(n, d, momenta)
    x = np.empty(d)
    ev = np.empty(NFIELDS, dtype=np.int64)

    t = 0.0
    n_clusters = n
    n_events = 0
    n_coll = 0
    n_wall = 0
    n_rebin = 0
    reason = SINGLE
    while True:
        if n_clusters <= 1:
            reason = SINGLE
            break
        if n_events >= max_events:
            reason = MAX_EVENTS
            break
        found, te, queue = next_event(queue, ev, clusters)
        if not found or te > max_time:
            # Nothing happens before max_time (with max_time = inf: every cluster is at
            # rest, so the configuration is final and the clock stays where it is).
            reason = MAX_TIME
            if max_time < np.inf:
                t = max_time
            break
        t = te
        c = ev[1]
        if ev[0] == PAIR:
            nbr, c = merge(ev[1], ev[2], t, n_coll, clusters, grid, lists, nbr, x, record)
            n_coll += 1
            n_events += 1
            n_clusters -= 1
            if n_clusters <= 1:
                continue
        elif ev[0] == WALL:
            reflect(c, ev[2], t, clusters, L)
            n_wall += 1
            n_events += 1
        else:
            nbr = rebin_cluster(c, t, clusters, grid, lists, nbr, x)
            restamp(clusters, c)
            n_rebin += 1
        queue = predict_cluster(c, t, max_time, L, h, clusters, lists, nbr, queue)

    positions, velocities = final_state(t, clusters, x)
    return RunOutcome(positions, velocities, clusters.cl.copy(), record.links[:n_coll].copy(),
                      record.times[:n_coll].copy(), t, n_events, n_coll, n_wall, n_rebin, reason,
                      record.momentum_before[:n_coll].copy(), record.momentum_after[:n_coll].copy())
