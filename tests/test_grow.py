"""Jobs that grow and shrink in their output folder: tasks are found by their point's values.

A grown job computes only its new tasks, and its dataset equals that of the grown job run at
once into a fresh folder, variable by variable; a point draws the same numbers whatever else
the sweep holds and in whatever order the keys are written.
"""

import shutil

import numpy as np
import pytest
import xarray as xr

from parsim.job import parse_job
from parsim.output.dataset import decoded, row_layout
from parsim.output.rows import read_rows, row_files
from parsim.solvers import SOLVERS
from tests.datasets import reproducible_part, run_serial
from tests.mpi import parsim_command, run_mpi

FIRST = """
name = "growing"
kind = "aggregation"
seed = 11
realizations = 2
[parameters]
dimension = 2
pair_distribution_points = 8
box_levels = 4
n_spheres = 40
[sweep]
volume_fraction = [0.1, 0.2]
"""
GROWN = """
name = "growing"
kind = "aggregation"
seed = 11
realizations = 3
[parameters]
dimension = 2
pair_distribution_points = 8
box_levels = 4
[sweep]
volume_fraction = [0.15, 0.2, 0.1]
n_spheres = [40, 60]
"""


def run_into(tmp_path, name: str, text: str, out: str, job_name: str = "growing") -> xr.Dataset:
    job = tmp_path / f"{name}.toml"
    job.write_text(text)
    result = run_serial("run", str(job), "--output", str(tmp_path / out), "--quiet")
    assert result.returncode == 0, result.stderr
    return reproducible_part(tmp_path / out / f"{job_name}.nc")


def rows_per_file(folder, text: str) -> list[int]:
    job = parse_job(text, SOLVERS)
    layout = row_layout(job, job.solver)
    return sorted(len(read_rows(folder, layout, [path])) for path in row_files(folder))


def assert_same_variables(grown: xr.Dataset, fresh: xr.Dataset) -> None:
    assert set(grown.data_vars) == set(fresh.data_vars)
    for name in fresh.data_vars:
        xr.testing.assert_identical(grown[name], fresh[name])
    xr.testing.assert_identical(grown, fresh)


def test_a_job_grown_in_two_steps_equals_the_grown_job_run_at_once(tmp_path):
    run_into(tmp_path, "first", FIRST, "out")
    grown = run_into(tmp_path, "grown", GROWN, "out")
    fresh = run_into(tmp_path, "grown", GROWN, "fresh")
    assert_same_variables(grown, fresh)
    # the first run's 4 tasks were kept: the second computed the other 3 x 2 x 3 - 4 = 14
    assert rows_per_file(tmp_path / "out" / "rows", GROWN) == [4, 14]
    assert grown.sizes == {"volume_fraction": 3, "n_spheres": 2, "realization": 3, "box_size": 4,
                           "component": 2, "r": 8, "q": 24}


def test_validate_says_how_many_tasks_a_grown_job_computes_and_refuses_a_changed_one(tmp_path):
    run_into(tmp_path, "first", FIRST, "out")
    (tmp_path / "grown.toml").write_text(GROWN)
    checked = run_serial("validate", str(tmp_path / "grown.toml"), "--output", str(tmp_path / "out"))
    assert checked.returncode == 0, checked.stderr
    assert f"{tmp_path / 'out'} holds 4 of these tasks finished: 14 to compute" in checked.stdout
    (tmp_path / "changed.toml").write_text(GROWN.replace("seed = 11", "seed = 12"))
    refused = run_serial("validate", str(tmp_path / "changed.toml"), "--output", str(tmp_path / "out"))
    assert refused.returncode == 2 and "which differs in: seed (11 then, 12 now)" in refused.stderr
    assert (tmp_path / "out" / "job.toml").read_text() == FIRST  # validate writes nothing


def test_a_point_draws_the_same_numbers_whatever_the_sweep_holds_and_its_order(tmp_path):
    grown = run_into(tmp_path, "grown", GROWN, "grown")
    reordered = GROWN.replace("volume_fraction = [0.15, 0.2, 0.1]\nn_spheres = [40, 60]",
                              "n_spheres = [60, 40]\nvolume_fraction = [0.2, 0.1]").replace(
        "dimension = 2\npair_distribution_points = 8", "pair_distribution_points = 8\ndimension = 2")
    other = run_into(tmp_path, "reordered", reordered, "reordered")
    assert list(other.dims)[:2] == ["n_spheres", "volume_fraction"]
    for name in ("fractal_dimension", "radius_of_gyration", "pair_distribution", "n_events"):
        same_points = grown[name].sel(n_spheres=other.n_spheres, volume_fraction=other.volume_fraction)
        np.testing.assert_array_equal(other[name].transpose(*same_points.dims).values, same_points.values)
    assert (grown.fractal_dimension.sel(volume_fraction=0.1) != grown.fractal_dimension.sel(volume_fraction=0.2)).all()


