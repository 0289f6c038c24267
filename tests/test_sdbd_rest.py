"""Every deposited particle comes to rest, and a sediment's beginning does not depend on its end.

Rods (spheres on a line) are the degenerate case: two pivots on the rod's own axis (on a rolling
floor, against a wall) make a rotation about an axis through the centre of mass, which lowers
nothing. Such a motion is no motion: the rod is at rest.
"""

import numpy as np
import pytest

from parsim.core import sdbd
from parsim.core.shapes import random_rotations, rod

from . import sediment_checks as sc

ROD_OFFSETS, ROD_RADII = rod(11)
ROD_OFFSETS = 0.5 * ROD_OFFSETS  # unit diameter
ROD_RADII = 0.5 * ROD_RADII
BOX = 20.0
LATERAL = {"periodic": sdbd.LATERAL_PERIODIC, "walls": sdbd.LATERAL_WALLS, "none": sdbd.LATERAL_NONE}
FLOOR = {"stop": sdbd.FLOOR_STOP, "roll": sdbd.FLOOR_ROLL}


def deposit_rods(scale, rotation, drop, lateral, floor, max_steps=100_000):
    n = len(scale)
    return sdbd.deposit_with_diagnostics(ROD_OFFSETS, ROD_RADII, np.array([0, len(ROD_RADII)]),
                                         np.zeros(n, dtype=np.int64), scale, rotation, drop, (0.0, 0.0),
                                         (BOX, BOX), lateral, floor, max_events_per_particle=max_steps)


def polydisperse_rods(n, lateral, seed):
    """Size factors uniform in [0.7, 1.3], random orientations, drop points that keep every rod
    inside the walls (a heap over a 4 x 4 square without lateral boundaries)."""
    rng = np.random.default_rng(seed)
    scale = rng.uniform(0.7, 1.3, n)
    rotation = random_rotations(n, rng)
    if lateral == sdbd.LATERAL_WALLS:
        drop = 4.5 + rng.random((n, 2)) * (BOX - 9.0)
    elif lateral == sdbd.LATERAL_NONE:
        drop = rng.random((n, 2)) * 4.0
    else:
        drop = rng.random((n, 2)) * BOX
    return scale, rotation, drop


def test_a_rod_dropped_on_a_rolling_floor_ends_flat_within_a_few_steps():
    flat, steps = [], []
    for seed in range(200):
        rng = np.random.default_rng(seed)
        res, _ = deposit_rods(np.ones(1), random_rotations(1, rng), rng.random((1, 2)) * BOX,
                              sdbd.LATERAL_PERIODIC, sdbd.FLOOR_ROLL, max_steps=1000)
        assert res.stopped_at == -1, f"seed {seed}: the rod never came to rest"
        assert res.state[0] in (sdbd.RESTING_ON_FLOOR, sdbd.RESTING_THREE_CONTACTS)
        flat.append(np.ptp(res.positions[:, 2]))
        steps.append(res.steps[0])
    # lying on the floor: every sphere's centre one radius above it
    assert max(flat) < 1e-9
    # drop, roll down to the second contact, roll flat, rest: a handful of steps
    assert max(steps) <= 20


@pytest.mark.parametrize("floor", FLOOR)
@pytest.mark.parametrize("lateral", LATERAL)
def test_a_thousand_polydisperse_rods_all_come_to_rest(lateral, floor):
    scale, rotation, drop = polydisperse_rods(1000, LATERAL[lateral], seed=7)
    res, diag = deposit_rods(scale, rotation, drop, LATERAL[lateral], FLOOR[floor])
    assert res.stopped_at == -1, f"particle {res.stopped_at} never came to rest"
    assert len(res.state) == 1000
    assert res.steps.max() < 10_000
    box = (np.zeros(2), np.full(2, BOX))
    problems = sc.check_sediment(res.positions, res.radii, res.particle, res.center_of_mass, res.state,
                                 *box, LATERAL[lateral], FLOOR[floor])
    assert problems == []


@pytest.mark.parametrize("lateral", LATERAL)
def test_the_first_particles_of_a_sediment_are_the_sediment_of_those_particles(lateral):
    # lognormal sizes: the largest sphere so far grows many times during the run
    rng = np.random.default_rng(3)
    n_all, n_first = 400, 150
    scale = np.exp(0.3 * rng.standard_normal(n_all))
    _, rotation, drop = polydisperse_rods(n_all, LATERAL[lateral], seed=4)
    if LATERAL[lateral] == sdbd.LATERAL_WALLS:
        scale = np.minimum(scale, 1.3)  # every rod fits between the walls from its drop point
    whole, _ = deposit_rods(scale, rotation, drop, LATERAL[lateral], sdbd.FLOOR_ROLL)
    first, _ = deposit_rods(scale[:n_first], rotation[:n_first], drop[:n_first], LATERAL[lateral],
                            sdbd.FLOOR_ROLL)
    assert whole.stopped_at == -1 and first.stopped_at == -1
    n_spheres = len(first.radii)
    assert np.array_equal(whole.positions[:n_spheres], first.positions)
    assert np.array_equal(whole.center_of_mass[:n_first], first.center_of_mass)
    assert np.array_equal(whole.rotation[:n_first], first.rotation)
    assert np.array_equal(whole.event_counts[:n_first], first.event_counts)
    assert np.array_equal(whole.state[:n_first], first.state)
