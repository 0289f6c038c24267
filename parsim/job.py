"""Job files: reading, validation, and the tasks a job is made of.

A job file is TOML::

    name = "quickstart"            # names the dataset file
    kind = "aggregation"           # which solver (see parsim.solvers)
    seed = 2024                    # job seed; every task's stream derives from it
    realizations = 4               # realisations per parameter point
    output = "output/quickstart"   # folder, relative to the working directory
    configurations = "all"         # tasks that keep their final configuration: "all", "first", "none"
    length_unit = "m"              # UDUNITS units of the job's numbers (defaults m, s, kg)

    [parameters]                   # fixed parameters of the solver
    radius = 0.2

    [sweep]                        # lists; their Cartesian product is the grid
    n_spheres = [100, 400]

Every key is checked against the solver's declared parameters before anything
is computed; errors name the key and the allowed values.
"""

import functools
import hashlib
import json
import math
import os
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from parsim.errors import JobError
from parsim.machine import check_memory
from parsim.parameters import Parameter, shown
from parsim.progress import preparing
from parsim.solver import Solver, TableArray

SI_PREFIXES = ("Y", "Z", "E", "P", "T", "G", "M", "k", "h", "da", "d", "c", "m", "u", "n", "p", "f", "a", "z", "y")
"""The SI prefixes as UDUNITS spells them (u: micro)."""


@dataclass(frozen=True)
class UnitKey:
    """A top-level key naming the unit of one quantity, as a UDUNITS symbol.

    Allowed: ``base`` with an SI prefix or none, or one of ``others`` (symbols taken without
    prefix).  This small grammar stands in for the UDUNITS library, which parsim does not need
    at run time: every symbol it accepts is a UDUNITS unit of the quantity.  The unit only labels
    the job's numbers (the dataset's ``units``); it changes no number and no random stream.
    """

    key: str
    quantity: str
    default: str
    base: str
    others: tuple[str, ...] = ()

    def accepts(self, symbol: Any) -> bool:
        return isinstance(symbol, str) and (symbol in self.others or
                                            any(symbol == prefix + self.base for prefix in ("", *SI_PREFIXES)))

    def allowed(self) -> str:
        examples = ", ".join(repr(symbol) for symbol in dict.fromkeys((self.default, "m" + self.base, "u" + self.base)))
        others = f", or one of {', '.join(repr(o) for o in self.others)}" if self.others else ""
        return (f"a UDUNITS {self.quantity} unit: {self.base!r} with an SI prefix ({' '.join(SI_PREFIXES)}) "
                f"or none, e.g. {examples}{others}")


UNIT_KEYS = (
    UnitKey("length_unit", "length", "m", base="m"),
    UnitKey("time_unit", "time", "s", base="s", others=("min", "h", "d")),
    UnitKey("mass_unit", "mass", "kg", base="g"),
)


def default_units() -> dict[str, str]:
    return {unit.quantity: unit.default for unit in UNIT_KEYS}


TOP_LEVEL_KEYS = ("name", "kind", "seed", "realizations", "output", "configurations",
                  *(unit.key for unit in UNIT_KEYS), "parameters", "sweep")
"""The keys of every job; a solver adds its arrays of tables (:attr:`parsim.solver.Solver.tables`)."""
REQUIRED_TOP_LEVEL = ("name", "kind", "seed", "realizations")
MAX_FILE_NAME_BYTES, MAX_PATH_BYTES = 255, 4096
"""The longest file name and path of Linux and macOS file systems."""
MAX_NAME_BYTES = 200
"""The longest job name, in UTF-8 bytes: NAME.partial.nc stays within the 255 bytes of a file name."""
TOML_INTEGERS = (-2**63, 2**63 - 1)
"""The integers of a TOML file (64-bit); tomllib returns larger ones too."""
MAX_SEED = TOML_INTEGERS[1]
SECONDS_PER_POINT_CHECK = 1e-4
"""Checking one parameter point of a sweep (0.09 ms measured for a deposition point): 10^6 points take minutes."""
MAX_TASKS = 1_000_000
"""Tasks a job may have: the job lists them all, with their keys, before it starts."""
CONFIGURATIONS = ("all", "first", "none")
"""Values of the key ``configurations``: which tasks write their final configuration to a task file
(every task; realisation 0 of every point; none).  The statistics of every task are kept whatever it says."""
DATASET_COPIES = 3
"""Copies of every task's statistics that rank 0 holds while it writes the dataset."""
KEY_BYTES = 16
"""Length of a point's key (:meth:`Job.point_key`): the first 16 bytes of a SHA-256."""


