"""Contacts of the moving particle, kept as parallel arrays (one row per contact).

A contact is ``(i, ob, j, sh)``: moving sphere ``i`` touches an obstacle of kind ``ob``
(``OB_SPHERE``, ``OB_FLOOR``, ``OB_WALL_*``); for a sphere obstacle ``j`` is the sediment
sphere and ``sh`` (row of 3, ``sh[2] = 0``) the periodic image shift that brings
``sed[j]`` next to the particle; planes have ``j = -1`` and ``sh = 0``.  The engine keeps
three such lists: the contacts (``con_*``), the pivots of a rotation (``pv_*``) and the
contacts released by the last decision (``dr_*``).

:func:`fill_contacts` turns the list into the geometry arrays of :mod:`.decision`;
:func:`keep_touching` and :func:`near_contacts` add obstacles that touch (4.3) or lie
within ``CYCLE_CLOSE_GAP`` (4.2).
"""

import math

from parsim.core.jit import jit
from parsim.core.sdbd.constants import (
    CYCLE_CLOSE_GAP,
    MAX_CONTACTS,
    OB_FLOOR,
    OB_SPHERE,
    OB_WALL_XHI,
    OB_WALL_XLO,
    OB_WALL_YLO,
    OB_WALL_YHI,
    TOUCH_TOL,
)
from parsim.core.sdbd.grid import grid_collect_growing, min_image

__all__ = [
    "plane_of",
    "find_contact",
    "add_contact",
    "copy_contact",
    "fill_contacts",
    "keep_touching",
    "near_contacts",
]


@jit
def plane_of(ob, r, geom, nrm):
    """Normal (-> nrm) and level of the plane obstacle ``ob`` for a sphere of radius ``r``:
    the sphere's centre ``a`` must satisfy ``nrm . a >= level``."""
    nrm[0] = 0.0
    nrm[1] = 0.0
    nrm[2] = 0.0
    if ob == OB_FLOOR:
        nrm[2] = 1.0
        return r
    if ob == OB_WALL_XLO:
        nrm[0] = 1.0
        return geom[0] + r
    if ob == OB_WALL_XHI:
        nrm[0] = -1.0
        return -(geom[0] + geom[2] - r)
    if ob == OB_WALL_YLO:
        nrm[1] = 1.0
        return geom[1] + r
    nrm[1] = -1.0
    return -(geom[1] + geom[3] - r)


@jit
def find_contact(n, arr_i, arr_ob, arr_j, i, ob, j):
    """Row of contact ``(i, ob, j)`` among the first ``n`` of a list, or -1."""
    for l in range(n):
        if arr_i[l] == i and arr_ob[l] == ob and arr_j[l] == j:
            return l
    return -1


@jit
def add_contact(n_c, con_i, con_ob, con_j, con_sh, i, ob, j, sh0, sh1):
    """Append contact ``(i, ob, j, (sh0, sh1, 0))`` if there is room (``MAX_CONTACTS``);
    returns the new number of contacts."""
    if n_c >= MAX_CONTACTS:
        return n_c
    con_i[n_c] = i
    con_ob[n_c] = ob
    con_j[n_c] = j
    con_sh[n_c, 0] = sh0
    con_sh[n_c, 1] = sh1
    con_sh[n_c, 2] = 0.0
    return n_c + 1


@jit
def copy_contact(src_i, src_ob, src_j, src_sh, a, dst_i, dst_ob, dst_j, dst_sh, b):
    """Row ``a`` of one contact list -> row ``b`` of another."""
    dst_i[b] = src_i[a]
    dst_ob[b] = src_ob[a]
    dst_j[b] = src_j[a]
    for k in range(3):
        dst_sh[b, k] = src_sh[a, k]


@jit
def fill_contacts(n_c, con_i, con_ob, con_j, con_sh, pos, rad, sed, sed_r, geom,
                  ca, cP, cN, cD, cc0, ckind, nrm):
    """Geometry of the contacts for :func:`decision.decide` (see its module docs)."""
    for l in range(n_c):
        i = con_i[l]
        ob = con_ob[l]
        ckind[l] = ob
        for k in range(3):
            ca[l, k] = pos[i, k]
        if ob == OB_SPHERE:
            j = con_j[l]
            for k in range(3):
                cP[l, k] = sed[j, k] + con_sh[l, k]
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
            c0 = plane_of(ob, rad[i], geom, nrm)
            for k in range(3):
                cP[l, k] = pos[i, k]
                cN[l, k] = nrm[k]
            cD[l] = rad[i]
            cc0[l] = c0


