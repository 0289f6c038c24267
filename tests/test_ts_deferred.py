"""The largest cluster's deferred flights (parsim.core.ts.deferred) leave a run bitwise unchanged.

While the look-aheads follow the paths of the few spheres outside the largest cluster, the
stepper logs that cluster's flights and wall reflections and applies them to a row when it is
read.  A run must be the eager run bit for bit: positions, velocities, links and the steps that
made them, the time and its history, every counter.  Tried on random tasks (size, volume
fraction, dimension, seed, time-step factor) and with a log bounded to a few increments, so
that it is applied and restarted many times within a run.
"""

import numpy as np
import pytest

from parsim.core.initial import box_length_for_volume_fraction, isotropic_velocities, lattice_positions
from parsim.core.ts import deferred, simulate_ts, stepper
from parsim.core.ts.deferred import DeferredFlight

FIELDS = ("positions", "velocities", "cluster", "links", "link_steps", "cluster_history", "time_history")
COUNTERS = ("time", "n_steps", "n_collisions", "n_wall_reflections", "n_minimisations", "n_iterations")


def random_task(rng):
    n = int(rng.integers(60, 700))
    dimension = int(rng.choice([2, 3]))
    volume_fraction = float(rng.uniform(0.05, 0.3 if dimension == 2 else 0.2))
    radius = 0.2
    L = box_length_for_volume_fraction(n, dimension, radius, volume_fraction)
    x = lattice_positions(n, dimension, L, rng)
    v = isotropic_velocities(n, dimension, 1.0, rng)
    return (x, v, np.full(n, radius), np.ones(n), L), float(rng.choice([0.005, 0.01, 0.015]))


def run(monkeypatch, task, factor, defer, max_increments=deferred.MAX_INCREMENTS):
    monkeypatch.setattr(stepper, "DEFER_FLIGHTS", defer)
    monkeypatch.setattr(deferred, "MAX_INCREMENTS", max_increments)
    return simulate_ts(*task, time_step_factor=factor)


def assert_bitwise_equal(deferred_run, eager_run):
    for name in FIELDS:
        assert np.array_equal(getattr(deferred_run, name), getattr(eager_run, name)), name
    for name in COUNTERS:
        assert getattr(deferred_run, name) == getattr(eager_run, name), name


@pytest.mark.parametrize("seed", range(4))
def test_deferred_flights_make_the_eager_run_bit_for_bit(monkeypatch, seed):
    """10 random tasks per seed, 40 in all, each run eagerly and deferred, the log once bounded
    to 3 increments."""
    rng = np.random.default_rng(1000 + seed)
    made = []
    monkeypatch.setattr(stepper, "DeferredFlight", lambda *a: made.append(1) or DeferredFlight(*a))
    for case in range(10):
        task, factor = random_task(rng)
        eager = run(monkeypatch, task, factor, defer=False)
        assert_bitwise_equal(run(monkeypatch, task, factor, defer=True, max_increments=3 if case % 2 else 1 << 16),
                             eager)
    assert made, "no run of the sample deferred a flight: the test would prove nothing"


def test_bringing_rows_up_to_date_adds_each_increment_in_order():
    """Row by row and in blocks, a row that has received some increments already gets the rest,
    each added in turn as the eager flights add them; rows outside the cluster are untouched."""
    rng = np.random.default_rng(7)
    X = rng.uniform(0.0, 10.0, (150, 2))
    V = np.tile(rng.normal(size=2), (150, 1))
    rows = np.arange(0, 150, 2)
    eager = X.copy()
    flight = DeferredFlight(X, V, rows)
    for k in range(40):
        if k % 7 == 3:
            shift = float(rng.uniform(-1e-3, 1e-3))
            flight.reflect(X, V, 1, shift, -1.0)
            eager[rows, 1] += shift
        else:
            duration = float(rng.uniform(0.0, 0.1))
            step = duration * flight.velocity
            flight.fly(X, V, duration)
            eager[rows] += step
        if k == 20:
            flight.bring_up_to_date(X, V, rows[:5])  # some rows ahead of the others
    before = X[1::2].copy()
    flight.settle(X, V)
    assert np.array_equal(X[rows], eager[rows])
    assert np.array_equal(X[1::2], before)
    assert np.all(V[rows] == flight.velocity)