@dataclass(frozen=True)
class Task:
    """One (parameter point, realisation) of a job.

    ``point`` is the flat index in the job's sweep grid as written now (row-major, last key
    fastest): where the task sits in the dataset.  ``key`` names the point by its values
    (:meth:`Job.point_key`): the task's row, file and random stream follow the key, so they
    stay the task's own when the sweep grows, shrinks or is written in another order.
    """

    point: int
    realization: int
    key: bytes = field(repr=False)

    @property
    def label(self) -> str:
        """The task's name in the output folder (its task file ``tasks/LABEL.h5``): the first 16 hex
        digits of its point's key and its realisation, e.g. ``3fa9c01b2d4e5f60_r0003``."""
        return f"{self.key.hex()[:16]}_r{self.realization:04d}"


@dataclass(frozen=True)
class Job:
    """A validated job: everything the runner needs, nothing computed yet."""

    name: str
    kind: str
    seed: int
    realizations: int
    output: Path
    fixed: dict[str, Any]  # every non-swept parameter, defaults filled in
    sweep: dict[str, list]  # swept parameter -> values, in file order
    text: str  # the job file as written
    input_hashes: dict[str, dict[str, str]]  # file parameter -> {path as written: SHA-256 of the content}
    units: dict[str, str] = field(default_factory=default_units)  # quantity -> UDUNITS symbol, e.g. "length": "m"
    tables: dict[str, tuple[dict, ...]] = field(default_factory=dict)  # [[name]] -> its entries, keys as written
    configurations: str = "all"  # which tasks write a task file: one of CONFIGURATIONS
    solver: Solver | None = field(default=None, compare=False, repr=False)  # the solver of ``kind``

    @property
    def sweep_shape(self) -> tuple[int, ...]:
        return tuple(len(values) for values in self.sweep.values())

    @property
    def n_points(self) -> int:
        return int(np.prod(self.sweep_shape, dtype=np.int64))

    def point_parameters(self, point: int) -> dict[str, Any]:
        """All parameters of sweep point ``point`` (row-major over the sweep, last key fastest),
        with the job's arrays of tables (``params["species"]``: a tuple of dicts)."""
        index = np.unravel_index(point, self.sweep_shape) if self.sweep else ()
        swept = {name: values[i] for (name, values), i in zip(self.sweep.items(), index)}
        return {**self.constants, **swept}

    @property
    def constants(self) -> dict[str, Any]:
        """What every point shares: the fixed parameters and the arrays of tables."""
        return {**self.fixed, **self.tables}

    def tasks(self) -> list[Task]:
        """Every task, point by point (row-major over the sweep), realisations fastest."""
        return [Task(point, r, key) for point, key in enumerate(self._point_keys) for r in range(self.realizations)]

    def keeps_configuration(self, task: Task) -> bool:
        """Whether ``task`` writes its final configuration to a task file (key ``configurations``)."""
        return self.configurations == "all" or (self.configurations == "first" and task.realization == 0)

    def point_key(self, point: int) -> bytes:
        """The key of sweep point ``point``: a digest of the canonical encoding of its parameters
        (:meth:`_canonical`), so that equal values give equal keys in any job."""
        return self._point_keys[point]

    def seed_sequence(self, task: Task) -> np.random.SeedSequence:
        """The task's seed: the job seed, its point's values and its realisation; never its place or rank.

        ``spawn_key`` is four 32-bit words of a digest of the point's parameters that affect the
        seed (:meth:`_canonical`), then the realisation index.  Tasks that differ only in the
        method (parameters with ``affects_seed=False``) share their initial condition; a point
        draws the same numbers whatever else the sweep holds and in whatever order it is written.
        """
        words = self._seed_words.get(task.point)
        if words is None:  # once per point, not per task: a point may have 10⁵ realisations
            digest = _digest(self._canonical(task.point, seeded_only=True))
            words = self._seed_words[task.point] = tuple(int(word) for word in np.frombuffer(digest[:16], "<u4"))
        return np.random.SeedSequence(self.seed, spawn_key=(*words, task.realization))

    @functools.cached_property
    def _seed_words(self) -> dict[int, tuple[int, ...]]:
        """The four words of each point's stream digest, filled in as :meth:`seed_sequence` meets the points."""
        return {}

    @functools.cached_property
    def _point_keys(self) -> list[bytes]:
        return [_digest(self._canonical(point, seeded_only=False))[:KEY_BYTES] for point in range(self.n_points)]

    def _canonical(self, point: int, seeded_only: bool) -> bytes:
        """The point's parameters as canonical JSON: names sorted; a parameter at its default left out
        (so a key added in a later version keeps every stream); an input file by its SHA-256, not its
        path; ``seeded_only`` leaves out the choices of method (``affects_seed=False``)."""
        params = self.point_parameters(point)
        values = {}
        for parameter in self.solver.parameters:
            value = params[parameter.name]
            if (seeded_only and not parameter.affects_seed) or _is_default(parameter, value):
                continue
            values[parameter.name] = self._content(parameter.name, value) if parameter.is_file else value
        for table in (table for table in self.solver.tables if table.name in self.tables):
            declared = {p.name: p for p in table.parameters}
            values[f"[[{table.name}]]"] = [
                {key: self._content(f"[[{table.name}]] {key}", value) if declared[key].is_file else value
                 for key, value in entry.items() if declared[key].affects_seed or not seeded_only}
                for entry in self.table_entries(table.name)]
        return json.dumps(values, sort_keys=True, separators=(",", ":")).encode()

    def table_entries(self, name: str) -> list[dict]:
        """The entries of ``[[name]]`` as they count for the job's identity: a key of the table alone
        (not a solver parameter an entry overrides) given at its default is left out."""
        table = self.solver.table(name)
        own = {p.name: p for p in table.parameters if p.name not in {q.name for q in self.solver.parameters}}
        return [{key: value for key, value in entry.items() if key not in own or not _is_default(own[key], value)}
                for entry in self.tables[name]]

    def _content(self, key: str, path: str) -> str:
        """An input file as the seed sees it: its content's SHA-256 (no file: the empty path)."""
        return f"sha256:{self.input_hashes[key][path]}" if path else ""

    @property
    def input_paths(self) -> dict[str, list[str]]:
        """The input files the job names, by key of :attr:`input_hashes` (:func:`named_input_files`)."""
        return named_input_files(self.solver, self.fixed, self.sweep, self.tables)

    @property
    def input_attributes(self) -> dict[str, str]:
        """The input files and their hashes as attributes of the dataset and task files.

        ``input_files``: one line ``path sha256`` per file the job names (empty if none).
        """
        lines = [f"{path} {digest}" for files in self.input_hashes.values() for path, digest in files.items()]
        return {"input_files": "\n".join(lines)}

    @property
    def table_attributes(self) -> dict[str, str]:
        """The arrays of tables as attributes of the dataset and task files: JSON, one per array."""
        return {name: json.dumps(entries) for name, entries in self.tables.items()}

    @property
    def unit_attributes(self) -> dict[str, str]:
        """The job's units as attributes of the dataset and task files (``length_unit``, ``time_unit``, ...)."""
        return {unit.key: self.units[unit.quantity] for unit in UNIT_KEYS}

    def describe_point(self, point: int) -> str:
        params = self.point_parameters(point)
        return ", ".join(f"{name}={params[name]!r}" for name in self.sweep) or "the single point"

    @classmethod
    def from_dict(cls, document: Mapping[str, Any], *, solvers: dict[str, Solver] | None = None,
                  source: str = "Job.from_dict", output: str | Path | None = None) -> "Job":
        """A job from a dict laid out as a job file reads: top-level keys, ``"parameters"``, ``"sweep"``.

        The dict is written as TOML and read back by :func:`parse_job`, so that it is validated
        by the very code that validates job files, with the same messages (``source`` in front,
        where a file has its path), and so that :attr:`text` is a job file: the output folder's
        ``job.toml`` can be run, resumed and read by ``parsim run`` and ``parsim info`` as any other.
        Python values a notebook holds are accepted as the TOML values they stand for: numpy
        numbers, tuples and arrays (lists), paths (strings).  ``solvers`` defaults to
        :data:`parsim.solvers.SOLVERS`; ``output`` overrides the folder, as in :func:`load_job`.
        """
        if solvers is None:
            from parsim.solvers import SOLVERS  # here: the solvers import numba, which a Job alone does not need

            solvers = SOLVERS
        return parse_job(_toml_document(document, source), solvers, source=source, output=output)


