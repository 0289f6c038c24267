"""One sediment spread over MPI ranks, bitwise the serial sediment.

The box is cut across x into one block of columns per rank (:class:`BlockLayout`).  A rank owns
the particles dropped in its block and settles them ahead of their turn on its local sediment
(:mod:`parsim.core.sdbd.blocks`): the substrate and committed particles in its *region* (the block
widened by the halo), and its own particles.  The serial drop order defines the answer; the ranks
go through it in rounds, each over a window of drop indices starting at the *frontier* (every
particle before it is committed, on every rank):

1. each rank settles its absent particles of the window in drop order;
2. each sends the footprints of its window's particles to the ranks whose region they meet;
3. each finds its first particle that cannot be committed once all before it are
   (:func:`parsim.core.sdbd.blocks.first_failure`): its rectangle leaves the region, or a particle
   of another rank dropped between the frontier and it has a sphere in its rectangle, or it stopped
   at the event limit; the smallest over the ranks (one reduction) is the new frontier;
4. a particle in conflict is withdrawn and settled again in the next round, when it is at the
   frontier and so exact; one whose rectangle left the region is settled again at once on the
   committed spheres its owner fetches from every rank, until its rectangle stays in what its
   owner holds;
5. each rank sends its newly committed particles to the ranks whose region holds one of their
   sphere centres, and inserts those it receives; they withdraw the present particles they touch.

What a rank holds: the inputs of its own particles alone (:func:`deposit_streamed` reads the
particles in chunks, validates them, surveys what the decomposition needs of all and keeps its own;
a heap, whose blocks depend on its drop points, or a box too narrow to split needs a second
reading), their settled spheres, and the committed spheres of the others in its region; so about
N/K of the sediment and a border.

Why it is the serial sediment: a descent reads only sediment spheres in grid cells that meet its
rectangle, and the grid's lists hold them in the serial order (keys).  A particle committed at
the frontier was settled on a local sediment that, within its rectangle widened by a column, held
every sphere of the particles before it: those of its own rank (kept so by the withdrawals), the
committed ones of the others (the halo holds all in the region, the rectangle lies in the region,
and those committed after it was settled withdrew it if they touched its rectangle), and none of
the particles being settled by other ranks (checked in 3).  So its descent read what the serial
descent reads, step by step, and gives the same bits.
"""

import math
import time
from dataclasses import dataclass

import numpy as np

from parsim.core import sdbd
from parsim.core.sdbd import blocks, grid as grid_module
from parsim.core.sdbd.blocks import FAIL_CONFLICT, FAIL_REGION, FINAL, N_FAILURES, STOPPED
from parsim.core.sdbd.constants import LATERAL_NONE, LATERAL_PERIODIC, N_EVENT_KINDS
from parsim.errors import JobError
from parsim.parallel.collective import abort_if_alone

__all__ = ["BlockLayout", "CellGrowth", "deposit_decomposed", "deposit_streamed", "DecomposedDeposition",
           "DecompositionError", "InvalidDeposition", "default_halo", "drop_order", "spans"]

#: particles per rank in a round's window of drop indices, on a block of REFERENCE_COLUMNS grid columns;
#: a smaller block takes a window smaller by the square root of its area (default_window)
WINDOW_PER_RANK = 512
REFERENCE_COLUMNS = 45_000  # a block of 150 x 300 sphere diameters
SMALLEST_WINDOW = 64
#: rows settled between two tests of whether every rank has settled its window
AHEAD_ROWS = 8


class InvalidDeposition(JobError, ValueError):
    """An argument of :func:`deposit_decomposed` that :func:`parsim.core.sdbd.deposit` would refuse too
    (a ValueError, and a JobError: one line names it when a rank alone meets it)."""


class DecompositionError(RuntimeError):
    """A committed particle's descent read sediment that changed afterwards (a defect of the
    decomposition, found by the checks of ``deposit_decomposed(..., check=True)``)."""


def default_halo(prep, largest_scale, largest_cell) -> float:
    """The halo (how far a region reaches beyond its block) for a deposition of particles of size factors
    up to ``largest_scale`` and a grid's cell that grows to ``largest_cell``: four columns and twice the
    largest particle extent, 5 diameters for spheres, wider than what nearly every particle's descent
    reads beyond its drop point in a box (a heap's particles roll farther; their owners fetch what they
    miss).  On 2 ranks it was the fastest of 3 to 9 diameters (docs/benchmarks.md)."""
    extent = 0.0
    for s in range(len(prep.shape_start) - 1):
        a, b = prep.shape_start[s], prep.shape_start[s + 1]
        extent = max(extent, float(np.max(np.linalg.norm(prep.shape_offsets[a:b], axis=1) + prep.shape_radii[a:b])))
    return 4.0 * largest_cell + 2.0 * extent * largest_scale


