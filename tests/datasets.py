"""Comparing job outputs between runs."""

import hashlib
import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import xarray as xr

from parsim.job import parse_job
from parsim.output.dataset import MEASURED_ATTRIBUTE, VOLATILE_ATTRIBUTES, all_statistics, build_dataset, row_layout
from parsim.output.rows import read_rows, row_files
from parsim.solvers import SOLVERS
from tests.mpi import parsim_command


def reproducible_part(path: Path) -> xr.Dataset:
    """The dataset without timings and run-describing attributes: what must not change between runs."""
    with xr.open_dataset(path) as dataset:
        dataset = dataset.load()
    measured = [name for name, v in dataset.data_vars.items() if v.attrs.get(MEASURED_ATTRIBUTE)]
    dataset = dataset.drop_vars(measured)
    for name in VOLATILE_ATTRIBUTES:
        dataset.attrs.pop(name)
    return dataset


def assert_same_statistics(one, spread):
    """The statistics of a sediment spread over ranks are reduced over them: counts equal, floats to round-off
    (sums in another order)."""
    xr.testing.assert_allclose(one, spread, rtol=1e-11, atol=1e-13)
    for name, variable in one.data_vars.items():
        if variable.dtype.kind in "iub":
            xr.testing.assert_identical(variable, spread[name])


def snapshot_arrays(path: Path) -> dict[str, np.ndarray]:
    """Every dataset of a task file except its statistics group (which holds timings)."""
    arrays = {}
    with h5py.File(path, "r") as file:
        file.visititems(lambda name, item: arrays.__setitem__(name, item[()])
                        if isinstance(item, h5py.Dataset) and not name.startswith("statistics") else None)
    return arrays


def run_serial(*arguments, cwd=None):
    return subprocess.run([sys.executable, *parsim_command(*arguments)], capture_output=True, text=True,
                          timeout=900, cwd=cwd)


def run_jobs(root: Path, jobs: dict[str, str]) -> dict[str, Path]:
    """Each job text of ``jobs`` (by name) written to ``root`` and run serially into ``root/NAME``;
    the output folders by name."""
    for name, text in jobs.items():
        (root / f"{name}.toml").write_text(text)
        result = run_serial("run", str(root / f"{name}.toml"), "--output", str(root / name), "--quiet")
        assert result.returncode == 0, result.stderr
    return {name: root / name for name in jobs}


def small_aggregation_job(name: str, seed: int) -> str:
    """A job of twelve small 2D aggregation tasks (4 points x 3 realisations), a second or two in all."""
    return f"""
name = "{name}"
kind = "aggregation"
seed = {seed}
realizations = 3
[parameters]
dimension = 2
pair_distribution_points = 8
box_levels = 4
[sweep]
n_spheres = [40, 80]
volume_fraction = [0.1, 0.2]
"""


def unfinish(out: Path, tasks: list[tuple[int, int]]) -> None:
    """Make the output folder ``out`` look as if ``tasks`` (point, realisation) of its job had not finished:
    their rows and task files gone, as if a kill had come before them."""
    job = parse_job((out / "job.toml").read_text(), SOLVERS)
    layout = row_layout(job, job.solver)
    rows = read_rows(out / "rows", layout)
    gone = {(job.point_key(point), realization) for point, realization in tasks}
    kept = rows[[(key.tobytes(), int(r)) not in gone for key, r in zip(rows["key"], rows["realization"])]]
    for path in row_files(out / "rows"):
        path.unlink()
    (out / "rows" / "kept.rows").write_bytes(layout.header(job.name) + kept.tobytes())
    for task in job.tasks():
        if (task.point, task.realization) in tasks:
            (out / "tasks" / f"{task.label}.h5").unlink(missing_ok=True)


def swept_mesh_files_dataset(paths: list[str]) -> xr.Dataset:
    """The dataset of a deposition job sweeping ``mesh_file`` over ``paths``, built from rows of zeros
    without running it; the files need not exist (each one's content digest is that of its path)."""
    text = (f'name = "meshes"\nkind = "deposition"\nseed = 1\nrealizations = 1\n[parameters]\nshape = "mesh"\n'
            f'n_particles = 10\nbox_length = 5.0\n[sweep]\nmesh_file = {json.dumps(paths)}\n')
    job = parse_job(text, SOLVERS, verify=False)
    job = replace(job, input_hashes={"mesh_file": {path: hashlib.sha256(path.encode()).hexdigest() for path in paths}})
    observable = job.solver.coordinates(job.constants)
    zeros = {s.name: np.zeros([len(observable[d].values) for d in s.dims]) for s in all_statistics(job.solver)}
    rows = row_layout(job, job.solver).rows([(task, zeros) for task in job.tasks()])
    return build_dataset(job, job.solver, rows, mpi_size=1, ranks_per_task=1)
