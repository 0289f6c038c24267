"""Structure statistics on configurations whose answers are known analytically."""

import numpy as np
import pytest

from parsim.core.sdbd.rotation import quat_to_matrix
from parsim.core.shapes.simple import cube, rod, sphere, spiky
from parsim.core.sediment import CONTACT_GAP_TOLERANCE
from parsim.core.structure import (angle_distribution, contact_network, contact_number_distribution, contact_pairs,
                                   contacts_per_particle, coordination, fabric_anisotropy, fabric_tensor, lab_axes, long_axis,
                                   nematic_order, radial_distribution, rotation_matrices, shell_counts, vertical_order)

# Simple cubic lattice of touching spheres: spacing a = 1, n x n sites per layer in a box of side n.
SIDE, LAYERS, RADIUS = 6, 8, 0.5


def simple_cubic():
    i, j, k = np.meshgrid(np.arange(SIDE), np.arange(SIDE), np.arange(LAYERS), indexing="ij")
    return np.column_stack([i.ravel(), j.ravel(), k.ravel()]) + 0.5


def uniform_quaternions(n, seed):
    """Uniform random rotations: normalised 4D standard normals (Shoemake, Graphics Gems III, 1992)."""
    q = np.random.default_rng(seed).standard_normal((n, 4))
    return q / np.linalg.norm(q, axis=1)[:, None]


@pytest.mark.parametrize("periodic", [True, False])
def test_simple_cubic_shells_hold_6_12_8_neighbours(periodic):
    x = simple_cubic()
    r_max, bins = 1.9, 100  # below the fourth shell at 2a; shells at 1, √2, √3 fall inside bins
    r, g, n_ref = radial_distribution(x, (0, 0), (SIDE, SIDE), periodic, 0.0, LAYERS, r_max, bins)
    # references: layers 1.9 <= z < 6.1, and without periodic sides 1.9 <= x, y <= 4.1
    assert n_ref == (SIDE**2 if periodic else 2 * 2) * 4
    edges = np.linspace(0.0, r_max, bins + 1)
    shell_counts = g * 1.0 * 4.0 / 3.0 * np.pi * (edges[1:] ** 3 - edges[:-1] ** 3)  # ∫ 4πr² ρ g dr, ρ = 1/a³
    peaks = np.searchsorted(edges, [1.0, np.sqrt(2.0), np.sqrt(3.0)]) - 1
    np.testing.assert_allclose(shell_counts[peaks], [6, 12, 8], rtol=1e-12)
    assert np.count_nonzero(g) == 3 and np.all(g[r < 1.0 - 0.5 * r_max / bins] == 0.0)


def test_poisson_points_have_g_one():
    n, side, height = 20_000, 20.0, 50.0  # density 1
    x = np.random.default_rng(7).uniform([0, 0, 0], [side, side, height], size=(n, 3))
    r_max, bins = 3.0, 15
    r, g, n_ref = radial_distribution(x, (0, 0), (side, side), True, 0.0, height, r_max, bins)
    assert n_ref == np.count_nonzero((x[:, 2] >= r_max) & (x[:, 2] < height - r_max))
    edges = np.linspace(0.0, r_max, bins + 1)
    expected_pairs = n_ref * (n / side**2 / height) * 4.0 / 3.0 * np.pi * (edges[1:] ** 3 - edges[:-1] ** 3)
    # Shell counts are near Poisson; a pair of two references is counted twice, so the variance is at
    # most 2 x the mean: sd(g) <= sqrt(2 / expected). Five sd on 15 bins fail with probability < 1e-5.
    assert np.all(np.abs(g - 1.0) < 5.0 * np.sqrt(2.0 / expected_pairs))


