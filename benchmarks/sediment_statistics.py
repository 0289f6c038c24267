"""Cost of a deposition sediment's statistics against that of its deposition, one core.

Requirement: the statistics of a sediment (everything ``parsim.deposition.statistics.measure`` computes:
packing fraction of the bulk slab and of the profile's slabs, coordination, contact numbers and
fabric, g(r), orientation) cost at most a fifth of its deposition; for spheres also at most a fifth
of the deposition at the speed aimed at, 100 000 spheres per second (2 microseconds per sphere).

For spheres, spiky (L = 3, 7 spheres), cube (L = 3, 26 spheres) and rod (L = 3, spheres 1 radius
apart, whose overlaps the packing fraction samples) particles, sediments of about 10^4, 10^5 and
10^6 spheres (up to --max-spheres) are solved as ``parsim run`` solves a deposition task: the
solver's default parameters (default packing_samples, profile_bins, rdf_range, rdf_bins), periodic
box, floor stops particles. The box side is chosen so that the filling height is about the box
side or less (from a guessed packing fraction per shape; the table prints h / box). The task runs
through the solver's own ``solve``; its deposition (``sdbd.deposit``) is timed by wrapping it, and
the statistics (``parsim.deposition.statistics.measure``) are measured --repeats times on the same
sediment, the fastest run counting. Times are CPU seconds of this process (time.process_time: the
kernels run on one thread, and other processes on the machine do not count); the deposition's
wall seconds are printed too.

Printed per sediment: spheres, deposition seconds, statistics seconds, their ratio (goal <= 0.2)
and each part's share of the deposition: the one contact search (pairs, normals and the spheres
that overlap), the packing fractions, g(r), the contact statistics computed from the search
(coordination, contact numbers, fabric) and the rest (heights, orientations, species, counts);
then the statistics per sphere, their ratio to a deposition of n / 100 000 s and the peak of the
memory the statistics allocate (tracemalloc, one more run), per sphere.

Numba compilation is paid first by the solver's warm-up task of each shape (a few particles).

    python benchmarks/sediment_statistics.py [--max-spheres 1000000] [--seed 1] [--repeats 3]
"""

import argparse
import contextlib
import math
import time
import tracemalloc

import numpy as np

from parsim.solvers import SOLVERS
from parsim.deposition import materials as deposition_materials, solver as deposition
from parsim.deposition import statistics as statistics

