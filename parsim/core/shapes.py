"""Rigid particles made of overlapping, polydisperse spheres (Topić & Pöschel 2016).

The deposition algorithm of ``papers/sdbd-complex-particles-topic-poschel-2016.txt``
(section 2) moves rigid aggregates of spheres ("multisphere particles"): the centre of
mass follows the steepest descent.  This module builds such particles.

Every shape function returns ``(offsets, radii)``:

- ``offsets`` (k, 3) float64: sphere centres relative to the centre of mass of the
  **union** of the spheres (a point covered by two spheres is counted once; uniform
  density), computed by :func:`centre_of_mass_of_union`;
- ``radii`` (k,) float64.

Lengths are in units of the sphere radius ``r`` (``radius=1.0`` by default); every
length argument (``spacing``, ``semi_axes``) is in the same unit as ``radius``.

Shapes (with the reading of the paper's figures that they implement):

- :func:`sphere`: one sphere.
- :func:`rod`: Fig. 1(a), "11 equal overlapping spheres" on a line; ``rod(11)`` with the
  default ``spacing = radius`` (centre distance one radius, half-overlapping spheres, a
  rod of length 12 r and aspect ratio 6) is that picture.
- :func:`four_rods`: Fig. 1(b), "4 equal rods having in total 17 overlapping spheres":
  read as a plane cross of four rods of 5 spheres that share one central sphere,
  4 (5 - 1) + 1 = 17.  (The caption of Fig. 14 calls Fig. 1(b) "rings" and Fig. 1(c)
  "tripods", contradicting Fig. 1's own caption, where 1(c) is a fractal agglomerate;
  we follow Fig. 1 and the sphere count 17, which a closed ring of four 5-sphere rods,
  4 * 5 - 4 = 16, does not give.)
- :func:`tripod`: three equal legs from a common sphere along three of the four
  vertex directions of a regular tetrahedron (109.47 degrees between legs).
- :func:`spiky`, :func:`cube`: the two test particles of section 5 / Fig. 8(a).
- :func:`ellipsoid`, :func:`superellipsoid`: smooth convex bodies approximated by many
  overlapping polydisperse spheres (Fig. 1(d)-(f) use 1785 to 6241 spheres).
- :func:`agglomerate`: arbitrary given spheres (Fig. 1(c); a cluster of a 2D/3D
  aggregation), re-centred.

Helpers: :func:`extent_below_com`, :func:`bounding_radius`, :func:`random_rotations`
(uniform unit quaternions, Shoemake's method) and :func:`rotate`.

Quaternions are ``(w, x, y, z)`` with ``w`` the scalar part; :func:`rotate` applies the
active rotation ``v -> q v q*`` to row vectors.
"""

import math

import numpy as np

from parsim.core.jit import jit

__all__ = [
    "DEFAULT_UNION_RESOLUTION",
    "centre_of_mass_of_union",
    "sphere",
    "rod",
    "four_rods",
    "tripod",
    "spiky",
    "cube",
    "ellipsoid",
    "superellipsoid",
    "agglomerate",
    "extent_below_com",
    "bounding_radius",
    "random_rotations",
    "rotate",
]

# Grid columns per mean sphere radius in centre_of_mass_of_union.  At 32 the measured
# errors are below 2e-4 (relative volume) and 3e-4 mean radii (centre of mass); the cost
# is about pi * 32^2 = 3200 column intervals per overlapping sphere.
DEFAULT_UNION_RESOLUTION = 32.0
# Two spheres are treated as overlapping when |c_i - c_j| < (r_i + r_j)(1 - OVERLAP_RTOL).
# Touching spheres (spiky, cube: centres 2r apart up to a few ulp) are then disjoint; the
# lens volume ignored at this separation is O(OVERLAP_RTOL^2) r^3, far below round-off.
OVERLAP_RTOL = 1e-12
# Relative tolerance on "spacing <= 2 radius" (connected chains), to admit 2r up to round-off.
SPACING_RTOL = 1e-12
# A sphere of ellipsoid/superellipsoid may protrude from the body by at most this times
# the largest semi-axis (the inside test of the medial-ball search): 5e4 ulp of the body
# size, above the round-off of the distance computations (a few ulp).
INSIDE_ATOL = 1e-11
# Relative width at which the search for a medial-ball radius stops: the radius is then
# within this fraction (of the body's half-width along the normal) below the largest
# inscribed ball tangent at that point; smaller than any effect on the cover.
MEDIAL_RTOL = 1e-6
# A tangent point whose cusp depth (see superellipsoid) is below this times the largest
# semi-axis is covered: the body is then exactly covered (e.g. a sphere: one ball).
COVERED_ATOL = 1e-9
# Number of Fibonacci directions scanned by the distance search of a superellipsoid
# before local refinement (angular spacing about 0.1 rad), and the number of mutually
# separated best directions refined from in each of its two parametrisations: 6 covers
# the 3 faces at a box corner and the 4 faces at an octahedron vertex (with 3, balls near
# the vertices of exponents 1.05 protruded by 4e-3).  The final check of every ball uses
# VERIFY_STARTS.
SUPPORT_GRID_SIZE = 1024
SUPPORT_STARTS = 6
VERIFY_STARTS = 16
# Newton searches of the superellipsoid distance (directions are unit vectors, so steps
# are angles in radians): stop when the tangential gradient is below NEWTON_GRADIENT_RTOL
# of its scale (amax for the support function, amax^2 for |y - p|^2 / 2) or a full
# Newton step gains less than NEWTON_CONVERGED_RTOL * amax (round-off of the values);
# steps are at most NEWTON_MAX_STEP; the Hessian comes from central differences of the
# analytic gradient with step HESSIAN_FD_STEP (truncation ~1e-12, round-off ~1e-10
# relative: ample for quadratic convergence); Armijo constant ARMIJO_C.
NEWTON_GRADIENT_RTOL = 1e-12
NEWTON_CONVERGED_RTOL = 1e-15
NEWTON_MAX_STEP = 0.5
HESSIAN_FD_STEP = 1e-6
ARMIJO_C = 1e-4
NEWTON_MAX_ITERATIONS = 60
# Start directions of the distance search are at least this angle apart (radians).
START_SEPARATION = 0.5
# Greedy cover: if the medial ball at the nearest surface point of the middle of a
# sample's uncovered segment left more than this fraction of the segment uncovered
# (it should leave at most half; only round-off can make it more), the medial ball at
# the sample itself is taken instead.
PROGRESS_FRACTION = 0.75
# Surface samples (candidate tangent points) per requested sphere, and a floor.
SURFACE_SAMPLES_PER_SPHERE = 16
MIN_SURFACE_SAMPLES = 2048
# Largest superellipsoid exponent (box-like bodies beyond it need very many spheres at the edges).
MAX_EXPONENT = 20.0
# Quaternions passed to rotate() must have |q| within this of 1.
QUATERNION_NORM_ATOL = 1e-6


# ----------------------------------------------------------------------------------------
# argument checks


