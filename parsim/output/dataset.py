"""The job's statistics as one xarray Dataset, written as netCDF (CF-1.10).

Dimensions: one per swept parameter (named after it, its values as
coordinate), then ``realization`` (CF ``standard_name = "realization"``), then
the observable dimensions a statistic declares (``r``, ``box_size``, ...; a
labelled one such as ``component`` holds integer codes named by its
``flag_values``/``flag_meanings``).  Fixed parameters that some task of the job
reads are scalar coordinates.  Every variable has UDUNITS ``units`` (in the
job's ``length_unit``, ``time_unit``, ``mass_unit``) and ``long_name``; no
coordinate has a ``_FillValue``.  The global attributes carry the parsim version
and output schema, the papers (``references``), the job file text, the job seed,
the job's units, the input files with the SHA-256 of their content, the MPI
size, the ranks per task and the creation time.
"""

import datetime
import json
from pathlib import Path
import numpy as np
import xarray as xr

from parsim.errors import OutputError
from parsim.job import Job
from parsim.output.atomic import write_bytes_atomically
from parsim.output.rows import RowLayout
from parsim.output.snapshot import check_schema, provenance_attributes
from parsim.solver import Solver, Statistic, coded_coordinate, flag_words, named_values, resolve_units
from parsim.version import __version__

WALL_TIME = Statistic("wall_time", "s", "wall-clock time of the task on its rank", measured=True)
"""Measured by the runner for every task, whatever the solver."""

VALUES_ATTRIBUTE = "parsim_values"
"""The values of a swept string parameter as the job wrote them (a JSON list, in code order): its
``flag_meanings`` are CF words (a file's path, say, with ``_`` for ``/``, and ``@2`` added to
tell it from another value that has the same word)."""

MISSING_INTEGER = -1
"""An integer statistic's value for a task that has not finished, in a partial dataset (its _FillValue)."""

MEASURED_ATTRIBUTE = "parsim_measured"
"""Set to 1 on variables that are timings and so differ between two runs of one job."""

REFERENCES = "\n".join((
    "Topić, N. & Pöschel, T. (2016): Steepest descent ballistic deposition of complex shaped particles. "
    "J. Comput. Phys. 308, 421–437.",
    "Degond, P., Dimarco, G., Ferreira, M. A. & Hecht, S. (2024): Modeling ballistic aggregation by time "
    "stepping approaches. SIAM Journal on Applied Dynamical Systems, in press. hal-04211646, arXiv:2309.09523",
))
"""The papers of the deposition and aggregation solvers, one a line (the dataset's ``references``)."""

COORDINATE_ENCODING = {"_FillValue": None}
"""CF 2.5.1: a coordinate variable has no missing values, hence no ``_FillValue`` (xarray adds NaN to floats)."""


def all_statistics(solver: Solver) -> tuple[Statistic, ...]:
    return (*solver.statistics, WALL_TIME)


def build_dataset(job: Job, solver: Solver, rows: np.ndarray, mpi_size: int, ranks_per_task: int,
                  partial: bool = False) -> xr.Dataset:
    """Assemble the dataset of ``job`` from task ``rows`` (:mod:`parsim.output.rows`, of :func:`row_layout`).

    Each task of the job takes the row of its point key and realisation; rows of tasks the job no
    longer has are left out.  A ``partial`` dataset (:mod:`parsim.output.collect`) may miss rows:
    its statistics are all floating point, NaN for such tasks.
    """
    coords = {**_sweep_coordinates(job, solver), **_observable_coordinates(job, solver),
              **_fixed_coordinates(job, solver)}
    return xr.Dataset(_statistics_variables(job, solver, rows, partial), coords=coords,
                      attrs=_global_attributes(job, mpi_size, ranks_per_task))


def row_layout(job: Job, solver: Solver) -> RowLayout:
    """The record of one task of ``job``: every statistic, in its type and its observable shape."""
    observable = solver.coordinates(job.constants)
    return RowLayout(tuple((s.name, s.dtype, tuple(len(observable[d].values) for d in s.dims))
                           for s in all_statistics(solver)))


