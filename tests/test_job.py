"""Job files: what is accepted, and the message for what is not; the job's identity in its output folder."""

import hashlib
import json
import re
import subprocess
import sys
import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest

import parsim
from parsim.agglomerate_file import read_agglomerate
from parsim.errors import JobError
from parsim.job import load_job, parse_job
from parsim.output.dataset import all_statistics, build_dataset, row_layout
from parsim.output.folder import OutputFolder
from parsim.output.rows import read_rows
from parsim.output.snapshot import OUTPUT_SCHEMA, write_task_file
from parsim.solver import Configuration, TaskResult
from parsim.solvers import SOLVERS

BASE = """
name = "t"
kind = "aggregation"
seed = 7
realizations = 2
output = "out"
[parameters]
radius = 0.2
[sweep]
n_spheres = [100, 400]
volume_fraction = [0.1, 0.2, 0.3]
"""

DEPOSITION = """
name = "d"
kind = "deposition"
seed = 1
realizations = 1
[parameters]
n_particles = 10
box_length = 20.0
"""

TWO_SPHERES = "x,y,z,r\n0,0,0,1\n1.5,0,0,1\n"


def parse(text):
    return parse_job(text, SOLVERS, source="job.toml")


def test_quickstart_is_valid():
    job = load_job("jobs/quickstart.toml", SOLVERS)
    assert job.kind == "aggregation"
    assert job.n_points * job.realizations == len(job.tasks())


def test_grid_order_and_defaults():
    job = parse(BASE)
    assert job.sweep_shape == (2, 3)
    assert job.point_parameters(0)["n_spheres"] == 100 and job.point_parameters(0)["volume_fraction"] == 0.1
    assert job.point_parameters(4)["n_spheres"] == 400 and job.point_parameters(4)["volume_fraction"] == 0.2
    assert job.fixed["mass"] == 1.0 and job.fixed["contact_factor"] == 2.1  # paper defaults


def test_a_task_draws_from_its_values_not_from_its_place_in_the_sweep():
    job = parse(BASE.replace("[sweep]", '[sweep]\nmethod = ["ed", "ts"]'))
    streams = {(task.point, task.realization): job.seed_sequence(task).generate_state(4).tobytes()
               for task in job.tasks()}
    by_values = {}
    for (point, realization), stream in streams.items():
        params = job.point_parameters(point)
        by_values[params["method"], params["n_spheres"], params["volume_fraction"], realization] = stream
    # the method does not enter the stream; every other point and realisation has its own
    for (method, n, phi, r), stream in by_values.items():
        assert stream == by_values["ed", n, phi, r]
    assert len(set(streams.values())) == len(streams) // 2
    # another sweep, in another order, with the fixed keys written otherwise: the same numbers per point
    other = parse(BASE.replace("radius = 0.2", "mass = 1.0\nradius = 0.20").replace(
        "n_spheres = [100, 400]\nvolume_fraction = [0.1, 0.2, 0.3]",
        "volume_fraction = [0.3, 0.25, 0.1]\nn_spheres = [900, 400]"))
    shared = 0
    for task in other.tasks():
        params = other.point_parameters(task.point)
        key = ("ed", params["n_spheres"], params["volume_fraction"], task.realization)
        if key in by_values:
            assert other.seed_sequence(task).generate_state(4).tobytes() == by_values[key]
            shared += 1
    assert shared == 2 * 2  # n_spheres 400 at volume fractions 0.1 and 0.3, two realisations each


def test_the_keys_of_points_are_distinct_and_name_the_method():
    job = parse(BASE.replace("[sweep]", '[sweep]\nmethod = ["ed", "ts"]'))
    keys = [job.point_key(point) for point in range(job.n_points)]
    assert len(set(keys)) == job.n_points == 12
    assert len({task.label for task in job.tasks()}) == len(job.tasks())


