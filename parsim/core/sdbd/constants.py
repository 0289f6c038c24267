"""Constants of the SDBD engine: boundary modes, particle states, event kinds, tolerances.

Every tolerance is a named constant with its scale.  Lengths are measured in units of the
*length scale* ``ell`` of a run, the mean radius of all spheres that will be deposited
(``sum_p scale_p * sum radii of shape_p / number of spheres``); angles are in radians.
"""

import numpy as np

# --------------------------------------------------------------------------- boundaries
#: Periodic in x and y over ``[box_lower_xy, box_upper_xy)`` (minimum-image distances).
LATERAL_PERIODIC = 0
#: Rigid vertical walls at the four box faces.
LATERAL_WALLS = 1
#: No lateral boundary: a heap on an unbounded floor.
LATERAL_NONE = 2

# --------------------------------------------------------------------------- the grid's geometry
# The sediment grid (:mod:`.grid`) carries its geometry in two arrays that kernels index by
# these names. ``geom`` (float64): the box's lower corner and side lengths, the columns' sides
# and the cell (the largest sphere diameter so far, also the layers' height), then from
# GEOM_CONTAINER on the cylinder's polygon (:mod:`.polygon`). ``igeom`` (int64): the lateral
# mode, the number of columns along x and y (periodic and walled boxes), the polygon's sides
# (0 for the box), and the number of a mesh vessel's faces (:mod:`.faces`) that follow in ``geom``
# instead of a polygon.
GEOM_LOWER_X, GEOM_LOWER_Y, GEOM_LENGTH_X, GEOM_LENGTH_Y, GEOM_COLUMN_X, GEOM_COLUMN_Y, GEOM_CELL = range(7)
GEOM_CONTAINER = 7
IGEOM_MODE, IGEOM_COLUMNS_X, IGEOM_COLUMNS_Y, IGEOM_SIDES, IGEOM_FACES = range(5)

#: The lateral walls of LATERAL_WALLS are the four faces of the box.
CONTAINER_BOX = 0
#: The lateral wall of LATERAL_WALLS is a cylinder, modelled as the regular polygon of planar
#: walls inscribed in its circle (see :mod:`parsim.core.sdbd`).
CONTAINER_CYLINDER = 1
#: The lateral walls of LATERAL_WALLS are the box's faces, and inside them the inclined and
#: vertical faces of a convex mesh vessel (:mod:`parsim.core.sdbd.faces`).
CONTAINER_MESH = 2
#: Fewest sides of the polygon that models a cylinder.
MIN_CYLINDER_SIDES = 8

#: A wall contact is a sphere of infinite radius (the default): the wall pushes only along its
#: normal, its pivot lies at infinity behind it, so the wall never holds a particle up by
#: itself, and with one other pivot ``P`` the particle rotates about the axis through ``P``
#: along the wall's normal, the touching sphere sliding along the wall.
WALL_FRICTIONLESS = 0
#: A wall contact holds the touching sphere's centre fixed (a pivot about that centre, no
#: sliding), like the floor under FLOOR_ROLL.
WALL_GLUED = 1

#: The paper's floor: a particle touching the plane ``z = 0`` is immobilised at once.
FLOOR_STOP = 0
#: The floor contact is a pivot like any other (about the touching sphere's own centre).
FLOOR_ROLL = 1

# --------------------------------------------------------------------------- states
#: At rest: no rotation about one contact or about a pair of contacts descends
#: (normally three contacts; a particle that rests with fewer contacts of which one is
#: the floor, under FLOOR_ROLL, is reported RESTING_ON_FLOOR).
RESTING_THREE_CONTACTS = 0
#: Stopped on the floor: FLOOR_STOP immobilised it at its first floor contact, or, under
#: FLOOR_ROLL, it rests with fewer than three contacts one of which is the floor.
RESTING_ON_FLOOR = 1
#: Hangs on one contact: the centre of mass is straight below the pivot.  (With glued walls,
#: also a particle held at rest by one wall contact and nothing else that lets it descend.)
HANGING_ONE = 2
#: Hangs on two contacts: the centre of mass is straight below the axis of the pivots.
#: With glued walls this also covers a particle held by a wall and one other contact: the
#: wall pivot is the touching sphere's own centre, so e.g. a single sphere touching a wall
#: and a sediment sphere has its centre on the axis and cannot roll.
HANGING_TWO = 3
#: The particle needed more than ``max_events_per_particle`` events; the run stopped there.
EVENT_LIMIT = 4
#: The largest ``max_events_per_particle``: a step executes at most MAX_TIES events and closes
#: at most MAX_CONTACTS contacts, so that a particle's event counts stay below 2^31 (int32).
MAX_EVENT_LIMIT = 10_000_000

