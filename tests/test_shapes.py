"""Tests of parsim.core.shapes: sphere counts, the centre of mass of a union of spheres,
ellipsoid/superellipsoid covers, uniform rotations and the helpers."""

import math

import numpy as np
import pytest

from parsim.core import shapes
from parsim.core.shapes import (
    agglomerate,
    bounding_radius,
    centre_of_mass_of_union,
    cube,
    ellipsoid,
    extent_below_com,
    four_rods,
    DrawnRotations,
    random_rotations,
    rod,
    rotate,
    sphere,
    spiky,
    superellipsoid,
    tripod,
)

# Accuracy of centre_of_mass_of_union's column integration at its default resolution for the
# shapes tested with it here (two spheres are exact; clusters measured: below 4e-5 relative volume
# and 8e-5 mean radii against resolution 128).
UNION_VOLUME_RTOL = 3e-4
UNION_COM_ATOL = 4.5e-4  # in mean radii
# Round-off level for results that are exact by symmetry or by construction.
EXACT_ATOL = 1e-12


def lens_union(r1, r2, d):
    """Analytic volume and centre of mass (on the axis, from sphere 1 towards sphere 2)
    of the union of two overlapping spheres at centre distance d.

    The lens is two spherical caps cut by the radical plane x = a,
    a = (d^2 + r1^2 - r2^2) / (2 d): heights h1 = r1 - a and h2 = r2 - (d - a), volume
    pi h^2 (3r - h) / 3, centroid 3 (2r - h)^2 / (4 (3r - h)) from the sphere's centre.
    """
    a = (d * d + r1 * r1 - r2 * r2) / (2.0 * d)
    h1 = r1 - a
    h2 = r2 - (d - a)

    def cap(r, h):
        return math.pi * h * h * (3.0 * r - h) / 3.0

    def centroid(r, h):
        return 3.0 * (2.0 * r - h) ** 2 / (4.0 * (3.0 * r - h))

    v1 = 4.0 / 3.0 * math.pi * r1**3
    v2 = 4.0 / 3.0 * math.pi * r2**3
    c1, c2 = cap(r1, h1), cap(r2, h2)
    volume = v1 + v2 - c1 - c2
    moment = v2 * d - c1 * centroid(r1, h1) - c2 * (d - centroid(r2, h2))
    return volume, moment / volume


def implicit(points, axes, e1=2.0, e2=2.0):
    """(|x/a|^e2 + |y/b|^e2)^(e1/e2) + |z/c|^e1, written independently of the module."""
    a = np.abs(points / np.asarray(axes, dtype=float))
    return (a[..., 0] ** e2 + a[..., 1] ** e2) ** (e1 / e2) + a[..., 2] ** e1


def fibonacci(m):
    i = np.arange(m) + 0.5
    z = 1.0 - 2.0 * i / m
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    rxy = np.sqrt(1.0 - z * z)
    return np.stack([rxy * np.cos(phi), rxy * np.sin(phi), z], axis=1)


def max_outside(centres, radii, axes, e1=2.0, e2=2.0, m=600):
    """Largest radial distance by which any of m points sampled on each sphere surface
    lies outside the body F <= 1 (negative: all inside); the radial distance outside of
    a point p is |p| (1 - F(p)^(-1/e1))."""
    u = fibonacci(m)
    worst = -np.inf
    for c, r in zip(centres, radii):
        p = c + r * u
        F = implicit(p, axes, e1, e2)
        j = np.argmax(F)
        worst = max(worst, np.linalg.norm(p[j]) * (1.0 - F[j] ** (-1.0 / e1)))
    return worst


def superellipsoid_volume(axes, e1, e2):
    """Barr's volume 2abc eps1 eps2 B(eps1/2 + 1, eps1) B(eps2/2, eps2/2), eps = 2/e."""
    eps1, eps2 = 2.0 / e1, 2.0 / e2

    def beta(x, y):
        return math.gamma(x) * math.gamma(y) / math.gamma(x + y)

    return 2.0 * np.prod(axes) * eps1 * eps2 * beta(eps1 / 2.0 + 1.0, eps1) * beta(eps2 / 2.0, eps2 / 2.0)


