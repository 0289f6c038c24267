"""The deposition loop: drop every particle in turn, let it descend, freeze it where it rests.

For each particle in order (Fig. 3 of the paper) :func:`run_deposition` drops it above the
sediment and :func:`_descend` repeats *decide, move* until it rests:

1. **decide**: the geometry of the present contacts goes to :func:`.decision.decide`, which
   chooses the steepest valid motion: fall, rotation on one contact, rotation on two, or
   rest;
2. **move**: :func:`.fall.fall` (3.1), :func:`.rolling.roll` (3.2, 3.3, with the trial
   rotation of 4.1 in :mod:`.frustration`) or, on frictionless inclined faces of a mesh vessel,
   :func:`.slide.slide`, each up to its earliest event, executing the events simultaneous with
   it (4.3);
3. **contacts after a move**: the contacts are the pivots and the contacts the events made;
   contacts released by the decision that still touch (gap ``<= TOUCH_TOL``, a move of zero
   or round-off length) stay (:func:`.contacts.keep_touching`), so that a decision always
   sees every obstacle touching the particle (4.3) and zero-length moves cannot cycle
   through them;
4. **cycling** (4.2, :func:`.cycling.after_move`): criterion (34) on the decrements of the
   height of the centre of mass (period 3 as in the paper, and periods 2 and 4), and a
   backstop when the centre of mass went down by less than ``CREEP_DESCENT`` in the last
   24 steps; either declares every obstacle within ``CYCLE_CLOSE_GAP`` a closed contact.
   The same remedy is applied once when the decision finds rest (obstacles left within
   ``CYCLE_CLOSE_GAP`` are then contacts, and the decision is taken again with them).

A particle that needs more than ``max_events`` decide-and-move steps stops the run
(``EVENT_LIMIT``): nothing is frozen or re-dropped silently.

Boundary modelling choices (not in the paper):

* a frictionless wall (``WALL_FRICTIONLESS``, the default) is a sphere of infinite radius
  centred at infinity behind it: it never holds a particle up by itself (rolling on it alone
  is the fall), and with one other pivot the particle rotates about the axis through that
  pivot along the wall's normal, its touching sphere sliding along the wall
  (:mod:`.decision`, :func:`.events.sliding_wall_release_plane`);
* a glued wall (``WALL_GLUED``) and, under FLOOR_ROLL, the floor pivot about the centre of
  the moving sphere that touches the plane: the plane holds that sphere (no sliding), the
  sphere stays tangent to the plane, and its contact opens when the particle rolls away;
* under FLOOR_STOP (the paper) the first floor contact immobilises the particle;
* a contact with a plane whose normal is horizontal (a wall) never blocks falling;
* a cylindrical container is the polygon of planar walls inscribed in it (:mod:`.polygon`),
  each side a wall as above;
* a substrate is a set of sediment spheres laid before the first particle (never moving).

The state the loop hands around is a set of named bundles (:mod:`.bundles`): the
:class:`~.bundles.Particle`, its contact lists and their geometry, the window of candidate
events, the sediment and its grid, and the run's settings.
"""

import math
import time
from typing import NamedTuple

import numpy as np
from numba import types

from parsim.core.growth import with_rows
from parsim.core.jit import jit
from parsim.core.sdbd import counters, reads
from parsim.core.sdbd.bundles import grid_arrays
from parsim.core.sdbd.borrowed import borrowed
from parsim.core.sdbd.bundles import (Record, Settings, new_grid, new_particle, new_workspace, sediment_in,
                                      set_grid_arrays)
