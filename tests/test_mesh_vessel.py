"""Deposition in mesh vessels (convex, open-topped): the kernel's faces against analytic rest
positions, and the invariants of random hoppers searched at random.

A frictionless face is a sphere of infinite radius: a sphere touching an inclined face alone slides
down its line of steepest descent, held by two faces it slides along their line; a glued face holds
the touching sphere's centre.  The analytic configurations below follow from those rules alone.
"""

import math

import numpy as np
import pytest

from parsim.core import sdbd
from parsim.deposition.vessel import bowl_mesh, hopper_mesh, prism_mesh, v_trough_mesh, vessel_from_mesh
from tests.sediment_checks import check_sediment

R = 0.5


def _sphere_drop(xy, faces, upper, floor=sdbd.FLOOR_STOP, wall=sdbd.WALL_FRICTIONLESS):
    """One sphere of radius R dropped at ``xy`` into the box ``[0, upper]`` with ``faces``."""
    res, diag = sdbd.deposit_with_diagnostics(
        np.zeros((1, 3)), np.array([R]), np.array([0, 1]), np.zeros(1, dtype=np.int64), np.ones(1),
        np.array([[1.0, 0, 0, 0]]), np.array([xy], dtype=np.float64), (0.0, 0.0), upper, sdbd.LATERAL_WALLS, floor,
        wall_contact=wall, container=sdbd.CONTAINER_MESH, faces=faces, check_overlaps=True)
    assert diag["max_overlap"] <= 1e-9
    return res


def _plane(angle_deg, foot_x, ly):
    """The face of an incline rising towards x = 0 at ``angle_deg``, its foot on the floor at ``foot_x``."""
    th = math.radians(angle_deg)
    normal = np.array([[math.sin(th), 0.0, math.cos(th)]])
    return normal, np.array([math.sin(th) * foot_x]), np.array([[0.0, foot_x, 0.0, ly, 0.0, foot_x * math.tan(th)]])


@pytest.mark.parametrize("angle", [10.0, 30.0, 60.0])
@pytest.mark.parametrize("floor", [sdbd.FLOOR_STOP, sdbd.FLOOR_ROLL])
def test_a_sphere_on_a_frictionless_incline_slides_to_its_foot(angle, floor):
    """It comes to rest on the floor against the incline: N . a = c + R with a_z = R."""
    faces = _plane(angle, 6.0, 4.0)
    res = _sphere_drop((1.5, 2.0), faces, (10.0, 4.0), floor)
    th = math.radians(angle)
    x = (math.sin(th) * 6.0 + R - math.cos(th) * R) / math.sin(th)
    np.testing.assert_allclose(res.positions[0], [x, 2.0, R], atol=1e-9)
    assert res.event_counts[0, sdbd.EVENT_KINDS.index("wall_contact")] == 1


def test_a_sphere_on_a_glued_incline_stays_where_it_lands():
    """A glued face holds the centre of the sphere that touches it: it stops straight below its drop."""
    faces = _plane(30.0, 6.0, 4.0)
    res = _sphere_drop((1.5, 2.0), faces, (10.0, 4.0), wall=sdbd.WALL_GLUED)
    th = math.radians(30.0)
    z = (math.sin(th) * 6.0 + R - math.sin(th) * 1.5) / math.cos(th)
    np.testing.assert_allclose(res.positions[0], [1.5, 2.0, z], atol=1e-9)


def _trough(half_angle_deg, centre_x, ly, tilt_deg=0.0):
    """A V-trough along y whose bottom line passes through (centre_x, 0, 0) and falls towards y = 0 at
    ``tilt_deg``; its two faces have inward normals at ``half_angle_deg`` from the vertical."""
    th, be = math.radians(half_angle_deg), math.radians(tilt_deg)
    normals = np.array([[math.sin(th), -math.cos(th) * math.sin(be), math.cos(th) * math.cos(be)],
                        [-math.sin(th), -math.cos(th) * math.sin(be), math.cos(th) * math.cos(be)]])
    levels = normals @ np.array([centre_x, 0.0, 0.0])
    boxes = np.array([[0.0, centre_x, 0.0, ly, 0.0, 10.0], [centre_x, 2 * centre_x, 0.0, ly, 0.0, 10.0]])
    return normals, levels, boxes


