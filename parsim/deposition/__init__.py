"""Ballistic deposition of rigid multi-sphere particles (Topić & Pöschel 2016), as a job runs it.

- :mod:`.solver`: the ``kind = "deposition"`` solver: keys, checks, cost, memory, ``solve``;
- :mod:`.materials`: species, particle templates (shapes, meshes, agglomerates, sieve curves)
  and the drawing of every particle's shape, scale, orientation and drop point;
- :mod:`.statistics`: a sediment's statistics (packing fractions, filling height, structure);
- :mod:`.spread`: one sediment spread over the ranks of a task's group, bitwise the serial one;
- :mod:`.spread_statistics`: a spread sediment's statistics, made in parts by each rank.

The kernels are in :mod:`parsim.core.sdbd` (the descent) and :mod:`parsim.core.sediment`,
:mod:`parsim.core.structure` (the measures).
"""
