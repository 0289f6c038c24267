"""A fixed cell grid over the box ``[0, L]^d`` with per-cell doubly linked lists.

The grid has ``k`` cells per side of side ``a = L / k >= cutoff``, so two points closer
than ``cutoff`` lie in the same or in adjacent cells (the ``3^d`` block around a cell).
Points outside the box are put in the nearest edge cell (clamping keeps that property:
a clamped point is still farther than ``a`` from every point two or more cells away).

Cells are numbered ``c = sum_a ix_a k^a``.  Each cell keeps a doubly linked list of the
points binned in it (``head[c]``, ``next[i]``, ``prev[i]``, ``cell_of[i]``) and their
number ``count[c]``, so moving one point from a cell to another is O(1).
"""

import math

import numpy as np

from parsim.core.jit import jit

__all__ = [
    "grid_size",
    "neighbour_offsets",
    "forward_offsets",
    "cell_index",
    "build_cells",
    "move_to_cell",
    "block_cells",
    "cells_over",
    "block_owners",
    "worst_overlap",
]

#: Upper bound on the number of cells per point, so that a dilute box in d = 3 does not
#: allocate a huge grid (cells then grow beyond the cutoff, which stays correct).
MAX_CELLS_PER_POINT = 8


def grid_size(box_length, cutoff, dimension, n_points, cells_per_point=MAX_CELLS_PER_POINT):
    """Cells per side ``k`` and cell side ``a = box_length / k`` with ``a >= cutoff``.

    ``k = floor(box_length / cutoff)``, at least 1, and at most what keeps ``k^d`` below
    about ``cells_per_point * n_points``.
    """
    k = max(1, int(math.floor(box_length / cutoff)))
    cap = max(1, int(math.floor((cells_per_point * n_points + 64) ** (1.0 / dimension))))
    k = min(k, cap)
    while k > 1 and box_length / k < cutoff:  # guard the floor against round-off
        k -= 1
    return k, box_length / k


@jit
def neighbour_offsets(dimension):
    """The ``3^d`` offsets in ``{-1, 0, 1}^d`` as an int64 array of shape ``(3^d, d)``."""
    count = 3**dimension
    out = np.empty((count, dimension), dtype=np.int64)
    for o in range(count):
        q = o
        for a in range(dimension):
            out[o, a] = q % 3 - 1
            q //= 3
    return out


@jit
def forward_offsets(dimension):
    """The ``(3^d - 1) / 2`` offsets of :func:`neighbour_offsets` whose last non-zero component
    is +1: of two distinct cells of a block, exactly one is a forward neighbour of the other, so
    a sweep over the cells visiting each cell and its forward neighbours sees every pair once."""
    offsets = neighbour_offsets(dimension)
    forward = np.zeros(offsets.shape[0], dtype=np.bool_)
    for o in range(offsets.shape[0]):
        for a in range(dimension - 1, -1, -1):
            if offsets[o, a] != 0:
                forward[o] = offsets[o, a] > 0
                break
    return offsets[forward]


@jit
def cell_index(x, i, side, k):
    """Linear index of the cell holding point ``x[i]`` (clamped into the grid).

    The point is named by its row: a row view ``x[i]`` made per call would triple the time of a
    pass binning the points."""
    c = 0
    mult = 1
    for a in range(x.shape[1]):
        q = int(math.floor(x[i, a] / side)) if x[i, a] > 0.0 else 0
        if q > k - 1:
            q = k - 1
        c += q * mult
        mult *= k
    return c


@jit
def block_owners(x, side, k, boundaries, dims, owner_of_block):
    """The owner of each point of ``x`` when the grid's cells are cut into blocks: along axis
    ``a`` the cell index of :func:`cell_index`'s rule (clamped) lies in block ``b`` of the
    ``dims[a]`` if ``boundaries[a, b] <= index < boundaries[a, b + 1]``, and
    ``owner_of_block`` names the owner of each block, numbered in C order (the last axis
    fastest).  Raises ValueError on a coordinate that is not finite.

    One pass over the points: the same rule with numpy's floor, clamp and searchsorted takes
    about six times as long, as much as a time step's free flight."""
    n, d = x.shape
    owners = np.empty(n, dtype=np.int64)
    for i in range(n):
        block = 0
        for a in range(d):
            value = x[i, a]
            if not math.isfinite(value):
                raise ValueError("positions: every coordinate must be finite")
            q = int(min(math.floor(value / side), k - 1)) if value > 0.0 else 0
            b = 0
            while b + 1 < dims[a] and boundaries[a, b + 1] <= q:
                b += 1
            block = block * dims[a] + b
        owners[i] = owner_of_block[block]
    return owners


