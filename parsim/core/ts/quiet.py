"""The watch list: which pairs of clusters can touch soon, and how many steps certainly change
nothing but positions.

In the late stage of an aggregation a few slow clusters drift for thousands of time steps
before the next collision, and each step would pay a contact search over the whole box.

A :class:`Watch` lists the pairs of spheres of different clusters with a gap of at most a
horizon ``h`` when it is made, and keeps a *slack*: every pair of different clusters not
listed has a gap above the slack.  The slack starts at ``h`` and shrinks by the most any pair
can have closed since: ``w dt`` per step of free flight, with ``w`` the closing speed below,
twice the longest jump of a wall reflection, twice the farthest a minimisation moved a sphere
(a Verlet list over time steps).  Merges only remove pairs of different clusters.  While the
slack is positive:

- a time step's contacts are among the listed pairs: the whole-box search is not needed;
- over ``j`` steps of constant ``dt`` every sphere flies straight: a listed pair touches first
  at the smaller root of a quadratic, if at all (a pair moving apart, or passing by, never
  does), and an unlisted one approaches by at most ``j dt w``; a cluster inside the box
  reaches a wall, with one of its outermost spheres, after a number of steps read off its
  velocity.  The stepper advances all the steps before the first possible contact or
  reflection with one advection: the steps still happen (time, histories, the dt law), only
  the searches that would have found nothing are skipped.

A look-ahead makes a new watch when the current one would not last two more steps, and it
leaves one step of slack, so that the watch also answers the search of the step that ends a
quiet stretch.  In a run to one cluster at N = 10^5 watches answer most contact searches (the
others, over the whole box, come mostly before the first quiet step), and more than half the
look-aheads make a watch.  Bounds are taken conservatively (round-off shortens them).

The closing speed ``w`` bounds ``|V_i - V_j|`` over all pairs of spheres:
``2 max_i |V_i - c|`` for any ``c``; :func:`closing_speed` takes the smaller of ``c = 0``
(``2 max |V|``) and the centre of the velocities' bounding box.  In a late stage the fastest
cluster is often a small one among slow ones, and ``w`` is then about its own speed rather
than twice it, so a watch lasts up to twice as many steps.
"""

import math

import numpy as np

from parsim.core.jit import jit
from parsim.core.ts.contacts import _distance_sq

#: Relative safety margin on every bound, far above round-off.
MARGIN = 1e-9


@jit
def steps_before(distance, closing):
    """Largest ``j >= 0`` with ``j closing < distance`` (less the margin); ``closing >= 0``."""
    if distance <= 0.0:
        return 0.0
    if closing <= 0.0:
        return math.inf
    return math.floor(distance * (1.0 - MARGIN) / closing)


@jit
def time_to_contact(X, V, R, i, j):
    """When spheres ``i`` and ``j``, flying straight, first touch: the smaller root of
    ``|dx + t dv| = R_i + R_j`` (``dx = X_i - X_j``, ``dv = V_i - V_j``), 0 if they touch now,
    ``inf`` if never.  Conservative: the distance is shrunk by ``MARGIN |dx|^2``, which keeps the
    rounding of ``b^2 - a c`` (about 1e-16 ``|dx|^2 |dv|^2``) on the safe side."""
    a = b = distance_sq = 0.0
    for k in range(X.shape[1]):
        dx = X[i, k] - X[j, k]
        dv = V[i, k] - V[j, k]
        a += dv * dv
        b += dx * dv
        distance_sq += dx * dx
    contact = R[i] + R[j]
    c = distance_sq * (1.0 - MARGIN) - contact * contact
    if c <= 0.0:
        return 0.0
    discriminant = b * b - a * c
    if b >= 0.0 or discriminant < 0.0:  # moving apart, or passing by
        return math.inf
    return c / (math.sqrt(discriminant) - b)  # the smaller root, without cancellation


@jit
def _steps_before_touching(X, V, R, cluster, rows, dt):
    """Steps of length ``dt`` during which none of the pairs of ``rows`` (``-1``: not held here)
    of different clusters can touch, each pair on its straight path (:func:`time_to_contact`)."""
    steps = math.inf
    for p in range(rows.shape[0]):
        i, j = rows[p, 0], rows[p, 1]
        if i < 0 or j < 0 or cluster[i] == cluster[j]:
            continue
        time = time_to_contact(X, V, R, i, j)
        if time < math.inf:
            steps = min(steps, steps_before(time, dt))
    return steps


@jit
def first_contact_among(X, V, R, cluster, rows):
    """The earliest time at which two of the spheres ``rows``, of different clusters and flying
    straight, touch (:func:`time_to_contact`); ``inf`` if none do."""
    earliest = math.inf
    for p in range(rows.shape[0]):
        for q in range(p + 1, rows.shape[0]):
            i, j = rows[p], rows[q]
            if cluster[i] != cluster[j]:
                earliest = min(earliest, time_to_contact(X, V, R, i, j))
    return earliest


@jit
def _touching(X, R, cluster, rows):
    """The pairs of ``rows`` (``-1``: not held here) of different clusters in contact, by the
    test of the whole-box search (:func:`parsim.core.ts.contacts.cross_cluster_contacts`)."""
    found = np.empty_like(rows)
    count = 0
    for p in range(rows.shape[0]):
        i, j = rows[p, 0], rows[p, 1]
        if i < 0 or j < 0 or cluster[i] == cluster[j]:
            continue
        contact = R[i] + R[j]
        if _distance_sq(X, i, X, j) <= contact * contact:
            found[count] = rows[p]
            count += 1
    return found[:count].copy()


