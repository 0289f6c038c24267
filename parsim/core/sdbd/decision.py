"""Steepest-descent decision: which motion a particle with given contacts follows.

Contacts are given by their :class:`.bundles.ContactGeometry` (``n_c`` rows used); the
functions below name its fields as the paper's symbols:

``ca``   (``centre``) centre of the moving sphere of the contact
``cP``   (``pivot``) the sediment sphere's centre (minimum image), or for the floor and a
         glued wall the moving sphere's own centre (the plane holds it; see the engine docs);
         a frictionless wall's pivot lies at infinity behind it and ``cP`` is not used
``cN``   (``normal``) unit contact normal pointing from the obstacle to the moving sphere
``ckind`` (``kind``) obstacle kind (``OB_SPHERE``, ``OB_FLOOR``, ``OB_WALL_*``)
``cD``   (``reach``) sum of radii (sphere contacts)
``cc0``  (``level``) plane level: the moving sphere's centre must satisfy ``N . a >= c0``

The candidate motions are those of the paper (Fig. 2, 3.2, 3.3):

* fall (3.1): allowed when every contact normal has ``N_z <= NZ_TOL`` (each moving sphere
  is below or level with its obstacle, 3.2.3 / 3.3.4); slope 1, the steepest;
* rotation on one contact ``k`` (3.2): axis ``n = e_z x (r_cm - P_k) / |...|`` (eq. 6),
  slope ``-dz_cm/ds = |d_xy| / |d|`` with ``d = r_cm - P_k``;
* rotation on two contacts ``k, m`` (3.3): axis along ``P_m - P_k`` (eq. 24), the sense
  that lowers the centre of mass, slope ``|(u x d)_z| / |u x d|``.

Frictionless walls (``sliding_walls``).  A wall of inward normal ``N`` (horizontal) is the
paper's sphere obstacle with its radius taken to infinity: its centre, the pivot, lies at
``P_w = a_w - R N`` with ``R -> infinity`` (``a_w`` the touching moving sphere).  Each motion of
the paper becomes, in that limit:

* fall (3.1, eqs. 1-2): the contact normal ``N`` has ``N_z = 0``, so the wall never blocks it
  (3.2.3 holds with equality);
* rotation on the wall alone (3.2, eq. 6): the centre of mass moves on the sphere
  ``|r_cm - P_w| = const``, which becomes the plane ``N . r_cm = const``; its path of steepest
  descent there is vertical, so this motion is the fall and is not a candidate of its own;
* rotation on a pivot ``P`` and the wall (3.3, eq. 24): the axis along ``P_w - P`` becomes the
  line through ``P`` along ``N``; every point keeps ``N . x``, so the wall's sphere stays
  tangent to the wall and slides along it, and the slope is that of eq. 24 with ``u = N``;
* two walls: both pivots at infinity, no axis; the only motion keeping both is the vertical
  translation, the fall again;
* loss of the pivot ``P`` (eq. 17) leaves the wall alone: the fall, decided anew;
* release from the wall while rolling on ``P`` and the wall (eqs. 25-30): rolling on ``P`` alone
  moves ``a_w`` at the rate ``(N . d)(z_aw - z_P)`` away from the wall, ``d = r_cm - P``; ``N . d``
  is constant about an axis along ``N``, so the release is ``a_w`` crossing the height of ``P``
  (:func:`.events.sliding_wall_release_plane`);
* rest (3.3.2, Fig. 2): no rotation descends.  For three pivots with one wall, the support
  "triangle" has a vertex at infinity in the direction ``-N``: the centre of mass rests when its
  horizontal projection lies in the half-strip bounded by the segment between the two finite
  pivots and the two rays from them towards the wall, which is what testing the rotations about
  each finite pivot with ``N`` and about the pair of finite pivots decides;
* hanging (eq. 32) on a pivot and the wall: the centre of mass straight below the line through
  ``P`` along ``N``; straight above it is an unstable equilibrium and is tipped like the others.

With glued walls a wall's pivot is the touching sphere's own centre, like the floor's under
FLOOR_ROLL.

A candidate is *valid* when every other contact opens or stays closed under it: the rate
``N_l . (omega x (a_l - P))`` of its gap is positive, or, when it is tangent within
``RATE_TOL``, the gap's second derivative is not negative (beyond ``CURVATURE_TOL``: the
second-order test of eq. 31).  The steepest valid candidate is chosen, as the paper
prescribes for three contacts (3.3.2); a rotation on one contact is always at least as
steep as a rotation on two that includes it (its centre-of-mass path is the steepest on
the sphere ``|r_cm - P_k| = const``), which is the paper's rule that a newly established
single contact is preferred (3.2.2).  "Steepest" is measured by the slope of the path of
the centre of mass, ``-dz/ds``.

A candidate descends when its slope exceeds ``DESCENT_TOL`` and the rate ``-dz/dphi`` of
the centre of mass exceeds ``DESCENT_RATE_TOL * ell``: a centre of mass on the axis of a
rotation (a rod on two pivots along its own axis) has a slope made of round-off and no
rotation about that axis is a motion.

No valid descending candidate means rest: three contacts, or hanging on one / two.  A
centre of mass exactly above a pivot (or above the axis of two) is an unstable
equilibrium; the decision then tips it about a fixed horizontal axis (x, then y) if that
is valid, so that measure-zero symmetric drops do not balance forever.
"""

