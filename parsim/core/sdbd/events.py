"""Event solvers of SDBD (Topic & Poeschel 2016, section 3), as small numba kernels.

Every rolling motion is a rotation by an angle ``phi >= 0`` about a unit axis ``u``
through a fixed point ``P`` (the pivot).  A point ``x`` of the particle then moves on the
circle ::

    x(phi) = P + h u + rho (cos phi e1 + sin phi e2),
    h = (x - P) . u,   rho e1 = x - P - h u,   e2 = u x e1.

All contact equations of the paper reduce to one scalar equation on this circle,

    f(phi) = A cos phi + B sin phi = K ,                                        (*)

whose "forbidden" side ``f > K`` is the set of positions where the event has happened
(an overlap, a point below a plane, ...).  ``f(0) = A <= K`` (the present position is
outside), and the event is the first entry ``phi_e = alpha - beta`` with
``alpha = atan2(B, A)`` and ``beta = arccos(K / M)``, ``M = sqrt(A^2 + B^2)``.  Following
the paper, the solution is first obtained as the pair ``(cos phi_e, sin phi_e)`` from
products (no inverse trigonometric function is needed for the rotation itself)::

    cos phi_e = (A K + B S) / M^2,   sin phi_e = (B K - A S) / M^2,   S = sqrt(M^2 - K^2);

the angle ``atan2(sin, cos)`` in ``[0, 2 pi)`` is used only to order events.

* Sphere-sphere contact (3.2.2, eqs. 7-12; 3.3.2 with the axis of eq. 24): ``|x(phi) - s|
  = D`` with ``D = R_a + R_s``.  With ``q = s - P``, ``A = e1 . q``, ``B = e2 . q`` and
  ``K = A + (|x - s|^2 - D^2) / (2 rho)``.  This is the paper's intersection of the
  circle of ``x`` (radius ``R_c1 = rho``) with the circle cut from the sphere of radius
  ``D`` about ``s`` by the plane of motion (radius ``R_c2 = sqrt(D^2 - (n.(s - O'))^2)``,
  eq. 12, at distance ``d`` from the axis), written in the frame of the moving point:
  the two intersection points are ``phi = alpha -/+ beta``; ``K >= M`` is the paper's
  negative root argument of eq. 12 or circles that do not meet.  The ``-`` root is the
  entry into contact, the ``+`` root the exit.
* Point-plane crossing (3.2.5 eqs. 19-23; 3.2.3 eq. 17; 3.3.3 eq. 30; 3.3.4): the point
  must stay on the side ``N . x >= c0``; ``A = -N . e1``, ``B = -N . e2``,
  ``K = A + (N . x - c0) / rho``.  The paper's line ``y' = Delta`` (eq. 23) is the same
  crossing in its frame (22).
* Hanging (3.2.4 eq. 18, 3.3.5 eq. 32): the centre of mass reaches the lowest point of
  its circle.

The comparison "the event with the highest centre of mass comes first" of the paper is the
comparison of angles in ``[0, phi_hang]``: along this arc the centre of mass descends
monotonically, and ``phi <= phi_hang`` is exactly the validity condition eq. 16 (the
centre of mass does not swing past its lowest point), see :func:`same_side_eq16`.
"""

import math

import numpy as np

from parsim.core.jit import jit
from parsim.core.sdbd.constants import (
    ANGLE_EPS,
    CURVATURE_TOL,
    NZ_TOL,
    RATE_TOL,
    TOUCH_TOL,
)

__all__ = [
    "POLICY_NEW",
    "POLICY_TRUSTED",
    "arc_frame",
    "arc_range",
    "circle_entry",
    "first_entry",
    "sphere_coefficients",
    "plane_coefficients",
    "sphere_contact_angle",
    "plane_contact_angle",
    "fall_drop",
    "hang_cos_sin",
    "hanging_com_one",
    "hanging_com_two",
    "loss_position_eq17",
    "release_plane",
    "sliding_wall_release_plane",
    "same_side_eq16",
]

TWO_PI = 2.0 * math.pi

