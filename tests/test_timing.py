"""A task's wall_time measures its computation, not the compilation of the kernels."""

import os
import subprocess
import sys

import numpy as np
import xarray as xr

from tests.mpi import parsim_command

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
    assert "parsim: preparing the kernels (compiled once per machine" in result.stderr
    with xr.open_dataset(tmp_path / "out" / "timing.nc") as dataset:
        wall_time = dataset.wall_time.values.ravel()
    # Four realisations of one point cost about the same, milliseconds; compiling takes tens of seconds.
    assert wall_time.max() < 20 * np.median(wall_time) + 0.5, wall_time
