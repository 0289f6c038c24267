"""One task run whole by ``parsim run``, from process start to dataset, split by phase, on 1 and 2 ranks.

A user waits for the whole command, not for its steps.  This runs a job of one task as a user does
(``parsim run JOB`` on one rank, ``mpiexec -n 2 parsim run JOB --ranks-per-task 2`` on two), times
the process from its start to its exit, and reads each rank's seconds by phase from
``--phase-times`` (:mod:`parsim.phases`): reading the job, claiming the folder, the warm-up (numba
kernels loaded from the cache: a run before the timed ones fills it), the task's initial condition,
a spread sediment's survey, the steps (time steps, or the deposition's rounds), the statistics, the
rest of the solve (building the configuration), the task file, the row and the dataset.  What no
phase covers ("outside phases": the interpreter's start, imports, MPI's start and end, waiting in
the scheduler) is the process's time less the phases'.  On 2 ranks a phase's figure is its longest
rank's.

The table gives per phase the seconds on 1 and 2 ranks and their ratio, and the remainder outside
the steps in seconds per 10⁶ spheres: what a whole run keeps serial, beside the steps it shares.

The projection to 4, 8 and 16 ranks is Amdahl's law fitted to the two runs: of the steps' seconds
on one rank, ``s = 2 T_2 - T_1`` did not shrink on two ranks and the rest divides among the
ranks; everything outside the steps stays what it was on two ranks.  It assumes the shared part
keeps dividing evenly, which ``benchmarks/tiles.py``'s counts and model support for the
time-stepping steps (efficiency 0.95 on 16 ranks at 10⁶ discs) and
``benchmarks/parallel_deposition.py``'s for the spread rounds.

    python benchmarks/whole_task.py --case ts --spheres 250000 [--steps 3] [--repeat 2]
    python benchmarks/whole_task.py --case deposition --spheres 200000 [--box 120]
    python benchmarks/whole_task.py --case ts --spheres 250000 --steps 0    # to one cluster
"""

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TS_JOB = """
name = "whole_ts"
kind = "aggregation"
seed = 1
realizations = 1
[parameters]
method = "ts"
dimension = 2
n_spheres = {spheres}
volume_fraction = {volume_fraction}
{steps}
"""

DEPOSITION_JOB = """
name = "whole_deposition"
kind = "deposition"
seed = 1
realizations = 1
[parameters]
n_particles = {spheres}
box_length = {box}
"""

#: the phases in the order a run meets them (parsim.phases' names)
PHASES = ("read_job", "claim_folder", "warm_up", "initial_condition", "survey", "steps", "statistics",
          "solve_rest", "task_file", "row", "dataset")


def job_text(args) -> str:
    if args.case == "ts":
        steps = f"max_events = {args.steps}" if args.steps else ""
        return TS_JOB.format(spheres=args.spheres, volume_fraction=args.volume_fraction, steps=steps)
    return DEPOSITION_JOB.format(spheres=args.spheres, box=args.box)


def run(job: Path, output: Path, ranks: int) -> dict:
    """``parsim run`` of ``job`` on ``ranks`` ranks (each task on all of them): the process's seconds and
    each rank's phase times."""
    times = output.with_suffix(".phases.json")
    command = [sys.executable, "-m", "parsim", "run", str(job), "--output", str(output), "--quiet",
               "--phase-times", str(times)]
    if ranks > 1:
        command = [str(Path(sys.executable).with_name("mpiexec")), "-n", str(ranks), *command,
                   "--ranks-per-task", str(ranks)]
    start = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    seconds = time.perf_counter() - start
    return {"process": seconds, "ranks": json.loads(times.read_text())["ranks"]}


def by_phase(measured: dict) -> dict:
    """Seconds per phase (the longest rank's), the phases' sum on that rank and the rest of the process."""
    ranks = measured["ranks"]
    phases = {name: max(rank["seconds"].get(name, 0.0) for rank in ranks) for name in PHASES}
    covered = max(sum(rank["seconds"].values()) for rank in ranks)
    phases["outside phases"] = measured["process"] - covered
    phases["whole process"] = measured["process"]
    return phases


def best(runs: list[dict]) -> dict:
    """The repeated run of the shortest process (the least disturbed by other work on the machine)."""
    return min(runs, key=lambda figures: figures["whole process"])


def table(one: dict, two: dict, spheres: int) -> str:
    lines = ["| phase | 1 rank (s) | 2 ranks (s) | 1 / 2 |", "|---|--:|--:|--:|"]
    for name in one:
        ratio = f"{one[name] / two[name]:.2f}" if two[name] > 1e-3 else ""
        lines.append(f"| {name} | {one[name]:.2f} | {two[name]:.2f} | {ratio} |")
    for label, figures in (("1 rank", one), ("2 ranks", two)):
        remainder = figures["whole process"] - figures["steps"] - figures["warm_up"]
        lines.append(f"\n{label}: outside the steps and the warm-up {remainder:.2f} s, "
                     f"{remainder / spheres * 1e6:.2f} s per 10⁶ spheres")
    speedup = (one["whole process"] - one["warm_up"]) / (two["whole process"] - two["warm_up"])
    lines.append(f"whole task without the warm-up: 2 ranks {speedup:.2f}x one; "
                 f"steps {one['steps'] / two['steps']:.2f}x")
    return "\n".join(lines)


def projection(one: dict, two: dict, ranks=(2, 4, 8, 16)) -> str:
    """Whole-process and step seconds projected on ``ranks`` (see the module's docstring)."""
    kept = max(2.0 * two["steps"] - one["steps"], 0.0)  # the steps' seconds that did not divide
    outside = two["whole process"] - two["steps"]
    lines = ["| ranks | steps (s) | steps speedup | whole process (s) | whole speedup |", "|--:|--:|--:|--:|--:|"]
    for k in ranks:
        steps = kept + (one["steps"] - kept) / k
        whole = outside + steps
        lines.append(f"| {k} | {steps:.2f} | {one['steps'] / steps:.2f} | {whole:.2f} | "
                     f"{one['whole process'] / whole:.2f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--case", choices=("ts", "deposition"), default="ts")
    parser.add_argument("--spheres", type=int, default=250_000, help="discs or spheres of the task (default 250000)")
    parser.add_argument("--volume_fraction", type=float, default=0.3, help="ts: V_f (default 0.3)")
    parser.add_argument("--steps", type=int, default=3, help="ts: time steps (max_events); 0: to one cluster")
    parser.add_argument("--box", type=float, default=120.0, help="deposition: the box's side in diameters")
    parser.add_argument("--repeat", type=int, default=1, help="runs on each rank count; the shortest counts")
    parser.add_argument("--json", type=Path, help="write the figures here")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="whole_task_") as folder:
        work = Path(folder)
        job = work / "job.toml"
        job.write_text(job_text(args))
        for ranks in (1, 2):  # fill the kernel cache, the spread kernels included: the timed runs load them
            run(job, work / f"warm_{ranks}", ranks)
        figures = {ranks: best([by_phase(run(job, work / f"out_{ranks}_{k}", ranks)) for k in range(args.repeat)])
                   for ranks in (1, 2)}
    print(table(figures[1], figures[2], args.spheres))
    print("\nprojected (Amdahl's law fitted to the 1- and 2-rank runs):\n" + projection(figures[1], figures[2]))
    if args.json:
        args.json.write_text(json.dumps({"arguments": vars(args) | {"json": str(args.json)}, "figures": figures},
                                        indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
