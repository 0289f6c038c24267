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
    OB_WALL_XHI,
    OB_WALL_XLO,
    OB_WALL_YHI,
    OB_WALL_YLO,
    RATE_TOL,
    RESTING_ON_FLOOR,
    RESTING_THREE_CONTACTS,
    SIMULTANEOUS_TOL,
    TINY,
    TOUCH_TOL,
    VIRTUAL_ANGLE,
)
from parsim.core.sdbd.decision import decide
from parsim.core.sdbd.events import (
    POLICY_NEW,
    POLICY_TRUSTED,
    fall_drop,
    first_entry,
    hang_cos_sin,
    plane_coefficients,
    release_plane,
)
from parsim.core.sdbd.grid import (
    column_lookup,
    grid_collect,
    grid_insert,
    min_image,
    wrap_position,
)
from parsim.core.sdbd.rotation import (
    matrix_to_quat,
    quat_from_axis_cos_sin,
    quat_mul,
    quat_normalize,
    quat_to_matrix,
    rotate_point,
)

__all__ = ["run_deposition"]

TWO_PI = 2.0 * math.pi

# diag slots
D_MAX_OVERLAP = 0      # largest overlap seen after a move (debug), units of length
D_EVENTS = 1           # decide/move steps, all particles
D_CHUNKS = 2           # chunk ends (bookkeeping steps)
D_CLOCKED_SECONDS = 3  # wall-clock seconds from the start of particle clock_from to the end


# ----------------------------------------------------------------------------- helpers
@jit
def _positions(n, body, rot, com, pos):
    for i in range(n):
        for k in range(3):
            pos[i, k] = com[k] + rot[k, 0] * body[i, 0] + rot[k, 1] * body[i, 1] + rot[k, 2] * body[i, 2]


@jit
def _plane_of(ob, r, geom, nrm):
    """Normal and level of the plane obstacle ``ob`` for a sphere of radius ``r``."""
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
def _fill_contacts(n_c, con_i, con_ob, con_j, con_sh, pos, rad, sed, sed_r, geom,
                   ca, cP, cN, cD, cc0, ckind, nrm):
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
            c0 = _plane_of(ob, rad[i], geom, nrm)
            for k in range(3):
                cP[l, k] = pos[i, k]
                cN[l, k] = nrm[k]
            cD[l] = rad[i]
            cc0[l] = c0


@jit
def _contact_gap(ob, a, P, N, D, c0):
    if ob == OB_SPHERE:
        return math.sqrt((a[0] - P[0]) ** 2 + (a[1] - P[1]) ** 2 + (a[2] - P[2]) ** 2) - D
    return N[0] * a[0] + N[1] * a[1] + N[2] * a[2] - c0


@jit
def _find(n, arr_i, arr_ob, arr_j, i, ob, j):
    for l in range(n):
        if arr_i[l] == i and arr_ob[l] == ob and arr_j[l] == j:
            return l
    return -1


@jit
def _push(n_t, best, tol, phi, c, s, ev, i, ob, j, sh0, sh1,
          t_phi, t_c, t_s, t_ev, t_i, t_ob, t_j, t_sh):
    """Add a potential event if it can still be among the earliest; returns (n_t, best)."""
    if phi > best + tol:
        return n_t, best
    if phi < best:
        best = phi
        # drop entries that fell out of the window
        w = 0
        for r in range(n_t):
            if t_phi[r] <= best + tol:
                if w != r:
                    t_phi[w] = t_phi[r]
                    t_c[w] = t_c[r]
                    t_s[w] = t_s[r]
                    t_ev[w] = t_ev[r]
                    t_i[w] = t_i[r]
                    t_ob[w] = t_ob[r]
                    t_j[w] = t_j[r]
                    t_sh[w, 0] = t_sh[r, 0]
                    t_sh[w, 1] = t_sh[r, 1]
                w += 1
        n_t = w
    if n_t >= t_phi.shape[0]:
        return n_t, best
    t_phi[n_t] = phi
    t_c[n_t] = c
    t_s[n_t] = s
    t_ev[n_t] = ev
    t_i[n_t] = i
    t_ob[n_t] = ob
    t_j[n_t] = j
    t_sh[n_t, 0] = sh0
    t_sh[n_t, 1] = sh1
    return n_t + 1, best


