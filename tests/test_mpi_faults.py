"""A failure on any rank, in any phase, ends every rank promptly with one line naming what failed.

Each case runs the real command line under ``mpiexec -n 2`` and asserts the exit status, the
single line parsim prints, and that the run ended within a bound (a hang fails the test and
its processes are killed).  Full disks are small tmpfs mounts, which need root; elsewhere
those cases are skipped with the reason.
"""

import os
import shutil
import subprocess
from pathlib import Path

import pytest

from tests.datasets import run_serial
from tests.mpi import error_lines, parsim_command, run_mpi_bounded

JOB = """
name = "faults"
kind = "aggregation"
seed = 5
realizations = 6
[parameters]
method = "ed"
dimension = 2
radius = 0.2
volume_fraction = 0.1
initial_condition = "lattice_isotropic"
[sweep]
n_spheres = [16, 25]
"""

#: Seconds a failing run may take, start-up of both ranks included; the kernels are compiled
#: beforehand by the ``finished`` fixture, so this bounds the time from the failure to the end.
BOUND = 60
#: Seconds a run refused before computing may take: the start-up of two interpreters, and little else.
REFUSAL_SECONDS = 20
PAGE = 4096  # a tmpfs gives a file whole pages of this size


@pytest.fixture(scope="module")
def job(tmp_path_factory):
    path = tmp_path_factory.mktemp("job") / "faults.toml"
    path.write_text(JOB)
    return path


@pytest.fixture(scope="module")
def finished(job, tmp_path_factory):
    """The job run to the end on one rank (this also compiles the kernels for the runs below)."""
    out = tmp_path_factory.mktemp("finished")
    result = run_serial("run", str(job), "--output", str(out), "--quiet")
    assert result.returncode == 0, result.stderr
    return out


def run_into(job, output):
    return run_mpi_bounded(parsim_command("run", str(job), "--output", str(output), "--quiet"), BOUND)


def assert_one_line(result, status, *fragments):
    lines = error_lines(result.stderr)
    assert result.returncode == status, result.stderr
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("parsim: error: "), result.stderr
    for fragment in fragments:
        assert fragment in lines[0], result.stderr
    assert "Traceback" not in result.stderr and "signal" not in result.stderr


# -- the output location, checked before anything is computed ----------------------------------

@pytest.fixture
def read_only_folder(tmp_path):
    """A folder nobody may write in: a read-only mount as root, a folder without write permission otherwise."""
    folder = tmp_path / "read_only"
    folder.mkdir()
    if os.geteuid() != 0:
        folder.chmod(0o555)
        yield folder
        folder.chmod(0o755)
        return
    if not _mount(["-t", "tmpfs", "-o", "ro,size=64k", "tmpfs", str(folder)]):
        pytest.skip("root ignores write permissions and this machine refuses a read-only tmpfs mount")
    yield folder
    _unmount(folder)


@pytest.mark.mpi
def test_read_only_folder_is_refused_before_computing(job, read_only_folder):
    target = read_only_folder / "place"
    result, seconds = run_into(job, target)
    assert_one_line(result, 2, str(target), "not writable")
    assert seconds < REFUSAL_SECONDS


@pytest.mark.mpi
def test_output_path_that_is_a_file_is_refused(job, tmp_path):
    target = tmp_path / "a_file"
    target.write_text("not a folder")
    for output in (target, target / "below"):
        result, seconds = run_into(job, output)
        assert_one_line(result, 2, str(target), "is a file")
        assert seconds < REFUSAL_SECONDS
    assert target.read_text() == "not a folder"


@pytest.mark.parametrize("make", ["file", "below_file"])
def test_validate_checks_the_output_location(job, tmp_path, make):
    a_file = tmp_path / "a_file"
    a_file.write_text("")
    target = a_file if make == "file" else a_file / "below"
    result = run_serial("validate", str(job), "--output", str(target))
    assert result.returncode == 2 and "is a file" in result.stderr and "Traceback" not in result.stderr


def test_validate_does_not_create_the_output_folder(job, tmp_path):
    result = run_serial("validate", str(job), "--output", str(tmp_path / "new" / "place"))
    assert result.returncode == 0, result.stderr
    assert not (tmp_path / "new").exists()


@pytest.mark.mpi
def test_an_mpi_without_thread_multiple_gets_one_line_naming_the_fix(job, tmp_path, monkeypatch):
    monkeypatch.setenv("MPI4PY_RC_THREAD_LEVEL", "serialized")  # what a cluster's MPI may grant at most
    result, seconds = run_into(job, tmp_path / "out")
    assert_one_line(result, 1, "MPI_THREAD_MULTIPLE", "MPICH_MAX_THREAD_SAFETY=multiple")
    assert seconds < REFUSAL_SECONDS and not (tmp_path / "out").exists()


# -- a full disk in each phase that writes -----------------------------------------------------

@pytest.fixture
def small_disk(tmp_path):
    """A 512 KiB tmpfs; ``fill(leave)`` fills it up to ``leave`` free bytes."""
    mount = tmp_path / "disk"
    mount.mkdir()
    if os.geteuid() != 0 or not _mount(["-t", "tmpfs", "-o", "size=512k", "tmpfs", str(mount)]):
        pytest.skip("a full disk is simulated by a size-limited tmpfs mount, which needs root")

    def fill(leave: int) -> None:
        free = shutil.disk_usage(mount).free
        (mount / "filler").write_bytes(b"\0" * max(free - leave, 0))

    yield mount, fill
    _unmount(mount)


@pytest.mark.mpi
def test_disk_full_when_the_run_records_its_job(job, small_disk):
    mount, fill = small_disk
    fill(PAGE)  # room for the lock file, not for the record of the job that follows it
    result, seconds = run_into(job, mount / "out")
    assert_one_line(result, 1, f"no space left on {mount / 'out'}")
    assert seconds < REFUSAL_SECONDS
    assert not (mount / "out" / "parsim.lock").exists()


@pytest.mark.mpi
def test_disk_full_while_task_files_are_written(job, finished, small_disk):
    mount, fill = small_disk
    task_pages = max(-(-path.stat().st_size // PAGE) for path in (finished / "tasks").glob("*.h5"))
    fill((3 + 3 * task_pages) * PAGE)  # the lock, inputs.json and job.toml, and three task files
    result, _ = run_into(job, mount / "out")
    assert_one_line(result, 1, "no space left on", str(mount / "out" / "tasks"), ", realization ")
    kept = list((mount / "out" / "tasks").glob("*.h5"))
    assert 1 <= len(kept) < 12
    resumed = run_serial("run", str(job), "--output", str(mount / "out"), "--quiet")
    assert resumed.returncode == 1 and "no space left on" in resumed.stderr  # still full, still one message


@pytest.mark.mpi
def test_disk_full_when_the_dataset_is_written(job, finished, small_disk):
    mount, fill = small_disk
    shutil.copytree(finished, mount / "out", ignore=shutil.ignore_patterns("*.nc"))
    fill(PAGE)  # room for the lock file alone
    result, _ = run_into(job, mount / "out")
    assert_one_line(result, 1, "no space left on", str(mount / "out" / "faults.nc"))
    assert len(list((mount / "out" / "tasks").glob("*.h5"))) == 12  # nothing computed is lost
    assert not list((mount / "out").glob("*.tmp"))


def _mount(arguments: list[str]) -> bool:
    return subprocess.run(["mount", *arguments], capture_output=True).returncode == 0


def _unmount(folder: Path) -> None:
    subprocess.run(["umount", "-l", str(folder)], capture_output=True)