def default_window(layout, prep, cell) -> int:
    """Drop indices per rank in a round: WINDOW_PER_RANK on a block of REFERENCE_COLUMNS columns of side
    ``cell``, fewer by the square root of a smaller block's area, a power of two, at least SMALLEST_WINDOW.
    More particles dropped at once on a small block conflict more often: on 2 ranks and 10^6 spheres,
    128 was the fastest of 64-512 in a box of 100 x 100 diameters (7.2 s against 8.4 s with 512),
    256 in one of 200 x 200 and 512 in one of 300 x 300 (docs/benchmarks.md)."""
    width = layout.length / layout.n_blocks
    depth = float(prep.box_upper_xy[1] - prep.box_lower_xy[1]) if prep.lateral != LATERAL_NONE \
        else layout.length  # a heap: about as deep as its drop area is wide
    columns = max(width * depth / cell**2, 1.0)
    window = WINDOW_PER_RANK * min(1.0, math.sqrt(columns / REFERENCE_COLUMNS))
    return max(SMALLEST_WINDOW, 1 << int(math.floor(math.log2(max(window, 1.0)))))


class CellGrowth:
    """The grid's cell after each particle's arrival (the largest sphere diameter so far, at least the
    first cell), kept as the particles at which it grows: a few numbers, whatever the number of
    particles.  :meth:`add` takes the particles in drop order, chunk after chunk."""

    def __init__(self, first_cell):
        self.at = [0]  # particle indices where the cell changes (0: its first value)
        self.cell = [float(first_cell)]
        self.seen = 0

    def add(self, prep) -> None:
        """The particles of ``prep`` (a chunk), the next in drop order."""
        diameters = 2.0 * prep.particle_scale * prep.shape_largest_radius[prep.particle_shape]
        running = np.maximum.accumulate(np.maximum(diameters, self.cell[-1]))
        grows = np.flatnonzero(np.diff(np.concatenate([[self.cell[-1]], running])) > 0)
        self.at += (self.seen + grows).tolist()
        self.cell += running[grows].tolist()
        self.seen += len(diameters)

    def after(self, particle) -> float:
        """The cell once ``particle`` has arrived."""
        return self.cell[np.searchsorted(self.at, particle, side="right") - 1]

    def growth(self) -> np.ndarray:
        """The particles larger than every one before them (the cell grows when they arrive)."""
        return np.array(self.at[1:], dtype=np.int64)


class BlockLayout:
    """Blocks of columns across x, one per rank that owns particles.

    A periodic or walled box is cut into equal blocks; a heap's drop area is, and its outer blocks
    reach to infinity.  ``region(k)`` is block ``k`` widened by ``halo`` on both sides (on a
    periodic box's circle, the whole circle if that covers it)."""

    def __init__(self, lateral, box_lower_xy, box_upper_xy, drop_x_range, n_blocks, halo):
        self.periodic = lateral == LATERAL_PERIODIC
        self.n_blocks = int(n_blocks)
        self.halo = float(halo)
        if lateral == LATERAL_NONE:  # the drop points' range of x
            low, high = (float(drop_x_range[0]), float(drop_x_range[1])) if drop_x_range[0] <= drop_x_range[1] \
                else (0.0, 1.0)
        else:
            low, high = float(box_lower_xy[0]), float(box_upper_xy[0])
        self.low, self.length = low, high - low
        self.edges = low + self.length * np.arange(self.n_blocks + 1) / self.n_blocks
        if not self.periodic:
            self.edges[0], self.edges[-1] = -np.inf, np.inf

    def owners(self, x) -> np.ndarray:
        """The block of each drop abscissa."""
        if self.periodic:
            x = self.low + np.mod(np.asarray(x) - self.low, self.length)
        inner = self.edges[1:-1]
        return np.searchsorted(inner, x, side="right").astype(np.int64)

    def region(self, k) -> np.ndarray:
        """``[x_low, x_high]`` of block ``k`` widened by the halo."""
        a, b = self.edges[k] - self.halo, self.edges[k + 1] + self.halo
        if self.periodic and b - a >= self.length:
            b = a + self.length
        return np.array([a, b])


@dataclass
class DecomposedDeposition:
    """One rank's share of a deposition spread over ranks: its committed particles (rows, in drop
    order: their places in it, their shapes and size factors, and how they settled) and what the run
    counted.  :meth:`gather` assembles the serial result on one rank."""

    index: np.ndarray
    particle_shape: np.ndarray
    particle_scale: np.ndarray
    center_of_mass: np.ndarray
    rotation: np.ndarray
    contacts: np.ndarray
    state: np.ndarray
    event_counts: np.ndarray
    steps: np.ndarray
    sphere_count: np.ndarray
    positions: np.ndarray
    radii: np.ndarray
    stopped_at: int
    clocked_seconds: float
    tally: dict

    @property
    def particle(self) -> np.ndarray:
        """The particle (drop index) of each sphere."""
        return np.repeat(self.index, self.sphere_count)

    def gather(self, comm, root=0):
        """The :class:`parsim.core.sdbd.DepositionResult` of the whole sediment on rank ``root``
        (None on the others)."""
        parts = comm.gather(self, root=root)
        if comm.Get_rank() != root:
            return None

        def joined(name):
            return np.concatenate([getattr(p, name) for p in parts])

        index = joined("index")
        counts = joined("sphere_count")
        order, take = drop_order(index, counts)
        return sdbd.DepositionResult(
            positions=joined("positions")[take], radii=joined("radii")[take],
            particle=np.repeat(index[order], counts[order]), center_of_mass=joined("center_of_mass")[order],
            rotation=joined("rotation")[order], contacts=joined("contacts")[order], state=joined("state")[order],
            event_counts=joined("event_counts")[order], steps=joined("steps")[order], stopped_at=self.stopped_at,
            clocked_seconds=self.clocked_seconds)


