"""parsim collect: the dataset of the tasks finished so far, beside a job that may still be running."""

import shutil

import numpy as np
import pytest
import xarray as xr

from parsim.cli import main
from parsim.output.lock import FolderLock
from tests.datasets import run_serial, small_aggregation_job, unfinish

JOB = small_aggregation_job("growing", seed=4)


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    folder = tmp_path_factory.mktemp("collect")
    (folder / "job.toml").write_text(JOB)
    result = run_serial("run", str(folder / "job.toml"), "--output", str(folder / "out"), "--quiet")
    assert result.returncode == 0, result.stderr
    return folder / "out"


@pytest.fixture
def half_done(finished, tmp_path):
    """A copy of the finished folder without its dataset and with five of its twelve tasks unfinished."""
    out = tmp_path / "out"
    shutil.copytree(finished, out)
    (out / "growing.nc").unlink()
    removed = [(0, 1), (1, 0), (1, 2), (3, 0), (3, 1)]
    unfinish(out, removed)
    return out, removed


def test_the_finished_tasks_are_those_of_the_whole_job(finished, half_done, capsys):
    out, removed = half_done
    lock = FolderLock(out)
    lock.acquire()  # as a running job holds it
    try:
        assert main(["collect", str(out)]) == 0
        assert lock.path.exists()  # collect took no lock and left the job's alone
    finally:
        lock.release()
    assert "7 of 12 tasks finished" in capsys.readouterr().out
    assert not (out / "growing.nc").exists()  # the job's own dataset is never written by collect
    with xr.open_dataset(out / "growing.partial.nc") as partial, xr.open_dataset(finished / "growing.nc") as whole:
        completed = partial["completed"]
        assert int(completed.sum()) == 7 and completed.attrs["flag_meanings"] == "unfinished finished"
        stacked = completed.stack(task=("n_spheres", "volume_fraction", "realization"))
        for task, done in zip(_tasks(whole), stacked.values):
            assert bool(done) == (task not in removed)
        for name in ("fractal_dimension", "n_collisions", "pair_distribution"):
            finished_part = partial[name].where(completed == 1)
            # every finished task's numbers are the whole job's, every unfinished one is NaN
            np.testing.assert_array_equal(finished_part.fillna(-1.0), whole[name].where(completed == 1).fillna(-1.0))
            assert bool(partial[name].where(completed == 0).isnull().all())


def test_plot_draws_the_partial_dataset(half_done, tmp_path):
    out, _ = half_done
    assert main(["collect", str(out)]) == 0
    assert main(["plot", str(out / "growing.partial.nc"), "--figure", "fractal_dimension",
                 "--out", str(tmp_path / "df.png")]) == 0
    assert (tmp_path / "df.png").stat().st_size > 1000


def test_nothing_to_collect_is_one_line(tmp_path, capsys):
    out = tmp_path / "out"
    (out / "tasks").mkdir(parents=True)
    (out / "job.toml").write_text(JOB)
    assert main(["collect", str(out)]) == 2
    assert "no task of job 'growing' has finished yet" in capsys.readouterr().err


def _tasks(dataset):
    """(point, realisation) of each task in the order of the stacked (sweep..., realization) dimensions."""
    points = len(dataset["n_spheres"]) * len(dataset["volume_fraction"])
    return [(point, realization) for point in range(points) for realization in range(len(dataset["realization"]))]