import math

from parsim.core.jit import jit
from parsim.core.sdbd.bundles import geometry_arrays
from parsim.core.sdbd.constants import (
    CURVATURE_TOL,
    DESCENT_RATE_TOL,
    DESCENT_TOL,
    MOTION_FALL,
    MOTION_PAIR,
    MOTION_REST,
    MOTION_SINGLE,
    MOTION_SLIDE,
    NZ_TOL,
    OB_FACE,
    OB_SPHERE,
    OB_WALL_XLO,
    RATE_TOL,
    STEEP_TOL,
    TINY,
)

__all__ = ["contact_opens", "decide", "gap_curvature"]

#: Two pivots closer than this (units of ell) are one point: no axis through them.
_SAME_PIVOT = 1e-9


@jit(inline="always")
def contact_opens(l, pivot, axis, ca, cN, ckind, cD, ell):
    """Does contact ``l`` open (or stay closed) under the rotation ``omega = axis`` about ``pivot``
    (both ``(x, y, z)``)?  ``ca, cN, ckind, cD`` are the contact geometry's arrays (module docs)."""
    p0, p1, p2 = pivot
    w0, w1, w2 = axis
    r0 = ca[l, 0] - p0
    r1 = ca[l, 1] - p1
    r2 = ca[l, 2] - p2
    v0 = w1 * r2 - w2 * r1
    v1 = w2 * r0 - w0 * r2
    v2 = w0 * r1 - w1 * r0
    g = cN[l, 0] * v0 + cN[l, 1] * v1 + cN[l, 2] * v2
    if g > RATE_TOL * ell:
        return True
    if g < -RATE_TOL * ell:
        return False
    return gap_curvature(l, r0, r1, r2, w0, w1, w2, cN, ckind, cD) >= -CURVATURE_TOL * ell


@jit(inline="always")
def gap_curvature(l, r0, r1, r2, w0, w1, w2, cN, ckind, cD):
    """The second derivative of the gap of contact ``l`` along the rotation about the unit axis
    ``w``, its moving sphere's centre at ``r`` from a point of the axis, at a tangent contact
    (first derivative zero).  With ``s`` the part of ``r`` normal to the axis (the radius of
    the sphere's circle), ``-N . s`` for a plane and ``|s|^2 / D - N . s`` for a sphere at the
    distance ``D``."""
    wr = w0 * r0 + w1 * r1 + w2 * r2
    s0 = r0 - wr * w0
    s1 = r1 - wr * w1
    s2 = r2 - wr * w2
    curvature = -(cN[l, 0] * s0 + cN[l, 1] * s1 + cN[l, 2] * s2)
    if ckind[l] == OB_SPHERE:
        curvature += (s0 * s0 + s1 * s1 + s2 * s2) / cD[l]
    return curvature


