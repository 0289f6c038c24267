"""The Python interface: jobs from dicts, run() and its resume, single tasks against a job's, the worked example.

docs/python-api.md is executed here block by block, so that its example cannot fall out of
step with the code.  Single tasks are compared bit for bit with the task files of ``parsim
run`` on the equivalent job file.
"""

import dataclasses
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import h5py
import numpy as np
import pytest
import xarray as xr

import parsim
import parsim.aggregation.solver as aggregation_solver
from parsim.errors import JobError
from parsim.job import parse_job
from parsim.output.dataset import MEASURED_ATTRIBUTE, VOLATILE_ATTRIBUTES
from parsim.output.export import export_output
from parsim.solvers import SOLVERS
from tests.datasets import reproducible_part, run_serial, snapshot_arrays
from tests.mpi import run_mpi_bounded
from tests.test_job import BASE

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "python-api.md"

AGGREGATION = BASE.replace('output = "out"\n', "")  # test_job's grid, without an output folder

DEPOSITION = """
name = "cubes"
kind = "deposition"
seed = 5
realizations = 2
[parameters]
n_particles = 12
shape = "cube"
shape_size = 2
box_length = 8.0
packing_samples = 2000
"""
DEPOSITION_PARAMETERS = {"n_particles": 12, "shape": "cube", "shape_size": 2, "box_length": 8.0,
                         "packing_samples": 2000}

DISCS = {"name": "discs", "kind": "aggregation", "seed": 3, "realizations": 2,
         "parameters": {"n_spheres": 30, "volume_fraction": 0.1}}


def measured(dataset: xr.Dataset) -> list[str]:
    return [name for name, variable in dataset.data_vars.items() if variable.attrs.get(MEASURED_ATTRIBUTE)]


def physics(dataset: xr.Dataset) -> xr.Dataset:
    """The variables that must agree between two computations of the same tasks, with their attributes."""
    return dataset.drop_vars(measured(dataset)).drop_attrs(deep=False)


def without_run_attributes(dataset: xr.Dataset) -> xr.Dataset:
    """The dataset without the global attributes that describe the run (its date, the ranks)."""
    return dataset.drop_attrs(deep=False).assign_attrs(
        {name: value for name, value in dataset.attrs.items() if name not in VOLATILE_ATTRIBUTES})


# --- Job.from_dict ------------------------------------------------------------------------------

@pytest.mark.parametrize("change", [
    ("seed = 7", "seed = 7\ncolour = 1"),
    ("seed = 7", "seed = -1"),
    ("seed = 7", "seed = 1.0"),
    ('name = "t"', 'name = "a/b"'),
    ('kind = "aggregation"', 'kind = "piles"'),
    ("realizations = 2", "realizations = 0"),
    ("radius = 0.2", "radius = 0.2\nradiuss = 1"),
    ("radius = 0.2", 'radius = "big"'),
    ("radius = 0.2", "radius = -1"),
    ("radius = 0.2", "radius = true"),
    ("radius = 0.2", "radius = 1" + "0" * 30),
    ("radius = 0.2", 'radius = 0.2\nmethod = "magic"'),
    ("[0.1, 0.2, 0.3]", "[0.1, 1.5]"),
    ("[0.1, 0.2, 0.3]", "[0.1, 0.1]"),
    ("[0.1, 0.2, 0.3]", "[0.1, 0.8]"),
    ("n_spheres = [100, 400]", "box_levels = [8, 9]\nn_spheres = [100, 400]"),
    ("n_spheres = [100, 400]", "n_spheres = [100, 400]\nradius = [0.2]"),
    ("n_spheres = [100, 400]", ""),
    ("n_spheres = [100, 400]", "n_spheres = 100"),
    ("n_spheres = [100, 400]", "n_spheres = [100, 1000000000000]"),
    ("seed = 7", 'seed = 7\nlength_unit = "metre"'),
    ("[parameters]\nradius = 0.2", "parameters = 3"),
])
def test_from_dict_refuses_what_a_job_file_refuses_with_the_same_message(change):
    text = AGGREGATION.replace(*change)
    with pytest.raises(JobError) as from_file:
        parse_job(text, SOLVERS, source="job.toml")
    with pytest.raises(JobError) as from_dict:
        parsim.Job.from_dict(tomllib.loads(text), source="job.toml")
    assert str(from_dict.value) == str(from_file.value)