def deposit_decomposed(comm, shape_offsets, shape_radii, shape_start, particle_shape, particle_scale,
                       particle_rotation, particle_drop_xy, box_lower_xy, box_upper_xy, lateral, floor,
                       **options) -> DecomposedDeposition:
    """:func:`parsim.core.sdbd.deposit` spread over the ranks of ``comm`` (collective; every rank
    passes the same arguments): each rank returns its share, whose :meth:`~DecomposedDeposition.gather`
    is bitwise the serial result.  ``options``: those of :func:`deposit_streamed`."""

    def chunks():
        yield particle_shape, particle_scale, particle_rotation, particle_drop_xy

    return deposit_streamed(comm, shape_offsets, shape_radii, shape_start, chunks, box_lower_xy, box_upper_xy,
                            lateral, floor, **options)


def deposit_streamed(comm, shape_offsets, shape_radii, shape_start, particle_chunks, box_lower_xy, box_upper_xy,
                     lateral, floor, trial_angle=1e-2, cycle_n=4, cycle_eps=1e-3, max_events_per_particle=100_000,
                     clock_from_particle=-1, wall_contact=sdbd.WALL_FRICTIONLESS, container=sdbd.CONTAINER_BOX,
                     cylinder=None, substrate_positions=None, substrate_radii=None, halo=None,
                     window_per_rank=None, check=False) -> DecomposedDeposition:
    """:func:`deposit_decomposed` of particles that no rank holds all of: ``particle_chunks()`` yields
    ``(particle_shape, particle_scale, particle_rotation, particle_drop_xy)`` of consecutive particles in
    drop order, the same on every rank, and starts again from the first at every call (it is called
    once, twice for a heap or a box too narrow to split); each rank keeps the inputs of the particles
    it owns.  The other arguments are those of
    :func:`parsim.core.sdbd.deposit`, and ``halo`` is how far a rank's region reaches beyond its block
    (default :func:`default_halo`); a box whose blocks would be narrower than the halo is settled
    whole by rank 0.  ``window_per_rank`` sets the drop indices of a round (that many per rank; default
    :func:`default_window`).
    ``clocked_seconds`` (of the gathered result) is the wall-clock time from the round in which
    particle ``clock_from_particle`` was committed to the end (NaN when it is -1).
    With ``check``, every particle's owner fingerprints the sediment its descent read when it settles
    it and again when it commits it, and raises :class:`DecompositionError` if they differ."""
    settings = dict(trial_angle=trial_angle, cycle_n=cycle_n, cycle_eps=cycle_eps,
                    max_events_per_particle=max_events_per_particle, wall_contact=wall_contact, container=container,
                    cylinder=cylinder, substrate_positions=substrate_positions, substrate_radii=substrate_radii)
    started = time.perf_counter()
    try:
        try:
            survey = _Survey(shape_offsets, shape_radii, shape_start, particle_chunks, box_lower_xy, box_upper_xy,
                             lateral, floor, settings, comm.Get_size(), comm.Get_rank())
            halo = default_halo(survey.prep, survey.largest_scale, survey.cells.cell[-1]) if halo is None \
                else float(halo)
            if not (np.isfinite(halo) and halo > 0):
                raise ValueError(f"halo must be a finite length > 0, got {halo}")
        except ValueError as error:
            raise InvalidDeposition(str(error)) from error
        prep = survey.prep
        layout = BlockLayout(prep.lateral, prep.box_lower_xy, prep.box_upper_xy, survey.drop_x_range,
                             comm.Get_size(), halo)
        if layout.length / layout.n_blocks < halo:  # blocks narrower than the halo: the task runs whole
            layout = BlockLayout(prep.lateral, prep.box_lower_xy, prep.box_upper_xy, survey.drop_x_range, 1, halo)
        own = survey.own_particles(layout, comm.Get_rank())
        surveyed = time.perf_counter() - started
        if window_per_rank is None:
            window_per_rank = default_window(layout, prep, survey.cells.cell[-1])
        share = _RankRun(comm, own, survey, layout, max(1, int(window_per_rank)) * layout.n_blocks, check,
                         int(clock_from_particle)).run()
        share.tally["survey_seconds"] = surveyed  # reading every particle's inputs, on every rank
        return share
    except BaseException as error:
        abort_if_alone(comm, error)  # the other ranks would wait in a collective: end them all, with one line
        raise


