"""A task's spheres as a solid/void voxel image, for porespy, OpenPNM and image tools.

The image is a boolean array ``void[x, y, z]``, True where the voxel's centre lies in no sphere
(porespy's and OpenPNM's convention: True is pore space).  It spans the box laterally, one voxel
count per axis chosen so that the voxels tile the box exactly (the voxel size is adjusted along x
and y by at most half a voxel over the box), and from the floor up to ``height`` (default: the
top of the highest sphere).  Periodic axes wrap: a sphere across the box's side fills voxels on
both sides.  Voxels outside a cylinder's circle are solid (not pore space).
"""

import io
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from parsim.errors import JobError
from parsim.output.atomic import write_bytes_atomically


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


def voxelize(task, voxel_size: float, height: float | None = None) -> VoxelImage:
    """The voxel image of ``task`` (a :class:`parsim.output.export.TaskSpheres` in 3-D) with voxels
    of about ``voxel_size`` (the task's length unit), up to ``height`` above the floor."""
    from parsim.core.voxels import carve_spheres

    if task.dimension != 3:
        raise JobError(f"format 'voxels' images three-dimensional tasks; {task.label} is {task.dimension}-D: "
                       "use one of extxyz, lammps, vtk, csv, yade")
    if not (np.isfinite(voxel_size) and voxel_size > 0.0):
        raise JobError(f"--voxel-size: must be a length > 0 in the task's unit ({task.length_unit}), got {voxel_size}")
    lower = task.box_lower.astype(np.float64).copy()
    top = float(np.max(task.position[:, 2] + task.radius, initial=lower[2] + voxel_size))
    height = top - lower[2] if height is None else float(height)
    if not (np.isfinite(height) and height > 0.0):
        raise JobError(f"--height: must be a length > 0 in the task's unit ({task.length_unit}), got {height}")
    lateral = task.box_upper[:2] - lower[:2]
    counts = [max(1, int(round(length / voxel_size))) for length in lateral]
    counts.append(max(1, int(np.ceil(height / voxel_size - 1e-9))))
    spacing = np.array([lateral[0] / counts[0], lateral[1] / counts[1], voxel_size])
    void = np.ones(counts, dtype=bool)
    carve_spheres(void, np.ascontiguousarray(task.position), np.ascontiguousarray(task.radius), lower, spacing,
                  np.asarray(task.periodic, dtype=np.bool_))
    _mask_outside_cylinder(void, task, lower, spacing)
    return VoxelImage(void, lower, spacing, task.length_unit)


def _mask_outside_cylinder(void, task, lower, spacing) -> None:
    """Voxels outside a cylinder's circle (about (R, R), radius R) are solid."""
    if str(task.attrs.get("container", "box")) != "cylinder":
        return
    radius = float(task.attrs["container_radius"])
    x = lower[0] + (np.arange(void.shape[0]) + 0.5) * spacing[0] - radius
    y = lower[1] + (np.arange(void.shape[1]) + 0.5) * spacing[1] - radius
    outside = x[:, None] ** 2 + y[None, :] ** 2 > radius**2
    void[outside] = False


def write_voxels(task, path, voxel_size: float | None = None, height: float | None = None) -> list:
    """``path`` (``LABEL_voxels.npy``, the boolean image numpy and porespy load), the same bytes as
    ``.raw`` (uint8, 1 void) with a ``.json`` header, and a ``.tif`` stack (z, y, x) if tifffile is
    installed; each written atomically, as every export is."""
    if voxel_size is None:
        raise JobError("format 'voxels' needs --voxel-size S: the voxels' edge, a length > 0 in the task's unit")
    image = voxelize(task, voxel_size, height)
    stem = str(path)[: -len(".npy")] if str(path).endswith(".npy") else str(path)
    files = {Path(f"{stem}.npy"): _npy_bytes(image.void), Path(f"{stem}.raw"): image.void.astype(np.uint8).tobytes(),
             Path(f"{stem}.json"): json.dumps(image.header(), indent=1).encode()}
    try:
        import tifffile
    except ImportError:
        tifffile = None
    if tifffile is not None:
        stack = io.BytesIO()
        tifffile.imwrite(stack, np.ascontiguousarray(np.transpose(image.void, (2, 1, 0)).astype(np.uint8)))
        files[Path(f"{stem}.tif")] = stack.getvalue()
    for target, data in files.items():
        write_bytes_atomically(target, data)
    return list(files)


def _npy_bytes(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array)
    return buffer.getvalue()
