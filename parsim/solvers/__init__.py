"""The solvers a job can name with ``kind``; each is a :class:`parsim.solver.Solver`."""

from parsim.solvers import aggregation

SOLVERS = {solver.kind: solver for solver in (aggregation.SOLVER,)}
