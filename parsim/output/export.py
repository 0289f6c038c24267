"""``parsim export``: a job's task files in the formats of other particle programs.

    parsim export OUTPUT [--task LABEL | --all] --format FORMAT [--out PATH]

Reads the documented task-file layout (``spheres/position``, ``spheres/radius``,
``spheres/particle`` or ``spheres/cluster``, the root attributes ``box_lower``,
``box_upper``, ``periodic``; see docs/jobs.md) through
:func:`parsim.output.snapshot.read_configuration`, and writes one file per task:

============  =========================  ================================================
format        file                       read by
============  =========================  ================================================
extxyz        LABEL.xyz                  OVITO, ASE (``ase.io.read``), any extended XYZ reader
lammps        LABEL.data                 LAMMPS ``read_data``, OVITO
vtk           LABEL.vtp (+ JOB.pvd)      ParaView, the ``vtk`` library
csv           LABEL.csv                  parsim's ``agglomerate_file``, spreadsheets, pandas
yade          LABEL.txt                  YADE ``ymport.textExt`` / ``ymport.textClumps``
particles     LABEL_particles.csv and    multi-sphere DEM codes: one rigid body per row,
              LABEL_shapes.csv           the sphere template of each shape (deposition only)
mstm          LABEL.inp                  MSTM, the multiple-sphere T-matrix code (with
                                         ``--wavelength`` and ``--refractive-index``)
============  =========================  ================================================

Discs (aggregation with ``dimension = 2``) are written as spheres at z = 0, in a box whose
z extent is [-R, R] (R the largest radius), so that three-dimensional readers accept them.
Each format is one ``write_<format>(task, path)`` function of :data:`FORMATS`; see
docs/export.md for the commands that load each file.
"""

import argparse
import functools
import io
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable
from xml.sax.saxutils import quoteattr

import numpy as np

from parsim import options
from parsim.errors import JobError, OutputError
from parsim.output import mstm
from parsim.output.atomic import written_atomically
from parsim.output.voxels import image_grid, write_voxels
from parsim.version import __version__

EXPORT_FOLDER = "export"
VESSEL_SUFFIX = "_vessel.vtp"
"""A ``vtk`` export of a task in a mesh vessel writes the vessel's walls beside its spheres, LABEL + this."""
VESSEL_MERGE_RTOL = 1e-9
"""Corners of a vessel's faces closer than this times its size are one point of its surface."""
REAL = "%.17g"
"""Every float is written with 17 significant digits: it reads back as the same double."""


@dataclass(frozen=True)
class TaskSpheres:
    """The spheres of one task file, in three dimensions, as every format writes them.

    ``body`` is each sphere's rigid body: its particle (deposition) or its cluster
    (aggregation), named by ``body_name``.  ``arrays`` and ``attrs`` are the whole task
    file, for the formats that need more (the particle table).
    """

    label: str
    kind: str
    dimension: int
    position: np.ndarray
    radius: np.ndarray
    body: np.ndarray
    body_name: str
    box_lower: np.ndarray
    box_upper: np.ndarray
    periodic: np.ndarray
    arrays: dict
    attrs: dict

    @property
    def length_unit(self) -> str:
        return str(self.attrs.get("length_unit", "m"))

    def describe(self) -> str:
        """One line naming the task, its job, kind and units, for the headers of the LAMMPS and YADE files."""
        return (f"task {self.label} of parsim job {str(self.attrs.get('job_name', ''))!r} ({self.kind}, "
                f"{self.dimension}D, length unit {self.length_unit}), written by parsim {__version__}")


BODY_ARRAYS = {"spheres/particle": ("deposition", "particle"), "spheres/cluster": ("aggregation", "cluster")}


def read_task(path: Path) -> TaskSpheres:
    """The spheres of the task file ``path``; a file that is not one is an error naming it."""
    from parsim.output.snapshot import check_schema, read_configuration

    try:
        configuration = read_configuration(path)
    except (OSError, KeyError) as error:
        raise OutputError(f"cannot read task file {path}: {error}") from None
    check_schema(configuration.attrs, f"task file {path}", path.parent.parent)
    arrays = configuration.arrays
    if "spheres/position" not in arrays or "spheres/radius" not in arrays or not any(map(arrays.__contains__,
                                                                                       BODY_ARRAYS)):
        raise OutputError(f"task file {path} lacks spheres/position, spheres/radius and spheres/particle "
                          "or spheres/cluster: it is not a deposition or aggregation task file")
    return task_spheres(configuration, path.stem)


