"""The deposition loop: one numba kernel that drops, rolls and freezes every particle.

For each particle in order the loop repeats *decide, move* (Fig. 3 of the paper):

1. fill the geometry of the current contacts and ask :func:`decision.decide` for the
   steepest valid motion (fall, rotation on one contact, rotation on two, or rest);
2. fall (3.1): scan the grid columns under every sphere of the particle from their top
   layer down (the height map), stop as soon as a layer lies below the best drop found;
   the floor is a candidate too.  All contacts within ``SIMULTANEOUS_TOL`` of the
   smallest drop are established together (4.3);
3. rotation (3.2, 3.3): the potential events are

   * new contacts of any moving sphere with sediment spheres (circle intersections,
     eqs. 7-12), with the floor (eqs. 19-23) and with walls (same, vertical planes),
   * loss of a pivot contact: its moving sphere comes level with its sediment sphere
     (eq. 17; for two pivots only if then the other one is level or below, 3.3.4),
   * for two pivots, rolling on one of them becomes possible (eqs. 25-30,
     :func:`events.release_plane`), with the virtual small rotation of eq. 31 when the
     release condition holds with zero rate,
   * hanging (eqs. 18, 32): the centre of mass reaches its lowest point,
   * the trial rotation of 4.1: if the decision taken after a rotation by ``trial_angle``
     (with the pivots as the only contacts) differs from the present one, a rotation by
     ``trial_angle`` is a potential event;

   the rotation is searched in angular chunks in which no sphere moves more than
   ``CHUNK_CELLS`` cells (the end of a chunk is a bookkeeping step, not an event), so that
   every grid query covers only the cells within reach of the arc of one sphere.  The
   earliest event and those within ``SIMULTANEOUS_TOL`` of arc length of it are executed
   together (4.3); the particle is rotated by eq. 15 with the event's ``(cos, sin)``;
4. contact bookkeeping after a move: the new contacts are the pivots, the contacts made by
   the executed events, and the released contacts that still touch (gap ``<= TOUCH_TOL``,
   a move of zero or round-off length), so that a decision always sees every obstacle
   touching the particle (4.3) and zero-length moves cannot cycle through them;
5. freezing by infinite cycling (4.2): after each move the decrements of the height of
   the centre of mass are tested with criterion (34) (period 3 as in the paper, and
   periods 2 and 4); when it holds, every obstacle within ``CYCLE_CLOSE_GAP`` of the
   particle is declared a closed contact and the steepest descent continues.  Two
   backstops use the same remedy: when the centre of mass went down by less than
   ``CYCLE_CLOSE_GAP`` in the last 24 steps (a cycle of another period, or a zigzag among
   obstacles at clearances of the order of the tolerances), and when the decision finds
   rest (obstacles left within ``CYCLE_CLOSE_GAP`` are then contacts, and the decision is
   taken again with them).  Each application that closes something is counted as a
   cycling interruption.

A particle that needs more than ``max_events`` decide-and-move steps stops the run
(``EVENT_LIMIT``): nothing is frozen or re-dropped silently.

Boundary modelling choices (not in the paper):

* a wall contact and (FLOOR_ROLL) a floor contact pivot about the centre of the moving
  sphere that touches the plane: the plane holds that sphere (no sliding), the sphere
  stays tangent to the plane, and its contact opens when the particle rolls away;
* under FLOOR_STOP (the paper) the first floor contact immobilises the particle;
* a contact with a plane whose normal is horizontal (a wall) never blocks falling.

Where the pieces live: the fall search in :mod:`.fall`, the window of simultaneous events
in :mod:`.ties`, the contact lists in :mod:`.contacts`, the cycling tests in
:mod:`.cycling`, the debug overlap measure in :mod:`.overlap`.  The event search of a
rotation stays in the loop: moved into a function of its own, the same code ran about 10%
slower (measured; numba/LLVM optimise the one large kernel better).
"""

import math
import time

import numba
import numpy as np

