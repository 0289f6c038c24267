"""One rank's part of a deposition spread over ranks: its particles settled ahead of their turn.

A rank owns the particles dropped in its block of columns (its *rows*, in drop order) and holds
a *local sediment*: the substrate and the committed particles whose spheres lie in its *region*
(the block widened by a halo), its own particles, and spheres fetched for a particle that
rolled out of the region.  Every sphere carries its *key*, its index in the serial sediment
(substrate first, then the particles' spheres in drop order), and the grid keeps each cell's
list in decreasing key (:func:`.grid.grid_insert_ordered`), as the serial run does, whatever
the order in which spheres arrive.

A row is *absent*, *present* (settled speculatively, its spheres in the sediment), *withdrawn*
(taken out, its slots keeping its old centres), *stopped* (settled speculatively into the event
limit, no spheres) or *final*.  Each settled row keeps its footprint (the lateral bounding box of
its sphere centres) and its read rectangle (:mod:`.reads`).  The kernels keep this invariant:

    every present row was settled on what the local sediment now holds in its read rectangle
    widened by a column, leaving out the particles dropped after it and the rows withdrawn
    before it, which are settled again (in drop order) before anything uses it.

A descent reads only sediment spheres whose cells meet its rectangle, so such a row equals the
serial particle as soon as the serial sediment before it agrees with the local one there: the
check of :func:`first_failure`.  Every change of the local sediment withdraws the later present
rows it touches:

* a row being settled withdraws the later present rows with spheres in its rectangle (they were
  not there in the serial run) and settles again if there were any;
* a row settled again where it was before (bitwise) changes nothing for the later rows settled
  before it was withdrawn; those settled since (ahead, while it was out) did not see it, and
  the ones whose rectangle meets its spheres are withdrawn.  A row that moved, or was absent,
  withdraws the later rows whose rectangle meets its old or new spheres;
* committed spheres of other ranks (halo, fetched) withdraw the rows whose rectangle they meet.

:func:`read_signature` fingerprints what a row read, when it is settled and when it is committed,
to check the invariant in the tests.
"""

import math
from collections import namedtuple

import numpy as np

from parsim.core.jit import jit
from parsim.core.sdbd import reads as read_box
from parsim.core.sdbd.bundles import (Settings, grid_arrays, new_grid, new_particle, new_workspace, sediment_in,
                                     set_grid_arrays)
from parsim.core.sdbd.constants import (
    EVENT_LIMIT,
    GEOM_CELL,
    GEOM_LENGTH_X,
    GEOM_LENGTH_Y,
    IGEOM_MODE,
    LATERAL_PERIODIC,
    LATERAL_WALLS,
    VIRTUAL_ANGLE,
    WALL_FRICTIONLESS,
)
from parsim.core.sdbd.cycling import new_descent_history
from parsim.core.sdbd.engine import _descend, _search_margin, join_sediment, largest_diameter
from parsim.core.sdbd.grid import grid_collect_growing, grid_insert_ordered, grid_remove, wrap_position
from parsim.core.sdbd.particle import drop_particle, place_spheres
from parsim.core.sdbd.rotation import matrix_to_quat
from parsim.core.sdbd.strips import mark_strips, meets_strips

__all__ = ["ABSENT", "PRESENT", "STOPPED", "FINAL", "WITHDRAWN", "Rows", "new_scratch", "settle_rows", "first_failure",
           "insert_committed", "withdraw", "lay_substrate", "read_signature", "first_changed", "drop_top",
           "rows_meeting", "rows_with_centre_in", "box_meets", "interval_within"]

ABSENT, PRESENT, STOPPED, FINAL, WITHDRAWN = 0, 1, 2, 3, 4
#: why a row cannot be committed (:func:`first_failure`), in the order they are examined
FAIL_REGION, FAIL_CONFLICT, FAIL_STOPPED = 0, 1, 2
N_FAILURES = 3


