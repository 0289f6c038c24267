"""Event-driven (ED) ballistic aggregation of hard spheres (Degond et al. 2024, section 2, SM A).

Model
-----
``n`` hard spheres (discs for d = 2) with radii ``R_i`` and masses ``m_i`` move freely in
the box ``[0, L]^d`` (walls, not periodic).  A sphere touching a wall reflects its whole
cluster specularly (eq. 2.2 applied to the cluster velocity: the component normal to
the wall changes sign).  Two spheres of different clusters that touch merge the two
clusters into one rigid cluster that translates, without rotating, with the
mass-weighted velocity (eq. 2.9).  Clusters never break.  Pair collision times are
eq. A.3; a pair that already overlaps by round-off and approaches collides at once
(negative times are clamped to 0), an overlapping pair that separates never collides.
The run stops when one cluster remains, at ``max_time`` or after ``max_events``
physical events (collisions + wall reflections).

Algorithm (why it is not O(N^2))
--------------------------------
The paper's ED method tests all pairs at every event.  Here a velocity change costs
O(1) plus the re-prediction of the pairs a cluster has with *nearby* foreign spheres,
a merge costs O(smaller cluster) on top, and keeping the neighbour lists valid costs
O(cluster size) each time a cluster has moved half a skin:

* **Lazy cluster frames.**  Sphere ``i`` stores an offset ``P_i`` in the frame of its
  cluster ``c``; the cluster stores an origin ``O_c`` at reference time ``T0_c`` and its
  velocity ``V_c``: ``X_i(t) = O_c + V_c (t - T0_c) + P_i``.  A velocity change rebases
  ``O_c, T0_c`` in O(1); nothing is stored per sphere about time.
* **Merge by size.**  The spheres of the smaller cluster are relabelled into the larger
  one (offsets rebased), the per-cluster sphere linked lists are concatenated through
  head/tail pointers in O(1), masses add, momenta give the new velocity (eq. 2.9), and
  the cluster's bounding box in its own frame (per-axis min/max of ``P_i -/+ R_i``) is
  extended by the smaller one's spheres.  Total relabelling work is O(N log N).
* **Walls from the bounding box.**  A cluster's next wall event is the first time its
  box reaches 0 or ``L`` along an axis it moves towards; clamped at 0, so a merged
  cluster already touching a wall and moving outwards reflects at once.  A cluster
  whose box touches both walls of an axis (it spans the box, possible only by
  round-off) would reflect infinitely often at one instant; its velocity component
  along that axis is set to 0 instead (documented exception to eq. 2.2).
* **Neighbour lists on binned positions.**  Each sphere has a binned position ``Xb_i``
  in a fixed cell grid (cell side >= ``2 R_max + skin``).  All spheres of a cluster share
  one displacement since binning ``delta_c = X_i - Xb_i`` (stored lazily like ``O_c``).
  Sphere ``i`` keeps the list of spheres ``j`` of *other* clusters with
  ``|Xb_i - Xb_j| < R_i + R_j + skin`` (symmetric, growable, never truncated).  While
  every ``|delta_c| < skin / 2`` a pair absent from the lists cannot touch, so only
  listed pairs need collision events.  A per-cluster *re-bin* event fires when
  ``|delta_c|`` reaches ``skin / 2``: the cluster's spheres are re-binned
  (``delta_c = 0``) and their lists rebuilt, O(cluster size); a sphere whose block of
  3^d cells holds only its own cluster's spheres (known from per-cell counts, without
  scanning the cells) needs no search, so the interior of a compact cluster is cheap.
  At a merge the smaller cluster's spheres are re-binned at ``X_i - delta_big`` so
  that the merged cluster again has a single ``delta`` - O(smaller size), not
  O(merged size).
* **Boundary lists.**  Each cluster keeps a linked list of its spheres that have at
  least one cross-cluster neighbour.  It is what gets re-predicted after a velocity
  change; it is cleaned lazily (spheres whose list became empty are dropped when
  visited) and rebuilt only for re-binned spheres.  So a giant cluster absorbing a
  small one costs the small one's size plus the giant's *boundary*, i.e. the number of
  foreign spheres within a skin of it - never the giant's size.
* **Event queue.**  A binary heap in arrays (:mod:`parsim.core.eventqueue`) holds pair,
  wall and re-bin events, ordered by time and then insertion sequence (deterministic
  ties).  Each cluster has a version stamp drawn from a global counter; any velocity
  change, re-bin or death of a cluster gives it a new stamp, and an event is stale
  (dropped when popped) unless the stamps it recorded still match.  An event later
  than the pending re-bin of either cluster involved is certain to go stale (the
  re-bin re-predicts everything), so it is not queued at all.  When the heap is full,
  stale events are filtered out; it is grown if that frees less than half.

Measured (benchmarks/aggregation_ed.py, d = 2, V_f = 0.2, lattice + isotropic): wall
time to a single cluster grows like N^1.1-1.2, about 5 s for N = 102400 on one core.
Strongly polydisperse radii are supported but slower: the cell side follows the
largest sphere and neighbour-list capacity follows the most crowded sphere.

Everything is float64 and deterministic: the same input gives bitwise the same output.
"""