@pytest.mark.parametrize("x", [2.0, 4.3, 7.5])
def test_a_sphere_dropped_into_a_v_trough_rests_on_its_bottom_line(x):
    """Down one slope, onto the other, then held by both: centred over the line at height R / sin of the
    slopes' angle to the horizontal (R / cos of the normals' angle to the vertical)."""
    res = _sphere_drop((x, 2.0), _trough(40.0, 5.0, 4.0), (10.0, 4.0))
    np.testing.assert_allclose(res.positions[0], [5.0, 2.0, R / math.cos(math.radians(40.0))], atol=1e-9)
    assert res.state[0] == sdbd.HANGING_TWO and res.contacts[0] == 2


def test_a_sphere_in_a_tilted_v_trough_slides_along_it_to_the_end_wall():
    """Along the line of the two faces, downhill, to the wall y = 0: three planes fix the centre."""
    faces = _trough(40.0, 5.0, 4.0, tilt_deg=15.0)
    res = _sphere_drop((3.0, 3.0), faces, (10.0, 4.0))
    normals, levels, _ = faces
    a = np.linalg.solve(np.vstack([normals, [0.0, 1.0, 0.0]]), np.concatenate([levels + R, [R]]))
    np.testing.assert_allclose(res.positions[0], a, atol=1e-9)
    assert res.state[0] == sdbd.RESTING_THREE_CONTACTS


def _random_vessel(rng):
    """A hopper (4 to 12 sides, steep or shallow, pointed or flat-bottomed) or a bowl (a polyhedral
    spherical cap, 6 to 16 sides, 2 to 6 rings, as deep as half to all of its sphere's radius)."""
    if rng.random() < 0.5:
        top = float(rng.uniform(3.0, 5.0))
        return vessel_from_mesh(hopper_mesh(top, float(rng.uniform(0.0, 0.8 * top)), float(rng.uniform(2.0, 6.0)),
                                            int(rng.integers(4, 13))))
    radius = float(rng.uniform(3.0, 6.0))
    return vessel_from_mesh(bowl_mesh(radius, float(rng.uniform(0.5, 1.0)) * radius, int(rng.integers(6, 17)),
                                      int(rng.integers(2, 7)), bottom=float(rng.uniform(0.1, 0.5))))


def _random_shape(rng):
    """A sphere, a dimer or a bent trimer of radius-R spheres (offsets about the centre of mass)."""
    kind = int(rng.integers(3))
    if kind == 0:
        offsets = np.zeros((1, 3))
    elif kind == 1:
        offsets = np.array([[-0.4, 0.0, 0.0], [0.4, 0.0, 0.0]])
    else:
        offsets = np.array([[-0.5, 0.0, 0.0], [0.2, 0.3, 0.0], [0.3, -0.3, 0.2]])
        offsets -= offsets.mean(axis=0)
    return offsets, np.full(len(offsets), R)


def test_random_hoppers_and_bowls_no_sphere_crosses_a_face_and_every_particle_is_reported():
    """60 random hoppers and bowls (:func:`_random_vessel`), each with 25
    particles of a random shape, frictionless or glued, the paper's floor or a rolling one: after every
    move no sphere overlaps a face, the floor, a wall or another sphere (the kernel's overlap check),
    every sphere ends inside the vessel, no particle reaches the event limit, each one's state is at
    rest or hanging on its contacts, and the independent check of tests/sediment_checks.py finds every
    particle at rest: no fall, slide or rotation about its contacts (faces included) lowers it unblocked,
    and one reported on three contacts has three."""
    rng = np.random.default_rng(20261203)
    for case in range(60):
        vessel = _random_vessel(rng)
        offsets, radii = _random_shape(rng)
        extent = float(np.max(np.linalg.norm(offsets, axis=1)) + R)
        n = 25
        drops = []
        while len(drops) < n:
            xy = rng.uniform(0.0, vessel.upper[:2], size=(64, 2))
            drops += list(xy[vessel.inside_opening(xy, extent * (1 + 1e-6))])
        q = rng.normal(size=(n, 4))
        wall = int(rng.integers(2))
        floor = int(rng.integers(2))
        res, diag = sdbd.deposit_with_diagnostics(
            offsets, radii, np.array([0, len(radii)]), np.zeros(n, dtype=np.int64), np.ones(n), q,
            np.array(drops[:n]), (0.0, 0.0), tuple(vessel.upper[:2]), sdbd.LATERAL_WALLS, floor,
            wall_contact=wall, container=sdbd.CONTAINER_MESH, faces=vessel.faces(), check_overlaps=True,
            max_events_per_particle=20_000)
        label = f"case {case}: {len(vessel.levels)} faces, {len(radii)} spheres, wall {wall}, floor {floor}"
        assert res.stopped_at < 0, label
        assert diag["max_overlap"] <= 1e-9 * diag["length_scale"], label
        assert np.all(vessel.inside(res.positions, res.radii - 1e-9)), label
        assert set(res.state.tolist()) <= {sdbd.RESTING_THREE_CONTACTS, sdbd.RESTING_ON_FLOOR, sdbd.HANGING_ONE,
                                           sdbd.HANGING_TWO}, label
        problems = check_sediment(res.positions, res.radii, res.particle, res.center_of_mass, res.state, (0.0, 0.0),
                                  vessel.upper[:2], sdbd.LATERAL_WALLS, floor,
                                  ("frictionless", "glued")[wall], faces=(vessel.normals, vessel.levels))
        assert not problems, (label, problems)


