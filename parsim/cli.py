"""The ``parsim`` command.

    parsim run JOB [--output DIR] [--quiet] [--ranks-per-task K]
                                              run (or resume) a job, on one rank or under mpiexec;
                                              K ranks run each task together (default 1)
    parsim validate JOB [--output DIR]        check a job file and its output location, compute nothing
    parsim compile [JOB] [--ranks-per-task K] compile the kernels a job needs (default: every solver's)
                                              into the cache, e.g. on a login node before a batch job;
                                              with K > 1 those of tasks spread over K ranks
    parsim info OUTPUT                        what an output folder holds and how far its job got
    parsim plot OUTPUT [--figure NAME] [--out PATH] [--task LABEL]
                                              the papers' figures from a job's outputs, PNG and PDF
                                              (default: every figure the dataset supports, in OUTPUT/figures)
    parsim export OUTPUT [--task LABEL | --all] --format FORMAT [--out PATH]
                                              a task's configuration for OVITO, ParaView, LAMMPS, YADE,
                                              ASE or a CSV table (docs/export.md)
    parsim --version                          the installed version

``python -m parsim`` is the same command.

Errors a user can cause are printed as one line, without a traceback: exit
status 2 for a job that cannot run as written (checked before anything is
computed), 1 for a failure while it runs (a task, a full disk).  Under
mpiexec, rank 0 prints the line and every rank ends; an unexpected failure on
one rank alone aborts the whole job.  Ctrl-C before a run's tasks start (or in
any other command) is one line and status 130; a reader of the output that has
gone (``parsim info OUT | head -1``) ends the command quietly with status 141,
as SIGPIPE ends ``cat``.
"""

import argparse
import os
import signal
import sys
from pathlib import Path

from parsim import options
from parsim.errors import EXIT_RUN_FAILED, EXIT_UNFINISHED, EXIT_USER_ERROR, JobError, ParsimError, exit_status
from parsim.version import __version__

#: Exit status after Ctrl-C, as the shell gives a process that SIGINT ended.
EXIT_INTERRUPTED = 128 + signal.SIGINT
#: Exit status when the reader of standard output has gone, as the shell gives a process that SIGPIPE ended.
EXIT_READER_GONE = 128 + signal.SIGPIPE


class _Parser(argparse.ArgumentParser):
    """argparse's parser whose usage errors are one line, as parsim's other errors: under mpiexec every
    rank meets the error before MPI starts, and the launcher's rank 0 alone prints it."""

    def error(self, message: str):
        from parsim.parallel.launcher import speaks_for_all  # nothing but os: no MPI yet

        self.exit(EXIT_USER_ERROR, f"parsim: error: {message} (see {self.prog} --help)\n" if speaks_for_all() else None)


