"""Throughput of the SDBD deposition engine, one core (Topić & Pöschel 2016, section 5).

Two tables, and with ``--counters`` two more:

1. monodisperse spheres in a periodic box of 50 x 50 diameters, sediments of 10^4, 10^5, 10^6
   (and 10^7) spheres up to ``--max-spheres``.  Columns: ``time [s]`` of the whole deposition,
   ``spheres/s`` over the whole sediment, ``2nd half/s`` over its second half (the paper's
   measure), each followed by ``ratio``, that throughput over the 10^4 row's; ``bytes/sphere``
   the engine's memory: the peak resident memory of the deposition minus the resident memory
   just before ``sdbd.deposit`` (kernels compiled, inputs made), over the number of spheres,
   measured in a fresh process per row (see :func:`deposition_memory`).
2. spiky and cube particles, L = 1 ... 9 (Fig. 12): spheres per second over the second half of
   sediments of about ``--spheres`` spheres in a periodic box of 50 x 50 diameters.

``--counters``: every row of both tables is deposited once more with the engine's counters on
(``sdbd.deposit_with_diagnostics(..., count=True)``, see ``parsim/core/sdbd/counters.py``);
the times above stay those of the runs without counters, since counting costs time.  One line
per monodisperse size and per spiky / cube L:

* ``ev/sph``: executed events per sphere.  An executed event is one counted in the result's
  ``event_counts`` under its kind (a contact made or lost, a hanging, a trial rotation, a
  cycling interruption); the column ``simultaneous`` is left out, since it counts once more
  the extra events a move executed together, each already counted under its kind;
* ``st/sph``: decide-and-move steps per sphere;
* ``cand/ev``: sediment spheres tested as candidates (by the search of a fall and by the
  contact search of a rotation) per executed event;
* ``ns/cand``: nanoseconds per candidate test: the cycles of the falls (all of a fall's work)
  and of the contact searches over the candidates, turned into seconds with seconds per cycle
  = the counted ``deposit_with_diagnostics`` call's wall-clock seconds / its ``total_cycles``;
* share of the total cycles in percent: ``fall``; ``roll``, of which ``search`` (the contact
  search), of which ``grid`` (its grid queries), and ``trial`` (the decision after a trial
  rotation, 4.1); ``decide`` (contacts' geometry and the steepest-descent decision);
  ``after`` (bookkeeping after a move: the contacts kept, the cycling test); ``part``
  (dropping a particle and freezing it into the sediment); ``rest``, the remainder.

Numba compilation is paid by a warm-up run first.  The memory column costs each monodisperse
row one more deposition, in a fresh process that starts and loads the compiled kernels from
numba's cache in about 0.7 s: some 60 % more time on the default run (estimated from the rows
of 10^4 and 10^5 spheres and the throughputs of the others), not double, so it is always
measured; the 10^7 row, which dominates its run, takes about twice as long with it.

    python benchmarks/deposition.py [--max-spheres 1000000] [--spheres 100000] [--counters]
    python benchmarks/deposition.py --max-spheres 10000000   # adds the 10^7 row: a few minutes, about 2 GB
"""

import argparse
import ctypes
import gc
import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from parsim.core import sdbd
from parsim.core.sdbd.constants import EVENT_KINDS
from parsim.core.shapes import cube, random_rotations, sphere, spiky

RADIUS = 0.5  # lengths in sphere diameters
BOX = 50.0
SIZES = (10_000, 100_000, 1_000_000, 10_000_000)
SHAPES = (("spiky", spiky), ("cube", cube))
EXECUTED = [kind != "simultaneous" for kind in EVENT_KINDS]
#: columns of the cycle shares: (header, counter)
SHARES = (("fall", "fall_cycles"), ("roll", "roll_cycles"), ("search", "contact_search_cycles"),
          ("grid", "grid_cycles"), ("trial", "trial_cycles"), ("decide", "decide_cycles"),
          ("after", "after_move_cycles"), ("part", "particle_cycles"))
#: the phases that do not overlap; the rest of the total cycles is outside all of them
DISJOINT = ("fall_cycles", "roll_cycles", "decide_cycles", "after_move_cycles", "particle_cycles")


def deposition_inputs(offsets, radii, n_particles, seed):
    """Keyword arguments of ``sdbd.deposit``: ``n_particles`` of one shape at random drops."""
    rng = np.random.default_rng(seed)
    return dict(shape_offsets=offsets * RADIUS, shape_radii=radii * RADIUS, shape_start=np.array([0, len(radii)]),
                particle_shape=np.zeros(n_particles, dtype=np.int64), particle_scale=np.ones(n_particles),
                particle_rotation=random_rotations(n_particles, rng),
                particle_drop_xy=rng.random((n_particles, 2)) * BOX, box_lower_xy=(0.0, 0.0),
                box_upper_xy=(BOX, BOX), lateral=sdbd.LATERAL_PERIODIC, floor=sdbd.FLOOR_STOP)


def sphere_inputs(n_spheres):
    return deposition_inputs(*sphere(), n_spheres, seed=1)


