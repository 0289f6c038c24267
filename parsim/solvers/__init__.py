"""The solvers a job can name with ``kind``; each is a :class:`parsim.solver.Solver`."""

from parsim.solvers import aggregation, deposition

SOLVERS = {solver.kind: solver for solver in (aggregation.SOLVER, deposition.SOLVER)}