@jit
def _arc_range(rho, e1k, e2k, phi_lim):
    """Range of ``rho (e1k cos phi + e2k sin phi)`` over ``[0, phi_lim]``."""
    f0 = rho * e1k
    f1 = rho * (e1k * math.cos(phi_lim) + e2k * math.sin(phi_lim))
    lo = min(f0, f1)
    hi = max(f0, f1)
    m = rho * math.sqrt(e1k * e1k + e2k * e2k)
    th = math.atan2(e2k, e1k)
    if th < 0.0:
        th += TWO_PI
    if th <= phi_lim:
        hi = m
    th += math.pi
    if th >= TWO_PI:
        th -= TWO_PI
    if th <= phi_lim:
        lo = -m
    return lo, hi


@jit
def _max_overlap(n, pos, rad, sed, sed_r, geom, igeom, head, col_top, nxt, hkeys, hval,
                 r_max_sed, lateral_walls, buf):
    """Largest overlap of the moving spheres with the sediment, the floor and walls;
    returns it and the (possibly grown) query buffer."""
    worst = -np.inf
    for i in range(n):
        reach = rad[i] + r_max_sed
        while True:
            cnt = grid_collect(geom, igeom, head, col_top, nxt, hkeys, hval,
                               pos[i, 0] - reach, pos[i, 0] + reach, pos[i, 1] - reach,
                               pos[i, 1] + reach, pos[i, 2] - reach, pos[i, 2] + reach, buf)
            if cnt >= 0:
                break
            buf = np.empty(2 * buf.shape[0], dtype=np.int64)
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
        if lateral_walls:
            for k in range(2):
                ov = geom[k] + rad[i] - pos[i, k]
                if ov > worst:
                    worst = ov
                ov = pos[i, k] + rad[i] - geom[k] - geom[2 + k]
                if ov > worst:
                    worst = ov
    return worst, buf


@jit
def _keep_touching(n_c, con_i, con_ob, con_j, con_sh, n_dr, dr_i, dr_ob, dr_j, dr_sh,
                   pos, rad, sed, sed_r, geom, ell, nrm):
    """Contacts released by the last decision that still touch (a move of zero or
    round-off length) stay contacts, so that the next decision sees every obstacle
    touching the particle (4.3) and a zero-length move cannot cycle through them."""
    for r in range(n_dr):
        if n_c >= MAX_CONTACTS:
            break
        if _find(n_c, con_i, con_ob, con_j, dr_i[r], dr_ob[r], dr_j[r]) >= 0:
            continue
        i = dr_i[r]
        if dr_ob[r] == OB_SPHERE:
            j = dr_j[r]
            g = math.sqrt((pos[i, 0] - sed[j, 0] - dr_sh[r, 0]) ** 2
                          + (pos[i, 1] - sed[j, 1] - dr_sh[r, 1]) ** 2
                          + (pos[i, 2] - sed[j, 2]) ** 2) - rad[i] - sed_r[j]
        else:
            c0 = _plane_of(dr_ob[r], rad[i], geom, nrm)
            g = nrm[0] * pos[i, 0] + nrm[1] * pos[i, 1] + nrm[2] * pos[i, 2] - c0
        if g <= TOUCH_TOL * ell:
            con_i[n_c] = i
            con_ob[n_c] = dr_ob[r]
            con_j[n_c] = dr_j[r]
            con_sh[n_c, 0] = dr_sh[r, 0]
            con_sh[n_c, 1] = dr_sh[r, 1]
            con_sh[n_c, 2] = 0.0
            n_c += 1
    return n_c


