"""Where a run's wall time goes: named phases timed on each rank.

A phase is a stretch of a run with a name: reading the job, the warm-up, a task's initial
condition, its steps, its statistics, its task file and row, the dataset.  :func:`phase` times
one and adds its seconds to this process's totals under that name.  A phase timed inside
another counts for the inner one alone (the outer one keeps its own time), so that the totals
add up to the time spent in phases, none twice.  ``parsim run --phase-times FILE`` writes every
rank's totals (:func:`write_phase_times`); ``benchmarks/whole_task.py`` reads them.

Timing costs two clock reads per phase; phases are coarse (a few per task), so it is always on.
"""

import json
import threading
import time
from contextlib import contextmanager
from pathlib import Path

#: Started when this module is first imported: the run's clock.
_STARTED = time.perf_counter()
_totals: dict[str, float] = {}
_counts: dict[str, int] = {}
_adding = threading.Lock()
_open = threading.local()  # per thread: the inner seconds of each phase under way, innermost last


@contextmanager
def phase(name: str, whole: bool = False):
    """Time the block as phase ``name``: its own time, less that of phases timed inside it, or with
    ``whole`` all of it (phases inside it are not timed: the warm-up's small tasks are warm-up)."""
    state = _open.__dict__
    stack = state.setdefault("inner", [])
    if state.get("whole", 0):
        yield
        return
    stack.append(0.0)
    state["whole"] = int(whole)
    start = time.perf_counter()
    try:
        yield
    finally:
        spent = time.perf_counter() - start
        state["whole"] = 0
        inner = stack.pop()
        if stack:
            stack[-1] += spent
        with _adding:
            _totals[name] = _totals.get(name, 0.0) + spent - inner
            _counts[name] = _counts.get(name, 0) + 1


def phase_times() -> dict:
    """This process's totals: ``{"seconds": {phase: s}, "count": {phase: n}, "wall": s}``, ``wall``
    the seconds since the module was imported (the start of the command)."""
    with _adding:
        return {"seconds": dict(_totals), "count": dict(_counts), "wall": time.perf_counter() - _STARTED}


def write_phase_times(path: Path, comm) -> None:
    """Every rank's :func:`phase_times`, gathered over ``comm`` and written by its rank 0 to ``path``
    as JSON: ``{"ranks": [totals of rank 0, rank 1, ...]}`` (collective)."""
    everyone = comm.gather(phase_times(), root=0)
    if comm.Get_rank() == 0:
        Path(path).write_text(json.dumps({"ranks": everyone}, indent=1) + "\n")
