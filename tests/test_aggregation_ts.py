"""Tests of the time-stepping aggregation with the DAHA minimiser (parsim.core.ts)."""

import math
from dataclasses import replace

import numpy as np
import pytest
import xarray as xr

from parsim.comparison import markdown, method_comparison
from parsim.core.initial import box_length_for_volume_fraction, isotropic_velocities, lattice_positions
from parsim.core.ts import DahaParameters, simulate_ts, stepper, tiles
from parsim.output.dataset import decoded
from parsim.core.ts.clusters import apply_reflections, free_flight, overruns, reflections, translate
from parsim.core.ts.contacts import cross_cluster_contacts
from parsim.core.ts.daha import attraction_energy, driver, minimise
from parsim.core.ts.daha.driver import FULL_SWEEP_EVERY
from parsim.core.ts.links import LinkSet
from parsim.core.ts.problem import build_problem
from parsim.core.ts.quiet import Watch
from tests.datasets import reproducible_part, run_serial
from tests.mpi import parsim_command, run_mpi

R = 0.2
PARAMS = DahaParameters()
#: A pair "in contact" after DAHA: its overlap measure sqrt(phi) is of order eps_c, so the
#: gap is of order eps_c^2 / (4R); a few times that bounds any single pair.
CONTACT_GAP = 10 * PARAMS.overlap_tolerance**2 / (4 * R)
#: The deepest overlap DAHA accepts: sqrt(phi_ij) <= eps_max, a gap of at least sqrt(4R^2 - eps_max^2) - 2R.
DEEPEST_GAP = math.sqrt(4 * R**2 - PARAMS.max_overlap_tolerance**2) - 2 * R - 1e-12


def all_gaps(x, radii):
    diff = x[:, None, :] - x[None, :, :]
    distance = np.sqrt((diff**2).sum(axis=2))
    iu = np.triu_indices(len(x), 1)
    return (distance - (radii[:, None] + radii[None, :]))[iu]


def touching_links(x, first=0):
    """Links between every pair of overlapping discs of ``x`` (numbered from ``first``)."""
    i, j = np.triu_indices(len(x), 1)
    touching = all_gaps(x, np.full(len(x), R)) <= 0
    return first + np.stack([i[touching], j[touching]], axis=1)


def problem_of(x, links_ij, moving=None):
    """All spheres moving (unless ``moving`` is given, then the others are anchors)."""
    n = len(x)
    radii = np.full(n, R)
    links = LinkSet(n)
    if len(links_ij):
        links_ij = np.asarray(links_ij)
        links.add(links_ij[:, 0], links_ij[:, 1], 1)
    moving = np.arange(n) if moving is None else np.asarray(moving)
    anchors = np.setdiff1d(np.arange(n), moving)
    return build_problem(np.asarray(x, float), radii, moving, anchors, links, R, np.full(n, -1)), radii


def test_two_overlapping_discs_are_pushed_apart_to_contact():
    problem, radii = problem_of([[1.0, 1.0], [1.3, 1.05]], [(0, 1)])
    outcome = minimise(problem, PARAMS)
    assert outcome.converged and outcome.finite
    gap = np.linalg.norm(problem.positions[0] - problem.positions[1]) - 2 * R
    assert abs(gap) < CONTACT_GAP
    # internal forces only: the centre of mass does not move (equal damping on both discs)
    assert np.allclose(problem.positions.mean(axis=0), [1.15, 1.025], atol=1e-12)


@pytest.mark.parametrize("params", [PARAMS, replace(PARAMS, dynamic=True)], ids=["constant", "eq_3_29"])
@pytest.mark.parametrize("k", [8, 30, 200])
def test_a_clump_of_overlapping_discs_converges(k, params):
    """Also with the dynamic damping and multiplier rate of (3.29), which give a disc deep in
    an overlap a damping delta c_i far above 1 (clipped at driver.MAX_DAMPING)."""
    rng = np.random.default_rng(k)
    x = 5.0 + rng.uniform(0.0, 0.4 * math.sqrt(k), (k, 2))  # area fraction ~0.8: many overlaps
    gaps = all_gaps(x, np.full(k, R))
    assert (gaps <= 0).sum() >= k / 2
    problem, radii = problem_of(x, touching_links(x))
    outcome = minimise(problem, params)
    assert outcome.converged, outcome
    assert outcome.mean_overlap <= PARAMS.overlap_tolerance  # eq. 3.28
    assert outcome.max_step <= PARAMS.steadiness_tolerance  # eq. 3.27
    assert outcome.max_overlap <= PARAMS.max_overlap_tolerance
    assert all_gaps(problem.positions, radii).min() >= DEEPEST_GAP  # no disc left inside another


