"""Cluster bookkeeping of the time-stepping method: free flight and wall reflection (section 3,
items i and ii), relabelling from the links and the mass-weighted velocity (step 3, eq. 2.9).

The kernels read only the spheres they are given, so that a decomposed run calls them on
each rank's spheres and combines the small results (overruns, momentum sums) over ranks.

Cluster labels are compact, ``0 .. M-1``, numbered in order of first appearance over
the spheres (the numbering of the event-driven solver).
"""

import numpy as np

from parsim.core.jit import jit


@jit
def free_flight(X, V, R, cluster, box_length, duration):
    """Item (i), in place: ``X += duration V``.  Returns the spheres then reaching past a wall:
    one row per sphere and axis, ``(cluster, axis)`` and ``(low, high)`` with ``low = X - R`` if
    below 0 (else inf) and ``high = X + R`` if above ``L`` (else -inf).

    The flight counts the overruns as it goes, and the rows are read again only if there are
    some: at N = 10^5 they outgrow the core's cache, and a separate search for overruns would
    double the flight's time."""
    n, d = X.shape
    count = 0
    for i in range(n):
        for a in range(d):
            X[i, a] += duration * V[i, a]
            if X[i, a] - R[i] < 0.0 or X[i, a] + R[i] > box_length:
                count += 1
    return _overruns(X, R, cluster, box_length, np.arange(n if count else 0), count)  # no rows if none past


@jit
def overruns(X, R, cluster, box_length, rows):
    """The rows of :func:`free_flight` for the spheres ``rows`` only, after a flight by
    :func:`translate`.  The reflections (:func:`reflections`) are those of all spheres if
    ``rows`` hold the spheres of each cluster farthest out along each axis."""
    return _overruns(X, R, cluster, box_length, rows, rows.shape[0] * X.shape[1])


@jit
def _overruns(X, R, cluster, box_length, rows, most):
    """The rows of :func:`free_flight` for the spheres and axes of ``rows`` past a wall, at
    most ``most`` of them."""
    where = np.empty((most, 2), dtype=np.int64)
    extent = np.empty((most, 2))
    count = 0
    for i in rows:
        for a in range(X.shape[1]):
            low, high = X[i, a] - R[i], X[i, a] + R[i]
            if low < 0.0 or high > box_length:
                where[count, 0] = cluster[i]
                where[count, 1] = a
                extent[count, 0] = low if low < 0.0 else np.inf
                extent[count, 1] = high if high > box_length else -np.inf
                count += 1
    return where[:count], extent[:count]


@jit
def translate(X, V, duration):
    """Item (i) for a flight that reaches no wall, in place: ``X += duration V`` (as
    :func:`free_flight`, without its search for spheres past a wall)."""
    for i in range(X.shape[0]):
        for a in range(X.shape[1]):
            X[i, a] += duration * V[i, a]


def reflections(where, extent, box_length):
    """Item (ii): every cluster reaching past a wall is mirrored across it as a whole (its
    extreme sphere then lies as far inside as it was outside) and its velocity component
    normal to the wall points inwards; the lower wall wins if a cluster reaches past both.

    ``where``, ``extent`` are the rows of :func:`free_flight` (of all processes).  Returns
    ``(where, shift, sign)``: one row per reflected cluster and axis, the displacement along
    that axis and the sign of the new velocity component.
    """
    if where.shape[0] == 0:
        return where, np.empty(0), np.empty(0)
    keys, group = np.unique(where, axis=0, return_inverse=True)
    group = group.reshape(-1)
    low = np.full(keys.shape[0], np.inf)
    high = np.full(keys.shape[0], -np.inf)
    np.minimum.at(low, group, extent[:, 0])
    np.maximum.at(high, group, extent[:, 1])
    below = low < 0.0
    shift = np.where(below, -2.0 * low, -2.0 * (high - box_length))
    return keys, shift, np.where(below, 1.0, -1.0)


