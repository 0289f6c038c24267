"""The commands that read an output folder (info, collect, export, plot) use what the folder holds.

They read the folder's job copy with the input hashes that ``inputs.json`` records, never the
input files the job names (which are relative to the working directory of the run), so they
work from any working directory and after an input file was edited or removed.  A damaged job
copy or input record is one line naming the file, for every command that reads the folder.
"""

import contextlib
import shutil
import subprocess
import sys

import pytest

from parsim.cli import main
from tests.datasets import run_serial, unfinish

FLAKE = "x,y,z,r\n0,0,0,1\n1.5,0,0,1\n"
JOB = """
name = "flakes"
kind = "deposition"
seed = 1
realizations = 2
output = "out"
[parameters]
n_particles = 10
box_length = 20.0
packing_samples = 1000
shape = "agglomerate"
agglomerate_file = "flake.csv"
[sweep]
trial_angle = [0.01, 0.02]
"""


@pytest.fixture(scope="module")
def computed(tmp_path_factory):
    """A project folder: the job, its agglomerate file (named relative to the project) and the finished output."""
    project = tmp_path_factory.mktemp("project")
    (project / "job.toml").write_text(JOB)
    (project / "flake.csv").write_text(FLAKE)
    result = run_serial("run", "job.toml", "--quiet", cwd=project)
    assert result.returncode == 0, result.stderr
    with contextlib.chdir(project):
        unfinish(project / "out", [(1, 0)])  # as if a run had stopped before it: 3 of 4 tasks finished
    return project


def change(project, how: str) -> None:
    if how == "edited":
        (project / "flake.csv").write_text(FLAKE.replace("1.5", "1.8"))
    elif how == "removed":
        (project / "flake.csv").unlink()


@pytest.fixture(params=["elsewhere", "edited", "removed"])
def project(request, computed, tmp_path, monkeypatch):
    """A copy of the computed project, its input file left, edited or removed, and a working directory
    that is not the project's."""
    copy = tmp_path / "project"
    shutil.copytree(computed, copy)
    change(copy, request.param)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    return copy


def test_info_describes_the_folder(project, capsys):
    assert main(["info", str(project / "out")]) == 0
    captured = capsys.readouterr()
    assert "tasks finished: 3 of 4 (75 %)" in captured.out and captured.err == ""


def test_collect_finds_the_finished_tasks(project, capsys):
    assert main(["collect", str(project / "out")]) == 0
    assert "3 of 4 tasks finished" in capsys.readouterr().out


def test_export_writes_the_first_task(project, capsys):
    assert main(["export", str(project / "out"), "--format", "csv", "--out", str(project / "first.csv")]) == 0
    assert (project / "first.csv").read_text().count("\n") > 10


def test_plot_draws_a_figure_and_the_sediment(project, capsys):
    assert main(["collect", str(project / "out")]) == 0
    partial = project / "out" / "flakes.partial.nc"
    for figure in ("filling_height", "sediment"):
        assert main(["plot", str(partial), "--figure", figure, "--out", str(project / figure)]) == 0
        assert (project / f"{figure}.png").stat().st_size > 1000


def test_info_in_a_terminal_away_from_the_project(computed, tmp_path):
    result = run_serial("info", str(computed / "out"), cwd=tmp_path)
    assert result.returncode == 0 and result.stderr == "", result.stderr
    assert "tasks finished: 3 of 4 (75 %)" in result.stdout


DAMAGES = {
    "binary job copy": ("job.toml", b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\xff\xfe"),
    "job copy that is not TOML": ("job.toml", b'name = "flakes\nkind = deposition\n'),
    "input record that is a list": ("inputs.json", b'["flake.csv"]\n'),
    "input record of lists": ("inputs.json", b'{"agglomerate_file": ["flake.csv"]}\n'),
    "input record that is not JSON": ("inputs.json", b"{agglomerate_file: flake.csv\n"),
    "input record that is binary": ("inputs.json", b"\xff\xfe\x00{"),
}
COMMANDS = {
    "info": ["info", "{out}"],
    "collect": ["collect", "{out}"],
    "plot": ["plot", "{out}"],
    "export": ["export", "{out}", "--format", "csv"],
    "validate": ["validate", "{job}", "--output", "{out}"],
    "run": ["run", "{job}", "--output", "{out}", "--quiet"],
}


@pytest.fixture
def damaged(request, computed, tmp_path, monkeypatch):
    """A copy of the computed project whose output folder has one damaged file; the file."""
    copy = tmp_path / "project"
    shutil.copytree(computed, copy)
    name, content = DAMAGES[request.param]
    (copy / "out" / name).write_bytes(content)
    monkeypatch.chdir(copy)
    return copy / "out" / name


@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.parametrize("damaged", DAMAGES, indirect=True)
def test_a_damaged_folder_is_one_line_naming_the_file(damaged, command, capsys):
    arguments = [part.format(out=damaged.parent, job=damaged.parent.parent / "job.toml") for part in COMMANDS[command]]
    assert main(arguments) == 2
    captured = capsys.readouterr()
    (line,) = captured.err.splitlines()
    assert line.startswith("parsim: error: ") and str(damaged) in line, line
    assert "Traceback" not in captured.err


def test_a_damaged_folder_in_a_terminal(computed, tmp_path):
    copy = tmp_path / "project"
    shutil.copytree(computed, copy)
    (copy / "out" / "inputs.json").write_text("[]\n")
    result = subprocess.run([sys.executable, "-m", "parsim", "collect", str(copy / "out")], capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 2
    (line,) = result.stderr.splitlines()
    assert line.startswith("parsim: error: ") and str(copy / "out" / "inputs.json") in line


def test_a_damaged_task_file_says_what_removing_it_does(computed, tmp_path, capsys):
    copy = tmp_path / "project"
    shutil.copytree(computed, copy)
    out = copy / "out"
    damaged = next((out / "tasks").glob("*.h5"))  # the task file the folder's checks read first
    damaged.write_bytes(b"\x89HDF\r\n\x1a\n cut off")
    assert main(["info", str(out)]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"parsim: error: cannot read task file {damaged}: ")
    assert line.endswith(f"remove it to use the folder again: its task stays finished (its statistics are in "
                         f"{out / 'rows'}), without its configuration, which only the job computed into another "
                         "output folder gives again")
    damaged.unlink()  # what the line says, and what follows
    assert main(["info", str(out)]) == 0
    assert "tasks finished: 3 of 4" in capsys.readouterr().out  # still finished
    result = run_serial("run", "job.toml", "--quiet", cwd=copy)
    assert result.returncode == 0, result.stderr
    assert not damaged.exists()  # its configuration is not computed again in this folder


def test_a_damaged_dataset_is_one_line(computed, tmp_path, capsys):
    copy = tmp_path / "project"
    shutil.copytree(computed, copy)
    dataset = copy / "out" / "flakes.nc"
    dataset.write_bytes(b"CDF\x01 cut off")
    assert main(["info", str(copy / "out")]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"parsim: error: cannot read the dataset {dataset}: ")
