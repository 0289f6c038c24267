"""Time-stepping (TS) ballistic aggregation with the damped Arrow–Hurwicz minimiser
(Degond, Dimarco, Ferreira & Hecht 2024, sections 3 and 4).

Modules, one job each:

- :mod:`~parsim.core.ts.stepper`: the time loop of section 3 (advection, interactions,
  velocities) and :func:`simulate_ts`;
- :mod:`~parsim.core.ts.daha`: the minimiser (3.20)–(3.29), with the sign choice derived
  from (3.15)–(3.16);
- :mod:`~parsim.core.ts.tiles`: the inner/outer rectangles of the almost-rigid form (3.3);
- :mod:`~parsim.core.ts.problem`: one minimisation assembled from a process's spheres (and ghosts);
- :mod:`~parsim.core.ts.domain`: where the spheres live (one process, or MPI ranks);
- :mod:`~parsim.core.ts.contacts`: contact and candidate-pair searches on cell lists;
- :mod:`~parsim.core.ts.links`: the link set ``S``;
- :mod:`~parsim.core.ts.clusters`: wall reflection, relabelling, eq. 2.9.
"""

from parsim.core.ts.daha import DahaParameters, SerialExchange
from parsim.core.ts.stepper import (FORMULATIONS, STOP_REASONS, TABLE1_TIME_STEP_FACTORS, MinimiserFailure,
                                    TSResult, simulate_ts)

__all__ = ["DahaParameters", "SerialExchange", "FORMULATIONS", "STOP_REASONS", "TABLE1_TIME_STEP_FACTORS",
           "MinimiserFailure", "TSResult", "simulate_ts"]
