"""Read an agglomerate (a rigid set of spheres) from a file, for deposition jobs.

Accepted files:

- CSV with columns x, y, z, r (a header line naming them, in any order, or exactly four
  unnamed columns in that order); x, y, r for an agglomerate in a plane.  Blank lines and
  everything after a ``#`` are ignored;
- HDF5 in parsim's snapshot layout (``spheres/position`` (n, d), ``spheres/radius``),
  such as a task file of an aggregation job: its final cluster(s), discs embedded at z = 0.

A file that cannot be read as one of these raises a :class:`JobError` naming the file and,
for a CSV, the line at fault.
"""

from pathlib import Path

import numpy as np

from parsim.errors import JobError

CSV_COLUMNS = ("x", "y", "z", "r")


def read_agglomerate(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Sphere centres (n, 2 or 3) and radii (n,) of the agglomerate in ``path``."""
    path = Path(path)
    if not path.is_file():
        raise _invalid(path, "no such file")
    if path.suffix.lower() in (".h5", ".hdf5"):
        centres, radii = _read_hdf5(path)
    elif path.suffix.lower() == ".csv":
        centres, radii = _read_csv(path)
    else:
        raise _invalid(path, "allowed: a .csv file (columns x, y, z, r) "
                             "or an HDF5 file (.h5, .hdf5) with spheres/position and spheres/radius")
    if centres.ndim != 2 or centres.shape[1] not in (2, 3) or centres.shape[0] != len(radii):
        raise _invalid(path, f"positions of shape {centres.shape} and radii of shape {radii.shape}; "
                             "allowed: (n, 2) or (n, 3) and (n,)")
    if len(radii) == 0 or not (np.all(np.isfinite(centres)) and np.all(np.isfinite(radii)) and np.all(radii > 0)):
        raise _invalid(path, "needs at least one sphere, finite positions, radii > 0")
    return centres, radii


def _invalid(path: Path, reason: str) -> JobError:
    return JobError(f"agglomerate_file = {str(path)!r}: {reason}")


def _read_hdf5(path: Path):
    import h5py

    try:
        file = h5py.File(path, "r")
    except OSError as error:
        raise _invalid(path, f"not an HDF5 file ({error})") from None
    with file:
        if "spheres/position" not in file or "spheres/radius" not in file:
            raise _invalid(path, "an HDF5 agglomerate needs the datasets spheres/position (n, d) "
                                 "and spheres/radius (n,)")
        try:
            return (np.asarray(file["spheres/position"][()], dtype=float),
                    np.asarray(file["spheres/radius"][()], dtype=float))
        except (TypeError, ValueError):
            raise _invalid(path, "spheres/position and spheres/radius must hold numbers") from None


def _read_csv(path: Path):
    rows = _csv_rows(path)
    has_header = bool(rows) and not _is_number(rows[0][1][0])
    data = rows[1:] if has_header else rows
    if not data:
        raise _invalid(path, "the CSV file holds no spheres")
    if has_header:
        names = [name.lower() for name in rows[0][1]]
        missing = [c for c in ("x", "y", "r") if c not in names]
        if missing:
            raise _invalid(path, f"the CSV header lacks the column(s) {missing}; "
                                 f"allowed columns: {', '.join(CSV_COLUMNS)}")
        table = _numbers(path, data, "the header", len(names))
    else:
        names = list(CSV_COLUMNS)
        if len(data[0][1]) != len(names):
            raise _invalid(path, f"a CSV without header needs 4 columns x, y, z, r; found {len(data[0][1])}")
        table = _numbers(path, data, f"line {data[0][0]}", len(names))
    axes = [names.index(c) for c in ("x", "y", "z") if c in names]
    return table[:, axes], table[:, names.index("r")]


def _csv_rows(path: Path) -> list[tuple[int, list[str]]]:
    """(line number, cells) of every line that is not blank or a comment."""
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise _invalid(path, "not a CSV file (not UTF-8 text)") from None
    rows = []
    for number, line in enumerate(text.splitlines(), start=1):
        content = line.split("#", 1)[0]
        if content.strip():
            rows.append((number, [cell.strip() for cell in content.split(",")]))
    return rows


def _numbers(path: Path, rows: list[tuple[int, list[str]]], first: str, width: int) -> np.ndarray:
    """The table of ``rows``, each of ``width`` numbers (as ``first`` has)."""
    table = np.empty((len(rows), width))
    for row, (number, cells) in enumerate(rows):
        if len(cells) != width:
            raise _invalid(path, f"line {number} has {len(cells)} values, {first} {width}")
        for column, cell in enumerate(cells):
            if not _is_number(cell):
                raise _invalid(path, f"line {number}: {cell!r} is not a number")
            table[row, column] = float(cell)
    return table


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