#: Policy for an obstacle touched at ``phi = 0`` that was not a contact before the move:
#: an entry at ``phi = 0`` is reported when the point moves into the forbidden side at
#: first order, or at second order (the curvature of its gap).
POLICY_NEW = 0
#: Policy for a contact that the steepest-descent decision has just released (it found
#: the contact opening): the root at ``phi = 0`` is that opening and is skipped.
POLICY_TRUSTED = 1


@jit
def arc_frame(x, pivot, axis, e1, e2):
    """Circle of ``x`` about the axis: returns ``(h, rho)`` and writes ``e1, e2``.

    ``rho = 0`` (the point lies on the axis) leaves ``e1, e2`` zero.
    """
    r0 = x[0] - pivot[0]
    r1 = x[1] - pivot[1]
    r2 = x[2] - pivot[2]
    h = r0 * axis[0] + r1 * axis[1] + r2 * axis[2]
    p0 = r0 - h * axis[0]
    p1 = r1 - h * axis[1]
    p2 = r2 - h * axis[2]
    rho = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
    if rho == 0.0:
        for k in range(3):
            e1[k] = 0.0
            e2[k] = 0.0
        return h, 0.0
    p0 /= rho
    p1 /= rho
    p2 /= rho
    e1[0] = p0
    e1[1] = p1
    e1[2] = p2
    e2[0] = axis[1] * p2 - axis[2] * p1
    e2[1] = axis[2] * p0 - axis[0] * p2
    e2[2] = axis[0] * p1 - axis[1] * p0
    return h, rho


@jit
def arc_range(rho, e1k, e2k, phi_lim, cos_lim, sin_lim):
    """Range of ``rho (e1k cos phi + e2k sin phi)`` over ``[0, phi_lim]``: the extent, along
    one coordinate, of the arc ``phi in [0, phi_lim]`` of a circle of :func:`arc_frame`
    (``e1k, e2k`` the components of ``e1, e2``; ``cos_lim, sin_lim`` those of ``phi_lim``)."""
    f0 = rho * e1k
    f1 = rho * (e1k * cos_lim + e2k * sin_lim)
    lo = min(f0, f1)
    hi = max(f0, f1)
    r = math.sqrt(e1k * e1k + e2k * e2k)
    m = rho * r
    if _direction_within(e2k, e1k, r, phi_lim, cos_lim, False):
        hi = m
    if _direction_within(e2k, e1k, r, phi_lim, cos_lim, True):
        lo = -m
    return lo, hi


@jit(inline="always")
def _direction_within(y, x, r, lim, cos_lim, opposite):
    """Does the angle of the direction ``(x, y)`` (of length ``r``; turned by pi if ``opposite``),
    taken in ``[0, 2 pi)``, lie within ``[0, lim]``?  Where the answer is certain from the cosine
    (the direction well away from the axis, ``lim`` well below pi) no arctangent is computed;
    elsewhere the arctangent decides, as it always did."""
    if lim < math.pi - _LIMIT_BELOW_PI and r > 0.0 and abs(y) > _COS_MARGIN * r:
        if (y < 0.0) != opposite:
            return False  # an angle in (pi, 2 pi)
        cosine = (-x if opposite else x) / r
        if cosine > cos_lim + _COS_MARGIN:
            return True
        if cosine < cos_lim - _COS_MARGIN:
            return False
    th = math.atan2(y, x)
    if th < 0.0:
        th += TWO_PI
    if opposite:
        th += math.pi
        if th >= TWO_PI:
            th -= TWO_PI
    return th <= lim


# An entry angle is known to lie beyond a limit without its arctangent when the limit is this far
# below pi and the cosine this far below the limit's (the arctangent's error is ~1e-16).
_LIMIT_BELOW_PI = 1e-6
_COS_MARGIN = 1e-9
NO_LIMIT = (np.inf, -2.0)
"""``(limit, cos limit)`` of :func:`first_entry` that skips nothing."""


