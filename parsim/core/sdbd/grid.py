"""Sediment neighbour grid whose cost does not grow with the height of the pile.

Space is cut into columns of side ``ax x ay`` (``>=`` the cell, the largest sphere diameter) and
every column into layers of height ``az`` (the same bound) starting at the floor
``z = 0``.  A cell ``(column, layer)`` keeps a singly linked list of the sediment spheres
whose (wrapped) centre lies in it: ``head[iz, col]`` is the newest sphere, ``nxt[j]`` the
next one, ``-1`` ends a list.  A deposition only adds spheres, each the newest; a deposition
spread over ranks also adds them out of order (:func:`grid_insert_ordered` keeps every list in
the order of the serial deposition) and takes out a particle settled ahead of its turn
(:func:`grid_remove`).  ``head`` is layer-major, so
the cells of the surface of the pile, where all queries happen, share few memory pages.

* ``col_top[col]`` is the highest non-empty layer of a column (the *height map*): a query
  never visits layers above it, and a falling particle starts its downward scan of a
  column there, whatever the height of the particle or of the pile.  A query therefore
  costs O(cells within reach of the moving spheres), independent of the pile height.
* Layers are added on top as the pile grows (``head`` is reallocated with twice as many
  layers when a sphere lands above the last one; amortised O(1) per sphere).
* Columns: periodic boxes wrap the column index (``ncx x ncy`` columns, cell side
  ``L / ncx``); walled boxes clip it; the unbounded floor (LATERAL_NONE) hashes the
  integer pair ``(ix, iy)`` into an open-addressing table and creates columns on demand,
  so nothing assumes bounds.

State is kept in plain arrays so that numba kernels can own and grow it:

``geom``     float64 ``[lo_x, lo_y, L_x, L_y, ax, ay, az]``, then the cylinder's polygon
             (:mod:`.polygon`) or a mesh vessel's faces (:mod:`.faces`) if any, read by name: ``geom[GEOM_CELL]`` is the cell (az), and so on
             (:mod:`.constants`: ``GEOM_LOWER_X`` ... ``GEOM_CELL``, ``GEOM_CONTAINER``)
``igeom``    int64 ``[mode, ncx, ncy, n_sides, n_faces]`` (mode = lateral boundary code, n_sides the
             polygon's sides, 0 for the box, n_faces the faces), read by name: ``IGEOM_MODE``,
             ``IGEOM_COLUMNS_X``, ``IGEOM_COLUMNS_Y``, ``IGEOM_SIDES``, ``IGEOM_FACES``
``head``     int64 ``(n_layer_capacity, n_col_capacity)``
``col_top``  int64 ``(n_col_capacity,)``
``nxt``      int64 ``(n_spheres_capacity,)``
``hkeys``    int64 ``(hash_capacity, 2)``, ``hval`` int64 ``(hash_capacity,)`` (LATERAL_NONE)
``counts``   int64 ``[n_columns_used]``
"""

import math

import numpy as np

from parsim.core.jit import jit
from parsim.core.sdbd.constants import (
    GEOM_CELL,
    GEOM_COLUMN_X,
    GEOM_COLUMN_Y,
    GEOM_LENGTH_X,
    GEOM_LENGTH_Y,
    GEOM_LOWER_X,
    GEOM_LOWER_Y,
    IGEOM_COLUMNS_X,
    IGEOM_COLUMNS_Y,
    IGEOM_MODE,
    LATERAL_NONE,
    LATERAL_PERIODIC,
    LATERAL_WALLS,
)
from parsim.core.sdbd.faces import FACE_WIDTH

__all__ = [
    "grid_new",
    "empty_grid",
    "grid_insert",
    "grid_insert_ordered",
    "grid_remove",
    "grid_collect",
    "grid_collect_growing",
    "top_near",
    "column_range",
    "column_lookup",
    "column_within",
    "wrap_position",
    "min_image",
    "periodic_image",
]

