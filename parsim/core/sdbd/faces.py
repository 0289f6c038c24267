"""The inclined and vertical faces of a convex mesh vessel, as planes.

A vessel whose inside is convex is the intersection of the half-spaces behind its faces, so a
sphere of radius ``r`` centred at ``a`` is inside exactly when ``N_k . a >= c_k + r`` for every
face ``k`` (inward unit normal ``N_k``, the face's plane ``N_k . x = c_k``): from inside, a
sphere meets a face's plane only within the face, and never an edge or a vertex (they are the
vessel's valleys).  The vessel sits in the walled box of its bounding box (its faces in the
box's sides are those walls, its bottom face in ``z = 0`` is the floor); the faces here are the
others.

A face is a wall in every respect (a plane obstacle ``OB_FACE`` with the face's index in the
contact's ``sediment`` field): frictionless, a sphere of infinite radius that the touching
sphere slides along, or glued, a pivot at the touching sphere's centre (see :mod:`.decision`
and :mod:`.slide` for the motions on inclined faces).

The grid's ``geom`` carries the faces after its own entries (``geom[GEOM_CONTAINER:]``, built by
:func:`face_geometry`): per face ``N_x, N_y, N_z, c`` and the box ``x0, x1, y0, y1, z0, z1``
that bounds it; ``igeom[IGEOM_FACES]`` holds their number.  A sphere can touch face ``k`` only
when its centre lies within ``r`` of that box (its contact point is on the face), so a search
skips every face whose box is out of reach.
"""

import numpy as np

from parsim.core.jit import jit
from parsim.core.sdbd.constants import GEOM_CONTAINER

__all__ = ["FACE_WIDTH", "face_geometry", "face_plane", "face_gap", "face_within", "face_count_of"]

#: Entries of one face in ``geom``: normal (3), level, bounding box (6).
FACE_WIDTH = 10
_LEVEL = 3
_BOX = 4


def face_geometry(normals, levels, boxes):
    """The entries ``geom[GEOM_CONTAINER:]`` of faces with inward unit ``normals`` (F, 3), plane
    levels ``levels`` (F,) (``N . x = c`` on the face) and bounding ``boxes`` (F, 6) as ``x0, x1,
    y0, y1, z0, z1`` (float64 array)."""
    normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    levels = np.asarray(levels, dtype=np.float64).reshape(-1, 1)
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 6)
    return np.ascontiguousarray(np.concatenate([normals, levels, boxes], axis=1).ravel())


def face_count_of(tail, n_sides):
    """Number of faces in a container tail of ``geom``: none with a cylinder's polygon
    (``n_sides > 0``), else one per ``FACE_WIDTH`` entries."""
    return 0 if n_sides > 0 else len(tail) // FACE_WIDTH


@jit(inline="always")
def _at(k):
    return GEOM_CONTAINER + FACE_WIDTH * k


@jit(inline="always")
def face_plane(geom, k, r, nrm):
    """Inward normal (-> nrm) and level of face ``k`` for a sphere of radius ``r``: its centre
    ``a`` must satisfy ``nrm . a >= level``."""
    s = _at(k)
    nrm[0] = geom[s]
    nrm[1] = geom[s + 1]
    nrm[2] = geom[s + 2]
    return geom[s + _LEVEL] + r


@jit(inline="always")
def face_gap(geom, k, r, x, y, z):
    """Gap ``N . a - c - r`` between face ``k`` and the sphere of radius ``r`` centred at
    ``a = (x, y, z)``, and the face's ``N_z`` (the rate at which a fall closes the gap)."""
    s = _at(k)
    return geom[s] * x + geom[s + 1] * y + geom[s + 2] * z - geom[s + _LEVEL] - r, geom[s + 2]


@jit(inline="always")
def face_within(geom, k, lower, upper, reach):
    """Can a sphere centred anywhere in the box from ``lower`` to ``upper`` (each ``(x, y, z)``)
    come within ``reach`` of face ``k``?  (Its bounding box grown by ``reach`` meets that box.)"""
    s = _at(k) + _BOX
    for q in range(3):
        if lower[q] > geom[s + 2 * q + 1] + reach or upper[q] < geom[s + 2 * q] - reach:
            return False
    return True
