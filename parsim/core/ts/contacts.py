"""Contact searches of the time-stepping method, all on cell lists (section 3, remark on
boxes of side ``l > 2 max R``).

A pair is *in contact* when ``phi_ij >= 0`` (eq. 3.2), that is ``|X_i - X_j| <= R_i + R_j``.
"""

import numpy as np

from parsim.core.celllist import (block_cells, build_cells, cell_index, forward_offsets, grid_size, move_to_cell,
                                  neighbour_offsets)
from parsim.core.growth import with_rows
from parsim.core.jit import jit
from parsim.core.ts.links import are_linked


@jit
def _with_pair(pairs, count, i, j):
    """``pairs`` (grown if full) with ``(i, j)`` written at row ``count``."""
    if count == pairs.shape[0]:
        pairs = with_rows(pairs, 2 * pairs.shape[0] + 16, count)
    pairs[count, 0] = i
    pairs[count, 1] = j
    return pairs


def check_discs_or_spheres(positions):
    """Refuse positions that are not ``(n, 2)`` or ``(n, 3)``: the time-stepping kernels read
    the components directly (:func:`_distance_sq`, the DAHA kick)."""
    if positions.ndim != 2 or positions.shape[1] not in (2, 3):
        raise ValueError(f"positions must have shape (n, 2) or (n, 3): the time-stepping kernels handle discs or "
                         f"spheres (d = 2 or 3), got shape {positions.shape}")


@jit
def _distance_sq(A, a, B, b):
    """``|A_a - B_b|^2`` in d = 2 or 3, written out, the sum in the order of a loop over the
    components: with that loop over the runtime d, DAHA's multiplier update over all pairs takes
    twice as long."""
    dx, dy = A[a, 0] - B[b, 0], A[a, 1] - B[b, 1]
    if A.shape[1] == 2:
        return dx * dx + dy * dy
    dz = A[a, 2] - B[b, 2]
    return dx * dx + dy * dy + dz * dz


@jit
def _sorted_by_cell(X, side, k):
    """Rows of ``X`` sorted cell by cell (counting sort): ``(order, first, cell_of)``, the
    rows of cell ``c`` being ``order[first[c]:first[c + 1]]``.

    32-bit indices: the counting writes at random into ``first``, which at 4 cells per sphere
    outgrows the core's cache in 64 bits (at 10^5 spheres the sort then takes twice as long)."""
    n = X.shape[0]
    first = np.zeros(k ** X.shape[1] + 1, dtype=np.int32)
    cell_of = np.empty(n, dtype=np.int32)
    for i in range(n):
        cell_of[i] = cell_index(X, i, side, k)
        first[cell_of[i] + 1] += 1
    for c in range(first.shape[0] - 1):
        first[c + 1] += first[c]
    fill = first[:-1].copy()
    order = np.empty(n, dtype=np.int32)
    for i in range(n):
        order[fill[cell_of[i]]] = i
        fill[cell_of[i]] += 1
    return order, first, cell_of


@jit
def _mostly_queries(queries, n_rows):
    """Whether at least half of ``n_rows`` rows are ``queries``: a search then sweeps the cells
    over all rows (:func:`_near_pairs`), else it looks around each query."""
    return 2 * queries.shape[0] >= n_rows


@jit
def _near_pairs(X, R, queries, group, reach, side, k):
    """Pairs ``(i, j)``, ``i`` in ``queries``, with a gap ``|X_i - X_j| - R_i - R_j <= reach``
    and ``group[i] != group[j]``; a pair of two queries is reported once, with ``i < j``.
    The order of the pairs is unspecified.

    The grid (``k`` cells per side of length ``side >= 2 max R + reach``) covers the points.
    The rows are copied cell by cell, so that the spheres a search examines lie next to each
    other in memory: in row order, which the motion of the clusters scrambles, a search over
    10^5 scattered spheres takes twice as long.  When at least half the rows are queries the
    cells are swept, each pair of rows examined once (about half the time of a search from each
    query); otherwise each query examines the block of cells around its own.
    """
    n, d = X.shape
    order, first, cell_of = _sorted_by_cell(X, side, k)
    is_query = np.zeros(n, dtype=np.bool_)
    for i in queries:
        is_query[i] = True
    Xs = np.empty((n, d))
    radius = np.empty(n)
    group_of = np.empty(n, dtype=group.dtype)
    queried = np.empty(n, dtype=np.bool_)
    for s in range(n):
        i = order[s]
        for a in range(d):
            Xs[s, a] = X[i, a]
        radius[s] = R[i]
        group_of[s] = group[i]
        queried[s] = is_query[i]
    if _mostly_queries(queries, n):
        return _pairs_by_cells(Xs, radius, group_of, queried, order, first, reach, k)
    return _pairs_by_queries(Xs, radius, group_of, queried, order, first, cell_of, reach, k)


