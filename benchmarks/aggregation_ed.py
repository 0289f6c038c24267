"""Benchmark: event-driven ballistic aggregation to a single cluster, time vs N.

Setup of Degond et al. 2024, Table 1: d = 2, R = 0.2, m = 1, L = sqrt(N pi / V_f) R,
spheres on the square lattice, isotropic velocities |V| = 1 (eq. 4.3).  One core
(numba kernels are serial).  Numba compilation is excluded: a small run warms the
kernels up first.

Prints a table (N, wall time, events, collisions, wall reflections, re-bins, physical
time to the single cluster) and the least-squares exponent of wall time vs N over
N >= 1000.

    python benchmarks/aggregation_ed.py [--max-n 102400] [--volume-fraction 0.2] [--seed 1]
"""

import argparse
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

DEFAULT_MAX_N = 102400  # sizes are 100 * 4^k up to --max-n
RADIUS = 0.2


def setup(n, volume_fraction, seed):
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(n,)))
    L = box_length_for_volume_fraction(n, 2, RADIUS, volume_fraction)
    x = lattice_positions(n, 2, L, rng)
    v = isotropic_velocities(n, 2, 1.0, rng)
    return x, v, np.full(n, RADIUS), np.ones(n), L


def run(n, volume_fraction, seed, skin):
    x, v, r, m, L = setup(n, volume_fraction, seed)
    start = time.perf_counter()
    res = simulate_ed(x, v, r, m, L, skin=skin)
    wall = time.perf_counter() - start
    return wall, res


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-n", type=int, default=DEFAULT_MAX_N,
                        help=f"largest N to run; sizes are 100 * 4^k (default {DEFAULT_MAX_N})")
    parser.add_argument("--volume-fraction", type=float, default=0.2)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--skin", type=float, default=None, help="neighbour-list skin (default: automatic)")
    args = parser.parse_args(argv)

    run(64, args.volume_fraction, args.seed, args.skin)  # compile / load the numba cache

    print(f"ED ballistic aggregation, d = 2, R = {RADIUS}, V_f = {args.volume_fraction}, "
          f"lattice + isotropic |V| = 1, seed {args.seed}")
    header = f"{'N':>8} {'wall [s]':>10} {'events':>9} {'collisions':>10} {'walls':>7} {'re-bins':>9} {'T_single':>10}"
    print(header)
    print("-" * len(header))
    ns, walls = [], []
    n = 100
    while n <= args.max_n:
        wall, res = run(n, args.volume_fraction, args.seed, args.skin)
        if res.stop_reason != "single_cluster":
            raise RuntimeError(f"N = {n}: stopped with {res.stop_reason}")
        print(f"{n:>8} {wall:>10.3f} {res.n_events:>9} {res.n_collisions:>10} "
              f"{res.n_wall_reflections:>7} {res.n_rebins:>9} {res.time:>10.2f}", flush=True)
        ns.append(n)
        walls.append(wall)
        n *= 4
    big = [(n, w) for n, w in zip(ns, walls) if n >= 1000]
    if len(big) >= 2:
        slope = np.polyfit(np.log([n for n, _ in big]), np.log([w for _, w in big]), 1)[0]
        print(f"least-squares exponent of wall time vs N (N >= 1000): {slope:.2f}")
    else:
        print("exponent: needs at least two sizes with N >= 1000")


if __name__ == "__main__":
    main()