@pytest.mark.parametrize("change, message", [
    (("seed = 7", "seed = 7\ncolour = 1"), "unknown key 'colour'; allowed top-level keys"),
    (("radius = 0.2", "radius = 0.2\nradiuss = 1"), r"\[parameters\] unknown key 'radiuss'; allowed keys"),
    (("radius = 0.2", 'radius = "big"'), "radius = 'big': must be a number"),
    (("radius = 0.2", "radius = -1"), r"radius = -1.0 is out of range; allowed: a number, 0 < radius"),
    (("[0.1, 0.2, 0.3]", "[0.1, 1.5]"), r"volume_fraction\[1\] = 1.5 is out of range; allowed: a number, 0 < volume_fraction < 1"),
    (("[0.1, 0.2, 0.3]", "[0.1, 0.1]"), "values must be distinct"),
    (("realizations = 2", "realizations = 0"), "realizations = 0: allowed: an integer >= 1"),
    (("radius = 0.2", 'radius = 0.2\nmethod = "magic"'), "method = 'magic': allowed: one of 'ed'"),
    (("radius = 0.2", "radius = 0.2\nbox_levels = 8\n[sweep.x]"), "unknown key 'x'"),
    (("n_spheres = [100, 400]", "box_levels = [8, 9]\nn_spheres = [100, 400]"), "'box_levels' cannot be swept"),
    (("n_spheres = [100, 400]", "n_spheres = [100, 400]\nradius = [0.2]"), "'radius' is both in"),
    (("n_spheres = [100, 400]", ""), "parameter 'n_spheres' is required"),
    (("[0.1, 0.2, 0.3]", "[0.1, 0.8]"), r"volume_fraction=0.8: the initial lattice does not fit .*condition 4\.2"),
    (("n_spheres = [100, 400]", "n_spheres = [100.0]"), r"n_spheres\[0\] = 100.0: must be an integer"),
    (("radius = 0.2", "radius = 0.2\nbox_levels = 8.0"), "box_levels = 8.0: must be an integer"),
    (("realizations = 2", "realizations = 2.0"), "realizations = 2.0: must be an integer"),
    (("seed = 7", "seed = 1.0"), "seed = 1.0: must be an integer"),
    (("radius = 0.2", "radius = true"), "radius = True: must be a number"),
    (("radius = 0.2", "radius = 1" + "0" * 30), r"parameters\.radius: an integer beyond the 64 bits of TOML"),
    (("[0.1, 0.2, 0.3]", "[0.1, 0x1" + "0" * 5000 + "]"), r"sweep\.volume_fraction\[1\]: an integer beyond"),
    (("seed = 7", "seed = 0x1" + "0" * 5000), "seed: an integer beyond the 64 bits"),
    (("radius = 0.2", "radius = 1" + "0" * 5000), "radius = an integer of 5001 digits; allowed: integers of at most 64 bits"),
    (("realizations = 2", "realizations = 1000000000000"),
     "6 parameter points x 1000000000000 realizations = 6000000000000 tasks; allowed: at most 1000000 tasks"),
    (("n_spheres = [100, 400]", "n_spheres = [100, 1000000000000]"),
     r"sweep point n_spheres=1000000000000, volume_fraction=0.1: one task needs about 1\.\d+ PiB of memory "
     r"\(estimated from n_spheres=1000000000000\), more than this machine's \d+(\.\d+)? [GT]iB"),
])
def test_invalid_jobs_name_the_field_and_the_allowed_values(change, message):
    with pytest.raises(JobError, match=message):
        parse(BASE.replace(*change))


@pytest.mark.parametrize("line, message", [
    ('length_unit = "metre"', r"length_unit = 'metre': allowed: a UDUNITS length unit: 'm' with an SI prefix "
                              r"\(Y Z E P T G M k h da d c m u n p f a z y\) or none, e\.g\. 'm', 'mm', 'um'$"),
    ('length_unit = "s"', "length_unit = 's': allowed: a UDUNITS length unit: 'm' with an SI prefix"),
    ("time_unit = 1", r"time_unit = 1: allowed: a UDUNITS time unit: 's' with an SI prefix .* or none, "
                      r"e\.g\. 's', 'ms', 'us', or one of 'min', 'h', 'd'$"),
    ('mass_unit = "1"', "mass_unit = '1': allowed: a UDUNITS mass unit: 'g' with an SI prefix"),
    ('mass_unit = "kilogram"', "mass_unit = 'kilogram': allowed: a UDUNITS mass unit"),
])
def test_units_must_be_udunits_symbols_of_their_quantity(line, message):
    with pytest.raises(JobError, match=f"^job.toml: {message}"):
        parse(BASE.replace("seed = 7", f"seed = 7\n{line}"))