class Watch:
    """Pairs of spheres of different clusters (global ids, ``(m, 2)``) that may touch before
    ``slack`` runs out; see the module docstring.  Every process holds all of them, in any
    order; a pair found from both ends (on two processes) may be listed twice."""

    def __init__(self, pairs, horizon, held=None, rows=None):
        self.pairs = pairs
        self.slack = horizon
        self._held = held  # the ids of the rows the pairs were last mapped to ...
        self._rows_of_pairs = rows  # ... and that mapping (known when the pairs were found here alone)

    def close_by(self, distance):
        """Account for every pair having come up to ``distance`` closer."""
        self.slack -= distance * (1.0 + MARGIN)

    @property
    def valid(self):
        return self.slack > 0.0

    def _rows(self, ids):
        """The pairs as rows of the spheres ``ids`` held here, -1 for a sphere not held; kept
        while the same spheres are held in the same rows (a mapping is a pass over every pair,
        and a late stage asks several times per watch)."""
        if self._held is not ids and (self._held is None or not np.array_equal(self._held, ids)):
            local_of = np.full(int(max(self.pairs.max(initial=-1), ids.max(initial=-1))) + 1, -1, dtype=np.int64)
            local_of[ids] = np.arange(ids.size)
            self._held, self._rows_of_pairs = ids.copy(), local_of[self.pairs]
        return self._rows_of_pairs

    def contacts(self, X, R, cluster, ids):
        """Pairs of rows (of the spheres ``ids``) of different clusters in contact: every such
        pair while the watch is valid, if ``X`` holds every sphere within ``2 max R`` of one."""
        return _touching(X, R, cluster, self._rows(ids))

    def lasts(self, dt, closing):
        """How many steps of length ``dt`` the watch certainly holds (``closing``: the closing
        speed, :func:`closing_speed`)."""
        return steps_before(self.slack, closing * dt)

    def quiet_steps(self, X, V, R, cluster, ids, dt, closing):
        """How many steps of length ``dt`` certainly make no contact, if ``X`` holds every sphere
        within ``2 max R + slack`` of one held here (the minimum over processes is the bound).
        The watch still holds for the step after them, so that it answers that step's search."""
        unlisted = max(self.lasts(dt, closing) - 1.0, 0.0)
        return min(unlisted, _steps_before_touching(X, V, R, cluster, self._rows(ids), dt))


@jit
def _velocity_box(V):
    """Per axis, the largest and (negated) the smallest velocity component of the rows ``V``
    (``-inf`` for no rows)."""
    d = V.shape[1]
    largest = np.full(2 * d, -math.inf)
    for i in range(V.shape[0]):
        for a in range(d):
            largest[a] = max(largest[a], V[i, a])
            largest[d + a] = max(largest[d + a], -V[i, a])
    return largest


@jit
def _farthest_from(V, centre):
    """``max_i |V_i - centre|`` over the rows ``V`` (0 for no rows)."""
    farthest = 0.0
    for i in range(V.shape[0]):
        s = 0.0
        for a in range(V.shape[1]):
            s += (V[i, a] - centre[a]) ** 2
        farthest = max(farthest, s)
    return math.sqrt(farthest)


def closing_speed(V, domain):
    """A bound on ``|V_i - V_j|`` over all spheres of the run: the rows ``V`` held here and,
    through ``domain`` (:mod:`parsim.core.ts.domain`), those of other processes (module
    docstring)."""
    d = V.shape[1]
    largest = np.array([domain.max(float(value)) for value in _velocity_box(V)])
    centre = 0.5 * (largest[:d] - largest[d:])
    about_centre = domain.max(_farthest_from(V, centre))
    about_zero = domain.max(_farthest_from(V, np.zeros(d)))
    return 2.0 * min(about_centre, about_zero)


@jit
def steps_before_wall(X, V, R, box_length, dt, rows):
    """Steps during which none of the spheres ``rows`` gets outside ``[0, L]^d`` (no
    reflection).  Sphere by sphere: the minimum over a cluster's spheres is the cluster's
    bound."""
    steps = math.inf
    for i in rows:
        for a in range(X.shape[1]):
            if V[i, a] < 0.0:
                steps = min(steps, steps_before(X[i, a] - R[i], -V[i, a] * dt))
            elif V[i, a] > 0.0:
                steps = min(steps, steps_before(box_length - (X[i, a] + R[i]), V[i, a] * dt))
    return steps


@jit
def outermost(X, R, rows, tolerance):
    """The ``rows`` within ``tolerance`` of the lowest ``X - R`` or the highest ``X + R`` along
    some axis: the spheres that reach a wall first when the rows translate together (for any
    velocity), should round-off shuffle spheres nearly level."""
    d = X.shape[1]
    lowest = np.full(d, np.inf)
    highest = np.full(d, -np.inf)
    for i in rows:
        for a in range(d):
            lowest[a] = min(lowest[a], X[i, a] - R[i])
            highest[a] = max(highest[a], X[i, a] + R[i])
    outer = np.empty(rows.shape[0], dtype=rows.dtype)
    count = 0
    for i in rows:
        for a in range(d):
            if X[i, a] - R[i] <= lowest[a] + tolerance or X[i, a] + R[i] >= highest[a] - tolerance:
                outer[count] = i
                count += 1
                break
    return outer[:count].copy()
