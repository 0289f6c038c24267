"""Halo (ghost) exchange between adjacent ranks, planned once per configuration.

In the almost-rigid formulation (section 3.3, Fig. 3) a sphere of an inner rectangle
interacts only with spheres of its own and of the surrounding (outer) rectangles.  When
the tiles are shared out among ranks, the outer rectangles of a rank's edge tiles belong
to the adjacent ranks, corners included; their spheres are this rank's *ghosts*.

A ghost of a rank is a sphere owned by another rank whose centre (clamped into the box, as
for ownership) lies closer than ``width`` to the rank's sub-box along every axis, i.e. in
the slabs and corner blocks of thickness ``width`` around it.  With ``width`` equal to the
tile side these are exactly the spheres of the tiles adjacent to the sub-box.  ``width``
may not exceed the narrowest rank slab of an axis, so ghosts always come from adjacent ranks.

:class:`HaloPlan` finds, once, which owned rows go to which neighbour and how many rows
come back; the buffers are then reused by every :meth:`HaloPlan.exchange` (one per
minimiser iteration).  On one rank there are no neighbours and no ghosts: the same code
runs and exchanges nothing.
"""

import numpy as np
from mpi4py import MPI

from parsim.core import kernel_mpi
from parsim.parallel.decomposition import Decomposition, checked_positions

kernel_mpi.bind_library()  # the jitted loops' MPI calls go to the library mpi4py has just loaded

COUNT_TAG = 21
ROWS_TAG = 22


class HaloPlan:
    """Which owned spheres are ghosts of which neighbour, and buffers to send them.

    Built collectively from the owned ``positions`` (n, d) and their ``global_id`` (n,)
    right after :func:`parsim.parallel.migration.migrate`; stale once spheres change
    owner or the tile splits change.

    Attributes
    ----------
    send_indices : for each of ``decomposition.neighbours``, the owned rows it receives, ascending.
    ghost_counts : for each neighbour, the number of ghost rows it sends here.
    ghost_source : the rank each ghost row comes from, shape ``(n_ghost,)``.
    ghost_global_id : the global id of each ghost row, shape ``(n_ghost,)``.

    Ghost rows are ordered by neighbour rank, then in the sender's row order.
    """

    def __init__(self, decomposition: Decomposition, positions, width: float, global_id):
        self.decomposition = decomposition
        positions = checked_positions(positions, decomposition.dimension)
        self.n_owned = positions.shape[0]
        self.width = _checked_width(decomposition, width)
        global_id = np.asarray(global_id, dtype=np.int64)
        if global_id.shape != (self.n_owned,):
            raise ValueError(f"global_id: need shape ({self.n_owned},) like positions, got {global_id.shape}")
        inside = np.clip(positions, 0.0, decomposition.box_length)  # the position that decides ownership
        lower, upper = decomposition.lower, decomposition.upper
        self.send_indices = [_rows_near_neighbour(inside, lower, upper, offset, self.width)
                             for offset in decomposition.neighbour_offsets]
        send_counts = np.array([len(rows) for rows in self.send_indices], dtype=np.int64)
        self.ghost_counts = self._swap_counts(send_counts)
        self.n_ghost = int(self.ghost_counts.sum())
        self.ghost_source = np.repeat(decomposition.neighbours, self.ghost_counts)
        self._send_parts = _consecutive_slices(send_counts)
        self._receive_parts = _consecutive_slices(self.ghost_counts)
        self._buffers = {}  # row shape -> (send, receive) float64 buffers, made on first use
        self.ghost_global_id = self._exchange_into(global_id, *self._new_buffers((), np.int64))

    def exchange(self, values) -> np.ndarray:
        """The ghost rows ``(n_ghost, ...)`` of ``values`` (owned rows ``(n_owned, ...)``, float64).

        Collective among neighbours.  The result is the plan's receive buffer for that row
        shape: the next exchange of same-shaped values overwrites it (copy it to keep it).
        """
        values = np.asarray(values, dtype=np.float64)
        if values.ndim == 0 or values.shape[0] != self.n_owned:
            raise ValueError(f"values: first axis must have the {self.n_owned} owned rows, got shape {values.shape}")
        trailing = values.shape[1:]
        if trailing not in self._buffers:
            self._buffers[trailing] = self._new_buffers(trailing, np.float64)
        return self._exchange_into(values, *self._buffers[trailing])

    def kernel_halo(self, width: int, tally=None) -> kernel_mpi.Halo:
        """This plan as a halo of :mod:`parsim.core.kernel_mpi`, for exchanges from jitted loops:
        rows of up to ``width`` floats, each with its place, and a count per neighbour; what they
        send is added to ``tally`` (``N_TALLIES`` floats)."""
        comm = self.decomposition.comm
        send_counts = np.array([len(rows) for rows in self.send_indices], dtype=np.int64)
        rows = np.concatenate([np.asarray(r, dtype=np.int64) for r in self.send_indices] + [np.zeros(0, np.int64)])
        n_neighbours = len(self.decomposition.neighbours)
        n_requests = max(2 * n_neighbours, 1)
        return kernel_mpi.Halo(
            comm=_handle(comm), size=np.int64(comm.Get_size()),
            neighbours=np.asarray(self.decomposition.neighbours, dtype=np.int32), rows=rows,
            send_ptr=_offsets(send_counts), recv_ptr=_offsets(self.ghost_counts),
            send=np.zeros(len(rows) * (width + 1) + n_neighbours),
            receive=np.zeros(self.n_ghost * (width + 1) + n_neighbours),
            request_slots=np.zeros(n_requests, dtype=np.int64), request_bytes=np.int64(MPI._sizeof(MPI.Request)),
            statuses=np.zeros(n_requests * kernel_mpi.STATUS_INTS, dtype=np.int32), double=_handle(MPI.DOUBLE),
            maximum=_handle(MPI.MAX), total=_handle(MPI.SUM),
            tally=np.zeros(kernel_mpi.N_TALLIES) if tally is None else tally)

    def _new_buffers(self, trailing: tuple, dtype) -> tuple[np.ndarray, np.ndarray]:
        """Send buffer (rows for all neighbours, back to back) and receive buffer (the ghosts)."""
        n_send = sum(len(rows) for rows in self.send_indices)
        return np.empty((n_send, *trailing), dtype=dtype), np.empty((self.n_ghost, *trailing), dtype=dtype)

    def _exchange_into(self, values, send, receive) -> np.ndarray:
        """Post every receive, pack and send each neighbour's rows, wait for all; returns ``receive``."""
        comm = self.decomposition.comm
        requests = []
        for rank, part in zip(self.decomposition.neighbours, self._receive_parts):
            if part.stop > part.start:
                requests.append(comm.Irecv(receive[part], source=int(rank), tag=ROWS_TAG))
        for rank, rows, part in zip(self.decomposition.neighbours, self.send_indices, self._send_parts):
            if len(rows):
                np.take(values, rows, axis=0, out=send[part], mode="clip")  # "clip": no hidden copy
                requests.append(comm.Isend(send[part], dest=int(rank), tag=ROWS_TAG))
        MPI.Request.Waitall(requests)
        return receive

    def _swap_counts(self, send_counts: np.ndarray) -> np.ndarray:
        """Tell each neighbour how many rows it will get; returns how many each sends here."""
        comm = self.decomposition.comm
        received = np.empty_like(send_counts)
        requests = []
        for i, rank in enumerate(self.decomposition.neighbours):
            requests.append(comm.Irecv(received[i:i + 1], source=int(rank), tag=COUNT_TAG))
            requests.append(comm.Isend(send_counts[i:i + 1], dest=int(rank), tag=COUNT_TAG))
        MPI.Request.Waitall(requests)
        return received