def test_units_label_the_job_and_leave_its_random_streams():
    default, chosen = parse(BASE), parse(BASE.replace("seed = 7", 'seed = 7\nlength_unit = "um"\ntime_unit = "ms"'
                                                                  '\nmass_unit = "ng"'))
    assert default.unit_attributes == {"length_unit": "m", "time_unit": "s", "mass_unit": "kg"}
    assert chosen.unit_attributes == {"length_unit": "um", "time_unit": "ms", "mass_unit": "ng"}
    for task in default.tasks():
        np.testing.assert_array_equal(default.seed_sequence(task).generate_state(4),
                                      chosen.seed_sequence(task).generate_state(4))
    assert default.fixed == chosen.fixed and default.sweep == chosen.sweep


@pytest.mark.parametrize("change, message", [
    (("n_particles = 10", "n_particles = 10.0"), "n_particles = 10.0: must be an integer"),
    (("n_particles = 10", "n_particles = 1000000000000"),
     r"one task needs about \d+ TiB of memory \(estimated from n_particles=1000000000000, shape='sphere'\)"),
    (("n_particles = 10", 'n_particles = 10000000000\nshape = "ellipsoid"\nshape_spheres = 100000'),
     r"one task needs about \d+(\.\d+)? PiB of memory \(estimated from n_particles=10000000000, "
     r"shape='ellipsoid', shape_spheres=100000\)"),
    (("n_particles = 10", 'n_particles = 10000000\nshape = "cube"\nshape_size = 1000'),
     r"\(estimated from n_particles=10000000, shape='cube', shape_size=1000\)"),
    (("n_particles = 10", 'n_particles = 10\nshape = "ellipsoid"\nshape_spheres = 1000000'),
     r"shape_spheres = 1000000 is out of range; allowed: an integer, 1 <= shape_spheres <= 100000"),
])
def test_invalid_deposition_sizes(change, message):
    with pytest.raises(JobError, match=message):
        parse(DEPOSITION.replace(*change))


JOBS = sorted((Path(__file__).resolve().parent.parent / "jobs").glob("*.toml"))


def test_the_example_jobs_are_found():
    assert len(JOBS) >= 7


@pytest.mark.parametrize("path", JOBS, ids=lambda path: path.stem)
def test_every_example_job_is_valid(path, tmp_path):
    flake = tmp_path / "flake.csv"
    flake.write_text(TWO_SPHERES)
    text = re.sub(r'agglomerate_file = ".*"', f'agglomerate_file = "{flake}"', path.read_text())
    assert parse(text).n_points >= 1


def test_a_job_file_must_be_utf8_text(tmp_path):
    path = tmp_path / "job.toml"
    path.write_bytes(BASE.replace('name = "t"', 'name = "caf\xe9"').encode("latin-1"))
    with pytest.raises(JobError, match=f"{re.escape(str(path))}: not a TOML job file \\(not UTF-8 text\\)"):
        load_job(path, SOLVERS)


