"""The statistics of a sediment spread over MPI ranks, measured where its particles lie.

:func:`measure_decomposed` gives on every rank of a group the statistics that
:func:`parsim.deposition.statistics.measure` gives for the gathered sediment, from the
ranks' shares (:class:`parsim.deposition.spread.DecomposedDeposition`). No rank holds more than
its own particles, copies of the other ranks' particles within reach of them, and the substrate.

Both are the same computation: each part of the sediment (the whole, for a serial task; a rank's
particles here) makes its sums (:mod:`parsim.deposition.statistics`: ``local_sums``, then
``contact_part``, ``rdf_part``, ``packing_part``, ``axis_part``, ``count_part``) and ``combine``
makes the statistics of the parts' sums, in rank order. What this module adds is how a rank gets
what its sums need:

- the sizes that steer the measurement are reduced first (``Whole.of`` of every rank's
  ``local_sums``): the mean sphere radius of the contact and floor tolerances, the mean
  volume-equivalent diameter (the bulk's distance from walls, g(r)'s shells), a heap's extent,
  the species' volumes and moments (the filling height, the mixture); sums of floats as exact,
  correctly rounded sums, so that the bulk, the slabs and the shells have the serial bits; then the
  number of bulk particles (g(r)'s density) and of sampled overlap caps (the points per cap);
- sums over pairs need a rank's own particles and copies of the others': every rank publishes
  the box of its sphere centres and centres of mass (on a periodic side the shortest arc that
  holds them), and every rank sends each other rank the particles with a sphere centre or centre of
  mass within reach (twice the largest sphere radius, or g(r)'s range) of that box, whatever the
  ranks the particles were given to. A rank's own particles then meet every sphere and centre they
  meet in the whole sediment: their numbers of sphere contacts and of particles touched are
  complete. The fabric tensor sums over contacts: a contact is counted by the owner of its lower
  particle index (a substrate contact by its particle's owner), so each contact once;
- g(r) takes the serial reference centres: the candidates in global particle order, at most
  ``RDF_REFERENCES`` of them evenly spaced over that list. A candidate's place in the global list
  is its rank's candidates before it plus the other ranks': these come from the number of
  candidates in every block of ``INDEX_BLOCK`` particle indices and, for the few blocks that hold
  a chosen place, a bitmap of their candidates (both summed over the ranks). Each rank counts the
  pairs about its own references, its distances from the centres as the sediment holds them (x_j
  − x_i, then the minimum image over the box's period, as on one rank: a pair at a shell's edge,
  touching spheres at 1 diameter, falls in the serial shell); the counts are summed;
- the packing fraction: the volume of every sphere in every slab is exact and summed by the
  sphere's owner; the overlap excess lies within particles (spheres of different particles touch
  and overlap by no more than round-off, below the overlap tolerance), so the particle's owner
  holds all of it. Its exact part (lenses) is the serial one; its sampled part (caps of multiple
  overlaps) has the serial points: as many per cap (from the caps sampled on every rank) and
  rotated by a shift drawn from the cap's spheres' keys (particle index and place in it), not from
  where the cap is measured. The substrate, whose spheres may overlap one another, is measured
  whole by rank 0.

Exact, and to round-off: integers and counts are exact; the filling height, the bulk's slab, the
mixture's volumes and heights, the orientation and fabric sums have the serial bits; g(r) too (its
counts are integers). Other floats are sums in another order, the same to about 1e-15 relative;
each rank's kernels see a sphere moved by a periodic side's length in the last bits of its
position (contacts, normals, overlap caps), which changes nothing beyond that.

Each rank lays its kernels' cell lists over a *frame*, the box of its own particles widened by a
margin (or the whole width of a periodic side its particles wrap around), so that no rank's
memory grows with the box; a copy from across a periodic side is moved by the period into it.
"""

from dataclasses import dataclass, replace

import numpy as np
from mpi4py import MPI

from parsim.core import structure
from parsim.parallel.collective import abort_if_alone
from parsim.deposition.spread import drop_order
from parsim.deposition import statistics as serial
from parsim.deposition.statistics import Particles

#: particle indices per block of the counts that find g(r)'s reference centres in the global list
INDEX_BLOCK = 1024
#: the reach of the halo exchange over the largest pair distance it must cover
REACH_SAFETY = 1.01