@jit(inline="always")
def _beyond(c, s, limit, cos_limit, wraps):
    """Is the angle of ``(c, s)`` in ``[0, 2 pi)`` certainly above ``limit``?  A cheap test that
    answers True only where ``atan2`` would give an angle above ``limit`` (``limit`` well below
    pi).  ``wraps``: an angle just below 2 pi counts as 0 (:func:`first_entry`), so a negative
    sine is beyond only away from it."""
    if limit >= math.pi - _LIMIT_BELOW_PI:
        return False
    if s < 0.0:
        return not wraps or c < 0.0 or s < -2.0 * ANGLE_EPS
    return c < cos_limit - _COS_MARGIN


@jit
def circle_entry(A, B, K, limit=np.inf, cos_limit=-2.0):
    """First entry ``phi in [0, 2 pi)`` into ``A cos phi + B sin phi > K``.

    Returns ``(phi, cos phi, sin phi)``; ``phi = inf`` when the circle never enters
    (``K >= M``, including the tangent case, which touches without overlapping), or when
    the entry certainly lies beyond ``limit`` (of cosine ``cos_limit``): then no arctangent
    is computed (:func:`_beyond`; an entry just below 2 pi is kept, it counts as 0).
    """
    M2 = A * A + B * B
    if M2 == 0.0:
        return np.inf, 1.0, 0.0
    M = math.sqrt(M2)
    if K >= M:
        return np.inf, 1.0, 0.0
    if K <= -M:
        # The whole circle except one point is on the forbidden side.
        return 0.0, 1.0, 0.0
    S = math.sqrt((M - K) * (M + K))
    c = (A * K + B * S) / M2
    s = (B * K - A * S) / M2
    if _beyond(c, s, limit, cos_limit, True):
        return np.inf, 1.0, 0.0
    phi = math.atan2(s, c)
    if phi < 0.0:
        phi += TWO_PI
    return phi, c, s


@jit
def first_entry(A, B, K, gap, gscale, ell, policy, limit=np.inf, cos_limit=-2.0):
    """Event angle of one obstacle along the circle, with the touching rules; ``inf`` also when
    the event certainly lies beyond ``limit`` (of cosine ``cos_limit``; :func:`circle_entry`),
    where a caller discards it anyway, so that no arctangent is computed for it.

    ``gap`` is the present clearance (length) and ``gscale`` converts lengths into units
    of ``f`` (``|x - s| / rho`` for a sphere, ``1 / rho`` for a plane).  When the point
    touches (``|gap| <= TOUCH_TOL ell``) the root at ``phi = 0`` is ambiguous:

    * ``POLICY_NEW``: the event is at ``phi = 0`` if the point moves into the forbidden
      side, at first order (rate ``> RATE_TOL ell``) or, when tangent, at second order
      (``f'' = -A`` above ``CURVATURE_TOL ell`` in units of ``f``, the decision's test of
      :func:`.decision.contact_opens`); otherwise the root at 0 is the exit and the next
      entry is returned;
    * ``POLICY_TRUSTED``: the root at 0 is skipped.

    A touching point that leaves the obstacle at first order (``B < 0``) is at the exit
    root ``phi = 0`` of the touching position (gap 0, ``K = A``), and its next entry is the
    other root of ``A (cos phi - 1) + B sin phi = 0``, ``tan(phi / 2) = B / A``::

        cos phi = (A^2 - B^2) / M^2,   sin phi = 2 A B / M^2,

    which lies in ``(0, pi)`` when the circle curves back into the obstacle (``A < 0``,
    ``phi ~ 2 B / A``).  The roots of (*) with the measured gap are not used there: the two
    roots near 0 are ``~ 2 |B| / |A|`` apart and a round-off gap of either sign shifts
    them by ``~ gap gscale / |B|``, so when the point leaves slowly (``B^2 <~ |A| gap
    gscale``) a gap of -1e-14 makes them vanish and the re-entry would be lost (the
    sphere would roll on through the obstacle).

    Returns ``(phi, cos phi, sin phi)``, ``phi = inf`` if there is no event.
    """
    touching = abs(gap) <= TOUCH_TOL * ell
    if touching:
        if policy == POLICY_NEW:
            tb = RATE_TOL * ell * gscale
            if B > tb:
                return 0.0, 1.0, 0.0
            if B >= -tb and -A > CURVATURE_TOL * ell * gscale:
                return 0.0, 1.0, 0.0
        if B < 0.0:
            # leaving: the next entry of the touching position, gap snapped to 0
            M2 = A * A + B * B
            c = (A * A - B * B) / M2
            s = 2.0 * A * B / M2
            if _beyond(c, s, limit, cos_limit, False):
                return np.inf, 1.0, 0.0
            phi = math.atan2(s, c)
            if phi < 0.0:
                phi += TWO_PI
            return phi, c, s
    phi, c, s = circle_entry(A, B, K, limit, cos_limit)
    if phi == np.inf:
        return phi, c, s
    if touching:
        if phi < ANGLE_EPS or phi > TWO_PI - ANGLE_EPS:
            return np.inf, 1.0, 0.0
    elif phi > TWO_PI - ANGLE_EPS:
        return 0.0, 1.0, 0.0
    return phi, c, s


