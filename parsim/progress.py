"""Rank 0's progress bar over the tasks of a job: done, elapsed, remaining."""

import sys

from tqdm import tqdm


class TaskProgress:
    """A bar over all tasks of the job, starting at the tasks finished by earlier runs."""

    def __init__(self, job_name: str, total: int, already_done: int, enabled: bool):
        self._bar = tqdm(total=total, initial=already_done, desc=job_name, unit="task", file=sys.stderr,
                         disable=not enabled, dynamic_ncols=True, mininterval=0.5,
                         bar_format="{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} tasks "
                                    "[{elapsed} elapsed, {remaining} left]")

    def task_finished(self) -> None:
        self._bar.update(1)

    def close(self) -> None:
        self._bar.close()
