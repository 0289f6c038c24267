"""Everything that knows about MPI. Works with one rank and without mpiexec."""