STATE_NAMES = ("resting_three_contacts", "resting_on_floor", "hanging_one", "hanging_two",
               "event_limit")

# --------------------------------------------------------------------------- event kinds
#: Column names of ``DepositionResult.event_counts``.
EVENT_KINDS = (
    "fall_contact",             # 3.1: a falling particle touches a sediment sphere
    "second_contact",           # 3.2.2 (a): rolling on one contact, a new sphere contact
    "loss_of_contact",          # 3.2.3 (b): rolling on one contact, it opens (fall)
    "hanging_one",              # 3.2.4 (c): centre of mass below the single pivot
    "wall_contact",             # 3.2.5 (d) / 3.3.6 (e): a lateral wall is touched
    "third_contact",            # 3.3.2 (a): rolling on two contacts, a new sphere contact
    "loss_of_one_contact",      # 3.3.3 (b): rolling on two, one of them opens (eq. 25-30)
    "loss_of_two_contacts",     # 3.3.4 (c): rolling on two, both open (fall)
    "hanging_two",              # 3.3.5 (d): centre of mass below the axis of two pivots
    "floor_contact",            # 3.1 / 3.2.5 / 3.3.6: the floor z = 0 is touched
    "frustrated_trial_rotation",  # 4.1: a trial rotation by the trial angle was executed
    "cycling_interruption",     # 4.2: criterion (34) met, cycling contacts declared closed
    "simultaneous",             # 4.3: extra events executed at the same height / angle
)
K_FALL_CONTACT = 0
K_SECOND_CONTACT = 1
K_LOSS_OF_CONTACT = 2
K_HANGING_ONE = 3
K_WALL_CONTACT = 4
K_THIRD_CONTACT = 5
K_LOSS_OF_ONE = 6
K_LOSS_OF_TWO = 7
K_HANGING_TWO = 8
K_FLOOR_CONTACT = 9
K_FRUSTRATED = 10
K_CYCLING = 11
K_SIMULTANEOUS = 12
N_EVENT_KINDS = len(EVENT_KINDS)

# --------------------------------------------------------------------------- internal codes
# Obstacle kinds of a contact.
OB_SPHERE = 0
OB_FLOOR = 1
OB_WALL_XLO = 2
OB_WALL_XHI = 3
OB_WALL_YLO = 4
OB_WALL_YHI = 5
#: A side of the polygon that models a cylinder; the contact's ``sediment`` field holds the
#: side's index.  Like the box walls it is a plane with a horizontal normal (``>= OB_WALL_XLO``).
OB_SIDE = 6
#: A face of a convex mesh vessel (:mod:`.faces`), a plane of any inward normal whose ``z``
#: component is not negative; the contact's ``sediment`` field holds the face's index.
OB_FACE = 7

# Motions chosen by the steepest-descent decision.
MOTION_FALL = 0
MOTION_SINGLE = 1
MOTION_PAIR = 2
MOTION_REST = 3
#: A translation along frictionless inclined faces (:mod:`.slide`).
MOTION_SLIDE = 4

# Kinds of potential events of a rotation.
EV_NONE = -1
EV_CHUNK = 0        # end of an angular chunk (no physical event; bookkeeping only)
EV_CONTACT = 1      # a new contact (sphere, floor or wall)
EV_LOSS = 2         # the pivot sphere reaches the height of its sediment sphere
EV_RELEASE = 3      # eq. 25-30: rolling on one of the two pivots becomes possible
EV_HANG = 4         # the centre of mass reaches the lowest point of its circle
EV_TRIAL = 5        # 4.1 trial rotation by the trial angle
EV_VIRTUAL = 6      # eq. 31: virtual small rotation

#: Most contacts a particle can hold at once (three at rest; simultaneous events and
#: cycling interruptions can add a few more for an instant).
MAX_CONTACTS = 16
#: Most events that can be executed together as simultaneous (4.3) in one step.
MAX_TIES = 64

