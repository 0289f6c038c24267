"""Frictionless container walls: a wall is a sphere of infinite radius.

A frictionless wall only pushes horizontally, so it never holds a particle up by itself: a
particle touching a wall and nothing below falls, a particle touching a wall and one sediment
sphere rolls about the axis through that sphere's centre along the wall's normal (it slides
along the wall), and the bulk of a walled sediment packs as a periodic one.  The former model,
in which a wall holds the touching sphere's centre fixed (``wall_contact = "glued"``), stays
available by name.
"""

import re

import numpy as np
import pytest

from parsim.core import sdbd
from parsim.core.shapes import random_rotations

from . import sediment_checks as sc

SPHERE = (np.zeros((1, 3)), np.ones(1))


def deposit_spheres(scale, drop, box, lateral, floor, wall_contact=sdbd.WALL_FRICTIONLESS):
    """Spheres of radius ``scale`` dropped at ``drop`` in the square box [0, box]^2."""
    n = len(scale)
    offsets, radii = SPHERE
    return sdbd.deposit(offsets, radii, np.array([0, 1]), np.zeros(n, dtype=np.int64), scale,
                        np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), drop, (0.0, 0.0), (box, box), lateral, floor,
                        wall_contact=wall_contact)


def wall_contacts_of_spheres(res, box, tol=1e-7):
    """Per particle (one sphere each): number of walls and of earlier spheres it touches,
    found from the positions alone."""
    x, r = res.positions, res.radii
    walls = ((x[:, 0] - r < tol) .astype(int) + (box - x[:, 0] - r < tol)
             + (x[:, 1] - r < tol) + (box - x[:, 1] - r < tol))
    d = np.linalg.norm(x[:, None, :] - x[None, :, :], axis=-1) - r[:, None] - r[None, :]
    earlier = np.tril(np.ones((len(r), len(r)), dtype=bool), k=-1)
    spheres = ((d < tol) & earlier).sum(axis=1)
    return walls, spheres


@pytest.mark.parametrize("floor", [sdbd.FLOOR_STOP, sdbd.FLOOR_ROLL])
def test_a_sphere_released_against_a_wall_onto_a_sphere_slides_down_to_the_floor(floor):
    # a large sphere rests on the floor against the wall x = 0; a small one, also touching
    # that wall, lands on its side: pressed against the wall it rolls round the large one
    scale = np.array([1.0, 0.5])
    drop = np.array([[1.0, 5.0], [0.5, 5.3]])
    res = deposit_spheres(scale, drop, 10.0, sdbd.LATERAL_WALLS, floor)
    small = res.positions[1]
    assert small[2] == pytest.approx(0.5, abs=1e-9)  # on the floor
    assert small[0] == pytest.approx(0.5, abs=1e-9)  # still against the wall
    assert small[1] > 5.0 + np.sqrt(2.0) - 1e-6      # beside the large sphere, not on it
    assert res.state[1] in (sdbd.RESTING_ON_FLOOR, sdbd.RESTING_THREE_CONTACTS)


def test_a_glued_wall_holds_the_sphere_on_the_side_of_the_other():
    scale = np.array([1.0, 0.5])
    drop = np.array([[1.0, 5.0], [0.5, 5.3]])
    res = deposit_spheres(scale, drop, 10.0, sdbd.LATERAL_WALLS, sdbd.FLOOR_STOP, wall_contact=sdbd.WALL_GLUED)
    assert res.positions[1, 2] > 1.0
    assert res.state[1] == sdbd.HANGING_TWO


@pytest.mark.parametrize("floor", [sdbd.FLOOR_STOP, sdbd.FLOOR_ROLL])
def test_no_sphere_rests_on_one_sphere_and_a_wall(floor):
    rng = np.random.default_rng(11)
    n, box = 600, 8.0
    scale = rng.uniform(0.35, 0.65, n)
    drop = scale[:, None] + rng.random((n, 2)) * (box - 2.0 * scale[:, None])
    res = deposit_spheres(scale, drop, box, sdbd.LATERAL_WALLS, floor)
    assert res.stopped_at == -1
    walls, spheres = wall_contacts_of_spheres(res, box)
    off_floor = res.positions[:, 2] - res.radii > 1e-7
    propped = np.nonzero(off_floor & (walls >= 1) & (walls + spheres < 3))[0]
    assert len(propped) == 0, f"spheres held by a wall and fewer than three contacts: {propped[:10]}"
    assert np.count_nonzero(off_floor & (walls >= 1)) > 20  # the walls were touched
    problems = sc.check_sediment(res.positions, res.radii, res.particle, res.center_of_mass, res.state,
                                 (0.0, 0.0), (box, box), sdbd.LATERAL_WALLS, floor)
    assert problems == []


