"""The rounds of one rank of a deposition spread over ranks, inside one jitted loop.

The protocol and why its sediment is the serial one are in :mod:`parsim.deposition.spread`.
Here a rank runs its rounds without returning to Python, messaging only its *neighbours* (the
ranks whose regions meet its own) through :mod:`parsim.core.kernel_mpi`, and it settles the
next rows instead of idling whenever it waits:

1. settle the window's absent rows;
2. send each neighbour the footprints of the window's rows that meet its region; settle ahead
   until every neighbour's have arrived;
3. start the minimum over all ranks of the first particle that cannot be committed
   (:func:`.blocks.first_failure`); settle ahead until it is known: the new frontier;
4. commit the rows before it, send each neighbour those with a sphere centre in its region,
   insert what the neighbours send (withdrawing the rows they touch);
5. a conflict withdraws the particle at the new frontier (on its owner); a particle whose rectangle
   left its owner's region (to be fetched), one stopped at the event limit, or, with the check, a
   committed particle whose read changed, ends the call: the caller goes on from there.

A round's window never spans a growth of the grid's cell (the *plan* lists them): a particle
larger than every one before is settled alone, dropped from the height found on the grid before
it grows, and every rank rebuilds its grid with the new cell before the next window.
"""

from collections import namedtuple

import math

import numpy as np

from parsim.core import kernel_mpi
from parsim.core.growth import with_rows_filled
from parsim.core.jit import jit
from parsim.core.sdbd.constants import GEOM_CELL
from parsim.core.sdbd.blocks import (FAIL_CONFLICT, FAIL_REGION, FINAL, N_FAILURES, drop_top, first_changed,
                                     first_failure, insert_committed, interval_meets, new_scratch, rows_with_centre_in,
                                     settle_rows, withdraw)
from parsim.core.sdbd.bundles import bundle, grid_arrays, new_grid, set_grid_arrays
from parsim.core.sdbd.engine import regrid

__all__ = ["Plan", "Held", "run_rounds", "settle_again", "insert_parcel", "DONE", "LEFT_REGION", "STOPPED_AT_LIMIT",
           "READ_CHANGED", "ROUNDS", "CONFLICTS", "ROUND_SECONDS", "SETTLE_SECONDS", "IDLE_SECONDS", "FOOTPRINT_BYTES",
           "HALO_BYTES", "HALO_PARTICLES", "N_TALLIES"]

#: How a call of :func:`run_rounds` ends.
DONE, LEFT_REGION, STOPPED_AT_LIMIT, READ_CHANGED = range(4)
#: Entries of the tally (float64): rounds, conflicts, seconds in rounds and, of those, settling and
#: waiting with nothing left to settle ahead, bytes of footprints and of committed particles sent,
#: committed particles sent.
ROUNDS, CONFLICTS, ROUND_SECONDS, SETTLE_SECONDS, IDLE_SECONDS, FOOTPRINT_BYTES, HALO_BYTES, HALO_PARTICLES = range(8)
N_TALLIES = 8
#: Message tags (the group's communicator carries nothing else point to point during the rounds).
FOOTPRINT_TAG, COMMITTED_TAG = 41, 42
#: Float64 per footprint sent (the particle and its box), per committed particle (its sphere count
#: and footprint) and per committed sphere (key, centre, radius).
FOOTPRINT_WIDTH, PARTICLE_WIDTH, SPHERE_WIDTH = 5, 5, 5
#: Slot of the reduction's request; the sends' take the slots after it.
REDUCTION_SLOT = 0
#: Seconds of settling ahead between two looks at the messages (a look costs about a microsecond).
POLL_SECONDS = 25e-6

