"""Launch ``mpiexec -n K`` from a test, with the interpreter running the tests."""

import os
import shutil
import subprocess
import sys
from pathlib import Path


def mpiexec() -> str:
    beside_python = Path(sys.executable).with_name("mpiexec")
    found = str(beside_python) if beside_python.exists() else shutil.which("mpiexec")
    if found is None:
        raise RuntimeError("mpiexec not found: install the test dependencies (pip install '.[test]')")
    return found


def run_mpi(arguments: list[str], ranks: int = 2, timeout: float = 600, cwd=None) -> subprocess.CompletedProcess:
    """Run ``python ARGUMENTS`` on ``ranks`` ranks; returns the completed process (output captured)."""
    command = [mpiexec(), "-n", str(ranks), sys.executable, *arguments]
    return subprocess.run(command, capture_output=True, text=True, timeout=timeout, cwd=cwd, env=dict(os.environ))


def parsim_command(*arguments: str) -> list[str]:
    """Arguments that run the parsim command line with the test interpreter."""
    return ["-m", "parsim.cli", *arguments]
