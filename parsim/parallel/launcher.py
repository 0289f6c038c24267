"""Does the launcher that started this process belong to the MPI library that mpi4py loaded?

When mpi4py is linked to another MPI library than the one whose launcher started the job
(``mpiexec`` of Open MPI with mpi4py on PyPI's MPICH, MPICH's ``mpiexec`` with mpi4py on Open
MPI, ``srun`` without the PMI that the library needs, ...), one of two things happens in
``MPI_Init``: the library aborts with its own error stack (MPICH meeting Open MPI's PMIx
environment), or every process initialises MPI as a singleton, ``COMM_WORLD`` has one rank on
each, and N copies of the whole job would write the same folder.

:func:`start_mpi` therefore looks before ``MPI_Init``: :func:`library_mismatch` compares the
launcher's environment with ``MPI.Get_library_version()``, which MPI allows before
initialisation, and only then initialises MPI itself.  Launchers are known by variables only
they set: Open MPI's ``mpirun`` sets ``OMPI_COMM_WORLD_*``; Hydra (the ``mpiexec`` of MPICH and
Intel MPI) passes ``PMI_FD`` or ``PMI_PORT`` (as Slurm's ``srun --mpi=pmi2`` also does, which
serves either library, so a Slurm step gets no verdict).  Once MPI is initialised,
:func:`launcher_mismatch` catches the rest: the launchers leave their own count of processes
and rank of this one in the environment; a count above 1, or a rank above 0, with a world of
one rank is that mistake.

``SLURM_NTASKS`` is not used: it is set in a batch script for the whole allocation, where one
``parsim run`` without ``srun`` is legitimate; ``SLURM_STEP_NUM_TASKS`` is that of the
``srun`` step that started this process.
"""

import os
import sys
import warnings

from parsim.errors import JobError

#: Environment variables holding the number of processes a launcher started.
SIZE_VARIABLES = ("PMI_SIZE", "OMPI_COMM_WORLD_SIZE", "PMIX_SIZE", "SLURM_STEP_NUM_TASKS", "MPI_LOCALNRANKS")
#: Environment variables holding this process's rank among them.
RANK_VARIABLES = ("PMI_RANK", "OMPI_COMM_WORLD_RANK", "PMIX_RANK", "SLURM_PROCID")

OPEN_MPI, MPICH = "Open MPI", "MPICH"
#: Variables that only Open MPI's launcher sets.
OPEN_MPI_LAUNCHER_VARIABLES = ("OMPI_COMM_WORLD_SIZE", "OMPI_COMM_WORLD_RANK")
#: Variables through which Hydra (MPICH's and Intel MPI's mpiexec) hands a process its PMI connection.
HYDRA_VARIABLES = ("PMI_FD", "PMI_PORT")
#: Library version texts of the MPICH family, which Hydra starts (Cray MPICH and MVAPICH included).
MPICH_FAMILY = ("MPICH", "MVAPICH", "Intel(R) MPI")
#: mpi4py's names of the thread levels (``mpi4py.rc.thread_level``, ``MPI4PY_RC_THREAD_LEVEL``).
THREAD_LEVELS = ("single", "funneled", "serialized", "multiple")


def start_mpi():
    """Initialise MPI for ``parsim run`` and return mpi4py's ``MPI`` module, unless the launcher
    and the library do not belong together: then a :class:`JobError` says so, and MPI stays
    uninitialised, so that no library aborts with its own error stack.

    Call it before anything imports ``mpi4py.MPI`` (which would initialise MPI at once); in a
    process where MPI is initialised already, only the world is checked.  MPI is initialised
    with mpi4py's thread level (``MPI4PY_RC_THREAD_LEVEL``, default "multiple", which the
    task scheduler needs) and finalised at exit.
    """
    import mpi4py

    if "mpi4py.MPI" not in sys.modules:
        mpi4py.rc.initialize = False
        mpi4py.rc.finalize = True
    with warnings.catch_warnings(record=True) as caught:  # held back until the library is known to fit
        from mpi4py import MPI
    if not MPI.Is_initialized():
        mismatch = library_mismatch(os.environ, MPI.Get_library_version())
        if mismatch:  # mpi4py's own warning about the environment says less: left out
            raise JobError(mismatch)
        for warning in caught:
            warnings.showwarning(warning.message, warning.category, warning.filename, warning.lineno)
        MPI.Init_thread(_thread_level(MPI, mpi4py.rc.thread_level))
    mismatch = launcher_mismatch(MPI.COMM_WORLD.Get_size())
    if mismatch:  # every process would run the whole job into the same folder
        raise JobError(mismatch)
    return MPI


def _thread_level(MPI, configured: str) -> int:
    """The MPI thread level mpi4py would request: ``MPI4PY_RC_THREAD_LEVEL`` or ``configured``."""
    name = os.environ.get("MPI4PY_RC_THREAD_LEVEL", configured).strip().lower()
    if name not in THREAD_LEVELS:
        raise JobError(f"MPI4PY_RC_THREAD_LEVEL={name}: allowed: {', '.join(THREAD_LEVELS)}")
    return getattr(MPI, f"THREAD_{name.upper()}")


def library_family(version: str) -> str | None:
    """OPEN_MPI or MPICH for the text of ``MPI_Get_library_version``, None for another library."""
    if "Open MPI" in version:
        return OPEN_MPI
    if any(name in version for name in MPICH_FAMILY):
        return MPICH
    return None


def launcher_family(environ) -> tuple[str, str] | None:
    """(family, evidence) of the launcher that left ``environ``: OPEN_MPI or MPICH (Hydra), and the
    variable that shows it; None for no launcher, or one that may serve either library (Slurm)."""
    for name in OPEN_MPI_LAUNCHER_VARIABLES:
        if name in environ:
            return OPEN_MPI, f"{name}={environ[name]}"
    if "SLURM_STEP_NUM_TASKS" in environ:
        return None
    for name in HYDRA_VARIABLES:
        if name in environ:
            size = f", PMI_SIZE={environ['PMI_SIZE']}" if "PMI_SIZE" in environ else ""
            return MPICH, f"{name}={environ[name]}{size}"
    return None


def library_mismatch(environ, library_version: str) -> str | None:
    """The problem in one line if ``environ`` shows the launcher of one MPI library and
    ``library_version`` names the other, else None (also when either is unknown)."""
    launcher = launcher_family(environ)
    library = library_family(library_version)
    if launcher is None or library is None or launcher[0] == library:
        return None
    family, evidence = launcher
    named = " ".join(library_version.strip().split("\n", 1)[0].split(",", 1)[0].split()) or library
    return (f"the launcher of {family} started this process ({evidence}), but mpi4py loaded {library} "
            f"({named}): start parsim with that library's mpiexec, or make mpi4py load {family} "
            f"(docs/cluster.md)")


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
