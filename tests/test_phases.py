"""Seconds by phase: a phase inside another counts once, and ``parsim run --phase-times`` accounts for
every rank's run with the phases a task goes through."""

import json
import time

import pytest

from parsim import phases
from parsim.phases import phase, phase_times
from tests.datasets import run_serial
from tests.mpi import parsim_command, run_mpi_bounded

#: a small spread deposition: every phase of a task, the survey included, on 2 ranks
DEPOSITION = """
name = "phased"
kind = "deposition"
seed = 3
realizations = 2
[parameters]
n_particles = 300
box_length = 14.0
"""


@pytest.fixture
def fresh_totals(monkeypatch):
    monkeypatch.setattr(phases, "_totals", {})
    monkeypatch.setattr(phases, "_counts", {})


def test_an_inner_phase_is_taken_out_of_the_outer_one(fresh_totals):
    start = time.perf_counter()
    with phase("outer"):
        time.sleep(0.05)
        with phase("inner"):
            time.sleep(0.1)
    block = time.perf_counter() - start
    seconds = phase_times()["seconds"]
    assert seconds["inner"] >= 0.1 and seconds["outer"] >= 0.05
    # the outer phase keeps its own time alone: counted with the inner one too, the two would exceed the block
    assert seconds["outer"] + seconds["inner"] <= block


def test_a_whole_phase_keeps_what_is_timed_inside_it(fresh_totals):
    with phase("warm_up", whole=True):
        with phase("steps"):
            time.sleep(0.05)
    with phase("steps"):
        pass
    times = phase_times()
    assert times["seconds"]["warm_up"] >= 0.05
    assert times["count"] == {"warm_up": 1, "steps": 1}  # the rehearsal's steps are warm-up


def test_a_failing_phase_is_timed_and_ends(fresh_totals):
    with pytest.raises(ValueError):
        with phase("statistics"):
            raise ValueError("numerical trouble")
    with phase("row"):
        pass
    assert phase_times()["count"] == {"statistics": 1, "row": 1}


@pytest.mark.mpi
def test_a_spread_task_run_reports_every_rank_by_phase(tmp_path):
    job = tmp_path / "phased.toml"
    job.write_text(DEPOSITION)
    report = tmp_path / "phases.json"
    process, seconds = run_mpi_bounded(parsim_command("run", str(job), "--output", str(tmp_path / "out"), "--quiet",
                                                      "--ranks-per-task", "2", "--phase-times", str(report)), 900)
    assert process.returncode == 0, process.stderr
    ranks = json.loads(report.read_text())["ranks"]
    assert len(ranks) == 2
    for rank, times in enumerate(ranks):
        # both ranks deposit, survey and measure both tasks together; rank 0 alone writes rows and the dataset
        for name in ("warm_up", "initial_condition", "survey", "steps", "statistics", "task_file"):
            assert times["count"][name] == (1 if name == "warm_up" else 2), (rank, name)
        assert ("row" in times["count"]) == (rank == 0)
        assert sum(times["seconds"].values()) <= times["wall"] <= seconds
        assert all(value >= 0.0 for value in times["seconds"].values())



@pytest.mark.parametrize("where", ["missing/phases.json", "."])
def test_a_phase_file_that_cannot_be_written_is_refused_before_the_run(tmp_path, where):
    """A path in a folder that does not exist, or a folder: one line naming --phase-times, status 2, no
    output folder (the run would compute every task and then fail to write the file)."""
    job = tmp_path / "phased.toml"
    job.write_text(DEPOSITION)
    result = run_serial("run", str(job), "--output", str(tmp_path / "out"), "--phase-times", str(tmp_path / where))
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and "--phase-times" in lines[0], result.stderr
    assert not (tmp_path / "out").exists()
