"""The deposition engine's counters (parsim.core.sdbd.counters): they count what the engine does
and change nothing of the sediment."""

import numpy as np

from parsim.core import sdbd
from parsim.core.sdbd import counters
from parsim.core.shapes import random_rotations, rod


def deposit(count: bool):
    offsets, radii = rod(3)
    n = 300
    rng = np.random.default_rng(5)
    return sdbd.deposit_with_diagnostics(
        offsets * 0.5, radii * 0.5, np.array([0, len(radii)]), np.zeros(n, dtype=np.int64), np.ones(n),
        random_rotations(n, rng), rng.random((n, 2)) * 8.0, (0.0, 0.0), (8.0, 8.0), sdbd.LATERAL_PERIODIC,
        sdbd.FLOOR_ROLL, count=count)


def test_counting_changes_no_sediment_and_counts_every_step():
    plain, plain_diagnostics = deposit(count=False)
    counted, diagnostics = deposit(count=True)
    assert plain_diagnostics["counters"] == {}
    for name in plain._fields:
        assert np.array_equal(getattr(plain, name), getattr(counted, name), equal_nan=True), name
    tally = diagnostics["counters"]
    assert tuple(tally) == counters.NAMES
    assert tally["steps"] == diagnostics["steps"] == counted.steps.sum()
    assert tally["falls"] + tally["rolls"] <= tally["steps"]  # a step may find rest: no move
    assert tally["falls"] >= 300  # every particle starts with a fall
    # one per sphere of a rod of three per rotation, but for a sphere on the axis (it does not move)
    assert tally["rolls"] < tally["grid_queries"] <= 3 * tally["rolls"]
    assert tally["roll_entries"] <= tally["roll_candidates"]
    assert tally["trial_decisions"] <= tally["rolls"]
    phases = sum(tally[f"{phase}_cycles"] for phase in ("decide", "fall", "roll", "after_move", "particle"))
    assert 0 < phases <= tally["total_cycles"]
    assert tally["grid_cycles"] <= tally["contact_search_cycles"] <= tally["roll_cycles"]
