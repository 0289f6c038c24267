"""Candidate pairs of the DAHA minimiser: the Verlet list refreshed sphere by sphere."""

import numpy as np
import pytest

from parsim.core.celllist import grid_size
from parsim.core.ts.contacts import (BinnedRows, candidate_pairs, cross_cluster_pairs, incidence, unlinked_contacts,
                                    updated_candidate_pairs)
from parsim.core.ts.links import LinkSet
from parsim.core.ts.daha.driver import REFRESH_DRIFT, REFRESH_SET


def brute_force_pairs(X, R, n_moving, gap):
    """Pairs ``a < b`` with a moving end and ``|X_a - X_b| - R_a - R_b <= gap``, as a set."""
    distance = np.linalg.norm(X[:, None] - X[None], axis=2) - (R[:, None] + R[None])
    a, b = np.nonzero(np.triu(distance <= gap, k=1))
    return {(i, j) for i, j in zip(a.tolist(), b.tolist()) if i < n_moving}


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("query_fraction", [1.0, 0.6, 0.1])
def test_pairs_of_different_clusters_within_reach_are_found_each_once(d, query_fraction):
    """With most spheres as queries the cells are swept pair by pair, otherwise searched around
    each query: either way every pair of different clusters within reach with a query end comes
    out once, the query first (the smaller row if both are); a few spheres lie outside the grid."""
    rng = np.random.default_rng(30 + d)
    n, L, reach = 400, 6.0 if d == 2 else 3.0, 0.3
    X = rng.uniform(-0.2, L + 0.2, (n, d))
    R = rng.uniform(0.1, 0.2, n)
    cluster = rng.integers(0, 150, n)
    queries = np.sort(rng.choice(n, int(query_fraction * n), replace=False))
    k, side = grid_size(L, 2 * R.max() + reach, d, n)
    found = cross_cluster_pairs(X, R, cluster, queries, reach, side, k)
    is_query = np.isin(np.arange(n), queries)
    expected = {(i, j) for i, j in brute_force_pairs(X, R, n, reach) if cluster[i] != cluster[j]
                and (is_query[i] or is_query[j])}
    assert len(expected) > 20
    as_found = [(i, j) if is_query[i] and is_query[j] else (j, i) if is_query[j] else (i, j) for i, j in expected]
    assert sorted(map(tuple, found.tolist())) == sorted(as_found)


@pytest.mark.parametrize("d", [2, 3])
def test_candidate_pairs_are_the_pairs_within_reach(d):
    rng = np.random.default_rng(d)
    n, n_moving, reach = 300, 250, 0.2
    X = rng.uniform(0.0, 4.0, (n, d))
    R = rng.uniform(0.15, 0.25, n)
    a, b = candidate_pairs(X, R, n_moving, reach)
    assert set(zip(a.tolist(), b.tolist())) == brute_force_pairs(X, R, n_moving, reach)
    assert np.all(np.diff(a * n + b) > 0)  # sorted, each once


@pytest.mark.parametrize("d", [2, 3])
def test_refreshing_the_moved_spheres_never_misses_a_contact(d):
    """Spheres wander (the anchors stay); whenever one is REFRESH_DRIFT x reach from where its
    pairs were searched, the pairs of those past REFRESH_SET of that are searched again, as
    DAHA does.  Every touching pair stays a candidate; the refreshed spheres' pairs are exactly
    those within reach, the others' pairs are kept, and each pair that was a candidate before
    is traced to its index then.  Some spheres leave the box their cells were built on."""
    rng = np.random.default_rng(10 + d)
    n, n_moving, reach = 300, 250, 0.2
    X = rng.uniform(0.0, 4.0, (n, d))
    R = rng.uniform(0.15, 0.25, n)
    a, b = candidate_pairs(X, R, n_moving, reach)
    binned = BinnedRows(X, R, reach)
    searched_at = X[:n_moving].copy()
    refreshes = 0
    for _ in range(400):
        X[:n_moving] += rng.normal(0.0, 0.01, (n_moving, d)) * rng.uniform(0.0, 1.0, (n_moving, 1)) ** 4
        drift = np.linalg.norm(X[:n_moving] - searched_at, axis=1)
        if drift.max() > REFRESH_DRIFT * reach:
            moved = np.zeros(n, dtype=np.bool_)
            moved[:n_moving] = drift > REFRESH_SET * REFRESH_DRIFT * reach
            kept = {(i, j) for i, j in zip(a.tolist(), b.tolist()) if not (moved[i] or moved[j])}
            old_a, old_b = a, b
            a, b, source = updated_candidate_pairs(X, R, n_moving, reach, a, b, moved, binned)
            pairs = set(zip(a.tolist(), b.tolist()))
            known = source >= 0
            assert np.array_equal(a[known], old_a[source[known]]) and np.array_equal(b[known], old_b[source[known]])
            was = set(zip(old_a.tolist(), old_b.tolist()))
            assert set(zip(a[known].tolist(), b[known].tolist())) == pairs & was
            fresh = {(i, j) for i, j in brute_force_pairs(X, R, n_moving, reach) if moved[i] or moved[j]}
            assert pairs == kept | fresh
            assert np.all(np.diff(a * n + b) > 0)
            searched_at[moved[:n_moving]] = X[:n_moving][moved[:n_moving]]
            refreshes += 1
        assert brute_force_pairs(X, R, n_moving, 0.0) <= set(zip(a.tolist(), b.tolist()))
    assert refreshes > 5, "the spheres did not wander far enough to test the refresh"
    assert ((X < 0.0) | (X > 4.0)).any(), "no sphere left the box of the cells"


def test_incidence_lists_each_pair_at_its_moving_ends():
    a = np.array([0, 0, 1, 2])
    b = np.array([1, 3, 2, 3])  # sphere 3 is an anchor
    ptr, pair_of, partner = incidence(a, b, 3)
    assert [sorted(pair_of[ptr[i]:ptr[i + 1]].tolist()) for i in range(3)] == [[0, 1], [0, 2], [2, 3]]
    ends = np.where(a[pair_of] == np.repeat(np.arange(3), np.diff(ptr)), b[pair_of], a[pair_of])
    assert np.array_equal(partner, ends)


@pytest.mark.parametrize("d", [2, 3])
def test_contacts_made_by_a_minimisation_are_those_of_the_moved_spheres_not_linked(d):
    """After some spheres moved (a corner of the box, as after a local minimisation), the
    contacts with a moved end are found, each once, except the linked ones."""
    rng = np.random.default_rng(20 + d)
    n, L = 400, 6.0 if d == 2 else 3.0
    X = rng.uniform(0.0, L, (n, d))
    R = rng.uniform(0.15, 0.25, n)
    moved = np.flatnonzero((X < L / 3).all(axis=1))
    touching = brute_force_pairs(X, R, n, 0.0)
    expected = {(i, j) for i, j in touching if i in moved or j in moved}
    linked = sorted(expected)[::3]
    links = LinkSet(n)
    links.add(np.array([i for i, _ in linked]), np.array([j for _, j in linked]), 1)
    k, side = grid_size(L, 2 * R.max(), d, n)
    found = unlinked_contacts(X, R, moved, side, k, np.arange(n), links.head, links.next, links.to)
    pairs = [tuple(sorted(p)) for p in found.tolist()]
    assert len(pairs) == len(set(pairs)) and set(pairs) == expected - set(linked)
    assert len(expected) > 10 and len(linked) > 3
