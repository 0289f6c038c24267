"""The job's statistics as one xarray Dataset, written as netCDF.

Dimensions: one per swept parameter (named after it, its values as
coordinate), then ``realization`` (CF ``standard_name = "realization"``), then
the observable dimensions a statistic declares (``r``, ``box_size``, ...).
Fixed parameters are scalar coordinates.  Every variable has ``units`` and
``long_name``; the global attributes carry the parsim version, the job file
text, the job seed, the input files with the SHA-256 of their content, the MPI
size, the ranks per task and the creation time.
"""

import datetime
from typing import Callable

import numpy as np
import xarray as xr

import parsim
from parsim.job import Job, Task
from parsim.output.atomic import write_bytes_atomically
from parsim.solver import Solver, Statistic

WALL_TIME = Statistic("wall_time", "s", "wall-clock time of the task on its rank", measured=True)
"""Measured by the runner for every task, whatever the solver."""

MEASURED_ATTRIBUTE = "parsim_measured"
"""Set to 1 on variables that are timings and so differ between two runs of one job."""


def all_statistics(solver: Solver) -> tuple[Statistic, ...]:
    return (*solver.statistics, WALL_TIME)


def build_dataset(job: Job, solver: Solver, statistics_of: Callable[[Task], dict], mpi_size: int,
                  ranks_per_task: int) -> xr.Dataset:
    """Assemble the dataset; ``statistics_of(task)`` gives one finished task's statistics."""
    observable = solver.coordinates(job.fixed)
    leading_shape = (*job.sweep_shape, job.realizations)
    statistics = all_statistics(solver)
    arrays = {s.name: np.empty(leading_shape + tuple(len(observable[d].values) for d in s.dims), dtype=s.dtype)
              for s in statistics}
    for task in job.tasks():
        values = statistics_of(task)
        index = (*np.unravel_index(task.point, job.sweep_shape), task.realization) if job.sweep else (task.realization,)
        for s in statistics:
            arrays[s.name][index] = values[s.name]

    leading_dims = (*job.sweep, "realization")
    variables = {}
    for s in statistics:
        attrs = {"units": s.units, "long_name": s.long_name, **s.attrs}
        if s.measured:
            attrs[MEASURED_ATTRIBUTE] = 1
        variables[s.name] = xr.Variable(leading_dims + s.dims, arrays[s.name], attrs)

    coords = {}
    for name, values in job.sweep.items():
        parameter = solver.parameter(name)
        coords[name] = xr.Variable(name, np.asarray(values), {"units": parameter.units, "long_name": parameter.description})
    coords["realization"] = xr.Variable("realization", np.arange(job.realizations),
                                        {"standard_name": "realization", "long_name": "realisation index", "units": "1"})
    for name, coordinate in observable.items():
        coords[name] = xr.Variable(name, coordinate.values, {"units": coordinate.units, "long_name": coordinate.long_name})
    for name, value in job.fixed.items():
        if value is not None:
            parameter = solver.parameter(name)
            coords[name] = xr.Variable((), value, {"units": parameter.units, "long_name": parameter.description})

    created = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    attrs = {
        "Conventions": "CF-1.10",
        "title": f"parsim {job.kind} job '{job.name}'",
        "source": f"parsim {parsim.__version__}",
        "history": f"{created} parsim run (job '{job.name}', {mpi_size} MPI ranks, {ranks_per_task} per task)",
        "parsim_version": parsim.__version__,
        "job_name": job.name,
        "job_kind": job.kind,
        "job_seed": job.seed,
        "job_text": job.text,
        **job.input_attributes,
        "mpi_size": mpi_size,
        "ranks_per_task": ranks_per_task,
        "date_created": created,
        "comment": "lengths are in the job's length unit (the unit of the sphere radii), "
                   "times in that length unit divided by the unit of the initial speed",
    }
    return xr.Dataset(variables, coords=coords, attrs=attrs)


VOLATILE_ATTRIBUTES = ("history", "mpi_size", "ranks_per_task", "date_created")
"""Global attributes that describe the run, not the results."""


def write_dataset(dataset: xr.Dataset, path) -> None:
    """Write ``dataset`` as netCDF-4 to ``path`` atomically; it is built in memory, then written in one piece."""
    write_bytes_atomically(path, dataset.to_netcdf(engine="netcdf4"))
