"""Benchmark: time-stepping vs event-driven ballistic aggregation to a single cluster, time vs N.

Setup of Degond et al. 2024, Table 1: d = 2, R = 0.2, m = 1, L = sqrt(N pi / V_f) R,
spheres on the square lattice, isotropic velocities |V| = 1 (eq. 4.3).  The time-stepping
method (TS, almost-rigid, DAHA defaults) uses dt(0) = 0.005 L / max|V| (Delta t_1 of
Table 1); the event-driven method (ED) runs on the same initial conditions.  The default
sizes are the N of Table 1 up to 90 000 (the paper's Figure 6 also has 250 000 and, at
V_f 0.3, 10^6).  One core (numba kernels are serial).  Numba compilation is excluded: a run
of each method at N = 1600 and each V_f warms the kernels up first.

Prints, per (method, V_f, N), the mean wall and CPU time over the realizations (CPU time
is the better measure when other processes share the cores), time steps (TS) or events
(ED), DAHA minimisations and iterations (TS), then per (method, V_f) the least-squares
exponents of wall and CPU time vs N over N >= 1000, of CPU time over N >= 10^4, and the CPU
exponent between the two largest N, next to the paper's TS exponents.  Below about 10^4 a TS
run costs mostly per time step (0.05 s at N = 100, 0.2 s at 2500), which flattens a fit that
reaches down there: at V_f 0.3 the fit over 2500 ... 10^6 gives 1.25, over 10^4 ... 10^6 1.32
(docs/benchmarks.md, measured 2026-11-23).
Once a run of a (method, V_f) takes longer than --max-seconds, its larger N are skipped.

    python benchmarks/aggregation_ts.py [--sizes 100 400 1600] [--fractions 0.2] [--methods ts ed]
"""

import argparse
import math
import os
import sys
import time

import numpy as np

if __package__ in (None, ""):  # run as a script from a source tree
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), os.pardir))

from parsim.core.ed import simulate_ed  # noqa: E402
from parsim.core.initial import (  # noqa: E402
    box_length_for_volume_fraction,
    isotropic_velocities,
    lattice_positions,
)
from parsim.core.ts import MinimiserFailure, simulate_ts  # noqa: E402

RADIUS = 0.2
TIME_STEP_FACTOR = 0.005  # Delta t_1 of Table 1
FIT_MIN_N = 1000
#: The fit above the sizes where a TS run's cost is mostly per time step (module docstring).
UPPER_FIT_MIN_N = 10_000
#: Warm-up size: its first steps hold over 10^3 interacting spheres, so the tiled paths compile too.
WARM_UP_N = 1600
PAPER_TS_EXPONENTS = {0.1: 1.22, 0.2: 1.25, 0.3: 1.29}  # Degond et al. 2024, TS, d = 2


def setup(n, volume_fraction, seed, realization):
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(n, realization)))
    L = box_length_for_volume_fraction(n, 2, RADIUS, volume_fraction)
    x = lattice_positions(n, 2, L, rng)
    v = isotropic_velocities(n, 2, 1.0, rng)
    return x, v, np.full(n, RADIUS), np.ones(n), L