@jit(inline="always")
def _all_open(n_c, skip1, skip2, pivot, axis, ca, cN, ckind, cD, ell):
    """Does every contact but ``skip1`` and ``skip2`` open under the rotation about ``pivot``
    (:func:`contact_opens`)?"""
    for l in range(n_c):
        if l == skip1 or l == skip2:
            continue
        if not contact_opens(l, pivot, axis, ca, cN, ckind, cD, ell):
            return False
    return True


@jit(inline="always")
def _descends(rate, lever, ell):
    """Does a rotation lower the centre of mass?  ``rate`` is -dz/dphi of the centre of mass
    for a unit axis, ``lever`` its distance from the axis: both the slope ``rate / lever``
    and the rate itself must exceed their tolerances (``DESCENT_TOL``, ``DESCENT_RATE_TOL``),
    so that a centre of mass on the axis to round-off, whose slope is meaningless, is no
    descent."""
    return rate > DESCENT_TOL * lever and rate > DESCENT_RATE_TOL * ell


@jit(inline="always")
def _offset_from_pivot(com, cP, k):
    """``d = r_cm - P_k``, its length and the length of its horizontal part."""
    d0 = com[0] - cP[k, 0]
    d1 = com[1] - cP[k, 1]
    d2 = com[2] - cP[k, 2]
    return d0, d1, d2, math.sqrt(d0 * d0 + d1 * d1 + d2 * d2), math.sqrt(d0 * d0 + d1 * d1)


@jit(inline="always")
def _slides(ckind, l, sliding_walls):
    """Is contact ``l`` a frictionless wall (a pivot at infinity)?"""
    return sliding_walls and ckind[l] >= OB_WALL_XLO


@jit(inline="always")
def _pair_axis(cP, cN, ckind, k, m, sliding_walls, ell):
    """The axis through the pivots of contacts ``k`` and ``m``: ``(True, u, b)``, ``u`` its
    unit vector (from pivot ``k`` to pivot ``m``, or along a frictionless wall's normal) and
    ``b`` the contact whose pivot lies on it; ``(False, 0, -1)`` when there is no axis (the
    two pivots are one point, or both at infinity)."""
    slides_k = _slides(ckind, k, sliding_walls)
    slides_m = _slides(ckind, m, sliding_walls)
    if slides_k and slides_m:
        return False, 0.0, 0.0, 0.0, -1
    if slides_k:
        return True, cN[k, 0], cN[k, 1], cN[k, 2], m
    if slides_m:
        return True, cN[m, 0], cN[m, 1], cN[m, 2], k
    u0 = cP[m, 0] - cP[k, 0]
    u1 = cP[m, 1] - cP[k, 1]
    u2 = cP[m, 2] - cP[k, 2]
    L = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    if L <= _SAME_PIVOT * ell:
        return False, 0.0, 0.0, 0.0, -1
    return True, u0 / L, u1 / L, u2 / L, k


@jit(inline="always")
def _face_slide(k, m, cN, ckind, out):
    """The slide on the frictionless planes of contacts ``k`` and ``m`` (``k = m``: on one) when
    one of them is a mesh vessel's face: its unit direction -> ``out[6:9]`` and its slope
    ``-dz/ds``, or ``-1`` when there is none that descends.

    On one plane of inward normal ``N`` (``N_z > 0``) the particle translates down the line of
    steepest descent, ``(N_z N - e_z) / sqrt(1 - N_z^2)``, slope ``sqrt(1 - N_z^2)``; on two, along
    their line ``N_k x N_m``, the sense that descends.  Planes with horizontal normals alone
    (walls, sides) give the fall, decided before."""
    if ckind[k] != OB_FACE and ckind[m] != OB_FACE:
        return -1.0
    if k == m:
        nz = cN[k, 2]
        if nz <= NZ_TOL or nz >= 1.0 - DESCENT_TOL:
            return -1.0
        norm = math.sqrt(1.0 - nz * nz)
        out[6] = nz * cN[k, 0] / norm
        out[7] = nz * cN[k, 1] / norm
        out[8] = (nz * nz - 1.0) / norm
        return norm
    u0 = cN[k, 1] * cN[m, 2] - cN[k, 2] * cN[m, 1]
    u1 = cN[k, 2] * cN[m, 0] - cN[k, 0] * cN[m, 2]
    u2 = cN[k, 0] * cN[m, 1] - cN[k, 1] * cN[m, 0]
    un = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    if un <= TINY:
        return -1.0
    sg = -1.0 / un if u2 > 0.0 else 1.0 / un
    out[6] = sg * u0
    out[7] = sg * u1
    out[8] = sg * u2
    if -out[8] <= DESCENT_TOL:
        return -1.0
    return -out[8]


