"""Cylindrical containers: the regular polygon of frictionless planar walls inscribed in the cylinder.

Every sphere centre must lie within ``R - r`` of the axis (the polygon shrunk by ``r`` has its
vertices at ``R - r / cos(pi / n)``), no sphere may cross a side, and a sphere pressed against a
side slides along it as along a box wall.  With four sides facing the axes the polygon is the
walled box of the same square.
"""

import numpy as np
import pytest

from parsim.core import sdbd
from parsim.core.shapes import random_rotations, rod, sphere

from . import sediment_checks as sc

CENTRE = (1.0, -2.0)


def cylinder_box(cx, cy, radius):
    """The box arguments of a cylinder: the square about it."""
    return (cx - radius, cy - radius), (cx + radius, cy + radius)


def deposit_mixture(n_sides, floor, wall_contact=sdbd.WALL_FRICTIONLESS, radius=4.0, seed=3):
    """300 polydisperse spheres and 100 rods of four spheres, in random order and orientation,
    dropped uniformly over the disc the polygon leaves them; returns the result, the
    diagnostics and the cylinder."""
    rng = np.random.default_rng(seed)
    (sphere_offsets, sphere_radii), (rod_offsets, rod_radii) = sphere(), rod(4)
    offsets = np.concatenate([sphere_offsets, rod_offsets])
    radii = np.concatenate([sphere_radii, rod_radii])
    n_particles = 400
    shape = np.zeros(n_particles, dtype=np.int64)
    shape[300:] = 1
    rng.shuffle(shape)
    scale = np.where(shape == 0, rng.uniform(0.3, 0.6, n_particles), 0.3)
    extent = scale * np.where(shape == 0, 1.0, 2.5)  # rod(4): 1.5 + 1 radii from its centre
    apothem = radius * np.cos(np.pi / n_sides)
    distance = (apothem - extent - 1e-6) * np.sqrt(rng.random(n_particles))
    angle = 2.0 * np.pi * rng.random(n_particles)
    drop = np.stack([distance * np.cos(angle), distance * np.sin(angle)], axis=1) + CENTRE
    cylinder = (*CENTRE, radius, n_sides)
    res, diag = sdbd.deposit_with_diagnostics(
        offsets, radii, np.array([0, 1, 5]), shape, scale, random_rotations(n_particles, rng), drop,
        *cylinder_box(*CENTRE, radius), sdbd.LATERAL_WALLS, floor, wall_contact=wall_contact,
        check_overlaps=True, container=sdbd.CONTAINER_CYLINDER, cylinder=cylinder)
    return res, diag, cylinder


@pytest.mark.parametrize("n_sides, floor", [(8, sdbd.FLOOR_STOP), (48, sdbd.FLOOR_ROLL), (720, sdbd.FLOOR_STOP)])
def test_spheres_and_rods_stay_inside_the_cylinder_at_rest(n_sides, floor):
    res, diag, cylinder = deposit_mixture(n_sides, floor)
    cx, cy, radius, _ = cylinder
    assert res.stopped_at == -1
    assert diag["max_overlap"] <= 1e-9 * diag["length_scale"]
    centre_distance = np.hypot(res.positions[:, 0] - cx, res.positions[:, 1] - cy)
    assert np.all(centre_distance <= radius - res.radii + 1e-9 * radius)
    theta = 2.0 * np.pi * np.arange(n_sides) / n_sides
    towards_side = (np.outer(res.positions[:, 0] - cx, np.cos(theta))
                    + np.outer(res.positions[:, 1] - cy, np.sin(theta)))
    apothem = radius * np.cos(np.pi / n_sides)
    assert np.all(towards_side.max(axis=1) <= apothem - res.radii + 1e-9 * radius)
    assert np.count_nonzero(towards_side.max(axis=1) > apothem - res.radii - 1e-7) > 20  # the sides were touched
    problems = sc.check_sediment(res.positions, res.radii, res.particle, res.center_of_mass, res.state,
                                 *cylinder_box(cx, cy, radius), sdbd.LATERAL_WALLS, floor, cylinder=cylinder)
    assert problems == []


def test_a_glued_cylinder_holds_its_spheres_inside():
    res, diag, cylinder = deposit_mixture(32, sdbd.FLOOR_STOP, wall_contact=sdbd.WALL_GLUED)
    assert res.stopped_at == -1
    assert diag["max_overlap"] <= 1e-9 * diag["length_scale"]
    problems = sc.check_sediment(res.positions, res.radii, res.particle, res.center_of_mass, res.state,
                                 *cylinder_box(*cylinder[:3]), sdbd.LATERAL_WALLS, sdbd.FLOOR_STOP,
                                 wall_contact="glued", cylinder=cylinder)
    assert problems == []


