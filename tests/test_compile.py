"""``parsim compile`` fills the kernel cache so that the runs after it compile nothing and say nothing
about kernels, on one rank and spread over several (``--ranks-per-task``).

Every test here uses one private cache (XDG_CACHE_HOME in a temporary folder), filled once for the
module: ``parsim compile`` of a deposition of spheres compiles its kernels for tasks on one rank, and
``parsim compile --ranks-per-task 2`` then those of spread tasks; the other commands only load them.
Cost: the two compilations, 1.8-3.8 and 2.6-3.3 minutes on 2 cores of an AMD EPYC shared with other
work (2026-12); every other command takes seconds.
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
    """A private cache with the job's kernels for tasks on one rank (``parsim compile JOB``): the job file, the
    environment, the folder for outputs and what the compilation printed."""
    root = tmp_path_factory.mktemp("compile")
    job = root / "compiled.toml"
    job.write_text(JOB)
    env = {key: value for key, value in os.environ.items() if key != "NUMBA_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(root / "cache")
    made = SimpleNamespace(job=str(job), env=env, root=root)
    made.compiled = parsim(made, "compile", made.job)
    assert made.compiled.returncode == 0, made.compiled.stderr
    return made


def test_compile_says_it_compiles_and_where_the_kernels_are(cache):
    assert PREPARING in cache.compiled.stderr, cache.compiled.stderr
    assert f"in the cache: {cache.root / 'cache' / 'parsim' / 'numba'}" in cache.compiled.stdout


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
    assert spread.returncode == 0 and PREPARING in spread.stderr, spread.stderr  # the spread tasks' own kernels
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


@pytest.mark.mpi
def test_a_spread_run_warms_up_the_kernels_of_spread_tasks(cache):
    script = cache.root / "spread_run.py"
    script.write_text(SPREAD_RUN)
    run = run_mpi([str(script), "run", cache.job, "--output", str(cache.root / "warmed"), "--ranks-per-task", "2"],
                  timeout=1800, env=cache.env)
    assert run.returncode == 0, run.stderr
    lines = run.stderr.splitlines()
    assert lines.count("warm-up: 1 spread loop") == 2, run.stderr  # on each rank, before the tasks
    assert lines.count("tasks compiled: []") == 2, run.stderr
