"""What ``parsim export --format voxels`` and ``voxelize`` refuse, and that a refusal makes nothing.

Every bad ``--voxel-size`` or ``--height`` (zero, negative, NaN, infinite, not a number, a voxel
wider than the box, an image too large for the machine's memory), a missing ``--voxel-size`` and
a task of discs end in one line naming the option, exit status 2, and no ``--out`` folder.  The
machine's memory is set to :data:`MEMORY` in these tests, so that the images refused for their
size are small and the refusals the same on any machine; the sizes the refusal names as fitting
are exported.  Needs numpy alone (porespy's reading is tests/test_voxels.py).
"""

import json
import math
import re
import tracemalloc
from dataclasses import replace

import numpy as np
import pytest

import parsim.machine
from parsim.cli import main
from parsim.errors import JobError
from parsim.output.export import TaskSpheres, read_task
from parsim.output.voxels import COLUMN_TEMPORARY_BYTES, image_grid, voxelize, write_voxels
from tests.datasets import run_jobs

MEMORY = 8 << 20
"""The machine's physical memory in these tests: 8 MiB."""

JOBS = {
    "deposition": 'name = "sediment"\nkind = "deposition"\nseed = 2\nrealizations = 1\n'
                  '[parameters]\nn_particles = 40\nshape = "sphere"\nbox_length = 4.0\n',
    "discs": 'name = "discs"\nkind = "aggregation"\nseed = 1\nrealizations = 1\n'
             "[parameters]\ndimension = 2\nn_spheres = 25\nvolume_fraction = 0.2\n",
}


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    return run_jobs(tmp_path_factory.mktemp("jobs"), JOBS)


@pytest.fixture(autouse=True)
def small_machine(monkeypatch):
    monkeypatch.setattr(parsim.machine, "physical_memory", lambda: MEMORY)


def export(capsys, output, *options):
    """``parsim export OUTPUT OPTIONS``: its exit status and the lines it printed on stderr."""
    try:
        status = main(["export", str(output), *options])
    except SystemExit as ended:  # argparse's refusal of a value that is not a number
        status = ended.code
    return status, [line for line in capsys.readouterr().err.splitlines() if line.strip()]


def export_voxels(capsys, output, out, *options):
    return export(capsys, output, "--format", "voxels", *options, "--out", f"{out}/")


def assert_refused(status, lines, out, *words):
    """One line on stderr, exit status 2, every one of ``words`` in the line, and no folder ``out``."""
    assert status == 2 and len(lines) == 1, lines
    assert lines[0].startswith("parsim: error: ") and all(word in lines[0] for word in words), lines[0]
    assert not out.exists()


@pytest.mark.parametrize("value", ["0", "-1", "nan", "inf", "-inf", "abc", "1e300", "1e-300", "0.001"])
def test_a_bad_voxel_size_is_one_line_and_makes_no_folder(outputs, tmp_path, capsys, value):
    out = tmp_path / "images"
    assert_refused(*export_voxels(capsys, outputs["deposition"], out, f"--voxel-size={value}"), out, "--voxel-size")


@pytest.mark.parametrize("value", ["0", "-1", "nan", "inf", "abc", "1e9", "1e300"])
def test_a_bad_height_is_one_line_and_makes_no_folder(outputs, tmp_path, capsys, value):
    out = tmp_path / "images"
    assert_refused(*export_voxels(capsys, outputs["deposition"], out, "--voxel-size=0.25", f"--height={value}"),
                   out, "--height")


@pytest.mark.parametrize("kind, options, words", [
    ("deposition", ["--format", "voxels"], ["needs --voxel-size"]),
    ("deposition", ["--all", "--format", "voxels", "--voxel-size=0"], ["--voxel-size"]),
    ("discs", ["--format", "voxels", "--voxel-size=0.1"], ["three-dimensional", "2-D"]),
    ("discs", ["--format", "particles"], ["format 'particles'", "aggregation task"]),
])
def test_a_refused_export_makes_no_folder(outputs, tmp_path, capsys, kind, options, words):
    out = tmp_path / "images"
    assert_refused(*export(capsys, outputs[kind], *options, "--out", f"{out}/"), out, *words)


def exported_files(out) -> dict:
    return {path.suffix: path for path in out.iterdir()}


def suggested(line: str, option: str, bound: str) -> float:
    """The value of ``option`` that the memory refusal ``line`` says fits (``bound``: 'more' or 'less')."""
    return float(re.search(f"{option} (\\S+) or {bound}", line).group(1))


def test_the_memory_refusal_names_the_smallest_voxel_size_that_fits(outputs, tmp_path, capsys):
    status, lines = export_voxels(capsys, outputs["deposition"], tmp_path / "refused", "--voxel-size=0.001")
    assert_refused(status, lines, tmp_path / "refused", "needs about", "more than this machine's 8 MiB")
    size = suggested(lines[0], "--voxel-size", "more")
    assert_refused(*export_voxels(capsys, outputs["deposition"], tmp_path / "finer", f"--voxel-size={0.99 * size}"),
                   tmp_path / "finer", "needs about")
    assert export_voxels(capsys, outputs["deposition"], tmp_path / "fits", f"--voxel-size={size}")[0] == 0


def test_the_memory_refusal_names_the_largest_height_that_fits(outputs, tmp_path, capsys):
    status, lines = export_voxels(capsys, outputs["deposition"], tmp_path / "refused", "--voxel-size=0.25",
                                  "--height=1e9")
    assert_refused(status, lines, tmp_path / "refused", "needs about")
    height = suggested(lines[0], "--height", "less")
    assert_refused(*export_voxels(capsys, outputs["deposition"], tmp_path / "higher", "--voxel-size=0.25",
                                  f"--height={1.01 * height}"), tmp_path / "higher", "needs about")
    assert export_voxels(capsys, outputs["deposition"], tmp_path / "fits", "--voxel-size=0.25",
                         f"--height={height}")[0] == 0
    void = np.load(exported_files(tmp_path / "fits")[".npy"])
    assert void.shape[2] == round(height / 0.25) and void[:, :, -1].all()  # the top: empty space