# ----------------------------------------------------------------------------------------
# sphere counts and geometry of the simple shapes


@pytest.mark.parametrize("L", range(1, 8))
def test_spiky_has_3L_minus_2_spheres(L):
    offsets, radii = spiky(L)
    assert offsets.shape == (3 * L - 2, 3) and radii.shape == (3 * L - 2,)
    assert offsets.dtype == np.float64 and radii.dtype == np.float64


@pytest.mark.parametrize("L", range(2, 8))
def test_cube_has_6L2_minus_12L_plus_8_spheres(L):
    offsets, radii = cube(L)
    assert len(radii) == 6 * L * L - 12 * L + 8
    # every sphere is on the surface of the lattice cube of half-edge (L - 1) r
    assert np.allclose(np.max(np.abs(offsets), axis=1), L - 1.0)


def test_single_sphere_shapes():
    for offsets, radii in (sphere(), spiky(1), cube(1), rod(1), four_rods(1), tripod(1)):
        assert offsets.shape == (1, 3) and np.all(offsets == 0.0) and radii[0] == 1.0


def test_counts_of_the_paper_figures():
    assert len(rod(11)[1]) == 11  # Fig. 1(a)
    assert len(four_rods()[1]) == 17  # Fig. 1(b): 4 (5 - 1) + 1
    assert len(tripod()[1]) == 10  # 3 (4 - 1) + 1
    assert len(four_rods(spheres_per_rod=3)[1]) == 9


def test_spiky_geometry_and_even_L_convention():
    # odd L: symmetric arms of (L - 1) / 2 spheres, neighbours touch (distance 2r)
    offsets, radii = spiky(5, radius=0.5)
    assert np.all(radii == 0.5)
    xs = np.sort(offsets[(np.abs(offsets[:, 1]) < EXACT_ATOL) & (np.abs(offsets[:, 2]) < EXACT_ATOL), 0])
    assert np.allclose(xs, [-2.0, -1.0, 0.0, 1.0, 2.0], atol=EXACT_ATOL)
    # even L = 4: k = -1 .. 2 on each axis; the centre of mass is the mean of the centres
    offsets, _ = spiky(4)
    k = np.array([-1, 1, 2])
    centres = np.vstack([np.zeros(3)] + [np.outer(2.0 * k, np.eye(3)[a]) for a in range(3)])
    expected = centres - centres.mean(axis=0)
    assert np.allclose(np.sort(offsets, axis=0), np.sort(expected, axis=0), atol=EXACT_ATOL)


def test_four_rods_and_tripod_geometry():
    offsets, _ = four_rods(spacing=1.0)
    assert np.allclose(offsets[:, 2], 0.0, atol=EXACT_ATOL)  # a plane cross
    assert np.allclose(offsets.mean(axis=0), 0.0, atol=1e-9)  # symmetric
    offsets, _ = tripod(spheres_per_leg=4, spacing=2.0)
    common = offsets[0]
    legs = offsets[1:] - common
    tips = legs[np.isclose(np.linalg.norm(legs, axis=1), 6.0)]
    assert len(tips) == 3
    cosines = (tips @ tips.T) / 36.0
    assert np.allclose(cosines[~np.eye(3, dtype=bool)], -1.0 / 3.0)  # tetrahedral angle


# ----------------------------------------------------------------------------------------
# centre of mass of a union of spheres


def test_union_two_equal_overlapping_spheres_com_is_midpoint():
    centres = np.array([[0.3, -1.2, 0.7], [1.1, -0.6, 1.3]])  # distance 1.166 < 2
    com, volume = centre_of_mass_of_union(centres, [1.0, 1.0])
    assert np.allclose(com, centres.mean(axis=0), atol=UNION_COM_ATOL)
    v_exact, _ = lens_union(1.0, 1.0, float(np.linalg.norm(centres[1] - centres[0])))
    assert abs(volume / v_exact - 1.0) < UNION_VOLUME_RTOL


