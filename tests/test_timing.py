"""A task's wall_time measures its computation, not the compilation of the kernels; the warm-up compiles
them once per node."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

from tests.mpi import parsim_command, run_mpi

JOB = """
name = "timing"
kind = "aggregation"
seed = 2
realizations = 4
[parameters]
method = "ed"
volume_fraction = 0.2
n_spheres = 64
"""


def test_first_task_is_timed_after_the_kernels_are_compiled(tmp_path):
    job = tmp_path / "timing.toml"
    job.write_text(JOB)
    # An empty cache: every kernel compiles in this run, which takes seconds against milliseconds per task.
    environment = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba_cache")}
    result = subprocess.run([sys.executable, *parsim_command("run", str(job), "--output", str(tmp_path / "out"))],
                            capture_output=True, text=True, env=environment, timeout=900)
    assert result.returncode == 0, result.stderr
    assert "parsim: preparing the kernels (compiled once per installation and processor model" in result.stderr
    with xr.open_dataset(tmp_path / "out" / "timing.nc") as dataset:
        wall_time = dataset.wall_time.values.ravel()
    # Four realisations of one point cost about the same, milliseconds; compiling takes tens of seconds.
    assert wall_time.max() < 20 * np.median(wall_time) + 0.5, wall_time


# The runner's warm-up on every rank of COMM_WORLD, from an empty cache (argv[1]): how many of
# parsim's kernels each rank compiled.
WARM_UP = """
import os, sys
os.environ["NUMBA_CACHE_DIR"] = sys.argv[1]  # before numba reads its configuration
import json
from mpi4py import MPI
from numba.core import event
from parsim.job import Job
from parsim.runner import warm_up

compiled = []
class Count(event.Listener):
    def on_start(self, ev):
        compiled.append(ev.data["dispatcher"].py_func.__module__)
    def on_end(self, ev):
        pass
event.register("numba:compile", Count())
job = Job.from_dict({"name": "warm", "kind": "aggregation", "seed": 1, "realizations": 2,
                     "parameters": {"method": "ed", "volume_fraction": 0.2, "n_spheres": 64}})
warm_up(job, job.tasks(), False, MPI.COMM_WORLD)
counts = MPI.COMM_WORLD.gather(sum(module.startswith("parsim.core") for module in compiled))
if MPI.COMM_WORLD.Get_rank() == 0:
    print(json.dumps(counts))
"""


@pytest.mark.mpi
def test_one_rank_of_a_node_compiles_the_others_load(tmp_path):
    result = run_mpi(["-c", WARM_UP, str(tmp_path / "numba_cache")], timeout=900)
    assert result.returncode == 0, result.stderr
    first, second = json.loads(result.stdout.strip().splitlines()[-1])
    assert first > 0 and second == 0  # rank 1 found every kernel in the cache rank 0 filled


def test_the_python_api_speaks_of_the_kernels_only_when_it_compiles_them(tmp_path):
    """From an empty cache the first call says it prepares the kernels and when they are ready; a
    later process that loads them all from the cache says nothing about them."""
    environment = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba_cache")}
    call = "import parsim; parsim.aggregate(n_spheres=40, volume_fraction=0.1, method='ed', seed=1)"
    first, second = (subprocess.run([sys.executable, "-c", call], capture_output=True, text=True, env=environment,
                                    timeout=900) for _ in range(2))
    assert first.returncode == 0 and second.returncode == 0, first.stderr + second.stderr
    assert "parsim: preparing the kernels" in first.stderr and "parsim: kernels ready in" in first.stderr
    assert "kernels" not in second.stderr, second.stderr


def test_compile_fills_the_cache_that_a_run_then_loads(tmp_path):
    """``parsim compile JOB`` (on a login node, before a batch job) compiles the job's kernels into
    the cache; the run that follows compiles nothing and says nothing about kernels."""
    job = tmp_path / "timing.toml"
    job.write_text(JOB)
    environment = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba_cache")}

    def parsim(*arguments):
        return subprocess.run([sys.executable, *parsim_command(*arguments)], capture_output=True, text=True,
                              env=environment, timeout=900)

    compiled = parsim("compile", str(job))
    assert compiled.returncode == 0, compiled.stderr
    assert "parsim: preparing the kernels" in compiled.stderr and "in the cache" in compiled.stdout
    run = parsim("run", str(job), "--output", str(tmp_path / "out"))
    assert run.returncode == 0, run.stderr
    assert "kernels" not in run.stderr, run.stderr
    again = parsim("compile", str(job))
    assert "preparing the kernels" not in again.stderr and "in the cache" in again.stdout
