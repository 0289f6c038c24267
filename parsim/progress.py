"""Rank 0's progress bar over the tasks of a job: done, elapsed, remaining.

Tasks run costliest first and their costs differ a hundredfold, so a bar that
counted tasks would predict the end from the slowest ones and overestimate the
time left many times over.  The bar advances by each task's estimated cost
(:attr:`parsim.solver.Solver.cost`) instead, and the time left is the elapsed
time scaled by the cost still to do over the cost done, averaged over the whole
run; it is shown beside the count of tasks.
"""

import sys

from tqdm import tqdm


class TaskProgress:
    """A bar over all tasks of the job, starting at the tasks finished by earlier runs."""

    def __init__(self, job_name: str, costs: list[float], already_done: list[float], enabled: bool):
        self._job_name = job_name
        self._tasks_total = len(costs) + len(already_done)
        self._tasks_done = len(already_done)
        self._bar = tqdm(total=sum(costs) + sum(already_done), initial=sum(already_done), desc=self._counted(),
                         file=sys.stderr, disable=not enabled, dynamic_ncols=True, mininterval=0.5, smoothing=0,
                         bar_format="{desc}: {percentage:3.0f}%|{bar}| [{elapsed} elapsed, {remaining} left]")

    def task_finished(self, cost: float) -> None:
        self._tasks_done += 1
        self._bar.set_description_str(self._counted(), refresh=False)
        self._bar.update(cost)

    def close(self) -> None:
        self._bar.close()

    def _counted(self) -> str:
        return f"{self._job_name} {self._tasks_done}/{self._tasks_total} tasks"
