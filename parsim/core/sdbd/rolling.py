"""Rolling: the rotation of the particle on one contact (3.2) or on two (3.3), up to its
earliest event.

The decision gives the axis and a point of it (a pivot).  The potential events of the
rotation, each an angle ``phi`` about the axis, are

* the end of the arc: hanging (eqs. 18, 32), the centre of mass at the lowest point of its
  circle, or, if that is farther, the end of an angular chunk in which no sphere moves more
  than ``CHUNK_CELLS`` grid cells (a bookkeeping step, not an event, so that every grid
  query covers only the cells within reach of the arc of one sphere), and in a periodic box
  less than the side less two cells (see below);
* loss of a pivot contact (:func:`_loss_events`): its moving sphere comes level with its
  sediment sphere (eq. 17; on two pivots only if then the other one is level or below,
  3.3.4);
* on two pivots, rolling on one of them becomes possible (:func:`_release_events`, eqs.
  25-30 and the virtual small rotation of eq. 31);
* the frustrated situation of 4.1 (:func:`.frustration.decision_changes`);
* a new contact of any moving sphere (:func:`_new_contact_events`) with a sediment sphere
  (circle intersections, eqs. 7-12), with the floor (eqs. 19-23), with a wall or a side of
  the cylinder's polygon (the same, vertical planes; :func:`_side_contact_events`) or with a
  face of a mesh vessel (a plane of any normal; :func:`_face_contact_events`).

The earliest event and those within ``SIMULTANEOUS_TOL`` of arc length of it are executed
together (4.3): the particle turns by eq. 15 and the pivots and the contacts made are its new
contacts.  Rolling on one and on two pivots share this search; only the loss condition and the
release events tell them apart.

Periodic images.  A sphere's new contacts are looked for among the obstacles within reach of
the region its arc sweeps (the arc's bounding box grown by the sphere's radius and the largest
sediment radius).  In a periodic box each obstacle is taken at its image nearest the centre of
that region, not nearest the sphere's starting point: an arc that carries the sphere across a
good part of the box meets, at its far end, an image that is not the one nearest where it
started.  The chunk keeps the region narrower than the box (the arc less than the side less two
cells, a cell bounding every diameter), so that at most one image of each obstacle lies in it.
"""

import math

import numpy as np

from parsim.core.jit import jit
from parsim.core.sdbd import counters
from parsim.core.sdbd.bundles import geometry_arrays, grid_arrays, window_arrays
from parsim.core.sdbd.constants import (
    CHUNK_CELLS,
    CYCLE_CLOSE_GAP,
    EV_CHUNK,
    EV_CONTACT,
    EV_HANG,
    EV_LOSS,
    EV_RELEASE,
    EV_TRIAL,
    EV_VIRTUAL,
    GEOM_CELL,
    GEOM_LENGTH_X,
    GEOM_LENGTH_Y,
    GEOM_LOWER_X,
    GEOM_LOWER_Y,
    IGEOM_MODE,
    IGEOM_FACES,
    IGEOM_SIDES,
    K_FLOOR_CONTACT,
    K_FRUSTRATED,
    K_HANGING_ONE,
    K_HANGING_TWO,
    K_LOSS_OF_CONTACT,
    K_LOSS_OF_ONE,
    K_LOSS_OF_TWO,
    K_SECOND_CONTACT,
    K_THIRD_CONTACT,
    K_WALL_CONTACT,
    LATERAL_PERIODIC,
    MOTION_SINGLE,
    NZ_TOL,
    OB_FLOOR,
    OB_FACE,
    OB_SIDE,
    OB_SPHERE,
    OB_WALL_XLO,
    RATE_TOL,
    SIMULTANEOUS_TOL,
    TINY,
    TOUCH_TOL,
)
from parsim.core.sdbd.contacts import add_contact, copy_contact, find_contact, plane_of
from parsim.core.sdbd.events import (
    POLICY_NEW,
    POLICY_TRUSTED,
    arc_range,
    first_entry,
    hang_cos_sin,
    plane_coefficients,
    release_plane,
    sliding_wall_release_plane,
)
from parsim.core.sdbd.frustration import decision_changes
from parsim.core.sdbd.grid import grid_collect
from parsim.core.sdbd.particle import rotate_particle
from parsim.core.sdbd.faces import face_plane, face_within
from parsim.core.sdbd.polygon import candidate_sides, side_gap_in_box, side_plane
from parsim.core.sdbd.reads import note
from parsim.core.sdbd.rotation import rotate_point
from parsim.core.sdbd.ties import NO_CONTACT, earliest_event, push_event