# --------------------------------------------------------------------------- tolerances
#: Largest overlap, in units of ell, that a move may leave between a sphere of the moving
#: particle and the sediment (or the floor, a wall); a larger one is a bug.
OVERLAP_LIMIT = 1e-9
#: A gap below TOUCH_TOL * ell counts as touching (round-off of positions up to ~1e3 ell
#: from the origin is ~1e-13 ell).
TOUCH_TOL = 1e-10
#: First-order rate d(gap)/d(phi) (length per radian) below RATE_TOL * ell in magnitude
#: is "tangent": the second derivative of the gap decides whether a contact opens.
RATE_TOL = 1e-10
#: A tangent contact opens unless the second derivative d^2(gap)/d(phi)^2 (length per
#: radian squared) is below -CURVATURE_TOL * ell: over a rotation by pi the gap then drops by
#: less than 5e-10 ell, below OVERLAP_LIMIT (the round-off of the derivative is ~1e-13 ell).
#: The curvature is computed exactly, not from the gap after a small probe rotation: a gap
#: that closes slowly (a moving sphere's circle nearly osculating the sphere it touches, a
#: curvature of 4e-4 ell) drops by less than the round-off of two gaps after any probe angle
#: small enough to be a second-order test.
CURVATURE_TOL = 1e-10
#: Falling is allowed when every contact normal has a z component <= NZ_TOL (the moving
#: sphere is below or level with its sediment sphere); dimensionless.
NZ_TOL = 1e-10
#: A motion whose centre of mass descends with slope -dz/ds <= DESCENT_TOL does not
#: descend (hanging / rest); dimensionless.
DESCENT_TOL = 1e-10
#: A rotation that lowers the centre of mass at a rate -dz/dphi (length per radian) below
#: DESCENT_RATE_TOL * ell is no motion, whatever its slope: the centre of mass is then on the
#: rotation axis to round-off (a rod turning about its own axis, ~1e-15 ell), where no angle
#: lowers it, or straight above it (an unstable equilibrium, tipped by the decision).
DESCENT_RATE_TOL = 1e-10
#: Two candidate motions whose slopes differ by less than STEEP_TOL are equally steep;
#: the first in the fixed order (singles, then pairs, by contact index) is taken.
STEEP_TOL = 1e-12
#: Events within SIMULTANEOUS_TOL * ell of fall height, or whose arcs differ by less than
#: that length, are simultaneous (4.3) and are executed together.
SIMULTANEOUS_TOL = 1e-11
#: Roots of the contact equations within ANGLE_EPS (rad) of 0 or 2 pi belong to the
#: current position (round-off), not to a future event.
ANGLE_EPS = 1e-10
#: Eq. 31: the virtual small rotation that decides whether a contact whose release
#: condition (25) holds with zero first derivative really opens is the trial angle of 4.1
#: (the paper refers to 4.1 for it); VIRTUAL_ANGLE (rad) is used when the trial test is
#: disabled (trial_angle = 0).  A much smaller angle makes the particle creep along the
#: contact in steps of that angle (release, virtual rotation, roll, re-contact, ...).
VIRTUAL_ANGLE = 1e-6
#: 4.2: when cycling is detected, every obstacle within CYCLE_CLOSE_GAP * ell of the
#: particle is declared a closed contact (the paper reports clearances ~1e-8 of the
#: radius); also the clearance below which obstacles count as contacts when the decision
#: finds rest.
CYCLE_CLOSE_GAP = 1e-7
#: 4.2 without a period: a particle whose centre of mass went down by less than
#: CREEP_DESCENT * ell over its last 24 steps is creeping (a zigzag among obstacles at
#: clearances of the order of the tolerances, e.g. a rod sliding down a groove in steps of
#: 1e-8 rad), and the obstacles near it are declared closed.  Harmless when none is near.
CREEP_DESCENT = 1e-6
#: Rotations are searched in chunks in which no sphere moves more than CHUNK_CELLS grid
#: cells, so that each query covers few cells (a chunk end is not a physical event).
CHUNK_CELLS = 1.5
#: Margin (units of ell) by which a particle starts above the top of the sediment.
DROP_MARGIN = 1e-2
#: Lengths below TINY * ell are zero (a sphere on a rotation axis, a degenerate axis).
TINY = 1e-14

INT = np.int64