@jit(inline="always")
def _all_open_sliding(n_c, skip1, skip2, out, cN):
    """Does every contact but ``skip1`` and ``skip2`` open, or stay tangent, under the slide along
    ``out[6:9]``?  The rate of a gap is ``N . s``; at a tangent contact a sphere's gap grows at
    second order and a plane's stays closed, so a rate above ``-RATE_TOL`` is enough."""
    for l in range(n_c):
        if l == skip1 or l == skip2:
            continue
        if cN[l, 0] * out[6] + cN[l, 1] * out[7] + cN[l, 2] * out[8] < -RATE_TOL:
            return False
    return True


@jit(inline="always")
def _keep_direction(out):
    """The slide's direction, ``out[6:9]``, becomes the decision's ``out[0:3]``."""
    for q in range(3):
        out[q] = out[6 + q]


@jit
def decide(com, n_c, geometry, ell, sliding_walls, out):
    """Choose the motion of a particle with centre of mass ``com`` and ``n_c`` contacts of
    the given geometry, wall contacts frictionless if ``sliding_walls``; returns ``(motion,
    k, m, slope)``.

    For a rotation, ``out[0:3]`` is the unit axis (rotation sense: positive angle) and
    ``out[3:6]`` a point of it (the pivot ``P_k``, or for a pair with a frictionless wall the
    other contact's pivot); ``k`` (and ``m`` for a pair) are the pivot contacts, ``-1``
    otherwise.

    The steps, in order: the fall (3.1); the steepest valid rotation on one contact (3.2); a
    steeper one on two (3.3); with neither, the tipping of an unstable equilibrium above one
    pivot or above the axis of two; else rest.

    Why so long: the decision runs at every step of every descent.  Split into those five steps
    as inlined functions, together with the contact search of a rotation
    (:func:`.rolling.roll`'s), it made a deposition of 2·10⁴ spheres execute 4.5 % more instructions
    (benchmarks/side_by_side.py), so the steps stay one function with a comment at the head of each.
    """
    ca, cP, cN, cD, cc0, ckind = geometry_arrays(geometry)
    if n_c == 0:
        return MOTION_FALL, -1, -1, 1.0
    fall = True
    for l in range(n_c):
        if cN[l, 2] > NZ_TOL:
            fall = False
            break
    if fall:
        return MOTION_FALL, -1, -1, 1.0
    best = -1.0
    motion = MOTION_REST
    bk = -1
    bm = -1
    base = -1  # the contact whose pivot lies on the chosen axis
    # rotation on one contact (on a frictionless wall alone: the fall, tested above; on a
    # frictionless inclined face alone: the slide down it)
    for k in range(n_c):
        if _slides(ckind, k, sliding_walls):
            slope = _face_slide(k, k, cN, ckind, out)
            if slope > best + STEEP_TOL and _all_open_sliding(n_c, k, -1, out, cN):
                best = slope
                motion = MOTION_SLIDE
                bk = k
                bm = -1
                base = k
                _keep_direction(out)
            continue
        d0, d1, d2, dn, dh = _offset_from_pivot(com, cP, k)
        if dn <= TINY * ell or not _descends(dh, dn, ell):
            continue
        slope = dh / dn
        if slope <= best + STEEP_TOL:
            continue
        w0 = -d1 / dh
        w1 = d0 / dh
        if _all_open(n_c, k, -1, (cP[k, 0], cP[k, 1], cP[k, 2]), (w0, w1, 0.0), ca, cN, ckind, cD, ell):
            best = slope
            motion = MOTION_SINGLE
            bk = k
            bm = -1
            base = k
            out[0] = w0
            out[1] = w1
            out[2] = 0.0
    # rotation on two contacts
    for k in range(n_c):
        for m in range(k + 1, n_c):
            ok, u0, u1, u2, b = _pair_axis(cP, cN, ckind, k, m, sliding_walls, ell)
            if not ok:
                if _slides(ckind, k, sliding_walls) and _slides(ckind, m, sliding_walls):
                    slope = _face_slide(k, m, cN, ckind, out)
                    if slope > best + STEEP_TOL and _all_open_sliding(n_c, k, m, out, cN):
                        best = slope
                        motion = MOTION_SLIDE
                        bk = k
                        bm = m
                        base = k
                        _keep_direction(out)
                continue
            d0 = com[0] - cP[b, 0]
            d1 = com[1] - cP[b, 1]
            d2 = com[2] - cP[b, 2]
            x0 = u1 * d2 - u2 * d1
            x1 = u2 * d0 - u0 * d2
            x2 = u0 * d1 - u1 * d0
            xn = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
            if xn <= TINY * ell or not _descends(abs(x2), xn, ell):
                continue
            slope = abs(x2) / xn
            if slope <= best + STEEP_TOL:
                continue
            sg = -1.0 if x2 > 0.0 else 1.0
            if _all_open(n_c, k, m, (cP[b, 0], cP[b, 1], cP[b, 2]), (sg * u0, sg * u1, sg * u2), ca, cN, ckind, cD,
                         ell):
                best = slope
                motion = MOTION_PAIR
                bk = k
                bm = m
                base = b
                out[0] = sg * u0
                out[1] = sg * u1
                out[2] = sg * u2
    if motion == MOTION_REST:
        # unstable equilibria: centre of mass straight above a pivot
        for k in range(n_c):
            if _slides(ckind, k, sliding_walls):
                continue
            d0, d1, d2, dn, dh = _offset_from_pivot(com, cP, k)
            if dn <= TINY * ell or _descends(dh, dn, ell) or d2 <= 0.0:
                continue
            for t in range(4):
                w0 = 0.0
                w1 = 0.0
                if t == 0:
                    w0 = 1.0
                elif t == 1:
                    w1 = 1.0
                elif t == 2:
                    w0 = -1.0
                else:
                    w1 = -1.0
                if _all_open(n_c, k, -1, (cP[k, 0], cP[k, 1], cP[k, 2]), (w0, w1, 0.0), ca, cN, ckind, cD, ell):
                    out[0] = w0
                    out[1] = w1
                    out[2] = 0.0
                    for q in range(3):
                        out[3 + q] = cP[k, q]
                    return MOTION_SINGLE, k, -1, 0.0
        # ... or straight above the axis of two pivots (top of its circle)
        for k in range(n_c):
            for m in range(k + 1, n_c):
                ok, u0, u1, u2, b = _pair_axis(cP, cN, ckind, k, m, sliding_walls, ell)
                if not ok:
                    continue
                if 1.0 - abs(u2) <= DESCENT_TOL:
                    continue  # vertical axis: no height change
                d0 = com[0] - cP[b, 0]
                d1 = com[1] - cP[b, 1]
                d2 = com[2] - cP[b, 2]
                h = d0 * u0 + d1 * u1 + d2 * u2
                p0 = d0 - h * u0
                p1 = d1 - h * u1
                p2 = d2 - h * u2
                pn = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
                if pn <= DESCENT_RATE_TOL * ell:
                    continue  # on the axis: no rotation about it lowers the centre of mass
                x2 = u0 * p1 - u1 * p0  # (u x d)_z
                # above: the offset from the axis points up (ez . p > 0) and is normal to
                # the descent direction
                if _descends(abs(x2), pn, ell) or p2 <= 0.0:
                    continue
                for t in range(2):
                    sg = 1.0 if t == 0 else -1.0
                    if _all_open(n_c, k, m, (cP[b, 0], cP[b, 1], cP[b, 2]), (sg * u0, sg * u1, sg * u2), ca, cN,
                                 ckind, cD, ell):
                        out[0] = sg * u0
                        out[1] = sg * u1
                        out[2] = sg * u2
                        for q in range(3):
                            out[3 + q] = cP[b, q]
                        return MOTION_PAIR, k, m, 0.0
        return MOTION_REST, -1, -1, 0.0
    for q in range(3):
        out[3 + q] = cP[base, q]
    return motion, bk, bm, best
