"""`parsim run --ranks-per-task K`: each task on a group of K ranks, the same dataset as on one rank."""

import subprocess
import sys
import time

import h5py
import netCDF4
import numpy as np
import pytest
import xarray as xr
from mpi4py import MPI

from parsim.errors import OutputError
from parsim.job import parse_job
from parsim.output.dataset import decoded
from parsim.output.snapshot import parts_folder, read_configuration
from parsim.solvers import SOLVERS
from tests.datasets import assert_same_statistics, reproducible_part, run_serial, snapshot_arrays
from tests.mpi import kill_session, mpiexec, parsim_command, run_mpi

PROBE = "tests/scripts/group_probe.py"

ED_JOB = """
name = "groups_ed"
kind = "aggregation"
seed = 11
realizations = 3
[parameters]
method = "ed"
volume_fraction = 0.2
[sweep]
n_spheres = [16, 36]
"""

DEPOSITION_JOB = """
name = "groups_deposition"
kind = "deposition"
seed = 3
realizations = 2
[parameters]
n_particles = 20
box_length = 6.0
packing_samples = 1000
"""

SPLIT_DEPOSITION_JOB = """
name = "groups_split_deposition"
kind = "deposition"
seed = 4
realizations = 1
[parameters]
n_particles = 500
box_length = 24.0  # two blocks of 12 diameters, wider than the halo of 5: the sediment is split
packing_samples = 1000
"""

TS_JOB = """
name = "groups_ts"
kind = "aggregation"
seed = 5
realizations = 2
[parameters]
n_spheres = 64
volume_fraction = 0.1  # L = 9: wide enough for two ranks' tiles
[sweep]
method = ["ed", "ts"]
"""

SMALL_TS_JOB = """
name = "groups_small_ts"
kind = "aggregation"
seed = 5
realizations = 1
[parameters]
dimension = 3
method = "ts"
volume_fraction = 0.1
[sweep]
n_spheres = [64, 343]  # L = 2.8 and 4.9: narrower than two tiles of two halos (3.2 each)
"""


def write_job(tmp_path, text):
    path = tmp_path / "job.toml"
    path.write_text(text)
    return str(path)


def run_on_groups(job, out, ranks, ranks_per_task):
    return run_mpi(parsim_command("run", job, "--output", str(out), "--quiet", "--ranks-per-task", str(ranks_per_task)),
                   ranks=ranks, timeout=300)


def run_grouped_and_serial(tmp_path, text, ranks, ranks_per_task):
    """The job ``text`` on ``ranks`` ranks in groups (output in ``grouped/``) and on one rank (``one/``)."""
    job = write_job(tmp_path, text)
    grouped = run_on_groups(job, tmp_path / "grouped", ranks=ranks, ranks_per_task=ranks_per_task)
    assert grouped.returncode == 0, grouped.stderr
    one = run_serial("run", job, "--output", str(tmp_path / "one"), "--quiet")
    assert one.returncode == 0, one.stderr
    return tmp_path / "grouped", tmp_path / "one"


def read_records(prefix, ranks):
    rows = []
    for rank in range(ranks):
        with open(f"{prefix}.{rank}") as file:
            rows += [tuple(map(int, line.split())) for line in file.read().splitlines() if line]
    return rows


@pytest.mark.mpi
def test_every_task_runs_once_on_a_whole_group_of_consecutive_ranks(tmp_path):
    result = run_mpi([PROBE, str(tmp_path / "rec"), "2", "12"], ranks=4)
    assert result.returncode == 0, result.stderr
    by_task = {}
    for k, world_rank, group_rank, group_size in read_records(tmp_path / "rec", 4):
        assert group_size == 2 and group_rank == world_rank % 2
        by_task.setdefault(k, []).append(world_rank)
    assert sorted(by_task) == list(range(12))
    assert all(sorted(ranks) in ([0, 1], [2, 3]) for ranks in by_task.values()), by_task


@pytest.mark.mpi
@pytest.mark.parametrize("ranks, task, group_rank", [(4, 1, 1), (2, 0, 0)], ids=["follower", "only_leader"])
def test_a_failure_on_any_rank_of_a_group_ends_the_job(tmp_path, ranks, task, group_rank):
    # The failing rank's group partners wait in a collective, the other group sleeps 30 s: neither may delay the end.
    start = time.perf_counter()
    result = run_mpi([PROBE, str(tmp_path / "rec"), "2", "4", str(task), str(group_rank)], ranks=ranks, timeout=120)
    assert result.returncode != 0
    assert f"synthetic failure in task {task}" in result.stderr
    assert time.perf_counter() - start < 25