@jit(inline="always")
def interval_meets(a0, a1, b0, b1, length, periodic):
    """Whether ``[a0, a1]`` and ``[b0, b1]`` overlap (on the circle of circumference ``length`` if
    ``periodic``); an empty interval (``a0 > a1``) meets nothing."""
    if a0 > a1 or b0 > b1:
        return False
    if not periodic:
        return a0 <= b1 and b0 <= a1
    if a1 - a0 >= length or b1 - b0 >= length:
        return True
    shift = length * math.floor((a0 - b0) / length)  # b moved by whole periods to start at or below a0
    b0 += shift
    b1 += shift
    return a0 <= b1 or b0 + length <= a1


@jit(inline="always")
def interval_within(a0, a1, b0, b1, length, periodic):
    """Whether ``[a0, a1]`` lies inside ``[b0, b1]`` (on the circle of circumference ``length`` if
    ``periodic``, where ``b1 - b0 >= length`` is the whole circle)."""
    if periodic:
        if b1 - b0 >= length:
            return True
        shift = length * math.floor((a0 - b0) / length)  # a moved by whole periods to start in [b0, b0 + L)
        a0 -= shift
        a1 -= shift
    return b0 <= a0 and a1 <= b1


@jit(inline="always")
def box_meets(box, other, margin, length_x, length_y, periodic):
    """Whether the rectangle ``box`` (x_low, x_high, y_low, y_high) widened by ``margin`` meets
    ``other`` (periodic boxes wrap)."""
    return (interval_meets(box[0] - margin, box[1] + margin, other[0], other[1], length_x, periodic)
            and interval_meets(box[2] - margin, box[3] + margin, other[2], other[3], length_y, periodic))


@jit
def withdraw(row, rows, centre, radius, grid_state, now):
    """Take row ``row`` (present or stopped) out of the local sediment at ``now`` (the rank's count
    of descents, kept in ``rows.withdrawn_at``): a present row becomes WITHDRAWN (its slots keep
    its old centres, out of the grid, for :func:`settle_rows` to compare), a stopped one ABSENT."""
    status = rows.status
    if status[row] == PRESENT:
        for j in range(rows.slot[row], rows.slot[row] + rows.count[row]):
            grid_remove(grid_state, j, (centre[j, 0], centre[j, 1], centre[j, 2]))
            radius[j] = 0.0  # out of the grid: not rebuilt into it
        status[row] = WITHDRAWN
        rows.withdrawn_at[row] = now
    elif status[row] == STOPPED:
        status[row] = ABSENT
        rows.withdrawn_at[row] = now


@jit
def _withdraw_met(first, last, box, by_footprint, rows, centre, radius, grid_state, margin, now, settled_after):
    """Withdraw (with :func:`withdraw`) the present rows in ``first .. last - 1`` that ``box`` meets:
    with ``by_footprint``, those with a sphere in ``box`` (a rectangle read) widened by ``margin``
    (stopped rows have none); else those whose rectangle widened by ``margin`` meets ``box`` (the
    footprint of spheres that joined), of those settled after ``settled_after`` (a count of
    descents; -1: all).  Returns whether any was."""
    geom = grid_state[0]
    periodic = grid_state[1][0] == LATERAL_PERIODIC
    status, footprint, rectangle = rows.status, rows.footprint, rows.rectangle
    any_met = False
    for o in range(first, last):
        if by_footprint:
            met = status[o] == PRESENT and box_meets(box, footprint[o], margin, geom[GEOM_LENGTH_X], geom[GEOM_LENGTH_Y], periodic)
        else:
            met = ((status[o] == PRESENT or status[o] == STOPPED) and rows.settled_at[o] > settled_after
                   and box_meets(rectangle[o], box, margin, geom[GEOM_LENGTH_X], geom[GEOM_LENGTH_Y], periodic))
        if met:
            withdraw(o, rows, centre, radius, grid_state, now)
            any_met = True
    return any_met