def test_a_converged_clump_restarted_with_its_multipliers_stays_put():
    """A converged state with its multipliers is a critical point of the Lagrangian (3.9):
    restarting DAHA there (what the stepper does for settled links) changes nothing."""
    rng = np.random.default_rng(3)
    x = 5.0 + rng.uniform(0.0, 0.4 * math.sqrt(30), (30, 2))
    problem, _ = problem_of(x, touching_links(x))
    first = minimise(problem, PARAMS)
    settled = problem.positions.copy()
    again = minimise(problem, PARAMS, multipliers=first.multipliers)
    assert again.converged and again.iterations <= 3 < first.iterations
    assert np.abs(problem.positions - settled).max() < PARAMS.steadiness_tolerance


def test_sleeping_spheres_give_the_plain_jacobi_result():
    """A settled clump restarted with its multipliers while a fresh clump overlaps far away
    (the settled spheres can sleep): with and without sleeping DAHA meets the same
    stopping conditions and ends in the same configuration within the steadiness tolerance."""
    rng = np.random.default_rng(3)
    x = 5.0 + rng.uniform(0.0, 0.4 * math.sqrt(30), (30, 2))
    settled, _ = problem_of(x, touching_links(x))
    tight = replace(PARAMS, overlap_tolerance=PARAMS.overlap_tolerance / 10)  # every contact well inside eps_c
    settled_multipliers = minimise(settled, tight).multipliers  # DAHA may refresh the pairs: read them after
    multiplier_of = dict(zip(zip(settled.pair_a, settled.pair_b), settled_multipliers))
    fresh = 12.0 + rng.uniform(0.0, 0.4 * math.sqrt(10), (10, 2))
    x = np.vstack([settled.positions, fresh])
    links = np.vstack([touching_links(x[:30]), touching_links(fresh, first=30)])
    finals = []
    for sleep in (0.0, PARAMS.sleep_tolerance):
        problem, radii = problem_of(x, links)
        carried = np.array([multiplier_of.get(pair, np.nan) for pair in zip(problem.pair_a, problem.pair_b)])
        outcome = minimise(problem, replace(PARAMS, sleep_tolerance=sleep), multipliers=carried)
        assert outcome.converged and outcome.iterations > FULL_SWEEP_EVERY
        assert outcome.mean_overlap <= PARAMS.overlap_tolerance and outcome.max_step <= PARAMS.steadiness_tolerance
        assert all_gaps(problem.positions, radii).min() >= DEEPEST_GAP
        finals.append(problem.positions.copy())
    assert np.abs(finals[0] - finals[1]).max() < 10 * PARAMS.steadiness_tolerance


def test_energy_decreases_while_the_constraints_hold():
    """A stretched link relaxes to contact: W (3.5) goes down at every iteration while no
    pair overlaps.  The scheme printed as (3.20)-(3.23) would move the discs apart."""
    problem, _ = problem_of([[1.0, 1.0], [2.0, 1.2]], [(0, 1)])
    energies, overlapping = [attraction_energy(problem)], []

    def record(_, p):
        energies.append(attraction_energy(p))
        overlapping.append(np.linalg.norm(p.positions[0] - p.positions[1]) < 2 * R)

    outcome = minimise(problem, PARAMS, on_iteration=record)
    assert outcome.converged
    first_overlap = overlapping.index(True) if True in overlapping else len(overlapping)
    assert first_overlap > 5
    assert np.all(np.diff(energies[: first_overlap + 1]) < 0)
    assert energies[-1] < 0.2 * energies[0]
    assert abs(np.linalg.norm(problem.positions[0] - problem.positions[1]) - 2 * R) < CONTACT_GAP


