"""Shape statistics of section 4.2 of Degond et al. (2024) on configurations with known answers."""

import numpy as np
import pytest

from parsim.core.statistics import (
    DEFAULT_N_MAX,
    aspect_ratio_and_orientation,
    box_counts,
    cluster_statistics,
    contact_pairs,
    fit_box_sizes,
    fractal_dimension,
    gyration_tensor,
    mass_radius_of_gyration,
    pair_distribution,
    pair_distribution_grid,
    radius_of_gyration,
    relative_contact_number,
)

# Results that are exact identities in real arithmetic are checked to this relative
# tolerance: a few hundred ulp of accumulated rounding in sums over <= 10^4 terms.
EXACT_RTOL = 1e-10


# --------------------------------------------------------------- configurations


def line_of_discs(n, radius, direction, start=(0.0, 0.0)):
    """n touching discs (spacing 2R) from ``start`` along the unit vector ``direction``."""
    return np.asarray(start) + 2.0 * radius * np.arange(n)[:, None] * np.asarray(direction)


def square_lattice(n, radius, d=2):
    """n^d spheres at zero interparticle distance (spacing 2R), centres at 2R (i + 1/2)."""
    axis = 2.0 * radius * (np.arange(n) + 0.5)
    return np.stack(np.meshgrid(*([axis] * d), indexing="ij"), axis=-1).reshape(-1, d)


def hexagonal_patch(p, q, radius):
    """Rhombic p x q patch of the triangular lattice, i a1 + j a2, a1 = (2R, 0), a2 = (R, sqrt3 R)."""
    i, j = np.meshgrid(np.arange(p), np.arange(q), indexing="ij")
    return radius * np.column_stack([2.0 * i.ravel() + j.ravel(), np.sqrt(3.0) * j.ravel()])


def three_lines(n_per_line, radius, box_length):
    """Fig. 9, left: three adjacent horizontal lines of touching discs through the box middle."""
    x = 2.0 * radius * (np.arange(n_per_line) + 0.5)
    rows = [np.column_stack([x, np.full_like(x, box_length / 2 + k * 2.0 * radius)]) for k in (-1, 0, 1)]
    return np.concatenate(rows)


def sierpinski_triangle(levels, radius):
    """Fig. 9, right: vertices of a Sierpinski triangle subdivided ``levels`` times down to
    equilateral triangles of side 2R; base on y = 0 from x = 0 to x = 2R 2^levels."""
    origins = np.zeros((1, 2), dtype=np.int64)  # lattice coordinates (i, j) of sub-triangles
    size = 2**levels
    while size > 1:
        size //= 2
        origins = np.concatenate([origins, origins + (size, 0), origins + (0, size)])
    ij = np.unique(np.concatenate([origins, origins + (1, 0), origins + (0, 1)]), axis=0)
    return 2.0 * radius * np.column_stack([ij[:, 0] + 0.5 * ij[:, 1], 0.5 * np.sqrt(3.0) * ij[:, 1]])


def brute_force_pair_distribution(x, r_values):
    distance = np.sqrt(((x[:, None, :] - x[None, :, :]) ** 2).sum(axis=-1))
    return np.array([(distance <= r).sum() for r in r_values]) / len(x)  # i = j included, as eq. 4.7


def brute_force_box_counts(x, lower, box_length, levels):
    counts = []
    for m in range(1, levels + 1):
        index = np.floor((x - lower) / (box_length / 2**m))
        index = np.clip(index, 0, 2**m - 1).astype(np.int64)
        counts.append(len(set(map(tuple, index))))
    return np.array(counts, dtype=np.float64)


# ------------------------------------------------------- aspect ratio, orientation


