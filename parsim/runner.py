"""Turn a job into tasks, run them over the MPI ranks, and assemble the dataset.

Every rank calls :func:`run_job`.  Rank 0 checks the output location, locks
the output folder, prepares it, merges its row files and finds the tasks that
earlier runs have not finished (by their point's values, so a grown job computes
only its new tasks); the scheduler hands those out, costliest first; each task's
rank writes its HDF5 task file if the job keeps its configuration, then appends
its statistics to the rank's row file; rank 0 then assembles the netCDF dataset
from the rows, so a resumed or grown job gives exactly the dataset of an
uninterrupted run of the job as written now.

Failures end every rank: the phases of rank 0 alone go through
:func:`~parsim.parallel.collective.on_root`, which hands their error to every
rank, and a failed task aborts the job from the scheduler.  SIGINT, SIGTERM
and SIGHUP end the run at once with one line saying how many tasks are kept.

With ``ranks_per_task = K > 1`` the ranks form groups of K consecutive ranks
that run one task at a time together: a decomposable solver gets the group's
communicator, any other solver runs on the group's rank 0 while the other
ranks wait.  The group's rank 0 writes the task file.
"""

import functools
import signal
import sys
import threading
import time
from pathlib import Path

import h5py
import numpy as np
from mpi4py import MPI

from parsim.core.cache import CACHE_REMEDY, cache_problem
from parsim.errors import JobError, describe_exception
from parsim.interrupts import ending_on_signals
from parsim.job import Job, Task
from parsim.output.collect import write_partial_dataset
from parsim.output.dataset import build_dataset, row_layout, task_rows, write_dataset
from parsim.output.folder import OutputFolder
from parsim.output.location import check_output_location
from parsim.output.lock import FolderLock
from parsim.output.rows import RowWriter
from parsim.output.snapshot import provenance_attributes, write_task_file
from parsim.parallel.collective import on_root, wait_for
from parsim.parallel.scheduler import TimeLimit, require_thread_multiple, run_group_tasks
from parsim.phases import phase
from parsim.progress import (TaskProgress, announcing_compilation, announcing_preparation, reporting_settled,
                             settled_lines)
from parsim.solver import TaskResult


#: A time-limited run stops handing out tasks this long before its limit (plus the next), at least.
TIME_RESERVE_SECONDS = 30.0
#: ... and this long per task of the job, for its row in the dataset (10⁵ rows: 1.6 s measured, 10 s kept).
TIME_RESERVE_PER_TASK = 1e-4
#: How long a rank other than 0 waits, after a signal, for rank 0's word that it has the signal too,
#: before it ends the job itself with its own line.
SIGNAL_GRACE_SECONDS = 2.0
#: How long a rank other than 0 then waits, silent, for rank 0 to end the job.
ROOT_ENDING_SECONDS = 20.0
#: How long rank 0 waits, after a signal, for the files and rows other ranks are writing, before it counts them.
WRITE_SETTLE_SECONDS = 0.2


def run_job(job: Job, comm: MPI.Comm = MPI.COMM_WORLD, progress: bool = True, ranks_per_task: int = 1,
            time_limit: float | None = None) -> tuple[Path | None, bool]:
    """Run every unfinished task of ``job`` on groups of ``ranks_per_task`` ranks.

    With ``time_limit`` (seconds from now), tasks start only while they can end with
    :func:`time_reserve` seconds left (:class:`~parsim.parallel.scheduler.TimeLimit`).  Returns
    (the dataset, True) when every task has finished; else (the partial dataset of
    :mod:`parsim.output.collect`, or None if no task has finished, False): the same command
    finishes the job.
    """
    limit = TimeLimit(time_limit, time_reserve(job)) if time_limit is not None else None
    on_root(comm, lambda: _check_ranks(comm, ranks_per_task))
    folder = OutputFolder(job.output, job.name)
    lock = FolderLock(folder.root)
    writing = threading.Lock()  # held while a task's file and row are written; a signal takes it to stop them
    rank = comm.Get_rank()
    signals = comm.Dup()  # carries rank 0's word that it has a signal, apart from every other message

    try:
        with ending_on_signals(lambda number: _end_on_signal(number, job, folder, lock, writing, signals)):
            with phase("claim_folder"):
                pending = on_root(comm, lambda: _claim(job, folder, lock))
            if not pending and on_root(comm, lambda: _dataset_is_current(job, folder)):
                if rank == 0:
                    print(f"parsim: nothing to compute: the {len(job.tasks())} tasks of {job.name} have finished "
                          "and the dataset is this job's; it is left as it is", file=sys.stderr, flush=True)
                return folder.dataset, True
            done, computing = _run_pending(job, pending, folder, writing, comm, progress and rank == 0,
                                           ranks_per_task, limit, settling=progress)
            wait_for(comm.Ibarrier())  # every rank has closed its row file before rank 0 reads them
            start = time.perf_counter()
            with phase("dataset"):
                outputs = on_root(comm, lambda: _write_outputs(job, folder, comm.Get_size(), ranks_per_task))
            if progress and rank == 0 and done:
                ranks = f"{comm.Get_size()} rank" + ("s" if comm.Get_size() > 1 else "")
                print(f"parsim: {done} tasks in {computing:.1f} s ({done / computing:.0f} tasks/s on "
                      f"{ranks}), dataset written in {time.perf_counter() - start:.1f} s",
                      file=sys.stderr, flush=True)
            return outputs
    finally:
        signals.Free()
        if rank == 0:
            lock.release()


