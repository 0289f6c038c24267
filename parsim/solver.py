"""What a solver is to the job runner.

The runner is generic: a solver is one function from (parameters, random
generator, communicator) to a :class:`TaskResult` (statistics and final
configuration), plus the declarations the runner needs to validate jobs and lay
out the dataset.
Every solver in :mod:`parsim.solvers` is a :class:`Solver`; adding one needs no
change to the scheduler, the output or the command line.
"""

import itertools
import re
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from parsim.parameters import Parameter

if TYPE_CHECKING:  # importing mpi4py.MPI initialises MPI, which `parsim validate` does not need
    from mpi4py import MPI

LENGTH_UNITS = "{length}"
TIME_UNITS = "{time}"
MASS_UNITS = "{mass}"
SPEED_UNITS = f"{LENGTH_UNITS} {TIME_UNITS}-1"
"""Units of declarations whose unit the job chooses (keys ``length_unit``, ``time_unit``, ``mass_unit``):
placeholders that :func:`resolve_units` replaces with the job's UDUNITS symbols, e.g. "m s-1"."""


def resolve_units(text: str, units: dict[str, str]) -> str:
    """``text`` with the placeholders of the job's units replaced by ``units`` ({"length": "m", ...})."""
    for quantity, symbol in units.items():
        text = text.replace(f"{{{quantity}}}", symbol)
    return text


def flag_attributes(meanings: tuple[str, ...], dtype: str = "int8") -> dict:
    """CF attributes of a variable that codes ``meanings`` as the integers 0, 1, ... (CF section 3.5).

    A single value is a scalar, as netCDF reads a one-element attribute back: a dataset in memory
    is then identical to the file it is written to."""
    values = np.arange(len(meanings), dtype=dtype)
    return {"flag_values": values if len(values) > 1 else values[0], "flag_meanings": " ".join(meanings)}


def coded_coordinate(long_name: str, meanings: tuple[str, ...]) -> "Coordinate":
    """A coordinate of named values (Cartesian components, species), coded as CF flags: int8
    values whose ``flag_meanings`` name them, since CF coordinates are numbers."""
    return Coordinate(np.arange(len(meanings), dtype="int8"), "1", f"{long_name} (coded: flag_meanings names each "
                      "flag_value)", attrs=flag_attributes(meanings))


def flag_word(value: str) -> str:
    """``value`` as one word of a CF ``flag_meanings``: letters, digits and ``_-.+@``, the other
    characters replaced by ``_`` (a mesh file's path, say)."""
    return re.sub(r"[^A-Za-z0-9_.+@-]", "_", str(value)) or "_"


def flag_words(values) -> tuple[str, ...]:
    """Distinct ``values`` as distinct words of a CF ``flag_meanings``, in their order.

    Each is its :func:`flag_word`.  Values that share one (``a/b`` and ``a_b``) are told apart: a
    value that is that word already keeps it, else the first of them does, and the others take it
    with ``@2``, ``@3``, ... added, the lowest that is no value's own word nor taken before.  The
    words depend on the values and their order alone, so a job's dataset names them alike every run."""
    own = [flag_word(value) for value in values]
    exact = {word for value, word in zip(values, own) if word == str(value)}
    unavailable = set(own)
    words = []
    for value, word in zip(values, own):
        if word in words or (word in exact and word != str(value)):
            word = next(f"{word}@{n}" for n in itertools.count(2) if f"{word}@{n}" not in unavailable)
        words.append(word)
        unavailable.add(word)
    return tuple(words)


def named_values(coordinate) -> list:
    """The values of an xarray coordinate, by name if it is coded as CF flags (a swept string
    parameter, a Cartesian component, a species), else as they are."""
    attrs = coordinate.attrs
    if "flag_meanings" not in attrs:
        return coordinate.values.tolist()
    meaning = dict(zip(np.atleast_1d(attrs["flag_values"]).tolist(), attrs["flag_meanings"].split()))
    return [meaning[value] for value in np.atleast_1d(coordinate.values).tolist()]


def flag_value(attrs: dict, meaning: str) -> int:
    """The integer that a flag-coded variable with attributes ``attrs`` stores for ``meaning``."""
    meanings = attrs["flag_meanings"].split()
    if meaning not in meanings:
        raise KeyError(f"{meaning!r} is not one of the flag meanings {', '.join(meanings)}")
    return int(np.atleast_1d(attrs["flag_values"])[meanings.index(meaning)])


@dataclass(frozen=True)
class Statistic:
    """One per-task output variable of the dataset.

    ``dims`` are the observable dimensions after (sweep..., realization);
    ``dtype`` is the stored type.  ``measured=True`` marks a machine-dependent
    timing, the only kind of variable allowed to differ between two runs of
    the same job.  ``attrs`` adds CF attributes (e.g. flag values).
    """

    name: str
    units: str
    long_name: str
    dims: tuple[str, ...] = ()
    dtype: str = "float64"
    measured: bool = False
    attrs: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Coordinate:
    """Values and CF attributes of an observable dimension; ``attrs`` adds CF attributes (e.g. flags)."""

    values: np.ndarray
    units: str
    long_name: str
    attrs: dict = field(default_factory=dict)