def task_spheres(configuration, label: str) -> TaskSpheres:
    """The spheres of a :class:`parsim.solver.Configuration` (a task file's, or a task's in memory)."""
    arrays = configuration.arrays
    found = [name for name in BODY_ARRAYS if name in arrays]
    kind, body_name = BODY_ARRAYS[found[0]]
    position = np.asarray(arrays["spheres/position"], dtype=np.float64)
    radius = np.asarray(arrays["spheres/radius"], dtype=np.float64)
    dimension = position.shape[1]
    lower = np.asarray(configuration.box_lower, dtype=np.float64)
    upper = np.asarray(configuration.box_upper, dtype=np.float64)
    periodic = np.asarray(configuration.periodic, dtype=bool)
    if dimension == 2:  # discs: spheres at z = 0 in the slab [-R, R], R the largest radius
        thickness = float(radius.max(initial=0.0))
        position = np.column_stack([position, np.zeros(len(position))])
        lower, upper = np.append(lower, -thickness), np.append(upper, thickness)
        periodic = np.append(periodic, False)
    return TaskSpheres(label=label, kind=kind, dimension=dimension, position=position, radius=radius,
                       body=np.asarray(arrays[found[0]], dtype=np.int64), body_name=body_name, box_lower=lower,
                       box_upper=upper, periodic=periodic, arrays=arrays, attrs=configuration.attrs)


def _rows(columns: list, line_format: str) -> str:
    """``columns`` (equal lengths) as text, one line per row formatted by ``line_format``."""
    buffer = io.StringIO()
    np.savetxt(buffer, np.column_stack(columns), fmt=line_format)
    return buffer.getvalue()


def _write_text(path: Path, text: str) -> list[Path]:
    with written_atomically(path) as temporary:
        temporary.write_text(text, encoding="utf-8")
    return [path]


def _axes(flags) -> str:
    return ", ".join("xyz"[axis] for axis, flag in enumerate(flags) if flag) or "none"


def write_extxyz(task: TaskSpheres, path: Path) -> list[Path]:
    """Extended XYZ: species (``X`` for every sphere), position, radius and body id per line.

    The comment line carries the box as ``Lattice`` (its edge vectors) and ``Origin`` (its
    lower corner, which OVITO reads and ASE keeps in ``atoms.info``), the periodicity as
    ``pbc``, and the task as ``parsim_task``; ``X`` is the placeholder element that ASE and
    OVITO accept for particles that are not atoms.
    """
    edges = np.diag(task.box_upper - task.box_lower)
    lattice = " ".join(REAL % value for value in edges.ravel())
    origin = " ".join(REAL % value for value in task.box_lower)
    pbc = " ".join("T" if flag else "F" for flag in task.periodic)
    header = (f'{len(task.radius)}\nLattice="{lattice}" Origin="{origin}" '
              f"Properties=species:S:1:pos:R:3:radius:R:1:{task.body_name}:I:1 "
              f'pbc="{pbc}" parsim_task={task.label} parsim_kind={task.kind} length_unit={task.length_unit}\n')
    rows = _rows([task.position, task.radius, task.body], f"X {REAL} {REAL} {REAL} {REAL} %d")
    return _write_text(path, header + rows)


