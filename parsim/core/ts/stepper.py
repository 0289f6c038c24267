"""One time-stepping aggregation run, section 3 of Degond et al. 2024.

Each time step:

1. free advection ``X += dt V``; a cluster with a sphere outside the box is reflected
   as a whole (item ii);
2. spheres of different clusters in contact are linked (``S^{n,0}``); DAHA moves the
   spheres of the interacting clusters to a nearby non-overlapping configuration
   (3.1); contacts made by that motion are linked too (3.2) and the minimisation is
   repeated until no new link appears (step 2e);
3. clusters are relabelled from the links and move with the mass-weighted velocity
   of their spheres (step 3, eq. 2.9).

Time step.  ``dt(0) = factor L / max_i |V_i|`` (Table 1).  It grows with the logarithm of
the mean cluster size ``N / M`` (``M`` clusters), ``dt = dt(0) (1 + ln(N / M) / ln N)``,
from ``dt(0)`` at the start to ``2 dt(0)`` when a single cluster remains (section 4.1: the
step grows because collisions become rarer).  The law linear in the merges done,
``1 + (N - M) / (N - 1)``, reached 1.8 dt(0) after two or three steps, while nearly every
sphere still collided in every step; at N = 10^5 its first six steps cost three times
as much.

Quiet steps.  After a time step that made no link, the stepper lists the pairs of clusters
that can touch soon (a watch, :mod:`parsim.core.ts.quiet`), bounds how many of the next steps
can make no contact and no wall reflection, and advances them with one advection, skipping
contact searches that would find nothing.  While the watch holds, it also answers the
contact search of each time step, and the look-aheads after it.  Once the largest cluster holds
more than half the spheres, a watch is searched from the spheres outside it, the largest
cluster's own being kept binned in its moving frame until the next merge
(:mod:`parsim.core.ts.frame`).  With few spheres outside it (``PATH_QUERIES``), a look-ahead
keeps no watch: it follows their straight paths through that frame to the first possible
contact, up to the next wall reflection, and the step after a quiet stretch finds its contacts
in the frame.  A run over several processes then goes on as one on each, all alike (its rows
gathered: :meth:`_Run._hold_everything`).  The largest cluster's flights and wall reflections
are then logged, not applied to its rows, and a row gets them when it is read
(:mod:`parsim.core.ts.deferred`): the same run bit for bit, without three passes over all
spheres per wall reflection.

Formulations.  ``"non_rigid"`` (section 3.1): every sphere of the interacting clusters
moves and every link attracts (eq. 3.5).  ``"almost_rigid"`` (section 3.3): only the
interacting spheres in the tiles holding a new link move, those in the surrounding
tiles are read as fixed anchors, and a link attracts only while its length is at most
``Delta_W`` (eq. 3.30, 3.31); see :mod:`parsim.core.ts.tiles`.  A minimisation that does
not converge in its tiles within ``TILED_ITERATIONS`` (a sphere caged by anchors cannot) is
solved again in one tile, every interacting sphere moving (``_Run._tilings``).

Repeated rounds (step 2e).  The first minimisation of a time step moves the tiles holding
the links made by free flight; each later round moves only the tiles holding the links the
previous round made (finer tiles than the first round's: :mod:`parsim.core.ts.tiles`), with
the clusters of all the step's links as the interacting ones.
Everywhere else the previous round has converged and the new links are not felt (the
attraction reaches ``Delta_W``, less than a tile), so re-solving it would change nothing
but cost: at N = 10^5 a time step can take up to 30 rounds, each of tens of thousands of moving
spheres for a few tens of new links.  In the non-rigid formulation there is one tile, and every
round moves every interacting sphere as before.

Processes.  The run holds the rows of the spheres its process owns and reaches the others
through a domain (:mod:`parsim.core.ts.domain`): on one process it owns everything; with
:class:`parsim.aggregation.tiled.DecomposedDomain` each MPI rank owns the spheres of its
sub-box and reads its neighbours' as ghosts.  Links are made in sorted order, so the same
links come out on any number of processes.
"""

import math
from dataclasses import dataclass, field, replace

import numpy as np

from parsim.core.celllist import grid_size
from parsim.core.ts.clusters import (apply_reflections, apply_reflections_to, cluster_momenta, free_flight,
                                     involved_spheres, merge_clusters, overruns, reflections, set_cluster_velocities,
                                     translate)
from parsim.core.ts.contacts import (check_discs_or_spheres, cross_cluster_contacts, cross_cluster_pairs,
                                    unlinked_contacts)
from parsim.core.ts.daha import DahaParameters, minimise
from parsim.core.ts.deferred import DeferredFlight, translate_rows
from parsim.core.ts.domain import SerialDomain
from parsim.core.ts.frame import ClusterFrame
from parsim.core.ts.links import LinkSet
from parsim.core.ts.problem import Ghosts, build_problem
from parsim.core.ts.quiet import (Watch, closing_speed, first_contact_among, outermost, steps_before,
                                  steps_before_wall)
from parsim.core.ts.tiles import (later_round_tiles_per_side, select_spheres, stopping_cells_per_side, tiles_of,
                                  tiles_per_side)

