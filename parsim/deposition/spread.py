"""One sediment spread over MPI ranks, bitwise the serial sediment.

The box is cut across x into one block of columns per rank (:class:`BlockLayout`).  A rank owns
the particles dropped in its block and settles them ahead of their turn on its local sediment
(:mod:`parsim.core.sdbd.blocks`): the substrate and committed particles in its *region* (the block
widened by the halo), and its own particles.  The serial drop order defines the answer; the ranks
go through it in rounds, each over a window of drop indices starting at the *frontier* (every
particle before it is committed, on every rank):

1. each rank settles its absent particles of the window in drop order;
2. each sends the footprints of its window's particles to the neighbours (the ranks whose region
   meets its own) whose region they meet;
3. each finds its first particle that cannot be committed once all before it are
   (:func:`parsim.core.sdbd.blocks.first_failure`): its rectangle leaves the region, or a particle
   of another rank dropped between the frontier and it has a sphere in its rectangle, or it stopped
   at the event limit; the smallest over the ranks (one reduction) is the new frontier;
4. a particle in conflict is withdrawn and settled again in the next round, when it is at the
   frontier and so exact; one whose rectangle left the region is settled again at once on the
   committed spheres its owner fetches from every rank, until its rectangle stays in what its
   owner holds;
5. each rank sends its newly committed particles to the neighbours whose region holds one of their
   sphere centres, and inserts those it receives; they withdraw the present particles they touch.

The rounds run inside one jitted loop per rank (:func:`parsim.core.sdbd.rounds.run_rounds`), which
calls the MPI library itself; while it waits for a message or the reduction it settles the next
windows' particles instead of idling.  It returns to Python only for a particle that left its
region (step 4: fetched here, from every rank) and at the end.

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

The argument leans on three things that a run must not break, each of which once did:

* *What it read is what it reads now.*  A row is settled while earlier rows of its rank may be out
  (withdrawn, to be settled again): rows settled ahead while waiting, or after the rows a committed
  particle touched.  An earlier row that comes back bitwise where it was leaves the rows settled
  before it went out as they were, but not those settled in between, which did not see it: they
  are withdrawn too if it meets their rectangle (:mod:`parsim.core.sdbd.blocks` keeps when each row
  was settled and withdrawn).  How many rows are settled ahead depends on the timing of messages,
  so without this the sediment differed from run to run.
* *Messages are what was sent.*  A kernel sends from arrays it made itself; MPI reads a large message
  only when the receive is posted, so the array must live until the send completes
  (:func:`parsim.core.kernel_mpi.wait_slots` takes it).  Freed early, large parcels (particles of
  many spheres, dense halos) arrived as garbage: overlapping particles at the borders, or a crash.
* *Nothing else is read.*  Walls, the cylinder's sides, a mesh vessel's faces and the floor are the same
  on every rank; particles of unequal radii read within their rectangle widened by the largest column, the grid's
  cell being that of the serial run at the same particle (it grows only between windows); a heap's
  particles that roll out of the region are settled at the frontier on what every rank fetches.

``deposit_decomposed(..., check=True)`` checks the first at every commit, and that the grid listed
every sphere of the local sediment in the rectangle when the row was settled; ``jitter`` varies
the timing at random.  ``benchmarks/spread_equivalence.py`` tries the claim on random jobs.
"""

import math
import time
from dataclasses import dataclass

import numba
import numpy as np

from parsim.core import kernel_mpi, sdbd
from parsim.core.sdbd import blocks, grid as grid_module, rounds, survey as survey_kernels
from parsim.core.sdbd.blocks import FINAL, STOPPED
from parsim.core.sdbd.constants import GEOM_COLUMN_X, GEOM_COLUMN_Y, LATERAL_NONE, LATERAL_PERIODIC, N_EVENT_KINDS
from parsim.errors import JobError
from parsim.parallel.collective import abort_if_alone
from parsim.parallel.halo import kernel_link
from parsim.phases import phase