@dataclass
class Configuration:
    """A final configuration, laid out as the HDF5 snapshot of DESIGN.md.

    ``arrays`` maps HDF5 paths (``"spheres/position"``, ``"links"``, ...) to
    arrays; ``attrs`` are extra root attributes (``floor_z``, ...).

    A configuration spread over the ranks of a task's group is one rank's share:
    ``rank_rows`` names its arrays that hold this rank's rows only (the others are
    the same on every rank); its task file joins the ranks' rows
    (:func:`parsim.output.snapshot.write_task_file`).
    """

    arrays: dict[str, np.ndarray]
    box_lower: np.ndarray
    box_upper: np.ndarray
    periodic: np.ndarray
    attrs: dict[str, Any] = field(default_factory=dict)
    rank_rows: tuple[str, ...] = ()


@dataclass
class TaskResult:
    """What one task returns: one value per declared statistic, and its configuration."""

    statistics: dict[str, np.ndarray | float | int]
    configuration: Configuration


@dataclass(frozen=True)
class TableArray:
    """An array of tables of a job file (``[[species]]``): a list of entries, each a table of keys.

    An entry may set each key of ``parameters`` (checked by its :class:`Parameter`); a key
    of ``required`` must be set.  ``parameters`` may hold solver parameters: an entry's value
    then replaces the job's for that entry (a species' own shape, say).  ``limit`` bounds the
    number of entries.  A solver's ``check`` does the checks across entries.
    """

    name: str
    description: str
    parameters: tuple[Parameter, ...]
    required: tuple[str, ...] = ()
    limit: int = 64


@dataclass(frozen=True)
class Solver:
    """A kind of job.

    - ``parameters``: every parameter a job of this kind may set;
    - ``statistics``: the per-task variables of the dataset;
    - ``coordinates(fixed)``: the observable coordinates, from the fixed parameters;
    - ``check(params)``: cross-field checks of one parameter point (raise JobError);
    - ``cost(params)``: relative cost estimate, so the costliest tasks start first;
    - ``memory(params)``: estimate of one task's peak memory in bytes (within a factor of
      about 2), computed from the parameters alone, so that a job whose tasks cannot fit
      in memory is refused before anything is built; ``memory_keys(params)``: the
      parameters that estimate grows with at that point, named when it is refused;
    - ``warm_up_parameters(params)``: a small point that calls the same kernels as
      ``params`` in a fraction of a second; the runner solves it once per rank before any
      task, so that compiling the kernels is not timed as part of a task;
    - ``solve(params, rng, comm)``: run one task.  ``comm`` is the task's group of
      ranks (``parsim run --ranks-per-task``; size 1 = serial); every rank of it calls
      ``solve`` with the same arguments, and the result of its rank 0 is the task's
      (the other ranks may return None, or the same statistics and their shares of a
      configuration spread over the ranks, :attr:`Configuration.rank_rows`);
    - ``tables``: the arrays of tables a job of this kind may hold (``[[species]]``); the
      entries reach ``check``, ``cost``, ``memory`` and ``solve`` as ``params[name]``, a tuple
      of dicts holding the keys each entry sets;
    - ``decomposable``: whether ``solve`` can use a group of several ranks.  A solver
      that cannot always gets a group of one: the runner calls it on the group's rank 0
      only, and the group's other ranks wait for the next task;
    - ``rehearse_spread(params)``: for a solver whose tasks on several ranks call kernels of
      their own, the warm-up of ``--ranks-per-task`` in place of solving ``params`` alone:
      it runs ``params`` on this process as a task spread over several ranks runs, so that
      its kernels are compiled (or loaded) before any task; None: such tasks call the
      kernels of a task on one rank;
    - ``rare_kernels(params)``: compiles, or loads, after the warm-up's solve of ``params``, the
      kernels of paths a small point seldom reaches; None: there are none.
    """

    kind: str
    description: str
    parameters: tuple[Parameter, ...]
    statistics: tuple[Statistic, ...]
    coordinates: Callable[[dict], dict[str, Coordinate]]
    check: Callable[[dict], None]
    cost: Callable[[dict], float]
    memory: Callable[[dict], int]
    memory_keys: Callable[[dict], tuple[str, ...]]
    warm_up_parameters: Callable[[dict], dict]
    solve: Callable[[dict, np.random.Generator, "MPI.Comm"], TaskResult | None]
    decomposable: bool = False
    tables: tuple["TableArray", ...] = ()
    rehearse_spread: Callable[[dict], None] | None = None
    rare_kernels: Callable[[dict], None] | None = None

    def parameter(self, name: str) -> Parameter:
        return next(p for p in self.parameters if p.name == name)

    def table(self, name: str) -> "TableArray":
        return next(t for t in self.tables if t.name == name)
