"""The output folder of a job, and what it says about how far the job got.

::

    <output>/job.toml                        the job file as last run
    <output>/inputs.json                     SHA-256 of every input file the job has named (a changed one is refused)
    <output>/rows/*.rows                     the statistics of the finished tasks (:mod:`parsim.output.rows`)
    <output>/tasks/3fa9c01b2d4e5f60_r0001.h5 the final configuration of a task that keeps one (key ``configurations``)
    <output>/<name>.nc                       the dataset, written once every task has finished

A task is finished exactly when its row is in a row file: a task file is written first, under
a temporary name then renamed, and the row is appended in one write, so a killed run leaves only
complete files and rows, and running the same command again computes just the missing tasks.

A folder may be run again with a grown or shrunk job: more or fewer realisations, values added
to or removed from the sweep, a key moved between ``[parameters]`` and ``[sweep]``, another
``configurations``.  Tasks are found by their point's values (:class:`~parsim.job.Task`), so
only the new ones are computed, and the dataset shows the job as written now; rows and files of
tasks it no longer has stay.  Another name, kind, seed, unit, array of tables or fixed parameter
value, or an input file whose content changed, is refused naming the key; input files are
compared by content, so a file named anew keeps its tasks.  A folder whose files record another
output schema (:data:`~parsim.output.snapshot.OUTPUT_SCHEMA`) is refused, with one line saying so.

The folder's own commands (``info``, ``collect``, ``plot``, ``export``) read the job copy with the
hashes that :data:`INPUTS` records, never the input files, so they work from any working
directory and after an input file was edited or removed.
"""

import json
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from parsim.errors import JobError, OutputError
from parsim.job import UNIT_KEYS, Job, Task, parse_job
from parsim.output.atomic import TEMPORARY_SUFFIX, written_atomically
from parsim.output.dataset import row_layout, task_rows
from parsim.output.rows import ROWS, merge_rows, read_header, read_rows, row_files
from parsim.output.snapshot import check_schema, read_schema_attributes

JOB_COPY = "job.toml"
INPUTS = "inputs.json"
TASKS = "tasks"