#: What the rounds of one rank need to know besides its rows: the number of particles, the window
#: (drop indices per round), the growth of the grid's cell (``growth_at``: the particles from which
#: each ``cell`` holds, the first 0; ``side``: the largest side of its columns), this rank's
#: ``region`` and its ``neighbours``' (ranks, and regions as rows of x_low, x_high), the box's
#: lateral ``length`` (x, y) and whether it is ``periodic``, the particle from whose commit the clock
#: runs (-1: none), and the most spheres of a particle; ``jitter`` (seconds, 0: none) and ``jitter_seed``
#: inject random delays before every message and at every look at the messages, each settling ahead a
#: random number of rows: what the sediment must not depend on (:func:`_jitter`).
Plan = namedtuple("Plan", ["n_particles", "window", "growth_at", "cell", "side", "region", "neighbours",
                           "neighbour_regions", "length", "periodic", "clock_from", "n_max", "jitter",
                           "jitter_seed"])

#: The local sediment and where the rank is: its :class:`.bundles.Grid`, the slots' centres, radii and
#: keys (the first ``n_used`` in use), the rows settled so far (``settled_end``), the margin of the
#: round, and what settling works in (``scratch``, ``buf``).  The grid is a bundle that the loop keeps
#: and updates in place, as the serial loop does.
Local = bundle("Local", ["grid", "centre", "radius", "key", "n_used", "settled_end", "margin", "scratch", "buf"])

#: The local sediment as the caller keeps it between kernel calls: the grid's state arrays (the tuple of
#: :func:`.grid.empty_grid`), the slots' centres, radii and keys (the first ``n_used`` in use), the rows
#: settled so far and the margin of the last round.  The kernels take it and return it, its arrays
#: possibly replaced as they grew.
Held = namedtuple("Held", ["grid", "centre", "radius", "key", "n_used", "settled_end", "margin"])


@jit
def _local(held, n_max):
    """The :data:`Local` bundle over the caller's local sediment ``held`` (a :data:`Held`), with a new
    scratch for particles of up to ``n_max`` spheres and a new query buffer."""
    return Local(new_grid(*held.grid), held.centre, held.radius, held.key, held.n_used, held.settled_end,
                 held.margin, new_scratch(n_max), np.empty(4096, dtype=np.int64))


@jit
def _held(local):
    """The :data:`Held` of a :data:`Local` bundle, for the caller."""
    return Held(local.grid.memory, local.centre, local.radius, local.key, local.n_used, local.settled_end,
                local.margin)


@jit
def run_rounds(frontier, particles, settings, rows, plan, held, link, tally, settles, clock):
    """Rounds from ``frontier`` (every particle before it committed on every rank) until every
    particle is committed or one needs the caller.  Collective over the link's ranks.

    ``particles`` and ``settings`` are those of :func:`.blocks.settle_rows`, ``rows`` the rank's
    :class:`.blocks.Rows`, ``plan`` a :class:`Plan`; ``held`` the local sediment (a :data:`Held`);
    ``link`` a :mod:`.kernel_mpi` link over the
    group; ``tally`` (N_TALLIES) and ``settles`` (the descents) count; ``clock[0]`` receives the
    :func:`.kernel_mpi.now` at which the round that committed particle ``plan.clock_from`` began.
    Returns ``(outcome, particle, held)``, ``held`` the local sediment now:
    DONE (particle: the number of particles), LEFT_REGION, STOPPED_AT_LIMIT or READ_CHANGED
    (particle: the one concerned, every particle before it committed)."""
    local = _local(held, plan.n_max)
    local.margin = 0.0
    if plan.jitter > 0.0:
        np.random.seed(plan.jitter_seed + frontier)
    outcome = DONE
    while frontier < plan.n_particles:
        started = kernel_mpi.now()
        outcome, frontier = _round(frontier, local, particles, settings, rows, plan, link, tally, settles, clock)
        tally[ROUND_SECONDS] += kernel_mpi.now() - started
        if outcome != DONE:
            break
    return outcome, frontier, _held(local)


