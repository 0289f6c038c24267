"""Launch ``mpiexec -n K`` from a test, with the interpreter running the tests."""

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path


def mpiexec() -> str:
    beside_python = Path(sys.executable).with_name("mpiexec")
    found = str(beside_python) if beside_python.exists() else shutil.which("mpiexec")
    if found is None:
        raise RuntimeError("mpiexec not found: install the test dependencies (pip install '.[test]')")
    return found


def run_mpi(arguments: list[str], ranks: int = 2, timeout: float = 600, cwd=None,
            env=None) -> subprocess.CompletedProcess:
    """Run ``python ARGUMENTS`` on ``ranks`` ranks, in ``env`` (default: this process's environment);
    returns the completed process (output captured)."""
    command = [mpiexec(), "-n", str(ranks), sys.executable, *arguments]
    return subprocess.run(command, capture_output=True, text=True, timeout=timeout, cwd=cwd,
                          env=dict(os.environ) if env is None else env)


def parsim_command(*arguments: str) -> list[str]:
    """Arguments that run the parsim command line with the test interpreter."""
    return ["-m", "parsim.cli", *arguments]


def run_mpi_bounded(arguments: list[str], bound: float, ranks: int = 2, cwd=None):
    """Run ``python ARGUMENTS`` on ``ranks`` ranks in a session of its own; ``(process, seconds)``.

    A run still going after ``bound`` seconds is a hang: every process of the session is
    killed (mpiexec and the ranks it started) and the test fails, so a hung job cannot
    outlive the test that found it.
    """
    command = [mpiexec(), "-n", str(ranks), sys.executable, *arguments]
    start = time.monotonic()
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=cwd,
                               start_new_session=True)
    try:
        stdout, stderr = process.communicate(timeout=bound)
    except subprocess.TimeoutExpired:
        kill_session(process)
        stdout, stderr = process.communicate()
        raise AssertionError(f"still running after {bound} s (a hang); stderr:\n{stderr}") from None
    return subprocess.CompletedProcess(command, process.returncode, stdout, stderr), time.monotonic() - start


def kill_session(process: subprocess.Popen) -> None:
    """SIGKILL every process of the session that ``process`` leads (mpiexec, its proxies and ranks)."""
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    members = _session_members(process.pid)
    for pid in members:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    process.wait()
    deadline = time.monotonic() + 30
    while any(Path(f"/proc/{pid}").exists() for pid in members) and time.monotonic() < deadline:
        time.sleep(0.01)  # gone, not merely signalled: a next run must not meet them


def _session_members(session: int) -> list[int]:
    """PIDs whose session is ``session`` (hydra puts its proxies in process groups of their own)."""
    members = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[3]) == session:  # field 6 of /proc/PID/stat: the session id
            members.append(int(stat.parent.name))
    return members


def error_lines(stderr: str) -> list[str]:
    """The lines parsim printed on standard error, without the MPI library's own abort notice."""
    return [line for line in stderr.splitlines() if line.strip() and not line.startswith("Abort(")]