__all__ = ["roll"]


@jit  # not inlined into the descent: that adds some 12 s and a GiB to the compilation, for no speed
def roll(n, particle, motion, k, m, n_c, work, sediment, grid, settings, event_counts, buf):
    """Rotate the particle of ``n`` spheres on contact ``k`` (``MOTION_SINGLE``) or on
    contacts ``k`` and ``m`` (``MOTION_PAIR``) about the axis of the decision up to the
    earliest event, and make the pivots and the contacts of the executed events the
    contacts.

    Returns ``(n_c, n_dr, n_executed, n_chunk_ends, floor_hit, n_t, phi, buf)``: contacts,
    contacts released by the decision, events executed, chunk ends reached, whether a floor
    contact was made, the event window's rows and angle (for the trace), the query buffer.
    """
    window = work.window
    scratch = work.scratch
    axis = scratch.axis
    pivot = scratch.pivot
    for q in range(3):
        axis[q] = scratch.decision[q]
        pivot[q] = scratch.decision[3 + q]
    n_pivots, n_dr = _pivots_and_released(motion, k, m, n_c, work)
    n_t, best, tol_phi = _end_of_arc(n, particle, axis, pivot, settings.ell, grid.geom, grid.igeom, window)
    n_t, best = _loss_events(n_pivots, k, m, work, axis, pivot, settings, n_t, best, tol_phi)
    if n_pivots == 2:
        n_t, best = _release_events(particle.com, k, m, work, axis, pivot, settings, n_t, best, tol_phi)
    trial_angle = settings.trial_angle
    if trial_angle > 0.0 and trial_angle <= best + tol_phi:
        started = counters.start(work.counters)
        changes = decision_changes(motion, n_pivots, k, m, work.geometry, particle.com, axis, pivot,
                                   trial_angle, work, settings)
        counters.stop(work.counters, counters.TRIAL, started)
        counters.add(work.counters, counters.TRIAL_DECISIONS, 1)
        if changes:
            n_t, best = push_event(n_t, best, tol_phi, (trial_angle, math.cos(trial_angle), math.sin(trial_angle)),
                                   EV_TRIAL, NO_CONTACT, window)
    started = counters.start(work.counters)
    n_t, best, buf = _new_contact_events(n, particle, (n_pivots, n_dr), work, (axis, pivot), sediment, grid,
                                         settings, (n_t, best, tol_phi), buf)
    counters.stop(work.counters, counters.CONTACT_SEARCH, started)
    n_c, n_executed, n_chunk_ends, floor_hit = _execute(n, particle, n_pivots, work, axis, pivot, n_t,
                                                        best, tol_phi, event_counts)
    return n_c, n_dr, n_executed, n_chunk_ends, floor_hit, n_t, best, buf


@jit(inline="always")
def _pivots_and_released(motion, k, m, n_c, work):
    """Copy the pivot contacts ``k`` (and ``m``) and the other contacts (released by the
    decision) into their lists; returns their numbers."""
    contacts = work.contacts
    n_pivots = 1 if motion == MOTION_SINGLE else 2
    copy_contact(contacts, k, work.pivots, 0)
    if n_pivots == 2:
        copy_contact(contacts, m, work.pivots, 1)
    n_dr = 0
    for l in range(n_c):
        if l == k or l == m:
            continue
        copy_contact(contacts, l, work.released, n_dr)
        n_dr += 1
    return n_pivots, n_dr


