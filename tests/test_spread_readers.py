"""Every reader of task files gives a spread deposition's configuration in the one-rank (drop) order.

A deposition task spread over two ranks (``parsim run --ranks-per-task 2``) is written as the ranks'
part files joined by virtual datasets, whose rows come rank after rank.  One small job (300 spheres
and 300 rods of three spheres in a periodic box 24 diameters wide, which cuts into two blocks wider
than the halo) runs once on two ranks and once on one; each reader of the spread task files must
give what it gives of the one-rank task files: ``read_configuration`` the same arrays bit for bit,
``parsim export`` the same files byte for byte in every format (voxels too), ``parsim plot`` the
same sediment picture, and the reader of ``substrate`` and ``agglomerate_file`` (HDF5 task files as
a job's input) the same spheres, or an error where a part is missing, never the zeros HDF5 reads.
"""

import os
import re
import shutil

import h5py
import numpy as np
import pytest

from parsim.agglomerate_file import read_agglomerate
from parsim.errors import JobError
from parsim.output.export import FORMATS, export_output
from parsim.output.snapshot import PARTICLE_ORDER, parts_folder, read_configuration
from tests.datasets import run_serial
from tests.mpi import parsim_command, run_mpi

JOB = """
name = "spread_readers"
kind = "deposition"
seed = 7
realizations = 1
[parameters]
n_particles = 300
box_length = 24.0  # two blocks of 12 diameters, wider than the halo: the sediment is split
shape_size = 3     # rods of three spheres
packing_samples = 1000
[sweep]
shape = ["sphere", "rod"]
"""

VOXEL_SIZE = 0.25


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    """The job's output folders on two ranks with ``--ranks-per-task 2`` and on one rank, and its task labels."""
    root = tmp_path_factory.mktemp("spread_readers")
    job = root / "job.toml"
    job.write_text(JOB)
    spread = run_mpi(parsim_command("run", str(job), "--output", str(root / "two"), "--quiet", "--ranks-per-task",
                                    "2"), ranks=2, timeout=600)
    assert spread.returncode == 0, spread.stderr
    one = run_serial("run", str(job), "--output", str(root / "one"), "--quiet")
    assert one.returncode == 0, one.stderr
    labels = sorted(path.stem for path in (root / "one" / "tasks").glob("*.h5"))
    assert len(labels) == 2
    return root / "two", root / "one", labels


def task_file(output, label):
    return output / "tasks" / f"{label}.h5"


def test_the_spread_task_files_store_their_rows_rank_by_rank(outputs):
    # what makes the other tests mean something: both ranks hold particles, and the stored order is not the drop
    # order; particles/index and spheres/particle give each row's place in it, as the docs say
    two, _, labels = outputs
    for label in labels:
        with h5py.File(task_file(two, label)) as file:
            assert file["spheres/position"].is_virtual
            index, particle = file[PARTICLE_ORDER][()], file["spheres/particle"][()]
            counts = np.diff(file["shapes/start"][()])[file["particles/shape"][()]]
        assert sorted(index) == list(range(len(index))) and not np.all(np.diff(index) > 0)
        np.testing.assert_array_equal(particle, np.repeat(index, counts))
        for rank in (0, 1):
            with h5py.File(parts_folder(task_file(two, label)) / f"rank{rank:04d}.h5") as part:
                assert len(part[PARTICLE_ORDER]) > 0


def test_read_configuration_gives_the_one_rank_configuration(outputs):
    two, one, labels = outputs
    for label in labels:
        serial, spread = read_configuration(task_file(one, label)), read_configuration(task_file(two, label))
        assert serial.arrays.keys() == spread.arrays.keys()
        for name, array in serial.arrays.items():
            assert array.dtype == spread.arrays[name].dtype, name
            np.testing.assert_array_equal(array, spread.arrays[name], err_msg=name)
        for name in ("box_lower", "box_upper", "periodic"):
            np.testing.assert_array_equal(getattr(serial, name), getattr(spread, name))
        assert serial.attrs.keys() == spread.attrs.keys()


