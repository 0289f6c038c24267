"""Progress: the time left holds from the first task, although the costliest tasks run first; a
batch log gets plain lines, not a bar."""

import tqdm.std

from parsim.progress import LOG_INTERVAL, TaskProgress
from tests.datasets import run_serial


class Clock:
    def __init__(self):
        self.now = 1000.0

    def __call__(self):
        return self.now


def test_time_left_counts_the_cost_still_to_do(monkeypatch):
    clock = Clock()
    monkeypatch.setattr(tqdm.std, "time", clock)
    # One task of cost 100 first, then five of cost 10, computed at one unit of cost per second;
    # two tasks of cost 10 were finished by an earlier run.
    bar = TaskProgress("job", [100.0] + [10.0] * 5, [10.0, 10.0], enabled=True, interactive=True)
    clock.now += 100.0
    bar.task_finished(100.0)
    shown = str(bar._bar)
    bar.close()
    assert "3/8 tasks" in shown
    assert "00:50 left" in shown, shown  # counting tasks would say 5 x 100 s = 08:20


def test_a_batch_log_gets_one_line_per_batch_of_tasks(capsys):
    clock = Clock()
    progress = TaskProgress("job", [100.0] + [10.0] * 5, [10.0, 10.0], enabled=True, interactive=False,
                            clock=clock)
    clock.now += 100.0
    progress.task_finished(100.0)       # a line: the first
    for _ in range(3):
        clock.now += 0.25 * LOG_INTERVAL
        progress.task_finished(10.0)    # within LOG_INTERVAL of the last line: none
    clock.now += LOG_INTERVAL
    progress.task_finished(10.0)        # a line
    clock.now += 1.0
    progress.task_finished(10.0)        # the last task: always a line
    progress.close()
    lines = capsys.readouterr().err.splitlines()
    # 150 cost units to do; left = elapsed x (150 - done) / done
    assert lines == ["job 3/8 tasks, 01:40 elapsed, 00:50 left",
                     "job 7/8 tasks, 01:48 elapsed, 00:07 left",
                     "job 8/8 tasks, 01:49 elapsed, 00:00 left"]


def test_a_run_whose_output_is_not_a_terminal_writes_plain_progress_lines(tmp_path):
    job = tmp_path / "job.toml"
    job.write_text('name = "lines"\nkind = "aggregation"\nseed = 1\nrealizations = 3\n'
                   '[parameters]\nn_spheres = 25\nvolume_fraction = 0.2\n')
    result = run_serial("run", str(job), "--output", str(tmp_path / "out"))
    assert result.returncode == 0, result.stderr
    assert "\r" not in result.stderr
    assert "lines 3/3 tasks, " in result.stderr and " left" in result.stderr


def test_a_long_deposition_says_how_many_particles_have_settled(monkeypatch, capsys):
    """While the kernel runs, its count of settled particles reaches a thread every
    PROGRESS_SECONDS (made short here): the counts grow, and the last is every particle; the
    Python API draws them as a bar, a run's tasks as log lines."""
    import numpy as np

    import parsim
    from parsim.core import sdbd
    from parsim.progress import reporting_settled, settled_lines, settled_reporter

    monkeypatch.setattr(sdbd.api, "PROGRESS_SECONDS", 0.002)
    n = 20_000
    rng = np.random.default_rng(1)
    heard = []
    sdbd.deposit(np.zeros((1, 3)), np.array([0.5]), np.array([0, 1]), np.zeros(n, dtype=np.int64), np.ones(n),
                 np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), rng.random((n, 2)) * 20.0, (0.0, 0.0), (20.0, 20.0),
                 sdbd.LATERAL_PERIODIC, sdbd.FLOOR_ROLL, progress=heard.append)
    assert len(heard) > 2 and heard == sorted(heard) and heard[-1] == n and 0 < heard[0] < n
    parsim.deposit(n_particles=5000, seed=1, shape="sphere", box_length=20.0)
    assert "parsim.deposit: 100%" in capsys.readouterr().err
    with reporting_settled(settled_lines("task abc")):  # as a run's rank reports its task
        sdbd.deposit(np.zeros((1, 3)), np.array([0.5]), np.array([0, 1]), np.zeros(n, dtype=np.int64), np.ones(n),
                     np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), rng.random((n, 2)) * 20.0, (0.0, 0.0), (20.0, 20.0),
                     sdbd.LATERAL_PERIODIC, sdbd.FLOOR_ROLL, progress=settled_reporter(n))
    lines = capsys.readouterr().err
    assert "parsim: task abc: " in lines and " of 20,000 particles settled (" in lines
