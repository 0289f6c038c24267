"""The progress bar's time left holds from the first task, although the costliest tasks run first."""

import tqdm.std

from parsim.progress import TaskProgress


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
    bar = TaskProgress("job", [100.0] + [10.0] * 5, [10.0, 10.0], enabled=True)
    clock.now += 100.0
    bar.task_finished(100.0)
    shown = str(bar._bar)
    bar.close()
    assert "3/8 tasks" in shown
    assert "00:50 left" in shown, shown  # counting tasks would say 5 x 100 s = 08:20
