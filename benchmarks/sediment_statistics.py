"""Cost of a deposition sediment's statistics against that of its deposition, one core.

Requirement: the statistics of a sediment (packing fraction of the bulk slab and of the profile's
slabs, parsim.core.sediment.packing_fractions; coordination in the bulk slab) cost at most a fifth
of its deposition.

For spheres, spiky (L = 3, 7 spheres) and cube (L = 3, 26 spheres) particles, sediments of about
10^4, 10^5 and 10^6 spheres (up to --max-spheres) are solved as ``parsim run`` solves a deposition
task: the solver's default parameters (default packing_samples and profile_bins), periodic box,
floor stops particles. The box side is chosen so that the filling height is about the box side or
less (from a guessed packing fraction per shape; the table prints h / box). The task runs through
the solver's own ``solve``, whose two parts are timed separately (time.perf_counter) by wrapping
them: the deposition (``sdbd.deposit``) and the statistics (``_statistics``). Printed: spheres,
deposition seconds, statistics seconds and their ratio (goal <= 0.2).

Numba compilation is paid first by the solver's warm-up task of each shape (a few particles).

    python benchmarks/sediment_statistics.py [--max-spheres 1000000] [--seed 1]
"""

import argparse
import contextlib
import math
import time

import numpy as np

from parsim.solvers import SOLVERS
from parsim.solvers import deposition, deposition_materials

SOLVER = SOLVERS["deposition"]
SIZES = (10_000, 100_000, 1_000_000)
GOAL = 0.2  # statistics / deposition
# shape: (its parameters, a packing fraction a little below the one reached, so that h <= box side;
# h / box = this guess / (n V / (h box^2)), which came out 0.59 for spheres, 0.27 spiky, 0.28 cube)
SHAPES = {
    "sphere": ({"shape": "sphere"}, 0.55),
    "spiky": ({"shape": "spiky", "shape_size": 3}, 0.25),
    "cube": ({"shape": "cube", "shape_size": 3}, 0.25),
}


def task_parameters(shape_params, phi_guess, spheres):
    """The parameters of a deposition task of about ``spheres`` spheres, as ``parsim run`` builds them."""
    params = {p.name: p.default for p in SOLVER.parameters}
    params.update(shape_params, lateral="periodic", floor="stop")
    _, radii, volume = deposition_materials.particle_shape(params)
    n_particles = max(2, round(spheres / len(radii)))
    # h = n V / (phi L^2) <= L  <=>  L >= (n V / phi)^(1/3)
    box = math.ceil((n_particles * volume / phi_guess) ** (1.0 / 3.0))
    params.update(n_particles=n_particles, box_length=float(box))
    SOLVER.check(params)
    return params


@contextlib.contextmanager
def timed(owner, name, seconds):
    """Replace ``owner.name`` by a wrapper that adds its wall time to ``seconds[name]``."""
    function = getattr(owner, name)

    def wrapper(*args, **kwargs):
        start = time.perf_counter()
        try:
            return function(*args, **kwargs)
        finally:
            seconds[name] = seconds.get(name, 0.0) + time.perf_counter() - start

    setattr(owner, name, wrapper)
    try:
        yield
    finally:
        setattr(owner, name, function)


def solve_timed(params, seed):
    """Seconds of the deposition and of the statistics of one task, and the task's statistics."""
    seconds = {}
    with timed(deposition.sdbd, "deposit", seconds), timed(deposition.statistics, "measure", seconds):
        result = SOLVER.solve(params, np.random.default_rng(seed), None)
    return seconds["deposit"], seconds["measure"], result.statistics


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--max-spheres", type=int, default=1_000_000, help="largest sediment, in spheres")
    parser.add_argument("--seed", type=int, default=1, help="seed of every task's generator")
    args = parser.parse_args()

    start = time.perf_counter()
    for shape_params, phi_guess in SHAPES.values():  # compile (or load from numba's cache)
        SOLVER.solve(SOLVER.warm_up_parameters(task_parameters(shape_params, phi_guess, 1000)),
                     np.random.default_rng(0), None)
    print(f"warm-up (compilation or cache loading): {time.perf_counter() - start:.1f} s")

    defaults = {p.name: p.default for p in SOLVER.parameters}
    print(f"\nperiodic box, floor stop, packing_samples = {defaults['packing_samples']}, "
          f"profile_bins = {defaults['profile_bins']}, one core; goal: statistics <= {GOAL:g} x deposition\n")
    print("| shape | spheres | box | h / box | deposition [s] | statistics [s] | statistics / deposition |")
    print("|---|--:|--:|--:|--:|--:|--:|")
    for name, (shape_params, phi_guess) in SHAPES.items():
        for spheres in SIZES:
            if spheres > args.max_spheres:
                break
            params = task_parameters(shape_params, phi_guess, spheres)
            deposit_s, statistics_s, statistics = solve_timed(params, args.seed)
            box = params["box_length"]
            print(f"| {name} | {statistics['n_spheres']:,} | {box:g} | {statistics['filling_height'] / box:.2f} "
                  f"| {deposit_s:.2f} | {statistics_s:.2f} | {statistics_s / deposit_s:.3f} |", flush=True)


if __name__ == "__main__":
    main()
