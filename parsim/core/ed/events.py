"""The event queue of an event-driven run: pair collisions, wall contacts and re-bins.

A binary heap in arrays (:mod:`parsim.core.eventqueue`) orders the events by time, then by
insertion sequence, so that ties resolve the same way every run.  An event records the version
stamps of the clusters it involves; it is stale, and dropped when popped, unless they still
match.  An event later than the pending re-bin of either cluster is certain to go stale (the
re-bin re-predicts everything), so it is never queued.
"""

from typing import NamedTuple

import numpy as np

from parsim.core.ed.frames import pair_time, rebin_time, wall_time
from parsim.core.eventqueue import heap_filter, heap_grow, heap_new, heap_pop, heap_push
from parsim.core.jit import jit

# Event kinds, and the payload field a kind leaves unused.  Numpy scalars, not Python ints:
# numba types a constant argument as a literal and would compile heap_push once per value.
PAIR, WALL, REBIN = np.int64(0), np.int64(1), np.int64(2)
UNUSED = np.int64(0)


class EventQueue(NamedTuple):
    """The heap's arrays (reallocated when it grows), its size and the next insertion number."""

    times: np.ndarray
    seqs: np.ndarray
    data: np.ndarray  #: (capacity, NFIELDS): kind, two payload fields, two version stamps
    size: np.int64
    seq: np.int64


@jit
def is_current(f0, f1, f2, f3, f4, cl, ver):
    """Whether an event's recorded version stamps are still its clusters' stamps."""
    if f0 == PAIR:
        return ver[cl[f1]] == f3 and ver[cl[f2]] == f4
    return ver[f1] == f3


@jit
def reserve(queue, need, cl, ver):
    """Make room for ``need`` more events: drop stale ones, grow if still > half full."""
    ht, hs, hd, size = queue.times, queue.seqs, queue.data, queue.size
    cap = ht.shape[0]
    if size + need <= cap:
        return queue
    keep = np.empty(size, dtype=np.bool_)
    for k in range(size):
        keep[k] = is_current(hd[k, 0], hd[k, 1], hd[k, 2], hd[k, 3], hd[k, 4], cl, ver)
    size = heap_filter(ht, hs, hd, size, keep)
    if 2 * (size + need) > cap:
        new_cap = max(2 * cap, 2 * (size + need))
        ht, hs, hd = heap_grow(ht, hs, hd, size, new_cap)
    return EventQueue(ht, hs, hd, size, queue.seq)


@jit(inline="always")  # one call site, in the event loop: a call would pass every array of the bundles
def next_event(queue, ev, clusters):
    """Pop events until a current one, into ``ev``: ``(found, time, queue)``."""
    ht, hs, hd, size = queue.times, queue.seqs, queue.data, queue.size
    te = np.inf
    found = False
    while size > 0:
        te, _s, size = heap_pop(ht, hs, hd, size, ev)
        if is_current(ev[0], ev[1], ev[2], ev[3], ev[4], clusters.cl, clusters.ver):
            found = True
            break
    return found, te, EventQueue(ht, hs, hd, size, queue.seq)


@jit
def initial_events(clusters, lists, nbr, max_time, L):
    """The queue at t = 0, every sphere its own cluster: its pairs, its wall, its re-bin."""
    n = clusters.R.shape[0]
    ver, t_rebin, nn = clusters.ver, clusters.t_rebin, lists.nn
    n_pairs = 0
    for i in range(n):
        n_pairs += nn[i]
    ht, hs, hd = heap_new(max(1024, n_pairs // 2 + 2 * n))  # bound on the initial events
    size = np.int64(0)  # not literals, whose first typing would compile extra copies of the callees
    seq = np.int64(0)
    t = 0.0
    for i in range(n):
        horizon = min(t_rebin[i], max_time)
        for q in range(nn[i]):
            j = nbr[i, q]
            if j > i:
                te = pair_time(i, j, t, clusters)
                if te <= horizon and te <= t_rebin[j] and te < np.inf:
                    size = heap_push(ht, hs, hd, size, te, seq, PAIR, i, j, ver[i], ver[j])
                    seq += 1
        te, axis, sd = wall_time(i, t, clusters, L)
        if te <= horizon and te < np.inf:
            size = heap_push(ht, hs, hd, size, te, seq, WALL, i, axis * 2 + sd, ver[i], UNUSED)
            seq += 1
        if t_rebin[i] <= max_time and t_rebin[i] < np.inf:
            size = heap_push(ht, hs, hd, size, t_rebin[i], seq, REBIN, i, UNUSED, ver[i], UNUSED)
            seq += 1
    return EventQueue(ht, hs, hd, size, seq)


@jit(inline="always")  # one call site, in the event loop: a call would pass every array of the bundles
def predict_cluster(c, t, max_time, L, h, clusters, lists, nbr, queue):
    """Queue the pair events of cluster ``c``'s boundary, its wall and its re-bin event.

    Cleans the boundary list on the way (drops spheres without neighbours).  Returns the
    queue.
    """
    cl, ver, t_rebin = clusters.cl, clusters.ver, clusters.t_rebin
    nn, inb, bnext, bhead, btail = lists.nn, lists.inb, lists.bnext, lists.bhead, lists.btail
    prev = -1
    k = bhead[c]
    need = 2
    while k >= 0:
        nk = bnext[k]
        if nn[k] == 0:
            inb[k] = 0
            if prev < 0:
                bhead[c] = nk
            else:
                bnext[prev] = nk
            if nk < 0:
                btail[c] = prev
        else:
            need += nn[k]
            prev = k
        k = nk
    queue = reserve(queue, need, cl, ver)
    ht, hs, hd, size, seq = queue
    vc = ver[c]
    # Events after a cluster's next re-bin are certainly stale (the re-bin gives it a new
    # version and re-predicts everything): queue only those before both re-bins.
    t_next = rebin_time(c, t, clusters.D, clusters.V, clusters.T0, h)
    t_rebin[c] = t_next
    horizon = min(t_next, max_time)
    k = bhead[c]
    while k >= 0:
        for q in range(nn[k]):
            j = nbr[k, q]
            cj = cl[j]
            if cj == c:
                continue
            te = pair_time(k, j, t, clusters)
            if te <= horizon and te <= t_rebin[cj] and te < np.inf:
                size = heap_push(ht, hs, hd, size, te, seq, PAIR, k, j, vc, ver[cj])
                seq += 1
        k = bnext[k]
    te, axis, side = wall_time(c, t, clusters, L)
    if te <= horizon and te < np.inf:
        size = heap_push(ht, hs, hd, size, te, seq, WALL, c, axis * 2 + side, vc, UNUSED)
        seq += 1
    if t_next <= max_time and t_next < np.inf:
        size = heap_push(ht, hs, hd, size, t_next, seq, REBIN, c, UNUSED, vc, UNUSED)
        seq += 1
    return EventQueue(ht, hs, hd, size, seq)