@jit
def apply_reflections(X, V, cluster, where, shift, sign):
    """Move and turn every sphere of the reflected clusters (rows of :func:`reflections`).

    Each sphere finds its cluster's rows in a table over the labels up to the largest reflected
    one, not by a binary search per sphere and axis: a late stage reflects a cluster of nearly
    every sphere thousands of times."""
    apply_reflections_to(X, V, cluster, where, shift, sign, np.arange(X.shape[0]))


@jit
def apply_reflections_to(X, V, cluster, where, shift, sign, rows):
    """:func:`apply_reflections` for the spheres ``rows`` only."""
    d = X.shape[1]
    if where.shape[0] == 0:
        return
    row = np.full((where[:, 0].max() + 1) * d, -1, dtype=np.int64)  # per (cluster, axis), -1: not reflected
    for r in range(where.shape[0]):
        row[where[r, 0] * d + where[r, 1]] = r
    for i in rows:
        if cluster[i] * d < row.shape[0]:
            for a in range(d):
                r = row[cluster[i] * d + a]
                if r >= 0:
                    X[i, a] += shift[r]
                    V[i, a] = sign[r] * abs(V[i, a])


@jit
def _root(parent, c):
    while parent[c] != c:
        parent[c] = parent[parent[c]]
        c = parent[c]
    return c


@jit
def _joined(cluster, n_clusters, pairs):
    """Union-find over the cluster labels after joining the clusters of each pair: the parent of
    each label (:func:`_root` gives its joined cluster's root, the least label in it)."""
    parent = np.arange(n_clusters)
    for p in range(pairs.shape[0]):
        a = _root(parent, cluster[pairs[p, 0]])
        b = _root(parent, cluster[pairs[p, 1]])
        if a != b:
            parent[max(a, b)] = min(a, b)
    return parent


@jit
def merge_clusters(cluster, n_clusters, pairs):
    """Labels after joining the clusters of each linked pair; returns ``(labels, M)``."""
    parent = _joined(cluster, n_clusters, pairs)
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
def involved_spheres(cluster, n_clusters, pairs, own_cluster):
    """Mask of the spheres of labels ``own_cluster`` (those a process owns) whose cluster will be
    joined by one of ``pairs``; ``cluster`` labels all spheres.  It reads the owned spheres
    alone: a process's share of the run, not every sphere on every process."""
    parent = _joined(cluster, n_clusters, pairs)
    hit = np.zeros(n_clusters, dtype=np.bool_)  # by root
    for p in range(pairs.shape[0]):
        hit[_root(parent, cluster[pairs[p, 0]])] = True
    touched = np.empty(own_cluster.shape[0], dtype=np.bool_)
    for i in range(own_cluster.shape[0]):
        touched[i] = hit[_root(parent, own_cluster[i])]
    return touched


@jit
def cluster_momenta(V, masses, labels, merged):
    """Mass and momentum of each cluster in ``merged`` (sorted labels) over the given spheres,
    ``(len(merged), d + 1)``: the sums of eq. 2.9, summed in sphere order."""
    n, d = V.shape
    sums = np.zeros((merged.shape[0], d + 1))
    for i in range(n):
        c = np.searchsorted(merged, labels[i])
        if c < merged.shape[0] and merged[c] == labels[i]:
            sums[c, 0] += masses[i]
            for a in range(d):
                sums[c, a + 1] += masses[i] * V[i, a]
    return sums


@jit
def set_cluster_velocities(V, labels, merged, sums):
    """Eq. 2.9: each sphere of a ``merged`` cluster moves with its cluster's momentum / mass."""
    n, d = V.shape
    for i in range(n):
        c = np.searchsorted(merged, labels[i])
        if c < merged.shape[0] and merged[c] == labels[i]:
            for a in range(d):
                V[i, a] = sums[c, a + 1] / sums[c, 0]
