"""Distance from an interior point to the surface of a convex superellipsoid.

Body: ``F(x) = (|x/a|^n2 + |y/b|^n2)^(n1/n2) + |z/c|^n1 <= 1`` (:func:`_implicit`), with the
dual exponents ``q_i = n_i / (n_i - 1)`` of its support function (:func:`_support`).
:func:`_superellipsoid_min` combines two local searches over the sphere of directions,
both run by the one Newton driver :func:`_refine_direction`:

- ``SUPPORT``: directions are outward normals n, the value is ``h(n) - n.p``, the
  distance to the supporting plane with normal n;
- ``RADIAL``: directions are u, the value is ``|y(u) - p|``, the distance to the surface
  point ``y(u)`` in direction u (:func:`_radial`).

Every value either search takes is an upper bound on the distance (p inside).  The body and
the start directions of the searches travel as one :class:`Superellipsoid`.
"""

from typing import NamedTuple

import numpy as np

from parsim.core.jit import jit

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

# The two searches (``search`` below; bit ``1 << search`` of the ``methods`` mask).
SUPPORT = 0
RADIAL = 1
# Columns of the direction grid (see smooth._direction_grid): normal n (0:3), h(n) (3),
# direction u (4:7), surface point y(u) (7:10).
_GRID_N = 0
_GRID_U = 4
_GRID_Y = 7


class Superellipsoid(NamedTuple):
    """A convex superellipsoid as its distance searches read it: semi-axes ``axes`` (3,), the
    exponents ``n1``, ``n2`` of :func:`_implicit` and their duals ``q1``, ``q2`` of
    :func:`_support`, the ``grid`` of start directions (rows: normal n, h(n), direction u,
    y(u); see smooth._direction_grid) and the largest semi-axis ``amax``."""

    axes: np.ndarray
    n1: float
    n2: float
    q1: float
    q2: float
    grid: np.ndarray
    amax: float


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
def _support_hessian(n, g, axes, q1, q2, t1, t2, nn, xa, xb, ht):
    """Hessian (h11, h12, h22) of g(n) = h(n) - n.p on the unit sphere in the frame (t1, t2):
    t_i . dx/dt_j, the support point x differentiated by central differences, minus
    g delta_ij (h is homogeneous of degree 1: the curvature term of the sphere).
    nn, xa, xb (3,), ht (2, 3): scratch."""
    eps = HESSIAN_FD_STEP
    for j in range(2):
        for i in range(3):
            nn[i] = n[i] + eps * (t1[i] if j == 0 else t2[i])
        _support(nn, axes, q1, q2, xa)
        for i in range(3):
            nn[i] = n[i] - eps * (t1[i] if j == 0 else t2[i])
        _support(nn, axes, q1, q2, xb)
        for i in range(3):
            ht[j, i] = (xa[i] - xb[i]) / (2.0 * eps)
    h11 = t1[0] * ht[0, 0] + t1[1] * ht[0, 1] + t1[2] * ht[0, 2] - g
    h22 = t2[0] * ht[1, 0] + t2[1] * ht[1, 1] + t2[2] * ht[1, 2] - g
    h12 = 0.5 * (t1[0] * ht[1, 0] + t1[1] * ht[1, 1] + t1[2] * ht[1, 2]
                 + t2[0] * ht[0, 0] + t2[1] * ht[0, 1] + t2[2] * ht[0, 2])
    return h11, h12, h22


