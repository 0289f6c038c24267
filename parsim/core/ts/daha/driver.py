"""DAHA's driver: its parameters and result, the iterations in one jitted call, and :func:`minimise`.

:func:`_iterations` runs iterations until a check asks Python for something or a pair search is
due; :class:`_Minimisation` keeps the state between its calls and does the searches.
"""

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from parsim.core import kernel_mpi
from parsim.core.jit import jit
from parsim.core.kernel_mpi import global_max
from parsim.core.ts.daha.ghosts import _drift_ghosts, _share_motion, GhostMotion, motion_width
from parsim.core.ts.daha.pairs import _carried, _rebase
from parsim.core.ts.daha.scheme import (
    _attracting_links, _constraint_values, _copy_rows, _drift, _initial_multipliers, _kick_damp_drift,
    _largest_step, _overlaps, _update_cross_pairs_near, _update_multipliers, _update_multipliers_near,
)
from parsim.core.ts.daha.sleeping import _drop_settled, _spread, _spread_dense
from parsim.core.ts.daha.stopping import _check, _GO_ON, CONVERGED, NOT_FINITE, REACHED_LAST, REFRESH_DUE


#: With dynamic parameters, phi_A below OVERLAP_FLOOR x eps_c counts as no overlap at all.
OVERLAP_FLOOR = 1e-9
#: The multiplier rate is kept below this fraction of the linear stability bound c gamma / (2 alpha).
STABILITY_MARGIN = 0.5
#: A sphere's kick is scaled down when delta^2 times its stiffness exceeds this (package docstring).
STIFFNESS_LIMIT = 2.0
#: The damping of one iteration, delta c_i, is clipped here: at 1 a sphere's velocity would be
#: erased in every iteration (package docstring, "Dynamic parameters").
MAX_DAMPING = 0.9
#: Once a moving sphere is this fraction of the candidate reach away from where its pairs were
#: last searched, its pairs are searched again (contacts.updated_candidate_pairs needs <= 1/3) ...
REFRESH_DRIFT = 1.0 / 3.0
#: ... and so are those of every sphere more than this fraction of that distance away.
REFRESH_SET = 0.5
#: With sleeping spheres, every sphere is updated (and the stopping conditions tested) once
#: in this many iterations.
FULL_SWEEP_EVERY = 16
#: A tile steady but deeper than eps_max at this many checks in a row is jammed (package docstring).
JAMMED_CHECKS = 4


@dataclass(frozen=True)
class DahaParameters:
    """The numerical parameters of DAHA: eq. 4.1 except ``damping`` and ``penalty``
    (see the package docstring: the printed pair is linearly unstable).

    ``initial_multiplier`` is the constant ``lambda`` of eq. 3.26 (the paper gives no
    value); ``max_iterations`` bounds one minimisation, beyond which it is reported as
    not converged.  ``max_overlap_tolerance``, ``carry_multipliers`` and ``sleep_tolerance`` are ours
    (package docstring).
    """

    damping: float = 3.0  #: c (c_bar of (3.29) when dynamic); eq. 4.1 has 1.3
    step: float = 0.15  #: delta, the artificial time step
    attraction: float = 0.3  #: alpha
    penalty: float = 30.0  #: gamma; eq. 4.1 has 0.3
    multiplier_rate: float = 10.0  #: beta (beta_bar of (3.29) when dynamic); eq. 4.1 has 3
    overlap_tolerance: float = 1e-2  #: eps_c of (3.28), a length
    steadiness_tolerance: float = 1e-3  #: eps_s of (3.27), a length
    max_overlap_tolerance: float = 0.1  #: eps_max, bound on the deepest overlap max o_ij, a length
    initial_multiplier: float = 1.0  #: lambda of (3.26)
    dynamic: bool = False  #: c and beta from (3.29); False: the constants c_bar, beta_bar of (3.15)-(3.16)
    max_iterations: int = 100_000
    carry_multipliers: bool = True  #: links start from their last multiplier, not from (3.26)
    sleep_tolerance: float = 1e-4  #: a length; 0: every sphere is updated in every iteration