@pytest.mark.parametrize("angle_deg", [30.0, 210.0])
def test_line_of_discs_2d_is_infinitely_elongated_along_its_direction(angle_deg):
    direction = np.array([np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))])
    aspect_ratio, orientation = aspect_ratio_and_orientation(
        line_of_discs(25, 0.5, direction, start=(3.0, -7.0)))
    assert aspect_ratio == np.inf
    # Sign rule: the largest component (cos 30 deg) is positive, for both senses of the line.
    expected = np.array([np.cos(np.radians(30.0)), np.sin(np.radians(30.0))])
    np.testing.assert_allclose(orientation, expected, atol=1e-12)


def test_line_of_spheres_3d_orientation_uses_first_of_tied_components():
    direction = np.array([1.0, -2.0, 2.0]) / 3.0  # |y| = |z|: the first of them (y) is made positive
    aspect_ratio, orientation = aspect_ratio_and_orientation(line_of_discs(12, 1.0, direction, start=(1.0, 2.0, 3.0)))
    assert aspect_ratio == np.inf
    np.testing.assert_allclose(orientation, -direction, atol=1e-12)


def test_ellipse_aspect_ratio_is_squared_axis_ratio():
    # Points a cos t e1 + b sin t e2 at equally spaced t: sum cos^2 = sum sin^2 = m/2 and
    # sum cos sin = 0 exactly, so G has eigenvalues a^2/2, b^2/2: A_r = (a/b)^2 up to rounding.
    a, b, angle = 5.0, 2.0, np.radians(120.0)
    t = 2.0 * np.pi * np.arange(64) / 64
    e1 = np.array([np.cos(angle), np.sin(angle)])
    e2 = np.array([-np.sin(angle), np.cos(angle)])
    points = np.array([10.0, -4.0]) + np.outer(a * np.cos(t), e1) + np.outer(b * np.sin(t), e2)
    aspect_ratio, orientation = aspect_ratio_and_orientation(points)
    assert aspect_ratio == pytest.approx((a / b) ** 2, rel=EXACT_RTOL)
    np.testing.assert_allclose(orientation, e1 if e1[np.argmax(np.abs(e1))] > 0 else -e1, atol=1e-10)


def test_ellipsoid_aspect_ratio_is_largest_over_second_largest():
    # +-a e1, +-b e2, +-c e3 of a rotated frame: G = diag(a^2, b^2, c^2) / 3 in that frame.
    a, b, c = 4.0, 2.0, 1.0
    frame, _ = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))
    axes = frame.T * np.array([[a], [b], [c]])
    aspect_ratio, orientation = aspect_ratio_and_orientation(np.concatenate([axes, -axes]))
    assert aspect_ratio == pytest.approx((a / b) ** 2, rel=EXACT_RTOL)
    assert abs(abs(orientation @ frame[:, 0]) - 1.0) < 1e-10


def test_orientation_needs_two_distinct_spheres():
    with pytest.raises(ValueError, match="at least two spheres"):
        aspect_ratio_and_orientation(np.zeros((1, 2)))
    with pytest.raises(ValueError, match="coincide"):
        aspect_ratio_and_orientation(np.ones((3, 3)))


def test_ring_has_radius_of_gyration_equal_to_its_radius():
    rho = 3.7
    t = 2.0 * np.pi * np.arange(50) / 50
    ring = np.column_stack([1.0 + rho * np.cos(t), -2.0 + rho * np.sin(t)])
    assert radius_of_gyration(ring) == pytest.approx(rho, rel=EXACT_RTOL)
    np.testing.assert_allclose(gyration_tensor(ring), 0.5 * rho**2 * np.eye(2), atol=1e-12)


# ------------------------------------------------------------------ contact number


def test_square_lattice_contacts():
    n, radius = 7, 0.8  # 2 directions x n(n-1) bonds, each counted for both spheres, plus i = j
    expected = (n * n + 2 * 2 * n * (n - 1)) / (n * n * 6)
    assert relative_contact_number(square_lattice(n, radius), radius) == pytest.approx(expected, rel=1e-14)