def task_rows(job: Job, rows: np.ndarray) -> np.ndarray:
    """For each task of ``job.tasks()``, the index of its row in ``rows``, -1 where there is none."""
    found = {(key.tobytes(), int(r)): i for i, (key, r) in enumerate(zip(rows["key"], rows["realization"]))}
    return np.array([found.get((task.key, task.realization), -1) for task in job.tasks()], dtype=np.int64)


def _statistics_variables(job: Job, solver: Solver, rows: np.ndarray, partial: bool) -> dict[str, xr.Variable]:
    """One variable per statistic, dimensions (sweep..., realization, observable...)."""
    index = task_rows(job, rows)
    missing = index < 0
    if missing.any() and not partial:
        raise OutputError(f"{int(missing.sum())} tasks of job '{job.name}' have no row of statistics; "
                          "run the same command again to compute them")
    leading_shape = (*job.sweep_shape, job.realizations)
    leading_dims = (*job.sweep, "realization")
    variables = {}
    for s in all_statistics(solver):
        column = rows[s.name][np.maximum(index, 0)] if len(rows) else np.zeros((len(index), *rows.dtype[s.name].shape))
        encoding = {}
        if partial:
            column, encoding = _with_missing(column, missing)
        attrs = {**_described(job, s.units, s.long_name), **s.attrs}
        if s.measured:
            attrs[MEASURED_ATTRIBUTE] = 1
        variables[s.name] = xr.Variable(leading_dims + s.dims, column.reshape(leading_shape + column.shape[1:]),
                                        attrs, encoding=encoding)
    return variables


def _with_missing(column: np.ndarray, missing: np.ndarray) -> tuple[np.ndarray, dict]:
    """``column`` with the tasks that have no row marked missing, and its netCDF encoding: integers
    keep their type (a flag variable's ``flag_values`` share it, CF 3.5) with ``MISSING_INTEGER`` as
    ``_FillValue``; other values become float64 NaN."""
    if np.issubdtype(column.dtype, np.integer):
        column = column.copy()
        column[missing] = MISSING_INTEGER
        return column, {"_FillValue": column.dtype.type(MISSING_INTEGER)}
    column = column.astype(np.float64)
    column[missing] = np.nan
    return column, {}


def decoded(dataset: xr.Dataset, names=None) -> xr.Dataset:
    """``dataset`` with its coordinates coded as CF flags (``names``; default: every such dimension
    coordinate: swept strings, components, species) holding their names instead, so that
    ``decoded(dataset).sel({"method": "ts"})`` selects by name (``sel(method=...)`` would be a keyword
    of ``sel``)."""
    names = [name for name in dataset.dims if name in dataset.coords and "flag_meanings" in dataset[name].attrs] \
        if names is None else list(names)
    return dataset.assign_coords({name: (dataset[name].dims, _names(dataset[name]),
                                         {"long_name": dataset[name].attrs.get("long_name", name)})
                                  for name in names})


def _names(coordinate) -> list:
    """A flag-coded coordinate's values by name: as the job wrote them for a swept string."""
    if VALUES_ATTRIBUTE not in coordinate.attrs:
        return named_values(coordinate)
    written = json.loads(coordinate.attrs[VALUES_ATTRIBUTE])
    return [written[code] for code in np.atleast_1d(coordinate.values).tolist()]