def write_lammps(task: TaskSpheres, path: Path) -> list[Path]:
    """A LAMMPS data file for granular work, ``atom_style hybrid sphere bond``.

    ``sphere`` gives each atom its diameter and density (granular pair styles need them),
    ``bond`` adds the molecule ID that ``fix rigid/small molecule`` makes rigid bodies of:
    the LAMMPS manual's fix property/atom page names an atom style that defines molecule IDs
    as the alternative to adding them with ``fix property/atom mol``, and ``bond`` is the
    smallest such style; with it the file is read by ``read_data`` alone.  Atom IDs are
    sphere index + 1, molecule IDs particle (cluster) + 1, since LAMMPS reserves molecule
    ID 0.  The atom type is the shape + 1 (deposition), or 1, and 2 for a sphere alone in
    its cluster (aggregation), since ``fix rigid`` refuses bodies of one sphere.  The
    density gives each sphere its mass by LAMMPS's rule m = 4/3 pi r^3 rho: the task's
    ``spheres/mass`` (aggregation), or 1 where the job has no masses (deposition).
    Positions are those of the task file: ``read_data`` wraps the ones outside a periodic
    box back in and sets their image flags.  The header comment gives the commands to read
    the file, as a data file cannot set the atom style or the boundaries.
    """
    n = len(task.radius)
    masses = task.arrays.get("spheres/mass")
    density = (np.asarray(masses, dtype=np.float64) / (4.0 / 3.0 * np.pi * task.radius**3)
               if masses is not None else np.ones(n))
    if "particles/shape" in task.arrays:
        types, typed = task.arrays["particles/shape"][task.body] + 1, "atom type = shape + 1"
    else:  # fix rigid refuses bodies of one sphere: type 2 tells them apart
        types = np.where(np.bincount(task.body)[task.body] == 1, 2, 1)
        typed = "atom type 1, or 2 for a sphere alone in its cluster"
    boundary = ["p" if flag else "f" for flag in task.periodic]
    if task.dimension == 2:  # LAMMPS wants a 2d box periodic in z, its z bounds straddling 0 (they do)
        boundary[2] = "p"
    commands = [*(["dimension 2"] if task.dimension == 2 else []), "atom_style hybrid sphere bond",
                f"boundary {' '.join(boundary)}", f"read_data {path.name}"]
    comment = "\n".join([
        f"LAMMPS data file of {task.describe()}",
        "# Read it with these commands (a data file cannot set the atom style or the boundaries):",
        *(f"#   {command}" for command in commands),
        f"# Periodic boundaries: {_axes(task.periodic)}; walls or open: {_axes(~task.periodic)}"
        + (" (z: periodic in the boundary command, as LAMMPS requires in 2d)." if task.dimension == 2 else "."),
        f"# One atom per sphere: atom ID = sphere index + 1, molecule ID = {task.body_name} + 1, {typed}.",
        f"# Rigid {task.body_name}s: fix rigid/small molecule on those of two or more spheres (it refuses "
        "one-sphere bodies; a body wider than the ghost cutoff needs comm_modify cutoff),",
        "# with neigh_modify exclude molecule/intra all (the spheres of one body overlap).",
        "# Density: " + ("from the task's sphere masses (m = 4/3 pi r^3 density)." if masses is not None
                         else "1 (deposition has no masses): set your own with 'set type * density D'."),
    ])
    counts = f"\n\n{n} atoms\n{int(types.max())} atom types\n\n"
    bounds = "".join(f"{REAL % low} {REAL % high} {axis}lo {axis}hi\n"
                     for low, high, axis in zip(task.box_lower, task.box_upper, "xyz"))
    atoms = _rows([np.arange(1, n + 1), types, task.position, 2.0 * task.radius, density, task.body + 1],
                  f"%d %d {REAL} {REAL} {REAL} {REAL} {REAL} %d")
    return _write_text(path, comment + counts + bounds + "\nAtoms # hybrid sphere bond\n\n" + atoms)


def _vtk_array(name: str, values: np.ndarray, vtk_type: str, line_format: str, components: int = 1) -> str:
    return (f'<DataArray type="{vtk_type}" Name={quoteattr(name)} NumberOfComponents="{components}" '
            f'NumberOfTuples="{len(values)}" format="ascii">\n{_rows([values], line_format)}</DataArray>\n')


def write_vtk(task: TaskSpheres, path: Path) -> list[Path]:
    """VTK XML PolyData (.vtp): one point per sphere with ``radius`` and the body id as point data.

    Each point is also a vertex cell, so that every ParaView representation shows it; the
    box is field data (``box_lower``, ``box_upper``, ``periodic``), as VTK has no box of its own.
    """
    n = len(task.radius)
    field = (_vtk_array("box_lower", task.box_lower, "Float64", REAL)
             + _vtk_array("box_upper", task.box_upper, "Float64", REAL)
             + _vtk_array("periodic", task.periodic.astype(np.uint8), "UInt8", "%d"))
    text = (
        '<?xml version="1.0"?>\n'
        '<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" header_type="UInt64">\n<PolyData>\n'
        f"<FieldData>\n{field}</FieldData>\n"
        f'<Piece NumberOfPoints="{n}" NumberOfVerts="{n}" NumberOfLines="0" NumberOfStrips="0" NumberOfPolys="0">\n'
        f'<PointData Scalars="radius">\n'
        + _vtk_array("radius", task.radius, "Float64", REAL)
        + _vtk_array(task.body_name, task.body, "Int64", "%d")
        + "</PointData>\n<Points>\n"
        + _vtk_array("Points", task.position, "Float64", f"{REAL} {REAL} {REAL}", components=3)
        + "</Points>\n<Verts>\n"
        + _vtk_array("connectivity", np.arange(n), "Int64", "%d")
        + _vtk_array("offsets", np.arange(1, n + 1), "Int64", "%d")
        + "</Verts>\n</Piece>\n</PolyData>\n</VTKFile>\n")
    written = _write_text(path, text)
    if "vessel_planes" in task.attrs and "vessel_upper" in task.attrs:
        written += write_vessel_vtk(task, path.with_name(f"{path.stem}{VESSEL_SUFFIX}"))
    return written