def test_hexagonal_patch_contacts():
    p, q, radius = 6, 5, 1.3  # bonds along a1, a2 and a2 - a1
    bonds = (p - 1) * q + p * (q - 1) + (p - 1) * (q - 1)
    expected = (p * q + 2 * bonds) / (p * q * 6)
    assert relative_contact_number(hexagonal_patch(p, q, radius), radius) == pytest.approx(expected, rel=1e-14)


def test_cubic_lattice_contacts_use_n_max_12_in_3d():
    n, radius = 4, 1.0
    expected = (n**3 + 2 * 3 * n * n * (n - 1)) / (n**3 * 12)
    assert relative_contact_number(square_lattice(n, radius, d=3), radius) == pytest.approx(expected, rel=1e-14)


def test_chain_contacts_and_contact_factor():
    n, radius = 10, 1.0
    chain = line_of_discs(n, radius, (1.0, 0.0))
    expected = (n + 2 * (n - 1)) / (n * 6)  # tends to (1 + 2)/6 = 0.5, the paper's value for trees
    assert relative_contact_number(chain, radius) == pytest.approx(expected, rel=1e-14)
    # alpha_R = 2.1 tolerates the small gaps left by the minimiser, not larger ones.
    gapped = chain * 1.04
    assert relative_contact_number(gapped, radius) == pytest.approx(expected, rel=1e-14)
    assert relative_contact_number(chain * 1.1, radius) == pytest.approx(1 / 6, rel=1e-14)  # isolated: the self pair


# --------------------------------------------------------------- pair distribution


@pytest.mark.parametrize("d", [2, 3])
def test_pair_distribution_matches_brute_force(d):
    rng = np.random.default_rng(d)
    x = rng.random((400, d)) * 10.0
    r_values = np.array([0.0, 0.3, 0.7, 1.0, 1.0, 2.5, 4.0, 20.0])
    np.testing.assert_allclose(pair_distribution(x, r_values), brute_force_pair_distribution(x, r_values))
    assert pair_distribution(x, [20.0])[0] == len(x)  # every sphere within reach, itself included


def test_pair_counts_equal_a_count_of_every_pair_on_random_configurations():
    """300 random configurations: uniform, on a coarse lattice (many distances exactly on a grid value), and
    random walks; 1 to 300 spheres over 10^-3 to 10^3; random r grids (negative values and repeats
    included) and the paper's.  Every count of eqs. 4.6 and 4.7 is the count of d^2 <= r^2 over all
    ordered pairs, exactly."""
    rng = np.random.default_rng(2026)
    for case in range(300):
        d, n, scale = int(rng.integers(2, 4)), int(rng.integers(1, 301)), 10 ** rng.uniform(-3, 3)
        x = [rng.uniform(0, scale, (n, d)), np.round(rng.uniform(0, 12, (n, d))) * scale / 12,
             np.cumsum(rng.normal(0, scale / 50, (n, d)), axis=0)][case % 3]
        radius = scale / 20 * rng.uniform(0.5, 2)
        r = np.sort(rng.uniform(-radius, 25 * radius, int(rng.integers(1, 80))))
        r = pair_distribution_grid(radius, int(rng.integers(1, 100))) if case % 4 == 0 else np.repeat(r, 1 + case % 2)
        squared = ((x[:, None, :] - x[None, :, :]) ** 2).sum(axis=-1)
        pairs = np.array([(squared <= v * v).sum() if v >= 0 else 0 for v in r])
        np.testing.assert_array_equal(pair_distribution(x, r), pairs / n, err_msg=f"case {case}")
        contact = 2.1 * radius
        contacts = (squared <= contact * contact).sum()
        assert relative_contact_number(x, radius) == contacts / (n * DEFAULT_N_MAX[d]), f"case {case}"
        if n >= 2:
            stats = cluster_statistics(x, np.full(n, radius), x.min(0), x.min(0) + 64 * radius + np.ptp(x),
                                       r_values=r, box_levels=3)
            assert stats["contact_number"] == relative_contact_number(x, radius)
            np.testing.assert_array_equal(stats["pair_distribution"], pair_distribution(x, r))


