"""What every method uses to run over MPI: the task scheduler, collectives and failure reports,
the rank grid of a decomposition, halos, migration and the launcher checks.  Works with one
rank and without mpiexec."""