@jit
def _pairs_by_cells(Xs, radius, group_of, queried, order, first, reach, k):
    """The pairs of :func:`_near_pairs` from a sweep over the cells, each cell against itself
    and its forward neighbours (rows sorted by cell: ``Xs`` ... ``queried`` of sorted row ``s``
    belong to row ``order[s]``)."""
    d = Xs.shape[1]
    forward = forward_offsets(d)
    shift = np.zeros(forward.shape[0], dtype=np.int64)  # linear index of each forward neighbour - own
    for o in range(forward.shape[0]):
        stride = 1
        for a in range(d):
            shift[o] += forward[o, a] * stride
            stride *= k
    coords = np.zeros(d, dtype=np.int64)  # of cell c, counted up with c
    pairs = np.empty((16, 2), dtype=np.int64)
    count = 0
    for c in range(first.shape[0] - 1):
        if c > 0:
            a = 0
            coords[0] += 1
            while coords[a] == k:
                coords[a] = 0
                a += 1
                coords[a] += 1
        if first[c] == first[c + 1]:
            continue
        for o in range(-1, forward.shape[0]):  # -1: the cell itself
            other = c
            if o >= 0:
                inside = True
                for a in range(d):
                    q = coords[a] + forward[o, a]
                    inside = inside and 0 <= q < k
                if not inside:
                    continue
                other = c + shift[o]
            for s in range(first[c], first[c + 1]):
                for t in range(s + 1 if o < 0 else first[other], first[other + 1]):
                    if not (queried[s] or queried[t]) or group_of[t] == group_of[s]:
                        continue
                    limit = radius[s] + radius[t] + reach
                    if _distance_sq(Xs, s, Xs, t) <= limit * limit:
                        i, j = order[s], order[t]
                        if queried[s] and queried[t]:
                            i, j = min(i, j), max(i, j)
                        elif queried[t]:
                            i, j = j, i
                        pairs = _with_pair(pairs, count, i, j)
                        count += 1
    return pairs[:count].copy()


@jit
def _pairs_by_queries(Xs, radius, group_of, queried, order, first, cell_of, reach, k):
    """The pairs of :func:`_near_pairs` seen from each query (arguments as for
    :func:`_pairs_by_cells`; ``cell_of`` the cell of each unsorted row)."""
    d = Xs.shape[1]
    offsets = neighbour_offsets(d)
    coords = np.empty(d, dtype=np.int64)
    block = np.empty(offsets.shape[0], dtype=np.int64)
    pairs = np.empty((16, 2), dtype=np.int64)
    count = 0
    for s in range(Xs.shape[0]):
        if not queried[s]:
            continue
        i = order[s]
        nb = block_cells(cell_of[i], k, offsets, coords, block)
        for b in range(nb):
            for t in range(first[block[b]], first[block[b] + 1]):
                j = order[t]
                if t == s or (queried[t] and j < i) or group_of[t] == group_of[s]:
                    continue
                limit = radius[s] + radius[t] + reach
                if _distance_sq(Xs, s, Xs, t) <= limit * limit:
                    pairs = _with_pair(pairs, count, i, j)
                    count += 1
    return pairs[:count].copy()


