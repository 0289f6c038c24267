"""``parsim collect``: the dataset of the tasks finished so far, while a job runs or after it stopped.

It reads the folder's job copy and the task files that exist (each is written in one piece, so
one that exists is complete), takes no lock and writes nothing the job writes: the partial
dataset goes to ``OUTPUT/NAME.partial.nc`` (or ``--out``), beside the job's own ``NAME.nc``.
Its statistics are floating point, NaN for the tasks not finished, and the variable
``completed`` (sweep..., realization) says which tasks it holds; ``parsim plot`` draws it
(``parsim plot OUTPUT/NAME.partial.nc``), leaving the missing tasks out of the ensemble means.
"""

import datetime
from pathlib import Path

import numpy as np
import xarray as xr

from parsim.errors import JobError
from parsim.job import Job
from parsim.output.dataset import build_dataset, write_dataset
from parsim.output.folder import open_output
from parsim.output.snapshot import read_statistics
from parsim.solver import flag_attributes
from parsim.solvers import SOLVERS

PARTIAL_SUFFIX = ".partial.nc"
COMPLETED_MEANINGS = ("unfinished", "finished")


def collect_output(root: Path, out: Path | None = None) -> tuple[Path, int, int]:
    """Write the partial dataset of the output folder ``root``; returns (path, finished tasks, tasks)."""
    folder, job = open_output(Path(root))
    tasks = job.tasks()
    finished = {task for task in tasks if folder.is_finished(task)}
    if not finished:
        raise JobError(f"output folder {root}: no task of job '{job.name}' has finished yet; nothing to collect")
    dataset = build_dataset(job, SOLVERS[job.kind],
                            lambda task: read_statistics(folder.task_path(task)) if task in finished else None,
                            mpi_size=1, ranks_per_task=1, partial=True)
    dataset["completed"] = _completed(job, finished, dataset)
    created = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    dataset.attrs.update(history=f"{created} parsim collect ({len(finished)} of {len(tasks)} tasks finished)",
                         tasks_finished=len(finished), tasks_total=len(tasks))
    for unknown in ("mpi_size", "ranks_per_task"):  # of the run, which collect does not know
        dataset.attrs.pop(unknown, None)
    path = Path(out) if out is not None else folder.root / f"{job.name}{PARTIAL_SUFFIX}"
    write_dataset(dataset, path)
    return path, len(finished), len(tasks)


def _completed(job: Job, finished: set, dataset: xr.Dataset) -> xr.Variable:
    """1 where the task has finished, 0 where not, dimensions (sweep..., realization)."""
    mask = np.zeros((*job.sweep_shape, job.realizations), dtype=np.int8)
    for task in finished:
        index = (*np.unravel_index(task.point, job.sweep_shape), task.realization) if job.sweep else (task.realization,)
        mask[index] = 1
    return xr.Variable((*job.sweep, "realization"), mask,
                       {"long_name": "whether the task had finished when the dataset was collected", "units": "1",
                        **flag_attributes(COMPLETED_MEANINGS)})
