"""One time-stepping aggregation on several MPI ranks: the domain of a decomposed run.

:func:`parsim.core.ts.simulate_ts` runs unchanged on every rank of a communicator when it
is given a :class:`DecomposedDomain` (the interface is in :mod:`parsim.core.ts.domain`):

- the box is cut into ``k^d`` tiles, at least twice as wide as the halo a minimisation needs
  (at most ``MAX_TILES_PER_SIDE`` per side); the ranks form a Cartesian grid and each owns a
  block of whole tiles and the spheres whose centres lie in it
  (:class:`parsim.parallel.decomposition.Decomposition`).  A box with fewer tiles per side
  than the rank grid has ranks along an axis is not decomposed: every rank runs the whole
  task in one tile, as one process does (the same result, bitwise).  The tiles only say who computes
  what: the minimiser's inner and outer rectangles (section 3.3) are chosen per minimisation
  from the interacting spheres, as on one process, so the physics does not depend on the ranks;
- after each free flight the spheres migrate to their new owners
  (:func:`parsim.parallel.migration.migrate`); when the owned spheres differ by more than
  ``REBALANCE_ABOVE`` (max / mean) the tile blocks are first moved to even them out;
- the halos of contact searches, quiet-step bounds and minimisations are
  :class:`parsim.parallel.halo.HaloPlan` s; in a minimisation every DAHA iteration sends each
  neighbour, in one message from inside the jitted loop (:mod:`parsim.core.kernel_mpi`), the
  ghost rows that moved (position, velocity, damping), and reduces the stopping tests; what runs in Python
  (the halo test before a pair search) reduces through :class:`_ProblemExchange`;
- the radii, masses, cluster labels and links are known on every rank: new links are
  gathered on all ranks each time step (a few per sphere over a whole run), so the cluster
  relabelling is the same deterministic union-find everywhere, and each merged cluster's
  velocity comes from one global mass-weighted reduction (eq. 2.9).

Results agree with one process to round-off, not bitwise: forces on a sphere and the
reductions sum in an order that depends on how the spheres are split, and the quiet-step
horizon is bounded by the narrowest rank slab.
"""

import math
import time
from collections import defaultdict

import numpy as np
from mpi4py import MPI

from parsim.core import kernel_mpi
from parsim.core.ts.daha import motion_width
from parsim.parallel.decomposition import Decomposition
from parsim.parallel.halo import HaloPlan
from parsim.parallel.migration import migrate

#: Most tiles per side (so at most 64 ranks along an axis): blocks fine enough to balance,
#: few enough that balancing and ownership stay cheap.
MAX_TILES_PER_SIDE = 64
#: Tiles are at least this many halo widths wide, leaving room for the halo to grow.
TILE_WIDTH_IN_HALOS = 2.0
#: Move the tile blocks when the most spheres a rank owns exceeds the mean by this factor.
REBALANCE_ABOVE = 1.25


class Traffic:
    """What this rank sent and how long it waited, per kind of communication: ``halo``
    (ghost rows), ``reduction`` (sums and maxima), ``gather`` (rows gathered on every rank:
    new links, reflections, multipliers), ``migration`` (spheres changing owner).
    ``calls[kind]``, ``bytes[kind]`` (sent by this rank) and ``seconds[kind]`` accumulate."""

    def __init__(self):
        self.calls = defaultdict(int)
        self.bytes = defaultdict(int)
        self.seconds = defaultdict(float)
        self.kernel = np.zeros(kernel_mpi.N_TALLIES)  # what the jitted iterations sent (kernel_mpi)

    def totals(self):
        """``calls``, ``bytes`` and ``seconds`` per kind, the jitted iterations' included: their
        ghost rows as ``halo``, their maxima as ``reduction``; ``calls`` counts the calls made from
        Python only."""
        calls, nbytes, seconds = dict(self.calls), dict(self.bytes), dict(self.seconds)
        tally = self.kernel
        nbytes["halo"] = nbytes.get("halo", 0) + int(tally[kernel_mpi.BYTES])
        nbytes["reduction"] = nbytes.get("reduction", 0) + 8 * int(tally[kernel_mpi.REDUCTIONS])
        seconds["halo"] = seconds.get("halo", 0.0) + float(tally[kernel_mpi.HALO_SECONDS])
        seconds["reduction"] = seconds.get("reduction", 0.0) + float(tally[kernel_mpi.REDUCTION_SECONDS])
        return calls, nbytes, seconds

    def add(self, kind, nbytes, started):
        self.calls[kind] += 1
        self.bytes[kind] += int(nbytes)
        self.seconds[kind] += time.perf_counter() - started


class _MeteredHalo:
    """A :class:`HaloPlan` whose exchanges are counted in a :class:`Traffic`."""

    def __init__(self, plan: HaloPlan, traffic: Traffic):
        self.plan = plan
        self.traffic = traffic
        self.n_ghost = plan.n_ghost
        self.ghost_global_id = plan.ghost_global_id
        self.rows_sent = sum(len(rows) for rows in plan.send_indices)

    def exchange(self, values):
        started = time.perf_counter()
        ghosts = self.plan.exchange(values)
        row_bytes = 8 * int(np.prod(np.shape(values)[1:]))
        self.traffic.add("halo", self.rows_sent * row_bytes, started)
        return ghosts


