"""The named bundles of arrays that the deposition loop hands from one step to the next.

A bundle lets a signature say what a function works on (the particle, its contacts, the
candidate events) instead of listing twenty arrays.  Bundles of arrays are numba
``structref`` objects, not named tuples: numba counts a reference to every array of a named
tuple on every call that receives it, which made the loop twice as slow on spheres
(measured); a structref is one reference.  A count that changes (the number of contacts, of
candidate events) travels beside its bundle as a plain integer.  The run's scalar settings
are a named tuple (nothing to count).

The functions of the loop are compiled into the one kernel (``inline="always"``): as
separate functions they were 10 % slower again.  The exceptions are the descent of a particle
and a rotation, large functions called once per particle and per step, whose inlining made
the first compilation much longer and no kernel faster.

The arrays in a bundle are borrowed views (:mod:`.borrowed`), which numba does not
reference-count: reading them costs no atomic operation.  A bundle that allocates holds the
arrays they borrow from in its ``memory`` field, so that they live as long as the bundle.
:func:`new_workspace` and :func:`new_particle` allocate every bundle of the loop once per run, so
that no step allocates memory.
"""

import sys
from collections import namedtuple

import numpy as np
from numba.core import types
from numba.experimental import structref

from parsim.core.jit import jit
from parsim.core.sdbd.borrowed import borrowed, carve, carve_rows
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
    "new_workspace",
    "new_particle",
    "sediment_in",
    "new_grid",
    "set_grid_arrays",
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
Particle = bundle("Particle", ["body", "radius", "centre", "com", "quaternion", "rotation", "memory"])

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

#: The frozen spheres: ``centre`` (N, 3) wrapped into the periodic box, ``radius`` (N,),
#: borrowed from the caller's arrays.
Sediment = bundle("Sediment", ["centre", "radius"])

#: The neighbour grid of the sediment, the arrays of :mod:`.grid` in its order (``head``,
#: ``col_top``, ``hkeys`` and ``hval`` are replaced by larger ones as the pile grows, all of
#: them when a particle with a larger sphere than the cell allows arrives: :func:`set_grid_arrays`).
#: Its cell ``geom[GEOM_CELL]`` is the largest sphere diameter so far, so half of it bounds every
#: sediment radius.  ``memory`` holds the arrays the fields borrow from, in the same order.
Grid = bundle("Grid", ["geom", "igeom", "head", "col_top", "nxt", "hkeys", "hval", "counts", "memory"])

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
#: decisions (the present one and the trial of 4.1: an axis or a slide's direction, a point of
#: the axis, and room for a candidate slide's direction).
Scratch = bundle("Scratch", ["axis", "pivot", "e1", "e2", "normal", "normal_2", "point",
                                 "q_step", "q_new", "decision", "trial_decision", "trial_com"])

#: Everything a particle's descent works on besides the particle and the sediment: its
#: ``contacts``, their ``geometry``, the ``pivots`` of a rotation and the contacts
#: ``released`` by the last decision, the ``trial`` geometry of the pivots after a trial
#: rotation (4.1), the event ``window``, ``scratch``, the run's ``counters``
#: (:mod:`.counters`; empty when not counting) and the particle's ``reads`` (:mod:`.reads`;
#: empty when not recording); ``memory`` holds what they all borrow from.
Workspace = bundle("Workspace", ["contacts", "geometry", "pivots", "released", "trial", "window",
                                     "scratch", "counters", "reads", "memory"])

#: The output of a run besides the sediment's spheres, preallocated for all particles: per
#: sphere the ``particle`` index; per particle the centre of mass ``com``, the orientation
#: quaternion ``rotation``, the number of ``contacts`` and the ``state`` at rest
#: (``RESTING_*``, ``HANGING_*``, ``EVENT_LIMIT``), the executed ``events`` by kind
#: (``EVENT_KINDS``) and the number of decide-and-move ``steps``.
Record = bundle("Record", ["particle", "com", "rotation", "contacts", "state", "events", "steps"])


# The numbers in the workspace's memory: contact lists (a sphere, an obstacle and a sediment sphere
# per row, and a shift of three) of MAX_CONTACTS rows for the contacts and those released, of two
# for the pivots; contact geometries (three vectors, two numbers and a kind per row) of
# MAX_CONTACTS rows and of two for the trial rotation; the event window (three numbers, four
# integers and a shift of two per row); and the scratch vectors.
_LIST_ROWS = 2 * MAX_CONTACTS + 2
_GEOMETRY_ROWS = MAX_CONTACTS + 2
_SCRATCH_FLOATS = 7 * 3 + 2 * 4 + 2 * 9 + 3
_WORKSPACE_FLOATS = 3 * _LIST_ROWS + 11 * _GEOMETRY_ROWS + 5 * MAX_TIES + _SCRATCH_FLOATS
_WORKSPACE_INTS = 3 * _LIST_ROWS + _GEOMETRY_ROWS + 4 * MAX_TIES


@jit(inline="always")
def _contact_list(ints, floats, i, f, size):
    """A contact list of ``size`` rows borrowed from ``ints`` and ``floats`` at ``i`` and ``f``;
    returns it and the next free positions."""
    sphere, i = carve(ints, i, size)
    obstacle, i = carve(ints, i, size)
    sediment, i = carve(ints, i, size)
    shift, f = carve_rows(floats, f, size, 3)
    return ContactList(sphere, obstacle, sediment, shift), i, f