def _sweep_coordinates(job: Job, solver: Solver) -> dict[str, xr.Variable]:
    """The swept parameters' values and ``realization``: the leading dimensions.  A swept string
    parameter is coded as CF flags, 0, 1, ... in the job's order (CF coordinates are numbers);
    :func:`decoded` names them again."""
    coords = {}
    for name, values in job.sweep.items():
        values, attrs = np.asarray(values), _parameter_attributes(job, solver, name)
        if values.dtype.kind in "USO":
            coded = coded_coordinate(attrs["long_name"], flag_words(values.tolist()))
            attrs = {"units": coded.units, "long_name": coded.long_name, **coded.attrs,
                     VALUES_ATTRIBUTE: json.dumps([str(value) for value in values])}
            values = coded.values
        coords[name] = _coordinate(name, values, attrs)
    coords["realization"] = _coordinate("realization", np.arange(job.realizations),
                                        {"standard_name": "realization", "long_name": "realisation index",
                                         "units": "1"})
    return coords


def _observable_coordinates(job: Job, solver: Solver) -> dict[str, xr.Variable]:
    return {name: _coordinate(name, coordinate.values,
                              {**_described(job, coordinate.units, coordinate.long_name), **coordinate.attrs})
            for name, coordinate in solver.coordinates(job.constants).items()}


def _fixed_coordinates(job: Job, solver: Solver) -> dict[str, xr.Variable]:
    """The fixed parameters as scalar coordinates, leaving out those unset or read by no task of the job."""
    read = _read_parameters(job, solver)
    return {name: _coordinate((), value, _parameter_attributes(job, solver, name))
            for name, value in job.fixed.items() if value is not None and name in read}


def _read_parameters(job: Job, solver: Solver) -> set[str]:
    """The fixed parameters that the task of some point of the job reads (one pass over the points)."""
    undecided = {name for name in job.fixed if solver.parameter(name).read_when is not None}
    read = set(job.fixed) - undecided
    for point in range(job.n_points):
        if not undecided:
            break
        params = job.point_parameters(point)
        found = {name for name in undecided if solver.parameter(name).is_read(params)}
        read |= found
        undecided -= found
    return read


def _coordinate(dims, values, attrs: dict) -> xr.Variable:
    return xr.Variable(dims, values, attrs, encoding=dict(COORDINATE_ENCODING))


def _parameter_attributes(job: Job, solver: Solver, name: str) -> dict:
    parameter = solver.parameter(name)
    return _described(job, parameter.units, parameter.description)


def _described(job: Job, units: str, long_name: str) -> dict:
    """``units`` and ``long_name`` with the placeholders of the job's units filled in."""
    return {"units": resolve_units(units, job.units), "long_name": resolve_units(long_name, job.units)}


def _global_attributes(job: Job, mpi_size: int, ranks_per_task: int) -> dict:
    created = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    return {
        "Conventions": "CF-1.10",
        "title": f"parsim {job.kind} job '{job.name}'",
        "source": f"parsim {__version__}",
        "history": f"{created} parsim run (job '{job.name}', {mpi_size} MPI ranks, {ranks_per_task} per task)",
        "references": REFERENCES,
        **provenance_attributes(),
        "job_name": job.name,
        "job_kind": job.kind,
        "job_seed": job.seed,
        "job_text": job.text,
        **job.unit_attributes,
        **job.input_attributes,
        **job.table_attributes,
        "mpi_size": mpi_size,
        "ranks_per_task": ranks_per_task,
        "date_created": created,
        "comment": "the job's length_unit, time_unit and mass_unit label its numbers and change none (the "
                   f"solvers have no scale of their own); variables with {MEASURED_ATTRIBUTE} = 1 are timings, "
                   "which differ between two runs of a job",
    }


VOLATILE_ATTRIBUTES = ("history", "mpi_size", "ranks_per_task", "date_created")
"""Global attributes that describe the run, not the results."""


def write_dataset(dataset: xr.Dataset, path) -> None:
    """Write ``dataset`` as netCDF-4 to ``path`` atomically; it is built in memory, then written in one piece."""
    write_bytes_atomically(path, dataset.to_netcdf(engine="netcdf4"))


def check_dataset_schema(dataset: xr.Dataset, path: Path) -> None:
    """Refuse a dataset (read from ``path``) that another output schema laid out, in one line."""
    check_schema(dataset.attrs, f"dataset {path}", Path(path).parent)
