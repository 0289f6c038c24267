"""Rank 0's work while the other ranks wait, with its failure seen by every rank.

A phase that only rank 0 does (read and check the job, prepare the output
folder, write the dataset) must never leave the other ranks waiting for a
message that will not come.  :func:`on_root` runs the phase on rank 0 and
hands its result, or its exception, to every rank: a failure there ends every
rank with the same error, and rank 0 alone reports it.  The waiting ranks
sleep between polls instead of spinning in a blocking MPI call, so a long
phase on rank 0 leaves their cores free.
"""

import os
import sys
import threading
import time
from typing import Callable, NoReturn, TypeVar

import numpy as np
from mpi4py import MPI

from parsim.errors import ParsimError, describe_exception, exit_status

POLL_SECONDS = 1e-3
#: Pause between printing a failure and MPI_Abort: without it mpiexec lost the message in 1 of 8 runs.
ABORT_GRACE_SECONDS = 0.5
#: How long a failing rank waits for its claim on the report (see FailureReport) before it reports anyway.
CLAIM_TIMEOUT_SECONDS = 5.0
#: How long a rank other than 0 that failed outside the task scheduler waits for rank 0's abort before its own.
DEFER_TO_ROOT_SECONDS = 2.0
T = TypeVar("T")


class FailedOnRoot(ParsimError):
    """What the other ranks raise when rank 0 failed with an exception that is not a ParsimError."""


def on_root(comm: MPI.Comm, work: Callable[[], T]) -> T:
    """Run ``work()`` on rank 0 of ``comm``; every rank returns its result or raises its exception.

    Collective.  A :class:`ParsimError` of ``work`` is raised on every rank,
    marked by :func:`raised_on_every_rank`; any other exception (a bug, or
    Ctrl-C before the run's signal handler is in place) is raised unchanged on
    rank 0 and as :class:`FailedOnRoot` on the other ranks.
    """
    if comm.Get_size() == 1:
        return _everywhere_if_parsim(work)
    failure = None
    if comm.Get_rank() == 0:
        try:
            outcome = (True, work())
        except ParsimError as error:
            outcome = (False, error)
        except BaseException as error:  # noqa: BLE001 - the other ranks must end too; rank 0 keeps the traceback
            outcome = (False, FailedOnRoot(f"rank 0 failed: {error!r}"))
            failure = error
    else:
        outcome = None
    wait_for(comm.Ibarrier())
    succeeded, value = comm.bcast(outcome, root=0)
    if failure is not None:
        raise failure
    if not succeeded:
        value.on_every_rank = True
        raise value
    return value


def raised_on_every_rank(error: ParsimError) -> bool:
    """Whether every rank raised ``error`` alike (it came through :func:`on_root`), so none waits for another."""
    return getattr(error, "on_every_rank", False)


def _everywhere_if_parsim(work: Callable[[], T]) -> T:
    """``work()`` on a single rank, where every error is everywhere."""
    try:
        return work()
    except ParsimError as error:
        error.on_every_rank = True
        raise


def wait_for(request: MPI.Request) -> None:
    """Complete a non-blocking request, sleeping between tests instead of spinning in ``Wait``."""
    while not request.Test():
        time.sleep(POLL_SECONDS)


def abort_job(comm: MPI.Comm, message: str, status: int = 1) -> NoReturn:
    """Print ``parsim: error: MESSAGE`` from this rank and end every rank of the job with ``status``."""
    try:
        sys.stdout.flush()
        print(f"\nparsim: error: {message}", file=sys.stderr, flush=True)
        time.sleep(ABORT_GRACE_SECONDS)  # let mpiexec forward the message before MPI_Abort ends the ranks
    finally:
        end_every_rank(comm, status)  # even if the message could not be printed (a closed pipe)


def end_every_rank(comm: MPI.Comm, status: int) -> NoReturn:
    """MPI_Abort on ``comm``, and this process's end even where MPI_Abort returns (MPICH's may, when
    the launcher is ending the job already): nothing after an abort may run on."""
    try:
        comm.Abort(status)
    finally:
        os._exit(status)


def abort_if_alone(comm: MPI.Comm, error: Exception) -> None:
    """End every rank when ``error`` was raised on this rank alone: the others would wait for it
    for ever.  Returns, for the caller to report ``error`` once, when no other rank waits: on a
    world of one rank, and for a ParsimError every rank raised alike (through :func:`on_root`).

    Several ranks often fail alike at once (every rank's next write on a full disk, a bug on
    the path every rank takes): a rank other than 0 waits :data:`DEFER_TO_ROOT_SECONDS` first,
    so that rank 0's report and abort, if it failed too, are the only ones.
    """
    if comm.Get_size() == 1 or (isinstance(error, ParsimError) and raised_on_every_rank(error)):
        return
    if comm.Get_rank() > 0:
        time.sleep(DEFER_TO_ROOT_SECONDS)
    if isinstance(error, ParsimError):
        abort_job(comm, f"{error} (on rank {comm.Get_rank()})", exit_status(error))
    else:
        abort_job(comm, f"rank {comm.Get_rank()} failed: {describe_exception(error)}", exit_status(error))


class FailureReport:
    """The first failure of any rank ends the job, and only its message is printed.

    Several ranks often fail at once (a full disk fails every rank's next
    write).  Each failing rank claims the report by an atomic compare-and-swap
    on a word that rank 0 holds: the first claim wins, its rank prints the
    message and aborts the job; the others stay silent until the abort ends
    them.  A claim without an answer after :data:`CLAIM_TIMEOUT_SECONDS` (rank
    0 itself stuck) reports anyway, so that no failure goes unsaid.
    Collective to create, on every rank of ``comm``.
    """

    def __init__(self, comm: MPI.Comm):
        self._comm = comm
        self._window = MPI.Win.Allocate(8 if comm.Get_rank() == 0 else 0, 8, comm=comm)
        if comm.Get_rank() == 0:
            self._window.Lock(0, MPI.LOCK_EXCLUSIVE)
            np.frombuffer(self._window.tomemory(), dtype=np.int64)[0] = 0
            self._window.Unlock(0)
        comm.Barrier()
        self._failing = threading.Lock()  # rank 0's two threads may fail together: one claims

    def fail(self, message: str, status: int = 1) -> NoReturn:
        """Report ``message`` and end every rank with ``status``, unless another rank reported first."""
        if self._failing.acquire(blocking=False):
            answer = threading.Event()
            first = []
            threading.Thread(target=self._claim, args=(answer, first), daemon=True).start()
            if not answer.wait(CLAIM_TIMEOUT_SECONDS) or first[0]:
                abort_job(self._comm, message, status)
        time.sleep(CLAIM_TIMEOUT_SECONDS)  # the reporting rank's abort ends this one
        end_every_rank(self._comm, status)

    def free(self) -> None:
        self._window.Free()

    def _claim(self, answer: threading.Event, first: list) -> None:
        mine = np.array([self._comm.Get_rank() + 1], dtype=np.int64)
        unclaimed = np.zeros(1, dtype=np.int64)
        before = np.empty(1, dtype=np.int64)
        self._window.Lock(0, MPI.LOCK_SHARED)
        self._window.Compare_and_swap(mine, unclaimed, before, 0, 0)
        self._window.Unlock(0)
        first.append(bool(before[0] == 0))
        answer.set()
