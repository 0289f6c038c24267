"""One sediment of monodisperse spheres spread over MPI ranks (``deposit_streamed``): time, counts,
memory and a model of the speedup on more cores.

Run it under ``mpiexec``; every rank draws the same inputs (``--spheres`` spheres of diameter 1
dropped at random over a periodic box of ``--box`` x ``--box`` diameters, FLOOR_ROLL) a chunk at a
time and keeps its own, as ``parsim run --ranks-per-task`` does; it compiles the kernels on a small
sediment first, then deposits the big one.  Rank 0 prints one row:

* ``seconds``: the decomposed deposition, wall clock (slowest rank);
* ``serial s`` and ``speedup``: the serial ``deposit`` of the same inputs, measured on one rank
  (``mpiexec -n 1``: its row's speedup is the decomposition's overhead alone), or given with
  ``--serial-seconds`` to the runs on more ranks;
* ``settled twice``: descents beyond one per particle, over the particles (work thrown away);
* ``rounds``, and per particle ``bytes`` sent to other ranks (footprints and committed spheres) and
  ``messages`` (two all-to-alls and one reduction per round: ``2 (K - 1) + log2 K`` per rank);
* ``MB/rank``: the largest peak resident memory of a rank during the deposition, above what it held
  before (its own particles' inputs included; the serial run holds all of them);
* ``settle``: the share of the slowest rank's time spent settling particles; the rest is waiting
  and communicating;
* ``survey``: the seconds every rank spends drawing and reading all the particles' inputs (to
  validate them, survey them and keep its own), included in ``seconds``: work that does not shrink
  with K.

With ``--model``, rank 0 also measures the MPI latency and bandwidth of this machine (a ping-pong
between ranks 0 and 1) and projects the speedup on ``K`` cores of one node from the counts:
``T(K) = N t (1 + twice) / K + rounds (3 latency log2(2K) + python) + bytes / bandwidth``, with ``t``
the serial seconds per particle and ``python`` the measured seconds per round outside the kernels.

    mpiexec -n 1 python benchmarks/parallel_deposition.py --spheres 1000000
    mpiexec -n 2 python benchmarks/parallel_deposition.py --spheres 1000000 --serial-seconds S --model
    mpiexec -n 8 python benchmarks/parallel_deposition.py --spheres 100000   # counts only (oversubscribed)
"""

import argparse
import math
import os
import sys
import time

import numpy as np
from mpi4py import MPI

if __package__ in (None, ""):  # run as a script from a source tree
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), os.pardir))

from benchmarks.mpi_timing import latency_and_bandwidth  # noqa: E402
from parsim.core import sdbd  # noqa: E402
from parsim.core.shapes import random_rotations, sphere  # noqa: E402
from parsim.parallel.deposition import deposit_streamed  # noqa: E402

CHUNK = 1 << 20  # particles drawn at a time


def particle_chunks(n, box, seed=1):
    """A function yielding the particles' inputs in chunks, from the first particle at every call."""

    def chunks():
        rotation_rng, drop_rng = np.random.default_rng(seed).spawn(2)
        for first in range(0, n, CHUNK):
            count = min(CHUNK, n - first)
            yield (np.zeros(count, dtype=np.int64), np.ones(count), random_rotations(count, rotation_rng),
                   drop_rng.random((count, 2)) * box)

    return chunks


def shapes_and_box(box):
    offsets, radii = sphere()
    return (0.5 * offsets, 0.5 * radii, np.array([0, 1])), ((0.0, 0.0), (box, box), sdbd.LATERAL_PERIODIC,
                                                             sdbd.FLOOR_ROLL)


def deposit_spread(comm, n, box, seed=1, **options):
    shapes, container = shapes_and_box(box)
    return deposit_streamed(comm, *shapes, particle_chunks(n, box, seed), *container, **options)


