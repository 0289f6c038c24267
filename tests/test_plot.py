"""parsim plot: every figure on small outputs laid out like a real job's, and the errors it gives.

The outputs are made without running a job: the dataset is assembled by the runner's own
build_dataset from synthetic statistics, and the task files are written by write_task_file.
"""

import subprocess
import sys
from pathlib import Path

import h5py
import matplotlib.pyplot as plt
import numpy as np
import pytest
import xarray as xr

from parsim.cli import main
from parsim.errors import PlotError
from parsim.job import parse_job
from parsim.output.dataset import decoded
from parsim.output.collect import write_partial_dataset
from parsim.output.dataset import all_statistics, build_dataset, row_layout, write_dataset
from parsim.output.folder import OutputFolder
from parsim.output.snapshot import write_task_file
from parsim.plots import FIGURES, FIGURES_BY_KIND, aggregation, deposition
from parsim.plots.aggregation import power_law
from parsim.plots.common import ensemble, image_paths, save
from parsim.plots.deposition import periodic_images
from parsim.plots.render import render_spheres
from parsim.solver import Configuration, TaskResult
from parsim.solvers import SOLVERS

AGGREGATION_JOB = """
name = "agg"
kind = "aggregation"
seed = 1
realizations = 3
[parameters]
pair_distribution_points = 8
box_levels = 5
[sweep]
method = ["ed", "ts"]
n_spheres = [100, 400, 900]
volume_fraction = [0.1, 0.2]
"""

DEPOSITION_JOB = """
name = "dep"
kind = "deposition"
seed = 1
realizations = 2
[parameters]
n_particles = 300
box_length = 20.0
profile_bins = 10
[sweep]
shape = ["cube", "spiky"]
shape_size = [2, 3]
trial_angle = [0.001, 0.01]
[[species]]
name = "large"
[[species]]
name = "small"
sphere_radius = 0.25
"""

PNG_SIGNATURE, PDF_SIGNATURE = b"\x89PNG\r\n\x1a\n", b"%PDF"


def statistics(job, task) -> dict:
    """Plausible values of every statistic of a task: the figures need shapes, not physics."""
    solver = SOLVERS[job.kind]
    observable = solver.coordinates(job.constants)
    rng = np.random.default_rng([task.point, task.realization])
    values = {s.name: rng.uniform(1.0, 2.0, tuple(len(observable[d].values) for d in s.dims))
              for s in all_statistics(solver)}
    if job.kind == "aggregation":
        n = job.point_parameters(task.point)["n_spheres"]
        values["wall_time"] = 1e-4 * n**1.25 * rng.uniform(0.9, 1.1)
        values["pair_distribution"] = np.cumsum(values["pair_distribution"])
        values["box_count"] = np.minimum(n, 4.0 ** np.arange(len(values["box_count"]), 0, -1))
        angle = rng.uniform(0.0, np.pi)
        values["orientation"] = np.array([abs(np.cos(angle)), np.sin(angle)])
    return values


def disc_chain(rng, dimension=2) -> Configuration:
    """60 touching discs (spheres) in a random chain, the last ten a second cluster."""
    n, radius = 60, 0.2
    steps = rng.normal(size=(n, dimension))
    position = 5.0 + np.cumsum(2 * radius * steps / np.linalg.norm(steps, axis=1, keepdims=True), axis=0)
    return Configuration(arrays={"spheres/position": position, "spheres/radius": np.full(n, radius),
                                 "spheres/cluster": (np.arange(n) >= 50).astype(np.int64)},
                         box_lower=np.zeros(dimension), box_upper=np.full(dimension, 10.0),
                         periodic=np.zeros(dimension, dtype=bool))


