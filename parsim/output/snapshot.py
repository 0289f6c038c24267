"""Per-task HDF5 files: the final configuration and the task's statistics.

Layout (DESIGN.md): ``spheres/position`` (n, d), ``spheres/radius`` (n,) and the
solver's other arrays (``spheres/velocity``, ``spheres/cluster``, ``links``,
``spheres/particle``, ...); root attributes ``box_lower``, ``box_upper``,
``periodic``, the task's parameters and seed, the job's units, ``parsim_version`` and
``parsim_output_schema``.  The group ``statistics`` holds one dataset per statistic
of the task, so that a task file describes its task alone; the job's dataset is
assembled from the row files (:mod:`parsim.output.rows`).
"""

import io
from pathlib import Path

import h5py
import numpy as np

import parsim
from parsim.errors import JobError, OutputError
from parsim.output.atomic import write_bytes_atomically
from parsim.solver import Configuration, TaskResult

STATISTICS_GROUP = "statistics"

OUTPUT_SCHEMA = 5
"""Version of the layout of the outputs (task files and dataset), recorded in both.

Raise it with any change that would make parsim misread the outputs of an earlier
version, e.g. a statistic added, a coordinate coded differently, or a parameter's default
changed (a point's key and stream leave parameters at their default out).  Schema 2 (parsim
0.2.0): UDUNITS units, a numeric ``component``, the schema and version recorded.  Schema 3
(parsim 0.3.0): the deposition's species, structure and substrate outputs.  Schema 4 (parsim 0.4.0):
random streams and task files named by the values of a task's point, statistics in row files.  Schema 5
(parsim 0.5.0): deposition heights that count the substrate, a bulk away from walls, every floor-touching
particle counted, the species' volumes; task files record the parameters their task reads.
"""
SCHEMA_ATTRIBUTE = "parsim_output_schema"
VERSION_ATTRIBUTE = "parsim_version"
UNRECORDED_SCHEMA = 1
"""The schema of outputs that record none: parsim 0.1 wrote them."""


def provenance_attributes() -> dict:
    """The parsim version and output schema, as attributes of every task file and of the dataset."""
    return {VERSION_ATTRIBUTE: parsim.__version__, SCHEMA_ATTRIBUTE: OUTPUT_SCHEMA}


def check_schema(attrs, subject: str, folder: Path) -> None:
    """Refuse outputs whose attributes ``attrs`` record another output schema than this parsim's.

    ``subject`` names what is refused ("output folder out", "dataset out/q.nc"); ``folder``
    is the output folder to compute again.  Raises a one-line :class:`JobError`.
    """
    found = int(attrs.get(SCHEMA_ATTRIBUTE, UNRECORDED_SCHEMA))
    if found == OUTPUT_SCHEMA:
        return
    recorded = f"output schema {found}" if SCHEMA_ATTRIBUTE in attrs else f"output schema {found}, which records none"
    if found < OUTPUT_SCHEMA:
        written, writer = f"an older parsim ({recorded})", "the parsim that wrote it"
    else:
        written, writer = f"a newer parsim ({recorded})", "that parsim or a newer one"
    raise JobError(f"{subject} was written by {written}; parsim {parsim.__version__} reads and writes output "
                   f"schema {OUTPUT_SCHEMA}: read or finish it with {writer}, or compute the job again into "
                   f"another output folder (key 'output' or option --output) or after removing {folder}")


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
        for name, value in {**configuration.attrs, **attrs, **provenance_attributes()}.items():
            if value is not None:
                file.attrs[name] = value
        group = file.create_group(STATISTICS_GROUP)
        for name, value in result.statistics.items():
            group.create_dataset(name, data=np.asarray(value))
    write_bytes_atomically(path, image.getbuffer())


def read_schema_attributes(path: Path) -> dict:
    """The root attributes of a task file that say which parsim wrote it (none for parsim 0.1)."""
    try:
        with h5py.File(path, "r") as file:
            return {name: file.attrs[name] for name in (SCHEMA_ATTRIBUTE, VERSION_ATTRIBUTE) if name in file.attrs}
    except OSError as error:  # the task's row stays: removing the file loses the configuration alone
        raise OutputError(f"cannot read task file {path}: {error}; remove it to use the folder again: its task "
                          f"stays finished (its statistics are in {Path(path).parent.parent / 'rows'}), without "
                          "its configuration, which only the job computed into another output folder gives "
                          "again") from None


def read_configuration(path: Path) -> Configuration:
    """The configuration of a task file, with every array of the snapshot."""
    arrays = {}
    with h5py.File(path, "r") as file:
        file.visititems(lambda name, item: arrays.__setitem__(name, item[()])
                        if isinstance(item, h5py.Dataset) and not name.startswith(STATISTICS_GROUP) else None)
        attrs = {name: value for name, value in file.attrs.items()}
    return Configuration(arrays=arrays, box_lower=attrs.pop("box_lower"), box_upper=attrs.pop("box_upper"),
                         periodic=attrs.pop("periodic"), attrs=attrs)
