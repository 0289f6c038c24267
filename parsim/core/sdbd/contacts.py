"""Contacts of the moving particle, kept as parallel arrays (one row per contact).

A contact is ``(i, ob, j, sh)``: moving sphere ``i`` touches an obstacle of kind ``ob``
(``OB_SPHERE``, ``OB_FLOOR``, ``OB_WALL_*``, ``OB_SIDE``, ``OB_FACE``); for a sphere obstacle ``j``
is the sediment sphere and ``sh`` (row of 3, ``sh[2] = 0``) the periodic image shift that brings
``sed[j]`` next to the particle; a side of the cylinder's polygon or a face of a mesh vessel has
its index in ``j``, the
other planes ``j = -1``; planes have ``sh = 0``.  A list is a
:class:`.bundles.ContactList` with its number of rows beside it.  The engine keeps three
such lists: the contacts, the pivots of a rotation and the contacts released by the last
decision.

:func:`fill_contacts` turns the list into the :class:`.bundles.ContactGeometry` of
:mod:`.decision`;
:func:`keep_touching` and :func:`near_contacts` add obstacles that touch (4.3) or lie
within ``CYCLE_CLOSE_GAP`` (4.2).
"""

import math

from parsim.core.jit import jit
from parsim.core.sdbd.bundles import geometry_arrays, grid_arrays
from parsim.core.sdbd.constants import (
    CYCLE_CLOSE_GAP,
    GEOM_CELL,
    GEOM_LENGTH_X,
    GEOM_LENGTH_Y,
    GEOM_LOWER_X,
    GEOM_LOWER_Y,
    IGEOM_FACES,
    IGEOM_SIDES,
    MAX_CONTACTS,
    OB_FACE,
    OB_FLOOR,
    OB_SIDE,
    OB_SPHERE,
    OB_WALL_XHI,
    OB_WALL_XLO,
    OB_WALL_YHI,
    OB_WALL_YLO,
    TOUCH_TOL,
)
from parsim.core.sdbd.faces import face_plane, face_within
from parsim.core.sdbd.grid import grid_collect_growing, min_image
from parsim.core.sdbd.polygon import candidate_sides, side_plane

__all__ = [
    "plane_of",
    "find_contact",
    "add_contact",
    "copy_contact",
    "fill_contacts",
    "keep_touching",
    "near_contacts",
]


@jit(inline="always")
def plane_of(ob, j, r, geom, nrm):
    """Normal (-> nrm) and level of the plane obstacle ``ob`` (a side of the cylinder or a face of
    a mesh vessel: side or face ``j``) for a sphere of radius ``r``: the sphere's centre ``a`` must satisfy
    ``nrm . a >= level``."""
    nrm[0] = 0.0
    nrm[1] = 0.0
    nrm[2] = 0.0
    if ob == OB_FLOOR:
        nrm[2] = 1.0
        return r
    if ob == OB_WALL_XLO:
        nrm[0] = 1.0
        return geom[GEOM_LOWER_X] + r
    if ob == OB_WALL_XHI:
        nrm[0] = -1.0
        return -(geom[GEOM_LOWER_X] + geom[GEOM_LENGTH_X] - r)
    if ob == OB_WALL_YLO:
        nrm[1] = 1.0
        return geom[GEOM_LOWER_Y] + r
    if ob == OB_SIDE:
        return side_plane(geom, j, r, nrm)
    if ob == OB_FACE:
        return face_plane(geom, j, r, nrm)
    nrm[1] = -1.0
    return -(geom[GEOM_LOWER_Y] + geom[GEOM_LENGTH_Y] - r)


@jit(inline="always")
def find_contact(n, contacts, i, ob, j):
    """Row of contact ``(i, ob, j)`` among the first ``n`` of a list, or -1."""
    sphere = contacts.sphere
    obstacle = contacts.obstacle
    sediment = contacts.sediment
    for l in range(n):
        if sphere[l] == i and obstacle[l] == ob and sediment[l] == j:
            return l
    return -1


