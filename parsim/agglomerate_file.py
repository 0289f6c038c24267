"""Read an agglomerate (a rigid set of spheres) from a file, for deposition jobs.

Accepted files:

- CSV with columns x, y, z, r (a header line naming them, in any order, or exactly four
  unnamed columns in that order); x, y, r for an agglomerate in a plane;
- HDF5 in parsim's snapshot layout (``spheres/position`` (n, d), ``spheres/radius``),
  such as a task file of an aggregation job: its final cluster(s), discs embedded at z = 0.
"""

from pathlib import Path

import numpy as np

from parsim.errors import JobError

CSV_COLUMNS = ("x", "y", "z", "r")


def read_agglomerate(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Sphere centres (n, 2 or 3) and radii (n,) of the agglomerate in ``path``."""
    path = Path(path)
    if not path.is_file():
        raise JobError(f"agglomerate_file = {str(path)!r}: no such file")
    if path.suffix.lower() in (".h5", ".hdf5"):
        centres, radii = _read_hdf5(path)
    elif path.suffix.lower() == ".csv":
        centres, radii = _read_csv(path)
    else:
        raise JobError(f"agglomerate_file = {str(path)!r}: allowed: a .csv file (columns x, y, z, r) "
                       "or an HDF5 file (.h5, .hdf5) with spheres/position and spheres/radius")
    if len(radii) == 0 or not (np.all(np.isfinite(centres)) and np.all(np.isfinite(radii)) and np.all(radii > 0)):
        raise JobError(f"agglomerate_file = {str(path)!r}: needs at least one sphere, finite positions, radii > 0")
    return centres, radii


def _read_hdf5(path: Path):
    import h5py

    with h5py.File(path, "r") as file:
        if "spheres/position" not in file or "spheres/radius" not in file:
            raise JobError(f"agglomerate_file = {str(path)!r}: an HDF5 agglomerate needs the datasets "
                           "spheres/position (n, d) and spheres/radius (n,)")
        return np.asarray(file["spheres/position"][()], dtype=float), np.asarray(file["spheres/radius"][()], dtype=float)


def _read_csv(path: Path):
    with open(path) as file:
        first = file.readline()
    names = [name.strip().lower() for name in first.split(",")]
    has_header = not _is_number(names[0])
    table = np.atleast_2d(np.loadtxt(path, delimiter=",", skiprows=1 if has_header else 0, ndmin=2))
    if has_header:
        missing = [c for c in ("x", "y", "r") if c not in names]
        if missing:
            raise JobError(f"agglomerate_file = {str(path)!r}: the CSV header lacks the column(s) {missing}; "
                           f"allowed columns: {', '.join(CSV_COLUMNS)}")
        axes = [names.index(c) for c in ("x", "y", "z") if c in names]
        return table[:, axes], table[:, names.index("r")]
    if table.shape[1] != 4:
        raise JobError(f"agglomerate_file = {str(path)!r}: a CSV without header needs 4 columns x, y, z, r; "
                       f"found {table.shape[1]}")
    return table[:, :3], table[:, 3]


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
