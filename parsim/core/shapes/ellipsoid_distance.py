"""Exact distance from a point to an ellipsoid surface (Eberly's robust bisection)."""

import numpy as np

from parsim.core.jit import jit


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
def _eberly_root(r0, r1, z0, z1, z2, g):
    """Root sigma = s + 1 of (r0 z0 / (sigma - 1 + r0))^2 + (r1 z1 / (sigma - 1 + r1))^2
    + (z2 / sigma)^2 = 1 (Eberly's GetRoot for the ellipsoid, shifted: bisection on sigma
    keeps full relative precision of sigma, and of x2 = y2 / sigma, when z2 is tiny).
    The ellipse is the case ``r1 = 1, z1 = 0`` (its middle term is exactly zero)."""
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
                sigma = _eberly_root(r0, 1.0, z0, 0.0, z1, g)
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
                    sigma = _eberly_root(r0, r1, z0, z1, z2, g)
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