@jit(inline="always")
def _end_of_arc(n, particle, axis, pivot, ell, geom, igeom, window):
    """Start the event window with hanging (eqs. 18, 32) or, if that lies beyond it, the end
    of the angular chunk.  Returns ``(n_t, best, tol_phi)``, ``tol_phi`` the angle of
    ``SIMULTANEOUS_TOL`` of arc length on the sphere farthest from the axis; a chunk is
    ``CHUNK_CELLS`` grid cells of arc on that sphere, and in a periodic box less than
    :func:`_periodic_arc`."""
    cell = geom[GEOM_CELL]
    pos = particle.centre
    phi_hang, c_hang, s_hang = hang_cos_sin(particle.com, pivot, axis)
    rho_max = 0.0
    for i in range(n):
        r0 = pos[i, 0] - pivot[0]
        r1 = pos[i, 1] - pivot[1]
        r2 = pos[i, 2] - pivot[2]
        h = r0 * axis[0] + r1 * axis[1] + r2 * axis[2]
        rr = r0 * r0 + r1 * r1 + r2 * r2 - h * h
        if rr > rho_max:
            rho_max = rr
    rho_max = math.sqrt(max(rho_max, 0.0))
    if rho_max < ell:
        rho_max = ell
    tol_phi = SIMULTANEOUS_TOL * ell / rho_max
    arc = CHUNK_CELLS * cell
    if igeom[IGEOM_MODE] == LATERAL_PERIODIC:
        arc = min(arc, _periodic_arc(geom))
    phi_lim = arc / rho_max
    if phi_lim > math.pi:
        phi_lim = math.pi
    n_t = 0
    best = np.inf
    if phi_hang <= phi_lim:
        n_t, best = push_event(n_t, best, tol_phi, (phi_hang, c_hang, s_hang), EV_HANG, NO_CONTACT, window)
    else:
        n_t, best = push_event(n_t, best, tol_phi, (phi_lim, math.cos(phi_lim), math.sin(phi_lim)),
                               EV_CHUNK, NO_CONTACT, window)
    return n_t, best, tol_phi


@jit(inline="always")
def _periodic_arc(geom):
    """The longest arc of a chunk in the periodic box of ``geom``: the region a sphere's arc
    sweeps, grown on each side by the sphere's radius and half a cell (together at most a cell),
    stays narrower than the box's shorter side, so that it holds at most one image of each
    obstacle.  Positive: the box is wider than four times the largest radius, two cells."""
    side = min(geom[GEOM_LENGTH_X], geom[GEOM_LENGTH_Y])
    return (side - 2.0 * geom[GEOM_CELL]) * (1.0 - 1e-9)


@jit(inline="always")
def _loss_events(n_pivots, k, m, work, axis, pivot, settings, n_t, best, tol_phi):
    """Loss of a pivot contact: its moving sphere comes level with its sediment sphere
    (eq. 17); on two pivots only if the other one is then level or below (3.3.4).

    On a sphere pivot ``l`` and a frictionless inclined face ``o`` (the rotation about the axis
    through ``P_l`` along the face's normal ``N_o``), the pivot is lost where sliding on the face
    alone opens it: the slide ``s = N_z N_o - e_z`` moves ``a_l`` away from ``P_l`` once
    ``N_l . s = N_z (N_l . N_o) - N_{l,z} >= 0``, and ``N_l . N_o`` is constant about that axis,
    so the event is ``a_l`` crossing the height ``z(P_l) + D N_z (N_l . N_o)`` (the height of
    ``P_l`` for a vertical face: eq. 17)."""
    ell = settings.ell
    window = work.window
    ca, cP, cN, cD, _, ckind = geometry_arrays(work.geometry)
    scratch = work.scratch
    e1 = scratch.e1
    e2 = scratch.e2
    nrm = scratch.normal
    point = scratch.point
    for t in range(n_pivots):
        l = k if t == 0 else m
        if ckind[l] != OB_SPHERE:
            continue
        o = m if t == 0 else k
        on_face = n_pivots == 2 and settings.sliding_walls and ckind[o] == OB_FACE
        level = cP[l, 2]
        if on_face:
            level += cD[l] * cN[o, 2] * (cN[l, 0] * cN[o, 0] + cN[l, 1] * cN[o, 1] + cN[l, 2] * cN[o, 2])
        nrm[0] = 0.0
        nrm[1] = 0.0
        nrm[2] = 1.0
        A, B, K, rho, gap = plane_coefficients(ca[l], pivot, axis, nrm, level, e1, e2)
        if rho == 0.0 or gap <= NZ_TOL * cD[l]:
            # level or below already: that crossing is not ahead
            continue
        phi, cc, ss = first_entry(A, B, K, gap, 1.0 / rho, ell, POLICY_TRUSTED)
        if phi > best + tol_phi:
            continue
        if n_pivots == 2 and not on_face:
            if ckind[o] == OB_SPHERE:
                rotate_point(ca[o], pivot, axis, cc, ss, point)
                nz = point[2] - cP[o, 2]
                dn = math.sqrt((point[0] - cP[o, 0]) ** 2 + (point[1] - cP[o, 1]) ** 2 + nz * nz)
                if nz > NZ_TOL * dn:
                    continue
            elif cN[o, 2] > NZ_TOL:
                continue
        n_t, best = push_event(n_t, best, tol_phi, (phi, cc, ss), EV_LOSS, (l, -1, -1, 0.0, 0.0), window)
    return n_t, best