import math
from typing import NamedTuple

import numpy as np

from parsim.core.celllist import (
    block_cells,
    build_cells,
    cell_index,
    grid_size,
    move_to_cell,
    neighbour_offsets,
    worst_overlap,
)
from parsim.core.eventqueue import NFIELDS, heap_filter, heap_grow, heap_new, heap_pop, heap_push
from parsim.core.jit import jit

__all__ = ["EDResult", "simulate_ed", "default_skin", "STOP_REASONS"]

#: Tolerance on initial overlaps and on spheres poking out of the box, relative to the
#: mean radius: input positions are typically computed to ~1e-15 relative precision.
OVERLAP_TOLERANCE = 1e-9
#: The default skin (neighbour-list margin) is chosen so that a sphere in a uniform gas
#: at the system's mean density would have this many spheres within 2 R_mean + skin.  A
#: larger skin means fewer re-bins but longer lists; measured on lattice + isotropic
#: initial conditions (N ~ 2.6e4, volume fractions 0.05-0.3, d = 2 and 3), 5-6 is
#: within ~10% of the best time everywhere (e.g. d = 2, V_f = 0.2: skin = 3 R).
DEFAULT_SKIN_NEIGHBOURS = 5.5
#: Bounds of the default skin, in mean radii.
DEFAULT_SKIN_RANGE = (0.25, 20.0)
#: A cluster is re-binned when it has moved (1 - REBIN_MARGIN) * skin / 2 since binning,
#: so the guaranteed gap of unlisted pairs, skin * REBIN_MARGIN, dwarfs round-off in the
#: lazily evaluated positions (~1e-16 L).
REBIN_MARGIN = 1e-6
#: Initial capacity of each sphere's neighbour list (doubled when one overflows).
INITIAL_NEIGHBOURS = 8

STOP_REASONS = ("single_cluster", "max_time", "max_events")
_SINGLE, _MAX_TIME, _MAX_EVENTS = 0, 1, 2
# Constants that kernels pass to other kernels are numpy scalars, not Python ints or bools:
# numba types a Python constant argument as a literal and compiles a separate copy of the
# callee for each value (heap_push was compiled seven times).
_PAIR, _WALL, _REBIN = np.int64(0), np.int64(1), np.int64(2)  # event kinds
_UNUSED = np.int64(0)  # a payload field that an event kind does not use
_GREATER_ONLY, _ANY_PARTNER = np.bool_(True), np.bool_(False)  # _attach's only_greater


class EDResult(NamedTuple):
    """Outcome of :func:`simulate_ed`."""

    positions: np.ndarray  #: (n, d) sphere centres at ``time``
    velocities: np.ndarray  #: (n, d) sphere velocities (each sphere carries its cluster's)
    cluster: np.ndarray  #: (n,) int64 cluster labels 0..n_clusters-1, by first appearance
    links: np.ndarray  #: (k, 2) int64 colliding pair (i < j) of every merge, in event order
    merge_times: np.ndarray  #: (k,) float64 time of every merge
    time: float  #: time reached
    n_events: int  #: physical events processed (collisions + wall reflections)
    n_collisions: int  #: merges (= k = n - n_clusters)
    n_wall_reflections: int  #: wall reflections of clusters
    stop_reason: str  #: "single_cluster", "max_time" or "max_events"
    merge_momentum_before: np.ndarray  #: (k, d) with record_merges, else (0, d)
    merge_momentum_after: np.ndarray  #: (k, d) with record_merges, else (0, d)
    n_rebins: int  #: re-bin (neighbour-list) events, bookkeeping only


