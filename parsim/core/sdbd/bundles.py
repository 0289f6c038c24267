"""The named bundles of arrays that the deposition loop hands from one step to the next.

A bundle lets a signature say what a function works on (the particle, its contacts, the
candidate events) instead of listing twenty arrays.  Bundles of arrays are numba
``structref`` objects, not named tuples: numba counts a reference to every array of a named
tuple on every call that receives it, which made the loop twice as slow on spheres
(measured); a structref is one reference.  A count that changes (the number of contacts, of
candidate events) travels beside its bundle as a plain integer.  The run's scalar settings
are a named tuple (nothing to count).

The functions of the loop are compiled into the one kernel (``inline="always"``): as
separate functions they were 10 % slower again.  What remains, the reference counts of the
bundles' arrays taken in every step, makes the kernel about 10 % slower than the same loop
written as one function over sixty local arrays (``benchmarks/deposition.py``, 2026-11-25).

:func:`new_workspace` allocates every bundle of the loop once per run, so that no step
allocates memory.
"""

import sys
from collections import namedtuple

import numpy as np
from numba.core import types
from numba.experimental import structref

from parsim.core.jit import jit
from parsim.core.sdbd.constants import MAX_CONTACTS, MAX_TIES

__all__ = [
    "bundle",
    "Particle",
    "ContactList",
    "ContactGeometry",
    "EventWindow",
    "Sediment",
    "Grid",
    "Settings",
    "Scratch",
    "Workspace",
    "Record",
    "new_contact_list",
    "new_contact_geometry",
    "new_workspace",
    "grid_arrays",
    "geometry_arrays",
    "window_arrays",
]

