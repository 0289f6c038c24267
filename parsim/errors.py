"""The kinds of failure parsim reports.

- :class:`JobError`: something the user can fix (a bad job file, an impossible
  geometry, a missing file).  The message names the field and the allowed values;
  the command line prints it without a traceback and exits non-zero.
- :class:`NumericalError`: a computation went wrong (NaN, an event limit that
  makes the result meaningless, a broken invariant).  It is raised with the task
  it happened in and is never silently accepted.
- :class:`PlotError`: ``parsim plot`` was asked for a figure that the job's
  outputs cannot give (a missing variable or task file); reported like a JobError.
- :class:`OutputError`: an output file or folder could not be written or read
  (a full disk, a quota, a file removed under a running job); the message names
  the path.
"""

import errno
import traceback
from pathlib import Path


#: Exit status of a job that cannot run as written (checked before anything is computed).
EXIT_USER_ERROR = 2
#: Exit status of a failure while a job runs (a task, a full disk).
EXIT_RUN_FAILED = 1
#: Exit status of ``parsim run --time-limit`` stopping with tasks left: the same command continues the job.
EXIT_UNFINISHED = 3


class ParsimError(Exception):
    """Base of the errors parsim raises on purpose."""


class JobError(ParsimError):
    """A job that cannot run as written; the message says which field and why."""


class NumericalError(ParsimError):
    """A numerical failure inside a task."""


class PlotError(ParsimError):
    """A figure the outputs cannot give; the message names the missing variable, dimension or file."""


class OutputError(ParsimError):
    """A file of the outputs that cannot be written or read; the message names the path."""

    @classmethod
    def from_os_error(cls, error: OSError, path: Path | str, doing: str = "write") -> "OutputError":
        """The one-line report of ``error``, met while doing ``doing`` on ``path``."""
        if error.errno == errno.ENOSPC:
            return cls(f"no space left on {path}")
        if error.errno == errno.EDQUOT:
            return cls(f"disk quota exceeded on {path}")
        return cls(f"cannot {doing} {path}: {error.strerror or error}")


def describe_exception(error: BaseException) -> str:
    """A ParsimError's message alone; any other exception with its traceback (a bug, to be reported)."""
    if isinstance(error, ParsimError):
        return str(error)
    return "".join(traceback.format_exception(error)).rstrip()


def first_sentence(error: BaseException) -> str:
    """The first sentence of ``error``'s message (or its type's name), for a one-line report of a
    library's error whose message goes on for lines (xarray's, netCDF's)."""
    return str(error).strip().split("\n", 1)[0].split(". ", 1)[0] or type(error).__name__


def exit_status(error: Exception) -> int:
    """The command line's exit status for ``error``: a job that cannot run, or a failed run."""
    return EXIT_USER_ERROR if isinstance(error, JobError) else EXIT_RUN_FAILED