def time_reserve(job: Job) -> float:
    """Seconds a time-limited run keeps for the tasks under way to be reported and the dataset written:
    ``TIME_RESERVE_SECONDS`` and ``TIME_RESERVE_PER_TASK`` for each task's row assembled."""
    return TIME_RESERVE_SECONDS + TIME_RESERVE_PER_TASK * len(job.tasks())


def _claim(job: Job, folder: OutputFolder, lock: FolderLock) -> list[Task]:
    """Rank 0: lock and prepare the output folder, merge its row files; the tasks still to run, in the job's order."""
    check_output_location(folder.root)
    folder.create()
    lock.acquire()
    try:
        found = task_rows(job, folder.prepare(job, folder.stored_job()))
        return [task for task, row in zip(job.tasks(), found) if row < 0]
    except BaseException:
        lock.release()
        raise


def _run_pending(job: Job, pending: list[Task], folder: OutputFolder, writing: threading.Lock, comm: MPI.Comm,
                 progress: bool, ranks_per_task: int, time_limit: TimeLimit | None,
                 settling: bool = False) -> tuple[int, float]:
    """Run the ``pending`` tasks; on rank 0, how many finished and in how many seconds (after the warm-up).
    ``progress``: this rank draws the job's bar; ``settling``: this rank's long tasks say how far they got."""
    solver = job.solver
    with phase("warm_up", whole=True):
        warm_up(job, pending, progress, comm, ranks_per_task)
    point_costs = [solver.cost(job.point_parameters(point)) for point in range(job.n_points)]
    # Costliest first, so that the last tasks to start are short and no rank idles at the end; every
    # rank sorts alike (a stable sort of the same list), so a task index means the same task everywhere.
    pending = sorted(pending, key=lambda task: -point_costs[task.point])
    to_do = set(pending)
    bar = TaskProgress(job.name, [point_costs[task.point] for task in pending],
                       [point_costs[task.point] for task in job.tasks() if task not in to_do], progress)
    rows = RowWriter(folder.rows, row_layout(job, solver), job.name, comm.Get_rank())
    finished = []

    def work(k: int, group: MPI.Comm) -> None:
        if not solver.decomposable:
            if group.Get_rank() > 0:
                return  # a serial solver runs on the group's rank 0; the others wait for the next task
            group = MPI.COMM_SELF
        task = pending[k]
        where = f"task {task.label}" + (f" on rank {comm.Get_rank()}" if comm.Get_rank() else "")
        with reporting_settled(settled_lines(where) if settling and group.Get_rank() == 0 else None):
            result = solve_task(job, task, group)
        if result is None:
            return  # the task's result is on the group's rank 0
        with writing:
            if job.keeps_configuration(task):  # every rank of a group whose ranks hold shares of the configuration
                with phase("task_file"):
                    write_task_file(folder.task_path(task), result, task_attributes(job, task), group)
            if group.Get_rank() == 0:
                with phase("row"):
                    rows.append(task.key, task.realization, result.statistics)

    def describe_failure(k: int, error: Exception) -> str:
        task = pending[k]
        return (f"task {task.label} ({job.describe_point(task.point)}, realization {task.realization}) failed: "
                f"{describe_exception(error)}")

    def on_finished(k: int, rank: int) -> None:
        finished.append(k)
        bar.task_finished(point_costs[pending[k].point])

    start = time.perf_counter()
    try:
        run_group_tasks(comm, ranks_per_task, len(pending), work, on_finished=on_finished,
                        describe_failure=describe_failure, time_limit=time_limit)
    finally:
        rows.close()  # a network file system shows a file's writes to other nodes once it is closed
    bar.close()
    return len(finished), time.perf_counter() - start