class _Survey:
    """A first pass over the particles, chunk by chunk: each chunk validated as :func:`parsim.core.sdbd.deposit`
    validates its arguments, and what the decomposition needs of all of them (their number and
    spheres, the range of drop points, the largest size factor, the growth of the grid's cell).
    In a box or a cylinder, whose blocks do not depend on the particles, it also keeps the particles
    of ``rank``'s block among ``n_blocks``, so that a second pass is needed only for a heap or a box
    too narrow to split."""

    def __init__(self, shape_offsets, shape_radii, shape_start, particle_chunks, box_lower_xy, box_upper_xy,
                 lateral, floor, settings, n_blocks, rank):
        self.shapes = (shape_offsets, shape_radii, shape_start)
        self.container = (box_lower_xy, box_upper_xy, lateral, floor)
        self.settings = settings
        self.particle_chunks = particle_chunks
        self.prep, self.cells, self.kept = None, None, None
        self.n_particles = self.n_spheres = 0
        self.largest_scale = 0.0
        self.drop_x_range = (np.inf, -np.inf)
        for chunk in self._prepared_chunks():
            self._add(chunk, n_blocks, rank)
        if self.prep is None:  # no particle at all: deposit's own checks and error
            self.prep = sdbd.prepare_deposition(*self.shapes, np.zeros(0, dtype=np.int64), np.zeros(0),
                                                np.zeros((0, 4)), np.zeros((0, 2)), *self.container, **settings)
            self.cells = CellGrowth(self.prep.first_cell)
            self.largest_scale = 1.0

    def _prepared_chunks(self):
        first = 0
        for shape, scale, rotation, drop_xy in self.particle_chunks():
            chunk = sdbd.prepare_deposition(*self.shapes, shape, scale, rotation, drop_xy, *self.container,
                                            **self.settings, first_particle=first)
            yield chunk
            first += len(chunk.particle_shape)

    def _add(self, chunk, n_blocks, rank) -> None:
        if not len(chunk.particle_shape):
            return
        if self.prep is None:  # the first particle sets the grid's first cell
            self.prep, self.cells = chunk, CellGrowth(chunk.first_cell)
            if chunk.lateral != LATERAL_NONE:  # the blocks' edges need no halo and no particle
                self.kept = _Keeping(BlockLayout(chunk.lateral, chunk.box_lower_xy, chunk.box_upper_xy,
                                                 (0.0, 0.0), n_blocks, 1.0), rank, len(chunk.substrate_radii))
        if self.kept is not None:
            self.kept.add(chunk, self.n_particles, self.n_spheres)
        self.cells.add(chunk)
        self.n_particles += len(chunk.particle_shape)
        self.n_spheres += chunk.n_spheres
        self.largest_scale = max(self.largest_scale, float(np.max(chunk.particle_scale)))
        x = chunk.particle_drop_xy[:, 0]
        self.drop_x_range = (min(self.drop_x_range[0], float(x.min())), max(self.drop_x_range[1], float(x.max())))

    def own_particles(self, layout, rank) -> "_OwnParticles":
        """The particles dropped in ``rank``'s block of ``layout``: those kept by the survey if its blocks are
        these, else from a second pass."""
        kept = self.kept
        if kept is None or kept.layout.n_blocks != layout.n_blocks:
            kept = _Keeping(layout, rank, len(self.prep.substrate_radii))
            particles = spheres = 0
            for chunk in self._prepared_chunks() if rank < layout.n_blocks else ():  # a rank beyond owns none
                kept.add(chunk, particles, spheres)
                particles += len(chunk.particle_shape)
                spheres += chunk.n_spheres
        self.kept = None
        return kept.own(self.prep, self.n_spheres)


class _Keeping:
    """The particles of one rank's block gathered from the chunks: their inputs, their places in the drop
    order and their first sphere keys."""

    def __init__(self, layout, rank, n_substrate):
        self.layout, self.rank, self.n_substrate = layout, rank, n_substrate
        self.inputs, self.index, self.first_key = [], [], []

    def add(self, chunk, particles_before, spheres_before) -> None:
        """The particles of ``chunk`` (a prepared chunk) that this rank owns; ``particles_before`` and
        ``spheres_before`` came in the chunks before it."""
        counts = np.diff(chunk.shape_start)[chunk.particle_shape]
        mine = np.flatnonzero(self.layout.owners(chunk.particle_drop_xy[:, 0]) == self.rank)
        self.inputs.append(tuple(array[mine] for array in chunk.kernel_inputs()[3:]))
        self.index.append(particles_before + mine)
        self.first_key.append(self.n_substrate + spheres_before + (np.cumsum(counts) - counts)[mine])

    def own(self, prep, n_spheres) -> "_OwnParticles":
        """The rank's particles, their inputs in ``prep`` (of the whole run's ``n_spheres``)."""
        columns = ([np.concatenate([part[k] for part in self.inputs]) for k in range(4)] if self.inputs
                   else list(prep.kernel_inputs()[3:]))
        own_prep = prep._replace(particle_shape=columns[0], particle_scale=columns[1], particle_rotation=columns[2],
                                 particle_drop_xy=columns[3], n_spheres=n_spheres)
        return _OwnParticles(own_prep, np.concatenate(self.index + [np.zeros(0, dtype=np.int64)]),
                             np.concatenate(self.first_key + [np.zeros(0, dtype=np.int64)]))


