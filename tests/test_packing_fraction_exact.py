"""Packing fraction against exact slab volumes: spherical caps, and lenses of overlapping spheres."""

import numpy as np
import pytest

from parsim.core.sediment import packing_fraction, packing_fraction_profile
from parsim.core.shapes.union import lens_volume


def volume_below(centre_z, radius, z):
    """Volume of a sphere below the plane z: integral of pi (r^2 - s^2) ds up to s = z - zc."""
    s = np.clip(z - centre_z, -radius, radius)
    return np.pi * (radius**2 * (s + radius) - (s**3 + radius**3) / 3)


def exact_fraction(centres, radii, area, z_low, z_high):
    z = centres[:, 2]
    return np.sum(volume_below(z, radii, z_high) - volume_below(z, radii, z_low)) / (area * (z_high - z_low))


def disjoint_spheres(rng, n_side, layers, pitch, lower_xy):
    """Spheres of random radii at jittered lattice sites; no two overlap."""
    i, j, k = np.meshgrid(np.arange(n_side), np.arange(n_side), np.arange(layers), indexing="ij")
    sites = pitch * (np.column_stack([i.ravel(), j.ravel(), k.ravel()]) + 0.5)
    radii = rng.uniform(0.2, 0.4, len(sites)) * pitch
    jitter = rng.uniform(-1, 1, sites.shape) * (0.5 * pitch - radii)[:, None]
    return sites + jitter + [lower_xy[0], lower_xy[1], 0.0], radii


@pytest.mark.parametrize("periodic", [True, False])
def test_disjoint_spheres_match_the_integral_of_caps(periodic):
    rng = np.random.default_rng(3)
    pitch, n_side, layers = 1.0, 6, 8
    lower = np.array([-2.0, 1.5])
    x, radii = disjoint_spheres(rng, n_side, layers, pitch, lower)
    side = pitch * n_side
    if periodic:  # shift the pile so that spheres cross the lateral sides; their images wrap back in
        x[:, :2] = lower + np.mod(x[:, :2] - lower + 0.37 * pitch, side)
    upper = lower + side
    area = side * side
    for z_low, z_high in [(1.13, 6.71), (2.0, 2.05), (0.0, 8.0), (-1.0, 0.31)]:
        phi = packing_fraction(x, radii, lower, upper, z_low, z_high, samples=1000)
        assert phi == pytest.approx(exact_fraction(x, radii, area, z_low, z_high), abs=1e-5)
    edges = np.linspace(0.0, 8.3, 37)  # slabs cut through the spheres
    profile = packing_fraction_profile(x, radii, lower, upper, edges, samples=1000)
    exact = [exact_fraction(x, radii, area, a, b) for a, b in zip(edges[:-1], edges[1:])]
    np.testing.assert_allclose(profile, exact, rtol=0, atol=1e-5)


def lens_section_area(a, b, d):
    """Area of the intersection of two discs of radii a, b at centre distance d."""
    a, b = np.maximum(a, 0.0), np.maximum(b, 0.0)
    out = np.where(d <= np.abs(a - b), np.pi * np.minimum(a, b) ** 2, 0.0)
    partial = (d > np.abs(a - b)) & (d < a + b)
    a, b, d = a[partial], b[partial], np.broadcast_to(d, partial.shape)[partial]
    ca = np.clip((d * d + a * a - b * b) / (2 * d * a), -1, 1)
    cb = np.clip((d * d + b * b - a * a) / (2 * d * b), -1, 1)
    root = np.sqrt(np.maximum((-d + a + b) * (d + a - b) * (d - a + b) * (d + a + b), 0.0))
    out[partial] = a * a * np.arccos(ca) + b * b * np.arccos(cb) - 0.5 * root
    return out