# --------------------------------------------------------------------------- geometry


@jit
def _position(i, t, P, cl, O, V, T0, out):
    c = cl[i]
    s = t - T0[c]
    for a in range(P.shape[1]):
        out[a] = (O[c, a] + V[c, a] * s) + P[i, a]


@jit
def _rebase(c, t, O, D, V, T0):
    """Move cluster ``c``'s reference time to ``t`` (origin and displacement since binning)."""
    s = t - T0[c]
    if s != 0.0:
        for a in range(O.shape[1]):
            O[c, a] += V[c, a] * s
            D[c, a] += V[c, a] * s
    T0[c] = t


@jit
def _pair_time(i, j, t, P, R, cl, O, V, T0):
    """Absolute collision time of spheres ``i`` and ``j`` (eq. A.3), or inf."""
    ci = cl[i]
    cj = cl[j]
    si = t - T0[ci]
    sj = t - T0[cj]
    dxdv = 0.0
    dvdv = 0.0
    dxdx = 0.0
    for a in range(P.shape[1]):
        dx = ((O[ci, a] + V[ci, a] * si) + P[i, a]) - ((O[cj, a] + V[cj, a] * sj) + P[j, a])
        dv = V[ci, a] - V[cj, a]
        dxdv += dx * dv
        dvdv += dv * dv
        dxdx += dx * dx
    if dxdv >= 0.0:
        return np.inf
    rr = R[i] + R[j]
    sigma = dxdv * dxdv - dvdv * (dxdx - rr * rr)
    if sigma < 0.0:
        return np.inf
    dt = -(dxdv + math.sqrt(sigma)) / dvdv
    if dt < 0.0:  # already overlapping by round-off and approaching: collide now
        dt = 0.0
    return t + dt


@jit
def _wall_event(c, t, O, V, T0, lo, hi, L):
    """Next wall contact of cluster ``c``'s bounding box: ``(time, axis, side)``."""
    best = np.inf
    axis = -1
    side = -1
    s = t - T0[c]
    for a in range(O.shape[1]):
        v = V[c, a]
        o = O[c, a] + v * s
        if v > 0.0:
            dt = (L - (o + hi[c, a])) / v
            sd = 1
        elif v < 0.0:
            dt = (0.0 - (o + lo[c, a])) / v
            sd = 0
        else:
            continue
        if dt < 0.0:
            dt = 0.0
        if dt < best:
            best = dt
            axis = a
            side = sd
    return t + best, axis, side


@jit
def _rebin_time(c, t, D, V, T0, h):
    """Time at which ``|delta_c|`` reaches ``h``, or inf for a cluster at rest."""
    s = t - T0[c]
    vv = 0.0
    dv = 0.0
    dd = 0.0
    for a in range(D.shape[1]):
        x = D[c, a] + V[c, a] * s
        vv += V[c, a] * V[c, a]
        dv += x * V[c, a]
        dd += x * x
    if vv == 0.0:
        return np.inf
    q = dd - h * h
    if q >= 0.0:
        return t
    return t + (-dv + math.sqrt(dv * dv - vv * q)) / vv


# --------------------------------------------------------------- neighbour lists


@jit
def _mark_boundary(k, c, inb, bnext, bhead, btail):
    """Append sphere ``k`` to cluster ``c``'s boundary list unless it is on it."""
    if inb[k]:
        return
    inb[k] = 1
    bnext[k] = -1
    if btail[c] < 0:
        bhead[c] = k
    else:
        bnext[btail[c]] = k
    btail[c] = k


@jit
def _add_neighbour(nbr, nn, i, j):
    if nn[i] == nbr.shape[1]:
        grown = np.empty((nbr.shape[0], 2 * nbr.shape[1]), dtype=np.int64)
        for p in range(nbr.shape[0]):
            for q in range(nn[p]):
                grown[p, q] = nbr[p, q]
        nbr = grown
    nbr[i, nn[i]] = j
    nn[i] += 1
    return nbr


@jit
def _detach(i, nbr, nn):
    """Remove sphere ``i`` from its neighbours' lists and empty its own."""
    for q in range(nn[i]):
        j = nbr[i, q]
        last = nn[j] - 1
        for p in range(nn[j]):
            if nbr[j, p] == i:
                nbr[j, p] = nbr[j, last]
                nn[j] = last
                break
    nn[i] = 0