def cross_cluster_contacts(X, R, cluster, side, k):
    """Pairs ``i < j`` of spheres of different clusters in contact, shape ``(m, 2)``.

    The grid (``k`` cells per side of length ``side >= 2 max R``) covers the box.
    """
    return cross_cluster_pairs(X, R, cluster, np.arange(X.shape[0]), 0.0, side, k)


def cross_cluster_pairs(X, R, cluster, queries, reach, side, k):
    """Pairs ``(i, j)``, ``i`` in ``queries``, of spheres of different clusters with a gap of at
    most ``reach`` (a pair of two queries once, ``i < j``), shape ``(m, 2)``.

    The grid (``k`` cells per side of length ``side >= 2 max R + reach``) covers the box.
    With queries in less than half the rows, only the rows near them are sorted
    (:func:`_pairs_near`): a late stage renews its watch thousands of times from fewer than a
    hundred spheres outside the largest cluster, and would sort every row each time.
    """
    if _mostly_queries(queries, X.shape[0]):
        return _near_pairs(X, R, queries, cluster, reach, side, k)
    return _pairs_near(X, R, queries, cluster, reach, side, k)


@jit
def _unlinked(pairs, global_id, link_head, link_next, link_to):
    """The pairs whose spheres (named by ``global_id``) are not linked."""
    kept = np.empty_like(pairs)
    count = 0
    for p in range(pairs.shape[0]):
        i, j = pairs[p, 0], pairs[p, 1]
        if not are_linked(link_head, link_next, link_to, global_id[i], global_id[j]):
            kept[count, 0] = i
            kept[count, 1] = j
            count += 1
    return kept[:count].copy()


@jit
def _rows_near(X, rows, side, k):
    """The rows of ``X`` (ascending) in the cells of the blocks around the cells of ``rows``:
    every row within one cell side of one of them."""
    n, d = X.shape
    marked = np.zeros(k**d, dtype=np.bool_)
    offsets = neighbour_offsets(d)
    coords = np.empty(d, dtype=np.int64)
    block = np.empty(offsets.shape[0], dtype=np.int64)
    for i in rows:
        for b in range(block_cells(cell_index(X, i, side, k), k, offsets, coords, block)):
            marked[block[b]] = True
    near = np.empty(n, dtype=np.int64)
    count = 0
    for j in range(n):
        if marked[cell_index(X, j, side, k)]:
            near[count] = j
            count += 1
    return near[:count]


def unlinked_contacts(X, R, moved, side, k, global_id, link_head, link_next, link_to):
    """Pairs of rows in contact with at least one row in ``moved`` whose spheres are not linked
    (eq. 3.2); a pair of two moved rows is reported once.  Row ``i`` is sphere
    ``global_id[i]`` of the link set.  The grid (``k`` cells per side of length ``side >=
    2 max R``) covers the box.

    Only the rows near the moved ones are sorted, into cells over their bounding box: after a
    minimisation of a few clusters that is a small part of the box, and a round costs what those
    rows hold, not a pass over every row."""
    touching = _pairs_near(X, R, moved, np.arange(X.shape[0]), 0.0, side, k)
    return _unlinked(touching, global_id, link_head, link_next, link_to)


def _pairs_near(X, R, queries, group, reach, side, k):
    """The pairs of :func:`_near_pairs` (``queries`` ascending) from the rows within one cell
    of a query alone, sorted into cells over their bounding box."""
    near = _rows_near(X, queries, side, k)
    if near.size < 2:  # a rank may hold no query
        return np.empty((0, 2), dtype=np.int64)
    lower, near_k, near_side = _bounding_grid(X[near], side)
    return near[_near_pairs(X[near] - lower, R[near], np.searchsorted(near, queries), group[near], reach, near_side,
                            near_k)]


def _bounding_grid(P, cutoff):
    """``(lower, k, side)``: the lower corner of the points' bounding box (the origin if there
    are none) and a grid over that box from there (``k`` cells per side of length
    ``side >= cutoff``)."""
    lower = P.min(axis=0) if P.shape[0] else np.zeros(P.shape[1])
    extent = float((P - lower).max()) + 1e-12 if P.shape[0] else 0.0
    k, side = grid_size(max(extent, cutoff), cutoff, P.shape[1], P.shape[0])
    return lower, k, side