__all__ = ["BlockLayout", "CellGrowth", "deposit_decomposed", "deposit_streamed", "DecomposedDeposition",
           "DecompositionError", "InvalidDeposition", "default_halo", "drop_order", "spans"]

#: drop indices of a round, all ranks together, in a box of REFERENCE_SIDE x REFERENCE_SIDE grid columns cut
#: into two blocks; other boxes and other numbers of blocks scale it (default_window)
REFERENCE_WINDOW = 1024
REFERENCE_SIDE = 300.0
SMALLEST_WINDOW, LARGEST_WINDOW = 16, 2048  # per rank


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
    miss).  On 2 ranks it is the fastest of halos 3 to 9 diameters wide."""
    extent = 0.0
    for s in range(len(prep.shape_start) - 1):
        a, b = prep.shape_start[s], prep.shape_start[s + 1]
        extent = max(extent, float(np.max(np.linalg.norm(prep.shape_offsets[a:b], axis=1) + prep.shape_radii[a:b])))
    return 4.0 * largest_cell + 2.0 * extent * largest_scale


def default_window(layout, prep, cell) -> int:
    """Drop indices per rank in a round.  A round commits the particles up to the first one that conflicts
    across a block border.  With particles dropped uniformly, a particle of the window conflicts with a
    chance that grows with the number of borders and with the particles dropped before it in the window,
    so the first conflict comes after about ``X sqrt(D / K)`` particles (``X`` the box's width across the
    blocks and ``D`` its depth, in grid columns; ``K`` blocks); a longer window only settles particles
    that will be settled again.  The window, in drop order, is REFERENCE_WINDOW scaled so, per rank the
    nearest power of two between SMALLEST_WINDOW and LARGEST_WINDOW: 512 in a box of 300 x 300 sphere
    diameters on 2 ranks, 32 on 16.  docs/benchmarks.md gives the particles settled twice and the time
    per round of several windows in blocks as wide as those of 16 ranks in that box."""
    depth = float(prep.box_upper_xy[1] - prep.box_lower_xy[1]) if prep.lateral != LATERAL_NONE \
        else layout.length  # a heap: about as deep as its drop area is wide
    width, depth = layout.length / cell / REFERENCE_SIDE, max(depth / cell / REFERENCE_SIDE, 0.0)
    window = REFERENCE_WINDOW * width * math.sqrt(depth * 2.0 / layout.n_blocks)
    per_rank = math.floor(math.log2(max(window / layout.n_blocks, 1.0)) + 0.5)
    return int(min(max(1 << per_rank, SMALLEST_WINDOW), LARGEST_WINDOW))


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
        grows, cells = survey_kernels.cell_growth(prep.particle_shape, prep.particle_scale,
                                                  prep.shape_largest_radius, self.cell[-1])
        self.at += (self.seen + grows).tolist()
        self.cell += cells.tolist()
        self.seen += len(prep.particle_shape)

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
        return survey_kernels.block_owners(np.ascontiguousarray(x, dtype=np.float64), *self.block_search())

    def block_search(self):
        """What :mod:`parsim.core.sdbd.survey` needs to find a drop abscissa's block."""
        return self.low, self.length, np.ascontiguousarray(self.edges[1:-1]), self.periodic

    def neighbours(self, k) -> list:
        """The other blocks whose regions meet block ``k``'s: where its particles' footprints and committed
        spheres can matter."""
        mine = self.region(k)
        return [q for q in range(self.n_blocks) if q != k and blocks.interval_meets(
            mine[0], mine[1], *self.region(q), self.length, self.periodic)]

    def region(self, k) -> np.ndarray:
        """``[x_low, x_high]`` of block ``k`` widened by the halo."""
        a, b = self.edges[k] - self.halo, self.edges[k + 1] + self.halo
        if self.periodic and b - a >= self.length:
            b = a + self.length
        return np.array([a, b])


