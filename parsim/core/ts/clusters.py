"""Cluster bookkeeping of the time-stepping method: wall reflection (section 3, item ii),
relabelling from the links and the mass-weighted velocity (step 3, eq. 2.9).

Cluster labels are compact, ``0 .. M-1``, numbered in order of first appearance over
the spheres (the numbering of the event-driven solver).
"""

import numpy as np

from parsim.core.jit import jit


@jit
def cluster_bounds(X, R, cluster, n_clusters):
    """Lowest and highest extent (``X -+ R``) of each cluster along each axis, ``(M, d)`` each."""
    n, d = X.shape
    low = np.full((n_clusters, d), np.inf)
    high = np.full((n_clusters, d), -np.inf)
    for i in range(n):
        c = cluster[i]
        for a in range(d):
            low[c, a] = min(low[c, a], X[i, a] - R[i])
            high[c, a] = max(high[c, a], X[i, a] + R[i])
    return low, high


@jit
def reflect_at_walls(X, V, R, cluster, n_clusters, box_length):
    """Reflect every cluster that has a sphere outside ``[0, L]^d`` back into the box.

    A cluster reaching past a wall is mirrored across it as a whole (its extreme sphere
    then lies as far inside as it was outside) and its velocity component normal to the
    wall points inwards.  Returns the number of reflections.
    """
    n, d = X.shape
    low, high = cluster_bounds(X, R, cluster, n_clusters)
    shift = np.zeros((n_clusters, d))
    flip = np.zeros((n_clusters, d), dtype=np.int8)  # +1: move up, -1: move down
    count = 0
    for c in range(n_clusters):
        for a in range(d):
            if low[c, a] < 0.0:
                shift[c, a] = -2.0 * low[c, a]
                flip[c, a] = 1
                count += 1
            elif high[c, a] > box_length:
                shift[c, a] = -2.0 * (high[c, a] - box_length)
                flip[c, a] = -1
                count += 1
    if count == 0:
        return 0
    for i in range(n):
        c = cluster[i]
        for a in range(d):
            if flip[c, a] != 0:
                X[i, a] += shift[c, a]
                V[i, a] = flip[c, a] * abs(V[i, a])
    return count


@jit
def _root(parent, c):
    while parent[c] != c:
        parent[c] = parent[parent[c]]
        c = parent[c]
    return c


@jit
def merge_clusters(cluster, n_clusters, pairs):
    """Labels after joining the clusters of each linked pair; returns ``(labels, M)``."""
    parent = np.arange(n_clusters)
    for p in range(pairs.shape[0]):
        a = _root(parent, cluster[pairs[p, 0]])
        b = _root(parent, cluster[pairs[p, 1]])
        if a != b:
            parent[max(a, b)] = min(a, b)
    new_label = np.full(n_clusters, -1, dtype=np.int64)
    labels = np.empty_like(cluster)
    m = 0
    for i in range(cluster.shape[0]):
        r = _root(parent, cluster[i])
        if new_label[r] < 0:
            new_label[r] = m
            m += 1
        labels[i] = new_label[r]
    return labels, m


@jit
def involved_spheres(cluster, n_clusters, pairs):
    """Mask of the spheres whose cluster will be joined by one of ``pairs``."""
    labels, _ = merge_clusters(cluster, n_clusters, pairs)
    touched = np.zeros(cluster.shape[0], dtype=np.bool_)
    hit = np.zeros(cluster.shape[0], dtype=np.bool_)  # by new label
    for p in range(pairs.shape[0]):
        hit[labels[pairs[p, 0]]] = True
    for i in range(cluster.shape[0]):
        touched[i] = hit[labels[i]]
    return touched


@jit
def mass_weighted_velocities(V, masses, labels, n_clusters):
    """Eq. 2.9: each cluster moves with the mass-weighted mean velocity of its spheres."""
    n, d = V.shape
    momentum = np.zeros((n_clusters, d))
    mass = np.zeros(n_clusters)
    for i in range(n):
        mass[labels[i]] += masses[i]
        for a in range(d):
            momentum[labels[i], a] += masses[i] * V[i, a]
    for i in range(n):
        for a in range(d):
            V[i, a] = momentum[labels[i], a] / mass[labels[i]]
