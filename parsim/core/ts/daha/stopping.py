"""The stopping tests after a check iteration: (3.27)–(3.28) and the deepest overlap, tile by tile.

Settled tiles, jammed tiles and polishing as :mod:`parsim.core.ts.daha` describes them; the
measures of tiles that several processes hold are reduced over them.
"""

import math

import numpy as np

from parsim.core.jit import jit
from parsim.core.kernel_mpi import global_max_array, share_flags
from parsim.core.ts.contacts import _distance_sq
from parsim.core.ts.daha.ghosts import _stop_ghosts
from parsim.core.ts.daha.scheme import _overlaps
from parsim.core.ts.daha.sleeping import _drop_settled, _restless, _settle


@jit
def _tile_measures(P, previous, phi, pair_a, pair_b, n_moving, tile_of, n_tiles):
    """Per tile of this process (rows of a ``(2, n_tiles)`` array): the largest step of its
    moving spheres (3.27) and its deepest overlap over the pairs with an end in it."""
    measures = np.zeros((2, n_tiles))
    largest, deepest = measures[0], measures[1]
    for i in range(n_moving):
        largest[tile_of[i]] = max(largest[tile_of[i]], math.sqrt(_distance_sq(P, i, previous, i)))
    for p in range(phi.shape[0]):
        if phi[p] > 0.0:
            overlap = math.sqrt(phi[p])
            deepest[tile_of[pair_a[p]]] = max(deepest[tile_of[pair_a[p]]], overlap)
            if pair_b[p] < n_moving:
                deepest[tile_of[pair_b[p]]] = max(deepest[tile_of[pair_b[p]]], overlap)
    return measures


@jit
def _over_all_tiles(tiles, shared_tiles, halo):
    """Maximise each row of ``tiles`` (measures, >= 0, of this process's tiles) over the processes
    at the tiles several of them hold (``shared_tiles``: the local index of each, -1 where this
    process holds none of it), in place, in one reduction with the largest of each row; returns
    those (numpy's max: a NaN stays)."""
    rows, n_shared = tiles.shape[0], shared_tiles.shape[0]
    packed = np.zeros(rows * (n_shared + 1))
    for r in range(rows):
        packed[r] = tiles[r].max() if tiles.shape[1] > 0 else 0.0
        for s in range(n_shared):
            if shared_tiles[s] >= 0:
                packed[rows + r * n_shared + s] = tiles[r, shared_tiles[s]]
    packed = global_max_array(packed, halo)
    for r in range(rows):
        for s in range(n_shared):
            if shared_tiles[s] >= 0:
                tiles[r, shared_tiles[s]] = packed[rows + r * n_shared + s]
    return packed[:rows]


@jit
def _any_over_all_tiles(a, b, c, halo):
    """Whether any tile of any process is flagged in ``a``, in ``b``, in ``c``: one reduction."""
    flags = np.array([1.0 if a.any() else 0.0, 1.0 if b.any() else 0.0, 1.0 if c.any() else 0.0])
    flags = global_max_array(flags, halo)
    return flags[0] > 0.0, flags[1] > 0.0, flags[2] > 0.0


@jit
def _pressed_tiles(phi, pair_a, pair_b, n_moving, tile_of, n_tiles, in_jammed_tile):
    """Per tile (one row), 1.0 if one of its moving spheres overlaps a moving sphere of a jammed
    tile (``in_jammed_tile``, per row; package docstring, "Jammed tiles"), else 0.0."""
    pressed_tiles = np.zeros((1, n_tiles))
    pressed = pressed_tiles[0]
    for p in range(phi.shape[0]):
        if phi[p] > 0.0:
            a, b = pair_a[p], pair_b[p]
            if in_jammed_tile[b]:
                pressed[tile_of[a]] = 1.0
            if in_jammed_tile[a] and b < n_moving:
                pressed[tile_of[b]] = 1.0
    return pressed_tiles


