"""Event-driven steepest descent ballistic deposition (SDBD) of rigid multi-sphere particles.

Topic & Poeschel (2016), sections 2-4: each particle, made of overlapping polydisperse
spheres, is dropped above the sediment and follows the path of steepest descent of its
centre of mass - falling, rolling on one contact, rolling on two - until it rests on three
contacts, hangs on one or two, or (FLOOR_STOP) touches the floor.  Frustrated situations
(4.1, trial angle), freezing by infinite cycling (4.2, criterion 34) and simultaneous
events (4.3) are handled.

Modules, in the order of the loop: :mod:`.engine` (the deposition loop, Fig. 3),
:mod:`.particle` (the drop and the rigid motions of a particle), :mod:`.decision` (the
steepest-descent choice), :mod:`.fall` (falling, 3.1), :mod:`.rolling` (rotation on one or
two contacts, 3.2-3.3), :mod:`.frustration` (the trial rotation, 4.1), :mod:`.cycling`
(criterion 34 and the creep test, 4.2), :mod:`.ties` (simultaneous events, 4.3); below
them :mod:`.events` (event solvers), :mod:`.rotation` (eq. 15, eqs. 13-14),
:mod:`.contacts` (contact lists), :mod:`.grid` (sediment grid), :mod:`.polygon` (the
cylindrical container), :mod:`.faces` and :mod:`.slide` (a mesh vessel's faces and the slide on them), :mod:`.overlap` (debug overlap measurement), :mod:`.bundles` (the
named bundles of arrays) and :mod:`.constants`.

The public entry point is :func:`deposit` (:mod:`.api`); :mod:`.inputs` checks its arguments and
builds the container they describe. This package re-exports them and the constants a caller passes.

Where this implementation departs from, or makes precise, the printed paper:

* eq. 14: the sign of ``sin phi`` is fixed by the right-hand rule about the axis,
  ``sin phi = n . ((x - O) x (x' - O)) / (|x - O| |x' - O|)``;
* events are ordered by their angle ``phi in [0, phi_hang]`` instead of by the height of
  the centre of mass (equivalent: the centre of mass descends monotonically on that arc,
  and ``phi <= phi_hang`` is eq. 16);
* eqs. 25-30 (loss of one of two contacts) are derived for a general release: with
  ``d = r_cm - P_x``, ``e = a_y - P_x``, ``f = a_y - P_y``, eq. 28 becomes
  ``F = (d.f) e_z - f_z (d.e)``; ``A = d.e`` and ``B = d.f`` are constant during the
  rotation about the axis through ``P_x`` and ``P_y``, so ``F = (B - A) z_ay - B z_Px + A z_Py``
  and rolling on ``x`` alone becomes possible when ``F`` turns positive (eq. 30, a plane
  for ``a_y``).  For a wall or floor contact ``y`` (pivot ``P_y = a_y``) the same
  derivation gives a plane for the centre of mass;
* eq. 31's virtual small rotation is the trial angle of 4.1 (the paper points to 4.1 for
  it); a much smaller angle makes particles creep along the contact;
* "steepest" is the slope ``-dz/ds`` of the path of the centre of mass;
* criterion (34) is read as ``|Q - 1| < epsilon`` with ``Q = dz(k) dz(k-4) / (dz(k-1)
  dz(k-3))`` and a decreasing ``dz``; it is also applied for periods 2 and 4, and a
  period-free backstop (no descent in 24 steps) catches zigzags among obstacles at
  round-off clearances.  The contacts "involved in the cycling" are all obstacles
  within ``CYCLE_CLOSE_GAP`` of the particle;
* touching obstacles: after any move, contacts released by the decision that still touch
  remain contacts, and at rest obstacles within ``CYCLE_CLOSE_GAP`` become contacts and
  the decision is taken again, so that rest is decided with every touching obstacle;
* unstable equilibria (centre of mass straight above a pivot or above the axis of two)
  are tipped about a fixed horizontal axis instead of balancing forever;
* a wall is frictionless by default: a sphere of infinite radius, whose pivot at infinity
  lets the touching sphere slide along it (``WALL_FRICTIONLESS``); the glued model
  (``WALL_GLUED``), in which a wall, like the floor under FLOOR_ROLL, holds the touching
  sphere's centre as a pivot, is kept by name; see :mod:`.engine`.

Containers (LATERAL_WALLS).  The box (``CONTAINER_BOX``) has four planar walls.  A cylinder
(``CONTAINER_CYLINDER``, ``cylinder = (cx, cy, R, n_sides)``) is modelled as the regular polygon
of ``n_sides`` planar walls inscribed in the circle of radius ``R`` about the vertical axis through
``(cx, cy)``, side ``k`` with the inward normal ``-(cos theta_k, sin theta_k, 0)``,
``theta_k = 2 pi k / n_sides``, at the apothem ``R cos(pi / n_sides)`` from the axis
(:mod:`.polygon`).  Why not the curved wall itself: the paper's motions are rotations about
fixed axes, and for a frictionless curved wall none keeps a touching sphere on the surface (the
only circles on a cylinder are the horizontal ones about its axis, along which the centre of
mass does not descend), so the event-driven motions of the paper do not exist there.  Each side
is a wall as above (frictionless or glued); two adjacent sides have a vertical ``N1 x N2``, and
the only motion that keeps both is the fall, as in a corner of the box.  Every sphere centre
lies in the polygon shrunk by its radius ``r``, whose vertices are ``R - r / cos(pi / n_sides)
<= R - r`` from the axis.  Only the sides within reach of a sphere are examined, so the cost per
sphere does not grow with ``n_sides``.

Mesh vessels (``CONTAINER_MESH``, ``faces``).  A vessel whose inside is convex is the walled box of
its bounding box with the planes of its other faces (:mod:`.faces`), each a wall as above; a
frictionless face that is not vertical adds the slide (:mod:`.slide`): on one such face the particle
translates down its line of steepest descent, on two along their line, until a new contact.

Substrate.  ``substrate_positions`` / ``substrate_radii`` are fixed spheres laid in the sediment
before the first particle (sediment spheres ``0 .. m - 1``, wrapped into a periodic box): the
particles drop above them and rest on them like on any sediment sphere; the grid's first cell
is at least their largest diameter.  They are not part of the result.  The engine is
prefix-independent (the first ``k`` particles of a run are those of a ``k``-particle run: the
length scale is that of the shapes, and the grid's cell, the drop heights and the sediment
indices depend only on the particles before), so depositing ``n1`` particles and then ``n2``
more on the first sediment as substrate gives, bitwise, the sediment of one run of ``n1 + n2``
particles.

Locality.  A particle is dropped with its lowest sphere ``DROP_MARGIN`` above the highest
sediment sphere within its reach (its extent plus the largest sediment radius, laterally:
:func:`.grid.top_near`), not above the whole sediment: its vertical fall cannot touch anything
beyond that reach, and from there on it only meets what lies on its path.  So a particle's
descent, bit for bit, depends only on the sediment near its path: particles dropped far apart do
not influence each other, whatever the rest of the pile does.

The numba cache of every kernel is stamped with all of :mod:`parsim.core`'s sources (see
:mod:`parsim.core.cache`): editing :mod:`.decision`, :mod:`.events`, :mod:`.grid` or
:mod:`.rotation` recompiles :func:`engine.run_deposition`.
"""