@pytest.mark.mpi
def test_ed_job_on_groups_of_two_is_the_one_rank_job(tmp_path):
    four, one = run_grouped_and_serial(tmp_path, ED_JOB, ranks=4, ranks_per_task=2)
    xr.testing.assert_identical(reproducible_part(one / "groups_ed.nc"), reproducible_part(four / "groups_ed.nc"))
    with xr.open_dataset(four / "groups_ed.nc") as ds:
        assert ds.attrs["mpi_size"] == 4 and ds.attrs["ranks_per_task"] == 2
        assert (ds.rank_imbalance == 1.0).all() and ds.rank_imbalance.attrs["units"] == "1"
    for path in (one / "tasks").glob("*.h5"):
        one_arrays, four_arrays = snapshot_arrays(path), snapshot_arrays(four / "tasks" / path.name)
        assert one_arrays.keys() == four_arrays.keys() and one_arrays["diagnostics/rank_imbalance"].shape == (0,)
        for name, array in one_arrays.items():
            np.testing.assert_array_equal(array, four_arrays[name], err_msg=name)


@pytest.mark.mpi
def test_a_deposition_too_narrow_to_split_runs_on_the_group_leader(tmp_path):
    two, one = run_grouped_and_serial(tmp_path, DEPOSITION_JOB, ranks=2, ranks_per_task=2)
    assert_same_statistics(reproducible_part(one / "groups_deposition.nc"),
                           reproducible_part(two / "groups_deposition.nc"))
    for path in (one / "tasks").glob("*.h5"):  # rank 1 holds no particle
        with h5py.File(parts_folder(two / "tasks" / path.name) / "rank0001.h5") as part:
            assert part["spheres/radius"].shape == (0,)


@pytest.mark.mpi
def test_a_deposition_split_over_a_group_is_the_one_rank_job(tmp_path):
    two, one = run_grouped_and_serial(tmp_path, SPLIT_DEPOSITION_JOB, ranks=2, ranks_per_task=2)
    assert_same_statistics(reproducible_part(one / "groups_split_deposition.nc"),
                           reproducible_part(two / "groups_split_deposition.nc"))
    for path in (one / "tasks").glob("*.h5"):
        spread = two / "tasks" / path.name
        one_configuration, spread_configuration = read_configuration(path), read_configuration(spread)
        assert one_configuration.arrays.keys() == spread_configuration.arrays.keys()
        for name, array in one_configuration.arrays.items():
            np.testing.assert_array_equal(array, spread_configuration.arrays[name], err_msg=name)
        for name in ("box_lower", "box_upper", "periodic"):
            np.testing.assert_array_equal(getattr(one_configuration, name), getattr(spread_configuration, name))
        # the task file joins the ranks' files: netCDF4's own HDF5 library reads its arrays as one, the ranks'
        # particles one after the other, which particles/index puts in the drop order
        parts = sorted(path.name for path in parts_folder(spread).iterdir())
        assert parts == ["rank0000.h5", "rank0001.h5"]
        with netCDF4.Dataset(spread) as joined:
            index = joined["particles"]["index"][:]
            assert sorted(index) == list(range(len(index))) and not np.all(np.diff(index) > 0)
            centres = joined["particles"]["center_of_mass"][:]
            np.testing.assert_array_equal(centres[np.argsort(index)],
                                          one_configuration.arrays["particles/center_of_mass"])
        with h5py.File(spread) as joined:
            assert joined["spheres/position"].is_virtual and not joined["shapes/offsets"].is_virtual
        (parts_folder(spread) / "rank0001.h5").rename(tmp_path / "moved.h5")  # HDF5 alone would read zeros
        with pytest.raises(OutputError, match="rank0001.h5 is missing"):
            read_configuration(spread)


@pytest.mark.mpi
def test_a_split_deposition_killed_mid_job_resumes_to_the_same_dataset(tmp_path):
    job = write_job(tmp_path, SPLIT_DEPOSITION_JOB.replace("realizations = 1", "realizations = 6")
                    .replace("n_particles = 500", "n_particles = 3000"))
    out = tmp_path / "grouped"
    arguments = parsim_command("run", job, "--output", str(out), "--quiet", "--ranks-per-task", "2")
    process = subprocess.Popen([mpiexec(), "-n", "2", sys.executable, *arguments], start_new_session=True,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 300
    while not list((out / "tasks").glob("*.h5")) and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.01)
    kill_session(process)  # mpiexec and both ranks, in the middle of a split task or between two
    assert 1 <= len(list((out / "tasks").glob("*.h5"))) < 6, "the kill should land in the middle of the job"
    assert run_on_groups(job, out, ranks=2, ranks_per_task=2).returncode == 0
    one = run_serial("run", job, "--output", str(tmp_path / "one"), "--quiet")
    assert one.returncode == 0, one.stderr
    assert_same_statistics(reproducible_part(tmp_path / "one" / "groups_split_deposition.nc"),
                           reproducible_part(out / "groups_split_deposition.nc"))