@jit(inline="always")
def _release_events(com, k, m, work, axis, pivot, settings, n_t, best, tol_phi):
    """On two pivots: rolling on one of them alone becomes possible (eqs. 25-30, the plane
    of :func:`.events.release_plane`, or of :func:`.events.sliding_wall_release_plane` when
    the other pivot is a frictionless wall).  When the release condition already holds with zero
    rate, the virtual small rotation of eq. 31 is the event."""
    ell = settings.ell
    window = work.window
    ca, cP, cN, _, _, ckind = geometry_arrays(work.geometry)
    scratch = work.scratch
    e1 = scratch.e1
    e2 = scratch.e2
    nrm2 = scratch.normal_2
    virtual = settings.virtual_angle
    for t in range(2):
        x = k if t == 0 else m
        y = m if t == 0 else k
        if settings.sliding_walls and ckind[x] >= OB_WALL_XLO:
            continue  # rolling on a frictionless wall alone is the fall: the loss of y (eq. 17)
        if settings.sliding_walls and ckind[y] >= OB_WALL_XLO:
            ok, use_com, c0, gap0 = sliding_wall_release_plane(com, cP[x], ca[y], cN[y], nrm2)
        else:
            ok, use_com, c0, gap0 = release_plane(com, cP[x], cP[y], ca[y], ckind[y] == OB_SPHERE, cN[y], nrm2)
        if not ok:
            continue
        if use_com:
            A, B, K, rho, gap = plane_coefficients(com, pivot, axis, nrm2, c0, e1, e2)
        else:
            A, B, K, rho, gap = plane_coefficients(ca[y], pivot, axis, nrm2, c0, e1, e2)
        if rho == 0.0:
            continue
        if abs(gap) <= TOUCH_TOL * ell:
            if B > RATE_TOL * ell / rho:
                # eq. 31: release condition holds with zero rate and the decision found the
                # contact not opening: rotate a little
                n_t, best = push_event(n_t, best, tol_phi, (virtual, math.cos(virtual), math.sin(virtual)),
                                       EV_VIRTUAL, NO_CONTACT, window)
                continue
        elif gap < 0.0:
            continue
        phi, cc, ss = first_entry(A, B, K, gap, 1.0 / rho, ell, POLICY_TRUSTED)
        if phi <= best + tol_phi:
            n_t, best = push_event(n_t, best, tol_phi, (phi, cc, ss), EV_RELEASE, (x, -1, -1, 0.0, 0.0), window)
    return n_t, best