def test_tiles_that_meet_the_stopping_tests_stop_while_others_go_on():
    """A clump of 400 overlapping discs cut into 2 x 2 tiles: some tiles settle and stop while
    others still move, the whole meets (3.27), (3.28) and eps_max, in fewer iterations than
    judged as one tile."""
    rng = np.random.default_rng(1)
    side = 0.4 * math.sqrt(400)
    x = 5.0 + rng.uniform(0.0, side, (400, 2))
    tile_of = 2 * (x[:, 0] > 5.0 + side / 2) + (x[:, 1] > 5.0 + side / 2)
    problem, radii = problem_of(x, touching_links(x))
    track = []
    outcome = minimise(problem, PARAMS, tile_of=tile_of, n_tiles=4,
                       on_iteration=lambda r, p: track.append(p.positions[:400].copy()))
    assert outcome.converged and outcome.max_step <= PARAMS.steadiness_tolerance
    assert outcome.mean_overlap <= PARAMS.overlap_tolerance and outcome.max_overlap <= PARAMS.max_overlap_tolerance
    assert all_gaps(problem.positions, radii).min() >= DEEPEST_GAP
    still = np.all(track[-FULL_SWEEP_EVERY] == track[-1], axis=1)  # did not move in the last sweep
    assert any(still[tile_of == t].all() for t in range(4)) and not still.all()
    whole, _ = problem_of(x, touching_links(x))
    assert outcome.iterations < minimise(whole, PARAMS).iterations


@pytest.mark.parametrize("jammed_checks, converges", [(driver.JAMMED_CHECKS, True), (10**9, False)])
def test_a_jammed_tile_holds_open_the_tiles_pressing_on_it(monkeypatch, jammed_checks, converges):
    """A disc between an anchor (overlap 0.11 > eps_max) and three discs of another tile
    (overlaps 0.095) that settle at the first check: a jam, until that tile is held open.
    The mean test (3.28) is set aside (eps_c = 1), as the settled links of a large
    minimisation dilute it; spheres do not sleep, so every iteration is a check."""
    monkeypatch.setattr(driver, "JAMMED_CHECKS", jammed_checks)
    x = [[1.0, 1.0]] + [[1.0 + 0.3885 * math.cos(a), 1.0 + 0.3885 * math.sin(a)] for a in (0.0, math.pi / 3,
                                                                                           -math.pi / 3)]
    problem, radii = problem_of(x + [[1.0 - 0.3847, 1.0]], [], moving=[0, 1, 2, 3])
    params = replace(PARAMS, overlap_tolerance=1.0, sleep_tolerance=0.0, max_iterations=2000)
    outcome = minimise(problem, params, tile_of=np.array([0, 1, 1, 1]), n_tiles=2)
    assert outcome.converged == converges
    if converges:
        assert all_gaps(problem.positions, radii).min() >= DEEPEST_GAP
    else:
        assert outcome.max_overlap > PARAMS.max_overlap_tolerance and outcome.max_step < 1e-9


def test_anchors_do_not_move():
    problem, _ = problem_of([[1.0, 1.0], [1.3, 1.0], [0.62, 1.0]], [(0, 1), (0, 2)], moving=[0, 1])
    anchor = problem.positions[2].copy()
    assert minimise(problem, PARAMS).converged
    assert np.array_equal(problem.positions[2], anchor)


@pytest.mark.parametrize("start, attracts", [(1.05, False), (0.95, True)])
def test_attraction_range_is_taken_where_the_minimisation_starts(start, attracts):
    """Eq. 3.30, Delta_W = 4R: disc A, linked to the anchor B at ``start`` Delta_W, is pushed
    towards B by the overlapping disc C, to 0.96 Delta_W.  A link longer than Delta_W at the
    start stays without pull (A stops there); a shorter one pulls A and C to B."""
    delta_w = 4 * R
    a = start * delta_w
    problem, _ = problem_of([[a, 0.0], [0.0, 0.0], [a + 0.25, 0.0]], [(0, 1), (0, 2)], moving=[0, 2])
    assert minimise(problem, PARAMS, attraction_range=delta_w).converged
    distance = np.linalg.norm(problem.positions[0] - problem.positions[2])  # rows: moving A, C, then anchor B
    if attracts:
        assert abs(distance - 2 * R) < CONTACT_GAP
    else:
        assert distance == pytest.approx(a - (0.4 - 0.25) / 2, abs=0.01)


def paper_system(n, volume_fraction, seed):
    rng = np.random.default_rng(seed)
    length = box_length_for_volume_fraction(n, 2, R, volume_fraction)
    return (lattice_positions(n, 2, length, rng), isotropic_velocities(n, 2, 1.0, rng), np.full(n, R),
            np.ones(n), length)


@pytest.mark.parametrize("formulation, carry, dynamic", [("almost_rigid", True, False), ("non_rigid", True, False),
                                                         ("almost_rigid", False, False), ("almost_rigid", True, True)])
