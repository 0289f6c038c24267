"""The statistics of a sediment spread over MPI ranks, measured where its particles lie.

:func:`measure_decomposed` gives on every rank of a group the statistics that
:func:`parsim.solvers.deposition_statistics.measure` gives for the gathered sediment, from the
ranks' shares (:class:`parsim.parallel.deposition.DecomposedDeposition`). No rank holds more than
its own particles, copies of the other ranks' particles within reach of them, and the substrate.

How each statistic is reduced, and why the reduction is the serial value:

- sizes that steer the measurement are reduced first, so that every rank measures with the
  serial values: the mean sphere radius of the contact and floor tolerances, the mean
  volume-equivalent diameter (the bulk's distance from walls, g(r)'s shells), a heap's extent,
  the number of bulk particles (g(r)'s density);
- sums over particles are summed over the ranks: spheres, events, steps (a maximum), hanging
  particles, particles on the floor (a particle's spheres are all its owner's), the timed spheres,
  and of the bulk particles' long axes their number, second moment, sum of P2 and histogram of
  angles. The filling height and the mixture are the serial functions applied to one pseudo
  particle per species, carrying the species' total volume at its volume-weighted mean height:
  2 z_cm, the volume shares and each species' mean height are ratios of sums of V and V z;
- sums over pairs need a rank's own particles and copies of the others': every rank publishes
  the box of its sphere centres and centres of mass (on a periodic side the shortest arc that
  holds them), and every rank sends each other rank the particles with a sphere centre or centre of
  mass within reach (twice the largest sphere radius, or g(r)'s range) of that box, whatever the
  ranks the particles were given to. A rank's own particles then meet every sphere and centre they
  meet in the whole sediment: their numbers of sphere contacts and of particles touched are
  complete, and they are summed over their owners. The fabric tensor sums over contacts: a
  contact is counted by the owner of its lower particle index (a substrate contact by its
  particle's owner), so each contact once;
- g(r) takes the serial reference centres: the candidates in global particle order, at most
  ``RDF_REFERENCES`` of them evenly spaced over that list. A candidate's place in the global list
  is its rank's candidates before it plus the other ranks': these come from the number of
  candidates in every block of ``INDEX_BLOCK`` particle indices and, for the few blocks that hold
  a chosen place, a bitmap of their candidates (both summed over the ranks). Each rank counts the
  pairs about its own references; g(r) of the whole is the references' weighted mean;
- the packing fraction: the volume of every sphere in every slab is exact and summed by the
  sphere's owner; the overlap excess lies within particles (spheres of different particles touch
  and overlap by no more than round-off, below the overlap tolerance), so the particle's owner
  holds all of it. The substrate, whose spheres may overlap one another, is measured whole by rank 0.

Exact, and to round-off: integers and counts (spheres, particles, events, contacts, contact
numbers, bulk coordination, species counts) are exact. Floats are sums in another order, the same
to about 1e-15 relative; each rank's kernels see a sphere moved by a periodic side's length in
the last bits of its position, which changes nothing beyond that. The contact tolerance is
CONTACT_GAP_TOLERANCE times the sediment's mean radius; the packing fraction's overlap tolerance (1e-9 of the mean
radius of the spheres measured together, which only tells overlap within a particle from
round-off) is that of a rank's spheres.

Not exact: the overlap excess of caps that :mod:`parsim.core.sediment` samples by quasi-Monte
Carlo (caps of a sphere overlapping more than one other, and the split over slabs of a pairwise
lens cut by a slab's edge) has sample points shifted by the cap's row in the grid of the spheres
measured together and as many points per cap as the sample budget over the sampled caps allows.
A rank measures its own particles with the budget in proportion to its spheres that overlap,
so its caps have about the serial number of points, at other shifts: these parts of the packing
fraction, its profile and the species' profiles differ from the serial by their sampling error.
Measured on 2 and 4 ranks (tests/scripts/decomposed_statistics_probe.py): for rods of three
overlapping spheres in a cylinder, up to 7e-3 in a slab of the profile and 1.4e-4 in the bulk
value with 1000 samples per slab (the serial value's own error against 2e5 samples: 6e-3 and
4e-5), 6e-4 and 3.5e-5 with 5e4, 2.3e-4 and 2.3e-5 with the default 2e5. For shapes whose caps are
all pairwise (rods of two overlapping spheres) only the split of a lens over the two slabs its
edge cuts is sampled: the profile's sum over the slabs agrees to 1e-14, a slab by the figures
above. Spheres, and particles of touching spheres, agree to 1e-14 in every statistic.

Each rank lays its kernels' cell lists over a *frame*, the box of its own particles widened by a
margin (or the whole width of a periodic side its particles wrap around), so that no rank's
memory grows with the box; a copy from across a periodic side is moved by the period into it.
"""