@jit
def _near_contacts(n, pos, rad, n_c, con_i, con_ob, con_j, con_sh, sed, sed_r, geom, igeom,
                   head, col_top, nxt, hkeys, hval, r_max_sed, walls, floor_too, ell, buf, nrm):
    """Declare closed every obstacle within ``CYCLE_CLOSE_GAP * ell`` of the particle that
    is not a contact yet (4.2).  Returns ``(n_c, added, floor_added, buf)``."""
    added = 0
    floor_added = False
    lim = CYCLE_CLOSE_GAP * ell
    for i in range(n):
        if n_c >= MAX_CONTACTS:
            break
        reach = rad[i] + r_max_sed + lim
        while True:
            cnt = grid_collect(geom, igeom, head, col_top, nxt, hkeys, hval,
                               pos[i, 0] - reach, pos[i, 0] + reach, pos[i, 1] - reach,
                               pos[i, 1] + reach, pos[i, 2] - reach, pos[i, 2] + reach, buf)
            if cnt >= 0:
                break
            buf = np.empty(2 * buf.shape[0], dtype=np.int64)
        for q in range(cnt):
            j = buf[q]
            rx = sed[j, 0] - pos[i, 0]
            ry = sed[j, 1] - pos[i, 1]
            mx, my = min_image(geom, igeom, rx, ry)
            dz = sed[j, 2] - pos[i, 2]
            g = math.sqrt(mx * mx + my * my + dz * dz) - rad[i] - sed_r[j]
            if g > lim:
                continue
            if _find(n_c, con_i, con_ob, con_j, i, OB_SPHERE, j) >= 0:
                continue
            if n_c >= MAX_CONTACTS:
                break
            con_i[n_c] = i
            con_ob[n_c] = OB_SPHERE
            con_j[n_c] = j
            con_sh[n_c, 0] = mx - rx
            con_sh[n_c, 1] = my - ry
            con_sh[n_c, 2] = 0.0
            n_c += 1
            added += 1
        last = OB_WALL_YHI if walls else OB_FLOOR
        for ob in range(OB_FLOOR, last + 1):
            if ob == OB_FLOOR and not floor_too:
                continue
            c0 = _plane_of(ob, rad[i], geom, nrm)
            g = nrm[0] * pos[i, 0] + nrm[1] * pos[i, 1] + nrm[2] * pos[i, 2] - c0
            if g > lim or n_c >= MAX_CONTACTS:
                continue
            if _find(n_c, con_i, con_ob, con_j, i, ob, -1) >= 0:
                continue
            con_i[n_c] = i
            con_ob[n_c] = ob
            con_j[n_c] = -1
            con_sh[n_c, 0] = 0.0
            con_sh[n_c, 1] = 0.0
            con_sh[n_c, 2] = 0.0
            n_c += 1
            added += 1
            if ob == OB_FLOOR:
                floor_added = True
    return n_c, added, floor_added, buf


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
    # contacts
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
    # pivots / released contacts of the present rotation
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
    # potential events (ties)
    t_phi = np.empty(MAX_TIES)
    t_c = np.empty(MAX_TIES)
    t_s = np.empty(MAX_TIES)
    t_ev = np.empty(MAX_TIES, dtype=np.int64)
    t_i = np.empty(MAX_TIES, dtype=np.int64)
    t_ob = np.empty(MAX_TIES, dtype=np.int64)
    t_j = np.empty(MAX_TIES, dtype=np.int64)
    t_sh = np.zeros((MAX_TIES, 2))
    # cycling (4.2)
    HIST = 32
    dz_hist = np.empty(HIST)
    CREEP = 24
    dz_all = np.zeros(CREEP)
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
        # start above the top of the sediment
        below = 0.0
        for i in range(n):
            zi = rot[2, 0] * body[i, 0] + rot[2, 1] * body[i, 1] + rot[2, 2] * body[i, 2]
            below = max(below, rad[i] - zi)
        com[0] = particle_drop_xy[p, 0]
        com[1] = particle_drop_xy[p, 1]
        com[2] = top_z + below + DROP_MARGIN * ell
        _positions(n, body, rot, com, pos)
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
            _fill_contacts(n_c, con_i, con_ob, con_j, con_sh, pos, rad, sed, sed_r, geom,
                           ca, cP, cN, cD, cc0, ckind, nrm)
            motion, mk, mm, slope = decide(com, n_c, ca, cP, cN, ckind, cD, cc0, ell, wk)
            n_c_before = n_c
            if motion == MOTION_REST and not rest_checked:
                # 4.2 at rest: obstacles left within CYCLE_CLOSE_GAP (by a cycle that
                # converged, or a round-off gap) are declared closed, and the steepest
                # descent is decided again with them
                rest_checked = True
                n_c, added, floor_added, buf = _near_contacts(
                    n, pos, rad, n_c, con_i, con_ob, con_j, con_sh, sed, sed_r, geom, igeom,
                    head, col_top, nxt, hkeys, hval, r_max_sed, walls, True, ell, buf, nrm)
                if added > 0:
                    ev_row[K_CYCLING] += 1
                    if floor_added and floor_mode == FLOOR_STOP:
                        state = RESTING_ON_FLOOR
                        break
                    continue
            if motion == MOTION_REST:
                has_floor = False
                for l in range(n_c):
                    if con_ob[l] == OB_FLOOR:
                        has_floor = True
                if n_c >= 3:
                    state = RESTING_THREE_CONTACTS
                elif has_floor:
                    state = RESTING_ON_FLOOR
                elif n_c == 2:
                    state = HANGING_TWO
                else:
                    state = HANGING_ONE
                break
            z_before = com[2]
            rest_checked = False
            if motion == MOTION_FALL:
                # ---------------------------------------------------------- fall (3.1)
                n_dr = n_c
                for l in range(n_c):
                    dr_i[l] = con_i[l]
                    dr_ob[l] = con_ob[l]
                    dr_j[l] = con_j[l]
                    for k in range(3):
                        dr_sh[l, k] = con_sh[l, k]
                n_c = 0
                tolz = SIMULTANEOUS_TOL * ell
                best = np.inf
                for i in range(n):
                    best = min(best, pos[i, 2] - rad[i])
                n_t = 0
                for i in range(n):
                    d = pos[i, 2] - rad[i]
                    n_t, best = _push(n_t, best, tolz, d, 1.0, 0.0, EV_CONTACT, i, OB_FLOOR, -1,
                                      0.0, 0.0, t_phi, t_c, t_s, t_ev, t_i, t_ob, t_j, t_sh)
                for i in range(n):
                    reach = rad[i] + r_max_sed
                    xi = pos[i, 0]
                    yi = pos[i, 1]
                    zi = pos[i, 2]
                    ix0 = int(math.floor((xi - reach - geom[0]) / geom[4]))
                    ix1 = int(math.floor((xi + reach - geom[0]) / geom[4]))
                    iy0 = int(math.floor((yi - reach - geom[1]) / geom[5]))
                    iy1 = int(math.floor((yi + reach - geom[1]) / geom[5]))
                    if lateral == LATERAL_PERIODIC:
                        if ix1 - ix0 + 1 >= igeom[1]:
                            ix0 = 0
                            ix1 = igeom[1] - 1
                        if iy1 - iy0 + 1 >= igeom[2]:
                            iy0 = 0
                            iy1 = igeom[2] - 1
                    izi = int(math.floor(zi / cell))
                    # pass 0 scans the top two layers of every column (the height map), so
                    # that pass 1, which goes down until a layer lies below the best drop,
                    # starts with a drop bounded by the local surface
                    for pas in range(2):
                        for iy in range(iy0, iy1 + 1):
                            dcx, dcy = min_image(geom, igeom, 0.0,
                                                 yi - geom[1] - (iy + 0.5) * geom[5])
                            ddy = max(abs(dcy) - 0.5 * geom[5], 0.0)
                            if ddy >= reach:
                                continue
                            for ix in range(ix0, ix1 + 1):
                                dcx, dcy = min_image(geom, igeom,
                                                     xi - geom[0] - (ix + 0.5) * geom[4], 0.0)
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
                                        dz = fall_drop(xi, yi, zi, rad[i], xi + mx, yi + my, sed[j, 2],
                                                       sed_r[j])
                                        if dz < np.inf and dz >= -TOUCH_TOL * ell:
                                            if dz < 0.0:
                                                dz = 0.0
                                            n_t, best = _push(n_t, best, tolz, dz, 1.0, 0.0, EV_CONTACT,
                                                              i, OB_SPHERE, j, mx - rx, my - ry,
                                                              t_phi, t_c, t_s, t_ev, t_i, t_ob, t_j,
                                                              t_sh)
                                        j = nxt[j]
                                    iz -= 1
                com[2] -= best
                for i in range(n):
                    pos[i, 2] -= best
                floor_hit = False
                n_new = 0
                for r in range(n_t):
                    if t_phi[r] > best + tolz:
                        continue
                    if n_c < MAX_CONTACTS:
                        con_i[n_c] = t_i[r]
                        con_ob[n_c] = t_ob[r]
                        con_j[n_c] = t_j[r]
                        con_sh[n_c, 0] = t_sh[r, 0]
                        con_sh[n_c, 1] = t_sh[r, 1]
                        con_sh[n_c, 2] = 0.0
                        n_c += 1
                    n_new += 1
                    if t_ob[r] == OB_FLOOR:
                        floor_hit = True
                        ev_row[K_FLOOR_CONTACT] += 1
                    else:
                        ev_row[K_FALL_CONTACT] += 1
                if n_new > 1:
                    ev_row[K_SIMULTANEOUS] += n_new - 1
                n_c = _keep_touching(n_c, con_i, con_ob, con_j, con_sh, n_dr, dr_i, dr_ob, dr_j,
                                     dr_sh, pos, rad, sed, sed_r, geom, ell, nrm)
                if debug:
                    ov, buf = _max_overlap(n, pos, rad, sed, sed_r, geom, igeom, head, col_top, nxt,
                                      hkeys, hval, r_max_sed, walls, buf)
                    max_ov = max(max_ov, ov)
                if floor_hit and floor_mode == FLOOR_STOP:
                    state = RESTING_ON_FLOOR
            else:
                # ------------------------------------------------------ rotation (3.2, 3.3)
                for k in range(3):
                    axis[k] = wk[k]
                    piv[k] = wk[3 + k]
                # pivots and released contacts
                npv = 1 if motion == MOTION_SINGLE else 2
                pv_i[0] = con_i[mk]
                pv_ob[0] = con_ob[mk]
                pv_j[0] = con_j[mk]
                for k in range(3):
                    pv_sh[0, k] = con_sh[mk, k]
                if npv == 2:
                    pv_i[1] = con_i[mm]
                    pv_ob[1] = con_ob[mm]
                    pv_j[1] = con_j[mm]
                    for k in range(3):
                        pv_sh[1, k] = con_sh[mm, k]
                n_dr = 0
                for l in range(n_c):
                    if l == mk or l == mm:
                        continue
                    dr_i[n_dr] = con_i[l]
                    dr_ob[n_dr] = con_ob[l]
                    dr_j[n_dr] = con_j[l]
                    for k in range(3):
                        dr_sh[n_dr, k] = con_sh[l, k]
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
                    phi_lim = phi_hang
                    n_t, best = _push(n_t, best, tol_phi, phi_hang, c_hang, s_hang, EV_HANG, -1, -1,
                                      -1, 0.0, 0.0, t_phi, t_c, t_s, t_ev, t_i, t_ob, t_j, t_sh)
                else:
                    n_t, best = _push(n_t, best, tol_phi, phi_lim, math.cos(phi_lim),
                                      math.sin(phi_lim), EV_CHUNK, -1, -1, -1, 0.0, 0.0,
                                      t_phi, t_c, t_s, t_ev, t_i, t_ob, t_j, t_sh)
                pivl0 = mk
                pivl1 = mm
                # loss of contact (eq. 17 / 3.3.4)
                for t in range(npv):
                    l = pivl0 if t == 0 else pivl1
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
                        o = pivl1 if t == 0 else pivl0
                        if ckind[o] == OB_SPHERE:
                            rotate_point(ca[o], piv, axis, cc, ss, tmp)
                            nz = tmp[2] - cP[o, 2]
                            dn = math.sqrt((tmp[0] - cP[o, 0]) ** 2 + (tmp[1] - cP[o, 1]) ** 2 + nz * nz)
                            if nz > NZ_TOL * dn:
                                continue
                        elif cN[o, 2] > NZ_TOL:
                            continue
                    n_t, best = _push(n_t, best, tol_phi, phi, cc, ss, EV_LOSS, l, -1, -1, 0.0, 0.0,
                                      t_phi, t_c, t_s, t_ev, t_i, t_ob, t_j, t_sh)
                # release of one of two pivots (eqs. 25-31)
                if npv == 2:
                    for t in range(2):
                        x = pivl0 if t == 0 else pivl1
                        y = pivl1 if t == 0 else pivl0
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
                                n_t, best = _push(n_t, best, tol_phi, virt,
                                                  math.cos(virt), math.sin(virt),
                                                  EV_VIRTUAL, -1, -1, -1, 0.0, 0.0,
                                                  t_phi, t_c, t_s, t_ev, t_i, t_ob, t_j, t_sh)
                                continue
                        elif gap < 0.0:
                            continue
                        phi, cc, ss = first_entry(A, B, K, gap, 1.0 / rho, ell, POLICY_TRUSTED)
                        if phi <= best + tol_phi:
                            n_t, best = _push(n_t, best, tol_phi, phi, cc, ss, EV_RELEASE, x, -1, -1,
                                              0.0, 0.0, t_phi, t_c, t_s, t_ev, t_i, t_ob, t_j, t_sh)
                # frustrated situation (4.1): does the decision change after trial_angle?
                if trial_angle > 0.0 and trial_angle <= best + tol_phi:
                    ct = math.cos(trial_angle)
                    st = math.sin(trial_angle)
                    rotate_point(com, piv, axis, ct, st, tcom)
                    for t in range(npv):
                        l = pivl0 if t == 0 else pivl1
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
                    m2, k2, mm2, sl2 = decide(tcom, npv, ta, tP, tN, tkind, tD, tc0, ell, wk2)
                    same = m2 == motion and k2 == 0 and (npv == 1 or mm2 == 1)
                    if not same:
                        n_t, best = _push(n_t, best, tol_phi, trial_angle, ct, st, EV_TRIAL, -1, -1,
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
                    xlo, xhi = _arc_range(rho, e1[0], e2[0], lim)
                    ylo, yhi = _arc_range(rho, e1[1], e2[1], lim)
                    zlo, zhi = _arc_range(rho, e1[2], e2[2], lim)
                    ri = rad[i]
                    # floor
                    if o2 + zlo - ri <= TOUCH_TOL * ell:
                        pl = _find(npv, pv_i, pv_ob, pv_j, i, OB_FLOOR, -1)
                        if pl < 0:
                            pol = POLICY_TRUSTED if _find(n_dr, dr_i, dr_ob, dr_j, i, OB_FLOOR, -1) >= 0 else POLICY_NEW
                            A = -e1[2]
                            B = -e2[2]
                            gap = pos[i, 2] - ri
                            phi, cc, ss = first_entry(A, B, A + gap / rho, gap, 1.0 / rho, ell, pol)
                            if phi <= best + tol_phi:
                                n_t, best = _push(n_t, best, tol_phi, phi, cc, ss, EV_CONTACT, i,
                                                  OB_FLOOR, -1, 0.0, 0.0, t_phi, t_c, t_s, t_ev, t_i,
                                                  t_ob, t_j, t_sh)
                    if walls:
                        for wdir in range(4):
                            ob = OB_WALL_XLO + wdir
                            c0 = _plane_of(ob, ri, geom, nrm)
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
                            if _find(npv, pv_i, pv_ob, pv_j, i, ob, -1) >= 0:
                                continue
                            pol = POLICY_TRUSTED if _find(n_dr, dr_i, dr_ob, dr_j, i, ob, -1) >= 0 else POLICY_NEW
                            A = -(nrm[0] * e1[0] + nrm[1] * e1[1])
                            B = -(nrm[0] * e2[0] + nrm[1] * e2[1])
                            gap = nrm[0] * pos[i, 0] + nrm[1] * pos[i, 1] - c0
                            phi, cc, ss = first_entry(A, B, A + gap / rho, gap, 1.0 / rho, ell, pol)
                            if phi <= best + tol_phi:
                                n_t, best = _push(n_t, best, tol_phi, phi, cc, ss, EV_CONTACT, i, ob,
                                                  -1, 0.0, 0.0, t_phi, t_c, t_s, t_ev, t_i, t_ob,
                                                  t_j, t_sh)
                    # sediment spheres
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
                            if _find(npv, pv_i, pv_ob, pv_j, i, OB_SPHERE, j) >= 0:
                                continue
                            if _find(n_dr, dr_i, dr_ob, dr_j, i, OB_SPHERE, j) >= 0:
                                pol = POLICY_TRUSTED
                        phi, cc, ss = first_entry(A, B, K, gap, dist / rho, ell, pol)
                        if phi <= best + tol_phi:
                            n_t, best = _push(n_t, best, tol_phi, phi, cc, ss, EV_CONTACT, i,
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
                    con_i[t] = pv_i[t]
                    con_ob[t] = pv_ob[t]
                    con_j[t] = pv_j[t]
                    for k in range(3):
                        con_sh[t, k] = pv_sh[t, k]
                n_exec = 0
                floor_hit = False
                for r in range(n_t):
                    if t_phi[r] > best + tol_phi:
                        continue
                    ev = t_ev[r]
                    if ev == EV_CHUNK:
                        n_chunks += 1
                        continue
                    n_exec += 1
                    if ev == EV_CONTACT:
                        if _find(n_c, con_i, con_ob, con_j, t_i[r], t_ob[r], t_j[r]) < 0 and n_c < MAX_CONTACTS:
                            con_i[n_c] = t_i[r]
                            con_ob[n_c] = t_ob[r]
                            con_j[n_c] = t_j[r]
                            con_sh[n_c, 0] = t_sh[r, 0]
                            con_sh[n_c, 1] = t_sh[r, 1]
                            con_sh[n_c, 2] = 0.0
                            n_c += 1
                        if t_ob[r] == OB_SPHERE:
                            if npv == 1:
                                ev_row[K_SECOND_CONTACT] += 1
                            else:
                                ev_row[K_THIRD_CONTACT] += 1
                        elif t_ob[r] == OB_FLOOR:
                            ev_row[K_FLOOR_CONTACT] += 1
                            floor_hit = True
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
                if n_exec > 1:
                    ev_row[K_SIMULTANEOUS] += n_exec - 1
                n_c = _keep_touching(n_c, con_i, con_ob, con_j, con_sh, n_dr, dr_i, dr_ob, dr_j,
                                     dr_sh, pos, rad, sed, sed_r, geom, ell, nrm)
                if debug:
                    ov, buf = _max_overlap(n, pos, rad, sed, sed_r, geom, igeom, head, col_top, nxt,
                                      hkeys, hval, r_max_sed, walls, buf)
                    max_ov = max(max_ov, ov)
                if floor_hit and floor_mode == FLOOR_STOP:
                    state = RESTING_ON_FLOOR
            if p == trace_particle and ev_count - 1 < trace.shape[0]:
                tr = trace[ev_count - 1]
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
            if state == RESTING_ON_FLOOR:
                break  # FLOOR_STOP: immobilised at its first floor contact
            # ---------------------------------------------------------- cycling (4.2)
            dzc = z_before - com[2]
            if dzc > 0.0:
                dz_hist[n_hist % HIST] = dzc
                n_hist += 1
                cyc = False
                # criterion (34) for the paper's period 3, and for periods 2 and 4
                for per in (3, 2, 4):
                    need = cycle_n + per + 1
                    if cyc or cycle_n <= 0 or n_hist < need or need > HIST:
                        continue
                    ok = True
                    last = n_hist - 1
                    if dz_hist[last % HIST] >= dz_hist[(last - per) % HIST]:
                        ok = False  # not decaying
                    for jj in range(cycle_n):
                        if not ok:
                            break
                        kk = last - jj
                        num = dz_hist[kk % HIST] * dz_hist[(kk - per - 1) % HIST]
                        den = dz_hist[(kk - 1) % HIST] * dz_hist[(kk - per) % HIST]
                        if not (den > 0.0) or abs(num / den - 1.0) >= cycle_eps:
                            ok = False
                    cyc = ok
                if cyc:
                    # declare the contacts of the cycle closed: every obstacle within
                    # CYCLE_CLOSE_GAP of the particle
                    n_c, added, floor_added, buf = _near_contacts(
                        n, pos, rad, n_c, con_i, con_ob, con_j, con_sh, sed, sed_r, geom, igeom,
                        head, col_top, nxt, hkeys, hval, r_max_sed, walls, True, ell, buf, nrm)
                    if added > 0:
                        ev_row[K_CYCLING] += 1
                        n_hist = 0
                        n_all = 0
                        if floor_added and floor_mode == FLOOR_STOP:
                            state = RESTING_ON_FLOOR
                            break
            # creeping (4.2 without a period): the centre of mass went down by less than
            # CYCLE_CLOSE_GAP in the last CREEP steps, so the particle zigzags among
            # obstacles at clearances of the order of the tolerances: declare them closed
            dz_all[n_all % CREEP] = max(dzc, 0.0)
            n_all += 1
            if n_all >= CREEP:
                tot = 0.0
                for r in range(CREEP):
                    tot += dz_all[r]
                if tot < CYCLE_CLOSE_GAP * ell:
                    n_c, added, floor_added, buf = _near_contacts(
                        n, pos, rad, n_c, con_i, con_ob, con_j, con_sh, sed, sed_r, geom, igeom,
                        head, col_top, nxt, hkeys, hval, r_max_sed, walls, True, ell, buf, nrm)
                    n_all = 0
                    if added > 0:
                        ev_row[K_CYCLING] += 1
                        n_hist = 0
                        if floor_added and floor_mode == FLOOR_STOP:
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
            ov, buf = _max_overlap(n, pos, rad, sed, sed_r, geom, igeom, head, col_top, nxt,
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