@pytest.mark.parametrize("volume_fraction", [0.1, 0.3])
def test_aggregation_ends_in_one_cluster_without_overlap(formulation, carry, dynamic, volume_fraction):
    x, v, radii, masses, length = paper_system(150, volume_fraction, seed=4)
    daha = DahaParameters(carry_multipliers=carry, dynamic=dynamic)
    result = simulate_ts(x, v, radii, masses, length, formulation=formulation, daha=daha)
    assert result.stop_reason == "single_cluster"
    assert np.all(result.cluster == 0) and result.n_collisions == 149
    links = result.links
    assert len(links) >= 149  # connected: a spanning tree at least
    assert all_gaps(result.positions, radii).min() >= DEEPEST_GAP
    # links join spheres at contact
    link_gaps = np.linalg.norm(result.positions[links[:, 0]] - result.positions[links[:, 1]], axis=1) - 2 * R
    assert np.abs(link_gaps).max() < 0.1 * R
    # one cluster: one velocity, the total momentum up to the reflections' sign changes
    assert np.allclose(result.velocities, result.velocities[0], atol=0, rtol=0)


def test_a_cluster_past_a_wall_is_mirrored_back_as_a_whole():
    """Item (ii): after the free flight a cluster with a sphere past a wall is mirrored across it
    as a whole, that sphere as far inside as it was outside, its normal velocity turned inwards;
    the other clusters fly on."""
    X = np.array([[9.5, 5.0], [9.0, 5.0], [5.0, 5.0], [0.6, 2.0], [5.0, 8.0]])
    V = np.array([[1.0, 0.5], [1.0, 0.5], [1.0, 0.0], [-1.0, 0.0], [0.0, 1.0]])
    R = np.full(5, 0.25)
    cluster = np.array([0, 0, 1, 2, 3])  # discs 0 and 1 form one cluster
    where, extent = free_flight(X, V, R, cluster, 10.0, 0.5)
    assert where.tolist() == [[0, 0], [2, 0]]  # disc 0 reaches 10.25, disc 3 -0.15
    where, shift, sign = reflections(where, extent, 10.0)
    apply_reflections(X, V, cluster, where, shift, sign)
    assert np.allclose(X, [[9.5, 5.25], [9.0, 5.25], [5.5, 5.0], [0.4, 2.0], [5.0, 8.5]], rtol=0, atol=1e-12)
    assert V.tolist() == [[-1.0, 0.5], [-1.0, 0.5], [1.0, 0.0], [1.0, 0.0], [0.0, 1.0]]
    where, _ = free_flight(np.full((9, 2), 9.5), np.ones((9, 2)), np.ones(9), np.arange(9), 10.0, 0.25)
    assert where.tolist() == [[i, a] for i in range(9) for a in range(2)]  # every disc past two walls


def test_a_flight_searched_for_overruns_among_some_rows_is_the_free_flight():
    """``translate`` then ``overruns`` over rows holding every sphere past a wall (the stepper's
    wall rows of a late stage) give the positions and the reflections of ``free_flight``."""
    rng = np.random.default_rng(3)
    X = rng.uniform(0.5, 9.5, (200, 2))
    V = rng.normal(size=(200, 2))
    R = np.full(200, 0.25)
    cluster = rng.integers(0, 7, 200)
    flown = X.copy()
    where, extent = free_flight(flown, V, R, cluster, 10.0, 0.4)
    assert where.shape[0] > 0
    translated = X.copy()
    translate(translated, V, 0.4)
    assert np.array_equal(translated, flown)
    past = np.flatnonzero(((translated - R[:, None] < 0.0) | (translated + R[:, None] > 10.0)).any(axis=1))
    rows = np.union1d(past, rng.choice(200, 20, replace=False))  # the spheres past a wall, and some others
    for a, b in zip(reflections(where, extent, 10.0), reflections(*overruns(translated, R, cluster, 10.0, rows), 10.0)):
        assert np.array_equal(a, b)


