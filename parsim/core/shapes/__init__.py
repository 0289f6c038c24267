"""Rigid particles made of overlapping, polydisperse spheres (Topić & Pöschel 2016).

The deposition algorithm of ``papers/sdbd-complex-particles-topic-poschel-2016.txt``
(section 2) moves rigid aggregates of spheres ("multisphere particles"): the centre of
mass follows the steepest descent.  This module builds such particles.

Every shape function returns ``(offsets, radii)``:

- ``offsets`` (k, 3) float64: sphere centres relative to the centre of mass of the
  **union** of the spheres (a point covered by two spheres is counted once; uniform
  density), computed by :func:`centre_of_mass_of_union`;
- ``radii`` (k,) float64.

Lengths are in units of the sphere radius ``r`` (``radius=1.0`` by default); every
length argument (``spacing``, ``semi_axes``) is in the same unit as ``radius``.

Shapes (with the reading of the paper's figures that they implement):

- :func:`sphere`: one sphere.
- :func:`rod`: Fig. 1(a), "11 equal overlapping spheres" on a line; ``rod(11)`` with the
  default ``spacing = radius`` (centre distance one radius, half-overlapping spheres, a
  rod of length 12 r and aspect ratio 6) is that picture.
- :func:`four_rods`: Fig. 1(b), "4 equal rods having in total 17 overlapping spheres":
  read as a plane cross of four rods of 5 spheres that share one central sphere,
  4 (5 - 1) + 1 = 17.  (The caption of Fig. 14 calls Fig. 1(b) "rings" and Fig. 1(c)
  "tripods", contradicting Fig. 1's own caption, where 1(c) is a fractal agglomerate;
  we follow Fig. 1 and the sphere count 17, which a closed ring of four 5-sphere rods,
  4 * 5 - 4 = 16, does not give.)
- :func:`tripod`: three equal legs from a common sphere along three of the four
  vertex directions of a regular tetrahedron (109.47 degrees between legs).
- :func:`spiky`, :func:`cube`: the two test particles of section 5 / Fig. 8(a).
- :func:`ellipsoid`, :func:`superellipsoid`: smooth convex bodies approximated by many
  overlapping polydisperse spheres (Fig. 1(d)-(f) use 1785 to 6241 spheres).
- :func:`agglomerate`: arbitrary given spheres (Fig. 1(c); a cluster of a 2D/3D
  aggregation), re-centred.

Helpers: :func:`extent_below_com`, :func:`bounding_radius`, :func:`random_rotations`
(uniform unit quaternions, Shoemake's method) and :func:`rotate`.

Quaternions are ``(w, x, y, z)`` with ``w`` the scalar part; :func:`rotate` applies the
active rotation ``v -> q v q*`` to row vectors.

Modules, one job each:

- :mod:`.union`: :func:`centre_of_mass_of_union` (column integration of a union of spheres);
- :mod:`.simple`: the shapes made of equal spheres and :func:`agglomerate`;
- :mod:`.smooth`: :func:`ellipsoid` and :func:`superellipsoid`, built by the greedy cover of
  :mod:`.medial_balls` with the point-to-surface distances of :mod:`.ellipsoid_distance`
  (exact) and :mod:`.superellipsoid_distance` (local searches);
- :mod:`.rotations`: :func:`random_rotations` (and :class:`DrawnRotations`, computed row by row when taken),
  :func:`rotate`;
- :mod:`.extents`: :func:`extent_below_com`, :func:`bounding_radius`;
- :mod:`.checks`: the argument checks they share.

The numba cache of every kernel is stamped with all of :mod:`parsim.core`'s sources (see
:mod:`parsim.core.cache`): editing a callee module (e.g. :mod:`.superellipsoid_distance`)
recompiles its callers.
"""

from parsim.core.shapes.extents import bounding_radius, extent_below_com
from parsim.core.shapes.rotations import DrawnRotations, random_rotations, rotate
from parsim.core.shapes.simple import agglomerate, cube, four_rods, rod, sphere, spiky, tripod
from parsim.core.shapes.smooth import ellipsoid, superellipsoid
from parsim.core.shapes.union import DEFAULT_UNION_RESOLUTION, centre_of_mass_of_union

__all__ = [
    "DEFAULT_UNION_RESOLUTION",
    "centre_of_mass_of_union",
    "sphere",
    "rod",
    "four_rods",
    "tripod",
    "spiky",
    "cube",
    "ellipsoid",
    "superellipsoid",
    "agglomerate",
    "extent_below_com",
    "bounding_radius",
    "random_rotations",
    "DrawnRotations",
    "rotate",
]