class OutputFolder:
    def __init__(self, root: Path, job_name: str):
        self.root = Path(root)
        self.job_copy = self.root / JOB_COPY
        self.inputs = self.root / INPUTS
        self.tasks = self.root / TASKS
        self.rows = self.root / ROWS
        self.dataset = self.root / f"{job_name}.nc"

    def task_path(self, task: Task) -> Path:
        return self.tasks / f"{task.label}.h5"

    def existing_task_files(self, job: Job) -> list[Path]:
        """The task files of ``job`` in the folder, in the job's order: those of tasks the job no longer
        has (a shrunk job) and those of tasks that keep none are left out."""
        return [path for path in map(self.task_path, job.tasks()) if path.exists()]

    def finished(self, job: Job) -> tuple[np.ndarray, np.ndarray]:
        """The rows of every finished task in the folder (:func:`parsim.output.rows.read_rows`), of this
        job's or not, and for each task of ``job.tasks()`` whether it has finished."""
        rows = read_rows(self.rows, row_layout(job, job.solver))
        return rows, task_rows(job, rows) >= 0

    def create(self) -> None:
        """Make the folder, its ``tasks`` and ``rows`` folders; a failure is an :class:`OutputError` naming the path."""
        for folder in (self.tasks, self.rows):
            try:
                folder.mkdir(parents=True, exist_ok=True)
            except OSError as error:
                raise OutputError.from_os_error(error, folder, doing="create") from None

    def prepare(self, job: Job, stored_job: Job | None) -> np.ndarray:
        """Create the folder for ``job``, or check that ``job`` may run where ``stored_job`` ran; merge the
        row files (:func:`~parsim.output.rows.merge_rows`; call it holding the folder's lock); remove stale
        temporaries.  Returns the rows of the finished tasks, of this job's or not.

        ``stored_job`` is the job read from :attr:`job_copy` (None if absent).  Once every check
        has passed, rows included, ``job`` becomes the folder's copy and the hashes of its input
        files join those recorded in :attr:`inputs`.
        """
        recorded = self.check(job, stored_job)
        self.create()
        rows = merge_rows(self.rows, row_layout(job, job.solver), job.name)
        inputs = {key: {**recorded.get(key, {}), **job.input_hashes.get(key, {})}
                  for key in {**recorded, **job.input_hashes}}
        if stored_job is None or inputs != recorded:
            with written_atomically(self.inputs) as temporary:
                temporary.write_text(json.dumps(inputs, indent=2) + "\n")
        if stored_job is None or stored_job.text != job.text:
            with written_atomically(self.job_copy) as temporary:
                temporary.write_text(job.text)
        for leftover in self.root.rglob(f"*{TEMPORARY_SUFFIX}"):
            leftover.unlink(missing_ok=True)
        return rows

    def check(self, job: Job, stored_job: Job | None) -> dict[str, dict[str, str]]:
        """Refuse to run ``job`` where ``stored_job`` ran (:meth:`prepare`'s checks, writing nothing);
        returns the input hashes recorded by earlier runs."""
        if stored_job is None:
            return {}
        self.check_schema()
        different = _differences(stored_job, job)
        if different:
            raise JobError(
                f"output folder {self.root} holds results of a different job, which differs in: "
                f"{', '.join(different)}; a job may only add or remove [sweep] values and realizations: "
                f"give another output folder (key 'output' or option --output) or remove {self.root}")
        recorded = self._recorded_inputs()
        self._check_inputs(job, recorded)
        return recorded

    def stored_job(self) -> Job | None:
        """The job of the folder's copy (None if there is none), read without its input files, which
        may be gone or changed: its :attr:`~parsim.job.Job.input_hashes` are those :attr:`inputs`
        records, so its tasks are the tasks computed here, from any working directory."""
        from parsim.solvers import SOLVERS  # here: the solvers import numba, which a folder alone does not need

        if not self.job_copy.exists():
            return None
        try:
            job = parse_job(self._job_copy_text(), SOLVERS, source=str(self.job_copy), output=self.root,
                            verify=False)
        except JobError as error:
            raise JobError(f"output folder {self.root} holds a job copy that cannot be used ({error}); copy the "
                           f"job file last run into it as {JOB_COPY}, or give another output folder") from None
        return replace(job, input_hashes=self._inputs_named_by(job, self._recorded_inputs()))

    def _job_copy_text(self) -> str:
        try:
            return self.job_copy.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            raise JobError(f"{self.job_copy}: not a TOML job file (not UTF-8 text)") from None
        except OSError as error:
            raise OutputError.from_os_error(error, self.job_copy, doing="read") from None

    def _inputs_named_by(self, job: Job, recorded: dict[str, dict[str, str]]) -> dict[str, dict[str, str]]:
        """The recorded hashes of the input files ``job`` names, by key and path as written."""
        named = {key: {path: recorded[key][path] for path in paths if path in recorded.get(key, {})}
                 for key, paths in job.input_paths.items()}
        return {key: files for key, files in named.items() if files}

    def check_inputs_recorded(self, job: Job) -> None:
        """Refuse a stored ``job`` naming an input file whose hash :attr:`inputs` does not record:
        its tasks cannot be told apart without it."""
        for key, paths in job.input_paths.items():
            for path in paths:
                if path not in job.input_hashes.get(key, {}):
                    raise JobError(f"output folder {self.root}: {self.inputs} records no hash of {key} {path!r}, "
                                   f"which {self.job_copy} names; copy the job file last run into it as {JOB_COPY}, "
                                   "or give another output folder")

    def check_schema(self) -> None:
        """Refuse a folder whose files record another output schema than this parsim's.

        One row file and one task file stand for all: every run in a folder is refused unless its
        schema is the folder's (and reading the rows checks each row file).
        """
        headers = (read_header(path) for path in row_files(self.rows))
        first_rows = next((header for header in headers if header is not None), None)
        if first_rows is not None:
            check_schema(first_rows, f"output folder {self.root}", self.root)
        first_task = next(self.tasks.glob("*.h5"), None) if self.tasks.is_dir() else None
        if first_task is not None:
            check_schema(read_schema_attributes(first_task), f"output folder {self.root}", self.root)

    def _check_inputs(self, job: Job, recorded: dict[str, dict[str, str]]) -> None:
        """Refuse ``job`` if an input file it names, recorded by an earlier run, has changed."""
        for key, files in recorded.items():
            for path, then in files.items():
                now = job.input_hashes.get(key, {}).get(path, then)
                if now != then:
                    raise JobError(
                        f"output folder {self.root} holds results computed from a different {key} {path!r} "
                        f"(its content changed since an earlier run: sha256 {then[:12]}... then, {now[:12]}... now); "
                        "give another output folder or restore the file")

    def _recorded_inputs(self) -> dict[str, dict[str, str]]:
        """The input hashes recorded by earlier runs, {key: {path: sha256}}; none for a folder that records none."""
        if not self.inputs.exists():
            return {}
        try:
            recorded = json.loads(self.inputs.read_bytes())
        except ValueError:  # not JSON, or not UTF-8
            recorded = None
        except OSError as error:
            raise OutputError.from_os_error(error, self.inputs, doing="read") from None
        if not _is_input_record(recorded):
            raise JobError(f"output folder {self.root}: {self.inputs} is not parsim's record of the input files "
                           "({\"key\": {\"path\": \"sha256\"}}); copy it back from a copy of the folder, or give "
                           "another output folder")
        return recorded


