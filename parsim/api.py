"""parsim from Python: jobs from dicts and files, runs from scripts and notebooks, single tasks in memory.

::

    import parsim
    job = parsim.Job.from_dict({"name": "q", "kind": "aggregation", "seed": 1, "realizations": 2,
                                "parameters": {"n_spheres": 100, "volume_fraction": 0.2}})
    ds = parsim.run(job)                                   # = parsim run; resumable; the dataset
    cubes = parsim.deposit(2000, seed=1, shape="cube", shape_size=3)
    cubes.statistics.packing_profile                       # one task's statistics, in memory
    cubes.export("cubes.xyz", "extxyz")                    # = parsim export of that task

:func:`run` is ``parsim run``: the same runner, output folder and resume, on one process or
on every rank of ``mpiexec -n K python script.py``.  :func:`deposit` and :func:`aggregate`
solve one task without writing a file: the task of a job with that seed and those parameters
(validated as a job's, with the solver's defaults), bit for bit the task (realisation 0) of
``parsim run`` on such a job.  Heavy modules (xarray, mpi4py, numba's kernels) are imported
when a function needs them, so that ``import parsim`` stays cheap.  docs/python-api.md has a
worked example.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar


from parsim import job as job_files
from parsim.errors import JobError
from parsim.job import UNIT_KEYS, Job

if TYPE_CHECKING:
    import xarray as xr
    from mpi4py import MPI

    from parsim.solver import Configuration, TaskResult

T = TypeVar("T")
_PREPARED: set[str] = set()
"""The small points whose kernels this process has compiled or loaded (see :func:`_prepare_kernels`)."""


def load_job(path: str | os.PathLike, output: str | os.PathLike | None = None) -> Job:
    """Read and validate the job file ``path`` as ``parsim run`` does; ``output`` overrides its folder."""
    from parsim.solvers import SOLVERS

    return job_files.load_job(path, SOLVERS, output=output)


def run(job: Job | Mapping | str | os.PathLike, output: str | os.PathLike | None = None, progress: bool = True,
        ranks_per_task: int = 1) -> xr.Dataset:
    """Run ``job`` as ``parsim run`` does and return its dataset, loaded into memory (the file is closed).

    ``job``: a :class:`Job`, a dict for :meth:`Job.from_dict` or the path of a job file.
    ``output`` overrides the job's folder (``--output``), ``progress=False`` is ``--quiet``,
    ``ranks_per_task`` is ``--ranks-per-task``.  Started as ``mpiexec -n K python script.py``,
    every rank calls ``run`` and the job runs on all of them (``MPI.COMM_WORLD``); every rank
    gets the dataset.  A folder that holds the job already is resumed: finished tasks are not
    computed again, and a finished job is only read.  As with ``parsim run``, a signal (Ctrl-C,
    a notebook's interrupt) ends the process at once, saying how many tasks are kept; calling
    ``run`` again finishes the job.  Raises the :class:`~parsim.errors.ParsimError` of ``parsim
    run`` on every rank; a failure of one rank alone ends every rank, as ``parsim run`` does.
    """
    from mpi4py import MPI

    from parsim.parallel.collective import on_root
    from parsim.parallel.launcher import launcher_mismatch
    from parsim.runner import run_job

    comm = MPI.COMM_WORLD
    mismatch = launcher_mismatch(comm.Get_size())
    if mismatch:  # every process would run the whole job into the same folder
        raise JobError(mismatch)
    chosen = _on_every_rank(comm, lambda: on_root(comm, lambda: _as_job(job, output)))
    path, _ = _on_every_rank(comm, lambda: run_job(chosen, comm, progress=progress, ranks_per_task=ranks_per_task))
    return _on_every_rank(comm, lambda: on_root(comm, lambda: _read_dataset(path)))


def _as_job(job: Job | Mapping | str | os.PathLike, output: str | os.PathLike | None) -> Job:
    if isinstance(job, Job):
        return job if output is None else replace(job, output=Path(output))
    if isinstance(job, Mapping):
        return Job.from_dict(job, output=output)
    if isinstance(job, (str, os.PathLike)):
        return load_job(job, output=output)
    raise TypeError(f"run(job={job!r}): allowed: a parsim.Job, a dict of a job's keys or the path of a job file")


def _on_every_rank(comm: MPI.Comm, work: Callable[[], T]) -> T:
    """``work()`` on every rank of ``comm``; a failure that not every rank shares ends every rank.

    An error that every rank raised alike (through :func:`~parsim.parallel.collective.on_root`)
    is raised on each.  Any other (a file that one rank alone cannot read, a bug) would leave
    the other ranks waiting for ever: as ``parsim run`` does, the failing rank prints it and
    aborts the job, with the command line's exit status.
    """
    from parsim.parallel.collective import abort_if_alone

    try:
        return work()
    except Exception as error:
        if comm.Get_size() > 1:  # a single process raises: a notebook's kernel lives on
            abort_if_alone(comm, error)
        raise


def _read_dataset(path: Path) -> xr.Dataset:
    """The dataset at ``path``, loaded into memory and the file closed."""
    import xarray as xr

    with xr.open_dataset(path) as dataset:
        return dataset.load()


@dataclass(frozen=True, repr=False)
class TaskOutcome:
    """One task solved in memory by :func:`deposit` or :func:`aggregate`.

    - ``statistics``: the task's row of a job's dataset (``dataset.isel(realization=0)``), built
      by the same code, so names, ``units`` and ``long_name`` agree: scalars, and the
      observable dimensions (``z_relative``, ``r``, ``box_size``, ...); the parameters are
      scalar coordinates;
    - ``configuration``: the final :class:`~parsim.solver.Configuration` (``arrays`` by task-file
      path, e.g. ``"spheres/position"``, box, periodicity);
    - ``job``: the one-task job it is the task of; ``job.text`` is its job file,
      which ``parsim run`` computes to the same numbers;
    - ``result``: the solver's :class:`~parsim.solver.TaskResult` (statistics as plain arrays).
    """

    job: Job
    result: TaskResult
    statistics: xr.Dataset

    @property
    def configuration(self) -> Configuration:
        return self.result.configuration

    def export(self, path: str | os.PathLike, format: str, **options) -> list[Path]:
        """Write the configuration for another program, as ``parsim export --format FORMAT`` does.

        ``format``: one of :data:`parsim.output.export.FORMATS` (extxyz, lammps, vtk, csv, yade,
        particles, voxels, mstm; docs/export.md); ``options`` are a format's own (``voxel_size``,
        ``height``; ``wavelength``, ``refractive_index``).  ``path`` is the file to write, or an existing folder to
        write the task's label + the format's suffix in.  The task goes through a task file in a
        temporary folder that is removed afterwards, so the files are those ``parsim export``
        writes for the job's task.  Returns the files written.
        """
        from parsim.output.export import export_output
        from parsim.output.folder import OutputFolder
        from parsim.output.snapshot import write_task_file
        from parsim.runner import task_attributes

        with tempfile.TemporaryDirectory(prefix="parsim-export-") as temporary:
            folder = OutputFolder(Path(temporary), self.job.name)
            folder.create()
            folder.job_copy.write_text(self.job.text, encoding="utf-8")
            task = self.job.tasks()[0]
            write_task_file(folder.task_path(task), self.result, task_attributes(self.job, task))
            return export_output(folder.root, format, out=Path(path), **options)

    def voxelize(self, voxel_size: float, height: float | None = None):
        """The configuration as a solid/void voxel image (:class:`parsim.output.voxels.VoxelImage`,
        ``void`` True in pore space, as porespy and OpenPNM take it), as ``parsim export --format
        voxels`` writes it: voxels of about ``voxel_size``, up to ``height`` above the floor
        (default: the top of the highest sphere), periodic sides wrapped."""
        from parsim.output.export import task_spheres
        from parsim.output.voxels import voxelize

        return voxelize(task_spheres(self.configuration, self.job.tasks()[0].label), voxel_size, height)

    def __repr__(self) -> str:
        fixed = ", ".join(f"{name}={value!r}" for name, value in self.job.fixed.items()
                          if value != _defaults(self.job.kind).get(name))
        spheres = len(self.configuration.arrays["spheres/radius"])
        return f"TaskOutcome({self.job.kind}, seed={self.job.seed}, {fixed}: {spheres} spheres)"


def deposit(n_particles: int, *, seed: int, **parameters: Any) -> TaskOutcome:
    """Deposit ``n_particles`` particles: one task of a deposition job, in memory, no file written.

    ``parameters``: any of the deposition job's keys (docs/jobs.md: ``shape``, ``shape_size``,
    ``box_length``, ``lateral``, ...), checked as a job's with the same messages, and
    ``length_unit``; the others take the solver's defaults.  ``species`` and ``layers`` take a
    list of dicts, the entries of the job file's ``[[species]]`` and ``[[layers]]``.  The random
    stream is that of realisation 0 of this point in any job with this ``seed``, so the outcome equals that task
    of ``parsim run`` bit for bit.  Serial; under mpiexec each rank that calls it computes it.
    """
    return _solve_one_task("deposition", "deposit", seed, {"n_particles": n_particles, **parameters})


def aggregate(n_spheres: int, *, seed: int, **parameters: Any) -> TaskOutcome:
    """Aggregate ``n_spheres`` discs or spheres until one cluster remains: one aggregation task, in memory.

    ``parameters``: any of the aggregation job's keys (``method`` "ed" or "ts", ``dimension``,
    ``volume_fraction``, ``radius``, ...), checked as a job's, and ``length_unit``,
    ``time_unit``, ``mass_unit``.  The method does not enter the random stream: ``method="ed"``
    and ``method="ts"`` with one seed start from the same initial condition.  The outcome
    equals realisation 0 of this point in ``parsim run`` on a job with this seed, bit for bit.  Serial
    (a time-stepping task on one rank); under mpiexec each rank that calls it computes it.
    """
    return _solve_one_task("aggregation", "aggregate", seed, {"n_spheres": n_spheres, **parameters})


def _solve_one_task(kind: str, name: str, seed: int, parameters: dict[str, Any]) -> TaskOutcome:
    """The task of the one-task job ``name`` of ``kind``, solved as the runner solves a task.

    Errors in the parameters name ``parsim.NAME`` where a job file's name its path."""
    from mpi4py import MPI

    from parsim.output.dataset import build_dataset, row_layout
    from parsim.progress import reporting_settled, settled_bar
    from parsim.runner import solve_task
    from parsim.solvers import SOLVERS

    units = {unit.key: parameters.pop(unit.key) for unit in UNIT_KEYS if unit.key in parameters}
    tables = {table.name: parameters.pop(table.name) for table in SOLVERS[kind].tables if table.name in parameters}
    job = Job.from_dict({"name": name, "kind": kind, "seed": seed, "realizations": 1, **units, **tables,
                         "parameters": parameters}, source=f"parsim.{name}")
    _prepare_kernels(job)
    task = job.tasks()[0]
    with settled_bar(f"parsim.{name}") as bar, reporting_settled(bar):
        result = solve_task(job, task, MPI.COMM_SELF)
    rows = row_layout(job, SOLVERS[kind]).rows([(task, result.statistics)])
    dataset = build_dataset(job, SOLVERS[kind], rows, mpi_size=1, ranks_per_task=1)
    return TaskOutcome(job=job, result=result, statistics=dataset.isel(realization=0))


def _prepare_kernels(job: Job) -> None:
    """Compile or load the kernels of ``job``'s task before it is timed, once per small point and process.

    The runner's warm-up (a small version of the point, solved and thrown away), so that the
    statistics' ``wall_time`` excludes compilation as a job's does; it says so on standard error.
    """
    from parsim.runner import warm_up
    from parsim.solvers import SOLVERS

    small = SOLVERS[job.kind].warm_up_parameters(job.point_parameters(0))
    key = repr((job.kind, sorted(small.items())))
    if key not in _PREPARED:
        warm_up(job, job.tasks()[:1], announce=True)
        _PREPARED.add(key)


def _defaults(kind: str) -> dict[str, Any]:
    from parsim.solvers import SOLVERS

    return {parameter.name: parameter.default for parameter in SOLVERS[kind].parameters}
