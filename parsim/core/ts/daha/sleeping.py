"""Sleeping spheres: which spheres an iteration updates (:mod:`parsim.core.ts.daha`, "Sleeping spheres").

A sphere that moved less than the sleep tolerance and overlaps no partner deeply is put at rest
after a check; a partner that moves wakes it in the next iteration.
"""

import numpy as np

from parsim.core.jit import jit
from parsim.core.ts.contacts import _distance_sq


@jit
def _wake_partners(i, n_moving, is_awake, link_ptr, link_to, pair_ptr, pair_partner, woken, count):
    """Wake the moving partners (links and candidate pairs) of sphere ``i``; returns the new count."""
    for e in range(link_ptr[i], link_ptr[i + 1]):
        j = link_to[e]
        if j < n_moving and not is_awake[j]:
            is_awake[j] = True
            woken[count] = j
            count += 1
    for e in range(pair_ptr[i], pair_ptr[i + 1]):
        j = pair_partner[e]
        if j < n_moving and not is_awake[j]:
            is_awake[j] = True
            woken[count] = j
            count += 1
    return count


@jit
def _wake_ghost_partners(g, first_ghost, is_awake, ghost_ptr, ghost_partner, woken, count):
    """Wake the local moving partners of ghost row ``first_ghost + g``; returns the new count."""
    for e in range(ghost_ptr[g], ghost_ptr[g + 1]):
        j = ghost_partner[e]
        if not is_awake[j]:
            is_awake[j] = True
            woken[count] = j
            count += 1
    return count


@jit
def _spread(state, adjacency, arrived, awake, tolerance):
    """The awake spheres after a partial iteration: those awake, and the partners of those
    (moving ghosts included: the ghost rows that ``arrived`` from their owners) that moved more
    than ``tolerance`` (a disturbance travels one contact per iteration).  ``state`` and
    ``adjacency`` are the driver's ``MinimiserState`` and ``Adjacency``."""
    P, previous, previous_ghost, is_awake = state.P, state.previous, state.previous_ghost, state.is_awake
    link_ptr, link_to, pair_ptr, pair_partner = adjacency.link_ptr, adjacency.link_to, adjacency.pair_ptr, \
        adjacency.pair_partner
    ghost_ptr, ghost_partner = adjacency.ghost_ptr, adjacency.ghost_partner
    n_moving, first_ghost = state.U.shape[0], P.shape[0] - previous_ghost.shape[0]
    woken = np.empty(n_moving, dtype=np.int64)
    count = 0
    for i in awake:
        if _distance_sq(P, i, previous, i) > tolerance * tolerance:
            count = _wake_partners(i, n_moving, is_awake, link_ptr, link_to, pair_ptr, pair_partner, woken, count)
    for g in arrived:
        if ghost_ptr[g + 1] > ghost_ptr[g] and _distance_sq(P, first_ghost + g, previous_ghost, g) > tolerance**2:
            count = _wake_ghost_partners(g, first_ghost, is_awake, ghost_ptr, ghost_partner, woken, count)
    if count == 0:
        return awake
    return _merged(awake, np.sort(woken[:count]))


