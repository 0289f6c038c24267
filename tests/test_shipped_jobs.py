"""Every job shipped in jobs/, shrunk to seconds, runs to its dataset: on one rank, on two (the same
dataset), and for a deposition with each sediment spread over a group of two ranks (``--ranks-per-task
2``): the same sediments, and the same statistics to round-off.

The shrinking is read off each job file, so that a job added to jobs/ is covered as it is: fewer
particles (its layers in proportion), realisations and packing samples, the sweep cut to two points
(the first value of every swept key, the first two of the last one); its shapes, species, layers,
containers and files stay.  A file a job reads from another shipped job's output folder (the
agglomerate made by the quick start) is read from that job's shrunk output, which is run first.
"""

import tomllib
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import parsim
from parsim.job import Job
from parsim.output.snapshot import read_configuration
from parsim.solvers import SOLVERS
from tests.datasets import assert_same_statistics, reproducible_part
from tests.mpi import parsim_command, run_mpi_bounded

REPO = Path(__file__).resolve().parent.parent
SHIPPED = {path.stem: tomllib.loads(path.read_text()) for path in sorted((REPO / "jobs").glob("*.toml"))}
#: the largest value a shrunk job keeps of each size key (aggregation: the paper's smallest N; spheres
#: per smooth particle, whose shape stays); a new solver kind adds its own
SIZES = {"n_particles": 24, "n_spheres": 100, "shape_spheres": 100, "packing_samples": 1000}
#: the sample counts of the statistics, set when a job leaves them at their (larger) default
SAMPLES = ("packing_samples",)
REALIZATIONS = 2
DEPOSITIONS = [name for name, document in SHIPPED.items() if document["kind"] == "deposition"]


def file_keys(kind: str) -> set[str]:
    return {parameter.name for parameter in SOLVERS[kind].parameters if parameter.is_file}


def producer(path: str) -> str | None:
    """The shipped job whose output folder holds ``path``, if any."""
    for name, document in SHIPPED.items():
        if "output" in document and Path(path).is_relative_to(document["output"]):
            return name
    return None


def located(path: str, outputs: Path) -> str:
    """``path`` as the shipped job reads it from the repository, or from the shrunk output of the job
    that writes it (in ``outputs/serial``)."""
    if not path or Path(path).is_absolute():
        return path
    made_by = producer(path)
    if made_by is None:
        return str(REPO / path)
    return str(outputs / "serial" / made_by / Path(path).relative_to(SHIPPED[made_by]["output"]))


def capped(key: str, value):
    return min(value, SIZES[key]) if key in SIZES and isinstance(value, int) else value


def small_samples(kind: str, sweep: dict) -> dict:
    """The statistics' sample counts of the solver of ``kind`` at their caps (unless swept)."""
    return {p.name: capped(p.name, p.default) for p in SOLVERS[kind].parameters
            if p.name in SAMPLES and p.name not in sweep}


def shrunk_sweep(sweep: dict) -> dict:
    """The first value of every swept key, the first two of the last one, sizes capped."""
    keys = list(sweep)
    return {key: list(dict.fromkeys(capped(key, value) for value in values[:2 if key == keys[-1] else 1]))
            for key, values in sweep.items()}