def test_simple_cubic_contacts_normals_and_fabric():
    x = simple_cubic()
    own = np.arange(len(x))
    pairs, normals = contact_pairs(x, np.full(len(x), RADIUS), own, (0, 0), (SIDE, SIDE), True)
    assert len(pairs) == SIDE**2 * (3 * LAYERS - 1) and np.all(pairs[:, 0] < pairs[:, 1])
    np.testing.assert_allclose(np.abs(normals).sum(axis=1), 1.0)  # along the lattice axes
    z = contacts_per_particle(pairs, own, len(x))
    bulk = (x[:, 2] > 1.0) & (x[:, 2] < LAYERS - 1.0)
    assert np.all(z[bulk] == 6) and np.all(z[~bulk] == 5)  # the floor and top layers miss one neighbour
    mean, _ = coordination(x, np.full(len(x), RADIUS), own, x[:, 2], (0, 0), (SIDE, SIDE), 1.0, LAYERS - 1.0)
    assert mean == z[bulk].mean()
    np.testing.assert_array_equal(contact_number_distribution(z, bulk, 8), [0, 0, 0, 0, 0, 0, 1, 0, 0])
    # each bulk particle's contacts, once per particle: ±x, ±y, ±z
    bulk_normals = np.concatenate([normals[bulk[pairs[:, 0]]], normals[bulk[pairs[:, 1]]]])
    fabric = fabric_tensor(bulk_normals)
    np.testing.assert_allclose(fabric, np.eye(3) / 3, atol=1e-12)
    assert fabric_anisotropy(fabric) == pytest.approx(0.0, abs=1e-12)