def candidate_pairs(P, R, n_moving, reach):
    """Local pairs ``a < b`` with a moving end and a gap of at most ``reach`` (the candidates).

    ``P`` are local positions, the first ``n_moving`` moving.  Returns ``(pair_a, pair_b)``,
    sorted by ``(a, b)``.
    """
    return _pairs_of(P, R, np.arange(n_moving), n_moving, reach)


class BinnedRows:
    """The rows of a minimisation binned on a cell grid where their candidate pairs were last
    searched, so that a refresh (:func:`updated_candidate_pairs`) rebins and searches the moved
    rows alone instead of sorting every row again.

    Cells are ``2 max R + 4/3 reach`` wide: a row is at most ``reach / 3`` from where it is
    binned (the contract of :func:`updated_candidate_pairs`), so every row within ``reach`` of a
    query is binned in the block of cells around the query's.  Rows outside the grid, which
    covers the rows where it was built, are binned in the nearest edge cell.
    """

    def __init__(self, P, R, reach):
        largest = float(R.max()) if R.size else 0.0  # a rank may hold no sphere of a minimisation
        self.lower, self.k, self.side = _bounding_grid(P, 2.0 * largest + 4.0 * reach / 3.0)
        self.head, self.next, self.prev, self.cell_of, self.count = build_cells(P - self.lower, self.side, self.k)

    def pairs_of(self, P, R, queries, n_moving, reach):
        """Pairs ``a < b`` (sorted) with an end in ``queries``, a moving end and a gap of at most
        ``reach``, after binning the ``queries`` where they are now."""
        pairs = _binned_pairs(P, R, self.lower, queries, reach, self.side, self.k, self.head, self.next, self.prev,
                              self.cell_of, self.count)
        return _sorted_moving_pairs(pairs, n_moving)


@jit
def _binned_pairs(X, R, lower, queries, reach, side, k, head, nxt, prv, cell_of, count):
    """Rebin the ``queries`` at ``X`` and return the pairs ``(i, j)``, ``i`` a query, with a gap
    of at most ``reach``; a pair of two queries once."""
    n, d = X.shape
    shifted = np.empty((1, d))
    is_query = np.zeros(n, dtype=np.bool_)
    for i in queries:
        is_query[i] = True
        for a in range(d):
            shifted[0, a] = X[i, a] - lower[a]
        move_to_cell(i, cell_index(shifted, 0, side, k), head, nxt, prv, cell_of, count)
    offsets = neighbour_offsets(d)
    coords = np.empty(d, dtype=np.int64)
    block = np.empty(offsets.shape[0], dtype=np.int64)
    pairs = np.empty((16, 2), dtype=np.int64)
    found = 0
    for i in queries:
        for b in range(block_cells(cell_of[i], k, offsets, coords, block)):
            j = head[block[b]]
            while j >= 0:
                if j != i and not (is_query[j] and j < i):
                    limit = R[i] + R[j] + reach
                    if _distance_sq(X, i, X, j) <= limit * limit:
                        pairs = _with_pair(pairs, found, i, j)
                        found += 1
                j = nxt[j]
    return pairs[:found].copy()


def updated_candidate_pairs(P, R, n_moving, reach, pair_a, pair_b, moved, binned):
    """The candidates after the rows flagged in ``moved`` have moved: the pairs ``(pair_a,
    pair_b)`` (sorted) with no moved end, and the pairs of the moved rows searched afresh
    (``binned``: a :class:`BinnedRows` of the rows where their pairs were last searched, updated).
    Returns ``(a, b, source)``, ``source`` the index of each pair in ``(pair_a, pair_b)``, -1 for
    a pair that was not there.

    This is a Verlet list refreshed sphere by sphere.  If every sphere stays within ``h`` of
    where its pairs were last searched and ``3 h <= reach``, a pair missing from the list had
    a gap above ``reach`` when it was last searched and has come at most ``3 h`` closer since:
    it does not touch.
    """
    fresh_a, fresh_b = binned.pairs_of(P, R, np.flatnonzero(moved), n_moving, reach)
    return _merge_kept(pair_a, pair_b, moved, fresh_a, fresh_b)


