"""Debug measure of a move: the largest overlap of the moving particle with the sediment,
the floor and the walls, the cylinder's sides or a mesh vessel's faces (``check_overlaps`` of :func:`parsim.core.sdbd.deposit_with_diagnostics`)."""

import math

import numpy as np

from parsim.core.jit import jit
from parsim.core.sdbd.constants import GEOM_CELL, GEOM_LENGTH_X, GEOM_LOWER_X, IGEOM_FACES, IGEOM_SIDES
from parsim.core.sdbd.bundles import grid_arrays
from parsim.core.sdbd.faces import face_plane
from parsim.core.sdbd.grid import grid_collect_growing, min_image
from parsim.core.sdbd.polygon import candidate_sides, side_gap_in_box

__all__ = ["max_overlap"]


@jit
def max_overlap(n, particle, sediment, grid, lateral_walls, buf):
    """Largest overlap of the moving spheres with the sediment, the floor and walls (or the
    cylinder's sides), and a mesh vessel's faces; returns it and the (possibly grown) query buffer."""
    pos = particle.centre
    rad = particle.radius
    sed = sediment.centre
    sed_r = sediment.radius
    grid_state = grid_arrays(grid)
    geom, igeom = grid.geom, grid.igeom
    nrm = np.empty(3)
    worst = -np.inf
    for i in range(n):
        reach = rad[i] + 0.5 * geom[GEOM_CELL]
        cnt, buf = grid_collect_growing(grid_state, (pos[i, 0] - reach, pos[i, 1] - reach, pos[i, 2] - reach),
                                        (pos[i, 0] + reach, pos[i, 1] + reach, pos[i, 2] + reach), buf)
        for q in range(cnt):
            j = buf[q]
            dx, dy = min_image(geom, igeom, sed[j, 0] - pos[i, 0], sed[j, 1] - pos[i, 1])
            dz = sed[j, 2] - pos[i, 2]
            ov = rad[i] + sed_r[j] - math.sqrt(dx * dx + dy * dy + dz * dz)
            if ov > worst:
                worst = ov
        ov = rad[i] - pos[i, 2]
        if ov > worst:
            worst = ov
        n_sides = igeom[IGEOM_SIDES]
        if lateral_walls and n_sides > 0:
            x = pos[i, 0]
            y = pos[i, 1]
            first, count = candidate_sides(geom, n_sides, x, x, y, y, rad[i])
            for t in range(count):
                ov = -side_gap_in_box(geom, (first + t) % n_sides, rad[i], x, x, y, y)
                if ov > worst:
                    worst = ov
        elif lateral_walls:
            for k in range(2):
                ov = geom[GEOM_LOWER_X + k] + rad[i] - pos[i, k]
                if ov > worst:
                    worst = ov
                ov = pos[i, k] + rad[i] - geom[GEOM_LOWER_X + k] - geom[GEOM_LENGTH_X + k]
                if ov > worst:
                    worst = ov
        for face in range(igeom[IGEOM_FACES]):
            level = face_plane(geom, face, rad[i], nrm)
            ov = level - (nrm[0] * pos[i, 0] + nrm[1] * pos[i, 1] + nrm[2] * pos[i, 2])
            if ov > worst:
                worst = ov
    return worst, buf
