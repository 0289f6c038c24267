"""Per-task HDF5 files: the final configuration and the task's statistics.

Layout (DESIGN.md): ``spheres/position`` (n, d), ``spheres/radius`` (n,) and the
solver's other arrays (``spheres/velocity``, ``spheres/cluster``, ``links``,
``spheres/particle``, ...); root attributes ``box_lower``, ``box_upper``,
``periodic``, the task's parameters and seed.  The group ``statistics`` holds one
dataset per statistic of the task: it is what the job's netCDF dataset is
assembled from, so a finished task file is also the resume record of its task.
"""

import io
from pathlib import Path

import h5py
import numpy as np

from parsim.errors import OutputError
from parsim.output.atomic import write_bytes_atomically
from parsim.solver import Configuration, TaskResult

STATISTICS_GROUP = "statistics"


def write_task_file(path: Path, result: TaskResult, attrs: dict) -> None:
    """Write one task's configuration, statistics and ``attrs`` (parameters, seed) atomically.

    The HDF5 file is built in memory and then written in one piece, so that a
    full disk raises an :class:`OutputError` naming ``path`` instead of failing
    inside the HDF5 library.
    """
    configuration = result.configuration
    image = io.BytesIO()
    with h5py.File(image, "w") as file:
        for name, array in configuration.arrays.items():
            file.create_dataset(name, data=np.asarray(array))
        file.attrs["box_lower"] = np.asarray(configuration.box_lower, dtype=np.float64)
        file.attrs["box_upper"] = np.asarray(configuration.box_upper, dtype=np.float64)
        file.attrs["periodic"] = np.asarray(configuration.periodic, dtype=bool)
        for name, value in {**configuration.attrs, **attrs}.items():
            if value is not None:
                file.attrs[name] = value
        group = file.create_group(STATISTICS_GROUP)
        for name, value in result.statistics.items():
            group.create_dataset(name, data=np.asarray(value))
    write_bytes_atomically(path, image.getbuffer())


def read_statistics(path: Path) -> dict[str, np.ndarray]:
    """The statistics of a finished task file; an unreadable file is an :class:`OutputError` naming it."""
    try:
        with h5py.File(path, "r") as file:
            return {name: dataset[()] for name, dataset in file[STATISTICS_GROUP].items()}
    except (OSError, KeyError) as error:
        raise OutputError(f"cannot read the statistics of task file {path}: {error}; "
                          "remove the file and run the same command again to recompute its task") from None


def read_configuration(path: Path) -> Configuration:
    """The configuration of a task file, with every array of the snapshot."""
    arrays = {}
    with h5py.File(path, "r") as file:
        file.visititems(lambda name, item: arrays.__setitem__(name, item[()])
                        if isinstance(item, h5py.Dataset) and not name.startswith(STATISTICS_GROUP) else None)
        attrs = {name: value for name, value in file.attrs.items()}
    return Configuration(arrays=arrays, box_lower=attrs.pop("box_lower"), box_upper=attrs.pop("box_upper"),
                         periodic=attrs.pop("periodic"), attrs=attrs)