@jit
def _round(frontier, local, particles, settings, rows, plan, link, tally, settles, clock):
    """One round from ``frontier``; returns ``(outcome, new frontier)``."""
    tally[ROUNDS] += 1.0
    started = kernel_mpi.now()
    _set_cell(local, _cell_after(plan, frontier - 1))
    end = _window_end(plan, frontier)
    local.margin = plan.side[_growth_step(plan, end - 1)]
    first_row = np.searchsorted(rows.index, frontier)
    last_row = np.searchsorted(rows.index, end)
    ahead_row = np.searchsorted(rows.index, _ahead_end(plan, frontier, end))
    _settle_span(local, first_row, last_row, particles, settings, rows, plan, tally, settles)
    other_index, other_footprint = _share_footprints(local, first_row, last_row, ahead_row, particles, settings,
                                                     rows, plan, link, tally, settles)
    mine = end * N_FAILURES
    if plan.region[0] <= plan.region[1]:  # a rank that owns no block has no rows
        others = (other_index, other_footprint, other_index.shape[0])
        code = first_failure(first_row, last_row, rows, plan.region, others, local.margin, plan.length, plan.periodic)
        if code >= 0:
            mine = code
    _jitter(plan, kernel_mpi.now())
    kernel_mpi.post_minimum(float(mine), link, REDUCTION_SLOT)
    polled = kernel_mpi.now()
    while not kernel_mpi.is_done(link, REDUCTION_SLOT):
        polled = _settle_ahead(local, ahead_row, particles, settings, rows, plan, tally, settles, polled)
    new_frontier, reason = divmod(np.int64(kernel_mpi.reduced(link)), N_FAILURES)
    committed_row = np.searchsorted(rows.index, min(new_frontier, end))
    for o in range(first_row, committed_row):
        rows.status[o] = FINAL
    _share_committed(local, first_row, committed_row, ahead_row, particles, settings, rows, plan, link, tally,
                     settles)
    if rows.signatures.shape[0]:
        changed = first_changed(first_row, committed_row, rows.signatures, rows.rectangle, local.margin,
                                rows.first_key, rows.status, grid_arrays(local.grid), local.centre, local.key)
        if changed >= 0:
            return READ_CHANGED, rows.index[changed]
    if math.isnan(clock[0]) and 0 <= plan.clock_from < min(new_frontier, end):
        clock[0] = started
    if new_frontier >= end:
        return DONE, end
    if reason == FAIL_CONFLICT:  # settled again at the frontier, where it is exact
        tally[CONFLICTS] += 1.0
        if committed_row < rows.index.shape[0] and rows.index[committed_row] == new_frontier:
            withdraw(committed_row, rows, local.centre, local.radius, grid_arrays(local.grid), settles[0])
        return DONE, new_frontier
    return (LEFT_REGION if reason == FAIL_REGION else STOPPED_AT_LIMIT), new_frontier


# ------------------------------------------------------------------------------------- settling
@jit
def _settle_span(local, first_row, last_row, particles, settings, rows, plan, tally, settles):
    """Settle the absent rows of ``first_row .. last_row - 1``.  A particle alone whose sphere is larger
    than the grid's cell is dropped from the height found on the grid before it grows, then the grid
    grows (as the serial run drops it, then grows its grid)."""
    started = kernel_mpi.now()
    given_top = math.nan
    if last_row == first_row + 1:
        cell = _cell_after(plan, rows.index[first_row])
        if cell > local.grid.geom[GEOM_CELL]:
            given_top = drop_top(first_row, particles, grid_arrays(local.grid), local.centre, local.radius,
                                 settings[6], plan.n_max)
            _set_cell(local, cell)
    settle_rows(local, first_row, last_row, particles, settings, rows, settles, given_top)
    local.settled_end = max(local.settled_end, last_row)
    tally[SETTLE_SECONDS] += kernel_mpi.now() - started


@jit
def _settle_ahead(local, ahead_row, particles, settings, rows, plan, tally, settles, since):
    """Settle the next rows never settled, before ``ahead_row``, until POLL_SECONDS have passed since
    ``since`` (the last look at the messages): the next windows' work, done while this rank waits
    for the others.  With nothing left to settle, the time since ``since`` counts as idle.  Returns
    the time of this call's end."""
    now = kernel_mpi.now()
    if local.settled_end >= ahead_row:
        tally[IDLE_SECONDS] += now - since
        return _jitter(plan, now)
    rows_left = np.random.randint(0, 3) if plan.jitter > 0.0 else ahead_row
    while local.settled_end < ahead_row and (now - since < POLL_SECONDS or plan.jitter > 0.0) and rows_left > 0:
        row = local.settled_end
        _settle_span(local, row, row + 1, particles, settings, rows, plan, tally, settles)
        rows_left -= 1
        now = kernel_mpi.now()
    return _jitter(plan, now)