@pytest.mark.parametrize("r1, r2, d", [(1.0, 0.5, 1.2), (1.0, 0.7, 0.5), (1.3, 1.0, 1.9), (0.8, 1.6, 1.0)])
def test_union_two_unequal_spheres_matches_lens_formula(r1, r2, d):
    rng = np.random.default_rng(7)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    c1 = rng.uniform(-2.0, 2.0, 3)
    com, volume = centre_of_mass_of_union([c1, c1 + d * axis], [r1, r2])
    v_exact, x_exact = lens_union(r1, r2, d)
    assert abs(volume / v_exact - 1.0) < UNION_VOLUME_RTOL
    assert np.linalg.norm(com - (c1 + x_exact * axis)) < UNION_COM_ATOL * 0.5 * (r1 + r2)


def collinear_union_volume(n, spacing, radius):
    """Volume of n equal spheres of ``radius`` on a line, centres ``spacing`` < 2 radius apart: n spheres less
    n - 1 lenses (the lens of Weisstein, MathWorld "Sphere-Sphere Intersection", of equal spheres:
    pi (4 r + d) (2 r - d)^2 / 12). Each cross-section perpendicular to the line is the disc of the nearest
    centre, so sphere k and k + 2 meet only inside k + 1: the formula holds at every spacing."""
    lens = math.pi * (4.0 * radius + spacing) * (2.0 * radius - spacing) ** 2 / 12.0
    return n * 4.0 / 3.0 * math.pi * radius**3 - (n - 1) * lens


def test_rod_of_four_spheres_of_radius_half_has_the_exact_volume():
    offsets, radii = rod(4, spacing=0.5, radius=0.5)
    _, volume = centre_of_mass_of_union(offsets, radii)
    assert collinear_union_volume(4, 0.5, 0.5) == pytest.approx(1.6035212502697, rel=1e-12)
    assert volume == pytest.approx(collinear_union_volume(4, 0.5, 0.5), rel=1e-12)


@pytest.mark.parametrize("n", [2, 3, 4, 11])
@pytest.mark.parametrize("spacing", [1.0, 1.37, 1.99])
def test_rods_of_pairwise_overlaps_have_the_exact_union(n, spacing):
    """Spacings of 1 radius and more: no point lies in three spheres, the union is spheres less lenses, exact;
    turned and moved, the centre of mass is the middle of the line."""
    offsets, radii = rod(n, spacing=spacing)
    quaternion = np.array([0.9, 0.1, -0.3, 0.3]) / np.linalg.norm([0.9, 0.1, -0.3, 0.3])
    centres = rotate(offsets, quaternion) + [1.5, -0.5, 2.0]
    com, volume = centre_of_mass_of_union(centres, radii)
    assert volume == pytest.approx(collinear_union_volume(n, spacing, 1.0), rel=1e-12)
    assert np.allclose(com, [1.5, -0.5, 2.0], atol=1e-12)


@pytest.mark.parametrize("n, spacing", [(3, 0.3), (4, 0.5), (6, 0.8), (11, 0.3)])
def test_rods_of_triple_overlaps_are_within_the_documented_accuracy(n, spacing):
    """Below 1 radius apart three spheres overlap and the union is integrated on columns: within the largest
    error centre_of_mass_of_union documents (8.5e-4), along the grid's axis and turned."""
    offsets, radii = rod(n, spacing=spacing)
    exact = collinear_union_volume(n, spacing, 1.0)
    for quaternion in ([1.0, 0.0, 0.0, 0.0], [0.9, 0.1, -0.3, 0.3], [0.2, 0.7, 0.1, -0.4]):
        q = np.array(quaternion) / np.linalg.norm(quaternion)
        com, volume = centre_of_mass_of_union(rotate(offsets, q) + [0.3, 0.2, 0.1], radii)
        assert volume == pytest.approx(exact, rel=8.5e-4)
        assert np.allclose(com, [0.3, 0.2, 0.1], atol=1e-9)  # symmetric: the middle of the line


