"""parsim's structure of a sediment against freud-analysis, the field's reference library.

A sediment of 600 rods of three spheres in a periodic box of 8 x 8: g(r) of the rods' centres in a
slab (freud's box periodic in x and y, not in z), the contact number of every rod, and the nematic
order of their axes.  freud computes in single precision: the tolerances below are its
round-off, and the bins of g(r) keep the rods' contact distance 1 off their edges, where a float
rounding would move a pair into the next bin.
"""

import numpy as np
import pytest

from tests.readers import require

require("freud")

import freud  # noqa: E402

import parsim  # noqa: E402
from parsim.core import structure  # noqa: E402
from parsim.core.sediment import CONTACT_GAP_TOLERANCE  # noqa: E402

FLOAT32 = 1e-5  # relative: freud's single precision, with room


@pytest.fixture(scope="module")
def sediment():
    outcome = parsim.deposit(n_particles=600, seed=3, shape="rod", shape_size=3, box_length=8.0)
    configuration = outcome.configuration
    arrays = configuration.arrays
    particle = arrays["spheres/particle"]
    n = int(particle.max()) + 1
    centres = np.array([arrays["spheres/position"][particle == p].mean(axis=0) for p in range(n)])
    return configuration, centres


def freud_box(lower_xy, upper_xy, z_low, z_high):
    """A freud box over the slab, periodic laterally only, and the shift into its centred frame."""
    length = np.asarray(upper_xy) - np.asarray(lower_xy)
    box = freud.box.Box(length[0], length[1], z_high - z_low)
    box.periodic = (True, True, False)
    return box, np.array([lower_xy[0] + length[0] / 2, lower_xy[1] + length[1] / 2, (z_low + z_high) / 2])


def test_radial_distribution_equals_freuds(sediment):
    configuration, centres = sediment
    lower, upper = configuration.box_lower[:2], configuration.box_upper[:2]
    z_low, z_high, r_max, bins = 1.5, centres[:, 2].max() - 1.5, 2.55, 30
    r, g, n_references = structure.radial_distribution(centres, lower, upper, (True, True), z_low, z_high, r_max,
                                                       bins)
    inside = (centres[:, 2] >= z_low) & (centres[:, 2] < z_high)
    reference = inside & (centres[:, 2] >= z_low + r_max) & (centres[:, 2] < z_high - r_max)
    assert n_references == reference.sum() > 100
    box, shift = freud_box(lower, upper, z_low, z_high)
    points = np.concatenate([centres[reference], centres[inside & ~reference]]) - shift  # references first,
    rdf = freud.density.RDF(bins, r_max)                                                # so exclude_ii is theirs
    rdf.compute(system=(box, points), query_points=centres[reference] - shift,
                neighbors={"r_max": r_max, "exclude_ii": True})
    np.testing.assert_allclose(rdf.bin_centers, r, rtol=FLOAT32)
    np.testing.assert_allclose(rdf.rdf, g, rtol=FLOAT32, atol=0.0)
    assert g.max() > 1.2  # the first shell of neighbours stands out


def test_contact_numbers_equal_those_of_freuds_neighbours(sediment):
    """freud's neighbour search finds the candidate pairs (within a diameter and a margin); their
    gaps, in double precision with the minimum image, decide the contacts by parsim's criterion."""
    configuration, _ = sediment
    arrays = configuration.arrays
    position, radius, particle = arrays["spheres/position"], arrays["spheres/radius"], arrays["spheres/particle"]
    lower, upper = configuration.box_lower[:2], configuration.box_upper[:2]
    n = int(particle.max()) + 1
    pairs, _ = structure.contact_pairs(position, radius, particle, lower, upper, (True, True))
    parsim_z = structure.contacts_per_particle(pairs, particle, n)
    top = position[:, 2].max() + 2.0
    box, shift = freud_box(lower, upper, -2.0, top)
    box.periodic = (True, True, True)  # freud queries no partly periodic box; z has room for no wrap-around
    found = freud.locality.AABBQuery(box, position - shift).query(
        position - shift, {"r_max": 2 * radius.max() + 0.1, "exclude_ii": True}).toNeighborList()
    i, j = found.query_point_indices.astype(np.int64), found.point_indices.astype(np.int64)
    separation = position[j] - position[i]
    length = upper - lower
    separation[:, :2] -= length * np.round(separation[:, :2] / length)
    gap = np.linalg.norm(separation, axis=1) - radius[i] - radius[j]
    touching = (particle[i] != particle[j]) & (gap < CONTACT_GAP_TOLERANCE * radius.mean()) & (i < j)
    freud_z = structure.contacts_per_particle(np.column_stack([i[touching], j[touching]]), particle, n)
    assert np.array_equal(parsim_z, freud_z)
    assert 2.0 < parsim_z.mean() < 8.0


def test_nematic_order_equals_freuds(sediment):
    configuration, _ = sediment
    arrays = configuration.arrays
    position, particle = arrays["spheres/position"], arrays["spheres/particle"]
    first = np.searchsorted(particle, np.arange(int(particle.max()) + 1))
    axes = position[first + 2] - position[first]  # a rod's first sphere to its third
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    order, _ = structure.nematic_order(axes)
    nematic = freud.order.Nematic()
    nematic.compute(axes)
    assert abs(nematic.order - order) < FLOAT32
    assert 0.0 < order < 1.0
