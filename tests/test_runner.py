"""Jobs end to end: the same dataset on 1 and 2 ranks, after a kill and resume, and the file layouts."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import xarray as xr

from tests.datasets import reproducible_part, run_serial
from tests.mpi import mpiexec, parsim_command, run_mpi

QUICKSTART = "jobs/quickstart.toml"


@pytest.fixture(scope="module")
def quickstart_two_ranks(tmp_path_factory):
    out = tmp_path_factory.mktemp("quickstart2")
    result = run_mpi(parsim_command("run", QUICKSTART, "--output", str(out), "--quiet"))
    assert result.returncode == 0, result.stderr
    return out


@pytest.mark.mpi
def test_quickstart_identical_on_one_and_two_ranks(quickstart_two_ranks, tmp_path):
    result = run_serial("run", QUICKSTART, "--output", str(tmp_path), "--quiet")
    assert result.returncode == 0, result.stderr
    one = reproducible_part(tmp_path / "quickstart.nc")
    two = reproducible_part(quickstart_two_ranks / "quickstart.nc")
    xr.testing.assert_identical(one, two)
    assert one.stop_reason.attrs["flag_meanings"].split()[0] == "single_cluster"
    assert (one.stop_reason == 0).all() and (one.n_clusters == 1).all()  # every task reached one cluster
    assert (one.n_collisions == one.n_spheres - 1).all()


@pytest.mark.mpi
def test_dataset_layout(quickstart_two_ranks):
    with xr.open_dataset(quickstart_two_ranks / "quickstart.nc") as ds:
        assert ds.fractal_dimension.dims == ("n_spheres", "volume_fraction", "realization")
        assert ds.pair_distribution.dims[-1] == "r" and ds.box_count.dims[-1] == "box_size"
        assert ds.realization.attrs["standard_name"] == "realization"
        for name, variable in {**ds.data_vars, **ds.coords}.items():
            assert "units" in variable.attrs and "long_name" in variable.attrs, name
        assert ds.attrs["mpi_size"] == 2 and ds.attrs["job_seed"] == 20240611
        assert "quickstart" in ds.attrs["job_text"] and ds.attrs["parsim_version"]
        assert float(ds.radius) == 0.2  # fixed parameters are scalar coordinates
        # a physicist's sanity check: fractal aggregates between a line and a filled plane
        assert float(ds.fractal_dimension.min()) > 1.0 and float(ds.fractal_dimension.max()) < 2.0


@pytest.mark.mpi
def test_task_snapshot_layout(quickstart_two_ranks):
    with h5py.File(quickstart_two_ranks / "tasks" / "p0004_r0001.h5") as snapshot:
        n = snapshot["spheres/position"].shape[0]
        assert snapshot["spheres/position"].shape == (n, 2) and snapshot["spheres/radius"].shape == (n,)
        assert snapshot["spheres/velocity"].shape == (n, 2) and snapshot["spheres/cluster"].dtype == np.int64
        assert snapshot["links"].shape == (n - 1, 2) and snapshot["links"].dtype == np.int64
        length = snapshot["statistics/box_length"][()]
        np.testing.assert_array_equal(snapshot.attrs["box_upper"], [length, length])
        assert list(snapshot.attrs["periodic"]) == [False, False]
        assert snapshot.attrs["n_spheres"] == n == 400 and snapshot.attrs["volume_fraction"] == 0.2
        assert snapshot.attrs["job_seed"] == 20240611 and list(snapshot.attrs["spawn_key"]) == [4, 1]


@pytest.mark.mpi
def test_killed_job_resumes_to_the_same_dataset(quickstart_two_ranks, tmp_path):
    tasks = tmp_path / "tasks"
    command = [mpiexec(), "-n", "2", sys.executable, *parsim_command("run", QUICKSTART, "--output", str(tmp_path), "--quiet")]
    process = subprocess.Popen(command, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 300
    while len(list(tasks.glob("*.h5"))) < 3 and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.01)
    os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    finished = len(list(tasks.glob("*.h5")))
    assert 3 <= finished < 36, "the kill should land in the middle of the job"
    assert not (tmp_path / "quickstart.nc").exists()
    (tasks / "p0000_r0000.h5.123.tmp").write_bytes(b"half-written")  # what a kill during a write leaves

    result = run_mpi(parsim_command("run", QUICKSTART, "--output", str(tmp_path), "--quiet"))
    assert result.returncode == 0, result.stderr
    assert not list(tmp_path.rglob("*.tmp"))
    xr.testing.assert_identical(reproducible_part(tmp_path / "quickstart.nc"),
                                reproducible_part(quickstart_two_ranks / "quickstart.nc").assign_attrs())


def test_resume_refuses_a_different_job(tmp_path):
    job = tmp_path / "job.toml"
    text = Path(QUICKSTART).read_text().replace("[100, 400, 900]", "[16]").replace("realizations = 4", "realizations = 1")
    job.write_text(text)
    assert run_serial("run", str(job), "--output", str(tmp_path / "out"), "--quiet").returncode == 0
    job.write_text(text.replace("seed = 20240611", "seed = 1"))
    result = run_serial("run", str(job), "--output", str(tmp_path / "out"), "--quiet")
    assert result.returncode == 2 and "differs in: seed" in result.stderr
    info = run_serial("info", str(tmp_path / "out"))
    assert info.returncode == 0 and "tasks finished: 3 of 3" in info.stdout and "fractal_dimension" in info.stdout
