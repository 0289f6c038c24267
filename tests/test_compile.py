"""``parsim compile`` fills the kernel cache so that the runs after it compile nothing and say nothing
about kernels.

Every test here uses one private cache (XDG_CACHE_HOME in a temporary folder), filled once for the
module: ``parsim compile`` of a deposition of spheres compiles its kernels; the other commands only
load them. Cost: that compilation, 3.8 minutes on 2 cores of an AMD EPYC shared with other work
(2026-12); every other command takes seconds.
"""

import os
import subprocess
import sys
from types import SimpleNamespace

import pytest

from tests.mpi import parsim_command

# Spheres in a periodic box; few particles and packing samples, so that every task takes well under a second.
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