def load_job(path: str | Path, solvers: dict[str, Solver], output: str | Path | None = None) -> Job:
    """Read and validate a job file; ``output`` overrides the file's output folder."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise JobError(f"cannot read job file {path}: {error.strerror}") from None
    except UnicodeDecodeError:
        raise JobError(f"{path}: not a TOML job file (not UTF-8 text)") from None
    return parse_job(text, solvers, source=str(path), output=output)


def parse_job(text: str, solvers: dict[str, Solver], source: str = "<job>", output=None,
              verify: bool = True) -> Job:
    """Read and validate the job file ``text``.  ``verify=False`` reads the keys alone: no input
    file is read and no point checked (for the copy of an earlier job, whose files may be gone)."""
    def fail(message: str):
        raise JobError(f"{source}: {message}")

    document = _toml(text, fail)

    _check_integers(document, "", fail)

    for key in REQUIRED_TOP_LEVEL:
        if key not in document:
            fail(f"missing key {key!r}")

    name = _top(document, "name", str, fail)
    _check_name(name, fail)
    kind = _top(document, "kind", str, fail)
    if kind not in solvers:
        fail(f"kind = {shown(kind)}: allowed: {', '.join(repr(k) for k in solvers)}")
    solver = solvers[kind]
    allowed = (*TOP_LEVEL_KEYS, *(table.name for table in solver.tables))
    unknown = [key for key in document if key not in allowed]
    if unknown:
        fail(f"unknown key {unknown[0]!r}; allowed top-level keys for kind {kind!r}: {', '.join(allowed)}")
    seed = _top(document, "seed", int, fail)
    if not 0 <= seed <= MAX_SEED:
        fail(f"seed = {seed}: allowed: an integer, 0 <= seed <= {MAX_SEED}")
    realizations = _top(document, "realizations", int, fail)
    if realizations < 1:
        fail(f"realizations = {realizations}: allowed: an integer >= 1")
    out = output if output is not None else document.get("output", f"output/{name}")
    _check_output_path(out, fail)

    units = {unit.quantity: _unit(document, unit, fail) for unit in UNIT_KEYS}
    fixed, sweep = _parameters(document, solver, source, fail)
    tables = {table.name: _table_entries(document, table, source, fail) for table in solver.tables
              if table.name in document}
    n_points = math.prod(len(values) for values in sweep.values())
    if n_points * realizations > MAX_TASKS:
        fail(f"{n_points} parameter points x {realizations} realizations = {n_points * realizations} tasks; "
             f"allowed: at most {MAX_TASKS} tasks; lower realizations or the [sweep]")
    configurations = document.get("configurations", "all")
    if configurations not in CONFIGURATIONS:
        fail(f"configurations = {shown(configurations)}: allowed: {', '.join(repr(c) for c in CONFIGURATIONS)}")
    hashes = _input_hashes(solver, fixed, sweep, tables, fail) if verify else {}
    job = Job(name=name, kind=kind, seed=seed, realizations=realizations, output=Path(out), fixed=fixed,
              sweep=sweep, text=text, input_hashes=hashes, units=units, tables=tables,
              configurations=configurations, solver=solver)
    if not verify:
        return job
    with preparing(f"checking {job.n_points} parameter points", SECONDS_PER_POINT_CHECK * job.n_points):
        for point in range(job.n_points):
            params = job.point_parameters(point)
            try:
                _check_memory(solver, params)  # before the solver's checks, which may build the particles
                solver.check(params)
            except JobError as error:
                fail(f"sweep point {job.describe_point(point)}: {error}" if sweep else str(error))
    _check_distinct_points(job, fail)
    try:
        _check_dataset_memory(job)
    except JobError as error:
        fail(str(error))
    return job


def _toml(text: str, fail) -> dict:
    """The TOML document ``text``; an integer too long for Python to convert is named by its key."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        fail(f"not valid TOML: {error}")
    except ValueError:  # Python converts integers of at most sys.get_int_max_str_digits() (4300) digits
        long = _LONG_INTEGER.search(text)
        line = text.count("\n", 0, long.start()) + 1 if long else 0
        key = re.match(r"\s*([^=\s]+)\s*=", text.splitlines()[line - 1]) if long else None
        where = f"line {line}: {key.group(1) if key else 'a value'} = an integer of {len(long.group())} digits" \
            if long else "an integer of thousands of digits"
        fail(f"{where}; allowed: integers of at most 64 bits ({TOML_INTEGERS[0]} to {TOML_INTEGERS[1]})")


