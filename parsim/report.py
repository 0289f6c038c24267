"""``parsim info``: what an output folder holds and how far its job got."""

from pathlib import Path

import xarray as xr

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
        with xr.open_dataset(folder.dataset) as dataset:
            lines.append(f"dataset {folder.dataset} (written {dataset.attrs.get('date_created', '?')} "
                         f"on {dataset.attrs.get('mpi_size', '?')} ranks):")
            lines.append("  dimensions: " + ", ".join(f"{d}={n}" for d, n in dataset.sizes.items()))
            for name, variable in dataset.data_vars.items():
                lines.append(f"  {name}({', '.join(variable.dims)}) [{variable.attrs.get('units', '')}]: "
                             f"{variable.attrs.get('long_name', '')}")
    else:
        lines.append("dataset: not yet written (it is written when every task has finished)")
    return "\n".join(lines)
