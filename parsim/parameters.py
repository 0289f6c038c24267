"""Declared parameters of a solver: type, default, allowed values, units.

A solver lists its parameters as :class:`Parameter` objects.  The same list
validates job files (with messages that name the field and the allowed values),
writes the job file reference, and gives the dataset coordinates their units.
"""

import math
from dataclasses import dataclass
from typing import Any, Callable

from parsim.errors import JobError

REQUIRED = object()
"""Default of a parameter that every job must give."""
LARGEST_QUANTITY = 1e30
"""Upper bound of a length, mass or speed a job gives, in the job's units.  Any physical size in
any unit a job may name (SI prefixes y to Y) lies far below it, and products of a few such numbers
(areas, volumes, a box of N spheres) stay far from the overflow of double precision at 1.8e308."""

_TYPE_NAMES = {bool: "true or false", int: "an integer", float: "a number", str: "a string"}


@dataclass(frozen=True)
class Parameter:
    """One model or run parameter of a solver (a ``default`` of None: may be left unset).

    ``low``/``high`` bound numbers (``*_inclusive`` says whether the bound itself
    is allowed); a number is finite unless ``high`` is ``math.inf`` (a limit that ``inf``
    lifts); ``choices`` lists the allowed strings or numbers.  A parameter
    with ``sweepable=False`` changes the shape of the outputs and must be fixed
    for the whole job.  ``affects_seed=False`` marks a choice of method: tasks
    that differ only in it get the same random stream, hence the same initial
    condition, so methods can be compared task by task.  ``is_file=True`` marks
    the path of an input file (a string; empty: no file): the job records the
    SHA-256 of the file's content, and a resume refuses a changed file.
    ``read_when(params)`` says whether the task of a parameter point reads the parameter,
    for a key of one method only (None: every task reads it); a fixed parameter that no
    task of a job reads is not a coordinate of the job's dataset.
    """

    name: str
    type: type
    default: Any
    units: str
    description: str
    low: float | None = None
    high: float | None = None
    low_inclusive: bool = True
    high_inclusive: bool = True
    choices: tuple | None = None
    sweepable: bool = True
    affects_seed: bool = True
    is_file: bool = False
    read_when: Callable[[dict], bool] | None = None

    @property
    def required(self) -> bool:
        return self.default is REQUIRED

    def is_read(self, params: dict) -> bool:
        """Whether the task of the parameter point ``params`` reads this parameter."""
        return self.read_when is None or self.read_when(params)

    def allowed(self) -> str:
        """The allowed values, as the error messages and the docs state them."""
        if self.choices is not None:
            return "one of " + ", ".join(repr(c) for c in self.choices)
        parts = []
        if self.low is not None:
            parts.append(f"{_fmt(self.low)} {'<=' if self.low_inclusive else '<'} ")
        parts.append(self.name)
        if self.high == math.inf:
            parts.append(" (inf: no limit)")
        elif self.high is not None:
            parts.append(f" {'<=' if self.high_inclusive else '<'} {_fmt(self.high)}")
        text = "".join(parts)
        return f"{_TYPE_NAMES[self.type]}, {text}" if len(parts) > 1 else _TYPE_NAMES[self.type]

    def coerce(self, value: Any, where: str) -> Any:
        """Return ``value`` as this parameter's type, or raise JobError naming ``where``.

        An integer is accepted where a number is meant, never a number where an integer is.
        """
        if self.type is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if not isinstance(value, self.type) or (self.type is not bool and isinstance(value, bool)):
            raise JobError(f"{where} = {shown(value)}: must be {_TYPE_NAMES[self.type]}; allowed: {self.allowed()}")
        if self.type is float and (math.isnan(value) or (math.isinf(value) and self.high != math.inf)):
            raise JobError(f"{where} = {value!r}: must be a finite number; allowed: {self.allowed()}")
        if self.choices is not None and value not in self.choices:
            raise JobError(f"{where} = {shown(value)}: allowed: {self.allowed()}")
        if self.type in (int, float) and not self._in_range(value):
            raise JobError(f"{where} = {value!r} is out of range; allowed: {self.allowed()}")
        return value

    def _in_range(self, value: float) -> bool:
        if self.low is not None and (value < self.low or (value == self.low and not self.low_inclusive)):
            return False
        if self.high is not None and (value > self.high or (value == self.high and not self.high_inclusive)):
            return False
        return True


def shown(value: Any, limit: int = 80) -> str:
    """``repr(value)`` as a one-line message shows it: cut short, with its length, beyond ``limit`` characters."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[:limit - 20]}... ({len(text)} characters)"


def _fmt(number: float) -> str:
    """A bound as messages show it: 50, 0.01, 1e+30 (not 1000000000000000019884624838656)."""
    if isinstance(number, float) and number.is_integer() and abs(number) < 1e16:
        return str(int(number))
    return repr(number)
