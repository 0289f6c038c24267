"""A job is checked completely before anything is created: its name, its input files, every size
it sets (through the memory estimates) and whatever the deposition kernel would refuse."""

import math
import re

import h5py
import numpy as np
import pytest

import parsim.machine
from parsim.errors import JobError
from parsim.job import MAX_NAME_BYTES, parse_job
from parsim.runner import task_attributes
from parsim.solvers import SOLVERS
from parsim.deposition.solver import PARAMETERS, container_sides
from parsim.deposition.materials import species_of

DEPOSITION = 'name = "d"\nkind = "deposition"\nseed = 1\nrealizations = 1\n[parameters]\nn_particles = 4\n'


def parse(text: str):
    return parse_job(text, SOLVERS, source="job.toml")


def refused(text: str, *fragments: str) -> str:
    """The one-line message refusing ``text``, which must hold every fragment."""
    with pytest.raises(JobError) as error:
        parse(text)
    message = str(error.value)
    assert "\n" not in message
    for fragment in fragments:
        assert fragment in message, (fragment, message)
    return message


@pytest.mark.parametrize("name, problem", [
    ("a\\u0000b", "NUL"), ("two\\nlines", "newline"), ("tab\\tbed", "tab"), ("a/b", "slash"), ("a\\\\b", "backslash"),
    (".hidden", "leading dot"), ("", "empty"), ("n" * (MAX_NAME_BYTES + 1), "long"),
    ("é" * (MAX_NAME_BYTES // 2 + 1), "long in UTF-8 bytes")])
def test_a_name_that_no_file_can_have_is_refused(name, problem):
    refused(DEPOSITION.replace('"d"', f'"{name}"'), "name = ", f"1 to {MAX_NAME_BYTES} bytes")


def test_the_longest_name_is_a_file_name():
    assert parse(DEPOSITION.replace('"d"', f'"{"é" * (MAX_NAME_BYTES // 2)}"')).name == "é" * (MAX_NAME_BYTES // 2)


@pytest.mark.parametrize("output", ['""', '"a\\u0000b"', f'"{"o" * 256}/x"', f'"{"o/" * 2100}"'])
def test_an_output_path_no_file_system_holds_is_refused(output):
    refused(DEPOSITION.replace("[parameters]", f"output = {output}\n[parameters]"), "output = ")


@pytest.mark.parametrize("value", ["9" * 5000, "-" + "9" * 5000, "[1, " + "9" * 5000 + "]"])
def test_an_integer_of_thousands_of_digits_is_refused_naming_its_key(value):
    refused(DEPOSITION.replace("seed = 1", f"seed = {value}"), "seed = an integer of 5000 digits", "64 bits")


def agglomerate_job(path) -> str:
    return DEPOSITION + f'shape = "agglomerate"\nagglomerate_file = "{path}"\n'


def test_a_csv_header_naming_a_column_twice_is_refused(tmp_path):
    for header, repeated in (("x,y,z,r,r", "['r']"), ("x,X,y,z,r", "['x']")):
        path = tmp_path / "twice.csv"
        path.write_text(f"{header}\n0,0,0,0,1\n1,0,0,0,1\n")
        refused(agglomerate_job(path), f"agglomerate_file = '{path}'", repeated, "more than once")


def write_hdf5(path, **arrays):
    with h5py.File(path, "w") as file:
        for name, array in arrays.items():
            file.create_dataset(name.replace("__", "/"), data=array)
    return path


@pytest.mark.parametrize("arrays, message", [
    ({"spheres__position": np.zeros((2, 3)), "spheres__radius": np.ones((2, 1))}, "spheres/radius of shape (2, 1)"),
    ({"spheres__position": np.zeros((2, 3)), "spheres__radius": np.ones(2, dtype=bool)},
     "spheres/radius must be a dataset of numbers"),
    ({"spheres__position": np.zeros((2, 3)), "spheres__radius": np.ones(2) * 1e31}, "beyond 1e+30"),
])
def test_hdf5_agglomerates_of_the_wrong_shape_or_type_are_refused(tmp_path, arrays, message):
    path = write_hdf5(tmp_path / "a.h5", **arrays)
    refused(agglomerate_job(path), f"agglomerate_file = '{path}'", message)


def substrate_job(path, extra: str = "box_length = 5.0\n") -> str:
    return DEPOSITION + extra + f'substrate = "{path}"\n'


def test_a_substrate_whose_groups_differ_in_dimension_is_refused(tmp_path):
    path = write_hdf5(tmp_path / "s.h5", substrate__position=np.ones((1, 3)), substrate__radius=np.full(1, 0.5),
                      spheres__position=np.ones((1, 2)), spheres__radius=np.full(1, 0.5))
    refused(substrate_job(path), "substrate = ", "different numbers of columns")


@pytest.mark.parametrize("content, extra, fragments", [
    ("x,y,z,r\n1,1,-0.5,0.5\n", "box_length = 5.0\n", ("substrate = ", "substrate sphere 0", "z >= 0")),
    ("x,y,z,r\n2,2,1,0.5\n0.2,2,1,0.5\n", 'box_length = 5.0\nlateral = "walls"\n',
     ("substrate = ", "substrate sphere 1", "inside the walls")),
    ("x,y,z,r\n10,10,1,0.5\n", 'container = "cylinder"\ncontainer_radius = 5.0\n', ("substrate sphere 0", "walls")),
    ("x,y,z,r\n1,1,2,2\n", "box_length = 5.0\n", ("box_length = 5.0", "four times the largest sphere radius (4 x 2)")),
])
def test_a_substrate_the_kernel_would_refuse_is_refused_before_anything_runs(tmp_path, content, extra, fragments):
    path = tmp_path / "substrate.csv"
    path.write_text(content)
    refused(substrate_job(path, extra), *fragments)


def test_a_periodic_box_narrower_than_four_sphere_radii_is_refused():
    """Twice the extent of a sphere (its diameter) fits; the kernel's minimum images need four radii."""
    refused(DEPOSITION + "box_length = 1.5\n", "box_length = 1.5", "four times the largest sphere radius")
    assert parse(DEPOSITION + "box_length = 2.01\n")


def test_a_size_factor_that_outgrows_the_box_names_the_size_distribution():
    refused(DEPOSITION + 'box_length = 50.0\nsize_distribution = "lognormal"\nsize_spread = 1.0\n',
            "box_length = 50.0", "size_distribution = 'lognormal' gives size factors up to 403.4")


def test_a_cylinder_too_wide_for_its_automatic_sides_is_refused_naming_its_radius():
    refused(DEPOSITION + 'container = "cylinder"\ncontainer_radius = 1e9\n', "container_radius = 1000000000.0",
            "automatic container_sides would be")


def test_the_sediment_grid_of_a_large_box_enters_the_memory_estimate():
    refused(DEPOSITION + 'container = "cylinder"\ncontainer_radius = 1e5\ncontainer_sides = 100000\n',
            "one task needs about", "container_radius=100000.0", "grid cell of 1")
    refused(DEPOSITION + "box_length = 1e6\n", "one task needs about", "box_length=1000000.0")


def test_the_dataset_of_every_task_enters_the_memory_estimate(monkeypatch):
    monkeypatch.setattr(parsim.machine, "physical_memory", lambda: 100 << 20)
    text = DEPOSITION.replace("realizations = 1", "realizations = 1000") + "box_length = 5.0\nprofile_bins = 10000\n"
    refused(text, "the dataset needs about", "1000 tasks x", "profile_bins=10000")
    assert parse(text.replace("profile_bins = 10000", "profile_bins = 50"))


def test_a_mesh_file_too_large_to_build_in_memory_is_refused_before_it_is_read(tmp_path, monkeypatch):
    monkeypatch.setattr(parsim.machine, "physical_memory", lambda: 100 << 20)
    path = tmp_path / "large.stl"
    path.write_bytes(b"\0" * (4 << 20))  # not even a mesh: it is never read
    refused(DEPOSITION + f'box_length = 5.0\nshape = "mesh"\nmesh_file = "{path}"\n', "one task needs about",
            f"mesh_file='{path}'")


def test_a_cylinder_is_flat_to_a_hundredth_of_the_smallest_sphere_any_size_factor_gives():
    params = {p.name: p.default for p in PARAMETERS}
    params.update(n_particles=10, container="cylinder", container_radius=10.0, size_distribution="uniform",
                  size_spread=0.5)
    sides = container_sides(params, species_of(params))
    smallest = 0.5 * (1.0 - 0.5)  # sphere_radius at the smallest size factor
    assert 10.0 * (1.0 - math.cos(math.pi / sides)) <= 0.01 * smallest
    assert 10.0 * (1.0 - math.cos(math.pi / (sides - 1))) > 0.01 * smallest


def test_a_cylinders_task_file_records_its_container_and_not_the_unused_lateral():
    job = parse(DEPOSITION + 'container = "cylinder"\ncontainer_radius = 5.0\n')
    attributes = task_attributes(job, job.tasks()[0])
    assert attributes["container"] == "cylinder" and attributes["container_radius"] == 5.0
    assert "lateral" not in attributes and "box_length" not in attributes and "drop_radius" not in attributes
    boxed = parse(DEPOSITION + 'lateral = "walls"\nbox_length = 5.0\n')
    assert task_attributes(boxed, boxed.tasks()[0])["lateral"] == "walls"


def test_a_particle_that_takes_seconds_to_build_says_so(capsys, monkeypatch):
    import parsim.progress

    monkeypatch.setattr(parsim.progress, "ANNOUNCED_PREPARATION_SECONDS", 0.0)
    monkeypatch.setattr(parsim.progress, "PREPARATION_INTERVAL", 0.05)
    parse(DEPOSITION + 'box_length = 20.0\nshape = "ellipsoid"\nshape_spheres = 1499\n')
    lines = [line for line in capsys.readouterr().err.splitlines() if "ellipsoid" in line]
    assert re.fullmatch(r"parsim: building the ellipsoid particle of 1499 spheres \(about \d\d:\d\d\)\.\.\.", lines[0])
    assert re.fullmatch(r"parsim: building the ellipsoid particle of 1499 spheres: done in \d\d:\d\d", lines[-1])
