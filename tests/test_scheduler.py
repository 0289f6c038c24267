"""The dynamic scheduler: every task once, every rank busy, failures end the job."""

import time

import pytest
from mpi4py import MPI

from parsim.parallel.scheduler import CHUNK_SECONDS, TaskFailed, _TaskCounter, run_tasks
from tests.mpi import run_mpi

PROBE = "tests/scripts/scheduler_probe.py"


def read_records(prefix, ranks):
    rows = []
    for rank in range(ranks):
        with open(f"{prefix}.{rank}") as file:
            rows += [line.split() for line in file.read().splitlines() if line]
    return [(int(k), int(r), float(s), float(e)) for k, r, s, e in rows]


def test_single_rank_runs_every_task_in_order():
    seen, finished = [], []
    run_tasks(MPI.COMM_SELF, 5, seen.append, on_finished=lambda k, rank: finished.append((k, rank)))
    assert seen == [0, 1, 2, 3, 4]
    assert finished == [(k, 0) for k in range(5)]


def test_single_rank_failure_names_the_task():
    def work(k):
        if k == 2:
            raise ValueError("boom")

    with pytest.raises(TaskFailed, match="(?s)task 2 failed.*boom"):
        run_tasks(MPI.COMM_SELF, 4, work)


@pytest.mark.mpi
def test_two_ranks_share_unequal_tasks(tmp_path):
    # One task 100 times longer than the others: a static split would leave a rank idle.
    costs = [2.0] + [0.02] * 100
    result = run_mpi([PROBE, str(tmp_path / "rec"), ",".join(map(str, costs))])
    assert result.returncode == 0, result.stderr
    records = read_records(tmp_path / "rec", 2)
    assert sorted(k for k, *_ in records) == list(range(len(costs)))  # every task exactly once
    busy = {rank: sum(e - s for k, r, s, e in records if r == rank) for rank in (0, 1)}
    assert min(busy.values()) > 1.5, busy  # both ranks computed, rank 0 included
    span = max(e for *_, e in records) - min(s for _, _, s, _ in records)
    assert span < 0.8 * sum(costs), span  # the long task overlapped the short ones


@pytest.mark.mpi
def test_failure_on_any_rank_ends_the_job(tmp_path):
    # Task 5 fails while the other rank is busy with a long task: the job must end at once.
    costs = [30.0] + [0.01] * 10
    start = time.perf_counter()
    result = run_mpi([PROBE, str(tmp_path / "rec"), ",".join(map(str, costs)), "5"], timeout=120)
    assert result.returncode != 0
    assert "synthetic failure in task 5" in result.stderr
    assert time.perf_counter() - start < 25


def test_short_tasks_go_out_in_chunks_of_about_chunk_seconds_and_long_ones_alone():
    counter = _TaskCounter(10_000, n_ranks=2, time_limit=None)
    assert counter.take() == (0, 1, None)  # nothing timed yet: one task
    counter.timed(1, 0.2)  # longer than CHUNK_SECONDS
    assert counter.take() == (1, 1, None)
    counter.timed(999, 0.8 - 0.2)  # now 1000 tasks in 0.8 s: 0.8 ms each
    first, count, _ = counter.take()
    assert first == 2 and count == int(CHUNK_SECONDS / 0.8e-3)
    small = _TaskCounter(10, n_ranks=2, time_limit=None)
    small.timed(100, 0.01)
    assert small.take() == (0, 2, None)  # never more than a share of what is left: 10 // (2 x 2)
    assert [small.take()[:2] for _ in range(5)] == [(2, 2), (4, 1), (5, 1), (6, 1), (7, 1)]


@pytest.mark.mpi
def test_many_tiny_tasks_go_out_in_chunks_each_once(tmp_path):
    costs = [0.0005] * 4000
    result = run_mpi([PROBE, str(tmp_path / "rec"), ",".join(map(str, costs))])
    assert result.returncode == 0, result.stderr  # the probe checks that rank 0 heard of every task
    records = read_records(tmp_path / "rec", 2)
    assert sorted(k for k, *_ in records) == list(range(len(costs)))
    chunks = 0
    for rank in (0, 1):
        mine = sorted(k for k, r, *_ in records if r == rank)
        assert len(mine) > 500, (rank, len(mine))  # both ranks computed
        chunks += 1 + sum(1 for a, b in zip(mine, mine[1:]) if b != a + 1)
    assert chunks < len(costs) / 10, chunks