def test_from_dict_gives_the_job_of_the_file_and_a_text_that_reads_back_to_it():
    from_file = parse_job(AGGREGATION, SOLVERS)
    job = parsim.Job.from_dict(tomllib.loads(AGGREGATION))
    assert dataclasses.replace(job, text="") == dataclasses.replace(from_file, text="")
    assert dataclasses.replace(parse_job(job.text, SOLVERS), text="") == dataclasses.replace(job, text="")


def test_from_dict_takes_numpy_values_and_names_the_key_of_a_value_toml_cannot_hold():
    document = {"name": "t", "kind": "aggregation", "seed": np.int64(7), "realizations": 1, "length_unit": "mm",
                "parameters": {"radius": np.float64(0.2), "n_spheres": np.int32(100)},
                "sweep": {"volume_fraction": np.linspace(0.1, 0.3, 3)}}
    job = parsim.Job.from_dict(document)
    assert job.sweep == {"volume_fraction": [0.1, 0.2, 0.3]} and job.fixed["n_spheres"] == 100
    assert job.seed == 7 and job.units["length"] == "mm"
    for where, value, message in [
            ("volume_fraction", None, r"\[parameters\] volume_fraction = None: a job file has no null; leave the key "
                                      "out for its default"),
            ("radius", object(), r"\[parameters\] radius = <object .*>: allowed: a string, an integer, a number"),
            (3, 0.1, "key 3 in parameters: keys must be strings")]:
        bad = {**document, "parameters": {**document["parameters"], where: value}}
        with pytest.raises(JobError, match=f"^Job.from_dict: {message}"):
            parsim.Job.from_dict(bad)


def test_load_job_is_the_command_line_reader(tmp_path):
    path = tmp_path / "discs.toml"
    path.write_text(AGGREGATION)
    assert parsim.load_job(path, output=tmp_path / "out") == parse_job(AGGREGATION, SOLVERS, output=tmp_path / "out")
    with pytest.raises(JobError, match="cannot read job file"):
        parsim.load_job(tmp_path / "missing.toml")


def test_import_parsim_loads_neither_numpy_nor_mpi():
    probe = ("import sys, parsim; print(parsim.__version__, 'numpy' in sys.modules, 'mpi4py' in sys.modules, "
             "parsim.Job.__module__, parsim.run.__module__, sorted(set(parsim.__all__) - set(dir(parsim))))")
    shown = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout.split()
    assert shown[1:] == ["False", "False", "parsim.job", "parsim.api", "[]"]
    with pytest.raises(AttributeError, match="no attribute 'solve'"):
        parsim.solve  # noqa: B018 - the attribute access is the test


# --- run ----------------------------------------------------------------------------------------

def test_run_returns_the_dataset_in_memory_and_resumes_without_computing(tmp_path, monkeypatch):
    job = parsim.Job.from_dict(DISCS)
    first = parsim.run(job, output=tmp_path / "discs", progress=False)
    dataset = tmp_path / "discs" / "discs.nc"
    with xr.open_dataset(dataset) as stored:
        xr.testing.assert_identical(first, stored.load())
    tasks = {path: path.stat().st_mtime_ns for path in (tmp_path / "discs" / "tasks").iterdir()}
    assert len(tasks) == 2

    def no_task(*args):
        raise AssertionError("a finished job computed a task again")

    solver = SOLVERS["aggregation"]
    monkeypatch.setitem(SOLVERS, "aggregation", dataclasses.replace(solver, solve=no_task))
    dataset.unlink()  # the dataset of the first call lives on in memory, and the second writes it again
    again = parsim.run(tmp_path / "discs" / "job.toml", output=tmp_path / "discs", progress=False)
    assert {path: path.stat().st_mtime_ns for path in (tmp_path / "discs" / "tasks").iterdir()} == tasks
    assert dataset.is_file()
    # timings included: both are read from the same task files
    xr.testing.assert_identical(without_run_attributes(again), without_run_attributes(first))
    assert first.fractal_dimension.shape == (2,) and np.all(np.isfinite(first.fractal_dimension))