@jit(inline="always")
def _new_contact_events(n, particle, known, work, rotation, sediment, grid, settings, events, buf):
    """New contacts of every moving sphere with the floor (eqs. 19-23), the walls or the
    cylinder's sides (the same, vertical planes) and the sediment spheres (eqs. 7-12) under the
    rotation ``rotation = (axis, pivot)``.  ``known = (n_pivots, n_dr)`` counts the pivots and the
    contacts released by the decision (``work.pivots``, ``work.released``): a contact released is
    trusted to open (``POLICY_TRUSTED`` of :func:`.events.first_entry`); a pivot cannot be made
    again.  ``events = (n_t, best, tol_phi)`` is the event window's state; returns ``(n_t, best,
    buf)``.

    For each moving sphere: its circle about the axis and the box its arc spans up to the
    earliest event so far, then the floor, the walls or the cylinder's sides
    (:func:`_side_contact_events`), then the sediment spheres the grid lists in that box.

    Why so long: this is the contact search of every rotation step, the deposition's hottest
    loop.  Split into a search for planes and one for sediment spheres (inlined functions), together
    with the steps of :func:`.decision.decide`, it made a deposition of 2·10⁴ spheres execute 4.5 %
    more instructions (benchmarks/side_by_side.py).
    """
    n_pivots, n_dr = known
    axis, pivot = rotation
    n_t, best, tol_phi = events
    window = work.window
    ell = settings.ell
    pos = particle.centre
    rad = particle.radius
    sed = sediment.centre
    sed_r = sediment.radius
    grid_state = grid_arrays(grid)
    geom, igeom = grid.geom, grid.igeom
    walls = settings.walls
    n_sides = igeom[IGEOM_SIDES]
    reach_sed = 0.5 * geom[GEOM_CELL]  # bounds every sediment radius
    periodic = igeom[IGEOM_MODE] == LATERAL_PERIODIC
    length_x = geom[GEOM_LENGTH_X]
    length_y = geom[GEOM_LENGTH_Y]
    pivots = work.pivots
    released = work.released
    scratch = work.scratch
    e1 = scratch.e1
    e2 = scratch.e2
    nrm = scratch.normal
    for i in range(n):
        r0 = pos[i, 0] - pivot[0]
        r1 = pos[i, 1] - pivot[1]
        r2 = pos[i, 2] - pivot[2]
        h = r0 * axis[0] + r1 * axis[1] + r2 * axis[2]
        p0 = r0 - h * axis[0]
        p1 = r1 - h * axis[1]
        p2 = r2 - h * axis[2]
        rho = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
        if rho <= TINY * ell:
            continue
        # the sphere's centre moves on the circle o + rho (cos phi e1 + sin phi e2)
        e1[0] = p0 / rho
        e1[1] = p1 / rho
        e1[2] = p2 / rho
        e2[0] = axis[1] * e1[2] - axis[2] * e1[1]
        e2[1] = axis[2] * e1[0] - axis[0] * e1[2]
        e2[2] = axis[0] * e1[1] - axis[1] * e1[0]
        lim = best + tol_phi
        if lim > math.pi:
            lim = math.pi
        # events beyond lim are discarded: first_entry skips their arctangents
        cos_lim = math.cos(lim)
        sin_lim = math.sin(lim)
        o0 = pivot[0] + h * axis[0]
        o1 = pivot[1] + h * axis[1]
        o2 = pivot[2] + h * axis[2]
        xlo, xhi = arc_range(rho, e1[0], e2[0], lim, cos_lim, sin_lim)
        ylo, yhi = arc_range(rho, e1[1], e2[1], lim, cos_lim, sin_lim)
        zlo, zhi = arc_range(rho, e1[2], e2[2], lim, cos_lim, sin_lim)
        # the middle of the swept region, relative to the sphere: obstacles are taken at their
        # image nearest it (see the module docs)
        mid_x = o0 + 0.5 * (xlo + xhi) - pos[i, 0]
        mid_y = o1 + 0.5 * (ylo + yhi) - pos[i, 1]
        ri = rad[i]
        # floor
        if o2 + zlo - ri <= TOUCH_TOL * ell:
            if find_contact(n_pivots, pivots, i, OB_FLOOR, -1) < 0:
                pol = POLICY_TRUSTED if find_contact(n_dr, released, i, OB_FLOOR, -1) >= 0 else POLICY_NEW
                A = -e1[2]
                B = -e2[2]
                gap = pos[i, 2] - ri
                phi, cc, ss = first_entry(A, B, A + gap / rho, gap, 1.0 / rho, ell, pol, lim, cos_lim)
                if phi <= best + tol_phi:
                    n_t, best = push_event(n_t, best, tol_phi, (phi, cc, ss),
                                           EV_CONTACT, (i, OB_FLOOR, -1, 0.0, 0.0), window)
        if walls and n_sides > 0:
            arc = (o0 + xlo, o0 + xhi, o1 + ylo, o1 + yhi, o2 + zlo, o2 + zhi)
            n_t, best = _side_contact_events(i, pos, ri, rho, arc, known, work, geom, n_sides, ell,
                                             (n_t, best, tol_phi))
        elif walls:
            for wdir in range(4):
                ob = OB_WALL_XLO + wdir
                c0 = plane_of(ob, -1, ri, geom, nrm)
                if wdir == 0:
                    near = o0 + xlo - ri - geom[GEOM_LOWER_X]
                elif wdir == 1:
                    near = geom[GEOM_LOWER_X] + geom[GEOM_LENGTH_X] - (o0 + xhi + ri)
                elif wdir == 2:
                    near = o1 + ylo - ri - geom[GEOM_LOWER_Y]
                else:
                    near = geom[GEOM_LOWER_Y] + geom[GEOM_LENGTH_Y] - (o1 + yhi + ri)
                if near > TOUCH_TOL * ell:
                    continue
                if find_contact(n_pivots, pivots, i, ob, -1) >= 0:
                    continue
                pol = POLICY_TRUSTED if find_contact(n_dr, released, i, ob, -1) >= 0 else POLICY_NEW
                A = -(nrm[0] * e1[0] + nrm[1] * e1[1])
                B = -(nrm[0] * e2[0] + nrm[1] * e2[1])
                gap = nrm[0] * pos[i, 0] + nrm[1] * pos[i, 1] - c0
                phi, cc, ss = first_entry(A, B, A + gap / rho, gap, 1.0 / rho, ell, pol)
                if phi <= best + tol_phi:
                    n_t, best = push_event(n_t, best, tol_phi, (phi, cc, ss), EV_CONTACT, (i, ob, -1, 0.0, 0.0), window)
        for face in range(igeom[IGEOM_FACES]):
            n_t, best = _face_contact_events(i, pos, ri, rho, (o0 + xlo, o1 + ylo, o2 + zlo),
                                             (o0 + xhi, o1 + yhi, o2 + zhi), known, work, geom, face, ell,
                                             (n_t, best, tol_phi))
        # sediment spheres (the most frequent grid query: grid_collect here rather than
        # grid_collect_growing, measured 8% faster)
        reach = ri + reach_sed
        note(work.reads, o0 + xlo - reach, o0 + xhi + reach, o1 + ylo - reach, o1 + yhi + reach)
        started = counters.start(work.counters)
        while True:
            cnt = grid_collect(grid_state, (o0 + xlo - reach, o1 + ylo - reach, o2 + zlo - reach),
                               (o0 + xhi + reach, o1 + yhi + reach, o2 + zhi + reach), buf)
            if cnt >= 0:
                break
            buf = np.empty(2 * buf.shape[0], dtype=np.int64)
        counters.stop(work.counters, counters.GRID, started)
        counters.add(work.counters, counters.GRID_QUERIES, 1)
        counters.add(work.counters, counters.ROLL_CANDIDATES, cnt)
        for qq in range(cnt):
            j = buf[qq]
            rx = sed[j, 0] - pos[i, 0]
            ry = sed[j, 1] - pos[i, 1]
            mx, my = _image_near(periodic, length_x, length_y, rx, ry, mid_x, mid_y)
            # obstacle relative to the pivot
            q0 = pos[i, 0] + mx - pivot[0]
            q1 = pos[i, 1] + my - pivot[1]
            q2 = sed[j, 2] - pivot[2]
            D = ri + sed_r[j]
            hq = q0 * axis[0] + q1 * axis[1] + q2 * axis[2]
            if abs(hq - h) >= D:
                continue
            A = e1[0] * q0 + e1[1] * q1 + e1[2] * q2
            B = e2[0] * q0 + e2[1] * q1 + e2[2] * q2
            dz = sed[j, 2] - pos[i, 2]
            dist2 = mx * mx + my * my + dz * dz
            K = A + (dist2 - D * D) / (2.0 * rho)
            if K > 0.0 and K * K >= A * A + B * B:
                continue
            dist = math.sqrt(dist2)
            gap = dist - D
            pol = POLICY_NEW
            if gap <= 2.0 * CYCLE_CLOSE_GAP * ell:
                if find_contact(n_pivots, pivots, i, OB_SPHERE, j) >= 0:
                    continue
                if find_contact(n_dr, released, i, OB_SPHERE, j) >= 0:
                    pol = POLICY_TRUSTED
            counters.add(work.counters, counters.ROLL_ENTRIES, 1)
            phi, cc, ss = first_entry(A, B, K, gap, dist / rho, ell, pol, lim, cos_lim)
            if phi <= best + tol_phi:
                n_t, best = push_event(n_t, best, tol_phi, (phi, cc, ss),
                                       EV_CONTACT, (i, OB_SPHERE, j, mx - rx, my - ry), window)
    return n_t, best, buf