@jit
def _radial_hessian(u, p, axes, n1, n2, t1, t2, uu, y, dy1, dy2, hh):
    """Hessian (h11, h12, h22) of |y(u) - p|^2 / 2 in the frame (t1, t2): central
    differences of its gradient (y - p) . dy/dt_i with the frame held fixed,
    symmetrised.  uu, y, dy1, dy2 (3,), hh (2, 3): scratch."""
    eps = HESSIAN_FD_STEP
    for j in range(2):
        plus1 = 0.0
        plus2 = 0.0
        for side in range(2):  # the gradient at u + eps t_j, then at u - eps t_j
            step = eps if side == 0 else -eps
            for i in range(3):
                uu[i] = u[i] + step * (t1[i] if j == 0 else t2[i])
            _radial(uu, axes, n1, n2, y, dy1, dy2, t1, t2)
            r0 = y[0] - p[0]
            r1 = y[1] - p[1]
            r2 = y[2] - p[2]
            g1 = r0 * dy1[0] + r1 * dy1[1] + r2 * dy1[2]
            g2 = r0 * dy2[0] + r1 * dy2[1] + r2 * dy2[2]
            if side == 0:
                plus1 = g1
                plus2 = g2
        hh[j, 0] = (plus1 - g1) / (2.0 * eps)
        hh[j, 1] = (plus2 - g2) / (2.0 * eps)
    return hh[0, 0], 0.5 * (hh[0, 1] + hh[1, 0]), hh[1, 1]


@jit(inline="always")
def _merit(search, value):
    """The function whose decrease the line search demands: g (SUPPORT) or f^2 / 2 (RADIAL)."""
    return value if search == SUPPORT else 0.5 * value * value


@jit(inline="always")
def _tangent_gradient(search, x, p, t1, t2, dx1, dx2):
    """Gradient (g1, g2) of the merit in the frame (t1, t2): t_i . (x - p) for SUPPORT (x the
    support point, the gradient of h), (y - p) . dy/dt_i for RADIAL (x = y, dx_i = dy/dt_i)."""
    r0 = x[0] - p[0]
    r1 = x[1] - p[1]
    r2 = x[2] - p[2]
    if search == SUPPORT:
        return t1[0] * r0 + t1[1] * r1 + t1[2] * r2, t2[0] * r0 + t2[1] * r1 + t2[2] * r2
    return r0 * dx1[0] + r1 * dx1[1] + r2 * dx1[2], r0 * dx2[0] + r1 * dx2[1] + r2 * dx2[2]


@jit(inline="always")
def _limited_step(d1, d2):
    """The step (d1, d2) shortened to at most NEWTON_MAX_STEP (radians)."""
    step = np.sqrt(d1 * d1 + d2 * d2)
    if step > NEWTON_MAX_STEP:
        d1 *= NEWTON_MAX_STEP / step
        d2 *= NEWTON_MAX_STEP / step
    return d1, d2


@jit(inline="always")
def _step_on_sphere(d, d1, d2, t1, t2, out):
    """out <- the unit vector along d + d1 t1 + d2 t2 (a step in tangent coordinates at d)."""
    for i in range(3):
        out[i] = d[i] + d1 * t1[i] + d2 * t2[i]
    norm = np.sqrt(out[0] * out[0] + out[1] * out[1] + out[2] * out[2])
    for i in range(3):
        out[i] /= norm