from parsim.core.sdbd.constants import (
    CYCLE_CLOSE_GAP,
    EVENT_LIMIT,
    FLOOR_STOP,
    GEOM_CELL,
    GEOM_LENGTH_X,
    GEOM_LENGTH_Y,
    GEOM_LOWER_X,
    GEOM_LOWER_Y,
    HANGING_ONE,
    HANGING_TWO,
    IGEOM_MODE,
    IGEOM_SIDES,
    K_SIMULTANEOUS,
    LATERAL_PERIODIC,
    LATERAL_WALLS,
    MOTION_FALL,
    MOTION_REST,
    MOTION_SLIDE,
    OB_FLOOR,
    OB_SPHERE,
    RESTING_ON_FLOOR,
    RESTING_THREE_CONTACTS,
    VIRTUAL_ANGLE,
    WALL_FRICTIONLESS,
)
from parsim.core.sdbd.contacts import fill_contacts, keep_touching
from parsim.core.sdbd.cycling import after_move, close_near_obstacles, forget_descents, new_descent_history
from parsim.core.sdbd.decision import decide
from parsim.core.sdbd.fall import fall
from parsim.core.sdbd.grid import empty_grid, grid_insert, grid_insert_ordered, wrap_position
from parsim.core.sdbd.overlap import max_overlap
from parsim.core.sdbd.particle import drop_particle, place_spheres
from parsim.core.sdbd.polygon import GEOM_CONTAINER
from parsim.core.sdbd.rolling import roll
from parsim.core.sdbd.rotation import matrix_to_quat
from parsim.core.sdbd.slide import slide

__all__ = ["run_deposition"]

_NO_KEYS = np.zeros(0, dtype=np.int64)  # the serial run inserts every sphere as the newest of its cell

# diag slots
D_MAX_OVERLAP = 0      # largest overlap seen after a move (debug), units of length
D_EVENTS = 1           # decide/move steps, all particles
D_CHUNKS = 2           # chunk ends (bookkeeping steps)
D_CLOCKED_SECONDS = 3  # wall-clock seconds from the start of particle clock_from to the end
D_SETTLED = 4          # particles settled so far, written as the run goes (read by a progress thread)
N_DIAGNOSTICS = 5


class Drops(NamedTuple):
    """The particles of a run in drop order, as :func:`run_deposition` takes them: the shapes' sphere
    ``shape_offsets`` (S, 3) and ``shape_radii`` (S,), shape ``k``'s spheres from ``shape_start[k]`` to
    ``shape_start[k + 1]``; each particle's shape, size factor, orientation quaternion and drop point."""

    shape_offsets: np.ndarray
    shape_radii: np.ndarray
    shape_start: np.ndarray
    particle_shape: np.ndarray
    particle_scale: np.ndarray
    particle_rotation: np.ndarray
    particle_drop_xy: np.ndarray


class Spheres(NamedTuple):
    """Sphere ``centre`` (m, 3) and ``radius`` (m,) arrays."""

    centre: np.ndarray
    radius: np.ndarray


class RunOptions(NamedTuple):
    """The run's settings: floor and wall-contact modes, the trial angle (4.1), cycle detection (4.2), the
    step limit per particle and the length scale ``ell`` of the tolerances."""

    floor_mode: int
    wall_contact: int
    trial_angle: float
    cycle_n: int
    cycle_eps: float
    max_events: int
    ell: float


class Diagnosis(NamedTuple):
    """What a run checks and records for tests: overlaps after every move (``debug``), the steps of
    ``trace_particle`` in ``trace`` (T, 16), the clock from particle ``clock_from`` on."""

    debug: bool
    trace_particle: int
    trace: np.ndarray
    clock_from: int


class Outputs(NamedTuple):
    """The run's preallocated outputs: each sphere's particle; each particle's centre of mass, rotation,
    contacts, state, event counts and steps; ``diag`` (N_DIAGNOSTICS,), the counters' ``tallies`` and the
    rectangles each descent read (``reads``, P x 4, or no rows)."""

    particle: np.ndarray
    com: np.ndarray
    rotation: np.ndarray
    contacts: np.ndarray
    state: np.ndarray
    events: np.ndarray
    steps: np.ndarray
    diag: np.ndarray
    tallies: np.ndarray
    reads: np.ndarray


