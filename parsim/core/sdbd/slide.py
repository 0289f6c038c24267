"""The slide: the particle translates along frictionless inclined faces of a mesh vessel.

A frictionless face is a sphere of infinite radius (:mod:`.decision`), so a particle held by it
alone moves as the paper's rotation on one contact does in the limit of an infinite radius: the
touching sphere keeps its distance from the face, and the centre of mass follows the line of
steepest descent on the face, the translation along ``s = (N_z N - e_z) / sqrt(1 - N_z^2)``; held
by two faces (or a face and a wall), along their line ``N_1 x N_2``, downwards.  The slide goes on
until one of the particle's spheres touches a new obstacle (a sediment sphere, the floor, a wall
or a face); the decision then chooses the next motion.

Along the ray ``a + t s`` the gap to a plane of normal ``N`` closes at the rate ``-N . s`` and
a sediment sphere of centre ``P`` at the sum of radii ``D`` is touched at the smaller root of
``t^2 + 2 t s . (a - P) + |a - P|^2 - D^2 = 0`` (eq. 2 of the fall, for a direction other than
``-e_z``).  The sediment is searched in chunks of ``CHUNK_CELLS`` cells of path, each a grid
query over the box the sphere sweeps, up to the nearest plane, which bounds the slide (the
floor lies below every descending path).  Every contact made within ``SIMULTANEOUS_TOL`` of
the earliest is established (4.3).
"""

import math

import numpy as np

from parsim.core.jit import jit
from parsim.core.sdbd.bundles import grid_arrays, window_arrays
from parsim.core.sdbd.constants import (
    CHUNK_CELLS,
    CYCLE_CLOSE_GAP,
    EV_CONTACT,
    GEOM_CELL,
    IGEOM_FACES,
    IGEOM_SIDES,
    K_FLOOR_CONTACT,
    K_SECOND_CONTACT,
    K_THIRD_CONTACT,
    K_WALL_CONTACT,
    OB_FACE,
    OB_FLOOR,
    OB_SPHERE,
    OB_WALL_XLO,
    RATE_TOL,
    SIMULTANEOUS_TOL,
)
from parsim.core.sdbd.contacts import add_contact, copy_contact, find_contact, plane_of
from parsim.core.sdbd.grid import grid_collect_growing
from parsim.core.sdbd.reads import note
from parsim.core.sdbd.ties import push_event

__all__ = ["slide"]


@jit
def slide(n, particle, k, m, n_c, work, sediment, grid, settings, event_counts, buf):
    """Translate the particle of ``n`` spheres along the decision's direction on the face contact
    ``k`` (and ``m``, or ``-1``) up to its earliest new contact.

    The held contacts stay; the others are released.  Returns ``(n_c, n_dr, n_made, floor_hit,
    n_t, distance, buf)``: contacts, released contacts, contacts made, whether one is the floor,
    the event window's rows, the distance slid (for the trace) and the query buffer."""
    contacts = work.contacts
    direction = work.scratch.axis
    for q in range(3):
        direction[q] = work.scratch.decision[q]
    n_held = 1 if m < 0 else 2
    copy_contact(contacts, k, work.pivots, 0)
    if n_held == 2:
        copy_contact(contacts, m, work.pivots, 1)
    n_dr = 0
    for l in range(n_c):
        if l != k and l != m:
            copy_contact(contacts, l, work.released, n_dr)
            n_dr += 1
    tol = SIMULTANEOUS_TOL * settings.ell
    n_t, best = _plane_events(n, particle, (n_held, n_dr), work, direction, grid, settings, tol)
    n_t, best, buf = _sphere_events(n, particle, n_dr, work, direction, sediment, grid, settings,
                                    (n_t, best, tol), buf)
    com = particle.com
    pos = particle.centre
    for q in range(3):
        com[q] += best * direction[q]
    for i in range(n):
        for q in range(3):
            pos[i, q] += best * direction[q]
    n_c = n_held
    for t in range(n_held):
        copy_contact(work.pivots, t, contacts, t)
    angle, _, _, _, sphere, obstacle, sediment_sphere, shift = window_arrays(work.window)
    n_made = 0
    floor_hit = False
    for r in range(n_t):
        if angle[r] > best + tol or find_contact(n_c, contacts, sphere[r], obstacle[r], sediment_sphere[r]) >= 0:
            continue
        n_c = add_contact(n_c, contacts, sphere[r], obstacle[r], sediment_sphere[r], shift[r, 0], shift[r, 1])
        n_made += 1
        ob = obstacle[r]
        if ob == OB_FLOOR:
            floor_hit = True
            event_counts[K_FLOOR_CONTACT] += 1
        elif ob == OB_SPHERE:
            event_counts[K_SECOND_CONTACT if n_held == 1 else K_THIRD_CONTACT] += 1
        else:
            event_counts[K_WALL_CONTACT] += 1
    return n_c, n_dr, n_made, floor_hit, n_t, best, buf


