"""How far a particle's descent reads the sediment from its drop point: what a conservative window
of a decomposed deposition would have to bound in advance.

A decomposed deposition may settle a particle before an earlier particle of another rank only if
that particle cannot change its path.  A *conservative* scheme decides it before settling, from a
bound on how far a descent reaches; the *speculative* one (``parsim.deposition.spread``)
settles first and checks the rectangle the descent actually read (``record_reads``).  This prints
the distribution of that reach, the largest distance from the drop point to an edge of the read
rectangle, in sphere diameters, for monodisperse spheres of diameter 1 (FLOOR_ROLL):

* in a periodic box of ``--box`` diameters, ``--spheres`` particles dropped over all of it;
* on a heap (no lateral bounds), ``--heap-spheres`` particles dropped over a square of 2 x 2
  diameters, whose flanks they roll down.

    python benchmarks/deposition_reach.py [--spheres 200000] [--box 100] [--heap-spheres 20000]
"""

import argparse

import numpy as np

from parsim.core import sdbd
from parsim.core.shapes import random_rotations, sphere


def reach(n, box, lateral, spread, seed=5):
    """The reach of each of ``n`` particles dropped uniformly over a centred square of side ``spread``."""
    offsets, radii = sphere()
    rng = np.random.default_rng(seed)
    rotation = random_rotations(n, rng)
    drop = rng.random((n, 2)) * spread + (box - spread) / 2
    _, diagnostics = sdbd.deposit_with_diagnostics(
        0.5 * offsets, 0.5 * radii, np.array([0, 1]), np.zeros(n, dtype=np.int64), np.ones(n), rotation, drop,
        (0.0, 0.0), (box, box), lateral, sdbd.FLOOR_ROLL, record_reads=True)
    x_low, x_high, y_low, y_high = diagnostics["reads"].T
    x, y = drop.T
    return np.maximum.reduce([x - x_low, x_high - x, y - y_low, y_high - y])


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--spheres", type=int, default=200_000)
    parser.add_argument("--box", type=float, default=100.0)
    parser.add_argument("--heap-spheres", type=int, default=20_000)
    options = parser.parse_args()
    print(f"{'sediment':<28} {'median':>7} {'99 %':>7} {'99.9 %':>7} {'largest':>7}   reach [diameters]")
    cases = ((f"box {options.box:g}, {options.spheres} spheres", options.spheres, options.box,
              sdbd.LATERAL_PERIODIC, options.box),
             (f"heap, {options.heap_spheres} spheres", options.heap_spheres, 4.0 * options.box, sdbd.LATERAL_NONE,
              2.0))
    for name, n, box, lateral, spread in cases:
        quantiles = np.percentile(reach(n, box, lateral, spread), [50, 99, 99.9, 100])
        print(f"{name:<28} " + " ".join(f"{q:>7.2f}" for q in quantiles))


if __name__ == "__main__":
    main()
