"""Greedy cover of a convex body by medial balls (see :func:`parsim.core.shapes.superellipsoid`)."""

import numpy as np

from parsim.core.jit import jit
from parsim.core.shapes.ellipsoid_distance import _ellipsoid_closest
from parsim.core.shapes.superellipsoid_distance import _implicit, _superellipsoid_min, _support

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


@jit
def _nearest_surface_point(kind, x, axes, n1, n2, e_sorted, perm, q1, q2, grid, amax, n_starts,
                           threshold, q, nu):
    """Distance of an interior point x to the surface; the nearest surface point goes to q
    and the outward unit normal there to nu.

    ``kind`` 0: the ellipsoid, exact (Eberly); otherwise a superellipsoid searched by
    :func:`_superellipsoid_min` with the bit mask ``kind``, which may stop as soon as it
    finds a distance below ``threshold``.
    """
    if kind == 0:
        d = _ellipsoid_closest(x, e_sorted, perm, q)
        for i in range(3):
            nu[i] = q[i] / (axes[i] * axes[i])
        norm = np.sqrt(nu[0] * nu[0] + nu[1] * nu[1] + nu[2] * nu[2])
        for i in range(3):
            nu[i] /= norm
        return d
    return _superellipsoid_min(x, axes, n1, n2, q1, q2, grid, amax, n_starts, threshold, q, nu, kind)


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
    d = _nearest_surface_point(kind, c, axes, n1, n2, e_sorted, perm, q1, q2, grid, amax, n_starts,
                               rho - tol, y, m)
    if d >= rho - tol:
        return np.inf
    denom = 1.0 - (m[0] * nu[0] + m[1] * nu[1] + m[2] * nu[2])
    if denom <= 1e-12:  # m = nu within round-off: the plane is the tangent plane at s
        return rho
    bound = (m[0] * (y[0] - s[0]) + m[1] * (y[1] - s[1]) + m[2] * (y[2] - s[2])) / denom
    return min(max(bound, 0.0), rho)


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
        _nearest_surface_point(kind, x, axes, n1, n2, e_sorted, perm, q1, q2, grid, amax, n_starts,
                               -np.inf, q, nu)
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
