"""The kinds of failure parsim reports.

- :class:`JobError`: something the user can fix (a bad job file, an impossible
  geometry, a missing file).  The message names the field and the allowed values;
  the command line prints it without a traceback and exits non-zero.
- :class:`NumericalError`: a computation went wrong (NaN, an event limit that
  makes the result meaningless, a broken invariant).  It is raised with the task
  it happened in and is never silently accepted.
- :class:`PlotError`: ``parsim plot`` was asked for a figure that the job's
  outputs cannot give (a missing variable or task file); reported like a JobError.
"""


class ParsimError(Exception):
    """Base of the errors parsim raises on purpose."""


class JobError(ParsimError):
    """A job that cannot run as written; the message says which field and why."""


class NumericalError(ParsimError):
    """A numerical failure inside a task."""


class PlotError(ParsimError):
    """A figure the outputs cannot give; the message names the missing variable, dimension or file."""
