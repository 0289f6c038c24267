"""A launcher that started several processes whose MPI sees a world of one stops them at once."""

import os
import subprocess
import sys

import pytest

from parsim.parallel.launcher import launcher_mismatch, speaks_for_all
from tests.mpi import parsim_command


@pytest.mark.parametrize("environ, evidence", [
    ({"OMPI_COMM_WORLD_SIZE": "4", "OMPI_COMM_WORLD_RANK": "0"}, "OMPI_COMM_WORLD_SIZE=4"),  # Open MPI's mpirun
    ({"PMI_SIZE": "2", "PMI_RANK": "1"}, "PMI_SIZE=2"),                                      # MPICH's hydra
    ({"SLURM_STEP_NUM_TASKS": "64", "SLURM_PROCID": "0"}, "SLURM_STEP_NUM_TASKS=64"),        # srun
    ({"PMIX_RANK": "3"}, "PMIX_RANK=3"),                                                     # PMIx, rank only
])
def test_several_launched_processes_in_a_world_of_one_are_a_mismatch(environ, evidence):
    message = launcher_mismatch(1, environ)
    assert message is not None and evidence in message and "docs/cluster.md" in message


@pytest.mark.parametrize("world, environ", [
    (1, {}),                                            # a plain serial run
    (1, {"SLURM_NTASKS": "8", "SLURM_PROCID": "0"}),    # one run in a batch script of 8 tasks, no srun
    (1, {"PMI_SIZE": "1", "PMI_RANK": "0"}),            # mpiexec -n 1
    (2, {"PMI_SIZE": "2", "PMI_RANK": "1"}),            # a working MPI
])
def test_a_consistent_world_is_no_mismatch(world, environ):
    assert launcher_mismatch(world, environ) is None


def test_only_the_launchers_rank_zero_speaks():
    assert speaks_for_all({"OMPI_COMM_WORLD_RANK": "0"}) and speaks_for_all({})
    assert not speaks_for_all({"PMI_RANK": "1"})


def test_two_processes_that_each_see_a_world_of_one_stop_before_touching_the_output(tmp_path):
    # What Open MPI's mpirun does to two processes whose mpi4py loaded PyPI's MPICH: each one is
    # an MPICH singleton, with Open MPI's variables in its environment
    job = tmp_path / "job.toml"
    job.write_text('name = "twice"\nkind = "aggregation"\nseed = 1\nrealizations = 2\n'
                   '[parameters]\nn_spheres = 25\nvolume_fraction = 0.2\n')
    processes = []
    for rank in range(2):
        environ = {**os.environ, "OMPI_COMM_WORLD_SIZE": "2", "OMPI_COMM_WORLD_RANK": str(rank)}
        processes.append(subprocess.Popen(
            [sys.executable, *parsim_command("run", str(job), "--output", str(tmp_path / "out"))],
            env=environ, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
    results = [process.communicate(timeout=120) + (process.returncode,) for process in processes]
    assert [status for _, _, status in results] == [2, 2]
    errors = [[line for line in err.splitlines() if line.startswith("parsim: error:")] for _, err, _ in results]
    assert len(errors[0]) == 1 and "OMPI_COMM_WORLD_SIZE=2" in errors[0][0]
    assert errors[1] == []
    assert not (tmp_path / "out").exists()