@jit
def run_deposition(drops, substrate, grid_state, options, diagnosis, sediment_spheres, outputs):
    """Deposit all particles of ``drops`` (:class:`Drops`); returns ``(stopped_at, n_spheres_written)``.

    Inputs are validated by :func:`parsim.core.sdbd.deposit`.  The ``m`` spheres of the
    ``substrate`` (:class:`Spheres`: ``substrate_centre`` (m, 3), ``substrate_radius`` (m,)) are
    sediment spheres ``0 .. m - 1`` before the first particle; the particles' spheres follow them.
    ``grid_state``, the arrays ``geom, igeom, head, ...``, is an empty grid from :func:`grid.grid_new` (for
    ``len(sediment_radius)`` spheres) whose cell is at least the first particle's and the
    substrate's largest sphere diameter; it grows with the largest sphere so far
    (:func:`_fit_grid`), so that nothing of a particle's descent depends on the particles
    after it.  ``sediment_spheres`` (``sediment_centre`` (m + n, 3), ``sediment_radius`` (m + n,)) hold the
    sediment during the run and its spheres at the end: rows ``m`` on are the particles'
    spheres in the lab frame (a periodic box holds each centre of mass wrapped into it and the
    spheres about it, a sphere beyond the box included), so that the sediment is not kept
    twice.  ``outputs`` (:class:`Outputs`: ``out_*``, ``diag``, ``tallies``, ``reads_out``) are
    preallocated for all particles (``out_*`` a :class:`.bundles.Record`); ``options`` is a
    :class:`RunOptions`, ``diagnosis`` a :class:`Diagnosis`;
    ``diag`` (N_DIAGNOSTICS,) receives diagnostics
    (largest overlap after a move when ``debug``, number of steps, number of chunk steps), and
    ``diag[D_SETTLED]`` the particles settled so far, as the run goes.
    The steps of particle ``trace_particle`` (``-1``: none) are recorded in the rows of
    ``trace`` (T, 16): motion, number of contacts before the step, pivot contacts k and m,
    first executed event kind, angle or drop, number of executed events, centre of mass
    after the step, number of contacts after the step, and the obstacle index of up to 5
    contacts.  ``diag[D_CLOCKED_SECONDS]`` receives the wall-clock time spent on particles
    ``clock_from`` onwards (untouched when ``clock_from`` is not a particle index).
    ``tallies`` receives the counters of :mod:`.counters` (an empty array: none are kept),
    ``reads_out`` (P, 4) the rectangle each particle's descent read (:mod:`.reads`; no rows: none
    is recorded).
    """
    (shape_offsets, shape_radii, shape_start, particle_shape, particle_scale, particle_rotation,
     particle_drop_xy) = drops
    substrate_centre, substrate_radius = substrate
    geom, igeom, head, col_top, nxt, hkeys, hval, counts = grid_state
    ell = options.ell
    debug, trace_particle, trace, clock_from = diagnosis
    sediment_centre, sediment_radius = sediment_spheres
    out_particle, out_com, out_rot, out_contacts, out_state, out_events, out_steps, diag, tallies, reads_out = outputs
    n_part = particle_shape.shape[0]
    n_sub = substrate_radius.shape[0]
    settings = _settings(options, igeom, debug)
    grid = new_grid(geom, igeom, head, col_top, nxt, hkeys, hval, counts)
    # the caller keeps the outputs alive: the record borrows them
    record = Record(borrowed(out_particle), borrowed(out_com), borrowed(out_rot), borrowed(out_contacts),
                    borrowed(out_state), borrowed(out_events), borrowed(out_steps))
    sediment = sediment_in(sediment_centre, sediment_radius)
    # the spheres whose centre the periodic box wraps: sediment index and centre unwrapped
    beyond_index = np.empty(16, dtype=np.int64)
    beyond_centre = np.empty((16, 3))
    n_beyond = np.int64(0)
    particle = new_particle(_most_spheres(shape_start))
    work = new_workspace(tallies, np.empty(reads.N_READS if reads_out.shape[0] else 0))
    run_started = counters.start(tallies)
    history = new_descent_history()
    buf = np.empty(4096, dtype=np.int64)
    n_sed = _lay_substrate(substrate_centre, substrate_radius, sediment, grid)
    worst_overlap = -np.inf
    n_steps = 0
    n_chunk_ends = 0
    stopped_at = -1
    clock_start = 0.0
    particles = (shape_offsets, shape_radii, shape_start, particle_shape, particle_scale, particle_rotation,
                 particle_drop_xy)
    for p in range(n_part):
        if p == clock_from:
            clock_start = _wall_clock()
        started = counters.start(tallies)
        reads.forget(work.reads)
        n, _ = drop_particle(p, particles, sediment, grid, ell, particle, work.reads, math.nan)
        _fit_grid(n, particle, sediment, n_sed, grid)
        counters.stop(tallies, counters.PARTICLE, started)
        state, n_c, steps, chunk_ends, overlap, buf = _descend(
            n, particle, work, history, sediment, grid, settings, out_events[p],
            p == trace_particle, trace, buf)
        n_steps += steps
        out_steps[p] = steps
        reads.note_spheres(work.reads, n, particle, _search_margin(grid, ell))
        if reads_out.shape[0] != 0:
            for k in range(reads.N_READS):
                reads_out[p, k] = work.reads[k]
        n_chunk_ends += chunk_ends
        worst_overlap = max(worst_overlap, overlap)
        if state == EVENT_LIMIT:
            out_state[p] = EVENT_LIMIT
            stopped_at = p
            break
        if igeom[IGEOM_MODE] == LATERAL_PERIODIC:
            _wrap_into_box(n, particle, grid)
        if debug:
            overlap, buf = max_overlap(n, particle, sediment, grid, settings.walls, buf)
            worst_overlap = max(worst_overlap, overlap)
        started = counters.start(tallies)
        n_sed = _freeze(p, n, particle, n_c, state, sediment, grid, n_sed, n_sub, record)
        n_beyond, beyond_index, beyond_centre = _note_wrapped(n, particle, sediment, n_sed, n_beyond,
                                                              beyond_index, beyond_centre)
        counters.stop(tallies, counters.PARTICLE, started)
        diag[D_SETTLED] = p + 1
    counters.stop(tallies, counters.TOTAL, run_started)
    for b in range(n_beyond):  # the sediment is done: its spheres as the particles hold them
        for k in range(3):
            sediment_centre[beyond_index[b], k] = beyond_centre[b, k]
    diag[D_MAX_OVERLAP] = worst_overlap
    diag[D_EVENTS] = n_steps
    diag[D_CHUNKS] = n_chunk_ends
    if 0 <= clock_from < n_part:
        diag[D_CLOCKED_SECONDS] = _wall_clock() - clock_start
    return stopped_at, n_sed - n_sub