def write_vessel_vtk(task: TaskSpheres, path: Path) -> list[Path]:
    """A mesh vessel's walls as the kernel took them (VTK XML PolyData, one polygon per face, the floor and
    the box's walls included, up to the rim): the polytope of the task file's ``vessel_planes`` within the
    box of ``vessel_upper``, so that ParaView shows the sediment in its vessel."""
    from parsim.deposition.inside import ConvexInside

    planes = np.asarray(task.attrs["vessel_planes"], dtype=np.float64).reshape(-1, 4)
    upper = np.asarray(task.attrs["vessel_upper"], dtype=np.float64)
    polygons = ConvexInside(planes[:, :3], planes[:, 3], np.zeros(2), upper[:2]).surface(float(upper[2]))
    points, connectivity = _shared_corners(np.concatenate(polygons), VESSEL_MERGE_RTOL * float(np.linalg.norm(upper)))
    offsets = np.cumsum([len(polygon) for polygon in polygons])
    text = (
        '<?xml version="1.0"?>\n'
        '<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" header_type="UInt64">\n<PolyData>\n'
        f'<Piece NumberOfPoints="{len(points)}" NumberOfVerts="0" NumberOfLines="0" NumberOfStrips="0" '
        f'NumberOfPolys="{len(polygons)}">\n<Points>\n'
        + _vtk_array("Points", points, "Float64", f"{REAL} {REAL} {REAL}", components=3)
        + "</Points>\n<Polys>\n"
        + _vtk_array("connectivity", connectivity, "Int64", "%d")
        + _vtk_array("offsets", offsets, "Int64", "%d")
        + "</Polys>\n</Piece>\n</PolyData>\n</VTKFile>\n")
    return _write_text(path, text)