@jit
def insert_committed(parcel, first_slot, local, first_row, rows, now):
    """Committed particles of other ranks, ``parcel = (particle_count, particle_footprint, sphere_key,
    sphere_centre, sphere_radius)``, join the local sediment ``local`` (:data:`.rounds.Local`) in slots
    from ``first_slot`` on: particle ``k`` has ``particle_count[k]`` spheres (keys, wrapped centres,
    radii in the next rows of ``sphere_*``) and footprint ``particle_footprint[k]``.  The present or
    stopped rows in ``first_row .. local.settled_end - 1`` whose rectangle widened by ``local.margin``
    meets one of the footprints are withdrawn first (at ``now``, a count of descents).  The grid's
    arrays grow as they must."""
    particle_count, particle_footprint, sphere_key, sphere_centre, sphere_radius = parcel
    n_particles = particle_count.shape[0]
    centre, radius, key, margin = local.centre, local.radius, local.key, local.margin
    grid_state = grid_arrays(local.grid)
    geom, igeom, head, col_top, nxt, hkeys, hval, counts = grid_state
    status, rectangle = rows.status, rows.rectangle
    periodic = igeom[IGEOM_MODE] == LATERAL_PERIODIC
    marked, origin, width = mark_strips(particle_footprint, n_particles, 0.0, geom[GEOM_LENGTH_X], periodic)
    for o in range(first_row, local.settled_end):
        if status[o] != PRESENT and status[o] != STOPPED:
            continue
        box = rectangle[o]
        if not meets_strips(box[0] - margin, box[1] + margin, marked, origin, width, periodic):
            continue
        for k in range(n_particles):
            if box_meets(box, particle_footprint[k], margin, geom[GEOM_LENGTH_X], geom[GEOM_LENGTH_Y], periodic):
                withdraw(o, rows, centre, radius, grid_state, now)
                break
    j = first_slot
    for s in range(len(sphere_radius)):
        for d in range(3):
            centre[j, d] = sphere_centre[s, d]
        radius[j] = sphere_radius[s]
        key[j] = sphere_key[s]
        head, col_top, hkeys, hval = grid_insert_ordered((geom, igeom, head, col_top, nxt, hkeys, hval, counts),
                                                         j, (centre[j, 0], centre[j, 1], centre[j, 2]), key)
        j += 1
    set_grid_arrays(local.grid, geom, igeom, head, col_top, nxt, hkeys, hval, counts)


#: One rank's rows (its particles in drop order) and what settling them gave: their places in the drop
#: order (``index``), numbers of spheres (``count``), first sphere keys, first rows in ``spheres``
#: (``sphere_row``) and slots in the local sediment; their ``status`` (ABSENT ... WITHDRAWN),
#: ``footprint`` and read ``rectangle`` (x_low, x_high, y_low, y_high); their centres of mass,
#: quaternions, contacts, states, event counts, steps and chunk ends; their spheres as the particles
#: hold them (``spheres``), the :func:`read_signature` of each and the spheres it should have seen
#: (``signatures``: count, hash, count held; no rows, none taken), and
#: when each was last settled and withdrawn (``settled_at``, ``withdrawn_at``: the rank's count of descents
#: then, which only grows).
Rows = namedtuple("Rows", ["index", "count", "first_key", "sphere_row", "slot", "status", "footprint", "rectangle",
                           "com", "rotation", "contacts", "state", "events", "steps", "chunks", "spheres",
                           "signatures", "settled_at", "withdrawn_at"])


@jit
def new_scratch(n_max):
    """What settling particles of up to ``n_max`` spheres works in (:func:`settle_rows`), allocated
    once per kernel call: the particle, the workspace, the descent's history and a trace row."""
    return (new_particle(n_max), new_workspace(np.empty(0, dtype=np.int64), np.empty(read_box.N_READS)),
            new_descent_history(), np.empty((1, 16)))