@jit
def sphere_coefficients(x, pivot, axis, s, D, e1, e2):
    """Coefficients of (*) for the contact of the moving point ``x`` with a sphere at ``s``.

    Returns ``(A, B, K, rho, dist0)``; ``rho = 0`` means the distance never changes.
    """
    h, rho = arc_frame(x, pivot, axis, e1, e2)
    d0 = x[0] - s[0]
    d1 = x[1] - s[1]
    d2 = x[2] - s[2]
    dist2 = d0 * d0 + d1 * d1 + d2 * d2
    if rho == 0.0:
        return 0.0, 0.0, 0.0, 0.0, math.sqrt(dist2)
    q0 = s[0] - pivot[0]
    q1 = s[1] - pivot[1]
    q2 = s[2] - pivot[2]
    A = e1[0] * q0 + e1[1] * q1 + e1[2] * q2
    B = e2[0] * q0 + e2[1] * q1 + e2[2] * q2
    K = A + (dist2 - D * D) / (2.0 * rho)
    return A, B, K, rho, math.sqrt(dist2)


@jit(inline="always")
def plane_coefficients(x, pivot, axis, normal, c0, e1, e2):
    """Coefficients of (*) for the point ``x`` crossing to ``normal . x < c0``.

    Returns ``(A, B, K, rho, gap)`` with ``gap = normal . x - c0``.
    """
    h, rho = arc_frame(x, pivot, axis, e1, e2)
    gap = normal[0] * x[0] + normal[1] * x[1] + normal[2] * x[2] - c0
    if rho == 0.0:
        return 0.0, 0.0, 0.0, 0.0, gap
    A = -(normal[0] * e1[0] + normal[1] * e1[1] + normal[2] * e1[2])
    B = -(normal[0] * e2[0] + normal[1] * e2[1] + normal[2] * e2[2])
    K = A + gap / rho
    return A, B, K, rho, gap


@jit
def sphere_contact_angle(x, pivot, axis, s, D, ell, policy):
    """Angle at which the sphere centred at ``x`` (rotating) first touches the sphere at ``s``.

    ``D`` is the sum of radii.  Returns ``(phi, cos, sin)`` (``inf`` if never).
    """
    e1 = np.empty(3)
    e2 = np.empty(3)
    A, B, K, rho, dist0 = sphere_coefficients(x, pivot, axis, s, D, e1, e2)
    if rho == 0.0:
        return np.inf, 1.0, 0.0
    return first_entry(A, B, K, dist0 - D, dist0 / rho, ell, policy)


@jit
def plane_contact_angle(x, pivot, axis, normal, c0, ell, policy):
    """Angle at which the rotating point ``x`` first reaches ``normal . x = c0`` from above."""
    e1 = np.empty(3)
    e2 = np.empty(3)
    A, B, K, rho, gap = plane_coefficients(x, pivot, axis, normal, c0, e1, e2)
    if rho == 0.0:
        return np.inf, 1.0, 0.0
    return first_entry(A, B, K, gap, 1.0 / rho, ell, policy)