def _check_int(name, value, minimum):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _check_positive(name, value):
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}") from None
    if not (math.isfinite(v) and v > 0.0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return v


def _check_spacing(spacing, radius):
    spacing = _check_positive("spacing", spacing)
    if spacing > 2.0 * radius * (1.0 + SPACING_RTOL):
        raise ValueError(
            f"spacing must be in (0, 2 * radius] = (0, {2.0 * radius!r}] so that neighbouring "
            f"spheres overlap or touch, got {spacing!r}"
        )
    return spacing


def _check_centres_radii(centres, radii, allow_2d):
    try:
        c = np.array(centres, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError("centres must be a numeric array of shape (n, 3)") from None
    dims = (2, 3) if allow_2d else (3,)
    if c.ndim != 2 or c.shape[1] not in dims or c.shape[0] < 1:
        allowed = "(n, 2) or (n, 3)" if allow_2d else "(n, 3)"
        raise ValueError(f"centres must have shape {allowed} with n >= 1, got {c.shape}")
    if not np.all(np.isfinite(c)):
        raise ValueError("centres must be finite (no NaN or inf)")
    try:
        r = np.array(radii, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"radii must be a numeric array of shape ({c.shape[0]},)") from None
    if r.shape != (c.shape[0],):
        raise ValueError(f"radii must have shape ({c.shape[0]},) to match centres, got {r.shape}")
    if not np.all(np.isfinite(r)) or np.any(r <= 0.0):
        raise ValueError(f"radii must be finite and > 0, got min {np.nanmin(r)!r}")
    if c.shape[1] == 2:
        c = np.hstack([c, np.zeros((c.shape[0], 1))])
    return np.ascontiguousarray(c), np.ascontiguousarray(r)


# ----------------------------------------------------------------------------------------
# centre of mass of a union of spheres


@jit
def _overlap_flags(centres, radii, order, rtol):
    """True for every sphere that overlaps at least one other (sweep over x; ``order``
    sorts the spheres by x - r)."""
    n = radii.shape[0]
    xmin = centres[:, 0] - radii
    flag = np.zeros(n, dtype=np.bool_)
    for a in range(n):
        i = order[a]
        xmax_i = centres[i, 0] + radii[i]
        for b in range(a + 1, n):
            j = order[b]
            if xmin[j] >= xmax_i:
                break
            dx = centres[i, 0] - centres[j, 0]
            dy = centres[i, 1] - centres[j, 1]
            dz = centres[i, 2] - centres[j, 2]
            s = (radii[i] + radii[j]) * (1.0 - rtol)
            if dx * dx + dy * dy + dz * dz < s * s:
                flag[i] = True
                flag[j] = True
    return flag


@jit
def _sift_down(lo, hi, a0, root, end):
    while True:
        child = 2 * root + 1
        if child >= end:
            return
        if child + 1 < end and lo[a0 + child + 1] > lo[a0 + child]:
            child += 1
        if lo[a0 + child] <= lo[a0 + root]:
            return
        tl = lo[a0 + root]
        th = hi[a0 + root]
        lo[a0 + root] = lo[a0 + child]
        hi[a0 + root] = hi[a0 + child]
        lo[a0 + child] = tl
        hi[a0 + child] = th
        root = child


@jit
def _sort_pairs(lo, hi, a0, a1):
    """Sort lo[a0:a1] ascending in place, carrying hi along (insertion sort for short
    runs, heapsort otherwise)."""
    m = a1 - a0
    if m <= 24:
        for p in range(a0 + 1, a1):
            kl = lo[p]
            kh = hi[p]
            q = p - 1
            while q >= a0 and lo[q] > kl:
                lo[q + 1] = lo[q]
                hi[q + 1] = hi[q]
                q -= 1
            lo[q + 1] = kl
            hi[q + 1] = kh
        return
    for root in range(m // 2 - 1, -1, -1):
        _sift_down(lo, hi, a0, root, m)
    for end in range(m - 1, 0, -1):
        tl = lo[a0]
        th = hi[a0]
        lo[a0] = lo[a0 + end]
        hi[a0] = hi[a0 + end]
        lo[a0 + end] = tl
        hi[a0 + end] = th
        _sift_down(lo, hi, a0, 0, end)


@jit
def _column_moments(centres, radii, order, x0, y0, h, nx, ny):
    """Volume and first moments of a union of spheres on a grid of z-columns.

    Column (i, j) is the line x = x0 + (i + 1/2) h, y = y0 + (j + 1/2) h.  Each sphere
    cuts it in an exact interval; the union of the intervals (sort and merge) gives the
    exact length L and exact integral of z over the column.  Volume and moments are
    h^2 sums over the columns (midpoint rule in x and y).  Rows (fixed x) are processed
    one at a time with the spheres whose x-range contains the row (``order`` sorts the
    spheres by x - r).
    """
    n = radii.shape[0]
    xmin = centres[:, 0] - radii
    active = np.empty(n, dtype=np.int64)
    nact = 0
    ptr = 0
    start = np.zeros(ny + 1, dtype=np.int64)
    fill = np.zeros(ny, dtype=np.int64)
    cap = 1024
    col = np.empty(cap, dtype=np.int64)
    lo = np.empty(cap)
    hi = np.empty(cap)
    slo = np.empty(cap)
    shi = np.empty(cap)
    vol = 0.0
    mx = 0.0
    my = 0.0
    mz = 0.0
    for i in range(nx):
        x = x0 + (i + 0.5) * h
        while ptr < n and xmin[order[ptr]] <= x:
            active[nact] = order[ptr]
            nact += 1
            ptr += 1
        k = 0
        total = 0
        for a in range(nact):
            s = active[a]
            if centres[s, 0] + radii[s] >= x:
                active[k] = s
                k += 1
                total += int(2.0 * radii[s] / h) + 2
        nact = k
        if nact == 0:
            continue
        if total > cap:
            cap = 2 * total
            col = np.empty(cap, dtype=np.int64)
            lo = np.empty(cap)
            hi = np.empty(cap)
            slo = np.empty(cap)
            shi = np.empty(cap)
        m = 0
        for a in range(nact):
            s = active[a]
            dx = x - centres[s, 0]
            w2 = radii[s] * radii[s] - dx * dx
            if w2 <= 0.0:
                continue
            w = np.sqrt(w2)
            cy = centres[s, 1]
            cz = centres[s, 2]
            jlo = int(np.ceil((cy - w - y0) / h - 0.5))
            jhi = int(np.floor((cy + w - y0) / h - 0.5))
            if jlo < 0:
                jlo = 0
            if jhi > ny - 1:
                jhi = ny - 1
            for j in range(jlo, jhi + 1):
                dy = y0 + (j + 0.5) * h - cy
                t2 = w2 - dy * dy
                if t2 <= 0.0:
                    continue
                t = np.sqrt(t2)
                col[m] = j
                lo[m] = cz - t
                hi[m] = cz + t
                m += 1
        if m == 0:
            continue
        start[:] = 0
        for q in range(m):
            start[col[q] + 1] += 1
        for j in range(ny):
            start[j + 1] += start[j]
        for j in range(ny):
            fill[j] = start[j]
        for q in range(m):
            p = fill[col[q]]
            slo[p] = lo[q]
            shi[p] = hi[q]
            fill[col[q]] += 1
        row_v = 0.0
        row_my = 0.0
        row_mz = 0.0
        for j in range(ny):
            a0 = start[j]
            a1 = start[j + 1]
            if a1 == a0:
                continue
            _sort_pairs(slo, shi, a0, a1)
            cur_lo = slo[a0]
            cur_hi = shi[a0]
            length = 0.0
            zmom = 0.0
            for q in range(a0 + 1, a1):
                if slo[q] > cur_hi:
                    length += cur_hi - cur_lo
                    zmom += 0.5 * (cur_hi - cur_lo) * (cur_hi + cur_lo)
                    cur_lo = slo[q]
                    cur_hi = shi[q]
                elif shi[q] > cur_hi:
                    cur_hi = shi[q]
            length += cur_hi - cur_lo
            zmom += 0.5 * (cur_hi - cur_lo) * (cur_hi + cur_lo)
            row_v += length
            row_my += (y0 + (j + 0.5) * h) * length
            row_mz += zmom
        vol += row_v
        mx += x * row_v
        my += row_my
        mz += row_mz
    a = h * h
    return vol * a, mx * a, my * a, mz * a


def _order_by_xmin(centres, radii):
    return np.argsort(centres[:, 0] - radii, kind="stable").astype(np.int64)


def centre_of_mass_of_union(centres, radii, resolution=DEFAULT_UNION_RESOLUTION):
    """Centre of mass and volume of the union of spheres (overlaps counted once).

    How it integrates.  Spheres that overlap no other sphere (touching counts as not
    overlapping, see ``OVERLAP_RTOL``) contribute their exact volume ``4/3 pi r^3`` at
    their centre.  The others are integrated on a grid of vertical lines ("columns")
    spaced ``h = mean radius / resolution`` (mean over the overlapping spheres) in x
    and y, laid symmetrically over their bounding box: on each column the spheres cut
    exact intervals in z, whose union (sort and merge) gives the exact covered length
    and the exact integral of z; volume and first moments are then the midpoint rule in
    x and y.  The only error is that of the 2D midpoint rule for a function with
    square-root edges at the sphere silhouettes, decreasing about as h^2.  A shape
    symmetric under reflection through its bounding-box centre gets its centre of mass
    there up to round-off.

    Accuracy (measured against the analytic union of two overlapping spheres with
    radius ratio 0.5-1 in random orientation, and against resolution 160 for random
    clusters of 3 to 200 overlapping spheres of radius ratio up to 3): at the default
    resolution 32 the relative error of the volume is below 2e-4 and the error of the
    centre of mass below 3e-4 mean radii (at 16: 1e-3 and 6e-4; at 64 about 4 times
    smaller than at 32).  Spheres much smaller than the mean radius are resolved by
    fewer columns and carry a larger relative error.

    Cost: about ``pi * resolution^2`` intervals per overlapping sphere.  Measured at the
    default resolution on one core: 1.3-2.2 s for the 6,241 heavily overlapping spheres
    of ``ellipsoid((2, 1.5, 1), 6241)``, 1.4 s for 6,000 random overlapping spheres of
    radius 0.5-1 in a 12 x 8 x 6 ellipsoid, 0.5 s for a 6,000-sphere overlapping
    chain; non-overlapping spheres cost nothing.

    Parameters
    ----------
    centres : (n, 3) array
    radii : (n,) array of positive numbers
    resolution : float > 0, grid columns per mean radius

    Returns
    -------
    com : (3,) float64
    volume : float
    """
    c, r = _check_centres_radii(centres, radii, allow_2d=False)
    resolution = _check_positive("resolution", resolution)
    overlapping = _overlap_flags(c, r, _order_by_xmin(c, r), OVERLAP_RTOL)
    isolated = ~overlapping
    v_iso = 4.0 / 3.0 * np.pi * r[isolated] ** 3
    volume = float(v_iso.sum())
    moment = (v_iso[:, None] * c[isolated]).sum(axis=0)
    if overlapping.any():
        co = np.ascontiguousarray(c[overlapping])
        ro = np.ascontiguousarray(r[overlapping])
        h = float(ro.mean()) / resolution
        lower = (co - ro[:, None]).min(axis=0)
        upper = (co + ro[:, None]).max(axis=0)
        mid = 0.5 * (lower + upper)
        nx = int(math.ceil((upper[0] - lower[0]) / h))
        ny = int(math.ceil((upper[1] - lower[1]) / h))
        x0 = mid[0] - 0.5 * nx * h
        y0 = mid[1] - 0.5 * ny * h
        v, mx, my, mz = _column_moments(co, ro, _order_by_xmin(co, ro), x0, y0, h, nx, ny)
        volume += v
        moment = moment + np.array([mx, my, mz])
    return moment / volume, volume


def _recentre(centres, radii):
    com, _ = centre_of_mass_of_union(centres, radii)
    return np.ascontiguousarray(centres - com), np.ascontiguousarray(radii, dtype=np.float64)


# ----------------------------------------------------------------------------------------
# simple shapes


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



# ----------------------------------------------------------------------------------------
# ellipsoids and superellipsoids: geometry kernels


@jit
def _robust_length(v0, v1, v2):
    m = max(abs(v0), abs(v1), abs(v2))
    if m == 0.0:
        return 0.0
    a = v0 / m
    b = v1 / m
    c = v2 / m
    return m * np.sqrt(a * a + b * b + c * c)


@jit
def _eberly_root2(r0, z0, z1, g):
    """Root sigma = s + 1 of (r0 z0 / (sigma - 1 + r0))^2 + (z1 / sigma)^2 = 1 (Eberly's
    GetRoot for the ellipse, shifted: bisection on sigma keeps full relative precision
    of sigma, and of x1 = y1 / sigma, when z1 is tiny)."""
    n0 = r0 * z0
    m0 = r0 - 1.0  # sigma + (r0 - 1), not (sigma - 1) + r0: exact for equal axes
    s0 = z1
    s1 = 1.0 if g < 0.0 else _robust_length(n0, z1, 0.0)
    s = 0.0
    for _ in range(2200):
        s = 0.5 * (s0 + s1)
        if s == s0 or s == s1:
            break
        a = n0 / (s + m0)
        b = z1 / s
        gg = a * a + b * b - 1.0
        if gg > 0.0:
            s0 = s
        elif gg < 0.0:
            s1 = s
        else:
            break
    return s


@jit
def _eberly_root3(r0, r1, z0, z1, z2, g):
    """Root sigma = s + 1 of Eberly's GetRoot for the ellipsoid (see _eberly_root2)."""
    n0 = r0 * z0
    n1 = r1 * z1
    m0 = r0 - 1.0  # sigma + (r_i - 1), not (sigma - 1) + r_i: exact for equal axes
    m1 = r1 - 1.0
    s0 = z2
    s1 = 1.0 if g < 0.0 else _robust_length(n0, n1, z2)
    s = 0.0
    for _ in range(2200):
        s = 0.5 * (s0 + s1)
        if s == s0 or s == s1:
            break
        a = n0 / (s + m0)
        b = n1 / (s + m1)
        c = z2 / s
        gg = a * a + b * b + c * c - 1.0
        if gg > 0.0:
            s0 = s
        elif gg < 0.0:
            s1 = s
        else:
            break
    return s


@jit
def _ellipse_closest(e0, e1, y0, y1):
    """Closest point (x0, x1) to (y0, y1) >= 0 on the ellipse with semi-axes e0 >= e1 (Eberly)."""
    if y1 > 0.0:
        if y0 > 0.0:
            z0 = y0 / e0
            z1 = y1 / e1
            g = z0 * z0 + z1 * z1 - 1.0
            if g != 0.0:
                r0 = (e0 / e1) ** 2
                sigma = _eberly_root2(r0, z0, z1, g)
                return r0 * y0 / (sigma + (r0 - 1.0)), y1 / sigma
            return y0, y1
        return 0.0, e1
    numer0 = e0 * y0
    denom0 = e0 * e0 - e1 * e1
    if numer0 < denom0:
        xde0 = numer0 / denom0
        return e0 * xde0, e1 * np.sqrt(1.0 - xde0 * xde0)
    return e0, 0.0


@jit
def _ellipsoid_closest(p, e, perm, out):
    """Distance from p to the ellipsoid surface; the closest surface point goes to ``out``.

    D. Eberly, "Distance from a point to an ellipse, an ellipsoid, or a hyperellipsoid"
    (Geometric Tools, 2013): in the first octant and with the semi-axes sorted
    (``e`` descending, ``perm[i]`` the coordinate of p that goes with ``e[i]``) the
    closest point is x_i = r_i y_i / (s + r_i) (r_i = e_i^2 / e_2^2) with s the unique
    root of a monotone function, found by bisection to full precision; points on a
    coordinate plane and equal axes are handled by the separate branches of the paper.
    Unlike the paper we bisect on sigma = s + 1, so that x_2 = y_2 / sigma keeps full
    relative precision for points very near the plane of the two largest axes, where
    the medial balls of an ellipsoid have their centres (bisecting on s lost up to 4e-7
    of the distance there), and we form sigma + (r_i - 1), exact for equal axes.  Works for points inside and outside.
    """
    e0 = e[0]
    e1 = e[1]
    e2 = e[2]
    y0 = abs(p[perm[0]])
    y1 = abs(p[perm[1]])
    y2 = abs(p[perm[2]])
    x0 = 0.0
    x1 = 0.0
    x2 = 0.0
    if y2 > 0.0:
        if y1 > 0.0:
            if y0 > 0.0:
                z0 = y0 / e0
                z1 = y1 / e1
                z2 = y2 / e2
                g = z0 * z0 + z1 * z1 + z2 * z2 - 1.0
                if g != 0.0:
                    r0 = (e0 / e2) ** 2
                    r1 = (e1 / e2) ** 2
                    sigma = _eberly_root3(r0, r1, z0, z1, z2, g)
                    x0 = r0 * y0 / (sigma + (r0 - 1.0))
                    x1 = r1 * y1 / (sigma + (r1 - 1.0))
                    x2 = y2 / sigma
                else:
                    x0 = y0
                    x1 = y1
                    x2 = y2
            else:
                x1, x2 = _ellipse_closest(e1, e2, y1, y2)
        elif y0 > 0.0:
            x0, x2 = _ellipse_closest(e0, e2, y0, y2)
        else:
            x2 = e2
    else:
        denom0 = e0 * e0 - e2 * e2
        denom1 = e1 * e1 - e2 * e2
        numer0 = e0 * y0
        numer1 = e1 * y1
        computed = False
        if numer0 < denom0 and numer1 < denom1:
            xde0 = numer0 / denom0
            xde1 = numer1 / denom1
            discr = 1.0 - xde0 * xde0 - xde1 * xde1
            if discr > 0.0:
                x0 = e0 * xde0
                x1 = e1 * xde1
                x2 = e2 * np.sqrt(discr)
                computed = True
        if not computed:
            x0, x1 = _ellipse_closest(e0, e1, y0, y1)
    dist = np.sqrt((x0 - y0) ** 2 + (x1 - y1) ** 2 + (x2 - y2) ** 2)
    out[perm[0]] = x0 if p[perm[0]] >= 0.0 else -x0
    out[perm[1]] = x1 if p[perm[1]] >= 0.0 else -x1
    out[perm[2]] = x2 if p[perm[2]] >= 0.0 else -x2
    return dist


@jit
def _implicit(p, axes, n1, n2):
    """F(x) = (|x/a|^n2 + |y/b|^n2)^(n1/n2) + |z/c|^n1; the body is F <= 1."""
    u = abs(p[0] / axes[0]) ** n2 + abs(p[1] / axes[1]) ** n2
    return u ** (n1 / n2) + abs(p[2] / axes[2]) ** n1


@jit
def _support(n, axes, q1, q2, x):
    """Support function h(n) = max_{y in body} n.y of the superellipsoid; x <- its gradient.

    h(n) = N*(a n_x, b n_y, c n_z) with the dual norm
    N*(m) = ((|m_x|^q2 + |m_y|^q2)^(q1/q2) + |m_z|^q1)^(1/q1), q_i = e_i / (e_i - 1);
    the gradient of h is the support point, the surface point with outward normal n.
    Homogeneous: n need not be a unit vector.
    """
    m0 = axes[0] * n[0]
    m1 = axes[1] * n[1]
    m2 = axes[2] * n[2]
    big = max(abs(m0), abs(m1), abs(m2))
    if big == 0.0:
        x[0] = 0.0
        x[1] = 0.0
        x[2] = 0.0
        return 0.0
    a0 = abs(m0) / big
    a1 = abs(m1) / big
    a2 = abs(m2) / big
    p0 = a0**q2 if a0 > 0.0 else 0.0
    p1 = a1**q2 if a1 > 0.0 else 0.0
    p2 = a2**q1 if a2 > 0.0 else 0.0
    u = p0 + p1
    w = u ** (q1 / q2) if u > 0.0 else 0.0
    S = w + p2  # >= 1e-300: the largest of a0, a1, a2 is 1
    value = S ** (1.0 / q1)
    pre = value / S
    gz = pre * p2 / a2 if a2 > 0.0 else 0.0
    if u > 0.0:
        pu = pre * w / u
        gx = pu * p0 / a0 if a0 > 0.0 else 0.0
        gy = pu * p1 / a1 if a1 > 0.0 else 0.0
    else:
        gx = 0.0
        gy = 0.0
    x[0] = axes[0] * (gx if m0 >= 0.0 else -gx)
    x[1] = axes[1] * (gy if m1 >= 0.0 else -gy)
    x[2] = axes[2] * (gz if m2 >= 0.0 else -gz)
    return big * value


@jit
def _tangent_basis(n, t1, t2):
    ax = abs(n[0])
    ay = abs(n[1])
    az = abs(n[2])
    # cross(n, e_k) with e_k the axis least aligned with n
    if ax <= ay and ax <= az:
        t1[0] = 0.0
        t1[1] = n[2]
        t1[2] = -n[1]
    elif ay <= az:
        t1[0] = -n[2]
        t1[1] = 0.0
        t1[2] = n[0]
    else:
        t1[0] = n[1]
        t1[1] = -n[0]
        t1[2] = 0.0
    norm = np.sqrt(t1[0] * t1[0] + t1[1] * t1[1] + t1[2] * t1[2])
    t1[0] /= norm
    t1[1] /= norm
    t1[2] /= norm
    t2[0] = n[1] * t1[2] - n[2] * t1[1]
    t2[1] = n[2] * t1[0] - n[0] * t1[2]
    t2[2] = n[0] * t1[1] - n[1] * t1[0]


@jit
def _newton_step(h11, h12, h22, g1, g2, gradient_scale):
    """Step d solving (H + mu I) d = -g for a symmetric 2x2 H, Levenberg-Marquardt style.

    mu lifts the smallest eigenvalue to at least 1e-6 of the largest, so a flat direction
    (a ring of equal minima on a symmetry axis) gets no spurious large step while the
    curved directions converge quadratically.  Without positive curvature: a gradient
    step scaled by gradient_scale.
    """
    mean = 0.5 * (h11 + h22)
    rad = np.sqrt(0.25 * (h11 - h22) ** 2 + h12 * h12)
    lmax = mean + rad
    lmin = mean - rad
    if not lmax > 0.0:
        return -g1 * gradient_scale, -g2 * gradient_scale
    mu = max(0.0, 1e-6 * lmax - lmin)
    a = h11 + mu
    b = h22 + mu
    det = a * b - h12 * h12
    return -(b * g1 - h12 * g2) / det, -(a * g2 - h12 * g1) / det


@jit
def _refine_support(n, p, axes, q1, q2, amax, threshold):
    """Local minimum of g(n) = h(n) - n.p over unit vectors n, starting from (and updating) n.

    Newton's method on the sphere in tangent coordinates: gradient t_i.(x*(n) - p),
    Hessian t_i.H t_j - g delta_ij with H t = d x*/dt by central differences of the
    support point x*; Levenberg-Marquardt shift (:func:`_newton_step`); step at most
    NEWTON_MAX_STEP; Armijo backtracking, so g only decreases and every value is an
    upper bound on the distance.  Stops early once g < threshold.
    """
    x = np.empty(3)
    xa = np.empty(3)
    xb = np.empty(3)
    nn = np.empty(3)
    t1 = np.empty(3)
    t2 = np.empty(3)
    ht1 = np.empty(3)
    ht2 = np.empty(3)
    g = _support(n, axes, q1, q2, x) - (n[0] * p[0] + n[1] * p[1] + n[2] * p[2])
    tol2 = (NEWTON_GRADIENT_RTOL * amax) ** 2
    eps = HESSIAN_FD_STEP
    for _ in range(NEWTON_MAX_ITERATIONS):
        if g < threshold:
            break
        _tangent_basis(n, t1, t2)
        r0 = x[0] - p[0]
        r1 = x[1] - p[1]
        r2 = x[2] - p[2]
        g1 = t1[0] * r0 + t1[1] * r1 + t1[2] * r2
        g2 = t2[0] * r0 + t2[1] * r1 + t2[2] * r2
        gn2 = g1 * g1 + g2 * g2
        if gn2 <= tol2:
            break
        for i in range(3):
            nn[i] = n[i] + eps * t1[i]
        _support(nn, axes, q1, q2, xa)
        for i in range(3):
            nn[i] = n[i] - eps * t1[i]
        _support(nn, axes, q1, q2, xb)
        for i in range(3):
            ht1[i] = (xa[i] - xb[i]) / (2.0 * eps)
        for i in range(3):
            nn[i] = n[i] + eps * t2[i]
        _support(nn, axes, q1, q2, xa)
        for i in range(3):
            nn[i] = n[i] - eps * t2[i]
        _support(nn, axes, q1, q2, xb)
        for i in range(3):
            ht2[i] = (xa[i] - xb[i]) / (2.0 * eps)
        h11 = t1[0] * ht1[0] + t1[1] * ht1[1] + t1[2] * ht1[2] - g
        h22 = t2[0] * ht2[0] + t2[1] * ht2[1] + t2[2] * ht2[2] - g
        h12 = 0.5 * (t1[0] * ht2[0] + t1[1] * ht2[1] + t1[2] * ht2[2] + t2[0] * ht1[0] + t2[1] * ht1[1] + t2[2] * ht1[2])
        d1, d2 = _newton_step(h11, h12, h22, g1, g2, 1.0 / amax)
        step = np.sqrt(d1 * d1 + d2 * d2)
        if step > NEWTON_MAX_STEP:
            d1 *= NEWTON_MAX_STEP / step
            d2 *= NEWTON_MAX_STEP / step
        slope = g1 * d1 + g2 * d2
        accepted = False
        full = True
        gg = g
        for _bt in range(50):
            for i in range(3):
                nn[i] = n[i] + d1 * t1[i] + d2 * t2[i]
            norm = np.sqrt(nn[0] * nn[0] + nn[1] * nn[1] + nn[2] * nn[2])
            for i in range(3):
                nn[i] /= norm
            gg = _support(nn, axes, q1, q2, xa) - (nn[0] * p[0] + nn[1] * p[1] + nn[2] * p[2])
            if gg <= g + ARMIJO_C * slope and gg < g:
                accepted = True
                break
            full = False
            d1 *= 0.5
            d2 *= 0.5
        if not accepted:
            break
        for i in range(3):
            n[i] = nn[i]
            x[i] = xa[i]
        converged = full and g - gg <= NEWTON_CONVERGED_RTOL * amax
        g = gg
        if converged:
            break
    return g


@jit
def _radial(u, axes, n1, n2, y, dy1, dy2, t1, t2):
    """Surface point y(u) = F(u)^(-1/n1) u in direction u, and its derivatives along t1, t2.

    F is homogeneous of degree n1, so y is homogeneous of degree 0 in u (u need not be a
    unit vector) and dy/du = t I + u (grad t)^T with grad t = -t / (n1 F) grad F.
    """
    a0 = abs(u[0] / axes[0])
    a1 = abs(u[1] / axes[1])
    a2 = abs(u[2] / axes[2])
    p0 = a0**n2 if a0 > 0.0 else 0.0
    p1 = a1**n2 if a1 > 0.0 else 0.0
    p2 = a2**n1 if a2 > 0.0 else 0.0
    w = p0 + p1
    Fw = w ** (n1 / n2) if w > 0.0 else 0.0
    F = Fw + p2
    t = F ** (-1.0 / n1)
    pw = n1 * Fw / w if w > 0.0 else 0.0
    g0 = pw * p0 / (a0 * axes[0]) if a0 > 0.0 else 0.0
    g1 = pw * p1 / (a1 * axes[1]) if a1 > 0.0 else 0.0
    g2 = n1 * p2 / (a2 * axes[2]) if a2 > 0.0 else 0.0
    if u[0] < 0.0:
        g0 = -g0
    if u[1] < 0.0:
        g1 = -g1
    if u[2] < 0.0:
        g2 = -g2
    c = -t / (n1 * F)
    dt1 = c * (g0 * t1[0] + g1 * t1[1] + g2 * t1[2])
    dt2 = c * (g0 * t2[0] + g1 * t2[1] + g2 * t2[2])
    for i in range(3):
        y[i] = t * u[i]
        dy1[i] = t * t1[i] + dt1 * u[i]
        dy2[i] = t * t2[i] + dt2 * u[i]


@jit
def _refine_radial(u, p, axes, n1, n2, amax, threshold):
    """Local minimum of |y(u) - p| over directions u (y on the surface), from (and updating) u.

    The primal counterpart of :func:`_refine_support`: Newton's method in tangent
    coordinates on f = |y(u) - p|^2 / 2 with the analytic gradient and a
    central-difference Hessian, Armijo backtracking, steps at most NEWTON_MAX_STEP.  Every value
    is the distance to a surface point, an upper bound on the distance to the surface.
    It converges fast where the surface is flat (large exponents), where the support
    function is nearly non-differentiable.
    """
    y = np.empty(3)
    dy1 = np.empty(3)
    dy2 = np.empty(3)
    ya = np.empty(3)
    da1 = np.empty(3)
    da2 = np.empty(3)
    uu = np.empty(3)
    t1 = np.empty(3)
    t2 = np.empty(3)
    hh = np.empty(4)
    _tangent_basis(u, t1, t2)
    _radial(u, axes, n1, n2, y, dy1, dy2, t1, t2)
    f = np.sqrt((y[0] - p[0]) ** 2 + (y[1] - p[1]) ** 2 + (y[2] - p[2]) ** 2)
    eps = HESSIAN_FD_STEP
    tol2 = (NEWTON_GRADIENT_RTOL * amax * amax) ** 2
    for _ in range(NEWTON_MAX_ITERATIONS):
        if f < threshold:
            break
        _tangent_basis(u, t1, t2)
        _radial(u, axes, n1, n2, y, dy1, dy2, t1, t2)
        r0 = y[0] - p[0]
        r1 = y[1] - p[1]
        r2 = y[2] - p[2]
        g1 = r0 * dy1[0] + r1 * dy1[1] + r2 * dy1[2]
        g2 = r0 * dy2[0] + r1 * dy2[1] + r2 * dy2[2]
        if g1 * g1 + g2 * g2 <= tol2:
            break
        # Hessian of f by central differences of the gradient in the fixed frame (t1, t2)
        for jdir in range(2):
            for i in range(3):
                uu[i] = u[i] + eps * (t1[i] if jdir == 0 else t2[i])
            _radial(uu, axes, n1, n2, ya, da1, da2, t1, t2)
            s0 = ya[0] - p[0]
            s1 = ya[1] - p[1]
            s2 = ya[2] - p[2]
            hp1 = s0 * da1[0] + s1 * da1[1] + s2 * da1[2]
            hp2 = s0 * da2[0] + s1 * da2[1] + s2 * da2[2]
            for i in range(3):
                uu[i] = u[i] - eps * (t1[i] if jdir == 0 else t2[i])
            _radial(uu, axes, n1, n2, ya, da1, da2, t1, t2)
            s0 = ya[0] - p[0]
            s1 = ya[1] - p[1]
            s2 = ya[2] - p[2]
            hm1 = s0 * da1[0] + s1 * da1[1] + s2 * da1[2]
            hm2 = s0 * da2[0] + s1 * da2[1] + s2 * da2[2]
            hh[2 * jdir] = (hp1 - hm1) / (2.0 * eps)
            hh[2 * jdir + 1] = (hp2 - hm2) / (2.0 * eps)
        h11 = hh[0]
        h22 = hh[3]
        h12 = 0.5 * (hh[1] + hh[2])
        d1, d2 = _newton_step(h11, h12, h22, g1, g2, 1.0 / (amax * amax))
        step = np.sqrt(d1 * d1 + d2 * d2)
        if step > NEWTON_MAX_STEP:
            d1 *= NEWTON_MAX_STEP / step
            d2 *= NEWTON_MAX_STEP / step
        slope = g1 * d1 + g2 * d2
        half = 0.5 * f * f
        accepted = False
        full = True
        fn = f
        for _bt in range(50):
            for i in range(3):
                uu[i] = u[i] + d1 * t1[i] + d2 * t2[i]
            norm = np.sqrt(uu[0] * uu[0] + uu[1] * uu[1] + uu[2] * uu[2])
            for i in range(3):
                uu[i] /= norm
            _radial(uu, axes, n1, n2, ya, da1, da2, t1, t2)
            fn = np.sqrt((ya[0] - p[0]) ** 2 + (ya[1] - p[1]) ** 2 + (ya[2] - p[2]) ** 2)
            if 0.5 * fn * fn <= half + ARMIJO_C * slope and fn < f:
                accepted = True
                break
            full = False
            d1 *= 0.5
            d2 *= 0.5
        if not accepted:
            break
        for i in range(3):
            u[i] = uu[i]
        converged = full and f - fn <= NEWTON_CONVERGED_RTOL * amax
        f = fn
        if converged:
            break
    return f


@jit
def _radial_normal(u, axes, n1, n2, q_out, nu_out):
    """Surface point y(u) -> q_out and its outward unit normal (t1' x t2') -> nu_out."""
    t1 = np.empty(3)
    t2 = np.empty(3)
    d1 = np.empty(3)
    d2 = np.empty(3)
    _tangent_basis(u, t1, t2)
    _radial(u, axes, n1, n2, q_out, d1, d2, t1, t2)
    nu_out[0] = d1[1] * d2[2] - d1[2] * d2[1]
    nu_out[1] = d1[2] * d2[0] - d1[0] * d2[2]
    nu_out[2] = d1[0] * d2[1] - d1[1] * d2[0]
    norm = np.sqrt(nu_out[0] ** 2 + nu_out[1] ** 2 + nu_out[2] ** 2)
    if nu_out[0] * q_out[0] + nu_out[1] * q_out[1] + nu_out[2] * q_out[2] < 0.0:
        norm = -norm
    for i in range(3):
        nu_out[i] /= norm


@jit
def _separated_best(vals, dirs, origin, chosen, nc, cos_sep):
    """Index of the smallest value whose direction (row of dirs minus origin, normalised)
    is more than the separation angle away from every already chosen one; -1 if none."""
    kbest = -1
    vbest = np.inf
    for k in range(vals.shape[0]):
        if vals[k] < vbest:
            a0 = dirs[k, 0] - origin[0]
            a1 = dirs[k, 1] - origin[1]
            a2 = dirs[k, 2] - origin[2]
            na = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
            ok = True
            for c in range(nc):
                j = chosen[c]
                b0 = dirs[j, 0] - origin[0]
                b1 = dirs[j, 1] - origin[1]
                b2 = dirs[j, 2] - origin[2]
                nb = np.sqrt(b0 * b0 + b1 * b1 + b2 * b2)
                if a0 * b0 + a1 * b1 + a2 * b2 > cos_sep * na * nb:
                    ok = False
                    break
            if ok:
                vbest = vals[k]
                kbest = k
    return kbest


@jit
def _superellipsoid_min(p, axes, n1, n2, q1, q2, grid, amax, n_starts, threshold, q_out, nu_out, methods=3):
    """Distance of an interior point p to the surface of a convex superellipsoid.

    Two independent local searches, each of whose values is an upper bound on the
    distance; the result is the smaller of those run (``methods``: bit 1 dual, bit 2
    primal):

    - dual: for a convex body the distance from an interior point to the boundary is
      the distance to the nearest supporting plane, min over unit n of h(n) - n.p with
      h the closed-form support function (:func:`_support`); negative outside;
    - primal: min over directions u of |y(u) - p|, y(u) the surface point in direction u.

    Each scans fixed directions (``grid`` rows: normal n, h(n), direction u, y(u)) and
    refines the best ``n_starts`` mutually separated ones by Newton's method
    (:func:`_refine_support`, :func:`_refine_radial`): normals more than
    START_SEPARATION apart, and surface points more than START_SEPARATION apart as seen
    from p, so that the nearest points on two faces meeting at an edge both get a start.
    Returns early, with a value below ``threshold``, as soon as one is found.  The
    nearest surface point found goes to q_out and its outward unit normal to nu_out.
    """
    m = grid.shape[0]
    gn = grid[:, 0:3]
    gu = grid[:, 4:7]
    gy = grid[:, 7:10]
    zero = np.zeros(3)
    vd = np.empty(m)
    vp = np.empty(m)
    kd = 0
    kp = 0
    for k in range(m):
        vd[k] = grid[k, 3] - (grid[k, 0] * p[0] + grid[k, 1] * p[1] + grid[k, 2] * p[2])
        vp[k] = np.sqrt((grid[k, 7] - p[0]) ** 2 + (grid[k, 8] - p[1]) ** 2 + (grid[k, 9] - p[2]) ** 2)
        if vd[k] < vd[kd]:
            kd = k
        if vp[k] < vp[kp]:
            kp = k
    if methods & 1 and vd[kd] < threshold:
        for i in range(3):
            nu_out[i] = gn[kd, i]
        _support(nu_out, axes, q1, q2, q_out)
        return vd[kd]
    if methods & 2 and vp[kp] < threshold:
        _radial_normal(gu[kp], axes, n1, n2, q_out, nu_out)
        return vp[kp]
    cos_sep = np.cos(START_SEPARATION)
    chosen = np.empty(n_starts, dtype=np.int64)
    n = np.empty(3)
    best = np.inf
    # dual
    nc = 0
    for _ in range(n_starts if methods & 1 else 0):
        kbest = _separated_best(vd, gn, zero, chosen, nc, cos_sep)
        if kbest < 0:
            break
        chosen[nc] = kbest
        nc += 1
        for i in range(3):
            n[i] = gn[kbest, i]
        v = _refine_support(n, p, axes, q1, q2, amax, threshold)
        if v < best:
            best = v
            _support(n, axes, q1, q2, q_out)
            for i in range(3):
                nu_out[i] = n[i]
        if best < threshold:
            return best
    # primal
    nc = 0
    for _ in range(n_starts if methods & 2 else 0):
        kbest = _separated_best(vp, gy, p, chosen, nc, cos_sep)
        if kbest < 0:
            break
        chosen[nc] = kbest
        nc += 1
        for i in range(3):
            n[i] = gu[kbest, i]
        v = _refine_radial(n, p, axes, n1, n2, amax, threshold)
        if v < best:
            best = v
            _radial_normal(n, axes, n1, n2, q_out, nu_out)
        if best < threshold:
            return best
    return best


@jit
def _ball_test(kind, c, rho, s, nu, axes, n1, n2, e_sorted, perm, q1, q2, grid, amax, n_starts):
    """Test whether the ball B(c, rho), tangent to the surface at s with outward normal
    nu (c = s - rho nu), is inside the body: distance(c) >= rho - INSIDE_ATOL * amax.

    Returns inf if it is.  If not, returns an upper bound on the radius of the largest
    ball inside tangent at s (below rho): the search found a surface point y with
    outward normal m whose supporting plane the ball crosses; every tangent ball at s of
    radius above m.(y - s) / (1 - m.nu) crosses that plane too (the body is convex).

    ``kind``: 0 ellipsoid (Eberly's exact distance); otherwise a superellipsoid with the
    bit mask of :func:`_superellipsoid_min` (2: surface-point search, 3: and the
    support-function search).
    """
    tol = INSIDE_ATOL * amax
    if _implicit(c, axes, n1, n2) > 1.0:
        return rho
    y = np.empty(3)
    m = np.empty(3)
    if kind == 0:
        d = _ellipsoid_closest(c, e_sorted, perm, y)
        if d >= rho - tol:
            return np.inf
        for i in range(3):
            m[i] = y[i] / (axes[i] * axes[i])
        norm = np.sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2])
        for i in range(3):
            m[i] /= norm
    else:
        d = _superellipsoid_min(c, axes, n1, n2, q1, q2, grid, amax, n_starts, rho - tol, y, m, kind)
        if d >= rho - tol:
            return np.inf
    denom = 1.0 - (m[0] * nu[0] + m[1] * nu[1] + m[2] * nu[2])
    if denom <= 1e-12:  # m = nu within round-off: the plane is the tangent plane at s
        return rho
    bound = (m[0] * (y[0] - s[0]) + m[1] * (y[1] - s[1]) + m[2] * (y[2] - s[2])) / denom
    return min(max(bound, 0.0), rho)


@jit
def _nearest_surface_point(kind, x, axes, n1, n2, e_sorted, perm, q1, q2, grid, amax, n_starts, q, nu):
    """Nearest surface point q of an interior point x, and the outward normal nu there."""
    if kind == 0:
        _ellipsoid_closest(x, e_sorted, perm, q)
        for i in range(3):
            nu[i] = q[i] / (axes[i] * axes[i])
        norm = np.sqrt(nu[0] * nu[0] + nu[1] * nu[1] + nu[2] * nu[2])
        for i in range(3):
            nu[i] /= norm
    else:
        _superellipsoid_min(x, axes, n1, n2, q1, q2, grid, amax, n_starts, -np.inf, q, nu, kind)


@jit
def _medial_radius(s, nu, rho_max, kind, axes, n1, n2, e_sorted, perm, q1, q2, grid, amax, n_starts):
    """Radius of the largest ball inside the body tangent to the surface at s.

    The balls B(s - rho nu, rho) (nu the outward normal at s) are nested in rho, so the
    radius rho* of the largest one inside is the end of the interval of feasible rho:
    a bracket [lo, hi] (lo feasible) is shrunk to MEDIAL_RTOL * rho_max.  Every
    failed test lowers hi to the bound of :func:`_ball_test`, which converges fast to
    rho* from above.  The next trial backs off from hi by ``width * 4^j / 2`` after j
    consecutive failures, but never goes below the midpoint of the bracket (so the
    bracket at least halves every two failures).  Returns lo, a tested feasible radius.
    """
    c = np.empty(3)
    width = MEDIAL_RTOL * rho_max
    lo = 0.0
    hi = rho_max
    trial = rho_max
    fails = 0
    for _ in range(200):
        for i in range(3):
            c[i] = s[i] - trial * nu[i]
        bound = _ball_test(kind, c, trial, s, nu, axes, n1, n2, e_sorted, perm, q1, q2, grid, amax, n_starts)
        if bound == np.inf:
            lo = trial
            fails = 0
        else:
            hi = max(min(trial, bound), lo)
            fails += 1
        if hi - lo <= width:
            break
        trial = max(hi - 0.5 * width * 4.0**fails, 0.5 * (lo + hi))
    return lo


@jit
def _chords(samples, normals, widths, axes, n1, n2):
    """Length of the inward normal line of each surface sample inside the (convex) body."""
    m = samples.shape[0]
    out = np.empty(m)
    c = np.empty(3)
    for k in range(m):
        lo = 0.0
        hi = widths[k]
        for _ in range(60):  # 2^-60 of the width: full precision
            mid = 0.5 * (lo + hi)
            for i in range(3):
                c[i] = samples[k, i] - mid * normals[k, i]
            if _implicit(c, axes, n1, n2) <= 1.0:
                lo = mid
            else:
                hi = mid
        out[k] = lo
    return out


@jit
def _entry_depth(s, nu, cx, cy, cz, rho):
    """Depth along the inward normal line s - t nu (t >= 0) at which it enters B(c, rho); inf if never."""
    v0 = s[0] - cx
    v1 = s[1] - cy
    v2 = s[2] - cz
    b = v0 * nu[0] + v1 * nu[1] + v2 * nu[2]
    disc = b * b - (v0 * v0 + v1 * v1 + v2 * v2 - rho * rho)
    if disc < 0.0:
        return np.inf
    sq = np.sqrt(disc)
    if b + sq < 0.0:
        return np.inf
    return max(b - sq, 0.0)


@jit
def _heap_before(ka, ia, kb, ib):
    """Heap order: larger depth first, then lower sample index."""
    return ka > kb or (ka == kb and ia < ib)


@jit
def _heap_push(hkey, hidx, hn, key, idx):
    i = hn
    hkey[i] = key
    hidx[i] = idx
    while i > 0:
        parent = (i - 1) // 2
        if not _heap_before(hkey[i], hidx[i], hkey[parent], hidx[parent]):
            break
        tk = hkey[i]
        ti = hidx[i]
        hkey[i] = hkey[parent]
        hidx[i] = hidx[parent]
        hkey[parent] = tk
        hidx[parent] = ti
        i = parent
    return hn + 1


@jit
def _heap_pop(hkey, hidx, hn):
    """Remove the top entry; returns the new size."""
    hn -= 1
    hkey[0] = hkey[hn]
    hidx[0] = hidx[hn]
    i = 0
    while True:
        left = 2 * i + 1
        if left >= hn:
            break
        best = left
        right = left + 1
        if right < hn and _heap_before(hkey[right], hidx[right], hkey[left], hidx[left]):
            best = right
        if not _heap_before(hkey[best], hidx[best], hkey[i], hidx[i]):
            break
        tk = hkey[i]
        ti = hidx[i]
        hkey[i] = hkey[best]
        hidx[i] = hidx[best]
        hkey[best] = tk
        hidx[best] = ti
        i = best
    return hn


def _sample_cells(samples, axes):
    """Cell list over the surface samples: lower corner, cell size, dims, cell of each
    sample and the samples ordered by cell."""
    lower = -axes * (1.0 + 1e-9) - 1e-12
    cs = float(axes.max()) / 24.0
    dims = np.maximum(1, np.ceil(2.0 * (axes * (1.0 + 1e-9) + 1e-12) / cs)).astype(np.int64)
    ci = np.clip(((samples - lower) / cs).astype(np.int64), 0, dims - 1)
    cell = ((ci[:, 0] * dims[1] + ci[:, 1]) * dims[2] + ci[:, 2]).astype(np.int64)
    order = np.argsort(cell, kind="stable").astype(np.int64)
    return lower, cs, dims, cell, order


@jit
def _greedy_medial_balls(
    samples, normals, depth0, half_width, n_target, lower, cs, dims, cell, order,
    kind, axes, n1, n2, e_sorted, perm, q1, q2, grid, amax, n_starts,
):
    """Greedy cover of a convex body by medial balls; see :func:`superellipsoid`.

    Returns centres (k, 3) and radii (k,), k <= n_target.
    """
    m = samples.shape[0]
    # cell list over the samples (cell index of each sample and their order by cell,
    # computed by _sample_cells)
    ncell = dims[0] * dims[1] * dims[2]
    cstart = np.zeros(ncell + 1, dtype=np.int64)
    for k in range(m):
        cstart[cell[k] + 1] += 1
    for c in range(ncell):
        cstart[c + 1] += cstart[c]

    # max-heap of (depth, -index) with lazy updates: an entry is stale when the
    # sample's depth has dropped since it was pushed
    depth = depth0.copy()
    hkey = np.empty(2 * m + 1)
    hidx = np.empty(2 * m + 1, dtype=np.int64)
    hn = 0
    for k in range(m):
        hn = _heap_push(hkey, hidx, hn, depth[k], k)

    centres = np.empty((n_target, 3))
    radii = np.empty(n_target)
    x = np.empty(3)
    q = np.empty(3)
    nu = np.empty(3)
    nb = 0
    stop = COVERED_ATOL * amax
    while nb < n_target and hn > 0:
        key = hkey[0]
        k = hidx[0]
        hn = _heap_pop(hkey, hidx, hn)
        if key > depth[k]:
            if depth[k] > stop:
                hn = _heap_push(hkey, hidx, hn, depth[k], k)
            continue
        e_cur = depth[k]
        if e_cur <= stop:
            break
        # the middle of the uncovered part of the normal line, its nearest surface point
        # q and the medial ball there (which contains the middle point)
        for i in range(3):
            x[i] = samples[k, i] - 0.5 * e_cur * normals[k, i]
        _nearest_surface_point(kind, x, axes, n1, n2, e_sorted, perm, q1, q2, grid, amax, n_starts, q, nu)
        # a ball tangent at q fits between the two supporting planes normal to nu
        rho_max_q = _support(nu, axes, q1, q2, x)
        rho = _medial_radius(q, nu, rho_max_q, kind, axes, n1, n2, e_sorted, perm, q1, q2, grid, amax, n_starts)
        cx = q[0] - rho * nu[0]
        cy = q[1] - rho * nu[1]
        cz = q[2] - rho * nu[2]
        if _entry_depth(samples[k], normals[k], cx, cy, cz, rho) > PROGRESS_FRACTION * e_cur:
            # numerical safety: no progress on this sample; take the medial ball at s itself
            rho = _medial_radius(samples[k], normals[k], half_width[k], kind, axes, n1, n2, e_sorted, perm, q1, q2, grid, amax, n_starts)
            cx = samples[k, 0] - rho * normals[k, 0]
            cy = samples[k, 1] - rho * normals[k, 1]
            cz = samples[k, 2] - rho * normals[k, 2]
            depth[k] = 0.0
        duplicate = rho <= 0.0
        for b in range(nb):
            dd = abs(centres[b, 0] - cx) + abs(centres[b, 1] - cy) + abs(centres[b, 2] - cz)
            if dd <= stop and abs(radii[b] - rho) <= stop:
                duplicate = True
                break
        if duplicate:
            depth[k] = 0.0
            continue
        centres[nb, 0] = cx
        centres[nb, 1] = cy
        centres[nb, 2] = cz
        radii[nb] = rho
        nb += 1
        # lower the cusp depth of the samples whose inward normal line enters the new ball
        reach = rho + e_cur
        lo0 = min(max(int((cx - reach - lower[0]) / cs), 0), dims[0] - 1)
        hi0 = min(max(int((cx + reach - lower[0]) / cs), 0), dims[0] - 1)
        lo1 = min(max(int((cy - reach - lower[1]) / cs), 0), dims[1] - 1)
        hi1 = min(max(int((cy + reach - lower[1]) / cs), 0), dims[1] - 1)
        lo2 = min(max(int((cz - reach - lower[2]) / cs), 0), dims[2] - 1)
        hi2 = min(max(int((cz + reach - lower[2]) / cs), 0), dims[2] - 1)
        for i0 in range(lo0, hi0 + 1):
            for i1 in range(lo1, hi1 + 1):
                for i2 in range(lo2, hi2 + 1):
                    c = (i0 * dims[1] + i1) * dims[2] + i2
                    for a in range(cstart[c], cstart[c + 1]):
                        j = order[a]
                        if depth[j] <= 0.0:
                            continue
                        t_in = _entry_depth(samples[j], normals[j], cx, cy, cz, rho)
                        if t_in < depth[j]:
                            depth[j] = t_in
    return centres[:nb].copy(), radii[:nb].copy()


@jit
def _verify_balls(centres, radii, axes, n1, n2, q1, q2, grid, amax, n_starts):
    """Re-check every ball of a superellipsoid with a wider search (n_starts starts):
    a ball whose centre is found closer to the surface than its radius (beyond
    INSIDE_ATOL) is shrunk to that distance.  Returns the number of balls shrunk."""
    q = np.empty(3)
    nu = np.empty(3)
    shrunk = 0
    for b in range(radii.shape[0]):
        d = _superellipsoid_min(centres[b], axes, n1, n2, q1, q2, grid, amax, n_starts, -np.inf, q, nu, 3)
        if d < radii[b] - INSIDE_ATOL * amax:
            radii[b] = max(d, 0.0)
            shrunk += 1
    return shrunk


# ----------------------------------------------------------------------------------------
# ellipsoids and superellipsoids: public functions


def _fibonacci_sphere(m):
    """m nearly uniform unit vectors (Fibonacci lattice), deterministic."""
    i = np.arange(m, dtype=np.float64) + 0.5
    z = 1.0 - 2.0 * i / m
    rxy = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = i * (math.pi * (3.0 - math.sqrt(5.0)))
    return np.stack([rxy * np.cos(phi), rxy * np.sin(phi), z], axis=1)


def _support_np(normals, axes, q1, q2):
    """Vectorised support function and support points (see _support)."""
    m = normals * axes[None, :]
    big = np.max(np.abs(m), axis=1)
    a = np.abs(m) / big[:, None]
    u = a[:, 0] ** q2 + a[:, 1] ** q2
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.where(u > 0.0, u ** (q1 / q2), 0.0)
        S = w + a[:, 2] ** q1
        value = big * S ** (1.0 / q1)
        pre = S ** (1.0 / q1 - 1.0)
        pu = np.where(u > 0.0, pre * u ** (q1 / q2 - 1.0), 0.0)
    g = np.stack([pu * a[:, 0] ** (q2 - 1.0), pu * a[:, 1] ** (q2 - 1.0), pre * a[:, 2] ** (q1 - 1.0)], axis=1)
    points = axes[None, :] * np.sign(m) * g
    return value, points


def _implicit_gradient_np(x, axes, n1, n2):
    ax = np.abs(x[:, 0] / axes[0])
    ay = np.abs(x[:, 1] / axes[1])
    az = np.abs(x[:, 2] / axes[2])
    u = ax**n2 + ay**n2
    with np.errstate(divide="ignore", invalid="ignore"):
        pu = np.where(u > 0.0, n1 * u ** (n1 / n2 - 1.0), 0.0)
    g = np.stack(
        [
            pu * ax ** (n2 - 1.0) / axes[0],
            pu * ay ** (n2 - 1.0) / axes[1],
            n1 * az ** (n1 - 1.0) / axes[2],
        ],
        axis=1,
    )
    return np.sign(x) * g


def _surface_samples(axes, n1, n2, q1, q2, m):
    """About m points on the surface with outward unit normals.

    Half are support points of Fibonacci normals plus the six axis directions (dense
    where the surface is strongly curved), half are radial projections of the
    Fibonacci points mapped onto the ellipsoid with the same semi-axes (spread over the
    flat parts, e.g. the faces of a box-like superellipsoid).
    """
    ma = m // 2
    normals_a = np.vstack([np.eye(3), -np.eye(3), _fibonacci_sphere(ma)])
    _, points_a = _support_np(normals_a, axes, q1, q2)
    x = _fibonacci_sphere(m - ma) * axes[None, :]
    u = np.abs(x[:, 0] / axes[0]) ** n2 + np.abs(x[:, 1] / axes[1]) ** n2
    F = u ** (n1 / n2) + np.abs(x[:, 2] / axes[2]) ** n1
    points_b = x * (F ** (-1.0 / n1))[:, None]
    g = _implicit_gradient_np(points_b, axes, n1, n2)
    normals_b = g / np.linalg.norm(g, axis=1)[:, None]
    points = np.ascontiguousarray(np.vstack([points_a, points_b]))
    normals = np.ascontiguousarray(np.vstack([normals_a, normals_b]))
    return points, normals


def _direction_grid(axes, n1, n2, q1, q2):
    """Start directions of the distance minimisation, one row each:
    normal n, h(n), direction u, surface point y(u) (n: Fibonacci set plus the six axis
    directions; u: the same set mapped by the semi-axes, spread more evenly over the surface)."""
    fib = np.vstack([np.eye(3), -np.eye(3), _fibonacci_sphere(SUPPORT_GRID_SIZE)])
    h, _ = _support_np(fib, axes, q1, q2)
    u = fib * axes[None, :]
    u /= np.linalg.norm(u, axis=1)[:, None]
    w = np.abs(u[:, 0] / axes[0]) ** n2 + np.abs(u[:, 1] / axes[1]) ** n2
    F = w ** (n1 / n2) + np.abs(u[:, 2] / axes[2]) ** n1
    y = u * (F ** (-1.0 / n1))[:, None]
    return np.ascontiguousarray(np.hstack([fib, h[:, None], u, y]))


def _check_axes(semi_axes):
    try:
        a = np.array(semi_axes, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"semi_axes must be three finite numbers > 0, got {semi_axes!r}") from None
    if a.shape != (3,) or not np.all(np.isfinite(a)) or np.any(a <= 0.0):
        raise ValueError(f"semi_axes must be three finite numbers > 0, got {semi_axes!r}")
    return a


def _medial_ball_body(axes, n1, n2, n_spheres, surface_samples, kind, frame):
    n_spheres = _check_int("n_spheres", n_spheres, 1)
    if frame not in ("com", "body"):
        raise ValueError(f'frame must be "com" or "body", got {frame!r}')
    if surface_samples is None:
        surface_samples = max(SURFACE_SAMPLES_PER_SPHERE * n_spheres, MIN_SURFACE_SAMPLES)
    surface_samples = _check_int("surface_samples", surface_samples, 16)
    q1 = n1 / (n1 - 1.0)
    q2 = n2 / (n2 - 1.0)
    amax = float(axes.max())
    grid = _direction_grid(axes, n1, n2, q1, q2)
    perm = np.argsort(-axes, kind="stable").astype(np.int64)
    e_sorted = np.ascontiguousarray(axes[perm])
    points, normals = _surface_samples(axes, n1, n2, q1, q2, surface_samples)
    h_plus, _ = _support_np(normals, axes, q1, q2)
    # width of the body along each sample normal (centrally symmetric body: 2 h(nu)):
    # the initial cusp depth, and twice the largest possible tangent-ball radius
    width = 2.0 * h_plus
    chord = _chords(points, normals, width, axes, float(n1), float(n2))
    lower, cs, dims, cell, order = _sample_cells(points, axes)
    centres, radii = _greedy_medial_balls(
        points, normals, chord, 0.5 * width, n_spheres, lower, cs, dims, cell, order,
        kind, axes, float(n1), float(n2), e_sorted, perm, q1, q2,
        grid, amax, SUPPORT_STARTS,
    )
    if kind != 0:
        _verify_balls(centres, radii, axes, float(n1), float(n2), q1, q2, grid, amax, VERIFY_STARTS)
        keep = radii > 0.0
        centres, radii = centres[keep], radii[keep]
    if frame == "body":
        return np.ascontiguousarray(centres), np.ascontiguousarray(radii)
    return _recentre(centres, radii)


def ellipsoid(semi_axes, n_spheres, surface_samples=None, frame="com"):
    """An ellipsoid with ``semi_axes`` (a, b, c) along x, y, z, as overlapping spheres.

    The construction of :func:`superellipsoid` with exponents (2, 2), but with the
    distance of a point to the surface computed exactly (to round-off) by Eberly's
    robust bisection ("Distance from a point to an ellipse, an ellipsoid, or a
    hyperellipsoid", Geometric Tools 2013; see ``_ellipsoid_closest``), so every sphere
    lies inside the ellipsoid to ``INSIDE_ATOL`` times the largest semi-axis.

    Measured volume of the union (with :func:`centre_of_mass_of_union`) for 2,000
    spheres: 0.085 % below 4/3 pi abc for (2, 1.5, 1), 0.04 % for (1.2, 1, 0.8), 0.27 %
    for (4, 2, 1), within the integration error for the spheroid (3, 1, 1); 0.3-1.1 %
    below for 500 spheres.  A sphere (a = b = c) gives one sphere.  Cost: about 0.5 ms
    per sphere (6,241 spheres: about 3 s, plus the centre of mass).

    ``surface_samples`` and ``frame`` as in :func:`superellipsoid`.
    """
    axes = _check_axes(semi_axes)
    return _medial_ball_body(axes, 2.0, 2.0, n_spheres, surface_samples, 0, frame)


def superellipsoid(semi_axes, exponents, n_spheres, surface_samples=None, frame="com"):
    """A convex superellipsoid approximated by ``n_spheres`` overlapping polydisperse spheres.

    Body: ``(|x/a|^e2 + |y/b|^e2)^(e1/e2) + |z/c|^e1 <= 1`` with ``semi_axes = (a, b, c)``
    and ``exponents = (e1, e2)``, each in (1, MAX_EXPONENT = 20]: (2, 2) is the ellipsoid,
    large exponents approach a box, exponents below 2 give pointed, octahedron-like
    shapes.  In Barr's notation e1 = 2 / eps1 (north-south) and e2 = 2 / eps2
    (east-west).  Exponents <= 1 (non-convex or not strictly convex) are not supported:
    the construction below needs a convex body.

    Construction (deterministic; no random numbers).  Every sphere is a *medial ball*:
    the largest ball inside the body tangent to the surface at some point q, centred
    at q - rho nu (nu the outward normal at q).  The balls are chosen greedily:

    1. Candidate points: ``surface_samples`` points s on the surface with outward
       normals (default ``max(16 n_spheres, 2048)``): support points of a Fibonacci
       set of normals and the six axis directions (dense where the surface is strongly
       curved) and radial projections of Fibonacci points mapped by the semi-axes
       (spread over flat parts).  Each carries a *cusp depth* e(s): the depth along its
       inward normal line at which the line enters the union of the balls chosen so far
       (initially the chord of the body along that line).
    2. Repeat until ``n_spheres`` balls: take the candidate with the largest e (ties:
       the lowest index) and the point x = s - (e/2) nu in the middle of the uncovered
       part of its normal line; find the surface point q nearest to x and add the
       medial ball at q.  That ball contains x (the ball B(x, dist(x)) is inside and
       tangent at q), so each step covers at least half of the uncovered segment of the
       chosen line; the first balls are the largest inscribed ones, the last fill the
       shallow cusps between tangent points near the surface.  Then lower the cusp
       depths of the candidates whose normal lines enter the new ball.  The loop stops
       early only when every e is below ``COVERED_ATOL`` (the body is covered exactly:
       a sphere gives one ball).
    3. Medial radius: the balls tangent at q are nested in rho, so the largest one
       inside is found by shrinking a bracket with the test "distance from the centre
       to the surface >= rho - INSIDE_ATOL * amax"; a failed test yields a supporting
       plane the trial ball crosses, i.e. an upper bound on rho (exact for convex
       bodies), so few tests are needed.
    4. Distance from an interior point p to the surface (robust local search): the
       smallest of Newton minimisations, on the sphere of directions, of |y(u) - p|
       with y(u) the surface point in direction u (always), and of h(n) - n.p, the
       distance to the supporting plane with normal n, h the closed-form support
       function (when an exponent is below 2, where the surface is only C^1), each from
       the 6 best mutually separated of 1030 fixed directions.  Every value found is an
       upper bound on the distance, so a missed minimum can only make a ball too big;
       at the end every ball is re-checked with 16 starts and shrunk if found to
       protrude.  Measured protrusion: below 1e-10 times the largest semi-axis for
       exponents from 1.05 to 20 (sphere surfaces sampled against the implicit
       function, and against Eberly's exact distance for (2, 2)).

    Measured volume deficit of the union for 2,000 spheres, semi-axes (2, 1.5, 1):
    0.09 % for exponents (2, 2) and (4, 4), 0.3 % for (1.5, 3), 0.3-0.4 % for (10, 10),
    0.7 % for (20, 20), 0.85 % for (1.2, 1.2); with 500 spheres 0.3 % to 3 %.  Cost:
    about 1.5 ms per sphere (6,241 spheres: about 10 s).

    ``frame="com"`` (default): offsets relative to the centre of mass of the union, like
    every shape; ``frame="body"``: relative to the centre of the body, in the frame of
    ``semi_axes`` (the union's centre of mass is then near, not at, the origin, because
    the greedy cover is not exactly symmetric).
    """
    axes = _check_axes(semi_axes)
    try:
        e = np.array(exponents, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"exponents must be two numbers (e1, e2) in (1, {MAX_EXPONENT}], got {exponents!r}") from None
    if e.shape != (2,) or not np.all(np.isfinite(e)) or np.any(e <= 1.0) or np.any(e > MAX_EXPONENT):
        raise ValueError(f"exponents must be two numbers (e1, e2) in (1, {MAX_EXPONENT}], got {exponents!r}")
    # distance search: the primal parametrisation always; the dual one too when an
    # exponent is below 2 (there the surface is only C^1 and the support function C^2)
    kind = 3 if min(e) < 2.0 else 2
    return _medial_ball_body(axes, float(e[0]), float(e[1]), n_spheres, surface_samples, kind, frame)


def agglomerate(centres, radii):
    """Arbitrary given spheres, re-centred on the centre of mass of their union.

    ``centres`` (n, 3), or (n, 2) for a 2D configuration, embedded in the plane z = 0;
    ``radii`` (n,) finite and > 0.  The spheres are returned unchanged in order and
    size, translated so that the union's centre of mass is at the origin.  They need not
    overlap (Fig. 1(c): 790 non-overlapping spheres).
    """
    c, r = _check_centres_radii(centres, radii, allow_2d=True)
    return _recentre(c, r)


# ----------------------------------------------------------------------------------------
# helpers


def _check_offsets_radii(offsets, radii):
    c, r = _check_centres_radii(offsets, radii, allow_2d=False)
    return c, r


def extent_below_com(offsets, radii):
    """Depth of the particle's lowest point below its centre of mass: ``max(r_i - z_i)``.

    With the centre of mass at height ``z_cm`` the particle's lowest point is at
    ``z_cm - extent_below_com``; a particle whose centre of mass is higher than that
    above the floor does not touch it.
    """
    c, r = _check_offsets_radii(offsets, radii)
    return float(np.max(r - c[:, 2]))


def bounding_radius(offsets, radii):
    """Largest distance from the centre of mass (origin) to any sphere surface,
    ``max(|offset_i| + r_i)``: the particle lies inside this ball in any orientation."""
    c, r = _check_offsets_radii(offsets, radii)
    return float(np.max(np.sqrt(np.sum(c * c, axis=1)) + r))


def random_rotations(n, rng):
    """``n`` uniformly distributed unit quaternions ``(w, x, y, z)``, shape (n, 4).

    Shoemake's method ("Uniform random rotations", Graphics Gems III, 1992): with
    ``u1, u2, u3`` uniform on [0, 1), ``q = (sqrt(u1) cos 2pi u3, sqrt(1-u1) sin 2pi u2,
    sqrt(1-u1) cos 2pi u2, sqrt(u1) sin 2pi u3)`` is uniform on the unit 3-sphere, hence the
    rotation is uniform (Haar) on SO(3).  Uses ``rng.random((n, 3))`` only.
    """
    n = _check_int("n", n, 0)
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    u = rng.random((n, 3))
    a = np.sqrt(1.0 - u[:, 0])
    b = np.sqrt(u[:, 0])
    t2 = 2.0 * np.pi * u[:, 1]
    t3 = 2.0 * np.pi * u[:, 2]
    return np.stack([b * np.cos(t3), a * np.sin(t2), a * np.cos(t2), b * np.sin(t3)], axis=1)


def rotate(offsets, quaternion):
    """Rotate row vectors by a unit quaternion ``(w, x, y, z)``: ``v -> q v q*``.

    ``offsets`` (k, 3); returns a new (k, 3) array ``offsets @ R.T`` with ``R`` the
    rotation matrix of ``q``.  ``|q|`` must be 1 within ``QUATERNION_NORM_ATOL``; it is
    normalised before use.
    """
    try:
        v = np.array(offsets, dtype=np.float64)
        q = np.array(quaternion, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError("offsets must be a (k, 3) and quaternion a (4,) numeric array") from None
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"offsets must have shape (k, 3), got {v.shape}")
    if q.shape != (4,) or not np.all(np.isfinite(q)):
        raise ValueError(f"quaternion must be 4 finite numbers (w, x, y, z), got shape {q.shape}")
    norm = float(np.sqrt(np.sum(q * q)))
    if abs(norm - 1.0) > QUATERNION_NORM_ATOL:
        raise ValueError(f"quaternion must have unit norm (within {QUATERNION_NORM_ATOL}), got {norm!r}")
    w, x, y, z = q / norm
    R = np.array(
        [
            [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)],
            [2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)],
            [2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)],
        ]
    )
    return v @ R.T
