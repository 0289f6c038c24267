"""Jobs in mesh vessels (``container = "mesh"``): an open box read from a mesh is the walled box bit for
bit, the hopper job spread over ranks is its serial sediment, and bad vessel files are refused with one
line naming the key."""

import json
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from parsim.deposition.vessel import box_mesh, hopper_mesh, read_vessel

REPOSITORY = Path(__file__).resolve().parent.parent
SEARCH = REPOSITORY / "benchmarks" / "spread_equivalence.py"

JOB = """name = "{name}"
kind = "deposition"
seed = 7
realizations = 1
output = "{output}"

[parameters]
n_particles = {n_particles}
shape = "{shape}"
shape_size = 3
floor = "roll"
{container}
"""


def _run(tmp_path, name, container):
    job = tmp_path / f"{name}.toml"
    job.write_text(JOB.format(name=name, output=(tmp_path / name).as_posix(), container=container, shape="rod",
                              n_particles=150))
    done = subprocess.run([sys.executable, "-m", "parsim.cli", "run", str(job)], capture_output=True, text=True,
                          timeout=600, cwd=tmp_path)
    return done, tmp_path / name


def _solved(tmp_path, name, container, stream, shape="rod", n_particles=150):
    """The job's one task solved in this process, as the runner solves it, from the random ``stream``."""
    from mpi4py import MPI

    from parsim.deposition.solver import SOLVER
    from parsim.job import parse_job
    from parsim.solvers import SOLVERS

    job = parse_job(JOB.format(name=name, output=(tmp_path / name).as_posix(), container=container, shape=shape,
                              n_particles=n_particles), SOLVERS, output=tmp_path / name)
    (task,) = job.tasks()
    return SOLVER.solve(job.point_parameters(task.point), np.random.default_rng(stream), MPI.COMM_SELF)


def test_an_open_box_read_from_a_mesh_is_the_walled_box_bit_for_bit(tmp_path):
    """The box's bottom is the floor and its sides the walls: no face is left, and from the same random
    stream (the particles drawn alike, dropped at the same places) the sediment is the walled box's in
    every bit, and so are its statistics but for the rounding of the volumes."""
    box_mesh(9.0, 9.0, 12.0).export(tmp_path / "box.stl")
    assert len(read_vessel(tmp_path / "box.stl").levels) == 0
    walled = _solved(tmp_path, "walled", 'lateral = "walls"\nbox_length = 9.0', 11)
    meshed = _solved(tmp_path, "meshed", f'container = "mesh"\ncontainer_file = "{tmp_path / "box.stl"}"', 11)
    for key in ("spheres/position", "spheres/radius", "particles/rotation", "particles/state",
                "particles/event_counts", "particles/center_of_mass"):
        assert walled.configuration.arrays[key].tobytes() == meshed.configuration.arrays[key].tobytes(), key
    # the statistics: the box's volumes as the vessel's (Simpson's rule of a constant section), to rounding
    from parsim.deposition.solver import SOLVER

    assert walled.statistics.keys() == meshed.statistics.keys()
    timings = {statistic.name for statistic in SOLVER.statistics if statistic.measured}
    for key, value in walled.statistics.items():
        if key in timings:
            continue
        np.testing.assert_allclose(meshed.statistics[key], value, rtol=1e-12, atol=0, equal_nan=True, err_msg=key)


def test_a_closed_vessel_is_refused_naming_its_key(tmp_path):
    """A watertight mesh has no opening to drop into: one line naming container_file, no task run."""
    import trimesh

    trimesh.creation.box(extents=(9.0, 9.0, 9.0)).export(tmp_path / "closed.stl")
    done, output = _run(tmp_path, "closed", f'container = "mesh"\ncontainer_file = "{tmp_path / "closed.stl"}"')
    assert done.returncode != 0
    assert "container_file" in done.stderr and "opening" in done.stderr, done.stderr
    assert not (output / "tasks").exists() or not list((output / "tasks").glob("*.h5"))


def test_the_hopper_job_spread_over_two_ranks_is_its_serial_sediment(tmp_path):
    """jobs/hopper.toml settled as one sediment spread over two blocks (with random delays before every
    message) and serially: every field of the sediment equal, bit for bit."""
    report_path = tmp_path / "report.json"
    done = subprocess.run([sys.executable, str(SEARCH), "--one", str(REPOSITORY / "jobs" / "hopper.toml"),
                           "--ranks", "2", "--jitter", "2e-5", "--timeout", "300", "--work", str(tmp_path / "work"),
                           "--report", str(report_path)], capture_output=True, text=True, timeout=1200,
                          cwd=REPOSITORY)
    assert report_path.exists(), done.stdout + done.stderr
    report = json.loads(report_path.read_text())
    assert not report["serial_errors"], report["serial_errors"]
    tally = report["ranks"]["2"]
    assert tally == {**tally, "run": 1, "split": 1, "divergent": 0, "failed": 0}, done.stdout


