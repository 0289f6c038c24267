"""Benchmark: one time-stepping aggregation decomposed over MPI ranks (parsim.aggregation.tiled).

The TS task of benchmarks/aggregation_ts.py (d = 2, R = 0.2, lattice, |V| = 1, V_f = 0.3,
dt(0) = 0.005 L / max|V|, seed 1) runs for its first ``--steps`` time steps on each number of
ranks of ``--ranks`` (``mpiexec -n K`` is launched for each).  Printed per (N, ranks), per time
step, on the slowest rank where it is a time:

* ``wall`` and ``minimiser`` (the time inside DAHA) in seconds, and their speedups over one rank;
* ``comm``: seconds spent in communication (ghost rows and reductions, from Python and from the
  jitted iterations), and its share of the wall time;
* ``DAHA it.``: iterations; ``msgs/it.``, ``kB/it.``: ghost-row messages and kilobytes one rank
  sends per iteration from the jitted iterations (the most of any rank); ``red./it.``: global
  reductions per iteration, from anywhere; ``py calls``: MPI calls made from Python (halo
  exchanges, reductions, gathers, migrations), all kinds;
* MB sent per step, all ranks together, by kind: halo rows, reductions, gathers, migration.

Counts are measured, not timed, so ``--ranks 4 8 16`` on a 2-core machine still gives what a
cluster would send.  With ``--model``, the 2-rank run also measures this machine's MPI latency and
bandwidth (a ping-pong from Python) and the table ends with a projection of the efficiency on
every ``--ranks`` count from its counts:
``T(K) = T(1) / K + it. (msgs/it. latency + kB/it. / bandwidth + red./it. latency log2 K) +
py calls x python``, ``python`` the measured seconds per MPI call from Python (the ping-pong's
latency), and ``E(K) = T(1) / (K T(K))``.  It assumes the computation divides evenly among the
ranks, which the measured rows test.

    python benchmarks/tiles.py [--sizes 100000 1000000] [--ranks 1 2] [--steps 3] [--model]
"""

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time


if __package__ in (None, ""):  # run as a script from a source tree
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), os.pardir))

VOLUME_FRACTION = 0.3
KINDS = ("halo", "reduction", "gather", "migration")


def worker(out, n, volume_fraction, steps):
    """Run on every rank of COMM_WORLD; rank 0 writes the measurements to ``out`` (JSON)."""
    from mpi4py import MPI

    import parsim.core.ts.stepper as stepper
    from benchmarks.aggregation_ts import TIME_STEP_FACTOR, setup
    from benchmarks.mpi_timing import latency_and_bandwidth
    from parsim.core import kernel_mpi
    from parsim.aggregation.tiled import DecomposedDomain

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
    calls, sent, seconds = domain.traffic.totals()
    kernel = domain.traffic.kernel
    communication = sum(seconds.values()) - seconds.get("migration", 0.0)
    rows = comm.gather({"minimiser": minimiser_seconds[0], "comm": communication,
                        "bytes": {k: sent.get(k, 0) for k in KINDS}, "py_calls": sum(calls.values()),
                        "kernel_messages": float(kernel[kernel_mpi.MESSAGES]),
                        "kernel_bytes": float(kernel[kernel_mpi.BYTES]),
                        "reductions": float(kernel[kernel_mpi.REDUCTIONS]) + calls.get("reduction", 0)}, root=0)
    timing = latency_and_bandwidth(comm) if comm.Get_size() > 1 else (None, None)
    if comm.Get_rank() == 0:
        summary = {"n": n, "ranks": comm.Get_size(), "steps": int(result.n_steps), "wall": wall,
                   "iterations": int(result.n_iterations), "clusters": int(result.cluster_history[-1]),
                   "minimiser": max(row["minimiser"] for row in rows), "comm": max(row["comm"] for row in rows),
                   "bytes": {k: sum(row["bytes"][k] for row in rows) for k in KINDS},
                   **{key: max(row[key] for row in rows)
                      for key in ("py_calls", "kernel_messages", "kernel_bytes", "reductions")},
                   "latency": timing[0], "bandwidth": timing[1]}
        with open(out, "w") as file:
            json.dump(summary, file)


def projected_efficiency(one, row, latency, bandwidth):
    """The model of the module docstring, per time step, from the 1-rank row ``one`` and a row."""
    iterations = row["iterations"]
    per_iteration = (row["kernel_messages"] * latency + row["kernel_bytes"] / bandwidth
                     + row["reductions"] * latency * math.log2(max(row["ranks"], 2))) / iterations
    t1 = one["wall"] / one["steps"]
    tk = t1 / row["ranks"] + (iterations * per_iteration + row["py_calls"] * latency) / row["steps"]
    return t1 / (row["ranks"] * tk)


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
    parser.add_argument("--model", action="store_true", help="project the efficiency from the counts")
    parser.add_argument("--worker", nargs=3, metavar=("OUT", "N", "STEPS"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        out, n, steps = args.worker
        worker(out, int(n), VOLUME_FRACTION, int(steps))
        return
    print(f"TS, V_f = {VOLUME_FRACTION}, first {args.steps} time steps, per step, slowest rank")
    print("| N | ranks | wall s | speedup | minimiser s | speedup | comm s | comm share | DAHA it. | msgs/it. "
          "| kB/it. | red./it. | py calls | MB sent: halo | reduction | gather | migration |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for n in args.sizes:
        rows = [launch(n, ranks, args.steps) for ranks in args.ranks]
        one = next((row for row in rows if row["ranks"] == 1), None)
        for s in rows:
            per_step = {key: s[key] / s["steps"] for key in ("wall", "minimiser", "comm", "py_calls")}
            speedup = {key: (one[key] / one["steps"] / per_step[key] if one else float("nan"))
                       for key in ("wall", "minimiser")}
            it = max(s["iterations"], 1)
            sent = [s["bytes"][k] / s["steps"] / 1e6 for k in KINDS]
            print(f"| {n} | {s['ranks']} | {per_step['wall']:.3g} | {speedup['wall']:.2f} "
                  f"| {per_step['minimiser']:.3g} "
                  f"| {speedup['minimiser']:.2f} | {per_step['comm']:.3g} | {per_step['comm'] / per_step['wall']:.1%} "
                  f"| {s['iterations'] / s['steps']:.0f} | {s['kernel_messages'] / it:.2f} "
                  f"| {s['kernel_bytes'] / it / 1e3:.3g} | {s['reductions'] / it:.2f} | {per_step['py_calls']:.0f} | "
                  + " | ".join(f"{b:.3g}" for b in sent) + " |", flush=True)
        timed = next((row for row in rows if row["latency"] is not None), None)
        if args.model and one and timed:
            latency, bandwidth = timed["latency"], timed["bandwidth"]
            print(f"\nmodel (N = {n}): latency {latency * 1e6:.2f} us, bandwidth {bandwidth / 1e9:.1f} GB/s")
            for s in rows:
                if s["ranks"] > 1:
                    print(f"  {s['ranks']} ranks: projected efficiency "
                          f"{projected_efficiency(one, s, latency, bandwidth):.2f}", flush=True)

if __name__ == "__main__":
    main()