def shrunk_layers(layers: list[dict], n_particles: int, shrunk_particles: int) -> list[dict]:
    """The layers in proportion, at least one particle each."""
    return [{**layer, "n_particles": max(1, layer["n_particles"] * shrunk_particles // n_particles)}
            for layer in layers]


def shrunk(document: dict, outputs: Path) -> dict:
    """The shipped job ``document`` (a job file's keys) made small, its files located (:func:`located`)."""
    files = file_keys(document["kind"])

    def small(table: dict) -> dict:
        return {key: located(value, outputs) if key in files else capped(key, value) for key, value in table.items()}

    job = {key: value for key, value in document.items() if key != "output"}
    job["realizations"] = min(document["realizations"], REALIZATIONS)
    job["sweep"] = {key: [located(v, outputs) for v in values] if key in files else values
                    for key, values in shrunk_sweep(document.get("sweep", {})).items()}
    job["parameters"] = {**small_samples(document["kind"], job["sweep"]), **small(document.get("parameters", {}))}
    for name in ("species", "layers"):
        if name in document:
            job[name] = [small(entry) for entry in document[name]]
    if "layers" in document:
        job["layers"] = shrunk_layers(document["layers"], document["parameters"]["n_particles"],
                                      job["parameters"]["n_particles"])
        job["parameters"]["n_particles"] = sum(layer["n_particles"] for layer in job["layers"])
    return job


def needs(name: str) -> list[str]:
    """The shipped jobs whose output job ``name`` reads."""
    files = file_keys(SHIPPED[name]["kind"])
    document = SHIPPED[name]
    tables = [document.get("parameters", {}), *document.get("species", [])]
    paths = [value for table in tables for key, value in table.items() if key in files]
    paths += [value for key, values in document.get("sweep", {}).items() if key in files for value in values]
    return sorted({made_by for made_by in map(producer, paths) if made_by is not None})


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    return tmp_path_factory.mktemp("shipped")


@pytest.fixture(scope="module")
def job_file(outputs):
    """The shrunk job file of a shipped job, written once."""
    def write(name: str) -> Path:
        path = outputs / "jobs" / f"{name}.toml"
        if not path.exists():
            path.parent.mkdir(exist_ok=True)
            path.write_text(Job.from_dict(shrunk(SHIPPED[name], outputs)).text)
        return path

    return write


@pytest.fixture(scope="module")
def serial(outputs, job_file):
    """The output folder of a shipped job's shrunk run on one rank (in this process), run once, after the
    jobs it reads from."""
    def run(name: str) -> Path:
        folder = outputs / "serial" / name
        if not folder.exists():
            for made_by in needs(name):
                run(made_by)
            parsim.run(job_file(name), output=folder, progress=False)
        return folder

    return run


def check_dataset(folder: Path, job_path: Path) -> xr.Dataset:
    """The run's dataset holds every task of its job; for a deposition every particle settled."""
    job = parsim.load_job(job_path)
    dataset = reproducible_part(folder / f"{job.name}.nc")
    expected = {**{key: len(values) for key, values in job.sweep.items()}, "realization": job.realizations}
    assert {dim: dataset.sizes[dim] for dim in expected} == expected
    if job.kind == "deposition":
        for task in job.tasks():
            particles = read_configuration(folder / "tasks" / f"{task.label}.h5").arrays["particles/center_of_mass"]
            assert len(particles) == job.point_parameters(task.point)["n_particles"], task.label
            assert np.all(particles[:, 2] > 0.0), task.label  # above the floor
    return dataset


def run_on_two_ranks(folder: Path, job_path: Path, *options: str) -> xr.Dataset:
    """``mpiexec -n 2 parsim run``: its dataset, checked (:func:`check_dataset`)."""
    # a hang's bound: a first run compiles the kernels of a spread deposition, minutes on 2 busy cores
    result, _ = run_mpi_bounded(parsim_command("run", str(job_path), "--output", str(folder), "--quiet", *options),
                                1800, ranks=2)
    assert result.returncode == 0, result.stderr
    return check_dataset(folder, job_path)


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_job_runs_on_one_rank(name, serial, job_file):
    check_dataset(serial(name), job_file(name))


@pytest.mark.mpi
@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_job_runs_on_two_ranks_as_on_one(name, outputs, serial, job_file):
    one = check_dataset(serial(name), job_file(name))
    xr.testing.assert_identical(run_on_two_ranks(outputs / "two" / name, job_file(name)), one)


@pytest.fixture(scope="module")
def grouped(outputs, serial, job_file):
    """The output folder of a shipped deposition's shrunk run on 2 ranks with each task spread over both, run
    once (after the jobs it reads from)."""
    def run(name: str) -> Path:
        folder = outputs / "groups" / name
        if not folder.exists():
            serial(name)
            run_on_two_ranks(folder, job_file(name), "--ranks-per-task", "2")
        return folder

    return run


@pytest.mark.mpi
@pytest.mark.parametrize("name", DEPOSITIONS)
def test_shipped_deposition_spread_over_two_ranks_is_the_serial_sediment(name, serial, grouped, job_file):
    for task in parsim.load_job(job_file(name)).tasks():
        one, spread = (read_configuration(out / "tasks" / f"{task.label}.h5") for out in (serial(name), grouped(name)))
        assert one.arrays.keys() == spread.arrays.keys()
        for key, array in one.arrays.items():
            np.testing.assert_array_equal(array, spread.arrays[key], err_msg=f"{task.label} {key}")


@pytest.mark.mpi
@pytest.mark.parametrize("name", DEPOSITIONS)
def test_shipped_deposition_spread_over_two_ranks_has_the_serial_statistics(name, serial, grouped, job_file):
    assert_same_statistics(check_dataset(serial(name), job_file(name)), check_dataset(grouped(name), job_file(name)))
