"""Measure small sediments spread over the ranks of ``mpiexec -n K`` with ``measure_decomposed`` and, on
rank 0, with the serial ``measure`` of the gathered sediment; writes a JSON report to ``argv[1]``.

Each case runs the deposition solver's own ``solve`` on every rank, which spreads the task over the
ranks and measures it where it lies (``measure_decomposed``). The probe gives the decomposition a
small halo (so that the blocks are narrow enough for every rank to own particles) and wraps
``measure_decomposed`` to keep what ``solve`` passes to it and what it returns. The serial ``measure``
then takes the gathered share and the same inputs (the ranks' drops joined in particle order),
exactly what a task measured on one rank takes. The cases: spheres in a periodic box, a mixture of
rods and smaller spheres between walls, overlapping rods in a cylinder, a heap, spheres of several
sizes on a substrate, and spheres on a substrate settled by rank 0 alone (the other ranks hold no
particle); and a lattice of touching spheres cut into blocks by hand (not deposited), whose contact
distance is an edge of g(r)'s shells.
"""

import json
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from mpi4py import MPI

import parsim
import parsim.deposition.spread as decomposition
import parsim.deposition.spread_statistics as decomposed_statistics
from parsim.core import sdbd, structure
from parsim.deposition import solver
from parsim.deposition import statistics as statistics
from parsim.deposition.materials import Drops

COMMON = {"packing_samples": 1000, "profile_bins": 20, "rdf_range": 1.5, "rdf_bins": 15, "orientation_bins": 9,
          "floor": "roll"}


def cases(folder: Path) -> dict:
    """name: (job parameters, [[species]] or None, options): ``halo`` of the decomposition, ``references``
    and ``index_block`` (when given, g(r) takes at most that many reference centres, found in blocks of that
    many particle indices: the reduction's selection runs over several blocks)."""
    rods_and_spheres = [{"name": "rods", "shape": "rod", "shape_size": 3, "shape_spacing": 2.0, "share": 1.0},
                        {"name": "spheres", "shape": "sphere", "sphere_radius": 0.35, "share": 2.0}]
    return {
        # wide enough for each rank's frame to be narrower than the box: copies move across its sides
        "spheres, periodic": ({"n_particles": 2400, "box_length": 20.0, "rdf_range": 1.0, "rdf_bins": 10}, None,
                              {"halo": 2.0, "references": 37, "index_block": 64}),
        "rods and spheres, walls": ({"n_particles": 700, "box_length": 12.0, "lateral": "walls"}, rods_and_spheres,
                                    {"halo": 2.5}),
        # spheres 0.6 radii apart: three overlap, the packing fraction's excess is partly sampled
        "overlapping rods, cylinder": ({"n_particles": 450, "shape": "rod", "shape_size": 3, "shape_spacing": 0.6,
                                        "container": "cylinder", "container_radius": 6.0, "packing_samples": 50_000},
                                       None, {"halo": 2.5}),
        "heap": ({"n_particles": 600, "lateral": "none", "drop_radius": 4.0}, None, {"halo": 1.5}),
        # a halo wider than the blocks: rank 0 settles the whole task, the other ranks hold no particle
        "substrate, rank 0 alone": ({"n_particles": 400, "box_length": 10.0,
                                     "substrate": str(folder / "substrate.csv")}, None, {"halo": 20.0}),
        "substrate, sizes": ({"n_particles": 700, "box_length": 10.0, "size_distribution": "uniform",
                              "size_spread": 0.2, "substrate": str(folder / "substrate.csv")}, None,
                             {"halo": 2.0, "references": 50}),
    }


def write_substrate(path: Path) -> None:
    """A square lattice of spheres of radius 0.35, 1 apart, on the floor of the 10 x 10 box."""
    ticks = np.arange(0.5, 10.0, 1.0)
    x, y = np.meshgrid(ticks, ticks)
    rows = [f"{a:.17g},{b:.17g},0.35,0.35" for a, b in zip(x.ravel(), y.ravel())]
    path.write_text("x,y,z,r\n" + "\n".join(rows) + "\n")


def point(parameters: dict, species) -> dict:
    tables = {"species": species} if species else {}
    job = parsim.Job.from_dict({"name": "probe", "kind": "deposition", "seed": 1, "realizations": 1, **tables,
                                "parameters": {**COMMON, **parameters}})
    return job.point_parameters(0)