from parsim.core.jit import jit
from parsim.core.sdbd.constants import (
    CHUNK_CELLS,
    CYCLE_CLOSE_GAP,
    DROP_MARGIN,
    EV_CHUNK,
    EV_CONTACT,
    EV_HANG,
    EV_LOSS,
    EV_RELEASE,
    EV_TRIAL,
    EV_VIRTUAL,
    EVENT_LIMIT,
    FLOOR_STOP,
    HANGING_ONE,
    HANGING_TWO,
    K_CYCLING,
    K_FALL_CONTACT,
    K_FLOOR_CONTACT,
    K_FRUSTRATED,
    K_HANGING_ONE,
    K_HANGING_TWO,
    K_LOSS_OF_CONTACT,
    K_LOSS_OF_ONE,
    K_LOSS_OF_TWO,
    K_SECOND_CONTACT,
    K_SIMULTANEOUS,
    K_THIRD_CONTACT,
    K_WALL_CONTACT,
    LATERAL_PERIODIC,
    LATERAL_WALLS,
    MAX_CONTACTS,
    MAX_TIES,
    MOTION_FALL,
    MOTION_REST,
    MOTION_SINGLE,
    NZ_TOL,
    OB_FLOOR,
    OB_SPHERE,
    OB_WALL_XLO,
    RATE_TOL,
    RESTING_ON_FLOOR,
    RESTING_THREE_CONTACTS,
    SIMULTANEOUS_TOL,
    TINY,
    TOUCH_TOL,
    VIRTUAL_ANGLE,
)
from parsim.core.sdbd.contacts import (
    add_contact,
    copy_contact,
    fill_contacts,
    find_contact,
    keep_touching,
    near_contacts,
    plane_of,
)
from parsim.core.sdbd.cycling import CREEP_STEPS, HISTORY, creeping, period_detected
from parsim.core.sdbd.decision import decide
from parsim.core.sdbd.events import (
    POLICY_NEW,
    POLICY_TRUSTED,
    arc_range,
    first_entry,
    hang_cos_sin,
    plane_coefficients,
    release_plane,
)
from parsim.core.sdbd.fall import fall_events
from parsim.core.sdbd.grid import grid_collect, grid_insert, min_image, wrap_position
from parsim.core.sdbd.overlap import max_overlap
from parsim.core.sdbd.rotation import (
    matrix_to_quat,
    quat_from_axis_cos_sin,
    quat_mul,
    quat_normalize,
    quat_to_matrix,
    rotate_point,
)
from parsim.core.sdbd.ties import push_event

__all__ = ["run_deposition"]

# diag slots
D_MAX_OVERLAP = 0      # largest overlap seen after a move (debug), units of length
D_EVENTS = 1           # decide/move steps, all particles
D_CHUNKS = 2           # chunk ends (bookkeeping steps)
D_CLOCKED_SECONDS = 3  # wall-clock seconds from the start of particle clock_from to the end


# ----------------------------------------------------------------------------- helpers
@jit
def _positions(n, body, rot, com, pos):
    """Sphere centres ``pos = com + rot body`` of the moving particle."""
    for i in range(n):
        for k in range(3):
            pos[i, k] = com[k] + rot[k, 0] * body[i, 0] + rot[k, 1] * body[i, 1] + rot[k, 2] * body[i, 2]


@jit
def _new_particle(p, shape_offsets, shape_radii, shape_start, particle_shape, particle_scale,
                  particle_rotation, particle_drop_xy, top_z, ell, body, rad, q, rot, com, pos):
    """Particle ``p`` at its drop: scaled body offsets and radii, orientation, centre of mass
    ``DROP_MARGIN`` above the top of the sediment; returns its number of spheres."""
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
    quat_normalize(q)
    quat_to_matrix(q, rot)
    below = 0.0
    for i in range(n):
        zi = rot[2, 0] * body[i, 0] + rot[2, 1] * body[i, 1] + rot[2, 2] * body[i, 2]
        below = max(below, rad[i] - zi)
    com[0] = particle_drop_xy[p, 0]
    com[1] = particle_drop_xy[p, 1]
    com[2] = top_z + below + DROP_MARGIN * ell
    _positions(n, body, rot, com, pos)
    return n


@jit
def _rest_state(n_c, con_ob):
    """State of a particle at rest with ``n_c`` contacts."""
    has_floor = False
    for l in range(n_c):
        if con_ob[l] == OB_FLOOR:
            has_floor = True
    if n_c >= 3:
        return RESTING_THREE_CONTACTS
    if has_floor:
        return RESTING_ON_FLOOR
    if n_c == 2:
        return HANGING_TWO
    return HANGING_ONE


@jit
def _count_rotation_event(ev_row, ev, ob, npv):
    """Count an executed event of a rotation on ``npv`` pivots by its kind (EVENT_KINDS)."""
    if ev == EV_CONTACT:
        if ob == OB_SPHERE:
            if npv == 1:
                ev_row[K_SECOND_CONTACT] += 1
            else:
                ev_row[K_THIRD_CONTACT] += 1
        elif ob == OB_FLOOR:
            ev_row[K_FLOOR_CONTACT] += 1
        else:
            ev_row[K_WALL_CONTACT] += 1
    elif ev == EV_LOSS:
        if npv == 1:
            ev_row[K_LOSS_OF_CONTACT] += 1
        else:
            ev_row[K_LOSS_OF_TWO] += 1
    elif ev == EV_RELEASE:
        ev_row[K_LOSS_OF_ONE] += 1
    elif ev == EV_HANG:
        if npv == 1:
            ev_row[K_HANGING_ONE] += 1
        else:
            ev_row[K_HANGING_TWO] += 1
    elif ev == EV_TRIAL or ev == EV_VIRTUAL:
        ev_row[K_FRUSTRATED] += 1