@jit(inline="always")
def _image_near(periodic, length_x, length_y, rx, ry, mid_x, mid_y):
    """The lateral difference ``rx, ry`` from a sphere to an obstacle, taken to the obstacle's
    image nearest the point ``mid_x, mid_y`` (relative to the sphere) in a periodic box.  The
    difference less whole periods, ``r - L floor((r - mid) / L + 1/2)``, so that where that image
    is also the one nearest the sphere the result is bitwise :func:`.grid.periodic_image`'s; a
    difference within a quarter of the side of ``mid`` needs no division."""
    if periodic:
        dx = rx - mid_x
        if abs(dx) >= 0.25 * length_x:
            rx -= length_x * math.floor(dx / length_x + 0.5)
        dy = ry - mid_y
        if abs(dy) >= 0.25 * length_y:
            ry -= length_y * math.floor(dy / length_y + 0.5)
    return rx, ry


@jit(inline="always")
def _side_contact_events(i, pos, ri, rho, arc, known, work, geom, n_sides, ell, events):
    """New contacts of moving sphere ``i`` (radius ``ri``, its centre on the circle of radius
    ``rho`` and frame ``work.scratch.e1, e2``, its arc within the lateral part of ``arc``) with the
    sides of the cylinder's polygon it can reach, as for a box wall.  Returns ``(n_t, best)``."""
    n_t, best, tol_phi = events
    n_pivots, n_dr = known
    x0, x1, y0, y1, _, _ = arc
    pivots, released, window = work.pivots, work.released, work.window
    e1, e2, nrm = work.scratch.e1, work.scratch.e2, work.scratch.normal
    first, count = candidate_sides(geom, n_sides, x0, x1, y0, y1, ri + TOUCH_TOL * ell)
    for t in range(count):
        side = (first + t) % n_sides
        if side_gap_in_box(geom, side, ri, x0, x1, y0, y1) > TOUCH_TOL * ell:
            continue
        if find_contact(n_pivots, pivots, i, OB_SIDE, side) >= 0:
            continue
        pol = POLICY_TRUSTED if find_contact(n_dr, released, i, OB_SIDE, side) >= 0 else POLICY_NEW
        c0 = side_plane(geom, side, ri, nrm)
        A = -(nrm[0] * e1[0] + nrm[1] * e1[1])
        B = -(nrm[0] * e2[0] + nrm[1] * e2[1])
        gap = nrm[0] * pos[i, 0] + nrm[1] * pos[i, 1] - c0
        phi, cc, ss = first_entry(A, B, A + gap / rho, gap, 1.0 / rho, ell, pol)
        if phi <= best + tol_phi:
            n_t, best = push_event(n_t, best, tol_phi, (phi, cc, ss), EV_CONTACT, (i, OB_SIDE, side, 0.0, 0.0), window)
    return n_t, best


