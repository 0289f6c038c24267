"""Event-driven (ED) ballistic aggregation of hard spheres (Degond et al. 2024, section 2, SM A).

Modules: :mod:`~parsim.core.ed.frames` (clusters in lazy frames, event times),
:mod:`~parsim.core.ed.neighbours` (cell grid and neighbour lists), :mod:`~parsim.core.ed.events`
(the queue), :mod:`~parsim.core.ed.collisions` (merge, eq. 2.9; wall reflection, eq. 2.2),
:mod:`~parsim.core.ed.run` (the event loop) and :mod:`~parsim.core.ed.api` (:func:`simulate_ed`).

Model
-----
``n`` hard spheres (discs for d = 2) with radii ``R_i`` and masses ``m_i`` move freely in
the box ``[0, L]^d`` (walls, not periodic).  A sphere touching a wall reflects its whole
cluster specularly (eq. 2.2 applied to the cluster velocity: the component normal to
the wall changes sign).  Two spheres of different clusters that touch merge the two
clusters into one rigid cluster that translates, without rotating, with the
mass-weighted velocity (eq. 2.9).  Clusters never break.  Pair collision times are
eq. A.3; a pair that already overlaps by round-off and approaches collides at once
(negative times are clamped to 0), an overlapping pair that separates never collides.
The run stops when one cluster remains, at ``max_time`` or after ``max_events``
physical events (collisions + wall reflections).

Algorithm (why it is not O(N^2))
--------------------------------
The paper's ED method tests all pairs at every event.  Here a velocity change costs
O(1) plus the re-prediction of the pairs a cluster has with *nearby* foreign spheres,
a merge costs O(smaller cluster) on top, and keeping the neighbour lists valid costs
O(cluster size) each time a cluster has moved half a skin:

* **Lazy cluster frames.**  Sphere ``i`` stores an offset ``P_i`` in the frame of its
  cluster ``c``; the cluster stores an origin ``O_c`` at reference time ``T0_c`` and its
  velocity ``V_c``: ``X_i(t) = O_c + V_c (t - T0_c) + P_i``.  A velocity change rebases
  ``O_c, T0_c`` in O(1); nothing is stored per sphere about time.
* **Merge by size.**  The spheres of the smaller cluster are relabelled into the larger
  one (offsets rebased), the per-cluster sphere linked lists are concatenated through
  head/tail pointers in O(1), masses add, momenta give the new velocity (eq. 2.9), and
  the cluster's bounding box in its own frame (per-axis min/max of ``P_i -/+ R_i``) is
  extended by the smaller one's spheres.  Total relabelling work is O(N log N).
* **Walls from the bounding box.**  A cluster's next wall event is the first time its
  box reaches 0 or ``L`` along an axis it moves towards; clamped at 0, so a merged
  cluster already touching a wall and moving outwards reflects at once.  A cluster
  whose box touches both walls of an axis (it spans the box, possible only by
  round-off) would reflect infinitely often at one instant; its velocity component
  along that axis is set to 0 instead (documented exception to eq. 2.2).
* **Neighbour lists on binned positions.**  Each sphere has a binned position ``Xb_i``
  in a fixed cell grid (cell side >= ``2 R_max + skin``).  All spheres of a cluster share
  one displacement since binning ``delta_c = X_i - Xb_i`` (stored lazily like ``O_c``).
  Sphere ``i`` keeps the list of spheres ``j`` of *other* clusters with
  ``|Xb_i - Xb_j| < R_i + R_j + skin`` (symmetric, growable, never truncated).  While
  every ``|delta_c| < skin / 2`` a pair absent from the lists cannot touch, so only
  listed pairs need collision events.  A per-cluster *re-bin* event fires when
  ``|delta_c|`` reaches ``skin / 2``: the cluster's spheres are re-binned
  (``delta_c = 0``) and their lists rebuilt, O(cluster size); a sphere whose block of
  3^d cells holds only its own cluster's spheres (known from per-cell counts, without
  scanning the cells) needs no search, so the interior of a compact cluster is cheap.
  At a merge the smaller cluster's spheres are re-binned at ``X_i - delta_big`` so
  that the merged cluster again has a single ``delta`` - O(smaller size), not
  O(merged size).
* **Boundary lists.**  Each cluster keeps a linked list of its spheres that have at
  least one cross-cluster neighbour.  It is what gets re-predicted after a velocity
  change; it is cleaned lazily (spheres whose list became empty are dropped when
  visited) and rebuilt only for re-binned spheres.  So a giant cluster absorbing a
  small one costs the small one's size plus the giant's *boundary*, i.e. the number of
  foreign spheres within a skin of it - never the giant's size.
* **Event queue.**  A binary heap in arrays (:mod:`parsim.core.eventqueue`) holds pair,
  wall and re-bin events, ordered by time and then insertion sequence (deterministic
  ties).  Each cluster has a version stamp drawn from a global counter; any velocity
  change, re-bin or death of a cluster gives it a new stamp, and an event is stale
  (dropped when popped) unless the stamps it recorded still match.  An event later
  than the pending re-bin of either cluster involved is certain to go stale (the
  re-bin re-predicts everything), so it is not queued at all.  When the heap is full,
  stale events are filtered out; it is grown if that frees less than half.

The wall time to a single cluster grows like N^1.1-1.2 on lattice + isotropic initial
conditions (``benchmarks/aggregation_ed.py``, figures in docs/benchmarks.md).  Strongly
polydisperse radii are supported but slower: the cell side follows the largest sphere and
neighbour-list capacity follows the most crowded sphere.

Everything is float64 and deterministic: the same input gives bitwise the same output.
"""

from parsim.core.ed.api import DEFAULT_SKIN_NEIGHBOURS, OVERLAP_TOLERANCE, EDResult, default_skin, simulate_ed
from parsim.core.ed.run import STOP_REASONS

__all__ = ["EDResult", "simulate_ed", "default_skin", "STOP_REASONS", "OVERLAP_TOLERANCE", "DEFAULT_SKIN_NEIGHBOURS"]
