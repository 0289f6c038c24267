"""Dynamic task scheduling over MPI ranks, with every rank computing.

Tasks ``0 .. n_tasks-1`` are handed out in index order (the caller orders them
by decreasing cost), to whichever rank asks first.  No rank is a pure master:
rank 0 computes tasks in its main thread while a small server thread answers
the other ranks' requests.  The solvers' numba kernels release the GIL, so the
server answers within a few milliseconds even while rank 0 computes.  This
keeps every core busy when task costs differ 100-fold, which a static split
cannot.  Tasks go out one at a time while they are long; once the tasks
finished so far show that they take less than :data:`CHUNK_SECONDS`, a request
gets a chunk of consecutive tasks that takes about that long (never more than a
share of what is left, so that the ranks end together), and 10⁵ tasks of a
millisecond need a few thousand requests, not 10⁵.

Groups (:func:`run_group_tasks`): the ranks can also be split into groups of K
consecutive ranks that run each task together.  The group leaders share the
tasks out as above and send each index they take to the rest of their group;
a rank waiting for its leader sleeps between polls, so it frees its core.

Failure: an exception in a task on any rank ends every rank at once through
``MPI_Abort``, after the message of the first failing rank is printed (several
ranks failing together print one message: see
:class:`~parsim.parallel.collective.FailureReport`); no rank waits forever
(with groups, the abort is on the whole communicator, whichever rank of a
group failed).
What the finished tasks wrote is complete on disk (the caller writes each task's
outputs whole), so nothing finished is lost.  On a single rank the
exception is raised as :class:`TaskFailed` instead.
"""

import threading
import time
from typing import Callable

import numpy as np
from mpi4py import MPI

from parsim.errors import ParsimError, describe_exception
from parsim.parallel.collective import POLL_SECONDS, FailureReport, wait_for

REQUEST_TAG = 1
REPLY_TAG = 2
NO_MORE_TASKS = -1
CHUNK_SECONDS = 0.05
"""How long the chunk of short tasks handed out at one request should take to compute."""
IDLE_POLL_SECONDS = 4e-3
"""The longest pause of rank 0's server between two looks for requests (it starts at POLL_SECONDS)."""


class TaskFailed(ParsimError):
    """A task raised; the message says which task, on which rank, and why."""


class TimeLimit:
    """Hands out a task only while it can end before a deadline, leaving ``reserve`` seconds after it.

    A task may start when now + the longest task so far + ``reserve`` <= the deadline, ``seconds``
    after this object was made (the run's start); once refused, every later task is (the clock and
    the longest task only grow).  A task's duration runs from its start to the report of its end;
    a chunk of short tasks (:data:`CHUNK_SECONDS`) counts as one task, named by its first index,
    and starts each of its tasks only while one as long as its longest so far ends within
    :meth:`budget`, so that tasks slower than those before them cannot carry a chunk past the limit.
    Thread-safe: rank 0's two threads share it.
    """

    def __init__(self, seconds: float, reserve: float, clock: Callable[[], float] = time.monotonic):
        self._clock = clock
        self.deadline = clock() + seconds
        self.reserve = reserve
        self.longest = 0.0
        self._started: dict[int, float] = {}
        self._lock = threading.Lock()

    def may_start(self, k: int) -> bool:
        with self._lock:
            now = self._clock()
            if now + self.longest + self.reserve > self.deadline:
                return False
            self._started[k] = now
            return True

    def task_finished(self, k: int) -> None:
        with self._lock:
            self.longest = max(self.longest, self._clock() - self._started.pop(k))

    def budget(self) -> float:
        """Seconds from now within which a task must end: to the deadline, less the reserve."""
        return self.deadline - self.reserve - self._clock()