@jit
def settle_rows(local, first, last, particles, settings, rows, settles, given_top):
    """Settle the absent rows among ``first .. last - 1`` in drop order (row ``o``'s inputs are entry
    ``o`` of the ``particles`` arrays: ``shape_offsets, shape_radii, shape_start, particle_shape,
    particle_scale, particle_rotation, particle_drop_xy``), keeping the invariant of the module docs,
    on the rank's local sediment ``local`` (:data:`.rounds.Local`: its grid, whose arrays may be
    replaced as the pile grows, its slots' centres, radii and keys, the round's margin, the scratch
    and query buffer to work in); rows from ``local.settled_end`` on were never settled.
    ``settings``: ``floor_mode, wall_contact, trial_angle, cycle_n, cycle_eps, max_events, ell``.
    Each writes its results into ``rows`` (:class:`Rows`; its spheres from ``spheres[sphere_row[o]]``
    on, as the particle holds them, a periodic box's beyond it included), its footprint and its
    rectangle, and its :func:`read_signature` when ``rows.signatures`` has rows; ``settles[0]`` counts
    the descents.  ``given_top``: see :func:`_settle`.  ``local.buf`` becomes a larger buffer if the
    queries needed one."""
    scratch, buf, settled_end, margin = local.scratch, local.buf, local.settled_end, local.margin
    grid, centre, radius, key = local.grid, local.centre, local.radius, local.key
    particle, work, _, _ = scratch
    floor_mode, wall_contact, trial_angle, cycle_n, cycle_eps, max_events, ell = settings
    virtual_angle = trial_angle if trial_angle > 0.0 else VIRTUAL_ANGLE
    descent = Settings(floor_mode, trial_angle, virtual_angle, cycle_n, cycle_eps, max_events, ell,
                       grid.igeom[IGEOM_MODE] == LATERAL_WALLS, wall_contact == WALL_FRICTIONLESS, False)
    sediment = sediment_in(centre, radius)
    periodic = grid.igeom[IGEOM_MODE] == LATERAL_PERIODIC
    status, footprint, rectangle, slot = rows.status, rows.footprint, rows.rectangle, rows.slot
    for o in range(first, last):
        was = status[o]
        if was != ABSENT and was != WITHDRAWN:
            continue
        later = max(settled_end, o + 1)
        while True:
            settles[0] += 1
            n, state, n_c, steps, chunks, buf = _settle(o, particles, sediment, grid, ell, scratch, descent,
                                                        rows.events[o], buf, periodic, given_top)
            # later rows were not there in the serial run: settle again without those it read
            if later == o + 1 or not _withdraw_met(o + 1, later, work.reads, True, rows, centre, radius,
                                                   grid_arrays(grid), margin, settles[0], -1):
                break
        rows.settled_at[o] = settles[0]
        for k in range(read_box.N_READS):
            rectangle[o, k] = work.reads[k]
        if rows.signatures.shape[0]:
            count_read, digest = read_signature(rectangle[o], margin, rows.first_key[o], grid_arrays(grid), centre,
                                                key)
            rows.signatures[o, 0] = count_read
            rows.signatures[o, 1] = np.int64(digest)
            rows.signatures[o, 2] = _count_held(rectangle[o], margin, rows.first_key[o], grid.geom, periodic, centre,
                                                radius, key)
        rows.steps[o] = steps
        rows.chunks[o] = chunks
        rows.state[o] = state
        old = (footprint[o, 0], footprint[o, 1], footprint[o, 2], footprint[o, 3])
        moved = True
        if state == EVENT_LIMIT:
            status[o] = STOPPED
            footprint[o, 0] = math.inf
            footprint[o, 1] = -math.inf
            footprint[o, 2] = math.inf
            footprint[o, 3] = -math.inf
        else:
            moved = was != WITHDRAWN or not _same_spheres(n, particle, centre, slot[o], grid.geom, grid.igeom)
            _freeze_row(o, n, particle, n_c, sediment, grid, key, rows)
            status[o] = PRESENT
        # later rows settled while this one was elsewhere read what changed; back where it was, it
        # changes nothing for those settled before it was withdrawn, but those settled since did
        # not see it
        if later > o + 1:
            if moved and was == WITHDRAWN:
                _withdraw_met(o + 1, later, np.array(old), False, rows, centre, radius, grid_arrays(grid), margin,
                              settles[0], -1)
            if state != EVENT_LIMIT:
                _withdraw_met(o + 1, later, footprint[o], False, rows, centre, radius, grid_arrays(grid), margin,
                              settles[0], -1 if moved else rows.withdrawn_at[o])
        settled_end = later
    local.buf = buf