from dataclasses import dataclass, replace
from types import SimpleNamespace

import numpy as np
from mpi4py import MPI

from parsim.core import sdbd, structure
from parsim.core.sediment import CONTACT_GAP_TOLERANCE, packing_fractions
from parsim.parallel.collective import abort_if_alone
from parsim.parallel.deposition import drop_order
from parsim.solvers import deposition_statistics as serial
from parsim.solvers.deposition_materials import Drops

#: particle indices per block of the counts that find g(r)'s reference centres in the global list
INDEX_BLOCK = 1024
#: the reach of the halo exchange over the largest pair distance it must cover
REACH_SAFETY = 1.01


def measure_decomposed(comm, params, share, species, drops, geometry, skip, substrate) -> dict:
    """Every statistic of :func:`parsim.solvers.deposition_statistics.measure` of the sediment spread
    over ``comm``, from this rank's ``share`` (:class:`parsim.parallel.deposition.DecomposedDeposition`).

    ``drops``: the species and size factors of this rank's particles, aligned with ``share.index``;
    ``species``, ``geometry``, ``skip`` and ``substrate`` (centres, radii: the whole substrate on
    every rank) as ``measure`` takes them. Collective; returns the same dict on every rank.
    """
    try:
        sediment = _Sediment.reduced(comm, params, share, species, drops, geometry, substrate)
        parts = comm.allgather(_partial_sums(comm, sediment, share, skip))
        return _statistics(sediment, parts)
    except BaseException as error:
        abort_if_alone(comm, error)  # the other ranks would wait in a collective
        raise


@dataclass(frozen=True)
class _Particles:
    """Particles as ranks hold and exchange them: global indices (ascending), centres of mass, sphere
    counts, and the spheres' centres and radii, particle after particle."""

    index: np.ndarray
    com: np.ndarray
    count: np.ndarray
    positions: np.ndarray
    radii: np.ndarray

    @classmethod
    def of(cls, share) -> "_Particles":
        """A rank's own particles: its share of the sediment."""
        points = [np.asarray(a, dtype=np.float64).reshape(-1, 3) for a in (share.center_of_mass, share.positions)]
        return cls(np.asarray(share.index, dtype=np.int64), points[0], np.asarray(share.sphere_count, dtype=np.int64),
                   points[1], np.asarray(share.radii, dtype=np.float64))

    @classmethod
    def joined(cls, parts) -> "_Particles":
        """The particles of ``parts`` (disjoint sets) in global order."""
        index = np.concatenate([p.index for p in parts])
        count = np.concatenate([p.count for p in parts])
        order, take = drop_order(index, count)
        return cls(index[order], np.concatenate([p.com for p in parts])[order], count[order],
                   np.concatenate([p.positions for p in parts])[take], np.concatenate([p.radii for p in parts])[take])

    def subset(self, chosen) -> "_Particles":
        spheres = np.repeat(chosen, self.count)
        return _Particles(self.index[chosen], self.com[chosen], self.count[chosen], self.positions[spheres],
                          self.radii[spheres])

    def row_of_sphere(self) -> np.ndarray:
        return np.repeat(np.arange(len(self.index)), self.count)


