"""``parsim plot``: the papers' figures from a job's outputs, as PNG and PDF.

:data:`FIGURES` maps each figure's name to its :class:`~parsim.plots.common.FigureSpec`
(drawing function and needs); :func:`plot_output` draws one figure or every figure a
dataset supports.  Figures of statistics read the job's netCDF dataset; pictures of
configurations (``sediment``, ``cluster``) also read one task file.  Only ``parsim plot``
imports this package, so running jobs never needs matplotlib.
"""

from pathlib import Path
from typing import Callable

import numpy as np
import xarray as xr

from parsim.errors import PlotError, first_sentence
from parsim.output.collect import COMPLETED
from parsim.output.dataset import check_dataset_schema
from parsim.output.folder import JOB_COPY, TASKS, open_output, task_files
from parsim.output.location import check_output_location
from parsim.plots import aggregation, deposition
from parsim.plots.common import REALIZATION, FigureSpec, image_paths, save

FIGURES_BY_KIND = {"aggregation": aggregation.FIGURES, "deposition": deposition.FIGURES}
FIGURES: dict[str, FigureSpec] = {name: spec for figures in FIGURES_BY_KIND.values() for name, spec in figures.items()}
FIGURE_FOLDER = "figures"
#: The attribute that every dataset of a job has, of any output schema.
JOB_KIND = "job_kind"


def plot_output(output: Path, figure: str | None = None, out: Path | None = None, task: str | None = None,
                report: Callable[[str], None] = print) -> list[Path]:
    """Draw figure ``figure`` of ``output`` (a job's output folder or its dataset), or every
    figure its dataset supports.

    ``out``: with ``figure``, the file to write (see :func:`parsim.plots.common.image_paths`),
    by default OUTPUT/figures/NAME; without, the folder for every figure, by default
    OUTPUT/figures.  ``task`` is the label of the task pictured (default: the job's first task that has a task file).
    Figures whose needs the outputs lack are skipped with one reported line each, unless
    ``figure`` asks for one: then :class:`PlotError` says what is missing.  Returns the files written.
    """
    dataset_path, tasks = _locate(Path(output))
    if task is not None:
        _task_file(tasks, task)  # a task that is not there is refused before any figure is drawn
    dataset = _open(dataset_path)
    lacking = "the finished tasks lack" if COMPLETED in dataset.data_vars else "the dataset lacks"
    folder = dataset_path.parent / FIGURE_FOLDER
    if figure is not None:
        spec = _lookup(figure)
        target = Path(out) if out is not None else folder / spec.name
        _check_writable(image_paths(target)[0].parent, out)
        return _draw(spec, dataset, tasks, task, target, report)
    folder = Path(out) if out is not None else folder
    _check_writable(folder, out)
    written = []
    for spec in FIGURES_BY_KIND.get(dataset.attrs.get(JOB_KIND), FIGURES).values():
        missing = spec.missing(dataset)
        if missing:
            report(f"skipped {spec.name}: {lacking} {'; '.join(missing)}")
            continue
        try:
            written += _draw(spec, dataset, tasks, task, folder / spec.name, report)
        except PlotError as error:  # a picture without its task file
            report(f"skipped {spec.name}: {error}")
    return written


def _check_writable(folder: Path, out: Path | None) -> None:
    """Refuse, before a figure is drawn, a ``folder`` for the figures that cannot be made or written."""
    if out is not None:
        check_output_location(folder, role="--out", remedy="give another --out")
    else:
        check_output_location(folder, role="figures folder", remedy="give a folder that can be written with --out")


def _draw(spec: FigureSpec, dataset: xr.Dataset, tasks: Path, task: str | None, target: Path,
          report: Callable[[str], None]) -> list[Path]:
    arguments = (dataset, _task_file(tasks, task)) if spec.picture else (dataset,)
    paths = save(spec.draw(*arguments), target)
    report(f"{spec.name}: {' and '.join(map(str, paths))}")
    return paths


def _lookup(name: str) -> FigureSpec:
    if name not in FIGURES:
        allowed = "; ".join(f"{kind}: {', '.join(figures)}" for kind, figures in FIGURES_BY_KIND.items())
        raise PlotError(f"unknown figure {name!r}; allowed: {allowed}")
    return FIGURES[name]


def _locate(output: Path) -> tuple[Path, Path]:
    """The dataset and the task folder of a job's output folder, or of its dataset file."""
    if output.is_file():
        return output, output.parent / TASKS
    if not (output / JOB_COPY).exists():
        raise PlotError(f"{output} is neither a netCDF dataset nor a parsim output folder (no {JOB_COPY} in it)")
    folder, _ = open_output(output)
    if not folder.dataset.exists():
        raise PlotError(f"no dataset {folder.dataset}: it is written when every task has finished "
                        f"(parsim info {output} says how far the job got)")
    return folder.dataset, folder.tasks


def _open(path: Path) -> xr.Dataset:
    """The dataset at ``path``, in one line if it cannot be read or parsim did not write it; one of
    another output schema (another coding of ``component``) is refused; of a partial dataset, the
    part its finished tasks give (:func:`_finished_part`)."""
    try:
        with xr.open_dataset(path) as dataset:
            dataset = dataset.load()
    except (OSError, ValueError) as error:  # not netCDF (a text, an image, an empty file), or damaged
        raise PlotError(f"cannot read {path} as a netCDF dataset: {first_sentence(error)}") from None
    if JOB_KIND not in dataset.attrs:  # another netCDF or HDF5 file, a task file
        raise PlotError(f"{path} is not the dataset of a parsim job (it has no attribute {JOB_KIND}): give a job's "
                        "NAME.nc or NAME.partial.nc, or its output folder")
    check_dataset_schema(dataset, path)
    return _finished_part(dataset)


def _finished_part(dataset: xr.Dataset) -> xr.Dataset:
    """A partial dataset (``parsim collect``) without the swept values for which no task has finished,
    so that figures show what the finished tasks give and skip what they do not; any other as it is."""
    if COMPLETED not in dataset.data_vars:
        return dataset
    completed = dataset[COMPLETED].astype(bool)
    swept = [dim for dim in completed.dims if dim != REALIZATION]
    return dataset.isel({dim: np.flatnonzero(completed.any([other for other in completed.dims if other != dim]).values)
                         for dim in swept})


def _task_file(tasks: Path, label: str | None) -> Path:
    """The task file pictured: ``label``'s, or that of the job's first task that keeps one."""
    files = task_files(tasks.parent) if (tasks.parent / JOB_COPY).is_file() else []
    if not files:
        raise PlotError(f"the pictures need task files, and {tasks} holds none (a job with configurations = "
                        "\"none\" keeps none)")
    if label is not None:
        path = tasks / f"{label}.h5"
        if not path.exists():
            raise PlotError(f"no task file {path}; --task takes the name of a file in {tasks} without .h5, "
                            f"such as {files[0].stem}")
        return path
    return files[0]
