"""The two kinds of failure parsim reports.

- :class:`JobError`: something the user can fix (a bad job file, an impossible
  geometry, a missing file).  The message names the field and the allowed values;
  the command line prints it without a traceback and exits non-zero.
- :class:`NumericalError`: a computation went wrong (NaN, an event limit that
  makes the result meaningless, a broken invariant).  It is raised with the task
  it happened in and is never silently accepted.
"""


class ParsimError(Exception):
    """Base of the errors parsim raises on purpose."""


class JobError(ParsimError):
    """A job that cannot run as written; the message says which field and why."""


class NumericalError(ParsimError):
    """A numerical failure inside a task."""
