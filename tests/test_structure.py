"""Structure statistics on configurations whose answers are known analytically."""

import numpy as np
import pytest

from parsim.core.sdbd.rotation import quat_to_matrix
from parsim.core.shapes.simple import cube, rod, sphere, spiky
from parsim.core.structure import (angle_distribution, contact_number_distribution, contact_pairs,
                                   contacts_per_particle, coordination, fabric_anisotropy, fabric_tensor, lab_axes, long_axis,
                                   nematic_order, radial_distribution, rotation_matrices, vertical_order)

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