_HASH_A = 0x9E3779B97F4A7C15 >> 1
_HASH_B = 0xC2B2AE3D27D4EB4F >> 1


def grid_new(lateral, box_lower_xy, box_upper_xy, cell, n_spheres, polygon=None, n_sides=0):
    """Empty grid for spheres of diameter ``<= cell``; returns the tuple of state arrays.
    ``polygon`` (:func:`.polygon.polygon_geometry`) and ``n_sides`` describe a cylinder."""
    lo = np.asarray(box_lower_xy, dtype=np.float64)
    hi = np.asarray(box_upper_xy, dtype=np.float64)
    length = np.zeros(2) if lateral == LATERAL_NONE else hi - lo
    polygon = np.zeros(0) if polygon is None else np.ascontiguousarray(polygon, dtype=np.float64)
    return empty_grid(int(lateral), float(lo[0]), float(lo[1]), float(length[0]), float(length[1]),
                      float(cell), int(n_spheres), polygon, int(n_sides))


@jit
def empty_grid(lateral, lo_x, lo_y, length_x, length_y, cell, n_spheres, polygon, n_sides):
    """Empty grid for spheres of diameter ``<= cell`` in the box of lower corner ``lo`` and
    side lengths ``length`` (ignored for LATERAL_NONE), with the cylinder's ``polygon`` of
    ``n_sides`` (an empty array and 0 for the box); returns the tuple of state arrays."""
    if lateral == LATERAL_NONE:
        ncx = 0
        ncy = 0
        ax = cell
        ay = cell
        ncol = 64
        hcap = 128
    else:
        ncx = max(1, int(math.floor(length_x / cell)))
        ncy = max(1, int(math.floor(length_y / cell)))
        while ncx > 1 and length_x / ncx < cell:
            ncx -= 1
        while ncy > 1 and length_y / ncy < cell:
            ncy -= 1
        ax = length_x / ncx
        ay = length_y / ncy
        ncol = ncx * ncy
        hcap = 2
    geom = np.concatenate((np.array([lo_x, lo_y, length_x, length_y, ax, ay, cell], dtype=np.float64),
                           polygon))
    n_faces = 0 if n_sides > 0 else polygon.shape[0] // FACE_WIDTH
    igeom = np.array([lateral, ncx, ncy, n_sides, n_faces], dtype=np.int64)
    head = np.full((8, ncol), -1, dtype=np.int64)
    col_top = np.full(ncol, -1, dtype=np.int64)
    nxt = np.full(max(1, n_spheres), -1, dtype=np.int64)
    hkeys = np.zeros((hcap, 2), dtype=np.int64)
    hval = np.full(hcap, -1, dtype=np.int64)
    counts = np.zeros(1, dtype=np.int64)
    return geom, igeom, head, col_top, nxt, hkeys, hval, counts


@jit
def _hash(ix, iy, mask):
    h = (ix * _HASH_A) ^ (iy * _HASH_B)
    h ^= h >> 29
    return h & mask


@jit
def column_lookup(igeom, hkeys, hval, ix, iy):
    """Column id of the integer column ``(ix, iy)`` or -1 (walled box outside, or unused)."""
    mode = igeom[IGEOM_MODE]
    if mode == LATERAL_PERIODIC:
        ncx = igeom[IGEOM_COLUMNS_X]
        return _wrapped(ix, ncx) + ncx * _wrapped(iy, igeom[IGEOM_COLUMNS_Y])
    if mode == LATERAL_WALLS:
        if ix < 0 or iy < 0 or ix >= igeom[IGEOM_COLUMNS_X] or iy >= igeom[IGEOM_COLUMNS_Y]:
            return -1
        return ix + igeom[IGEOM_COLUMNS_X] * iy
    mask = hval.shape[0] - 1
    k = _hash(ix, iy, mask)
    while True:
        v = hval[k]
        if v < 0:
            return -1
        if hkeys[k, 0] == ix and hkeys[k, 1] == iy:
            return v
        k = (k + 1) & mask