def main(argv: list[str] | None = None) -> int:
    """The command line; heavy modules are imported only here, so that a Ctrl-C while they load is
    one line too (the launcher's rank 0 alone prints it under mpiexec)."""
    from parsim.parallel.launcher import speaks_for_all  # nothing but os: no MPI yet

    try:
        args = _parser().parse_args(argv)
        status = _command(args)
        sys.stdout.flush()  # a reader that has gone is met here, not when the interpreter exits
        return status
    except KeyboardInterrupt:
        if speaks_for_all():
            print("\nparsim: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        return _reader_gone()


def _parser() -> argparse.ArgumentParser:
    from parsim.output.export import add_export_command

    parser = _Parser(prog="parsim", description="Particle piles and clusters, run as MPI ensembles.")
    parser.add_argument("--version", action="version", version=f"parsim {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    run = commands.add_parser("run", help="run or resume a job (use mpiexec -n K for K ranks)")
    run.add_argument("job", type=options.path, help="job file (TOML)")
    run.add_argument("--output", type=options.path, help="output folder (overrides the job's 'output')")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    run.add_argument("--ranks-per-task", type=int, default=1, metavar="K",
                     help="run each task on a group of K ranks (a divisor of the number of ranks; default 1): "
                          "time-stepping aggregation and deposition tasks are decomposed over the group, "
                          "event-driven aggregation tasks run on the group's first rank while the others wait")
    run.add_argument("--phase-times", type=options.file_to_write, metavar="FILE",
                     help="write, as JSON, each rank's seconds by phase of the run (reading the job, warm-up, each "
                          "task's initial condition, steps, statistics, task file and row, the dataset)")
    run.add_argument("--time-limit", type=options.duration, metavar="[D-]HH:MM:SS",
                     help="stop handing out tasks in time for the tasks under way to end and the (partial) dataset "
                          "to be written before this much time has passed, e.g. a batch job's limit minus a margin; "
                          "the same command continues the job (exit status 3 while tasks are left)")

    validate = commands.add_parser("validate", help="check a job file and its output location without computing")
    validate.add_argument("job", type=options.path)
    validate.add_argument("--output", type=options.path, help="output folder (overrides the job's 'output')")

    compile_ = commands.add_parser("compile", help="compile the kernels of a job (default: of every solver) into "
                                                   "numba's cache, so that the runs that follow only load them")
    compile_.add_argument("job", type=options.path, nargs="?", help="job file (TOML); without: every solver's kernels")
    compile_.add_argument("--ranks-per-task", type=options.ranks, default=1, metavar="K",
                          help="the kernels of 'parsim run --ranks-per-task K': K > 1 compiles those of tasks spread "
                               "over several ranks (the same for any K) in place of those of tasks on one rank")

    info = commands.add_parser("info", help="describe an output folder")
    info.add_argument("output", type=options.path, help="output folder of a job")

    plot = commands.add_parser("plot", help="draw figures of a job's outputs as PNG and PDF")
    plot.add_argument("output", type=options.path, help="output folder of a job, or its netCDF dataset")
    plot.add_argument("--figure", metavar="NAME",
                      help="draw this figure only (default: every figure the dataset supports, in OUTPUT/figures)")
    plot.add_argument("--out", type=options.path, metavar="PATH",
                      help="with --figure: the file to write, PATH.png and PATH.pdf (or PATH itself if it ends in "
                           ".png or .pdf, and the other format); without: the folder for every figure")
    plot.add_argument("--task", type=options.name, metavar="LABEL",
                      help="the task the pictures show (sediment, cluster): its file name in OUTPUT/tasks without .h5; "
                      "default: the job's first task that has one")

    collect = commands.add_parser("collect", help="write the dataset of the tasks finished so far (the job may be "
                                  "running: collect takes no lock and writes beside the job's dataset)")
    collect.add_argument("output", type=options.path, help="output folder of a job")
    collect.add_argument("--out", type=options.path, metavar="PATH",
                         help="the netCDF file to write (default: OUTPUT/NAME.partial.nc)")

    add_export_command(commands)
    return parser


def _command(args) -> int:
    """Run the command ``args`` names; a ParsimError of any command but ``run`` is one line, status 2."""
    if args.command == "run":
        return _run(args)
    from parsim.output.export import run_export

    try:
        return {"validate": _validate, "compile": _compile, "info": _info, "plot": _plot, "collect": _collect,
                "export": run_export}[args.command](args)
    except ParsimError as error:
        print(f"parsim: error: {error}", file=sys.stderr)
        return EXIT_USER_ERROR


def _reader_gone() -> int:
    """End quietly, as ``cat`` does when the reader of its output has gone (``parsim info OUT | head -1``):
    what is still buffered goes nowhere, instead of failing again when the interpreter exits."""
    try:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    except (OSError, ValueError):  # no file descriptor behind sys.stdout: nothing buffered to lose
        pass
    return EXIT_READER_GONE


def _run(args) -> int:
    """``parsim run`` on every rank: rank 0 reads the job and hands it out, then all ranks run it.

    MPI is initialised once the launcher is known to match the MPI library
    (:func:`~parsim.parallel.launcher.start_mpi`).  A ParsimError of rank 0's phases reaches every
    rank alike, so rank 0 prints it and all ranks return its status.  Any other exception, and a
    ParsimError of one rank alone, is printed by its rank, which aborts the job; on a single rank
    a ParsimError is one line and any other exception is raised (a bug: its traceback).
    """
    from parsim.parallel.launcher import speaks_for_all, start_mpi

    try:
        MPI = start_mpi()
    except ParsimError as error:  # the launcher and the library do not belong together: nothing is done
        if speaks_for_all():
            print(f"parsim: error: {error}", file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        return _interrupted_before_tasks()
    from parsim.parallel.collective import FailedOnRoot, abort_if_alone

    comm = MPI.COMM_WORLD
    try:
        path, complete = _run_job(args, comm)
    except FailedOnRoot:
        return EXIT_RUN_FAILED  # rank 0 has printed its traceback
    except KeyboardInterrupt:  # before the run's own handler is in place (reading the job)
        return _interrupted_before_tasks()
    except ParsimError as error:
        abort_if_alone(comm, error)  # e.g. a file that this rank alone cannot read
        if comm.Get_rank() == 0:
            print(f"parsim: error: {error}", file=sys.stderr)
        return exit_status(error)
    except Exception as error:  # noqa: BLE001 - one rank's failure must not leave the others waiting
        abort_if_alone(comm, error)  # ends every rank; returns on a single rank, where the traceback says it
        raise
    return _outcome(path, complete, speaks=comm.Get_rank() == 0)


def _outcome(path: Path | None, complete: bool, speaks: bool) -> int:
    """The status of a run that ended (rank 0 ``speaks``: says where its dataset is): 0 when every task has
    finished, else EXIT_UNFINISHED with ``path`` the partial dataset (None if no task has finished)."""
    if complete:
        if speaks:
            print(f"dataset: {path}")
        return 0
    if speaks:
        kept = f"partial dataset: {path}" if path else "no task has finished"
        print(f"parsim: --time-limit reached with tasks left ({kept}); run the same command to continue",
              file=sys.stderr)
    return EXIT_UNFINISHED


def _run_job(args, comm) -> tuple[Path | None, bool]:
    """Read the job on rank 0 and run it on every rank of ``comm`` (:func:`parsim.runner.run_job`)."""
    from parsim.job import load_job
    from parsim.parallel.collective import on_root
    from parsim.phases import phase, write_phase_times
    from parsim.runner import run_job
    from parsim.solvers import SOLVERS

    with phase("read_job"):
        job = on_root(comm, lambda: load_job(args.job, SOLVERS, output=args.output))
    outcome = run_job(job, comm, progress=not args.quiet, ranks_per_task=args.ranks_per_task,
                      time_limit=args.time_limit)
    if args.phase_times is not None:
        write_phase_times(args.phase_times, comm)
    return outcome


def _interrupted_before_tasks() -> int:
    from parsim.parallel.launcher import speaks_for_all

    if speaks_for_all():
        print("\nparsim: interrupted before any task started", file=sys.stderr)
    return EXIT_INTERRUPTED


def _validate(args) -> int:
    from parsim.job import load_job
    from parsim.output.folder import OutputFolder
    from parsim.output.location import check_output_location
    from parsim.solvers import SOLVERS

    job = load_job(args.job, SOLVERS, output=args.output)
    check_output_location(job.output)
    print(f"{args.job}: valid {job.kind} job '{job.name}': {job.n_points} parameter points x "
          f"{job.realizations} realizations = {len(job.tasks())} tasks, output in {job.output}")
    folder = OutputFolder(job.output, job.name)
    stored = folder.stored_job()
    if stored is not None:  # a rerun: resumed or grown
        folder.check(job, stored)
        done = int(folder.finished(job)[1].sum())
        print(f"{job.output} holds {done} of these tasks finished: {len(job.tasks()) - done} to compute")
    return 0


def _compile(args) -> int:
    """Compile (or find in the cache) the kernels of the job's points, or of every solver, on this process;
    with ``--ranks-per-task K`` > 1, those of tasks spread over K ranks (the same for any number of ranks).

    A cache that cannot be written is a JobError (status 2, as an output folder that cannot be written):
    the command cannot do what it is for, and says so before compiling anything.
    """
    from parsim.core.cache import CACHE_REMEDY, cache_problem, kernel_cache_dir
    from parsim.job import Job, load_job
    from parsim.runner import warm_up
    from parsim.solvers import SOLVERS

    problem = cache_problem()
    if problem is not None:
        raise JobError(f"{problem}: nothing compiled; {CACHE_REMEDY}")
    if args.job is not None:
        jobs = [load_job(args.job, SOLVERS)]
    else:  # one small job per solver and method, with the defaults
        small = {"n_spheres": 100, "volume_fraction": 0.1}
        points = {"aggregation": [{"method": "ed", **small}, {"method": "ts", **small}],
                  "deposition": [{"n_particles": 100}]}
        jobs = [Job.from_dict({"name": "compile", "kind": kind, "seed": 1, "realizations": 1, "parameters": chosen},
                              solvers=SOLVERS)
                for kind in SOLVERS for chosen in points[kind]]
    for job in jobs:
        warm_up(job, job.tasks(), announce=True, ranks_per_task=args.ranks_per_task)
    what = f"job '{jobs[0].name}'" if args.job is not None else "every solver"
    if args.ranks_per_task > 1:
        what += f" on {args.ranks_per_task} ranks per task"
    print(f"the kernels of {what} are in the cache: {kernel_cache_dir()}")
    return 0


def _info(args) -> int:
    from parsim.report import describe_output

    print(describe_output(args.output))
    return 0


def _collect(args) -> int:
    from parsim.output.collect import collect_output

    path, finished, total = collect_output(args.output, args.out)
    print(f"{path}: {finished} of {total} tasks finished (the others NaN, 'completed' = 0)")
    return 0


def _plot(args) -> int:
    from parsim.plots import plot_output

    plot_output(args.output, figure=args.figure, out=args.out, task=args.task)
    return 0


if __name__ == "__main__":
    sys.exit(main())