@jit(inline="always")
def _face_contact_events(i, pos, ri, rho, lower, upper, known, work, geom, face, ell, events):
    """New contact of moving sphere ``i`` (radius ``ri``, its centre on the circle of radius ``rho``
    and frame ``work.scratch.e1, e2``, its arc within the box from ``lower`` to ``upper``) with a
    mesh vessel's ``face`` (:mod:`.faces`), a plane as for a box wall but of any normal.  Returns
    ``(n_t, best)``."""
    n_t, best, tol_phi = events
    n_pivots, n_dr = known
    if not face_within(geom, face, lower, upper, ri + TOUCH_TOL * ell):
        return n_t, best
    pivots, released, window = work.pivots, work.released, work.window
    if find_contact(n_pivots, pivots, i, OB_FACE, face) >= 0:
        return n_t, best
    e1, e2, nrm = work.scratch.e1, work.scratch.e2, work.scratch.normal
    pol = POLICY_TRUSTED if find_contact(n_dr, released, i, OB_FACE, face) >= 0 else POLICY_NEW
    c0 = face_plane(geom, face, ri, nrm)
    A = -(nrm[0] * e1[0] + nrm[1] * e1[1] + nrm[2] * e1[2])
    B = -(nrm[0] * e2[0] + nrm[1] * e2[1] + nrm[2] * e2[2])
    gap = nrm[0] * pos[i, 0] + nrm[1] * pos[i, 1] + nrm[2] * pos[i, 2] - c0
    phi, cc, ss = first_entry(A, B, A + gap / rho, gap, 1.0 / rho, ell, pol)
    if phi <= best + tol_phi:
        n_t, best = push_event(n_t, best, tol_phi, (phi, cc, ss), EV_CONTACT, (i, OB_FACE, face, 0.0, 0.0), window)
    return n_t, best