@jit(inline="always")
def _plane_events(n, particle, known, work, direction, grid, settings, tol):
    """The floor, the walls and every face that the slide along ``direction`` approaches: the
    distance at which each sphere meets it.  The held planes (``work.pivots``) are not
    obstacles, and a released plane the decision found tangent is trusted to stay open.
    Returns ``(n_t, best)``; ``best`` is finite, for the floor lies below every slide."""
    n_held, n_dr = known
    pos = particle.centre
    rad = particle.radius
    geom, igeom = grid.geom, grid.igeom
    nrm = work.scratch.normal
    window = work.window
    n_t = 0
    best = np.inf
    n_walls = 4 if settings.walls and igeom[IGEOM_SIDES] == 0 else 0
    n_faces = igeom[IGEOM_FACES]
    for i in range(n):
        for t in range(1 + n_walls + n_faces):
            ob = OB_FLOOR
            j = -1
            if t > n_walls:
                ob = OB_FACE
                j = t - 1 - n_walls
            elif t > 0:
                ob = OB_WALL_XLO + t - 1
            c0 = plane_of(ob, j, rad[i], geom, nrm)
            rate = nrm[0] * direction[0] + nrm[1] * direction[1] + nrm[2] * direction[2]
            if rate >= 0.0 or find_contact(n_held, work.pivots, i, ob, j) >= 0:
                continue
            if rate >= -RATE_TOL and find_contact(n_dr, work.released, i, ob, j) >= 0:
                continue
            gap = nrm[0] * pos[i, 0] + nrm[1] * pos[i, 1] + nrm[2] * pos[i, 2] - c0
            n_t, best = push_event(n_t, best, tol, (max(gap, 0.0) / -rate, 1.0, 0.0), EV_CONTACT,
                                   (i, ob, j, 0.0, 0.0), window)
    return n_t, best


@jit(inline="always")
def _sphere_events(n, particle, n_dr, work, direction, sediment, grid, settings, events, buf):
    """The sediment spheres met along the slide, searched chunk by chunk of path up to the
    earliest event so far; a released sphere contact within ``2 CYCLE_CLOSE_GAP`` is trusted to
    open (the decision found its gap opening).  Returns ``(n_t, best, buf)``."""
    n_t, best, tol = events
    pos = particle.centre
    rad = particle.radius
    sed = sediment.centre
    sed_r = sediment.radius
    grid_state = grid_arrays(grid)
    chunk = CHUNK_CELLS * grid.geom[GEOM_CELL]
    reach_sed = 0.5 * grid.geom[GEOM_CELL]
    ell = settings.ell
    start = 0.0
    while start <= best + tol:
        end = min(start + chunk, best) + tol
        for i in range(n):
            reach = rad[i] + reach_sed
            lower = (min(pos[i, 0] + start * direction[0], pos[i, 0] + end * direction[0]) - reach,
                     min(pos[i, 1] + start * direction[1], pos[i, 1] + end * direction[1]) - reach,
                     pos[i, 2] + end * direction[2] - reach)
            upper = (max(pos[i, 0] + start * direction[0], pos[i, 0] + end * direction[0]) + reach,
                     max(pos[i, 1] + start * direction[1], pos[i, 1] + end * direction[1]) + reach,
                     pos[i, 2] + start * direction[2] + reach)
            note(work.reads, lower[0], upper[0], lower[1], upper[1])
            cnt, buf = grid_collect_growing(grid_state, lower, upper, buf)
            for qq in range(cnt):
                j = buf[qq]
                q0 = pos[i, 0] - sed[j, 0]
                q1 = pos[i, 1] - sed[j, 1]
                q2 = pos[i, 2] - sed[j, 2]
                b = direction[0] * q0 + direction[1] * q1 + direction[2] * q2
                if b >= 0.0:
                    continue  # not approaching
                D = rad[i] + sed_r[j]
                dist2 = q0 * q0 + q1 * q1 + q2 * q2
                c = dist2 - D * D
                disc = b * b - c
                if disc < 0.0:
                    continue
                if math.sqrt(dist2) - D <= 2.0 * CYCLE_CLOSE_GAP * ell and \
                        find_contact(n_dr, work.released, i, OB_SPHERE, j) >= 0:
                    continue
                t = max(c, 0.0) / (math.sqrt(disc) - b)  # the smaller root, without cancellation
                n_t, best = push_event(n_t, best, tol, (t, 1.0, 0.0), EV_CONTACT, (i, OB_SPHERE, j, 0.0, 0.0),
                                       work.window)
        start += chunk
    return n_t, best, buf