@jit
def _close_near_obstacles(n, pos, rad, n_c, con_i, con_ob, con_j, con_sh, sed, sed_r, geom, igeom,
                          head, col_top, nxt, hkeys, hval, r_max_sed, walls, ell, buf, nrm,
                          floor_mode, ev_row):
    """4.2: declare closed every obstacle within ``CYCLE_CLOSE_GAP`` (:func:`near_contacts`),
    counted as a cycling interruption when that adds a contact.  Returns
    ``(n_c, closed, stop, buf)``: ``stop`` when a floor contact immobilises the particle
    (FLOOR_STOP)."""
    n_c, added, floor_added, buf = near_contacts(n, pos, rad, n_c, con_i, con_ob, con_j, con_sh,
                                                 sed, sed_r, geom, igeom, head, col_top, nxt, hkeys,
                                                 hval, r_max_sed, walls, ell, buf, nrm)
    if added > 0:
        ev_row[K_CYCLING] += 1
    return n_c, added > 0, floor_added and floor_mode == FLOOR_STOP, buf


@jit
def _record_trace(tr, motion, n_c_before, mk, mm, t_ev, t_phi, best, n_t, com, n_c, con_ob, con_j):
    """One row of the trace of a step (see :func:`run_deposition`)."""
    tr[0] = motion
    tr[1] = n_c_before
    tr[2] = mk
    tr[3] = mm
    tr[4] = t_ev[0] if motion != MOTION_FALL else -1
    tr[5] = t_phi[0] if motion != MOTION_FALL else best
    tr[6] = n_t
    tr[7] = com[0]
    tr[8] = com[1]
    tr[9] = com[2]
    tr[10] = n_c
    for l in range(min(n_c, 5)):
        tr[11 + l] = con_j[l] if con_ob[l] == OB_SPHERE else -con_ob[l]