@jit
def _jitter(plan, now):
    """With ``plan.jitter``, wait a random time up to it (a message late, a rank slow); returns the time then."""
    if plan.jitter <= 0.0:
        return now
    until = now + plan.jitter * np.random.random()
    while now < until:
        now = kernel_mpi.now()
    return now


@jit
def _set_cell(local, cell):
    """The grid rebuilt with cell ``cell`` if it has another, its spheres (the slots of radius > 0)
    inserted in increasing key: every list as the serial run's."""
    if local.grid.geom[GEOM_CELL] != cell:
        used = np.flatnonzero(local.radius > 0.0)
        regrid(local.grid, cell, local.centre, used[np.argsort(local.key[used], kind="mergesort")])


# ---------------------------------------------------------------------------------------- plan
@jit
def _growth_step(plan, particle):
    """The entry of ``plan.cell`` that holds once ``particle`` has arrived (particle -1: before any)."""
    return max(np.searchsorted(plan.growth_at, particle, side="right") - 1, 0)


@jit
def _cell_after(plan, particle):
    """The grid's cell once ``particle`` has arrived (-1: the first cell)."""
    return plan.cell[_growth_step(plan, particle)]


@jit
def _next_growth(plan, particle):
    """The first particle after ``particle`` that grows the grid's cell (the number of particles if none)."""
    at = np.searchsorted(plan.growth_at, particle, side="right")
    return plan.growth_at[at] if at < plan.growth_at.shape[0] else plan.n_particles


@jit
def _grows_at(plan, particle):
    at = np.searchsorted(plan.growth_at, particle)
    return particle > 0 and at < plan.growth_at.shape[0] and plan.growth_at[at] == particle


@jit
def _window_end(plan, frontier):
    """A window never spans a growth of the grid's cell: a particle larger than all before is settled
    alone, and the ranks rebuild their grids after it."""
    if _grows_at(plan, frontier):
        return frontier + 1
    return min(frontier + plan.window, _next_growth(plan, frontier))


@jit
def _ahead_end(plan, frontier, end):
    """The particle before which rows may be settled ahead of the window: one window further, and never
    past a growth of the grid's cell."""
    if end == frontier + 1 and _grows_at(plan, frontier):
        return end
    return min(end + plan.window, _next_growth(plan, frontier))


# ------------------------------------------------------------------------------------ messages
@jit
def _share_footprints(local, first_row, last_row, ahead_row, particles, settings, rows, plan, link, tally, settles):
    """Send each neighbour the footprints of rows ``first_row .. last_row - 1`` that meet its region in x
    and receive theirs, settling ahead while waiting; returns the received particles (sorted) and their
    footprints."""
    n_neighbours = plan.neighbours.shape[0]
    send = np.empty(max(n_neighbours * (last_row - first_row) * FOOTPRINT_WIDTH, 1))
    at = 0
    for k in range(n_neighbours):
        start = at
        for o in range(first_row, last_row):
            box = rows.footprint[o]
            if interval_meets(box[0], box[1], plan.neighbour_regions[k, 0], plan.neighbour_regions[k, 1],
                              plan.length[0], plan.periodic):
                send[at] = rows.index[o]
                for d in range(4):
                    send[at + 1 + d] = box[d]
                at += FOOTPRINT_WIDTH
        _jitter(plan, kernel_mpi.now())
        kernel_mpi.post_send(send[start:], at - start, plan.neighbours[k], FOOTPRINT_TAG, link, REDUCTION_SLOT + 1 + k)
        tally[FOOTPRINT_BYTES] += 8.0 * (at - start)
    received = _receive_all(local, FOOTPRINT_TAG, ahead_row, particles, settings, rows, plan, link, tally, settles)
    kernel_mpi.wait_slots(link, REDUCTION_SLOT + 1, n_neighbours, send)
    n = received.shape[0] // FOOTPRINT_WIDTH
    index = np.empty(n, dtype=np.int64)
    for j in range(n):
        index[j] = np.int64(received[j * FOOTPRINT_WIDTH])
    order = np.argsort(index, kind="mergesort")
    footprint = np.empty((n, 4))
    for j in range(n):
        for d in range(4):
            footprint[j, d] = received[order[j] * FOOTPRINT_WIDTH + 1 + d]
        index[j] = np.int64(received[order[j] * FOOTPRINT_WIDTH])
    return index, footprint


