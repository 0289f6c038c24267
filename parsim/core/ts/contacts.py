"""Contact searches of the time-stepping method, all on cell lists (section 3, remark on
boxes of side ``l > 2 max R``).

A pair is *in contact* when ``phi_ij >= 0`` (eq. 3.2), that is ``|X_i - X_j| <= R_i + R_j``.
"""

import numpy as np

from parsim.core.celllist import block_cells, build_cells, grid_size, neighbour_offsets
from parsim.core.jit import jit
from parsim.core.ts.links import are_linked


@jit
def _grow(pairs, count):
    if count < pairs.shape[0]:
        return pairs
    bigger = np.empty((2 * pairs.shape[0] + 16, 2), dtype=np.int64)
    bigger[:count] = pairs[:count]
    return bigger


@jit
def _distance_sq(X, i, j):
    s = 0.0
    for a in range(X.shape[1]):
        dx = X[i, a] - X[j, a]
        s += dx * dx
    return s


@jit
def _near_pairs(X, R, queries, group, reach, side, k):
    """Pairs ``(i, j)``, ``i`` in ``queries``, with a gap ``|X_i - X_j| - R_i - R_j <= reach``
    and ``group[i] != group[j]``; a pair of two queries is reported once, with ``i < j``.

    The grid (``k`` cells per side of length ``side >= 2 max R + reach``) covers the points.
    """
    n, d = X.shape
    head, nxt, _, cell_of, _ = build_cells(X, side, k)
    offsets = neighbour_offsets(d)
    coords = np.empty(d, dtype=np.int64)
    block = np.empty(offsets.shape[0], dtype=np.int64)
    is_query = np.zeros(n, dtype=np.bool_)
    for i in queries:
        is_query[i] = True
    pairs = np.empty((16, 2), dtype=np.int64)
    count = 0
    for i in queries:
        nb = block_cells(cell_of[i], k, offsets, coords, block)
        for b in range(nb):
            j = head[block[b]]
            while j >= 0:
                if j != i and not (is_query[j] and j < i) and group[j] != group[i]:
                    limit = R[i] + R[j] + reach
                    if _distance_sq(X, i, j) <= limit * limit:
                        pairs = _grow(pairs, count)
                        pairs[count, 0] = i
                        pairs[count, 1] = j
                        count += 1
                j = nxt[j]
    return pairs[:count].copy()


def cross_cluster_contacts(X, R, cluster, side, k):
    """Pairs ``i < j`` of spheres of different clusters in contact, shape ``(m, 2)``.

    The grid (``k`` cells per side of length ``side >= 2 max R``) covers the box.
    """
    return _near_pairs(X, R, np.arange(X.shape[0]), cluster, 0.0, side, k)


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


def unlinked_contacts(X, R, moved, side, k, global_id, link_head, link_next, link_to):
    """Pairs of rows in contact with at least one row in ``moved`` whose spheres are not linked
    (eq. 3.2); a pair of two moved rows is reported once.  Row ``i`` is sphere
    ``global_id[i]`` of the link set."""
    n = X.shape[0]
    touching = _near_pairs(X, R, moved, np.arange(n), 0.0, side, k)
    return _unlinked(touching, global_id, link_head, link_next, link_to)


def candidate_pairs(P, R, n_moving, reach):
    """Local pairs ``a < b`` with a moving end and a gap of at most ``reach`` (the candidates).

    ``P`` are local positions, the first ``n_moving`` moving; the cell grid covers their
    bounding box only.  Returns ``(pair_a, pair_b)``, sorted by ``(a, b)``.
    """
    if P.shape[0] < 2 or n_moving == 0:
        empty = np.empty(0, dtype=np.int64)
        return empty, empty
    lower = P.min(axis=0)
    shifted = P - lower
    extent = float(shifted.max()) + 1e-12
    cutoff = 2.0 * float(R.max()) + reach
    k, side = grid_size(max(extent, cutoff), cutoff, P.shape[1], P.shape[0])
    # anchors are not queries: anchor pairs are seen from their moving end only
    pairs = _near_pairs(shifted, R, np.arange(n_moving), np.arange(P.shape[0]), reach, side, k)
    order = np.lexsort((pairs[:, 1], pairs[:, 0]))
    return np.ascontiguousarray(pairs[order, 0]), np.ascontiguousarray(pairs[order, 1])


def incidence(pair_a, pair_b, n_moving):
    """CSR lists of the pairs incident to each moving sphere: ``(ptr, pair_of)``."""
    ends = np.concatenate([pair_a, pair_b])
    ids = np.concatenate([np.arange(pair_a.size), np.arange(pair_b.size)])
    keep = ends < n_moving
    ends, ids = ends[keep], ids[keep]
    order = np.argsort(ends, kind="stable")
    ptr = np.zeros(n_moving + 1, dtype=np.int64)
    np.add.at(ptr, ends + 1, 1)
    return np.cumsum(ptr), np.ascontiguousarray(ids[order], dtype=np.int64)
