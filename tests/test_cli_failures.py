"""Every failure of the command line ends in one line, or for a bug in one traceback, never two.

A phase made to fail (by a small script that replaces it, then runs the command line) shows
what the terminal gets: one line ``parsim: error: ...`` with the right status; a bug's
traceback once, however many ranks met it; Ctrl-C while parsim starts, one line and status
130; a reader that closes the pipe, a quiet end.
"""

import os
import signal
import subprocess
import sys

import pytest

from parsim.cli import main
from parsim.options import duration
from parsim.output.folder import OutputFolder
from parsim.job import parse_job
from parsim.solvers import SOLVERS
from tests.mpi import error_lines, run_mpi

JOB = """
name = "failing"
kind = "aggregation"
seed = 1
realizations = 2
[parameters]
dimension = 2
n_spheres = 25
volume_fraction = 0.2
"""

PATCHED = """
import os, signal, sys, time
import {module}
from parsim.errors import OutputError
from mpi4py import MPI

def replaced(*args, **kwargs):
    if {ranks} is None or MPI.COMM_WORLD.Get_rank() in {ranks}:
        {action}
    return original(*args, **kwargs)

original = {module}.{name}
{module}.{name} = replaced
from parsim.cli import main
sys.exit(main(sys.argv[1:]))
"""


def patched_script(tmp_path, target: str, action: str, ranks=None) -> str:
    """A script that runs the command line with ``target`` (module.function) doing ``action`` first
    (on the ``ranks`` listed, or every rank); its path."""
    module, name = target.rsplit(".", 1)
    script = tmp_path / "patched.py"
    script.write_text(PATCHED.format(module=module, name=name, action=action, ranks=ranks))
    return str(script)


@pytest.fixture
def job(tmp_path):
    path = tmp_path / "job.toml"
    path.write_text(JOB)
    return path


def lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.strip()]


def test_a_bug_in_a_one_rank_run_is_raised_once(job, tmp_path, monkeypatch):
    import parsim.runner

    def bug(*args, **kwargs):
        raise RuntimeError("a bug")

    monkeypatch.setattr(parsim.runner, "run_job", bug)
    with pytest.raises(RuntimeError, match="a bug"):  # its one traceback, no error about the run's outcome
        main(["run", str(job), "--output", str(tmp_path / "out"), "--quiet"])