def shape_inputs(make, size, spheres):
    """About ``spheres`` spheres in particles ``make(size)``."""
    offsets, radii = make(size)
    return deposition_inputs(offsets, radii, max(2, spheres // len(radii)), seed=size)


def sphere_count(inputs, first_particle=0):
    """Spheres of the particles from ``first_particle`` on."""
    return len(inputs["shape_radii"]) * (len(inputs["particle_shape"]) - first_particle)


def checked(result):
    if result.stopped_at >= 0:
        raise RuntimeError(f"particle {result.stopped_at} exceeded the event limit")
    return result


def warm_up():
    """Compile the kernels (or load them from numba's cache)."""
    checked(sdbd.deposit(**deposition_inputs(*sphere(), 100, seed=0)))


def deposit_timed(inputs):
    """Seconds of the deposition; spheres per second over the whole sediment and over its second half."""
    half = len(inputs["particle_shape"]) // 2
    start = time.perf_counter()
    result = checked(sdbd.deposit(**inputs, clock_from_particle=half))
    seconds = time.perf_counter() - start
    return seconds, sphere_count(inputs) / seconds, sphere_count(inputs, half) / result.clocked_seconds


def status_bytes(field):
    """A field of /proc/self/status given in kB (VmRSS, VmHWM), in bytes."""
    with open("/proc/self/status") as status:
        line = next(line for line in status if line.startswith(field + ":"))
    return int(line.split()[1]) * 1024


def deposition_memory(n_spheres):
    """Bytes per sphere of depositing ``n_spheres`` spheres; to run in a fresh process.

    The temporaries freed while making the inputs stay resident in glibc's heap, where the
    deposition would reuse them unseen: ``malloc_trim`` hands them back first (measured at
    10^4 spheres: 108 bytes per sphere without it, 180 with, as at 10^5).  Writing "5" to
    /proc/self/clear_refs then resets the peak VmHWM to the current VmRSS (Linux >= 4.0;
    checked on this machine: a freed 400 MB array's peak went back to the resident 26 MB),
    so that the compilation's and the inputs' peaks do not hide the deposition's."""
    warm_up()
    inputs = sphere_inputs(n_spheres)
    gc.collect()
    ctypes.CDLL("libc.so.6").malloc_trim(0)
    baseline = status_bytes("VmRSS")
    with open("/proc/self/clear_refs", "w") as clear_refs:
        clear_refs.write("5")
    checked(sdbd.deposit(**inputs))
    return (status_bytes("VmHWM") - baseline) / n_spheres


def memory_in_child(n_spheres):
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(deposition_memory, n_spheres).result()


def monodisperse_table(sizes):
    print(f"monodisperse spheres, periodic box {BOX:g} x {BOX:g} diameters, one core")
    print(f"{'spheres':>9} {'time [s]':>9} {'spheres/s':>10} {'ratio':>6} {'2nd half/s':>11} {'ratio':>6}"
          f" {'bytes/sphere':>13}")
    first = None
    for n in sizes:
        seconds, *rates = deposit_timed(sphere_inputs(n))
        first = first or rates
        print(f"{n:>9} {seconds:>9.2f} {rates[0]:>10.0f} {rates[0] / first[0]:>6.2f} {rates[1]:>11.0f}"
              f" {rates[1] / first[1]:>6.2f} {memory_in_child(n):>13.0f}")


def shapes_table(spheres):
    print(f"\nspiky and cube particles (Fig. 12), about {spheres} spheres each, second half timed")
    print(f"{'L':>3} {'spiky spheres/s':>16} {'cube spheres/s':>15}")
    for size in range(1, 10):
        rates = [deposit_timed(shape_inputs(make, size, spheres))[2] for _, make in SHAPES]
        print(f"{size:>3} {rates[0]:>16.0f} {rates[1]:>15.0f}")


COUNTERS_HEADER = (f"{'ev/sph':>6} {'st/sph':>6} {'cand/ev':>7} {'ns/cand':>7} |"
                   + "".join(f"{name:>7}" for name, _ in SHARES) + f"{'rest':>7}  (% of cycles)")


def counted(inputs):
    """The columns of the counters tables for a deposition of ``inputs`` with counters."""
    n_spheres = sphere_count(inputs)
    start = time.perf_counter()
    result, diagnostics = sdbd.deposit_with_diagnostics(**inputs, count=True)
    wall = time.perf_counter() - start
    c = diagnostics["counters"]
    events = checked(result).event_counts[:, EXECUTED].sum()
    candidates = c["fall_candidates"] + c["roll_candidates"]
    ns_per_candidate = 1e9 * wall / c["total_cycles"] * (c["fall_cycles"] + c["contact_search_cycles"]) / candidates
    shares = [100 * c[counter] / c["total_cycles"] for _, counter in SHARES]
    rest = 100 - 100 * sum(c[counter] for counter in DISJOINT) / c["total_cycles"]
    return (f"{events / n_spheres:>6.2f} {c['steps'] / n_spheres:>6.2f} {candidates / events:>7.1f}"
            f" {ns_per_candidate:>7.1f} |" + "".join(f"{share:>7.1f}" for share in shares + [rest]))


def counters_tables(sizes, spheres):
    print("\nmonodisperse spheres, counted runs")
    print(f"{'spheres':>9} {COUNTERS_HEADER}")
    for n in sizes:
        print(f"{n:>9} {counted(sphere_inputs(n))}")
    print("\nspiky and cube particles, counted runs")
    print(f"{'L':>3} {'shape':>5} {COUNTERS_HEADER}")
    for size in range(1, 10):
        for name, make in SHAPES:
            print(f"{size:>3} {name:>5} {counted(shape_inputs(make, size, spheres))}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--max-spheres", type=int, default=1_000_000,
                        help="largest monodisperse sediment (10000000 adds the 10^7 row)")
    parser.add_argument("--spheres", type=int, default=100_000, help="spheres per spiky/cube sediment")
    parser.add_argument("--counters", action="store_true", help="run every row again with the engine's counters")
    args = parser.parse_args()
    sizes = [n for n in SIZES if n <= args.max_spheres]

    warm_up()
    monodisperse_table(sizes)
    shapes_table(args.spheres)
    if args.counters:
        counters_tables(sizes, args.spheres)


if __name__ == "__main__":
    main()
