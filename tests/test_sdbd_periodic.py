"""Rolling across the side of a small periodic box.

A rotation's new contacts are searched on the arc its spheres sweep; in a periodic box each
obstacle must be met through the image that lies in the swept region.  The image nearest the
sphere at the start of the arc is not always that one: when the arc carries the sphere a good part
of the box's side, the obstacle it meets at the end of the arc is the other image.  These tests
deposit particles in periodic boxes barely wider than the engine allows (twice the particle's
extent, four sphere radii) and check, with the independent checker, that no two particles overlap.
"""

import numpy as np
import pytest

from parsim.core import sdbd
from parsim.core.shapes import bounding_radius, random_rotations, rod, sphere, tripod
from parsim.job import parse_job
from parsim.solvers import SOLVERS
from parsim.deposition.solver import deposition_inputs

from . import sediment_checks as sc

#: the smallest job of the randomised search whose serial sediment overlapped: 17 tripods of
#: 7 spheres in a box of 3.9 sphere diameters, the 17th rolling through the box's side
TRIPODS_IN_A_SMALL_BOX = """
name = "tripods"
kind = "deposition"
seed = 764071051
realizations = 1
[parameters]
n_particles = 50
sphere_radius = 0.8206
shape = "tripod"
shape_size = 3
size_distribution = "uniform"
size_spread = 0.06058
cycle_n = 7
cycle_eps = 1.492e-05
lateral = "periodic"
box_length = 6.434
"""


def overlaps(result, side, tolerance=1e-9):
    """Pairs of spheres of different particles that overlap by more than ``tolerance`` radii in the
    periodic box [0, side]^2, found by the independent checker's pair search: (i, j, depth) each."""
    pairs, distances = sc.close_pairs(result.positions, result.radii, sdbd.LATERAL_PERIODIC, (0.0, 0.0),
                                      (side, side), 0.0)
    i, j = pairs.T if len(pairs) else (np.zeros(0, dtype=int), np.zeros(0, dtype=int))
    depth = (result.radii[i] + result.radii[j] - distances) / result.radii.mean()
    bad = (result.particle[i] != result.particle[j]) & (depth > tolerance)
    return list(zip(i[bad].tolist(), j[bad].tolist(), depth[bad].round(4).tolist()))


def test_a_tripod_rolling_through_the_side_meets_the_image_ahead_of_it():
    job = parse_job(TRIPODS_IN_A_SMALL_BOX, SOLVERS, source="tripods")
    task = job.tasks()[0]
    params = {**job.point_parameters(task.point), "n_particles": 17}
    inputs = deposition_inputs(params, np.random.default_rng(job.seed_sequence(task)), False)
    drops, rotation, drop_xy = next(inputs.particles())
    result = sdbd.deposit(*inputs.shapes, drops.species, drops.scale, rotation, drop_xy, *inputs.container,
                          **inputs.options)
    assert overlaps(result, params["box_length"]) == []


def random_shape(rng):
    kind = rng.integers(3)
    if kind == 0:
        return sphere()
    if kind == 1:
        return rod(int(rng.integers(2, 6)), spacing=float(rng.uniform(0.5, 1.5)))
    return tripod(int(rng.integers(2, 4)), spacing=float(rng.uniform(0.6, 1.4)))


@pytest.mark.parametrize("seed", range(40))
def test_no_overlap_in_periodic_boxes_barely_wider_than_allowed(seed):
    """A random shape (sphere, rod or tripod) in a box 1.0-1.6 times the smallest side allowed."""
    rng = np.random.default_rng(seed)
    offsets, radii = random_shape(rng)
    extent = bounding_radius(offsets, radii)
    side = max(2.0 * extent, 4.0 * radii.max()) * rng.uniform(1.0 + 1e-6, 1.6)
    n = 25
    result = sdbd.deposit(offsets, radii, np.array([0, len(radii)]), np.zeros(n, dtype=np.int64), np.ones(n),
                          random_rotations(n, rng), rng.uniform(0.0, side, (n, 2)), (0.0, 0.0), (side, side),
                          sdbd.LATERAL_PERIODIC, sdbd.FLOOR_STOP)
    assert overlaps(result, side) == []
