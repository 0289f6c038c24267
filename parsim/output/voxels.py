"""A task's spheres as a solid/void voxel image, for porespy, OpenPNM and image tools.

The image is a boolean array ``void[x, y, z]``, True where the voxel's centre lies in no sphere
(porespy's and OpenPNM's convention: True is pore space).  It spans the box laterally, one voxel
count per axis chosen so that the voxels tile the box exactly (the voxel size is adjusted along x
and y by at most half a voxel over the box), and from the floor up to ``height`` (default: the
top of the highest sphere).  Periodic axes wrap: a sphere across the box's side fills voxels on
both sides.  Voxels outside a cylinder's circle or behind a mesh vessel's faces are solid (not pore space).

The image is checked before any of it is made (:func:`image_grid`): the voxel size is a length
> 0 at most the box's narrowest side, the height a length > 0, and the image with its temporaries
(:attr:`VoxelGrid.memory`) fits in this machine's physical memory; a refusal names the option
and, for the memory, the smallest voxel size (and largest height) that fits.
"""

import functools
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from parsim.errors import JobError
from parsim.machine import check_memory
from parsim.output.atomic import opened_atomically

#: Bytes per column (x, y) of the temporaries an image is made and written with, beside its byte per
#: voxel: a cylinder's mask (float64 squared distances, then the bool mask) or one TIFF page (uint8).
COLUMN_TEMPORARY_BYTES = 9


@dataclass(frozen=True)
class VoxelImage:
    """``void`` (True: pore space) with the lower corner ``origin`` and the voxel edges ``spacing``."""

    void: np.ndarray
    origin: np.ndarray
    spacing: np.ndarray
    length_unit: str

    @property
    def porosity(self) -> float:
        return float(self.void.mean())

    def header(self) -> dict:
        """The JSON header of the ``.raw`` file: how to read its bytes back."""
        return {"shape": list(self.void.shape), "axes": ["x", "y", "z"], "order": "C", "dtype": "uint8",
                "void": 1, "solid": 0, "origin": self.origin.tolist(), "spacing": self.spacing.tolist(),
                "length_unit": self.length_unit}


@dataclass(frozen=True)
class VoxelGrid:
    """The voxels of an image: ``shape`` voxels of edges ``spacing`` from the lower corner ``origin``."""

    origin: np.ndarray
    spacing: np.ndarray
    shape: tuple[int, int, int]

    @property
    def memory(self) -> int:
        """The bytes the image needs while it is made and written (:func:`_image_bytes`)."""
        return _image_bytes(self.shape)


def image_grid(task, voxel_size: float | None = None, height: float | None = None) -> VoxelGrid:
    """The voxels of the image of ``task`` (a :class:`parsim.output.export.TaskSpheres`) with voxels
    of about ``voxel_size`` (the task's length unit), up to ``height`` above the floor (default: the
    top of the highest sphere); a :class:`JobError` for a task that is not 3-D, a size that is not a
    length > 0 (a voxel size at most the box's narrowest side) or an image larger than the memory."""
    if task.dimension != 3:
        raise JobError(f"format 'voxels' images three-dimensional tasks; {task.label} is {task.dimension}-D: "
                       "use one of extxyz, lammps, vtk, csv, yade")
    if voxel_size is None:
        raise JobError("format 'voxels' needs --voxel-size S: the voxels' edge, a length > 0 in the task's unit")
    lower = task.box_lower.astype(np.float64).copy()
    lateral = [float(length) for length in task.box_upper[:2] - lower[:2]]
    voxel_size = _length(voxel_size, "--voxel-size", task.length_unit, at_most=min(lateral))
    given = height is not None
    if not given:
        height = float(np.max(task.position[:, 2] + task.radius, initial=lower[2] + voxel_size)) - lower[2]
    height = _length(height, "--height", task.length_unit)
    _check_image_memory(lateral, voxel_size, height, given)
    counts = tuple(int(count) for count in _counts(lateral, voxel_size, height))
    return VoxelGrid(lower, np.array([lateral[0] / counts[0], lateral[1] / counts[1], voxel_size]), counts)


def _length(value, option: str, unit: str, at_most: float = math.inf) -> float:
    """``value`` as a finite length > 0 and at most ``at_most``, or a JobError naming ``option``."""
    try:
        length = float(value)
    except (TypeError, ValueError):
        length = math.nan
    if not (math.isfinite(length) and 0.0 < length <= at_most):
        bound = f" and at most the box's narrowest side, {at_most:.6g}," if math.isfinite(at_most) else ""
        raise JobError(f"{option}: must be a length > 0{bound} in the task's unit ({unit}), got {value}")
    return length


def _counts(lateral: list[float], voxel_size: float, height: float) -> list[float]:
    """The voxels along x and y (tiling the box's sides) and z (reaching ``height``), as floats:
    infinite for a voxel too small to count them, so that the memory check refuses it."""
    return ([float(np.rint(length / voxel_size)) for length in lateral]
            + [max(1.0, float(np.ceil(height / voxel_size - 1e-9)))])


def _image_bytes(counts) -> float:
    """The bytes an image of ``counts`` voxels needs at most while it is made and written: one per
    voxel (the bool image, written from itself) and COLUMN_TEMPORARY_BYTES per column."""
    return counts[0] * counts[1] * (counts[2] + COLUMN_TEMPORARY_BYTES)


