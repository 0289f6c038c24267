"""Deposit a set of small sediments with ``deposit_decomposed`` on every rank of ``mpiexec -n K``
and, on rank 0, compare each with the serial ``deposit``; writes a JSON report to ``argv[1]``.  Every
other case gives the particles in chunks (``deposit_streamed``), of which each rank keeps its own.

The cases cover every particle shape kind, container, floor, wall contact, a species mixture whose
larger particles arrive later (the grid's cell grows), a substrate and a run that stops at the
event limit; their halos are small, so that particles conflict across blocks and roll out of
their owner's region.
"""

import json
import sys

import numpy as np
from mpi4py import MPI

from parsim.core import sdbd
from parsim.core.shapes import cube, random_rotations, rod, sphere, spiky, tripod
from parsim.deposition.spread import deposit_decomposed, deposit_streamed

FIELDS = ("positions", "radii", "particle", "center_of_mass", "rotation", "contacts", "state", "event_counts",
          "steps", "stopped_at")


def shapes(*made):
    """Shape arrays of (offsets, radii) pairs, each scaled to sphere radius 0.5."""
    offsets = np.concatenate([0.5 * o for o, _ in made])
    radii = np.concatenate([0.5 * r for _, r in made])
    start = np.concatenate([[0], np.cumsum([len(r) for _, r in made])])
    return offsets, radii, start


def case(n, box, lateral, floor, made, seed, shape_of=None, scale=None, inset=1.0, **options):
    rng = np.random.default_rng(seed)
    offsets, radii, start = shapes(*made)
    particle_shape = np.zeros(n, dtype=np.int64) if shape_of is None else shape_of(rng, n)
    drop = inset + rng.random((n, 2)) * (box - 2 * inset)
    return ((offsets, radii, start, particle_shape, np.ones(n) if scale is None else scale(particle_shape),
             random_rotations(n, rng), drop, (0.0, 0.0), (box, box), lateral, floor), options)


def lattice(box, spacing, radius):
    """A square lattice of spheres on the floor: a substrate."""
    ticks = np.arange(0.5 * spacing, box, spacing)
    x, y = np.meshgrid(ticks, ticks)
    positions = np.stack([x.ravel(), y.ravel(), np.full(x.size, radius)], axis=1)
    return positions, np.full(len(positions), radius)


def cases():
    substrate = lattice(12.0, 1.0, 0.35)
    return {
        "spheres, periodic, rolling floor": case(500, 12.0, sdbd.LATERAL_PERIODIC, sdbd.FLOOR_ROLL, [sphere()], 1,
                                                 halo=2.0),
        "tripods, periodic, sticking floor": case(160, 14.0, sdbd.LATERAL_PERIODIC, sdbd.FLOOR_STOP, [tripod(2)], 2,
                                                  halo=3.0),
        "cubes, walls, glued": case(120, 12.0, sdbd.LATERAL_WALLS, sdbd.FLOOR_ROLL, [cube(2)], 3, inset=1.6,
                                    halo=2.5, wall_contact=sdbd.WALL_GLUED),
        "rods and spiky, cylinder": case(140, 12.0, sdbd.LATERAL_WALLS, sdbd.FLOOR_STOP, [rod(3), spiky(3)], 4,
                                         shape_of=lambda rng, n: rng.integers(0, 2, n), inset=3.5, halo=2.5,
                                         container=sdbd.CONTAINER_CYLINDER, cylinder=(6.0, 6.0, 6.0, 24)),
        "heap": case(300, 8.0, sdbd.LATERAL_NONE, sdbd.FLOOR_ROLL, [sphere()], 5, inset=2.0, halo=1.5),
        "mixture growing, substrate": case(400, 12.0, sdbd.LATERAL_PERIODIC, sdbd.FLOOR_ROLL, [sphere(), sphere()],
                                           6, shape_of=lambda rng, n: (np.arange(n) > n // 3).astype(np.int64)
                                           * rng.integers(0, 2, n), scale=lambda s: np.where(s == 1, 1.4, 0.8),
                                           halo=2.0, substrate_positions=substrate[0],
                                           substrate_radii=substrate[1]),
        "event limit": case(300, 12.0, sdbd.LATERAL_PERIODIC, sdbd.FLOOR_ROLL, [sphere()], 7, halo=2.0,
                            max_events_per_particle=9),
    }


def in_chunks(arrays, size):
    """A function yielding ``arrays`` (particle_shape, particle_scale, particle_rotation, particle_drop_xy) in
    chunks of ``size`` particles."""
    return lambda: (tuple(array[first:first + size] for array in arrays) for first in range(0, len(arrays[0]), size))


def main(report_path):
    comm = MPI.COMM_WORLD
    report = {}
    for number, (name, (args, options)) in enumerate(cases().items()):
        if number % 2 == 0:  # every rank holds all particles' inputs
            share = deposit_decomposed(comm, *args, **options, window_per_rank=48, check=True)
        else:  # each rank keeps its own of chunks of 41 particles (the grid's cell grows within and across them)
            share = deposit_streamed(comm, *args[:3], in_chunks(args[3:7], 41), *args[7:], **options,
                                     window_per_rank=48, check=True)
        tallies = comm.gather(share.tally)
        whole = share.gather(comm)
        if comm.rank == 0:
            serial = sdbd.deposit(*args, **{k: v for k, v in options.items() if k != "halo"})
            report[name] = {
                "equal": {f: bool(np.array_equal(getattr(whole, f), getattr(serial, f))
                                  and np.shape(getattr(whole, f)) == np.shape(getattr(serial, f))) for f in FIELDS},
                "particles": len(serial.state), "stopped_at": serial.stopped_at,
                "tally": {k: sum(t[k] for t in tallies) for k in ("conflicts", "fetches", "settles", "rounds",
                                                                  "halo_particles")},
                "blocks_with_particles": sum(1 for t in tallies if t["particles"] > 0),
            }
    if comm.rank == 0:
        with open(report_path, "w") as out:
            json.dump(report, out, indent=1)


if __name__ == "__main__":
    main(sys.argv[1])