def test_merges_conserve_momentum_away_from_walls():
    """Three discs in a large box collide before reaching a wall: total momentum is exact."""
    x = np.array([[10.0, 10.0], [11.0, 10.0], [10.5, 11.0]])
    v = np.array([[1.0, 0.1], [-1.0, 0.0], [0.0, -1.2]])
    masses = np.array([1.0, 2.0, 3.0])
    result = simulate_ts(x, v, np.full(3, R), masses, 20.0, time_step_factor=0.001)
    assert result.stop_reason == "single_cluster" and result.n_wall_reflections == 0
    before = (masses[:, None] * v).sum(axis=0)
    after = (masses[:, None] * result.velocities).sum(axis=0)
    assert np.allclose(after, before, rtol=0, atol=1e-14)


def test_two_discs_link_at_the_first_step_they_overlap(monkeypatch):
    """Head-on approach, gap 2.61, closing 2 dt(0) = 0.04 per step: contact in step 66, not
    earlier, and the quiet steps before it skip the contact searches."""
    searches = []

    def counted(*args):
        searches.append(1)
        return cross_cluster_contacts(*args)

    monkeypatch.setattr(stepper, "cross_cluster_contacts", counted)
    x = np.array([[5.0, 10.0], [8.01, 10.0]])
    v = np.array([[1.0, 0.0], [-1.0, 0.0]])
    result = simulate_ts(x, v, np.full(2, R), np.ones(2), 20.0, time_step_factor=0.001)
    assert result.n_steps == 66 and result.link_steps.tolist() == [66]
    assert len(searches) < 66 / 4  # a search per ~QUIET_HORIZON_STEPS steps, not per step


def test_quiet_steps_change_nothing_but_round_off(monkeypatch):
    """Quiet steps fused into one advection, and contact searches answered by the watch, give the
    links and the histories of the run that searches the whole box at every step."""
    x, v, radii, masses, length = paper_system(200, 0.1, seed=6)
    watched = []
    real_contacts = Watch.contacts

    def contacts(watch, *args):
        watched.append(1)
        return real_contacts(watch, *args)

    monkeypatch.setattr(Watch, "contacts", contacts)
    fused = simulate_ts(x, v, radii, masses, length)
    assert len(watched) > 10
    monkeypatch.setattr(stepper._Run, "quiet_steps", lambda self, dt: 0.0)
    stepwise = simulate_ts(x, v, radii, masses, length)
    assert np.array_equal(fused.links, stepwise.links) and np.array_equal(fused.link_steps, stepwise.link_steps)
    assert (fused.n_steps, fused.n_wall_reflections) == (stepwise.n_steps, stepwise.n_wall_reflections)
    assert np.allclose(fused.positions, stepwise.positions, rtol=0, atol=1e-9)
    # a quiet stretch's histories are the steps' own: the same M, and t added up step by step
    assert fused.cluster_history.size == fused.n_steps
    assert np.array_equal(fused.cluster_history, stepwise.cluster_history)
    assert np.array_equal(fused.time_history, stepwise.time_history)


def test_almost_rigid_with_one_tile_is_the_non_rigid_method():
    x, v, radii, masses, length = paper_system(120, 0.2, seed=8)
    one_tile = simulate_ts(x, v, radii, masses, length, formulation="almost_rigid", tiles=1,
                           attraction_range=math.inf)
    non_rigid = simulate_ts(x, v, radii, masses, length, formulation="non_rigid")
    assert np.array_equal(one_tile.links, non_rigid.links)
    assert np.array_equal(one_tile.positions, non_rigid.positions)


@pytest.mark.parametrize("n_interacting", [10, 5_000, 800_000])
def test_later_rounds_use_tiles_of_two_interaction_ranges_or_finer(n_interacting):
    box, least = 647.0, 0.8  # N = 10^6, V_f = 0.3, R = 0.2; Delta_W = 4 R
    first = tiles.tiles_per_side(n_interacting, 2, box, least)
    later = tiles.later_round_tiles_per_side(n_interacting, 2, box, least)
    assert later >= first
    assert box / later >= tiles.LATER_ROUND_TILE_WIDTHS * least
    assert box / (later + 1) < tiles.LATER_ROUND_TILE_WIDTHS * least  # as fine as that allows


@pytest.mark.parametrize("k", [1, 100, 500])
def test_minimisations_stop_on_cells_of_four_diameters_or_on_finer_tiles(k):
    box, diameter = 647.0, 0.4  # N = 10^6, V_f = 0.3, R = 0.2
    cells = tiles.stopping_cells_per_side(k, box, diameter)
    if k > box / (tiles.STOPPING_CELL_DIAMETERS * diameter):
        assert cells == k
    else:
        assert box / (cells + 1) < tiles.STOPPING_CELL_DIAMETERS * diameter <= box / cells