@dataclass
class Outcome:
    """What one minimisation did."""

    converged: bool
    iterations: int
    mean_overlap: float  #: mean overlap over the links at the end (3.28)
    max_overlap: float  #: the deepest overlap max o_ij at the end
    max_step: float  #: largest displacement of the last iteration (3.27)
    finite: bool
    multipliers: np.ndarray  #: lambda of each candidate pair of the problem at the end
    left_halo: bool = False  #: a sphere moved farther than the exchange's ``margin`` (decomposed runs)


class SerialExchange:
    """The halo interface of the minimiser on one process: every call is a no-op.

    A decomposed run passes an object with the same members: ``sum`` and ``max`` reduce a float
    over all parts of the problem;
    ``margin`` is how far a sphere may move from where the ghosts were chosen; ``kernel_halo``
    is the same exchange for the jitted iterations (:mod:`parsim.core.kernel_mpi`).
    """

    margin = math.inf

    @property
    def kernel_halo(self):
        """The halo of :mod:`parsim.core.kernel_mpi` for the jitted iterations: none."""
        return kernel_mpi.no_halo()

    def sum(self, value):
        return value

    def max(self, value):
        return value


@jit
def _iterations(iteration, last, state, awake, stepped, drift, refresh_at, flags, measures, adjacency, pairs,
                coefficients, checks, dynamic, ghost_motion, halo):
    """DAHA iterations from ``iteration`` on, in one call, with the ghost rows and the reductions
    exchanged from here (:mod:`parsim.core.kernel_mpi`), until ``last``, the stopping tests, a
    non-finite value, or an iteration whose pairs must be searched again (the global ``drift``
    above ``refresh_at``; it returns before moving anything).  Returns ``(iteration, awake,
    stepped, drift, why, flags, measures)``, ``flags`` = ``(polishing, any_settled)`` and
    ``measures`` = ``(mean_overlap, typical_overlap, largest, deepest)``.

    Each iteration: the drift test; on a full sweep every sphere outside settled tiles awake;
    (3.20)-(3.23) for the awake spheres; (3.24) for their pairs; then, between checks, the
    spheres that a moving partner wakes (package docstring, "Sleeping spheres"), and on a check
    the tests of :func:`_check`.

    Why so many parameters: besides the named bundles (``state`` a :class:`MinimiserState`,
    ``adjacency``, ``pairs``, ``coefficients``, ``checks``, ``ghost_motion``, ``halo``), a call takes the
    progress the previous one returned (iteration, awake and stepped rows, drift, flags, measures)."""
    P, R, U, new, previous, previous_ghost = state.P, state.R, state.U, state.new, state.previous, state.previous_ghost
    built_at, lam, phi, damping_of = state.built_at, state.lam, state.phi, state.damping_of
    is_awake, settled, is_anchor = state.is_awake, state.settled, state.is_anchor
    pair_a, pair_b, cross_pairs = pairs
    delta, stable, sleep = coefficients.step, coefficients.stable, coefficients.sleep
    multiplier_rate, floor, n_spheres = coefficients.multiplier_rate, coefficients.floor, coefficients.n_spheres
    polishing, any_settled = flags
    n_moving = U.shape[0]
    first_ghost = P.shape[0] - previous_ghost.shape[0]
    ghost_U, arrived = ghost_motion.ghost_U, ghost_motion.arrived
    while iteration < last:
        guarded = max(measures[1], floor)
        rate = delta * multiplier_rate * (math.sqrt(n_spheres) / guarded if dynamic else 1.0)
        check = sleep == 0.0 or iteration % FULL_SWEEP_EVERY == 0
        _copy_rows(previous, P, stepped)
        drift = max(drift, _largest_step(P, built_at, stepped))
        if global_max(drift, halo) > refresh_at:  # a pair may come within reach
            return iteration, awake, stepped, drift, REFRESH_DUE, (polishing, any_settled), measures
        full = check and not polishing
        if full:
            awake = _drop_settled(np.arange(n_moving), settled, is_awake) if any_settled else np.arange(n_moving)
        stepped = awake
        _drift(P, U, awake, 0.5 * delta)
        _drift_ghosts(P, ghost_U, previous_ghost, first_ghost, 0.5 * delta)
        _kick_damp_drift(state, adjacency, coefficients, awake, guarded, dynamic)
        _copy_rows(P, new, awake)  # accept the new positions
        n_arrived = _share_motion(P, U, damping_of, previous_ghost, is_awake, awake, ghost_motion, halo)
        mostly_awake = 2 * awake.shape[0] > n_moving  # then pair by pair beats sphere by sphere
        if full:
            _update_multipliers(P, R, phi, pair_a, pair_b, lam, rate, damping_of, stable, settled | is_anchor)
        elif mostly_awake:
            _update_multipliers(P, R, phi, pair_a, pair_b, lam, rate, damping_of, stable, ~is_awake)
        else:
            _update_multipliers_near(state, adjacency, awake, rate, stable)
            _update_cross_pairs_near(P, R, cross_pairs, pair_a, pair_b, is_awake, phi, lam, rate, damping_of, stable)
        iteration += 1
        if check:
            why, awake, polishing, any_settled, measures = _check(state, awake, polishing, adjacency, pairs, checks,
                                                                  sleep, ghost_U, halo)
            if why != _GO_ON:
                return iteration, awake, stepped, drift, why, (polishing, any_settled), measures
            continue
        if mostly_awake:
            awake = _spread_dense(state, adjacency, pairs, arrived[:n_arrived], awake, sleep)
        else:
            awake = _spread(state, adjacency, arrived[:n_arrived], awake, sleep)
        if any_settled:
            awake = _drop_settled(awake, settled, is_awake)
    return iteration, awake, stepped, drift, REACHED_LAST, (polishing, any_settled), measures


