"""The ensemble runner: parallel efficiency on unequal tasks, and throughput on very many tiny ones.

``spread``: one aggregation job of 24 tasks whose costs differ about 100-fold (N from 1600 to
102400) on 1 rank and on 2 ranks; prints the efficiency T1 / (2 T2).

``tiny``: one aggregation job of ``--tasks`` tasks (default 10⁵) of 9 discs each, about a
millisecond of computing apiece, with ``configurations = "none"``; on 1 and 2 ranks, prints the
tasks per second handed out and finished (from ``parsim run``'s closing line), the time to
assemble and write the dataset, the wall time, and the files the output folder holds.

Numba compilation is paid by a warm-up run first.

    python benchmarks/ensemble.py [--case spread|tiny|both] [--realizations 6] [--tasks 100000]
"""

import argparse
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SPREAD_JOB = """
name = "ensemble_benchmark"
kind = "aggregation"
seed = 1
realizations = {realizations}
[parameters]
volume_fraction = 0.2
[sweep]
n_spheres = [1600, 6400, 25600, 102400]
"""

TINY_JOB = """
name = "tiny_tasks"
kind = "aggregation"
seed = 1
realizations = {realizations}
configurations = "none"
[parameters]
dimension = 2
n_spheres = 9
pair_distribution_points = 2
box_levels = 2
[sweep]
volume_fraction = [0.03, 0.04, 0.05, 0.06]
"""

CLOSING_LINE = re.compile(r"parsim: (\d+) tasks in ([\d.]+) s \((\d+) tasks/s on (\d+) ranks\), "
                          r"dataset written in ([\d.]+) s")


def run(job: Path, output: Path, ranks: int, quiet: bool = True) -> tuple[float, str]:
    """Wall time and standard error of ``parsim run`` on ``ranks`` ranks."""
    command = [sys.executable, "-m", "parsim.cli", "run", str(job), "--output", str(output)]
    if quiet:
        command.append("--quiet")
    if ranks > 1:
        command = [str(Path(sys.executable).with_name("mpiexec")), "-n", str(ranks), *command]
    start = time.perf_counter()
    finished = subprocess.run(command, check=True, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
    return time.perf_counter() - start, finished.stderr


def spread(folder: Path, realizations: int) -> None:
    job = folder / "spread.toml"
    job.write_text(SPREAD_JOB.format(realizations=realizations))
    warm = folder / "warm.toml"
    warm.write_text(SPREAD_JOB.format(realizations=1).replace("[1600, 6400, 25600, 102400]", "[16]"))
    run(warm, folder / "warm", 1)
    start_up, _ = run(warm, folder / "warm", 1)  # everything done: start-up and dataset only
    one, _ = run(job, folder / "one", 1)
    two, _ = run(job, folder / "two", 2)
    print(f"spread: {4 * realizations} tasks (N = 1600 ... 102400, ~100-fold cost spread), wall time including "
          f"start-up ({start_up:.2f} s for a job with nothing left to do)")
    print(f"{'ranks':>5} {'time [s]':>10}")
    print(f"{1:>5} {one:>10.2f}")
    print(f"{2:>5} {two:>10.2f}")
    print(f"parallel efficiency T1 / (2 T2) = {one / (2 * two):.3f}")


def tiny(folder: Path, tasks: int) -> None:
    job = folder / "tiny.toml"
    job.write_text(TINY_JOB.format(realizations=-(-tasks // 4)))
    warm = folder / "tiny_warm.toml"
    warm.write_text(TINY_JOB.format(realizations=1))
    run(warm, folder / "tiny_warm", 1)
    print(f"tiny: {4 * -(-tasks // 4)} tasks of 9 discs, configurations = \"none\"")
    print(f"{'ranks':>5} {'tasks/s':>8} {'computing [s]':>14} {'dataset [s]':>12} {'wall [s]':>9} {'files':>6} "
          f"{'dataset again [s]':>18}")
    for ranks in (1, 2):
        output = folder / f"tiny{ranks}"
        wall, log = run(job, output, ranks, quiet=False)
        closing = CLOSING_LINE.search(log)
        if closing is None:
            raise SystemExit(f"no closing line in parsim run's output:\n{log[-2000:]}")
        _, computing, rate, _, dataset = closing.groups()
        files = sum(1 for path in output.rglob("*") if path.is_file())
        again, _ = run(job, output, ranks)  # nothing to compute: start-up, reading the rows, the dataset
        print(f"{ranks:>5} {rate:>8} {float(computing):>14.1f} {float(dataset):>12.2f} {wall:>9.1f} {files:>6} "
              f"{again:>18.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--case", choices=("spread", "tiny", "both"), default="both")
    parser.add_argument("--realizations", type=int, default=6, help="spread: realisations per N (4 values of N)")
    parser.add_argument("--tasks", type=int, default=100_000, help="tiny: number of tasks")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        if args.case in ("spread", "both"):
            spread(Path(folder), args.realizations)
        if args.case in ("tiny", "both"):
            tiny(Path(folder), args.tasks)


if __name__ == "__main__":
    main()