_LONG_INTEGER = re.compile(r"\d{4000,}")


def _check_name(name: str, fail) -> None:
    """The job's name names its dataset file, NAME.nc and NAME.partial.nc: refuse what no file name can be."""
    if (not name or "/" in name or "\\" in name or name.startswith(".")
            or any(ord(c) < 32 or ord(c) == 127 for c in name) or len(name.encode()) > MAX_NAME_BYTES):
        fail(f"name = {shown(name)}: allowed: a file name of 1 to {MAX_NAME_BYTES} bytes (UTF-8) without slashes, "
             "control characters (NUL, newline, tab, ...) or a leading dot")


def _check_output_path(out: Any, fail) -> None:
    """The output folder must be a path this system can hold: no NUL, names of at most 255 bytes."""
    if (not isinstance(out, (str, Path)) or not str(out) or "\0" in str(out)
            or len(os.fsencode(out)) > MAX_PATH_BYTES or any(len(os.fsencode(part)) > MAX_FILE_NAME_BYTES
                                                             for part in Path(out).parts)):
        fail(f"output = {shown(out)}: allowed: a folder path, a non-empty string without NUL characters, of at most "
             f"{MAX_PATH_BYTES} bytes with names of at most {MAX_FILE_NAME_BYTES} bytes")


def _check_distinct_points(job: Job, fail) -> None:
    """Refuse two sweep points with one key: input files of the same content under two names."""
    seen = {}
    for point in range(job.n_points):
        key = job.point_key(point)
        if key in seen:
            fail(f"sweep points {job.describe_point(seen[key])} and {job.describe_point(point)} are one point: "
                 "their input files have the same content; give each file once")
        seen[key] = point