def test_pair_distribution_of_far_apart_clusters():
    # Two clusters 10^6 apart: the cell list is coarsened instead of allocating 10^12 cells.
    rng = np.random.default_rng(7)
    x = np.concatenate([rng.random((150, 2)), 1e6 + rng.random((150, 2))])
    r_values = np.array([0.1, 0.5, 1.5])
    np.testing.assert_allclose(pair_distribution(x, r_values), brute_force_pair_distribution(x, r_values))


def test_pair_distribution_grid_follows_paper():
    radius = 1.5
    r = pair_distribution_grid(radius)
    assert r.shape == (72,)
    assert r[0] == pytest.approx(2.25 * radius) and r[-1] == 20.0 * radius
    np.testing.assert_allclose(np.diff(r), radius / 4)


# -------------------------------------------------------------------- box counting


@pytest.mark.parametrize("d, levels", [(2, 12), (3, 20)])
def test_box_counts_match_brute_force(d, levels):
    rng = np.random.default_rng(11 + d)
    lower, box_length = np.full(d, -3.0), 8.0
    x = lower + box_length * rng.random((300, d)) ** 3  # crowded near the lower corner: all levels differ
    x[0] = lower + box_length  # corner on the upper faces
    x[1, 0] = lower[0] + box_length  # one coordinate on an upper face
    x[2] = lower  # lower corner
    eps, counts = box_counts(x, lower, box_length, levels)
    np.testing.assert_array_equal(eps, box_length / 2.0 ** np.arange(1, levels + 1))
    np.testing.assert_array_equal(counts, brute_force_box_counts(x, lower, box_length, levels))


def test_centre_on_upper_face_counts_in_last_cell():
    lower, box_length, levels = np.zeros(3), 1.0, 20
    x = np.array([[1.0, 1.0, 1.0], [1.0 - 2.0**-21] * 3])  # face and middle of the last finest cell
    _, counts = box_counts(x, lower, box_length, levels)
    np.testing.assert_array_equal(counts, np.ones(levels))


# ---------------------------------------------------- fractal dimension (Fig. 9)

FIG9_BOX = 120.0  # Fig. 9: N = 900 discs in a box of side L = 120, eps = L/2^k, k = 1..10


def fit_over_paper_range(x, radius, box_length=FIG9_BOX, levels=10):
    eps, counts = box_counts(x, np.zeros(2), box_length, levels)
    return fractal_dimension(eps, counts, 3.0 * radius, box_length / 2.0)


def test_three_lines_have_dimension_one():
    # 3 x 300 touching discs, R = 0.2 spans the box. Over 3R <= eps <= L/2 every column
    # of cells is occupied and the lines at y = L/2 - 2R, L/2, L/2 + 2R fill exactly two
    # rows of cells, so N = 2 L / eps: D_f = 1 and a = 2L exactly.
    radius = 0.2
    d_f, prefactor = fit_over_paper_range(three_lines(300, radius, FIG9_BOX), radius)
    assert d_f == pytest.approx(1.0, abs=1e-9)
    assert prefactor == pytest.approx(2.0 * FIG9_BOX, rel=1e-9)


def test_square_lattice_has_dimension_two():
    # 30 x 30 touching discs with R = 2 fill the box; every cell of side eps >= 3R holds a
    # centre, so N = (L/eps)^2: D_f = 2 and a = L^2 exactly.
    radius = 2.0
    d_f, prefactor = fit_over_paper_range(square_lattice(30, radius), radius)
    assert d_f == pytest.approx(2.0, abs=1e-9)
    assert prefactor == pytest.approx(FIG9_BOX**2, rel=1e-9)


