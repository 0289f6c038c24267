"""Cross-cluster neighbour lists of an event-driven run, on positions binned in a cell grid.

Sphere ``i`` lists the spheres ``j`` of other clusters with ``|Xb_i - Xb_j| < R_i + R_j +
skin``, where ``Xb`` is the position at binning.  While every cluster has moved less than
``skin / 2`` since its spheres were binned, a pair absent from the lists cannot touch, so
only listed pairs get collision events.  Each cluster also keeps a boundary list: its spheres
with at least one cross-cluster neighbour, the only ones re-predicted after its velocity
changes.
"""

from typing import NamedTuple

import numpy as np

from parsim.core.celllist import block_cells, build_cells, cell_index, move_to_cell, neighbour_offsets
from parsim.core.ed.frames import position, rebase
from parsim.core.jit import jit

#: Initial capacity of each sphere's neighbour list (doubled when one overflows).
INITIAL_NEIGHBOURS = 8
# Numpy scalars, not Python bools: numba would compile attach once per literal value.
GREATER_ONLY, ANY_PARTNER = np.bool_(True), np.bool_(False)


class CellGrid(NamedTuple):
    """The spheres' binned positions in a grid of ``k_side^d`` cells of side ``side``."""

    k_side: int  #: cells per side
    side: float  #: cell side, at least 2 R_max + skin
    offsets: np.ndarray  #: (3^d, d) offsets of a cell's block of neighbour cells
    cell_head: np.ndarray  #: first sphere binned in each cell, -1 if none
    cell_next: np.ndarray  #: next sphere in its cell, -1 at the end
    cell_prev: np.ndarray  #: previous sphere in its cell, -1 at the start
    cell_of: np.ndarray  #: (n,) cell of each sphere
    cell_count: np.ndarray  #: spheres binned in each cell
    own: np.ndarray  #: scratch: one cluster's spheres in each cell, zero between uses
    binned: np.ndarray  #: (n, d) each sphere's position when it was binned
    coords: np.ndarray  #: (d,) scratch for a cell's coordinates
    block: np.ndarray  #: (3^d,) scratch for a cell's block of cells


class NeighbourLists(NamedTuple):
    """Each sphere's count of cross-cluster neighbours and each cluster's boundary list.

    The neighbours themselves are the ``(n, capacity)`` array ``nbr``, passed beside this
    bundle because it is reallocated when a list overflows.
    """

    nn: np.ndarray  #: (n,) neighbours listed for each sphere
    inb: np.ndarray  #: (n,) 1 if the sphere is on its cluster's boundary list
    bnext: np.ndarray  #: (n,) next sphere on its cluster's boundary list
    bhead: np.ndarray  #: (n,) first sphere of each cluster's boundary list, -1 if none
    btail: np.ndarray  #: (n,) last sphere of each cluster's boundary list
    skin: float  #: margin of the lists beyond contact


@jit
def new_grid(X0, side, k_side):
    """The spheres binned at their initial positions."""
    binned = X0.copy()
    cell_head, cell_next, cell_prev, cell_of, cell_count = build_cells(binned, side, k_side)
    offsets = neighbour_offsets(X0.shape[1])
    return CellGrid(k_side, side, offsets, cell_head, cell_next, cell_prev, cell_of, cell_count,
                    np.zeros(cell_head.shape[0], dtype=np.int64), binned,
                    np.empty(X0.shape[1], dtype=np.int64), np.empty(offsets.shape[0], dtype=np.int64))


@jit
def new_lists(clusters, grid, skin):
    """Every sphere's cross-cluster neighbours at t = 0: ``(lists, nbr)``."""
    n = clusters.R.shape[0]
    nbr = np.empty((n, INITIAL_NEIGHBOURS), dtype=np.int64)
    lists = NeighbourLists(np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int8),
                           np.full(n, -1, dtype=np.int64), np.full(n, -1, dtype=np.int64),
                           np.full(n, -1, dtype=np.int64), skin)
    for i in range(n):
        nbr = attach(i, GREATER_ONLY, clusters.R, clusters.cl, grid, lists, nbr)
    return lists, nbr


