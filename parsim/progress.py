"""Rank 0's progress over the tasks of a job (done, elapsed, remaining), and over long preparation.

Tasks run costliest first and their costs differ a hundredfold, so progress that
counted tasks would predict the end from the slowest ones and overestimate the
time left many times over.  Progress advances by each task's estimated cost
(:attr:`parsim.solver.Solver.cost`) instead, and the time left is the elapsed
time scaled by the cost still to do over the cost done, averaged over the whole
run; it is shown beside the count of tasks.

On a terminal this is a bar redrawn in place.  Elsewhere (a batch system's log
file, a pipe) it is one plain line per finished batch of tasks, at most every
``LOG_INTERVAL`` seconds and always for the last task, so that a log holds a
readable history instead of thousands of carriage returns.

Preparation that may take more than a few seconds before any task (building a particle of
thousands of spheres) says what it does, its estimated time and, every few seconds, the time
elapsed (:func:`preparing`).
"""

import math
import sys
import time
from contextlib import contextmanager

from tqdm import tqdm

from parsim.core.ticker import ticking

#: Seconds between two progress lines when standard error is not a terminal.
LOG_INTERVAL = 5.0
#: Preparation (building a particle, say) estimated to take longer than this says so, and how far it got.
ANNOUNCED_PREPARATION_SECONDS = 3.0
#: Seconds between two lines of a preparation under way.
PREPARATION_INTERVAL = 10.0
_preparation_announced = [True]  # off on the ranks other than 0 and with --quiet (:func:`announcing_preparation`)