@contextmanager
def captured(halo: float, references=None, index_block=None):
    """While open, the decomposition has the halo ``halo`` and ``measure_decomposed`` keeps its inputs, its
    result and its time in the dict yielded; g(r) takes at most ``references`` reference centres, found in
    blocks of ``index_block`` particle indices."""
    kept = {}
    halo_of, measure = decomposition.default_halo, decomposed_statistics.measure_decomposed

    def keeping_measure(comm, params, share, species, drops, geometry, skip, substrate):
        kept.update(share=share, drops=drops, inputs=(species, geometry, skip, substrate))
        started = time.perf_counter()
        kept["decomposed"] = measure(comm, params, share, species, drops, geometry, skip, substrate)
        kept["seconds"] = comm.allreduce(time.perf_counter() - started, op=MPI.MAX)
        return kept["decomposed"]

    constants = statistics.RDF_REFERENCES, decomposed_statistics.INDEX_BLOCK
    decomposition.default_halo = lambda *args, **options: halo
    decomposed_statistics.measure_decomposed = keeping_measure
    statistics.RDF_REFERENCES = references or constants[0]
    decomposed_statistics.INDEX_BLOCK = index_block or constants[1]
    try:
        yield kept
    finally:
        decomposition.default_halo, decomposed_statistics.measure_decomposed = halo_of, measure
        statistics.RDF_REFERENCES, decomposed_statistics.INDEX_BLOCK = constants


def joined_drops(parts) -> Drops:
    """The drops of every particle, in particle order, from the ranks' (index, drops) pairs."""
    index = np.concatenate([i for i, _ in parts])
    order = np.argsort(index)
    return Drops(np.concatenate([d.species for _, d in parts])[order],
                 np.concatenate([d.scale for _, d in parts])[order])


def jsonable(value):
    array = np.asarray(value)
    return {"dtype": "int" if array.dtype.kind in "iub" else "float", "shape": list(array.shape),
            "values": array.astype(float).ravel().tolist()}


def cross_rank_contacts(result, geometry, params, owner) -> int:
    """Contacts of the gathered sediment between particles that different ranks own."""
    periodic = geometry.cylinder is None and params["lateral"] == "periodic"
    pairs, _ = structure.contact_pairs(result.positions, result.radii, result.particle, geometry.lower,
                                       geometry.upper, periodic)
    particles = owner[result.particle[pairs]]
    return int(np.count_nonzero(particles[:, 0] != particles[:, 1]))


def run_case(comm, params, options) -> dict | None:
    with captured(**options) as kept:
        solver.solve(params, np.random.default_rng(7), comm)
        if "decomposed" not in kept:
            raise RuntimeError("the deposition solver did not measure the spread sediment with measure_decomposed")
        share, mine = kept["share"], kept["decomposed"]
        species, geometry, skip, substrate = kept["inputs"]
        whole = share.gather(comm)
        everyone = comm.gather(mine, root=0)
        drops = comm.gather((share.index, kept["drops"]), root=0)
        if comm.rank != 0:
            return None
        indices = [index for index, _ in drops]
        started = time.perf_counter()
        serial = statistics.measure(params, whole, species, joined_drops(drops), geometry, skip, substrate)
        serial_seconds = time.perf_counter() - started
    outcome = compared(whole, geometry, params, indices, serial, mine, everyone)
    outcome["seconds"] = {"serial_measure": serial_seconds, "decomposed_measure": kept["seconds"]}
    return outcome


def compared(whole, geometry, params, indices, serial: dict, mine: dict, everyone: list[dict]) -> dict:
    """What a case reports: rank 0's spread statistics ``mine`` beside the serial ``serial`` of the gathered
    sediment ``whole``, whether every rank's statistics (``everyone``) are rank 0's, and how the particles
    (``indices``, per rank) and their contacts fell over the ranks."""
    owner = np.empty(len(whole.center_of_mass), dtype=np.int64)
    for rank, index in enumerate(indices):
        owner[index] = rank
    return {
        "particles_per_rank": [len(i) for i in indices],
        "cross_rank_contacts": cross_rank_contacts(whole, geometry, params, owner),
        "same_on_every_rank": all(set(other) == set(mine) and all(
            np.array_equal(np.asarray(other[k]), np.asarray(mine[k]), equal_nan=True) for k in mine)
            for other in everyone),
        "missing": sorted(set(serial) - set(mine)), "extra": sorted(set(mine) - set(serial)),
        "serial": {k: jsonable(v) for k, v in serial.items()},
        "decomposed": {k: jsonable(v) for k, v in mine.items() if k in serial},
    }


LATTICE = "touching lattice, periodic"


