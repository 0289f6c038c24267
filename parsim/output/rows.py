"""Row files: the statistics of the finished tasks, one fixed-size record per task.

::

    <output>/rows/rank00001-5f3a9c2e.rows

A row file is one line of JSON, its header (the format, the output schema, the parsim version,
the job name and the record layout), then records.  A record holds the task's point key
(:meth:`parsim.job.Job.point_key`, 16 bytes), its realisation (uint32), every statistic in its
declared type and shape (little-endian), and a CRC-32 of the bytes before it.

Each rank of a run appends to a file of its own, created with its first record, one ``write``
of the whole record once the task has finished (after its task file, if it keeps one).  A kill
at any moment leaves complete records and at most a cut-off last one, which a reader ignores,
as it ignores a record whose CRC does not match: that task is computed again.  When a run
starts, rank 0 merges the folder's row files into one (:func:`merge_rows`), so a folder holds
one file, plus one per rank of the run under way.  Reading is one ``numpy.fromfile`` per file:
10⁵ tasks' rows are read in well under a second.
"""

import json
import os
import secrets
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parsim.errors import JobError, OutputError
from parsim.job import KEY_BYTES, Task
from parsim.output.atomic import write_bytes_atomically
from parsim.output.snapshot import SCHEMA_ATTRIBUTE, check_schema, provenance_attributes

ROWS = "rows"
SUFFIX = ".rows"
FORMAT = "parsim task rows"
MAX_HEADER_BYTES = 1 << 20
READ_ATTEMPTS = 3


@dataclass(frozen=True)
class RowLayout:
    """What a record holds after its key and realisation: (name, numpy type, shape) per statistic."""

    fields: tuple[tuple[str, str, tuple[int, ...]], ...]

    @property
    def dtype(self) -> np.dtype:
        statistics = [(name, np.dtype(kind).newbyteorder("<"), shape) for name, kind, shape in self.fields]
        return np.dtype([("key", f"V{KEY_BYTES}"), ("realization", "<u4"), *statistics, ("crc", "<u4")])

    def header(self, job_name: str) -> bytes:
        record = {"format": FORMAT, **provenance_attributes(), "job_name": job_name,
                  "fields": [[name, kind, list(shape)] for name, kind, shape in self.fields]}
        return (json.dumps(record) + "\n").encode()

    def record(self, key: bytes, realization: int, statistics: dict) -> bytes:
        """One task's record: ``statistics`` by name, each of its field's shape."""
        row = np.zeros((), dtype=self.dtype)
        row["key"] = np.void(key)
        row["realization"] = realization
        for name, _, _ in self.fields:
            row[name] = statistics[name]
        data = bytearray(row.tobytes())
        data[-4:] = zlib.crc32(data[:-4]).to_bytes(4, "little")
        return bytes(data)


    def rows(self, finished: list[tuple[Task, dict]]) -> np.ndarray:
        """The rows of ``finished`` (task, statistics) pairs in memory, as :func:`read_rows` returns them."""
        records = b"".join(self.record(task.key, task.realization, statistics) for task, statistics in finished)
        return np.frombuffer(records, dtype=self.dtype)


class RowWriter:
    """This rank's row file of a run, created in ``folder`` with the first record appended to it."""

    def __init__(self, folder: Path, layout: RowLayout, job_name: str, rank: int):
        self.folder = Path(folder)
        self.layout = layout
        self.job_name = job_name
        self.rank = rank
        self.path: Path | None = None
        self._descriptor: int | None = None

    def append(self, key: bytes, realization: int, statistics: dict) -> None:
        """Append one finished task's record, in one write."""
        record = self.layout.record(key, realization, statistics)
        if self._descriptor is None:
            self._open()
            record = self.layout.header(self.job_name) + record  # a file holds its header before any record
        self._write(record)

    def close(self) -> None:
        """Flush the file to the disk and close it (a no-op for a rank that finished no task)."""
        if self._descriptor is None:
            return
        try:
            os.fsync(self._descriptor)
        except OSError as error:
            raise OutputError.from_os_error(error, self.path) from None
        finally:
            os.close(self._descriptor)
            self._descriptor = None

    def _open(self) -> None:
        """Create a file of a name no earlier run used (a random suffix, drawn again if taken)."""
        while self._descriptor is None:
            self.path = self.folder / f"rank{self.rank:05d}-{secrets.token_hex(4)}{SUFFIX}"
            try:
                self.folder.mkdir(exist_ok=True)
                self._descriptor = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_APPEND, 0o644)
            except FileExistsError:
                continue
            except OSError as error:
                raise OutputError.from_os_error(error, self.path, doing="create") from None

    def _write(self, data: bytes) -> None:
        try:
            written = os.write(self._descriptor, data)
        except OSError as error:
            raise OutputError.from_os_error(error, self.path) from None
        if written != len(data):  # a full disk may cut a write short instead of failing it
            raise OutputError(f"no space left on {self.path} (wrote {written} of {len(data)} bytes)")