def measure_decomposed(comm, params, share, species, drops, geometry, skip, substrate) -> dict:
    """Every statistic of :func:`parsim.deposition.statistics.measure` of the sediment spread
    over ``comm``, from this rank's ``share`` (:class:`parsim.deposition.spread.DecomposedDeposition`).

    ``drops``: the species and size factors of this rank's particles, aligned with ``share.index``;
    ``species``, ``geometry``, ``skip`` and ``substrate`` (centres, radii: the whole substrate on
    every rank) as ``measure`` takes them. Collective; returns the same dict on every rank.
    """
    try:
        own = Particles.of_result(share.result, share.index, share.sphere_count)
        whole = serial.Whole.of(params, species, geometry, substrate,
                                comm.allgather(serial.local_sums(own, species, drops)))
        in_bulk = whole.in_bulk(own.com)
        local = _Local.exchanged(comm, whole, own)
        pairs, normals, overlapping = _contact_network(local, whole.mean_radius)
        spheres, flags, frame, cover = _packing_cover(comm, whole, own, drops, overlapping[local.own_spheres()]
                                                      if local is not None else np.zeros(0, dtype=bool))
        whole = whole.counted(*comm.allreduce(np.array([int(in_bulk.sum()),
                                                        cover.sampled_caps if cover is not None else 0])))
        lower, upper = (frame.lower, frame.upper) if frame is not None else (None, None)
        part = {**_contact_part(whole, local, pairs, normals), **_rdf_part(comm, whole, own, local),
                "packing": serial.packing_part(whole, spheres, flags, cover, lower, upper),
                **serial.axis_part(whole, np.asarray(share.result.rotation), drops, in_bulk),
                **serial.count_part(whole, own, share.result, skip)}
        return serial.combine(whole, comm.allgather(part))
    except BaseException as error:
        abort_if_alone(comm, error)  # the other ranks would wait in a collective
        raise


def _joined(parts) -> Particles:
    """The particles of ``parts`` (disjoint sets) in global order."""
    index = np.concatenate([p.index for p in parts])
    count = np.concatenate([p.count for p in parts])
    order, take = drop_order(index, count)
    return Particles(index[order], np.concatenate([p.com for p in parts])[order], count[order],
                     np.concatenate([p.positions for p in parts])[take], np.concatenate([p.radii for p in parts])[take])


def _reach(whole) -> float:
    """How far the pairs measured reach: sphere contacts, and g(r)'s range."""
    shells = whole.shells()
    reach_radius = max(whole.largest_radius, float(np.max(whole.substrate[1], initial=0.0)))
    contact = 2.0 * reach_radius + 3.0 * whole.contact_tolerance()
    return REACH_SAFETY * max(contact, shells[1] if shells else 0.0)


def _margin(whole) -> float:
    """A frame's margin about the box of its rank's particles: the copies it receives lie within the reach
    and a particle's span of that box, and twice that keeps the kernels' periodic images of the frame
    farther apart than any pair they measure."""
    return 2.0 * (_reach(whole) + whole.span)


@dataclass(frozen=True)
class _Frame:
    """The lateral box of one rank's kernels: its particles' box widened by a margin, or on a periodic side
    whose width that covers, the whole side. ``period``: the periodic length by which points are moved into
    a narrower frame (0: never moved)."""

    lower: np.ndarray
    upper: np.ndarray
    periodic: bool
    period: np.ndarray

    @classmethod
    def about(cls, box, region, margin) -> "_Frame":
        lower, upper = box[0] - margin, box[1] + margin
        period = np.zeros(2)
        for axis in range(2):
            length = float(region.upper[axis] - region.lower[axis])
            if region.periodic and upper[axis] - lower[axis] >= length:
                lower[axis], upper[axis] = region.lower[axis], region.upper[axis]
            elif region.periodic:
                period[axis] = length
        return cls(lower, upper, region.periodic, period)

    def placed(self, points) -> np.ndarray:
        """``points`` (n, 3) with those outside a narrower frame than the periodic side moved into it."""
        points = np.array(points, dtype=np.float64)
        for axis in np.flatnonzero(self.period):
            x = points[:, axis]
            out = (x < self.lower[axis]) | (x >= self.upper[axis])
            x[out] = self.lower[axis] + np.mod(x[out] - self.lower[axis], self.period[axis])
        return points

    def area(self) -> float:
        return float(np.prod(self.upper - self.lower))