@jit
def fall_drop(ax, ay, az, ra, sx, sy, sz, rs):
    """Eqs. 1-2: vertical drop of sphere ``a`` until it touches sphere ``s`` (``inf`` if never).

    ``Delta_xy = (R_a + R_s)^2 - (x_a - x_s)^2 - (y_a - y_s)^2 > 0`` (eq. 1) and the drop is
    ``z_a - z_s - sqrt(Delta_xy)`` (eq. 2).  A contact whose normal would be horizontal
    within ``NZ_TOL`` only grazes and is not an event; a drop below ``-TOUCH_TOL``
    (sphere ``s`` not below ``a``) is none.  ``x, y`` differences must already be minimum
    images.  Returns the drop clamped at 0 (touching), in units of length.
    """
    D = ra + rs
    dx = ax - sx
    dy = ay - sy
    delta = D * D - dx * dx - dy * dy
    if delta <= 0.0:
        return np.inf
    h = math.sqrt(delta)
    if h <= NZ_TOL * D:
        return np.inf
    dz = az - sz - h
    return dz


@jit
def hanging_com_one(com, pivot, out):
    """Eq. 18: position of the centre of mass hanging straight below the pivot."""
    d0 = com[0] - pivot[0]
    d1 = com[1] - pivot[1]
    d2 = com[2] - pivot[2]
    dist = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    out[0] = pivot[0]
    out[1] = pivot[1]
    out[2] = pivot[2] - dist


@jit
def hanging_com_two(com, pivot, axis, out):
    """Eq. 32: centre of mass at the lowest point of its circle about ``axis`` through ``pivot``.

    ``O' + |r_cm - O'| n x (n x e_z) / |n x e_z|`` with ``O'`` the projection of the
    centre of mass on the axis; returns False if the axis is vertical (no lowest point).
    """
    h = (com[0] - pivot[0]) * axis[0] + (com[1] - pivot[1]) * axis[1] + (com[2] - pivot[2]) * axis[2]
    o0 = pivot[0] + h * axis[0]
    o1 = pivot[1] + h * axis[1]
    o2 = pivot[2] + h * axis[2]
    r = math.sqrt((com[0] - o0) ** 2 + (com[1] - o1) ** 2 + (com[2] - o2) ** 2)
    # n x (n x ez) = n (n . ez) - ez
    w0 = axis[0] * axis[2]
    w1 = axis[1] * axis[2]
    w2 = axis[2] * axis[2] - 1.0
    wn = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)  # = |n x ez|
    if wn == 0.0:
        return False
    out[0] = o0 + r * w0 / wn
    out[1] = o1 + r * w1 / wn
    out[2] = o2 + r * w2 / wn
    return True


@jit(inline="always")
def hang_cos_sin(com, pivot, axis):
    """Angle ``phi_hang`` of eqs. 18 / 32: the rotation bringing the centre of mass lowest.

    The hanging position is eq. 32 (eq. 18 for a horizontal axis through the pivot),
    ``O' + |r_cm - O'| w`` with ``w = n x (n x e_z) / |n x e_z|``; its ``(cos, sin)``
    follow from eqs. 13-14.  Returns ``(phi, cos, sin)`` with ``phi in [0, 2 pi)``;
    ``inf`` for a vertical axis or a centre of mass on the axis.  Allocation-free.
    """
    h = (com[0] - pivot[0]) * axis[0] + (com[1] - pivot[1]) * axis[1] + (com[2] - pivot[2]) * axis[2]
    a0 = com[0] - pivot[0] - h * axis[0]
    a1 = com[1] - pivot[1] - h * axis[1]
    a2 = com[2] - pivot[2] - h * axis[2]
    na = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    w0 = axis[0] * axis[2]
    w1 = axis[1] * axis[2]
    w2 = axis[2] * axis[2] - 1.0
    wn = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    if wn == 0.0 or na == 0.0:
        return np.inf, 1.0, 0.0
    w0 /= wn
    w1 /= wn
    w2 /= wn
    c = (a0 * w0 + a1 * w1 + a2 * w2) / na
    s = (axis[0] * (a1 * w2 - a2 * w1) + axis[1] * (a2 * w0 - a0 * w2)
         + axis[2] * (a0 * w1 - a1 * w0)) / na
    phi = math.atan2(s, c)
    if phi < 0.0:
        phi += TWO_PI
    return phi, c, s