@jit(inline="always")
def _wrapped(i, n):
    """``i % n`` (n > 0), without a division for the indices of a query: one period off at most."""
    if i < 0:
        i += n
        return i if i >= 0 else i % n
    if i >= n:
        i -= n
        return i if i < n else i % n
    return i


@jit
def wrap_position(geom, igeom, x, y):
    """Position folded into the periodic box (unchanged for other boundaries)."""
    if igeom[IGEOM_MODE] == LATERAL_PERIODIC:
        x = geom[GEOM_LOWER_X] + (x - geom[GEOM_LOWER_X]) % geom[GEOM_LENGTH_X]
        y = geom[GEOM_LOWER_Y] + (y - geom[GEOM_LOWER_Y]) % geom[GEOM_LENGTH_Y]
        # round-off of % can give exactly L
        if x >= geom[GEOM_LOWER_X] + geom[GEOM_LENGTH_X]:
            x -= geom[GEOM_LENGTH_X]
        if y >= geom[GEOM_LOWER_Y] + geom[GEOM_LENGTH_Y]:
            y -= geom[GEOM_LENGTH_Y]
    return x, y


@jit
def min_image(geom, igeom, dx, dy):
    """Minimum-image lateral difference (unchanged for other boundaries)."""
    return periodic_image(igeom[IGEOM_MODE] == LATERAL_PERIODIC, geom[GEOM_LENGTH_X], geom[GEOM_LENGTH_Y], dx, dy)


@jit
def periodic_image(periodic, length_x, length_y, dx, dy):
    """The minimum image of the lateral difference ``dx, dy`` in a periodic box of sides
    ``length_x, length_y`` (unchanged if not ``periodic``): :func:`min_image` for the loops over
    candidates, which read the box once (scalar arguments cost numba no reference counting).

    A difference within a quarter of the box's side is its own minimum image: there
    ``floor(d / L + 0.5)`` is 0 whatever the rounding, so the division is skipped and the
    result is bitwise that of the formula."""
    if periodic:
        if abs(dx) >= 0.25 * length_x:
            dx -= length_x * math.floor(dx / length_x + 0.5)
        if abs(dy) >= 0.25 * length_y:
            dy -= length_y * math.floor(dy / length_y + 0.5)
    return dx, dy


@jit
def _column_index(geom, x, y):
    ix = int(math.floor((x - geom[GEOM_LOWER_X]) / geom[GEOM_COLUMN_X]))
    iy = int(math.floor((y - geom[GEOM_LOWER_Y]) / geom[GEOM_COLUMN_Y]))
    return ix, iy


@jit
def _new_column(igeom, head, col_top, hkeys, hval, counts, ix, iy):
    """LATERAL_NONE: create column ``(ix, iy)``; returns (col, head, col_top, hkeys, hval)."""
    n = counts[0]
    if 2 * (n + 1) > hval.shape[0]:
        cap = 2 * hval.shape[0]
        nk = np.zeros((cap, 2), dtype=np.int64)
        nv = np.full(cap, -1, dtype=np.int64)
        mask = cap - 1
        for k in range(hval.shape[0]):
            v = hval[k]
            if v >= 0:
                h = _hash(hkeys[k, 0], hkeys[k, 1], mask)
                while nv[h] >= 0:
                    h = (h + 1) & mask
                nk[h, 0] = hkeys[k, 0]
                nk[h, 1] = hkeys[k, 1]
                nv[h] = v
        hkeys = nk
        hval = nv
    if n >= head.shape[1]:
        nh = np.full((head.shape[0], 2 * head.shape[1]), -1, dtype=np.int64)
        nh[:, : head.shape[1]] = head
        head = nh
        nt = np.full(2 * col_top.shape[0], -1, dtype=np.int64)
        nt[: col_top.shape[0]] = col_top
        col_top = nt
    mask = hval.shape[0] - 1
    h = _hash(ix, iy, mask)
    while hval[h] >= 0:
        h = (h + 1) & mask
    hkeys[h, 0] = ix
    hkeys[h, 1] = iy
    hval[h] = n
    counts[0] = n + 1
    return n, head, col_top, hkeys, hval


