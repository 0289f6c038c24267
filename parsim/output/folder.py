"""The output folder of a job, and what it says about how far the job got.

::

    <output>/job.toml               the job file as first run (resume refuses a different job)
    <output>/tasks/p0003_r0001.h5   one file per finished task (configuration + statistics)
    <output>/<name>.nc              the dataset, written once every task has finished

A task is finished exactly when its file exists: files are written under a
temporary name and renamed, so a killed run leaves only complete files, and
running the same command again computes just the missing tasks.
"""

from pathlib import Path

from parsim.errors import JobError, OutputError
from parsim.job import Job, Task
from parsim.output.atomic import TEMPORARY_SUFFIX, written_atomically

JOB_COPY = "job.toml"
TASKS = "tasks"


class OutputFolder:
    def __init__(self, root: Path, job_name: str):
        self.root = Path(root)
        self.job_copy = self.root / JOB_COPY
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

        ``stored_job`` is the job read from :attr:`job_copy` (None if absent).
        """
        if stored_job is not None:
            different = [key for key, value in _identity(job).items() if _identity(stored_job)[key] != value]
            if different:
                raise JobError(
                    f"output folder {self.root} holds results of a different job "
                    f"(it differs in: {', '.join(different)}); give another output folder "
                    f"(key 'output' or option --output) or remove {self.root}")
        self.tasks.mkdir(parents=True, exist_ok=True)
        if stored_job is None:
            with written_atomically(self.job_copy) as temporary:
                temporary.write_text(job.text)
        for leftover in self.root.rglob(f"*{TEMPORARY_SUFFIX}"):
            leftover.unlink(missing_ok=True)


def _identity(job: Job) -> dict:
    """What must agree between a run and its resume (the file's comments and layout need not)."""
    return {"name": job.name, "kind": job.kind, "seed": job.seed, "realizations": job.realizations,
            "parameters": job.fixed, "sweep": job.sweep}
