"""The solvers a job can name with ``kind``; each is a :class:`parsim.solver.Solver`."""

from parsim.aggregation import solver as aggregation
from parsim.deposition import solver as deposition

SOLVERS = {solver.kind: solver for solver in (aggregation.SOLVER, deposition.SOLVER)}
