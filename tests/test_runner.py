"""Jobs end to end: the same dataset on 1 and 2 ranks, after a kill and resume, and the file layouts."""

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import xarray as xr

import parsim
from parsim.job import load_job
from parsim.output.lock import LOCK_NAME, read_holder
from parsim.output.snapshot import OUTPUT_SCHEMA
from parsim.solvers import SOLVERS
from tests.datasets import reproducible_part, run_serial
from tests.mpi import error_lines, kill_session, mpiexec, parsim_command, run_mpi

QUICKSTART = "jobs/quickstart.toml"


@pytest.fixture(scope="module")
def quickstart_two_ranks(tmp_path_factory):
    out = tmp_path_factory.mktemp("quickstart2")
    result = run_mpi(parsim_command("run", QUICKSTART, "--output", str(out), "--quiet"))
    assert result.returncode == 0, result.stderr
    return out


@pytest.mark.mpi
def test_quickstart_identical_on_one_and_two_ranks(quickstart_two_ranks, tmp_path):
    result = run_serial("run", QUICKSTART, "--output", str(tmp_path), "--quiet")
    assert result.returncode == 0, result.stderr
    one = reproducible_part(tmp_path / "quickstart.nc")
    two = reproducible_part(quickstart_two_ranks / "quickstart.nc")
    xr.testing.assert_identical(one, two)
    assert one.stop_reason.attrs["flag_meanings"].split()[0] == "single_cluster"
    assert (one.stop_reason == 0).all() and (one.n_clusters == 1).all()  # every task reached one cluster
    assert (one.n_collisions == one.n_spheres - 1).all()


@pytest.mark.mpi
def test_dataset_layout(quickstart_two_ranks):
    with xr.open_dataset(quickstart_two_ranks / "quickstart.nc") as ds:
        assert ds.fractal_dimension.dims == ("n_spheres", "volume_fraction", "realization")
        assert ds.pair_distribution.dims[-1] == "r" and ds.box_count.dims[-1] == "box_size"
        assert ds.realization.attrs["standard_name"] == "realization"
        for name, variable in {**ds.data_vars, **ds.coords}.items():
            assert "units" in variable.attrs and "long_name" in variable.attrs, name
        assert ds.attrs["mpi_size"] == 2 and ds.attrs["job_seed"] == 20240611
        assert "quickstart" in ds.attrs["job_text"] and ds.attrs["parsim_version"]
        assert float(ds.radius) == 0.2  # fixed parameters are scalar coordinates
        # a physicist's sanity check: fractal aggregates between a line and a filled plane
        assert float(ds.fractal_dimension.min()) > 1.0 and float(ds.fractal_dimension.max()) < 2.0


@pytest.mark.mpi
def test_task_snapshot_layout(quickstart_two_ranks):
    job = load_job(QUICKSTART, SOLVERS)
    task = job.tasks()[4 * job.realizations + 1]  # n_spheres = 400, volume_fraction = 0.2, realisation 1
    with h5py.File(quickstart_two_ranks / "tasks" / f"{task.label}.h5") as snapshot:
        n = snapshot["spheres/position"].shape[0]
        assert snapshot["spheres/position"].shape == (n, 2) and snapshot["spheres/radius"].shape == (n,)
        assert snapshot["spheres/velocity"].shape == (n, 2) and snapshot["spheres/cluster"].dtype == np.int64
        assert snapshot["links"].shape == (n - 1, 2) and snapshot["links"].dtype == np.int64
        length = snapshot["statistics/box_length"][()]
        np.testing.assert_array_equal(snapshot.attrs["box_upper"], [length, length])
        assert list(snapshot.attrs["periodic"]) == [False, False]
        assert snapshot.attrs["n_spheres"] == n == 400 and snapshot.attrs["volume_fraction"] == 0.2
        assert snapshot.attrs["job_seed"] == 20240611 and snapshot.attrs["task"] == task.label
        assert list(snapshot.attrs["spawn_key"]) == list(job.seed_sequence(task).spawn_key)
        assert len(snapshot.attrs["spawn_key"]) == 5 and snapshot.attrs["spawn_key"][-1] == 1
        assert snapshot.attrs["parsim_version"] == parsim.__version__
        assert snapshot.attrs["parsim_output_schema"] == OUTPUT_SCHEMA
        units = [snapshot.attrs[key] for key in ("length_unit", "time_unit", "mass_unit")]
        assert units == ["m", "s", "kg"]