@jit(inline="always")  # a call would reference-count its dozen arrays and bundles, per particle
def _settle(p, particles, sediment, grid, ell, scratch, settings, events, buf, periodic, given_top):
    """Drop particle ``p`` (its inputs in ``particles``, :func:`.particle.drop_particle`) and let it
    descend as the serial loop does (:func:`.engine.run_deposition`) in the :func:`new_scratch`
    ``scratch``; its rectangle is in the workspace's ``reads``.  A particle with a sphere larger than any
    before is dropped at ``given_top`` (:func:`drop_top`, on the grid before it grew), else ``given_top``
    is NaN.  Returns ``(n, state, n_c, steps, chunk_ends, buf)``."""
    particle, work, history, trace = scratch
    for k in range(events.shape[0]):
        events[k] = 0
    read_box.forget(work.reads)
    n, _ = drop_particle(p, particles, sediment, grid, ell, particle, work.reads, given_top)
    if largest_diameter(n, particle) > grid.geom[GEOM_CELL]:
        raise ValueError("a particle larger than the grid's cell: grow the grid first (drop_top)")
    state, n_c, steps, chunk_ends, _, buf = _descend(n, particle, work, history, sediment, grid, settings, events,
                                                     False, trace, buf)
    read_box.note_spheres(work.reads, n, particle, _search_margin(grid, ell))
    if state != EVENT_LIMIT and periodic:
        cx, cy = wrap_position(grid.geom, grid.igeom, particle.com[0], particle.com[1])
        particle.com[0] = cx
        particle.com[1] = cy
        place_spheres(n, particle)
    return n, state, n_c, steps, chunk_ends, buf


@jit(inline="always")
def _same_spheres(n, particle, centre, first_slot, geom, igeom):
    """Whether the particle's ``n`` spheres, wrapped, are bitwise the centres kept in its slots."""
    for i in range(n):
        wx, wy = wrap_position(geom, igeom, particle.centre[i, 0], particle.centre[i, 1])
        j = first_slot + i
        if wx != centre[j, 0] or wy != centre[j, 1] or particle.centre[i, 2] != centre[j, 2]:
            return False
    return True


@jit(inline="always")
def _freeze_row(o, n, particle, n_c, sediment, grid, key, rows):
    """Row ``o``'s particle of ``n`` spheres at rest, with ``n_c`` contacts, joins the local sediment
    (slots from ``rows.slot[o]``, keys from ``rows.first_key[o]``) and its results are written into
    ``rows`` (:class:`Rows`): footprint, centre of mass, orientation, contacts and sphere centres."""
    first_slot, first_key, sphere_row = rows.slot[o], rows.first_key[o], rows.sphere_row[o]
    out_sphere, footprint = rows.spheres, rows.footprint
    x_low = y_low = math.inf
    x_high = y_high = -math.inf
    for i in range(n):
        key[first_slot + i] = first_key + i
        x = particle.centre[i, 0]
        y = particle.centre[i, 1]
        join_sediment(first_slot + i, x, y, particle.centre[i, 2], particle.radius[i], sediment, grid, key)
        for d in range(3):
            out_sphere[sphere_row + i, d] = particle.centre[i, d]
        x_low = min(x_low, x)
        x_high = max(x_high, x)
        y_low = min(y_low, y)
        y_high = max(y_high, y)
    footprint[o, 0] = x_low
    footprint[o, 1] = x_high
    footprint[o, 2] = y_low
    footprint[o, 3] = y_high
    for d in range(3):
        rows.com[o, d] = particle.com[d]
    matrix_to_quat(particle.rotation, rows.rotation[o])
    rows.contacts[o] = n_c