@jit
def _attach(i, only_greater, Xb, R, cl, skin, grid, nbr, nn, inb, bnext, bhead, btail):
    """Find the cross-cluster neighbours of ``i`` in the grid and list the pairs both ways.

    With ``only_greater`` only partners ``j > i`` are taken (initial build).  Returns the
    neighbour array (reallocated if a list overflowed).
    """
    k_side, side, offsets, cell_head, cell_next, cell_prev, cell_of, cell_count, coords, block = grid
    d = Xb.shape[1]
    ci = cl[i]
    nb = block_cells(cell_of[i], k_side, offsets, coords, block)
    for b in range(nb):
        j = cell_head[block[b]]
        while j >= 0:
            if cl[j] != ci and (not only_greater or j > i):
                s = 0.0
                for a in range(d):
                    dx = Xb[i, a] - Xb[j, a]
                    s += dx * dx
                cut = R[i] + R[j] + skin
                if s < cut * cut:
                    nbr = _add_neighbour(nbr, nn, i, j)
                    nbr = _add_neighbour(nbr, nn, j, i)
                    _mark_boundary(j, cl[j], inb, bnext, bhead, btail)
            j = cell_next[j]
    if nn[i] > 0:
        _mark_boundary(i, ci, inb, bnext, bhead, btail)
    return nbr


@jit
def _bin(k, x, Xb, grid):
    k_side, side, offsets, cell_head, cell_next, cell_prev, cell_of, cell_count, coords, block = grid
    for a in range(Xb.shape[1]):
        Xb[k, a] = x[a]
    move_to_cell(k, cell_index(Xb, k, side, k_side), cell_head, cell_next, cell_prev, cell_of, cell_count)


@jit
def _rebin_cluster(c, t, state, Xb, grid, own, nbr, lists, x):
    """Re-bin every sphere of cluster ``c`` at its position at ``t`` and rebuild its lists.

    A sphere whose 3^d cell block holds only spheres of ``c`` has no cross neighbour; it
    is recognised from per-cell counts (``own`` counts c's spheres per cell, zero on entry
    and on exit) without scanning the cells, which makes re-binning the interior of a
    large compact cluster cheap.  Returns the neighbour array.
    """
    P, R, cl, O, V, T0, D, lo, hi, ver, head, nxt, trb = state
    nn, inb, bnext, bhead, btail, skin = lists
    k_side, side, offsets, cell_head, cell_next, cell_prev, cell_of, cell_count, coords, block = grid
    _rebase(c, t, O, D, V, T0)
    for a in range(D.shape[1]):
        D[c, a] = 0.0
    bhead[c] = -1
    btail[c] = -1
    k = head[c]
    while k >= 0:
        _position(k, t, P, cl, O, V, T0, x)
        _bin(k, x, Xb, grid)
        own[cell_of[k]] += 1
        inb[k] = 0
        k = nxt[k]
    k = head[c]
    while k >= 0:
        _detach(k, nbr, nn)
        nb = block_cells(cell_of[k], k_side, offsets, coords, block)
        alone = True
        for b in range(nb):
            if own[block[b]] != cell_count[block[b]]:
                alone = False
                break
        if not alone:
            nbr = _attach(k, _ANY_PARTNER, Xb, R, cl, skin, grid, nbr, nn, inb, bnext, bhead, btail)
        k = nxt[k]
    k = head[c]
    while k >= 0:
        own[cell_of[k]] = 0
        k = nxt[k]
    return nbr


# ------------------------------------------------------------------------ events


@jit
def _valid(f0, f1, f2, f3, f4, cl, ver):
    if f0 == _PAIR:
        return ver[cl[f1]] == f3 and ver[cl[f2]] == f4
    return ver[f1] == f3


@jit
def _reserve(ht, hs, hd, size, need, cl, ver):
    """Make room for ``need`` more events: drop stale ones, grow if still > half full."""
    cap = ht.shape[0]
    if size + need <= cap:
        return ht, hs, hd, size
    keep = np.empty(size, dtype=np.bool_)
    for k in range(size):
        keep[k] = _valid(hd[k, 0], hd[k, 1], hd[k, 2], hd[k, 3], hd[k, 4], cl, ver)
    size = heap_filter(ht, hs, hd, size, keep)
    if 2 * (size + need) > cap:
        new_cap = max(2 * cap, 2 * (size + need))
        ht, hs, hd = heap_grow(ht, hs, hd, size, new_cap)
    return ht, hs, hd, size


