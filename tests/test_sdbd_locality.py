"""A particle's descent depends only on the sediment within its reach (parsim.core.sdbd): what
lies far from its path, however high, changes nothing of it, bit for bit.  This is what lets
particles dropped far apart be settled independently."""

import numpy as np

from parsim.core import sdbd
from parsim.core.shapes import random_rotations, sphere, tripod

BOX = 30.0
RADIUS = 0.5


def far_substrate(stacked: bool):
    """30 fixed spheres in the corner of the box, 10 diameters from where the particles fall:
    a tower 30 diameters high, or a patch on the floor."""
    k = np.arange(30)
    if stacked:
        centres = np.column_stack([np.full(30, 1.5), np.full(30, 1.5), 0.5 + k])
    else:
        centres = np.column_stack([0.5 + k % 6, 0.5 + k // 6, np.full(30, 0.5)])
    return centres, np.full(30, RADIUS)


def deposit_beside(substrate, make, n):
    offsets, radii = make()
    rng = np.random.default_rng(3)
    drop = 12.0 + rng.random((n, 2)) * 6.0  # the middle of the box, far from the corner
    return sdbd.deposit(offsets * RADIUS, radii * RADIUS, np.array([0, len(radii)]), np.zeros(n, dtype=np.int64),
                        np.ones(n), random_rotations(n, rng), drop, (0.0, 0.0), (BOX, BOX), sdbd.LATERAL_PERIODIC,
                        sdbd.FLOOR_ROLL, substrate_positions=substrate[0], substrate_radii=substrate[1])


def test_a_distant_tower_changes_no_particle():
    for make, n in ((sphere, 150), (lambda: tripod(2), 60)):
        beside_tower = deposit_beside(far_substrate(stacked=True), make, n)
        beside_patch = deposit_beside(far_substrate(stacked=False), make, n)
        assert beside_tower.stopped_at == beside_patch.stopped_at == -1
        # the particles stayed far from the corner: no contact with the substrate either way
        assert np.all(np.abs(beside_tower.positions[:, :2] - BOX / 2) < BOX / 2 - 4.0)
        for name in ("positions", "center_of_mass", "rotation", "contacts", "state", "event_counts", "steps"):
            assert np.array_equal(getattr(beside_tower, name), getattr(beside_patch, name)), name
