"""A launcher that started several processes whose MPI sees a world of one stops them at once."""

import os
import subprocess
import sys

import pytest

from parsim.parallel.launcher import launcher_mismatch, library_mismatch, speaks_for_all
from tests.mpi import parsim_command

MPICH_VERSION = "MPICH Version:      5.0.2\nMPICH Release date: Fri Sep 25 2026\nMPICH ABI:          18:2:6\n"
OPEN_MPI_VERSION = "Open MPI v5.0.11, package: Open MPI user@localhost Distribution, ident: 5.0.11, repo rev: v5.0.11"
HYDRA = {"PMI_FD": "9", "PMI_RANK": "0", "PMI_SIZE": "2", "MPI_LOCALNRANKS": "2"}
OPEN_MPI_RUN = {"OMPI_COMM_WORLD_SIZE": "2", "OMPI_COMM_WORLD_RANK": "0", "PMIX_RANK": "0",
                "PMIX_NAMESPACE": "prterun-vm-6366@1"}


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


@pytest.mark.parametrize("environ, version, evidence", [
    (OPEN_MPI_RUN, MPICH_VERSION, "the launcher of Open MPI started this process (OMPI_COMM_WORLD_SIZE=2), but mpi4py "
                                  "loaded MPICH (MPICH Version: 5.0.2)"),
    (HYDRA, OPEN_MPI_VERSION, "the launcher of MPICH started this process (PMI_FD=9, PMI_SIZE=2), but mpi4py loaded "
                              "Open MPI (Open MPI v5.0.11)"),
    (OPEN_MPI_RUN, "Intel(R) MPI Library 2021.13 for Linux* OS", "mpi4py loaded MPICH (Intel(R) MPI Library"),
])
def test_a_launcher_of_the_other_library_is_a_mismatch_before_mpi_starts(environ, version, evidence):
    message = library_mismatch(environ, version)
    assert message is not None and evidence in message and "docs/cluster.md" in message


@pytest.mark.parametrize("environ, version", [
    (HYDRA, MPICH_VERSION),                                               # mpiexec of PyPI's MPICH
    (OPEN_MPI_RUN, OPEN_MPI_VERSION),                                     # mpirun of Open MPI
    ({}, OPEN_MPI_VERSION),                                               # no launcher
    ({**HYDRA, "SLURM_STEP_NUM_TASKS": "2"}, OPEN_MPI_VERSION),           # srun --mpi=pmi2 serves either library
    ({"PMIX_RANK": "0", "PMIX_NAMESPACE": "slurm.1"}, MPICH_VERSION),     # srun --mpi=pmix: the library knows
    (OPEN_MPI_RUN, "Microsoft MPI 10.1"),                                 # a library of neither family
])
def test_a_launcher_of_the_same_or_an_unknown_library_is_no_mismatch(environ, version):
    assert library_mismatch(environ, version) is None


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


def test_open_mpis_launcher_with_mpich_ends_in_parsims_line_before_mpi_init(tmp_path):
    # What Open MPI's mpirun leaves a process: with these variables PyPI's MPICH aborts inside MPI_Init
    # ("Runtime environment uses unsupported PMI version PMIx") with its own error stack, unless
    # parsim looks first
    job = tmp_path / "job.toml"
    job.write_text('name = "once"\nkind = "aggregation"\nseed = 1\nrealizations = 1\n'
                   '[parameters]\nn_spheres = 25\nvolume_fraction = 0.2\n')
    result = subprocess.run([sys.executable, *parsim_command("run", str(job), "--output", str(tmp_path / "out"))],
                            env={**os.environ, **OPEN_MPI_RUN}, capture_output=True, text=True, timeout=120)
    assert result.returncode == 2, result.stderr
    assert result.stderr.splitlines() == [
        f"parsim: error: {library_mismatch(OPEN_MPI_RUN, MPICH_VERSION)}"], result.stderr
    assert not (tmp_path / "out").exists()