def run(method, n, volume_fraction, seed, realization):
    """Wall time, CPU time and (steps or events, minimisations, DAHA iterations) of one run."""
    x, v, r, m, L = setup(n, volume_fraction, seed, realization)
    start, start_cpu = time.perf_counter(), time.process_time()
    if method == "ts":
        res = simulate_ts(x, v, r, m, L, time_step_factor=TIME_STEP_FACTOR)
        counts = (res.n_steps, res.n_minimisations, res.n_iterations)
    else:
        res = simulate_ed(x, v, r, m, L)
        counts = (res.n_events, 0, 0)
    wall, cpu = time.perf_counter() - start, time.process_time() - start_cpu
    if res.stop_reason != "single_cluster":
        raise RuntimeError(f"{method} N = {n}: stopped with {res.stop_reason}")
    return wall, cpu, counts


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[100, 400, 900, 2500, 10_000, 40_000, 90_000])
    parser.add_argument("--fractions", type=float, nargs="+", default=[0.1, 0.2, 0.3])
    parser.add_argument("--realizations", type=int, default=1)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--methods", nargs="+", choices=("ts", "ed"), default=["ts", "ed"])
    parser.add_argument("--max-seconds", type=float, default=600.0,
                        help="skip larger N for a (method, V_f) once a run took longer (default 600)")
    args = parser.parse_args(argv)

    for method in args.methods:  # compile / load the numba cache, tiled minimisations included
        for vf in args.fractions:
            run(method, WARM_UP_N, vf, args.seed, 0)

    print(f"ballistic aggregation to one cluster, d = 2, R = {RADIUS}, lattice + isotropic |V| = 1, "
          f"TS dt(0) = {TIME_STEP_FACTOR} L / max|V|, seed {args.seed}, {args.realizations} realization(s)")
    header = (f"{'method':>6} {'V_f':>5} {'N':>7} {'wall [s]':>10} {'CPU [s]':>10} {'steps/events':>12} "
              f"{'minimisations':>13} {'DAHA iters':>11}")
    print(header)
    print("-" * len(header))
    times = {}  # (method, V_f) -> {N: (mean wall time, mean CPU time)}
    stopped = set()
    for vf in args.fractions:
        for n in sorted(args.sizes):
            for method in args.methods:
                if (method, vf) in stopped:
                    continue
                try:
                    runs = [run(method, n, vf, args.seed, k) for k in range(args.realizations)]
                except MinimiserFailure as failure:
                    print(f"{method:>6} {vf:>5.2f} {n:>7}  MinimiserFailure: {failure}", flush=True)
                    stopped.add((method, vf))
                    continue
                wall, cpu = np.mean([(w, c) for w, c, _ in runs], axis=0)
                steps, minimisations, iterations = np.mean([counts for _, _, counts in runs], axis=0)
                print(f"{method:>6} {vf:>5.2f} {n:>7} {wall:>10.3f} {cpu:>10.3f} {steps:>12.0f} "
                      f"{minimisations:>13.0f} {iterations:>11.0f}", flush=True)
                times.setdefault((method, vf), {})[n] = (wall, cpu)
                if max(w for w, _, _ in runs) > args.max_seconds:
                    stopped.add((method, vf))

    print(f"\nleast-squares exponents of wall and CPU time vs N (N >= {FIT_MIN_N}), of CPU time over "
          f"N >= {UPPER_FIT_MIN_N}, and of CPU time between the two largest N")
    for (method, vf), by_n in times.items():
        paper = PAPER_TS_EXPONENTS.get(vf)
        paper = f"{paper:.2f}" if paper is not None else "-"
        big = {n: t for n, t in by_n.items() if n >= FIT_MIN_N}
        if len(big) < 2:
            print(f"{method:>6} V_f = {vf:.2f}: needs at least two sizes with N >= {FIT_MIN_N}   (paper TS: {paper})")
            continue
        wall, cpu = _exponents(big)
        upper = {n: t for n, t in big.items() if n >= UPPER_FIT_MIN_N}
        upper = f"{_exponents(upper)[1]:.2f}" if len(upper) >= 2 else "-"
        (n1, (_, cpu1)), (n2, (_, cpu2)) = sorted(big.items())[-2:]
        top = math.log(cpu2 / cpu1) / math.log(n2 / n1)  # where the curve is steepest
        print(f"{method:>6} V_f = {vf:.2f}: wall {wall:.2f}, CPU {cpu:.2f}, CPU over N >= {UPPER_FIT_MIN_N}: {upper}, "
              f"CPU from N = {n1} to {n2}: {top:.2f}   (paper TS: {paper})")


def _exponents(by_n):
    """Least-squares exponents of the mean wall and CPU times ``by_n`` (N -> (wall, CPU)) vs N."""
    return np.polyfit(np.log(list(by_n)), np.log(list(by_n.values())), 1)[0]


if __name__ == "__main__":
    main()