def test_a_trough_read_from_its_mesh_is_the_trough_of_its_planes():
    """The V-trough built as a mesh and read as a vessel gives the analytic rest of a sphere."""
    vessel = vessel_from_mesh(v_trough_mesh(4.0, 10.0, 5.0))
    res = _sphere_drop((3.0, 2.0), vessel.faces(), tuple(vessel.upper[:2]))
    half = math.atan2(5.0, 5.0)  # the slopes rise 5 over 5
    np.testing.assert_allclose(res.positions[0], [5.0, 2.0, R / math.sin(half)], atol=1e-9)


@pytest.mark.parametrize("floor", [sdbd.FLOOR_STOP, sdbd.FLOOR_ROLL])
@pytest.mark.parametrize("dimers", [False, True])
def test_a_200_sided_prism_gives_the_cylinders_sediment(floor, dimers):
    """The prism read from a mesh and the cylinder modelled as the same polygon are one container, in two
    codes: 4 sides become the box's walls and 196 faces, against 200 sides of the polygon.  120 spheres
    (or dimers, randomly turned) dropped at the same random places end where the cylinder puts them, to
    round-off (the prism's box is the polygon's, the cylinder's the square about its circle)."""
    radius, sides, n = 4.0, 200, 120
    vessel = vessel_from_mesh(prism_mesh(radius, 6.0, sides))
    apothem = radius * math.cos(math.pi / sides)
    assert len(vessel.levels) == sides - 4
    np.testing.assert_allclose(vessel.upper[:2], 2.0 * apothem, rtol=1e-12)
    rng = np.random.default_rng(3)
    offsets = np.array([[-0.4, 0.0, 0.0], [0.4, 0.0, 0.0]]) if dimers else np.zeros((1, 3))
    extent = float(np.max(np.linalg.norm(offsets, axis=1))) + R
    angle = rng.uniform(0.0, 2.0 * np.pi, n)
    distance = (apothem - extent) * np.sqrt(rng.uniform(0.0, 1.0, n)) * 0.999
    xy = np.column_stack([apothem + distance * np.cos(angle), apothem + distance * np.sin(angle)])
    particles = (offsets, np.full(len(offsets), R), np.array([0, len(offsets)]), np.zeros(n, dtype=np.int64),
                 np.ones(n), rng.normal(size=(n, 4)))
    prism = sdbd.deposit(*particles, xy, (0.0, 0.0), tuple(vessel.upper[:2]), sdbd.LATERAL_WALLS, floor,
                         container=sdbd.CONTAINER_MESH, faces=vessel.faces())
    shift = radius - apothem
    cylinder = sdbd.deposit(*particles, xy + shift, (0.0, 0.0), (2 * radius, 2 * radius), sdbd.LATERAL_WALLS, floor,
                            container=sdbd.CONTAINER_CYLINDER, cylinder=(radius, radius, radius, sides))
    np.testing.assert_allclose(prism.positions, cylinder.positions - [shift, shift, 0.0], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(prism.state, cylinder.state)
