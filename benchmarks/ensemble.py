"""Parallel efficiency of the ensemble scheduler on tasks of unequal cost.

Runs one aggregation job of 24 tasks whose costs differ about 100-fold
(N from 1600 to 102400) on 1 rank and on 2 ranks, and prints the efficiency
T1 / (2 T2).  Numba compilation is paid by a warm-up run first.

    python benchmarks/ensemble.py [--realizations 6]
"""

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

JOB = """
name = "ensemble_benchmark"
kind = "aggregation"
seed = 1
realizations = {realizations}
[parameters]
volume_fraction = 0.2
[sweep]
n_spheres = [1600, 6400, 25600, 102400]
"""


def timed_run(job: Path, output: Path, ranks: int) -> float:
    command = [sys.executable, "-m", "parsim.cli", "run", str(job), "--output", str(output), "--quiet"]
    if ranks > 1:
        command = [str(Path(sys.executable).with_name("mpiexec")), "-n", str(ranks), *command]
    start = time.perf_counter()
    subprocess.run(command, check=True)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--realizations", type=int, default=6, help="realisations per N (4 values of N)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        job = folder / "job.toml"
        job.write_text(JOB.format(realizations=args.realizations))
        warm = folder / "warm.toml"
        warm.write_text(JOB.format(realizations=1).replace("[1600, 6400, 25600, 102400]", "[16]"))
        timed_run(warm, folder / "warm", 1)
        start_up = timed_run(warm, folder / "warm", 1)  # everything done: start-up and dataset only
        one = timed_run(job, folder / "one", 1)
        two = timed_run(job, folder / "two", 2)
    tasks = 4 * args.realizations
    print(f"{tasks} tasks (N = 1600 ... 102400, ~100-fold cost spread), wall time including start-up "
          f"({start_up:.2f} s for a job with nothing left to do)")
    print(f"{'ranks':>5} {'time [s]':>10}")
    print(f"{1:>5} {one:>10.2f}")
    print(f"{2:>5} {two:>10.2f}")
    print(f"parallel efficiency T1 / (2 T2) = {one / (2 * two):.3f}")


if __name__ == "__main__":
    main()