@jit
def _settings(options, igeom, debug):
    """The run's :class:`.bundles.Settings` from its :class:`RunOptions`: eq. 31's virtual small rotation
    is the trial angle of 4.1 (the paper refers to section 4.1 for it), ``VIRTUAL_ANGLE`` only when the
    trial test is disabled."""
    floor_mode, wall_contact, trial_angle, cycle_n, cycle_eps, max_events, ell = options
    virtual_angle = trial_angle if trial_angle > 0.0 else VIRTUAL_ANGLE
    return Settings(floor_mode, trial_angle, virtual_angle, cycle_n, cycle_eps, max_events, ell,
                    igeom[IGEOM_MODE] == LATERAL_WALLS, wall_contact == WALL_FRICTIONLESS, debug)


@jit
def _most_spheres(shape_start):
    """The most spheres of any shape (at least 1)."""
    n_max = 1
    for s in range(shape_start.shape[0] - 1):
        n_max = max(n_max, shape_start[s + 1] - shape_start[s])
    return n_max


@jit
def _wrap_into_box(n, particle, grid):
    """Wrap a resting particle's centre of mass into the periodic box, its ``n`` spheres about it."""
    cx, cy = wrap_position(grid.geom, grid.igeom, particle.com[0], particle.com[1])
    particle.com[0] = cx
    particle.com[1] = cy
    place_spheres(n, particle)