@jit
def grid_insert(grid_state, j, point):
    """Add sphere ``j`` with (wrapped) centre ``point = (x, y, z)`` at the head of its cell's list (the
    newest sphere first) in the grid of state arrays ``grid_state`` (:func:`empty_grid`'s tuple);
    returns the possibly grown arrays ``(head, col_top, hkeys, hval)``."""
    geom, igeom, head, col_top, nxt, hkeys, hval, counts = grid_state
    col, iz, head, col_top, hkeys, hval = _cell_of(geom, igeom, head, col_top, hkeys, hval, counts, point)
    nxt[j] = head[iz, col]
    head[iz, col] = j
    return head, col_top, hkeys, hval


@jit
def grid_insert_ordered(grid_state, j, point, key):
    """:func:`grid_insert` for spheres that arrive out of order: sphere ``j`` goes into its cell's
    list before the first sphere of smaller ``key``, so that every list runs in decreasing ``key``
    whatever the order of insertion (a list filled in increasing ``key`` by :func:`grid_insert`
    is the same list)."""
    geom, igeom, head, col_top, nxt, hkeys, hval, counts = grid_state
    col, iz, head, col_top, hkeys, hval = _cell_of(geom, igeom, head, col_top, hkeys, hval, counts, point)
    before = -1
    k = head[iz, col]
    while k >= 0 and key[k] > key[j]:
        before = k
        k = nxt[k]
    nxt[j] = k
    if before < 0:
        head[iz, col] = j
    else:
        nxt[before] = j
    return head, col_top, hkeys, hval


@jit
def grid_remove(grid_state, j, point):
    """Take sphere ``j`` (centre ``point = (x, y, z)`` as inserted) out of its cell's list; the column's
    top layer comes down to the highest layer still holding a sphere, as if ``j`` had never been in."""
    geom, igeom, head, col_top, nxt, hkeys, hval, _ = grid_state
    x, y, z = point
    ix, iy = _clamped_column_index(geom, igeom, x, y)
    col = column_lookup(igeom, hkeys, hval, ix, iy)
    iz = max(int(math.floor(z / geom[GEOM_CELL])), 0)
    before = -1
    k = head[iz, col]
    while k != j:
        before = k
        k = nxt[k]
    if before < 0:
        head[iz, col] = nxt[j]
    else:
        nxt[before] = nxt[j]
    nxt[j] = -1
    top = col_top[col]
    while top >= 0 and head[top, col] < 0:
        top -= 1
    col_top[col] = top


@jit(inline="always")
def _clamped_column_index(geom, igeom, x, y):
    """Integer column of a centre; in a box, round-off at its faces is kept in the outer columns."""
    ix, iy = _column_index(geom, x, y)
    if igeom[IGEOM_MODE] != LATERAL_NONE:
        ix = min(max(ix, 0), igeom[IGEOM_COLUMNS_X] - 1)
        iy = min(max(iy, 0), igeom[IGEOM_COLUMNS_Y] - 1)
    return ix, iy


@jit(inline="always")
def _cell_of(geom, igeom, head, col_top, hkeys, hval, counts, point):
    """The cell ``(col, iz)`` of a centre ``point``, its column created and its layer allocated if new,
    the column's top raised to it; returns ``(col, iz, head, col_top, hkeys, hval)``, possibly grown."""
    x, y, z = point
    ix, iy = _clamped_column_index(geom, igeom, x, y)
    col = column_lookup(igeom, hkeys, hval, ix, iy)
    if col < 0:
        col, head, col_top, hkeys, hval = _new_column(igeom, head, col_top, hkeys, hval, counts, ix, iy)
    iz = int(math.floor(z / geom[GEOM_CELL]))
    if iz < 0:
        iz = 0
    if iz >= head.shape[0]:
        nl = max(2 * head.shape[0], iz + 1)
        nh = np.full((nl, head.shape[1]), -1, dtype=np.int64)
        nh[: head.shape[0], :] = head
        head = nh
    if iz > col_top[col]:
        col_top[col] = iz
    return col, iz, head, col_top, hkeys, hval