def _check_integers(value: Any, where: str, fail) -> None:
    """Refuse an integer beyond the 64 bits of TOML anywhere in ``value`` (tomllib reads any size)."""
    if isinstance(value, dict):
        for key, item in value.items():
            _check_integers(item, f"{where}.{key}" if where else key, fail)
    elif isinstance(value, list):
        for i, item in enumerate(value):
            _check_integers(item, f"{where}[{i}]", fail)
    elif isinstance(value, int) and not TOML_INTEGERS[0] <= value <= TOML_INTEGERS[1]:
        fail(f"{where}: an integer beyond the 64 bits of TOML integers ({TOML_INTEGERS[0]} to {TOML_INTEGERS[1]})")


def _parameters(document: dict, solver: Solver, source: str, fail) -> tuple[dict[str, Any], dict[str, list]]:
    """The fixed parameters (defaults filled in) and the swept ones of a job document, checked."""
    fixed_table = _table(document, "parameters", fail)
    sweep_table = _table(document, "sweep", fail)
    declared = {p.name: p for p in solver.parameters}
    for table_name, table in (("parameters", fixed_table), ("sweep", sweep_table)):
        for key in table:
            if key not in declared:
                fail(f"[{table_name}] unknown key {key!r}; allowed keys for kind {solver.kind!r}: "
                     f"{', '.join(declared)}")
    both = set(fixed_table) & set(sweep_table)
    if both:
        fail(f"{sorted(both)[0]!r} is both in [parameters] and in [sweep]; give it in one of them")

    sweep = {}
    for key, values in sweep_table.items():
        parameter = declared[key]
        if not parameter.sweepable:
            fail(f"[sweep] {key!r} cannot be swept (it changes the shape of the outputs); set it in [parameters]")
        if not isinstance(values, list) or not values:
            fail(f"[sweep] {key} = {shown(values)}: must be a non-empty list of values")
        coerced = [parameter.coerce(v, f"{source}: [sweep] {key}[{i}]") for i, v in enumerate(values)]
        if len(set(coerced)) != len(coerced):
            fail(f"[sweep] {key} = {shown(values)}: values must be distinct")
        sweep[key] = coerced

    fixed = {}
    for parameter in solver.parameters:
        if parameter.name in sweep:
            continue
        if parameter.name in fixed_table:
            fixed[parameter.name] = parameter.coerce(fixed_table[parameter.name], f"{source}: [parameters] {parameter.name}")
        elif parameter.required:
            fail(f"parameter {parameter.name!r} is required ({parameter.description}); "
                 f"give it in [parameters] or [sweep]; allowed: {parameter.allowed()}")
        else:
            fixed[parameter.name] = parameter.default
    return fixed, sweep