@jit(inline="always")
def _execute(n, particle, n_pivots, work, axis, pivot, n_t, best, tol_phi, event_counts):
    """Turn the particle to the earliest event; the pivots and the contacts made by the
    events within ``tol_phi`` of it (4.3) become the contacts.  Returns ``(n_c, n_executed,
    n_chunk_ends, floor_hit)``."""
    window = work.window
    contacts = work.contacts
    angle, cos, sin, kind, sphere, obstacle, sediment_sphere, shift = window_arrays(window)
    r_best = earliest_event(n_t, window)
    if angle[r_best] > 0.0:
        rotate_particle(n, particle, axis, pivot, cos[r_best], sin[r_best], work.scratch)
    n_c = n_pivots
    for t in range(n_pivots):
        copy_contact(work.pivots, t, contacts, t)
    n_executed = 0
    n_chunk_ends = 0
    floor_hit = False
    for r in range(n_t):
        if angle[r] > best + tol_phi:
            continue
        ev = kind[r]
        if ev == EV_CHUNK:
            n_chunk_ends += 1
            continue
        n_executed += 1
        ob = obstacle[r]
        if ev == EV_CONTACT:
            if find_contact(n_c, contacts, sphere[r], ob, sediment_sphere[r]) < 0:
                n_c = add_contact(n_c, contacts, sphere[r], ob, sediment_sphere[r], shift[r, 0],
                                  shift[r, 1])
            if ob == OB_FLOOR:
                floor_hit = True
        _count_event(event_counts, ev, ob, n_pivots)
    return n_c, n_executed, n_chunk_ends, floor_hit


@jit(inline="always")
def _count_event(event_counts, ev, ob, n_pivots):
    """Count an executed event of a rotation on ``n_pivots`` pivots by its kind (EVENT_KINDS)."""
    if ev == EV_CONTACT:
        if ob == OB_SPHERE:
            if n_pivots == 1:
                event_counts[K_SECOND_CONTACT] += 1
            else:
                event_counts[K_THIRD_CONTACT] += 1
        elif ob == OB_FLOOR:
            event_counts[K_FLOOR_CONTACT] += 1
        else:
            event_counts[K_WALL_CONTACT] += 1
    elif ev == EV_LOSS:
        if n_pivots == 1:
            event_counts[K_LOSS_OF_CONTACT] += 1
        else:
            event_counts[K_LOSS_OF_TWO] += 1
    elif ev == EV_RELEASE:
        event_counts[K_LOSS_OF_ONE] += 1
    elif ev == EV_HANG:
        if n_pivots == 1:
            event_counts[K_HANGING_ONE] += 1
        else:
            event_counts[K_HANGING_TWO] += 1
    elif ev == EV_TRIAL or ev == EV_VIRTUAL:
        event_counts[K_FRUSTRATED] += 1
