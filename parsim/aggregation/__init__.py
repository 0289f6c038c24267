"""Ballistic aggregation of hard spheres (Degond, Dimarco, Ferreira & Hecht 2024), as a job runs it.

- :mod:`.solver`: the ``kind = "aggregation"`` solver (event-driven or time-stepping method):
  keys, checks, cost, memory, ``solve`` and the cluster statistics it reports;
- :mod:`.tiled`: one time-stepping task over the ranks of a task's group
  (``DecomposedDomain``: tiles, ghosts, migration).

The kernels are in :mod:`parsim.core.ed`, :mod:`parsim.core.ts` and
:mod:`parsim.core.statistics`.
"""
