"""The fall (3.1): the particle translates straight down until one of its spheres touches the
floor, a mesh vessel's face or a sediment sphere (eqs. 1-2); every contact made at the smallest drop is
established (4.3)."""

import math

import numpy as np

from parsim.core.jit import jit
from parsim.core.sdbd.bundles import grid_arrays, window_arrays
from parsim.core.sdbd.constants import (
    EV_CONTACT,
    GEOM_CELL,
    IGEOM_FACES,
    K_FALL_CONTACT,
    K_FLOOR_CONTACT,
    K_WALL_CONTACT,
    OB_FACE,
    OB_FLOOR,
    OB_SPHERE,
    SIMULTANEOUS_TOL,
    TOUCH_TOL,
)
from parsim.core.sdbd.contacts import add_contact, copy_contact
from parsim.core.sdbd.counters import FALL_CANDIDATES
from parsim.core.sdbd.counters import add as counters_add
from parsim.core.sdbd.events import fall_drop
from parsim.core.sdbd.faces import face_gap, face_within
from parsim.core.sdbd.grid import column_range, column_within, min_image
from parsim.core.sdbd.ties import push_event

__all__ = ["fall", "fall_events"]


@jit(inline="always")
def fall(n, particle, n_c, work, sediment, grid, settings, event_counts):
    """Let the particle of ``n`` spheres fall (3.1).

    The ``n_c`` present contacts become the released ones (a fall leaves them all), the
    particle moves down by the smallest drop, and the contacts made at that drop are the new
    contacts, counted in ``event_counts`` as fall or floor contacts.  Returns ``(n_c, n_dr,
    n_made, floor_hit, n_t, drop)``: contacts and released contacts, contacts made, whether
    one is the floor, and the event window's rows and drop (for the trace).
    """
    contacts = work.contacts
    window = work.window
    angle, _, _, _, sphere, obstacle, sediment_sphere, shift = window_arrays(window)
    pos = particle.centre
    n_dr = n_c
    for l in range(n_c):
        copy_contact(contacts, l, work.released, l)
    n_t, drop, tol = fall_events(n, particle, sediment, grid, settings.ell, window, work.counters)
    particle.com[2] -= drop
    for i in range(n):
        pos[i, 2] -= drop
    # the contacts are those made at the smallest drop (4.3)
    n_c = 0
    n_made = 0
    floor_hit = False
    for r in range(n_t):
        if angle[r] > drop + tol:
            continue
        n_c = add_contact(n_c, contacts, sphere[r], obstacle[r], sediment_sphere[r], shift[r, 0],
                          shift[r, 1])
        n_made += 1
        if obstacle[r] == OB_FLOOR:
            floor_hit = True
            event_counts[K_FLOOR_CONTACT] += 1
        elif obstacle[r] == OB_FACE:
            event_counts[K_WALL_CONTACT] += 1
        else:
            event_counts[K_FALL_CONTACT] += 1
    return n_c, n_dr, n_made, floor_hit, n_t, drop


@jit(inline="always")
def _face_drops(n, particle, geom, face, events, window):
    """Push the drops at which the spheres of the falling particle meet ``face`` (a mesh vessel's
    face that faces up, ``N_z > 0``: the gap ``N . a - level`` closes at the rate ``N_z`` per unit of
    drop) into the event window; returns ``(n_t, best)``."""
    n_t, best, tolz = events
    pos = particle.centre
    rad = particle.radius
    for i in range(n):
        gap, rate = face_gap(geom, face, rad[i], pos[i, 0], pos[i, 1], pos[i, 2])
        if rate <= 0.0:
            break
        # a sphere falls onto the face only where it lies above the face's box
        if not face_within(geom, face, (pos[i, 0], pos[i, 1], -np.inf), (pos[i, 0], pos[i, 1], pos[i, 2]), rad[i]):
            continue
        d = max(gap / rate, 0.0)
        n_t, best = push_event(n_t, best, tolz, (d, 1.0, 0.0), EV_CONTACT, (i, OB_FACE, face, 0.0, 0.0), window)
    return n_t, best


@jit(inline="always")
def fall_events(n, particle, sediment, grid, ell, window, counters):
    """Fill the event window (:mod:`.ties`) with the smallest drop of the falling particle
    and those within ``tolz = SIMULTANEOUS_TOL * ell`` of it; returns ``(n_t, best, tolz)``,
    ``best`` the drop.

    The floor is a candidate for every sphere.  The grid columns under each sphere are
    scanned from their top layer down (the height map), and a column stops as soon as a
    layer lies below the best drop found, so the cost does not grow with the pile.  The
    spheres tested are counted in ``counters`` (:mod:`.counters`).
    """
    pos = particle.centre
    rad = particle.radius
    sed = sediment.centre
    sed_r = sediment.radius
    geom, igeom, head, col_top, nxt, hkeys, hval, _ = grid_arrays(grid)
    cell = geom[GEOM_CELL]
    r_max_sed = 0.5 * cell  # bounds every sediment radius
    tolz = SIMULTANEOUS_TOL * ell
    best = np.inf
    for i in range(n):
        best = min(best, pos[i, 2] - rad[i])
    n_t = 0
    for i in range(n):
        d = pos[i, 2] - rad[i]
        n_t, best = push_event(n_t, best, tolz, (d, 1.0, 0.0), EV_CONTACT, (i, OB_FLOOR, -1, 0.0, 0.0), window)
    for face in range(igeom[IGEOM_FACES]):
        n_t, best = _face_drops(n, particle, geom, face, (n_t, best, tolz), window)
    for i in range(n):
        reach = rad[i] + r_max_sed
        xi = pos[i, 0]
        yi = pos[i, 1]
        zi = pos[i, 2]
        ix0, ix1, iy0, iy1 = column_range(geom, igeom, xi - reach, xi + reach, yi - reach, yi + reach)
        izi = int(math.floor(zi / cell))
        # pass 0 scans the top two layers of every column (the height map), so that
        # pass 1, which goes down until a layer lies below the best drop, starts with a
        # drop bounded by the local surface
        for pas in range(2):
            for iy in range(iy0, iy1 + 1):
                for ix in range(ix0, ix1 + 1):
                    col = column_within(geom, igeom, hkeys, hval, xi, yi, reach, ix, iy)
                    if col < 0:
                        continue
                    top = col_top[col]
                    if pas == 0:
                        iz = min(top, izi)
                        iz_end = top - 1
                    else:
                        iz = min(top - 2, izi)
                        iz_end = 0
                    while iz >= iz_end and iz >= 0:
                        if (iz + 1) * cell <= zi - reach - best - tolz:
                            break
                        j = head[iz, col]
                        while j >= 0:
                            counters_add(counters, FALL_CANDIDATES, 1)
                            rx = sed[j, 0] - xi
                            ry = sed[j, 1] - yi
                            mx, my = min_image(geom, igeom, rx, ry)
                            dz = fall_drop(xi, yi, zi, rad[i], xi + mx, yi + my, sed[j, 2], sed_r[j])
                            if dz < np.inf and dz >= -TOUCH_TOL * ell:
                                if dz < 0.0:
                                    dz = 0.0
                                n_t, best = push_event(n_t, best, tolz, (dz, 1.0, 0.0),
                                                       EV_CONTACT, (i, OB_SPHERE, j, mx - rx, my - ry), window)
                            j = nxt[j]
                        iz -= 1
    return n_t, best, tolz
