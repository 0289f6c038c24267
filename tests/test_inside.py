"""A vessel's inside (:mod:`parsim.deposition.inside`): its volumes between two heights against an independent
computation, the divergence theorem over the polytope's facets, on random convex vessels; and analytic
sections and volumes."""

import math

import numpy as np
import pytest

from parsim.deposition.vessel import bowl_mesh, hopper_mesh, prism_mesh, v_trough_mesh, vessel_from_mesh, wedge_mesh
from tests.polytopes import centroid_height, facet_volume

RANDOM_CASES = 300


def _random_mesh(rng):
    kind = rng.integers(5)
    if kind == 0:
        top = rng.uniform(2.0, 8.0)
        rim = rng.uniform(0.5, 3.0) if rng.random() < 0.5 else None
        return hopper_mesh(top, rng.uniform(0.3, 0.9) * top, rng.uniform(2.0, 8.0), int(rng.integers(3, 13)),
                           rim=rim)
    if kind == 1:
        return v_trough_mesh(rng.uniform(3.0, 12.0), rng.uniform(2.0, 8.0), rng.uniform(1.0, 5.0))
    if kind == 2:
        lx, angle, start = rng.uniform(3.0, 9.0), rng.uniform(5.0, 60.0), rng.uniform(0.0, 1.0)
        rise = (lx - start) * math.tan(math.radians(angle))
        return wedge_mesh(lx, rng.uniform(3.0, 9.0), rise + rng.uniform(1.0, 4.0), angle, start)
    if kind == 3:
        return prism_mesh(rng.uniform(2.0, 6.0), rng.uniform(2.0, 6.0), int(rng.integers(3, 40)))
    radius = rng.uniform(2.0, 6.0)
    return bowl_mesh(radius, rng.uniform(0.3, 1.0) * radius, int(rng.integers(5, 11)), int(rng.integers(1, 5)))


def _random_vessel(rng):
    return vessel_from_mesh(_random_mesh(rng))


def test_volumes_between_heights_equal_the_facet_sums_on_random_vessels():
    """Random hoppers (with and without a collar), V-troughs, wedges, prisms and bowls, shrunk by a random distance,
    between random heights below, across and above the rim: Simpson between the section's break heights
    equals the divergence theorem over the polytope's facets, and (every third case) the centroid from the
    moment of the sections the centroid of the facets' tetrahedra."""
    rng = np.random.default_rng(20261203)
    for case in range(RANDOM_CASES):
        vessel = _random_vessel(rng)
        inside = vessel.convex_inside()
        if rng.random() < 0.5:
            inside = inside.shrunk(rng.uniform(0.0, 0.2) * float(np.min(vessel.upper[:2])))
        top = float(vessel.upper[2])
        low, high = np.sort(rng.uniform(-0.1 * top, 1.6 * top, 2))
        expected = facet_volume(inside, low, high)
        assert inside.volume_between(low, high) == pytest.approx(expected, rel=1e-9, abs=1e-9 * top**3), case
        if expected > 1e-6 * top**3 and case % 3 == 0:
            centroid = inside.moment_between(low, high) / inside.volume_between(low, high)
            assert centroid == pytest.approx(centroid_height(inside, low, high), rel=1e-9), case


def test_a_vessel_closed_at_its_rim_has_the_volume_of_its_mesh():
    """The volume the mesh's triangles enclose with the rim's plane, sum det(a - o, b - o, c - o) / 6 with o in
    that plane (the opening's cap adds nothing), equals the inside's up to the rim."""
    rng = np.random.default_rng(5)
    for _ in range(40):
        mesh = _random_mesh(rng)
        vessel = vessel_from_mesh(mesh)
        corners = mesh.vertices[mesh.faces] - mesh.vertices.min(axis=0) - [0.0, 0.0, vessel.upper[2]]
        enclosed = abs(float(np.sum(np.linalg.det(corners)))) / 6.0
        assert vessel.convex_inside().volume_between(0.0, vessel.upper[2]) == pytest.approx(enclosed, rel=1e-9)


def test_a_square_funnel_is_a_frustum_and_the_box_above_its_rim():
    """Four faces from a square rim (the box's sides) to a smaller square: V = h (A1 + A2 + sqrt(A1 A2)) / 3
    up to the rim; above it the faces lean out of the box, whose square is the section."""
    vessel = vessel_from_mesh(hopper_mesh(4.0 * math.sqrt(2.0), 2.0 * math.sqrt(2.0), 6.0, 4))
    inside = vessel.convex_inside()
    bottom, top = 4.0**2, 8.0**2  # squares of sides 4 and 8
    assert inside.volume_between(0.0, 6.0) == pytest.approx(6.0 * (bottom + top + math.sqrt(bottom * top)) / 3.0,
                                                           rel=1e-12)
    assert inside.area_at(3.0) == pytest.approx(6.0**2, rel=1e-12)
    width = float(np.prod(vessel.upper[:2]))
    assert inside.volume_between(6.0, 9.0) == pytest.approx(3.0 * width, rel=1e-12)


def test_a_prism_has_its_polygons_area_at_every_height():
    """An n-gon prism: the regular polygon's area 0.5 n r^2 sin(2 pi / n) at every height, inside and above."""
    for sides in (5, 8, 200):
        inside = vessel_from_mesh(prism_mesh(3.0, 4.0, sides)).convex_inside()
        area = 0.5 * sides * 9.0 * math.sin(2.0 * math.pi / sides)
        assert inside.volume_between(0.5, 7.0) == pytest.approx(6.5 * area, rel=1e-12)
        assert len(inside.vertex_heights(7.0)) == 2  # vertical faces: vertices on the floor and the cut only


def test_the_filled_height_has_the_centre_of_mass_asked_for():
    """A prism filled to H has its centroid at H / 2; a square funnel's filled height has the centroid of
    its facets' tetrahedra; the height holding a volume holds it."""
    prism = vessel_from_mesh(prism_mesh(3.0, 4.0, 7)).convex_inside()
    assert prism.filled_height(1.7) == pytest.approx(3.4, rel=1e-12)
    funnel = vessel_from_mesh(hopper_mesh(4.0 * math.sqrt(2.0), 2.0 * math.sqrt(2.0), 6.0, 4)).convex_inside()
    for centre in (0.5, 2.0, 4.0):  # the last above the rim
        height = funnel.filled_height(centre)
        assert centroid_height(funnel, 0.0, height) == pytest.approx(centre, rel=1e-10)
        half = funnel.height_holding(0.5 * funnel.volume_between(0.0, height), height)
        assert facet_volume(funnel, 0.0, half) == pytest.approx(0.5 * facet_volume(funnel, 0.0, height), rel=1e-10)