def test_a_valid_export_is_the_sediment_image(outputs, tmp_path, capsys):
    """Voxels of a tenth of the spheres' diameter: the image's porosity is the exact one up to its
    top, 1 - (the spheres' volume) / (its volume), to a hundredth."""
    status, lines = export_voxels(capsys, outputs["deposition"], tmp_path / "images", "--voxel-size=0.1")
    assert status == 0 and lines == []
    files = exported_files(tmp_path / "images")
    void, layout = np.load(files[".npy"]), json.loads(files[".json"].read_text())
    assert void.dtype == bool and layout["shape"] == list(void.shape) and void.shape[:2] == (40, 40)
    assert np.array_equal(np.fromfile(files[".raw"], dtype=np.uint8).reshape(void.shape).astype(bool), void)
    radius = read_task(next((outputs["deposition"] / "tasks").glob("*.h5"))).radius
    exact = 1.0 - (4.0 / 3.0 * np.pi * radius**3).sum() / (16.0 * void.shape[2] * layout["spacing"][2])
    assert abs(void.mean() - exact) < 0.01, (void.mean(), exact)


def test_the_tiff_stack_is_the_image_ordered_z_y_x(outputs, tmp_path, capsys):
    tifffile = pytest.importorskip("tifffile")
    assert export_voxels(capsys, outputs["deposition"], tmp_path / "images", "--voxel-size=0.2")[0] == 0
    files = exported_files(tmp_path / "images")
    stack = tifffile.imread(files[".tif"])
    assert stack.dtype == np.uint8 and np.array_equal(stack, np.transpose(np.load(files[".npy"]), (2, 1, 0)))


def sphere_task(container: str = "box", dimension: int = 3) -> TaskSpheres:
    """A sphere of radius 1 at the centre of a box of 4 x 4 x 4 (a cylinder of radius 2 with
    ``container = "cylinder"``), periodic along x and y; discs with ``dimension = 2``."""
    return TaskSpheres(label="one", kind="deposition", dimension=dimension, position=np.full((1, 3), 2.0),
                       radius=np.ones(1), body=np.zeros(1, dtype=np.int64), body_name="particle",
                       box_lower=np.zeros(3), box_upper=np.full(3, 4.0), periodic=np.array([True, True, False]),
                       arrays={}, attrs={"container": container, "container_radius": 2.0})


@pytest.mark.parametrize("arguments, option", [
    ((0.0,), "--voxel-size"), ((-1.0,), "--voxel-size"), ((math.nan,), "--voxel-size"), (("abc",), "--voxel-size"),
    ((None,), "--voxel-size"), ((5.0,), "--voxel-size"), ((1e-300,), "--voxel-size"), ((1e-320,), "--voxel-size"),
    ((0.1, math.inf), "--height"), ((0.1, "x"), "--height"), ((0.1, 1e300), "--height"),
])
def test_voxelize_refuses_a_bad_size_naming_its_option(arguments, option):
    with pytest.raises(JobError, match=f"{option}") as refused:
        voxelize(sphere_task(), *arguments)
    assert "\n" not in str(refused.value)


def test_a_limit_that_three_digits_would_pass_is_given_in_full(monkeypatch):
    """A box 1.0004 wide, an image 1.0002 high and memory for one voxel: the voxel sizes that fit lie
    between about 1.0002 and the box's side, where three digits (1.01) are wider than the box."""
    monkeypatch.setattr(parsim.machine, "physical_memory", lambda: 1 + COLUMN_TEMPORARY_BYTES)
    task = replace(sphere_task(), box_upper=np.array([1.0004, 1.0004, 4.0]))
    with pytest.raises(JobError, match="give --voxel-size") as refused:
        voxelize(task, 0.5, 1.0002)
    size = suggested(str(refused.value), "--voxel-size", "more")
    assert 1.0001 < size < 1.0004 and voxelize(task, size, 1.0002).void.shape == (1, 1, 1)


def test_voxelize_refuses_discs():
    with pytest.raises(JobError, match="format 'voxels' images three-dimensional tasks; one is 2-D"):
        voxelize(sphere_task(dimension=2), 0.1)


#: What Python and numpy allocate while an image is made and written that does not grow with it:
#: frames, small objects, ufunc buffers (8192 elements of each operand).
FIXED_BYTES = 256 << 10


@pytest.mark.parametrize("container", ["box", "cylinder"])
def test_the_memory_estimate_bounds_what_the_export_allocates(tmp_path, container):
    """An image of 200 x 200 x 50 voxels (2 MB) made and written as every file (the TIFF stack if
    tifffile is installed): the most it holds at once is the image and at most the estimate's
    column temporaries (a cylinder's mask, a TIFF page)."""
    task = sphere_task(container)
    voxelize(task, 0.5)  # the carving kernel compiled, tifffile imported: neither is the image's
    write_voxels(task, tmp_path / "warm_voxels.npy", 0.5)
    grid = image_grid(task, 0.02, 1.0)
    tracemalloc.start()
    try:
        write_voxels(task, tmp_path / "one_voxels.npy", 0.02, 1.0)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert grid.shape == (200, 200, 50)
    assert math.prod(grid.shape) <= peak <= grid.memory + FIXED_BYTES, (peak, grid.memory)