#: Why :func:`_iterations` returned: it reached the iteration it was asked to stop at, the pairs
#: must be searched again before the next iteration moves anything, the stopping tests hold, or a
#: position or the mean overlap is not finite.
REACHED_LAST, REFRESH_DUE, CONVERGED, NOT_FINITE = 0, 1, 2, 3


_GO_ON = -1


@jit
def _check(state, awake, polishing, adjacency, pairs, checks, sleep, ghost_U, halo):
    """The tests after a check iteration (package docstring, "Stopping tile by tile", "Jammed
    tiles", "Polishing"): ``(why, awake, polishing, any_settled, measures)``, ``why`` CONVERGED,
    NOT_FINITE or ``_GO_ON``; settles tiles and puts spheres to sleep when it goes on."""
    P, R, U, new, previous, previous_ghost, built_at, lam, phi, sphere_overlap, attracts, damping_of, is_awake, \
        settled, is_anchor = state
    link_ptr, link_to, pair_ptr, pair_of, pair_partner, ghost_ptr, ghost_partner = adjacency
    pair_a, pair_b, cross_pairs = pairs
    tile_of, shared_tiles, jammed_checks, in_jammed_tile, restless, pair_counted, tolerances, n_links, \
        jammed_limit = checks
    steadiness, max_overlap, overlap = tolerances
    n_moving, n_tiles = U.shape[0], jammed_checks.shape[0]
    first_ghost = P.shape[0] - previous_ghost.shape[0]
    mean_overlap, typical_overlap = _overlaps(phi, pair_counted, link_ptr, pair_ptr, pair_of, sphere_overlap, n_links,
                                              halo)
    tiles = _tile_measures(P, previous, phi, pair_a, pair_b, n_moving, tile_of, n_tiles)
    maxima = _over_all_tiles(tiles, shared_tiles, halo)
    largest, deepest = maxima[0], maxima[1]
    measures = (mean_overlap, typical_overlap, largest, deepest)
    if not (math.isfinite(largest) and math.isfinite(mean_overlap)):
        return NOT_FINITE, awake, polishing, False, measures
    steady = tiles[0] <= steadiness
    too_deep = tiles[1] > max_overlap
    done = steady & ~too_deep & (mean_overlap <= overlap)
    for t in range(n_tiles):
        jammed_checks[t] = jammed_checks[t] + 1 if steady[t] and too_deep[t] else 0
    jammed = jammed_checks >= jammed_limit
    not_all_done, any_done, any_jammed = _any_over_all_tiles(~done, done, jammed, halo)
    if not not_all_done:
        return CONVERGED, awake, polishing, False, measures
    if any_jammed and any_done:  # a jammed tile holds open the tiles pressing on it
        in_jammed_tile[:n_moving] = jammed[tile_of]
        share_flags(in_jammed_tile, first_ghost, halo)
        pressed = _pressed_tiles(phi, pair_a, pair_b, n_moving, tile_of, n_tiles, in_jammed_tile)
        _over_all_tiles(pressed, shared_tiles, halo)
        done &= pressed[0] == 0.0
    any_settled = done.any()
    settled[:n_moving] = done[tile_of]
    share_flags(settled, first_ghost, halo)
    for i in range(n_moving):
        if settled[i]:
            U[i, :] = 0.0
    _stop_ghosts(ghost_U, settled, first_ghost, True)
    if sleep > 0.0:
        polishing = (polishing or largest <= steadiness) and mean_overlap <= overlap
        _restless(P, previous, phi, pair_ptr, pair_of, sleep, overlap**2, settled, restless)
        share_flags(restless, first_ghost, halo)
        awake = _settle(restless, U, is_awake, first_ghost, link_ptr, link_to, pair_ptr, pair_partner, ghost_ptr,
                        ghost_partner)
        if any_settled:
            awake = _drop_settled(awake, settled, is_awake)
        share_flags(is_awake, first_ghost, halo)
        _stop_ghosts(ghost_U, is_awake, first_ghost, False)
    return _GO_ON, awake, polishing, any_settled, measures