@jit(inline="always")  # as a call, its eight array arguments cost numba reference counting
def top_near(geom, igeom, head, col_top, nxt, hkeys, hval, centre, x, y, reach):
    """A height above every sediment sphere (centres ``centre``) whose centre lies within lateral
    distance ``reach`` of ``(x, y)``, 0 (the floor) when none does: ``(L + 1.5) cell``, ``L`` the
    highest layer holding such a centre, since half the cell bounds every sediment radius.  It
    depends on those spheres alone, neither on the rest of the sediment nor on how the box is
    cut into columns.  The layers are scanned from the highest top of the columns within reach
    down, each over all those columns, to the first that holds a centre within reach."""
    ix0, ix1, iy0, iy1 = column_range(geom, igeom, x - reach, x + reach, y - reach, y + reach)
    periodic = igeom[IGEOM_MODE] == LATERAL_PERIODIC
    length_x, length_y = geom[GEOM_LENGTH_X], geom[GEOM_LENGTH_Y]
    highest = -1
    for iy in range(iy0, iy1 + 1):
        for ix in range(ix0, ix1 + 1):
            col = column_within(geom, igeom, hkeys, hval, x, y, reach, ix, iy)
            if col >= 0:
                highest = max(highest, col_top[col])
    for iz in range(highest, -1, -1):
        for iy in range(iy0, iy1 + 1):
            for ix in range(ix0, ix1 + 1):
                col = column_within(geom, igeom, hkeys, hval, x, y, reach, ix, iy)
                if col < 0 or col_top[col] < iz:
                    continue
                j = head[iz, col]
                while j >= 0:
                    dx, dy = periodic_image(periodic, length_x, length_y, centre[j, 0] - x, centre[j, 1] - y)
                    if dx * dx + dy * dy < reach * reach:
                        return (iz + 1.5) * geom[GEOM_CELL]
                    j = nxt[j]
    return 0.0


@jit(inline="always")
def column_within(geom, igeom, hkeys, hval, x, y, reach, ix, iy):
    """The column ``(ix, iy)`` if it exists and part of it lies within lateral distance ``reach``
    of ``(x, y)``, else -1."""
    gap_x, gap_y = periodic_image(igeom[IGEOM_MODE] == LATERAL_PERIODIC, geom[GEOM_LENGTH_X], geom[GEOM_LENGTH_Y], x - geom[GEOM_LOWER_X] - (ix + 0.5) * geom[GEOM_COLUMN_X],
                                  y - geom[GEOM_LOWER_Y] - (iy + 0.5) * geom[GEOM_COLUMN_Y])
    gap_x = max(abs(gap_x) - 0.5 * geom[GEOM_COLUMN_X], 0.0)
    gap_y = max(abs(gap_y) - 0.5 * geom[GEOM_COLUMN_Y], 0.0)
    if gap_x * gap_x + gap_y * gap_y >= reach * reach:
        return -1
    if igeom[IGEOM_MODE] == LATERAL_PERIODIC:  # column_lookup's arithmetic, here without a call
        return _wrapped(ix, igeom[IGEOM_COLUMNS_X]) + igeom[IGEOM_COLUMNS_X] * _wrapped(iy, igeom[IGEOM_COLUMNS_Y])
    return column_lookup(igeom, hkeys, hval, ix, iy)