class _TaskCounter:
    """The next chunk of tasks, shared by rank 0's two threads; none once the time limit refuses one."""

    def __init__(self, n_tasks: int, n_ranks: int, time_limit: TimeLimit | None):
        self._next = 0
        self._n_tasks = n_tasks
        self._n_ranks = n_ranks
        self._time_limit = time_limit
        self._tasks_timed = 0
        self._seconds = 0.0
        self._lock = threading.Lock()

    def take(self) -> tuple[int, int, float | None] | None:
        """(first task, number of tasks, seconds within which they must end or None) of the next chunk, or None."""
        with self._lock:
            remaining = self._n_tasks - self._next
            if remaining <= 0 or (self._time_limit and not self._time_limit.may_start(self._next)):
                self._next = self._n_tasks
                return None
            first, count = self._next, self._chunk(remaining)
            self._next += count
            return first, count, self._time_limit.budget() if self._time_limit else None

    def timed(self, count: int, seconds: float) -> None:
        """Record that ``count`` tasks took ``seconds`` to compute."""
        with self._lock:
            self._tasks_timed += count
            self._seconds += seconds

    def _chunk(self, remaining: int) -> int:
        """As many tasks as take about CHUNK_SECONDS, at the mean time of the tasks so far; 1 before any."""
        if self._seconds <= 0.0:
            return 1
        fits = int(CHUNK_SECONDS * self._tasks_timed / self._seconds)
        return max(1, min(fits, remaining // (2 * self._n_ranks)))


def run_tasks(
    comm: MPI.Comm,
    n_tasks: int,
    work: Callable[[int], None],
    on_finished: Callable[[int, int], None] | None = None,
    describe_failure: Callable[[int, Exception], str] | None = None,
    time_limit: TimeLimit | None = None,
) -> None:
    """Run ``work(k)`` for every ``k`` in ``range(n_tasks)`` on the ranks of ``comm``.

    ``on_finished(k, rank)`` is called on rank 0 (from either of its threads,
    never concurrently) when task ``k`` has finished on ``rank``;
    ``describe_failure(k, error)`` words the message of a failed task (default:
    the task index and the traceback).  With a ``time_limit`` (used on rank 0),
    tasks are handed out only while it allows, so some may be left undone.
    Collective: every rank of ``comm`` calls it and it returns when all tasks
    handed out are done.
    """
    require_thread_multiple(comm)
    describe_failure = describe_failure or _traceback_message
    if comm.Get_size() == 1:
        _run_alone(n_tasks, work, on_finished, describe_failure, time_limit)
        return
    sched = comm.Dup()  # private tags: the scheduler never sees other messages
    report = FailureReport(sched)
    chunks = _Chunks(work, on_finished, describe_failure, time_limit, report, comm.Get_rank(),
                     _TaskCounter(n_tasks, sched.Get_size(), time_limit))
    try:
        if sched.Get_rank() == 0:
            server = threading.Thread(target=_serve, args=(sched, chunks.counter, chunks.finished, report),
                                      daemon=True)
            server.start()
            while (chunk := chunks.counter.take()) is not None:
                chunks.finished(chunks.run(*chunk), 0)
            server.join()
        else:
            done = None
            while True:
                sched.send(done, dest=0, tag=REQUEST_TAG)
                chunk = sched.recv(source=0, tag=REPLY_TAG)
                if chunk is None:
                    break
                done = chunks.run(*chunk)
    finally:
        report.free()
        sched.Free()


def _run_alone(n_tasks, work, on_finished, describe_failure, time_limit) -> None:
    """:func:`run_tasks` on one rank: the tasks in order, while the time limit allows; a failure raises."""
    for k in range(n_tasks):
        if time_limit is not None and not time_limit.may_start(k):
            break
        try:
            work(k)
        except Exception as error:  # noqa: BLE001 - raised with the task's description
            raise TaskFailed(describe_failure(k, error)) from error
        if time_limit is not None:
            time_limit.task_finished(k)
        if on_finished is not None:
            on_finished(k, 0)


class _Chunks:
    """How a rank of :func:`run_tasks` runs a chunk of consecutive tasks, and how rank 0 records one done."""

    def __init__(self, work, on_finished, describe_failure, time_limit, report, rank, counter):
        self.work, self.on_finished, self.describe_failure = work, on_finished, describe_failure
        self.time_limit, self.report, self.rank, self.counter = time_limit, report, rank, counter
        self.finished_lock = threading.Lock()

    def run(self, first: int, count: int, budget: float | None) -> tuple[int, int, float]:
        """Run the chunk's tasks in order; with a ``budget``, start one only while a task as long as the
        chunk's longest so far would end within it (the others are left undone).  Returns (first, tasks
        done, seconds)."""
        start = time.perf_counter()
        longest = 0.0
        for k in range(first, first + count):
            began = time.perf_counter()
            if budget is not None and k > first and began - start + longest > budget:
                return first, k - first, began - start
            try:
                self.work(k)
            except Exception as error:  # noqa: BLE001 - every failure must end the job with its message
                self.report.fail(f"{self.describe_failure(k, error)} (on rank {self.rank})")
            longest = max(longest, time.perf_counter() - began)
        return first, count, time.perf_counter() - start

    def finished(self, chunk: tuple[int, int, float], rank: int) -> None:
        """Rank 0, either thread: the first ``count`` tasks of the chunk have finished on ``rank``."""
        first, count, seconds = chunk
        self.counter.timed(count, seconds)
        if self.time_limit is not None:
            self.time_limit.task_finished(first)
        if self.on_finished is not None:
            with self.finished_lock:
                for k in range(first, first + count):
                    self.on_finished(k, rank)


def require_thread_multiple(comm: MPI.Comm) -> None:
    """Raise a ParsimError naming the fix if ``comm`` has several ranks and MPI gives no MPI_THREAD_MULTIPLE."""
    if MPI.Query_thread() < MPI.THREAD_MULTIPLE and comm.Get_size() > 1:
        raise ParsimError("the MPI library gives no MPI_THREAD_MULTIPLE, which parsim's task server thread needs; "
                          "use an MPI library built with it (MPICH, Open MPI), or enable it "
                          "(Cray MPICH: export MPICH_MAX_THREAD_SAFETY=multiple)")


def run_group_tasks(
    comm: MPI.Comm,
    ranks_per_task: int,
    n_tasks: int,
    work: Callable[[int, MPI.Comm], None],
    on_finished: Callable[[int, int], None] | None = None,
    describe_failure: Callable[[int, Exception], str] | None = None,
    time_limit: TimeLimit | None = None,
) -> None:
    """Run every task on a group of ``ranks_per_task`` consecutive ranks of ``comm``.

    Every rank of the group that takes task ``k`` calls ``work(k, group)``, with
    ``group`` the group's communicator.  The group leaders (group rank 0) share
    the tasks out with :func:`run_tasks`, so ``on_finished(k, leader)`` names
    the leader by its rank among the leaders.  An exception on any rank of a
    group ends the job (``MPI_Abort`` on ``comm``).  With ``ranks_per_task = 1``
    this is :func:`run_tasks` over ``comm``, each rank a group of one
    (``MPI.COMM_SELF``).  ``time_limit`` as in :func:`run_tasks`.  Collective over ``comm``.
    """
    if ranks_per_task == 1:
        run_tasks(comm, n_tasks, lambda k: work(k, MPI.COMM_SELF), on_finished, describe_failure, time_limit)
        return
    describe_failure = describe_failure or _traceback_message
    rank = comm.Get_rank()
    group = comm.Split(color=rank // ranks_per_task, key=rank)
    leading = group.Get_rank() == 0
    leaders = comm.Split(color=0 if leading else MPI.UNDEFINED, key=rank)
    report = FailureReport(comm)

    def run_in_group(k: int) -> None:
        try:
            work(k, group)
        except Exception as error:  # noqa: BLE001 - the other ranks of the group would wait forever
            report.fail(f"{describe_failure(k, error)} (on rank {rank})")

    def lead(k: int) -> None:
        _send_task(group, k)
        run_in_group(k)

    try:
        if leading:
            run_tasks(leaders, n_tasks, lead, on_finished, describe_failure, time_limit)
            _send_task(group, NO_MORE_TASKS)
        else:
            while (k := _receive_task(group)) != NO_MORE_TASKS:
                run_in_group(k)
    finally:
        report.free()
        group.Free()
        if leaders != MPI.COMM_NULL:
            leaders.Free()


def _send_task(group: MPI.Comm, k: int) -> None:
    """The leader's side of :func:`_receive_task`."""
    index = np.array([k], dtype=np.int64)
    group.Ibcast(index, root=0).Wait()


def _receive_task(group: MPI.Comm) -> int:
    """The next task index from the group's leader; polls and sleeps instead of spinning in a blocking call."""
    index = np.empty(1, dtype=np.int64)
    wait_for(group.Ibcast(index, root=0))
    return int(index[0])


def _serve(sched: MPI.Comm, counter: _TaskCounter, finished: Callable[[tuple[int, int, float], int], None],
           report: FailureReport) -> None:
    """Rank 0's server thread: answer each request with the next chunk, until every rank is told to stop."""
    try:
        still_asking = sched.Get_size() - 1
        status = MPI.Status()
        pause = POLL_SECONDS
        while still_asking:
            if not sched.Iprobe(source=MPI.ANY_SOURCE, tag=REQUEST_TAG):
                time.sleep(pause)
                # no request: look less often, up to IDLE_POLL_SECONDS, so that rank 0's own tasks keep the GIL
                pause = min(2.0 * pause, IDLE_POLL_SECONDS)
                continue
            pause = POLL_SECONDS
            done = sched.recv(source=MPI.ANY_SOURCE, tag=REQUEST_TAG, status=status)
            rank = status.Get_source()
            if done is not None:
                finished(done, rank)
            chunk = counter.take()
            sched.send(chunk, dest=rank, tag=REPLY_TAG)
            if chunk is None:
                still_asking -= 1
    except Exception as error:  # noqa: BLE001 - a dead server would leave ranks waiting forever
        report.fail(f"the task server on rank 0 failed: {describe_exception(error)}")


def _traceback_message(k: int, error: Exception) -> str:
    return f"task {k} failed: {describe_exception(error)}"