class BundleType(types.StructRef):
    """numba type of a bundle; its fields keep their declared types (never literals)."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


def bundle(name, fields, module=__name__):
    """A structref bundle class ``name`` with the given fields, constructed in jitted code
    as ``name(*values)`` in field order.  Its numba type class ``<name>Type`` is made a
    global of ``module`` (where the bundle must be assigned to ``name``) so that numba's
    cache can find both again by name."""
    type_class = type(f"{name}Type", (BundleType,), {"__module__": module})
    structref.register(type_class)
    proxy = type(name, (structref.StructRefProxy,), {"__module__": module})
    structref.define_proxy(proxy, type_class, list(fields))
    setattr(sys.modules[module], type_class.__name__, type_class)
    return proxy


#: The moving particle: ``body`` (n, 3) sphere offsets from the centre of mass in the body
#: frame and ``radius`` (n,), both scaled; ``centre`` (n, 3) the sphere centres in the lab
#: frame, ``com`` (3,) the centre of mass, ``quaternion`` (4,) and ``rotation`` (3, 3) its
#: orientation.  Rows beyond the particle's number of spheres are unused.
Particle = bundle("Particle", ["body", "radius", "centre", "com", "quaternion", "rotation"])

#: A list of contacts, one row each (see :mod:`.contacts`): moving sphere ``sphere`` touches
#: an obstacle of kind ``obstacle`` (``OB_*``); ``sediment`` is the sediment sphere (``-1``
#: for a plane) and ``shift`` (rows of 3) its periodic image shift.
ContactList = bundle("ContactList", ["sphere", "obstacle", "sediment", "shift"])

#: The geometry of contacts that :func:`.decision.decide` reads, one row per contact:
#: ``centre`` the moving sphere's centre (a), ``pivot`` the obstacle's centre or, for a
#: plane, the moving sphere's own centre (P), ``normal`` the unit normal from the obstacle to
#: the moving sphere (N), ``reach`` the sum of radii (D), ``level`` the plane level (c0:
#: ``N . a >= c0``), ``kind`` the obstacle kind.
ContactGeometry = bundle("ContactGeometry", ["centre", "pivot", "normal", "reach", "level", "kind"])

#: The candidate events of one move that can still be the earliest (see :mod:`.ties`): row r
#: holds the drop or angle ``angle``, its ``cos`` and ``sin``, the event ``kind`` (``EV_*``)
#: and the contact it makes (``sphere``, ``obstacle``, ``sediment``, ``shift`` (rows of 2)).
EventWindow = bundle("EventWindow",
                         ["angle", "cos", "sin", "kind", "sphere", "obstacle", "sediment", "shift"])

#: The frozen spheres: ``centre`` (N, 3) wrapped into the periodic box, ``radius`` (N,).
Sediment = bundle("Sediment", ["centre", "radius"])

#: The neighbour grid of the sediment, the arrays of :mod:`.grid` in its order (``head``,
#: ``col_top``, ``hkeys`` and ``hval`` are replaced by larger ones as the pile grows, all of
#: them when a particle with a larger sphere than the cell allows arrives).  Its cell
#: ``geom[6]`` is the largest sphere diameter so far, so half of it bounds every sediment
#: radius.
Grid = bundle("Grid", ["geom", "igeom", "head", "col_top", "nxt", "hkeys", "hval", "counts"])

#: The parameters of a run: floor mode (``FLOOR_*``), trial angle of 4.1 (0: off), the
#: virtual small rotation of eq. 31, criterion (34)'s ``cycle_n`` and ``cycle_eps``, the
#: largest number of steps of a particle, the length scale ``ell`` of the tolerances,
#: whether the container has lateral walls (the box's faces or the cylinder's sides)
#: and whether they are frictionless (``WALL_FRICTIONLESS``),
#: whether every move is checked for overlaps.
Settings = namedtuple("Settings", ["floor_mode", "trial_angle", "virtual_angle", "cycle_n", "cycle_eps",
                                   "max_events", "ell", "walls", "sliding_walls", "debug"])

#: Three-vectors and small arrays reused by every step: the rotation ``axis`` and a point
#: ``pivot`` of it, the arc frame ``e1, e2``, plane normals ``normal, normal_2``, a rotated
#: ``point``, the quaternions of a step and of the new orientation, and the outputs of two
#: decisions (the present one and the trial of 4.1).
Scratch = bundle("Scratch", ["axis", "pivot", "e1", "e2", "normal", "normal_2", "point",
                                 "q_step", "q_new", "decision", "trial_decision", "trial_com"])

#: Everything a particle's descent works on besides the particle and the sediment: its
#: ``contacts``, their ``geometry``, the ``pivots`` of a rotation and the contacts
#: ``released`` by the last decision, the ``trial`` geometry of the pivots after a trial
#: rotation (4.1), the event ``window``, ``scratch``, and the run's ``counters``
#: (:mod:`.counters`; empty when not counting).
Workspace = bundle("Workspace", ["contacts", "geometry", "pivots", "released", "trial", "window",
                                     "scratch", "counters"])

#: The output of a run, preallocated for all particles: per sphere ``positions`` (lab
#: frame, wrapped into a periodic box), ``radii`` and ``particle`` index; per particle the
#: centre of mass ``com``, the orientation quaternion ``rotation``, the number of
#: ``contacts`` and the ``state`` at rest (``RESTING_*``, ``HANGING_*``, ``EVENT_LIMIT``),
#: the executed ``events`` by kind (``EVENT_KINDS``) and the number of decide-and-move
#: ``steps``.
Record = bundle("Record", ["positions", "radii", "particle", "com", "rotation", "contacts", "state",
                           "events", "steps"])


@jit
def new_contact_list(size):
    """An empty contact list of ``size`` rows."""
    return ContactList(np.empty(size, dtype=np.int64), np.empty(size, dtype=np.int64),
                       np.empty(size, dtype=np.int64), np.zeros((size, 3)))


@jit
def new_contact_geometry(size):
    """Contact geometry of ``size`` rows."""
    return ContactGeometry(np.empty((size, 3)), np.empty((size, 3)), np.empty((size, 3)),
                           np.empty(size), np.empty(size), np.empty(size, dtype=np.int64))


@jit
def new_workspace(counters):
    """Every bundle of :class:`Workspace`, allocated once per run, with the run's ``counters``."""
    window = EventWindow(np.empty(MAX_TIES), np.empty(MAX_TIES), np.empty(MAX_TIES),
                         np.empty(MAX_TIES, dtype=np.int64), np.empty(MAX_TIES, dtype=np.int64),
                         np.empty(MAX_TIES, dtype=np.int64), np.empty(MAX_TIES, dtype=np.int64),
                         np.zeros((MAX_TIES, 2)))
    scratch = Scratch(np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3),
                      np.empty(3), np.empty(4), np.empty(4), np.empty(8), np.empty(8), np.empty(3))
    return Workspace(new_contact_list(MAX_CONTACTS), new_contact_geometry(MAX_CONTACTS),
                     new_contact_list(2), new_contact_list(MAX_CONTACTS), new_contact_geometry(2),
                     window, scratch, counters)


@jit(inline="always")
def grid_arrays(grid):
    """The arrays of a :class:`Grid`, in the order of :mod:`.grid`'s functions."""
    return (grid.geom, grid.igeom, grid.head, grid.col_top, grid.nxt, grid.hkeys, grid.hval, grid.counts)


@jit(inline="always")
def geometry_arrays(geometry):
    """The arrays of a :class:`ContactGeometry`: ``(a, P, N, D, c0, kind)``."""
    return (geometry.centre, geometry.pivot, geometry.normal, geometry.reach, geometry.level,
            geometry.kind)


@jit(inline="always")
def window_arrays(window):
    """The arrays of an :class:`EventWindow`, in field order."""
    return (window.angle, window.cos, window.sin, window.kind, window.sphere, window.obstacle,
            window.sediment, window.shift)