def sediment_spheres(rng) -> Configuration:
    """300 particles of eight spheres in a periodic box of side 20, some crossing its sides."""
    n = 2400
    position = rng.uniform([-0.4, -0.4, 0.5], [20.4, 20.4, 8.0], size=(n, 3))
    return Configuration(arrays={"spheres/position": position, "spheres/radius": np.full(n, 0.5),
                                 "spheres/particle": np.arange(n) // 8},
                         box_lower=np.zeros(3), box_upper=np.array([20.0, 20.0, 8.5]),
                         periodic=np.array([True, True, False]), attrs={"floor_z": 0.0})


def write_outputs(root, job_text, configuration):
    """An output folder as a finished job leaves it: job.toml, the dataset, and two task files."""
    job = parse_job(job_text, SOLVERS, output=root)
    folder = OutputFolder(root, job.name)
    folder.prepare(job, None)
    rows = row_layout(job, job.solver).rows([(task, statistics(job, task)) for task in job.tasks()])
    write_dataset(build_dataset(job, SOLVERS[job.kind], rows, 1, 1), folder.dataset)
    rng = np.random.default_rng(0)
    for task in job.tasks()[:2]:
        attrs = {**job.point_parameters(task.point), **job.table_attributes, "task": task.label,
                 "realization": task.realization}
        write_task_file(folder.task_path(task), TaskResult(statistics(job, task), configuration(rng)), attrs)
    return root


def open_dataset(root) -> xr.Dataset:
    with xr.open_dataset(next(root.glob("*.nc"))) as dataset:
        return dataset.load()


def assert_images(paths):
    png, pdf = paths
    assert png.read_bytes().startswith(PNG_SIGNATURE) and png.stat().st_size > 1000
    assert pdf.read_bytes().startswith(PDF_SIGNATURE) and pdf.stat().st_size > 1000


@pytest.fixture(scope="module")
def aggregation_output(tmp_path_factory):
    return write_outputs(tmp_path_factory.mktemp("aggregation"), AGGREGATION_JOB, disc_chain)


@pytest.fixture(scope="module")
def deposition_output(tmp_path_factory):
    return write_outputs(tmp_path_factory.mktemp("deposition"), DEPOSITION_JOB, sediment_spheres)


@pytest.fixture(autouse=True)
def no_figure_left_open():
    yield
    assert plt.get_fignums() == []


@pytest.mark.parametrize("name", list(FIGURES))
def test_each_figure_writes_a_png_and_a_pdf(name, aggregation_output, deposition_output, tmp_path):
    root = aggregation_output if name in FIGURES_BY_KIND["aggregation"] else deposition_output
    spec = FIGURES[name]
    dataset = open_dataset(root)
    arguments = (dataset, sorted((root / "tasks").glob("*.h5"))[0]) if spec.picture else (dataset,)
    assert_images(save(spec.draw(*arguments), tmp_path / name))


def test_plot_writes_every_figure_of_the_dataset_into_its_folder(aggregation_output, capsys):
    assert main(["plot", str(aggregation_output)]) == 0
    written = {path.name for path in (aggregation_output / "figures").iterdir()}
    assert written == {f"{name}{suffix}" for name in FIGURES_BY_KIND["aggregation"] for suffix in (".png", ".pdf")}
    assert "skipped" not in capsys.readouterr().out


def test_plot_skips_figures_whose_variables_are_missing(deposition_output, tmp_path, capsys):
    dataset_path = tmp_path / "dep.nc"  # beside it no tasks folder: no sediment picture either
    open_dataset(deposition_output).isel(shape_size=0).drop_vars("packing_profile").to_netcdf(dataset_path)
    assert main(["plot", str(dataset_path), "--out", str(tmp_path / "figures")]) == 0
    out = capsys.readouterr().out
    assert "skipped efficiency: the dataset lacks dimension 'shape_size'" in out
    assert "skipped packing_profile: the dataset lacks variable 'packing_profile'" in out
    assert "skipped sediment" in out and "holds none" in out
    drawn = {"filling_height", "species_profiles", "long_axes", "radial_distribution"}
    assert sorted(path.name for path in (tmp_path / "figures").iterdir()) == sorted(
        f"{name}{suffix}" for name in drawn for suffix in (".pdf", ".png"))


def test_one_figure_to_a_named_file(deposition_output, tmp_path):
    assert main(["plot", str(deposition_output), "--figure", "filling_height", "--out", str(tmp_path / "h.pdf")]) == 0
    assert_images([tmp_path / "h.png", tmp_path / "h.pdf"])


def test_image_paths():
    assert image_paths("a/fig.v2") == [Path("a/fig.v2.png"), Path("a/fig.v2.pdf")]
    assert image_paths("fig.png") == [Path("fig.png"), Path("fig.pdf")]
    assert image_paths("fig.pdf") == [Path("fig.pdf"), Path("fig.png")]


def test_a_figure_without_its_variable_names_it(deposition_output, tmp_path, capsys):
    dataset = open_dataset(deposition_output).drop_vars("filling_height")
    with pytest.raises(PlotError, match="figure 'filling_height' cannot be drawn: the dataset lacks variable "
                                        "'filling_height'"):
        deposition.filling_height(dataset)
    dataset.to_netcdf(tmp_path / "dep.nc")
    assert main(["plot", str(tmp_path / "dep.nc"), "--figure", "filling_height"]) == 2
    error = capsys.readouterr().err
    assert "variable 'filling_height'" in error and len(error.splitlines()) == 1


def test_the_error_figure_needs_both_methods(aggregation_output):
    with pytest.raises(PlotError, match="dimension 'method' holding 'ed' and 'ts'"):
        aggregation.fractal_error(decoded(open_dataset(aggregation_output), ["method"]).sel({"method": "ts"}))


def test_an_unknown_figure_lists_the_allowed_ones(aggregation_output, capsys):
    assert main(["plot", str(aggregation_output), "--figure", "nonsense"]) == 2
    error = capsys.readouterr().err
    assert "unknown figure 'nonsense'" in error and all(name in error for name in FIGURES)


def test_a_folder_without_a_job_is_refused(tmp_path, capsys):
    assert main(["plot", str(tmp_path)]) == 2
    assert "nor a parsim output folder (no job.toml in it)" in capsys.readouterr().err


def test_the_task_option_picks_the_pictured_task(aggregation_output, tmp_path, capsys):
    label = parse_job(AGGREGATION_JOB, SOLVERS).tasks()[1].label
    fig = aggregation.cluster(open_dataset(aggregation_output), aggregation_output / "tasks" / f"{label}.h5")
    assert f"task {label}: method = ed, n_spheres = 100, volume_fraction = 0.1" in fig.get_suptitle()
    assert "2 clusters" in fig.get_suptitle()
    assert main(["plot", str(aggregation_output), "--figure", "cluster", "--task", label,
                 "--out", str(tmp_path / "c")]) == 0
    assert_images([tmp_path / "c.png", tmp_path / "c.pdf"])
    assert main(["plot", str(aggregation_output), "--figure", "cluster", "--task", "0123456789abcdef_r0000"]) == 2
    assert "no task file" in capsys.readouterr().err


def test_an_unknown_task_is_refused_before_any_figure_is_drawn(aggregation_output, tmp_path, capsys):
    out = tmp_path / "figures"
    assert main(["plot", str(aggregation_output), "--task", "0123456789abcdef_r0000", "--out", str(out)]) == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and "no task file" in error[0] and "--task" in error[0], error
    assert not out.exists()


def test_a_cluster_in_3d_is_rendered(aggregation_output, tmp_path):
    path = tmp_path / "p0000_r0000.h5"
    configuration = disc_chain(np.random.default_rng(1), dimension=3)
    write_task_file(path, TaskResult({}, configuration), {"n_spheres": 60})
    assert_images(save(aggregation.cluster(open_dataset(aggregation_output), path), tmp_path / "cluster3d"))


def test_the_nearer_sphere_hides_the_farther():
    red, blue = [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]
    image, (u0, u1, v0, v1) = render_spheres([0.0, 1.0], [0.0, 0.0], [0.0, -1.0], [1.0, 1.0], np.array([red, blue]))
    rows, columns, _ = image.shape

    def colour_at(u, v):
        return image[int((v - v0) / (v1 - v0) * rows), int((u - u0) / (u1 - u0) * columns)]

    assert colour_at(0.5, 0.0)[2] > 0 and colour_at(0.5, 0.0)[0] == 0  # both cover it; blue is in front
    assert colour_at(-0.5, 0.0)[0] > 0 and colour_at(-0.5, 0.0)[2] == 0  # only red is there
    assert colour_at(-0.9, 0.9)[3] == 0  # outside both discs: transparent


def test_periodic_images_wrap_and_copy_spheres_across_the_sides():
    position, index = periodic_images(np.array([[-0.2, 5.0, 1.0], [5.0, 5.0, 1.0]]), np.array([0.5, 0.5]),
                                      np.zeros(3), np.array([10.0, 10.0, 2.0]), np.array([True, True, False]))
    assert index.tolist() == [0, 1, 0]
    np.testing.assert_allclose(position[[0, 2], 0], [9.8, -0.2])


def test_wall_time_exponent_and_ensemble_statistics():
    n = np.array([100.0, 400.0, 900.0])
    exponent, prefactor = power_law(n, 2.0 * n**1.25)
    assert exponent == pytest.approx(1.25) and prefactor == pytest.approx(2.0)
    assert power_law(n[:1], n[:1]) is None
    ratio = xr.DataArray([[2.0, np.inf, 4.0]], dims=("n_spheres", "realization"))
    mean, spread = ensemble(ratio)  # a straight cluster (infinite aspect ratio) is left out
    assert float(mean[0]) == 3.0 and float(spread[0]) == pytest.approx(np.sqrt(2.0))


def test_running_a_job_does_not_import_matplotlib():
    code = "import sys, parsim.cli, parsim.runner; sys.exit('matplotlib' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


def write_partial(root, job_text, finished) -> Path:
    """The output folder of ``job_text`` where only the tasks ``finished(parameters, task)`` chooses have
    finished, and its partial dataset as parsim collect writes it; the dataset's path."""
    job = parse_job(job_text, SOLVERS, output=root)
    folder = OutputFolder(root, job.name)
    folder.prepare(job, None)
    done = np.array([finished(job.point_parameters(task.point), task) for task in job.tasks()])
    rows = row_layout(job, job.solver).rows([(task, statistics(job, task))
                                             for task, kept in zip(job.tasks(), done) if kept])
    return write_partial_dataset(folder, job, rows, done)[0]


@pytest.mark.parametrize("finished, skipped", [
    # no task of the larger clusters has finished: their panels of box counting would be empty
    (lambda parameters, task: parameters["n_spheres"] == 100, []),
    # no task of time stepping: nothing to compare event-driven runs with
    (lambda parameters, task: parameters["method"] == "ed",
     ["skipped fractal_error: the finished tasks lack a dimension 'method' holding 'ed' and 'ts'"]),
    # a single task
    (lambda parameters, task: task.point == 0 and task.realization == 0,
     ["skipped fractal_error: the finished tasks lack a dimension 'method' holding 'ed' and 'ts'"]),
], ids=["smallest clusters", "event driven", "one task"])
def test_a_partial_dataset_draws_what_its_finished_tasks_give(tmp_path, capsys, finished, skipped):
    partial = write_partial(tmp_path / "out", AGGREGATION_JOB, finished)
    assert main(["plot", str(partial)]) == 0
    captured = capsys.readouterr()
    said = [line for line in captured.out.splitlines() if line.startswith("skipped") and "cluster" not in line]
    assert [line.split(" (")[0] for line in said] == skipped and captured.err == ""
    drawn = {path.stem for path in (tmp_path / "out" / "figures").glob("*.png")}
    assert drawn == set(FIGURES_BY_KIND["aggregation"]) - {"cluster"} - {line.split()[1][:-1] for line in said}


@pytest.mark.parametrize("content", [
    b"sieve size, passing\n1.0, 0\n",       # a text file
    PNG_SIGNATURE + b"\x00\x00\x00\rIHDR",  # an image
    b"",                                    # an empty file
    "hdf5",                                 # an HDF5 file that is not a dataset of a job
    "task",                                 # a task file
], ids=["text", "png", "empty", "hdf5", "task file"])
def test_plot_of_a_file_that_is_no_dataset_is_one_line(deposition_output, tmp_path, capsys, content):
    path = tmp_path / "given.nc"
    if content == "hdf5":
        with h5py.File(path, "w") as file:
            file["values"] = np.arange(3.0)
    elif content == "task":
        path = sorted((deposition_output / "tasks").glob("*.h5"))[0]
    else:
        path.write_bytes(content)
    assert main(["plot", str(path)]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"parsim: error: cannot read {path} as a netCDF dataset: ") or line.startswith(
        f"parsim: error: {path} is not the dataset of a parsim job (it has no attribute job_kind)"), line


def test_plot_of_a_text_file_in_a_terminal(tmp_path):
    path = tmp_path / "notes.nc"
    path.write_text("not a dataset\n")
    result = subprocess.run([sys.executable, "-m", "parsim", "plot", str(path)], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 2
    (line,) = result.stderr.splitlines()
    assert line.startswith(f"parsim: error: cannot read {path} as a netCDF dataset: ")