@jit(inline="always")
def add_contact(n_c, contacts, i, ob, j, sh0, sh1):
    """Append contact ``(i, ob, j, (sh0, sh1, 0))`` if there is room (``MAX_CONTACTS``);
    returns the new number of contacts."""
    if n_c >= MAX_CONTACTS:
        return n_c
    contacts.sphere[n_c] = i
    contacts.obstacle[n_c] = ob
    contacts.sediment[n_c] = j
    shift = contacts.shift
    shift[n_c, 0] = sh0
    shift[n_c, 1] = sh1
    shift[n_c, 2] = 0.0
    return n_c + 1


@jit(inline="always")
def copy_contact(source, a, target, b):
    """Row ``a`` of one contact list -> row ``b`` of another."""
    target.sphere[b] = source.sphere[a]
    target.obstacle[b] = source.obstacle[a]
    target.sediment[b] = source.sediment[a]
    source_shift = source.shift
    target_shift = target.shift
    for k in range(3):
        target_shift[b, k] = source_shift[a, k]


@jit(inline="always")
def fill_contacts(n_c, contacts, particle, sediment, geom, geometry, nrm):
    """Geometry of the contacts for :func:`decision.decide` (see its module docs)."""
    pos = particle.centre
    rad = particle.radius
    sed = sediment.centre
    sed_r = sediment.radius
    c_sphere = contacts.sphere
    c_obstacle = contacts.obstacle
    c_sediment = contacts.sediment
    c_shift = contacts.shift
    ca, cP, cN, cD, cc0, ckind = geometry_arrays(geometry)
    for l in range(n_c):
        i = c_sphere[l]
        ob = c_obstacle[l]
        ckind[l] = ob
        for k in range(3):
            ca[l, k] = pos[i, k]
        if ob == OB_SPHERE:
            j = c_sediment[l]
            for k in range(3):
                cP[l, k] = sed[j, k] + c_shift[l, k]
            cD[l] = rad[i] + sed_r[j]
            n0 = ca[l, 0] - cP[l, 0]
            n1 = ca[l, 1] - cP[l, 1]
            n2 = ca[l, 2] - cP[l, 2]
            nn = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
            cN[l, 0] = n0 / nn
            cN[l, 1] = n1 / nn
            cN[l, 2] = n2 / nn
            cc0[l] = 0.0
        else:
            c0 = plane_of(ob, c_sediment[l], rad[i], geom, nrm)
            for k in range(3):
                cP[l, k] = pos[i, k]
                cN[l, k] = nrm[k]
            cD[l] = rad[i]
            cc0[l] = c0


@jit(inline="always")
def keep_touching(n_c, contacts, n_dr, released, particle, sediment, geom, ell, nrm):
    """Contacts released by the last decision that still touch (a move of zero or
    round-off length) stay contacts, so that the next decision sees every obstacle
    touching the particle (4.3) and a zero-length move cannot cycle through them."""
    pos = particle.centre
    rad = particle.radius
    sed = sediment.centre
    sed_r = sediment.radius
    r_sphere = released.sphere
    r_obstacle = released.obstacle
    r_sediment = released.sediment
    r_shift = released.shift
    for r in range(n_dr):
        if n_c >= MAX_CONTACTS:
            break
        i = r_sphere[r]
        ob = r_obstacle[r]
        j = r_sediment[r]
        if find_contact(n_c, contacts, i, ob, j) >= 0:
            continue
        if ob == OB_SPHERE:
            g = math.sqrt((pos[i, 0] - sed[j, 0] - r_shift[r, 0]) ** 2
                          + (pos[i, 1] - sed[j, 1] - r_shift[r, 1]) ** 2
                          + (pos[i, 2] - sed[j, 2]) ** 2) - rad[i] - sed_r[j]
        else:
            c0 = plane_of(ob, j, rad[i], geom, nrm)
            g = nrm[0] * pos[i, 0] + nrm[1] * pos[i, 1] + nrm[2] * pos[i, 2] - c0
        if g <= TOUCH_TOL * ell:
            n_c = add_contact(n_c, contacts, i, ob, j, r_shift[r, 0], r_shift[r, 1])
    return n_c


