"""The part of the sediment a descent reads (parsim.core.sdbd.reads): a particle settled again on
the spheres whose cells meet its recorded rectangle, and on no other, settles bit for bit as it
did on the whole sediment.  This is the invariant that lets a decomposed deposition commit a
particle settled ahead of its turn."""

import numpy as np
import pytest

from parsim.core import sdbd
from parsim.core.shapes import random_rotations, sphere, tripod

BOX = 8.0  # diameters: small, so that particles meet much of the sediment
RADIUS = 0.5


def deposit(make, n, lateral, substrate=None, rows=slice(None)):
    offsets, radii = make()
    rng = np.random.default_rng(11)
    rotation = random_rotations(n, rng)[rows]
    if lateral == sdbd.LATERAL_NONE:  # a heap: particles roll far down its flanks
        drop = (BOX / 2 + rng.random((n, 2)) - 0.5)[rows]
    else:
        drop = (1.0 + rng.random((n, 2)) * (BOX - 2.0))[rows]
    count = len(drop)
    return sdbd.deposit_with_diagnostics(
        offsets * RADIUS, radii * RADIUS, np.array([0, len(radii)]), np.zeros(count, dtype=np.int64),
        np.ones(count), rotation, drop, (0.0, 0.0), (BOX, BOX), lateral, sdbd.FLOOR_ROLL,
        substrate_positions=None if substrate is None else substrate[0],
        substrate_radii=None if substrate is None else substrate[1], record_reads=True)


def spheres_in_rectangle(positions, rectangle, margin, periodic):
    """Which centres lie within ``margin`` of the rectangle (a periodic box's images included)."""
    x_low, x_high, y_low, y_high = rectangle
    shifts = (-BOX, 0.0, BOX) if periodic else (0.0,)
    inside = np.zeros(len(positions), dtype=bool)
    for sx in shifts:
        for sy in shifts:
            x = positions[:, 0] + sx
            y = positions[:, 1] + sy
            inside |= (x >= x_low - margin) & (x <= x_high + margin) & (y >= y_low - margin) & (y <= y_high + margin)
    return inside


@pytest.mark.parametrize("make, n, lateral", [
    (sphere, 400, sdbd.LATERAL_PERIODIC),
    (lambda: tripod(2), 120, sdbd.LATERAL_PERIODIC),
    (lambda: tripod(2), 120, sdbd.LATERAL_WALLS),
    (sphere, 300, sdbd.LATERAL_NONE),
])
def test_a_particle_settled_on_what_it_read_settles_the_same(make, n, lateral):
    whole, diagnostics = deposit(make, n, lateral)
    reads = diagnostics["reads"]
    assert reads.shape == (n, 4) and np.all(reads[:, 0] < reads[:, 1]) and np.all(reads[:, 2] < reads[:, 3])
    cell = 2.0 * RADIUS  # the largest sphere diameter: a cell meeting the rectangle holds centres within it
    smaller = 0
    for p in range(n // 4, n, n // 12):
        earlier = whole.particle < p
        read = spheres_in_rectangle(whole.positions[earlier], reads[p], cell, lateral == sdbd.LATERAL_PERIODIC)
        smaller += np.count_nonzero(read) < np.count_nonzero(earlier)
        substrate = (whole.positions[earlier][read], whole.radii[earlier][read])
        alone, _ = deposit(make, n, lateral, substrate, rows=slice(p, p + 1))
        for name in ("center_of_mass", "rotation", "contacts", "state", "event_counts", "steps"):
            assert np.array_equal(getattr(alone, name)[0], getattr(whole, name)[p]), (p, name)
    assert smaller >= 6  # the rectangles leave out part of the sediment: the test is not the whole run again


def test_recording_the_rectangles_leaves_the_sediment_bitwise_the_same():
    """The rectangles are written into the kernel's workspace at every step of every descent; a
    mixture whose particles grow the grid's cell again and again (each growth allocates the grid's
    arrays anew) must settle bit for bit as without them."""
    offsets, radii = sphere()
    n = 400
    rng = np.random.default_rng(5)
    scale = np.where(rng.random(n) < 0.5, 0.5, np.linspace(0.5, 1.0, n))  # every other one the largest yet
    inputs = (offsets * RADIUS, radii * RADIUS, np.array([0, 1]), np.zeros(n, dtype=np.int64), scale,
              random_rotations(n, rng), 1.0 + rng.random((n, 2)) * (BOX - 2.0), (0.0, 0.0), (BOX, BOX),
              sdbd.LATERAL_PERIODIC, sdbd.FLOOR_ROLL)
    assert len(np.unique(np.maximum.accumulate(scale))) >= 100  # the cell grows again and again
    plain = sdbd.deposit(*inputs)
    recorded, diagnostics = sdbd.deposit_with_diagnostics(*inputs, record_reads=True)
    for name in ("positions", "center_of_mass", "rotation", "contacts", "state", "event_counts", "steps"):
        assert np.array_equal(getattr(recorded, name), getattr(plain, name)), name
    reads = diagnostics["reads"]
    assert np.all(reads[:, 0] < reads[:, 1]) and np.all(reads[:, 2] < reads[:, 3])