@jit
def loss_position_eq17(a1, pivot, axis, out):
    """Eq. 17: position of the pivot sphere when it is level with its sediment sphere.

    ``O' + |r_1 - O'| n x e_z / |n x e_z|`` (the paper writes it for a horizontal axis,
    where ``|n x e_z| = 1``); ``O'`` is the projection of ``a1`` on the axis.
    """
    h = (a1[0] - pivot[0]) * axis[0] + (a1[1] - pivot[1]) * axis[1] + (a1[2] - pivot[2]) * axis[2]
    o0 = pivot[0] + h * axis[0]
    o1 = pivot[1] + h * axis[1]
    o2 = pivot[2] + h * axis[2]
    r = math.sqrt((a1[0] - o0) ** 2 + (a1[1] - o1) ** 2 + (a1[2] - o2) ** 2)
    w0 = axis[1]
    w1 = -axis[0]
    wn = math.sqrt(w0 * w0 + w1 * w1)
    out[0] = o0 + r * w0 / wn
    out[1] = o1 + r * w1 / wn
    out[2] = o2


@jit(inline="always")
def release_plane(com, px, py, ay, y_is_sphere, normal_y, out_normal):
    """Eqs. 25-30: the plane whose crossing releases rolling on pivot ``x`` from contact ``y``.

    While the particle rotates about the axis through the pivots ``px`` and ``py``, rolling
    on ``x`` alone (steepest descent, axis ``n_x = e_z x (r_cm - px) / |...|``) becomes
    possible when the velocity it would give the sphere ``a_y`` of contact ``y`` no longer
    points into the obstacle, ``t_{x,y} . N_y = 0`` (eq. 25).

    * ``y`` a sphere contact (``N_y`` along ``a_y - py``): with ``A = (a_y - px).(r_cm - px)``
      and ``B = (r_cm - px).(a_y - py)``, both constant during the rotation because ``px``
      and ``py`` lie on the axis, eq. 29 reads ``F = (B - A) z_ay - B z_px + A z_py`` and the
      release is ``F > 0``: a horizontal plane for the point ``a_y`` (eq. 30).  (Derivation:
      ``(e_z x d) x e = d (e_z . e) - e_z (d . e)`` with ``d = r_cm - px``, ``e = a_y - px``,
      dotted with ``f = a_y - py``.)
    * ``y`` a plane contact (floor, wall; its pivot is its own sphere centre ``py = a_y``,
      fixed on the axis): ``F = e_z (N . r_cm) - [e_z N . px + N_z (d . e)]`` with
      ``e = py - px`` and ``d . e`` constant: a plane crossing of the centre of mass.

    Writes the plane as ``out_normal . point >= c0`` (the side where ``x`` is still
    blocked) and returns ``(valid, use_com, c0, gap)``; ``gap = out_normal . point - c0``
    is negative when the release condition already holds.
    """
    d0 = com[0] - px[0]
    d1 = com[1] - px[1]
    d2 = com[2] - px[2]
    if y_is_sphere:
        A = (ay[0] - px[0]) * d0 + (ay[1] - px[1]) * d1 + (ay[2] - px[2]) * d2
        B = d0 * (ay[0] - py[0]) + d1 * (ay[1] - py[1]) + d2 * (ay[2] - py[2])
        slope = B - A
        scale = abs(A) + abs(B)
        if abs(slope) <= 1e-14 * scale or scale == 0.0:
            return False, False, 0.0, 0.0
        zstar = (B * px[2] - A * py[2]) / slope
        out_normal[0] = 0.0
        out_normal[1] = 0.0
        if slope > 0.0:
            # release when z_ay > z*: stay blocked while -z >= -z*
            out_normal[2] = -1.0
            c0 = -zstar
        else:
            out_normal[2] = 1.0
            c0 = zstar
        gap = out_normal[2] * ay[2] - c0
        return True, False, c0, gap
    e0 = py[0] - px[0]
    e1 = py[1] - px[1]
    e2 = py[2] - px[2]
    en = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    if abs(e2) <= 1e-14 * en or en == 0.0:
        return False, True, 0.0, 0.0
    de = d0 * e0 + d1 * e1 + d2 * e2
    nx = normal_y[0]
    ny = normal_y[1]
    nz = normal_y[2]
    level = nx * px[0] + ny * px[1] + nz * px[2] + nz * de / e2
    if e2 > 0.0:
        out_normal[0] = -nx
        out_normal[1] = -ny
        out_normal[2] = -nz
        c0 = -level
    else:
        out_normal[0] = nx
        out_normal[1] = ny
        out_normal[2] = nz
        c0 = level
    gap = out_normal[0] * com[0] + out_normal[1] * com[1] + out_normal[2] * com[2] - c0
    return True, True, c0, gap


