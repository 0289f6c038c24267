"""Per-task HDF5 files: the final configuration and the task's statistics.

Layout (DESIGN.md): ``spheres/position`` (n, d), ``spheres/radius`` (n,) and the
solver's other arrays (``spheres/velocity``, ``spheres/cluster``, ``links``,
``spheres/particle``, ...); root attributes ``box_lower``, ``box_upper``,
``periodic``, the task's parameters and seed, the job's units, ``parsim_version`` and
``parsim_output_schema``.  The group ``statistics`` holds one dataset per statistic
of the task, so that a task file describes its task alone; the job's dataset is
assembled from the row files (:mod:`parsim.output.rows`).

A sediment spread over the ranks of a task's group (``parsim run --ranks-per-task K``) is written
without gathering it: each rank writes its particles and spheres to ``LABEL.parts/rankNNNN.h5``
beside the task file, and the task file ``LABEL.h5`` joins them as HDF5 virtual datasets, which
h5py, netCDF4 and every HDF5 1.10+ reader open as one array (their rows in rank order;
``particles/index`` holds each particle's place in the drop order).  Every parsim reader of task
files reads them through :func:`read_arrays` (:func:`read_configuration`, ``parsim export`` and
``parsim plot`` through it, a job's ``substrate`` and ``agglomerate_file`` too), which returns
them in the serial order: the one-rank task's arrays, bit for bit.  Virtual datasets in that order
would need a mapping per run of one rank's consecutive particles, about one per particle.
"""

import io
from pathlib import Path

import h5py
import numpy as np

from parsim.errors import JobError, OutputError
from parsim.output.atomic import write_bytes_atomically, written_atomically
from parsim.solver import Configuration, TaskResult
from parsim.version import __version__

STATISTICS_GROUP = "statistics"
PARTS_SUFFIX = ".parts"
PARTICLE_ORDER = "particles/index"
#: the arrays of each group of a spread configuration, and the array whose stable sort puts them in
#: the serial order (a particle's spheres are on its rank, one after the other)
SERIAL_ORDER = {"particles/": PARTICLE_ORDER, "spheres/": "spheres/particle"}

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
    return {VERSION_ATTRIBUTE: __version__, SCHEMA_ATTRIBUTE: OUTPUT_SCHEMA}


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
    raise JobError(f"{subject} was written by {written}; parsim {__version__} reads and writes output "
                   f"schema {OUTPUT_SCHEMA}: read or finish it with {writer}, or compute the job again into "
                   f"another output folder (key 'output' or option --output) or after removing {folder}")


def write_task_file(path: Path, result: TaskResult, attrs: dict, comm=None) -> None:
    """Write one task's configuration, statistics and ``attrs`` (parameters, seed) atomically.

    The HDF5 file is built in memory and then written in one piece, so that a
    full disk raises an :class:`OutputError` naming ``path`` instead of failing
    inside the HDF5 library.  A configuration spread over the ranks of ``comm``
    (:attr:`Configuration.rank_rows`) is written by every rank, collectively: see
    the module docs.
    """
    configuration = result.configuration
    if configuration.rank_rows and comm is not None and comm.Get_size() > 1:
        _write_joined_task_file(path, result, attrs, comm)
        return
    write_bytes_atomically(path, _task_image(result, attrs, lambda file, name, array: file.create_dataset(
        name, data=np.asarray(array))))


def _task_image(result: TaskResult, attrs: dict, write_array) -> memoryview:
    """The task file in memory; ``write_array(file, name, array)`` writes each configuration array."""
    configuration = result.configuration
    image = io.BytesIO()
    with h5py.File(image, "w") as file:
        for name, array in configuration.arrays.items():
            write_array(file, name, array)
        file.attrs["box_lower"] = np.asarray(configuration.box_lower, dtype=np.float64)
        file.attrs["box_upper"] = np.asarray(configuration.box_upper, dtype=np.float64)
        file.attrs["periodic"] = np.asarray(configuration.periodic, dtype=bool)
        for name, value in {**configuration.attrs, **attrs, **provenance_attributes()}.items():
            if value is not None:
                file.attrs[name] = value
        group = file.create_group(STATISTICS_GROUP)
        for name, value in result.statistics.items():
            group.create_dataset(name, data=np.asarray(value))
    return image.getbuffer()


def parts_folder(path: Path) -> Path:
    """The folder of the ranks' files of the task file ``path`` of a spread configuration."""
    return Path(path).with_suffix(PARTS_SUFFIX)


def _part_name(rank: int) -> str:
    return f"rank{rank:04d}.h5"


def _write_joined_task_file(path: Path, result: TaskResult, attrs: dict, comm) -> None:
    """Every rank writes its rows to its part file; the group's rank 0 then writes the task file, whose
    arrays of rows are virtual datasets over the parts (in rank order).  Collective over ``comm``."""
    configuration = result.configuration
    folder = parts_folder(path)
    rows = {name: np.asarray(configuration.arrays[name]) for name in configuration.rank_rows}
    with written_atomically(folder / _part_name(comm.Get_rank())) as temporary:
        folder.mkdir(exist_ok=True)
        with h5py.File(temporary, "w") as file:  # large: written in place, an OSError names the part
            for name, array in rows.items():
                file.create_dataset(name, data=array)
    layouts = comm.gather({name: (array.shape, array.dtype.str) for name, array in rows.items()}, root=0)
    if comm.Get_rank() != 0:
        return
    current = {_part_name(rank) for rank in range(len(layouts))}
    for stale in folder.glob(f"rank*{Path(_part_name(0)).suffix}"):  # of an earlier run on more ranks
        if stale.name not in current:
            stale.unlink(missing_ok=True)

    def write_array(file, name, array):
        if name in rows:
            file.create_virtual_dataset(name, _joined_layout(name, layouts, folder.name))
        else:
            file.create_dataset(name, data=np.asarray(array))

    write_bytes_atomically(path, _task_image(result, attrs, write_array))