def read_rows(folder: Path, layout: RowLayout, files: list[Path] | None = None) -> np.ndarray:
    """Every complete record of the row files in ``folder`` (or ``files``), one per task, in file order.

    A cut-off last record and records whose CRC does not match are left out; a task found
    twice keeps its first record.  A file of another layout or output schema is a
    :class:`JobError` naming it.  A file that vanishes while it is read (a run that starts
    merges the files: :func:`merge_rows`) sends the reading back to the folder's files.
    """
    for attempt in range(READ_ATTEMPTS):
        listed = row_files(folder) if files is None else files
        try:
            parts = [_read_file(path, layout) for path in listed]
            break
        except FileNotFoundError as error:
            if files is not None or attempt == READ_ATTEMPTS - 1:
                raise OutputError.from_os_error(error, error.filename, doing="read") from None
    rows = np.concatenate(parts) if parts else np.zeros(0, dtype=layout.dtype)
    identity = np.zeros(len(rows), dtype=[("key", f"V{KEY_BYTES}"), ("realization", "<u4")])
    identity["key"], identity["realization"] = rows["key"], rows["realization"]
    _, first = np.unique(identity, return_index=True)
    return rows[np.sort(first)]


def row_files(folder: Path) -> list[Path]:
    return sorted(Path(folder).glob(f"*{SUFFIX}")) if Path(folder).is_dir() else []


def merge_rows(folder: Path, layout: RowLayout, job_name: str) -> np.ndarray:
    """Merge the row files of ``folder`` into one and return their rows (call it holding the folder's lock).

    The merged file is written atomically before the files it replaces are removed: a kill in
    between leaves rows twice, which :func:`read_rows` reads once.
    """
    files = row_files(folder)
    rows = read_rows(folder, layout, files)
    complete = len(layout.header(job_name)) + len(rows) * layout.dtype.itemsize
    if len(files) > 1 or (files and _size(files[0]) != complete):
        merged = folder / f"merged-{secrets.token_hex(4)}{SUFFIX}"
        write_bytes_atomically(merged, layout.header(job_name) + rows.tobytes())
        for path in files:
            path.unlink(missing_ok=True)
    return rows


def read_header(path: Path) -> dict | None:
    """The header of a row file; None for a file cut off before its header's end (a kill as it was
    created).  A file that is not a row file is a :class:`JobError` naming it."""
    try:
        with open(path, "rb") as file:
            line = file.readline(MAX_HEADER_BYTES)
    except FileNotFoundError:
        raise
    except OSError as error:
        raise OutputError.from_os_error(error, path, doing="read") from None
    if not line.endswith(b"\n") and len(line) < MAX_HEADER_BYTES:
        return None
    try:
        header = json.loads(line)
        if header.get("format") != FORMAT:
            raise ValueError
        int(header[SCHEMA_ATTRIBUTE])
        header["fields"] = [(str(name), str(kind), tuple(int(n) for n in shape))
                            for name, kind, shape in header["fields"]]
    except (ValueError, AttributeError, KeyError, TypeError):
        raise JobError(f"{path} is not a row file of parsim; remove it from {path.parent}") from None
    header["header_bytes"] = len(line)
    return header


def _size(path: Path) -> int:
    try:
        return path.stat().st_size
    except FileNotFoundError:
        raise
    except OSError as error:
        raise OutputError.from_os_error(error, path, doing="read") from None


def _read_file(path: Path, layout: RowLayout) -> np.ndarray:
    header = read_header(path)
    if header is None:
        return np.zeros(0, dtype=layout.dtype)
    check_schema(header, f"row file {path}", path.parent.parent)
    if header["fields"] != list(layout.fields):
        raise JobError(f"row file {path} holds statistics laid out otherwise than this job's (another solver "
                       f"version or observable sizes); give another output folder or remove {path.parent.parent}")
    size = _size(path) - header["header_bytes"]
    rows = np.fromfile(path, dtype=layout.dtype, count=size // layout.dtype.itemsize, offset=header["header_bytes"])
    raw = rows.view(np.uint8).reshape(len(rows), layout.dtype.itemsize)
    intact = np.array([zlib.crc32(record[:-4]) for record in raw], dtype=np.uint32) == rows["crc"]
    return rows[intact]
