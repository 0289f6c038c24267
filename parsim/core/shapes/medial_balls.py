"""Greedy cover of a convex body by medial balls (see :func:`parsim.core.shapes.superellipsoid`).

The body's surface travels as one :class:`ConvexSurface`, the candidate tangent points as
:class:`SurfaceSamples` and their cell list as :class:`SampleCells`.
"""

from typing import NamedTuple

import numpy as np

from parsim.core.jit import jit
from parsim.core.shapes.ellipsoid_distance import _ellipsoid_closest
from parsim.core.shapes.superellipsoid_distance import Superellipsoid, _implicit, _superellipsoid_min, _support

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
# Greedy cover: if the medial ball at the nearest surface point of the middle of a
# sample's uncovered segment left more than this fraction of the segment uncovered
# (it should leave at most half; only round-off can make it more), the medial ball at
# the sample itself is taken instead.
PROGRESS_FRACTION = 0.75


class ConvexSurface(NamedTuple):
    """The surface of a convex body as the medial-ball search asks it for distances.

    ``kind`` 0: the ellipsoid with the semi-axes of ``body``, distances exact (Eberly) from
    the semi-axes sorted descending, ``e_sorted``, and their order ``perm``; otherwise the
    superellipsoid ``body`` (a :class:`Superellipsoid`), searched by
    :func:`_superellipsoid_min` with the bit mask ``kind`` (2: surface-point search, 3: and
    the support-function search) from ``n_starts`` starts per search.
    """

    kind: int
    body: Superellipsoid
    e_sorted: np.ndarray
    perm: np.ndarray
    n_starts: int


class SurfaceSamples(NamedTuple):
    """Candidate tangent points of the greedy cover: ``points`` (m, 3) on the surface, their
    outward unit ``normals`` (m, 3), the ``chord`` (m,) of the body along each inward normal
    line (the initial cusp depth) and ``half_width`` (m,), half the body's width along each
    normal (the largest radius of a ball tangent there)."""

    points: np.ndarray
    normals: np.ndarray
    chord: np.ndarray
    half_width: np.ndarray


class SampleCells(NamedTuple):
    """Cell list over the surface samples: ``lower`` corner (3,), cubic cells of edge ``size``,
    ``dims`` (3,) cells per axis; the samples of cell c = (i0 dims[1] + i1) dims[2] + i2 are
    ``order[start[c]:start[c + 1]]``."""

    lower: np.ndarray
    size: float
    dims: np.ndarray
    start: np.ndarray
    order: np.ndarray


@jit
def _nearest_surface_point(surface, x, threshold, q, nu):
    """Distance of an interior point x to the surface; the nearest surface point goes to q
    and the outward unit normal there to nu.

    ``surface.kind`` 0: the ellipsoid, exact (Eberly); otherwise a superellipsoid searched by
    :func:`_superellipsoid_min` with the bit mask ``kind``, which may stop as soon as it
    finds a distance below ``threshold``.
    """
    axes = surface.body.axes
    if surface.kind == 0:
        d = _ellipsoid_closest(x, surface.e_sorted, surface.perm, q)
        for i in range(3):
            nu[i] = q[i] / (axes[i] * axes[i])
        norm = np.sqrt(nu[0] * nu[0] + nu[1] * nu[1] + nu[2] * nu[2])
        for i in range(3):
            nu[i] /= norm
        return d
    return _superellipsoid_min(x, surface.body, surface.n_starts, threshold, q, nu, surface.kind)


@jit
def _ball_test(surface, c, rho, s, nu):
    """Test whether the ball B(c, rho), tangent to the surface at s with outward normal
    nu (c = s - rho nu), is inside the body: distance(c) >= rho - INSIDE_ATOL * amax.

    Returns inf if it is.  If not, returns an upper bound on the radius of the largest
    ball inside tangent at s (below rho): the search found a surface point y with
    outward normal m whose supporting plane the ball crosses; every tangent ball at s of
    radius above m.(y - s) / (1 - m.nu) crosses that plane too (the body is convex).
    """
    body = surface.body
    tol = INSIDE_ATOL * body.amax
    if _implicit(c, body.axes, body.n1, body.n2) > 1.0:
        return rho
    y = np.empty(3)
    m = np.empty(3)
    d = _nearest_surface_point(surface, c, rho - tol, y, m)
    if d >= rho - tol:
        return np.inf
    denom = 1.0 - (m[0] * nu[0] + m[1] * nu[1] + m[2] * nu[2])
    if denom <= 1e-12:  # m = nu within round-off: the plane is the tangent plane at s
        return rho
    bound = (m[0] * (y[0] - s[0]) + m[1] * (y[1] - s[1]) + m[2] * (y[2] - s[2])) / denom
    return min(max(bound, 0.0), rho)