@pytest.mark.mpi
@pytest.mark.parametrize("ranks, ranks_per_task", [(4, 3), (2, 0)])
def test_ranks_per_task_must_divide_the_ranks(tmp_path, ranks, ranks_per_task):
    result = run_on_groups(write_job(tmp_path, ED_JOB), tmp_path / "out", ranks=ranks, ranks_per_task=ranks_per_task)
    divisors = {4: "1, 2, 4", 2: "1, 2"}[ranks]
    assert result.returncode == 2
    assert (f"parsim: error: --ranks-per-task {ranks_per_task}: allowed: a divisor of the number of MPI ranks "
            f"({ranks}): {divisors}") in result.stderr
    assert result.stderr.count("parsim: error:") == 1 and "Traceback" not in result.stderr
    assert not (tmp_path / "out").exists()  # checked before anything is written


def test_ranks_per_task_must_be_positive(tmp_path):
    result = run_serial("run", write_job(tmp_path, ED_JOB), "--output", str(tmp_path / "out"), "--ranks-per-task", "0")
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert "--ranks-per-task 0: allowed: a divisor of the number of MPI ranks (1): 1" in result.stderr


@pytest.mark.parametrize("method", ["ed", "ts"])
def test_serial_task_records_a_unit_imbalance(method):
    job = parse_job(TS_JOB.replace('method = ["ed", "ts"]', f'method = ["{method}"]'), SOLVERS)
    params = job.point_parameters(0)
    result = SOLVERS["aggregation"].solve(params, np.random.default_rng(1), MPI.COMM_SELF)
    imbalance = result.configuration.arrays["diagnostics/rank_imbalance"]
    assert result.statistics["rank_imbalance"] == 1.0 and (imbalance == 1.0).all()
    if method == "ts":  # one value per time step that searched for contacts (not the quiet ones)
        assert 0 < len(imbalance) <= result.statistics["n_events"]
    else:
        assert imbalance.shape == (0,)


@pytest.mark.mpi
def test_ts_and_ed_job_on_groups_of_two(tmp_path):
    four, one = run_grouped_and_serial(tmp_path, TS_JOB, ranks=4, ranks_per_task=2)
    # TS decomposed over two ranks sums forces in another order: equal to round-off, same counts
    one_rank, two_ranks = (reproducible_part(out / "groups_ts.nc") for out in (one, four))
    xr.testing.assert_allclose(one_rank, two_ranks, rtol=1e-9, atol=1e-12)
    for name in ("n_events", "n_collisions", "n_minimisations", "n_minimiser_iterations", "n_wall_reflections"):
        assert (one_rank[name] == two_ranks[name]).all(), name
    with xr.open_dataset(four / "groups_ts.nc") as ds:
        named = decoded(ds, ["method"])
        ts, ed = named.sel({"method": "ts"}), named.sel({"method": "ed"})
        assert (ds.n_clusters == 1).all() and (ds.n_collisions == 63).all()
        assert (ts.n_minimisations > 0).all() and (ed.rank_imbalance == 1.0).all()
        assert np.isfinite(ts.rank_imbalance).all() and (ts.rank_imbalance >= 1.0).all()
    for path in (four / "tasks").glob("*.h5"):
        with h5py.File(path) as task:
            imbalance = task["diagnostics/rank_imbalance"][:]
            if task.attrs["method"] == "ts":
                assert 0 < len(imbalance) <= task["statistics/n_events"][()] and (imbalance >= 1.0).all()
            else:
                assert imbalance.shape == (0,)
            assert task["statistics/rank_imbalance"][()] == imbalance.max(initial=1.0)


@pytest.mark.mpi
def test_ts_task_too_small_for_the_groups_tiles_runs_in_one_tile(tmp_path):
    """A box narrower than a tile per rank is not decomposed: the group gives the one-rank result, bitwise."""
    two, one = run_grouped_and_serial(tmp_path, SMALL_TS_JOB, ranks=2, ranks_per_task=2)
    xr.testing.assert_identical(reproducible_part(one / "groups_small_ts.nc"),
                                reproducible_part(two / "groups_small_ts.nc"))
    with xr.open_dataset(two / "groups_small_ts.nc") as ds:
        assert (ds.n_clusters == 1).all() and (ds.rank_imbalance == 1.0).all()
    for path in (one / "tasks").glob("*.h5"):
        one_arrays, two_arrays = snapshot_arrays(path), snapshot_arrays(two / "tasks" / path.name)
        assert one_arrays.keys() == two_arrays.keys()
        for name, array in one_arrays.items():
            np.testing.assert_array_equal(array, two_arrays[name], err_msg=name)