def minimise(problem, params, attraction_range=math.inf, exchange=None, on_iteration=None, multipliers=None,
             tile_of=None, n_tiles=1, shared_tiles=None):
    """Run DAHA on ``problem`` until (3.27), (3.28) and the deepest-overlap bound hold in
    every tile, or ``max_iterations``.

    ``tile_of`` gives the tile (``0 .. n_tiles - 1``, numbered on each process) of each moving
    sphere, the regions that stop one by one; ``None`` is one tile, the whole problem.  The
    tiles that several processes hold are ``shared_tiles``, in one order on every process: the
    local number of each, -1 where this process holds none of it (``None``: none).

    ``multipliers`` (one per candidate pair, NaN where unknown) replace the initial
    multipliers of (3.26) where given.  ``attraction_range`` is ``Delta_W`` of eq. 3.30 (``inf``: eq. 3.5).  ``exchange``
    is the halo interface (:class:`SerialExchange` by default).  ``on_iteration(r,
    problem)``, if given, is called after every iteration (a test hook).  Moving
    positions are updated in ``problem.positions``.  Stops early, with
    ``finite=False``, at the first full sweep after a position becomes non-finite, and with
    ``left_halo=True`` when a sphere moved farther than ``exchange.margin``.
    """
    run = _Minimisation(problem, params, attraction_range, exchange or SerialExchange(), multipliers,
                        np.zeros(problem.n_moving, dtype=np.int64) if tile_of is None else tile_of, n_tiles,
                        np.zeros(0, dtype=np.int64) if shared_tiles is None else shared_tiles)
    while run.iteration < params.max_iterations:
        why = run.iterate(params.max_iterations if on_iteration is None else run.iteration + 1)
        if why == REFRESH_DUE:
            if run.left_halo():
                return run.outcome(False, left_halo=True)
            run.refresh_pairs()
            continue
        if on_iteration is not None:
            on_iteration(run.iteration, problem)
        if why != REACHED_LAST:
            return run.outcome(why == CONVERGED, finite=why != NOT_FINITE)
    return run.outcome(False)


class MinimiserState(NamedTuple):
    """What the iterations read and change: positions ``P`` (moving rows, then anchors and ghosts) and
    ``R``, velocities ``U``, the trial ``new`` rows, ``previous`` positions (and the ghosts'), where the
    pairs were searched (``built_at``), multipliers ``lam`` and constraint values ``phi`` per pair, each
    sphere's overlap, which links attract, each row's damping, and the awake, settled and anchor flags."""

    P: np.ndarray
    R: np.ndarray
    U: np.ndarray
    new: np.ndarray
    previous: np.ndarray
    previous_ghost: np.ndarray
    built_at: np.ndarray
    lam: np.ndarray
    phi: np.ndarray
    sphere_overlap: np.ndarray
    attracts: np.ndarray
    damping_of: np.ndarray
    is_awake: np.ndarray
    settled: np.ndarray
    is_anchor: np.ndarray