def lattice_share(comm, side=24, layers=12):
    """This rank's share of spheres of diameter 1 in touching rows along x (a periodic chain across the box of
    ``side``) stacked on a square lattice of rows in y and z, each row at a random offset in x, so that a
    centre distance of 1 rounds differently across the box's sides than inside it; the box cut across x into
    one block per rank: a sediment whose contact distance, 1 diameter, is an edge of g(r)'s shells, and
    whose ranks' frames are narrower than the box."""
    offset = np.random.default_rng(3).random((side, layers))
    i, j, k = np.meshgrid(np.arange(side, dtype=np.float64), np.arange(side), np.arange(layers), indexing="ij")
    com = np.column_stack([offset[j.ravel(), k.ravel()] + i.ravel(), j.ravel() + 0.5, k.ravel() + 0.5])
    mine = np.flatnonzero(np.minimum((com[:, 0] / side * comm.size).astype(np.int64), comm.size - 1) == comm.rank)
    n = len(mine)
    events = np.zeros((n, len(sdbd.EVENT_KINDS)), dtype=np.int32)
    rotation = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    result = sdbd.DepositionResult(
        positions=com[mine], radii=np.full(n, 0.5), particle=mine.astype(np.int64), center_of_mass=com[mine],
        rotation=rotation, contacts=np.full(n, 6, dtype=np.int8),
        state=np.full(n, sdbd.RESTING_THREE_CONTACTS, dtype=np.int8), event_counts=events,
        steps=np.ones(n, dtype=np.int32), stopped_at=-1, clocked_seconds=1.0)
    return decomposition.DecomposedDeposition(result, mine.astype(np.int64), np.ones(n, dtype=np.int64),
                                              np.zeros(n, dtype=np.int64), np.ones(n), {})


def lattice_case(comm) -> dict | None:
    """``measure_decomposed`` of :func:`lattice_share` against ``measure`` of the gathered lattice."""
    params = point({"n_particles": 24 * 24 * 12, "box_length": 24.0, "rdf_range": 1.5, "rdf_bins": 30}, None)
    species = solver.species_of(params)
    geometry = solver._container(params, species)
    substrate = solver.substrate_spheres(params)
    share = lattice_share(comm)
    drops = Drops(share.particle_shape, share.particle_scale)
    mine = decomposed_statistics.measure_decomposed(comm, params, share, species, drops, geometry, 0, substrate)
    whole = share.gather(comm)
    everyone = comm.gather(mine, root=0)
    indices = comm.gather(share.index, root=0)
    if comm.rank != 0:
        return None
    serial = statistics.measure(params, whole, species, Drops(np.zeros(len(whole.center_of_mass), dtype=np.int64),
                                                              np.ones(len(whole.center_of_mass))),
                                geometry, 0, substrate)
    return compared(whole, geometry, params, indices, serial, mine, everyone)


def reference_selections(comm) -> list[bool]:
    """Whether the references that ranks choose together are those the serial estimator chooses: candidates
    drawn at random among particle indices given to the ranks at random, for several numbers of references
    and blocks of indices."""
    outcomes = []
    for seed, (n_index, most, block) in enumerate([(5000, 37, 64), (5000, 1, 16), (5000, 2, 1024), (300, 2000, 64),
                                                   (20_000, 2000, 1024), (4096, 1500, 7)]):
        rng = np.random.default_rng(seed)
        owner = rng.integers(0, comm.size, n_index)
        candidate = rng.random(n_index) < 0.4
        mine = np.flatnonzero(candidate & (owner == comm.rank))
        kept = decomposed_statistics.INDEX_BLOCK
        decomposed_statistics.INDEX_BLOCK = block
        try:
            chosen = mine[decomposed_statistics._evenly_spaced(comm, mine, n_index, most)]
        finally:
            decomposed_statistics.INDEX_BLOCK = kept
        together = np.sort(np.concatenate(comm.allgather(chosen)))
        every = np.flatnonzero(candidate)
        alone = every[np.linspace(0, len(every) - 1, most).astype(np.int64)] if len(every) > most else every
        outcomes.append(bool(np.array_equal(together, alone)))
    return outcomes


def main(report_path):
    comm = MPI.COMM_WORLD
    folder = Path(report_path).resolve().parent
    if comm.rank == 0:
        write_substrate(folder / "substrate.csv")
    comm.Barrier()
    report = {"cases": {}, "reference_selections": reference_selections(comm)}
    lattice = lattice_case(comm)
    if comm.rank == 0:
        report["cases"][LATTICE] = lattice
    for name, (parameters, species, options) in cases(folder).items():
        outcome = run_case(comm, point(parameters, species), options)
        if comm.rank == 0:
            report["cases"][name] = outcome
    if comm.rank == 0:
        Path(report_path).write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main(sys.argv[1])
