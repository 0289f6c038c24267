"""Sediment statistics on packings whose answers are known analytically."""

import math

import numpy as np
import pytest

from parsim.core.sediment import (
    SlabCover,
    covered_volumes,
    exact_sum,
    filling_height,
    packing_fraction,
    packing_fraction_profile,
    packing_fractions,
    sphere_keys,
    sum_expansion,
    union_volume_and_height,
)
from parsim.core.shapes.union import centre_of_mass_of_union, lens_volume as _lens_volume
from parsim.core.structure import contact_network, coordination


def simple_cubic(n, layers, radius):
    """Touching spheres on a simple cubic lattice: n x n per layer in a periodic box of side 2Rn."""
    i, j, k = np.meshgrid(np.arange(n), np.arange(n), np.arange(layers), indexing="ij")
    return (2 * radius * np.column_stack([i.ravel(), j.ravel(), k.ravel()]) + radius), 2 * radius * n


def face_centred_cubic(cells, layers, radius):
    """FCC of touching spheres: cubic cell a = 2 sqrt(2) R with 4 sites."""
    a = 2 * np.sqrt(2) * radius
    basis = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]])
    i, j, k = np.meshgrid(np.arange(cells), np.arange(cells), np.arange(layers), indexing="ij")
    origins = np.column_stack([i.ravel(), j.ravel(), k.ravel()])
    return a * (origins[:, None, :] + basis[None, :, :]).reshape(-1, 3) + [0, 0, radius], a * cells, a


def test_simple_cubic_packing_fraction_is_pi_over_6():
    radius = 0.5
    x, side = simple_cubic(6, 8, radius)
    phi = packing_fraction(x, np.full(len(x), radius), (0, 0), (side, side), 2.0, 6.0)  # four whole layers
    assert phi == pytest.approx(np.pi / 6, abs=1e-3)


def test_fcc_packing_fraction_and_twelve_contacts():
    radius = 1.0
    x, side, a = face_centred_cubic(4, 6, radius)
    radii = np.full(len(x), radius)
    phi = packing_fraction(x, radii, (0, 0), (side, side), radius + a, radius + 4 * a)  # three whole cells
    assert phi == pytest.approx(np.pi / (3 * np.sqrt(2)), abs=1e-3)
    own = np.arange(len(x))
    mean, count = coordination(x, radii, own, x[:, 2], (0, 0), (side, side), radius + a, radius + 4 * a)
    assert mean == 12.0 and count == 4 * 4 * 4 * 3  # every bulk sphere touches twelve, through the periodic sides