def test_the_glued_model_props_spheres_on_walls():
    rng = np.random.default_rng(11)
    n, box = 600, 8.0
    scale = rng.uniform(0.35, 0.65, n)
    drop = scale[:, None] + rng.random((n, 2)) * (box - 2.0 * scale[:, None])
    res = deposit_spheres(scale, drop, box, sdbd.LATERAL_WALLS, sdbd.FLOOR_STOP, wall_contact=sdbd.WALL_GLUED)
    walls, spheres = wall_contacts_of_spheres(res, box)
    off_floor = res.positions[:, 2] - res.radii > 1e-7
    assert np.count_nonzero(off_floor & (walls >= 1) & (walls + spheres < 3)) > 0
    problems = sc.check_sediment(res.positions, res.radii, res.particle, res.center_of_mass, res.state,
                                 (0.0, 0.0), (box, box), sdbd.LATERAL_WALLS, sdbd.FLOOR_STOP, wall_contact="glued")
    assert problems == []


def bulk_packing_fraction(res, box, margin):
    """Packing fraction of monodisperse spheres in the bulk, from the number of centres in the
    box ``margin`` away from the walls, the floor and the filling height (unbiased for a
    homogeneous packing: each centre carries one sphere volume)."""
    x, r = res.positions, res.radii[0]
    height = 2.0 * x[:, 2].mean()  # the filling height 2 z_cm
    lo, hi = np.array([margin, margin, margin]), np.array([box - margin, box - margin, height - margin])
    inside = np.all((x > lo) & (x < hi), axis=1)
    return inside.sum() * 4.0 / 3.0 * np.pi * r ** 3 / np.prod(hi - lo)


def test_the_bulk_of_a_walled_sediment_packs_as_a_periodic_one():
    # Visscher-Bolsterli spheres (phi = 0.5813 in a periodic box); three realisations of
    # 15 000 spheres in a box of 24 diameters each, bulk 3 diameters from every boundary
    box, n = 24.0, 15_000
    phi = {}
    for lateral in (sdbd.LATERAL_PERIODIC, sdbd.LATERAL_WALLS):
        values = []
        for seed in range(3):
            rng = np.random.default_rng(seed)
            drop = 0.5 + rng.random((n, 2)) * (box - 1.0)
            res = deposit_spheres(np.full(n, 0.5), drop, box, lateral, sdbd.FLOOR_STOP)
            values.append(bulk_packing_fraction(res, box, margin=3.0))
        phi[lateral] = (np.mean(values), np.std(values, ddof=1) / np.sqrt(len(values)))
    (periodic, e_periodic), (walls, e_walls) = phi[sdbd.LATERAL_PERIODIC], phi[sdbd.LATERAL_WALLS]
    assert periodic == pytest.approx(0.5813, abs=0.002)
    assert abs(walls - periodic) < 3.0 * np.hypot(e_periodic, e_walls) + 2e-4


@pytest.mark.parametrize("cylinder", [None, (5.0, 5.0, 5.0, 48)], ids=["box", "cylinder"])
def test_the_first_particle_dropped_across_a_wall_is_named(cylinder):
    """Rods of three spheres dropped at random with room to spare all fit; of two moved across a wall
    (to x = 0.3, their rods lying along x) the first is named, counted from ``first_particle`` in a chunk."""
    n = 400
    rng = np.random.default_rng(5)
    angle = 2.0 * np.pi * rng.random(n)
    drop = np.column_stack([5.0 + 2.5 * np.cos(angle), 5.0 + 2.5 * np.sin(angle)])  # 1.25 from the walls at least
    offsets = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    along_x = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    arguments = [offsets, np.full(3, 0.5), np.array([0, 3]), np.zeros(n, dtype=np.int64), np.ones(n), along_x, drop,
                 (0.0, 0.0), (10.0, 10.0), sdbd.LATERAL_WALLS, sdbd.FLOOR_ROLL]
    options = {} if cylinder is None else {"container": sdbd.CONTAINER_CYLINDER, "cylinder": cylinder}
    sdbd.prepare_deposition(*arguments, **options)
    drop[[250, 37]] = (0.3, 5.0)  # both cross the wall: the first in the drop order is named
    message = "particle 137: dropped at (0.3, 5.0), it does not fit inside the walls"
    with pytest.raises(ValueError, match=re.escape(message)):
        sdbd.prepare_deposition(*arguments, **options, first_particle=100)
