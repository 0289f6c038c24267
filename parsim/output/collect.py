"""``parsim collect``: the dataset of the tasks finished so far, while a job runs or after it stopped.

It reads the folder's job copy and the rows of the finished tasks (a cut-off last row of a
row file being written is left out), takes no lock and writes nothing the job writes: the partial
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
from parsim.output.dataset import build_dataset, write_dataset
from parsim.job import Job
from parsim.output.folder import OutputFolder, open_output
from parsim.solver import flag_attributes

PARTIAL_SUFFIX = ".partial.nc"
#: The variable of a partial dataset that says which tasks it holds.
COMPLETED = "completed"
COMPLETED_MEANINGS = ("unfinished", "finished")


def collect_output(root: Path, out: Path | None = None) -> tuple[Path, int, int]:
    """Write the partial dataset of the output folder ``root``; returns (path, finished tasks, tasks)."""
    folder, job = open_output(Path(root))
    rows, finished = folder.finished(job)
    return write_partial_dataset(folder, job, rows, finished, out)


def write_partial_dataset(folder: OutputFolder, job: Job, rows: np.ndarray, finished: np.ndarray,
                          out: Path | None = None) -> tuple[Path, int, int]:
    """Write the partial dataset of ``job`` from the ``rows`` of its folder and the ``finished`` mask of its
    tasks (:meth:`~parsim.output.folder.OutputFolder.finished`); returns (path, finished tasks, tasks)."""
    if not finished.any():
        raise JobError(f"output folder {folder.root}: no task of job '{job.name}' has finished yet; nothing to collect")
    dataset = build_dataset(job, job.solver, rows, mpi_size=1, ranks_per_task=1, partial=True)
    dataset[COMPLETED] = xr.Variable(
        (*job.sweep, "realization"), finished.astype(np.int8).reshape(*job.sweep_shape, job.realizations),
        {"long_name": "whether the task had finished when the dataset was collected", "units": "1",
         **flag_attributes(COMPLETED_MEANINGS)})
    n_finished, n_tasks = int(finished.sum()), len(finished)
    created = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    dataset.attrs.update(history=f"{created} parsim collect ({n_finished} of {n_tasks} tasks finished)",
                         tasks_finished=n_finished, tasks_total=n_tasks)
    for unknown in ("mpi_size", "ranks_per_task"):  # of the run, which collect does not know
        dataset.attrs.pop(unknown, None)
    path = Path(out) if out is not None else folder.root / f"{job.name}{PARTIAL_SUFFIX}"
    write_dataset(dataset, path)
    return path, n_finished, n_tasks
