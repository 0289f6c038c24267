"""parsim: piles and clusters of particles, simulated exactly and run as MPI ensembles.

The Python interface (:mod:`parsim.api`, docs/python-api.md): :class:`Job` (``Job.from_dict``),
:func:`load_job`, :func:`run`, :func:`deposit`, :func:`aggregate`, :class:`TaskOutcome`, and
:func:`decoded` (a dataset's flag-coded coordinates by name), :func:`fractal_law` (D_f and k_f of an
aggregation dataset from N = k_f (R_g / a)^D_f).
They are imported on first use, so that ``import parsim`` (which the command line does for
its version) loads neither numpy nor MPI.
"""

import importlib
from typing import TYPE_CHECKING

from parsim.version import __version__

_API = {"Job": "parsim.job", "load_job": "parsim.api", "run": "parsim.api", "deposit": "parsim.api",
        "aggregate": "parsim.api", "TaskOutcome": "parsim.api", "decoded": "parsim.output.dataset",
        "fractal_law": "parsim.aggregation.fractal_law"}
"""Name of the Python interface -> the module that defines it."""

__all__ = ["__version__", *_API]

if TYPE_CHECKING:  # for editors and type checkers; at run time __getattr__ imports them
    from parsim.aggregation.fractal_law import fractal_law
    from parsim.api import TaskOutcome, aggregate, deposit, load_job, run
    from parsim.job import Job
    from parsim.output.dataset import decoded


def __getattr__(name: str):
    """Import a name of the Python interface when it is first used (PEP 562)."""
    if name not in _API:
        raise AttributeError(f"module 'parsim' has no attribute {name!r}")
    value = getattr(importlib.import_module(_API[name]), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_API})