@dataclass
class _OwnParticles:
    """A rank's particles: ``prep``'s particle arrays hold their inputs (row by row), ``index`` their places
    in the drop order, ``first_key`` the serial index of their first sphere (substrate included)."""

    prep: object
    index: np.ndarray
    first_key: np.ndarray


class _RankRun:
    """The rounds of :func:`deposit_decomposed` on one rank (see the module docs)."""

    def __init__(self, comm, own, survey, layout, window, check, clock_from):
        self.comm = comm
        self.rank = comm.Get_rank()
        self.prep = prep = own.prep
        self.n_particles = survey.n_particles
        self.layout = layout
        self.window = window
        self.periodic = layout.periodic
        self.length = (prep.box_upper_xy - prep.box_lower_xy).astype(float)
        n_sub = len(prep.substrate_radii)
        self.index = own.index
        self.count = np.diff(prep.shape_start)[prep.particle_shape]
        self.first_key = own.first_key
        self.sphere_row = np.cumsum(self.count) - self.count
        n = len(self.index)
        self.slot = np.full(n, -1, dtype=np.int64)
        self.status = np.zeros(n, dtype=np.int8)
        self.footprint = np.zeros((n, 4))
        self.rectangle = np.zeros((n, 4))
        self.com = np.zeros((n, 3))
        self.rot = np.zeros((n, 4))
        self.contacts = np.zeros(n, dtype=np.int8)
        self.state = np.zeros(n, dtype=np.int8)
        self.events = np.zeros((n, N_EVENT_KINDS), dtype=np.int32)
        self.steps = np.zeros(n, dtype=np.int32)
        self.chunks = np.zeros(n, dtype=np.int64)
        self.signatures = np.zeros((n if check else 0, 2), dtype=np.int64)
        self.spheres = np.zeros((int(self.count.sum()), 3))
        self.n_max = int(np.max(np.diff(prep.shape_start)))
        self.cells = survey.cells
        self.growth = self.cells.growth()
        self.settled_end = 0
        self.fetched = set()
        self.column_sides = {}
        self.clock_from = clock_from
        self.tally = {"rounds": 0, "settles": np.zeros(1, dtype=np.int64), "conflicts": 0, "fetches": 0,
                      "halo_particles": 0, "halo_bytes": 0, "footprint_bytes": 0, "settle_seconds": 0.0}
        self._lay_substrate(n_sub)

    # ------------------------------------------------------------------ local sediment
    def _lay_substrate(self, n_sub):
        prep = self.prep
        capacity = n_sub + int(self.count.sum()) + 1024
        self.centre = np.zeros((capacity, 3))
        self.radius = np.zeros(capacity)
        self.key = np.full(capacity, -1, dtype=np.int64)
        grid_state = grid_module.grid_new(prep.lateral, prep.box_lower_xy, prep.box_upper_xy, prep.first_cell,
                                          capacity, prep.polygon, prep.n_sides)
        region = self.layout.region(self.rank) if self.rank < self.layout.n_blocks else np.array([1.0, 0.0])
        self.n_used, self.grid = blocks.lay_substrate(prep.substrate_positions, prep.substrate_radii, region,
                                                      self.centre, self.radius, self.key, grid_state)
        self.n_substrate = self.n_used

    def _reserve(self, n_spheres):
        """Room for ``n_spheres`` more spheres; returns the first free slot."""
        need = self.n_used + n_spheres
        if need > len(self.radius):
            capacity = max(need, 2 * len(self.radius))
            self.centre = _grown(self.centre, capacity, 0.0)
            self.radius = _grown(self.radius, capacity, 0.0)
            self.key = _grown(self.key, capacity, -1)
            grid_state = list(self.grid)
            grid_state[4] = _grown(grid_state[4], capacity, -1)
            self.grid = tuple(grid_state)
        first = self.n_used
        self.n_used = need
        return first

    def _give_slots(self, first_row, last_row):
        """Slots for the rows that have none yet, one after the other."""
        rows = first_row + np.flatnonzero(self.slot[first_row:last_row] < 0)
        if len(rows):
            counts = self.count[rows]
            self.slot[rows] = self._reserve(int(counts.sum())) + np.cumsum(counts) - counts

    def _set_cell(self, cell):
        if self.grid[0][6] != cell:
            self.grid = blocks.grid_with_cell(self.grid, cell, self.centre, self.radius, self.key)

    def _settle(self, first_row, last_row):
        prep = self.prep
        self._give_slots(first_row, last_row)
        given_top = np.nan
        if last_row == first_row + 1:
            cell = self.cells.after(int(self.index[first_row]))
            if cell > self.grid[0][6]:  # the serial run drops it, then grows the grid
                given_top = blocks.drop_top(first_row, *prep.kernel_inputs(), self.grid, self.centre, self.radius,
                                            prep.length_scale, self.n_max)
                self._set_cell(cell)
        self.grid = blocks.settle_rows(
            first_row, last_row, self.settled_end, *prep.kernel_inputs(), self.grid, self.centre,
            self.radius, self.key, *prep.kernel_settings(), self.status, self.footprint, self.rectangle,
            self.slot, self.count, self.first_key, self.com, self.rot, self.contacts, self.state, self.events,
            self.steps, self.chunks, self.spheres, self.sphere_row, self.margin, self.n_max, self.tally["settles"],
            self.signatures, given_top)
        self.settled_end = max(self.settled_end, last_row)

    def _withdraw(self, row):
        blocks.withdraw(row, self.status, self.slot, self.count, self.centre, self.radius, self.grid)

    def _insert(self, parcel, first_row):
        """Committed particles of other ranks (a :func:`_parcel`) join the local sediment."""
        counts, footprints, keys, centres, radii = parcel
        first = self._reserve(len(radii))
        self.grid = blocks.insert_committed(len(counts), counts, footprints, keys, centres, radii, first,
                                            self.centre, self.radius, self.key, self.grid, first_row,
                                            self.settled_end, self.status, self.footprint, self.rectangle,
                                            self.slot, self.count, self.margin)

    def _parcel(self, rows):
        """The spheres of ``rows`` as sent to another rank: counts, footprints, keys, wrapped centres, radii."""
        counts = self.count[rows]
        slots = spans(self.slot[rows], counts)
        return counts, self.footprint[rows], self.key[slots], self.centre[slots], self.radius[slots]

    # ------------------------------------------------------------------ rounds
    def run(self) -> DecomposedDeposition:
        n_particles = self.n_particles
        frontier = 0
        stopped_at = -1
        clock_start = None
        while frontier < n_particles and stopped_at < 0:
            self.tally["rounds"] += 1
            self._set_cell(self._cell_before(frontier))
            end = self._window_end(frontier, n_particles)
            self.margin = self._column_side(self.cells.after(end - 1))
            first_row, last_row = np.searchsorted(self.index, [frontier, end])
            started = time.perf_counter()
            self._settle(first_row, last_row)
            self._settle_while_waiting(last_row, self._ahead_end(frontier, end, n_particles))
            self.tally["settle_seconds"] += time.perf_counter() - started
            others = self._share_footprints(first_row, last_row)
            failure = self._first_failure(first_row, last_row, others, end)
            new_frontier, reason = divmod(failure, N_FAILURES)
            committed_end = np.searchsorted(self.index, min(new_frontier, end))
            self._commit(first_row, committed_end)
            if new_frontier >= end:
                new_frontier = end
            elif reason == FAIL_CONFLICT:
                self.tally["conflicts"] += 1
                if self._owns(new_frontier):
                    self._withdraw(self._row(new_frontier))
            elif reason == FAIL_REGION:
                self.tally["fetches"] += 1
                if self._fetch_and_settle(new_frontier):
                    stopped_at = new_frontier
                else:
                    new_frontier += 1
                    self._commit(committed_end, np.searchsorted(self.index, new_frontier))
            else:  # FAIL_STOPPED: the serial run stops at this particle too
                stopped_at = new_frontier
            if clock_start is None and 0 <= self.clock_from < new_frontier:
                clock_start = started
            frontier = new_frontier
        clocked = time.perf_counter() - clock_start if clock_start is not None else float("nan")
        return self._share(stopped_at, clocked)

    def _cell_before(self, particle):
        """The grid's cell when ``particle`` is dropped."""
        return self.prep.first_cell if particle == 0 else self.cells.after(particle - 1)

    def _column_side(self, cell):
        if cell not in self.column_sides:
            self.column_sides[cell] = _column_side(self.prep, cell)
        return self.column_sides[cell]

    def _settle_while_waiting(self, first_row, end_row):
        """Until every rank has settled its window, settle the rows after it (up to ``end_row``), a few
        at a time: the next windows' work, done while a faster rank would otherwise wait."""
        done = self.comm.Ibarrier()
        row = max(first_row, self.settled_end)
        while not done.Test():
            if row >= end_row:
                done.Wait()
                break
            self._settle(row, min(row + AHEAD_ROWS, end_row))
            row = self.settled_end

    def _ahead_end(self, frontier, end, n_particles):
        """The row after the last one that may be settled ahead of the window: one window further, and
        never past a growth of the grid's cell."""
        if end == frontier + 1 and _holds(self.growth, frontier):
            return np.searchsorted(self.index, end)
        return int(np.searchsorted(self.index, min(end + self.window, self._next_growth(frontier, n_particles))))

    def _window_end(self, frontier, n_particles):
        """A window never spans a growth of the grid's cell: a particle larger than all before is
        settled alone, and the ranks rebuild their grids after it."""
        if _holds(self.growth, frontier):
            return frontier + 1
        return min(frontier + self.window, self._next_growth(frontier, n_particles))

    def _next_growth(self, particle, n_particles):
        """The first particle after ``particle`` that grows the grid's cell (``n_particles`` if none)."""
        at = np.searchsorted(self.growth, particle, side="right")
        return int(self.growth[at]) if at < len(self.growth) else n_particles

    def _owns(self, particle):
        return _holds(self.index, particle)

    def _row(self, particle):
        return int(np.searchsorted(self.index, particle))

    def _destinations(self):
        return [q for q in range(self.layout.n_blocks) if q != self.rank]

    def _share_footprints(self, first_row, last_row):
        """Every rank's window footprints that meet this rank's region, sorted by particle."""
        outgoing = [None] * self.comm.Get_size()
        boxes = self.footprint[first_row:last_row]
        for q in self._destinations():
            region = self.layout.region(q)
            met = blocks.rows_meeting(boxes, region[0], region[1], self.length[0], self.periodic)
            outgoing[q] = (self.index[first_row:last_row][met], boxes[met])
            self.tally["footprint_bytes"] += outgoing[q][0].nbytes + outgoing[q][1].nbytes
        incoming = [part for part in self.comm.alltoall(outgoing) if part is not None]
        index = np.concatenate([p[0] for p in incoming] + [np.zeros(0, dtype=np.int64)])
        footprints = np.concatenate([p[1] for p in incoming] + [np.zeros((0, 4))])
        order = np.argsort(index, kind="stable")
        return index[order], footprints[order]

    def _first_failure(self, first_row, last_row, others, end):
        from mpi4py import MPI
        none = end * N_FAILURES
        mine = none
        if self.rank < self.layout.n_blocks:
            code = blocks.first_failure(first_row, last_row, self.index, self.status, self.rectangle,
                                        self.layout.region(self.rank), others[0], others[1], len(others[0]),
                                        self.margin, self.length[0], self.length[1], self.periodic)
            if code >= 0:
                mine = code
        return int(self.comm.allreduce(mine, op=MPI.MIN))

    def _commit(self, first_row, last_row):
        """Rows ``first_row .. last_row - 1`` are committed: final, and sent to the ranks whose region
        holds one of their sphere centres.  Collective."""
        self.status[first_row:last_row] = FINAL
        self._share_committed(first_row, last_row)
        if len(self.signatures):
            changed = blocks.first_changed(first_row, last_row, self.signatures, self.rectangle, self.margin,
                                           self.first_key, self.status, self.grid, self.centre, self.key)
            if changed >= 0:
                raise DecompositionError(
                    f"particle {self.index[changed]} was committed, but the sediment it read changed after it "
                    f"was settled: the decomposed sediment would not be the serial one")

    def _share_committed(self, first_row, last_row):
        """Send the newly committed rows to the ranks whose region holds one of their sphere centres;
        insert what the others send."""
        rows = np.arange(first_row, last_row)
        outgoing = [None] * self.comm.Get_size()
        for q in self._destinations():
            region = self.layout.region(q)
            box = np.array([region[0], region[1], np.inf, -np.inf])
            inside = blocks.rows_with_centre_in(rows, self.slot, self.count, self.centre, box, self.length[0],
                                                self.length[1], self.periodic)
            if np.any(inside):
                outgoing[q] = self._parcel(rows[inside])
                self.tally["halo_particles"] += int(np.count_nonzero(inside))
                self.tally["halo_bytes"] += sum(a.nbytes for a in outgoing[q])
        for parcel in self.comm.alltoall(outgoing):
            if parcel is not None:
                self._insert(parcel, last_row)

    def _fetch_and_settle(self, particle):
        """Settle ``particle``, at the frontier, on the committed spheres its owner fetches from every
        rank, until its rectangle stays in what the owner holds; returns whether it stopped at the
        event limit.  Collective."""
        from mpi4py import MPI
        owner = self.comm.allreduce(self.rank if self._owns(particle) else self.comm.Get_size(), op=MPI.MIN)
        reach = 2.0 * self.margin
        region = self.layout.region(owner)
        row = self._row(particle) if self.rank == owner else -1
        extent = self.comm.bcast(self._widened(row, reach) if row >= 0 else None, root=owner)
        while True:
            parts = self.comm.gather(self._committed_in(extent, region, particle), root=owner)
            message = None
            if self.rank == owner:
                for source, parcel in enumerate(parts):
                    if source != owner:  # the owner's own particles are in its sediment
                        self._insert(self._not_fetched(parcel), row)
                self._set_cell(self._cell_before(particle))
                self._withdraw(row)
                self._settle(row, row + 1)
                box = self._widened(row, self.margin)
                done = (blocks.interval_within(box[0], box[1], region[0], region[1], self.length[0], self.periodic)
                        or _box_within(box, extent, self.length, self.periodic))
                message = (done, _hull(extent, self._widened(row, reach)), self.status[row] == STOPPED)
            done, extent, stopped = self.comm.bcast(message, root=owner)
            if done:
                return stopped

    def _widened(self, row, by):
        box = self.rectangle[row]
        return np.array([box[0] - by, box[1] + by, box[2] - by, box[3] + by])

    def _committed_in(self, extent, region, particle):
        """This rank's committed particles (and substrate spheres in its block) with a sphere centre in
        ``extent`` and none in the owner's ``region`` (which holds those already)."""
        final = np.flatnonzero(self.status == FINAL)
        x_only = np.array([region[0], region[1], np.inf, -np.inf])
        inside = blocks.rows_with_centre_in(final, self.slot, self.count, self.centre, extent, self.length[0],
                                            self.length[1], self.periodic)
        held = blocks.rows_with_centre_in(final, self.slot, self.count, self.centre, x_only, self.length[0],
                                          self.length[1], self.periodic)
        counts, footprints, keys, centres, radii = self._parcel(final[inside & ~held])
        substrate = np.arange(self.n_substrate)
        single = np.ones(len(substrate), dtype=np.int64)
        in_extent = blocks.rows_with_centre_in(substrate, substrate, single, self.centre, extent, self.length[0],
                                               self.length[1], self.periodic)
        in_region = blocks.rows_with_centre_in(substrate, substrate, single, self.centre, x_only, self.length[0],
                                               self.length[1], self.periodic)
        mine = self.layout.owners(self.centre[:self.n_substrate, 0]) == self.rank
        lay = substrate[in_extent & ~in_region & mine]
        points = self.centre[lay]
        substrate_footprints = np.stack([points[:, 0], points[:, 0], points[:, 1], points[:, 1]], axis=1)
        return (np.concatenate([counts, np.ones(len(lay), dtype=np.int64)]),
                np.concatenate([footprints, substrate_footprints]), np.concatenate([keys, self.key[lay]]),
                np.concatenate([centres, points]), np.concatenate([radii, self.radius[lay]]))

    def _not_fetched(self, parcel):
        """The particles of ``parcel`` not fetched before (by their first key), now marked fetched."""
        counts, footprints, keys, centres, radii = parcel
        starts = np.cumsum(counts) - counts
        new = np.array([int(keys[s]) not in self.fetched for s in starts], dtype=bool)
        self.fetched.update(int(keys[s]) for s in starts[new])
        spheres = np.repeat(new, counts)
        return counts[new], footprints[new], keys[spheres], centres[spheres], radii[spheres]

    def _share(self, stopped_at, clocked_seconds) -> DecomposedDeposition:
        done = self.n_particles if stopped_at < 0 else stopped_at
        rows = np.flatnonzero((self.status == FINAL) & (self.index < done))
        spheres = spans(self.sphere_row[rows], self.count[rows])
        slots = spans(self.slot[rows], self.count[rows])
        tally = dict(self.tally, settles=int(self.tally["settles"][0]), particles=len(rows),
                     chunk_steps=int(self.chunks[rows].sum()))
        return DecomposedDeposition(self.index[rows], self.prep.particle_shape[rows], self.prep.particle_scale[rows],
                                    self.com[rows], self.rot[rows], self.contacts[rows], self.state[rows],
                                    self.events[rows], self.steps[rows], self.count[rows], self.spheres[spheres],
                                    self.radius[slots], stopped_at, clocked_seconds, tally)