@jit
def near_contacts(n, particle, n_c, contacts, sediment, grid, walls, ell, buf, nrm):
    """Declare closed every obstacle within ``CYCLE_CLOSE_GAP * ell`` of the particle that
    is not a contact yet (4.2).  Returns ``(n_c, added, floor_added, buf)``."""
    pos = particle.centre
    rad = particle.radius
    sed = sediment.centre
    sed_r = sediment.radius
    grid_state = grid_arrays(grid)
    geom, igeom = grid.geom, grid.igeom
    added = 0
    floor_added = False
    lim = CYCLE_CLOSE_GAP * ell
    for i in range(n):
        if n_c >= MAX_CONTACTS:
            break
        reach = rad[i] + 0.5 * geom[GEOM_CELL] + lim
        cnt, buf = grid_collect_growing(grid_state, (pos[i, 0] - reach, pos[i, 1] - reach, pos[i, 2] - reach),
                                        (pos[i, 0] + reach, pos[i, 1] + reach, pos[i, 2] + reach), buf)
        for q in range(cnt):
            j = buf[q]
            rx = sed[j, 0] - pos[i, 0]
            ry = sed[j, 1] - pos[i, 1]
            mx, my = min_image(geom, igeom, rx, ry)
            dz = sed[j, 2] - pos[i, 2]
            g = math.sqrt(mx * mx + my * my + dz * dz) - rad[i] - sed_r[j]
            if g > lim:
                continue
            if find_contact(n_c, contacts, i, OB_SPHERE, j) >= 0:
                continue
            if n_c >= MAX_CONTACTS:
                break
            n_c = add_contact(n_c, contacts, i, OB_SPHERE, j, mx - rx, my - ry)
            added += 1
        n_sides = igeom[IGEOM_SIDES]
        last = OB_WALL_YHI if walls and n_sides == 0 else OB_FLOOR
        for ob in range(OB_FLOOR, last + 1):
            n_c, new = _close_plane(n_c, contacts, i, ob, -1, pos, rad, geom, lim, nrm)
            added += new
            if new and ob == OB_FLOOR:
                floor_added = True
        if walls and n_sides > 0:
            first, count = candidate_sides(geom, n_sides, pos[i, 0], pos[i, 0], pos[i, 1], pos[i, 1],
                                           rad[i] + lim)
            for t in range(count):
                n_c, new = _close_plane(n_c, contacts, i, OB_SIDE, (first + t) % n_sides, pos, rad,
                                        geom, lim, nrm)
                added += new
        for face in range(igeom[IGEOM_FACES]):
            if face_within(geom, face, (pos[i, 0], pos[i, 1], pos[i, 2]), (pos[i, 0], pos[i, 1], pos[i, 2]),
                           rad[i] + lim):
                n_c, new = _close_plane(n_c, contacts, i, OB_FACE, face, pos, rad, geom, lim, nrm)
                added += new
    return n_c, added, floor_added, buf


@jit(inline="always")
def _close_plane(n_c, contacts, i, ob, j, pos, rad, geom, lim, nrm):
    """Add the plane ``(ob, j)`` as a contact of sphere ``i`` if it is within ``lim`` of it and
    not a contact yet; returns ``(n_c, 1 if added else 0)``."""
    c0 = plane_of(ob, j, rad[i], geom, nrm)
    g = nrm[0] * pos[i, 0] + nrm[1] * pos[i, 1] + nrm[2] * pos[i, 2] - c0
    if g > lim or n_c >= MAX_CONTACTS:
        return n_c, 0
    if find_contact(n_c, contacts, i, ob, j) >= 0:
        return n_c, 0
    return add_contact(n_c, contacts, i, ob, j, 0.0, 0.0), 1
