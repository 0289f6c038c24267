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
  ``messages`` (all ranks: per round two to each neighbour, and the reduction's);
* ``MB/rank``: the largest peak resident memory of a rank during the deposition, above what it held
  before (its own particles' inputs included; the serial run holds all of them);
* ``settle``: the share of the slowest rank's time spent settling particles (ahead of their turn
  while waiting included); ``us/round``: that rank's microseconds per round outside settling
  (packing, checking, inserting, and waiting when nothing is left to settle ahead);
* ``survey``: the seconds every rank spends drawing and reading all the particles' inputs (to
  validate them, survey them and keep its own), included in ``seconds``: work that does not shrink
  with K.

With ``--model``, rank 0 projects the time on as many cores of one node as the run has ranks, from
the run's own counts: ``T(K) = N t (1 + twice) / K + rounds (overhead + (2 + log2 K) latency) +
bytes / bandwidth + survey``, with ``t`` the serial seconds per particle, ``overhead`` the seconds
per round outside settling, the latencies those of the two exchanges with the neighbours and of
the reduction, ``bytes`` the most one rank sent.  Latency and bandwidth come from a ping-pong
between ranks 0 and 1, or from ``--latency-us`` and ``--bandwidth-gbs``, and the overhead from the
run or ``--overhead-us``, the survey from the run or ``--survey-seconds``: an oversubscribed run (its
times mean nothing, its counts do) takes all four from a 2-rank run of the same sediment.

    mpiexec -n 1 python benchmarks/parallel_deposition.py --spheres 1000000
    mpiexec -n 2 python benchmarks/parallel_deposition.py --spheres 1000000 --serial-seconds S --model
    mpiexec -n 8 python benchmarks/parallel_deposition.py --spheres 1000000 --serial-seconds S --model \
        --latency-us L --bandwidth-gbs B --overhead-us O --survey-seconds S2   # oversubscribed: its counts,
                                                                                # the 2-rank costs
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
from parsim.core.shapes import DrawnRotations, sphere  # noqa: E402
from parsim.deposition.spread import deposit_streamed  # noqa: E402

CHUNK = 1 << 20  # particles drawn at a time


def particle_chunks(n, box, seed=1):
    """A function yielding the particles' inputs in chunks, from the first particle at every call (``box``: the
    side of a square, or the (x, y) sides)."""

    def chunks():
        rotation_rng, drop_rng = np.random.default_rng(seed).spawn(2)
        for first in range(0, n, CHUNK):
            count = min(CHUNK, n - first)
            yield (np.zeros(count, dtype=np.int64), np.ones(count), DrawnRotations.draw(count, rotation_rng),
                   drop_rng.random((count, 2)) * np.broadcast_to(box, 2))

    return chunks