@jit
def _refine_direction(search, d, p, axes, ea, eb, amax, threshold):
    """Local minimum of the search's objective over unit directions d, from (and updating) d.

    SUPPORT (d a normal n; ``ea, eb`` the dual exponents q1, q2): g(n) = h(n) - n.p, whose
    tangential gradient is t_i . (x - p) with x the support point (the gradient of h).
    RADIAL (d a direction u; ``ea, eb`` the exponents n1, n2): f(u) = |y(u) - p|, with the
    gradient (y - p) . dy/dt_i of f^2 / 2; it converges fast where the surface is flat
    (large exponents), where the support function is nearly non-differentiable.

    Newton's method on the sphere in tangent coordinates (t1, t2): analytic gradient
    (:func:`_tangent_gradient`), central-difference Hessian (:func:`_support_hessian`,
    :func:`_radial_hessian`), Levenberg-Marquardt shift (:func:`_newton_step`), steps at most
    NEWTON_MAX_STEP, Armijo backtracking on g (SUPPORT) or f^2 / 2 (RADIAL) (:func:`_merit`),
    so the value only decreases and every value is an upper bound on the distance.  Stops
    early once the value is below threshold.  Returns the value.
    """
    x = np.empty(3)  # surface point of the last evaluated direction
    dx1 = np.empty(3)  # RADIAL: its derivatives along t1, t2
    dx2 = np.empty(3)
    trial = np.empty(3)
    t1 = np.empty(3)
    t2 = np.empty(3)
    # scratch of the finite-difference Hessians
    s1 = np.empty(3)
    s2 = np.empty(3)
    s3 = np.empty(3)
    s4 = np.empty(3)
    hs = np.empty((2, 3))
    # the gradient is a length (SUPPORT) or a squared length (RADIAL): scale amax or amax^2
    extra_length = 1.0 if search == SUPPORT else amax
    tol2 = (NEWTON_GRADIENT_RTOL * amax * extra_length) ** 2
    gradient_scale = 1.0 / (amax * extra_length)
    _tangent_basis(d, t1, t2)
    if search == SUPPORT:
        value = _support(d, axes, ea, eb, x) - (d[0] * p[0] + d[1] * p[1] + d[2] * p[2])
    else:
        _radial(d, axes, ea, eb, x, dx1, dx2, t1, t2)
        value = np.sqrt((x[0] - p[0]) ** 2 + (x[1] - p[1]) ** 2 + (x[2] - p[2]) ** 2)
    for _ in range(NEWTON_MAX_ITERATIONS):
        if value < threshold:
            break
        _tangent_basis(d, t1, t2)
        if search == RADIAL:
            # the derivatives of y along the new frame (x, the support point, needs no frame)
            _radial(d, axes, ea, eb, x, dx1, dx2, t1, t2)
        g1, g2 = _tangent_gradient(search, x, p, t1, t2, dx1, dx2)
        if g1 * g1 + g2 * g2 <= tol2:
            break
        if search == SUPPORT:
            h11, h12, h22 = _support_hessian(d, value, axes, ea, eb, t1, t2, s1, s2, s3, hs)
        else:
            h11, h12, h22 = _radial_hessian(d, p, axes, ea, eb, t1, t2, s1, s2, s3, s4, hs)
        d1, d2 = _newton_step(h11, h12, h22, g1, g2, gradient_scale)
        d1, d2 = _limited_step(d1, d2)
        slope = g1 * d1 + g2 * d2
        merit = _merit(search, value)
        accepted = False
        full = True
        new = value
        for _bt in range(50):  # Armijo backtracking
            _step_on_sphere(d, d1, d2, t1, t2, trial)
            if search == SUPPORT:
                new = _support(trial, axes, ea, eb, x) - (trial[0] * p[0] + trial[1] * p[1] + trial[2] * p[2])
            else:
                _radial(trial, axes, ea, eb, x, dx1, dx2, t1, t2)
                new = np.sqrt((x[0] - p[0]) ** 2 + (x[1] - p[1]) ** 2 + (x[2] - p[2]) ** 2)
            if _merit(search, new) <= merit + ARMIJO_C * slope and new < value:
                accepted = True
                break
            full = False
            d1 *= 0.5
            d2 *= 0.5
        if not accepted:
            break
        for i in range(3):
            d[i] = trial[i]
        converged = full and value - new <= NEWTON_CONVERGED_RTOL * amax
        value = new
        if converged:
            break
    return value


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
def _surface_point_normal(search, d, axes, ea, eb, q_out, nu_out):
    """The surface point (-> q_out) and outward unit normal (-> nu_out) of direction d."""
    if search == SUPPORT:
        for i in range(3):
            nu_out[i] = d[i]
        _support(nu_out, axes, ea, eb, q_out)
    else:
        _radial_normal(d, axes, ea, eb, q_out, nu_out)


@jit(inline="always")
def _exponents(search, body):
    """The exponents the search's functions take: the duals q1, q2 (SUPPORT) or n1, n2 (RADIAL)."""
    if search == SUPPORT:
        return body.q1, body.q2
    return body.n1, body.n2