def _table_entries(document: dict, table: TableArray, source: str, fail) -> tuple[dict, ...]:
    """The entries of the array of tables ``[[table]]``, each key checked; keys as written, no defaults."""
    entries = document[table.name]
    if not isinstance(entries, list) or not entries or not all(isinstance(e, dict) for e in entries):
        fail(f"{table.name} must be an array of tables, each entry starting with a line [[{table.name}]]")
    if len(entries) > table.limit:
        fail(f"{len(entries)} [[{table.name}]] entries; allowed: at most {table.limit}")
    declared = {p.name: p for p in table.parameters}
    checked = []
    for i, entry in enumerate(entries):
        where = f"[[{table.name}]] entry {i + 1}"
        for key in entry:
            if key not in declared:
                fail(f"{where}: unknown key {key!r}; allowed keys: {', '.join(declared)}")
        for key in table.required:
            if key not in entry:
                fail(f"{where}: missing key {key!r} ({declared[key].description}); allowed: {declared[key].allowed()}")
        checked.append({key: declared[key].coerce(value, f"{source}: {where}: {key}") for key, value in entry.items()})
    return tuple(checked)


def _input_hashes(solver: Solver, fixed: dict, sweep: dict, tables: dict, fail) -> dict[str, dict[str, str]]:
    """The SHA-256 of every file the job names, by key of :func:`named_input_files` and path."""
    return {key: {path: _sha256(key, path, fail) for path in paths}
            for key, paths in named_input_files(solver, fixed, sweep, tables).items()}


def named_input_files(solver: Solver, fixed: dict, sweep: dict, tables: dict) -> dict[str, list[str]]:
    """The input files a job names, by parameter (``[[table]] key`` for a file named in an array of
    tables), each path once, as written; keys naming none (only empty paths) are left out."""
    named = {}
    for parameter in (p for p in solver.parameters if p.is_file):
        named[parameter.name] = sweep[parameter.name] if parameter.name in sweep else [fixed[parameter.name]]
    for table in solver.tables:
        for parameter in (p for p in table.parameters if p.is_file):
            named[f"[[{table.name}]] {parameter.name}"] = [entry.get(parameter.name, "")
                                                           for entry in tables.get(table.name, ())]
    paths = {key: [path for path in dict.fromkeys(values) if path] for key, values in named.items()}
    return {key: listed for key, listed in paths.items() if listed}


def _sha256(key: str, path: str, fail) -> str:
    if "\0" in path:
        fail(f"{key} = {shown(path)}: allowed: a file path, without NUL characters")
    try:
        if not Path(path).is_file():
            fail(f"{key} = {shown(path)}: no such file")
        with open(path, "rb") as file:
            return hashlib.file_digest(file, "sha256").hexdigest()
    except OSError as error:
        fail(f"{key} = {shown(path)}: cannot read the file ({error.strerror})")


def _check_dataset_memory(job: Job) -> None:
    """Refuse a job whose dataset, assembled on rank 0 from the rows of every task, needs more memory than
    this machine has: ``DATASET_COPIES`` copies of every task's row (the rows read, the variables, the write)."""
    constants = job.constants
    observable = job.solver.coordinates(constants)
    row = sum(np.dtype(s.dtype).itemsize * math.prod(len(observable[d].values) for d in s.dims)
              for s in job.solver.statistics)
    tasks = job.n_points * job.realizations
    sizes = [f"{p.name}={constants[p.name]!r}" for p in job.solver.parameters if p.type is int and not p.sweepable]
    check_memory(DATASET_COPIES * row * tasks, "the dataset",
                 f"{tasks} tasks x {row} bytes per task's statistics, with {', '.join(sizes)}")


def _check_memory(solver: Solver, params: dict) -> None:
    """Refuse a point whose task would need more memory than this machine has."""
    keys = ", ".join(f"{key}={params[key]!r}" for key in solver.memory_keys(params))
    check_memory(solver.memory(params), "one task", keys)


def _top(document: dict, key: str, expected: type, fail) -> Any:
    value = document[key]
    if not isinstance(value, expected) or isinstance(value, bool):
        fail(f"{key} = {shown(value)}: must be {'an integer' if expected is int else 'a string'}")
    return value