FORMULATIONS = ("almost_rigid", "non_rigid")
STOP_REASONS = ("single_cluster", "max_time", "max_steps")
#: Factors of Table 1: dt(0) = factor L / max|V|.
TABLE1_TIME_STEP_FACTORS = (0.005, 0.01, 0.015)
#: Cells per sphere, at most, of the grids of the whole-box searches: over 10^5 scattered spheres
#: (V_f 0.1) a contact search is fastest with 4, and some 40 % slower with 8 (more cells, mostly
#: empty, to count and visit) or with 2 (more spheres per cell to test).
CONTACT_CELLS_PER_SPHERE = 4
#: Gap (in mean radii) below which two interacting spheres get a constraint multiplier.
CANDIDATE_REACH = 1.0
#: How far (in largest radii) a sphere may move in one minimisation of a decomposed run, at least
#: (the halo is that much wider on both sides; the rank blocks' tiles are sized for it) ...
HALO_MARGIN = 2.0
#: ... and at most at first, where the narrowest rank slab leaves room.  A minimisation that
#: goes farther is run again from its start with the margin doubled, which gives the same
#: result: at N = 10^6, V_f = 0.3 first-step minimisations moved spheres up to 4.8 radii, and
#: from a first margin of 2 radii two of the first 13 were run again, 30 % more sphere updates
#: on each of 2 ranks; a full run at N = 10^5 moved them up to 3.1 radii.
FIRST_MARGIN = 6.0
#: A minimisation that moves a sphere farther than this (in largest radii) has gone unstable
#: and is reported (DAHA resolves overlaps of at most 2 R; a few radii of chain pushing is normal).
MAX_DISPLACEMENT = 10.0
#: A minimisation in tiles gives up after this many DAHA iterations and is solved again in
#: coarser tiles (``_Run._tilings``; minimisations converge in at most a few thousand).
TILED_ITERATIONS = 10_000
#: Rounds of steps 2c-2d in one time step before it is reported as not settling.
MAX_LINK_ROUNDS = 1000
#: A watch lists pairs up to the gap the fastest pair closes in this many steps (doubling after
#: each quiet stretch found, up to the most, back to the least after a look-ahead found none) ...
QUIET_HORIZON_STEPS = (8, 1024)
#: ... and at most the gap at which a search from the spheres outside the largest cluster
#: examines about this many pairs per sphere of the run (the cost of a few contact searches) ...
QUIET_PAIRS_PER_SPHERE = 64.0
#: ... and at most this fraction of the box.  With few spheres outside the largest cluster the
#: pairs within the horizon cost more than the renewal's sort of every sphere once the horizon
#: is long: on long late stages at N = 10^5 (two small clusters wandering) L/8 is faster than
#: L/16 or L/4, by up to 10 %.
QUIET_HORIZON_BOX_FRACTION = 1.0 / 8.0


#: With at most this many spheres outside the largest cluster, the look-aheads follow their
#: straight paths through its frame instead of keeping a watch.
PATH_QUERIES = 1024

#: Whether the largest cluster's flights and reflections are deferred while the look-aheads
#: follow paths on one process (:mod:`parsim.core.ts.deferred`; the same run bit for bit).
DEFER_FLIGHTS = True

#: Spheres of one cluster whose distances to a wall differ by less than this (times L) count as
#: level when the run looks for the cluster's outermost spheres.
WALL_TIE = 1e-6


class MinimiserFailure(RuntimeError):
    """DAHA did not converge, or produced a non-finite position; the message says where."""


@dataclass
class TSResult:
    positions: np.ndarray
    velocities: np.ndarray
    cluster: np.ndarray  #: compact cluster label of each sphere
    links: np.ndarray  #: (m, 2) linked pairs i < j, in the order made
    link_steps: np.ndarray  #: time step that made each link (1-based)
    time: float
    n_steps: int
    n_collisions: int  #: cluster merges, N - M
    n_wall_reflections: int
    n_minimisations: int  #: DAHA runs (rounds of step 2c)
    n_iterations: int  #: DAHA iterations summed over all runs
    max_iterations: int  #: most iterations of one DAHA run
    stop_reason: str
    cluster_history: np.ndarray = field(repr=False)  #: M after each time step
    time_history: np.ndarray = field(repr=False)  #: t after each time step
    imbalance: np.ndarray = field(repr=False)  #: per searched time step, max / mean work over the ranks


def check_formulation(formulation):
    if formulation not in FORMULATIONS:
        raise ValueError(f"formulation must be one of {FORMULATIONS}, got {formulation!r}")


class _LargestCluster:
    """The largest cluster (``label``, ``size`` spheres; ``holds_most``: more than half of all
    spheres) and the owned rows ``outside`` it, for the labels ``cluster`` and the owned spheres
    ``global_id`` it was made for; and, once asked for, its owned rows in their own frame
    (:class:`parsim.core.ts.frame.ClusterFrame`)."""

    def __init__(self, cluster, n_clusters, global_id, own_cluster):
        sizes = np.bincount(cluster, minlength=n_clusters)
        self.label = int(sizes.argmax())
        self.size = int(sizes[self.label])
        self.holds_most = 2 * self.size > cluster.size  # of all spheres: the same on every process
        inside = own_cluster == self.label
        self.outside = np.flatnonzero(~inside)
        self._inside = np.flatnonzero(inside)
        self._made_for = (cluster, global_id)
        self._frame = None
        self._outermost = None

    def holds(self, cluster, global_id):
        """Whether these are still the labels and owned spheres it was made for: merges make new
        labels; a migration makes new rows, which hold the same spheres in the same order (by
        global id) unless spheres came or went."""
        made_for = self._made_for[1]
        return self._made_for[0] is cluster and (made_for is global_id or np.array_equal(made_for, global_id))

    @property
    def inside(self):
        """The owned rows of the cluster."""
        return self._inside

    def has_wall_rows(self):
        return self._outermost is not None

    def has_frame(self, cutoff):
        """Whether :meth:`frame` for ``cutoff`` returns the frame it has (bins nothing)."""
        return self._frame is not None and cutoff <= self._frame.cutoff <= 2.0 * cutoff

    def wall_rows(self, X, R, box_length):
        """The owned rows that can reach a wall first: those outside the cluster and its
        outermost ones (:func:`parsim.core.ts.quiet.outermost`; the cluster translates rigidly,
        and its spheres drift apart by round-off only, far below ``WALL_TIE`` L)."""
        if self._outermost is None:
            self._outermost = np.concatenate([self.outside, outermost(X, R, self._inside, WALL_TIE * box_length)])
        return self._outermost

    def frame(self, X, R, cutoff, box_length):
        """The owned rows of the cluster in its frame, in cells sized for searches up to
        ``cutoff`` (binned again when the frame's were sized for less, or for more than twice
        as much: any size is right, these are fast)."""
        if not self.has_frame(cutoff):
            self._frame = ClusterFrame(X, R, self._inside, cutoff, box_length)
        return self._frame