def _holds(ascending, value) -> bool:
    """Whether the ascending array ``ascending`` holds ``value``."""
    at = np.searchsorted(ascending, value)
    return bool(at < len(ascending) and ascending[at] == value)


def _box_within(box, extent, length, periodic):
    return (blocks.interval_within(box[0], box[1], extent[0], extent[1], length[0], periodic)
            and blocks.interval_within(box[2], box[3], extent[2], extent[3], length[1], periodic))


def _hull(a, b):
    """The smallest rectangle holding rectangles ``a`` and ``b`` (not across a periodic seam)."""
    return np.array([min(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), max(a[3], b[3])])


def drop_order(index, sphere_count):
    """The order that puts particles of drop indices ``index`` (each with ``sphere_count`` spheres, particle
    after particle) in the drop order, and the sphere rows in that order."""
    order = np.argsort(index, kind="stable")
    return order, spans((np.cumsum(sphere_count) - sphere_count)[order], sphere_count[order])


def spans(starts, counts):
    """The indices ``starts[k] .. starts[k] + counts[k] - 1`` of every ``k``, one after the other."""
    counts = np.asarray(counts, dtype=np.int64)
    return np.repeat(np.asarray(starts, dtype=np.int64) - (np.cumsum(counts) - counts), counts) \
        + np.arange(int(counts.sum()), dtype=np.int64)


def _grown(array, rows, fill):
    grown = np.full((rows,) + array.shape[1:], fill, dtype=array.dtype)
    grown[:len(array)] = array
    return grown


def _column_side(prep, cell) -> float:
    """The largest side of the grid's columns for ``cell``: a cell that meets a rectangle holds
    centres within this distance of it."""
    geom = grid_module.grid_new(prep.lateral, prep.box_lower_xy, prep.box_upper_xy, cell, 1, prep.polygon,
                                prep.n_sides)[0]
    return float(max(geom[4], geom[5]))
