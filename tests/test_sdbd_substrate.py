"""A fixed substrate: spheres laid in the sediment before the first particle.

Particles rest on the substrate like on any sediment sphere and never pass through it.  The
engine is prefix-independent, so a sediment deposited in two calls, the second on the first's
spheres as its substrate, is the sediment of one call.
"""

import numpy as np
import pytest

from parsim.core import sdbd
from parsim.core.shapes import random_rotations, rod, sphere

from . import sediment_checks as sc

IDENTITY = [1.0, 0.0, 0.0, 0.0]


def square_lattice(side, spacing, radius, shift):
    """Touching spheres of ``radius`` on the floor, a square lattice of ``spacing`` over
    ``[0, side)^2`` moved by ``shift`` (some centres then lie outside the periodic box)."""
    k = np.arange(int(round(side / spacing))) * spacing + shift
    x, y = np.meshgrid(k, k, indexing="ij")
    positions = np.stack([x.ravel(), y.ravel(), np.full(x.size, radius)], axis=1)
    return positions, np.full(x.size, radius)


@pytest.mark.parametrize("floor", [sdbd.FLOOR_STOP, sdbd.FLOOR_ROLL])
def test_spheres_rest_on_a_rough_floor_without_passing_through_it(floor):
    # holes of the lattice (radius 0.5, spacing 1) let through spheres of radius < 0.21 only
    # and reach the floor for radius <= 0.25; these have radius >= 0.3
    side, n = 8.0, 200
    substrate = square_lattice(side, 1.0, 0.5, shift=-0.25)
    rng = np.random.default_rng(7)
    scale = rng.uniform(0.3, 0.5, n)
    res, diag = sdbd.deposit_with_diagnostics(
        np.zeros((1, 3)), np.ones(1), np.array([0, 1]), np.zeros(n, dtype=np.int64), scale,
        np.tile(IDENTITY, (n, 1)), rng.random((n, 2)) * side, (0.0, 0.0), (side, side),
        sdbd.LATERAL_PERIODIC, floor, check_overlaps=True, substrate_positions=substrate[0],
        substrate_radii=substrate[1])
    assert res.stopped_at == -1 and len(res.radii) == n
    assert diag["max_overlap"] <= 1e-9 * diag["length_scale"]
    # resting in a hole of the lattice at the least: 0.5 + sqrt((0.5 + r)^2 - 1/2) - r
    assert np.min(res.positions[:, 2] - res.radii) > 0.5
    problems = sc.check_sediment(res.positions, res.radii, res.particle, res.center_of_mass, res.state,
                                 (0.0, 0.0), (side, side), sdbd.LATERAL_PERIODIC, floor, substrate=substrate)
    assert problems == []
    # the first particles land on the substrate, none on the floor
    assert np.all(res.state != sdbd.RESTING_ON_FLOOR)


CONTAINERS = {
    "periodic": dict(lateral=sdbd.LATERAL_PERIODIC, box_lower_xy=(0.0, 0.0), box_upper_xy=(6.0, 6.0)),
    "walls": dict(lateral=sdbd.LATERAL_WALLS, box_lower_xy=(0.0, 0.0), box_upper_xy=(6.0, 6.0)),
    "cylinder": dict(lateral=sdbd.LATERAL_WALLS, box_lower_xy=(0.0, 0.0), box_upper_xy=(6.0, 6.0),
                     container=sdbd.CONTAINER_CYLINDER, cylinder=(3.0, 3.0, 3.0, 40)),
    "none": dict(lateral=sdbd.LATERAL_NONE, box_lower_xy=(0.0, 0.0), box_upper_xy=(0.0, 0.0)),
}