def solve_task(job: Job, task: Task, comm: MPI.Comm) -> TaskResult | None:
    """Solve ``task`` of ``job`` on ``comm`` from its own random stream; its ``wall_time`` is the solve's.

    A decomposed task's result lives on ``comm``'s rank 0, and the other ranks get None, unless its
    configuration stays spread over the ranks (a deposition's): then each rank gets the statistics and
    its share.
    """
    solver = job.solver
    start = time.perf_counter()
    with phase("solve_rest"):  # what the solver's own phases (initial condition, steps, statistics) leave
        result = solver.solve(job.point_parameters(task.point), np.random.default_rng(job.seed_sequence(task)), comm)
    if result is not None:
        result.statistics["wall_time"] = time.perf_counter() - start
    return result


def task_attributes(job: Job, task: Task) -> dict:
    """The root attributes of ``task``'s file: the parameters it reads (a cylinder's task has no
    ``lateral``, an ED task no DAHA key), its input files, units and origin."""
    params = job.point_parameters(task.point)
    read = {p.name: params[p.name] for p in job.solver.parameters if p.is_read(params)}
    return {**read, **job.table_attributes, **job.input_attributes, **job.unit_attributes,
            "job_name": job.name, "job_seed": job.seed, "spawn_key": list(job.seed_sequence(task).spawn_key),
            "task": task.label, "realization": task.realization}


#: Said when the warm-up compiles a kernel; the times it gives are those of docs/benchmarks.md,
#: "Compilation of the kernels".
PREPARING_KERNELS = ("parsim: preparing the kernels (compiled once per installation and processor model: 10-30 s "
                     "for an aggregation, about a minute for a deposition on one core of an AMD EPYC; loaded from "
                     "the cache in about a second afterwards)...")


def warm_up(job: Job, pending: list[Task], announce: bool, comm: MPI.Comm | None = None,
            ranks_per_task: int = 1) -> None:
    """Compile, or load from numba's cache, the kernels of the pending tasks before any task is timed.

    Each distinct small version of the pending points (:attr:`Solver.warm_up_parameters`)
    is solved once on this rank and thrown away, so that a task's ``wall_time``
    measures the computation alone.  For tasks on groups of ``ranks_per_task`` > 1 ranks,
    a solver's :attr:`Solver.rehearse_spread` solves it instead, on this rank alone, as a
    task spread over the group runs (the kernels do not depend on the number of ranks).

    With ``comm`` (collective over it), the ranks of each node take turns: the node's first
    rank solves the small points while the others wait, then the others solve them too and
    load the kernels from the cache the first one has just filled, instead of every rank
    compiling the same kernels at once.  The ranks of a node share its disk and, normally, the
    cache folder; nodes need not (a home directory local to each node, or another processor
    model, which has a cache folder of its own), so each node compiles once, with less CPU time
    and memory than every rank compiling at once; where each rank has a free core, the turns cost
    the others' loading, about a second.  Rank 0 announces the kernels ready once every rank has
    them.
    """
    solver = job.solver
    rehearsals = {}
    for task in pending:
        small = solver.warm_up_parameters(job.point_parameters(task.point))
        rehearsals.setdefault(repr(sorted(small.items())), small)
    if not rehearsals:
        return
    problem = cache_problem()
    if problem is not None and (comm is None or comm.Get_rank() == 0):
        _say_uncached(problem)
    start = time.perf_counter()
    with announcing_compilation(PREPARING_KERNELS, announce) as compiled:
        _rehearse(_rehearsal(solver, ranks_per_task), rehearsals.values(), announce, comm)
    if compiled():
        print(f"parsim: kernels ready in {time.perf_counter() - start:.1f} s", file=sys.stderr, flush=True)


@functools.cache  # once per process, however many warm-ups it runs (the Python API's calls)
def _say_uncached(problem: str) -> None:
    print(f"parsim: {problem}: the kernels are compiled in every process, every run; {CACHE_REMEDY} to cache them",
          file=sys.stderr, flush=True)


def _rehearsal(solver, ranks_per_task: int):
    """How :func:`warm_up` solves a small point for tasks on groups of ``ranks_per_task`` ranks, and
    prepares the solver's rare kernels."""
    def rehearsal(small: dict) -> None:
        if ranks_per_task > 1 and solver.rehearse_spread is not None:
            solver.rehearse_spread(small)
        else:
            solver.solve(small, np.random.default_rng(0), MPI.COMM_SELF)
        if solver.rare_kernels is not None:
            solver.rare_kernels(small)

    return rehearsal