@dataclass(frozen=True)
class _Sizes:
    """The sizes of the whole sediment that steer its measurement, reduced over the ranks."""

    n_particles: int
    n_index: int  # the largest particle index + 1
    mean_radius: float  # of every sphere, the substrate's included (the contact and floor tolerances)
    diameter: float  # mean volume-equivalent particle diameter
    largest_radius: float  # of the particles' spheres
    reach_radius: float  # of every sphere, the substrate's included
    span: float  # the farthest two points of one particle (sphere centres, centre of mass) can be apart
    low: np.ndarray  # the sphere centres' lateral extent
    high: np.ndarray

    @classmethod
    def reduced(cls, comm, own, species, drops, substrate) -> "_Sizes":
        n = len(own.index)
        diameters = np.array([s.equivalent_diameter for s in species])[drops.species] * drops.scale
        extents = np.array([s.extent for s in species])[drops.species] * drops.scale
        spheres = own.positions[:, :2]
        local = (n, len(own.radii), float(own.radii.sum()), float(diameters.sum()),
                 float(own.radii.max(initial=0.0)), 2.0 * float(extents.max(initial=0.0)),
                 spheres.min(axis=0) if len(spheres) else np.full(2, np.inf),
                 spheres.max(axis=0) if len(spheres) else np.full(2, -np.inf), int(own.index.max(initial=-1)) + 1)
        parts = comm.allgather(local)
        column = [[part[k] for part in parts] for k in range(len(local))]
        n_particles, n_spheres = sum(column[0]), sum(column[1])
        largest = max(column[4])
        return cls(n_particles, max(column[8]),
                   (float(np.sum(substrate[1])) + sum(column[2])) / (len(substrate[1]) + n_spheres),
                   sum(column[3]) / n_particles, largest, max(largest, float(np.max(substrate[1], initial=0.0))),
                   max(column[5]), np.min(column[6], axis=0), np.max(column[7], axis=0))

    def extent(self):
        """The sediment as :func:`parsim.solvers.deposition_statistics.measuring_region` reads a heap's
        extent from it: its extreme sphere centres and its largest particle sphere."""
        return SimpleNamespace(positions=np.array([[*self.low, 0.0], [*self.high, 0.0]]),
                               radii=np.array([self.largest_radius]))