def _joined_layout(name: str, layouts: list[dict], folder_name: str) -> h5py.VirtualLayout:
    """The virtual layout of array ``name``: the parts' rows one after the other, in rank order; the
    sources are named relative to the task file, so that the output folder can move."""
    shapes = [layout[name][0] for layout in layouts]
    total = sum(shape[0] for shape in shapes)
    joined = h5py.VirtualLayout(shape=(total, *shapes[0][1:]), dtype=np.dtype(layouts[0][name][1]))
    first = 0
    for rank, shape in enumerate(shapes):
        if shape[0]:
            joined[first:first + shape[0]] = h5py.VirtualSource(f"{folder_name}/{_part_name(rank)}", name, shape=shape)
            first += shape[0]
    return joined


def read_schema_attributes(path: Path) -> dict:
    """The root attributes of a task file that say which parsim wrote it (none for parsim 0.1)."""
    try:
        with h5py.File(path, "r") as file:
            return {name: file.attrs[name] for name in (SCHEMA_ATTRIBUTE, VERSION_ATTRIBUTE) if name in file.attrs}
    except OSError as error:
        raise OutputError(f"cannot read task file {path}: {error}; remove it to use the folder again: "
                          f"{_kept_without_configuration(path)}, which only the job computed into another output "
                          "folder gives again") from None


def _kept_without_configuration(path: Path) -> str:
    """What removing the unreadable task file ``path`` leaves: its task's row stays, so the task stays
    finished and a run into the folder does not compute it again."""
    return (f"its task stays finished (its statistics are in {Path(path).parent.parent / 'rows'}), without its "
            "configuration")


def read_configuration(path: Path) -> Configuration:
    """The configuration of a task file, with every array of the snapshot; a spread configuration's
    rows in the serial order (:func:`read_arrays`)."""
    with h5py.File(path, "r") as file:
        arrays = read_arrays(file)
        attrs = {name: value for name, value in file.attrs.items()}
    return Configuration(arrays=arrays, box_lower=attrs.pop("box_lower"), box_upper=attrs.pop("box_upper"),
                         periodic=attrs.pop("periodic"), attrs=attrs)


def read_arrays(file: h5py.File, names=None) -> dict:
    """The datasets ``names`` of the open task file ``file`` (default: every one outside the statistics
    group), as arrays, read by every reader of task files.

    A spread configuration (:data:`PARTICLE_ORDER` in the file) stores its particles' and spheres' rows
    rank after rank; they are returned in the serial (drop) order, each group by the stable sort of its
    key in :data:`SERIAL_ORDER`, and without :data:`PARTICLE_ORDER` unless ``names`` asks for it, so that
    a reader gets the one-rank configuration.  Names that are not datasets of ``file`` are left out.  A
    joined array whose part file is missing is an :class:`OutputError`, not the zeros HDF5 would read.
    """
    if names is None:
        names = []
        file.visititems(lambda name, item: names.append(name) if isinstance(item, h5py.Dataset) and not
                        name.startswith(STATISTICS_GROUP) and name != PARTICLE_ORDER else None)
    wanted = list(names)
    spread = isinstance(file.get(PARTICLE_ORDER), h5py.Dataset)
    keys = [key for group, key in SERIAL_ORDER.items() if spread and any(name.startswith(group) for name in wanted)]
    arrays = {name: _read_array(file, name) for name in dict.fromkeys([*wanted, *keys])
              if isinstance(file.get(name), h5py.Dataset)}
    for group, key in SERIAL_ORDER.items():
        if key in keys and key in arrays:
            order = np.argsort(arrays[key], kind="stable")
            arrays.update({name: array[order] for name, array in arrays.items() if name.startswith(group)})
    return {name: arrays[name] for name in wanted if name in arrays}


def _read_array(file: h5py.File, name: str) -> np.ndarray:
    """The values of dataset ``name``; a virtual one's part files must exist (HDF5 would read zeros instead),
    and one that HDF5 cannot read is named (HDF5's error names the task file, which is intact)."""
    dataset, path = file[name], Path(file.filename)
    if not dataset.is_virtual:
        return dataset[()]
    parts = [path.parent / source.file_name for source in dataset.virtual_sources()]
    for part in parts:
        if not part.is_file():
            raise OutputError(f"task file {path} joins the ranks' files in {parts_folder(path)}, and "
                              f"{part.name} is missing: copy or move the task file with that folder")
    try:
        return dataset[()]
    except OSError:
        for part in parts:
            _check_part(part, name, path)
        raise


def _check_part(part: Path, name: str, path: Path) -> None:
    """Refuse the part file ``part`` of task file ``path`` if its array ``name`` cannot be read (truncated,
    overwritten): a one-line OutputError naming it, and what to do."""
    try:
        with h5py.File(part, "r") as file:
            file[name][()]
    except (OSError, KeyError) as error:
        raise OutputError(f"cannot read {part}, a part of task file {path} ({error}): compute the job again into "
                          f"another output folder (key 'output' or option --output) for this task's configuration, "
                          f"or remove {path} and {parts_folder(path)}: {_kept_without_configuration(path)}") from None