def _rehearse(rehearsal, rehearsals, announce: bool, comm: MPI.Comm | None) -> None:
    """Solve each small point of :func:`warm_up` with ``rehearsal`` on this rank, the node's first rank
    before the others (all at once when the kernels cannot be cached: the others would compile them
    again anyway)."""
    several = comm is not None and comm.Get_size() > 1
    node = comm.Split_type(MPI.COMM_TYPE_SHARED) if several and cache_problem() is None else None
    if node is not None and node.Get_rank() > 0:
        wait_for(node.Ibarrier())  # until the node's first rank has compiled and cached the kernels
    try:
        with announcing_preparation(announce):  # the particles are built here on every rank; rank 0 speaks
            for small in rehearsals:
                rehearsal(small)
    finally:
        if node is not None and node.Get_rank() == 0:
            wait_for(node.Ibarrier())  # the others go on, to load what it has cached (or to fail as it did)
    if node is not None:
        node.Free()
    if several:
        wait_for(comm.Ibarrier())  # every rank has its kernels


def _dataset_is_current(job: Job, folder: OutputFolder) -> bool:
    """Rank 0: whether the folder's dataset was written for this very job file (its ``job_text``) by
    this parsim (version and output schema), so that a finished job run again need not write it."""
    expected = {"job_text": job.text, **provenance_attributes()}
    try:
        with h5py.File(folder.dataset, "r") as dataset:
            found = {key: dataset.attrs.get(key) for key in expected}
    except (OSError, ValueError):  # no dataset, or not one h5py reads: write it again
        return False
    found = {key: value.decode() if isinstance(value, bytes) else value for key, value in found.items()}
    return found == expected


def _write_outputs(job: Job, folder: OutputFolder, mpi_size: int, ranks_per_task: int) -> tuple[Path | None, bool]:
    """Rank 0: the dataset if every task has finished, else the partial dataset of those that have."""
    rows, found = folder.finished(job)
    if found.all():
        write_dataset(build_dataset(job, job.solver, rows, mpi_size, ranks_per_task), folder.dataset)
        return folder.dataset, True
    if not found.any():
        return None, False
    return write_partial_dataset(folder, job, rows, found)[0], False


def _end_on_signal(number: signal.Signals, job: Job, folder: OutputFolder, lock: FolderLock,
                   writing: threading.Lock, signals: MPI.Comm) -> None:
    """A signal's last words: no more task files or rows; rank 0 releases the lock and says what is kept.

    Every rank stops writing task files and rows at once (a write under way completes).
    Rank 0 tells the other ranks that it has the signal, waits a moment for their writes
    under way, counts the finished tasks' rows, prints the line and exits; the launcher then
    ends the other ranks.  A rank other than 0 that has not heard from rank 0 within
    ``SIGNAL_GRACE_SECONDS`` (a signal sent to it alone) ends the job itself with a line of
    its own; one that has heard stays silent, so that however long rank 0 takes to count,
    the run ends with one line.
    """
    writing.acquire()
    rank = signals.Get_rank()
    if rank == 0:
        for other in range(1, signals.Get_size()):
            signals.isend(int(number), dest=other)  # eager and never waited for: the process exits soon
        time.sleep(WRITE_SETTLE_SECONDS)
        lock.release()
        kept = int(folder.finished(job)[1].sum())
        what = "interrupted" if number == signal.SIGINT else f"stopped by {number.name}"
        print(f"\nparsim: {what}; {kept} of {len(job.tasks())} tasks kept, run the same command to finish",
              file=sys.stderr, flush=True)
        return
    if _heard_from_root(signals, SIGNAL_GRACE_SECONDS):
        time.sleep(ROOT_ENDING_SECONDS)
        print(f"\nparsim: rank 0 did not end the job within {ROOT_ENDING_SECONDS:.0f} s of {number.name}; "
              "run the same command to finish", file=sys.stderr, flush=True)
    else:
        print(f"\nparsim: rank {rank} got {number.name}; run the same command to finish",
              file=sys.stderr, flush=True)
    signals.Abort(128 + number)


def _heard_from_root(signals: MPI.Comm, seconds: float) -> bool:
    """Whether rank 0's word that it has a signal arrives on ``signals`` within ``seconds``."""
    deadline = time.monotonic() + seconds
    while not signals.Iprobe(source=0):
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


def _check_ranks(comm: MPI.Comm, ranks_per_task: int) -> None:
    """What the ranks must offer before anything is done: threads for the scheduler, groups that divide them."""
    require_thread_multiple(comm)
    _check_ranks_per_task(ranks_per_task, comm.Get_size())


def _check_ranks_per_task(ranks_per_task: int, n_ranks: int) -> None:
    if ranks_per_task < 1 or n_ranks % ranks_per_task:
        divisors = ", ".join(str(k) for k in range(1, n_ranks + 1) if n_ranks % k == 0)
        raise JobError(f"--ranks-per-task {ranks_per_task}: allowed: a divisor of the number of MPI ranks "
                       f"({n_ranks}): {divisors}")