@jit  # not inlined: numba's inlining of this large function doubled the first compilation
def _descend(n, particle, work, history, sediment, grid, settings, event_counts, traced, trace, buf):
    """Decide and move the particle of ``n`` spheres until it rests (steps 1-4 of the module
    docs).  Returns ``(state, n_c, n_steps, n_chunk_ends, worst_overlap, buf)``: its state
    (``EVENT_LIMIT`` after ``max_events`` steps), its number of contacts, the steps taken,
    the chunk ends among them, the largest overlap after a move (``debug``, else -inf) and
    the query buffer.  When ``traced``, step s is recorded in ``trace[s]``."""
    contacts = work.contacts
    geometry = work.geometry
    released = work.released
    tallies = work.counters
    normal = work.scratch.normal
    decision = work.scratch.decision
    com = particle.com
    geom = grid.geom
    ell = settings.ell
    forget_descents(history)
    n_c = np.int64(0)  # typed, not the literal 0: numba would compile decide() for the literal too
    rest_checked = False
    n_steps = 0
    n_chunk_ends = 0
    worst_overlap = -np.inf
    while True:
        if n_steps >= settings.max_events:
            return EVENT_LIMIT, n_c, n_steps, n_chunk_ends, worst_overlap, buf
        n_steps += 1
        counters.add(tallies, counters.STEPS, 1)
        reads.note_spheres(work.reads, n, particle, _search_margin(grid, ell))
        # ------------------------------------------------------------------- decide
        started = counters.start(tallies)
        fill_contacts(n_c, contacts, particle, sediment, geom, geometry, normal)
        motion, k, m, _ = decide(com, n_c, geometry, ell, settings.sliding_walls, decision)
        counters.stop(tallies, counters.DECIDE, started)
        n_c_before = n_c
        if motion == MOTION_REST:
            if not rest_checked:
                # 4.2 at rest: obstacles left within CYCLE_CLOSE_GAP (by a cycle that
                # converged, or a round-off gap) are declared closed, and the steepest
                # descent is decided again with them
                rest_checked = True
                started = counters.start(tallies)
                n_c, closed, stop, buf = close_near_obstacles(n, particle, n_c, contacts, sediment,
                                                              grid, settings, buf, normal, event_counts)
                counters.stop(tallies, counters.AFTER_MOVE, started)
                if stop:
                    return RESTING_ON_FLOOR, n_c, n_steps, n_chunk_ends, worst_overlap, buf
                if closed:
                    continue
            return _rest_state(n_c, contacts.obstacle), n_c, n_steps, n_chunk_ends, worst_overlap, buf
        rest_checked = False
        # --------------------------------------------------------------------- move
        z_before = com[2]
        n_c, n_dr, n_executed, chunk_ends, floor_hit, n_t, phi, buf = _move(n, particle, (motion, k, m), n_c, work,
                                                                            sediment, grid, settings, event_counts,
                                                                            buf)
        n_chunk_ends += chunk_ends
        started = counters.start(tallies)
        if n_executed > 1:
            event_counts[K_SIMULTANEOUS] += n_executed - 1
        n_c = keep_touching(n_c, contacts, n_dr, released, particle, sediment, geom, ell, normal)
        counters.stop(tallies, counters.AFTER_MOVE, started)
        if settings.debug:
            overlap, buf = max_overlap(n, particle, sediment, grid, settings.walls, buf)
            worst_overlap = max(worst_overlap, overlap)
        if traced and n_steps - 1 < trace.shape[0]:
            _record_trace(trace[n_steps - 1], motion, n_c_before, k, m, work.window, phi, n_t,
                          com, n_c, contacts)
        if floor_hit and settings.floor_mode == FLOOR_STOP:
            return RESTING_ON_FLOOR, n_c, n_steps, n_chunk_ends, worst_overlap, buf
        # ------------------------------------------------------------------ cycling
        started = counters.start(tallies)
        n_c, stop, buf = after_move(z_before - com[2], history, n, particle, n_c, contacts, sediment,
                                    grid, settings, buf, normal, event_counts)
        counters.stop(tallies, counters.AFTER_MOVE, started)
        if stop:
            return RESTING_ON_FLOOR, n_c, n_steps, n_chunk_ends, worst_overlap, buf


@jit(inline="always")
def _move(n, particle, chosen, n_c, work, sediment, grid, settings, event_counts, buf):
    """Step 2 of the module docs: the motion ``chosen = (motion, k, m)`` of the decision, up to its
    earliest event, timed in the counters.  Returns ``(n_c, n_dr, n_executed, n_chunk_ends, floor_hit,
    n_t, phi, buf)`` (:func:`.rolling.roll`'s; a fall or a slide has no chunk ends)."""
    motion, k, m = chosen
    tallies = work.counters
    started = counters.start(tallies)
    if motion == MOTION_FALL:
        n_c, n_dr, n_executed, floor_hit, n_t, phi = fall(n, particle, n_c, work, sediment, grid, settings,
                                                          event_counts)
        counters.stop(tallies, counters.FALL, started)
        counters.add(tallies, counters.FALLS, 1)
        return n_c, n_dr, n_executed, 0, floor_hit, n_t, phi, buf
    if motion == MOTION_SLIDE:
        n_c, n_dr, n_executed, floor_hit, n_t, phi, buf = slide(n, particle, k, m, n_c, work, sediment, grid,
                                                               settings, event_counts, buf)
        counters.stop(tallies, counters.FALL, started)
        counters.add(tallies, counters.FALLS, 1)
        return n_c, n_dr, n_executed, 0, floor_hit, n_t, phi, buf
    n_c, n_dr, n_executed, chunk_ends, floor_hit, n_t, phi, buf = roll(
        n, particle, motion, k, m, n_c, work, sediment, grid, settings, event_counts, buf)
    counters.stop(tallies, counters.ROLL, started)
    counters.add(tallies, counters.ROLLS, 1)
    return n_c, n_dr, n_executed, chunk_ends, floor_hit, n_t, phi, buf