def test_run_refuses_a_folder_of_another_job(tmp_path):
    parsim.run(DISCS, output=tmp_path, progress=False)
    with pytest.raises(JobError, match=r"holds results of a different job, which differs in: seed \(3 then, 4 now\)"):
        parsim.run({**DISCS, "seed": 4}, output=tmp_path, progress=False)
    with pytest.raises(TypeError, match="allowed: a parsim.Job, a dict"):
        parsim.run(42)


RANKS_SCRIPT = """
import sys
from mpi4py import MPI
import parsim
from parsim.errors import JobError

rank = MPI.COMM_WORLD.Get_rank()
job = parsim.Job.from_dict({job!r})
ds = parsim.run(job, output=sys.argv[1], progress=False)
lines = [f"dataset {{ds.attrs['mpi_size']}} {{float(ds.fractal_dimension.sum())!r}}"]
try:
    parsim.run({{**{job!r}, "realizations": 0}}, output=sys.argv[1])
except JobError as error:
    lines.append(f"error {{error}}")
with open(f"{{sys.argv[1]}}/rank{{rank}}.txt", "w") as report:  # mpiexec may interleave the ranks' stdout
    report.write("\\n".join(lines))
"""


@pytest.mark.mpi
def test_run_under_mpiexec_runs_on_every_rank_and_every_rank_gets_the_dataset(tmp_path):
    script = tmp_path / "script.py"
    script.write_text(RANKS_SCRIPT.format(job=DISCS))
    result, _ = run_mpi_bounded([str(script), str(tmp_path / "two")], bound=300, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    serial = parsim.run(DISCS, output=tmp_path / "one", progress=False)
    expected = (f"dataset 2 {float(serial.fractal_dimension.sum())!r}\n"
                "error Job.from_dict: realizations = 0: allowed: an integer >= 1")
    for rank in (0, 1):
        assert (tmp_path / "two" / f"rank{rank}.txt").read_text() == expected
    xr.testing.assert_identical(physics(reproducible_part(tmp_path / "two" / "discs.nc")), physics(serial))


# --- deposit, aggregate -------------------------------------------------------------------------

@pytest.fixture(scope="module")
def deposition_job(tmp_path_factory):
    """DEPOSITION run by the command line, two realisations."""
    folder = tmp_path_factory.mktemp("cubes")
    (folder / "cubes.toml").write_text(DEPOSITION)
    result = run_serial("run", str(folder / "cubes.toml"), "--output", str(folder / "out"), "--quiet")
    assert result.returncode == 0, result.stderr
    return folder / "out"


def assert_same_arrays(mine: dict, theirs: dict) -> None:
    """The same names, dtypes and values, bit for bit (NaN where NaN)."""
    assert sorted(mine) == sorted(theirs)
    for name, array in mine.items():
        expected = theirs[name]
        assert np.asarray(array).dtype == expected.dtype and np.array_equal(array, expected, equal_nan=True), name


def test_deposit_is_the_first_task_of_the_job_with_its_seed_bit_for_bit(deposition_job, tmp_path):
    cubes = parsim.deposit(seed=5, **DEPOSITION_PARAMETERS)
    label = cubes.job.tasks()[0].label  # the task's label follows its values, whatever job it is in
    task_file = deposition_job / "tasks" / f"{label}.h5"
    assert_same_arrays(cubes.configuration.arrays, snapshot_arrays(task_file))
    with xr.open_dataset(deposition_job / "cubes.nc") as dataset:
        row = dataset.isel(realization=0).load()
    xr.testing.assert_identical(physics(cubes.statistics), physics(row))
    with h5py.File(task_file) as file:
        statistics = {name: dataset[()] for name, dataset in file["statistics"].items()}
    unmeasured = {name for name in statistics if name not in measured(row)}
    assert_same_arrays({name: cubes.result.statistics[name] for name in unmeasured},
                       {name: statistics[name] for name in unmeasured})
    other = snapshot_arrays(deposition_job / "tasks" / f"{label[:-5]}r0001.h5")
    assert not np.array_equal(cubes.configuration.arrays["spheres/position"], other["spheres/position"])

    mine = cubes.export(tmp_path / "mine.xyz", "extxyz")
    theirs = export_output(deposition_job, "extxyz", task=label, out=tmp_path / "theirs.xyz")
    assert mine == [tmp_path / "mine.xyz"] and mine[0].read_bytes() == theirs[0].read_bytes()
    assert cubes.export(tmp_path, "csv") == [tmp_path / f"{label}.csv"]


def test_aggregate_equals_the_jobs_tasks_and_the_method_keeps_the_initial_condition(tmp_path, monkeypatch):
    starts = {}  # function name -> what it returned, call after call
    parameters = DISCS["parameters"]

    def recorded(name, function):
        """``function``, recording what it returns for the tasks' spheres (the warm-ups have fewer)."""
        def wrapper(n, *args):
            value = function(n, *args)
            if n == parameters["n_spheres"]:
                starts.setdefault(name, []).append(value)
            return value
        monkeypatch.setattr(aggregation_solver, name, wrapper)

    recorded("lattice_positions", aggregation_solver.lattice_positions)
    recorded("isotropic_velocities", aggregation_solver.isotropic_velocities)
    outcomes = {method: parsim.aggregate(seed=3, method=method, **parameters) for method in ("ed", "ts")}
    parsim.aggregate(seed=4, **parameters)
    assert sorted(starts) == ["isotropic_velocities", "lattice_positions"]
    for name, (ed, ts, other_seed) in starts.items():
        np.testing.assert_array_equal(ed, ts, err_msg=name)
        assert not np.array_equal(ed, other_seed), name

    both = parsim.run({**DISCS, "sweep": {"method": ["ed", "ts"]}}, output=tmp_path, progress=False)
    for point, method in enumerate(("ed", "ts")):
        task_file = tmp_path / "tasks" / f"{outcomes[method].job.tasks()[0].label}.h5"
        assert_same_arrays(outcomes[method].configuration.arrays, snapshot_arrays(task_file))
        # the parameters only TS reads are coordinates of the job's dataset, not of the ED task's row
        row = both.isel(method=point, realization=0)
        xr.testing.assert_identical(physics(outcomes[method].statistics).reset_coords(drop=True),
                                    physics(row).reset_coords(drop=True))


@pytest.mark.parametrize("call, job_file, message", [
    (lambda: parsim.deposit(10, seed=1, shape="blob"),
     'name = "deposit"\nkind = "deposition"\nseed = 1\nrealizations = 1\n[parameters]\nn_particles = 10\n'
     'shape = "blob"', r"\[parameters\] shape = 'blob': allowed: one of 'sphere', 'rod'"),
    (lambda: parsim.deposit(10, seed=1, colour=3),
     'name = "deposit"\nkind = "deposition"\nseed = 1\nrealizations = 1\n[parameters]\nn_particles = 10\n'
     'colour = 3', r"\[parameters\] unknown key 'colour'; allowed keys for kind 'deposition': n_particles, shape"),
    (lambda: parsim.deposit(10, seed=-1),
     'name = "deposit"\nkind = "deposition"\nseed = -1\nrealizations = 1\n[parameters]\nn_particles = 10',
     r"seed = -1: allowed: an integer, 0 <= seed"),
    (lambda: parsim.aggregate(30, seed=1, length_unit="metre"),
     'name = "aggregate"\nkind = "aggregation"\nseed = 1\nrealizations = 1\nlength_unit = "metre"\n'
     '[parameters]\nn_spheres = 30', r"length_unit = 'metre': allowed: a UDUNITS length unit"),
    (lambda: parsim.aggregate(30, seed=1),
     'name = "aggregate"\nkind = "aggregation"\nseed = 1\nrealizations = 1\n[parameters]\nn_spheres = 30',
     r"volume_fraction is required with initial_condition = 'lattice_isotropic'"),
])
def test_deposit_and_aggregate_check_their_parameters_as_a_job_does(call, job_file, message):
    source = job_file.split('"')[1]
    with pytest.raises(JobError, match=f"^parsim\\.{source}: {message}") as from_call:
        call()
    with pytest.raises(JobError) as from_file:
        parse_job(job_file, SOLVERS, source=f"parsim.{source}")
    assert str(from_call.value) == str(from_file.value)


def test_a_task_outcome_labels_its_units_and_refuses_an_unknown_export_format(tmp_path):
    clusters = parsim.aggregate(30, seed=3, volume_fraction=0.1, length_unit="um", time_unit="ms")
    assert clusters.statistics.box_length.attrs["units"] == "um"
    assert clusters.statistics.final_time.attrs["units"] == "ms"
    assert clusters.statistics.pair_distribution.dims == ("r",)
    assert int(clusters.statistics.n_clusters) == 1 and int(clusters.statistics.n_collisions) == 29
    assert repr(clusters) == "TaskOutcome(aggregation, seed=3, n_spheres=30, volume_fraction=0.1: 30 spheres)"
    with pytest.raises(JobError, match="unknown export format 'pdb'; allowed: extxyz, lammps, vtk, csv, yade"):
        clusters.export(tmp_path / "c.pdb", "pdb")
    assert list(tmp_path.iterdir()) == []


# --- the worked example -------------------------------------------------------------------------

def python_blocks(markdown: str) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```$", markdown, flags=re.DOTALL | re.MULTILINE)


def test_the_worked_example_of_the_python_api_runs(tmp_path, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    monkeypatch.chdir(tmp_path)
    blocks = python_blocks(DOC.read_text(encoding="utf-8"))
    assert len(blocks) == 4
    namespace = {}
    for block in blocks:
        exec(compile(block, str(DOC), "exec"), namespace)

    # the job block: resumed to the same dataset
    assert (tmp_path / "output" / "discs" / "discs.nc").is_file()
    xr.testing.assert_identical(physics(namespace["again"]), physics(namespace["ds"]))
    # the sediment: 26 spheres per cube, phi(z) over the whole sediment, the exported file
    cubes, phi = namespace["cubes"], namespace["phi"]
    assert namespace["positions"].shape == (26 * namespace["N_CUBES"], 3)
    assert phi.dims == ("z_relative",) and phi.attrs["units"] == "1"
    assert 0.1 < float(cubes.statistics.bulk_packing_fraction) < 0.6
    assert (tmp_path / "cubes_phi.png").stat().st_size > 0
    assert namespace["written"] == [Path("cubes.xyz")]
    assert len((tmp_path / "cubes.xyz").read_text().splitlines()) == 2 + 26 * namespace["N_CUBES"]
    # the clusters: one each, fractal, from the same initial condition
    clusters = namespace["clusters"]
    for outcome in clusters.values():
        assert int(outcome.statistics.n_clusters) == 1
    assert all(1.0 < value < 2.0 for value in namespace["d_f"].values())