def test_two_sphere_contacts_between_two_particles_count_once():
    x = simple_cubic()
    i, j, k = np.round(x - 0.5).astype(np.int64).T
    dimer = ((i // 2) * SIDE + j) * LAYERS + k  # neighbours along x glued into dimers
    pairs, _ = contact_pairs(x, np.full(len(x), RADIUS), dimer, (0, 0), (SIDE, SIDE), True)
    z = contacts_per_particle(pairs, dimer, dimer.max() + 1)
    bulk = np.unique(dimer[(k > 0) & (k < LAYERS - 1)])
    assert np.all(z[bulk] == 6)  # 10 sphere contacts with 6 distinct dimers
    com_z = np.bincount(dimer, weights=x[:, 2]) / 2
    mean, _ = coordination(x, np.full(len(x), RADIUS), dimer, com_z, (0, 0), (SIDE, SIDE), 1.0, LAYERS - 1.0)
    assert mean == 10.0


def test_contact_across_the_periodic_side_has_the_minimum_image_normal():
    x = np.array([[0.2, 5.0, 1.0], [8.2, 5.0, 1.0], [5.0, 5.0, 1.0], [5.0, 7.0, 1.0]])
    radii = np.ones(4)
    pairs, normals = contact_pairs(x, radii, [0, 1, 2, 2], (0, 0), (10, 10), True)
    np.testing.assert_array_equal(pairs, [[0, 1]])  # spheres 2 and 3 touch but are one particle
    np.testing.assert_allclose(normals, [[-1.0, 0.0, 0.0]], atol=1e-15)
    pairs, _ = contact_pairs(x, radii, [0, 1, 2, 2], (0, 0), (10, 10), False)
    assert len(pairs) == 0
    np.testing.assert_array_equal(contacts_per_particle(pairs, [0, 1, 2, 2], 3), [0, 0, 0])


def test_heap_in_its_own_extent_does_not_wrap():
    x = np.column_stack([2.0 * np.arange(4), np.zeros(4), np.ones(4)])  # a chain, ends 6 apart
    pairs, normals = contact_pairs(x, np.ones(4), np.arange(4), (0, 0), (6, 0.5), False)
    np.testing.assert_array_equal(pairs, [[0, 1], [1, 2], [2, 3]])
    np.testing.assert_allclose(normals, np.tile([1.0, 0.0, 0.0], (3, 1)))


def test_gaps_beyond_the_tolerance_are_no_contacts():
    x = np.array([[0.0, 0.0, 1.0], [2.0 + 1e-8, 0.0, 1.0], [0.0, 2.0 + 1e-4, 1.0]])
    pairs, _ = contact_pairs(x, np.ones(3), np.arange(3), (-5, -5), (5, 5), True)
    np.testing.assert_array_equal(pairs, [[0, 1]])


def test_fabric_of_parallel_and_planar_normals():
    vertical = fabric_tensor([[0.0, 0.0, 2.0], [0.0, 0.0, -1.0]])  # normalised, sign-blind
    np.testing.assert_allclose(vertical, np.diag([0.0, 0.0, 1.0]))
    assert fabric_anisotropy(vertical) == pytest.approx(2.0 / 3.0)
    phi = np.linspace(0.0, 2.0 * np.pi, 12, endpoint=False)
    planar = fabric_tensor(np.column_stack([np.cos(phi), np.sin(phi), np.zeros(12)]))
    np.testing.assert_allclose(planar, np.diag([0.5, 0.5, 0.0]), atol=1e-15)
    assert fabric_anisotropy(planar) == pytest.approx(1.0 / 6.0)


def test_aligned_axes_are_fully_ordered():
    vertical = np.tile([0.0, 0.0, 1.0], (50, 1))
    vertical[::2] *= -1.0  # axes are unsigned
    s, director = nematic_order(vertical)
    assert s == pytest.approx(1.0, abs=1e-12) and np.allclose(director, [0, 0, 1])
    assert vertical_order(vertical) == pytest.approx(1.0, abs=1e-12)
    edges, density = angle_distribution(vertical, 9)
    assert density[0] == pytest.approx(1.0 / (edges[1] - edges[0])) and np.all(density[1:] == 0.0)
    horizontal = np.tile([1.0, 0.0, 0.0], (50, 1))
    s, director = nematic_order(horizontal)
    assert s == pytest.approx(1.0, abs=1e-12) and np.allclose(director, [1, 0, 0])
    assert vertical_order(horizontal) == pytest.approx(-0.5, abs=1e-12)


def test_random_axes_are_isotropic():
    n = 20_000
    axes = lab_axes(uniform_quaternions(n, seed=3), [0.0, 0.0, 1.0])
    np.testing.assert_allclose(np.linalg.norm(axes, axis=1), 1.0)
    # E ||Q||_F² = 3/(2n) and a traceless Q has λ_max² <= 2/3 ||Q||_F², so E λ_max² <= 1/n:
    # by Markov's inequality S > 4/sqrt(n) has probability <= 1/16 (far less in fact).
    assert nematic_order(axes)[0] < 4.0 / np.sqrt(n)
    assert abs(vertical_order(axes)) < 5.0 * np.sqrt(0.2 / n)  # Var P2(cos θ) = 1/5
    bins = 18
    edges, density = angle_distribution(axes, bins)
    observed = density * np.diff(edges) * n
    expected = n * (np.cos(edges[:-1]) - np.cos(edges[1:]))  # ∫ sin θ dθ over each bin
    chi_square = np.sum((observed - expected) ** 2 / expected)
    assert chi_square < 60.0  # 17 degrees of freedom: exceeded with probability 1e-6


def test_rod_long_axis_along_any_direction():
    offsets, radii = rod(5)  # along x
    body_axis, anisotropy = long_axis(offsets, radii)
    np.testing.assert_allclose(body_axis, [1.0, 0.0, 0.0], atol=1e-12)
    assert 0.5 < anisotropy < 1.0
    q = uniform_quaternions(1, seed=11)
    rotation = rotation_matrices(q)[0]
    direction, rotated_anisotropy = long_axis(offsets @ rotation.T + [3.0, -2.0, 1.0], radii)  # any origin
    assert abs(direction @ rotation[:, 0]) == pytest.approx(1.0, abs=1e-12)
    assert abs(direction @ lab_axes(q, body_axis)[0]) == pytest.approx(1.0, abs=1e-12)
    assert rotated_anisotropy == pytest.approx(anisotropy, rel=1e-12)


@pytest.mark.parametrize("template", [sphere(), cube(3), spiky(3), spiky(4)], ids=["sphere", "cube", "spiky3",
                                                                                   "spiky4"])
def test_symmetric_particles_have_no_long_axis(template):
    axis, anisotropy = long_axis(*template)
    assert np.all(np.isnan(axis)) and abs(anisotropy) <= 1e-6


def test_rotation_matrices_turn_body_into_lab_vectors():
    half = np.sqrt(0.5)
    about_x = np.array([[half, half, 0.0, 0.0]])  # 90° about x: z → −y
    np.testing.assert_allclose(lab_axes(about_x, [0, 0, 1]), [[0.0, -1.0, 0.0]], atol=1e-15)
    q = uniform_quaternions(5, seed=5)
    matrices = rotation_matrices(q)
    for quaternion, matrix in zip(q, matrices):
        expected = np.empty((3, 3))
        quat_to_matrix(quaternion, expected)
        np.testing.assert_allclose(matrix, expected, atol=1e-15)
    np.testing.assert_allclose(matrices @ matrices.transpose(0, 2, 1), np.broadcast_to(np.eye(3), (5, 3, 3)),
                               atol=1e-14)


def every_contact(x, radii, particle, width, periodic):
    """The contacts of contact_pairs found by checking every pair of spheres: (pairs, normals)."""
    tolerance = CONTACT_GAP_TOLERANCE * radii.mean()
    pairs, normals = [], []
    for i in range(len(x)):
        for j in range(i + 1, len(x)):
            d = x[j] - x[i]
            if periodic:
                d[:2] -= width * np.floor(d[:2] / width + 0.5)
            distance = np.sqrt(d @ d)
            if particle[i] != particle[j] and distance - radii[i] - radii[j] < tolerance:
                pairs.append((i, j))
                normals.append(d / distance)
    return np.array(pairs, dtype=np.int64).reshape(-1, 2), np.array(normals).reshape(-1, 3)


@pytest.mark.parametrize("cells, periodic", [(2, True), (3, True), (4, False)])
def test_contacts_are_those_of_every_pair_checked_directly(cells, periodic):
    """An FCC packing of touching spheres, shuffled, some spheres shrunk so that their contacts open and some
    neighbours glued into one particle: the contacts, their order and normals are those of the direct check
    of every pair, also in a box only two lattice cells wide."""
    rng = np.random.default_rng(5)
    radius = 0.5
    a = 2.0 * np.sqrt(2.0) * radius
    basis = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]])
    i, j, k = np.meshgrid(np.arange(cells), np.arange(cells), np.arange(4), indexing="ij")
    x = (a * (np.column_stack([i.ravel(), j.ravel(), k.ravel()])[:, None, :] + basis).reshape(-1, 3)
         + [0.1, 0.2, radius])
    x = x[rng.permutation(len(x))]
    radii = np.where(rng.random(len(x)) < 0.2, radius - 1e-4, radius)
    particle = np.arange(len(x))
    particle[1::7] = particle[0::7][:len(particle[1::7])]  # some spheres share a particle with another
    width = np.full(2, a * cells)
    pairs, normals = contact_pairs(x, radii, particle, (0, 0), tuple(width), periodic)
    expected_pairs, expected_normals = every_contact(x, radii, particle, width, periodic)
    assert len(pairs) > 2 * len(x)
    np.testing.assert_array_equal(pairs, expected_pairs)
    np.testing.assert_allclose(normals, expected_normals, rtol=0, atol=1e-14)