class TaskProgress:
    """Progress over all tasks of the job, starting at the tasks finished by earlier runs.

    ``interactive``: a bar redrawn in place (True) or plain lines (False); by default,
    whether standard error is a terminal.
    """

    def __init__(self, job_name: str, costs: list[float], already_done: list[float], enabled: bool,
                 interactive: bool | None = None, clock=time.monotonic):
        self._job_name = job_name
        self._tasks_total = len(costs) + len(already_done)
        self._tasks_done = len(already_done)
        if interactive is None:
            interactive = sys.stderr.isatty()
        self._bar = None
        self._lines = None
        if enabled and interactive:
            self._bar = tqdm(total=sum(costs) + sum(already_done), initial=sum(already_done), desc=self._counted(),
                             file=sys.stderr, dynamic_ncols=True, mininterval=0.5, smoothing=0,
                             bar_format="{desc}: {percentage:3.0f}%|{bar}| [{elapsed} elapsed, {remaining} left]")
        elif enabled:
            self._lines = _ProgressLines(sum(costs), clock)

    def task_finished(self, cost: float) -> None:
        self._tasks_done += 1
        if self._bar is not None:
            self._bar.set_description_str(self._counted(), refresh=False)
            self._bar.update(cost)
        elif self._lines is not None:
            line = self._lines.task_finished(cost, last=self._tasks_done == self._tasks_total)
            if line:
                print(f"{self._counted()}, {line}", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()

    def _counted(self) -> str:
        return f"{self._job_name} {self._tasks_done}/{self._tasks_total} tasks"


class _ProgressLines:
    """Elapsed time and time left of this run, as text at most every ``LOG_INTERVAL`` seconds."""

    def __init__(self, cost_to_do: float, clock):
        self._cost_to_do = cost_to_do
        self._cost_done = 0.0
        self._clock = clock
        self._start = clock()
        self._last_line = -math.inf

    def task_finished(self, cost: float, last: bool) -> str | None:
        """``"E elapsed, L left"`` if a line is due (``last``: the job's last task), else None."""
        self._cost_done += cost
        now = self._clock()
        if not last and now - self._last_line < LOG_INTERVAL:
            return None
        self._last_line = now
        elapsed = now - self._start
        left = elapsed * max(self._cost_to_do - self._cost_done, 0.0) / self._cost_done if self._cost_done > 0 else 0.0
        return f"{tqdm.format_interval(elapsed)} elapsed, {tqdm.format_interval(left)} left"


@contextmanager
def announcing_preparation(enabled: bool):
    """Within the block, :func:`preparing` prints (``enabled``) or keeps silent."""
    before = _preparation_announced[0]
    _preparation_announced[0] = enabled
    try:
        yield
    finally:
        _preparation_announced[0] = before


@contextmanager
def announcing_compilation(message: str, enabled: bool):
    """Within the block, print ``message`` on standard error (if ``enabled``) when one of parsim's
    kernels starts to compile, not when they all load from numba's cache (numba announces no
    compilation then); yields a function that tells whether it was printed."""
    if not enabled:
        yield lambda: False
        return
    from numba.core import event

    from parsim.core.jit import defined_in_core

    started = []

    class FirstCompilation(event.Listener):
        def on_start(self, ev):
            if not started and defined_in_core((ev.data or {}).get("dispatcher")):
                started.append(True)
                print(message, file=sys.stderr, flush=True)

        def on_end(self, ev):
            pass

    watch = FirstCompilation()
    event.register("numba:compile", watch)
    try:
        yield lambda: bool(started)
    finally:
        event.unregister("numba:compile", watch)


@contextmanager
def preparing(what: str, estimated_seconds: float, clock=time.monotonic):
    """Report on standard error the preparation of ``what`` while the block runs, if it is estimated to
    take more than ``ANNOUNCED_PREPARATION_SECONDS``: a line when it starts, with the estimate, one every
    ``PREPARATION_INTERVAL`` seconds with the time elapsed, and one when it is done.

    The lines come from a thread, which runs while the block computes in a jitted kernel (the kernels
    release the GIL).
    """
    if estimated_seconds <= ANNOUNCED_PREPARATION_SECONDS or not _preparation_announced[0]:
        yield
        return
    print(f"parsim: {what} (about {tqdm.format_interval(estimated_seconds)})...", file=sys.stderr, flush=True)
    start = clock()

    def report() -> None:
        print(f"parsim: {what}: {tqdm.format_interval(clock() - start)} elapsed", file=sys.stderr, flush=True)

    with ticking(PREPARATION_INTERVAL, report, "parsim-preparation"):
        yield
    print(f"parsim: {what}: done in {tqdm.format_interval(clock() - start)}", file=sys.stderr, flush=True)


_settling = [None]  # report(done, total) of the task this process runs (:func:`reporting_settled`)


@contextmanager
def reporting_settled(report):
    """Within the block, a task's long loop (a deposition's particles) tells ``report(done, total)``
    how far it got, every few seconds (:func:`settled_reporter`)."""
    before = _settling[0]
    _settling[0] = report
    try:
        yield
    finally:
        _settling[0] = before


def settled_reporter(total: int):
    """The ``progress(done)`` callback of a loop over ``total`` items under :func:`reporting_settled`, or None."""
    report = _settling[0]
    return None if report is None else (lambda done: report(done, total))


def settled_lines(what: str, clock=time.monotonic):
    """A ``report(done, total)`` that prints ``parsim: WHAT: done of total particles settled (x %),
    elapsed`` on standard error, above a progress bar if one is drawn (:func:`tqdm.write`)."""
    start = clock()

    def report(done: int, total: int) -> None:
        if done < total:
            tqdm.write(f"parsim: {what}: {done:,} of {total:,} particles settled ({done / max(total, 1):.0%}, "
                       f"{tqdm.format_interval(clock() - start)} elapsed)", file=sys.stderr)

    return report


@contextmanager
def settled_bar(what: str):
    """A ``report(done, total)`` drawing a tqdm bar (``tqdm.auto``: a widget in a notebook) once the
    first report comes, closed with the block."""
    from tqdm.auto import tqdm as auto_tqdm

    bar = []

    def report(done: int, total: int) -> None:
        if not bar:
            bar.append(auto_tqdm(total=total, desc=what, unit=" particles", file=sys.stderr))
        bar[0].update(done - bar[0].n)

    try:
        yield report
    finally:
        if bar:
            bar[0].close()
