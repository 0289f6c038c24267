"""The cylindrical container, modelled as the regular polygon of planar walls inscribed in it.

A cylinder of radius ``R`` about the vertical axis through ``c = (cx, cy)`` is modelled by the
``n`` planar frictionless walls of the regular polygon inscribed in its circle (why a polygon:
see :mod:`parsim.core.sdbd`).  Side ``k`` (``0 <= k < n``) has the outward horizontal unit
normal ``u_k = (cos theta_k, sin theta_k, 0)`` with ``theta_k = 2 pi k / n`` (side 0 faces
``+x``; with ``n = 4`` the polygon is a square box) and lies on the line ``u_k . x = d_k``,
``d_k = u_k . c + h``, at the apothem ``h = R cos(pi / n)`` from the axis.  A sphere of radius
``r`` centred at ``a`` is inside when ``u_k . a <= d_k - r`` for every side; with the
contact normal ``N_k = -u_k`` that points into the container this is the plane convention of
:func:`.contacts.plane_of`, ``N_k . a >= r - d_k``.  The centres of spheres inside lie in the
polygon shrunk by ``r``, whose vertices are at ``R - r / cos(pi / n) <= R - r`` from the axis.

The grid's ``geom`` carries the polygon after the grid's own entries (``geom[GEOM_CONTAINER:]``,
written by :func:`polygon_geometry`): ``cx, cy, h``, then ``u_k`` and ``d_k`` of every side;
``igeom[IGEOM_SIDES]`` holds ``n`` (0: the box).

A sphere whose reach (its radius and a tolerance) does not get it within the apothem of the
axis touches no side; otherwise only the sides whose normal points within the angular reach of
its position can be touched (:func:`candidate_sides`), so that the cost per sphere does not grow
with ``n``.
"""

import math

import numpy as np

from parsim.core.jit import jit
from parsim.core.sdbd.constants import GEOM_CONTAINER

__all__ = [
    "GEOM_CONTAINER",
    "polygon_geometry",
    "side_plane",
    "candidate_sides",
    "side_index",
    "side_gap_in_box",
]

_CX = 0
_CY = 1
_APOTHEM = 2
_SIDES = 3  # then (ux, uy, d) per side
_PER_SIDE = 3


def polygon_geometry(cx, cy, radius, n_sides):
    """The entries ``geom[GEOM_CONTAINER:]`` of the polygon of ``n_sides`` sides inscribed in the
    circle of ``radius`` about ``(cx, cy)`` (float64 array)."""
    k = np.arange(n_sides)
    theta = 2.0 * np.pi * k / n_sides
    ux = np.cos(theta)
    uy = np.sin(theta)
    # the sides facing +-x and +-y are exactly the box walls (cos and sin of multiples of pi / 2
    # are not exact in floating point)
    quarter = (4 * k) % n_sides == 0
    turns = (4 * k[quarter]) // n_sides
    ux[quarter] = np.array([1.0, 0.0, -1.0, 0.0])[turns]
    uy[quarter] = np.array([0.0, 1.0, 0.0, -1.0])[turns]
    apothem = radius * math.cos(math.pi / n_sides)
    d = ux * cx + uy * cy + apothem
    sides = np.stack([ux, uy, d], axis=1).ravel()
    return np.concatenate([np.array([cx, cy, apothem], dtype=np.float64), sides])


@jit(inline="always")
def side_index(k):
    """Position of side ``k`` in ``geom`` (its ``ux``; then ``uy`` and ``d``)."""
    return GEOM_CONTAINER + _SIDES + _PER_SIDE * k


@jit(inline="always")
def side_plane(geom, k, r, nrm):
    """Inward normal (-> nrm) and level of side ``k`` for a sphere of radius ``r``: its centre
    ``a`` must satisfy ``nrm . a >= level``."""
    s = side_index(k)
    nrm[0] = -geom[s]
    nrm[1] = -geom[s + 1]
    nrm[2] = 0.0
    return r - geom[s + 2]


@jit(inline="always")
def side_gap_in_box(geom, k, r, x0, x1, y0, y1):
    """Smallest gap between side ``k`` and a sphere of radius ``r`` centred anywhere in the
    rectangle ``[x0, x1] x [y0, y1]`` (negative: it may cross the side)."""
    s = side_index(k)
    ux = geom[s]
    uy = geom[s + 1]
    far = (ux * 0.5 * (x0 + x1) + abs(ux) * 0.5 * (x1 - x0)
           + uy * 0.5 * (y0 + y1) + abs(uy) * 0.5 * (y1 - y0))
    return geom[s + 2] - r - far


@jit
def candidate_sides(geom, n_sides, x0, x1, y0, y1, reach):
    """The sides that a sphere centred anywhere in the rectangle ``[x0, x1] x [y0, y1]`` can
    come within ``reach`` (its radius and a tolerance) of: ``(first, count)``, the sides
    ``(first + t) % n_sides`` for ``t < count`` (``count = 0``: none).

    A centre ``x`` near side ``k`` has ``u_k . (x - c) >= h - reach``: it is at least
    ``h - reach`` from the axis, and ``u_k`` makes an angle of at most
    ``alpha = arccos((h - reach) / |x - c|)`` with ``x - c``.  The rectangle lies in the disc of
    its half-diagonal ``delta`` about its middle ``m``, so ``|x - c| <= |m - c| + delta`` and the
    direction of ``x - c`` is within ``arcsin(delta / |m - c|)`` of that of ``m - c``.  The range
    of side angles is widened by one side at either end against round-off.
    """
    cx = geom[GEOM_CONTAINER + _CX]
    cy = geom[GEOM_CONTAINER + _CY]
    need = geom[GEOM_CONTAINER + _APOTHEM] - reach
    mx = 0.5 * (x0 + x1) - cx
    my = 0.5 * (y0 + y1) - cy
    delta = 0.5 * math.sqrt((x1 - x0) ** 2 + (y1 - y0) ** 2)
    dist = math.sqrt(mx * mx + my * my)
    if dist + delta < need:
        return 0, 0
    if need <= 0.0 or dist <= delta:
        return 0, n_sides
    half_width = math.asin(delta / dist) + math.acos(min(need / (dist + delta), 1.0))
    if half_width >= math.pi:
        return 0, n_sides
    psi = math.atan2(my, mx)
    per_radian = n_sides / (2.0 * math.pi)
    k0 = int(math.floor((psi - half_width) * per_radian))
    k1 = int(math.ceil((psi + half_width) * per_radian))
    count = k1 - k0 + 1
    if count >= n_sides:
        return 0, n_sides
    return k0 % n_sides, count