@jit
def _spread_dense(state, adjacency, pairs, arrived, awake, tolerance):
    """:func:`_spread` pair by pair and link by link, the same awake spheres: cheaper when most
    spheres are awake (it visits each pair once, in memory order, not from both ends).  ``pairs`` is
    the driver's ``PairLists``."""
    P, previous, previous_ghost, is_awake = state.P, state.previous, state.previous_ghost, state.is_awake
    link_ptr, link_to, pair_a, pair_b = adjacency.link_ptr, adjacency.link_to, pairs.pair_a, pairs.pair_b
    n_moving, first_ghost = state.U.shape[0], P.shape[0] - previous_ghost.shape[0]
    moved = np.zeros(P.shape[0], dtype=np.bool_)
    for i in awake:
        moved[i] = _distance_sq(P, i, previous, i) > tolerance * tolerance
    for g in arrived:
        moved[first_ghost + g] = _distance_sq(P, first_ghost + g, previous_ghost, g) > tolerance * tolerance
    woken = np.empty(n_moving, dtype=np.int64)
    count = 0
    for p in range(pair_a.shape[0]):  # pair_a < n_moving
        a, b = pair_a[p], pair_b[p]
        if moved[a] and b < n_moving and not is_awake[b]:
            is_awake[b] = True
            woken[count] = b
            count += 1
        if moved[b] and not is_awake[a]:
            is_awake[a] = True
            woken[count] = a
            count += 1
    for i in range(n_moving):  # a link is listed at each moving end
        if not is_awake[i]:
            for e in range(link_ptr[i], link_ptr[i + 1]):
                if moved[link_to[e]]:
                    is_awake[i] = True
                    woken[count] = i
                    count += 1
                    break
    if count == 0:
        return awake
    return _merged(awake, np.sort(woken[:count]))


@jit
def _merged(a, b):
    """The sorted union of the sorted, disjoint arrays ``a`` and ``b`` (cheaper than sorting
    their concatenation when ``b`` is short)."""
    out = np.empty(a.shape[0] + b.shape[0], dtype=a.dtype)
    i = j = 0
    for k in range(out.shape[0]):
        if j == b.shape[0] or (i < a.shape[0] and a[i] < b[j]):
            out[k] = a[i]
            i += 1
        else:
            out[k] = b[j]
            j += 1
    return out


@jit
def _restless(P, previous, phi, pair_ptr, pair_of, tolerance, restless_phi, settled, restless):
    """After a full sweep: a moving sphere outside the ``settled`` tiles is restless if it moved
    more than ``tolerance`` or overlaps a partner by more than ``sqrt(restless_phi)`` (a settled
    sphere's deep partners are restless themselves, so they wake what it would wake)."""
    for i in range(previous.shape[0]):
        if settled[i]:
            restless[i] = False
            continue
        moved = _distance_sq(P, i, previous, i) > tolerance * tolerance
        for e in range(pair_ptr[i], pair_ptr[i + 1]):
            moved = moved or phi[pair_of[e]] > restless_phi
        restless[i] = moved


@jit
def _settle(restless, U, is_awake, first_ghost, link_ptr, link_to, pair_ptr, pair_partner, ghost_ptr, ghost_partner):
    """The restless spheres (ghost rows: restless on their owner) and their partners stay
    awake; the others sleep, at rest, with their pairs' multipliers, until a partner moves.
    Returns the awake moving spheres, in order: read off the flags in the pass that stops the
    others, not sorted as they woke (a sort that would about double the checks' time here)."""
    n_moving = U.shape[0]
    for i in range(is_awake.shape[0]):
        is_awake[i] = False
    woken = np.empty(n_moving, dtype=np.int64)
    count = 0
    for i in range(n_moving):
        if restless[i]:
            if not is_awake[i]:
                is_awake[i] = True
                woken[count] = i
                count += 1
            count = _wake_partners(i, n_moving, is_awake, link_ptr, link_to, pair_ptr, pair_partner, woken, count)
    for g in range(ghost_ptr.shape[0] - 1):
        if restless[first_ghost + g]:
            count = _wake_ghost_partners(g, first_ghost, is_awake, ghost_ptr, ghost_partner, woken, count)
    count = 0
    for i in range(n_moving):
        if is_awake[i]:
            woken[count] = i
            count += 1
        else:
            for k in range(U.shape[1]):
                U[i, k] = 0.0
    return woken[:count]


@jit
def _drop_settled(awake, settled, is_awake):
    """The ``awake`` spheres outside settled tiles (the others are marked asleep)."""
    kept = np.empty_like(awake)
    count = 0
    for i in awake:
        if settled[i]:
            is_awake[i] = False
        else:
            kept[count] = i
            count += 1
    return kept[:count]