class _Run:
    """The state of one run and the three steps of section 3.

    This process holds the rows of the spheres it owns (``global_id``, ``X``, ``V``); the
    radii, masses, cluster labels and links of all spheres are known everywhere (they change
    only through links, which every process learns).
    """

    def __init__(self, X, V, R, m, L, formulation, daha, attraction_range, tiles, domain):
        n, d = X.shape
        self.n, self.d, self.L = n, d, L
        self.R_all, self.m_all = R, m
        self.cluster = np.arange(n, dtype=np.int64)
        self.n_clusters = n
        self.links = LinkSet(n)
        self.formulation = formulation
        self.daha = daha
        self.attraction_range = attraction_range if formulation == "almost_rigid" else math.inf
        self.tiles = tiles
        self.domain = domain
        self.reach = CANDIDATE_REACH * float(R.mean())
        self.contact = 2.0 * float(R.max())
        self.grid_k, self.grid_side = grid_size(L, self.contact, d, n, CONTACT_CELLS_PER_SPHERE)
        self.min_tile = max(self.contact + self.reach, attraction_range if math.isfinite(attraction_range) else 0.0)
        self.margin = HALO_MARGIN * float(R.max())  # raised when a minimisation leaves its halo
        self.first_margin = FIRST_MARGIN * float(R.max())
        self.max_displacement = MAX_DISPLACEMENT * float(R.max())
        self.global_id, self.X, self.V = domain.distribute(X, V, self._problem_width(0.0, self.margin))
        self.R = R[self.global_id]
        self.own_cluster = self.cluster[self.global_id]  # the cluster labels of the owned rows
        self.local_of = np.full(n, -1, dtype=np.int64)
        self.n_minimisations = 0
        self.n_iterations = 0
        self.max_iterations = 0
        self.work = 0.0
        self.horizon_steps = QUIET_HORIZON_STEPS[0]
        self.watch = None  # the pairs that can touch soon (a Watch), while it holds
        self._largest = _LargestCluster(self.cluster, self.n_clusters, self.global_id, self.own_cluster)
        self._closing = None  # the closing speed, once computed
        self._deferred = None  # the largest cluster's deferred flights (a DeferredFlight), while kept

    def advect(self, dt):
        """Step 1: free flight, then the whole-cluster wall reflection; returns the reflections made."""
        flight = dt * self.closing() if self.watch is not None else 0.0  # at the velocities of the flight
        largest = self._largest  # as the look-aheads left it: not made again after every merge
        if largest.holds_most and largest.holds(self.cluster, self.global_id):
            wall_rows = self._wall_rows(largest)  # the only rows that can reach a wall first
            self._translate(dt)
            self._bring_up_to_date(wall_rows)
            where, extent = overruns(self.X, self.R, self.own_cluster, self.L, wall_rows)
        else:
            self._settle()
            where, extent = free_flight(self.X, self.V, self.R, self.own_cluster, self.L, dt)
        where, shift, sign = reflections(self.domain.gather(where), self.domain.gather(extent), self.L)
        if shift.size:
            self._reflect(where, shift, sign)
            self._closing = None  # turned velocities
        global_id, self.X, self.V = self.domain.redistribute(self.global_id, self.X, self.V)
        if global_id is not self.global_id:  # rows migrated (one process keeps its rows)
            self.global_id, self.R, self.own_cluster = global_id, self.R_all[global_id], self.cluster[global_id]
        jump = math.sqrt(self.d) * float(np.abs(shift).max()) if shift.size else 0.0  # a cluster's, at most
        self._closed_by(flight + 2.0 * jump)
        return where.shape[0]

    def coast(self, steps, dt):
        """``steps`` quiet steps of length ``dt`` in one advection (no contact, no reflection)."""
        if self.watch is not None:  # the closing speed costs O(N) after every reflection
            self._closed_by(steps * dt * self.closing())
        self._translate(steps * dt)

    def _translate(self, duration):
        """Item (i) when no sphere reaches a wall: every row flies ``duration``; the largest
        cluster's rows by a deferred flight while one is kept (:meth:`_deferral`)."""
        deferred = self._deferral()
        if deferred is None:
            translate(self.X, self.V, duration)
        else:
            translate_rows(self.X, self.V, duration, self._largest.outside)
            deferred.fly(self.X, self.V, duration)

    def _reflect(self, where, shift, sign):
        """Item (ii) for the reflections ``where`` (rows of :func:`reflections`): the largest
        cluster's as deferred shifts while its flights are deferred, the others' in place."""
        deferred = self._deferred
        if deferred is None:
            apply_reflections(self.X, self.V, self.own_cluster, where, shift, sign)
            return
        largest = where[:, 0] == self._largest.label
        for r in np.flatnonzero(largest):
            deferred.reflect(self.X, self.V, int(where[r, 1]), float(shift[r]), float(sign[r]))
        others = ~largest
        apply_reflections_to(self.X, self.V, self.own_cluster, where[others], shift[others], sign[others],
                             self._largest.outside)

    def _deferral(self):
        """The log of the largest cluster's flights and reflections (:mod:`parsim.core.ts.deferred`),
        made if none is kept, while the look-aheads follow paths on one process and the largest
        cluster is the one it was made for; else None, any log applied first."""
        largest = self._largest
        if not (DEFER_FLIGHTS and self.domain.size == 1 and self.watch is None and self._follows_paths(largest)
                and largest.holds(self.cluster, self.global_id) and largest.has_wall_rows()
                and largest.has_frame(self._frame_cutoff())):
            self._settle()
            return None
        if self._deferred is None or self._deferred.rows is not largest.inside:
            self._settle()
            self._deferred = DeferredFlight(self.X, self.V, largest.inside)
        return self._deferred

    def _settle(self):
        """Bring every row up to date and drop the log of deferred flights (before anything
        reads all rows, or the largest cluster changes)."""
        if self._deferred is not None:
            self._deferred.settle(self.X, self.V)
            self._deferred = None

    def _bring_up_to_date(self, rows):
        if self._deferred is not None:
            self._deferred.bring_up_to_date(self.X, self.V, rows)

    def _log(self):
        """The deferred flights as the frame's kernels take them (None: every row up to date)."""
        return None if self._deferred is None else self._deferred.log(self.V)

    def _wall_rows(self, largest):
        """:meth:`_LargestCluster.wall_rows`, every row brought up to date before they are found."""
        if not largest.has_wall_rows():
            self._settle()
        return largest.wall_rows(self.X, self.R, self.L)

    def _frame(self, largest, cutoff):
        """:meth:`_LargestCluster.frame`, every row brought up to date before it is binned."""
        if not largest.has_frame(cutoff):
            self._settle()
        return largest.frame(self.X, self.R, cutoff, self.L)

    def _closed_by(self, gap):
        """Every pair of spheres came at most ``gap`` closer: shrink the watch's slack, and drop
        the watch once it no longer holds."""
        if self.watch is not None:
            self.watch.close_by(gap)
            if not self.watch.valid:
                self.watch = None

    def _largest_cluster(self):
        """The largest cluster and the owned rows outside it (:class:`_LargestCluster`), kept
        until a merge or a migration."""
        if not self._largest.holds(self.cluster, self.global_id):
            self._largest = _LargestCluster(self.cluster, self.n_clusters, self.global_id, self.own_cluster)
        return self._largest

    def closing(self):
        """The closing speed (:func:`parsim.core.ts.quiet.closing_speed`), kept until the
        velocities change (a merge or a reflection)."""
        if self._closing is None:
            self._closing = closing_speed(self.V, self.domain)
        return self._closing

    def _with_ghosts(self, width):
        """Owned and ghost rows, to be read, not written: ``(halo, global ids, positions, radii,
        cluster labels)``."""
        if self.domain.size == 1:  # no ghosts: spare the copies and gathers of every row
            return None, self.global_id, self.X, self.R, self.own_cluster
        halo = self.domain.ghosts(self.X, self.global_id, width)
        ids = np.concatenate([self.global_id, halo.ghost_global_id])
        return halo, ids, np.concatenate([self.X, halo.exchange(self.X)]), self.R_all[ids], self.cluster[ids]

    def quiet_steps(self, dt):
        """How many of the next steps of length ``dt`` certainly make no link and no reflection
        (a float bound): from the paths of the few spheres outside the largest cluster
        (:meth:`_steps_before_contact`), or else from a watch, made if none holds."""
        largest = self._largest_cluster()
        if self.domain.size > 1 and self._follows_paths(largest):
            largest = self._hold_everything()
        wall_rows = self._wall_rows(largest)
        self._bring_up_to_date(wall_rows)
        quiet = self.domain.min(steps_before_wall(self.X, self.V, self.R, self.L, dt, wall_rows))
        if 0 < quiet < math.inf and self._follows_paths(largest):
            self.watch = None
            return min(quiet, self._steps_before_contact(largest, (quiet + 1.0) * dt, dt))
        if quiet > 0:
            self._settle()  # the watch reads every row
            closing = self.closing()
            if self.watch is None or self.watch.lasts(dt, closing) < 2.0:  # no quiet step left: renew
                self.watch = self._new_watch(dt, closing)
            halo, ids, X, R, cluster = self._with_ghosts(self.contact + max(self.watch.slack, 0.0))
            V = self.V if self.domain.size == 1 else np.concatenate([self.V, halo.exchange(self.V)])
            quiet = min(quiet, self.domain.min(self.watch.quiet_steps(X, V, R, cluster, ids, dt, closing)))
            if not self.watch.valid:  # made with no slack: nothing moves, or no room for a halo
                self.watch = None
        self.horizon_steps = min(2 * self.horizon_steps, QUIET_HORIZON_STEPS[1]) if quiet > 0 else QUIET_HORIZON_STEPS[0]
        return quiet

    def _hold_everything(self):
        """Every process takes every sphere and runs the rest alone, all alike; returns the new
        :class:`_LargestCluster`.  Called once the look-aheads follow paths: the steps of such a
        late stage move a few small clusters and one rigid cluster, which sharing out does not
        speed up (each step its rows cross rank borders, to be migrated and binned again), and
        on one process the rigid cluster's flights are deferred (:meth:`_deferral`)."""
        self.global_id, self.X, self.V = self.domain.hold_everything(self.global_id, self.X, self.V)
        self.R, self.own_cluster = self.R_all[self.global_id], self.cluster[self.global_id]
        self.watch = None
        self._closing = None
        self._largest = _LargestCluster(self.cluster, self.n_clusters, self.global_id, self.own_cluster)
        return self._largest

    def _follows_paths(self, largest):
        """Whether the look-aheads follow the paths of the few spheres outside the largest
        cluster through its frame, with no watch (at most ``PATH_QUERIES`` of them)."""
        return largest.holds_most and self.n - largest.size <= PATH_QUERIES

    def _steps_before_contact(self, largest, duration, dt):
        """Steps of length ``dt`` before any two spheres of different clusters, flying straight,
        can touch, looked at over ``duration``: the paths of the spheres outside the largest
        cluster through its frame, and every pair of them (one process: :meth:`_hold_everything`)."""
        frame = self._frame(largest, self._frame_cutoff())
        first = min(frame.first_contact(self.X, self.V, self.R, largest.outside, duration, log=self._log()),
                    first_contact_among(self.X, self.V, self.R, self.own_cluster, largest.outside))
        return steps_before(first, dt) if first < math.inf else math.inf

    def _frame_cutoff(self):
        """The search distance the largest cluster's frame is binned for: that of the longest
        watch."""
        return self.contact + QUIET_HORIZON_BOX_FRACTION * self.L

    def _new_watch(self, dt, closing):
        """A watch of the pairs within the gap the fastest pair closes in ``horizon_steps`` steps,
        or less (see the constants), searched from the spheres outside the largest cluster
        (every pair of different clusters has an end there)."""
        self._settle()
        largest = self._largest_cluster()
        horizon = min(self.horizon_steps * closing * dt, QUIET_HORIZON_BOX_FRACTION * self.L,
                      self.domain.max_halo_width - self.contact, self._affordable_horizon(self.n - largest.size))
        _, ids, X, R, cluster = self._with_ghosts(self.contact + horizon)
        n_owned = self.X.shape[0]
        if largest.holds_most:  # search in the largest one's frame
            pairs = self._pairs_outside(largest, X, R, cluster, n_owned, horizon, self.contact + horizon)
        else:
            k, side = grid_size(self.L, self.contact + horizon, self.d, self.n, CONTACT_CELLS_PER_SPHERE)
            pairs = cross_cluster_pairs(X, R, cluster, largest.outside, horizon, side, k)
        # every pair has an owned end (a query); a watch needs neither order nor uniqueness, which
        # _shared_pairs would buy with a sort of every pair (over a million in a late-stage watch
        # with a long horizon)
        if self.domain.size == 1:  # the pairs' rows are known: spare the watch mapping them back (O(N))
            return Watch(ids[pairs], horizon, held=ids, rows=pairs)
        return Watch(self.domain.gather(ids[pairs]), horizon)

    def _pairs_outside(self, largest, X, R, cluster, n_owned, horizon, cells_for):
        """The pairs of spheres of different clusters with a gap of at most ``horizon`` and an
        end outside the largest cluster, ``largest`` searched in its own frame (binned for
        searches up to ``cells_for``): each process reports those with an owned end in the
        largest cluster, and those between two other spheres with an owned end."""
        queries = np.concatenate([largest.outside, n_owned + np.flatnonzero(cluster[n_owned:] != largest.label)])
        frame = self._frame(largest, cells_for)
        with_largest = frame.pairs_near(X, R, queries, horizon, log=self._log())
        k, side = grid_size(self.L, self.contact + horizon, self.d, max(queries.size, 1), CONTACT_CELLS_PER_SPHERE)
        among = queries[cross_cluster_pairs(X[queries], R[queries], cluster[queries], np.arange(queries.size),
                                            horizon, side, k)]
        among = among[(among < n_owned).any(axis=1)]
        return np.concatenate([with_largest, among])

    def _affordable_horizon(self, n_queries):
        """The largest horizon at which the quiet-step search from ``n_queries`` spheres looks at
        about ``QUIET_PAIRS_PER_SPHERE`` pairs per sphere of the run (its ``3^d`` cells of side
        ``contact + horizon`` hold ``n / L^d`` spheres per unit volume).  A search between two large
        clusters up to L/4 costs more than all the steps it saves."""
        per_query = QUIET_PAIRS_PER_SPHERE * self.n / max(n_queries, 1)
        block_side = (per_query * self.L**self.d / self.n) ** (1.0 / self.d)
        return max(block_side / 3.0 - self.contact, 0.0)

    def _shared_pairs(self, pairs, ids, n_owned):
        """Local pairs with an owned end, as global ids ``(min, max)``, from every process:
        sorted, each once."""
        pairs = pairs[(pairs < n_owned).any(axis=1)] if pairs.size else pairs.reshape(0, 2)
        first, second = ids[pairs[:, 0]], ids[pairs[:, 1]]
        keys = np.minimum(first, second) * self.n + np.maximum(first, second)
        keys = _distinct(self.domain.gather(keys))  # a 1-d sort: 6x faster than of the rows
        return np.column_stack([keys // self.n, keys % self.n])

    def _problem_width(self, drift, margin):
        """Halo width of a minimisation: the reach of its pairs and links, twice the ``margin``
        (both ends move), and ``drift``, how far spheres moved earlier in the time step."""
        return max(self.contact + self.reach, self.min_tile) + 2.0 * margin + drift

    def _first_margin(self, drift):
        """The margin a minimisation starts with: ``first_margin``, or what the narrowest rank
        slab leaves room for, but not less than ``margin`` (the same on every process)."""
        room = 0.5 * (self.domain.max_halo_width - self._problem_width(drift, 0.0))
        return max(self.margin, min(self.first_margin, room))

    def _drift(self, start, rows):
        """Largest displacement since ``start`` of the owned ``rows``, over all processes."""
        local = float(np.sqrt(((self.X[rows] - start[rows]) ** 2).sum(axis=1)).max()) if rows.size else 0.0
        return self.domain.max(local)

    def interact(self, step, time):
        """Step 2: link, minimise, link what the minimisation made touch, until nothing new.
        Returns whether any link was made."""
        follows_paths = self._follows_paths(self._largest_cluster())
        if self.watch is not None or not follows_paths:
            self._settle()
        _, ids, X, R, cluster = self._with_ghosts(self.contact)
        n_owned = self.X.shape[0]
        if self.watch is not None:
            touching = self.watch.contacts(X, R, cluster, ids)
        elif follows_paths:
            touching = self._pairs_outside(self._largest_cluster(), X, R, cluster, n_owned, 0.0, self._frame_cutoff())
        else:
            touching = cross_cluster_contacts(X, R, cluster, self.grid_side, self.grid_k)
        new = self._shared_pairs(touching, ids, n_owned)
        if new.shape[0] == 0:
            return False
        self._settle()  # the minimisation reads and moves every sphere of the merging clusters
        made = [new]
        self.links.add(new[:, 0], new[:, 1], step)
        start = self.X.copy()
        drift = 0.0  # how far any sphere has moved since the step's free flight
        for _ in range(MAX_LINK_ROUNDS):
            moving = self._minimise(np.concatenate(made), made[-1], step, time, drift)
            drift = max(drift, self._drift(start, moving))  # only the moving rows have moved
            _, ids, X, R, _ = self._with_ghosts(self.contact + drift)
            touching = unlinked_contacts(X, R, moving, self.grid_side, self.grid_k, ids,
                                         self.links.head, self.links.next, self.links.to)
            fresh = self._shared_pairs(touching, ids, n_owned)
            if fresh.shape[0] == 0 or self.links.add(fresh[:, 0], fresh[:, 1], step) == 0:
                break
            made.append(fresh)
        else:
            raise MinimiserFailure(f"time step {step} (t = {time:.6g}): the link set still changed after "
                                   f"{MAX_LINK_ROUNDS} rounds of minimisation (step 2e)")
        self._closed_by(2.0 * drift)
        made = np.concatenate(made)
        labels, m = merge_clusters(self.cluster, self.n_clusters, made)
        merged = _distinct(labels[made[:, 0]])  # every merged cluster holds an end of a new link
        own_labels = labels[self.global_id]  # step 3, eq. 2.9
        sums = self.domain.sum_array(cluster_momenta(self.V, self.m_all[self.global_id], own_labels, merged))
        set_cluster_velocities(self.V, own_labels, merged, sums)
        self._closing = None
        self.cluster, self.n_clusters, self.own_cluster = labels, m, own_labels
        return True

    def _minimise(self, made, latest, step, time, drift):
        """One minimisation (step 2c) of the clusters joined by the links ``made`` in this time
        step, in the tiles holding an end of the ``latest`` of them; returns the owned rows that
        moved.  ``drift``: how far spheres moved earlier in this time step."""
        involved = involved_spheres(self.cluster, self.n_clusters, made, self.own_cluster)  # owned rows
        tilings = self._tilings(involved, first_round=latest.shape[0] == made.shape[0])
        for k in tilings:
            cap = self.daha.max_iterations if k == tilings[-1] else min(self.daha.max_iterations, TILED_ITERATIONS)
            moving, problem, outcome = self._solve(involved, latest, k, drift, replace(self.daha, max_iterations=cap))
            if outcome.converged or not outcome.finite or outcome.left_halo:
                break
        if self.daha.carry_multipliers:
            self._keep_multipliers(problem, outcome.multipliers)

        def where():  # collective: every rank reports the same failure
            return (f"time step {step} (t = {time:.6g}), {int(self.domain.sum(problem.n_moving))} moving spheres, "
                    f"{int(self.domain.sum(problem.n_links))} links")

        if not outcome.finite:
            raise MinimiserFailure(f"DAHA produced a non-finite position at iteration {outcome.iterations}, {where()}")
        moved = self.domain.max(float(np.sqrt(((problem.positions[:problem.n_moving] - self.X[moving]) ** 2)
                                              .sum(axis=1)).max()) if moving.size else 0.0)
        if outcome.left_halo or moved > self.max_displacement:
            raise MinimiserFailure(f"DAHA moved a sphere by more than {self.max_displacement:g} ({MAX_DISPLACEMENT:g} "
                                   f"largest radii) at iteration {outcome.iterations}: the iteration went "
                                   f"unstable, {where()}")
        if not outcome.converged:
            raise MinimiserFailure(
                f"DAHA did not converge in {outcome.iterations} iterations, {where()}: mean overlap "
                f"{outcome.mean_overlap:.3g} (eps_c {self.daha.overlap_tolerance:g}), deepest overlap "
                f"{outcome.max_overlap:.3g} (eps_max {self.daha.max_overlap_tolerance:g}), last step "
                f"{outcome.max_step:.3g} (eps_s {self.daha.steadiness_tolerance:g})")
        self.X[moving] = problem.positions[: problem.n_moving]
        return moving

    def _tilings(self, involved, first_round):
        """Tiles per side to minimise in, in the order tried, each but the last for at most
        ``TILED_ITERATIONS``.  A later round of step 2e tries finer tiles
        (:mod:`parsim.core.ts.tiles`) before the first round's: at N = 102 400, V_f = 0.1 the 16
        spheres of one round could not meet the stopping tests between anchors so near.  The
        last resort is one tile, every involved sphere moving and none held as an anchor: at
        N = 10^6, V_f = 0.3 a first round of 494 361 spheres left one caged 0.16 deep by three
        anchors, and it stayed caged for 100 000 iterations."""
        if self.formulation != "almost_rigid":
            return [1]
        if self.tiles:
            tilings = [self.tiles]
        else:
            n_interacting = int(self.domain.sum(float(involved.sum())))
            law = tiles_per_side(n_interacting, self.d, self.L, self.min_tile)
            fine = later_round_tiles_per_side(n_interacting, self.d, self.L, self.min_tile)
            tilings = [law] if first_round or fine == law else [fine, law]
        return tilings if tilings[-1] == 1 else tilings + [1]

    def _solve(self, involved, latest, k, drift, daha):
        """DAHA (parameters ``daha``) on the ``involved`` owned rows (a mask) in the tiles (``k`` per side)
        holding an end of a ``latest`` link, the surrounding tiles' as anchors:
        ``(moving, problem, outcome)``.
        A sphere leaving the halo doubles the margin (:meth:`_first_margin`) and starts again.  A failed attempt in
        some tiles counts as a minimisation of its own."""
        seeds = np.flatnonzero(np.isin(self.global_id, latest.reshape(-1)))
        active = _distinct(self.domain.gather(tiles_of(self.X, seeds, self.L, k)))
        moving, anchors = select_spheres(self.X, involved, active, self.L, k)
        moving = moving[self._memory_order(moving)]
        cell_of, n_cells, shared_cells = self._stopping_cells(moving, k)
        margin = self._first_margin(drift)
        while True:
            problem, exchange = self._problem(moving, anchors, drift, margin)
            carried = self._carried_multipliers(problem) if self.daha.carry_multipliers else None
            outcome = minimise(problem, daha, self.attraction_range, exchange, multipliers=carried,
                               tile_of=cell_of, n_tiles=n_cells, shared_tiles=shared_cells)
            self.work += problem.n_moving * outcome.iterations
            if not outcome.left_halo:
                break
            margin *= 2.0  # every rank saw the same largest displacement
            self.margin = max(self.margin, margin)
            if margin > self.max_displacement:
                break
        self.n_minimisations += 1  # counted once: a run with a wider halo from the start is the same
        self.n_iterations += outcome.iterations
        self.max_iterations = max(self.max_iterations, outcome.iterations)
        return moving, problem, outcome

    def _stopping_cells(self, moving, k):
        """The cells the minimisation of the owned rows ``moving`` in ``k`` tiles per side stops
        in one by one (:func:`parsim.core.ts.daha.minimise`): the cell of each moving row among
        those of this process, how many it holds, and the cells held by several processes (in
        the order of the grid, the same everywhere) as numbered here, -1 if not held here."""
        cells = tiles_of(self.X, moving, self.L, stopping_cells_per_side(k, self.L, self.contact))
        held = _distinct(cells)
        everyone, holders = np.unique(self.domain.gather(held), return_counts=True)
        shared = everyone[holders > 1]
        here = np.searchsorted(held, shared)
        found = here < held.size
        found[found] = held[here[found]] == shared[found]
        return np.searchsorted(held, cells), held.size, np.where(found, here, -1).astype(np.int64)

    def _memory_order(self, rows):
        """An order of the owned ``rows`` cell by cell on the contact grid (ties by global id), so
        that a sphere's partners sit near it in the minimiser's arrays: a replayed minimisation
        of 84 000 spheres ran 1.5x faster, with the same iterations, than in row order."""
        cells = tiles_of(self.X, rows, self.L, self.grid_k)
        return np.argsort(cells * self.n + self.global_id[rows])  # one key: 10x faster than np.lexsort

    def _problem(self, moving, anchors, drift, margin):
        """The minimisation of the owned rows ``moving`` with ``anchors`` fixed, the members of
        other processes within the halo width (for spheres moving up to ``margin``) as ghosts; and
        its exchange."""
        members = np.concatenate([moving, anchors])
        width = self._problem_width(drift, margin)
        if width > self.domain.max_halo_width:
            raise MinimiserFailure(f"the halo a minimisation needs ({width:g} wide: spheres moved {drift:g} earlier "
                                   f"in the step, margin {margin:g}) is wider than the narrowest rank slab "
                                   f"({self.domain.max_halo_width:g}); run this task on fewer ranks")
        halo = self.domain.ghosts(self.X[members], self.global_id[members], width)
        is_moving = np.zeros(members.size)
        is_moving[: moving.size] = 1.0
        ghosts = Ghosts(positions=halo.exchange(self.X[members]).copy(), radii=self.R_all[halo.ghost_global_id],
                        global_id=halo.ghost_global_id, moving=halo.exchange(is_moving) > 0.5)
        problem = build_problem(self.X, self.R, moving, anchors, self.links, self.reach, self.local_of,
                                global_id=self.global_id, ghosts=ghosts)
        return problem, self.domain.problem_exchange(halo, margin)

    def _carried_multipliers(self, problem):
        """Each candidate pair's multiplier at the end of its link's last minimisation (NaN if none)."""
        index = problem.pair_links(self.links)
        return np.where(index >= 0, self.links.multiplier[index], np.nan)

    def _keep_multipliers(self, problem, multipliers):
        """Store the linked pairs' final multipliers, on every process (each counted pair once)."""
        index = problem.pair_links(self.links)
        kept = (index >= 0) & problem.pair_counted
        rows = np.column_stack([index[kept].astype(np.float64), multipliers[kept]])
        rows = self.domain.gather(rows)
        self.links.multiplier[rows[:, 0].astype(np.int64)] = rows[:, 1]

    def step_imbalance(self):
        """max / mean over the ranks of the work since the last call (owned spheres plus
        moving-sphere iterations)."""
        imbalance = self.domain.imbalance(self.X.shape[0] + self.work)
        self.work = 0.0
        return imbalance

    def result_rows(self):
        """Positions and velocities of all spheres, by global id."""
        self._settle()
        ids = self.domain.gather(self.global_id)
        order = np.argsort(ids)
        return self.domain.gather(self.X)[order], self.domain.gather(self.V)[order]


def _distinct(values):
    """The distinct ``values`` (1-d integers), sorted, as ``np.unique`` gives them.  ``np.unique``
    hashes them first since numpy 2.3, some forty times slower than this sort on the million link
    keys of the first two steps at N = 10^6."""
    values = np.sort(values)
    first = np.ones(values.shape[0], dtype=np.bool_)
    first[1:] = values[1:] != values[:-1]
    return values[first]


def _quiet_steps_within(quiet, steps_left, time_left_in_steps):
    """``quiet`` (a float bound) as a number of steps that stays within the run's limits."""
    return int(min(quiet, steps_left, math.floor(time_left_in_steps) if math.isfinite(time_left_in_steps)
                   else math.inf))


def _time_steps(run, dt0, max_time, max_steps):
    """The time loop of section 3 until one cluster remains or a limit is reached.  The
    histories (M and t after each step) are kept in chunks, one per quiet stretch or searched
    step: a late stage can take tens of millions of steps (N = 250 000, V_f 0.2: 22 million)."""
    n = run.n
    t = 0.0
    step = 0
    n_wall = 0
    clusters, times, imbalance = [], [], []
    reason = "single_cluster"
    look_ahead = False  # after a step that made no link, look for quiet steps
    while run.n_clusters > 1:
        if t >= max_time:
            reason = "max_time"
            break
        if step >= max_steps:
            reason = "max_steps"
            break
        dt = dt0 * (1.0 + math.log(n / run.n_clusters) / math.log(n))
        quiet = _quiet_steps_within(run.quiet_steps(dt), max_steps - step, (max_time - t) / dt) if look_ahead else 0
        if quiet > 0:  # steps 1 only: nothing touches, nothing reaches a wall
            run.coast(quiet, dt)
            stretch = np.add.accumulate(np.concatenate([[t], np.full(quiet, dt)]))[1:]  # t += dt, step by step
            t = float(stretch[-1])
            times.append(stretch)
            clusters.append(np.full(quiet, run.n_clusters, dtype=np.int64))
            step += quiet
            look_ahead = False  # the next step may link: search it
            continue
        dt = min(dt, max_time - t)
        step += 1
        t += dt
        n_wall += run.advect(dt)  # step 1
        look_ahead = not run.interact(step, t)
        imbalance.append(run.step_imbalance())
        clusters.append(np.array([run.n_clusters], dtype=np.int64))
        times.append(np.array([t]))
    return t, step, n_wall, reason, _joined(clusters, np.int64), _joined(times, np.float64), imbalance


def _joined(chunks, dtype):
    """One array of the history ``chunks`` (empty for none)."""
    return np.concatenate(chunks) if chunks else np.empty(0, dtype=dtype)


def simulate_ts(positions, velocities, radii, masses, box_length, time_step_factor=0.005,
                formulation="almost_rigid", daha=None, attraction_range=None, max_time=math.inf,
                max_steps=None, tiles=None, domain=None):
    """Run time-stepping ballistic aggregation in the box ``[0, box_length]^d``.

    Parameters
    ----------
    positions, velocities, radii, masses : as for :func:`parsim.core.ed.simulate_ed`,
        in d = 2 or 3.
    time_step_factor : float > 0
        ``dt(0) = factor L / max|V|`` (Table 1: 0.005, 0.01, 0.015).
    formulation : "almost_rigid" (section 3.3) or "non_rigid" (section 3.1).
    daha : DahaParameters, default eq. 4.1.
    attraction_range : float, ``Delta_W`` of eq. 3.30 (almost-rigid only); default 4 max R.
    max_time, max_steps : stop there if several clusters remain.
    tiles : int or None
        Tiles per side (almost-rigid); ``None`` follows the law of :mod:`parsim.core.ts.tiles`.
        A minimisation that does not converge in them is solved again in one tile.
    domain : where the spheres live (:mod:`parsim.core.ts.domain`); default one process,
        :class:`parsim.aggregation.tiled.DecomposedDomain` for a run over MPI ranks.  Every rank
        passes the same arguments and gets the same result.

    Raises
    ------
    MinimiserFailure
        A minimisation did not converge or went non-finite; the message gives the time step.

    Why so many parameters: the initial condition (four arrays and the box length) and the method's
    options, each a keyword with its default (Table 1, eq. 4.1, eq. 3.30), named by the caller.
    """
    check_formulation(formulation)
    X = np.array(positions, dtype=np.float64, copy=True)
    check_discs_or_spheres(X)
    V = np.array(velocities, dtype=np.float64, copy=True)
    R = np.ascontiguousarray(radii, dtype=np.float64)
    m = np.ascontiguousarray(masses, dtype=np.float64)
    n = X.shape[0]
    L = float(box_length)
    daha = daha or DahaParameters()
    if attraction_range is None:
        attraction_range = 4.0 * float(R.max())
    max_steps = np.iinfo(np.int64).max if max_steps is None else int(max_steps)
    speed = float(np.sqrt((V**2).sum(axis=1)).max())
    if not speed > 0.0:
        raise ValueError("velocities must not all be zero (dt(0) = factor L / max|V|)")
    dt0 = time_step_factor * L / speed
    domain = domain or SerialDomain()
    try:
        run = _Run(X, V, R, m, L, formulation, daha, attraction_range, tiles, domain)
        t, step, n_wall, reason, clusters, times, imbalance = _time_steps(run, dt0, max_time, max_steps)
        X, V = run.result_rows()
    finally:
        domain.close()
    return TSResult(positions=X, velocities=V, cluster=run.cluster, links=run.links.pairs(),
                    link_steps=run.links.steps(), time=t, n_steps=step, n_collisions=n - run.n_clusters,
                    n_wall_reflections=n_wall, n_minimisations=run.n_minimisations,
                    n_iterations=run.n_iterations, max_iterations=run.max_iterations, stop_reason=reason,
                    cluster_history=clusters, time_history=times,
                    imbalance=np.array(imbalance))
