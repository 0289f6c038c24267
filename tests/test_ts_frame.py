"""A cluster binned in its own frame (parsim.core.ts.frame), checked against brute force."""

import numpy as np
import pytest

from parsim.core.ts.frame import ClusterFrame
from parsim.core.ts.quiet import time_to_contact


BOX = 12.0


def spheres_and_cluster(rng, dimension, fraction):
    """600 spheres at random in the box; about ``fraction`` of them (``inside``) a cluster, the
    rest (``outside``) not."""
    X = rng.uniform(0.0, BOX, (600, dimension))
    R = rng.uniform(0.15, 0.25, 600)
    inside = np.flatnonzero(rng.random(600) < fraction)
    return X, R, inside, np.setdiff1d(np.arange(600), inside)


def near_pairs(X, R, queries, rows, reach):
    """Pairs (q, j), q in queries, j in rows, with a gap of at most reach, by brute force."""
    gap = np.linalg.norm(X[queries][:, None] - X[rows][None], axis=2) - (R[queries][:, None] + R[rows][None])
    a, b = np.nonzero(gap <= reach)
    return set(zip(queries[a].tolist(), rows[b].tolist()))


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("dimension", [2, 3])
def test_a_translated_cluster_is_found_in_its_frame(seed, dimension):
    """A large cluster binned once, then flown for 50 steps, shifted as by a wall reflection
    and flown again, gives the pairs with the spheres outside it that brute force gives, for
    the gap its cells were sized for and for others."""
    rng = np.random.default_rng(seed)
    X, R, inside, outside = spheres_and_cluster(rng, dimension, 0.9)
    reach = 1.3
    frame = ClusterFrame(X, R, inside, 2.0 * R.max() + reach, BOX)
    velocity = rng.normal(0.0, 1.0, dimension)
    for _ in range(50):
        X[inside] += 0.013 * velocity
        X[outside] += 0.013 * rng.normal(0.0, 5.0, (outside.size, dimension))
    X[inside, 0] += 0.37  # a reflection: the cluster shifted as a whole
    X[inside] += 0.2 * velocity
    found = frame.pairs_near(X, R, outside, reach)
    expected = near_pairs(X, R, outside, inside, reach)
    assert len(expected) > 100
    assert set(map(tuple, found.tolist())) == expected
    assert found.shape[0] == len(expected)  # each pair once
    for other in (0.5 * reach, 2.5 * reach):  # the cells are sized for reach, but any gap is searched right
        assert set(map(tuple, frame.pairs_near(X, R, outside, other).tolist())) == near_pairs(X, R, outside, inside,
                                                                                              other)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("dimension", [2, 3])
def test_the_first_contact_along_straight_paths_is_found_in_the_frame(seed, dimension):
    """A few spheres fly through a large cluster, itself flying and shifted since it was binned:
    the earliest contact the frame finds is the earliest over every pair (brute force), or
    none before the time looked at if there is none."""
    rng = np.random.default_rng(seed)
    X, R, inside, outside = spheres_and_cluster(rng, dimension, 0.97)
    frame = ClusterFrame(X, R, inside, 2.0 * R.max() + 1.0, BOX)
    V = rng.normal(0.0, 1.0, (X.shape[0], dimension))
    V[inside] = rng.normal(0.0, 0.3, dimension)
    X[inside] += 0.37 * V[inside] + 0.2  # flown and shifted as a whole
    for q in outside:  # each in a free spot: no contact at the start
        while True:
            X[q] = rng.uniform(0.0, BOX, dimension)
            if (np.linalg.norm(X[inside] - X[q], axis=1) > R[inside] + R[q] + 0.05).all():
                break
    times = np.array([time_to_contact(X, V, R, q, j) for q in outside for j in inside])
    first = times.min()
    assert 0.0 < first < 1.0 and np.isinf(times).sum() > times.size / 2  # most pairs never meet
    for duration in (0.5 * first, 2.0 * first, 5.0):
        found = frame.first_contact(X, V, R, outside, duration)
        assert found == first if first <= duration else found > duration


@pytest.mark.parametrize("n, volume_fraction", [(900, 0.1), (600, 0.2)])
def test_look_aheads_along_paths_and_with_a_watch_make_the_same_run(monkeypatch, n, volume_fraction):
    """Two independent bounds on the quiet steps of a late stage: the first contact along the
    paths of the spheres outside the largest cluster (the default on one process) and the
    watch's.  Runs to a single cluster make the same links in the same steps, with positions
    equal to round-off (quiet stretches are advected in other chunks)."""
    from parsim.core.ts import simulate_ts
    from parsim.core.ts import stepper
    from tests.scripts.tiled_ts_probe import initial_condition

    runs = []
    for path_queries in (stepper.PATH_QUERIES, -1):  # -1: never follow paths
        monkeypatch.setattr(stepper, "PATH_QUERIES", path_queries)
        runs.append(simulate_ts(*initial_condition(n, volume_fraction)))
    paths, watch = runs
    assert paths.stop_reason == "single_cluster" and paths.n_steps == watch.n_steps
    assert np.array_equal(paths.links, watch.links) and np.array_equal(paths.link_steps, watch.link_steps)
    assert np.abs(paths.positions - watch.positions).max() < 1e-9
