"""Cluster labels and cluster velocities of one aggregation spread over several ranks.

A cluster is a connected component of the graph whose vertices are the spheres and whose
edges are the links (step 3 of the TS method; with the tiles of section 3.3 shared out
among ranks, a cluster can span several ranks).  Its label is the smallest global id of its
spheres, which does not depend on the number of ranks.

:func:`global_cluster_labels` never gathers the spheres: each rank joins its own links
(union-find), and only the spheres met by links that cross ranks, paired with the smallest
id of their local component, are gathered everywhere (two small ``Allgatherv``).
:func:`cluster_velocities` sums mass and momentum per label on each rank and combines the
partial sums of a label on one *home* rank (``label mod size``), which sends the totals back.
"""

import numpy as np

from parsim.core.ts.clusters import merge_clusters
from parsim.parallel.decomposition import Decomposition


def global_cluster_labels(decomposition: Decomposition, global_id, links) -> np.ndarray:
    """The smallest global id of the cluster of each owned sphere, shape ``(n,)`` int64.

    ``global_id`` (n,) are the ids of this rank's spheres; ``links`` (m, 2) are pairs of
    global ids known on this rank, typically those with at least one owned end.  The
    clusters are the components of the union of every rank's links; a link may be known
    on one rank or on several (duplicates are harmless).  Collective.
    """
    global_id = np.asarray(global_id, dtype=np.int64)
    links = _checked_links(links)
    n_owned = global_id.shape[0]
    node_id, node_of = np.unique(np.concatenate([global_id, links.ravel()]), return_inverse=True)
    owned_node, link_nodes = node_of[:n_owned], node_of[n_owned:].reshape(-1, 2)
    local_smallest = _component_smallest_id(node_id, link_nodes)
    labels = local_smallest[owned_node]
    if decomposition.size == 1:
        return labels
    # Local components on different ranks are one cluster when they share a sphere, and every
    # sphere seen on two ranks is an end of a link crossing ranks: tie those ends, wherever
    # they are seen, to the smallest id of their local component, and join the ties.
    shared = _nodes_on_several_ranks(decomposition, node_id, owned_node, link_nodes)
    on_this_rank = np.isin(node_id, shared)
    joins = decomposition.allgatherv_rows(np.column_stack([local_smallest[on_this_rank], node_id[on_this_rank]]))
    join_id, join_nodes = np.unique(joins, return_inverse=True)
    join_smallest = _component_smallest_id(join_id, join_nodes.reshape(-1, 2))
    return _relabel(labels, join_id, join_smallest)


def cluster_velocities(decomposition: Decomposition, labels, masses, velocities) -> np.ndarray:
    """Eq. 2.9 across ranks: each owned sphere gets ``sum m V / sum m`` over its whole cluster.

    ``labels`` (n,) are global cluster labels (the same on every rank for the same
    cluster, e.g. from :func:`global_cluster_labels`), ``masses`` (n,) positive,
    ``velocities`` (n, d).  Returns a new ``(n, d)`` array.  Collective.
    """
    labels = np.asarray(labels, dtype=np.int64)
    masses = np.asarray(masses, dtype=np.float64)
    velocities = np.asarray(velocities, dtype=np.float64)
    n = labels.shape[0]
    if masses.shape != (n,) or velocities.ndim != 2 or velocities.shape[0] != n:
        raise ValueError(f"masses, velocities: need shapes ({n},) and ({n}, d) like labels, "
                         f"got {masses.shape} and {velocities.shape}")
    if np.any(masses <= 0.0):
        raise ValueError("masses: every mass must be > 0")
    label_ids, cluster_of = np.unique(labels, return_inverse=True)
    sums = np.zeros((label_ids.shape[0], 1 + velocities.shape[1]))  # mass, then momentum
    np.add.at(sums, cluster_of, np.column_stack([masses, masses[:, None] * velocities]))
    totals = _combine_at_home(decomposition, label_ids, sums)
    return (totals[:, 1:] / totals[:, :1])[cluster_of]


def compact_labels(decomposition: Decomposition, labels) -> tuple[np.ndarray, int]:
    """Labels renumbered ``0 .. M-1`` in increasing order of label, and ``M`` (collective).

    With labels from :func:`global_cluster_labels` and spheres in global id order this is
    the serial numbering (order of first appearance).  Gathers the distinct labels of every
    rank on every rank: one value per cluster, not per sphere.
    """
    labels = np.asarray(labels, dtype=np.int64)
    distinct = np.unique(decomposition.allgatherv_rows(np.unique(labels)[:, None]))
    return np.searchsorted(distinct, labels), int(distinct.shape[0])


def _checked_links(links) -> np.ndarray:
    links = np.asarray(links, dtype=np.int64)
    if links.size == 0:
        return links.reshape(0, 2)
    if links.ndim != 2 or links.shape[1] != 2:
        raise ValueError(f"links: need shape (m, 2) (pairs of global ids), got {links.shape}")
    return links


def _component_smallest_id(node_id: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """For each node, the smallest id of its component; ``node_id`` ascending, ``pairs`` index it."""
    n = node_id.shape[0]
    component, _ = merge_clusters(np.arange(n, dtype=np.int64), n, np.ascontiguousarray(pairs, dtype=np.int64))
    _, first_node = np.unique(component, return_index=True)  # components are numbered by first node
    return node_id[first_node][component]


def _nodes_on_several_ranks(decomposition, node_id, owned_node, link_nodes) -> np.ndarray:
    """Every rank's ends of links that cross ranks (a superset of the spheres seen on several ranks)."""
    owned = np.zeros(node_id.shape[0], dtype=bool)
    owned[owned_node] = True
    crossing = link_nodes[~owned[link_nodes].all(axis=1)]
    return np.unique(decomposition.allgatherv_rows(node_id[np.unique(crossing)][:, None]))


def _relabel(labels: np.ndarray, join_id: np.ndarray, join_smallest: np.ndarray) -> np.ndarray:
    """Replace each label found in ``join_id`` by the smallest id of its joined component."""
    found = np.isin(labels, join_id)
    relabelled = labels.copy()
    relabelled[found] = join_smallest[np.searchsorted(join_id, labels[found])]
    return relabelled


def _combine_at_home(decomposition, label_ids: np.ndarray, sums: np.ndarray) -> np.ndarray:
    """Sum the rows of ``sums`` of equal label over all ranks; returns the totals for ``label_ids``."""
    if decomposition.size == 1:
        return sums
    home = label_ids % decomposition.size
    by_home = np.argsort(home, kind="stable")
    send_counts = np.bincount(home, minlength=decomposition.size)
    arrived_ids, from_each_rank = decomposition.alltoallv_rows(label_ids[by_home, None], send_counts)
    arrived_sums, _ = decomposition.alltoallv_rows(sums[by_home], send_counts, from_each_rank)
    home_ids, home_of = np.unique(arrived_ids[:, 0], return_inverse=True)
    home_totals = np.zeros((home_ids.shape[0], sums.shape[1]))
    np.add.at(home_totals, home_of, arrived_sums)
    returned, _ = decomposition.alltoallv_rows(home_totals[home_of], from_each_rank, send_counts)  # as sent
    totals = np.empty_like(sums)
    totals[by_home] = returned
    return totals
