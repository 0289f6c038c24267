"""``parsim info``: what an output folder holds and how far its job got."""

from pathlib import Path

import xarray as xr

from parsim.errors import OutputError, first_sentence
from parsim.output.folder import open_output


def describe_output(root: Path) -> str:
    folder, job = open_output(root)
    tasks = job.tasks()
    rows, finished = folder.finished(job)
    done = int(finished.sum())

    lines = [f"job '{job.name}' ({job.kind}), seed {job.seed}, {job.realizations} realizations per point"]
    for name, values in job.sweep.items():
        lines.append(f"  sweep {name}: {', '.join(map(str, values))}")
    fixed = ", ".join(f"{name}={value}" for name, value in job.fixed.items() if value is not None)
    lines.append(f"  fixed: {fixed}")
    lines.append(f"tasks finished: {done} of {len(tasks)} ({100 * done / len(tasks):.0f} %)")
    if done < len(tasks):
        lines.append(f"  to finish: parsim run {folder.job_copy} --output {root}")
    if len(rows) > done:
        lines.append(f"  kept: {len(rows) - done} finished tasks of values or realisations the job no longer has "
                     "(back in the dataset if the job is grown to them again)")
    if folder.dataset.exists():
        lines += _dataset_lines(folder.dataset)
    else:
        lines.append("dataset: not yet written (it is written when every task has finished)")
    return "\n".join(lines)


def _dataset_lines(path: Path) -> list[str]:
    """What the dataset at ``path`` holds; a damaged one is an :class:`OutputError` naming it."""
    try:
        with xr.open_dataset(path) as dataset:
            if not dataset.attrs:  # a file cut off at its header opens as an empty dataset
                raise ValueError("it holds no attributes, as every dataset of a job does")
            lines = [f"dataset {path} (written {dataset.attrs.get('date_created', '?')} "
                     f"on {dataset.attrs.get('mpi_size', '?')} ranks):",
                     "  dimensions: " + ", ".join(f"{d}={n}" for d, n in dataset.sizes.items())]
            for name, variable in dataset.data_vars.items():
                lines.append(f"  {name}({', '.join(variable.dims)}) [{variable.attrs.get('units', '')}]: "
                             f"{variable.attrs.get('long_name', '')}")
    except (OSError, ValueError) as error:  # cut off or overwritten: the rows still hold every statistic
        raise OutputError(f"cannot read the dataset {path}: {first_sentence(error)}; remove it: parsim run of "
                          "the job writes it again from the folder's rows, computing nothing") from None
    return lines