@jit
def _scan_grid(p, grid, values):
    """values[search, k] <- the value of each search at grid direction k (SUPPORT: h(n) - n.p,
    RADIAL: |y(u) - p|); returns the first index of the smallest value of each."""
    k_support = 0
    k_radial = 0
    for k in range(grid.shape[0]):
        values[SUPPORT, k] = grid[k, 3] - (grid[k, 0] * p[0] + grid[k, 1] * p[1] + grid[k, 2] * p[2])
        values[RADIAL, k] = np.sqrt((grid[k, 7] - p[0]) ** 2 + (grid[k, 8] - p[1]) ** 2 + (grid[k, 9] - p[2]) ** 2)
        if values[SUPPORT, k] < values[SUPPORT, k_support]:
            k_support = k
        if values[RADIAL, k] < values[RADIAL, k_radial]:
            k_radial = k
    return k_support, k_radial


@jit
def _refine_starts(search, p, body, values, n_starts, threshold, best, q_out, nu_out):
    """The smallest of ``best`` and the search's values refined (:func:`_refine_direction`) from
    its best ``n_starts`` mutually separated grid directions (``values``: the search's row of
    :func:`_scan_grid`); q_out, nu_out <- the surface point and normal of each new smallest.
    Starts are separated by their normals (SUPPORT) or by their surface points seen from p
    (RADIAL).  Returns as soon as the smallest is below ``threshold``."""
    grid = body.grid
    ea, eb = _exponents(search, body)
    start = _GRID_N if search == SUPPORT else _GRID_U
    apart = _GRID_N if search == SUPPORT else _GRID_Y
    cos_sep = np.cos(START_SEPARATION)
    chosen = np.empty(n_starts, dtype=np.int64)
    d = np.empty(3)
    origin = np.zeros(3)
    for i in range(3):
        origin[i] = 0.0 if search == SUPPORT else p[i]
    nc = 0
    for _ in range(n_starts):
        kbest = _separated_best(values, grid[:, apart:apart + 3], origin, chosen, nc, cos_sep)
        if kbest < 0:
            break
        chosen[nc] = kbest
        nc += 1
        for i in range(3):
            d[i] = grid[kbest, start + i]
        v = _refine_direction(search, d, p, body.axes, ea, eb, body.amax, threshold)
        if v < best:
            best = v
            _surface_point_normal(search, d, body.axes, ea, eb, q_out, nu_out)
        if best < threshold:
            return best
    return best


@jit
def _superellipsoid_min(p, body, n_starts, threshold, q_out, nu_out, methods=3):
    """Distance of an interior point p to the surface of the convex superellipsoid ``body``
    (a :class:`Superellipsoid`).

    Two independent local searches, each of whose values is an upper bound on the
    distance; the result is the smaller of those run (``methods``: bit 1 SUPPORT, bit 2
    RADIAL):

    - SUPPORT: for a convex body the distance from an interior point to the boundary is
      the distance to the nearest supporting plane, min over unit n of h(n) - n.p with
      h the closed-form support function (:func:`_support`); negative outside;
    - RADIAL: min over directions u of |y(u) - p|, y(u) the surface point in direction u.

    Each scans fixed directions (``body.grid`` rows: normal n, h(n), direction u, y(u);
    :func:`_scan_grid`) and refines the best ``n_starts`` mutually separated ones with
    :func:`_refine_direction` (:func:`_refine_starts`): normals more than START_SEPARATION
    apart, and surface points more than START_SEPARATION apart as seen from p, so that the
    nearest points on two faces meeting at an edge both get a start.  Returns early, with a
    value below ``threshold``, as soon as one is found.  The nearest surface point found
    goes to q_out and its outward unit normal to nu_out.
    """
    grid = body.grid
    values = np.empty((2, grid.shape[0]))
    k_support, k_radial = _scan_grid(p, grid, values)
    for search in (SUPPORT, RADIAL):
        k = k_support if search == SUPPORT else k_radial
        if methods & (1 << search) and values[search, k] < threshold:
            ea, eb = _exponents(search, body)
            start = _GRID_N if search == SUPPORT else _GRID_U
            _surface_point_normal(search, grid[k, start:start + 3], body.axes, ea, eb, q_out, nu_out)
            return values[search, k]
    best = np.inf
    for search in (SUPPORT, RADIAL):
        if methods & (1 << search):
            best = _refine_starts(search, p, body, values[search], n_starts, threshold, best, q_out, nu_out)
            if best < threshold:
                return best
    return best