@jit
def build_cells(x, side, k):
    """Bin all points; returns ``head, next, prev, cell_of, count`` (-1 ends a list).

    Points are pushed at the head of their cell in index order.
    """
    n, d = x.shape
    head = np.full(k**d, -1, dtype=np.int64)
    count = np.zeros(k**d, dtype=np.int64)
    nxt = np.full(n, -1, dtype=np.int64)
    prv = np.full(n, -1, dtype=np.int64)
    cell_of = np.empty(n, dtype=np.int64)
    for i in range(n):
        c = cell_index(x, i, side, k)
        cell_of[i] = c
        h = head[c]
        nxt[i] = h
        if h >= 0:
            prv[h] = i
        head[c] = i
        count[c] += 1
    return head, nxt, prv, cell_of, count


@jit
def move_to_cell(i, c, head, nxt, prv, cell_of, count):
    """Move point ``i`` into cell ``c`` (no-op if it is there already)."""
    old = cell_of[i]
    if old == c:
        return
    count[old] -= 1
    count[c] += 1
    p = prv[i]
    q = nxt[i]
    if p >= 0:
        nxt[p] = q
    else:
        head[old] = q
    if q >= 0:
        prv[q] = p
    h = head[c]
    nxt[i] = h
    prv[i] = -1
    if h >= 0:
        prv[h] = i
    head[c] = i
    cell_of[i] = c


@jit
def block_cells(c, k, offsets, coords, out):
    """Linear indices of the cells of the ``3^d`` block around cell ``c`` inside the grid.

    Written to ``out`` (length >= 3^d); returns how many.  ``coords`` is scratch (d,).
    """
    d = coords.shape[0]
    for a in range(d):
        coords[a] = c % k
        c //= k
    m = 0
    for o in range(offsets.shape[0]):
        lin = 0
        mult = 1
        ok = True
        for a in range(d):
            q = coords[a] + offsets[o, a]
            if q < 0 or q >= k:
                ok = False
                break
            lin += q * mult
            mult *= k
        if ok:
            out[m] = lin
            m += 1
    return m


@jit
def cells_over(lower, upper, side, k):
    """Linear indices of the cells (``k`` per side of length ``side``) overlapping the box from
    ``lower`` to ``upper``, clamped into the grid."""
    d = lower.shape[0]
    low = np.empty(d, dtype=np.int64)
    span = np.empty(d, dtype=np.int64)
    n_cells = 1
    for a in range(d):
        low[a] = min(max(int(math.floor(lower[a] / side)), 0), k - 1)
        span[a] = min(max(int(math.floor(upper[a] / side)), 0), k - 1) - low[a] + 1
        n_cells *= span[a]
    cells = np.empty(n_cells, dtype=np.int64)
    coords = np.zeros(d, dtype=np.int64)  # of the cell low + coords, counting up to span
    for m in range(n_cells):
        c = 0
        stride = 1
        for a in range(d):
            c += (low[a] + coords[a]) * stride
            stride *= k
        cells[m] = c
        a = 0
        coords[0] += 1
        while a < d - 1 and coords[a] == span[a]:
            coords[a] = 0
            a += 1
            coords[a] += 1
    return cells


@jit
def worst_overlap(x, radii, side, k):
    """The pair with the smallest gap ``|x_i - x_j| - (r_i + r_j)`` among pairs in adjacent cells.

    With ``side >= 2 max(r)`` every overlapping pair is examined.  Returns
    ``(i, j, gap)`` with ``i < j``, or ``(-1, -1, inf)`` if no pair is in adjacent cells.
    """
    n, d = x.shape
    head, nxt, prv, cell_of, count = build_cells(x, side, k)
    offsets = neighbour_offsets(d)
    coords = np.empty(d, dtype=np.int64)
    block = np.empty(offsets.shape[0], dtype=np.int64)
    best = np.inf
    bi = -1
    bj = -1
    for i in range(n):
        nb = block_cells(cell_of[i], k, offsets, coords, block)
        for b in range(nb):
            j = head[block[b]]
            while j >= 0:
                if j > i:
                    s = 0.0
                    for a in range(d):
                        dx = x[i, a] - x[j, a]
                        s += dx * dx
                    gap = math.sqrt(s) - (radii[i] + radii[j])
                    if gap < best:
                        best = gap
                        bi = i
                        bj = j
                j = nxt[j]
    return bi, bj, best