def test_simple_cubic_has_six_contacts_between_particles_only():
    radius, n, layers = 0.5, 6, 6
    x, side = simple_cubic(n, layers, radius)
    radii = np.full(len(x), radius)
    mean, _ = coordination(x, radii, np.arange(len(x)), x[:, 2], (0, 0), (side, side), 1.0, 5.0)
    assert mean == 6.0
    # Neighbours along x glued into dimers: the glue is no contact between particles,
    # so each dimer has 2 x 5 contacts.
    i, j, k = (np.round((x - radius) / (2 * radius)).astype(np.int64)).T
    dimer = ((i // 2) * n + j) * layers + k
    com_z = np.bincount(dimer, weights=x[:, 2]) / 2
    mean, count = coordination(x, radii, dimer, com_z, (0, 0), (side, side), 1.0, 5.0)
    assert mean == 10.0 and count == (n // 2) * n * 4


def test_gaps_beyond_the_tolerance_are_no_contacts():
    radius = 1.0
    x = np.array([[0.0, 0.0, 1.0], [2.0 + 1e-8, 0.0, 1.0], [0.0, 2.0 + 1e-4, 1.0]])
    mean, count = coordination(x, np.full(3, radius), np.arange(3), x[:, 2], (-5, -5), (5, 5), 0.0, 2.0)
    assert count == 3 and mean == pytest.approx(2 / 3)  # only the 1e-8 gap closes


def test_profile_integrates_to_the_sphere_volume():
    radius = 0.5
    x, side = simple_cubic(4, 1, radius)  # one layer on the floor
    edges = np.linspace(0.0, 2 * radius, 11)
    profile = packing_fraction_profile(x, np.full(len(x), radius), (0, 0), (side, side), edges, samples=50_000)
    z = 0.5 * (edges[1:] + edges[:-1])
    exact = np.pi * (radius**2 - (z - radius) ** 2) / (2 * radius) ** 2  # section area / column area, at the slab middle
    assert profile.mean() == pytest.approx(np.pi / 6, abs=2e-3)
    np.testing.assert_allclose(profile, exact, atol=0.02)  # slab-averaged against mid-slab values


def test_overlapping_spheres_are_counted_once():
    radius = 1.0
    single = np.array([[2.0, 2.0, 2.0]])
    double = np.array([[2.0, 2.0, 2.0], [2.0, 2.0, 2.0]])  # the same sphere twice: the same covered volume
    one = packing_fraction(single, [radius], (0, 0), (4, 4), 0.0, 4.0)
    two = packing_fraction(double, [radius, radius], (0, 0), (4, 4), 0.0, 4.0)
    assert one == pytest.approx(4 / 3 * np.pi / 64, abs=1e-12)  # exact: the sphere's volume
    assert two == pytest.approx(one, rel=1e-9)  # the duplicate's lens is the whole sphere, known exactly


def test_filling_height_is_twice_the_volume_weighted_centre():
    assert filling_height([1.0, 3.0], [1.0, 1.0]) == 4.0
    assert filling_height([1.0, 3.0], [3.0, 1.0]) == 3.0
    with pytest.raises(ValueError):
        filling_height([], [])


def collinear_union_volume(n, spacing, radius):
    """Volume of the union of n equal spheres whose centres lie on a line ``spacing`` <= 2 radius apart: each
    cross-section perpendicular to the line is the disc of the nearest centre, so the union is cut into
    pieces at the midpoints between centres, the middle ones alike."""
    middle = np.pi * (radius**2 * spacing - spacing**3 / 12.0)
    end = np.pi * (radius**2 * (0.5 * spacing + radius) - ((0.5 * spacing) ** 3 + radius**3) / 3.0)
    return 2.0 * end + (n - 2) * middle


@pytest.mark.parametrize("spacing, rel", [(1.5, 1e-12), (1.0, 1e-12), (0.5, 5e-4)])
def test_union_of_a_tilted_rod(spacing, rel):
    """Spacings of 1 radius and more overlap pairwise: exact; below, three spheres overlap and the union is
    integrated on columns (errors about 2e-4)."""
    radius, n = 0.5, 7
    line = np.array([0.6, 0.0, 0.8])
    centres = np.array([2.0, 1.0, 3.0]) + np.outer(np.arange(n) - 0.5 * (n - 1), spacing * radius * line)
    volume, height = union_volume_and_height(centres, np.full(n, radius))
    assert volume == pytest.approx(collinear_union_volume(n, spacing * radius, radius), rel=rel)
    assert height == pytest.approx(3.0, rel=rel)  # the middle sphere's centre, by symmetry


def test_union_of_two_unequal_spheres():
    big, small, distance = 1.0, 0.6, 0.9
    centres = np.array([[0.0, 0.0, 2.0], [0.0, 0.6 * distance, 2.0 + 0.8 * distance]])
    volume, height = union_volume_and_height(centres, [big, small])
    lens = _lens_volume(big, small, distance)  # Weisstein's closed form
    assert volume == pytest.approx(4.0 / 3.0 * np.pi * (big**3 + small**3) - lens, rel=1e-12)
    columns, _ = centre_of_mass_of_union(centres, np.array([big, small]), resolution=128)
    assert height == pytest.approx(columns[2], abs=1e-5)
    # a sphere inside the other adds nothing
    inside = np.array([[0.0, 0.0, 2.0], [0.0, 0.1, 2.2]])
    volume, height = union_volume_and_height(inside, [big, small])
    assert volume == pytest.approx(4.0 / 3.0 * np.pi * big**3, rel=1e-12)
    assert height == pytest.approx(2.0, rel=1e-12)


def test_union_of_spheres_apart_is_their_sum():
    rng = np.random.default_rng(3)
    centres = np.column_stack([np.arange(50) * 3.0, rng.random(50), 1.0 + rng.random(50)])
    radii = rng.uniform(0.5, 1.0, 50)
    volume, height = union_volume_and_height(centres, radii)
    sphere = 4.0 / 3.0 * np.pi * radii**3
    assert volume == pytest.approx(sphere.sum(), rel=1e-14)
    assert height == pytest.approx(np.dot(sphere, centres[:, 2]) / sphere.sum(), rel=1e-14)


def test_spheres_flagged_as_not_overlapping_need_no_overlap_search():
    """A lattice of randomly turned rods (spheres 1 radius apart: pairwise lenses, some cut by the slabs'
    edges; 0.3 radii apart: three spheres overlap, sampled) and lone spheres: the packing fractions with the
    overlap flags of the contact search are those of the search over every sphere, to the last bit, for all
    the spheres and for a subset of them."""
    rng = np.random.default_rng(11)
    radius, spacing = 0.5, 2.2
    sites = (np.stack(np.meshgrid(*[np.arange(5)] * 3, indexing="ij"), axis=-1).reshape(-1, 3) + 0.5) * spacing
    x, radii, particle = [], [], []
    for p, site in enumerate(sites):
        kind = p % 3  # a lone sphere, a rod of pairwise overlaps, a rod of triple overlaps
        axis = rng.standard_normal(3)
        steps = [0.0] if kind == 0 else np.array([-1.0, 0.0, 1.0]) * (1.0 if kind == 1 else 0.3) * radius
        x.extend(site + step * axis / np.linalg.norm(axis) for step in steps)
        radii.extend([radius] * len(steps))
        particle.extend([p] * len(steps))
    x, radii, particle = np.array(x), np.array(radii), np.array(particle)
    side = 5 * spacing
    flags = contact_network(x, radii, particle, (0, 0), (side, side), True).overlapping
    np.testing.assert_array_equal(flags, np.isin(particle, np.flatnonzero(np.arange(len(sites)) % 3 > 0)))
    edges = np.linspace(0.0, side, 23)
    slabs = np.column_stack([edges[:-1], edges[1:]])
    everything = packing_fractions(x, radii, (0, 0), (side, side), slabs, samples=4000)
    assert np.all(everything > 0.0)
    np.testing.assert_array_equal(packing_fractions(x, radii, (0, 0), (side, side), slabs, samples=4000,
                                                    overlapping=flags), everything)
    part = x[:, 0] < 0.5 * side
    np.testing.assert_array_equal(packing_fractions(x[part], radii[part], (0, 0), (side, side), slabs, samples=4000,
                                                    overlapping=flags[part]),
                                  packing_fractions(x[part], radii[part], (0, 0), (side, side), slabs, samples=4000))


def test_exact_sums_do_not_depend_on_how_the_numbers_are_split():
    """Sums over parts, as ranks make them, are the correctly rounded sum of all the numbers: math.fsum's."""
    rng = np.random.default_rng(8)
    values = rng.standard_normal(100_000) * 10.0 ** rng.integers(-8, 9, 100_000)
    cut = rng.permutation(len(values))
    parts = np.array_split(values[cut], 7)
    assert exact_sum(sum_expansion(values)) == math.fsum(values)
    assert exact_sum(*(sum_expansion(p) for p in parts)) == math.fsum(values)
    assert float(np.sum(values)) != math.fsum(values) or float(sum(np.sum(p) for p in parts)) != math.fsum(values)


def turned_rods(rng, n_side, layers, radius, spacing):
    """Rods of three spheres ``spacing`` radii apart in random orientations on a lattice (no two rods meet):
    (centres, radii, particle of each sphere, the rods' first spheres)."""
    pitch = 2.0 * (1.0 + spacing) * radius * 1.01
    i, j, k = np.meshgrid(np.arange(n_side), np.arange(n_side), np.arange(layers), indexing="ij")
    centres = pitch * (np.column_stack([i.ravel(), j.ravel(), k.ravel()]) + 0.5)
    u = rng.normal(size=centres.shape)
    u /= np.linalg.norm(u, axis=1)[:, None]
    x = (centres[:, None, :] + spacing * radius * np.array([-1.0, 0.0, 1.0])[None, :, None] * u[:, None, :])
    particle = np.repeat(np.arange(len(centres)), 3)
    return x.reshape(-1, 3), np.full(3 * len(centres), radius), particle, pitch * n_side


def test_a_sampled_cap_has_the_same_points_in_any_part_of_the_spheres():
    """Rods of three spheres 0.5 radii apart (three overlap: sampled caps). With the spheres' keys, the covered
    volumes of two halves of the rods add up to those of all rods, and a shuffled order of the spheres gives
    them too, to round-off; with keys that are the order in which the spheres come, another order draws other
    points."""
    rng = np.random.default_rng(12)
    x, radii, particle, side = turned_rods(rng, 4, 4, 0.5, 0.5)
    keys = sphere_keys(particle, 3 * particle)
    slabs = np.column_stack([np.linspace(0.0, side, 13)[:-1], np.linspace(0.0, side, 13)[1:]])
    box = (0.0, 0.0), (side, side)
    cover = SlabCover(x, radii, *box, np.unique(slabs), keys=keys)
    assert cover.sampled_caps == 6 * (len(radii) // 3)
    points = 700
    whole = covered_volumes(x, radii, *box, slabs, keys=keys, points=points)
    first = particle % 2 == 0
    halves = sum(covered_volumes(x[m], radii[m], *box, slabs, keys=keys[m], points=points) for m in (first, ~first))
    np.testing.assert_allclose(halves, whole, rtol=1e-13)
    shuffle = rng.permutation(len(radii))
    np.testing.assert_allclose(covered_volumes(x[shuffle], radii[shuffle], *box, slabs, keys=keys[shuffle],
                                               points=points), whole, rtol=1e-13)
    unkeyed = covered_volumes(x, radii, *box, slabs, points=points)
    assert np.max(np.abs(covered_volumes(x[shuffle], radii[shuffle], *box, slabs, points=points) - unkeyed)) > 1e-9