def _is_input_record(recorded: Any) -> bool:
    """Whether ``recorded`` is laid out as :attr:`OutputFolder.inputs` records: {key: {path: sha256}}."""
    return isinstance(recorded, dict) and all(
        isinstance(files, dict) and all(isinstance(path, str) and isinstance(digest, str)
                                        for path, digest in files.items())
        for files in recorded.values())


def open_output(root: Path) -> tuple[OutputFolder, Job]:
    """The output folder ``root`` of a job and its job, schema checked: the folder's copy of the job,
    with the input hashes the folder records (:meth:`OutputFolder.stored_job`), so that the folder
    reads alike from any working directory and after its input files were edited or removed."""
    folder = OutputFolder(root, job_name="")
    job = folder.stored_job()
    if job is None:
        raise JobError(f"{root} is not a parsim output folder (no {folder.job_copy.name} in it); give the folder "
                       "a job wrote: its key 'output' or the --output of parsim run")
    folder = OutputFolder(root, job.name)
    folder.check_schema()
    folder.check_inputs_recorded(job)
    return folder, job


def task_files(root: Path) -> list[Path]:
    """The task files of the job of the output folder ``root`` (:meth:`OutputFolder.existing_task_files`)."""
    folder, job = open_output(Path(root))
    return folder.existing_task_files(job)


_UNSET = object()


@dataclass(frozen=True)
class _InputFile:
    """An input file as two runs in one folder compare it: by its content (the same file under
    another name is the same input), shown with its path."""

    path: str = field(compare=False)
    content: str  # "sha256:..." of the recorded content, or the path where no hash is recorded

    def __repr__(self) -> str:
        digest = self.content.removeprefix("sha256:")
        return f"{self.path!r} (sha256 {digest[:12]}...)" if digest != self.content else repr(self.path)


def _input_file(job: Job, key: str, path: str) -> _InputFile | str:
    """The value of input-file key ``key`` of ``job`` as :func:`_identity` compares it ("" names no file)."""
    if not path:
        return path
    digest = job.input_hashes.get(key, {}).get(path)
    return _InputFile(path, f"sha256:{digest}" if digest else path)


def _table_identity(job: Job, name: str) -> list[dict]:
    """The entries of ``[[name]]`` as :func:`_identity` compares them, input files by content."""
    files = {p.name for p in job.solver.table(name).parameters if p.is_file}
    return [{key: _input_file(job, f"[[{name}]] {key}", value) if key in files else value
             for key, value in entry.items()} for entry in job.table_entries(name)]


def _identity(job: Job) -> dict[str, Any]:
    """What must agree between two runs in one folder, key by key (the file's comments and layout,
    the realisations, the swept values, ``configurations`` and the names of input files need not)."""
    files = {p.name for p in job.solver.parameters if p.is_file}
    return {"name": job.name, "kind": job.kind, "seed": job.seed,
            **{unit.key: job.units[unit.quantity] for unit in UNIT_KEYS},
            **{f"[parameters] {key}": _input_file(job, key, value) if key in files else value
               for key, value in job.fixed.items()},
            **{f"[[{key}]]": _table_identity(job, key) for key in job.tables}}


def _differences(then: Job, now: Job) -> list[str]:
    """Each key whose value differs between the stored job and ``now``, with both values.

    A parameter fixed in one of them and swept in the other is growing or shrinking, not a
    difference.  Jobs of different kinds have different parameters: only their top-level keys
    are compared.
    """
    old, new = _identity(then), _identity(now)
    swept = {f"[parameters] {key}" for key in (*then.sweep, *now.sweep)}
    keys = [key for key in {**old, **new} if key not in swept and old.get(key, _UNSET) != new.get(key, _UNSET)]
    if "kind" in keys:
        keys = [key for key in keys if not key.startswith("[")]
    return [f"{key} ({_shown(old, key)} then, {_shown(new, key)} now)" for key in keys]


def _shown(identity: dict[str, Any], key: str) -> str:
    return repr(identity[key]) if key in identity else "unset"