# ----------------------------------------------------------------------------- kernel
@jit
def run_deposition(shape_offsets, shape_radii, shape_start, particle_shape, particle_scale,
                   particle_rotation, particle_drop_xy,
                   geom, igeom, head, col_top, nxt, hkeys, hval, counts,
                   floor_mode, trial_angle, cycle_n, cycle_eps, max_events, ell, r_max_sed,
                   debug, trace_particle, trace, clock_from,
                   out_pos, out_rad, out_particle, out_com, out_rot, out_contacts, out_state,
                   out_events, diag):
    """Deposit all particles; returns ``(stopped_at, n_spheres_written)``.

    Inputs are validated by :func:`parsim.core.sdbd.deposit`.  ``geom, igeom, head, ...``
    is an empty grid from :func:`grid.grid_new`; ``out_*`` are preallocated outputs for
    all particles; ``diag`` (3,) receives diagnostics (largest overlap after a move when
    ``debug``, number of steps, number of chunk steps).  The steps of particle
    ``trace_particle`` (``-1``: none) are recorded in the rows of ``trace`` (T, 16):
    motion, number of contacts before the step, pivot contacts k and m, first executed
    event kind, angle or drop, number of executed events, centre of mass after the step,
    number of contacts after the step, and the obstacle index of up to 5 contacts.
    ``diag[D_CLOCKED_SECONDS]`` receives the wall-clock time spent on particles
    ``clock_from`` onwards (untouched when ``clock_from`` is not a particle index).
    """
    n_part = particle_shape.shape[0]
    lateral = igeom[0]
    walls = lateral == LATERAL_WALLS
    cell = geom[6]
    nmax = 1
    for s in range(shape_start.shape[0] - 1):
        nmax = max(nmax, shape_start[s + 1] - shape_start[s])
    n_total = out_rad.shape[0]
    # sediment (internal positions wrapped into the periodic box)
    sed = np.empty((max(n_total, 1), 3))
    sed_r = np.empty(max(n_total, 1))
    n_sed = 0
    top_z = 0.0
    # moving particle
    body = np.empty((nmax, 3))
    rad = np.empty(nmax)
    pos = np.empty((nmax, 3))
    com = np.empty(3)
    q = np.empty(4)
    qr = np.empty(4)
    qt = np.empty(4)
    rot = np.empty((3, 3))
    # contacts (see contacts.py) and their geometry for the decision
    con_i = np.empty(MAX_CONTACTS, dtype=np.int64)
    con_ob = np.empty(MAX_CONTACTS, dtype=np.int64)
    con_j = np.empty(MAX_CONTACTS, dtype=np.int64)
    con_sh = np.zeros((MAX_CONTACTS, 3))
    ca = np.empty((MAX_CONTACTS, 3))
    cP = np.empty((MAX_CONTACTS, 3))
    cN = np.empty((MAX_CONTACTS, 3))
    cD = np.empty(MAX_CONTACTS)
    cc0 = np.empty(MAX_CONTACTS)
    ckind = np.empty(MAX_CONTACTS, dtype=np.int64)
    # pivots / released contacts of the present move
    pv_i = np.empty(2, dtype=np.int64)
    pv_ob = np.empty(2, dtype=np.int64)
    pv_j = np.empty(2, dtype=np.int64)
    pv_sh = np.zeros((2, 3))
    dr_i = np.empty(MAX_CONTACTS, dtype=np.int64)
    dr_ob = np.empty(MAX_CONTACTS, dtype=np.int64)
    dr_j = np.empty(MAX_CONTACTS, dtype=np.int64)
    dr_sh = np.zeros((MAX_CONTACTS, 3))
    # trial-state copies (4.1)
    ta = np.empty((2, 3))
    tP = np.empty((2, 3))
    tN = np.empty((2, 3))
    tD = np.empty(2)
    tc0 = np.empty(2)
    tkind = np.empty(2, dtype=np.int64)
    tcom = np.empty(3)
    # potential events of a move (see ties.py)
    t_phi = np.empty(MAX_TIES)
    t_c = np.empty(MAX_TIES)
    t_s = np.empty(MAX_TIES)
    t_ev = np.empty(MAX_TIES, dtype=np.int64)
    t_i = np.empty(MAX_TIES, dtype=np.int64)
    t_ob = np.empty(MAX_TIES, dtype=np.int64)
    t_j = np.empty(MAX_TIES, dtype=np.int64)
    t_sh = np.zeros((MAX_TIES, 2))
    # cycling (4.2): positive decrements of the height, descents of the last steps
    dz_hist = np.empty(HISTORY)
    dz_all = np.zeros(CREEP_STEPS)
    # scratch
    wk = np.empty(8)
    wk2 = np.empty(8)
    axis = np.empty(3)
    piv = np.empty(3)
    e1 = np.empty(3)
    e2 = np.empty(3)
    nrm = np.empty(3)
    nrm2 = np.empty(3)
    tmp = np.empty(3)
    buf = np.empty(4096, dtype=np.int64)
    # eq. 31: the virtual small rotation is the trial angle of 4.1 (the paper refers to
    # section 4.1 for it); VIRTUAL_ANGLE only when the trial test is disabled
    virt = trial_angle if trial_angle > 0.0 else VIRTUAL_ANGLE
    max_ov = -np.inf
    n_steps = 0
    n_chunks = 0
    stopped_at = -1

    clock_start = 0.0
    for p in range(n_part):
        if p == clock_from:
            clock_start = _wall_clock()
        n = _new_particle(p, shape_offsets, shape_radii, shape_start, particle_shape, particle_scale,
                          particle_rotation, particle_drop_xy, top_z, ell, body, rad, q, rot, com, pos)
        n_c = 0
        n_hist = 0
        n_all = 0
        rest_checked = False
        state = -1
        ev_count = 0
        ev_row = out_events[p]
        while True:
            if ev_count >= max_events:
                state = EVENT_LIMIT
                break
            ev_count += 1
            n_steps += 1
            fill_contacts(n_c, con_i, con_ob, con_j, con_sh, pos, rad, sed, sed_r, geom,
                          ca, cP, cN, cD, cc0, ckind, nrm)
            motion, mk, mm, _ = decide(com, n_c, ca, cP, cN, ckind, cD, cc0, ell, wk)
            n_c_before = n_c
            if motion == MOTION_REST and not rest_checked:
                # 4.2 at rest: obstacles left within CYCLE_CLOSE_GAP (by a cycle that
                # converged, or a round-off gap) are declared closed, and the steepest
                # descent is decided again with them
                rest_checked = True
                n_c, closed, stop, buf = _close_near_obstacles(
                    n, pos, rad, n_c, con_i, con_ob, con_j, con_sh, sed, sed_r, geom, igeom,
                    head, col_top, nxt, hkeys, hval, r_max_sed, walls, ell, buf, nrm, floor_mode, ev_row)
                if stop:
                    state = RESTING_ON_FLOOR
                    break
                if closed:
                    continue
            if motion == MOTION_REST:
                state = _rest_state(n_c, con_ob)
                break
            z_before = com[2]
            rest_checked = False
            n_exec = 0
            floor_hit = False
            if motion == MOTION_FALL:
                # ---------------------------------------------------------- fall (3.1)
                n_dr = n_c
                for l in range(n_c):
                    copy_contact(con_i, con_ob, con_j, con_sh, l, dr_i, dr_ob, dr_j, dr_sh, l)
                n_c = 0
                n_t, best, tol = fall_events(n, pos, rad, sed, sed_r, geom, igeom, head, col_top, nxt,
                                             hkeys, hval, r_max_sed, ell,
                                             t_phi, t_c, t_s, t_ev, t_i, t_ob, t_j, t_sh)
                com[2] -= best
                for i in range(n):
                    pos[i, 2] -= best
                # the contacts are those made at the smallest drop (4.3)
                for r in range(n_t):
                    if t_phi[r] > best + tol:
                        continue
                    n_c = add_contact(n_c, con_i, con_ob, con_j, con_sh, t_i[r], t_ob[r], t_j[r],
                                      t_sh[r, 0], t_sh[r, 1])
                    n_exec += 1
                    if t_ob[r] == OB_FLOOR:
                        floor_hit = True
                        ev_row[K_FLOOR_CONTACT] += 1
                    else:
                        ev_row[K_FALL_CONTACT] += 1
            else:
                # ------------------------------------------------------ rotation (3.2, 3.3)
                for k in range(3):
                    axis[k] = wk[k]
                    piv[k] = wk[3 + k]
                # pivots and released contacts
                npv = 1 if motion == MOTION_SINGLE else 2
                copy_contact(con_i, con_ob, con_j, con_sh, mk, pv_i, pv_ob, pv_j, pv_sh, 0)
                if npv == 2:
                    copy_contact(con_i, con_ob, con_j, con_sh, mm, pv_i, pv_ob, pv_j, pv_sh, 1)
                n_dr = 0
                for l in range(n_c):
                    if l == mk or l == mm:
                        continue
                    copy_contact(con_i, con_ob, con_j, con_sh, l, dr_i, dr_ob, dr_j, dr_sh, n_dr)
                    n_dr += 1
                # hanging angle (eqs. 18, 32) bounds the rotation
                phi_hang, c_hang, s_hang = hang_cos_sin(com, piv, axis)
                # arcs of the spheres: largest distance from the axis
                rho_max = 0.0
                for i in range(n):
                    r0 = pos[i, 0] - piv[0]
                    r1 = pos[i, 1] - piv[1]
                    r2 = pos[i, 2] - piv[2]
                    h = r0 * axis[0] + r1 * axis[1] + r2 * axis[2]
                    rr = r0 * r0 + r1 * r1 + r2 * r2 - h * h
                    if rr > rho_max:
                        rho_max = rr
                rho_max = math.sqrt(max(rho_max, 0.0))
                if rho_max < ell:
                    rho_max = ell
                tol_phi = SIMULTANEOUS_TOL * ell / rho_max
                phi_lim = CHUNK_CELLS * cell / rho_max
                if phi_lim > math.pi:
                    phi_lim = math.pi
                n_t = 0
                best = np.inf
                if phi_hang <= phi_lim:
                    n_t, best = push_event(n_t, best, tol_phi, phi_hang, c_hang, s_hang, EV_HANG, -1, -1,
                                           -1, 0.0, 0.0, t_phi, t_c, t_s, t_ev, t_i, t_ob, t_j, t_sh)
                else:
                    n_t, best = push_event(n_t, best, tol_phi, phi_lim, math.cos(phi_lim),
                                           math.sin(phi_lim), EV_CHUNK, -1, -1, -1, 0.0, 0.0,
                                           t_phi, t_c, t_s, t_ev, t_i, t_ob, t_j, t_sh)
                # loss of contact (eq. 17 / 3.3.4)
                for t in range(npv):
                    l = mk if t == 0 else mm
                    if ckind[l] != OB_SPHERE:
                        continue
                    nrm[0] = 0.0
                    nrm[1] = 0.0
                    nrm[2] = 1.0
                    A, B, K, rho, gap = plane_coefficients(ca[l], piv, axis, nrm, cP[l, 2], e1, e2)
                    if rho == 0.0 or gap <= NZ_TOL * cD[l]:
                        # level or below already: that crossing is not ahead
                        continue
                    phi, cc, ss = first_entry(A, B, K, gap, 1.0 / rho, ell, POLICY_TRUSTED)
                    if phi > best + tol_phi:
                        continue
                    if npv == 2:
                        o = mm if t == 0 else mk
                        if ckind[o] == OB_SPHERE:
                            rotate_point(ca[o], piv, axis, cc, ss, tmp)
                            nz = tmp[2] - cP[o, 2]
                            dn = math.sqrt((tmp[0] - cP[o, 0]) ** 2 + (tmp[1] - cP[o, 1]) ** 2 + nz * nz)
                            if nz > NZ_TOL * dn:
                                continue
                        elif cN[o, 2] > NZ_TOL:
                            continue
                    n_t, best = push_event(n_t, best, tol_phi, phi, cc, ss, EV_LOSS, l, -1, -1, 0.0, 0.0,
                                           t_phi, t_c, t_s, t_ev, t_i, t_ob, t_j, t_sh)
                # release of one of two pivots (eqs. 25-31)
                if npv == 2:
                    for t in range(2):
                        x = mk if t == 0 else mm
                        y = mm if t == 0 else mk
                        ok, use_com, c0, gap0 = release_plane(com, cP[x], cP[y], ca[y],
                                                              ckind[y] == OB_SPHERE, cN[y], nrm2)
                        if not ok:
                            continue
                        if use_com:
                            A, B, K, rho, gap = plane_coefficients(com, piv, axis, nrm2, c0, e1, e2)
                        else:
                            A, B, K, rho, gap = plane_coefficients(ca[y], piv, axis, nrm2, c0, e1, e2)
                        if rho == 0.0:
                            continue
                        if abs(gap) <= TOUCH_TOL * ell:
                            if B > RATE_TOL * ell / rho:
                                # eq. 31: release condition holds with zero rate and the
                                # decision found the contact not opening: rotate a little
                                n_t, best = push_event(n_t, best, tol_phi, virt,
                                                       math.cos(virt), math.sin(virt),
                                                       EV_VIRTUAL, -1, -1, -1, 0.0, 0.0,
                                                       t_phi, t_c, t_s, t_ev, t_i, t_ob, t_j, t_sh)
                                continue
                        elif gap < 0.0:
                            continue
                        phi, cc, ss = first_entry(A, B, K, gap, 1.0 / rho, ell, POLICY_TRUSTED)
                        if phi <= best + tol_phi:
                            n_t, best = push_event(n_t, best, tol_phi, phi, cc, ss, EV_RELEASE, x, -1, -1,
                                                   0.0, 0.0, t_phi, t_c, t_s, t_ev, t_i, t_ob, t_j, t_sh)
                # frustrated situation (4.1): does the decision change after trial_angle?
                if trial_angle > 0.0 and trial_angle <= best + tol_phi:
                    ct = math.cos(trial_angle)
                    st = math.sin(trial_angle)
                    rotate_point(com, piv, axis, ct, st, tcom)
                    for t in range(npv):
                        l = mk if t == 0 else mm
                        rotate_point(ca[l], piv, axis, ct, st, tmp)
                        tkind[t] = ckind[l]
                        tD[t] = cD[l]
                        tc0[t] = cc0[l]
                        for k in range(3):
                            ta[t, k] = tmp[k]
                        if ckind[l] == OB_SPHERE:
                            for k in range(3):
                                tP[t, k] = cP[l, k]
                            nn = math.sqrt((tmp[0] - cP[l, 0]) ** 2 + (tmp[1] - cP[l, 1]) ** 2
                                           + (tmp[2] - cP[l, 2]) ** 2)
                            for k in range(3):
                                tN[t, k] = (tmp[k] - cP[l, k]) / nn
                        else:
                            for k in range(3):
                                tP[t, k] = tmp[k]
                                tN[t, k] = cN[l, k]
                    m2, k2, mm2, _ = decide(tcom, npv, ta, tP, tN, tkind, tD, tc0, ell, wk2)
                    same = m2 == motion and k2 == 0 and (npv == 1 or mm2 == 1)
                    if not same:
                        n_t, best = push_event(n_t, best, tol_phi, trial_angle, ct, st, EV_TRIAL, -1, -1,
                                               -1, 0.0, 0.0, t_phi, t_c, t_s, t_ev, t_i, t_ob, t_j, t_sh)
                # new contacts of every sphere (eqs. 7-12, 19-23)
                for i in range(n):
                    r0 = pos[i, 0] - piv[0]
                    r1 = pos[i, 1] - piv[1]
                    r2 = pos[i, 2] - piv[2]
                    h = r0 * axis[0] + r1 * axis[1] + r2 * axis[2]
                    p0 = r0 - h * axis[0]
                    p1 = r1 - h * axis[1]
                    p2 = r2 - h * axis[2]
                    rho = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
                    if rho <= TINY * ell:
                        continue
                    e1[0] = p0 / rho
                    e1[1] = p1 / rho
                    e1[2] = p2 / rho
                    e2[0] = axis[1] * e1[2] - axis[2] * e1[1]
                    e2[1] = axis[2] * e1[0] - axis[0] * e1[2]
                    e2[2] = axis[0] * e1[1] - axis[1] * e1[0]
                    lim = best + tol_phi
                    if lim > math.pi:
                        lim = math.pi
                    o0 = piv[0] + h * axis[0]
                    o1 = piv[1] + h * axis[1]
                    o2 = piv[2] + h * axis[2]
                    xlo, xhi = arc_range(rho, e1[0], e2[0], lim)
                    ylo, yhi = arc_range(rho, e1[1], e2[1], lim)
                    zlo, zhi = arc_range(rho, e1[2], e2[2], lim)
                    ri = rad[i]
                    # floor
                    if o2 + zlo - ri <= TOUCH_TOL * ell:
                        pl = find_contact(npv, pv_i, pv_ob, pv_j, i, OB_FLOOR, -1)
                        if pl < 0:
                            pol = POLICY_TRUSTED if find_contact(n_dr, dr_i, dr_ob, dr_j, i, OB_FLOOR, -1) >= 0 else POLICY_NEW
                            A = -e1[2]
                            B = -e2[2]
                            gap = pos[i, 2] - ri
                            phi, cc, ss = first_entry(A, B, A + gap / rho, gap, 1.0 / rho, ell, pol)
                            if phi <= best + tol_phi:
                                n_t, best = push_event(n_t, best, tol_phi, phi, cc, ss, EV_CONTACT, i,
                                                       OB_FLOOR, -1, 0.0, 0.0, t_phi, t_c, t_s, t_ev, t_i,
                                                       t_ob, t_j, t_sh)
                    if walls:
                        for wdir in range(4):
                            ob = OB_WALL_XLO + wdir
                            c0 = plane_of(ob, ri, geom, nrm)
                            if wdir == 0:
                                near = o0 + xlo - ri - geom[0]
                            elif wdir == 1:
                                near = geom[0] + geom[2] - (o0 + xhi + ri)
                            elif wdir == 2:
                                near = o1 + ylo - ri - geom[1]
                            else:
                                near = geom[1] + geom[3] - (o1 + yhi + ri)
                            if near > TOUCH_TOL * ell:
                                continue
                            if find_contact(npv, pv_i, pv_ob, pv_j, i, ob, -1) >= 0:
                                continue
                            pol = POLICY_TRUSTED if find_contact(n_dr, dr_i, dr_ob, dr_j, i, ob, -1) >= 0 else POLICY_NEW
                            A = -(nrm[0] * e1[0] + nrm[1] * e1[1])
                            B = -(nrm[0] * e2[0] + nrm[1] * e2[1])
                            gap = nrm[0] * pos[i, 0] + nrm[1] * pos[i, 1] - c0
                            phi, cc, ss = first_entry(A, B, A + gap / rho, gap, 1.0 / rho, ell, pol)
                            if phi <= best + tol_phi:
                                n_t, best = push_event(n_t, best, tol_phi, phi, cc, ss, EV_CONTACT, i, ob,
                                                       -1, 0.0, 0.0, t_phi, t_c, t_s, t_ev, t_i, t_ob,
                                                       t_j, t_sh)
                    # sediment spheres (the most frequent grid query: grid_collect here
                    # rather than grid_collect_growing, measured 8% faster)
                    reach = ri + r_max_sed
                    while True:
                        cnt = grid_collect(geom, igeom, head, col_top, nxt, hkeys, hval,
                                           o0 + xlo - reach, o0 + xhi + reach,
                                           o1 + ylo - reach, o1 + yhi + reach,
                                           o2 + zlo - reach, o2 + zhi + reach, buf)
                        if cnt >= 0:
                            break
                        buf = np.empty(2 * buf.shape[0], dtype=np.int64)
                    for qq in range(cnt):
                        j = buf[qq]
                        rx = sed[j, 0] - pos[i, 0]
                        ry = sed[j, 1] - pos[i, 1]
                        mx, my = min_image(geom, igeom, rx, ry)
                        # obstacle relative to the pivot
                        q0 = pos[i, 0] + mx - piv[0]
                        q1 = pos[i, 1] + my - piv[1]
                        q2 = sed[j, 2] - piv[2]
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
                            if find_contact(npv, pv_i, pv_ob, pv_j, i, OB_SPHERE, j) >= 0:
                                continue
                            if find_contact(n_dr, dr_i, dr_ob, dr_j, i, OB_SPHERE, j) >= 0:
                                pol = POLICY_TRUSTED
                        phi, cc, ss = first_entry(A, B, K, gap, dist / rho, ell, pol)
                        if phi <= best + tol_phi:
                            n_t, best = push_event(n_t, best, tol_phi, phi, cc, ss, EV_CONTACT, i,
                                                   OB_SPHERE, j, mx - rx, my - ry, t_phi, t_c, t_s,
                                                   t_ev, t_i, t_ob, t_j, t_sh)
                # ---- execute the earliest event (and those simultaneous with it)
                r_best = 0
                for r in range(n_t):
                    if t_phi[r] < t_phi[r_best]:
                        r_best = r
                cb = t_c[r_best]
                sb = t_s[r_best]
                if t_phi[r_best] > 0.0:
                    rotate_point(com, piv, axis, cb, sb, tmp)
                    for k in range(3):
                        com[k] = tmp[k]
                    quat_from_axis_cos_sin(axis, cb, sb, qr)
                    quat_mul(qr, q, qt)
                    for k in range(4):
                        q[k] = qt[k]
                    quat_normalize(q)
                    quat_to_matrix(q, rot)
                    _positions(n, body, rot, com, pos)
                # new contact set: the pivots, then the new contacts
                n_c = npv
                for t in range(npv):
                    copy_contact(pv_i, pv_ob, pv_j, pv_sh, t, con_i, con_ob, con_j, con_sh, t)
                for r in range(n_t):
                    if t_phi[r] > best + tol_phi:
                        continue
                    if t_ev[r] == EV_CHUNK:
                        n_chunks += 1
                        continue
                    n_exec += 1
                    if t_ev[r] == EV_CONTACT:
                        if find_contact(n_c, con_i, con_ob, con_j, t_i[r], t_ob[r], t_j[r]) < 0:
                            n_c = add_contact(n_c, con_i, con_ob, con_j, con_sh, t_i[r], t_ob[r],
                                              t_j[r], t_sh[r, 0], t_sh[r, 1])
                        if t_ob[r] == OB_FLOOR:
                            floor_hit = True
                    _count_rotation_event(ev_row, t_ev[r], t_ob[r], npv)
            # ---------------------------------------------------------- after every move
            if n_exec > 1:
                ev_row[K_SIMULTANEOUS] += n_exec - 1
            n_c = keep_touching(n_c, con_i, con_ob, con_j, con_sh, n_dr, dr_i, dr_ob, dr_j,
                                dr_sh, pos, rad, sed, sed_r, geom, ell, nrm)
            if debug:
                ov, buf = max_overlap(n, pos, rad, sed, sed_r, geom, igeom, head, col_top, nxt,
                                      hkeys, hval, r_max_sed, walls, buf)
                max_ov = max(max_ov, ov)
            if floor_hit and floor_mode == FLOOR_STOP:
                state = RESTING_ON_FLOOR
            if p == trace_particle and ev_count - 1 < trace.shape[0]:
                _record_trace(trace[ev_count - 1], motion, n_c_before, mk, mm, t_ev, t_phi, best, n_t,
                              com, n_c, con_ob, con_j)
            if state == RESTING_ON_FLOOR:
                break  # FLOOR_STOP: immobilised at its first floor contact
            # ---------------------------------------------------------- cycling (4.2)
            dzc = z_before - com[2]
            if dzc > 0.0:
                dz_hist[n_hist % HISTORY] = dzc
                n_hist += 1
                if period_detected(dz_hist, n_hist, cycle_n, cycle_eps):
                    # declare the contacts of the cycle closed: every obstacle within
                    # CYCLE_CLOSE_GAP of the particle
                    n_c, closed, stop, buf = _close_near_obstacles(
                        n, pos, rad, n_c, con_i, con_ob, con_j, con_sh, sed, sed_r, geom, igeom,
                        head, col_top, nxt, hkeys, hval, r_max_sed, walls, ell, buf, nrm, floor_mode,
                        ev_row)
                    if closed:
                        n_hist = 0
                        n_all = 0
                    if stop:
                        state = RESTING_ON_FLOOR
                        break
            # creeping (4.2 without a period): the centre of mass went down by less than
            # CYCLE_CLOSE_GAP in the last CREEP_STEPS steps, so the particle zigzags among
            # obstacles at clearances of the order of the tolerances: declare them closed
            dz_all[n_all % CREEP_STEPS] = max(dzc, 0.0)
            n_all += 1
            if n_all >= CREEP_STEPS and creeping(dz_all, ell):
                n_c, closed, stop, buf = _close_near_obstacles(
                    n, pos, rad, n_c, con_i, con_ob, con_j, con_sh, sed, sed_r, geom, igeom,
                    head, col_top, nxt, hkeys, hval, r_max_sed, walls, ell, buf, nrm, floor_mode, ev_row)
                n_all = 0
                if closed:
                    n_hist = 0
                if stop:
                    state = RESTING_ON_FLOOR
                    break
        # ------------------------------------------------------------- particle done
        if state == EVENT_LIMIT:
            out_state[p] = EVENT_LIMIT
            stopped_at = p
            break
        if lateral == LATERAL_PERIODIC:
            cx, cy = wrap_position(geom, igeom, com[0], com[1])
            com[0] = cx
            com[1] = cy
            _positions(n, body, rot, com, pos)
        if debug:
            ov, buf = max_overlap(n, pos, rad, sed, sed_r, geom, igeom, head, col_top, nxt,
                                  hkeys, hval, r_max_sed, walls, buf)
            max_ov = max(max_ov, ov)
        for i in range(n):
            j = n_sed
            for k in range(3):
                out_pos[j, k] = pos[i, k]
            out_rad[j] = rad[i]
            out_particle[j] = p
            wx, wy = wrap_position(geom, igeom, pos[i, 0], pos[i, 1])
            sed[j, 0] = wx
            sed[j, 1] = wy
            sed[j, 2] = pos[i, 2]
            sed_r[j] = rad[i]
            head, col_top, hkeys, hval = grid_insert(geom, igeom, head, col_top, nxt, hkeys, hval,
                                                     counts, j, wx, wy, pos[i, 2])
            top_z = max(top_z, pos[i, 2] + rad[i])
            n_sed += 1
        for k in range(3):
            out_com[p, k] = com[k]
        matrix_to_quat(rot, out_rot[p])
        out_contacts[p] = n_c
        out_state[p] = state
    diag[D_MAX_OVERLAP] = max_ov
    diag[D_EVENTS] = n_steps
    diag[D_CHUNKS] = n_chunks
    if 0 <= clock_from < n_part:
        diag[D_CLOCKED_SECONDS] = _wall_clock() - clock_start
    return stopped_at, n_sed


@jit(nogil=False)  # it takes the GIL for the interpreter call anyway
def _wall_clock():
    """``time.perf_counter()`` from inside a kernel (a short excursion to the interpreter)."""
    with numba.objmode(now="float64"):
        now = time.perf_counter()
    return now