def mixture(n, seed):
    """Spheres and rods of three spheres, polydisperse, the first a small sphere so that the
    grid's cell grows during the run; every particle fits in the 6 x 6 square and the
    cylinder inscribed in it when dropped within 1.2 of its centre."""
    rng = np.random.default_rng(seed)
    (sphere_offsets, sphere_radii), (rod_offsets, rod_radii) = sphere(), rod(3)
    shape = (rng.random(n) < 0.4).astype(np.int64)
    shape[0] = 0
    scale = rng.uniform(0.25, 0.5, n)
    scale[0] = 0.2
    angle = 2.0 * np.pi * rng.random(n)
    distance = 1.2 * np.sqrt(rng.random(n))
    drop = 3.0 + np.stack([distance * np.cos(angle), distance * np.sin(angle)], axis=1)
    return dict(shape_offsets=np.concatenate([sphere_offsets, rod_offsets]),
                shape_radii=np.concatenate([sphere_radii, rod_radii]), shape_start=np.array([0, 1, 4]),
                particle_shape=shape, particle_scale=scale, particle_rotation=random_rotations(n, rng),
                particle_drop_xy=drop)


def first(particles, k, stop=None):
    """The particles ``k:stop`` of a :func:`mixture`."""
    per_particle = ("particle_shape", "particle_scale", "particle_rotation", "particle_drop_xy")
    return {key: value[k:stop] if key in per_particle else value for key, value in particles.items()}


@pytest.mark.parametrize("container", list(CONTAINERS))
@pytest.mark.parametrize("floor", [sdbd.FLOOR_STOP, sdbd.FLOOR_ROLL])
def test_a_sediment_continued_on_its_own_spheres_is_the_sediment_of_one_run(container, floor):
    n1, n2 = 90, 60
    particles = mixture(n1 + n2, seed=17)
    boundary = {**CONTAINERS[container], "floor": floor}
    whole = sdbd.deposit(**particles, **boundary)
    part1 = sdbd.deposit(**first(particles, 0, n1), **boundary)
    part2 = sdbd.deposit(**first(particles, n1), **boundary, substrate_positions=part1.positions,
                         substrate_radii=part1.radii)
    assert whole.stopped_at == part1.stopped_at == part2.stopped_at == -1
    split = len(part1.radii)
    np.testing.assert_array_equal(part1.positions, whole.positions[:split])
    np.testing.assert_array_equal(part2.positions, whole.positions[split:])
    np.testing.assert_array_equal(part2.radii, whole.radii[split:])
    np.testing.assert_array_equal(part2.particle + n1, whole.particle[split:])
    np.testing.assert_array_equal(part2.center_of_mass, whole.center_of_mass[n1:])
    np.testing.assert_array_equal(part2.rotation, whole.rotation[n1:])
    np.testing.assert_array_equal(part2.state, whole.state[n1:])
    np.testing.assert_array_equal(part2.event_counts, whole.event_counts[n1:])


def test_bad_substrates_raise_value_error_naming_the_sphere():
    ok = dict(shape_offsets=np.zeros((1, 3)), shape_radii=np.ones(1), shape_start=[0, 1], particle_shape=[0],
              particle_scale=[1.0], particle_rotation=[IDENTITY], particle_drop_xy=[(5.0, 5.0)],
              box_lower_xy=(0.0, 0.0), box_upper_xy=(10.0, 10.0), lateral=sdbd.LATERAL_WALLS,
              floor=sdbd.FLOOR_STOP, substrate_positions=[(2.0, 2.0, 1.0), (5.0, 5.0, 0.5)],
              substrate_radii=[1.0, 0.5])
    assert sdbd.deposit(**ok).stopped_at == -1
    for change, sphere_index in ((dict(substrate_positions=[(2.0, 2.0, 1.0), (5.0, 5.0, -0.1)]), 1),
                                 (dict(substrate_positions=[(0.5, 2.0, 1.0), (5.0, 5.0, 0.5)]), 0),  # through a wall
                                 (dict(substrate_radii=[1.0, -0.5]), 1),
                                 (dict(lateral=sdbd.LATERAL_WALLS, container=sdbd.CONTAINER_CYLINDER,
                                       cylinder=(5.0, 5.0, 5.0, 16),
                                       substrate_positions=[(5.0, 5.0, 1.0), (1.2, 1.2, 0.5)]), 1)):
        with pytest.raises(ValueError, match=f"substrate sphere {sphere_index}"):
            sdbd.deposit(**{**ok, **change})
    for change in (dict(substrate_radii=None), dict(substrate_radii=[1.0])):
        with pytest.raises(ValueError):
            sdbd.deposit(**{**ok, **change})