@jit
def _predict_cluster(c, t, max_time, L, h, state, lists, nbr, ht, hs, hd, size, seq):
    """Queue the pair events of cluster ``c``'s boundary, its wall and its re-bin event.

    Cleans the boundary list on the way (drops spheres without neighbours).  Returns
    ``ht, hs, hd, size, seq``.
    """
    P, R, cl, O, V, T0, D, lo, hi, ver, head, nxt, trb = state
    nn, inb, bnext, bhead, btail, skin = lists
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
    ht, hs, hd, size = _reserve(ht, hs, hd, size, need, cl, ver)
    vc = ver[c]
    # Events after a cluster's next re-bin are certainly stale (the re-bin gives it a new
    # version and re-predicts everything): queue only those before both re-bins.
    t_rebin = _rebin_time(c, t, D, V, T0, h)
    trb[c] = t_rebin
    horizon = min(t_rebin, max_time)
    k = bhead[c]
    while k >= 0:
        for q in range(nn[k]):
            j = nbr[k, q]
            cj = cl[j]
            if cj == c:
                continue
            te = _pair_time(k, j, t, P, R, cl, O, V, T0)
            if te <= horizon and te <= trb[cj] and te < np.inf:
                size = heap_push(ht, hs, hd, size, te, seq, _PAIR, k, j, vc, ver[cj])
                seq += 1
        k = bnext[k]
    te, axis, side = _wall_event(c, t, O, V, T0, lo, hi, L)
    if te <= horizon and te < np.inf:
        size = heap_push(ht, hs, hd, size, te, seq, _WALL, c, axis * 2 + side, vc, _UNUSED)
        seq += 1
    if t_rebin <= max_time and t_rebin < np.inf:
        size = heap_push(ht, hs, hd, size, t_rebin, seq, _REBIN, c, _UNUSED, vc, _UNUSED)
        seq += 1
    return ht, hs, hd, size, seq


@jit
def _cluster_momentum(c, m, V, head, nxt, out):
    """Add ``sum_i m_i V_i`` over the spheres of cluster ``c`` to ``out``."""
    k = head[c]
    while k >= 0:
        for a in range(V.shape[1]):
            out[a] += m[k] * V[c, a]
        k = nxt[k]


# ---------------------------------------------------------------------- main loop