def test_a_shrunk_job_shows_the_job_as_written_now_and_keeps_the_rest(tmp_path):
    run_into(tmp_path, "grown", GROWN, "out")
    shrunk = GROWN.replace("[0.15, 0.2, 0.1]", "[0.2]").replace("realizations = 3", "realizations = 2")
    kept = run_into(tmp_path, "shrunk", shrunk, "out")
    assert_same_variables(kept, run_into(tmp_path, "shrunk", shrunk, "fresh"))
    assert rows_per_file(tmp_path / "out" / "rows", GROWN) == [18]  # nothing computed, nothing removed
    info = run_serial("info", str(tmp_path / "out"))
    assert "tasks finished: 4 of 4 (100 %)" in info.stdout and "kept: 14 finished tasks of values" in info.stdout
    assert len(list((tmp_path / "out" / "tasks").glob("*.h5"))) == 18


def test_a_fixed_key_moved_to_the_sweep_keeps_its_tasks(tmp_path):
    run_into(tmp_path, "first", FIRST, "out")
    moved = FIRST.replace("n_spheres = 40\n", "").replace("[sweep]", "[sweep]\nn_spheres = [40]")
    dataset = run_into(tmp_path, "moved", moved, "out")
    assert rows_per_file(tmp_path / "out" / "rows", FIRST) == [4]
    first = run_into(tmp_path, "first", FIRST, "first")
    np.testing.assert_array_equal(dataset.fractal_dimension.sel(n_spheres=40).values, first.fractal_dimension.values)


@pytest.mark.parametrize("change, named", [
    (("n_spheres = 40", "n_spheres = 41"), "[parameters] n_spheres (40 then, 41 now)"),
    (("seed = 11", "seed = 12"), "seed (11 then, 12 now)"),
    (("dimension = 2", "dimension = 2\nradius = 0.25"), "[parameters] radius (0.2 then, 0.25 now)"),
])
def test_a_changed_fixed_parameter_or_seed_is_still_refused_naming_the_key(tmp_path, change, named):
    run_into(tmp_path, "first", FIRST, "out")
    job = tmp_path / "changed.toml"
    job.write_text(FIRST.replace(*change))
    result = run_serial("run", str(job), "--output", str(tmp_path / "out"), "--quiet")
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert f"holds results of a different job, which differs in: {named}; a job may only add or remove" in result.stderr


@pytest.mark.parametrize("keep, files", [("first", 2), ("none", 0)])
def test_configurations_choose_the_task_files_and_never_the_numbers(tmp_path, keep, files):
    every = run_into(tmp_path, "first", FIRST, "every")
    chosen = run_into(tmp_path, "first", FIRST.replace("seed = 11", f'seed = 11\nconfigurations = "{keep}"'), keep)
    saved = sorted((tmp_path / keep / "tasks").glob("*.h5"))
    assert len(saved) == files and all(path.stem.endswith("_r0000") for path in saved)
    assert {path.name for path in saved} <= {path.name for path in (tmp_path / "every" / "tasks").glob("*.h5")}
    xr.testing.assert_identical(chosen.drop_attrs(), every.drop_attrs())
    if keep == "none":  # a picture of a task says why it cannot be drawn
        drawn = run_serial("plot", str(tmp_path / keep), "--figure", "cluster")
        assert drawn.returncode == 2 and 'holds none (a job with configurations = "none" keeps none)' in drawn.stderr