def test_the_hopper_job_keeps_every_sphere_inside_its_vessel(tmp_path):
    """Every sphere of the hopper's sediment lies behind every face of the funnel and the collar, every
    particle is at rest on its contacts (tests/sediment_checks.py: no fall, slide or rotation lowers it
    unblocked), and its voxel image counts the space behind the faces as solid: no void voxel outside the
    vessel, and every voxel inside the vessel that no sphere covers is void."""
    from parsim.core.sdbd import FLOOR_ROLL, LATERAL_WALLS
    from parsim.output.export import read_task
    from parsim.output.voxels import voxelize
    from tests.sediment_checks import check_sediment

    done = subprocess.run([sys.executable, "-m", "parsim.cli", "run", str(REPOSITORY / "jobs" / "hopper.toml"),
                           "--output", str(tmp_path / "hopper")], capture_output=True, text=True, timeout=600,
                          cwd=REPOSITORY)
    assert done.returncode == 0, done.stderr
    vessel = read_vessel(REPOSITORY / "jobs" / "data" / "hopper.obj")
    for task in sorted((tmp_path / "hopper" / "tasks").glob("*.h5")):
        with h5py.File(task) as f:
            position, radius = f["spheres/position"][()], f["spheres/radius"][()]
            assert np.all(vessel.inside(position, radius - 1e-9)), task
            assert f.attrs["vessel_volume"] == vessel.volume
            problems = check_sediment(position, radius, f["spheres/particle"][()], f["particles/center_of_mass"][()],
                                      f["particles/state"][()], (0.0, 0.0), vessel.upper[:2], LATERAL_WALLS,
                                      FLOOR_ROLL, "frictionless", faces=(vessel.normals, vessel.levels))
            assert not problems, (task, problems)
        image = voxelize(read_task(task), 0.5)
        axes = [image.origin[k] + (np.arange(image.void.shape[k]) + 0.5) * image.spacing[k] for k in range(3)]
        centres = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        inside = vessel.inside(centres, np.zeros(len(centres))).reshape(image.void.shape)
        assert not np.any(image.void & ~inside)
        covered = np.zeros(len(centres), dtype=bool)
        for centre, r in zip(position, radius):
            covered |= np.sum((centres - centre) ** 2, axis=1) <= r * r
        assert np.array_equal(image.void, inside & ~covered.reshape(image.void.shape))


def _slab_volumes(position, radius, low, high):
    """The spheres' volume between heights ``low`` and ``high``: pi (r^2 t - t^3 / 3) between the clipped
    heights t = z - z_c of each sphere, summed (spheres that do not overlap)."""
    a = np.clip(low - position[:, 2], -radius, radius)
    b = np.clip(high - position[:, 2], -radius, radius)
    return float(np.sum(np.pi * (radius**2 * (b - a) - (b**3 - a**3) / 3.0)))


def test_packing_in_a_hopper_is_the_spheres_volume_over_the_vessels(tmp_path):
    """600 spheres in an octagonal hopper: the filling height is where the vessel filled uniformly has the
    spheres' centre of mass (the tetrahedra of its facets), each slab's phi(z) is the spheres' volume in it
    over the vessel's (the divergence theorem over the polytope's facets), and the bulk's phi is the volume in the bulk slab of
    the spheres whose centres lie 4 diameters inside every face and wall, over that region's volume in the
    slab.  (Frictionless faces leave a crater: the spheres that slide down them pile up against them.)"""
    from parsim.deposition.statistics import BULK_SLAB, BULK_WALL_DIAMETERS, PROFILE_TOP
    from tests.mesh_files import write
    from tests.polytopes import centroid_height, facet_volume

    path = write(hopper_mesh(10.0, 6.0, 6.0, 8), tmp_path, "hopper.obj")
    vessel = read_vessel(path)
    result = _solved(tmp_path, "spheres", f'container = "mesh"\ncontainer_file = "{path}"', 5,
                     shape="sphere", n_particles=600)
    arrays, statistics = result.configuration.arrays, result.statistics
    position, radius = arrays["spheres/position"], arrays["spheres/radius"]
    inside = vessel.convex_inside()
    h = statistics["filling_height"]
    # the vessel filled uniformly to h has the spheres' centre of mass (equal spheres: their mean height)
    assert centroid_height(inside, 0.0, h) == pytest.approx(np.mean(position[:, 2]), rel=1e-9)
    edges = np.linspace(0.0, PROFILE_TOP * h, len(statistics["packing_profile"]) + 1)
    expected = [_slab_volumes(position, radius, low, high) / facet_volume(inside, low, high)
                for low, high in zip(edges[:-1], edges[1:])]
    np.testing.assert_allclose(statistics["packing_profile"], expected, rtol=1e-9)

    distance = BULK_WALL_DIAMETERS * 2.0 * float(radius[0])
    low, high = BULK_SLAB[0] * h, BULK_SLAB[1] * h
    behind_faces = np.all(position @ vessel.normals.T >= vessel.levels + distance, axis=1)
    within_walls = np.all((position[:, :2] >= distance) & (position[:, :2] <= vessel.upper[:2] - distance), axis=1)
    in_region = behind_faces & within_walls
    assert statistics["n_bulk_particles"] == np.sum(in_region & (position[:, 2] >= low) & (position[:, 2] < high)) > 10
    # the spheres of every particle over the bulk's region, clipped to the slab (as over a walled box's area)
    phi = (_slab_volumes(position[in_region], radius[in_region], low, high)
           / facet_volume(inside.shrunk(distance), low, high))
    assert statistics["bulk_packing_fraction"] == pytest.approx(phi, rel=1e-9)