@pytest.mark.parametrize("floor", [sdbd.FLOOR_STOP, sdbd.FLOOR_ROLL])
def test_a_sphere_released_against_a_side_onto_a_sphere_slides_down_to_the_floor(floor):
    # as against a box wall: a large sphere rests on the floor against side 3 of 16; a small
    # one, also touching that side, lands on it and rolls round it pressed against the side
    n_sides, radius, k = 16, 10.0, 3
    theta = 2.0 * np.pi * k / n_sides
    out, along = np.array([np.cos(theta), np.sin(theta)]), np.array([-np.sin(theta), np.cos(theta)])
    apothem = radius * np.cos(np.pi / n_sides)
    drop = np.array([CENTRE + (apothem - 1.0) * out, CENTRE + (apothem - 0.5) * out + 0.3 * along])
    res = sdbd.deposit(np.zeros((1, 3)), np.ones(1), np.array([0, 1]), np.zeros(2, dtype=np.int64),
                       np.array([1.0, 0.5]), np.tile([1.0, 0.0, 0.0, 0.0], (2, 1)), drop,
                       *cylinder_box(*CENTRE, radius), sdbd.LATERAL_WALLS, floor,
                       container=sdbd.CONTAINER_CYLINDER, cylinder=(*CENTRE, radius, n_sides))
    small = res.positions[1]
    assert small[2] == pytest.approx(0.5, abs=1e-9)                           # on the floor
    assert (small[:2] - CENTRE) @ out == pytest.approx(apothem - 0.5, abs=1e-9)  # against the side
    assert (small[:2] - CENTRE) @ along == pytest.approx(np.sqrt(2.0), abs=1e-9)  # beside the large one
    assert res.state[1] in (sdbd.RESTING_ON_FLOOR, sdbd.RESTING_THREE_CONTACTS)


def test_four_sides_facing_the_axes_are_the_walled_box(monkeypatch):
    # the box [0, 8]^2 is the square of apothem 4 about (4, 4); the engine's sides facing
    # +-x and +-y have exact normals, so the walls are the same planes to the last bit
    monkeypatch.setattr(sdbd.inputs, "MIN_CYLINDER_SIDES", 4)
    half = 4.0
    radius = half / np.cos(np.pi / 4)
    while radius * np.cos(np.pi / 4) != half:
        radius = np.nextafter(radius, 0.0 if radius * np.cos(np.pi / 4) > half else np.inf)
    rng = np.random.default_rng(5)
    n = 300
    scale = rng.uniform(0.3, 0.6, n)
    drop = scale[:, None] + rng.random((n, 2)) * (2.0 * half - 2.0 * scale[:, None])
    args = (np.zeros((1, 3)), np.ones(1), np.array([0, 1]), np.zeros(n, dtype=np.int64), scale,
            np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), drop)
    box = sdbd.deposit(*args, (0.0, 0.0), (2.0 * half, 2.0 * half), sdbd.LATERAL_WALLS, sdbd.FLOOR_ROLL)
    polygon = sdbd.deposit(*args, *cylinder_box(half, half, radius), sdbd.LATERAL_WALLS, sdbd.FLOOR_ROLL,
                           container=sdbd.CONTAINER_CYLINDER, cylinder=(half, half, radius, 4))
    assert np.count_nonzero(box.event_counts[:, 4]) > 20  # the walls were touched
    np.testing.assert_array_equal(polygon.positions, box.positions)
    np.testing.assert_array_equal(polygon.state, box.state)


def test_bad_cylinder_arguments_raise_value_error():
    ok = dict(shape_offsets=np.zeros((1, 3)), shape_radii=np.ones(1), shape_start=[0, 1], particle_shape=[0],
              particle_scale=[1.0], particle_rotation=[[1.0, 0.0, 0.0, 0.0]], particle_drop_xy=[(1.0, 1.0)],
              box_lower_xy=(-4.0, -4.0), box_upper_xy=(6.0, 6.0), lateral=sdbd.LATERAL_WALLS,
              floor=sdbd.FLOOR_STOP, container=sdbd.CONTAINER_CYLINDER, cylinder=(1.0, 1.0, 5.0, 16))
    sdbd.deposit(**ok)
    for change in (dict(lateral=sdbd.LATERAL_PERIODIC), dict(cylinder=(1.0, 1.0, 5.0, 7)),
                   dict(cylinder=None), dict(container=sdbd.CONTAINER_BOX), dict(container=2),
                   dict(box_upper_xy=(6.0, 7.0)),                        # not the square of the cylinder
                   dict(cylinder=(1.0, 1.0, 0.9, 16), box_lower_xy=(0.1, 0.1), box_upper_xy=(1.9, 1.9)),
                   dict(particle_drop_xy=[(1.0, 5.0)])):                 # does not start inside
        with pytest.raises(ValueError):
            sdbd.deposit(**{**ok, **change})