class Adjacency(NamedTuple):
    """Each moving sphere's links (``link_ptr``, ``link_to``) and pairs (``pair_ptr``, ``pair_of``,
    ``pair_partner``), and each ghost's pairs (``ghost_ptr``, ``ghost_partner``), in CSR form."""

    link_ptr: np.ndarray
    link_to: np.ndarray
    pair_ptr: np.ndarray
    pair_of: np.ndarray
    pair_partner: np.ndarray
    ghost_ptr: np.ndarray
    ghost_partner: np.ndarray


class PairLists(NamedTuple):
    """The pairs' two rows, and the pairs across the rank's border."""

    pair_a: np.ndarray
    pair_b: np.ndarray
    cross_pairs: np.ndarray


class Coefficients(NamedTuple):
    """The scheme's coefficients: delta, alpha, gamma, c_bar of (3.20)-(3.24), the damping where
    (3.26) is stable, the sleep tolerance, the stiffness and damping limits, beta, the overlap floor
    of the dynamic rate (3.29) and the number of moving spheres over all ranks."""

    step: float
    attraction: float
    penalty: float
    damping: float
    stable: float
    sleep: float
    stiffness_limit: float
    max_damping: float
    multiplier_rate: float
    floor: float
    n_spheres: float


class Checks(NamedTuple):
    """What the stopping tests read: each row's tile, the tiles shared with neighbours, each tile's
    jammed count and flag, the restless rows, which pairs are counted, the tolerances
    (eps_s, eps_max, eps_c), the number of links and the jammed limit."""

    tile_of: np.ndarray
    shared_tiles: np.ndarray
    jammed_checks: np.ndarray
    in_jammed_tile: np.ndarray
    restless: np.ndarray
    pair_counted: np.ndarray
    tolerances: tuple
    n_links: float
    jammed_limit: int