@jit
def first_failure(first, last, rows, region, others, margin, length, periodic):
    """The first of rows ``first .. last - 1`` of ``rows`` (:class:`Rows`, settled) that cannot be committed
    once every particle before it is, as ``index * N_FAILURES + reason``, or -1: FAIL_REGION if its
    rectangle widened by ``margin`` leaves the ``region`` (x_low, x_high) whose committed sediment this
    rank holds, FAIL_CONFLICT if a particle of another rank dropped after the rows committed so far and
    before it has a sphere there, FAIL_STOPPED if it stopped at the event limit.  ``others`` lists the
    other ranks' particles, sorted by index: ``(other_index, other_footprint, n_other)``.  Others'
    particles dropped before it meet its rectangle only if their footprint meets the region: they are
    all listed.  ``length`` is the box's lateral (x, y), ``periodic`` whether it wraps."""
    index, status, rectangle = rows.index, rows.status, rows.rectangle
    other_index, other_footprint, n_other = others
    length_x, length_y = length[0], length[1]
    marked, origin, width = mark_strips(other_footprint, n_other, margin, length_x, periodic)
    start = 0
    for o in range(first, last):
        p = index[o]
        box = rectangle[o]
        if not interval_within(box[0] - margin, box[1] + margin, region[0], region[1], length_x, periodic):
            return p * N_FAILURES + FAIL_REGION
        while start < n_other and other_index[start] < p:
            start += 1
        if start > 0 and meets_strips(box[0], box[1], marked, origin, width, periodic):
            for k in range(start):
                if box_meets(box, other_footprint[k], margin, length_x, length_y, periodic):
                    return p * N_FAILURES + FAIL_CONFLICT
        if status[o] == STOPPED:
            return p * N_FAILURES + FAIL_STOPPED
    return -1


@jit
def lay_substrate(positions, radii, region, centre, radius, key, grid_state):
    """The substrate's spheres (keys ``0 .. m - 1``) whose wrapped centre lies in the ``region``
    (x_low, x_high) join the empty local sediment, as the serial run lays them
    (:func:`.engine.join_sediment`).  Returns their number and the grid's arrays."""
    grid = new_grid(*grid_state)
    sediment = sediment_in(centre, radius)
    periodic = grid.igeom[IGEOM_MODE] == LATERAL_PERIODIC
    n = 0
    for j in range(radii.shape[0]):
        wx, _ = wrap_position(grid.geom, grid.igeom, positions[j, 0], positions[j, 1])
        if interval_within(wx, wx, region[0], region[1], grid.geom[GEOM_LENGTH_X], periodic):
            key[n] = j
            join_sediment(n, positions[j, 0], positions[j, 1], positions[j, 2], radii[j], sediment, grid, key)
            n += 1
    return n, grid.memory  # the arrays themselves: borrowed views never go back to Python


@jit
def rows_meeting(boxes, x_low, x_high, length, periodic):
    """Which rows' boxes (x_low, x_high, ...) meet ``[x_low, x_high]`` in x."""
    met = np.zeros(boxes.shape[0], dtype=np.bool_)
    for o in range(boxes.shape[0]):
        met[o] = interval_meets(boxes[o, 0], boxes[o, 1], x_low, x_high, length, periodic)
    return met


@jit
def rows_with_centre_in(rows, slot, count, centre, box, length_x, length_y, periodic):
    """Which of ``rows`` have a sphere (slots ``slot[o] ..`` of ``count[o]``) whose centre lies in
    ``box`` (x_low, x_high, y_low, y_high; y ignored when ``y_low > y_high``)."""
    inside = np.zeros(rows.shape[0], dtype=np.bool_)
    for r in range(rows.shape[0]):
        o = rows[r]
        for j in range(slot[o], slot[o] + count[o]):
            x = centre[j, 0]
            y = centre[j, 1]
            if interval_within(x, x, box[0], box[1], length_x, periodic) and (
                    box[2] > box[3] or interval_within(y, y, box[2], box[3], length_y, periodic)):
                inside[r] = True
                break
    return inside