def _rows_near_neighbour(positions, lower, upper, offset, width) -> np.ndarray:
    """Rows closer than ``width`` to the side, edge or corner shared with the neighbour at grid ``offset``.

    Along an axis with offset +1 the row must lie within ``width`` below ``upper``, with -1
    within ``width`` above ``lower``; axes with offset 0 are shared whole.
    """
    near = np.ones(positions.shape[0], dtype=bool)
    for axis, step in enumerate(offset):
        if step > 0:
            near &= positions[:, axis] > upper[axis] - width
        elif step < 0:
            near &= positions[:, axis] < lower[axis] + width
    return np.flatnonzero(near)


def _checked_width(decomposition: Decomposition, width) -> float:
    """``width`` if positive and no wider than the narrowest rank slab of any axis split among ranks."""
    width = float(width)
    slabs = [np.diff(split).min() * decomposition.tile_side
             for split, parts in zip(decomposition.tile_splits, decomposition.dims) if parts > 1]
    narrowest = min(slabs, default=np.inf)
    if not 0.0 < width <= narrowest:
        raise ValueError(f"width: must be > 0 and at most the narrowest rank slab ({narrowest:g}, ghosts come "
                         f"only from adjacent ranks), got {width:g}")
    return width


def kernel_link(comm, n_requests: int) -> tuple:
    """A link of :mod:`parsim.core.kernel_mpi` over ``comm``, for messages and reductions from jitted loops
    with up to ``n_requests`` requests at a time."""
    n_requests = max(int(n_requests), 1)
    return (_handle(comm), np.int64(comm.Get_size()), _handle(MPI.DOUBLE), _handle(MPI.MIN),
            np.zeros(n_requests, dtype=np.int64), np.int64(MPI._sizeof(MPI.Request)),
            np.zeros(n_requests * kernel_mpi.STATUS_INTS, dtype=np.int32), np.zeros(1, dtype=np.int32), np.zeros(2),
            np.zeros(kernel_mpi.N_LINK_TALLIES))


def _handle(mpi_object) -> np.int64:
    """The library's handle of ``mpi_object`` as a signed 64-bit integer (mpi4py gives it unsigned)."""
    value = MPI._handleof(mpi_object)
    return np.int64(value - (1 << 64) if value >= (1 << 63) else value)


def _offsets(counts) -> np.ndarray:
    """``[0, c0, c0 + c1, ...]``: where each neighbour's rows start, and the end."""
    return np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


def _consecutive_slices(counts: np.ndarray) -> list[slice]:
    """Slices of consecutive blocks of ``counts`` rows."""
    ends = np.cumsum(counts)
    return [slice(int(end - count), int(end)) for count, end in zip(counts, ends)]