@jit(inline="always")
def mark_boundary(k, c, lists):
    """Append sphere ``k`` to cluster ``c``'s boundary list unless it is on it."""
    inb, bnext, bhead, btail = lists.inb, lists.bnext, lists.bhead, lists.btail
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
def add_neighbour(nbr, nn, i, j):
    """List ``j`` as a neighbour of ``i``; returns ``nbr``, doubled in width if it was full."""
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
def detach(i, nbr, nn):
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
def attach(i, only_greater, R, cl, grid, lists, nbr):
    """Find the cross-cluster neighbours of ``i`` (radii ``R``, clusters ``cl``) in the grid and list the
    pairs both ways.

    With ``only_greater`` only partners ``j > i`` are taken (initial build).  Returns the
    neighbour array (reallocated if a list overflowed).  It takes the two arrays it reads rather
    than the whole :class:`Clusters`: a call passes every array of a bundle, and this one runs for
    every sphere re-binned.
    """
    Xb, nn, skin = grid.binned, lists.nn, lists.skin
    d = Xb.shape[1]
    ci = cl[i]
    nb = block_cells(grid.cell_of[i], grid.k_side, grid.offsets, grid.coords, grid.block)
    for b in range(nb):
        j = grid.cell_head[grid.block[b]]
        while j >= 0:
            if cl[j] != ci and (not only_greater or j > i):
                s = 0.0
                for a in range(d):
                    dx = Xb[i, a] - Xb[j, a]
                    s += dx * dx
                cut = R[i] + R[j] + skin
                if s < cut * cut:
                    nbr = add_neighbour(nbr, nn, i, j)
                    nbr = add_neighbour(nbr, nn, j, i)
                    mark_boundary(j, cl[j], lists)
            j = grid.cell_next[j]
    if nn[i] > 0:
        mark_boundary(i, ci, lists)
    return nbr


@jit(inline="always")
def bin_sphere(k, x, grid):
    """Bin sphere ``k`` at position ``x``."""
    Xb = grid.binned
    for a in range(Xb.shape[1]):
        Xb[k, a] = x[a]
    move_to_cell(k, cell_index(Xb, k, grid.side, grid.k_side), grid.cell_head, grid.cell_next,
                 grid.cell_prev, grid.cell_of, grid.cell_count)


@jit(inline="always")  # one call site, in the event loop: a call would pass every array of the bundles
def rebin_cluster(c, t, clusters, grid, lists, nbr, x):
    """Re-bin every sphere of cluster ``c`` at its position at ``t`` and rebuild its lists.

    A sphere whose 3^d cell block holds only spheres of ``c`` has no cross neighbour; it
    is recognised from per-cell counts (``grid.own`` counts c's spheres per cell, zero on
    entry and on exit) without scanning the cells, which makes re-binning the interior of a
    large compact cluster cheap.  Returns the neighbour array.
    """
    D, head, nxt = clusters.D, clusters.head, clusters.nxt
    own, cell_of, cell_count, block = grid.own, grid.cell_of, grid.cell_count, grid.block
    rebase(c, t, clusters)
    for a in range(D.shape[1]):
        D[c, a] = 0.0
    lists.bhead[c] = -1
    lists.btail[c] = -1
    k = head[c]
    while k >= 0:
        position(k, t, clusters, x)
        bin_sphere(k, x, grid)
        own[cell_of[k]] += 1
        lists.inb[k] = 0
        k = nxt[k]
    k = head[c]
    while k >= 0:
        detach(k, nbr, lists.nn)
        nb = block_cells(cell_of[k], grid.k_side, grid.offsets, grid.coords, block)
        alone = True
        for b in range(nb):
            if own[block[b]] != cell_count[block[b]]:
                alone = False
                break
        if not alone:
            nbr = attach(k, ANY_PARTNER, clusters.R, clusters.cl, grid, lists, nbr)
        k = nxt[k]
    k = head[c]
    while k >= 0:
        own[cell_of[k]] = 0
        k = nxt[k]
    return nbr