def test_union_of_disjoint_and_contained_spheres():
    # touching spheres are integrated exactly (no overlap)
    offsets, radii = cube(4)
    _, volume = centre_of_mass_of_union(offsets, radii)
    assert volume == pytest.approx(len(radii) * 4.0 / 3.0 * math.pi, rel=1e-14)
    # a sphere inside another adds nothing
    _, volume = centre_of_mass_of_union([[0, 0, 0], [0.2, 0.1, 0.0]], [1.0, 0.5])
    assert abs(volume / (4.0 / 3.0 * math.pi) - 1.0) < UNION_VOLUME_RTOL


@pytest.mark.parametrize("shape", [lambda: spiky(5), lambda: spiky(7, 0.3), lambda: cube(3), lambda: cube(4)])
def test_symmetric_shapes_have_com_at_their_centre(shape):
    offsets, radii = shape()
    # the shapes are re-centred: the geometric centre is now at the origin
    assert np.allclose(offsets.mean(axis=0), 0.0, atol=EXACT_ATOL)
    com, _ = centre_of_mass_of_union(offsets + [3.0, -1.0, 2.0], radii)
    assert np.allclose(com, [3.0, -1.0, 2.0], atol=EXACT_ATOL)


def test_symmetric_overlapping_shapes_have_com_at_their_centre():
    # overlapping spheres: the column grid is laid symmetrically over the bounding box
    for offsets, radii in (rod(11), four_rods(), spiky(3)):
        centres = offsets - offsets.mean(axis=0) + [0.5, 0.25, -1.0]
        com, _ = centre_of_mass_of_union(centres, radii)
        assert np.allclose(com, [0.5, 0.25, -1.0], atol=1e-12)


def test_asymmetric_rod_matches_monte_carlo():
    """Unequal overlapping spheres on a line against an independent Monte-Carlo estimate.

    2e6 uniform points in the bounding box (fixed seed); a point counts if it lies in any
    sphere.  Standard error of the volume ~ V sqrt(p(1-p)/N)/p ~ 1e-3 V, of the com
    ~ std(x)/sqrt(N p) ~ 1.5e-3; tolerance 5 standard errors plus the integration error.
    """
    centres = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.8, 0.0, 0.0], [3.0, 0.0, 0.0]])
    radii = np.array([1.0, 0.6, 1.3, 0.8])
    com, volume = centre_of_mass_of_union(centres, radii)

    rng = np.random.default_rng(12345)
    lower = (centres - radii[:, None]).min(axis=0)
    upper = (centres + radii[:, None]).max(axis=0)
    n = 2_000_000
    p = lower + (upper - lower) * rng.random((n, 3))
    inside = np.zeros(n, dtype=bool)
    for c, r in zip(centres, radii):
        inside |= np.sum((p - c) ** 2, axis=1) <= r * r
    frac = inside.mean()
    box = np.prod(upper - lower)
    v_mc = frac * box
    se_v = box * math.sqrt(frac * (1.0 - frac) / n)
    pts = p[inside]
    com_mc = pts.mean(axis=0)
    se_com = pts.std(axis=0) / math.sqrt(len(pts))
    assert abs(volume - v_mc) < 5.0 * se_v + UNION_VOLUME_RTOL * volume
    assert np.all(np.abs(com - com_mc) < 5.0 * se_com + UNION_COM_ATOL * radii.mean())
    # and the asymmetry is real: the com is off the mean of the centres
    assert abs(com[0] - centres[:, 0].mean()) > 0.02  # 0.035, 20 standard errors
    # the re-centred rod has its union com at the origin
    offsets, r = agglomerate(centres, radii)
    assert np.allclose(offsets, centres - com, atol=EXACT_ATOL)


