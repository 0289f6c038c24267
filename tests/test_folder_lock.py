"""One run per output folder: a second run is refused at once, a dead run's lock is taken over."""

import os
import socket
import subprocess
import sys
import time

import pytest

from parsim.errors import JobError
from parsim.output.lock import LOCK_NAME, STALE_SECONDS, FolderLock, read_holder
from tests.mpi import error_lines, kill_session, mpiexec, parsim_command, run_mpi_bounded

LONG_JOB = """
name = "long"
kind = "aggregation"
seed = 3
realizations = 10
[parameters]
method = "ed"
volume_fraction = 0.2
n_spheres = 40000
"""


#: A refusal comes before anything is computed: the start-up of two interpreters, and little else.
REFUSAL_SECONDS = 20


def write_lock(folder, host, pid, age=0.0):
    path = folder / LOCK_NAME
    path.write_text(f'host = "{host}"\npid = {pid}\nstarted = "2026-01-01T00:00:00+00:00"\ncommand = "parsim run"\n')
    then = time.time() - age
    os.utime(path, (then, then))
    return path


def dead_pid():
    process = subprocess.Popen([sys.executable, "-c", "pass"])
    process.wait()
    return process.pid


def test_a_live_holder_is_named_and_its_lock_kept(tmp_path):
    path = write_lock(tmp_path, socket.gethostname(), os.getpid())
    with pytest.raises(JobError, match=f"in use by another parsim run \\(process {os.getpid()} on host ") as error:
        FolderLock(tmp_path).acquire()
    assert str(error.value).endswith("; wait for it to finish or give another output folder")  # it is alive
    assert path.exists()


def test_a_dead_holder_on_this_host_is_taken_over(tmp_path):
    write_lock(tmp_path, socket.gethostname(), dead_pid())
    lock = FolderLock(tmp_path)
    lock.acquire()
    assert f"pid = {os.getpid()}" in (tmp_path / LOCK_NAME).read_text()
    lock.release()
    assert not (tmp_path / LOCK_NAME).exists()


def test_a_holder_on_another_host_counts_as_alive_while_it_beats(tmp_path):
    write_lock(tmp_path, "another-node", 1, age=STALE_SECONDS / 2)
    with pytest.raises(JobError, match="on host another-node") as error:
        FolderLock(tmp_path).acquire()
    assert str(error.value).endswith(f"; wait for it to finish or give another output folder (if that run is dead, "
                                     f"the next run takes its lock over {STALE_SECONDS:.0f} s after its last refresh)")
    write_lock(tmp_path, "another-node", 1, age=2 * STALE_SECONDS)  # no heartbeat: that run is gone
    lock = FolderLock(tmp_path)
    lock.acquire()
    lock.release()


def test_a_second_lock_in_the_same_process_is_refused(tmp_path):
    first = FolderLock(tmp_path)
    first.acquire()
    with pytest.raises(JobError, match="in use by another parsim run"):
        FolderLock(tmp_path).acquire()
    first.release()


@pytest.mark.mpi
def test_a_second_run_into_a_busy_folder_is_refused_at_once(tmp_path):
    job = tmp_path / "long.toml"
    job.write_text(LONG_JOB)
    out = tmp_path / "out"
    arguments = parsim_command("run", str(job), "--output", str(out), "--quiet")
    first = subprocess.Popen([mpiexec(), "-n", "2", sys.executable, *arguments], start_new_session=True,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 300
        while (holder := read_holder(out / LOCK_NAME)) is None and time.monotonic() < deadline:
            assert first.poll() is None, "the first run ended before it took the lock"
            time.sleep(0.01)
        second, seconds = run_mpi_bounded(arguments, bound=60)
        assert first.poll() is None, "the first run should still be running"
        lines = error_lines(second.stderr)
        assert second.returncode == 2 and len(lines) == 1, second.stderr
        assert lines[0].startswith(f"parsim: error: output folder {out} is in use by another parsim run "
                                   f"(process {holder.pid} on host {socket.gethostname()}")
        assert seconds < REFUSAL_SECONDS
        _, stderr = first.communicate(timeout=600)
    except BaseException:
        kill_session(first)
        raise
    assert first.returncode == 0, stderr  # the refused run took nothing from the first one
    assert (out / "long.nc").exists() and not (out / LOCK_NAME).exists()
