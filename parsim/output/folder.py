"""The output folder of a job, and what it says about how far the job got.

::

    <output>/job.toml               the job file as first run (resume refuses a different job)
    <output>/inputs.json            SHA-256 of every input file the job names (resume refuses a changed one)
    <output>/tasks/p0003_r0001.h5   one file per finished task (configuration + statistics)
    <output>/<name>.nc              the dataset, written once every task has finished

A task is finished exactly when its file exists: files are written under a
temporary name and renamed, so a killed run leaves only complete files, and
running the same command again computes just the missing tasks.  A folder whose
task files record another output schema (:data:`~parsim.output.snapshot.OUTPUT_SCHEMA`)
is refused, with one line saying so.
"""

import json
from pathlib import Path
from typing import Any

from parsim.errors import JobError, OutputError
from parsim.job import UNIT_KEYS, Job, Task, parse_job
from parsim.output.atomic import TEMPORARY_SUFFIX, written_atomically
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
        self.dataset = self.root / f"{job_name}.nc"

    def task_path(self, task: Task) -> Path:
        return self.tasks / f"{task.label}.h5"

    def is_finished(self, task: Task) -> bool:
        return self.task_path(task).exists()

    def create(self) -> None:
        """Make the folder and its ``tasks`` folder; a failure is an :class:`OutputError` naming the path."""
        try:
            self.tasks.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise OutputError.from_os_error(error, self.tasks, doing="create") from None

    def prepare(self, job: Job, stored_job: Job | None) -> None:
        """Create the folder for ``job``, or check that it holds the same job; remove stale temporaries.

        ``stored_job`` is the job read from :attr:`job_copy` (None if absent).  The hashes
        of the job's input files are recorded in :attr:`inputs`, and compared on a resume.
        """
        if stored_job is not None:
            self.check_schema()
            different = _differences(stored_job, job)
            if different:
                raise JobError(
                    f"output folder {self.root} holds results of a different job, which differs in: "
                    f"{', '.join(different)}; give another output folder "
                    f"(key 'output' or option --output) or remove {self.root}")
            self._check_inputs(job)
        self.tasks.mkdir(parents=True, exist_ok=True)
        if stored_job is None or not self.inputs.exists():
            with written_atomically(self.inputs) as temporary:
                temporary.write_text(json.dumps(job.input_hashes, indent=2) + "\n")
        if stored_job is None:
            with written_atomically(self.job_copy) as temporary:
                temporary.write_text(job.text)
        for leftover in self.root.rglob(f"*{TEMPORARY_SUFFIX}"):
            leftover.unlink(missing_ok=True)

    def check_schema(self) -> None:
        """Refuse a folder whose task files record another output schema than this parsim's.

        One task file stands for all: every run in a folder is refused unless its schema is
        the folder's (and the dataset assembly checks each file as it reads it).
        """
        first = next(self.tasks.glob("p*_r*.h5"), None) if self.tasks.is_dir() else None
        if first is not None:
            check_schema(read_schema_attributes(first), f"output folder {self.root}", self.root)

    def _check_inputs(self, job: Job) -> None:
        """Refuse to resume ``job`` if an input file recorded by the first run has changed."""
        for key, files in self._recorded_inputs().items():
            for path, then in files.items():
                now = job.input_hashes[key][path]  # the same job names the same files
                if now != then:
                    raise JobError(
                        f"output folder {self.root} holds results computed from a different {key} {path!r} "
                        f"(its content changed since the first run: sha256 {then[:12]}... then, {now[:12]}... now); "
                        "give another output folder or restore the file")

    def _recorded_inputs(self) -> dict[str, dict[str, str]]:
        """The input hashes of the first run; none for a folder that records none."""
        if not self.inputs.exists():
            return {}
        try:
            return json.loads(self.inputs.read_text())
        except ValueError:
            raise JobError(f"output folder {self.root}: {self.inputs} is not parsim's record of the input files; "
                           f"give another output folder or remove {self.root}") from None


def open_output(root: Path) -> tuple[OutputFolder, Job]:
    """The output folder ``root`` of a job and its job (from the folder's copy), schema checked."""
    from parsim.solvers import SOLVERS  # here: the solvers import numba, which a folder alone does not need

    folder = OutputFolder(root, job_name="")
    if not folder.job_copy.exists():
        raise JobError(f"{root} is not a parsim output folder (no {folder.job_copy.name} in it)")
    job = parse_job(folder.job_copy.read_text(), SOLVERS, source=str(folder.job_copy), output=root)
    folder = OutputFolder(root, job.name)
    folder.check_schema()
    return folder, job


_UNSET = object()


def _identity(job: Job) -> dict[str, Any]:
    """What must agree between a run and its resume, key by key (the file's comments and layout need not)."""
    return {"name": job.name, "kind": job.kind, "seed": job.seed, "realizations": job.realizations,
            **{unit.key: job.units[unit.quantity] for unit in UNIT_KEYS},
            **{f"[parameters] {key}": value for key, value in job.fixed.items()},
            **{f"[sweep] {key}": values for key, values in job.sweep.items()},
            **{f"[[{key}]]": list(entries) for key, entries in job.tables.items()}}


def _differences(then: Job, now: Job) -> list[str]:
    """Each key whose value differs between the stored job and ``now``, with both values.

    Jobs of different kinds have different parameters: only their top-level keys are compared.
    """
    old, new = _identity(then), _identity(now)
    keys = [key for key in {**old, **new} if old.get(key, _UNSET) != new.get(key, _UNSET)]
    if "kind" in keys:
        keys = [key for key in keys if not key.startswith("[")]
    return [f"{key} ({_shown(old, key)} then, {_shown(new, key)} now)" for key in keys]


def _shown(identity: dict[str, Any], key: str) -> str:
    return repr(identity[key]) if key in identity else "unset"