def test_union_is_deterministic_and_converges_with_resolution():
    rng = np.random.default_rng(3)
    centres = np.cumsum(rng.normal(scale=0.8, size=(30, 3)), axis=0)
    radii = rng.uniform(0.5, 1.5, 30)
    a = centre_of_mass_of_union(centres, radii)
    b = centre_of_mass_of_union(centres, radii)
    assert np.array_equal(a[0], b[0]) and a[1] == b[1]
    fine_com, fine_v = centre_of_mass_of_union(centres, radii, resolution=96)
    assert abs(a[1] / fine_v - 1.0) < UNION_VOLUME_RTOL
    assert np.linalg.norm(a[0] - fine_com) < UNION_COM_ATOL * radii.mean()


# ----------------------------------------------------------------------------------------
# ellipsoids and superellipsoids


def test_ellipsoid_spheres_inside_and_volume_close():
    """2,000 spheres for semi-axes (2, 1.5, 1).

    Inside: every sphere surface, sampled, lies inside the ellipsoid (within 1e-9 of the
    largest semi-axis; construction tolerance 2e-11).  Volume: the union misses only the
    cusps between tangent points; with spacing delta ~ sqrt(area / n) = 0.11 and
    medial-ball radii >= c^2 / a = 0.5 the cusps are ~ delta^2 / (8 * 0.5) = 3e-3 deep,
    a layer of at most area * depth / 2 = 0.03 = 0.25 % of the volume; we assert 1 %
    (measured 0.085 %), and no excess beyond the integration error.
    """
    axes = (2.0, 1.5, 1.0)
    offsets, radii = ellipsoid(axes, 2000)
    assert len(radii) == 2000
    body_offsets, body_radii = ellipsoid(axes, 2000, frame="body")
    assert np.array_equal(radii, body_radii)
    com, volume = centre_of_mass_of_union(body_offsets, body_radii)
    assert np.allclose(offsets, body_offsets - com, atol=EXACT_ATOL)
    assert max_outside(body_offsets, body_radii, axes) < 1e-9 * max(axes)
    v_exact = 4.0 / 3.0 * math.pi * np.prod(axes)
    assert 0.99 * v_exact < volume < (1.0 + UNION_VOLUME_RTOL) * v_exact
    assert np.linalg.norm(com) < 0.01  # nearly symmetric cover


def test_ellipsoid_of_a_sphere_is_one_sphere():
    offsets, radii = ellipsoid((1.5, 1.5, 1.5), 500)
    assert len(radii) == 1 and radii[0] == pytest.approx(1.5, rel=1e-12)


def test_superellipsoid_distance_reproduces_eberly_for_exponents_2_2():
    """The support-function/surface-point distance search of the superellipsoid, at
    exponents (2, 2), against Eberly's exact ellipsoid distance at random interior points."""
    axes = np.array([2.0, 1.5, 1.0])
    body = shapes.smooth._superellipsoid_body(axes, 2.0, 2.0)
    perm = np.argsort(-axes, kind="stable").astype(np.int64)
    e_sorted = np.ascontiguousarray(axes[perm])
    rng = np.random.default_rng(1)
    p = rng.uniform(-1.0, 1.0, (3000, 3)) * axes
    p = p[implicit(p, axes) < 1.0][:300]
    q = np.empty(3)
    nu = np.empty(3)
    for point in p:
        exact = shapes.ellipsoid_distance._ellipsoid_closest(point, e_sorted, perm, q)
        for methods in (1, 2):
            d = shapes.superellipsoid_distance._superellipsoid_min(point, body, 6, -np.inf, q, nu, methods)
            assert d == pytest.approx(exact, abs=1e-12)


def test_superellipsoid_2_2_reproduces_the_ellipsoid():
    axes = (2.0, 1.5, 1.0)
    body, radii = superellipsoid(axes, (2, 2), 600, frame="body")
    assert len(radii) == 600
    assert max_outside(body, radii, axes) < 1e-9 * max(axes)
    _, v_super = centre_of_mass_of_union(body, radii)
    _, v_ell = centre_of_mass_of_union(*ellipsoid(axes, 600))
    v_exact = 4.0 / 3.0 * math.pi * np.prod(axes)
    # same construction, distances equal to round-off: the same volume within the
    # integration error plus the small differences of a greedy choice (measured 3e-5)
    assert abs(v_super - v_ell) < 2e-3 * v_exact
    assert 0.97 * v_exact < v_super < (1.0 + UNION_VOLUME_RTOL) * v_exact