@jit(inline="always")
def sliding_wall_release_plane(com, px, ay, normal_y, out_normal):
    """Eqs. 25-30 for a frictionless wall or face ``y``: the plane whose crossing releases rolling
    on pivot ``x`` from it.

    The particle rotates about the axis through ``px`` along the wall's normal ``N``.  Rolling
    on ``x`` alone (axis ``e_z x d / |...|``, ``d = r_cm - px``) moves the wall's sphere
    ``a_y`` at the rate ``N . ((e_z x d) x e) = (N . d) (z_ay - z_px) - N_z (d . e)`` away from
    the wall (``e = a_y - px``).  ``N . d`` and ``d . e`` are constant during the rotation (the
    axis is along ``N``, and ``r_cm`` and ``a_y`` turn together about it), so the release is the
    crossing by ``a_y`` of the height ``z_px + N_z (d . e) / (N . d)``, on the side of the sign of
    ``N . d``: the height of the pivot for a vertical wall (``N_z = 0``).

    Same return and plane convention as :func:`release_plane`; the point is ``a_y``
    (``use_com`` False).  ``N . d = 0`` (the centre of mass in the wall-parallel plane through
    the pivot) never releases.
    """
    nd = (normal_y[0] * (com[0] - px[0]) + normal_y[1] * (com[1] - px[1])
          + normal_y[2] * (com[2] - px[2]))
    scale = math.sqrt((com[0] - px[0]) ** 2 + (com[1] - px[1]) ** 2 + (com[2] - px[2]) ** 2)
    if abs(nd) <= 1e-14 * scale or scale == 0.0:
        return False, False, 0.0, 0.0
    height = px[2]
    if normal_y[2] != 0.0:
        de = ((com[0] - px[0]) * (ay[0] - px[0]) + (com[1] - px[1]) * (ay[1] - px[1])
              + (com[2] - px[2]) * (ay[2] - px[2]))
        height += normal_y[2] * de / nd
    out_normal[0] = 0.0
    out_normal[1] = 0.0
    if nd > 0.0:
        # release when z_ay > height: stay blocked while -z_ay >= -height
        out_normal[2] = -1.0
        c0 = -height
    else:
        out_normal[2] = 1.0
        c0 = height
    gap = out_normal[2] * ay[2] - c0
    return True, False, c0, gap


@jit
def same_side_eq16(com, com_new, pivot, axis):
    """Eq. 16: the new centre of mass is on the same side of the vertical plane through the
    pivot containing the axis as the present one (it did not swing past its lowest point):
    ``((r_cm - r_s) . (e_z x n)) ((r'_cm - r_s) . (e_z x n)) > 0``."""
    w0 = -axis[1]
    w1 = axis[0]
    a = (com[0] - pivot[0]) * w0 + (com[1] - pivot[1]) * w1
    b = (com_new[0] - pivot[0]) * w0 + (com_new[1] - pivot[1]) * w1
    return a * b > 0.0