def _pairs_of(P, R, queries, n_moving, reach):
    """Pairs ``a < b``, sorted, with an end in ``queries``, a moving end and a gap of at most
    ``reach``; the cell grid covers the bounding box of ``P`` only."""
    if P.shape[0] < 2 or queries.size == 0:
        empty = np.empty(0, dtype=np.int64)
        return empty, empty
    lower, k, side = _bounding_grid(P, 2.0 * float(R.max()) + reach)
    # anchors are not queries: anchor pairs are seen from their moving end only
    return _sorted_moving_pairs(_near_pairs(P - lower, R, queries, np.arange(P.shape[0]), reach, side, k), n_moving)


def _sorted_moving_pairs(pairs, n_moving):
    """The rows ``(i, j)`` of ``pairs`` (each pair once) as ``a = min < b = max`` with ``a`` moving,
    sorted by ``(a, b)``: by the one key ``a (max b + 1) + b``, about ten times faster than
    ``np.lexsort`` on ``(a, b)``."""
    a, b = np.minimum(pairs[:, 0], pairs[:, 1]), np.maximum(pairs[:, 0], pairs[:, 1])
    keep = a < n_moving
    a, b = a[keep], b[keep]
    order = np.argsort(a * (int(b.max(initial=0)) + 1) + b)
    return np.ascontiguousarray(a[order]), np.ascontiguousarray(b[order])


@jit
def _merge_kept(pair_a, pair_b, moved, fresh_a, fresh_b):
    """The sorted union of the pairs with no end in ``moved`` and the sorted fresh pairs
    (which all have an end in ``moved``, so the two sets are disjoint), with the index of each
    in ``pair_a`` (-1 for a pair that was not a candidate before)."""
    n = pair_a.shape[0] + fresh_a.shape[0]
    out_a = np.empty(n, dtype=np.int64)
    out_b = np.empty(n, dtype=np.int64)
    source = np.empty(n, dtype=np.int64)
    count = 0
    f = 0
    for p in range(pair_a.shape[0]):
        while f < fresh_a.shape[0] and (fresh_a[f], fresh_b[f]) < (pair_a[p], pair_b[p]):
            out_a[count], out_b[count], source[count] = fresh_a[f], fresh_b[f], -1
            count += 1
            f += 1
        found_again = f < fresh_a.shape[0] and fresh_a[f] == pair_a[p] and fresh_b[f] == pair_b[p]
        if found_again or not (moved[pair_a[p]] or moved[pair_b[p]]):
            out_a[count], out_b[count], source[count] = pair_a[p], pair_b[p], p
            count += 1
            f += 1 if found_again else 0
    while f < fresh_a.shape[0]:
        out_a[count], out_b[count], source[count] = fresh_a[f], fresh_b[f], -1
        count += 1
        f += 1
    return out_a[:count].copy(), out_b[:count].copy(), source[:count].copy()


@jit
def incidence(pair_a, pair_b, n_moving):
    """CSR lists of the pairs incident to each moving sphere, in pair order: ``(ptr, pair_of,
    partner)``, ``partner[e]`` the other end of pair ``pair_of[e]``.  Every ``pair_a`` is
    moving (the candidates' ``a = min < b``)."""
    ptr = np.zeros(n_moving + 1, dtype=np.int64)
    for p in range(pair_a.shape[0]):
        for end in (pair_a[p], pair_b[p]):
            if end < n_moving:
                ptr[end + 1] += 1
    for i in range(n_moving):
        ptr[i + 1] += ptr[i]
    fill = ptr[:-1].copy()
    pair_of = np.empty(ptr[n_moving], dtype=np.int64)
    partner = np.empty(ptr[n_moving], dtype=np.int64)
    for p in range(pair_a.shape[0]):
        a, b = pair_a[p], pair_b[p]
        pair_of[fill[a]], partner[fill[a]] = p, b
        fill[a] += 1
        if b < n_moving:
            pair_of[fill[b]], partner[fill[b]] = p, a
            fill[b] += 1
    return ptr, pair_of, partner