@jit
def _medial_radius(surface, s, nu, rho_max):
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
        bound = _ball_test(surface, c, trial, s, nu)
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
def _medial_ball(surface, s, nu, rho_max):
    """Centre (cx, cy, cz) and radius of the medial ball tangent at s (outward normal nu,
    radius at most rho_max): :func:`_medial_radius`, centred at s - rho nu."""
    rho = _medial_radius(surface, s, nu, rho_max)
    return s[0] - rho * nu[0], s[1] - rho * nu[1], s[2] - rho * nu[2], rho


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
def _heap_swap(hkey, hidx, a, b):
    tk = hkey[a]
    ti = hidx[a]
    hkey[a] = hkey[b]
    hidx[a] = hidx[b]
    hkey[b] = tk
    hidx[b] = ti


@jit
def _heap_push(hkey, hidx, hn, key, idx):
    i = hn
    hkey[i] = key
    hidx[i] = idx
    while i > 0:
        parent = (i - 1) // 2
        if not _heap_before(hkey[i], hidx[i], hkey[parent], hidx[parent]):
            break
        _heap_swap(hkey, hidx, i, parent)
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
        _heap_swap(hkey, hidx, i, best)
        i = best
    return hn


def _sample_cells(samples, axes):
    """The :class:`SampleCells` over the surface samples of a body of semi-axes ``axes``."""
    lower = -axes * (1.0 + 1e-9) - 1e-12
    cs = float(axes.max()) / 24.0
    dims = np.maximum(1, np.ceil(2.0 * (axes * (1.0 + 1e-9) + 1e-12) / cs)).astype(np.int64)
    ci = np.clip(((samples - lower) / cs).astype(np.int64), 0, dims - 1)
    cell = ((ci[:, 0] * dims[1] + ci[:, 1]) * dims[2] + ci[:, 2]).astype(np.int64)
    order = np.argsort(cell, kind="stable").astype(np.int64)
    start = np.zeros(int(np.prod(dims)) + 1, dtype=np.int64)
    start[1:] = np.cumsum(np.bincount(cell, minlength=len(start) - 1))
    return SampleCells(lower, cs, dims, start, order)


@jit
def _depth_heap(depth):
    """Max-heap (keys, sample indices, size) of the samples by cusp depth (:func:`_heap_before`),
    with room for the lazy updates of :func:`_deepest_sample`."""
    m = depth.shape[0]
    hkey = np.empty(2 * m + 1)
    hidx = np.empty(2 * m + 1, dtype=np.int64)
    hn = 0
    for k in range(m):
        hn = _heap_push(hkey, hidx, hn, depth[k], k)
    return hkey, hidx, hn


@jit
def _deepest_sample(hkey, hidx, hn, depth, stop):
    """The sample of largest current cusp depth, popped from the heap, and the heap's new size;
    -1 when the heap runs empty.  The heap is updated lazily: an entry is stale when its
    sample's depth has dropped since it was pushed; it is pushed again with the current
    depth if that is still above ``stop``."""
    while hn > 0:
        key = hkey[0]
        k = hidx[0]
        hn = _heap_pop(hkey, hidx, hn)
        if key > depth[k]:
            if depth[k] > stop:
                hn = _heap_push(hkey, hidx, hn, depth[k], k)
            continue
        return k, hn
    return -1, hn


@jit
def _ball_through_middle(surface, samples, k, e_cur):
    """The medial ball at the surface point q nearest to the middle x of the uncovered part
    (depth ``e_cur``) of sample k's normal line: it contains x (B(x, dist(x)) is inside and
    tangent at q).  A ball tangent at q fits between the two supporting planes normal to the
    outward normal nu at q, so its radius is at most h(nu), half the width of the (centrally
    symmetric) body along nu."""
    x = np.empty(3)
    q = np.empty(3)
    nu = np.empty(3)
    for i in range(3):
        x[i] = samples.points[k, i] - 0.5 * e_cur * samples.normals[k, i]
    _nearest_surface_point(surface, x, -np.inf, q, nu)
    body = surface.body
    rho_max = _support(nu, body.axes, body.q1, body.q2, x)
    return _medial_ball(surface, q, nu, rho_max)


@jit
def _repeats_a_ball(centres, radii, nb, cx, cy, cz, rho, atol):
    """Whether one of the first nb balls has the centre (cx, cy, cz) and radius rho within atol."""
    for b in range(nb):
        dd = abs(centres[b, 0] - cx) + abs(centres[b, 1] - cy) + abs(centres[b, 2] - cz)
        if dd <= atol and abs(radii[b] - rho) <= atol:
            return True
    return False


