"""What pip installs: mpi4py as the only MPI dependency, an MPI runtime only by request, one version."""

import subprocess
import sys
import tomllib
from importlib.metadata import metadata, requires
from pathlib import Path

import parsim

ROOT = Path(__file__).resolve().parent.parent


def test_the_mpi_runtime_comes_only_with_an_extra():
    requirements = requires("parsim")
    unconditional = {r.split(";")[0].split(">")[0].split("=")[0].strip() for r in requirements if ";" not in r}
    assert "mpi4py" in unconditional
    assert not unconditional & {"mpich", "openmpi", "impi-rt"}
    assert any(r.startswith("mpich") and 'extra == "mpich"' in r for r in requirements)
    assert any(r.startswith("openmpi") and 'extra == "openmpi"' in r for r in requirements)


def test_one_version_everywhere():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    citation = (ROOT / "CITATION.cff").read_text()
    assert parsim.__version__ == project["version"] == metadata("parsim")["Version"]
    assert f'version: "{project["version"]}"' in citation
    assert f"## [{project['version']}]" in (ROOT / "CHANGELOG.md").read_text()
    for command in (["-m", "parsim", "--version"], ["-m", "parsim.cli", "--version"]):
        shown = subprocess.run([sys.executable, *command], capture_output=True, text=True, check=True).stdout
        assert shown.strip() == f"parsim {project['version']}"


def test_the_licence_is_declared_and_shipped():
    assert metadata("parsim")["License-Expression"] == "BSD-3-Clause"
    assert (ROOT / "LICENSE").read_text().startswith("BSD 3-Clause License")