@jit
def _share_committed(local, first_row, last_row, ahead_row, particles, settings, rows, plan, link, tally, settles):
    """Send each neighbour the committed rows ``first_row .. last_row - 1`` with a sphere centre in its
    region, and insert into the local sediment those the neighbours send (settling ahead while waiting)."""
    n_neighbours = plan.neighbours.shape[0]
    committed = np.arange(first_row, last_row)
    spheres = 0
    for o in range(first_row, last_row):
        spheres += rows.count[o]
    send = np.empty(max(n_neighbours * ((last_row - first_row) * PARTICLE_WIDTH + spheres * SPHERE_WIDTH + 2), 1))
    at = 0
    for k in range(n_neighbours):
        box = np.array([plan.neighbour_regions[k, 0], plan.neighbour_regions[k, 1], math.inf, -math.inf])
        inside = rows_with_centre_in(committed, rows.slot, rows.count, local.centre, box, plan.length[0],
                                     plan.length[1], plan.periodic)
        start = at
        at = _pack_parcel(send, at, committed, inside, rows, local)
        _jitter(plan, kernel_mpi.now())
        kernel_mpi.post_send(send[start:], at - start, plan.neighbours[k], COMMITTED_TAG, link, REDUCTION_SLOT + 1 + k)
        tally[HALO_BYTES] += 8.0 * (at - start - 2)
        tally[HALO_PARTICLES] += send[start]
    parcels = _receive_all(local, COMMITTED_TAG, ahead_row, particles, settings, rows, plan, link, tally, settles)
    kernel_mpi.wait_slots(link, REDUCTION_SLOT + 1, n_neighbours, send)
    at = 0
    while at < parcels.shape[0]:
        at = _insert_packed(local, parcels, at, last_row, rows, settles)


@jit
def _pack_parcel(send, at, committed, inside, rows, local):
    """Write the rows ``committed[inside]`` at ``send[at]``: their number and their spheres' number, each
    row's sphere count and footprint, then each sphere's key, centre and radius.  Returns the end."""
    n_particles = 0
    n_spheres = 0
    for r in range(committed.shape[0]):
        if inside[r]:
            n_particles += 1
            n_spheres += rows.count[committed[r]]
    send[at] = n_particles
    send[at + 1] = n_spheres
    particle_at = at + 2
    sphere_at = particle_at + n_particles * PARTICLE_WIDTH
    for r in range(committed.shape[0]):
        if not inside[r]:
            continue
        o = committed[r]
        send[particle_at] = rows.count[o]
        for d in range(4):
            send[particle_at + 1 + d] = rows.footprint[o, d]
        particle_at += PARTICLE_WIDTH
        for j in range(rows.slot[o], rows.slot[o] + rows.count[o]):
            send[sphere_at] = local.key[j]
            for d in range(3):
                send[sphere_at + 1 + d] = local.centre[j, d]
            send[sphere_at + 4] = local.radius[j]
            sphere_at += SPHERE_WIDTH
    return sphere_at


@jit
def _receive_all(local, tag, ahead_row, particles, settings, rows, plan, link, tally, settles):
    """The messages with ``tag`` of every neighbour, one each, back to back; settles ahead while none is
    there."""
    n_neighbours = plan.neighbours.shape[0]
    pending = np.ones(n_neighbours, dtype=np.bool_)
    parts = np.empty(0)
    left = n_neighbours
    polled = kernel_mpi.now()
    while left > 0:
        got = False
        for k in range(n_neighbours):
            if pending[k]:
                count = kernel_mpi.arrived_count(plan.neighbours[k], tag, link)
                if count >= 0:
                    part = kernel_mpi.receive_arrived(plan.neighbours[k], tag, count, link)
                    parts = np.concatenate((parts, part))
                    pending[k] = False
                    left -= 1
                    got = True
        if not got and left > 0:
            polled = _settle_ahead(local, ahead_row, particles, settings, rows, plan, tally, settles, polled)
    return parts


