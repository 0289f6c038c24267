"""The moving particle (a :class:`.bundles.Particle`): its drop, and its rigid motions.

The particle is rigid: its state is the centre of mass and the orientation, and the sphere
centres follow as ``centre_i = com + R body_i``.
"""

import math

from parsim.core.jit import jit
from parsim.core.sdbd.constants import DROP_MARGIN, GEOM_CELL, IGEOM_FACES
from parsim.core.sdbd.faces import face_gap
from parsim.core.sdbd.grid import top_near
from parsim.core.sdbd.reads import note
from parsim.core.sdbd.rotation import (
    quat_from_axis_cos_sin,
    quat_mul,
    quat_normalize,
    quat_to_matrix,
    rotate_point,
)

__all__ = ["place_spheres", "drop_particle", "rotate_particle"]


@jit
def place_spheres(n, particle):
    """Sphere centres ``com + R body`` of the particle's ``n`` spheres."""
    body = particle.body
    rot = particle.rotation
    com = particle.com
    pos = particle.centre
    for i in range(n):
        for k in range(3):
            pos[i, k] = com[k] + rot[k, 0] * body[i, 0] + rot[k, 1] * body[i, 1] + rot[k, 2] * body[i, 2]


@jit
def drop_particle(p, particles, sediment, grid, ell, particle, reads, given_top):
    """Particle ``p`` at its drop: scaled body offsets and radii, orientation (from
    ``particle_rotation[p]``, any non-zero quaternion), centre of mass above its drop point
    with its lowest sphere ``DROP_MARGIN`` above the sediment within its reach
    (:func:`.grid.top_near`: the particle's extent plus the largest sediment radius, or
    ``given_top`` unless it is NaN); returns its number of spheres and that height; the square it
    read joins ``reads`` (:mod:`.reads`).  The sediment beyond that reach, which the vertical fall cannot
    touch, does not change the drop, nor therefore the particle's descent.

    ``particles`` holds every particle's inputs: ``(shape_offsets, shape_radii, shape_start,
    particle_shape, particle_scale, particle_rotation, particle_drop_xy)``, the shapes' sphere offsets
    and radii (shape ``s`` is rows ``shape_start[s] .. shape_start[s + 1] - 1``) and each particle's
    shape, scale, quaternion and drop point."""
    shape_offsets, shape_radii, shape_start, particle_shape, particle_scale, particle_rotation, particle_drop_xy = \
        particles
    body = particle.body
    rad = particle.radius
    q = particle.quaternion
    rot = particle.rotation
    com = particle.com
    s = particle_shape[p]
    sc = particle_scale[p]
    i0 = shape_start[s]
    n = shape_start[s + 1] - i0
    for i in range(n):
        for k in range(3):
            body[i, k] = sc * shape_offsets[i0 + i, k]
        rad[i] = sc * shape_radii[i0 + i]
    for k in range(4):
        q[k] = particle_rotation[p, k]
    # the given quaternion is made unit, then normalised as after a rotation: twice, as the
    # sediments of the fingerprints were made (benchmarks/sediment_fingerprint.py)
    quat_normalize(q)
    quat_normalize(q)
    quat_to_matrix(q, rot)
    below = 0.0
    extent = 0.0
    for i in range(n):
        zi = rot[2, 0] * body[i, 0] + rot[2, 1] * body[i, 1] + rot[2, 2] * body[i, 2]
        below = max(below, rad[i] - zi)
        extent = max(extent, math.sqrt(body[i, 0] ** 2 + body[i, 1] ** 2 + body[i, 2] ** 2) + rad[i])
    com[0] = particle_drop_xy[p, 0]
    com[1] = particle_drop_xy[p, 1]
    geom = grid.geom
    reach = extent + 0.5 * geom[GEOM_CELL]
    top = given_top
    if math.isnan(top):
        top = top_near(geom, grid.igeom, grid.head, grid.col_top, grid.nxt, grid.hkeys, grid.hval, sediment.centre,
                       com[0], com[1], reach)
    note(reads, com[0] - reach, com[0] + reach, com[1] - reach, com[1] + reach)
    com[2] = top + below + DROP_MARGIN * ell
    if grid.igeom[IGEOM_FACES] > 0:
        com[2] = max(com[2], _above_faces(n, particle, geom, grid.igeom[IGEOM_FACES]) + DROP_MARGIN * ell)
    place_spheres(n, particle)
    return n, top


@jit(inline="always")
def _above_faces(n, particle, geom, n_faces):
    """The lowest height of the centre of mass at which no sphere of the particle lies below a
    face of a mesh vessel that faces up (``N_z > 0``): sphere ``i`` at ``com + R b_i`` needs
    ``N . (com + R b_i) >= c + r_i``.  In a convex vessel that is where the particle, above a
    point of the vessel's floor, starts inside it."""
    body = particle.body
    rot = particle.rotation
    com = particle.com
    lowest = -math.inf
    for face in range(n_faces):
        for i in range(n):
            ox = rot[0, 0] * body[i, 0] + rot[0, 1] * body[i, 1] + rot[0, 2] * body[i, 2]
            oy = rot[1, 0] * body[i, 0] + rot[1, 1] * body[i, 1] + rot[1, 2] * body[i, 2]
            oz = rot[2, 0] * body[i, 0] + rot[2, 1] * body[i, 1] + rot[2, 2] * body[i, 2]
            gap, rate = face_gap(geom, face, particle.radius[i], com[0] + ox, com[1] + oy, oz)
            if rate <= 0.0:
                break
            lowest = max(lowest, -gap / rate)
    return lowest


@jit(inline="always")
def rotate_particle(n, particle, axis, pivot, c, s, scratch):
    """Rotate the particle by the angle of cosine ``c`` and sine ``s`` about ``axis`` through
    ``pivot`` (eq. 15 for the centre of mass, the same rotation composed with the
    orientation)."""
    com = particle.com
    q = particle.quaternion
    point = scratch.point
    q_step = scratch.q_step
    q_new = scratch.q_new
    rotate_point(com, pivot, axis, c, s, point)
    for k in range(3):
        com[k] = point[k]
    quat_from_axis_cos_sin(axis, c, s, q_step)
    quat_mul(q_step, q, q_new)
    for k in range(4):
        q[k] = q_new[k]
    quat_normalize(q)
    quat_to_matrix(q, particle.rotation)
    place_spheres(n, particle)