@jit
def _fit_grid(n, particle, sediment, n_sed, grid):
    """Make the grid's cell at least the largest sphere diameter of the particle of ``n``
    spheres: when it is larger than any before, the grid is built anew with that cell and the
    ``n_sed`` sediment spheres are inserted again in their order."""
    cell = largest_diameter(n, particle)
    if cell > grid.geom[GEOM_CELL]:
        regrid(grid, cell, sediment.centre, np.arange(n_sed))


@jit(inline="always")
def largest_diameter(n, particle):
    """The largest sphere diameter of the particle of ``n`` spheres."""
    cell = 0.0
    for i in range(n):
        cell = max(cell, 2.0 * particle.radius[i])
    return cell


@jit
def regrid(grid, cell, centre, order):
    """Build the grid anew with cell ``cell`` and insert the sediment spheres ``order`` (centres
    ``centre``) in that order, each the newest of its cell."""
    geom = grid.geom
    geom, igeom, head, col_top, nxt, hkeys, hval, counts = empty_grid(
        grid.igeom[IGEOM_MODE], geom[GEOM_LOWER_X], geom[GEOM_LOWER_Y], geom[GEOM_LENGTH_X], geom[GEOM_LENGTH_Y], cell, 1, geom[GEOM_CONTAINER:], grid.igeom[IGEOM_SIDES])
    nxt = grid.nxt
    for j in order:
        head, col_top, hkeys, hval = grid_insert((geom, igeom, head, col_top, nxt, hkeys, hval, counts), j,
                                                 (centre[j, 0], centre[j, 1], centre[j, 2]))
    set_grid_arrays(grid, geom, igeom, head, col_top, nxt, hkeys, hval, counts)


@jit(inline="always")
def _search_margin(grid, ell):
    """How far beyond a sphere's surface the fall and the closing of near obstacles search the
    grid: the largest sediment radius (half the cell) and the gap of 4.2."""
    return 0.5 * grid.geom[GEOM_CELL] + CYCLE_CLOSE_GAP * ell


@jit(inline="always")
def _rest_state(n_c, obstacles):
    """State of a particle at rest with ``n_c`` contacts on the given obstacles."""
    has_floor = False
    for l in range(n_c):
        if obstacles[l] == OB_FLOOR:
            has_floor = True
    if n_c >= 3:
        return RESTING_THREE_CONTACTS
    if has_floor:
        return RESTING_ON_FLOOR
    if n_c == 2:
        return HANGING_TWO
    return HANGING_ONE


@jit
def join_sediment(j, x, y, z, r, sediment, grid, key):
    """Sphere ``j`` (centre ``x, y, z`` wrapped into a periodic box, radius ``r``) joins the
    sediment and the grid: the newest of its cell, or with ``key`` (not empty) in the order of
    the keys (:func:`.grid.grid_insert_ordered`).  Returns its wrapped ``x, y``."""
    grid_state = grid_arrays(grid)
    geom, igeom, head, col_top, nxt, hkeys, hval, counts = grid_state
    wx, wy = wrap_position(geom, igeom, x, y)
    sediment.centre[j, 0] = wx
    sediment.centre[j, 1] = wy
    sediment.centre[j, 2] = z
    sediment.radius[j] = r
    if key.shape[0]:
        grown = grid_insert_ordered(grid_state, j, (wx, wy, z), key)
    else:
        grown = grid_insert(grid_state, j, (wx, wy, z))
    # the grid's arrays grow with the pile
    if (grown[0].ctypes.data != head.ctypes.data or grown[1].ctypes.data != col_top.ctypes.data
            or grown[2].ctypes.data != hkeys.ctypes.data or grown[3].ctypes.data != hval.ctypes.data):
        set_grid_arrays(grid, geom, igeom, grown[0], grown[1], nxt, grown[2], grown[3], counts)
    return wx, wy