@dataclass(frozen=True)
class _Sediment:
    """What every rank knows of the whole sediment, and this rank's own particles."""

    params: dict
    species: tuple
    substrate: tuple
    own: _Particles
    drops: Drops
    rotation: np.ndarray
    sizes: _Sizes
    region: serial.Region
    heights: serial.Heights
    species_totals: np.ndarray  # (3, species): particles, volume, volume x height of centre of mass
    n_bulk: int  # particles with their centre of mass in the bulk, over every rank

    @classmethod
    def reduced(cls, comm, params, share, species, drops, geometry, substrate) -> "_Sediment":
        own = _Particles.of(share)
        sizes = _Sizes.reduced(comm, own, species, drops, substrate)
        region = serial.measuring_region(params, geometry, sizes.extent(), sizes.diameter)
        volume = np.array([s.volume for s in species])[drops.species] * drops.scale**3
        local = np.stack([np.bincount(drops.species, weights=w, minlength=len(species)) for w in
                          (np.ones(len(volume)), volume, volume * own.com[:, 2])])
        totals = np.sum(np.stack(comm.allgather(local)), axis=0)  # in rank order: the same bits on every rank
        present = totals[0] > 0
        heights = serial.pile_heights(totals[2, present] / totals[1, present], totals[1, present], substrate)
        sediment = cls(params, tuple(species), substrate, own, drops, np.asarray(share.rotation), sizes, region,
                       heights, totals, 0)
        return replace(sediment, n_bulk=comm.allreduce(int(sediment.in_bulk(own.com).sum())))

    def in_bulk(self, com) -> np.ndarray:
        """Which centres of mass ``com`` lie in the bulk (its area and slab)."""
        slab = self.heights.bulk_slab()
        return self.region.in_bulk_area(com[:, :2]) & (com[:, 2] >= slab[0]) & (com[:, 2] < slab[1])

    def contact_tolerance(self) -> float:
        return CONTACT_GAP_TOLERANCE * self.sizes.mean_radius

    def shells(self):
        """g(r)'s usable shells and range r_max, None when it has none."""
        return serial.rdf_shells(self.params, self.sizes.diameter, self.region)

    def reach(self) -> float:
        """How far the pairs measured reach: sphere contacts, and g(r)'s range."""
        shells = self.shells()
        contact = 2.0 * self.sizes.reach_radius + 3.0 * self.contact_tolerance()
        return REACH_SAFETY * max(contact, shells[1] if shells else 0.0)

    def margin(self) -> float:
        """A frame's margin about the box of its rank's particles: the copies it receives lie within the reach
        and a particle's span of that box, and twice that keeps the kernels' periodic images of the frame
        farther apart than any pair they measure."""
        return 2.0 * (self.reach() + self.sizes.span)


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

    particles: _Particles  # centres of mass where they are; sphere centres moved into the frame
    own: np.ndarray  # (P,) bool
    positions: np.ndarray  # (S, 3): the substrate's spheres within reach, then the particles'
    radii: np.ndarray
    particle: np.ndarray  # (S,) the row of each sphere's particle, P for the substrate
    n_substrate: int
    frame: _Frame

    @classmethod
    def exchanged(cls, comm, sediment) -> "_Local | None":
        """Collective: the copies every rank sends each other; None on a rank without particles."""
        own, region, reach = sediment.own, sediment.region, sediment.reach()
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
        frame = _Frame.about(box, region, sediment.margin())
        particles = _Particles.joined([own, *copies])
        particles = replace(particles, positions=frame.placed(particles.positions))
        substrate = _near(sediment.substrate[0][:, :2], box, reach, region)
        mine = np.isin(particles.index, own.index, assume_unique=True)
        return cls(particles, mine, np.concatenate([frame.placed(sediment.substrate[0][substrate]),
                                                    particles.positions]),
                   np.concatenate([sediment.substrate[1][substrate], particles.radii]),
                   np.concatenate([np.full(int(substrate.sum()), len(particles.index)), particles.row_of_sphere()]),
                   int(substrate.sum()), frame)

    def own_spheres(self) -> np.ndarray:
        """The rows of the own particles' spheres, in the order of the share."""
        return self.n_substrate + np.flatnonzero(np.repeat(self.own, self.particles.count))


def _contact_network(local, mean_radius):
    """:func:`parsim.core.structure.contact_network` of the local spheres with the contact tolerance of the
    whole sediment (of its ``mean_radius``): (pairs, normals, overlapping)."""
    frame = local.frame
    network = structure.contact_network(local.positions, local.radii, local.particle, frame.lower, frame.upper,
                                        frame.periodic, mean_radius=mean_radius)
    return network.pairs, network.normals, network.overlapping


def _contact_sums(sediment, local) -> tuple[dict, np.ndarray]:
    """This rank's share of the contact statistics: its bulk particles' number, sphere contacts and histogram
    of contact numbers, and the fabric sum n n over the contacts with a bulk particle that it counts (those
    whose lower particle index is its own); and the overlap flags of its own spheres."""
    cap = serial.MAX_CONTACT_NUMBER
    sums = {"bulk": 0, "sphere_contacts": 0, "contact_numbers": np.zeros(cap + 1, dtype=np.int64),
            "fabric": np.zeros((3, 3)), "fabric_contacts": 0}
    if local is None:
        return sums, np.zeros(0, dtype=bool)
    pairs, normals, overlapping = _contact_network(local, sediment.sizes.mean_radius)
    n = len(local.particles.index)
    in_bulk = sediment.in_bulk(local.particles.com)
    mine = local.own & in_bulk
    owners = local.particle[pairs]
    bulk = np.append(in_bulk, False)  # the substrate is never in the bulk
    counted = local.own[owners.min(axis=1)] & (bulk[owners[:, 0]] | bulk[owners[:, 1]])
    sums["bulk"] = int(mine.sum())
    sums["sphere_contacts"] = int(structure.sphere_contacts_per_particle(pairs, local.particle, n + 1)[:n][mine].sum())
    if sums["bulk"]:
        touched = structure.contacts_per_particle(pairs, local.particle, n + 1)[:n]
        fractions = structure.contact_number_distribution(touched, mine, cap)
        sums["contact_numbers"] = np.rint(fractions * sums["bulk"]).astype(np.int64)
    if counted.any():
        sums["fabric_contacts"] = int(counted.sum())
        sums["fabric"] = structure.fabric_tensor(normals[counted]) * sums["fabric_contacts"]
    return sums, overlapping[local.own_spheres()]


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