def test_an_error_of_a_one_rank_run_is_one_line(job, tmp_path):
    script = patched_script(tmp_path, "parsim.runner.run_job", "raise OutputError('no space left on the disk')")
    result = subprocess.run([sys.executable, script, "run", str(job), "--output", str(tmp_path / "out")],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 1
    assert lines(result.stderr) == ["parsim: error: no space left on the disk"]


@pytest.mark.mpi
@pytest.mark.parametrize("target, action, ranks, status, line", [
    # a bug on the path every rank takes: one traceback, not one per rank
    ("parsim.runner.run_job", "raise RuntimeError('a bug')", None, 1, "parsim: error: rank 0 failed: Traceback"),
    # a bug in a phase of rank 0 alone
    ("parsim.runner._claim", "raise RuntimeError('a bug')", None, 1, "parsim: error: rank 0 failed: Traceback"),
    # the same error on every rank, as a full disk gives: one line
    ("parsim.runner.run_job", "raise OutputError('no space left')", None, 1,
     "parsim: error: no space left (on rank 0)"),
    # an error of one rank other than 0: its line
    ("parsim.runner.run_job", "raise OutputError('no space left')", [1], 1,
     "parsim: error: no space left (on rank 1)"),
])
def test_a_failure_under_mpi_is_reported_once(job, tmp_path, target, action, ranks, status, line):
    script = patched_script(tmp_path, target, action, ranks)
    result = run_mpi([script, "run", str(job), "--output", str(tmp_path / "out"), "--quiet"], timeout=120)
    assert result.returncode == status, result.stderr
    reported = [text for text in error_lines(result.stderr) if text.startswith("parsim: error:")]
    assert len(reported) == 1 and reported[0].startswith(line), result.stderr
    assert result.stderr.count("Traceback") <= 1 and "UnboundLocalError" not in result.stderr, result.stderr


@pytest.mark.parametrize("command", ["run", "validate"])
def test_ctrl_c_while_the_job_is_read_is_one_line(job, tmp_path, command):
    script = patched_script(tmp_path, "parsim.job.load_job", "os.kill(os.getpid(), signal.SIGINT); time.sleep(30)")
    # a test suite started in the background of a shell ignores SIGINT, and so would the child: undo that
    result = subprocess.run([sys.executable, script, command, str(job), "--output", str(tmp_path / "out")],
                            capture_output=True, text=True, timeout=120,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert result.returncode == 128 + signal.SIGINT
    assert len(lines(result.stderr)) == 1 and lines(result.stderr)[0].startswith("parsim: interrupted"), result.stderr


def test_ctrl_c_while_mpi_starts_is_one_line(job, tmp_path, monkeypatch, capsys):
    import parsim.parallel.launcher

    def interrupted():
        raise KeyboardInterrupt

    monkeypatch.setattr(parsim.parallel.launcher, "start_mpi", interrupted)
    assert main(["run", str(job), "--output", str(tmp_path / "out")]) == 128 + signal.SIGINT
    assert lines(capsys.readouterr().err) == ["parsim: interrupted before any task started"]


def test_info_into_a_closed_pipe_ends_quietly(job, tmp_path):
    out = tmp_path / "out"
    OutputFolder(out, "failing").prepare(parse_job(JOB, SOLVERS, output=out), None)
    reader, writer = os.pipe()
    os.close(reader)  # the reader is gone before parsim writes, as `parsim info OUT | head -1` may leave it
    result = subprocess.run([sys.executable, "-m", "parsim", "info", str(out)], stdout=writer,
                            stderr=subprocess.PIPE, text=True, timeout=120)
    os.close(writer)
    assert result.stderr == ""
    assert result.returncode == 128 + signal.SIGPIPE


@pytest.mark.parametrize("limit", ["-00:00:05", "-1-00:00:00", "1--00:00:05", "1-", "+1-00:00:00"])
def test_a_negative_or_malformed_time_limit_is_refused(limit):
    with pytest.raises(Exception, match="allowed: HH:MM:SS or D-HH:MM:SS"):
        duration(limit)


def test_a_negative_time_limit_is_one_line(job, capsys):
    with pytest.raises(SystemExit) as ended:
        main(["run", str(job), "--time-limit=-00:00:05"])
    assert ended.value.code == 2
    (line,) = lines(capsys.readouterr().err)
    assert line.startswith("parsim: error: argument --time-limit: '-00:00:05': allowed: HH:MM:SS")


USAGE_ERRORS = [(["--ranks-per-task", "two"], "argument --ranks-per-task: invalid int value: 'two'"),
                (["--time-limit", "5 minutes"], "argument --time-limit: '5 minutes': allowed: HH:MM:SS")]


@pytest.mark.mpi
@pytest.mark.parametrize("option, line", USAGE_ERRORS)
def test_a_usage_error_under_mpi_is_one_line(job, tmp_path, option, line):
    result = run_mpi(["-m", "parsim", "run", str(job), "--output", str(tmp_path / "out"), *option], timeout=120)
    assert result.returncode == 2, result.stderr
    (reported,) = error_lines(result.stderr)
    assert reported.startswith(f"parsim: error: {line}"), result.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("option, line", USAGE_ERRORS)
def test_a_usage_error_is_said_by_the_launchers_rank_0_alone(job, tmp_path, option, line):
    """Each rank of a launch exits with status 2; the others say nothing, whichever launcher started them."""
    for rank, said in (("0", [line]), ("1", [])):
        environment = {**os.environ, "PMI_RANK": rank}
        result = subprocess.run([sys.executable, "-m", "parsim", "run", str(job), *option], capture_output=True,
                                text=True, timeout=120, env=environment)
        assert result.returncode == 2, result.stderr
        assert [text.split("parsim: error: ")[1][:len(line)] for text in lines(result.stderr)] == said, rank


def test_nothing_runs_on_after_an_abort_that_returns(tmp_path):
    # MPICH's MPI_Abort may return when the launcher is ending the job already; the rank must end anyway,
    # or the command would go on with a result it does not have
    script = tmp_path / "returning.py"
    script.write_text("from parsim.parallel.collective import abort_job\n"
                      "class Returning:\n"
                      "    def Abort(self, status):\n"
                      "        pass\n"
                      "abort_job(Returning(), 'no space left', 3)\n"
                      "print('ran on')\n")
    result = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 3 and "ran on" not in result.stdout
    assert lines(result.stderr) == ["parsim: error: no space left"]


def unwritable_cache(tmp_path, below: str):
    """An environment whose kernel cache cannot be written: XDG_CACHE_HOME at a regular file (``below``
    empty) or at a folder below one (root may write in a read-only folder, not below a file); the file."""
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    env = {key: value for key, value in os.environ.items() if key != "NUMBA_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(blocker / below)
    return env, blocker


@pytest.mark.parametrize("below", ["", "cache"])
@pytest.mark.parametrize("with_job", [True, False])
def test_compile_into_a_cache_it_cannot_write_is_one_line(job, tmp_path, below, with_job):
    env, blocker = unwritable_cache(tmp_path, below)
    result = subprocess.run([sys.executable, "-m", "parsim", "compile", *([str(job)] if with_job else [])],
                            capture_output=True, text=True, timeout=120, env=env)
    assert result.returncode == 2 and result.stdout == ""  # nothing compiled, nothing said to be in the cache
    (line,) = lines(result.stderr)
    assert line.startswith(f"parsim: error: the kernel cache {blocker / below / 'parsim' / 'numba'}"), line
    assert f"cannot be written ({blocker} is a file)" in line and "set XDG_CACHE_HOME" in line, line


@pytest.mark.mpi
def test_a_run_without_a_writable_cache_says_so_once_and_runs(job, tmp_path):
    """Rank 0 alone says that the kernels are compiled in every process, once, --quiet or not; costs the
    job's kernels compiled on both ranks at once (a 2-D event-driven aggregation: 10-30 s)."""
    env, blocker = unwritable_cache(tmp_path, "")
    result = run_mpi(["-m", "parsim", "run", str(job), "--output", str(tmp_path / "out"), "--quiet"], timeout=900,
                     env=env)
    assert result.returncode == 0, result.stderr
    (line,) = error_lines(result.stderr)
    assert line.startswith(f"parsim: the kernel cache {blocker / 'parsim' / 'numba'}"), line
    assert "the kernels are compiled in every process" in line and "set XDG_CACHE_HOME" in line, line
    assert (tmp_path / "out" / "failing.nc").exists()