def test_a_cut_off_or_damaged_row_is_computed_again(tmp_path):
    reference = run_into(tmp_path, "first", FIRST, "out")
    (path,) = row_files(tmp_path / "out" / "rows")
    data = bytearray(path.read_bytes())
    job = parse_job(FIRST, SOLVERS)
    size = row_layout(job, job.solver).dtype.itemsize
    data[-size - 10] ^= 0xFF  # a bit flipped in the third row
    path.write_bytes(bytes(data[:-size // 2]))  # and the fourth cut off, as a kill in its write would leave it
    (path.parent / "rank00001-00000000.rows").write_bytes(data[:20])  # a file killed as it was created
    info = run_serial("info", str(tmp_path / "out"))
    assert "tasks finished: 2 of 4" in info.stdout
    (tmp_path / "out" / "growing.nc").unlink()
    assert_same_variables(run_into(tmp_path, "first", FIRST, "out"), reference)


@pytest.mark.mpi
def test_a_job_grown_on_two_ranks_equals_the_grown_job_run_at_once(tmp_path):
    (tmp_path / "first.toml").write_text(FIRST)
    (tmp_path / "grown.toml").write_text(GROWN)
    for name in ("first", "grown"):
        result = run_mpi(parsim_command("run", str(tmp_path / f"{name}.toml"), "--output", str(tmp_path / "out"),
                                        "--quiet"))
        assert result.returncode == 0, result.stderr
    assert_same_variables(reproducible_part(tmp_path / "out" / "growing.nc"),
                          run_into(tmp_path, "grown", GROWN, "fresh"))


def test_a_job_shrunk_away_from_an_input_file_that_is_gone_runs(tmp_path):
    floors = [tmp_path / "one.csv", tmp_path / "two.csv"]
    floors[0].write_text("x,y,z,r\n1,1,0,0.5\n")
    floors[1].write_text("x,y,z,r\n2,2,0,0.5\n")
    job = f"""
name = "growing"
kind = "deposition"
seed = 3
realizations = 1
[parameters]
n_particles = 5
box_length = 6.0
packing_samples = 1000
[sweep]
substrate = ["{floors[0]}", "{floors[1]}"]
"""
    both = run_into(tmp_path, "both", job, "out")
    floors[1].unlink()  # the second sediment is done: its floor file may go
    shrunk = run_into(tmp_path, "shrunk", job.replace(f', "{floors[1]}"', ""), "out")
    # the substrate's code follows the job's list: compare by the files' names
    xr.testing.assert_identical(decoded(shrunk).filling_height, decoded(both).filling_height.isel(substrate=[0]))
    assert decoded(shrunk)["substrate"].values.tolist() == [str(floors[0])]


RENAMED = """
name = "renamed"
kind = "deposition"
seed = 3
realizations = 2
[parameters]
n_particles = 5
box_length = 20.0
packing_samples = 1000
{fixed}
[sweep]
trial_angle = [0.01, 0.02]
{species}
"""
FILE_KEYS = {  # where the job names the file, and the key a changed content is refused by
    "[parameters] agglomerate_file": ('shape = "agglomerate"\nagglomerate_file = "{path}"', ""),
    "[[species]]": ("", '[[species]]\nname = "flakes"\nshape = "agglomerate"\nagglomerate_file = "{path}"'),
}


@pytest.mark.parametrize("key", FILE_KEYS)
def test_an_input_file_under_another_name_keeps_its_tasks(tmp_path, key):
    first, copy = tmp_path / "flake.csv", tmp_path / "flake copy.csv"
    first.write_text("x,y,z,r\n0,0,0,1\n1.5,0,0,1\n")
    shutil.copy(first, copy)
    fixed, species = FILE_KEYS[key]

    def job(path) -> str:
        return RENAMED.format(fixed=fixed.format(path=path), species=species.format(path=path))

    computed = run_into(tmp_path, "first", job(first), "out", job_name="renamed")
    first.unlink()  # only the copy is left
    again = run_into(tmp_path, "again", job(copy), "out", job_name="renamed")
    assert sum(rows_per_file(tmp_path / "out" / "rows", job(copy))) == 4  # nothing computed again
    for name in computed.data_vars:  # the dataset names the file as the job does now
        xr.testing.assert_equal(again[name].reset_coords(drop=True), computed[name].reset_coords(drop=True))
    copy.write_text("x,y,z,r\n0,0,0,1\n1.8,0,0,1\n")  # another content under the name is another input
    (tmp_path / "changed.toml").write_text(job(copy))
    refused = run_serial("validate", str(tmp_path / "changed.toml"), "--output", str(tmp_path / "out"))
    assert refused.returncode == 2 and f"{key} (" in refused.stderr and "flake copy.csv" in refused.stderr


def test_a_finished_job_run_again_computes_nothing_and_leaves_its_dataset(tmp_path):
    """The same command once more: one line says there is nothing to compute, and the dataset's
    file is not touched; once the job file changes (a sweep value removed) the dataset is written
    again, for the tasks the job now has."""
    run_into(tmp_path, "first", FIRST, "out")
    dataset = tmp_path / "out" / "growing.nc"
    before = dataset.stat().st_mtime_ns, dataset.read_bytes()
    again = run_serial("run", str(tmp_path / "first.toml"), "--output", str(tmp_path / "out"))
    assert again.returncode == 0, again.stderr
    assert "nothing to compute" in again.stderr and "0 tasks" not in again.stderr
    assert (dataset.stat().st_mtime_ns, dataset.read_bytes()) == before
    shrunk = run_into(tmp_path, "shrunk", FIRST.replace("[0.1, 0.2]", "[0.2]"), "out")
    assert shrunk["volume_fraction"].values.tolist() == [0.2]