def _box(xy, region) -> np.ndarray:
    """(lower, upper) (2, 2) of points ``xy``: their extent, on a periodic side the shortest arc holding them
    (of its images one period apart, the one that holds the most points where they are)."""
    box = np.stack([xy.min(axis=0), xy.max(axis=0)])
    if not region.periodic:
        return box
    for axis in range(2):
        length = float(region.upper[axis] - region.lower[axis])
        around = np.sort(np.mod(xy[:, axis] - region.lower[axis], length))
        gaps = np.diff(around, append=around[0] + length)
        widest = int(np.argmax(gaps))
        arc = length - gaps[widest]
        if box[1, axis] - box[0, axis] > arc:  # the arc across the side is shorter
            start = region.lower[axis] + around[(widest + 1) % len(around)] - np.array([length, 0.0])
            held = [np.count_nonzero((xy[:, axis] >= s) & (xy[:, axis] <= s + arc)) for s in start]
            box[0, axis] = start[int(np.argmax(held))]
            box[1, axis] = box[0, axis] + arc
    return box


def _near(xy, box, reach, region) -> np.ndarray:
    """Which points ``xy`` lie within ``reach`` of ``box`` in x and in y (across a periodic side)."""
    near = np.ones(len(xy), dtype=bool)
    for axis in range(2):
        low, high = box[0, axis], box[1, axis]
        x = xy[:, axis]
        if not region.periodic:
            near &= (x >= low - reach) & (x <= high + reach)
            continue
        length = float(region.upper[axis] - region.lower[axis])
        if high - low + 2.0 * reach < length:
            ahead = np.mod(x - low, length)
            near &= (ahead <= high - low + reach) | (ahead >= length - reach)
    return near


@dataclass(frozen=True)
class _Local:
    """A rank's own particles and the copies of the other ranks' particles within reach, in global order,
    and the substrate spheres within reach, first among the spheres; positions in the rank's frame."""

    particles: Particles  # centres of mass where they are; sphere centres moved into the frame
    own: np.ndarray  # (P,) bool
    positions: np.ndarray  # (S, 3): the substrate's spheres within reach, then the particles'
    radii: np.ndarray
    particle: np.ndarray  # (S,) the row of each sphere's particle, P for the substrate
    n_substrate: int
    frame: _Frame

    @classmethod
    def exchanged(cls, comm, whole, own) -> "_Local | None":
        """Collective: the copies every rank sends each other; None on a rank without particles."""
        region, reach = whole.region, _reach(whole)
        box = _box(np.concatenate([own.positions[:, :2], own.com[:, :2]]), region) if len(own.index) else None
        outgoing = [None] * comm.Get_size()
        for rank, other in enumerate(comm.allgather(box)):
            if rank != comm.Get_rank() and other is not None and box is not None:
                near = (np.logical_or.reduceat(_near(own.positions[:, :2], other, reach, region),
                                               np.cumsum(own.count) - own.count)
                        | _near(own.com[:, :2], other, reach, region))
                outgoing[rank] = own.subset(near) if near.any() else None
        copies = [part for part in comm.alltoall(outgoing) if part is not None]
        if box is None:
            return None
        frame = _Frame.about(box, region, _margin(whole))
        particles = _joined([own, *copies])
        particles = replace(particles, positions=frame.placed(particles.positions))
        substrate = _near(whole.substrate[0][:, :2], box, reach, region)
        mine = np.isin(particles.index, own.index, assume_unique=True)
        return cls(particles, mine, np.concatenate([frame.placed(whole.substrate[0][substrate]),
                                                    particles.positions]),
                   np.concatenate([whole.substrate[1][substrate], particles.radii]),
                   np.concatenate([np.full(int(substrate.sum()), len(particles.index)), particles.row_of_sphere()]),
                   int(substrate.sum()), frame)

    def own_spheres(self) -> np.ndarray:
        """The rows of the own particles' spheres, in the order of the share."""
        return self.n_substrate + np.flatnonzero(np.repeat(self.own, self.particles.count))