@jit
def _simulate(X0, V0, R, m, L, max_time, max_events, skin, k_side, side, record):
    n, d = X0.shape
    h = 0.5 * skin * (1.0 - REBIN_MARGIN)

    # Clusters: cluster i starts as sphere i.
    P = np.zeros((n, d))
    cl = np.arange(n)
    O = X0.copy()
    V = V0.copy()
    T0 = np.zeros(n)
    D = np.zeros((n, d))
    M = m.copy()
    count = np.ones(n, dtype=np.int64)
    head = np.arange(n)
    tail = np.arange(n)
    nxt = np.full(n, -1, dtype=np.int64)
    lo = np.empty((n, d))
    hi = np.empty((n, d))
    for i in range(n):
        for a in range(d):
            lo[i, a] = -R[i]
            hi[i, a] = R[i]
    ver = np.arange(n)
    gver = n
    trb = np.empty(n)  # time of each cluster's pending re-bin event
    for i in range(n):
        trb[i] = _rebin_time(i, 0.0, D, V, T0, h)
    state = (P, R, cl, O, V, T0, D, lo, hi, ver, head, nxt, trb)

    # Cell grid on binned positions and cross-cluster neighbour lists.
    Xb = X0.copy()
    cell_head, cell_next, cell_prev, cell_of, cell_count = build_cells(Xb, side, k_side)
    offsets = neighbour_offsets(d)
    grid = (k_side, side, offsets, cell_head, cell_next, cell_prev, cell_of, cell_count,
            np.empty(d, dtype=np.int64), np.empty(offsets.shape[0], dtype=np.int64))
    own = np.zeros(cell_head.shape[0], dtype=np.int64)
    nbr = np.empty((n, INITIAL_NEIGHBOURS), dtype=np.int64)
    nn = np.zeros(n, dtype=np.int64)
    inb = np.zeros(n, dtype=np.int8)
    bnext = np.full(n, -1, dtype=np.int64)
    bhead = np.full(n, -1, dtype=np.int64)
    btail = np.full(n, -1, dtype=np.int64)
    lists = (nn, inb, bnext, bhead, btail, skin)
    for i in range(n):
        nbr = _attach(i, _GREATER_ONLY, Xb, R, cl, skin, grid, nbr, nn, inb, bnext, bhead, btail)

    # Initial events.
    n_pairs = 0
    for i in range(n):
        n_pairs += nn[i]
    ht, hs, hd = heap_new(max(1024, n_pairs // 2 + 2 * n))  # bound on the initial events
    size = np.int64(0)  # not literals, whose first typing would compile extra copies of the callees
    seq = np.int64(0)
    t = 0.0
    for i in range(n):
        horizon = min(trb[i], max_time)
        for q in range(nn[i]):
            j = nbr[i, q]
            if j > i:
                te = _pair_time(i, j, t, P, R, cl, O, V, T0)
                if te <= horizon and te <= trb[j] and te < np.inf:
                    size = heap_push(ht, hs, hd, size, te, seq, _PAIR, i, j, ver[i], ver[j])
                    seq += 1
        te, axis, sd = _wall_event(i, t, O, V, T0, lo, hi, L)
        if te <= horizon and te < np.inf:
            size = heap_push(ht, hs, hd, size, te, seq, _WALL, i, axis * 2 + sd, ver[i], _UNUSED)
            seq += 1
        if trb[i] <= max_time and trb[i] < np.inf:
            size = heap_push(ht, hs, hd, size, trb[i], seq, _REBIN, i, _UNUSED, ver[i], _UNUSED)
            seq += 1

    n_links = max(n - 1, 0)
    links = np.empty((n_links, 2), dtype=np.int64)
    merge_times = np.empty(n_links)
    n_rec = n_links if record else 0
    mom_before = np.zeros((n_rec, d))
    mom_after = np.zeros((n_rec, d))
    x = np.empty(d)
    ev = np.empty(NFIELDS, dtype=np.int64)

    n_clusters = n
    n_events = 0
    n_coll = 0
    n_wall = 0
    n_rebin = 0
    reason = _SINGLE
    while True:
        if n_clusters <= 1:
            reason = _SINGLE
            break
        if n_events >= max_events:
            reason = _MAX_EVENTS
            break
        found = False
        te = np.inf
        while size > 0:
            te, _s, size = heap_pop(ht, hs, hd, size, ev)
            if _valid(ev[0], ev[1], ev[2], ev[3], ev[4], cl, ver):
                found = True
                break
        if not found or te > max_time:
            # Nothing happens before max_time (with max_time = inf: every cluster is at
            # rest, so the configuration is final and the clock stays where it is).
            reason = _MAX_TIME
            if max_time < np.inf:
                t = max_time
            break
        t = te
        kind = ev[0]

        if kind == _PAIR:
            i = ev[1]
            j = ev[2]
            ci = cl[i]
            cj = cl[j]
            _rebase(ci, t, O, D, V, T0)
            _rebase(cj, t, O, D, V, T0)
            if record:
                _cluster_momentum(ci, m, V, head, nxt, mom_before[n_coll])
                _cluster_momentum(cj, m, V, head, nxt, mom_before[n_coll])
            if count[ci] > count[cj] or (count[ci] == count[cj] and ci < cj):
                big = ci
                small = cj
            else:
                big = cj
                small = ci
            mtot = M[big] + M[small]
            for a in range(d):
                V[big, a] = (M[big] * V[big, a] + M[small] * V[small, a]) / mtot
            M[big] = mtot
            # Relabel the smaller cluster's spheres into the larger one's frame.
            first = head[small]
            k = first
            while k >= 0:
                for a in range(d):
                    P[k, a] = (O[small, a] + P[k, a]) - O[big, a]
                    if P[k, a] - R[k] < lo[big, a]:
                        lo[big, a] = P[k, a] - R[k]
                    if P[k, a] + R[k] > hi[big, a]:
                        hi[big, a] = P[k, a] + R[k]
                cl[k] = big
                inb[k] = 0
                k = nxt[k]
            nxt[tail[big]] = first
            tail[big] = tail[small]
            count[big] += count[small]
            count[small] = 0
            head[small] = -1
            tail[small] = -1
            bhead[small] = -1
            btail[small] = -1
            ver[small] = gver
            ver[big] = gver + 1
            gver += 2
            # Re-bin them so that the merged cluster has one displacement, D[big].
            k = first
            while k >= 0:
                _position(k, t, P, cl, O, V, T0, x)
                for a in range(d):
                    x[a] -= D[big, a]
                _bin(k, x, Xb, grid)
                _detach(k, nbr, nn)
                nbr = _attach(k, _ANY_PARTNER, Xb, R, cl, skin, grid, nbr, nn, inb, bnext, bhead, btail)
                k = nxt[k]
            if record:
                _cluster_momentum(big, m, V, head, nxt, mom_after[n_coll])
            links[n_coll, 0] = min(i, j)
            links[n_coll, 1] = max(i, j)
            merge_times[n_coll] = t
            n_coll += 1
            n_events += 1
            n_clusters -= 1
            if n_clusters <= 1:
                continue
            c = big

        elif kind == _WALL:
            c = ev[1]
            axis = ev[2] // 2
            wall_side = ev[2] % 2
            _rebase(c, t, O, D, V, T0)
            V[c, axis] = -V[c, axis]
            # A cluster spanning the box along this axis (round-off) cannot move along it.
            if wall_side == 1 and O[c, axis] + lo[c, axis] <= 0.0:
                V[c, axis] = 0.0
            elif wall_side == 0 and O[c, axis] + hi[c, axis] >= L:
                V[c, axis] = 0.0
            ver[c] = gver
            gver += 1
            n_wall += 1
            n_events += 1

        else:
            c = ev[1]
            nbr = _rebin_cluster(c, t, state, Xb, grid, own, nbr, lists, x)
            ver[c] = gver
            gver += 1
            n_rebin += 1

        ht, hs, hd, size, seq = _predict_cluster(c, t, max_time, L, h, state, lists, nbr,
                                                 ht, hs, hd, size, seq)

    positions = np.empty((n, d))
    velocities = np.empty((n, d))
    for i in range(n):
        _position(i, t, P, cl, O, V, T0, x)
        for a in range(d):
            positions[i, a] = x[a]
            velocities[i, a] = V[cl[i], a]
    return (positions, velocities, cl.copy(), links[:n_coll].copy(), merge_times[:n_coll].copy(),
            t, n_events, n_coll, n_wall, n_rebin, reason,
            mom_before[: (n_coll if record else 0)].copy(), mom_after[: (n_coll if record else 0)].copy())


# ------------------------------------------------------------------------ wrapper


def _as_array(name, value, shape):
    try:
        arr = np.array(value, dtype=np.float64, copy=True)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be an array of numbers: {exc}") from None
    if arr.ndim != len(shape) or any(s is not None and s != t for s, t in zip(shape, arr.shape)):
        want = "(" + ", ".join("?" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite")
    return np.ascontiguousarray(arr)


def _compact_labels(raw):
    """Relabel cluster ids to 0..k-1 in order of first appearance over the spheres."""
    _, first, inverse = np.unique(raw, return_index=True, return_inverse=True)
    rank = np.empty(first.size, dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(first.size, dtype=np.int64)
    return rank[inverse.reshape(-1)]


def default_skin(n, dimension, box_length, mean_radius):
    """Skin giving ``DEFAULT_SKIN_NEIGHBOURS`` neighbours per sphere at the mean density.

    Solves ``rho v_d (2 R + skin)^d = DEFAULT_SKIN_NEIGHBOURS`` with ``rho = n / L^d`` and
    ``v_d`` the volume of the unit d-ball, clamped to ``DEFAULT_SKIN_RANGE`` mean radii.
    """
    unit_ball = math.pi ** (dimension / 2.0) / math.gamma(dimension / 2.0 + 1.0)
    reach = (DEFAULT_SKIN_NEIGHBOURS * box_length**dimension / (n * unit_ball)) ** (1.0 / dimension)
    lo, hi = DEFAULT_SKIN_RANGE
    return min(max(reach - 2.0 * mean_radius, lo * mean_radius), hi * mean_radius)


def simulate_ed(positions, velocities, radii, masses, box_length, max_time=np.inf,
                max_events=None, skin=None, record_merges=False):
    """Run event-driven ballistic aggregation in the box ``[0, box_length]^d``.

    Parameters
    ----------
    positions, velocities : (n, d) arrays, d in 1..3
        Initial centres (every sphere inside the box, no overlaps) and velocities.
    radii, masses : (n,) arrays of positive numbers.
    box_length : float > 0.
    max_time : float >= 0, default inf
        Stop when the next event would come after this time (state returned at it).
    max_events : int >= 0 or None (no limit)
        Stop after this many physical events (collisions + wall reflections).
    skin : float > 0 or None
        Neighbour-list margin; default :func:`default_skin`.  Affects speed only, not
        the result (beyond round-off in the event times).
    record_merges : bool
        Also return the momentum of the two merging clusters before and of the merged
        cluster after each merge, summed over spheres (test hook).

    Returns
    -------
    EDResult
        ``stop_reason`` is "single_cluster", "max_time" or "max_events"; ``n_events``
        counts collisions and wall reflections (re-bin events are in ``n_rebins``).

    Raises
    ------
    ValueError
        Bad shapes or values; the message names the argument.
    """
    x = _as_array("positions", positions, (None, None))
    n, d = x.shape
    if n < 1:
        raise ValueError("positions must hold at least one sphere, got shape (0, d)")
    if not 1 <= d <= 3:
        raise ValueError(f"positions must have 1, 2 or 3 columns (the dimension), got {d}")
    v = _as_array("velocities", velocities, (n, d))
    r = _as_array("radii", radii, (n,))
    mass = _as_array("masses", masses, (n,))
    if np.any(r <= 0.0):
        raise ValueError(f"radii must be > 0, got min {r.min()!r}")
    if np.any(mass <= 0.0):
        raise ValueError(f"masses must be > 0, got min {mass.min()!r}")
    try:
        L = float(box_length)
    except (TypeError, ValueError):
        raise ValueError(f"box_length must be a number, got {box_length!r}") from None
    if not (math.isfinite(L) and L > 0.0):
        raise ValueError(f"box_length must be a finite number > 0, got {box_length!r}")
    try:
        max_time = float(max_time)
    except (TypeError, ValueError):
        raise ValueError(f"max_time must be a number, got {max_time!r}") from None
    if math.isnan(max_time) or max_time < 0.0:
        raise ValueError(f"max_time must be >= 0 (inf allowed), got {max_time!r}")
    if max_events is None:
        max_events = np.iinfo(np.int64).max
    elif isinstance(max_events, bool) or not isinstance(max_events, (int, np.integer)) or max_events < 0:
        raise ValueError(f"max_events must be an integer >= 0 or None, got {max_events!r}")
    r_mean = float(r.mean())
    if skin is None:
        skin = default_skin(n, d, L, r_mean)
    else:
        try:
            skin = float(skin)
        except (TypeError, ValueError):
            raise ValueError(f"skin must be a number, got {skin!r}") from None
        if not (math.isfinite(skin) and skin > 0.0):
            raise ValueError(f"skin must be a finite number > 0, got {skin!r}")

    tol = OVERLAP_TOLERANCE * r_mean
    below = x - r[:, None] < -tol
    above = x + r[:, None] > L + tol
    if np.any(below | above):
        i, a = np.argwhere(below | above)[0]
        raise ValueError(
            f"positions: sphere {i} (centre {x[i, a]!r} on axis {a}, radius {r[i]!r}) "
            f"is not inside the box [0, {L!r}]"
        )
    cutoff = 2.0 * float(r.max()) + skin
    k_side, side = grid_size(L, cutoff, d, n)
    if n > 1:
        i, j, gap = worst_overlap(x, r, side, k_side)
        if gap < -tol:
            raise ValueError(
                f"positions: spheres {i} and {j} overlap by {-gap!r} "
                f"(tolerance {tol!r} = {OVERLAP_TOLERANCE} x mean radius)"
            )

    out = _simulate(x, v, r, mass, L, max_time, np.int64(max_events), skin, k_side, side,
                    bool(record_merges))
    (pos, vel, raw, links, times, t, n_events, n_coll, n_wall, n_rebin, reason,
     mom_b, mom_a) = out
    return EDResult(
        positions=pos,
        velocities=vel,
        cluster=_compact_labels(raw),
        links=links,
        merge_times=times,
        time=float(t),
        n_events=int(n_events),
        n_collisions=int(n_coll),
        n_wall_reflections=int(n_wall),
        stop_reason=STOP_REASONS[reason],
        merge_momentum_before=mom_b,
        merge_momentum_after=mom_a,
        n_rebins=int(n_rebin),
    )