@dataclass
class DecomposedDeposition:
    """One rank's share of a deposition spread over ranks.

    ``result``: a :class:`parsim.core.sdbd.DepositionResult` of the rank's committed particles, in drop
    order (its ``particle`` holds their drop indices; ``stopped_at`` and ``clocked_seconds`` are the whole
    run's); ``index`` and ``sphere_count``: each particle's drop index and number of spheres;
    ``particle_shape``, ``particle_scale``: its species and size factor; ``tally``: what the run counted.
    :meth:`gather` assembles the serial result on one rank."""

    result: sdbd.DepositionResult
    index: np.ndarray
    sphere_count: np.ndarray
    particle_shape: np.ndarray
    particle_scale: np.ndarray
    tally: dict

    def gather(self, comm, root=0):
        """The :class:`parsim.core.sdbd.DepositionResult` of the whole sediment on rank ``root``
        (None on the others): the shares' particles and spheres in drop order."""
        parts = comm.gather((self.result, self.index, self.sphere_count), root=root)
        if comm.Get_rank() != root:
            return None
        results, indices, counts = zip(*parts)
        order, take = drop_order(np.concatenate(indices), np.concatenate(counts))
        per_sphere = {"positions", "radii", "particle"}
        whole = {name: np.concatenate([getattr(r, name) for r in results])[take if name in per_sphere else order]
                 for name in sdbd.DepositionResult._fields if name not in ("stopped_at", "clocked_seconds")}
        return sdbd.DepositionResult(**whole, stopped_at=self.result.stopped_at,
                                     clocked_seconds=self.result.clocked_seconds)


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
                     window_per_rank=None, check=False, jitter=0.0, rehearsal=False, faces=None) -> DecomposedDeposition:
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
    it and again when it commits it, and raises :class:`DecompositionError` if they differ.
    A ``rehearsal`` (a warm-up, on one rank: the kernels are the same for any number) also compiles, or
    loads from the cache, the kernels that only several blocks or a fetch call (:meth:`_RankRun.compile_rare`).

    Why so many parameters: they are :func:`parsim.core.sdbd.deposit`'s, each with its default and named
    by the caller, and the spread run's own few (``halo``, ``window_per_rank``, ``check``, ``rehearsal``);
    the kernels take them in named groups."""
    settings = dict(trial_angle=trial_angle, cycle_n=cycle_n, cycle_eps=cycle_eps,
                    max_events_per_particle=max_events_per_particle, wall_contact=wall_contact, container=container,
                    cylinder=cylinder, substrate_positions=substrate_positions, substrate_radii=substrate_radii,
                    faces=faces)
    started = time.perf_counter()
    try:
        try:
            with phase("survey"):
                survey = _Survey(shape_offsets, shape_radii, shape_start, particle_chunks, box_lower_xy,
                                 box_upper_xy, lateral, floor, settings, comm.Get_size(), comm.Get_rank())
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
        run = _RankRun(comm, own, survey, layout, max(1, int(window_per_rank)) * layout.n_blocks, check,
                       int(clock_from_particle), float(jitter))
        share = run.run()
        if rehearsal:
            run.compile_rare()
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
                                            **self.settings, first_particle=first, keep_drawn_rotations=True)
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
        drop_x = np.ascontiguousarray(chunk.particle_drop_xy[:, 0])
        mine, spheres_in_chunk = survey_kernels.rows_of_block(drop_x, chunk.particle_shape, chunk.shape_start,
                                                              *self.layout.block_search(), self.rank)
        self.inputs.append(tuple(array[mine] for array in chunk.kernel_inputs()[3:]))
        self.index.append(particles_before + mine)
        self.first_key.append(self.n_substrate + spheres_before + spheres_in_chunk)

    def own(self, prep, n_spheres) -> "_OwnParticles":
        """The rank's particles, their inputs in ``prep`` (of the whole run's ``n_spheres``)."""
        columns = ([np.concatenate([part[k] for part in self.inputs]) for k in range(4)] if self.inputs
                   else [array[:0] for array in prep.kernel_inputs()[3:]])
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
    """One rank's part of :func:`deposit_decomposed` (see the module docs): the rounds run in a jitted loop
    (:func:`parsim.core.sdbd.rounds.run_rounds`), which hands back to Python only a particle whose
    rectangle left its owner's region, to be settled on what its owner fetches from every rank."""

    def __init__(self, comm, own, survey, layout, window, check, clock_from, jitter):
        self.comm = comm
        self.rank = comm.Get_rank()
        self.prep = prep = own.prep
        self.n_particles = survey.n_particles
        self.layout = layout
        self.periodic = layout.periodic
        self.length = (prep.box_upper_xy - prep.box_lower_xy).astype(float)
        self.owns_block = self.rank < layout.n_blocks
        self.region = layout.region(self.rank) if self.owns_block else np.array([1.0, 0.0])  # empty: a rank beyond the blocks
        n = len(own.index)
        count = np.diff(prep.shape_start)[prep.particle_shape]
        sphere_row = np.cumsum(count) - count
        self.n_max = int(np.max(np.diff(prep.shape_start)))
        self._lay_substrate(int(count.sum()))
        self.rows = blocks.Rows(
            index=own.index, count=count, first_key=own.first_key, sphere_row=sphere_row,
            slot=self.n_used + sphere_row, status=np.zeros(n, dtype=np.int8), footprint=np.zeros((n, 4)),
            rectangle=np.zeros((n, 4)), com=np.zeros((n, 3)), rotation=np.zeros((n, 4)),
            contacts=np.zeros(n, dtype=np.int8), state=np.zeros(n, dtype=np.int8),
            events=np.zeros((n, N_EVENT_KINDS), dtype=np.int32), steps=np.zeros(n, dtype=np.int32),
            chunks=np.zeros(n, dtype=np.int64), spheres=np.zeros((int(count.sum()), 3)),
            signatures=np.zeros((n if check else 0, 3), dtype=np.int64), settled_at=np.zeros(n, dtype=np.int64),
            withdrawn_at=np.zeros(n, dtype=np.int64))
        self.n_used += int(count.sum())  # every own particle's spheres have their slots from the start
        neighbours = layout.neighbours(self.rank) if self.owns_block else []
        cells = survey.cells
        self.plan = rounds.Plan(
            n_particles=self.n_particles, window=int(window), growth_at=np.array(cells.at, dtype=np.int64),
            cell=np.array(cells.cell), side=np.array([_column_side(prep, cell) for cell in cells.cell]),
            region=self.region,
            neighbours=np.array(neighbours, dtype=np.int64),
            neighbour_regions=np.array([layout.region(q) for q in neighbours]).reshape(-1, 2), length=self.length,
            periodic=self.periodic, clock_from=int(clock_from), n_max=self.n_max, jitter=jitter,
            jitter_seed=int(np.random.SeedSequence().entropy % 2**30) + self.rank if jitter > 0 else 0)
        self.link = kernel_link(comm, 1 + len(neighbours))
        self.settled_end = 0
        self.margin = float(self.plan.side[0])
        self.settles = np.zeros(1, dtype=np.int64)
        self.counts = np.zeros(rounds.N_TALLIES)
        self.fetches = 0
        self.fetched = set()
        self.clock = np.full(1, np.nan)

    def _lay_substrate(self, own_spheres):
        """The substrate's spheres in the region join the empty local sediment, whose arrays have room for
        them, the own spheres and those of the neighbours' particles in the halo (about as many, per
        own sphere, as the halo's two strips are wide per block width), so that they seldom grow."""
        prep, layout = self.prep, self.layout
        halo_share = min(1.0, 2.0 * layout.halo * layout.n_blocks / layout.length) if layout.n_blocks > 1 else 0.0
        capacity = len(prep.substrate_radii) + own_spheres + int(1.25 * halo_share * own_spheres) + 1024
        self.centre = np.zeros((capacity, 3))
        self.radius = np.zeros(capacity)
        self.key = np.full(capacity, -1, dtype=np.int64)
        grid_state = grid_module.grid_new(prep.lateral, prep.box_lower_xy, prep.box_upper_xy, prep.first_cell,
                                          capacity, prep.polygon, prep.n_sides)
        self.n_used, self.grid = blocks.lay_substrate(prep.substrate_positions, prep.substrate_radii, self.region,
                                                      self.centre, self.radius, self.key, grid_state)
        self.n_substrate = self.n_used

    # ------------------------------------------------------------------ rounds
    def run(self) -> DecomposedDeposition:
        from mpi4py import MPI
        frontier = 0
        stopped_at = -1
        while frontier < self.n_particles and stopped_at < 0:
            outcome, particle = self._rounds(frontier)
            if outcome == rounds.DONE:
                frontier = particle
            elif outcome == rounds.LEFT_REGION:
                self.fetches += 1
                started = MPI.Wtime()
                if self._fetch_and_settle(particle):
                    stopped_at = particle
                else:
                    frontier = particle + 1
                    self._commit(*np.searchsorted(self.rows.index, [particle, frontier]))
                    if np.isnan(self.clock[0]) and 0 <= self.plan.clock_from < frontier:
                        self.clock[0] = started
            elif outcome == rounds.STOPPED_AT_LIMIT:  # the serial run stops at this particle too
                stopped_at = particle
            else:
                raise self._read_changed(particle)
        clocked = MPI.Wtime() - self.clock[0] if not np.isnan(self.clock[0]) else float("nan")
        return self._share(stopped_at, clocked)

    def _rounds(self, frontier):
        """Rounds in the jitted loop from ``frontier`` until it needs Python; returns its outcome and
        particle."""
        prep = self.prep
        outcome, particle, held = rounds.run_rounds(frontier, prep.kernel_inputs(), prep.kernel_settings(), self.rows,
                                                    self.plan, self._held(), self.link, self.counts, self.settles,
                                                    self.clock)
        self._keep(held)
        return int(outcome), int(particle)

    def _held(self):
        """The local sediment as the kernels take it (:data:`.rounds.Held`)."""
        return rounds.Held(self.grid, self.centre, self.radius, self.key, self.n_used, self.settled_end, self.margin)

    def _keep(self, held):
        """The local sediment a kernel returned becomes this block's."""
        (self.grid, self.centre, self.radius, self.key, self.n_used, self.settled_end, self.margin) = held

    def compile_rare(self):
        """Compile, or load from the cache, the kernels that neither a small task nor one rank alone may call,
        for the types of this run's arguments, without running them: the neighbours' regions (several blocks)
        and a fetch (:meth:`_fetch_and_settle`; another rank's particles, :meth:`_insert`).  A task that met
        them first would compile them inside its wall time (tens of seconds)."""
        nothing = np.zeros(0, dtype=np.int64)
        _compile_for(blocks.interval_meets, 0.0, 0.0, 0.0, 0.0, self.layout.length, self.periodic)
        _compile_for(blocks.interval_within, 0.0, 0.0, 0.0, 0.0, self.length[0], self.periodic)
        _compile_for(survey_kernels.block_owners, np.zeros(0), *self.layout.block_search())
        _compile_for(rounds.settle_again, *self._settle_again_arguments(0))
        _compile_for(rounds.insert_parcel, *self._insert_arguments(self._parcel(nothing), 0))

    def _owns(self, particle):
        return _holds(self.rows.index, particle)

    def _row(self, particle):
        return int(np.searchsorted(self.rows.index, particle))

    def _destinations(self):
        return [q for q in range(self.layout.n_blocks) if q != self.rank]

    def _commit(self, first_row, last_row):
        """Rows ``first_row .. last_row - 1`` are committed: final, and sent to every rank whose region
        holds one of their sphere centres (a fetched particle may lie beyond the neighbours' regions).
        Collective."""
        rows = self.rows
        rows.status[first_row:last_row] = FINAL
        self._share_committed(first_row, last_row)
        if len(rows.signatures):
            changed = blocks.first_changed(first_row, last_row, rows.signatures, rows.rectangle, self.margin,
                                           rows.first_key, rows.status, self.grid, self.centre, self.key)
            if changed >= 0:
                raise self._read_changed(rows.index[changed])

    def _read_changed(self, particle) -> "DecompositionError":
        """The error of a committed particle whose read sediment changed after it was settled (the check):
        how many spheres of earlier particles its rectangle held then and now, and this rank's particles
        settled since that have a sphere there (none: another rank's committed particle arrived)."""
        rows = self.rows
        row = self._row(particle)
        box, margin = rows.rectangle[row], self.margin
        now, _ = blocks.read_signature(box, margin, rows.first_key[row], self.grid, self.centre, self.key)
        earlier = np.flatnonzero((rows.index < particle) & (rows.settled_at > rows.settled_at[row]))
        widened = np.array([box[0] - margin, box[1] + margin, box[2] - margin, box[3] + margin])
        inside = blocks.rows_with_centre_in(earlier, rows.slot, rows.count, self.centre, widened, self.length[0],
                                            self.length[1], self.periodic)
        since = rows.index[earlier[inside]].tolist()
        if rows.signatures[row, 2] != rows.signatures[row, 0]:
            return DecompositionError(
                f"particle {particle} was settled on a grid that listed {rows.signatures[row, 0]} of the "
                f"{rows.signatures[row, 2]} spheres of earlier particles its local sediment held in its rectangle "
                f"x [{box[0]:.6g}, {box[1]:.6g}], y [{box[2]:.6g}, {box[3]:.6g}] widened by {margin:.6g}; the "
                "decomposed sediment would not be the serial one")
        return DecompositionError(
            f"particle {particle} was committed, but the sediment it read changed after it was settled: its "
            f"rectangle x [{box[0]:.6g}, {box[1]:.6g}], y [{box[2]:.6g}, {box[3]:.6g}] widened by {margin:.6g} held "
            f"{rows.signatures[row, 0]} spheres of earlier particles then and {now} now; "
            + (f"particles {since} of rank {self.rank} were settled there since" if since else
               f"no particle of rank {self.rank} was settled there since: a committed particle of another rank "
               "arrived") + "; the decomposed sediment would not be the serial one")

    def _share_committed(self, first_row, last_row):
        """Send the newly committed rows to the ranks whose region holds one of their sphere centres;
        insert what the others send."""
        committed = np.arange(first_row, last_row)
        outgoing = [None] * self.comm.Get_size()
        for q in self._destinations():
            region = self.layout.region(q)
            box = np.array([region[0], region[1], np.inf, -np.inf])
            inside = blocks.rows_with_centre_in(committed, self.rows.slot, self.rows.count, self.centre, box,
                                                self.length[0], self.length[1], self.periodic)
            if np.any(inside):
                outgoing[q] = self._parcel(committed[inside])
                self.counts[rounds.HALO_PARTICLES] += int(np.count_nonzero(inside))
                self.counts[rounds.HALO_BYTES] += sum(a.nbytes for a in outgoing[q])
        for parcel in self.comm.alltoall(outgoing):
            if parcel is not None:
                self._insert(parcel, last_row)

    def _insert(self, parcel, first_row):
        """Committed particles of other ranks (a :func:`_parcel`) join the local sediment; the present rows
        from ``first_row`` on that they touch are withdrawn."""
        self._keep(rounds.insert_parcel(*self._insert_arguments(parcel, first_row)))

    def _insert_arguments(self, parcel, first_row):
        return tuple(parcel), first_row, self.rows, self._held(), self.n_max, self.settles

    def _parcel(self, rows):
        """The spheres of ``rows`` as sent to another rank: counts, footprints, keys, wrapped centres, radii."""
        counts = self.rows.count[rows]
        slots = spans(self.rows.slot[rows], counts)
        return counts, self.rows.footprint[rows], self.key[slots], self.centre[slots], self.radius[slots]

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
                self._keep(rounds.settle_again(*self._settle_again_arguments(row)))
                box = self._widened(row, self.margin)
                done = (blocks.interval_within(box[0], box[1], region[0], region[1], self.length[0], self.periodic)
                        or _box_within(box, extent, self.length, self.periodic))
                message = (done, _hull(extent, self._widened(row, reach)), self.rows.status[row] == STOPPED)
            done, extent, stopped = self.comm.bcast(message, root=owner)
            if done:
                return stopped

    def _settle_again_arguments(self, row):
        prep = self.prep
        return row, prep.kernel_inputs(), prep.kernel_settings(), self.rows, self.plan, self._held(), self.settles

    def _widened(self, row, by):
        box = self.rows.rectangle[row]
        return np.array([box[0] - by, box[1] + by, box[2] - by, box[3] + by])

    def _committed_in(self, extent, region, particle):
        """This rank's committed particles (and substrate spheres in its block) with a sphere centre in
        ``extent`` and none in the owner's ``region`` (which holds those already)."""
        rows = self.rows
        final = np.flatnonzero(rows.status == FINAL)
        x_only = np.array([region[0], region[1], np.inf, -np.inf])
        inside = blocks.rows_with_centre_in(final, rows.slot, rows.count, self.centre, extent, self.length[0],
                                            self.length[1], self.periodic)
        held = blocks.rows_with_centre_in(final, rows.slot, rows.count, self.centre, x_only, self.length[0],
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
        rows = self.rows
        done = self.n_particles if stopped_at < 0 else stopped_at
        final = (rows.status == FINAL) & (rows.index < done)
        if final.all():  # the usual end: every row, already in order
            kept, spheres = slice(0, len(final)), slice(None)
            slots = slice(self.n_substrate, self.n_substrate + len(rows.spheres))
        else:
            kept = np.flatnonzero(final)
            spheres = spans(rows.sphere_row[kept], rows.count[kept])
            slots = spans(rows.slot[kept], rows.count[kept])
        counts = self.counts
        link = self.link[-1]
        tally = {"rounds": int(counts[rounds.ROUNDS]), "settles": int(self.settles[0]),
                 "conflicts": int(counts[rounds.CONFLICTS]), "fetches": self.fetches,
                 "halo_particles": int(counts[rounds.HALO_PARTICLES]), "halo_bytes": int(counts[rounds.HALO_BYTES]),
                 "footprint_bytes": int(counts[rounds.FOOTPRINT_BYTES]),
                 "round_seconds": float(counts[rounds.ROUND_SECONDS]),
                 "settle_seconds": float(counts[rounds.SETTLE_SECONDS]),
                 "idle_seconds": float(counts[rounds.IDLE_SECONDS]),
                 "messages": int(link[kernel_mpi.LINK_MESSAGES]), "particles": int(np.count_nonzero(final)),
                 "chunk_steps": int(rows.chunks[kept].sum()), "jitter_seed": int(self.plan.jitter_seed)}
        index, count = rows.index[kept], rows.count[kept]
        result = sdbd.DepositionResult(
            positions=rows.spheres[spheres], radii=self.radius[slots].copy(), particle=np.repeat(index, count),
            center_of_mass=rows.com[kept], rotation=rows.rotation[kept], contacts=rows.contacts[kept],
            state=rows.state[kept], event_counts=rows.events[kept], steps=rows.steps[kept], stopped_at=stopped_at,
            clocked_seconds=clocked_seconds)
        return DecomposedDeposition(result, index, count, self.prep.particle_shape[kept],
                                    self.prep.particle_scale[kept], tally)


def _compile_for(kernel, *arguments) -> None:
    """Compile ``kernel``, or load it from the cache, for the types of ``arguments``, as a call with them would."""
    kernel.compile(tuple(numba.typeof(argument) for argument in arguments))


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


def _column_side(prep, cell) -> float:
    """The largest side of the grid's columns for ``cell``: a cell that meets a rectangle holds
    centres within this distance of it."""
    geom = grid_module.grid_new(prep.lateral, prep.box_lower_xy, prep.box_upper_xy, cell, 1, prep.polygon,
                                prep.n_sides)[0]
    return float(max(geom[GEOM_COLUMN_X], geom[GEOM_COLUMN_Y]))
