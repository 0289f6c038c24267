"""The watch of the time-stepping method: the pairs of clusters that can touch soon, checked
against brute force."""

import numpy as np
import pytest

from parsim.core.celllist import grid_size
from parsim.core.ts.contacts import cross_cluster_pairs
from parsim.core.ts.domain import SerialDomain
from parsim.core.ts.quiet import Watch, closing_speed, outermost, steps_before_wall


def cross_contacts(X, R, cluster):
    """Pairs ``i < j`` of different clusters in contact, by brute force, as a set."""
    gap = np.linalg.norm(X[:, None] - X[None], axis=2) - (R[:, None] + R[None])
    a, b = np.nonzero(np.triu((gap <= 0.0) & (cluster[:, None] != cluster[None]), k=1))
    return set(zip(a.tolist(), b.tolist()))


def discs_in_clusters(seed, side=16, spacing=0.5, drift=(0.0, 0.0)):
    """Discs on a square lattice, gaps 0.06 to 0.14, in 30 clusters moving rigidly (one
    velocity per cluster, about ``drift``)."""
    rng = np.random.default_rng(seed)
    n = side * side
    X = spacing * (np.stack(np.unravel_index(np.arange(n), (side, side)), axis=1) + 0.5)
    R = rng.uniform(0.18, 0.22, n)
    cluster = rng.integers(0, 30, n)
    velocity = np.asarray(drift) + rng.normal(0.0, 1.0, (30, 2))
    return X, velocity[cluster], R, cluster, side * spacing


def make_watch(X, R, cluster, box, horizon):
    k, side = grid_size(box, 2.0 * R.max() + horizon, 2, X.shape[0])
    pairs = cross_cluster_pairs(X, R, cluster, np.arange(X.shape[0]), horizon, side, k)
    return Watch(np.sort(pairs, axis=1), horizon)


@pytest.mark.parametrize("seed", range(4))
def test_every_contact_is_watched_while_the_slack_lasts(seed):
    """Clusters fly, and their discs jump at random besides (as in reflections and minimisations);
    the slack shrinks by twice the longest move of each round.  As long as it is positive, the
    watch's contacts are exactly the contacts of the whole box."""
    X, V, R, cluster, box = discs_in_clusters(seed)
    rng = np.random.default_rng(100 + seed)
    watch = make_watch(X, R, cluster, box, horizon=1.0)
    rounds, contacts = 0, 0
    while True:
        jump = 0.02 * V + rng.normal(0.0, 0.005, X.shape)
        longest = np.linalg.norm(jump, axis=1).max()
        watch.close_by(2.0 * longest)
        if not watch.valid:
            break
        X = X + jump
        found = watch.contacts(X, R, cluster, np.arange(X.shape[0]))
        assert {(min(i, j), max(i, j)) for i, j in found.tolist()} == cross_contacts(X, R, cluster)
        rounds += 1
        contacts += found.shape[0]
    assert rounds >= 5 and contacts > 0


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("drift", [(0.0, 0.0), (3.0, -2.0)])
def test_no_contact_within_the_quiet_steps(seed, drift):
    """Clusters fly straight: no pair of different clusters touches within the bound the
    watch gives, and the step after it, which the watch must still answer, leaves slack."""
    X, V, R, cluster, box = discs_in_clusters(seed, drift=drift)
    dt = 0.01
    closing = closing_speed(V, SerialDomain())
    watch = make_watch(X, R, cluster, box, horizon=1.0)
    ids = np.arange(X.shape[0])
    quiet = watch.quiet_steps(X, V, R, cluster, ids, dt, closing)
    assert 0 < quiet < watch.lasts(dt, closing)
    for j in range(1, int(quiet) + 1):
        assert not cross_contacts(X + j * dt * V, R, cluster)
    watch.close_by((quiet + 1) * dt * closing)
    assert watch.valid
    touching = {(min(i, j), max(i, j)) for i, j in watch.contacts(X + (quiet + 1) * dt * V, R, cluster, ids).tolist()}
    assert touching == cross_contacts(X + (quiet + 1) * dt * V, R, cluster)


@pytest.mark.parametrize("seed", range(4))
def test_the_closing_speed_bounds_every_relative_speed(seed):
    """At least every |V_i - V_j|, at most twice max |V|; for clusters drifting together
    (a common velocity of 10, spread 1) it is set by the spread, not by the drift."""
    rng = np.random.default_rng(seed)
    V = np.array([10.0, 0.0]) + rng.normal(0.0, 1.0, (40, 2))
    closing = closing_speed(V, SerialDomain())
    relative = np.linalg.norm(V[:, None] - V[None], axis=2).max()
    assert relative <= closing <= 2.0 * np.linalg.norm(V, axis=1).max()
    assert closing < 2.0 * relative  # the bounding-box centre is within the spread
    still = closing_speed(np.zeros((3, 2)), SerialDomain())
    assert still == 0.0


def test_one_fast_cluster_among_still_ones_closes_at_its_own_speed():
    """The late stage: a small cluster at speed 1, two at rest."""
    V = np.array([[1.0, 0.0], [1.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    assert closing_speed(V, SerialDomain()) == pytest.approx(1.0)


def test_listed_pairs_limit_the_quiet_steps_only_on_a_collision_course():
    """Two discs head-on (contact after 4.5 time units) end the quiet stretch after 4 steps;
    two passing each other 1.5 apart (not touching, though closing at the same speed) do
    not limit it, and the slack alone does."""
    R = np.full(2, 0.5)
    cluster = np.array([0, 1])
    ids = np.arange(2)
    head_on = np.array([[0.0, 0.0], [10.0, 0.0]]), np.array([[1.0, 0.0], [-1.0, 0.0]])
    passing = np.array([[0.0, 0.0], [10.0, 1.5]]), np.array([[1.0, 0.0], [-1.0, 0.0]])
    quiet = []
    for X, V in (head_on, passing):
        watch = Watch(np.array([[0, 1]]), 40.0)
        quiet.append(watch.quiet_steps(X, V, R, cluster, ids, 1.0, closing=2.0))
        assert watch.lasts(1.0, 2.0) == 19
    assert quiet == [4, 18]
    X, V = head_on
    assert not cross_contacts(X + 4.0 * V, R, cluster) and cross_contacts(X + 5.0 * V, R, cluster)


@pytest.mark.parametrize("seed", range(4))
def test_a_translating_cluster_reaches_a_wall_first_with_an_outermost_sphere(seed):
    """One cluster of 500 discs flying at one velocity through a box of side 40: its outermost
    discs, picked once, bound the steps before a wall exactly as all its discs do, at every
    step of its flight, for any velocity."""
    rng = np.random.default_rng(seed)
    X = rng.uniform(15.0, 25.0, (500, 2))
    R = rng.uniform(0.1, 0.3, 500)
    rows = np.arange(500)
    outer = outermost(X, R, rows, 1e-6 * 40.0)
    assert 4 <= outer.size < 20
    for velocity in rng.normal(0.0, 1.0, (5, 2)):
        V = np.broadcast_to(velocity, X.shape).copy()
        Y = X.copy()
        while True:
            every = steps_before_wall(Y, V, R, 40.0, 0.07, rows)
            assert steps_before_wall(Y, V, R, 40.0, 0.07, outer) == every
            if every == 0:
                break
            Y += 0.07 * V