from parsim.core.sdbd.api import DepositionResult, deposit, deposit_with_diagnostics
from parsim.core.sdbd.constants import (
    CONTAINER_BOX,
    CONTAINER_CYLINDER,
    CONTAINER_MESH,
    EVENT_KINDS,
    EVENT_LIMIT,
    FLOOR_ROLL,
    FLOOR_STOP,
    HANGING_ONE,
    HANGING_TWO,
    LATERAL_NONE,
    LATERAL_PERIODIC,
    LATERAL_WALLS,
    MAX_EVENT_LIMIT,
    MIN_CYLINDER_SIDES,
    RESTING_ON_FLOOR,
    RESTING_THREE_CONTACTS,
    STATE_NAMES,
    WALL_FRICTIONLESS,
    WALL_GLUED,
)
from parsim.core.sdbd.inputs import PreparedDeposition, check_container, prepare_deposition

__all__ = [
    "deposit",
    "deposit_with_diagnostics",
    "prepare_deposition",
    "PreparedDeposition",
    "check_container",
    "DepositionResult",
    "EVENT_KINDS",
    "STATE_NAMES",
    "WALL_FRICTIONLESS",
    "WALL_GLUED",
    "LATERAL_PERIODIC",
    "LATERAL_WALLS",
    "LATERAL_NONE",
    "CONTAINER_BOX",
    "CONTAINER_CYLINDER",
    "CONTAINER_MESH",
    "MIN_CYLINDER_SIDES",
    "FLOOR_STOP",
    "FLOOR_ROLL",
    "RESTING_THREE_CONTACTS",
    "RESTING_ON_FLOOR",
    "HANGING_ONE",
    "HANGING_TWO",
    "EVENT_LIMIT",
    "MAX_EVENT_LIMIT",
]