def lens_slab_volume(ci, cj, r, z_low, z_high, panels=200):
    """Volume of the lens of two spheres of radius r inside z_low <= z <= z_high: the integral over z of the
    area of the intersection of the spheres' horizontal sections (lens_section_area), by Gauss-Legendre on
    panels spaced as 1 - cos between the lens's lowest and highest points, the meeting circle's lowest and
    highest points (where the sections' circles touch from outside), the spheres' poles and the slab's edges
    (converged to 3e-15 of the lens at 200 panels, 1e-12 at 64)."""
    axis = (cj - ci) / np.linalg.norm(cj - ci)
    d = np.linalg.norm(cj - ci)
    centre_z = 0.5 * (ci[2] + cj[2])
    circle = np.sqrt(r * r - 0.25 * d * d) * np.sqrt(1.0 - axis[2] ** 2)  # the meeting circle's half height
    top, bottom = min(ci[2], cj[2]) + r, max(ci[2], cj[2]) - r
    poles = [ci[2] - r, ci[2] + r, cj[2] - r, cj[2] + r]
    cuts = np.unique(np.clip([bottom, centre_z - circle, centre_z + circle, top, z_low, z_high, *poles], bottom, top))
    cuts = cuts[(cuts >= max(bottom, z_low)) & (cuts <= min(top, z_high))]
    nodes, weights = np.polynomial.legendre.leggauss(10)
    horizontal = np.hypot(*(ci[:2] - cj[:2]))
    total = 0.0
    for lo, hi in zip(cuts[:-1], cuts[1:]):
        a = lo + (hi - lo) * 0.5 * (1.0 - np.cos(np.linspace(0.0, np.pi, panels + 1)))
        half = 0.5 * np.diff(a)
        z = (0.5 * (a[1:] + a[:-1]))[:, None] + half[:, None] * nodes
        area = lens_section_area(np.sqrt(np.maximum(r * r - (z - ci[2]) ** 2, 0)),
                                 np.sqrt(np.maximum(r * r - (z - cj[2]) ** 2, 0)), horizontal)
        total += float(np.sum(half[:, None] * weights * area))
    return total


def rods(rng, n_side, layers, r):
    """Rods of three spheres 1 radius apart, random orientations, on a lattice: only neighbours within a rod overlap."""
    pitch = 4 * r * (1 + 1e-9)
    i, j, k = np.meshgrid(np.arange(n_side), np.arange(n_side), np.arange(layers), indexing="ij")
    centres = pitch * (np.column_stack([i.ravel(), j.ravel(), k.ravel()]) + 0.5)
    u = rng.normal(size=centres.shape)
    u /= np.linalg.norm(u, axis=1)[:, None]
    x = centres[:, None, :] + r * np.array([-1.0, 0.0, 1.0])[None, :, None] * u[:, None, :]
    return x, pitch * n_side


def test_rods_match_caps_minus_lenses():
    """Rods of three spheres 1 radius apart in random orientations (pairwise lenses, many cut by the slabs'
    edges): the profile and the bulk value are the spheres' caps less the lenses in each slab, to round-off."""
    rng = np.random.default_rng(5)
    r = 0.5
    x, side = rods(rng, 5, 5, r)
    spheres = x.reshape(-1, 3)
    radii = np.full(len(spheres), r)
    edges = np.linspace(0.3, 9.7, 11)
    profile = packing_fraction_profile(spheres, radii, (0, 0), (side, side), edges)
    cut = 0
    for k, (z_low, z_high) in enumerate(zip(edges[:-1], edges[1:])):
        lenses = 0.0
        for rod in x:
            for m in range(2):
                part = lens_slab_volume(rod[m], rod[m + 1], r, z_low, z_high)
                cut += 0.0 < part < lens_volume(r, r, np.linalg.norm(rod[m + 1] - rod[m])) * (1 - 1e-9)
                lenses += part
        exact = exact_fraction(spheres, radii, side * side, z_low, z_high) - lenses / (side * side * (z_high - z_low))
        assert profile[k] == pytest.approx(exact, rel=1e-12, abs=1e-14)
        if k == 4:
            bulk = packing_fraction(spheres, radii, (0, 0), (side, side), z_low, z_high)
            assert bulk == pytest.approx(exact, rel=1e-12)
    assert cut > 20  # lenses split between two slabs