def _check_image_memory(lateral: list[float], voxel_size: float, height: float, height_given: bool) -> None:
    """Refuse an image larger than this machine's memory, naming the smallest voxel size that fits
    and, if the height was given, the largest height."""
    def remedy(memory: int) -> str:
        def size_fits(size):
            return size <= min(lateral) and _image_bytes(_counts(lateral, size, height)) <= memory

        def height_fits(top):
            return _image_bytes(_counts(lateral, voxel_size, top)) <= memory

        limits = [("--voxel-size", _limit(size_fits, voxel_size, min(lateral)), "more")]
        if height_given:  # one voxel high is the lowest image
            limits.append(("--height", _limit(height_fits, height, voxel_size), "less"))
        advice = [f"{option} {value} or {direction}" for option, value, direction in limits if value is not None]
        return f"give {', or '.join(advice)}" if advice else ""

    counts = _counts(lateral, voxel_size, height)
    check_memory(_image_bytes(counts), "the voxel image",
                 f"--voxel-size {voxel_size:.6g} and --height {height:.6g}: {' x '.join(f'{n:.4g}' for n in counts)} "
                 "voxels", remedy)


def _limit(fits: Callable[[float], bool], refused: float, bound: float) -> str | None:
    """The value nearest ``refused`` that ``fits`` (true from some point on the way to ``bound``,
    false at ``refused``) as it is typed: three significant digits if these fit too, else every
    digit; None if ``bound`` does not fit."""
    if not fits(bound):
        return None
    inside = bound
    for _ in range(200):  # geometric bisection: the two may be hundreds of orders of magnitude apart
        middle = math.sqrt(refused) * math.sqrt(inside)
        if middle in (refused, inside):
            break
        if fits(middle):
            inside = middle
        else:
            refused = middle
    unit = 10.0 ** (math.floor(math.log10(inside)) - 2)
    rounded = f"{(math.ceil if bound > inside else math.floor)(inside / unit) * unit:.3g}"
    return rounded if fits(float(rounded)) else repr(inside)


def voxelize(task, voxel_size: float, height: float | None = None) -> VoxelImage:
    """The voxel image of ``task`` (a :class:`parsim.output.export.TaskSpheres` in 3-D) on the voxels
    :func:`image_grid` gives, which refuses what cannot be imaged."""
    from parsim.core.voxels import carve_spheres

    grid = image_grid(task, voxel_size, height)
    void = np.ones(grid.shape, dtype=bool)
    carve_spheres(void, np.ascontiguousarray(task.position), np.ascontiguousarray(task.radius), grid.origin,
                  grid.spacing, np.asarray(task.periodic, dtype=np.bool_))
    _mask_outside_cylinder(void, task, grid.origin, grid.spacing)
    _mask_outside_vessel(void, task, grid.origin, grid.spacing)
    return VoxelImage(void, grid.origin, grid.spacing, task.length_unit)


def _mask_outside_cylinder(void, task, lower, spacing) -> None:
    """Voxels outside a cylinder's circle (about (R, R), radius R) are solid; the mask is one
    layer, applied in place (no temporary as large as the image)."""
    if str(task.attrs.get("container", "box")) != "cylinder":
        return
    radius = float(task.attrs["container_radius"])
    x = lower[0] + (np.arange(void.shape[0]) + 0.5) * spacing[0] - radius
    y = lower[1] + (np.arange(void.shape[1]) + 0.5) * spacing[1] - radius
    inside = x[:, None] ** 2 + y[None, :] ** 2 <= radius**2
    void &= inside[:, :, None]


def _mask_outside_vessel(void, task, lower, spacing) -> None:
    """Voxels behind a mesh vessel's faces (``N . x < c`` at their centres) are solid, a layer at a time."""
    if str(task.attrs.get("container", "box")) != "mesh":
        return
    planes = np.asarray(task.attrs["vessel_planes"], dtype=np.float64).reshape(-1, 4)
    x = lower[0] + (np.arange(void.shape[0]) + 0.5) * spacing[0]
    y = lower[1] + (np.arange(void.shape[1]) + 0.5) * spacing[1]
    for k in range(void.shape[2]):
        z = lower[2] + (k + 0.5) * spacing[2]
        for nx, ny, nz, c in planes:
            void[:, :, k] &= nx * x[:, None] + ny * y[None, :] + nz * z >= c


def write_voxels(task, path, voxel_size: float | None = None, height: float | None = None) -> list:
    """``path`` (``LABEL_voxels.npy``, the boolean image numpy and porespy load), the same bytes as
    ``.raw`` (uint8, 1 void) with a ``.json`` header, and a ``.tif`` stack (z, y, x) if tifffile is
    installed; each written atomically, as every export is, straight from the image (the TIFF a
    page at a time), so that the image is the only large thing held."""
    image = voxelize(task, voxel_size, height)
    stem = str(path)[: -len(".npy")] if str(path).endswith(".npy") else str(path)
    header = json.dumps(image.header(), indent=1).encode()
    writers = {Path(f"{stem}.npy"): functools.partial(np.save, arr=image.void),
               Path(f"{stem}.raw"): image.void.view(np.uint8).tofile,
               Path(f"{stem}.json"): lambda file: file.write(header)}
    try:
        import tifffile
    except ImportError:
        tifffile = None
    if tifffile is not None:
        writers[Path(f"{stem}.tif")] = functools.partial(_write_tiff, tifffile, image.void)
    for target, write in writers.items():
        with opened_atomically(target) as file:
            write(file)
    return list(writers)


def _write_tiff(tifffile, void: np.ndarray, file) -> None:
    """``void`` as a uint8 TIFF stack ordered z, y, x, written a page (one z) at a time."""
    pages = (np.ascontiguousarray(void[:, :, k].T).view(np.uint8) for k in range(void.shape[2]))
    tifffile.imwrite(file, pages, shape=void.shape[::-1], dtype=np.uint8)