def test_sierpinski_triangle_has_dimension_log3_over_log2():
    # 7 subdivisions, 3282 discs, box side = triangle side = 256 R (the right vertex lies on
    # the upper face). The square cells are not aligned with the triangular sub-triangles, so
    # N(eps) is 3^m times a factor that drifts (4/3 ... 1.42) over the fitted decades; this
    # gives D_f = 1.607, 0.022 above log 3/log 2. The tolerance 0.1 is well above that
    # drift and still far from the line (1) and the plane (2).
    levels, radius = 7, 1.0
    x = sierpinski_triangle(levels, radius)
    assert len(x) == 3 * (3**levels + 1) // 2
    d_f, _ = fit_over_paper_range(x, radius, box_length=2.0 * radius * 2**levels, levels=levels + 2)
    assert abs(d_f - np.log(3.0) / np.log(2.0)) < 0.1


def test_fractal_fit_needs_two_box_sizes_in_range():
    eps, counts = box_counts(square_lattice(8, 1.0), np.zeros(2), 16.0, 6)
    with pytest.raises(ValueError, match="fit range"):
        fractal_dimension(eps, counts, 5.0, 7.9)  # only eps = 8 would qualify, and it is above


@pytest.mark.parametrize("box_length, expected", [(11.9, 1), (12.0, 2), (12.0 * (1 - 1e-13), 2), (24.0, 3)])
def test_fit_box_sizes_counts_what_cluster_statistics_fits(box_length, expected):
    """3R <= L/2^m <= L/2 with R = 1: L/4 >= 3 from L = 12 on (a rounding of 3R below 1e-12 is forgiven)."""
    assert fit_box_sizes(box_length, 1.0, 12) == expected
    x = square_lattice(4, box_length / 8)  # centres at L/8 (2i + 1), inside the box
    if expected < 2:
        with pytest.raises(ValueError, match="fewer than two box sizes"):
            cluster_statistics(x, np.ones(len(x)), np.zeros(2), np.full(2, box_length), r_values=[3.0], box_levels=12)
    else:
        stats = cluster_statistics(x, np.ones(len(x)), np.zeros(2), np.full(2, box_length), r_values=[3.0],
                                   box_levels=12)
        assert np.isfinite(stats["fractal_dimension"])


# ------------------------------------------------------------------- all together


def test_cluster_statistics_combines_the_indicators():
    rng = np.random.default_rng(5)
    x = sierpinski_triangle(5, 1.0)
    radii = rng.uniform(0.9, 1.1, len(x))
    radius = radii.mean()
    lower, upper = np.array([0.0, 0.0]), np.array([64.0, 60.0])
    r_values = pair_distribution_grid(radius)
    stats = cluster_statistics(x, radii, lower, upper, r_values=r_values, box_levels=8)
    assert set(stats) == {"aspect_ratio", "orientation", "contact_number", "pair_distribution", "box_size",
                          "box_count", "fractal_dimension", "fractal_prefactor", "radius_of_gyration"}
    aspect_ratio, orientation = aspect_ratio_and_orientation(x)
    assert stats["aspect_ratio"] == aspect_ratio
    np.testing.assert_array_equal(stats["orientation"], orientation)
    assert stats["contact_number"] == contact_pairs(x, radii, 2.1) / (len(x) * 6)  # eq. 4.6 pair by pair
    np.testing.assert_array_equal(stats["pair_distribution"], pair_distribution(x, r_values))
    eps, counts = box_counts(x, lower, 64.0, 8)  # L = the longest side
    np.testing.assert_array_equal(stats["box_size"], eps)
    np.testing.assert_array_equal(stats["box_count"], counts)
    assert (stats["fractal_dimension"], stats["fractal_prefactor"]) == fractal_dimension(eps, counts, 3 * radius, 32.0)
    assert stats["radius_of_gyration"] == mass_radius_of_gyration(x, radii, radii**2)  # one density
    equal = cluster_statistics(x, np.full(len(x), radius), lower, upper, r_values=r_values, box_levels=8)
    assert equal["contact_number"] == relative_contact_number(x, radius)
    assert contact_pairs(x, np.full(len(x), radius), 2.1) / (len(x) * 6) == relative_contact_number(x, radius)
