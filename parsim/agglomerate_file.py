"""Read an agglomerate (a rigid set of spheres) from a file, for deposition jobs.

Accepted files:

- CSV with columns x, y, z, r (a header line naming them, in any order, or exactly four
  unnamed columns in that order); x, y, r for an agglomerate in a plane.  Blank lines and
  everything after a ``#`` are ignored;
- HDF5 in parsim's snapshot layout (``spheres/position`` (n, d), ``spheres/radius``),
  such as a task file of an aggregation job: its final cluster(s), discs embedded at z = 0.
  A deposition task file spread over ranks is read as every task file is
  (:func:`parsim.output.snapshot.read_arrays`): its spheres in the drop order, as in the
  one-rank task file.

A file that cannot be read as one of these raises a :class:`JobError` naming the job key,
the file and, for a CSV, the line at fault.  The same files serve as a deposition's substrate
(``substrate``): then an HDF5 task file's own substrate (``substrate/position``,
``substrate/radius``) is read too, so that a sediment deposited onto an earlier one carries
the whole pile.
"""

from pathlib import Path

import numpy as np

from parsim.errors import JobError
from parsim.parameters import LARGEST_QUANTITY

CSV_COLUMNS = ("x", "y", "z", "r")


def read_agglomerate(path: str | Path, key: str = "agglomerate_file",
                     with_substrate: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Sphere centres (n, 2 or 3) and radii (n,) of the agglomerate in ``path``; ``key`` names the
    job key in errors; ``with_substrate``: an HDF5 file's substrate spheres come first."""
    try:
        return _read_spheres(Path(path), with_substrate)
    except _Unreadable as error:
        raise JobError(f"{key} = {str(path)!r}: {error}") from None


class _Unreadable(Exception):
    """Why a file holds no spheres parsim can read."""


def _read_spheres(path: Path, with_substrate: bool) -> tuple[np.ndarray, np.ndarray]:
    if not path.is_file():
        raise _Unreadable("no such file")
    if path.suffix.lower() in (".h5", ".hdf5"):
        centres, radii = _read_hdf5(path, with_substrate)
    elif path.suffix.lower() == ".csv":
        centres, radii = _read_csv(path)
    else:
        raise _Unreadable("allowed: a .csv file (columns x, y, z, r) "
                             "or an HDF5 file (.h5, .hdf5) with spheres/position and spheres/radius")
    _check_shapes(centres, radii)
    if len(radii) == 0 or not (np.all(np.isfinite(centres)) and np.all(np.isfinite(radii)) and np.all(radii > 0)):
        raise _Unreadable("needs at least one sphere, finite positions, radii > 0")
    if max(np.abs(centres).max(), radii.max()) > LARGEST_QUANTITY:
        raise _Unreadable(f"a position or radius beyond {LARGEST_QUANTITY:g} (in the job's length unit); allowed: "
                          f"values of magnitude at most {LARGEST_QUANTITY:g}")
    return centres, radii


def _check_shapes(centres: np.ndarray, radii: np.ndarray, names=("positions", "radii")) -> None:
    if centres.ndim != 2 or centres.shape[1] not in (2, 3) or radii.ndim != 1 or centres.shape[0] != len(radii):
        raise _Unreadable(f"{names[0]} of shape {centres.shape} and {names[1]} of shape {radii.shape}; "
                          "allowed: (n, 2) or (n, 3) and (n,)")


def _read_hdf5(path: Path, with_substrate: bool):
    import h5py

    from parsim.errors import OutputError
    from parsim.output.snapshot import read_arrays

    try:
        file = h5py.File(path, "r")
    except OSError as error:
        raise _Unreadable(f"not an HDF5 file ({error})") from None
    with file:
        if "spheres/position" not in file or "spheres/radius" not in file:
            raise _Unreadable("an HDF5 agglomerate needs the datasets spheres/position (n, d) "
                                 "and spheres/radius (n,)")
        groups = ("substrate", "spheres") if with_substrate and "substrate/position" in file else ("spheres",)
        names = [f"{group}/{array}" for group in groups for array in ("position", "radius")]
        for name in names:
            _check_numbers(file, name)
        try:  # a deposition spread over ranks: its spheres in the drop order, as in the one-rank task file
            arrays = read_arrays(file, names)
        except OutputError as error:
            raise _Unreadable(str(error)) from None
    read = [(np.asarray(arrays[f"{group}/position"], dtype=float), np.asarray(arrays[f"{group}/radius"], dtype=float))
            for group in groups]
    for group, (centres, radii) in zip(groups, read):
        _check_shapes(centres, radii, (f"{group}/position", f"{group}/radius"))
    if len({centres.shape[1] for centres, _ in read}) > 1:
        raise _Unreadable("substrate/position and spheres/position have different numbers of columns; allowed: "
                          "both (n, 3)")
    return np.concatenate([centres for centres, _ in read]), np.concatenate([radii for _, radii in read])


def _check_numbers(file, name: str) -> None:
    """The dataset ``name`` of an open HDF5 file must hold integers or floating-point numbers."""
    import h5py

    item = file.get(name)
    if not isinstance(item, h5py.Dataset) or item.dtype.kind not in "iuf":
        raise _Unreadable(f"{name} must be a dataset of numbers (integers or floating point)")


def _read_csv(path: Path):
    rows = _csv_rows(path)
    has_header = bool(rows) and not _is_number(rows[0][1][0])
    data = rows[1:] if has_header else rows
    if not data:
        raise _Unreadable("the CSV file holds no spheres")
    if has_header:
        names = [name.lower() for name in rows[0][1]]
        repeated = sorted({name for name in names if names.count(name) > 1})
        if repeated:
            raise _Unreadable(f"the CSV header names the column(s) {repeated} more than once; allowed: each of "
                              f"{', '.join(CSV_COLUMNS)} once")
        missing = [c for c in ("x", "y", "r") if c not in names]
        if missing:
            raise _Unreadable(f"the CSV header lacks the column(s) {missing}; "
                                 f"allowed columns: {', '.join(CSV_COLUMNS)}")
        table = _numbers(path, data, "the header", len(names))
    else:
        names = list(CSV_COLUMNS)
        if len(data[0][1]) != len(names):
            raise _Unreadable(f"a CSV without header needs 4 columns x, y, z, r; found {len(data[0][1])}")
        table = _numbers(path, data, f"line {data[0][0]}", len(names))
    axes = [names.index(c) for c in ("x", "y", "z") if c in names]
    return table[:, axes], table[:, names.index("r")]


def _csv_rows(path: Path) -> list[tuple[int, list[str]]]:
    """(line number, cells) of every line that is not blank or a comment."""
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise _Unreadable("not a CSV file (not UTF-8 text)") from None
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
            raise _Unreadable(f"line {number} has {len(cells)} values, {first} {width}")
        for column, cell in enumerate(cells):
            if not _is_number(cell):
                raise _Unreadable(f"line {number}: {cell!r} is not a number")
            table[row, column] = float(cell)
    return table


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
