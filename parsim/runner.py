"""Turn a job into tasks, run them over the MPI ranks, and assemble the dataset.

Every rank calls :func:`run_job`.  Rank 0 prepares the output folder and finds
the tasks that earlier runs have not finished; the scheduler hands those out,
costliest first; each task's rank writes its HDF5 file; rank 0 then assembles
the netCDF dataset from the task files, so a resumed job gives exactly the
dataset of an uninterrupted one.

With ``ranks_per_task = K > 1`` the ranks form groups of K consecutive ranks
that run one task at a time together: a decomposable solver gets the group's
communicator, any other solver runs on the group's rank 0 while the other
ranks wait.  The group's rank 0 writes the task file.
"""

import time
import traceback
from pathlib import Path

import numpy as np
from mpi4py import MPI

from parsim.errors import JobError, ParsimError
from parsim.job import Job, parse_job
from parsim.output.dataset import build_dataset, write_dataset
from parsim.output.folder import OutputFolder
from parsim.output.snapshot import read_statistics, write_task_file
from parsim.parallel.scheduler import run_group_tasks
from parsim.progress import TaskProgress
from parsim.solvers import SOLVERS


def run_job(job: Job, comm: MPI.Comm = MPI.COMM_WORLD, progress: bool = True, ranks_per_task: int = 1) -> Path:
    """Run every unfinished task of ``job`` on groups of ``ranks_per_task`` ranks; returns the dataset path."""
    _check_ranks_per_task(ranks_per_task, comm.Get_size())
    solver = SOLVERS[job.kind]
    folder = OutputFolder(job.output, job.name)
    rank = comm.Get_rank()

    pending = None
    if rank == 0:
        try:
            folder.prepare(job, _stored_job(folder))
            pending = [task for task in job.tasks() if not folder.is_finished(task)]
        except ParsimError as error:
            pending = error
    pending = comm.bcast(pending, root=0)
    if isinstance(pending, ParsimError):
        raise pending
    # Costliest first, so that the last tasks to start are short and no rank idles at the end.
    pending.sort(key=lambda task: -solver.cost(job.point_parameters(task.point)))

    bar = TaskProgress(job.name, len(job.tasks()), len(job.tasks()) - len(pending), progress and rank == 0)

    def work(k: int, group: MPI.Comm) -> None:
        if not solver.decomposable:
            if group.Get_rank() > 0:
                return  # a serial solver runs on the group's rank 0; the others wait for the next task
            group = MPI.COMM_SELF
        task = pending[k]
        params = job.point_parameters(task.point)
        seed = job.seed_sequence(task, solver)
        start = time.perf_counter()
        result = solver.solve(params, np.random.default_rng(seed), group)
        if group.Get_rank() > 0:
            return
        result.statistics["wall_time"] = time.perf_counter() - start
        attrs = {**params, "job_name": job.name, "job_seed": job.seed, "spawn_key": list(seed.spawn_key),
                 "point": task.point, "realization": task.realization}
        write_task_file(folder.task_path(task), result, attrs)

    def describe_failure(k: int, error: Exception) -> str:
        task = pending[k]
        reason = str(error) if isinstance(error, ParsimError) else "".join(traceback.format_exception(error)).rstrip()
        return f"task {task.label} ({job.describe_point(task.point)}, realization {task.realization}) failed: {reason}"

    run_group_tasks(comm, ranks_per_task, len(pending), work, on_finished=lambda k, r: bar.task_finished(),
                    describe_failure=describe_failure)
    bar.close()

    if rank == 0:
        dataset = build_dataset(job, solver, lambda task: read_statistics(folder.task_path(task)), comm.Get_size(),
                                ranks_per_task)
        write_dataset(dataset, folder.dataset)
    comm.Barrier()
    return folder.dataset


def _check_ranks_per_task(ranks_per_task: int, n_ranks: int) -> None:
    if ranks_per_task < 1 or n_ranks % ranks_per_task:
        divisors = ", ".join(str(k) for k in range(1, n_ranks + 1) if n_ranks % k == 0)
        raise JobError(f"--ranks-per-task {ranks_per_task}: allowed: a divisor of the number of MPI ranks "
                       f"({n_ranks}): {divisors}")


def _stored_job(folder: OutputFolder) -> Job | None:
    if not folder.job_copy.exists():
        return None
    try:
        return parse_job(folder.job_copy.read_text(), SOLVERS, source=str(folder.job_copy))
    except JobError as error:
        raise JobError(f"output folder {folder.root} holds a job file that is no longer valid ({error}); "
                       f"give another output folder or remove {folder.root}") from None
