"""The potential events of a fall (3.1): the drops at which a sphere of the particle
touches the floor or a sediment sphere (eqs. 1-2)."""

import math

import numpy as np

from parsim.core.jit import jit
from parsim.core.sdbd.constants import EV_CONTACT, OB_FLOOR, OB_SPHERE, SIMULTANEOUS_TOL, TOUCH_TOL
from parsim.core.sdbd.events import fall_drop
from parsim.core.sdbd.grid import column_lookup, column_range, min_image
from parsim.core.sdbd.ties import push_event

__all__ = ["fall_events"]


@jit
def fall_events(n, pos, rad, sed, sed_r, geom, igeom, head, col_top, nxt, hkeys, hval,
                r_max_sed, ell, t_phi, t_c, t_s, t_ev, t_i, t_ob, t_j, t_sh):
    """Fill the event window (:mod:`.ties`) with the smallest drop of the falling particle
    and those within ``tolz = SIMULTANEOUS_TOL * ell`` of it; returns ``(n_t, best, tolz)``,
    ``best`` the drop.

    The floor is a candidate for every sphere.  The grid columns under each sphere are
    scanned from their top layer down (the height map), and a column stops as soon as a
    layer lies below the best drop found, so the cost does not grow with the pile.
    """
    cell = geom[6]
    tolz = SIMULTANEOUS_TOL * ell
    best = np.inf
    for i in range(n):
        best = min(best, pos[i, 2] - rad[i])
    n_t = 0
    for i in range(n):
        d = pos[i, 2] - rad[i]
        n_t, best = push_event(n_t, best, tolz, d, 1.0, 0.0, EV_CONTACT, i, OB_FLOOR, -1, 0.0, 0.0,
                               t_phi, t_c, t_s, t_ev, t_i, t_ob, t_j, t_sh)
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
                dcx, dcy = min_image(geom, igeom, 0.0, yi - geom[1] - (iy + 0.5) * geom[5])
                ddy = max(abs(dcy) - 0.5 * geom[5], 0.0)
                if ddy >= reach:
                    continue
                for ix in range(ix0, ix1 + 1):
                    dcx, dcy = min_image(geom, igeom, xi - geom[0] - (ix + 0.5) * geom[4], 0.0)
                    ddx = max(abs(dcx) - 0.5 * geom[4], 0.0)
                    if ddx * ddx + ddy * ddy >= reach * reach:
                        continue
                    col = column_lookup(igeom, hkeys, hval, ix, iy)
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
                            rx = sed[j, 0] - xi
                            ry = sed[j, 1] - yi
                            mx, my = min_image(geom, igeom, rx, ry)
                            dz = fall_drop(xi, yi, zi, rad[i], xi + mx, yi + my, sed[j, 2], sed_r[j])
                            if dz < np.inf and dz >= -TOUCH_TOL * ell:
                                if dz < 0.0:
                                    dz = 0.0
                                n_t, best = push_event(n_t, best, tolz, dz, 1.0, 0.0, EV_CONTACT,
                                                       i, OB_SPHERE, j, mx - rx, my - ry,
                                                       t_phi, t_c, t_s, t_ev, t_i, t_ob, t_j, t_sh)
                            j = nxt[j]
                        iz -= 1
    return n_t, best, tolz