# ----------------------------------------------------------------------- the local sediment
@jit
def _insert_packed(local, parcel, at, first_row, rows, settles):
    """The committed particles of another rank packed in ``parcel`` from ``at`` on (by
    :func:`_pack_parcel`) join the local sediment (:func:`_insert`); returns where the next parcel starts."""
    n_particles = np.int64(parcel[at])
    n_spheres = np.int64(parcel[at + 1])
    counts = np.empty(n_particles, dtype=np.int64)
    footprints = np.empty((n_particles, 4))
    at += 2
    for p in range(n_particles):
        counts[p] = np.int64(parcel[at])
        for d in range(4):
            footprints[p, d] = parcel[at + 1 + d]
        at += PARTICLE_WIDTH
    keys = np.empty(n_spheres, dtype=np.int64)
    centres = np.empty((n_spheres, 3))
    radii = np.empty(n_spheres)
    for j in range(n_spheres):
        keys[j] = np.int64(parcel[at])
        for d in range(3):
            centres[j, d] = parcel[at + 1 + d]
        radii[j] = parcel[at + 4]
        at += SPHERE_WIDTH
    _insert(local, (counts, footprints, keys, centres, radii), first_row, rows, settles)
    return at


@jit
def _insert(local, parcel, first_row, rows, settles):
    """Committed particles of other ranks, ``parcel = (counts, footprints, keys, centres, radii)`` (particle
    ``k`` has ``counts[k]`` spheres, the next of ``keys``, ``centres`` (wrapped) and ``radii``, and footprint
    ``footprints[k]``), join the local sediment; the present rows from ``first_row`` on whose rectangle
    meets one of them are withdrawn first (at the count of descents ``settles[0]``)."""
    counts, _, _, _, radii = parcel
    if counts.shape[0] == 0:
        return
    first = _reserve(local, radii.shape[0])
    insert_committed(parcel, first, local, first_row, rows, settles[0])


@jit
def _reserve(local, n_spheres):
    """Room for ``n_spheres`` more spheres in the local sediment (its arrays doubled when full); returns
    the first free slot."""
    need = local.n_used + n_spheres
    capacity = local.radius.shape[0]
    if need > capacity:
        capacity = max(need, 2 * capacity)
        local.centre = with_rows_filled(local.centre, capacity, local.n_used, 0.0)
        local.radius = with_rows_filled(local.radius, capacity, local.n_used, 0.0)
        local.key = with_rows_filled(local.key, capacity, local.n_used, -1)
        g = local.grid
        set_grid_arrays(g, g.geom, g.igeom, g.head, g.col_top, with_rows_filled(g.nxt, capacity, g.nxt.shape[0], -1),
                        g.hkeys, g.hval, g.counts)
    first = local.n_used
    local.n_used = need
    return first


# ------------------------------------------------------------- the caller's steps (fetching)
@jit
def settle_again(row, particles, settings, rows, plan, held, settles):
    """Settle row ``row`` (its particle at the frontier) again on what the local sediment ``held`` (a
    :data:`Held`) holds now, with the grid's cell of its turn.  Returns the local sediment then."""
    local = _local(held, plan.n_max)
    _set_cell(local, _cell_after(plan, rows.index[row] - 1))
    withdraw(row, rows, local.centre, local.radius, grid_arrays(local.grid), settles[0])
    _settle_span(local, row, row + 1, particles, settings, rows, plan, np.zeros(N_TALLIES), settles)
    return _held(local)


@jit
def insert_parcel(parcel, first_row, rows, held, n_max, settles):
    """:func:`_insert` of ``parcel`` (``counts, footprints, keys, centres, radii``) into the local sediment
    ``held`` (a :data:`Held`), from the caller.  Returns the local sediment then."""
    local = _local(held, n_max)
    _insert(local, parcel, first_row, rows, settles)
    return _held(local)