def test_a_drop_disc_pours_a_heap_where_it_lies(tmp_path):
    """Poured over the whole opening of a hopper with frictionless faces, 400 spheres leave a crater (those
    sliding down the faces pile up against them); poured through a disc of radius 1 at the opening's
    centroid they heap up on the axis, and through a disc near one face, at that face."""
    from tests.mesh_files import write

    path = write(hopper_mesh(10.0, 6.0, 6.0, 8), tmp_path, "hopper.obj")
    axis = read_vessel(path).opening_centroid()
    np.testing.assert_allclose(axis, 10.0 * np.cos(np.pi / 8.0), rtol=1e-12)  # the apothem: the box's middle

    def top(extra):
        container = f'container = "mesh"\ncontainer_file = "{path}"{extra}'
        position = _solved(tmp_path, "poured", container, 5, shape="sphere", n_particles=400).configuration.arrays[
            "spheres/position"]
        return position[np.argsort(position[:, 2])[-10:]]

    assert np.all(np.hypot(*(top("")[:, :2] - axis).T) > 5.0)
    central = top("\ndrop_area_radius = 1.0")
    assert np.all(np.hypot(*(central[:, :2] - axis).T) < 2.0) and central[:, 2].min() > 6.0  # above the rim
    aside = top(f"\ndrop_area_radius = 1.5\ndrop_area_x = 4.0\ndrop_area_y = {axis[1]}")
    assert np.all(np.hypot(aside[:, 0] - 4.0, aside[:, 1] - axis[1]) < 2.5)


def test_a_drop_disc_out_of_the_opening_or_without_its_radius_is_refused(tmp_path):
    box_mesh(9.0, 9.0, 12.0).export(tmp_path / "box.stl")
    vessel = f'container = "mesh"\ncontainer_file = "{tmp_path / "box.stl"}"'
    done, _ = _run(tmp_path, "outside", f"{vessel}\ndrop_area_radius = 2.0\ndrop_area_x = 20.0")
    assert done.returncode == 2
    assert "drop_area_radius = 2.0: the drop disc about (20, 4.5) holds no place" in done.stderr
    done, _ = _run(tmp_path, "centre", f"{vessel}\ndrop_area_y = 3.0")
    assert done.returncode == 2 and "drop_area_y = 3.0: the centre of the drop disc needs its radius" in done.stderr
    done, _ = _run(tmp_path, "radius", f"{vessel}\ndrop_area_radius = -1.0")
    assert done.returncode == 2 and "drop_area_radius = -1.0 is out of range" in done.stderr


def test_a_vtk_export_shows_the_vessel_with_its_opening_at_the_rim(tmp_path):
    """The vessel's walls written beside the spheres, read back by VTK: its surface area is the mesh
    file's (trimesh), and its only boundary is the opening, one loop at the rim's height."""
    pytest.importorskip("vtkmodules.vtkIOXML", reason="the readers extra is not installed")
    import trimesh
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkFiltersCore import vtkFeatureEdges, vtkTriangleFilter
    from vtkmodules.vtkFiltersCore import vtkMassProperties
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

    from parsim.output.export import VESSEL_SUFFIX, export_output

    mesh_file = REPOSITORY / "jobs" / "data" / "hopper.obj"
    done, output = _run(tmp_path, "exported", f'container = "mesh"\ncontainer_file = "{mesh_file}"')
    assert done.returncode == 0, done.stderr
    written = export_output(output, "vtk", out=tmp_path / "export")
    (walls,) = [path for path in written if path.name.endswith(VESSEL_SUFFIX)]
    reader = vtkXMLPolyDataReader()
    reader.SetFileName(str(walls))
    reader.Update()
    triangles = vtkTriangleFilter()
    triangles.SetInputConnection(reader.GetOutputPort())
    area = vtkMassProperties()
    area.SetInputConnection(triangles.GetOutputPort())
    area.Update()
    assert area.GetSurfaceArea() == pytest.approx(trimesh.load(mesh_file, force="mesh").area, rel=1e-9)
    edges = vtkFeatureEdges()
    edges.SetInputConnection(triangles.GetOutputPort())
    for feature in ("FeatureEdges", "NonManifoldEdges", "ManifoldEdges"):
        getattr(edges, f"{feature}Off")()
    edges.BoundaryEdgesOn()
    edges.Update()
    rim = read_vessel(mesh_file).upper[2]
    boundary = vtk_to_numpy(edges.GetOutput().GetPoints().GetData())
    np.testing.assert_allclose(boundary[:, 2], rim, rtol=0, atol=1e-9 * rim)
