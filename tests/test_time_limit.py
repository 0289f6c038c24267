"""parsim run --time-limit: tasks start only while they can end in time; the same command continues."""

import pytest
import xarray as xr
from mpi4py import MPI

from parsim.options import duration
from parsim.parallel.scheduler import TimeLimit, run_tasks
from tests.datasets import reproducible_part, run_serial, small_aggregation_job
from tests.mpi import parsim_command, run_mpi

JOB = small_aggregation_job("limited", seed=6)


class FakeClock:
    """Seconds that pass only when a task runs."""

    def __init__(self):
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_tasks_start_while_the_longest_so_far_ends_before_the_reserve():
    clock = FakeClock()
    limit = TimeLimit(10.0, reserve=3.0, clock=clock)
    started = []

    def work(k):
        started.append(k)
        clock.now += 2.0  # every task takes 2 s

    run_tasks(MPI.COMM_SELF, 8, work, time_limit=limit)
    # starts at 0 (nothing measured yet), 2 (2 + 2 + 3 <= 10) and 4 (4 + 2 + 3 <= 10), not at 6 (11 > 10)
    assert started == [0, 1, 2]


def test_batch_times_are_read_as_slurm_writes_them():
    assert duration("23:50:00") == 23 * 3600 + 50 * 60
    assert duration("1-00:00:30") == 86430
    for wrong in ("90", "1:60:00", "12:00", "-1-00:00:00", "a:b:c"):
        with pytest.raises(Exception, match="allowed: HH:MM:SS or D-HH:MM:SS"):
            duration(wrong)


@pytest.mark.mpi
def test_a_run_out_of_time_stops_on_every_rank_and_the_same_command_finishes_it(tmp_path):
    job = tmp_path / "job.toml"
    job.write_text(JOB)
    out = tmp_path / "out"
    # a second is less than the time kept for writing the dataset: no task may start
    stopped = run_mpi(parsim_command("run", str(job), "--output", str(out), "--quiet", "--time-limit", "00:00:01"))
    assert stopped.returncode == 3, stopped.stderr
    assert "--time-limit reached with tasks left (no task has finished); run the same command" in stopped.stderr
    assert not list((out / "tasks").glob("*.h5")) and not (out / "limited.nc").exists()
    finished = run_mpi(parsim_command("run", str(job), "--output", str(out), "--quiet", "--time-limit", "01:00:00"))
    assert finished.returncode == 0, finished.stderr
    fresh = run_serial("run", str(job), "--output", str(tmp_path / "fresh"), "--quiet")
    assert fresh.returncode == 0, fresh.stderr
    xr.testing.assert_identical(reproducible_part(out / "limited.nc"), reproducible_part(tmp_path / "fresh" / "limited.nc"))


@pytest.mark.mpi
def test_a_chunk_of_short_tasks_stops_in_time_when_the_tasks_turn_long():
    result = run_mpi(["tests/scripts/time_limit_probe.py", "2.0", "0.3"])
    assert result.returncode == 0, result.stderr
    ended, finished = result.stdout.split()
    assert float(ended) < 2.0 - 0.3 + 0.15, ended  # the reserve kept, give or take a long task and the polling
    assert 400 < int(finished) < 600
