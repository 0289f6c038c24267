"""Particles built from equal spheres: sphere, rod, four rods, tripod, spiky, cube, and
arbitrary given spheres (agglomerate); each re-centred on the centre of mass of the union."""

import math

import numpy as np

from parsim.core.shapes.checks import _check_centres_radii, _check_int, _check_positive, _check_spacing
from parsim.core.shapes.union import _recentre


def sphere(radius=1.0):
    """One sphere of ``radius`` at the origin: ``offsets = [[0, 0, 0]]``."""
    radius = _check_positive("radius", radius)
    return np.zeros((1, 3)), np.array([radius])


def rod(n_spheres, spacing=1.0, radius=1.0):
    """``n_spheres`` equal spheres on the x axis, centre distance ``spacing``.

    Fig. 1(a) of the paper (11 overlapping spheres) is ``rod(11)``: the default
    ``spacing = 1.0 = radius`` (each sphere reaches the centres of its neighbours) gives a
    rod of length ``(n - 1) spacing + 2 radius = 12`` radii.  ``spacing`` must be in
    ``(0, 2 radius]``: the spheres overlap (``< 2 radius``) or touch (``= 2 radius``).
    """
    n_spheres = _check_int("n_spheres", n_spheres, 1)
    radius = _check_positive("radius", radius)
    spacing = _check_spacing(spacing, radius)
    centres = np.zeros((n_spheres, 3))
    centres[:, 0] = (np.arange(n_spheres) - 0.5 * (n_spheres - 1)) * spacing
    return _recentre(centres, np.full(n_spheres, radius))


def _arms(directions, spheres_per_arm, spacing, radius):
    k = np.arange(1, spheres_per_arm)
    centres = [np.zeros((1, 3))]
    for d in directions:
        centres.append(k[:, None] * spacing * np.asarray(d, dtype=np.float64)[None, :])
    centres = np.vstack(centres)
    return _recentre(centres, np.full(centres.shape[0], radius))


def four_rods(spheres_per_rod=5, spacing=1.0, radius=1.0):
    """Fig. 1(b): four equal rods joined at one common central sphere, a plane cross.

    The rods lie along +x, -x, +y, -y in the plane z = 0; each has ``spheres_per_rod``
    spheres counting the shared central one, so the particle has
    ``4 (spheres_per_rod - 1) + 1`` spheres: 17 for the default 5, the paper's count.
    Centre distance along a rod is ``spacing`` (default = radius, as in Fig. 1(a)),
    in ``(0, 2 radius]``.  ``spheres_per_rod = 1`` is a single sphere.
    """
    spheres_per_rod = _check_int("spheres_per_rod", spheres_per_rod, 1)
    radius = _check_positive("radius", radius)
    spacing = _check_spacing(spacing, radius)
    directions = [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0)]
    return _arms(directions, spheres_per_rod, spacing, radius)


# Three of the four vertex directions of a regular tetrahedron centred at the origin:
# the fourth vertex is at +z, these three at z = -1/3 and azimuths 0, 120, 240 degrees.
_TETRA_LEGS = np.array(
    [
        [math.sqrt(8.0 / 9.0) * math.cos(phi), math.sqrt(8.0 / 9.0) * math.sin(phi), -1.0 / 3.0]
        for phi in (0.0, 2.0 * math.pi / 3.0, 4.0 * math.pi / 3.0)
    ]
)


def tripod(spheres_per_leg=4, spacing=1.0, radius=1.0):
    """Three equal legs joined at one common sphere (the paper's "tripods", Fig. 14).

    The legs point from the common sphere along three of the four vertex directions of
    a regular tetrahedron centred there: unit vectors with z = -1/3 at azimuths 0, 120
    and 240 degrees (the unused fourth vertex direction is +z), so any two legs meet at
    ``arccos(-1/3) = 109.47`` degrees and the tripod stands on its three feet.  Each
    leg has ``spheres_per_leg`` spheres counting the shared one, so the particle has
    ``3 (spheres_per_leg - 1) + 1`` spheres (10 for the default 4).  Centre distance
    along a leg is ``spacing`` in ``(0, 2 radius]``.  Offsets are relative to the
    centre of mass of the union, which lies below the common sphere.
    """
    spheres_per_leg = _check_int("spheres_per_leg", spheres_per_leg, 1)
    radius = _check_positive("radius", radius)
    spacing = _check_spacing(spacing, radius)
    return _arms(_TETRA_LEGS, spheres_per_leg, spacing, radius)


def spiky(L, radius=1.0):
    """Section 5, Fig. 8(a): the spiky particle, 3L - 2 equal touching spheres.

    Three perpendicular rows of ``L`` spheres along x, y and z share one common sphere;
    neighbours touch (centre distance ``2 radius``).  On each axis the spheres sit at
    ``k * 2 radius`` for ``k = -((L - 1) // 2), ..., L // 2`` (the common sphere is k = 0):
    symmetric for odd ``L``; for even ``L`` the positive side carries one sphere more
    (e.g. L = 2: one extra sphere on each of +x, +y, +z).  ``L = 1`` is a single sphere.
    Offsets are relative to the centre of mass (exact here: touching spheres do not
    overlap, so it is the mean of the centres).
    """
    L = _check_int("L", L, 1)
    radius = _check_positive("radius", radius)
    ks = [k for k in range(-((L - 1) // 2), L // 2 + 1) if k != 0]
    centres = [np.zeros(3)]
    for axis in range(3):
        for k in ks:
            p = np.zeros(3)
            p[axis] = 2.0 * radius * k
            centres.append(p)
    centres = np.array(centres)
    return _recentre(centres, np.full(centres.shape[0], radius))


def cube(L, radius=1.0):
    """Section 5, Fig. 8(a): the cube-like particle, the surface of an L x L x L lattice.

    Equal spheres on the surface sites of a simple cubic lattice of ``L`` sites per
    edge and spacing ``2 radius`` (neighbours touch): ``L^3 - (L - 2)^3 = 6L^2 - 12L + 8``
    spheres for ``L >= 2``.  ``L = 1`` is one sphere (the formula would give 2; the paper
    states that both particle types are single spheres at L = 1).  Offsets are relative
    to the centre of the cube (the exact centre of mass).
    """
    L = _check_int("L", L, 1)
    radius = _check_positive("radius", radius)
    idx = np.arange(L)
    i, j, k = np.meshgrid(idx, idx, idx, indexing="ij")
    on_surface = (i == 0) | (i == L - 1) | (j == 0) | (j == L - 1) | (k == 0) | (k == L - 1)
    sites = np.stack([i[on_surface], j[on_surface], k[on_surface]], axis=1).astype(np.float64)
    centres = (sites - 0.5 * (L - 1)) * 2.0 * radius
    return _recentre(centres, np.full(centres.shape[0], radius))


def agglomerate(centres, radii):
    """Arbitrary given spheres, re-centred on the centre of mass of their union.

    ``centres`` (n, 3), or (n, 2) for a 2D configuration, embedded in the plane z = 0;
    ``radii`` (n,) finite and > 0.  The spheres are returned unchanged in order and
    size, translated so that the union's centre of mass is at the origin.  They need not
    overlap (Fig. 1(c): 790 non-overlapping spheres).
    """
    c, r = _check_centres_radii(centres, radii, allow_2d=True)
    return _recentre(c, r)