def _shell_sums(comm, sediment, local) -> dict:
    """This rank's share of g(r): the number of its reference centres and their g(r) times that number.
    Collective."""
    shells = sediment.shells()
    if shells is None:
        return {"references": 0, "weighted_g": np.zeros(0)}
    bins, r_max = shells
    com, slab = sediment.own.com, sediment.heights.bulk_slab()
    candidate = np.flatnonzero((com[:, 2] >= slab[0] + r_max) & (com[:, 2] < slab[1] - r_max)
                               & sediment.region.in_bulk_area(com[:, :2], r_max))
    chosen = candidate[_evenly_spaced(comm, sediment.own.index[candidate], sediment.sizes.n_index,
                                      serial.RDF_REFERENCES)]
    if not len(chosen):
        return {"references": 0, "weighted_g": np.zeros(bins)}
    references = np.searchsorted(local.particles.index, sediment.own.index[chosen])
    n = len(local.particles.index)
    # every local centre in the region, of a volume that gives it the density of the whole bulk
    volume = n * sediment.region.bulk_area() * (slab[1] - slab[0]) / sediment.n_bulk
    frame = local.frame
    g = structure.region_radial_distribution(frame.placed(local.particles.com), np.ones(n, dtype=bool), volume,
                                             references, r_max, bins, frame.lower, frame.upper, frame.periodic)[1]
    return {"references": len(chosen), "weighted_g": g * len(chosen)}


def _packing_slabs(sediment):
    """The profile's slabs, the bulk slab and the slabs measured in one pass (in a periodic box the bulk's
    first, then the profile's)."""
    bins = sediment.params["profile_bins"]
    edges = np.linspace(0.0, serial.PROFILE_TOP * sediment.heights.filling, bins + 1)
    profile = np.column_stack([edges[:-1], edges[1:]])
    bulk = np.array([sediment.heights.bulk_slab()])
    return profile, bulk, (np.concatenate([bulk, profile]) if sediment.region.periodic else profile)


def _covered_volumes(comm, sediment, own_overlapping) -> np.ndarray:
    """This rank's covered volumes (the union of its spheres, the substrate's on rank 0): of the bulk slab
    (by the spheres in the bulk's area when walled), of the profile's slabs, and of the profile's slabs by
    each species, one after the other. Collective."""
    own, region = sediment.own, sediment.region
    substrate = sediment.substrate if comm.Get_rank() == 0 else (np.zeros((0, 3)), np.zeros(0))
    positions = np.concatenate([substrate[0], own.positions])
    radii = np.concatenate([substrate[1], own.radii])
    flags = np.concatenate([np.ones(len(substrate[1]), dtype=bool), own_overlapping])
    flagged = comm.allreduce(int(flags.sum()))
    samples = sediment.params["packing_samples"]
    if flagged:  # the sample budget in proportion to the spheres that may overlap: about the serial points per cap
        samples = max(1, round(samples * int(flags.sum()) / flagged))
    profile, bulk, slabs = _packing_slabs(sediment)
    n_species = len(sediment.species)
    volumes = np.zeros(1 + (1 + n_species) * len(profile))
    if not len(radii):
        return volumes
    frame = _Frame.about(_box(positions[:, :2], region), region, sediment.margin())
    positions = frame.placed(positions)

    def covered(chosen, measured):
        if not chosen.any():
            return np.zeros(len(measured))
        return (packing_fractions(positions[chosen], radii[chosen], frame.lower, frame.upper, measured, samples,
                                  flags[chosen]) * frame.area() * (measured[:, 1] - measured[:, 0]))

    everything = covered(np.ones(len(radii), dtype=bool), slabs)
    row = own.row_of_sphere()
    in_area = np.concatenate([region.in_bulk_area(substrate[0][:, :2]), region.in_bulk_area(own.com[row, :2])])
    volumes[0] = everything[0] if region.periodic else covered(in_area, bulk)[0]
    volumes[1:1 + len(profile)] = everything[-len(profile):]
    sphere_species = np.concatenate([np.full(len(substrate[1]), -1), sediment.drops.species[row]])
    for s in range(n_species):
        part = (everything if n_species == 1 and not len(substrate[1]) else covered(sphere_species == s, slabs))
        volumes[(1 + s) * len(profile) + 1:(2 + s) * len(profile) + 1] = part[-len(profile):]
    return volumes