@jit
def keep_touching(n_c, con_i, con_ob, con_j, con_sh, n_dr, dr_i, dr_ob, dr_j, dr_sh,
                  pos, rad, sed, sed_r, geom, ell, nrm):
    """Contacts released by the last decision that still touch (a move of zero or
    round-off length) stay contacts, so that the next decision sees every obstacle
    touching the particle (4.3) and a zero-length move cannot cycle through them."""
    for r in range(n_dr):
        if n_c >= MAX_CONTACTS:
            break
        if find_contact(n_c, con_i, con_ob, con_j, dr_i[r], dr_ob[r], dr_j[r]) >= 0:
            continue
        i = dr_i[r]
        if dr_ob[r] == OB_SPHERE:
            j = dr_j[r]
            g = math.sqrt((pos[i, 0] - sed[j, 0] - dr_sh[r, 0]) ** 2
                          + (pos[i, 1] - sed[j, 1] - dr_sh[r, 1]) ** 2
                          + (pos[i, 2] - sed[j, 2]) ** 2) - rad[i] - sed_r[j]
        else:
            c0 = plane_of(dr_ob[r], rad[i], geom, nrm)
            g = nrm[0] * pos[i, 0] + nrm[1] * pos[i, 1] + nrm[2] * pos[i, 2] - c0
        if g <= TOUCH_TOL * ell:
            n_c = add_contact(n_c, con_i, con_ob, con_j, con_sh, i, dr_ob[r], dr_j[r],
                              dr_sh[r, 0], dr_sh[r, 1])
    return n_c


@jit
def near_contacts(n, pos, rad, n_c, con_i, con_ob, con_j, con_sh, sed, sed_r, geom, igeom,
                  head, col_top, nxt, hkeys, hval, r_max_sed, walls, ell, buf, nrm):
    """Declare closed every obstacle within ``CYCLE_CLOSE_GAP * ell`` of the particle that
    is not a contact yet (4.2).  Returns ``(n_c, added, floor_added, buf)``."""
    added = 0
    floor_added = False
    lim = CYCLE_CLOSE_GAP * ell
    for i in range(n):
        if n_c >= MAX_CONTACTS:
            break
        reach = rad[i] + r_max_sed + lim
        cnt, buf = grid_collect_growing(geom, igeom, head, col_top, nxt, hkeys, hval,
                                        pos[i, 0] - reach, pos[i, 0] + reach, pos[i, 1] - reach,
                                        pos[i, 1] + reach, pos[i, 2] - reach, pos[i, 2] + reach, buf)
        for q in range(cnt):
            j = buf[q]
            rx = sed[j, 0] - pos[i, 0]
            ry = sed[j, 1] - pos[i, 1]
            mx, my = min_image(geom, igeom, rx, ry)
            dz = sed[j, 2] - pos[i, 2]
            g = math.sqrt(mx * mx + my * my + dz * dz) - rad[i] - sed_r[j]
            if g > lim:
                continue
            if find_contact(n_c, con_i, con_ob, con_j, i, OB_SPHERE, j) >= 0:
                continue
            if n_c >= MAX_CONTACTS:
                break
            n_c = add_contact(n_c, con_i, con_ob, con_j, con_sh, i, OB_SPHERE, j, mx - rx, my - ry)
            added += 1
        last = OB_WALL_YHI if walls else OB_FLOOR
        for ob in range(OB_FLOOR, last + 1):
            c0 = plane_of(ob, rad[i], geom, nrm)
            g = nrm[0] * pos[i, 0] + nrm[1] * pos[i, 1] + nrm[2] * pos[i, 2] - c0
            if g > lim or n_c >= MAX_CONTACTS:
                continue
            if find_contact(n_c, con_i, con_ob, con_j, i, ob, -1) >= 0:
                continue
            n_c = add_contact(n_c, con_i, con_ob, con_j, con_sh, i, ob, -1, 0.0, 0.0)
            added += 1
            if ob == OB_FLOOR:
                floor_added = True
    return n_c, added, floor_added, buf
