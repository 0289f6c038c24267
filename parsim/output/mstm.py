"""``parsim export --format mstm``: a cluster as the input file of MSTM (Mackowski's multiple-sphere T-matrix code).

MSTM computes the light scattering of a cluster of spheres from a keyword file: ``number_spheres``,
then ``sphere_data`` with one line ``x,y,z,radius,(Re m,Im m)`` per sphere and ``end_of_sphere_data``,
``length_scale_factor`` (it multiplies every position and radius into a size parameter k r, k = 2 pi /
wavelength), and ``end_of_options``.  The file keeps the task's lengths in its length unit and sets
``length_scale_factor = 2 pi / wavelength`` from the wavelength given in that unit, so MSTM reads the
cluster in its own units; every sphere gets the one refractive index given.  Numbers are Fortran
double literals with 17 significant digits (``1.2345678901234567d-01``), read back as the same doubles.
Discs of a 2-D task are spheres at z = 0.
"""

import math
from pathlib import Path

import numpy as np

from parsim.errors import JobError
from parsim.output.atomic import written_atomically


def fortran_real(value: float) -> str:
    """``value`` as a Fortran double-precision literal of 17 significant digits."""
    return f"{float(value):.16e}".replace("e", "d")


def refractive_index(text: str) -> complex:
    """The refractive index of ``--refractive-index`` (``1.6+0.6j``, ``1.5``); ValueError names what is allowed."""
    try:
        value = complex(str(text).replace(" ", ""))
    except ValueError:
        value = None
    if value is None or not _is_index(value):
        raise ValueError(f"{text!r}: allowed: a complex number with Re m > 0 and Im m >= 0 (absorption), "
                         "e.g. 1.5 or 1.6+0.6j")
    return value


def _is_index(value: complex) -> bool:
    return math.isfinite(value.real) and math.isfinite(value.imag) and value.real > 0.0 and value.imag >= 0.0


def check_options(wavelength: float | None, index: complex | None) -> None:
    """Both options of the format are given: a positive finite wavelength and an index with Re m > 0, Im m >= 0."""
    if wavelength is None or index is None:
        raise JobError("format 'mstm' needs --wavelength (in the task's length unit) and --refractive-index "
                       "(e.g. 1.6+0.6j): MSTM reads size parameters 2 pi r / wavelength and complex indices")
    if not (math.isfinite(wavelength) and wavelength > 0.0):
        raise JobError(f"--wavelength {wavelength!r}: allowed a finite number > 0, in the task's length unit")
    if not _is_index(complex(index)):
        raise JobError(f"--refractive-index {index!r}: allowed Re m > 0 and Im m >= 0, finite")


def write_mstm(task, path: Path, wavelength: float, index: complex) -> list[Path]:
    """The MSTM input file of ``task`` (a :class:`parsim.output.export.TaskSpheres`) at ``path``."""
    m = f"({fortran_real(index.real)},{fortran_real(index.imag)})"
    spheres = "".join(f"{fortran_real(x)},{fortran_real(y)},{fortran_real(z)},{fortran_real(r)},{m}\n"
                      for (x, y, z), r in zip(np.asarray(task.position), np.asarray(task.radius)))
    text = (f"! {task.describe()}\n"
            f"! lengths in {task.length_unit}; length_scale_factor = 2 pi / wavelength, wavelength {wavelength!r} "
            f"{task.length_unit}; refractive index {index.real!r}{index.imag:+}i for every sphere\n"
            f"output_file\n{path.stem}.dat\n"
            f"length_scale_factor\n{fortran_real(2.0 * math.pi / wavelength)}\n"
            f"number_spheres\n{len(task.radius)}\n"
            f"sphere_data\n{spheres}end_of_sphere_data\n"
            "end_of_options\n")
    with written_atomically(path) as temporary:
        temporary.write_text(text, encoding="utf-8")
    return [path]