@jit(inline="always")  # part of grid_collect, the most frequent query of the engine
def column_range(geom, igeom, x0, x1, y0, y1):
    """Integer columns ``ix0..ix1, iy0..iy1`` that meet ``[x0, x1] x [y0, y1]``.

    A periodic range as wide as the box is cut to one period (each column once); a walled
    box clips it to the existing columns.  Returns ``(ix0, ix1, iy0, iy1)``.
    """
    mode = igeom[IGEOM_MODE]
    ix0, iy0 = _column_index(geom, x0, y0)
    ix1, iy1 = _column_index(geom, x1, y1)
    if mode == LATERAL_PERIODIC:
        if ix1 - ix0 + 1 >= igeom[IGEOM_COLUMNS_X]:
            ix0 = 0
            ix1 = igeom[IGEOM_COLUMNS_X] - 1
        if iy1 - iy0 + 1 >= igeom[IGEOM_COLUMNS_Y]:
            iy0 = 0
            iy1 = igeom[IGEOM_COLUMNS_Y] - 1
    elif mode == LATERAL_WALLS:
        ix0 = max(ix0, 0)
        iy0 = max(iy0, 0)
        ix1 = min(ix1, igeom[IGEOM_COLUMNS_X] - 1)
        iy1 = min(iy1, igeom[IGEOM_COLUMNS_Y] - 1)
    return ix0, ix1, iy0, iy1


@jit
def grid_collect(grid_state, lower, upper, buf):
    """Indices of the spheres whose cells meet the box from ``lower = (x0, y0, z0)`` to
    ``upper = (x1, y1, z1)``, in the grid of state arrays ``grid_state`` (the tuple of
    :func:`empty_grid`, or :func:`.bundles.grid_arrays` of a grid bundle).

    Writes them into ``buf`` and returns their number, or ``-1`` if ``buf`` is too small
    (:func:`grid_collect_growing` grows it and asks again).  Each sphere is listed once
    even when a periodic query box is wider than the box itself; the caller applies
    minimum images.
    """
    geom, igeom, head, col_top, nxt, hkeys, hval, _ = grid_state
    x0, y0, z0 = lower
    x1, y1, z1 = upper
    ix0, ix1, iy0, iy1 = column_range(geom, igeom, x0, x1, y0, y1)
    iz0 = int(math.floor(z0 / geom[GEOM_CELL]))
    if iz0 < 0:
        iz0 = 0
    iz1 = int(math.floor(z1 / geom[GEOM_CELL]))
    cap = buf.shape[0]
    n = 0
    periodic = igeom[IGEOM_MODE] == LATERAL_PERIODIC
    ncx = igeom[IGEOM_COLUMNS_X]
    # periodic columns wrap by counting rather than by a division per column (the same columns)
    wy = iy0 % igeom[IGEOM_COLUMNS_Y] if periodic else 0
    for iy in range(iy0, iy1 + 1):
        wx = ix0 % ncx if periodic else 0
        for ix in range(ix0, ix1 + 1):
            if periodic:
                col = wx + ncx * wy
                wx = wx + 1 if wx + 1 < ncx else 0
            else:
                col = column_lookup(igeom, hkeys, hval, ix, iy)
                if col < 0:
                    continue
            top = col_top[col]
            if top < iz0:
                continue
            hi = iz1 if iz1 < top else top
            for iz in range(iz0, hi + 1):
                j = head[iz, col]
                while j >= 0:
                    if n >= cap:
                        return -1
                    buf[n] = j
                    n += 1
                    j = nxt[j]
        if periodic:
            wy = wy + 1 if wy + 1 < igeom[IGEOM_COLUMNS_Y] else 0
    return n


@jit
def grid_collect_growing(grid_state, lower, upper, buf):
    """:func:`grid_collect` with a buffer that is doubled until it holds them all;
    returns ``(count, buf)``."""
    while True:
        cnt = grid_collect(grid_state, lower, upper, buf)
        if cnt >= 0:
            return cnt, buf
        buf = np.empty(2 * buf.shape[0], dtype=np.int64)