@pytest.mark.mpi
def test_killed_job_resumes_to_the_same_dataset(quickstart_two_ranks, tmp_path):
    tasks = tmp_path / "tasks"
    command = [mpiexec(), "-n", "2", sys.executable, *parsim_command("run", QUICKSTART, "--output", str(tmp_path), "--quiet")]
    process = subprocess.Popen(command, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 300
    while len(list(tasks.glob("*.h5"))) < 3 and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.01)
    kill_session(process)  # mpiexec and every rank at once, as a node failure would
    finished = len(list(tasks.glob("*.h5")))
    assert 3 <= finished < 36, "the kill should land in the middle of the job"
    assert not (tmp_path / "quickstart.nc").exists()
    (tasks / "0123456789abcdef_r0000.h5.123.tmp").write_bytes(b"half-written")  # what a kill during a write leaves

    result = run_mpi(parsim_command("run", QUICKSTART, "--output", str(tmp_path), "--quiet"))
    assert result.returncode == 0, result.stderr
    assert not list(tmp_path.rglob("*.tmp"))
    xr.testing.assert_identical(reproducible_part(tmp_path / "quickstart.nc"),
                                reproducible_part(quickstart_two_ranks / "quickstart.nc").assign_attrs())


def test_a_folder_of_an_older_parsim_is_refused_in_one_line(tmp_path):
    """Task files without the schema attribute, as parsim 0.1 wrote them: one line naming folder and schemas."""
    job = tmp_path / "job.toml"
    job.write_text(Path(QUICKSTART).read_text().replace("[100, 400, 900]", "[16]").replace("realizations = 4",
                                                                                          "realizations = 1"))
    out = tmp_path / "out"
    assert run_serial("run", str(job), "--output", str(out), "--quiet").returncode == 0
    for path in (out / "tasks").glob("*.h5"):
        with h5py.File(path, "a") as task:
            del task.attrs["parsim_output_schema"], task.attrs["parsim_version"]
    result = run_serial("run", str(job), "--output", str(out), "--quiet")
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert error_lines(result.stderr) == [
        f"parsim: error: output folder {out} was written by an older parsim (output schema 1, which records none); "
        f"parsim {parsim.__version__} reads and writes output schema {OUTPUT_SCHEMA}: read or finish it with the parsim "
        f"that wrote it, or compute the job again into another output folder (key 'output' or option --output) or "
        f"after removing {out}"]


def test_resume_refuses_a_different_job(tmp_path):
    job = tmp_path / "job.toml"
    text = Path(QUICKSTART).read_text().replace("[100, 400, 900]", "[16]").replace("realizations = 4", "realizations = 1")
    job.write_text(text)
    assert run_serial("run", str(job), "--output", str(tmp_path / "out"), "--quiet").returncode == 0
    job.write_text(text.replace("seed = 20240611", "seed = 1"))
    result = run_serial("run", str(job), "--output", str(tmp_path / "out"), "--quiet")
    assert result.returncode == 2 and "differs in: seed" in result.stderr
    info = run_serial("info", str(tmp_path / "out"))
    assert info.returncode == 0 and "tasks finished: 3 of 3" in info.stdout and "fractal_dimension" in info.stdout


def wait_for_task_files(tasks: Path, count: int, process: subprocess.Popen, seconds: float = 300) -> None:
    deadline = time.monotonic() + seconds
    while len(list(tasks.glob("*.h5"))) < count and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.01)


def ended_after_signal(process: subprocess.Popen, what: str) -> tuple[list[str], str]:
    """The lines parsim printed, and the whole standard error, of a run that must end within 30 s of the
    signal ``what`` (else every process of its session is killed and the test fails)."""
    try:
        _, stderr = process.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        kill_session(process)
        raise AssertionError(f"the ranks did not end within 30 s of {what}") from None
    return [line for line in error_lines(stderr) if not line.startswith("[mpiexec@")], stderr  # not the launcher's