class _Minimisation:
    """The state of one :func:`minimise` between calls of :func:`_iterations`, and the pair searches
    it returns for."""

    def __init__(self, problem, params, attraction_range, exchange, multipliers, tile_of, n_tiles, shared_tiles):
        self.problem, self.params, self.exchange = problem, params, exchange
        self.tile_of, self.shared_tiles = tile_of, shared_tiles
        P, R = problem.positions, problem.radii
        n_moving, d = problem.n_moving, P.shape[1]
        self.start = P[:n_moving].copy()
        self.built_at = P.copy()  # where the pairs of each row were last searched (anchors: never again)
        self.U = np.zeros((n_moving, d))
        self.lam = _initial_multipliers(P, R, problem.pair_a, problem.pair_b, params.initial_multiplier)
        if multipliers is not None:
            known = np.isfinite(multipliers)
            self.lam[known] = multipliers[known]
        self.sphere_overlap = np.zeros(n_moving if params.dynamic else 0)  # phi_i^A of (3.29), dynamic damping
        self.previous = self.start.copy()
        self.previous_ghost = P[problem.first_ghost:].copy()
        self.phi = np.empty(problem.pair_a.size)
        _constraint_values(P, R, problem.pair_a, problem.pair_b, self.phi)
        self.n_links = exchange.sum(float(problem.n_links))
        self.n_spheres = exchange.sum(float(n_moving))
        self.halo = exchange.kernel_halo
        n_rows, n_ghost = P.shape[0], P.shape[0] - problem.first_ghost
        sends = np.zeros(n_rows, dtype=np.bool_)
        sends[self.halo.rows] = True  # the owned rows some neighbour holds as ghosts
        # ghost velocities as on their owners, rows sent and received, flags of the changed rows, ghost rows arrived
        self.ghost_motion = GhostMotion(np.zeros((n_ghost, d)), np.zeros((n_rows, motion_width(d))),
                                        np.zeros(n_rows, dtype=np.bool_), sends, np.empty(n_ghost, dtype=np.int64))
        mean_overlap, typical_overlap = _overlaps(self.phi, problem.pair_counted, problem.link_ptr, problem.pair_ptr,
                                                  problem.pair_of, self.sphere_overlap, self.n_links, self.halo)
        self.measures = (mean_overlap, typical_overlap, math.inf, math.inf)  # and the largest step, deepest overlap
        range_sq = attraction_range**2 if math.isfinite(attraction_range) else math.inf
        self.attracts = _attracting_links(P, problem.link_ptr, problem.link_to, range_sq)
        self.new = np.empty((n_moving, d))
        self.damping_of = np.where(problem.moving_ghost, params.damping, math.inf)  # anchors never limit a rate
        self.damping_of[:n_moving] = params.damping
        self.is_anchor = self.damping_of == math.inf
        self.stable = params.step * STABILITY_MARGIN * params.penalty / (2.0 * params.attraction)
        self.everyone = np.arange(n_moving)
        self.awake = self.everyone
        self.is_awake = np.zeros(P.shape[0], dtype=np.bool_)  # moving rows, then ghost rows as on their owner
        self.restless = np.zeros(P.shape[0], dtype=np.bool_)
        self.moved = np.zeros(P.shape[0], dtype=np.bool_)  # whose candidate pairs are searched again
        self.settled = np.zeros(P.shape[0], dtype=np.bool_)  # moving rows in settled tiles, ghosts as on owner
        self.jammed_checks = np.zeros(n_tiles, dtype=np.int64)
        self.in_jammed_tile = np.zeros(P.shape[0], dtype=np.bool_)  # moving rows, then ghosts as on their owner
        self.flags = (False, False)  # polishing, any tile settled
        self.iteration = 0
        # Only the spheres stepped in an iteration move, so the bookkeeping between iterations
        # goes over those alone: ``previous`` equals ``P`` on every other moving row, and
        # ``drift`` bounds from above how far any moving sphere is from ``built_at``.
        self.stepped = self.everyone[:0]
        self.drift = 0.0

    def outcome(self, converged, finite=True, left_halo=False):
        mean_overlap, _, largest, deepest = self.measures
        return Outcome(converged, self.iteration, mean_overlap, deepest, largest, finite, self.lam,
                       left_halo=left_halo)

    def iterate(self, last):
        """Iterations up to ``last`` at most (:func:`_iterations`); returns why it stopped."""
        problem, params = self.problem, self.params
        state = MinimiserState(problem.positions, problem.radii, self.U, self.new, self.previous,
                               self.previous_ghost, self.built_at, self.lam, self.phi, self.sphere_overlap,
                               self.attracts, self.damping_of, self.is_awake, self.settled, self.is_anchor)
        adjacency = Adjacency(problem.link_ptr, problem.link_to, problem.pair_ptr, problem.pair_of,
                              problem.pair_partner, problem.ghost_ptr, problem.ghost_partner)
        coefficients = Coefficients(params.step, params.attraction, params.penalty, params.damping, self.stable,
                                    params.sleep_tolerance, STIFFNESS_LIMIT, MAX_DAMPING, params.multiplier_rate,
                                    OVERLAP_FLOOR * params.overlap_tolerance, self.n_spheres)
        tolerances = (params.steadiness_tolerance, params.max_overlap_tolerance, params.overlap_tolerance)
        checks = Checks(self.tile_of, self.shared_tiles, self.jammed_checks, self.in_jammed_tile, self.restless,
                        problem.pair_counted, tolerances, self.n_links, JAMMED_CHECKS)
        self.iteration, self.awake, self.stepped, self.drift, why, self.flags, self.measures = _iterations(
            self.iteration, last, state, self.awake, self.stepped, self.drift, REFRESH_DRIFT * problem.reach,
            self.flags, self.measures, adjacency, PairLists(problem.pair_a, problem.pair_b, problem.cross_pairs),
            coefficients, checks, params.dynamic, self.ghost_motion, self.halo)
        return why

    def left_halo(self):
        """Whether a sphere may now reach beyond the ghosts chosen for this minimisation."""
        problem, exchange = self.problem, self.exchange
        reach = REFRESH_DRIFT * problem.reach
        return exchange.max(_largest_step(problem.positions, self.start, self.everyone)) + reach > exchange.margin

    def refresh_pairs(self):
        """Search again the pairs of the spheres that drifted (package docstring, "Candidate pairs")."""
        problem = self.problem
        P, R = problem.positions, problem.radii
        self.drift = _rebase(P, self.built_at, problem.n_moving, problem.first_ghost,
                             REFRESH_SET * REFRESH_DRIFT * problem.reach, self.moved)
        self.lam, self.phi = _carried(problem.refresh_pairs(self.moved), self.lam, self.phi, P, R, problem.pair_a,
                                      problem.pair_b)
