"""Is this process one of several that a launcher started, while MPI sees it alone?

When mpi4py is linked to another MPI library than the one whose launcher started the job
(``mpiexec`` of Open MPI with mpi4py on PyPI's MPICH, ``srun`` without the PMI that the library
needs, ...), every process initialises MPI as a singleton: ``COMM_WORLD`` has one rank on each,
and N copies of the whole job would write the same folder.  The launchers leave their own
count of processes and rank of this one in the environment; a count above 1, or a rank above
0, with a world of one rank is that mistake.

``SLURM_NTASKS`` is not used: it is set in a batch script for the whole allocation, where one
``parsim run`` without ``srun`` is legitimate; ``SLURM_STEP_NUM_TASKS`` is that of the
``srun`` step that started this process.
"""

import os

#: Environment variables holding the number of processes a launcher started.
SIZE_VARIABLES = ("PMI_SIZE", "OMPI_COMM_WORLD_SIZE", "PMIX_SIZE", "SLURM_STEP_NUM_TASKS", "MPI_LOCALNRANKS")
#: Environment variables holding this process's rank among them.
RANK_VARIABLES = ("PMI_RANK", "OMPI_COMM_WORLD_RANK", "PMIX_RANK", "SLURM_PROCID")


def _integer(environ, name: str) -> int | None:
    try:
        return int(environ[name])
    except (KeyError, ValueError):
        return None


def launcher_mismatch(world_size: int, environ=os.environ) -> str | None:
    """The problem in one line if a launcher started several processes but MPI's world has one
    rank, else None."""
    if world_size != 1:
        return None
    for name in SIZE_VARIABLES:
        size = _integer(environ, name)
        if size is not None and size > 1:
            return _message(f"{name}={size}")
    for name in RANK_VARIABLES:
        rank = _integer(environ, name)
        if rank is not None and rank > 0:
            return _message(f"{name}={rank}")
    return None


def speaks_for_all(environ=os.environ) -> bool:
    """Is this process the launcher's rank 0 (or the only one), which prints the line for all?"""
    ranks = [_integer(environ, name) for name in RANK_VARIABLES]
    return all(rank in (None, 0) for rank in ranks)


def _message(evidence: str) -> str:
    return (f"the launcher started several processes ({evidence}) but MPI sees each one alone: mpi4py loaded "
            f"another MPI library than the launcher's; start parsim with the launcher of the library that "
            f"python -c \"from mpi4py import MPI; print(MPI.Get_library_version())\" names, or make mpi4py load "
            f"the launcher's library (docs/cluster.md)")