def _axis_sums(sediment, in_bulk) -> dict:
    """This rank's share of the orientation statistics: of its bulk particles' long axes u their number, the
    second moment sum u u, the sum of P2(u_z) and the histogram of the angle to the vertical."""
    bins = sediment.params["orientation_bins"]
    axes = serial.long_axes(SimpleNamespace(rotation=sediment.rotation), sediment.species, sediment.drops)[in_bulk]
    axes = axes[np.all(np.isfinite(axes), axis=1)]
    if not len(axes):
        return {"axes": 0, "moment": np.zeros((3, 3)), "p2": 0.0, "angles": np.zeros(bins, dtype=np.int64)}
    unit = axes / np.linalg.norm(axes, axis=1)[:, None]
    return {"axes": len(axes), "moment": unit.T @ unit, "p2": structure.vertical_order(axes) * len(axes),
            "angles": structure.angle_histogram(axes, bins)[1].astype(np.int64)}


def _partial_sums(comm, sediment, share, skip) -> dict:
    """Everything this rank adds to the statistics (collective: the halo exchange, g(r)'s references and
    the packing's sample budget)."""
    own = sediment.own
    in_bulk = sediment.in_bulk(own.com)
    local = _Local.exchanged(comm, sediment)
    contacts, own_overlapping = _contact_sums(sediment, local)
    shells = _shell_sums(comm, sediment, local)
    packing = _covered_volumes(comm, sediment, own_overlapping) if sediment.region.measured else None
    floor = serial.particles_on_floor(SimpleNamespace(positions=own.positions, radii=own.radii,
                                                       particle=own.row_of_sphere()),
                                       CONTACT_GAP_TOLERANCE * sediment.sizes.mean_radius)
    events = np.asarray(share.event_counts, dtype=np.int64)
    return {**contacts, **shells, **_axis_sums(sediment, in_bulk), "packing": packing, "on_floor": floor,
            "spheres": len(own.radii), "events": events.sum(axis=0), "steps": int(np.max(share.steps, initial=0)),
            "hanging": int(np.isin(share.state, serial.HANGING).sum()),
            "timed_spheres": int(np.sum(np.repeat(own.index, own.count) >= skip)),
            "clocked_seconds": share.clocked_seconds}


def _statistics(sediment, parts) -> dict:
    """The statistics of the whole from every rank's partial sums (in rank order: the same on every rank)."""

    def total(key):
        return np.sum(np.stack([np.asarray(part[key]) for part in parts]), axis=0)

    n = sediment.sizes.n_particles
    events = total("events")
    clocked = parts[0]["clocked_seconds"]  # the gathered sediment's clock is rank 0's
    statistics = {
        "filling_height": sediment.heights.filling,
        "substrate_height": sediment.heights.substrate,
        "bulk_wall_distance": sediment.region.wall_distance,
        **_packing(sediment, total),
        **_mixture(sediment),
        **_orientations(total),
        "radial_distribution": _radial_distribution(sediment, total),
        **_contacts(total),
        "n_spheres": int(total("spheres")),
        "events_per_particle": int(events.sum()) / n,
        "largest_steps_per_particle": int(max(part["steps"] for part in parts)),
        "hanging_particles": int(total("hanging")),
        "particles_on_floor": int(total("on_floor")),
        "spheres_per_second": int(total("timed_spheres")) / clocked if clocked > 0 else np.nan,
    }
    for name, kind in serial.EVENT_TOTALS.items():
        statistics[name] = int(events[sdbd.EVENT_KINDS.index(kind)])
    return statistics