@jit(inline="always")
def _lay_substrate(centre, radius, sediment, grid):
    """The substrate's spheres are the first sediment spheres; returns their number."""
    for j in range(radius.shape[0]):
        join_sediment(j, centre[j, 0], centre[j, 1], centre[j, 2], radius[j], sediment, grid, _NO_KEYS)
    return radius.shape[0]


@jit(inline="always")
def _freeze(p, n, particle, n_c, state, sediment, grid, n_sed, n_sub, record):
    """Particle ``p`` at rest joins the sediment and the grid and is written to the record
    (whose spheres are the sediment's after the ``n_sub`` of the substrate); returns the new
    number of sediment spheres."""
    pos = particle.centre
    rad = particle.radius
    for i in range(n):
        record.particle[n_sed - n_sub] = p
        join_sediment(n_sed, pos[i, 0], pos[i, 1], pos[i, 2], rad[i], sediment, grid, _NO_KEYS)
        n_sed += 1
    for k in range(3):
        record.com[p, k] = particle.com[k]
    matrix_to_quat(particle.rotation, record.rotation[p])
    record.contacts[p] = n_c
    record.state[p] = state
    return n_sed


@jit(inline="always")
def _note_wrapped(n, particle, sediment, n_sed, n_beyond, beyond_index, beyond_centre):
    """Note the spheres of the particle of ``n`` spheres just frozen (the last of the ``n_sed``
    sediment spheres) whose centre in the sediment is not bitwise the particle's (a sphere
    that the periodic box wraps); returns the new count and the arrays (grown by doubling)."""
    for i in range(n):
        j = n_sed - n + i
        moved = False
        for k in range(2):
            a = particle.centre[i, k]
            b = sediment.centre[j, k]
            moved = moved or a != b or math.copysign(1.0, a) != math.copysign(1.0, b)
        if not moved:
            continue
        if n_beyond == beyond_index.shape[0]:
            beyond_index = with_rows(beyond_index, 2 * n_beyond, n_beyond)
            beyond_centre = with_rows(beyond_centre, 2 * n_beyond, n_beyond)
        beyond_index[n_beyond] = j
        for k in range(3):
            beyond_centre[n_beyond, k] = particle.centre[i, k]
        n_beyond += 1
    return n_beyond, beyond_index, beyond_centre


@jit(inline="always")
def _record_trace(row, motion, n_c_before, k, m, window, phi, n_t, com, n_c, contacts):
    """One row of the trace of a step (see :func:`run_deposition`)."""
    row[0] = motion
    row[1] = n_c_before
    row[2] = k
    row[3] = m
    row[4] = window.kind[0] if motion != MOTION_FALL else -1
    row[5] = window.angle[0] if motion != MOTION_FALL else phi
    row[6] = n_t
    row[7] = com[0]
    row[8] = com[1]
    row[9] = com[2]
    row[10] = n_c
    for l in range(min(n_c, 5)):
        ob = contacts.obstacle[l]
        row[11 + l] = contacts.sediment[l] if ob == OB_SPHERE else -ob


#: clock_gettime(2) of the C library, called by its name: the cached machine code holds no address of the process
#: (a ``numba.objmode`` call of ``time.perf_counter`` would be compiled again in every process, numba caching no
#: object-mode code)
_clock_gettime = types.ExternalFunction("clock_gettime", types.int32(types.int32, types.voidptr))
#: The clock of ``time.perf_counter`` on Linux: monotonic, from an arbitrary origin.
_MONOTONIC = time.CLOCK_MONOTONIC


@jit
def _wall_clock():
    """Seconds of the monotonic clock, read from inside a kernel."""
    spec = np.zeros(2, dtype=np.int64)  # struct timespec: tv_sec, tv_nsec, 64-bit each on 64-bit Linux and macOS
    _clock_gettime(_MONOTONIC, spec.ctypes)
    return spec[0] + 1e-9 * spec[1]