def test_a_lens_split_by_a_plane_through_its_axis_has_half_below():
    """Two spheres side by side at one height, and one above the other: an edge through the horizontal lens's
    axis leaves half of it in each slab; the vertical lens is bounded by two spherical caps."""
    r, d = 1.0, 1.3
    lens = lens_volume(r, r, d)
    side = (0.0, 0.0), (10.0, 10.0)
    edges = [0.0, 4.0, 8.0]
    flat = np.array([[3.0, 3.0, 4.0], [3.0 + d, 3.0, 4.0]])
    caps = 2 * (volume_below(4.0, r, 4.0) - volume_below(4.0, r, 0.0))  # half of each sphere below z = 4
    below = packing_fraction_profile(flat, [r, r], *side, edges)[0] * 100.0 * 4.0
    assert below == pytest.approx(caps - 0.5 * lens, rel=1e-13)
    upright = np.array([[3.0, 3.0, 3.5], [3.0, 3.0, 3.5 + d]])
    below = packing_fraction_profile(upright, [r, r], *side, edges)[0] * 100.0 * 4.0
    # below z = 4: sphere 1's part less the lens's: the lens lies between the meeting plane 3.5 + d/2 and the poles
    plane = 3.5 + 0.5 * d
    lens_below = (volume_below(3.5 + d, r, min(4.0, plane)) + (volume_below(3.5, r, 4.0) - volume_below(3.5, r, plane)
                                                                if 4.0 > plane else 0.0))
    exact = volume_below(3.5, r, 4.0) + volume_below(3.5 + d, r, 4.0) - lens_below
    assert below == pytest.approx(exact, rel=1e-13)


def test_many_overlapping_spheres_of_one_particle_match_a_fine_grid():
    # Medial balls of a prolate body: every sphere overlaps several others.
    t = np.linspace(-1.0, 1.0, 9)
    centres = np.column_stack([1.2 * t, 0.4 * t, 0.3 * t]) + [2.0, 2.0, 2.0]
    radii = 0.7 * np.sqrt(1.0 - 0.8 * t**2)
    side, edges = 4.0, np.array([0.5, 1.3, 1.9, 2.1, 2.6, 3.5])
    profile = packing_fraction_profile(centres, radii, (0, 0), (side, side), edges, samples=200_000)
    n = 1000  # columns per side; in each column the union of the spheres' chords is exact
    g = (np.arange(n) + 0.5) / n * side
    X, Y = np.meshgrid(g, g, indexing="ij")
    rho2 = (X.ravel()[:, None] - centres[:, 0]) ** 2 + (Y.ravel()[:, None] - centres[:, 1]) ** 2
    half = np.sqrt(np.maximum(radii**2 - rho2, 0.0))
    hit = half > 0
    for k, (z_low, z_high) in enumerate(zip(edges[:-1], edges[1:])):
        start = np.where(hit, np.clip(centres[:, 2] - half, z_low, z_high), z_high)
        end = np.where(hit, np.clip(centres[:, 2] + half, z_low, z_high), z_high)
        order = np.argsort(start, axis=1)
        start, end = np.take_along_axis(start, order, 1), np.take_along_axis(end, order, 1)
        reach = np.maximum.accumulate(end, axis=1)
        previous = np.concatenate([np.full((len(start), 1), z_low), reach[:, :-1]], axis=1)
        length = np.sum(np.maximum(end - np.maximum(start, previous), 0.0), axis=1)
        covered = length.mean() / (z_high - z_low)
        assert profile[k] == pytest.approx(covered, abs=2e-4)