@pytest.mark.parametrize("exponents, bound", [((4, 4), 0.02), ((1.5, 3), 0.03)])
def test_superellipsoid_inside_and_volume(exponents, bound):
    """Box-like (4, 4) and pointed (1.5, 3) superellipsoids of 600 spheres: inside the
    body and within ``bound`` of Barr's volume (measured 0.5 % and 1.2 %)."""
    axes = (2.0, 1.5, 1.0)
    body, radii = superellipsoid(axes, exponents, 600, frame="body")
    assert max_outside(body, radii, axes, *exponents) < 1e-9 * max(axes)
    _, volume = centre_of_mass_of_union(body, radii)
    v_exact = superellipsoid_volume(axes, *exponents)
    assert (1.0 - bound) * v_exact < volume < (1.0 + UNION_VOLUME_RTOL) * v_exact


def test_ellipsoid_is_deterministic():
    a = ellipsoid((1.2, 1.0, 0.7), 150)
    b = ellipsoid((1.2, 1.0, 0.7), 150)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


# ----------------------------------------------------------------------------------------
# rotations


def test_random_rotations_are_unit_and_uniform():
    """Rotated unit vectors of uniform rotations are uniform on the sphere: each
    component is uniform on [-1, 1] (mean 0, variance 1/3).  N = 1e5, fixed seed; the
    standard errors are sqrt(1/3 / N) = 1.8e-3 for the mean and
    sqrt((1/5 - 1/9) / N) = 9.4e-4 for the variance; tolerance 5 standard errors."""
    n = 100_000
    q = random_rotations(n, np.random.default_rng(2024))
    assert q.shape == (n, 4)
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-14)
    w, x, y, z = q.T
    # third column of the rotation matrix = R e_z, and first column = R e_x
    ez = np.stack([2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y)], axis=1)
    ex = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y + z * w), 2 * (x * z - y * w)], axis=1)
    for v in (ez, ex):
        for comp in v.T:
            assert abs(comp.mean()) < 5 * math.sqrt(1.0 / 3.0 / n)
            assert abs(comp.var() - 1.0 / 3.0) < 5 * math.sqrt((0.2 - 1.0 / 9.0) / n)
        hist, _ = np.histogram(v[:, 2], bins=10, range=(-1.0, 1.0))
        assert np.all(np.abs(hist / n - 0.1) < 5 * math.sqrt(0.09 / n))
    # reproducible from the seed
    assert np.array_equal(random_rotations(5, np.random.default_rng(1)), random_rotations(5, np.random.default_rng(1)))


def test_drawn_rotations_are_the_random_rotations_row_by_row():
    """A rank of a spread deposition computes the orientations of its own particles only: any rows
    taken from the drawn uniforms are bitwise those rows of random_rotations, and the generator goes
    on from the same place."""
    n = 1001
    rng, drawn_rng = np.random.default_rng(7), np.random.default_rng(7)
    whole = random_rotations(n, rng)
    drawn = DrawnRotations.draw(n, drawn_rng)
    rows = np.flatnonzero(np.random.default_rng(3).random(n) < 0.3)
    assert len(drawn) == n and drawn.shape == (n, 4)
    assert np.array_equal(drawn[rows], whole[rows]) and np.array_equal(drawn[5], whole[5:6])
    assert np.array_equal(np.asarray(drawn), whole) and drawn[rows[:0]].shape == (0, 4)
    assert rng.random() == drawn_rng.random()