def test_spheres_that_overlap_are_flagged_whichever_particle_they_belong_to():
    """Rods of overlapping spheres, two spheres of different particles overlapping by 1e-3 of a radius, two
    overlapping across the box's side (flagged although the contacts are not periodic), two touching to
    round-off and lone spheres: exactly the overlapping spheres are flagged."""
    offsets, rod_radii = rod(3)  # spheres 1 radius apart
    rods = np.concatenate([[2.0, 2.0, 1.0] + offsets, [2.0, 6.0, 1.0] + offsets])
    x = np.concatenate([rods, [[7.0, 2.0, 1.0], [7.999, 2.0, 1.0],  # overlapping by 1e-3
                               [0.3, 8.0, 1.0], [9.5, 8.0, 1.0],  # 0.8 apart across the side x = 0 = 10
                               [5.0, 9.0, 3.0], [6.0, 9.0, 3.0],  # touching
                               [5.0, 5.0, 6.0], [2.0, 8.0, 6.0]]])
    radii = np.concatenate([rod_radii, rod_radii, np.full(8, 0.5)])
    particle = np.concatenate([[0, 0, 0, 1, 1, 1], np.arange(2, 10)])
    network = contact_network(x, radii, particle, (0, 0), (10, 10), False)
    np.testing.assert_array_equal(network.overlapping, [True] * 6 + [True, True, True, True] + [False] * 4)
    np.testing.assert_array_equal(network.pairs, [[6, 7], [10, 11]])  # the side is no contact without periodic sides