def sha256(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_input_files_enter_the_job_with_the_hash_of_their_content(tmp_path):
    flake, other = tmp_path / "flake.csv", tmp_path / "other.csv"
    flake.write_text(TWO_SPHERES)
    other.write_text(TWO_SPHERES.replace("1.5", "1.8"))
    job = parse(DEPOSITION + f'shape = "agglomerate"\n[sweep]\nagglomerate_file = ["{flake}", "{other}"]\n')
    assert job.input_hashes == {"agglomerate_file": {str(flake): sha256(flake), str(other): sha256(other)}}
    assert job.input_attributes == {"input_files": f"{flake} {sha256(flake)}\n{other} {sha256(other)}"}
    assert parse(DEPOSITION.replace("[parameters]", '[parameters]\nagglomerate_file = ""')).input_hashes == {}
    assert parse(BASE).input_attributes == {"input_files": ""}


def test_the_dataset_names_its_input_files(tmp_path):
    flake = tmp_path / "flake.csv"
    flake.write_text(TWO_SPHERES)
    job = parse(DEPOSITION + f'shape = "agglomerate"\nagglomerate_file = "{flake}"\n')
    solver = SOLVERS["deposition"]
    observable = solver.coordinates(job.fixed)
    zeros = {s.name: np.zeros([len(observable[d].values) for d in s.dims]) for s in all_statistics(solver)}
    rows = row_layout(job, solver).rows([(task, zeros) for task in job.tasks()])
    dataset = build_dataset(job, solver, rows, mpi_size=1, ranks_per_task=1)
    assert dataset.attrs["input_files"] == f"{flake} {sha256(flake)}"


@pytest.mark.parametrize("name, content, message", [
    ("flake.h5", b"x,y,z,r\n0,0,0,1\n", "not an HDF5 file"),
    ("flake.csv", b"x,y,z,r\n0,0,0,1\n0,zero,0,1\n", "line 3: 'zero' is not a number"),
    ("flake.csv", b"", "the CSV file holds no spheres"),
    ("flake.csv", b"x,y,z,r\n", "the CSV file holds no spheres"),
    ("flake.csv", b"x,y,z,r\n0,0,0,1\n0,0,1\n", "line 3 has 3 values, the header 4"),
    ("flake.csv", b"0,0,0,1\n0,0,1\n", "line 2 has 3 values, line 1 4"),
    ("flake.csv", b"0,0,1\n1,0,1\n", "a CSV without header needs 4 columns x, y, z, r; found 3"),
    ("flake.csv", b"x,y,z,r\n\xe9\n", "not UTF-8 text"),
])
def test_unreadable_agglomerate_files(tmp_path, name, content, message):
    path = tmp_path / name
    path.write_bytes(content)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(JobError, match=f"agglomerate_file = '{re.escape(str(path))}': .*{re.escape(message)}"):
            read_agglomerate(path)


@pytest.mark.parametrize("position, radius, message", [
    ([b"a", b"b"], [1.0, 1.0], "spheres/position must be a dataset of numbers (integers or floating point)"),
    ([[0.0, 0.0], [1.5, 0.0]], [1.0], "spheres/position of shape (2, 2) and spheres/radius of shape (1,); allowed: "
                                      "(n, 2) or (n, 3)"),
])
def test_hdf5_agglomerates_of_the_wrong_layout(tmp_path, position, radius, message):
    path = tmp_path / "flake.h5"
    with h5py.File(path, "w") as file:
        file["spheres/position"], file["spheres/radius"] = position, radius
    with pytest.raises(JobError, match=re.escape(message)):
        read_agglomerate(path)


def test_csv_agglomerates_with_and_without_header(tmp_path):
    path = tmp_path / "flake.csv"
    path.write_text("# two discs\nr, y ,x\n1,0,0\n\n1,0,1.5\n")
    centres, radii = read_agglomerate(path)
    np.testing.assert_array_equal(centres, [[0, 0], [1.5, 0]])
    np.testing.assert_array_equal(radii, [1, 1])
    path.write_text("0,0,0,1\n1.5,0,0,2\n")
    centres, radii = read_agglomerate(path)
    assert centres.shape == (2, 3) and list(radii) == [1, 2]


def resumed(tmp_path, first: str, second: str) -> None:
    """Prepare an output folder for job ``first``, then for job ``second`` as a resume would."""
    folder = OutputFolder(tmp_path / "out", "t")
    folder.prepare(parse(first), None)
    folder.prepare(parse(second), parse(folder.job_copy.read_text()))


@pytest.mark.parametrize("change, message", [
    (("seed = 7", "seed = 8"), "differs in: seed (7 then, 8 now);"),
    (("radius = 0.2", "radius = 0.3"), "differs in: [parameters] radius (0.2 then, 0.3 now);"),
    (("radius = 0.2", "radius = 0.2\nmass = 2.0"), "differs in: [parameters] mass (1.0 then, 2.0 now);"),
    (("seed = 7\nrealizations = 2", 'seed = 8\nrealizations = 3\nlength_unit = "mm"'),
     "differs in: seed (7 then, 8 now), length_unit ('m' then, 'mm' now);"),
    (("seed = 7", 'seed = 7\nlength_unit = "mm"'), "differs in: length_unit ('m' then, 'mm' now);"),
])
def test_resume_names_each_key_that_differs(tmp_path, change, message):
    with pytest.raises(JobError, match=re.escape(message)):
        resumed(tmp_path, BASE, BASE.replace(*change))


def test_resume_accepts_the_same_job_written_differently(tmp_path):
    resumed(tmp_path, BASE, "# the same job\n" + BASE.replace("radius = 0.2", "radius = 0.20\nmass = 1.0")
            .replace("seed = 7", 'seed = 7\nlength_unit = "m"'))


def test_resume_refuses_a_changed_input_file(tmp_path):
    flake = tmp_path / "flake.csv"
    flake.write_text(TWO_SPHERES)
    text = DEPOSITION + f'shape = "agglomerate"\nagglomerate_file = "{flake}"\n'
    before = sha256(flake)
    folder = OutputFolder(tmp_path / "out", "d")
    folder.prepare(parse(text), None)
    assert json.loads((tmp_path / "out" / "inputs.json").read_text()) == {"agglomerate_file": {str(flake): before}}
    folder.prepare(parse(text), parse(folder.job_copy.read_text()))  # unchanged: resumes
    flake.write_text(TWO_SPHERES.replace("1.5", "1.9"))
    with pytest.raises(JobError, match=re.escape(
            f"output folder {tmp_path / 'out'} holds results computed from a different agglomerate_file "
            f"'{flake}' (its content changed since an earlier run: sha256 {before[:12]}... then, "
            f"{sha256(flake)[:12]}... now); give another output folder or restore the file")):
        folder.prepare(parse(text), parse(folder.job_copy.read_text()))


def folder_with_a_task(tmp_path) -> tuple[OutputFolder, Path]:
    """An output folder of job BASE holding one finished task file (a single sphere; the statistics of no solver)."""
    folder = OutputFolder(tmp_path / "out", "t")
    job = parse(BASE)
    folder.prepare(job, None)
    task = job.tasks()[0]
    configuration = Configuration(arrays={"spheres/position": np.zeros((1, 2)), "spheres/radius": np.ones(1)},
                                  box_lower=np.zeros(2), box_upper=np.ones(2), periodic=np.zeros(2, dtype=bool))
    write_task_file(folder.task_path(task), TaskResult({"box_length": 1.0}, configuration), {"point": task.point})
    return folder, folder.task_path(task)


def test_task_files_record_the_parsim_version_and_the_output_schema(tmp_path):
    _, path = folder_with_a_task(tmp_path)
    with h5py.File(path) as file:
        assert file.attrs["parsim_version"] == parsim.__version__ == "0.6.0"
        assert file.attrs["parsim_output_schema"] == OUTPUT_SCHEMA == 5
        assert file["statistics/box_length"][()] == 1.0


@pytest.mark.parametrize("recorded, found", [
    (None, "an older parsim (output schema 1, which records none)"),
    (1, "an older parsim (output schema 1)"),
    (OUTPUT_SCHEMA + 1, f"a newer parsim (output schema {OUTPUT_SCHEMA + 1})"),
])
def test_a_folder_of_another_output_schema_is_refused_in_one_line(tmp_path, recorded, found):
    folder, path = folder_with_a_task(tmp_path)
    with h5py.File(path, "a") as file:
        del file.attrs["parsim_output_schema"]
        if recorded is not None:
            file.attrs["parsim_output_schema"] = recorded
    root = tmp_path / "out"
    expected = (f"output folder {root} was written by {found}; parsim {parsim.__version__} reads and writes output "
                f"schema {OUTPUT_SCHEMA}: read or finish it with ")
    with pytest.raises(JobError, match=re.escape(expected)) as refused:
        folder.prepare(parse(BASE), parse(folder.job_copy.read_text()))
    message = str(refused.value)
    assert "\n" not in message and message.endswith(f"into another output folder (key 'output' or option "
                                                     f"--output) or after removing {root}")


def test_a_row_file_of_another_output_schema_is_refused_naming_it(tmp_path):
    job = parse(BASE)
    layout = row_layout(job, job.solver)
    header = json.loads(layout.header(job.name))
    header["parsim_output_schema"] = OUTPUT_SCHEMA - 1
    path = tmp_path / "rows" / "old.rows"
    path.parent.mkdir()
    zeros = {name: np.zeros(shape) for name, _, shape in layout.fields}
    path.write_bytes((json.dumps(header) + "\n").encode() + layout.rows([(job.tasks()[0], zeros)]).tobytes())
    with pytest.raises(JobError, match=re.escape(f"row file {path} was written by an older parsim (output schema "
                                                 f"{OUTPUT_SCHEMA - 1})")):
        read_rows(path.parent, layout)  # reading the rows checks each file


def test_supplementary_initial_condition_needs_no_volume_fraction():
    text = BASE.replace("volume_fraction = [0.1, 0.2, 0.3]", "").replace(
        "radius = 0.2", 'radius = 0.2\ninitial_condition = "unit_lattice_uniform"')
    assert parse(text).n_points == 2
    with pytest.raises(JobError, match="volume_fraction must not be given"):
        parse(text.replace("n_spheres = [100, 400]", "n_spheres = [100, 400]\nvolume_fraction = [0.2]"))


def test_cli_rejects_an_invalid_job_without_traceback_and_computes_nothing(tmp_path):
    job = tmp_path / "bad.toml"
    job.write_text(BASE.replace('output = "out"', f'output = "{tmp_path / "out"}"').replace("[0.1, 0.2, 0.3]", "[2.0]"))
    for command in ("validate", "run"):
        result = subprocess.run([sys.executable, "-m", "parsim.cli", command, str(job)], capture_output=True, text=True)
        assert result.returncode == 2
        assert "volume_fraction[0] = 2.0 is out of range" in result.stderr
        assert "Traceback" not in result.stderr
    assert not (tmp_path / "out").exists()


def test_every_parameter_is_in_the_job_reference():
    reference = open("docs/jobs.md").read()
    for solver in SOLVERS.values():
        for parameter in solver.parameters:
            assert f"| `{parameter.name}` |" in reference, parameter.name
        for statistic in solver.statistics:
            assert f"`{statistic.name}`" in reference, statistic.name


SPECIES = DEPOSITION + '''
[[species]]
name = "large"
sphere_radius = 0.5
[[species]]
name = "small"
sphere_radius = 0.25
'''


def test_a_table_key_written_at_its_default_is_the_same_job_and_the_same_stream(tmp_path):
    plain, explicit = parse(SPECIES), parse(SPECIES.replace('name = "small"', 'name = "small"\nshare = 1.0'))
    task, same = plain.tasks()[0], explicit.tasks()[0]
    assert task.key == same.key
    assert plain.seed_sequence(task).spawn_key == explicit.seed_sequence(same).spawn_key
    folder = OutputFolder(tmp_path / "out", "d")
    folder.prepare(plain, None)
    folder.prepare(explicit, parse(folder.job_copy.read_text()))  # not a different job
    # a species' own value of a job parameter is an override, never a default left out
    override = parse(SPECIES.replace('name = "large"', 'name = "large"\nshape = "sphere"'))
    assert override.table_entries("species")[0] == {"name": "large", "sphere_radius": 0.5, "shape": "sphere"}
    assert override.tasks()[0].key != task.key


def test_two_files_of_one_content_are_one_point_and_refused(tmp_path):
    first, second = tmp_path / "a.csv", tmp_path / "b.csv"
    first.write_text(TWO_SPHERES)
    second.write_text(TWO_SPHERES)
    with pytest.raises(JobError, match=re.escape(
            f"sweep points agglomerate_file='{first}' and agglomerate_file='{second}' are one point: their input "
            "files have the same content; give each file once")):
        parse(DEPOSITION + f'shape = "agglomerate"\n[sweep]\nagglomerate_file = ["{first}", "{second}"]\n')


def test_a_species_whose_shape_lacks_its_file_is_named():
    with pytest.raises(JobError, match=re.escape("[[species]] name = 'large': shape = 'mesh' needs mesh_file")):
        parse(SPECIES.replace('name = "large"', 'name = "large"\nshape = "mesh"'))