def _shared_corners(corners: np.ndarray, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """The distinct points of polygon ``corners`` (n, 3), each the first corner within ``tolerance`` of it
    (a vertex computed from each of its faces differs by rounding), and each corner's point index: polygons
    that share their corners make one connected surface."""
    first = np.empty(len(corners), dtype=np.int64)
    for start in range(0, len(corners), 1024):
        near = np.linalg.norm(corners[start:start + 1024, None, :] - corners[None, :, :], axis=2) <= tolerance
        first[start:start + 1024] = np.argmax(near, axis=1)
    distinct, index = np.unique(first, return_inverse=True)
    return corners[distinct], index


def write_vtk_collection(files: list[Path], path: Path) -> list[Path]:
    """A ParaView collection (.pvd) of the tasks' .vtp files, task i at "time" i, paths relative to it."""
    entries = "".join(f'<DataSet timestep="{step}" group="" part="0" file={quoteattr(file.name)}/>\n'
                      for step, file in enumerate(files))
    return _write_text(path, '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n'
                             f"<Collection>\n{entries}</Collection>\n</VTKFile>\n")


def write_csv(task: TaskSpheres, path: Path) -> list[Path]:
    """CSV ``x,y,z,r,particle`` (``cluster`` for aggregation): the columns ``agglomerate_file`` reads."""
    header = f"x,y,z,r,{task.body_name}\n"
    return _write_text(path, header + _rows([task.position, task.radius, task.body],
                                            f"{REAL},{REAL},{REAL},{REAL},%d"))


def write_yade(task: TaskSpheres, path: Path) -> list[Path]:
    """YADE's ``x y z r`` text with a fifth column, the particle (cluster) id.

    The first line ``#format x_y_z_r_attrs`` makes ``ymport.textExt`` read the fifth column
    into its ``attrs`` list; ``ymport.textClumps`` reads the same file as clumps, one per id,
    since it groups consecutive lines of equal id: the lines are therefore ordered by id
    (stably: a deposition keeps its order).  Other lines start with ``#``, which both skip;
    no line is blank, which both would fail on.
    """
    order = np.argsort(task.body, kind="stable")
    box = (f"# box lower {' '.join(REAL % v for v in task.box_lower)} upper "
           f"{' '.join(REAL % v for v in task.box_upper)}, periodic along: {_axes(task.periodic)}\n")
    header = f"#format x_y_z_r_attrs\n# {task.describe()}\n{box}# x y z r {task.body_name}\n"
    return _write_text(path, header + _rows([task.position[order], task.radius[order], task.body[order]],
                                            f"{REAL} {REAL} {REAL} {REAL} %d"))


def shape_templates(task: TaskSpheres) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Sphere offsets (k, 3) and radii (k,) of each shape at scale 1, from the task file itself.

    Every particle obeys position = centre of mass + R(q) · scale · offset and radius =
    scale · template radius (docs/jobs.md), so the first particle of each shape gives its
    template, to round-off: the same spheres as the solver's ``particle_shape`` for the task's
    parameters (and as the ``shapes/*`` a task file of output schema 3 stores), with no need of
    the job's input files.  Every other particle is checked against it; a task file that disagrees is refused.
    """
    from parsim.core.structure import rotation_matrices  # here: it compiles kernels, which export needs only here

    arrays = task.arrays
    centre, scale = arrays["particles/center_of_mass"], arrays["particles/scale"]
    shape, matrices = arrays["particles/shape"], rotation_matrices(arrays["particles/rotation"])
    # offset of each sphere in its particle's frame, at scale 1: R^T (x - c) / s
    local = np.einsum("nji,nj->ni", matrices[task.body], task.position - centre[task.body]) / scale[task.body, None]
    templates = {}
    for kind in np.unique(shape):
        first = np.flatnonzero(shape == kind)[0]
        mine = task.body == first
        templates[int(kind)] = (local[mine], task.radius[mine] / scale[first])
    sizes = np.array([len(templates[int(kind)][1]) for kind in shape])
    counts = np.bincount(task.body, minlength=len(shape))
    if np.array_equal(counts, sizes) and np.all(np.diff(task.body) >= 0):
        expected = np.concatenate([templates[int(kind)][0] for kind in shape])
        expected_radius = np.concatenate([templates[int(kind)][1] for kind in shape])
        tolerance = 1e-9 * max(1.0, float(np.abs(task.position).max()))
        if (np.abs(local - expected).max() * scale.max() <= tolerance
                and np.allclose(task.radius, expected_radius * scale[task.body], rtol=1e-12)):
            return templates
    raise OutputError(f"task file of {task.label}: its spheres are not its particles' shapes placed by "
                      f"particles/center_of_mass, particles/rotation and particles/scale, as the deposition "
                      "solver writes them; it cannot be exported as a particle table")


def write_particles(task: TaskSpheres, path: Path) -> list[Path]:
    """The rigid bodies of a deposition: ``LABEL_particles.csv`` and the shape templates ``LABEL_shapes.csv``.

    Particle table: ``particle,shape,scale,x,y,z,qw,qx,qy,qz`` with (x, y, z) the centre of
    mass and q the unit quaternion of its orientation.  Templates: ``shape,name,sphere,dx,dy,dz,r``,
    the sphere offsets from the centre of mass and the radii at scale 1, so that sphere j of a
    particle is at centre + R(q) · scale · (dx, dy, dz) with radius scale · r: what a
    multi-sphere DEM code (clump templates, LIGGGHTS multisphere, LAMMPS molecule files) needs.
    """
    check_particle_table(task)
    arrays = task.arrays
    templates = shape_templates(task)
    names = [str(name) for name in task.attrs.get("shape_names", [])]
    count = len(arrays["particles/scale"])
    table = "particle,shape,scale,x,y,z,qw,qx,qy,qz\n" + _rows(
        [np.arange(count), arrays["particles/shape"], arrays["particles/scale"], arrays["particles/center_of_mass"],
         arrays["particles/rotation"]], "%d,%d," + ",".join([REAL] * 8))
    shapes = "shape,name,sphere,dx,dy,dz,r\n" + "".join(
        f"{kind},{names[kind] if kind < len(names) else ''},{sphere},"
        + ",".join(REAL % value for value in (*offsets[sphere], radii[sphere])) + "\n"
        for kind, (offsets, radii) in templates.items() for sphere in range(len(radii)))
    shapes_path = path.with_name(f"{path.stem.removesuffix('_particles')}_shapes{path.suffix}")
    return _write_text(path, table) + _write_text(shapes_path, shapes)


def check_particle_table(task: TaskSpheres) -> None:
    """Refuse a task that has no particle table: an aggregation, whose clusters have no orientation."""
    if task.kind != "deposition":
        raise JobError(f"format 'particles' is the particle table of a deposition, and {task.label} is an "
                       f"{task.kind} task; its clusters have no orientation: use one of "
                       f"{', '.join(name for name in FORMATS if name != 'particles')}")


@dataclass(frozen=True)
class Format:
    """One export format: the file suffix, its writer and what reads it (for the help); ``check``
    refuses a task the writer would refuse (a JobError), called on every task before any folder
    or file is made, so that a refused export makes nothing."""

    suffix: str
    write: Callable[[TaskSpheres, Path], list[Path]]
    readers: str
    collect: Callable[[list[Path], Path], list[Path]] | None = None
    collection_suffix: str = ""
    check: Callable[[TaskSpheres], object] | None = None


FORMATS: dict[str, Format] = {
    "extxyz": Format(".xyz", write_extxyz, "OVITO, ASE"),
    "lammps": Format(".data", write_lammps, "LAMMPS read_data, OVITO"),
    "vtk": Format(".vtp", write_vtk, "ParaView", collect=write_vtk_collection, collection_suffix=".pvd"),
    "csv": Format(".csv", write_csv, "parsim agglomerate_file, spreadsheets"),
    "yade": Format(".txt", write_yade, "YADE ymport.textExt, ymport.textClumps"),
    "particles": Format("_particles.csv", write_particles, "multi-sphere DEM codes, deposition only",
                        check=check_particle_table),
    "voxels": Format("_voxels.npy", write_voxels, "porespy, OpenPNM (numpy); image tools (.raw + .json, .tif); "
                     "3-D tasks, with --voxel-size", check=image_grid),
    "mstm": Format(".inp", mstm.write_mstm, "MSTM multiple-sphere T-matrix, with --wavelength and --refractive-index"),
}
#: The options of the formats that take any, by the names export_output takes them.
FORMAT_OPTIONS = {"voxels": ("voxel_size", "height"), "mstm": ("wavelength", "refractive_index")}


def _job_folder(output: Path) -> tuple[str, list[Path]]:
    """The job name and task files of the output folder ``output``; any other folder is an error."""
    from parsim.output.folder import TASKS, open_output

    folder, job = open_output(output)
    files = folder.existing_task_files(job)
    if not files:
        raise JobError(f"{output / TASKS} holds no task file yet: a task's file is written when it finishes, if "
                       f"the job keeps its configuration (key configurations; parsim info {output} says how far "
                       "the job got)")
    return job.name, files


def export_output(output: Path, format: str, task: str | None = None, all_tasks: bool = False,
                  out: Path | None = None, voxel_size: float | None = None, height: float | None = None,
                  wavelength: float | None = None, refractive_index: complex | None = None) -> list[Path]:
    """Export the task ``task`` (default: the job's first task that has a task file) or every task of the
    job in ``output`` as ``format``; the files written.

    ``out`` is, for one task, the file to write or a folder to write LABEL + the format's suffix
    in (an existing folder, a path ending in a slash, or a name without a suffix; created if need
    be); for every task, the folder (both default to OUTPUT/export).  A ``vtk`` export of every
    task also writes JOB.pvd, the collection ParaView opens as one series.  ``voxel_size`` and
    ``height`` are those of format ``voxels`` (:mod:`parsim.output.voxels`), ``wavelength`` and
    ``refractive_index`` those of format ``mstm`` (:mod:`parsim.output.mstm`).  Every task is checked
    (the format's ``check``) before the folder is created: a refusal makes nothing.
    """
    if format not in FORMATS:
        raise JobError(f"unknown export format {format!r}; allowed: {', '.join(FORMATS)}")
    spec = FORMATS[format]
    given = {"voxel_size": voxel_size, "height": height, "wavelength": wavelength,
             "refractive_index": refractive_index}
    options = {name: value for name, value in given.items() if value is not None}
    stray = sorted(set(options) - set(FORMAT_OPTIONS.get(format, ())))
    if stray:
        flags = ", ".join("--" + name.replace("_", "-") for name in stray)
        owners = " and ".join(f"{name!r}" for name, names in FORMAT_OPTIONS.items() if set(stray) & set(names))
        raise JobError(f"{flags}: options of format {owners}, not {format!r}")
    if format == "voxels":
        spec = replace(spec, write=functools.partial(spec.write, **options),
                       check=functools.partial(spec.check, **options))
    elif format == "mstm":
        mstm.check_options(wavelength, refractive_index)
        spec = replace(spec, write=functools.partial(spec.write, wavelength=wavelength, index=refractive_index))
    output = Path(output)
    job_name, files = _job_folder(output)
    if all_tasks:
        folder = Path(out) if out is not None else output / EXPORT_FOLDER
        if spec.check is not None:  # each task is read again to be written: only one is held at a time
            for file in files:
                spec.check(read_task(file))
        _make_folder(folder)
        written = []
        for file in files:
            written += spec.write(read_task(file), folder / f"{file.stem}{spec.suffix}")
        if spec.collect is not None:
            written += spec.collect([folder / f"{file.stem}{spec.suffix}" for file in files],
                                    folder / f"{job_name}{spec.collection_suffix}")
        return written
    if task is None:
        chosen = files[0]
    else:
        chosen = files[0].parent / f"{task}.h5"
        if not chosen.is_file():
            shown = ", ".join(file.stem for file in files[:5]) + (f", ... ({len(files)} tasks)" * (len(files) > 5))
            raise JobError(f"no task {task!r} in {chosen.parent}; --task takes one of: {shown} (or give --all)")
    target = Path(out) if out is not None else output / EXPORT_FOLDER
    if out is None or _names_folder(out):
        target = target / f"{chosen.stem}{spec.suffix}"
    chosen_task = read_task(chosen)
    if spec.check is not None:
        spec.check(chosen_task)
    _make_folder(target.parent)
    return spec.write(chosen_task, target)


def _names_folder(out) -> bool:
    """Whether ``out`` (as typed) is a folder: an existing one, a path ending in a slash, or a name
    without a suffix (exports always have one)."""
    text = os.fspath(out)
    return text.endswith(("/", os.sep)) or Path(text).is_dir() or not Path(text).suffix


def _make_folder(folder: Path) -> None:
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise OutputError.from_os_error(error, folder, doing="create") from None


def add_export_command(subparsers) -> None:
    """Declare ``parsim export`` on the command line's ``subparsers``; :func:`run_export` runs it."""
    export = subparsers.add_parser("export", help="write task files for OVITO, ParaView, LAMMPS, YADE, ASE")
    export.add_argument("output", type=options.path, help="output folder of a job")
    which = export.add_mutually_exclusive_group()
    which.add_argument("--task", type=options.name, metavar="LABEL",
                       help="the task to export, its file name in OUTPUT/tasks "
                       "without .h5 (default: the job's first task that has one)")
    which.add_argument("--all", action="store_true", help="export every task (vtk: with a .pvd collection)")
    export.add_argument("--format", required=True, metavar="FORMAT",
                        help="; ".join(f"{name} ({spec.readers})" for name, spec in FORMATS.items()))
    export.add_argument("--voxel-size", type=float, metavar="S",
                        help="format voxels: the voxels' edge, in the task's length unit")
    export.add_argument("--height", type=float, metavar="H",
                        help="format voxels: the image's height above the floor (default: the top of the highest "
                             "sphere)")
    export.add_argument("--wavelength", type=float, metavar="LAMBDA",
                        help="format mstm: the wavelength of the light, in the task's length unit")
    export.add_argument("--refractive-index", type=_refractive_index, metavar="M",
                        help="format mstm: the spheres' complex refractive index, e.g. 1.6+0.6j")
    export.add_argument("--out", type=options.target, metavar="PATH",
                        help="the file to write, or a folder to write LABEL.suffix in (an existing folder, DIR/ "
                             "or a name without a suffix; default OUTPUT/export); with --all, the folder "
                             "(default OUTPUT/export)")


def _refractive_index(text: str) -> complex:
    try:
        return mstm.refractive_index(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def run_export(args: argparse.Namespace) -> int:
    """``parsim export``: write the files and print their paths; errors are one-line ParsimErrors."""
    for path in export_output(args.output, args.format, task=args.task, all_tasks=args.all, out=args.out,
                              voxel_size=args.voxel_size, height=args.height, wavelength=args.wavelength,
                              refractive_index=args.refractive_index):
        print(path)
    return 0