SOLVER = SOLVERS["deposition"]
SIZES = (10_000, 100_000, 1_000_000)
GOAL = 0.2  # statistics / deposition
AIMED_SPHERES_PER_SECOND = 100_000  # the deposition's speed aimed at, one core
# shape: (its parameters, a packing fraction a little below the one reached, so that h <= box side;
# h / box = this guess / (n V / (h box^2)), which came out 0.59 for spheres, 0.27 spiky, 0.28 cube)
SHAPES = {
    "sphere": ({"shape": "sphere"}, 0.55),
    "spiky": ({"shape": "spiky", "shape_size": 3}, 0.25),
    "cube": ({"shape": "cube", "shape_size": 3}, 0.25),
    "rod": ({"shape": "rod", "shape_size": 3}, 0.5),
}
# the parts of the statistics: (owner, function) timed inside measure
PARTS = {
    "contact search": (statistics.structure, "contact_network"),
    "packing (overlaps)": (statistics, "packing_cover"),
    "packing": (statistics, "packing_part"),
    "g(r)": (statistics, "rdf_part"),
    "contact statistics": (statistics, "contact_part"),
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
    """Replace ``owner.name`` by a wrapper that adds its CPU seconds to ``seconds[name]`` (and its wall
    seconds to ``seconds[name + " wall"]``)."""
    function = getattr(owner, name)

    def wrapper(*args, **kwargs):
        cpu, wall = time.process_time(), time.perf_counter()
        try:
            return function(*args, **kwargs)
        finally:
            seconds[name] = seconds.get(name, 0.0) + time.process_time() - cpu
            seconds[name + " wall"] = seconds.get(name + " wall", 0.0) + time.perf_counter() - wall

    setattr(owner, name, wrapper)
    try:
        yield
    finally:
        setattr(owner, name, function)


def solve(params, seed):
    """Deposit one task through the solver: (deposition CPU seconds, its wall seconds, the arguments of
    its statistics)."""
    seconds, arguments = {}, []
    measure = statistics.measure

    def keep(*args):
        arguments.append(args)
        return measure(*args)

    statistics.measure = keep
    try:
        with timed(deposition.sdbd, "deposit", seconds):
            SOLVER.solve(params, np.random.default_rng(seed), None)
    finally:
        statistics.measure = measure
    return seconds["deposit"], seconds["deposit wall"], arguments[0]


def measure_timed(arguments, repeats):
    """CPU seconds of the statistics and of their parts, from the fastest of ``repeats`` runs, and the
    statistics."""
    best = None
    for _ in range(repeats):
        seconds = {}
        with contextlib.ExitStack() as stack:
            for owner, name in PARTS.values():
                stack.enter_context(timed(owner, name, seconds))
            stack.enter_context(timed(statistics, "measure", seconds))
            result = statistics.measure(*arguments)
        if best is None or seconds["measure"] < best[0]["measure"]:
            best = seconds, result
    return best


def peak_bytes(arguments):
    """Peak of the memory the statistics allocate (tracemalloc: numpy's and numba's arrays)."""
    tracemalloc.start()
    try:
        statistics.measure(*arguments)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--max-spheres", type=int, default=1_000_000, help="largest sediment, in spheres")
    parser.add_argument("--seed", type=int, default=1, help="seed of every task's generator")
    parser.add_argument("--repeats", type=int, default=3, help="runs of the statistics of each sediment")
    args = parser.parse_args()

    start = time.perf_counter()
    for shape_params, phi_guess in SHAPES.values():  # compile (or load from numba's cache)
        SOLVER.solve(SOLVER.warm_up_parameters(task_parameters(shape_params, phi_guess, 1000)),
                     np.random.default_rng(0), None)
    print(f"warm-up (compilation or cache loading): {time.perf_counter() - start:.1f} s")

    defaults = {p.name: p.default for p in SOLVER.parameters}
    print(f"\nperiodic box, floor stop, packing_samples = {defaults['packing_samples']}, "
          f"profile_bins = {defaults['profile_bins']}, rdf_range = {defaults['rdf_range']:g}, "
          f"rdf_bins = {defaults['rdf_bins']}; CPU seconds of one core (deposition also wall); goal: statistics "
          f"<= {GOAL:g} x deposition; parts and 'at 100k/s' as fractions of the deposition\n")
    print("| shape | spheres | box | h / box | deposition [s] (wall) | statistics [s] | statistics / deposition "
          "| " + " | ".join(PARTS) + " | rest | statistics [µs/sphere] | statistics / (n / 100k/s) "
          "| peak [B/sphere] |")
    print("|---|--:|--:|--:|--:|--:|--:|" + "--:|" * len(PARTS) + "--:|--:|--:|--:|")
    for name, (shape_params, phi_guess) in SHAPES.items():
        for spheres in SIZES:
            if spheres > args.max_spheres:
                break
            params = task_parameters(shape_params, phi_guess, spheres)
            deposit_s, deposit_wall, arguments = solve(params, args.seed)
            seconds, result = measure_timed(arguments, args.repeats)
            peak = peak_bytes(arguments)
            n = result["n_spheres"]
            total = seconds["measure"]
            parts = [seconds[function] for _, function in PARTS.values()]
            aimed = n / AIMED_SPHERES_PER_SECOND
            box = params["box_length"]
            print(f"| {name} | {n:,} | {box:g} | {result['filling_height'] / box:.2f} "
                  f"| {deposit_s:.2f} ({deposit_wall:.2f}) | {total:.3f} | {total / deposit_s:.3f} | "
                  + " | ".join(f"{part / deposit_s:.3f}" for part in parts)
                  + f" | {(total - sum(parts)) / deposit_s:.3f} | {total / n * 1e6:.2f} | {total / aimed:.3f} "
                  f"| {peak / n:.0f} |", flush=True)
            del arguments, result


if __name__ == "__main__":
    main()
