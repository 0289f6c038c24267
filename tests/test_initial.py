"""Tests of the initial conditions (parsim.core.initial)."""

import math

import numpy as np
import pytest

from parsim.core.initial import (
    box_length_for_volume_fraction,
    isotropic_velocities,
    lattice_positions,
    lattice_sites_per_side,
    lattice_spacing,
    uniform_cube_velocities,
)


def min_pair_distance(x):
    diff = x[:, None, :] - x[None, :, :]
    dist = np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))
    return dist[np.triu_indices(len(x), 1)].min()


def test_sites_per_side_is_exact_ceiling():
    assert lattice_sites_per_side(100, 2) == 10
    assert lattice_sites_per_side(101, 2) == 11
    assert lattice_sites_per_side(99, 2) == 10
    assert lattice_sites_per_side(27, 3) == 3  # 27 ** (1/3) is 3.0000000000000004
    assert lattice_sites_per_side(28, 3) == 4
    assert lattice_sites_per_side(64, 3) == 4
    assert lattice_sites_per_side(1, 2) == 1
    assert lattice_sites_per_side(7, 1) == 7


def test_lattice_spacing():
    assert lattice_spacing(100, 2, 10.0) == 1.0
    assert lattice_spacing(101, 2, 11.0) == 1.0
    assert lattice_spacing(27, 3, 6.0) == 2.0
    assert lattice_spacing(30, 3, 8.0) == 2.0


def test_full_lattice_in_lattice_order_at_cell_centres():
    rng = np.random.default_rng(0)
    state = rng.bit_generator.state
    x = lattice_positions(9, 2, 3.0, rng)
    expected = [[0.5, 0.5], [0.5, 1.5], [0.5, 2.5], [1.5, 0.5], [1.5, 1.5],
                [1.5, 2.5], [2.5, 0.5], [2.5, 1.5], [2.5, 2.5]]
    np.testing.assert_allclose(x, expected)
    assert rng.bit_generator.state == state  # n = k^d draws nothing
    x3 = lattice_positions(8, 3, 4.0, rng)
    assert x3.shape == (8, 3) and x3.dtype == np.float64
    np.testing.assert_allclose(np.sort(np.unique(x3)), [1.0, 3.0])


def test_partial_lattice_distinct_sorted_sites_and_reproducible():
    n, d, L = 50, 2, 8.0  # k = 8, 64 sites
    x = lattice_positions(n, d, L, np.random.default_rng(5))
    assert x.shape == (n, d)
    spacing = lattice_spacing(n, d, L)
    idx = x / spacing - 0.5
    np.testing.assert_allclose(idx, np.round(idx), atol=1e-12)
    idx = np.round(idx).astype(int)
    assert idx.min() >= 0 and idx.max() <= 7
    site = idx[:, 0] * 8 + idx[:, 1]
    assert len(np.unique(site)) == n
    assert np.all(np.diff(site) > 0)  # lattice order
    again = lattice_positions(n, d, L, np.random.default_rng(5))
    np.testing.assert_array_equal(x, again)
    other = lattice_positions(n, d, L, np.random.default_rng(6))
    assert not np.array_equal(x, other)


def test_partial_lattice_site_choice_is_uniform():
    counts = np.zeros(9)
    rng = np.random.default_rng(1)
    trials = 3000
    for _ in range(trials):
        x = lattice_positions(5, 2, 3.0, rng)
        site = np.round(x[:, 0] - 0.5) * 3 + np.round(x[:, 1] - 0.5)
        counts[site.astype(int)] += 1
    expected = trials * 5 / 9
    assert np.all(np.abs(counts - expected) < 5 * math.sqrt(expected))


@pytest.mark.parametrize("n", [100, 400, 900])
def test_no_overlap_under_condition_4_2(n):
    # Table 1 with V_f = 0.3, the densest case: L = sqrt(N pi / V_f) R satisfies (4.2).
    R = 0.2
    L = box_length_for_volume_fraction(n, 2, R, 0.3)
    assert L**2 > 4 * R**2 * n
    x = lattice_positions(n, 2, L, np.random.default_rng(0))
    assert min_pair_distance(x) >= 2 * R
    assert np.all(x >= R) and np.all(x <= L - R)


def test_no_overlap_when_spacing_allows_it_for_any_n():
    R, n = 0.25, 37  # k = 7
    L = 2 * R * lattice_sites_per_side(n, 2) * 1.001
    x = lattice_positions(n, 2, L, np.random.default_rng(3))
    assert min_pair_distance(x) >= 2 * R
    assert np.all(x >= R) and np.all(x <= L - R)


def test_box_length_for_volume_fraction_matches_table_1():
    assert box_length_for_volume_fraction(400, 2, 0.2, 0.2) == pytest.approx(math.sqrt(400 * math.pi / 0.2) * 0.2)
    L3 = box_length_for_volume_fraction(1000, 3, 0.5, 0.1)
    assert 1000 * 4 / 3 * math.pi * 0.5**3 / L3**3 == pytest.approx(0.1)


@pytest.mark.parametrize("d", [2, 3])
def test_isotropic_velocities_have_fixed_speed_and_uniform_direction(d):
    rng = np.random.default_rng(42)
    v = isotropic_velocities(20000, d, 1.7, rng)
    assert v.shape == (20000, d)
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), 1.7, rtol=1e-14)
    # Uniform direction: mean of the unit vector ~ 0, second moment ~ I / d.
    u = v / 1.7
    assert np.all(np.abs(u.mean(axis=0)) < 5 / math.sqrt(20000))
    np.testing.assert_allclose(u.T @ u / 20000, np.eye(d) / d, atol=0.02)
    again = isotropic_velocities(20000, d, 1.7, np.random.default_rng(42))
    np.testing.assert_array_equal(v, again)


def test_isotropic_angle_uniform_in_2d():
    v = isotropic_velocities(40000, 2, 1.0, np.random.default_rng(7))
    theta = np.mod(np.arctan2(v[:, 1], v[:, 0]), 2 * np.pi)
    hist, _ = np.histogram(theta, bins=8, range=(0, 2 * np.pi))
    assert np.all(np.abs(hist - 5000) < 5 * math.sqrt(5000))


def test_uniform_cube_velocities():
    rng = np.random.default_rng(3)
    v = uniform_cube_velocities(10000, 2, rng)
    assert v.shape == (10000, 2)
    assert np.all(v >= -0.5) and np.all(v < 0.5)
    assert np.all(np.abs(v.mean(axis=0)) < 5 * math.sqrt(1 / 12 / 10000))
    np.testing.assert_allclose(v.var(axis=0), 1 / 12, rtol=0.05)
    np.testing.assert_array_equal(v, uniform_cube_velocities(10000, 2, np.random.default_rng(3)))


def test_bad_arguments():
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="n"):
        lattice_positions(-1, 2, 1.0, rng)
    with pytest.raises(ValueError, match="dimension"):
        lattice_positions(4, 4, 1.0, rng)
    with pytest.raises(ValueError, match="box_length"):
        lattice_positions(4, 2, 0.0, rng)
    with pytest.raises(ValueError, match="rng"):
        lattice_positions(4, 2, 1.0, 123)
    with pytest.raises(ValueError, match="speed"):
        isotropic_velocities(4, 2, -1.0, rng)
    with pytest.raises(ValueError, match="volume_fraction"):
        box_length_for_volume_fraction(4, 2, 0.2, 1.5)
    assert lattice_positions(0, 2, 1.0, rng).shape == (0, 2)