def exported(output, format, folder):
    """Every task of ``output`` exported as ``format`` into ``folder``: {file name: bytes}."""
    options = {"voxels": {"voxel_size": VOXEL_SIZE}, "mstm": {"wavelength": 0.5, "refractive_index": 1.6 + 0.6j}}.get(format, {})
    files = export_output(output, format, all_tasks=True, out=folder, **options)
    return {path.name: path.read_bytes() for path in files}


@pytest.mark.parametrize("format", list(FORMATS))
def test_every_export_format_writes_the_one_rank_files(outputs, tmp_path, format):
    two, one, labels = outputs
    serial, spread = exported(one, format, tmp_path / "one"), exported(two, format, tmp_path / "two")
    assert sorted(serial) == sorted(spread) and any(labels[0] in name for name in serial)
    for name, content in serial.items():
        assert content == spread[name], f"{format}: {name} differs"


def test_the_sediment_picture_is_the_one_rank_picture(outputs, tmp_path):
    from parsim.plots import plot_output

    two, one, labels = outputs
    for label in labels:
        pictures = []
        for output in (one, two):
            written = plot_output(output, figure="sediment", task=label, out=tmp_path / output.name / f"{label}.png",
                                  report=lambda line: None)
            pictures.append([path.read_bytes() for path in written if path.suffix == ".png"])
        assert len(pictures[0]) == 1 and pictures[0] == pictures[1], label


@pytest.mark.parametrize("with_substrate", [True, False], ids=["substrate", "agglomerate_file"])
def test_a_spread_task_file_as_a_jobs_input_gives_the_one_rank_spheres(outputs, with_substrate):
    two, one, labels = outputs
    for label in labels:
        serial = read_agglomerate(task_file(one, label), key="substrate", with_substrate=with_substrate)
        spread = read_agglomerate(task_file(two, label), key="substrate", with_substrate=with_substrate)
        for name, expected, found in zip(("centres", "radii"), serial, spread):
            np.testing.assert_array_equal(expected, found, err_msg=f"{label}: {name}")


def test_a_spread_task_file_as_a_jobs_input_without_its_part_is_refused(outputs, tmp_path):
    two, _, labels = outputs
    source = task_file(two, labels[0])
    copy = tmp_path / source.name
    shutil.copyfile(source, copy)
    shutil.copytree(parts_folder(source), parts_folder(copy))
    assert np.all(read_agglomerate(copy, with_substrate=True)[1] > 0)  # the copy reads as the original
    (parts_folder(copy) / "rank0001.h5").unlink()  # HDF5 alone would read its rows as zeros
    with pytest.raises(JobError, match=f"substrate = {re.escape(repr(str(copy)))}: .*rank0001.h5 is missing"):
        read_agglomerate(copy, key="substrate", with_substrate=True)


@pytest.mark.parametrize("damage", ["truncated", "garbage"])
@pytest.mark.parametrize("command", ["export", "plot"])
def test_a_damaged_part_file_is_named_with_what_to_do(outputs, tmp_path, damage, command):
    two, _, labels = outputs
    out = tmp_path / "two"
    shutil.copytree(two, out)
    task = task_file(out, labels[0])
    part = parts_folder(task) / "rank0001.h5"
    if damage == "truncated":
        os.truncate(part, part.stat().st_size // 2)
    else:
        part.write_bytes(b"not HDF5 " * 100)
    written = tmp_path / f"{labels[0]}.csv" if command == "export" else tmp_path / f"{labels[0]}.png"
    options = ["--format", "csv"] if command == "export" else ["--figure", "sediment"]
    result = run_serial(command, str(out), "--task", labels[0], *options, "--out", str(written))
    assert result.returncode == 2, result.stderr
    (line,) = result.stderr.splitlines()
    assert line.startswith(f"parsim: error: cannot read {part}, a part of task file {task} ("), line
    assert line.endswith(f"): compute the job again into another output folder (key 'output' or option --output) "
                         f"for this task's configuration, or remove {task} and {parts_folder(task)}: its task stays "
                         f"finished (its statistics are in {out / 'rows'}), without its configuration"), line
    assert not list(tmp_path.glob(f"{labels[0]}.*"))