def _unit(document: dict, unit: UnitKey, fail) -> str:
    symbol = document.get(unit.key, unit.default)
    if not unit.accepts(symbol):
        fail(f"{unit.key} = {shown(symbol)}: allowed: {unit.allowed()}")
    return symbol


def _table(document: dict, key: str, fail) -> dict:
    table = document.get(key, {})
    if not isinstance(table, dict):
        fail(f"{key} must be a table [{key}], got {table!r}")
    return table


_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def _toml_document(document: Mapping[str, Any], source: str) -> str:
    """``document`` as TOML text: its plain keys first, then each table as a ``[table]`` section.

    TOML wants every plain key of the root before the first section; tables nested deeper
    are inline tables.  A value TOML cannot hold is a :class:`JobError` naming its key.
    """
    if not isinstance(document, Mapping):
        raise JobError(f"{source}: a job must be a dict of its keys (name, kind, seed, ...), got {document!r}")
    plain = [f"{_toml_key(key, '', source)} = {_toml_value(value, key, source)}\n"
             for key, value in document.items() if not isinstance(value, Mapping) and not _is_table_array(value)]
    tables = [_toml_section(f"[{_toml_key(key, '', source)}]", table, key, source, f"[{key}]")
              for key, table in document.items() if isinstance(table, Mapping)]
    arrays = [_toml_section(f"[[{_toml_key(key, '', source)}]]", entry, f"[[{key}]] entry {i + 1}", source,
                            f"[[{key}]] entry {i + 1}")
              for key, entries in document.items() if _is_table_array(entries) for i, entry in enumerate(entries)]
    return "".join(plain + tables + arrays)


def _is_table_array(value: Any) -> bool:
    return isinstance(value, (list, tuple)) and bool(value) and all(isinstance(item, Mapping) for item in value)


def _toml_section(header: str, table: Mapping, name_of_table: str, source: str, where: str) -> str:
    """One section; ``name_of_table`` names the table in a key error, ``where`` in a value error."""
    return f"\n{header}\n" + "".join(f"{_toml_key(name, name_of_table, source)} = "
                                     f"{_toml_value(value, f'{where} {name}', source)}\n"
                                     for name, value in table.items())


def _toml_key(key: Any, table: str, source: str) -> str:
    if not isinstance(key, str):
        raise JobError(f"{source}: key {key!r}{f' in {table}' if table else ''}: keys must be strings")
    return key if _BARE_KEY.fullmatch(key) else _toml_string(key)


def _toml_value(value: Any, where: str, source: str) -> str:
    """One TOML value; ``where`` (``[parameters] radius``) names it in an error."""
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return _toml_integer(int(value))
    if isinstance(value, (float, np.floating)):
        return repr(float(value))  # shortest round trip; TOML spells inf and nan as Python does
    if isinstance(value, (str, Path)):
        return _toml_string(str(value))
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{_toml_key(k, where, source)} = {_toml_value(v, f'{where}.{k}', source)}"
                               for k, v in value.items()) + "}"
    if isinstance(value, (list, tuple, np.ndarray)):
        items = value.tolist() if isinstance(value, np.ndarray) else value
        return "[" + ", ".join(_toml_value(item, f"{where}[{i}]", source) for i, item in enumerate(items)) + "]"
    if value is None:
        raise JobError(f"{source}: {where} = None: a job file has no null; leave the key out for its default")
    raise JobError(f"{source}: {where} = {value!r}: allowed: a string, an integer, a number, true or false, "
                   "a list or a dict")


def _toml_integer(value: int) -> str:
    """An integer as TOML; one beyond the 64 bits of TOML is written as the first such integer,
    which :func:`parse_job` refuses with the same message naming its key (Python cannot even
    print integers of more than 4300 digits)."""
    if not TOML_INTEGERS[0] <= value <= TOML_INTEGERS[1]:
        return str(TOML_INTEGERS[1] + 1)
    return str(value)


def _toml_string(text: str) -> str:
    """A TOML basic string: JSON's escapes are TOML's, and TOML also escapes DEL."""
    return json.dumps(text, ensure_ascii=False).replace("\x7f", "\\u007f")


def _is_default(parameter: Parameter, value: Any) -> bool:
    return value == parameter.default and type(value) is type(parameter.default)


def _digest(data: bytes) -> bytes:
    return hashlib.sha256(data).digest()