def test_a_later_round_that_fails_in_fine_tiles_is_solved_in_the_first_rounds(monkeypatch):
    """Every later round is made to fail in its fine tiles: the run still ends in one cluster
    without overlap, each failure (given TILED_ITERATIONS) followed by the same round in
    the first round's tiles (one tile at this size, given max_iterations)."""
    tried = []  # (tiles per side, whether they are the fine ones of a later round, iteration cap)
    real_solve, real_minimise = stepper._Run._solve, stepper.minimise

    def solve(run, involved, latest, k, drift, daha):
        is_fine = k != tiles.tiles_per_side(int(involved.sum()), run.d, run.L, run.min_tile)
        tried.append((k, is_fine, daha.max_iterations))
        return real_solve(run, involved, latest, k, drift, daha)

    def minimise(problem, params, *args, **kwargs):
        outcome = real_minimise(problem, params, *args, **kwargs)
        return replace(outcome, converged=False) if tried[-1][1] else outcome

    monkeypatch.setattr(stepper._Run, "_solve", solve)
    monkeypatch.setattr(stepper, "minimise", minimise)
    x, v, radii, masses, length = paper_system(150, 0.3, seed=4)
    result = simulate_ts(x, v, radii, masses, length)
    assert result.stop_reason == "single_cluster"
    assert all_gaps(result.positions, radii).min() >= DEEPEST_GAP
    fine = [n for n, (_, is_fine, _) in enumerate(tried) if is_fine]
    assert fine, "no later round ran"
    assert all(not tried[n + 1][1] and tried[n + 1][0] < tried[n][0] for n in fine)
    assert {tried[n][2] for n in fine} == {stepper.TILED_ITERATIONS}
    assert {cap for _, is_fine, cap in tried if not is_fine} == {PARAMS.max_iterations}


def test_a_minimisation_that_fails_in_tiles_is_solved_again_in_one_tile(monkeypatch):
    """Every attempt in several tiles is made to give up at once: the run is then, bit for bit,
    the run in one tile, where every interacting sphere moves and none is an anchor (the way
    out for a sphere caged by anchors, as one was at N = 10^6)."""
    x, v, radii, masses, length = paper_system(3000, 0.3, seed=3)
    first_rounds = []
    real_tilings = stepper._Run._tilings

    def tilings(run, involved, first_round):
        tried = real_tilings(run, involved, first_round)
        if first_round:
            first_rounds.append(tried)
        return tried

    monkeypatch.setattr(stepper._Run, "_tilings", tilings)
    monkeypatch.setattr(stepper, "TILED_ITERATIONS", 0)
    fallen_back = simulate_ts(x, v, radii, masses, length)
    one_tile = simulate_ts(x, v, radii, masses, length, tiles=1)
    assert any(tried[0] > 1 for tried in first_rounds), "no first round in several tiles"
    assert all(tried[-1] == 1 for tried in first_rounds)
    assert fallen_back.n_minimisations > one_tile.n_minimisations  # the attempts in tiles count
    assert np.array_equal(fallen_back.links, one_tile.links)
    assert np.array_equal(fallen_back.positions, one_tile.positions)


def test_time_step_grows_to_twice_the_initial_one():
    x, v, radii, masses, length = paper_system(64, 0.3, seed=2)
    result = simulate_ts(x, v, radii, masses, length, time_step_factor=0.01)
    dt = np.diff(np.concatenate([[0.0], result.time_history]))
    dt0 = 0.01 * length / np.abs(np.linalg.norm(v, axis=1)).max()
    assert dt[0] == pytest.approx(dt0)
    clusters_before = np.concatenate([[64], result.cluster_history[:-1]])
    expected = dt0 * (1 + np.log(64 / clusters_before) / np.log(64))  # 2 dt0 would be reached at one cluster
    assert np.allclose(dt, expected, rtol=1e-12)
    assert result.cluster_history[-1] == 1


JOB = """
name = "ts_vs_ed"
kind = "aggregation"
seed = 5
realizations = 2
[parameters]
n_spheres = 64
[sweep]
method = ["ed", "ts"]
volume_fraction = [0.1, 0.3]
"""


