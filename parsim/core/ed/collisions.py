"""What an event does to the clusters: a merge (Degond et al. 2024, eq. 2.9) or a wall reflection (eq. 2.2)."""

from typing import NamedTuple

import numpy as np

from parsim.core.ed.frames import cluster_momentum, position, rebase, restamp
from parsim.core.ed.neighbours import ANY_PARTNER, attach, bin_sphere, detach
from parsim.core.jit import jit


class MergeRecord(NamedTuple):
    """Every merge of a run, in event order."""

    links: np.ndarray  #: (n - 1, 2) colliding pair (i < j) of each merge
    times: np.ndarray  #: (n - 1,) time of each merge
    momenta: bool  #: whether the momenta below are recorded
    momentum_before: np.ndarray  #: (n - 1, d) summed momentum of the two clusters, or (0, d)
    momentum_after: np.ndarray  #: (n - 1, d) momentum of the merged cluster, or (0, d)


@jit
def new_record(n, d, momenta):
    """Room for the ``n - 1`` merges a run of ``n`` spheres can have."""
    n_links = max(n - 1, 0)
    n_momenta = n_links if momenta else 0
    return MergeRecord(np.empty((n_links, 2), dtype=np.int64), np.empty(n_links), momenta,
                       np.zeros((n_momenta, d)), np.zeros((n_momenta, d)))


@jit(inline="always")  # one call site, in the event loop: a call would pass every array of the bundles
def merge(i, j, t, k_merge, clusters, grid, lists, nbr, x, record):
    """Merge the clusters of touching spheres ``i`` and ``j`` at ``t`` (eq. 2.9).

    The merged cluster moves with the mass-weighted velocity ``(M_a V_a + M_b V_b) / (M_a +
    M_b)``.  The smaller cluster's spheres join the larger one's frame and list, extend its
    bounding box, and are re-binned at ``X - D_big`` so that the merged cluster has the one
    displacement ``D_big``; their neighbour lists are rebuilt.  The merge is the
    ``k_merge``-th of ``record``.  Returns ``(nbr, merged cluster)``.
    """
    P, R, cl, O, V = clusters.P, clusters.R, clusters.cl, clusters.O, clusters.V
    M, count, head, tail, nxt = clusters.M, clusters.count, clusters.head, clusters.tail, clusters.nxt
    lo, hi, D = clusters.lo, clusters.hi, clusters.D
    d = P.shape[1]
    ci = cl[i]
    cj = cl[j]
    rebase(ci, t, clusters)
    rebase(cj, t, clusters)
    if record.momenta:
        cluster_momentum(ci, clusters, record.momentum_before[k_merge])
        cluster_momentum(cj, clusters, record.momentum_before[k_merge])
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
        lists.inb[k] = 0
        k = nxt[k]
    nxt[tail[big]] = first
    tail[big] = tail[small]
    count[big] += count[small]
    count[small] = 0
    head[small] = -1
    tail[small] = -1
    lists.bhead[small] = -1
    lists.btail[small] = -1
    restamp(clusters, small)
    restamp(clusters, big)
    # Re-bin them so that the merged cluster has one displacement, D[big].
    k = first
    while k >= 0:
        position(k, t, clusters, x)
        for a in range(d):
            x[a] -= D[big, a]
        bin_sphere(k, x, grid)
        detach(k, nbr, lists.nn)
        nbr = attach(k, ANY_PARTNER, R, cl, grid, lists, nbr)
        k = nxt[k]
    if record.momenta:
        cluster_momentum(big, clusters, record.momentum_after[k_merge])
    record.links[k_merge, 0] = min(i, j)
    record.links[k_merge, 1] = max(i, j)
    record.times[k_merge] = t
    return nbr, big


@jit(inline="always")  # one call site, in the event loop: a call would pass every array of the bundles
def reflect(c, face, t, clusters, L):
    """Reflect cluster ``c`` off the wall ``face = 2 axis + side`` at ``t`` (eq. 2.2).

    The velocity component normal to the wall changes sign.  A cluster whose bounding box
    touches both walls of that axis (it spans the box, by round-off) would reflect again at
    once, forever; its velocity along the axis becomes 0 instead.
    """
    O, V, lo, hi = clusters.O, clusters.V, clusters.lo, clusters.hi
    axis = face // 2
    wall_side = face % 2
    rebase(c, t, clusters)
    V[c, axis] = -V[c, axis]
    if wall_side == 1 and O[c, axis] + lo[c, axis] <= 0.0:
        V[c, axis] = 0.0
    elif wall_side == 0 and O[c, axis] + hi[c, axis] >= L:
        V[c, axis] = 0.0
    restamp(clusters, c)