@jit(inline="always")
def _contact_geometry(ints, floats, i, f, size):
    """Contact geometry of ``size`` rows borrowed like :func:`_contact_list`."""
    centre, f = carve_rows(floats, f, size, 3)
    pivot, f = carve_rows(floats, f, size, 3)
    normal, f = carve_rows(floats, f, size, 3)
    reach, f = carve(floats, f, size)
    level, f = carve(floats, f, size)
    kind, i = carve(ints, i, size)
    return ContactGeometry(centre, pivot, normal, reach, level, kind), i, f


@jit(inline="always")
def _event_window(ints, floats, i, f):
    angle, f = carve(floats, f, MAX_TIES)
    cos, f = carve(floats, f, MAX_TIES)
    sin, f = carve(floats, f, MAX_TIES)
    kind, i = carve(ints, i, MAX_TIES)
    sphere, i = carve(ints, i, MAX_TIES)
    obstacle, i = carve(ints, i, MAX_TIES)
    sediment, i = carve(ints, i, MAX_TIES)
    shift, f = carve_rows(floats, f, MAX_TIES, 2)
    return EventWindow(angle, cos, sin, kind, sphere, obstacle, sediment, shift), i, f


@jit(inline="always")
def _scratch(floats, f):
    axis, f = carve(floats, f, 3)
    pivot, f = carve(floats, f, 3)
    e1, f = carve(floats, f, 3)
    e2, f = carve(floats, f, 3)
    normal, f = carve(floats, f, 3)
    normal_2, f = carve(floats, f, 3)
    point, f = carve(floats, f, 3)
    q_step, f = carve(floats, f, 4)
    q_new, f = carve(floats, f, 4)
    decision, f = carve(floats, f, 9)
    trial_decision, f = carve(floats, f, 9)
    trial_com, f = carve(floats, f, 3)
    return Scratch(axis, pivot, e1, e2, normal, normal_2, point, q_step, q_new, decision, trial_decision,
                   trial_com), f


@jit
def new_workspace(counters, reads):
    """Every bundle of :class:`Workspace`, allocated once per run in one block of numbers and one of
    integers (zero-filled), with the run's ``counters`` and the particles' ``reads`` (which it keeps
    alive)."""
    floats = np.zeros(_WORKSPACE_FLOATS)
    ints = np.zeros(_WORKSPACE_INTS, dtype=np.int64)
    contacts, i, f = _contact_list(ints, floats, 0, 0, MAX_CONTACTS)
    geometry, i, f = _contact_geometry(ints, floats, i, f, MAX_CONTACTS)
    pivots, i, f = _contact_list(ints, floats, i, f, 2)
    released, i, f = _contact_list(ints, floats, i, f, MAX_CONTACTS)
    trial, i, f = _contact_geometry(ints, floats, i, f, 2)
    window, i, f = _event_window(ints, floats, i, f)
    scratch, f = _scratch(floats, f)
    # the memory keeps the counters and the reads alive too: a caller's temporary would be freed at
    # once, and the rectangles written into whatever took its place
    return Workspace(contacts, geometry, pivots, released, trial, window, scratch, borrowed(counters), borrowed(reads),
                     (floats, ints, counters, reads))


@jit
def new_particle(n_max):
    """A :class:`Particle` of up to ``n_max`` spheres."""
    floats = np.zeros(7 * n_max + 16)
    body, f = carve_rows(floats, 0, n_max, 3)
    radius, f = carve(floats, f, n_max)
    centre, f = carve_rows(floats, f, n_max, 3)
    com, f = carve(floats, f, 3)
    quaternion, f = carve(floats, f, 4)
    rotation, f = carve_rows(floats, f, 3, 3)
    return Particle(body, radius, centre, com, quaternion, rotation, floats)


@jit
def sediment_in(centre, radius):
    """The :class:`Sediment` kept in the caller's ``centre`` (N, 3) and ``radius`` (N,), which the
    caller keeps alive."""
    return Sediment(borrowed(centre), borrowed(radius))


@jit
def new_grid(geom, igeom, head, col_top, nxt, hkeys, hval, counts):
    """The :class:`Grid` of the arrays of :mod:`.grid`, which it keeps alive."""
    memory = (geom, igeom, head, col_top, nxt, hkeys, hval, counts)
    return Grid(borrowed(geom), borrowed(igeom), borrowed(head), borrowed(col_top), borrowed(nxt),
                borrowed(hkeys), borrowed(hval), borrowed(counts), memory)


@jit(inline="always")
def set_grid_arrays(grid, geom, igeom, head, col_top, nxt, hkeys, hval, counts):
    """Make the grid's arrays these (each either the grid's own or a new one, which the grid keeps)."""
    memory = grid.memory
    grid.memory = (_owner(geom, grid.geom, memory[0]), _owner(igeom, grid.igeom, memory[1]),
                   _owner(head, grid.head, memory[2]), _owner(col_top, grid.col_top, memory[3]),
                   _owner(nxt, grid.nxt, memory[4]), _owner(hkeys, grid.hkeys, memory[5]),
                   _owner(hval, grid.hval, memory[6]), _owner(counts, grid.counts, memory[7]))
    grid.geom = borrowed(geom)
    grid.igeom = borrowed(igeom)
    grid.head = borrowed(head)
    grid.col_top = borrowed(col_top)
    grid.nxt = borrowed(nxt)
    grid.hkeys = borrowed(hkeys)
    grid.hval = borrowed(hval)
    grid.counts = borrowed(counts)


@jit(inline="always")
def _owner(array, current, current_owner):
    """What keeps ``array`` alive: the grid's own array if ``array`` is it (the same data),
    else ``array`` itself, new from the grid's functions."""
    if array.ctypes.data == current.ctypes.data:
        return current_owner
    return array


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
