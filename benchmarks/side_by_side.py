"""Two checkouts of parsim side by side: the instructions each executes for one task of each method.

    python benchmarks/side_by_side.py OLD_CHECKOUT NEW_CHECKOUT [--workloads ed ts dep]

A restructuring of the kernels must not slow them down, and on a shared 2-core machine the wall
time of one task varies by 10-20 % from one run to the next: too much to see 2 %.  The count of
executed instructions does not vary so: each workload below runs under valgrind's cachegrind
(``I refs``), once with the task and once without (the imports and a warm-up of a few spheres),
and the difference is the task's.  Numba compiles for a generic x86-64 (``NUMBA_CPU_NAME=generic``)
into a cache of each checkout's own, filled natively first, so that valgrind never compiles.

Workloads: event-driven aggregation of 25 600 discs (V_f 0.2, to one cluster), time stepping of
2 500 discs (V_f 0.2, to one cluster), deposition of 20 000 spheres in the benchmark's 50 x 50 box.
Instructions are a proxy for time: equal counts with a changed memory layout can still differ in
time, which the wall-time benchmarks of each method measure.
"""

import argparse
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

WORKLOADS = {"ed": 25_600, "ts": 2_500, "dep": 20_000}

TASK = """
import sys
tree, kind, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
sys.path[:0] = [tree, tree + "/benchmarks"]
import numpy as np
from parsim.core.initial import box_length_for_volume_fraction, isotropic_velocities, lattice_positions

def discs(n):
    rng = np.random.default_rng(1)
    length = box_length_for_volume_fraction(n, 2, 0.2, 0.2)
    return lattice_positions(n, 2, length, rng), isotropic_velocities(n, 2, 1.0, rng), np.full(n, 0.2), np.ones(n), length

if kind == "dep":
    import deposition
    from parsim.core import sdbd
    deposition.warm_up()
    if n:
        sdbd.deposit(**deposition.sphere_inputs(n))
else:
    try:
        from parsim.core.ed import simulate_ed
    except ImportError:  # a checkout from before the event-driven kernel became a package
        from parsim.core.aggregation_ed import simulate_ed
    from parsim.core.ts import simulate_ts
    run = simulate_ed if kind == "ed" else simulate_ts
    run(*discs(100))
    if n:
        run(*discs(n))
"""


#: cachegrind counts every thread: an idle BLAS or OpenMP thread that spins while it waits for work
#: executes as many instructions as the machine's load lets it, which made counts vary by several per cent
SINGLE_THREADED = {name: "1" for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
                                          "NUMBA_NUM_THREADS")}


def instructions(checkout: Path, cache: Path, script: Path, kind: str, n: int) -> int:
    """Instructions of one process running ``kind`` with ``n`` spheres (0: the warm-up alone)."""
    env = {**os.environ, "XDG_CACHE_HOME": str(cache), "PYTHONPATH": str(checkout), "NUMBA_CPU_NAME": "generic",
           "NUMBA_CPU_FEATURES": "", "PYTHONHASHSEED": "0", **SINGLE_THREADED}
    command = ["valgrind", "--tool=cachegrind", "--cache-sim=no", "--cachegrind-out-file=/dev/null",
               sys.executable, str(script), str(checkout), kind, str(n)]
    done = subprocess.run(command, env=env, capture_output=True, text=True, check=True)
    return int(re.search(r"I\s+refs:\s+([\d,]+)", done.stderr).group(1).replace(",", ""))


def net_instructions(checkout: Path, cache: Path, script: Path, kind: str, n: int) -> int:
    """Instructions of the task alone: one process with it less the median of three with the warm-up alone.
    A process with the warm-up alone executes one of two counts some 1.5 % apart from run to run (with
    the task, the count repeats to 0.02 %); the median takes the more frequent."""
    warm_ups = sorted(instructions(checkout, cache, script, kind, 0) for _ in range(3))
    return instructions(checkout, cache, script, kind, n) - warm_ups[1]


def compile_natively(checkout: Path, cache: Path, script: Path, kinds: list[str]) -> None:
    env = {**os.environ, "XDG_CACHE_HOME": str(cache), "PYTHONPATH": str(checkout), "NUMBA_CPU_NAME": "generic",
           "NUMBA_CPU_FEATURES": ""}
    for kind in kinds:
        subprocess.run([sys.executable, str(script), str(checkout), kind, "0"], env=env, check=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old", type=Path, help="a checkout of parsim (a git worktree of the older revision)")
    parser.add_argument("new", type=Path, help="another checkout")
    parser.add_argument("--workloads", nargs="+", choices=list(WORKLOADS), default=list(WORKLOADS),
                        help="the workloads to count (default: all)")
    options = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="parsim-side-by-side-") as folder:
        script = Path(folder) / "task.py"
        script.write_text(TASK)
        caches = {name: Path(folder) / f"cache-{name}" for name in ("old", "new")}
        for name in caches:
            compile_natively(getattr(options, name).resolve(), caches[name], script, options.workloads)
        print(f"{'workload':<28} {'old [10^9 instr.]':>18} {'new [10^9 instr.]':>18} {'new/old':>8}")
        for kind in options.workloads:
            n = WORKLOADS[kind]
            net = {}
            for name in caches:
                checkout = getattr(options, name).resolve()
                net[name] = net_instructions(checkout, caches[name], script, kind, n)
            print(f"{kind + ' ' + str(n):<28} {net['old'] / 1e9:>18.3f} {net['new'] / 1e9:>18.3f}"
                  f" {net['new'] / net['old']:>8.4f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