@pytest.mark.mpi
def test_ctrl_c_ends_every_rank_with_one_line_and_resumes(quickstart_two_ranks, tmp_path):
    # Ctrl-C in a terminal signals mpiexec, which forwards SIGINT to every rank.
    command = [mpiexec(), "-n", "2", sys.executable, *parsim_command("run", QUICKSTART, "--output", str(tmp_path), "--quiet")]
    # (SIGINT as in a terminal: a test suite started in the background of a shell ignores it)
    process = subprocess.Popen(command, start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    wait_for_task_files(tmp_path / "tasks", 3, process)
    interrupted = time.monotonic()
    process.send_signal(signal.SIGINT)
    lines, stderr = ended_after_signal(process, "Ctrl-C")
    assert time.monotonic() - interrupted < 10
    assert process.returncode == 130, stderr
    assert len(lines) == 1 and "Traceback" not in stderr, stderr
    kept = len(list((tmp_path / "tasks").glob("*.h5")))
    assert lines[0] == f"parsim: interrupted; {kept} of 36 tasks kept, run the same command to finish"
    assert 3 <= kept < 36, "the interrupt should land in the middle of the job"
    assert not (tmp_path / "parsim.lock").exists()

    result = run_mpi(parsim_command("run", QUICKSTART, "--output", str(tmp_path), "--quiet"))
    assert result.returncode == 0, result.stderr
    xr.testing.assert_identical(reproducible_part(tmp_path / "quickstart.nc"),
                                reproducible_part(quickstart_two_ranks / "quickstart.nc"))


def _rank_pids(launcher: int) -> dict[int, int]:
    """The PIDs of the ranks that the launcher ``launcher`` started, by rank (each one's PMI_RANK)."""
    parents = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            parents[int(stat.parent.name)] = int(stat.read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError):
            continue
    descendants, added = {launcher}, True
    while added:
        grown = descendants | {pid for pid, parent in parents.items() if parent in descendants}
        added, descendants = grown != descendants, grown
    ranks = {}
    for pid in descendants:
        try:
            environment = Path(f"/proc/{pid}/environ").read_bytes().split(b"\0")
        except OSError:
            continue
        for entry in environment:
            if entry.startswith(b"PMI_RANK="):
                ranks[int(entry.split(b"=", 1)[1])] = pid
    return ranks


@pytest.mark.mpi
def test_a_slow_rank_0_still_gives_one_line(quickstart_two_ranks, tmp_path):
    """Rank 0 takes longer to count the kept tasks than the other ranks wait for it: they hear that it has
    the signal, and the run still ends with its line alone."""
    slow = (f"import parsim.runner, parsim.cli; parsim.runner.WRITE_SETTLE_SECONDS = "
            f"2 * parsim.runner.SIGNAL_GRACE_SECONDS; parsim.cli.main(['run', '{QUICKSTART}', '--output', "
            f"'{tmp_path}', '--quiet'])")
    process = subprocess.Popen([mpiexec(), "-n", "2", sys.executable, "-c", slow], start_new_session=True,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    wait_for_task_files(tmp_path / "tasks", 3, process)
    os.killpg(process.pid, signal.SIGTERM)
    lines, stderr = ended_after_signal(process, "SIGTERM")
    assert len(lines) == 1 and lines[0].startswith("parsim: stopped by SIGTERM; "), stderr
    assert not (tmp_path / "parsim.lock").exists()


@pytest.mark.mpi
def test_a_signal_to_one_other_rank_alone_ends_the_job_with_its_line(quickstart_two_ranks, tmp_path):
    """A SIGTERM that reaches rank 1 but not rank 0: rank 1 says so and ends the job within seconds."""
    command = [mpiexec(), "-n", "2", sys.executable, *parsim_command("run", QUICKSTART, "--output", str(tmp_path),
                                                                      "--quiet")]
    process = subprocess.Popen(command, start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    wait_for_task_files(tmp_path / "tasks", 3, process)
    os.kill(_rank_pids(process.pid)[1], signal.SIGTERM)
    signalled = time.monotonic()
    lines, stderr = ended_after_signal(process, "SIGTERM to rank 1")
    assert time.monotonic() - signalled < 10
    assert process.returncode != 0
    assert lines == ["parsim: rank 1 got SIGTERM; run the same command to finish"], stderr


@pytest.mark.parametrize("number", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_or_sighup_of_the_process_group_keeps_the_finished_tasks(tmp_path, number):
    """A batch system's SIGTERM, a closed terminal's SIGHUP: the line, the shell's status, the lock gone; the
    same command then computes the other tasks alone."""
    command = [sys.executable, *parsim_command("run", QUICKSTART, "--output", str(tmp_path), "--quiet")]
    process = subprocess.Popen(command, start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    wait_for_task_files(tmp_path / "tasks", 2, process)
    os.killpg(process.pid, number)
    _, stderr = process.communicate(timeout=30)
    kept = {path: path.read_bytes() for path in (tmp_path / "tasks").glob("*.h5")}
    assert process.returncode == 128 + number
    assert error_lines(stderr) == [f"parsim: stopped by {number.name}; {len(kept)} of 36 tasks kept, run the same "
                                   "command to finish"]
    assert not (tmp_path / "parsim.lock").exists()

    result = run_serial("run", QUICKSTART, "--output", str(tmp_path), "--quiet")
    assert result.returncode == 0, result.stderr
    assert all(path.read_bytes() == content for path, content in kept.items())  # kept, not computed again
    with xr.open_dataset(tmp_path / "quickstart.nc") as dataset:
        assert dataset.fractal_dimension.size == 36 and bool(dataset.fractal_dimension.notnull().all())


@pytest.mark.mpi
def test_sighup_of_mpiexec_leaves_no_lock_to_remove_and_loses_nothing(quickstart_two_ranks, tmp_path):
    """MPICH's mpiexec does not forward SIGHUP, as it does SIGINT and SIGTERM: it ends at once, and its proxies
    kill the ranks, which get no signal (each runs in a session of its own), so no rank can say a line or remove
    the lock. The next run takes the lock over by itself (its holder, rank 0, is gone) and finishes the job."""
    command = [mpiexec(), "-n", "2", sys.executable, *parsim_command("run", QUICKSTART, "--output", str(tmp_path),
                                                                       "--quiet")]
    process = subprocess.Popen(command, start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    wait_for_task_files(tmp_path / "tasks", 3, process)
    holder = read_holder(tmp_path / LOCK_NAME)
    os.killpg(process.pid, signal.SIGHUP)
    try:
        process.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        kill_session(process)
        raise AssertionError("mpiexec did not end within 30 s of SIGHUP") from None
    deadline = time.monotonic() + 30
    while Path(f"/proc/{holder.pid}").exists() and time.monotonic() < deadline:
        time.sleep(0.01)
    assert 3 <= len(list((tmp_path / "tasks").glob("*.h5"))) < 36, "the signal should land in the middle of the job"

    result = run_mpi(parsim_command("run", QUICKSTART, "--output", str(tmp_path), "--quiet"))
    assert result.returncode == 0, result.stderr
    assert not (tmp_path / LOCK_NAME).exists()
    xr.testing.assert_identical(reproducible_part(tmp_path / "quickstart.nc"),
                                reproducible_part(quickstart_two_ranks / "quickstart.nc"))


@pytest.mark.mpi
def test_kill_while_the_dataset_is_assembled_loses_nothing(quickstart_two_ranks, tmp_path):
    # Every task is finished, so the run goes straight to the dataset; it is killed at several moments of it.
    reference = reproducible_part(quickstart_two_ranks / "quickstart.nc")
    shutil.copytree(quickstart_two_ranks / "tasks", tmp_path / "tasks")
    shutil.copy(quickstart_two_ranks / "job.toml", tmp_path / "job.toml")
    command = [sys.executable, *parsim_command("run", QUICKSTART, "--output", str(tmp_path), "--quiet")]
    killed_while_assembling = 0
    for delay in (0.0, 0.05, 0.1, 0.2, 0.4):
        (tmp_path / "quickstart.nc").unlink(missing_ok=True)
        process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        holds_the_lock = f"pid = {process.pid}\n"  # from then on, the run has nothing left but the dataset
        while holds_the_lock not in _text(tmp_path / "parsim.lock") and process.poll() is None:
            time.sleep(0.001)
        time.sleep(delay)
        process.kill()
        process.wait()
        if (tmp_path / "quickstart.nc").exists():  # the kill came after the write: the dataset is whole
            xr.testing.assert_identical(reproducible_part(tmp_path / "quickstart.nc"), reference)
        else:
            killed_while_assembling += process.returncode == -signal.SIGKILL
    assert killed_while_assembling >= 1
    result = run_mpi(parsim_command("run", QUICKSTART, "--output", str(tmp_path), "--quiet"))
    assert result.returncode == 0, result.stderr
    assert not list(tmp_path.rglob("*.tmp"))
    xr.testing.assert_identical(reproducible_part(tmp_path / "quickstart.nc"), reference)


def _text(path: Path) -> str:
    try:
        return path.read_text()
    except FileNotFoundError:
        return ""
