"""Benchmark: one time-stepping aggregation decomposed over MPI ranks (parsim.parallel.tiled).

The TS task of benchmarks/aggregation_ts.py (d = 2, R = 0.2, lattice, |V| = 1, V_f = 0.3,
dt(0) = 0.005 L / max|V|, seed 1) runs for its first ``--steps`` time steps on each number of
ranks of ``--ranks`` (``mpiexec -n K`` is launched for each).  Printed per (N, ranks): wall
time per step, the time inside the minimiser per step, the time the slowest rank spent in halo
exchanges and in reductions/gathers, the speedups over one rank, and the data sent per step
(all ranks together) by kind: halo rows, reductions, gathers, migration.  Byte counts are
measured, not timed, so ``--ranks 4 8`` on a 2-core machine still gives the communication
volume a cluster would see.

    python benchmarks/tiles.py [--sizes 100000 1000000] [--ranks 1 2] [--steps 3]
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

if __package__ in (None, ""):  # run as a script from a source tree
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), os.pardir))

VOLUME_FRACTION = 0.3
KINDS = ("halo", "reduction", "gather", "migration")


def worker(out, n, volume_fraction, steps):
    """Run on every rank of COMM_WORLD; rank 0 writes the measurements to ``out`` (JSON)."""
    from mpi4py import MPI

    import parsim.core.ts.stepper as stepper
    from benchmarks.aggregation_ts import TIME_STEP_FACTOR, setup
    from parsim.parallel.tiled import DecomposedDomain

    comm = MPI.COMM_WORLD
    minimiser_seconds = [0.0]
    timed = stepper.minimise

    def minimise(*args, **kwargs):  # the time inside DAHA, halo exchanges and reductions included
        started = time.perf_counter()
        try:
            return timed(*args, **kwargs)
        finally:
            minimiser_seconds[0] += time.perf_counter() - started

    stepper.minimise = minimise
    warm = setup(200, volume_fraction, 1, 0)  # compile (or load) the numba kernels first, on each rank alone
    stepper.simulate_ts(*warm, time_step_factor=TIME_STEP_FACTOR)
    minimiser_seconds[0] = 0.0
    x, v, r, m, L = setup(n, volume_fraction, 1, 0)
    domain = DecomposedDomain(comm, L, 2)
    comm.Barrier()
    started = time.perf_counter()
    result = stepper.simulate_ts(x, v, r, m, L, time_step_factor=TIME_STEP_FACTOR, max_steps=steps, domain=domain)
    wall = comm.allreduce(time.perf_counter() - started, op=MPI.MAX)
    traffic = domain.traffic
    rows = comm.gather({"minimiser": minimiser_seconds[0],
                        "seconds": {k: traffic.seconds[k] for k in KINDS},
                        "bytes": {k: traffic.bytes[k] for k in KINDS}}, root=0)
    if comm.Get_rank() == 0:
        summary = {"n": n, "ranks": comm.Get_size(), "steps": int(result.n_steps), "wall": wall,
                   "iterations": int(result.n_iterations), "clusters": int(result.cluster_history[-1]),
                   "imbalance": float(np.mean(result.imbalance)) if result.imbalance.size else 1.0,
                   "minimiser": max(row["minimiser"] for row in rows),
                   "seconds": {k: max(row["seconds"][k] for row in rows) for k in KINDS},
                   "bytes": {k: sum(row["bytes"][k] for row in rows) for k in KINDS}}
        with open(out, "w") as file:
            json.dump(summary, file)


def launch(n, ranks, steps):
    """One ``mpiexec -n ranks`` run of :func:`worker`; returns its summary."""
    mpiexec = os.path.join(os.path.dirname(sys.executable), "mpiexec")
    with tempfile.TemporaryDirectory() as folder:
        out = os.path.join(folder, "summary.json")
        root = os.path.join(os.path.dirname(os.path.abspath(__file__)), os.pardir)
        command = [mpiexec if os.path.exists(mpiexec) else "mpiexec", "-n", str(ranks), sys.executable,
                   "-m", "benchmarks.tiles", "--worker", out, str(n), str(steps)]
        subprocess.run(command, check=True, cwd=root)
        with open(out) as file:
            return json.load(file)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[100_000, 1_000_000])
    parser.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--steps", type=int, default=3, help="time steps timed per run")
    parser.add_argument("--worker", nargs=3, metavar=("OUT", "N", "STEPS"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        out, n, steps = args.worker
        worker(out, int(n), VOLUME_FRACTION, int(steps))
        return
    print(f"TS, V_f = {VOLUME_FRACTION}, first {args.steps} time steps, times per step (s), slowest rank")
    print("| N | ranks | wall | speedup | minimiser | speedup | halo | reductions+gathers | imbalance "
          "| DAHA it. | MB sent per step: halo | reduction | gather | migration |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for n in args.sizes:
        one = None
        for ranks in args.ranks:
            s = launch(n, ranks, args.steps)
            per_step = {key: s[key] / s["steps"] for key in ("wall", "minimiser")}
            one = one or per_step if ranks == 1 else one
            speedup = {key: (one[key] / per_step[key] if one else float("nan")) for key in per_step}
            sent = [s["bytes"][k] / s["steps"] / 1e6 for k in KINDS]
            print(f"| {n} | {ranks} | {per_step['wall']:.3g} | {speedup['wall']:.2f} | {per_step['minimiser']:.3g} "
                  f"| {speedup['minimiser']:.2f} | {s['seconds']['halo'] / s['steps']:.3g} "
                  f"| {(s['seconds']['reduction'] + s['seconds']['gather']) / s['steps']:.3g} "
                  f"| {s['imbalance']:.2f} | {s['iterations']} | " + " | ".join(f"{b:.3g}" for b in sent) + " |",
                  flush=True)


if __name__ == "__main__":
    main()