def _contact_network(local, mean_radius):
    """:func:`parsim.core.structure.contact_network` of the local spheres with the contact tolerance of the
    whole sediment (of its ``mean_radius``): (pairs, normals, overlapping); empty on a rank without particles."""
    if local is None:
        return np.zeros((0, 2), dtype=np.int64), np.zeros((0, 3)), np.zeros(0, dtype=bool)
    frame = local.frame
    network = structure.contact_network(local.positions, local.radii, local.particle, frame.lower, frame.upper,
                                        frame.periodic, mean_radius=mean_radius)
    return network.pairs, network.normals, network.overlapping


def _contact_part(whole, local, pairs, normals) -> dict:
    """This rank's share of the contact statistics (:func:`parsim.deposition.statistics.contact_part`
    of its local spheres, counting its own particles)."""
    if local is None:
        return serial.contact_part(pairs, normals, np.zeros(0, dtype=np.int64), np.zeros(0, dtype=bool),
                                   np.zeros(0, dtype=bool))
    return serial.contact_part(pairs, normals, local.particle, local.own, whole.in_bulk(local.particles.com))


def _evenly_spaced(comm, candidates, n_index, most) -> np.ndarray:
    """Which of this rank's ``candidates`` (global particle indices, ascending) are at the places
    ``np.linspace(0, n - 1, most)`` of the list of every rank's candidates in index order (n of them; all
    when n <= ``most``): the references :func:`parsim.core.structure.region_radial_distribution` keeps.
    Collective."""
    total = comm.allreduce(len(candidates))
    if total <= most:
        return np.ones(len(candidates), dtype=bool)
    places = np.linspace(0, total - 1, most).astype(np.int64)
    block = candidates // INDEX_BLOCK
    counts = np.bincount(block, minlength=-(-n_index // INDEX_BLOCK)).astype(np.int64)
    comm.Allreduce(MPI.IN_PLACE, counts, op=MPI.SUM)
    ends = np.cumsum(counts)
    held = np.unique(np.searchsorted(ends, places, side="right"))  # the blocks holding a chosen place
    row = np.minimum(np.searchsorted(held, block), len(held) - 1)
    inside = held[row] == block
    members = np.zeros((len(held), INDEX_BLOCK), dtype=np.uint8)
    members[row[inside], candidates[inside] % INDEX_BLOCK] = 1
    comm.Allreduce(MPI.IN_PLACE, members, op=MPI.SUM)  # the ranks' candidates are disjoint
    place = (ends - counts)[held][:, None] + np.cumsum(members, axis=1, dtype=np.int64) - 1
    chosen = np.zeros(len(candidates), dtype=bool)
    chosen[inside] = np.isin(place[row[inside], candidates[inside] % INDEX_BLOCK], places)
    return chosen


def _rdf_part(comm, whole, own, local) -> dict:
    """This rank's share of g(r): the pairs about its own references among the serial ones, counted in its frame
    from the centres as the sediment holds them. Collective."""
    candidate = np.flatnonzero(whole.rdf_candidates(own.com))
    chosen = candidate[_evenly_spaced(comm, own.index[candidate], whole.n_index, serial.RDF_REFERENCES)]
    if local is None or not len(chosen):
        return serial.rdf_part(whole, own.com, np.zeros(0, dtype=np.int64), None, None)
    references = np.searchsorted(local.particles.index, own.index[chosen])
    frame, region = local.frame, whole.region
    period = region.upper - region.lower if region.periodic else None
    return serial.rdf_part(whole, local.particles.com, references, frame.lower, frame.upper, period)


def _packing_cover(comm, whole, own, drops, own_overlapping):
    """This rank's measured spheres (its own, the substrate's on rank 0) placed in their frame, their overlap
    flags, the frame and their :func:`parsim.deposition.statistics.packing_cover` (frame and cover None
    when it has no sphere or the container no packing fraction)."""
    spheres = serial.MeasuredSpheres.of(whole, own, drops, comm.Get_rank() == 0)
    flags = np.concatenate([np.ones(len(spheres.radii) - len(own.radii), dtype=bool), own_overlapping])
    if not len(spheres.radii) or not whole.region.measured:
        return spheres, flags, None, None
    frame = _Frame.about(_box(spheres.positions[:, :2], whole.region), whole.region, _margin(whole))
    placed = replace(spheres, positions=frame.placed(spheres.positions))
    return placed, flags, frame, serial.packing_cover(whole, placed, flags, frame.lower, frame.upper)
