"""Throughput of the SDBD deposition engine, one core (Topić & Pöschel 2016, section 5).

Two tables:

1. monodisperse spheres in a periodic box of 50 x 50 diameters, sediments of 10^4, 10^5 and
   10^6 spheres: spheres per second over the whole sediment and over its second half;
2. spiky and cube particles, L = 1 ... 9 (Fig. 12): spheres per second over the second half of
   sediments of about --spheres spheres in a periodic box of 50 x 50 diameters.

Numba compilation is paid by a warm-up run first.

    python benchmarks/deposition.py [--max-spheres 1000000] [--spheres 100000]
"""

import argparse
import time

import numpy as np

from parsim.core import sdbd
from parsim.core.shapes import cube, random_rotations, sphere, spiky

RADIUS = 0.5  # lengths in sphere diameters
BOX = 50.0


def deposit_timed(offsets, radii, n_particles, seed):
    """Seconds for the whole sediment and for its second half."""
    rng = np.random.default_rng(seed)
    rotation = random_rotations(n_particles, rng)
    drop = rng.random((n_particles, 2)) * BOX
    start = time.perf_counter()
    result = sdbd.deposit(offsets * RADIUS, radii * RADIUS, np.array([0, len(radii)]),
                          np.zeros(n_particles, dtype=np.int64), np.ones(n_particles), rotation, drop,
                          (0.0, 0.0), (BOX, BOX), sdbd.LATERAL_PERIODIC, sdbd.FLOOR_STOP,
                          clock_from_particle=n_particles // 2)
    total = time.perf_counter() - start
    if result.stopped_at >= 0:
        raise RuntimeError(f"particle {result.stopped_at} exceeded the event limit")
    return total, result.clocked_seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--max-spheres", type=int, default=1_000_000, help="largest monodisperse sediment")
    parser.add_argument("--spheres", type=int, default=100_000, help="spheres per spiky/cube sediment")
    args = parser.parse_args()

    one = sphere()
    deposit_timed(*one, 2000, seed=0)  # compile

    print(f"monodisperse spheres, periodic box {BOX:g} x {BOX:g} diameters, one core")
    print(f"{'spheres':>9} {'time [s]':>9} {'spheres/s':>10} {'2nd half spheres/s':>19}")
    for n in (10_000, 100_000, 1_000_000):
        if n > args.max_spheres:
            break
        total, second_half = deposit_timed(*one, n, seed=1)
        print(f"{n:>9} {total:>9.2f} {n / total:>10.0f} {(n - n // 2) / second_half:>19.0f}")

    print(f"\nspiky and cube particles (Fig. 12), about {args.spheres} spheres each, second half timed")
    print(f"{'L':>3} {'spiky spheres/s':>16} {'cube spheres/s':>15}")
    for size in range(1, 10):
        rates = []
        for make in (spiky, cube):
            offsets, radii = make(size)
            n_particles = max(2, args.spheres // len(radii))
            _, second_half = deposit_timed(offsets, radii, n_particles, seed=size)
            rates.append((n_particles - n_particles // 2) * len(radii) / second_half)
        print(f"{size:>3} {rates[0]:>16.0f} {rates[1]:>15.0f}")


if __name__ == "__main__":
    main()