class _ProblemExchange:
    """DAHA's exchange (:class:`parsim.core.ts.daha.SerialExchange`) over a halo plan."""

    def __init__(self, halo: _MeteredHalo, domain: "DecomposedDomain", margin: float):
        self.domain = domain
        self.margin = margin
        if domain.size > 1:
            self.kernel_halo = halo.plan.kernel_halo(motion_width(domain.dimension), domain.traffic.kernel)
        else:
            self.kernel_halo = kernel_mpi.no_halo()

    def sum(self, value):
        return self.domain.sum(value)

    def max(self, value):
        return self.domain.max(value)


class DecomposedDomain:
    """The spheres of one run shared out among the ranks of ``comm`` (collective; every rank
    builds it with the same arguments and passes it to ``simulate_ts``)."""

    def __init__(self, comm: MPI.Comm, box_length: float, dimension: int):
        self.comm = comm
        self.size = comm.Get_size()
        self.peers = self.size > 1  # whether anything is sent at all
        self.box_length = float(box_length)
        self.dimension = dimension
        self.decomposition = None
        self.traffic = Traffic()

    def distribute(self, X, V, tile_side):
        """This rank's spheres, at the start of the run; ``tile_side`` is the halo width of a
        minimisation, a tile is ``TILE_WIDTH_IN_HALOS`` of them wide."""
        k = max(1, min(MAX_TILES_PER_SIDE, int(self.box_length // (TILE_WIDTH_IN_HALOS * tile_side))))
        if k < max(MPI.Compute_dims(self.size, self.dimension)):  # too few tiles for a block per rank
            self._run_whole()
            k = 1
        self.decomposition = Decomposition(self.comm, self.box_length, self.dimension, k)
        mine = np.flatnonzero(self.decomposition.owner_of(X) == self.decomposition.rank)
        return mine.astype(np.int64), X[mine].copy(), V[mine].copy()

    def _run_whole(self):
        """Every rank runs the whole task on its own, in one tile: nothing is shared."""
        self.comm = MPI.COMM_SELF
        self.size = 1
        self.peers = False

    def redistribute(self, global_id, X, V):
        if self.size == 1:  # the rows stay sorted by global id: nothing to sort or send
            return global_id, X, V
        decomposition = self.decomposition
        if decomposition.imbalance(X.shape[0]) > REBALANCE_ABOVE:
            decomposition.set_tile_splits(decomposition.balanced_splits(decomposition.tile_counts(X)))
        started = time.perf_counter()
        owner = decomposition.owner_of(X)
        leaving = int(np.count_nonzero(owner != decomposition.rank))
        global_id, arrays = migrate(decomposition, global_id, {"position": X, "velocity": V}, owner)
        self.traffic.add("migration", leaving * 8 * (1 + 2 * self.dimension), started)
        return global_id, arrays["position"], arrays["velocity"]

    def hold_everything(self, global_id, X, V):
        """From here on every rank holds every sphere and runs alone (collective): the rows of
        all ranks, sorted by global id."""
        ids, X, V = self.gather(global_id), self.gather(X), self.gather(V)
        order = np.argsort(ids)
        self.decomposition.free()
        self._run_whole()
        self.decomposition = Decomposition(self.comm, self.box_length, self.dimension, 1)
        return ids[order], X[order], V[order]

    @property
    def max_halo_width(self):
        """The narrowest rank slab along the axes shared among ranks (ghosts come from adjacent ranks)."""
        d = self.decomposition
        slabs = [np.diff(split).min() * d.tile_side for split, parts in zip(d.tile_splits, d.dims) if parts > 1]
        return min(slabs, default=math.inf)

    def ghosts(self, X, global_id, width):
        return _MeteredHalo(HaloPlan(self.decomposition, X, width, global_id), self.traffic)

    def problem_exchange(self, halo, margin):
        return _ProblemExchange(halo, self, margin if self.size > 1 else math.inf)

    def _reduce(self, value, op):
        started = time.perf_counter()
        total = self.comm.allreduce(value, op=op)
        self.traffic.add("reduction", 8 * self.peers, started)
        return total

    def sum(self, value):
        return self._reduce(value, MPI.SUM)

    def max(self, value):
        return self._reduce(value, MPI.MAX)

    def min(self, value):
        return self._reduce(value, MPI.MIN)

    def _reduce_array(self, values, op):
        started = time.perf_counter()
        values = np.ascontiguousarray(values, dtype=np.float64)
        reduced = np.empty_like(values)
        self.comm.Allreduce(values, reduced, op=op)
        self.traffic.add("reduction", values.nbytes * self.peers, started)
        return reduced

    def sum_array(self, values):
        return self._reduce_array(values, MPI.SUM)

    def gather(self, rows):
        started = time.perf_counter()
        rows = np.asarray(rows)
        flat = self.decomposition.allgatherv_rows(rows.reshape(rows.shape[0], int(np.prod(rows.shape[1:]))))
        self.traffic.add("gather", rows.nbytes * (self.size - 1), started)
        return flat.reshape(-1, *rows.shape[1:])

    def imbalance(self, work):
        started = time.perf_counter()
        imbalance = self.decomposition.imbalance(work)
        self.traffic.add("reduction", 16 * self.peers, started)
        return imbalance

    def close(self):
        """Release the Cartesian communicator (collective)."""
        if self.decomposition is not None:
            self.decomposition.free()
            self.decomposition = None