@jit(inline="always")
def _mix(h):
    """A 64-bit finaliser (splitmix64): nearby inputs give unrelated outputs."""
    h = (h ^ (h >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    h = (h ^ (h >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return h ^ (h >> np.uint64(31))


@jit
def read_signature(box, margin, below_key, grid_state, centre, key):
    """A fingerprint of the sediment spheres of key below ``below_key`` whose centre lies in ``box``
    widened by ``margin``: their number and an order-free hash of their keys and centres' bits.
    Taken when a row is settled and again when it is committed, it checks the invariant that makes
    the decomposed sediment the serial one: what a descent read is final when it is committed."""
    geom, igeom, head, col_top, nxt, hkeys, hval, _ = grid_state
    periodic = igeom[IGEOM_MODE] == LATERAL_PERIODIC
    buf = np.empty(1024, dtype=np.int64)
    n, buf = grid_collect_growing(grid_state, (box[0] - margin, box[2] - margin, 0.0),
                                  (box[1] + margin, box[3] + margin, (head.shape[0] + 1) * geom[GEOM_CELL]), buf)
    count = 0
    digest = np.uint64(0)
    bits = centre.view(np.uint64)
    for s in range(n):
        j = buf[s]
        if key[j] >= below_key:
            continue
        x = centre[j, 0]
        y = centre[j, 1]
        if not (interval_within(x, x, box[0] - margin, box[1] + margin, geom[GEOM_LENGTH_X], periodic)
                and interval_within(y, y, box[2] - margin, box[3] + margin, geom[GEOM_LENGTH_Y], periodic)):
            continue
        count += 1
        digest += _mix(np.uint64(key[j]) ^ _mix(bits[j, 0] ^ _mix(bits[j, 1] ^ _mix(bits[j, 2]))))
    return count, digest


@jit
def _count_held(box, margin, below_key, geom, periodic, centre, radius, key):
    """The spheres of the local sediment (slots of radius > 0) of key below ``below_key`` whose centre lies in
    ``box`` widened by ``margin``, counted slot by slot: what :func:`read_signature` must find in the grid."""
    count = 0
    for j in range(radius.shape[0]):
        if radius[j] > 0.0 and 0 <= key[j] < below_key:
            x = centre[j, 0]
            y = centre[j, 1]
            if (interval_within(x, x, box[0] - margin, box[1] + margin, geom[GEOM_LENGTH_X], periodic)
                    and interval_within(y, y, box[2] - margin, box[3] + margin, geom[GEOM_LENGTH_Y], periodic)):
                count += 1
    return count


@jit
def first_changed(first, last, signatures, rectangle, margin, first_key, status, grid_state, centre, key):
    """The first committed row among ``first .. last - 1`` whose :func:`read_signature` now differs
    from the one taken when it was settled, or whose grid did not list every sphere of the local
    sediment there when it was settled (``signatures[o, 2]``), or -1."""
    for o in range(first, last):
        if status[o] != FINAL:
            continue
        count_read, digest = read_signature(rectangle[o], margin, first_key[o], grid_state, centre, key)
        if (count_read != signatures[o, 0] or np.int64(digest) != signatures[o, 1]
                or signatures[o, 2] != signatures[o, 0]):
            return o
    return -1


@jit
def drop_top(p, particles, grid_state, centre, radius, ell, n_max):
    """The height above which particle ``p`` is dropped (:func:`.particle.drop_particle`) on this grid:
    for a particle with a sphere larger than any before, taken before the grid grows (the serial
    run drops it, then grows the grid's cell)."""
    particle = new_particle(n_max)
    _, top = drop_particle(p, particles, sediment_in(centre, radius), new_grid(*grid_state), ell, particle,
                           np.empty(0), math.nan)
    return top
