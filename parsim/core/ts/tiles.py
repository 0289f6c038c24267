"""Inner and outer rectangles of the almost-rigid formulation (section 3.3, Fig. 3).

The box is cut into ``k^d`` equal tiles.  A minimisation moves the spheres of the
interacting clusters that lie in the *active* tiles (those holding an end of a link made
in the current time step: the inner rectangles) and reads, without moving them, the
interacting spheres of the surrounding tiles (the outer rectangles).  Tiles are at least
as wide as the interaction range, so an inner sphere meets every sphere it can touch or
be linked to in its own or an adjacent tile.

The number of tiles grows with the number ``#S`` of interacting spheres as the paper
states: one tile below 10^3 spheres, about 100^2 at 10^6.  We interpolate with the power
law ``Mr = (#S / 10^3)^(4/3)`` through those two points, ``k = round(Mr^(1/d))``.

Later rounds of step 2e (ours, see :mod:`parsim.core.ts.stepper`) move only the tiles around
the few links the previous round made; everywhere else that round has converged.  They use
tiles ``LATER_ROUND_TILE_WIDTHS`` interaction ranges wide, finer than the law above once
``#S`` exceeds a few thousand: at N = 10^5 the paper's tiles (about 50 R wide) put tens of
thousands of spheres in a round made for a few hundred new links.

A minimisation stops region by region (ours, :mod:`parsim.core.ts.daha`, "Stopping tile by
tile"): on square cells ``STOPPING_CELL_DIAMETERS`` largest diameters wide, or on the tiles
where those are finer.
"""

import math

import numpy as np

from parsim.core.celllist import block_cells, cell_index, neighbour_offsets
from parsim.core.jit import jit

#: Below this many interacting spheres the whole box is one tile (section 3.3).
ONE_TILE_BELOW = 1000
#: Exponent of Mr against #S: Mr = 1 at 10^3 and 10^4 = 100^2 at 10^6 spheres.
TILE_GROWTH = 4.0 / 3.0
#: Width of the tiles of later rounds of step 2e, in interaction ranges (the least tile width).
LATER_ROUND_TILE_WIDTHS = 2.0
#: Width of the cells a minimisation stops in one by one, in largest sphere diameters.
STOPPING_CELL_DIAMETERS = 4.0


def tiles_per_side(n_interacting, dimension, box_length, min_side):
    """``k``, the tiles per side for ``n_interacting`` spheres; tiles stay ``>= min_side`` wide."""
    if n_interacting < ONE_TILE_BELOW:
        return 1
    total = (n_interacting / ONE_TILE_BELOW) ** TILE_GROWTH
    k = max(1, int(round(total ** (1.0 / dimension))))
    return max(1, min(k, int(math.floor(box_length / min_side))))


def later_round_tiles_per_side(n_interacting, dimension, box_length, min_side):
    """``k`` for a later round of step 2e: tiles ``LATER_ROUND_TILE_WIDTHS * min_side`` wide, or
    those of :func:`tiles_per_side` where these are finer."""
    return max(_per_side(box_length, LATER_ROUND_TILE_WIDTHS * min_side),
               tiles_per_side(n_interacting, dimension, box_length, min_side))


def stopping_cells_per_side(k, box_length, diameter):
    """Cells per side of the grid a minimisation in ``k`` tiles per side stops on cell by cell:
    ``STOPPING_CELL_DIAMETERS`` largest diameters wide, or the tiles where these are finer."""
    return max(_per_side(box_length, STOPPING_CELL_DIAMETERS * diameter), k)


def _per_side(box_length, width):
    """The most cells per side at least ``width`` wide (at least one)."""
    return max(1, int(math.floor(box_length / width)))


@jit
def _tile_indices(X, rows, side, k):
    tile = np.empty(rows.shape[0], dtype=np.int64)
    for r in range(rows.shape[0]):
        tile[r] = cell_index(X, rows[r], side, k)
    return tile


@jit
def _select(X, involved, active, side, k):
    """Moving and anchor spheres: involved spheres in active tiles, and in the tiles around them."""
    n, d = X.shape
    tile = np.empty(n, dtype=np.int64)
    for i in range(n):
        tile[i] = cell_index(X, i, side, k) if involved[i] else -1
    state = np.zeros(k**d, dtype=np.int8)  # 2 active (inner), 1 outer
    for t in active:
        state[t] = 2
    offsets = neighbour_offsets(d)
    coords = np.empty(d, dtype=np.int64)
    block = np.empty(offsets.shape[0], dtype=np.int64)
    for c in range(k**d):
        if state[c] == 2:
            nb = block_cells(c, k, offsets, coords, block)
            for b in range(nb):
                if state[block[b]] == 0:
                    state[block[b]] = 1
    n_moving = 0
    n_anchor = 0
    for i in range(n):
        if tile[i] >= 0:
            if state[tile[i]] == 2:
                n_moving += 1
            elif state[tile[i]] == 1:
                n_anchor += 1
    moving = np.empty(n_moving, dtype=np.int64)
    anchors = np.empty(n_anchor, dtype=np.int64)
    n_moving = 0
    n_anchor = 0
    for i in range(n):
        if tile[i] >= 0:
            if state[tile[i]] == 2:
                moving[n_moving] = i
                n_moving += 1
            elif state[tile[i]] == 1:
                anchors[n_anchor] = i
                n_anchor += 1
    return moving, anchors


def tiles_of(X, rows, box_length, k):
    """The tiles (flat indices, ``k`` per side, x fastest) holding the rows ``rows`` of ``X``."""
    return _tile_indices(X, np.asarray(rows, dtype=np.int64), box_length / k, k)


def select_spheres(X, involved, active_tiles, box_length, k):
    """``(moving, anchors)``, sorted rows of ``X``, for ``k`` tiles per side.

    ``involved`` marks the spheres of the interacting clusters; ``active_tiles`` are the
    tiles holding an end of a link made in this time step (:func:`tiles_of`, over all
    processes).  With ``k = 1`` every involved sphere moves (the non-rigid formulation of
    section 3.1).
    """
    return _select(X, involved, np.asarray(active_tiles, dtype=np.int64), box_length / k, k)