def serial_inputs(n, box, seed=1):
    """The arguments of ``sdbd.deposit`` for the same particles, all of them at once."""
    shapes, container = shapes_and_box(box)
    return (*shapes, *[np.concatenate(column) for column in zip(*particle_chunks(n, box, seed)())], *container)


def status_mb(field):
    """A memory field of /proc/self/status (``VmRSS``, ``VmHWM``) in MB."""
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def reset_peak():
    with open("/proc/self/clear_refs", "w") as refs:
        refs.write("5")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--spheres", type=int, default=1_000_000)
    parser.add_argument("--box", type=float, default=300.0)
    parser.add_argument("--serial-seconds", type=float, default=None)
    parser.add_argument("--model", action="store_true")
    parser.add_argument("--window", type=int, default=None,
                        help="drop indices per rank in a round (default: deposit_streamed's)")
    parser.add_argument("--halo", type=float, default=None, help="halo in diameters (default: deposit_streamed's)")
    options = parser.parse_args()
    comm = MPI.COMM_WORLD
    ranks = comm.Get_size()
    deposit_spread(comm, 2000, 40.0, seed=2)  # compile
    comm.Barrier()
    reset_peak()
    before = status_mb("VmRSS")
    start = time.perf_counter()
    tuning = {"window_per_rank": options.window, "halo": options.halo}
    share = deposit_spread(comm, options.spheres, options.box,
                           **{key: value for key, value in tuning.items() if value is not None})
    seconds = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
    memory = comm.allreduce(status_mb("VmHWM") - before, op=MPI.MAX)
    tallies = comm.gather(share.tally)
    serial = options.serial_seconds
    if ranks == 1 and serial is None:
        sdbd.deposit(*serial_inputs(2000, 40.0, seed=2))  # compile
        arguments = serial_inputs(options.spheres, options.box)
        start = time.perf_counter()
        sdbd.deposit(*arguments)
        serial = time.perf_counter() - start
    if comm.rank == 0:
        n = options.spheres
        settles = sum(t["settles"] for t in tallies)
        rounds = tallies[0]["rounds"]
        sent = sum(t["halo_bytes"] + t["footprint_bytes"] for t in tallies)
        messages = rounds * (2 * (ranks - 1) + math.ceil(math.log2(ranks))) * ranks if ranks > 1 else 0
        slowest = max(tallies, key=lambda t: t["settle_seconds"])
        print(f"{'ranks':>5} {'spheres':>9} {'seconds':>8} {'serial s':>8} {'speedup':>7} {'settled twice':>13} "
              f"{'rounds':>6} {'bytes/p':>7} {'msgs/p':>6} {'MB/rank':>7} {'settle':>6} {'survey':>6}")
        print(f"{ranks:>5} {n:>9} {seconds:>8.2f} {serial if serial else float('nan'):>8.2f} "
              f"{(serial / seconds) if serial else float('nan'):>7.2f} {settles / n - 1:>13.2e} {rounds:>6} "
              f"{sent / n:>7.1f} {messages / n:>6.3f} {memory:>7.0f} {slowest['settle_seconds'] / seconds:>6.2f} "
              f"{max(t['survey_seconds'] for t in tallies):>6.2f}",
              flush=True)
    if options.model and ranks >= 2:
        latency, bandwidth = latency_and_bandwidth(comm)
        if comm.rank == 0:
            t_particle = serial / n
            python = (seconds - slowest["settle_seconds"]) / rounds
            twice = settles / n - 1
            print(f"latency {latency * 1e6:.1f} us, bandwidth {bandwidth / 1e9:.2f} GB/s, "
                  f"{python * 1e3:.2f} ms per round outside the kernels")
            for cores in (2, 4, 8, 16):
                modelled = (n * t_particle * (1 + twice) / cores + rounds * (3 * latency * math.log2(2 * cores)
                                                                            + python) + sent / bandwidth)
                print(f"model: {cores:>2} cores, {modelled:8.2f} s, speedup {serial / modelled:5.2f}")


if __name__ == "__main__":
    main()
