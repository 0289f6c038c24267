"""The strip prefilter of the decomposed deposition's checks never drops a meeting pair."""

import numpy as np
import pytest

from parsim.core.sdbd.blocks import interval_meets
from parsim.core.sdbd.strips import mark_strips, meets_strips


def _intervals(rng, n, lower, upper, widest):
    low = rng.uniform(lower, upper, n)
    return low, low + rng.uniform(0.0, widest, n)


@pytest.mark.parametrize("periodic", [True, False])
@pytest.mark.parametrize("widest", [0.5, 7.0, 400.0])
def test_every_meeting_interval_touches_a_marked_strip(periodic, widest):
    """Against the exact test (:func:`interval_meets`) on random intervals, some of them beyond the
    period, some meeting only across it: no pair that meets is missed, and far intervals are told
    apart (the prefilter is worth its cost)."""
    rng = np.random.default_rng(7)
    length, margin = 300.0, 0.75
    low, high = _intervals(rng, 40, -320.0, 620.0, widest)
    boxes = np.zeros((40, 4))
    boxes[:, 0], boxes[:, 1] = low, high
    marked, origin, width = mark_strips(boxes, len(boxes), margin, length, periodic)
    rows_low, rows_high = _intervals(rng, 20000, -320.0, 620.0, 2.0)
    met = told_apart = 0
    for a0, a1 in zip(rows_low, rows_high):
        exact = any(interval_meets(a0, a1, b0 - margin, b1 + margin, length, periodic) for b0, b1 in zip(low, high))
        touches = meets_strips(a0, a1, marked, origin, width, periodic)
        assert touches or not exact, (a0, a1)
        met += exact
        told_apart += not touches
    assert met > 0
    if widest < 1.0:
        assert told_apart > 0.2 * len(rows_low)


def test_no_boxes_mark_nothing():
    marked, origin, width = mark_strips(np.zeros((0, 4)), 0, 1.0, 10.0, True)
    assert not meets_strips(-5.0, 50.0, marked, origin, width, True)


def test_an_interval_wider_than_the_period_touches_any_mark():
    boxes = np.array([[3.0, 3.1, 0.0, 0.0]])
    marked, origin, width = mark_strips(boxes, 1, 0.0, 10.0, True)
    assert meets_strips(-40.0, -25.0, marked, origin, width, True)
    assert meets_strips(13.05, 13.06, marked, origin, width, True)
    assert not meets_strips(5.0, 6.0, marked, origin, width, True)


@pytest.mark.parametrize("periodic", [True, False])
def test_empty_footprints_mark_nothing_and_unbounded_ones_everything(periodic):
    """A particle stopped at the event limit has an empty footprint (inf, -inf): it meets nothing."""
    empty = np.array([[np.inf, -np.inf, np.inf, -np.inf], [2.0, 2.5, 0.0, 1.0]])
    marked, origin, width = mark_strips(empty, 2, 0.1, 10.0, periodic)
    assert meets_strips(2.2, 2.3, marked, origin, width, periodic)
    assert not meets_strips(6.0, 6.5, marked, origin, width, periodic)
    unbounded = np.array([[-np.inf, np.inf, 0.0, 1.0]])
    marked, origin, width = mark_strips(unbounded, 1, 0.1, 10.0, periodic)
    assert meets_strips(6.0, 6.5, marked, origin, width, periodic)


def test_one_point_far_from_the_query_in_an_open_box():
    """A heap's single footprint is a point: its strips must still catch an interval around it
    and leave far ones out, with no overflow of the strip index."""
    point = np.array([[5.22, 5.22, 0.0, 0.0]])
    marked, origin, width = mark_strips(point, 1, 0.0, 10.0, False)
    assert meets_strips(2.74, 5.74, marked, origin, width, False)
    assert meets_strips(5.22, 5.22, marked, origin, width, False)
    assert not meets_strips(-1e300, 1.0, marked, origin, width, False)
    assert not meets_strips(9.0, 1e300, marked, origin, width, False)