def collinear_disc_union(rho, s, n):
    """Area of the union of n equal discs of radius rho whose centres lie on a line s apart: n discs less n - 1
    lenses (a disc meets the next but one only inside the one between)."""
    rho = np.maximum(rho, 0.0)
    return n * np.pi * rho**2 - (n - 1) * lens_section_area(rho, rho, np.full_like(rho, s))


def horizontal_rod_slab_volume(zc, r, s, n, z_low, z_high, panels=200):
    """Volume in z_low <= z <= z_high of a horizontal rod of n spheres of radius r, s apart, at height zc: the
    integral over z of its sections' area, panels spaced as 1 - cos between the heights where the sections'
    discs stop overlapping (|z - zc| = sqrt(r^2 - s^2 / 4)), the poles and the slab's edges."""
    apart = np.sqrt(r * r - 0.25 * s * s)
    cuts = np.unique(np.clip([zc - r, zc - apart, zc + apart, zc + r, z_low, z_high], max(z_low, zc - r),
                             min(z_high, zc + r)))
    nodes, weights = np.polynomial.legendre.leggauss(10)
    total = 0.0
    for lo, hi in zip(cuts[:-1], cuts[1:]):
        a = lo + (hi - lo) * 0.5 * (1.0 - np.cos(np.linspace(0.0, np.pi, panels + 1)))
        half = 0.5 * np.diff(a)
        z = (0.5 * (a[1:] + a[:-1]))[:, None] + half[:, None] * nodes
        area = collinear_disc_union(np.sqrt(np.maximum(r * r - (z - zc) ** 2, 0.0)), s, n).reshape(z.shape)
        total += float(np.sum(half[:, None] * weights * area))
    return total


def vertical_rod_below(zc, r, s, n, z):
    """Volume below z of a vertical rod of n spheres of radius r, s apart, the lowest centred at zc: each sphere
    between the planes halfway to its neighbours."""
    total = 0.0
    for k in range(n):
        centre = zc + k * s
        low = centre - 0.5 * s if k > 0 else centre - r
        high = centre + 0.5 * s if k < n - 1 else centre + r
        total += volume_below(centre, r, np.clip(z, low, high)) - volume_below(centre, r, low)
    return total


def test_rods_of_triple_overlaps_are_within_the_documented_sampling_error():
    """Rods of three spheres 0.5 radii apart (three overlap; sampled with the default samples), lying in random
    horizontal directions and standing upright, against their exact profile: within the largest error per slab
    docs/jobs.md gives for them (6e-4)."""
    rng = np.random.default_rng(9)
    r, s, n = 0.5, 0.25, 3
    side, centres, radii, lying, standing = 8.0, [], [], [], []
    for i in range(4):
        for j in range(4):
            base = np.array([1.0 + 2.0 * i, 1.0 + 2.0 * j])
            zc = 0.6 + 1.7 * rng.random()
            if (i + j) % 2:
                turn = rng.uniform(0.0, np.pi)
                for k in (-1, 0, 1):
                    centres.append([*(base + k * s * np.array([np.cos(turn), np.sin(turn)])), zc])
                lying.append(zc)
            else:
                for k in range(n):
                    centres.append([*base, zc + k * s])
                standing.append(zc)
            radii += [r] * n
    edges = np.linspace(0.0, 3.5, 11)
    profile = packing_fraction_profile(np.array(centres), np.array(radii), (0, 0), (side, side), edges)
    for k, (z_low, z_high) in enumerate(zip(edges[:-1], edges[1:])):
        exact = (sum(horizontal_rod_slab_volume(zc, r, s, n, z_low, z_high) for zc in lying)
                 + sum(vertical_rod_below(zc, r, s, n, z_high) - vertical_rod_below(zc, r, s, n, z_low)
                       for zc in standing)) / (side * side * (z_high - z_low))
        assert profile[k] == pytest.approx(exact, abs=6e-4)