def _packing(sediment, total) -> dict:
    """Bulk packing fraction and the profiles phi(z), phi_s(z) from the ranks' covered volumes."""
    params, region = sediment.params, sediment.region
    bins, n_species = params["profile_bins"], len(sediment.species)
    if not region.measured:
        return {"bulk_packing_fraction": np.nan, "packing_profile": np.full(bins, np.nan),
                "species_packing_profile": np.full((n_species, bins), np.nan)}
    volumes = total("packing")
    profile, bulk, _ = _packing_slabs(sediment)
    box_area = float(np.prod(region.upper - region.lower))
    layers = box_area * (profile[:, 1] - profile[:, 0]) * region.inside_fraction
    bulk_volume = float(bulk[0, 1] - bulk[0, 0])
    if region.periodic:
        fraction = volumes[0] / (box_area * bulk_volume) / region.inside_fraction
    else:
        fraction = volumes[0] / (region.bulk_area() * bulk_volume) if region.bulk_area() > 0.0 else np.nan
    return {"bulk_packing_fraction": float(fraction), "packing_profile": volumes[1:bins + 1] / layers,
            "species_packing_profile": volumes[bins + 1:].reshape(n_species, bins) / layers}


def _mixture(sediment) -> dict:
    """The mixture's statistics: :func:`parsim.solvers.deposition_statistics.mixture` of one pseudo particle
    per species present, of the species' volume at its volume-weighted mean height, and the species' counts."""
    count, volume, moment = sediment.species_totals
    present = np.flatnonzero(count > 0)
    com = np.zeros((len(present), 3))
    com[:, 2] = moment[present] / volume[present]
    pseudo = serial.mixture(SimpleNamespace(center_of_mass=com), sediment.species,
                             Drops(present, np.ones(len(present))), volume[present], sediment.heights)
    return {**pseudo, "species_particles": count.astype(np.int64)}


def _orientations(total) -> dict:
    """Nematic order, <P2> and the density of the angle to the vertical of the bulk particles' long axes (the
    density from the summed histogram as numpy's histogram makes it)."""
    n = int(total("axes"))
    angles = total("angles")
    if not n:
        return {"nematic_order": np.nan, "vertical_order": np.nan, "orientation_density": np.full(len(angles), np.nan)}
    order = np.linalg.eigh(structure.order_tensor(total("moment"), n))[0][-1]
    width = np.diff(np.linspace(0.0, 0.5 * np.pi, len(angles) + 1))
    return {"nematic_order": float(order), "vertical_order": float(total("p2")) / n,
            "orientation_density": angles / width / n}


def _radial_distribution(sediment, total) -> np.ndarray:
    """g(r) on the job's shells: the references' mean over the ranks; NaN beyond the usable shells."""
    g = np.full(sediment.params["rdf_bins"], np.nan)
    references = int(total("references"))
    if references:
        weighted = total("weighted_g")
        g[:len(weighted)] = weighted / references
    return g


def _contacts(total) -> dict:
    """Coordination, contact numbers and fabric of the bulk particles from the ranks' sums."""
    bulk, contacts = int(total("bulk")), int(total("fabric_contacts"))
    cap = serial.MAX_CONTACT_NUMBER
    return {"bulk_coordination": int(total("sphere_contacts")) / bulk if bulk else np.nan,
            "n_bulk_particles": bulk,
            "contact_number_fraction": total("contact_numbers") / bulk if bulk else np.full(cap + 1, np.nan),
            "fabric_tensor": total("fabric") / contacts if contacts else np.full((3, 3), np.nan)}
