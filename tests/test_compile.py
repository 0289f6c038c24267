"""``parsim compile`` fills the kernel cache so that the runs after it compile nothing and say nothing
about kernels, on one rank and spread over several (``--ranks-per-task``).

The tests use the suite's kernel cache (what other tests compiled stays there): ``parsim compile`` of a
deposition of spheres compiles whatever its tasks on one rank still lack, ``parsim compile
--ranks-per-task 2`` then whatever spread tasks lack, and the runs after each must compile nothing.
Cost: at most the two compilations, 1.8-3.8 and 2.6-3.3 minutes on 2 cores of an AMD EPYC shared with
other work (2026-12), which the suite's other deposition tests then load instead of compiling; every
other command takes seconds.  A short time-stepping task tiled over 2 ranks must compile nothing after
its warm-up either.
"""

import os
import subprocess
import sys
from types import SimpleNamespace

import pytest

from tests.mpi import parsim_command, run_mpi

# Spheres in a periodic box wide enough for two blocks of columns, so that a task spread over 2 ranks
# is cut in two; few particles and packing samples, so that every task takes well under a second.
JOB = """
name = "compiled"
kind = "deposition"
seed = 5
realizations = 2
[parameters]
n_particles = 100
box_length = 24.0
packing_samples = 1000
"""

PREPARING = "parsim: preparing the kernels"


def parsim(cache, *arguments):
    return subprocess.run([sys.executable, *parsim_command(*arguments)], capture_output=True, text=True,
                          env=cache.env, timeout=1800)


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """The cache with the job's kernels for tasks on one rank (``parsim compile JOB``): the job file, the
    environment, the folder for outputs and what the compilation printed."""
    root = tmp_path_factory.mktemp("compile")
    job = root / "compiled.toml"
    job.write_text(JOB)
    made = SimpleNamespace(job=str(job), env=dict(os.environ), root=root)
    made.compiled = parsim(made, "compile", made.job)
    assert made.compiled.returncode == 0, made.compiled.stderr
    return made


def test_compile_says_where_the_kernels_are(cache):
    from parsim.core.cache import kernel_cache_dir

    assert f"in the cache: {kernel_cache_dir()}" in cache.compiled.stdout, cache.compiled.stdout


def test_a_run_after_compile_says_nothing_about_kernels(cache):
    run = parsim(cache, "run", cache.job, "--output", str(cache.root / "serial"))
    assert run.returncode == 0, run.stderr
    assert "kernels" not in run.stderr, run.stderr


def test_compile_again_compiles_nothing(cache):
    again = parsim(cache, "compile", cache.job)
    assert again.returncode == 0 and PREPARING not in again.stderr, again.stderr


@pytest.mark.mpi
def test_compile_for_spread_tasks_leaves_nothing_to_compile_to_the_spread_run(cache):
    spread = parsim(cache, "compile", cache.job, "--ranks-per-task", "2")
    assert spread.returncode == 0, spread.stderr
    assert "on 2 ranks per task are in the cache" in spread.stdout
    run = run_mpi([*parsim_command("run", cache.job, "--output", str(cache.root / "spread"), "--ranks-per-task", "2")],
                  timeout=900, env=cache.env)
    assert run.returncode == 0, run.stderr
    assert "kernels" not in run.stderr, run.stderr


# The run on every rank, saying on standard error whether the warm-up had the spread rounds' loop ready
# before any task, and how many of parsim's kernels numba compiled while the tasks ran.
SPREAD_RUN = """
import sys
from numba.core import event
import parsim.runner
from parsim.cli import main
from parsim.core.jit import defined_in_core
from parsim.core.sdbd.rounds import run_rounds

in_tasks, compiled = [False], []
class InTasks(event.Listener):
    def on_start(self, ev):
        if in_tasks[0] and defined_in_core(ev.data["dispatcher"]):
            compiled.append(ev.data["dispatcher"].py_func.__qualname__)
    def on_end(self, ev):
        pass
event.register("numba:compile", InTasks())
warm_up = parsim.runner.warm_up

def warmed_up(*args, **kwargs):
    warm_up(*args, **kwargs)
    in_tasks[0] = True
    print(f"warm-up: {len(run_rounds.signatures)} spread loop", file=sys.stderr, flush=True)

parsim.runner.warm_up = warmed_up
status = main(sys.argv[1:])
print(f"tasks compiled: {compiled}", file=sys.stderr, flush=True)
sys.exit(status)
"""


def spread_run(cache, job: str, output: str):
    """``parsim run JOB --ranks-per-task 2`` on 2 ranks by :data:`SPREAD_RUN`: its standard error, in which the
    two ranks' lines may interleave (a print writes its text and its newline apart), so counted by substring."""
    script = cache.root / "spread_run.py"
    script.write_text(SPREAD_RUN)
    run = run_mpi([str(script), "run", job, "--output", str(cache.root / output), "--ranks-per-task", "2"],
                  timeout=1800, env=cache.env)
    assert run.returncode == 0, run.stderr
    return run.stderr


@pytest.mark.mpi
def test_a_spread_run_warms_up_the_kernels_of_spread_tasks(cache):
    text = spread_run(cache, cache.job, "warmed")
    assert text.count("warm-up: 1 spread loop") == 2, text  # on each rank, before the tasks
    assert text.count("tasks compiled: []") == 2, text


# Time stepping in tiles over 2 ranks, a few steps long: the warm-up's small point must still reach the
# minimiser, the refresh of its candidate pairs and the pairs across ranks.
TILED_JOB = """
name = "tiled"
kind = "aggregation"
seed = 1
realizations = 1
[parameters]
method = "ts"
dimension = 2
n_spheres = 20000
volume_fraction = 0.3
max_events = 3
"""


@pytest.mark.mpi
def test_a_short_tiled_time_stepping_task_compiles_nothing_after_the_warm_up(cache):
    job = cache.root / "tiled.toml"
    job.write_text(TILED_JOB)
    text = spread_run(cache, str(job), "tiled")
    assert text.count("tasks compiled: []") == 2, text