@pytest.mark.mpi
def test_ts_job_identical_on_one_and_two_ranks(tmp_path):
    job = tmp_path / "job.toml"
    job.write_text(JOB)
    two = run_mpi(parsim_command("run", str(job), "--output", str(tmp_path / "two"), "--quiet"))
    assert two.returncode == 0, two.stderr
    one = run_serial("run", str(job), "--output", str(tmp_path / "one"), "--quiet")
    assert one.returncode == 0, one.stderr
    a = reproducible_part(tmp_path / "one" / "ts_vs_ed.nc")
    b = reproducible_part(tmp_path / "two" / "ts_vs_ed.nc")
    xr.testing.assert_identical(a, b)
    assert (a.n_clusters == 1).all()
    named = decoded(a, ["method"])  # a swept string is coded as CF flags
    ts, ed = named.sel({"method": "ts"}), named.sel({"method": "ed"})  # not sel(method=...): a keyword of sel
    assert (ts.n_minimisations > 0).all() and (ed.n_minimisations == 0).all()
    table = markdown(method_comparison(a))
    assert table.count("\n| 64 |") == 2  # one row per volume fraction
    for row in method_comparison(a):
        assert 0.3 < row["N_c ED"] < 0.8 and 0.3 < row["N_c TS"] < 0.8  # near 0.5 (Fig. 7)


def test_stiff_contacts_do_not_throw_spheres_away(monkeypatch):
    """A jammed clump with large multipliers on its pairs (as in long minimisations at
    N = 10^5, where a disc was thrown 130 R away): the explicit kick is unstable there, the
    stiffness-limited kick keeps every disc near its place along the whole iteration (it may
    need more iterations than allowed here; the stepper would then report the failure)."""
    rng = np.random.default_rng(13)
    n = int(rng.integers(8, 30))
    x = 5.0 + rng.uniform(0.0, 0.22 * math.sqrt(n), (n, 2))
    multipliers = None
    moved = {}
    limited = driver.STIFFNESS_LIMIT
    for limit in (math.inf, limited):
        monkeypatch.setattr(driver, "STIFFNESS_LIMIT", limit)
        problem, _ = problem_of(x, touching_links(x))
        if multipliers is None:
            multipliers = np.exp(rng.uniform(0.0, math.log(300.0), problem.pair_a.size))
        moved[limit] = 0.0

        def farthest(r, problem):  # a thrown disc may be pulled back later by its links
            moved[limit] = max(moved[limit], np.linalg.norm(problem.positions - x, axis=1).max())

        minimise(problem, replace(PARAMS, max_iterations=4000), multipliers=multipliers, on_iteration=farthest)
    assert moved[math.inf] > 50 * R, "the test no longer shows the instability"
    assert moved[limited] < 10 * R


def test_a_minimisation_that_throws_a_sphere_is_reported(monkeypatch):
    """A sphere moved more than MAX_DISPLACEMENT radii by one minimisation stops the run with a
    MinimiserFailure naming the time step, instead of going on with a teleported sphere."""
    honest = stepper.minimise

    def throwing(problem, *args, **kwargs):
        outcome = honest(problem, *args, **kwargs)
        problem.positions[0] += 2 * stepper.MAX_DISPLACEMENT * R
        return outcome

    monkeypatch.setattr(stepper, "minimise", throwing)
    n = 100
    rng = np.random.default_rng(2)
    L = box_length_for_volume_fraction(n, 2, R, 0.3)
    with pytest.raises(stepper.MinimiserFailure, match=r"moved a sphere by more than .*time step 1 "):
        simulate_ts(lattice_positions(n, 2, L, rng), isotropic_velocities(n, 2, 1.0, rng), np.full(n, R), np.ones(n),
                    L, time_step_factor=0.05)


@pytest.mark.parametrize("d", [1, 4])
def test_a_dimension_other_than_2_or_3_is_refused(d):
    """The DAHA kernels are written for discs and spheres: other positions are refused up front
    with the shape they had."""
    with pytest.raises(ValueError, match=rf"positions must have shape \(n, 2\) or \(n, 3\).*\(5, {d}\)"):
        simulate_ts(np.zeros((5, d)), np.ones((5, d)), np.full(5, R), np.ones(5), 10.0)


def test_a_minimisation_in_one_dimension_is_refused():
    """Its kernels are written for discs and spheres: a problem of points on a line is refused
    before any kernel reads a second coordinate that is not there."""
    with pytest.raises(ValueError, match=r"discs or spheres \(d = 2 or 3\).*\(2, 1\)"):
        problem_of([[1.0], [1.3]], [(0, 1)])