def shapes_and_box(box):
    offsets, radii = sphere()
    container = ((0.0, 0.0), tuple(np.broadcast_to(box, 2)), sdbd.LATERAL_PERIODIC, sdbd.FLOOR_ROLL)
    return (0.5 * offsets, 0.5 * radii, np.array([0, 1])), container


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
    parser.add_argument("--width", type=float, default=None,
                        help="the box's side along x, across the blocks (default: --box)")
    parser.add_argument("--serial-seconds", type=float, default=None)
    parser.add_argument("--model", action="store_true")
    parser.add_argument("--latency-us", type=float, default=None,
                        help="the model's latency (default: a ping-pong between ranks 0 and 1 of this run)")
    parser.add_argument("--bandwidth-gbs", type=float, default=None, help="the model's bandwidth (default: ping-pong)")
    parser.add_argument("--overhead-us", type=float, default=None,
                        help="the model's cost of a round outside settling (default: this run's)")
    parser.add_argument("--survey-seconds", type=float, default=None,
                        help="the model's survey seconds (default: this run's)")
    parser.add_argument("--window", type=int, default=None,
                        help="drop indices per rank in a round (default: deposit_streamed's)")
    parser.add_argument("--halo", type=float, default=None, help="halo in diameters (default: deposit_streamed's)")
    options = parser.parse_args()
    comm = MPI.COMM_WORLD
    ranks = comm.Get_size()
    if options.model and ranks > 1 and options.serial_seconds is None:
        parser.error("--model on several ranks needs --serial-seconds: the serial time, from a run on one rank")
    deposit_spread(comm, 2000, 40.0, seed=2)  # compile
    comm.Barrier()
    reset_peak()
    before = status_mb("VmRSS")
    start = time.perf_counter()
    tuning = {"window_per_rank": options.window, "halo": options.halo}
    box = (options.width or options.box, options.box)
    share = deposit_spread(comm, options.spheres, box,
                           **{key: value for key, value in tuning.items() if value is not None})
    seconds = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
    memory = comm.allreduce(status_mb("VmHWM") - before, op=MPI.MAX)
    tallies = comm.gather(share.tally)
    serial = options.serial_seconds
    if ranks == 1 and serial is None:
        sdbd.deposit(*serial_inputs(2000, 40.0, seed=2))  # compile
        arguments = serial_inputs(options.spheres, box)
        start = time.perf_counter()
        sdbd.deposit(*arguments)
        serial = time.perf_counter() - start
    counts = Counts.of(tallies, options.spheres) if comm.rank == 0 else None
    if comm.rank == 0:
        print(f"{'ranks':>5} {'spheres':>9} {'seconds':>8} {'serial s':>8} {'speedup':>7} {'settled twice':>13} "
              f"{'rounds':>6} {'bytes/p':>7} {'msgs/p':>6} {'MB/rank':>7} {'settle':>6} {'us/round':>8} "
              f"{'survey':>6}")
        print(f"{ranks:>5} {options.spheres:>9} {seconds:>8.2f} {serial if serial else float('nan'):>8.2f} "
              f"{(serial / seconds) if serial else float('nan'):>7.2f} {counts.twice:>13.2e} {counts.rounds:>6} "
              f"{counts.bytes_sent / options.spheres:>7.1f} {counts.messages / options.spheres:>6.3f} {memory:>7.0f} "
              f"{counts.settle_seconds / seconds:>6.2f} {counts.overhead * 1e6:>8.1f} {counts.survey:>6.2f}",
              flush=True)
    if options.model:
        measured = latency_and_bandwidth(comm) if ranks >= 2 and options.latency_us is None else (None, None)
        if comm.rank == 0:
            latency = options.latency_us * 1e-6 if options.latency_us is not None else measured[0]
            bandwidth = options.bandwidth_gbs * 1e9 if options.bandwidth_gbs is not None else measured[1]
            overhead = options.overhead_us * 1e-6 if options.overhead_us is not None else counts.overhead
            survey = options.survey_seconds if options.survey_seconds is not None else counts.survey
            modelled = counts.modelled(serial / options.spheres, ranks, latency, bandwidth, overhead, survey)
            print(f"model: {ranks} cores, latency {latency * 1e6:.1f} us, bandwidth {bandwidth / 1e9:.2f} GB/s, "
                  f"{overhead * 1e6:.1f} us per round outside settling, survey {survey:.2f} s: {modelled:.2f} s, "
                  f"speedup {serial / modelled:.2f}")


class Counts:
    """What a run of ``n`` particles counted, over its ranks: descents beyond one per particle (``twice``), rounds,
    bytes and messages sent, the slowest rank's seconds settling and, per round, outside settling
    (``overhead``), the largest bytes one rank sent, and the survey's seconds."""

    def __init__(self, **values):
        self.__dict__.update(values)

    @classmethod
    def of(cls, tallies, n):
        slowest = max(tallies, key=lambda t: t["round_seconds"])
        rounds = tallies[0]["rounds"]
        return cls(n=n, twice=sum(t["settles"] for t in tallies) / n - 1, rounds=rounds,
                   bytes_sent=sum(t["halo_bytes"] + t["footprint_bytes"] for t in tallies),
                   most_bytes=max(t["halo_bytes"] + t["footprint_bytes"] for t in tallies),
                   messages=sum(t["messages"] for t in tallies), settle_seconds=slowest["settle_seconds"],
                   overhead=(slowest["round_seconds"] - slowest["settle_seconds"]) / max(rounds, 1),
                   survey=max(t["survey_seconds"] for t in tallies))

    def modelled(self, t_particle, cores, latency, bandwidth, overhead, survey):
        """Seconds on ``cores`` cores of one node: the particles' descents (this run's share settled
        twice) evenly divided, each round's cost outside settling and its latencies (two exchanges
        with the neighbours, a reduction over every rank), the most bytes a rank sends, the survey."""
        per_round = overhead + (2 + math.ceil(math.log2(max(cores, 2)))) * latency
        return (self.n * t_particle * (1 + self.twice) / cores + self.rounds * per_round
                + self.most_bytes / bandwidth + survey)


if __name__ == "__main__":
    main()