@jit
def _cell_span(x, reach, lower, size, dim):
    """First and last cell, along one axis, of the cells within ``reach`` of the coordinate x."""
    return (min(max(int((x - reach - lower) / size), 0), dim - 1),
            min(max(int((x + reach - lower) / size), 0), dim - 1))


@jit
def _lower_depths(samples, cells, depth, cx, cy, cz, rho, reach):
    """Lower the cusp depth of every sample whose inward normal line enters the ball
    B((cx, cy, cz), rho) to the depth where it enters (:func:`_entry_depth`), among the
    samples of the cells within ``reach`` of the centre; covered samples (depth 0) stay."""
    lower, size, dims, start, order = cells
    lo0, hi0 = _cell_span(cx, reach, lower[0], size, dims[0])
    lo1, hi1 = _cell_span(cy, reach, lower[1], size, dims[1])
    lo2, hi2 = _cell_span(cz, reach, lower[2], size, dims[2])
    for i0 in range(lo0, hi0 + 1):
        for i1 in range(lo1, hi1 + 1):
            for i2 in range(lo2, hi2 + 1):
                c = (i0 * dims[1] + i1) * dims[2] + i2
                for a in range(start[c], start[c + 1]):
                    j = order[a]
                    if depth[j] <= 0.0:
                        continue
                    t_in = _entry_depth(samples.points[j], samples.normals[j], cx, cy, cz, rho)
                    if t_in < depth[j]:
                        depth[j] = t_in


@jit
def _greedy_medial_balls(samples, cells, surface, n_target):
    """Greedy cover of a convex body (``surface``, a :class:`ConvexSurface`) by medial balls
    tangent near the ``samples`` (:class:`SurfaceSamples`, in the :class:`SampleCells`
    ``cells``); see :func:`superellipsoid`.

    Repeatedly takes the sample of largest cusp depth e (:func:`_deepest_sample`) and adds
    the medial ball through the middle of the uncovered part of its normal line
    (:func:`_ball_through_middle`), then lowers the depths of the samples whose normal lines
    enter it (:func:`_lower_depths`).  Should that ball leave more than PROGRESS_FRACTION of
    the segment uncovered (only round-off can make it), the medial ball at the sample itself
    is taken and the sample counts as covered.  A ball of radius 0 or one already chosen is
    not added, its sample counts as covered.  Stops at ``n_target`` balls or when every depth
    is below COVERED_ATOL * amax.

    Returns centres (k, 3) and radii (k,), k <= n_target.
    """
    points, normals = samples.points, samples.normals
    depth = samples.chord.copy()
    hkey, hidx, hn = _depth_heap(depth)
    centres = np.empty((n_target, 3))
    radii = np.empty(n_target)
    nb = 0
    stop = COVERED_ATOL * surface.body.amax
    while nb < n_target:
        k, hn = _deepest_sample(hkey, hidx, hn, depth, stop)
        if k < 0:
            break
        e_cur = depth[k]
        if e_cur <= stop:
            break
        cx, cy, cz, rho = _ball_through_middle(surface, samples, k, e_cur)
        if _entry_depth(points[k], normals[k], cx, cy, cz, rho) > PROGRESS_FRACTION * e_cur:
            # numerical safety: no progress on this sample; take the medial ball at s itself
            cx, cy, cz, rho = _medial_ball(surface, points[k], normals[k], samples.half_width[k])
            depth[k] = 0.0
        if rho <= 0.0 or _repeats_a_ball(centres, radii, nb, cx, cy, cz, rho, stop):
            depth[k] = 0.0
            continue
        centres[nb, 0] = cx
        centres[nb, 1] = cy
        centres[nb, 2] = cz
        radii[nb] = rho
        nb += 1
        _lower_depths(samples, cells, depth, cx, cy, cz, rho, rho + e_cur)
    return centres[:nb].copy(), radii[:nb].copy()


@jit
def _verify_balls(centres, radii, body, n_starts):
    """Re-check every ball of the superellipsoid ``body`` with a wider search (n_starts starts):
    a ball whose centre is found closer to the surface than its radius (beyond
    INSIDE_ATOL) is shrunk to that distance.  Returns the number of balls shrunk."""
    q = np.empty(3)
    nu = np.empty(3)
    shrunk = 0
    for b in range(radii.shape[0]):
        d = _superellipsoid_min(centres[b], body, n_starts, -np.inf, q, nu, 3)
        if d < radii[b] - INSIDE_ATOL * body.amax:
            radii[b] = max(d, 0.0)
            shrunk += 1
    return shrunk