def test_rotate_matches_axis_angle_and_preserves_distances():
    rng = np.random.default_rng(5)
    v = rng.normal(size=(20, 3))
    axis = np.array([1.0, -2.0, 0.5])
    axis /= np.linalg.norm(axis)
    theta = 0.7
    q = np.concatenate([[math.cos(theta / 2)], math.sin(theta / 2) * axis])
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    R = np.eye(3) + math.sin(theta) * K + (1 - math.cos(theta)) * K @ K  # Rodrigues
    out = rotate(v, q)
    assert np.allclose(out, v @ R.T, atol=1e-14)
    d_before = np.linalg.norm(v[:, None] - v[None], axis=2)
    for quat in random_rotations(10, rng):
        w = rotate(v, quat)
        assert np.allclose(np.linalg.norm(w[:, None] - w[None], axis=2), d_before, atol=1e-13)
        assert np.allclose(np.linalg.norm(w, axis=1), np.linalg.norm(v, axis=1), atol=1e-13)
    with pytest.raises(ValueError, match="quaternion"):
        rotate(v, [1.0, 0.1, 0.0, 0.0])


# ----------------------------------------------------------------------------------------
# agglomerates, helpers, errors


def test_agglomerate_embeds_2d_positions_and_recentres():
    rng = np.random.default_rng(11)
    pos2d = np.cumsum(rng.normal(scale=1.0, size=(40, 2)), axis=0)  # overlapping chain
    radii = np.full(40, 0.8)
    offsets, r = agglomerate(pos2d, radii)
    assert offsets.shape == (40, 3) and np.array_equal(r, radii)
    assert np.all(offsets[:, 2] == 0.0)
    com, _ = centre_of_mass_of_union(offsets, r)
    assert np.allclose(com, 0.0, atol=1e-12)
    # the shift is a pure translation of the given positions
    shift = offsets[:, :2] - pos2d
    assert np.allclose(shift, shift[0], atol=EXACT_ATOL)


@pytest.mark.parametrize(
    "centres, radii, match",
    [
        ([[0, 0, 0], [1, 0, 0]], [1.0, 0.0], "radii"),
        ([[0, 0, 0], [1, 0, 0]], [1.0, -1.0], "radii"),
        ([[0, 0, 0], [1, 0, 0]], [1.0, float("nan")], "radii"),
        ([[0, 0, 0], [1, 0, 0]], [1.0], "radii"),
        ([[0, 0, 0, 0]], [1.0], "centres"),
        ([0.0, 0.0], [1.0], "centres"),
    ],
)
def test_agglomerate_rejects_bad_input(centres, radii, match):
    with pytest.raises(ValueError, match=match):
        agglomerate(centres, radii)


def test_bad_arguments_name_the_argument():
    with pytest.raises(ValueError, match="L"):
        spiky(0)
    with pytest.raises(ValueError, match="spacing"):
        rod(3, spacing=2.5)
    with pytest.raises(ValueError, match="radius"):
        cube(2, radius=-1.0)
    with pytest.raises(ValueError, match="exponents"):
        superellipsoid((1, 1, 1), (1.0, 2.0), 10)
    with pytest.raises(ValueError, match="semi_axes"):
        ellipsoid((1, 0, 1), 10)
    with pytest.raises(ValueError, match="n_spheres"):
        ellipsoid((1, 1, 1), 0)
    with pytest.raises(ValueError, match="rng"):
        random_rotations(3, rng=1)
    with pytest.raises(ValueError, match="resolution"):
        centre_of_mass_of_union([[0, 0, 0]], [1.0], resolution=0)


def test_extent_below_com_and_bounding_radius():
    offsets, radii = sphere(2.0)
    assert extent_below_com(offsets, radii) == 2.0 and bounding_radius(offsets, radii) == 2.0
    offsets, radii = rod(3, spacing=1.0)  # along x, from -1 to 1
    assert bounding_radius(offsets, radii) == pytest.approx(2.0)
    assert extent_below_com(offsets, radii) == pytest.approx(1.0)
    upright = rotate(offsets, [math.cos(math.pi / 4), 0.0, -math.sin(math.pi / 4), 0.0])  # x -> z
    assert extent_below_com(upright, radii) == pytest.approx(2.0)
    offsets, radii = tripod()
    lowest = np.min(offsets[:, 2] - radii)
    assert extent_below_com(offsets, radii) == pytest.approx(-lowest)