@pytest.mark.parametrize("side, periodic", [(6.0, True), (13.0, True), (13.0, False)])
def test_shell_counts_are_those_of_every_pair_counted_directly(side, periodic):
    """Random points: g(r) holds the distances from each reference to every other centre, also when r_max is
    half the periodic box's width (fewer columns of cells fit across it than a reference scans)."""
    height, r_max, bins = 12.0, 3.0, 12
    x = np.random.default_rng(2).uniform([0, 0, 0], [side, side, height], size=(int(0.8 * side**2 * height), 3))
    r, g, n_ref = radial_distribution(x, (0, 0), (side, side), periodic, 0.0, height, r_max, bins)
    reference = (x[:, 2] >= r_max) & (x[:, 2] < height - r_max)
    if not periodic:
        reference &= np.all((x[:, :2] >= r_max) & (x[:, :2] <= side - r_max), axis=1)
    counts = np.zeros(bins)
    for i in np.flatnonzero(reference):
        d = np.delete(x, i, axis=0) - x[i]
        if periodic:
            d[:, :2] -= side * np.floor(d[:, :2] / side + 0.5)
        distance = np.sqrt(np.sum(d * d, axis=1))
        counts += np.bincount(np.minimum((distance[distance < r_max] / r_max * bins).astype(int), bins - 1),
                              minlength=bins)
    edges = np.linspace(0.0, r_max, bins + 1)
    shell = 4.0 / 3.0 * np.pi * (edges[1:] ** 3 - edges[:-1] ** 3)
    assert n_ref == np.count_nonzero(reference) > 0
    np.testing.assert_allclose(g * n_ref * len(x) / (side**2 * height) * shell, counts, rtol=1e-12)


def test_shell_counts_in_a_window_of_the_periodic_box_are_the_whole_box_counts_to_the_bit():
    """Rows of touching spheres (centres exactly 1 apart along x, each row at a random offset) across a periodic
    box; shells 0.05 wide, so that the contact distance is a shell's edge. The counts about the references of
    one half of the box, counted in a window narrower than the box (the centres across its side outside it
    by one period, as a rank holds them), are the whole box's: every distance x_j - x_i, then its minimum
    image over the period, as in the whole box. Moving those centres by the period first changes them."""
    side, r_max, bins = 16, 1.5, 30
    offset = np.random.default_rng(4).random((side, side))
    i, j, k = np.meshgrid(np.arange(side, dtype=float), np.arange(side), np.arange(side), indexing="ij")
    x = np.column_stack([offset[j.ravel(), k.ravel()] + i.ravel(), j.ravel() + 0.5, k.ravel() + 0.5])
    reference = np.flatnonzero((x[:, 0] < 0.5 * side) & (x[:, 2] > r_max) & (x[:, 2] < side - r_max))
    whole = shell_counts(x, reference, r_max, bins, (0, 0), (side, side), True)
    lower, upper = np.array([-3.5, 0.0]), np.array([side / 2 + 3.5, side])  # 15 of the box's 16 in x
    near = (x[:, 0] < upper[0]) | (x[:, 0] >= side + lower[0])
    window = np.flatnonzero(near)
    inside = np.searchsorted(window, reference)
    counts = shell_counts(x[window], inside, r_max, bins, lower, upper, True, period=(side, side))
    np.testing.assert_array_equal(counts, whole)
    assert whole[19] > 0 and whole[20] > 0  # the contacts, split by round-off about 1 diameter
    moved = x[window].copy()
    moved[moved[:, 0] >= upper[0], 0] -= side
    assert not np.array_equal(shell_counts(moved, inside, r_max, bins, lower, upper, True, period=(side, side)),
                              whole)
