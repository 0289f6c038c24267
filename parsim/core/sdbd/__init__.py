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
cylindrical container), :mod:`.overlap` (debug overlap measurement), :mod:`.bundles` (the
named bundles of arrays) and :mod:`.constants`.

The public entry point is :func:`deposit`.

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

import contextlib
from typing import NamedTuple

import numpy as np

from parsim.core.sdbd.constants import (
    CONTAINER_BOX,
    CONTAINER_CYLINDER,
    EVENT_KINDS,
    EVENT_LIMIT,
    FLOOR_ROLL,
    MAX_EVENT_LIMIT,
    FLOOR_STOP,
    HANGING_ONE,
    HANGING_TWO,
    LATERAL_NONE,
    LATERAL_PERIODIC,
    LATERAL_WALLS,
    MIN_CYLINDER_SIDES,
    N_EVENT_KINDS,
    RESTING_ON_FLOOR,
    RESTING_THREE_CONTACTS,
    STATE_NAMES,
    WALL_FRICTIONLESS,
    WALL_GLUED,
)
from parsim.core.shapes.rotations import DrawnRotations
from parsim.core.ticker import ticking

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

#: How often a deposition's ``progress`` hears how many particles have settled.
PROGRESS_SECONDS = 5.0


class DepositionResult(NamedTuple):
    """Outcome of :func:`deposit` (only the particles deposited before ``stopped_at``).

    positions      (n, 3) sphere centres of the deposited particles (the substrate's spheres
                   are not included)
    radii          (n,)
    particle       (n,) int64 particle of each sphere (contiguous, deposition order)
    center_of_mass (P, 3)
    rotation       (P, 4) final orientation quaternion (w, x, y, z): the initial one
                   composed with every rolling rotation, so that
                   ``positions == com + R(q) scale offsets``
    contacts       (P,) int8 number of contacts at rest
    state          (P,) int8 RESTING_THREE_CONTACTS, RESTING_ON_FLOOR, HANGING_ONE,
                   HANGING_TWO; EVENT_LIMIT is the condition of particle ``stopped_at``,
                   which is not included (the arrays hold the particles before it)
    event_counts   (P, len(EVENT_KINDS)) int32 events per particle and kind
    steps          (P,) int32 decide-and-move steps per particle (at most
                   ``max_events_per_particle``)
    stopped_at     index of the particle that exceeded ``max_events_per_particle``, or -1
    clocked_seconds  wall-clock seconds spent on particles ``clock_from_particle`` onwards
                   (NaN when no clock was asked for): the paper's efficiency measure
                   discards the first half of the sediment (section 5)
    """

    positions: np.ndarray
    radii: np.ndarray
    particle: np.ndarray
    center_of_mass: np.ndarray
    rotation: np.ndarray
    contacts: np.ndarray
    state: np.ndarray
    event_counts: np.ndarray
    steps: np.ndarray
    stopped_at: int
    clocked_seconds: float


def deposit(shape_offsets, shape_radii, shape_start, particle_shape, particle_scale,
            particle_rotation, particle_drop_xy, box_lower_xy, box_upper_xy, lateral, floor,
            trial_angle=1e-2, cycle_n=4, cycle_eps=1e-3, max_events_per_particle=100_000,
            clock_from_particle=-1, wall_contact=WALL_FRICTIONLESS, container=CONTAINER_BOX, cylinder=None,
            substrate_positions=None, substrate_radii=None, progress=None):
    """Deposit particles one after the other by steepest descent; see the module docs.

    Parameters
    ----------
    shape_offsets : (k, 3) float
        Sphere centres of all shapes relative to each shape's centre of mass.
    shape_radii : (k,) float
        Sphere radii (> 0).
    shape_start : (S + 1,) int
        Shape ``s`` owns spheres ``shape_start[s]:shape_start[s + 1]`` (non-empty).
    particle_shape : (P,) int
        Shape of each particle, in deposition order.
    particle_scale : (P,) float
        Scale factor of offsets and radii (> 0).
    particle_rotation : (P, 4) float
        Initial orientation, unit quaternion (w, x, y, z) (normalised here).
    particle_drop_xy : (P, 2) float
        Horizontal position of the centre of mass at the drop.
    box_lower_xy, box_upper_xy : (2,) float
        Lateral box (ignored by LATERAL_NONE).  A periodic box must be wider than twice the
        largest particle extent (distance from the centre of mass to the farthest sphere
        surface) and than four sphere radii (contact distances below half the box).
    lateral : int
        LATERAL_PERIODIC, LATERAL_WALLS or LATERAL_NONE.
    floor : int
        FLOOR_STOP or FLOOR_ROLL.
    trial_angle : float
        Trial angle of frustrated situations (4.1), radians, >= 0 (0 disables the test).
    cycle_n, cycle_eps :
        Parameters ``(n, epsilon)`` of the cycling criterion (34); ``cycle_n = 0`` disables it.
    max_events_per_particle : int
        The run stops at the first particle that needs more events (``stopped_at``); at most
        ``MAX_EVENT_LIMIT`` (10^7), so that a particle's event counts fit 32 bits.
    clock_from_particle : int
        Measure the wall-clock time spent on particles from this index on
        (``clocked_seconds``); -1: no clock.
    wall_contact : int
        Wall contact model of LATERAL_WALLS: WALL_FRICTIONLESS (a sphere of infinite radius,
        the touching sphere slides along the wall) or WALL_GLUED (the wall holds the touching
        sphere's centre).
    container : int
        The lateral walls of LATERAL_WALLS: CONTAINER_BOX (the four faces of the box) or
        CONTAINER_CYLINDER (a vertical cylinder, ``cylinder``).
    cylinder : (cx, cy, radius, n_sides)
        With CONTAINER_CYLINDER (and only then): the cylinder of ``radius`` about the vertical
        axis through ``(cx, cy)``, modelled as the regular polygon of ``n_sides``
        (``>= MIN_CYLINDER_SIDES``) planar walls inscribed in its circle, side ``k`` facing the
        direction ``2 pi k / n_sides`` from the x axis (see the module docs).  ``radius`` must
        exceed the largest sphere radius, ``lateral`` must be LATERAL_WALLS and the box must be
        the square ``[cx - radius, cx + radius] x [cy - radius, cy + radius]``; every particle
        must start inside the polygon.
    substrate_positions, substrate_radii : (m, 3), (m,) float
        Fixed spheres in the sediment before the first particle (default: none): obstacles
        like the deposited spheres, never moving.  Centres at ``z >= 0``; with walls each
        sphere lies inside the box or the cylinder's polygon; a periodic box wraps them.
        They are not part of the result.
    progress : callable, optional
        Called as ``progress(settled)`` with the particles settled so far, from another thread,
        every ``PROGRESS_SECONDS`` while the run goes on (the kernel releases the GIL), and once
        at its end.
    """
    return deposit_with_diagnostics(
        shape_offsets, shape_radii, shape_start, particle_shape, particle_scale,
        particle_rotation, particle_drop_xy, box_lower_xy, box_upper_xy, lateral, floor,
        trial_angle, cycle_n, cycle_eps, max_events_per_particle,
        clock_from_particle=clock_from_particle, wall_contact=wall_contact, container=container,
        cylinder=cylinder, substrate_positions=substrate_positions, substrate_radii=substrate_radii,
        progress=progress)[0]


@contextlib.contextmanager
def _reporting(progress, counts, index):
    """While the block runs, call ``progress(int(counts[index]))`` every ``PROGRESS_SECONDS`` from a
    thread, and once when it ends (not when it fails)."""
    if progress is None:
        yield
        return

    def report():
        settled = counts[index]
        if settled == settled:  # not NaN: the first particle has settled
            progress(int(settled))

    with ticking(PROGRESS_SECONDS, report, "parsim-deposition-progress"):
        yield
    progress(int(np.nan_to_num(counts[index])))


def deposit_with_diagnostics(shape_offsets, shape_radii, shape_start, particle_shape,
                             particle_scale, particle_rotation, particle_drop_xy, box_lower_xy,
                             box_upper_xy, lateral, floor, trial_angle=1e-2, cycle_n=4,
                             cycle_eps=1e-3, max_events_per_particle=100_000, clock_from_particle=-1,
                             wall_contact=WALL_FRICTIONLESS, check_overlaps=False,
                             trace_particle=-1, trace_steps=0, container=CONTAINER_BOX, cylinder=None,
                             substrate_positions=None, substrate_radii=None, count=False, record_reads=False,
                             progress=None):
    """:func:`deposit` plus a dict of diagnostics, for tests and benchmarks.

    With ``check_overlaps`` the kernel measures, after every move, the largest overlap of
    the moving particle with the sediment, the floor and the walls
    (``diagnostics["max_overlap"]``, in units of length).  ``diagnostics["steps"]`` counts
    decide-and-move steps of all particles, ``diagnostics["chunk_steps"]`` the ends of
    angular search chunks among them; ``diagnostics["length_scale"]`` is the mean radius.
    ``trace_particle`` / ``trace_steps`` record the first steps of one particle in
    ``diagnostics["trace"]`` (see :func:`engine.run_deposition`).  With ``count``,
    ``diagnostics["counters"]`` holds the engine's counts and cycles by phase (:mod:`.counters`).
    With ``record_reads``, ``diagnostics["reads"]`` (P, 4) holds per particle the lateral rectangle
    ``x_low, x_high, y_low, y_high`` of the sediment its descent read (:mod:`.reads`).
    """
    from parsim.core.sdbd import counters, engine, grid, reads

    prep = prepare_deposition(shape_offsets, shape_radii, shape_start, particle_shape, particle_scale,
                              particle_rotation, particle_drop_xy, box_lower_xy, box_upper_xy, lateral, floor,
                              trial_angle, cycle_n, cycle_eps, max_events_per_particle, wall_contact, container,
                              cylinder, substrate_positions, substrate_radii)
    P = len(prep.particle_shape)
    n_total = prep.n_spheres
    n_sub = len(prep.substrate_radii)
    g = grid.grid_new(prep.lateral, prep.box_lower_xy, prep.box_upper_xy, prep.first_cell, n_total + n_sub,
                      prep.polygon, prep.n_sides)
    # the sediment's spheres, substrate first; after the run the particles' spheres are the result
    sediment_centre = np.zeros((n_sub + n_total, 3))
    sediment_radius = np.zeros(n_sub + n_total)
    out_particle = np.zeros(n_total, dtype=np.int64)
    out_com = np.zeros((P, 3))
    out_rot = np.zeros((P, 4))
    out_contacts = np.zeros(P, dtype=np.int8)
    out_state = np.zeros(P, dtype=np.int8)
    out_events = np.zeros((P, N_EVENT_KINDS), dtype=np.int32)
    out_steps = np.zeros(P, dtype=np.int32)
    diag = np.full(engine.N_DIAGNOSTICS, np.nan)
    trace = np.full((max(int(trace_steps), 1), 16), np.nan)
    counts = np.zeros(counters.N_COUNTERS if count else 0, dtype=np.int64)
    reads_out = np.zeros((P if record_reads else 0, reads.N_READS))
    with _reporting(progress, diag, engine.D_SETTLED):
        stopped_at, n_written = engine.run_deposition(
            engine.Drops(*prep.kernel_inputs()), engine.Spheres(prep.substrate_positions, prep.substrate_radii), g,
            engine.RunOptions(*prep.kernel_settings()),
            engine.Diagnosis(bool(check_overlaps), int(trace_particle), trace, int(clock_from_particle)),
            engine.Spheres(sediment_centre, sediment_radius),
            engine.Outputs(out_particle, out_com, out_rot, out_contacts, out_state, out_events, out_steps, diag,
                           counts, reads_out))
    n_done = P if stopped_at < 0 else int(stopped_at)
    return DepositionResult(
        positions=sediment_centre[n_sub:n_sub + n_written],
        radii=sediment_radius[n_sub:n_sub + n_written],
        particle=out_particle[:n_written],
        center_of_mass=out_com[:n_done],
        rotation=out_rot[:n_done],
        contacts=out_contacts[:n_done],
        state=out_state[:n_done],
        event_counts=out_events[:n_done],
        steps=out_steps[:n_done],
        stopped_at=int(stopped_at),
        clocked_seconds=float(diag[3]),
    ), {"max_overlap": float(diag[0]), "steps": int(diag[1]), "chunk_steps": int(diag[2]),
        "length_scale": prep.length_scale, "trace": trace,
        "counters": dict(zip(counters.NAMES, counts.tolist())) if count else {},
        "reads": reads_out[:n_done] if record_reads else None}



class PreparedDeposition(NamedTuple):
    """The inputs of a deposition validated and in the kernel's types (:func:`prepare_deposition`),
    with what follows from them: the length scale ``ell`` of the tolerances, the grid's first
    cell, the largest sphere radius of each shape, the substrate and the container."""

    shape_offsets: np.ndarray
    shape_radii: np.ndarray
    shape_start: np.ndarray
    particle_shape: np.ndarray
    particle_scale: np.ndarray
    particle_rotation: np.ndarray
    particle_drop_xy: np.ndarray
    box_lower_xy: np.ndarray
    box_upper_xy: np.ndarray
    lateral: int
    floor: int
    wall_contact: int
    trial_angle: float
    cycle_n: int
    cycle_eps: float
    max_events: int
    length_scale: float
    first_cell: float
    shape_largest_radius: np.ndarray
    n_spheres: int
    substrate_positions: np.ndarray
    substrate_radii: np.ndarray
    polygon: np.ndarray | None
    n_sides: int

    def kernel_inputs(self):
        """The particles' arguments of the kernels, in their order."""
        return (self.shape_offsets, self.shape_radii, self.shape_start, self.particle_shape, self.particle_scale,
                self.particle_rotation, self.particle_drop_xy)

    def kernel_settings(self):
        """``floor_mode, wall_contact, trial_angle, cycle_n, cycle_eps, max_events, ell`` of the kernels."""
        return (self.floor, self.wall_contact, self.trial_angle, self.cycle_n, self.cycle_eps, self.max_events,
                self.length_scale)


def prepare_deposition(shape_offsets, shape_radii, shape_start, particle_shape, particle_scale,
                       particle_rotation, particle_drop_xy, box_lower_xy, box_upper_xy, lateral, floor,
                       trial_angle=1e-2, cycle_n=4, cycle_eps=1e-3, max_events_per_particle=100_000,
                       wall_contact=WALL_FRICTIONLESS, container=CONTAINER_BOX, cylinder=None,
                       substrate_positions=None, substrate_radii=None, first_particle=0, keep_drawn_rotations=False):
    """The arguments of :func:`deposit` validated (a ValueError names the first bad one) as a
    :class:`PreparedDeposition`; ``first_particle`` is the first particle's place in the drop order
    when these are a chunk of a longer run (the errors name particles by it).  With
    ``keep_drawn_rotations``, ``particle_rotation`` given as :class:`~parsim.core.shapes.rotations.DrawnRotations`
    (unit quaternions by construction) stays one, its rows computed only when taken."""

    offsets = np.ascontiguousarray(shape_offsets, dtype=np.float64)
    radii = np.ascontiguousarray(shape_radii, dtype=np.float64)
    start = np.ascontiguousarray(shape_start, dtype=np.int64)
    pshape = np.ascontiguousarray(particle_shape, dtype=np.int64)
    pscale = np.ascontiguousarray(particle_scale, dtype=np.float64)
    drawn = keep_drawn_rotations and isinstance(particle_rotation, DrawnRotations)
    prot = particle_rotation if drawn else np.ascontiguousarray(particle_rotation, dtype=np.float64)  # read only
    pxy = np.ascontiguousarray(particle_drop_xy, dtype=np.float64)
    lo = np.asarray(box_lower_xy, dtype=np.float64)
    hi = np.asarray(box_upper_xy, dtype=np.float64)

    if offsets.ndim != 2 or offsets.shape[1] != 3:
        raise ValueError(f"shape_offsets must have shape (k, 3), got {offsets.shape}")
    if radii.shape != (offsets.shape[0],):
        raise ValueError(f"shape_radii must have shape ({offsets.shape[0]},), got {radii.shape}")
    if not (np.all(np.isfinite(offsets)) and np.all(np.isfinite(radii)) and np.all(radii > 0)):
        raise ValueError("shape_offsets must be finite and shape_radii finite and > 0")
    if start.ndim != 1 or start.shape[0] < 2 or start[0] != 0 or start[-1] != offsets.shape[0] \
            or np.any(np.diff(start) <= 0):
        raise ValueError("shape_start must increase strictly from 0 to len(shape_radii)")
    n_shapes = start.shape[0] - 1
    P = pshape.shape[0]
    if pshape.ndim != 1 or np.any(pshape < 0) or np.any(pshape >= n_shapes):
        raise ValueError(f"particle_shape must be a 1-d array of shape indices in [0, {n_shapes})")
    if pscale.shape != (P,) or not np.all(np.isfinite(pscale)) or np.any(pscale <= 0):
        raise ValueError(f"particle_scale must have shape ({P},) with finite values > 0")
    if prot.shape != (P, 4) or not (drawn or np.all(np.isfinite(prot))):
        raise ValueError(f"particle_rotation must have shape ({P}, 4) with finite values")
    if not drawn and np.any(np.linalg.norm(prot, axis=1) < 1e-12):  # the kernel normalises them
        raise ValueError("particle_rotation must hold non-zero quaternions")
    if pxy.shape != (P, 2) or not np.all(np.isfinite(pxy)):
        raise ValueError(f"particle_drop_xy must have shape ({P}, 2) with finite values")
    if lateral not in (LATERAL_PERIODIC, LATERAL_WALLS, LATERAL_NONE):
        raise ValueError(f"lateral must be LATERAL_PERIODIC (0), LATERAL_WALLS (1) or LATERAL_NONE (2), got {lateral}")
    if floor not in (FLOOR_STOP, FLOOR_ROLL):
        raise ValueError(f"floor must be FLOOR_STOP (0) or FLOOR_ROLL (1), got {floor}")
    if wall_contact not in (WALL_FRICTIONLESS, WALL_GLUED):
        raise ValueError(f"wall_contact must be WALL_FRICTIONLESS (0) or WALL_GLUED (1), got {wall_contact}")
    if not (np.isfinite(trial_angle) and 0.0 <= trial_angle < np.pi):
        raise ValueError(f"trial_angle must be in [0, pi), got {trial_angle}")
    if int(cycle_n) != cycle_n or not 0 <= cycle_n <= 28:
        raise ValueError(f"cycle_n must be an integer in [0, 28], got {cycle_n}")
    if not (np.isfinite(cycle_eps) and cycle_eps > 0):
        raise ValueError(f"cycle_eps must be > 0, got {cycle_eps}")
    if int(max_events_per_particle) != max_events_per_particle or not 1 <= max_events_per_particle <= MAX_EVENT_LIMIT:
        raise ValueError(f"max_events_per_particle must be an integer in [1, {MAX_EVENT_LIMIT}], "
                         f"got {max_events_per_particle}")

    counts = np.diff(start)
    n_total = int(np.sum(counts[pshape])) if P else 0
    # scales: extent of each shape about its centre of mass, largest radius.  The length scale
    # of the tolerances is the mean radius of the shapes' spheres at scale 1, and the grid's
    # first cell the first particle's largest sphere diameter: nothing about a particle's
    # descent depends on the particles after it
    shape_extent = np.array([np.max(np.linalg.norm(offsets[start[s]:start[s + 1]], axis=1)
                                    + radii[start[s]:start[s + 1]]) for s in range(n_shapes)])
    shape_rmax = np.array([np.max(radii[start[s]:start[s + 1]]) for s in range(n_shapes)])
    if P:
        ell = float(np.mean(radii))
        r_max = float(np.max(pscale * shape_rmax[pshape]))
        ext_max = float(np.max(pscale * shape_extent[pshape]))
    else:
        ell = 1.0
        r_max = 1.0
        ext_max = 1.0

    sub_pos, sub_rad, polygon, n_sides, lo, hi = _container(lo, hi, lateral, r_max, ext_max, container, cylinder,
                                                            substrate_positions, substrate_radii, 1e-9 * ell)
    r_sub = float(np.max(sub_rad)) if len(sub_rad) else 0.0
    if lateral == LATERAL_WALLS and P:
        # the caller guarantees that each particle starts inside; check it
        outside = _first_outside_walls(offsets, radii, start, pshape, pscale, np.asarray(prot), pxy, lo, hi, polygon,
                                       n_sides, 1e-9 * ell)
        if outside >= 0:
            raise ValueError(f"particle {first_particle + outside}: dropped at {tuple(pxy[outside].tolist())}, it "
                             "does not fit inside the walls")
    if lateral == LATERAL_NONE:
        lo = np.zeros(2)
        hi = np.zeros(2)

    # the cell bounds every sediment radius: the first particle's and the substrate's
    cell = 2.0 * pscale[0] * shape_rmax[pshape[0]] if P else 2.0 * r_max
    cell = max(cell, 2.0 * r_sub)
    return PreparedDeposition(offsets, radii, start, pshape, pscale, prot, pxy, lo, hi, int(lateral), int(floor),
                              int(wall_contact), float(trial_angle), int(cycle_n), float(cycle_eps),
                              int(max_events_per_particle), ell, cell, shape_rmax, n_total, sub_pos, sub_rad,
                              polygon, int(n_sides))


def check_container(box_lower_xy, box_upper_xy, lateral, largest_radius, largest_extent, length_scale,
                    container=CONTAINER_BOX, cylinder=None, substrate_positions=None, substrate_radii=None):
    """Raise the ValueError :func:`deposit` would raise for this container and substrate, for particles
    whose spheres have radii up to ``largest_radius`` and reach ``largest_extent`` from their centre
    of mass, and whose mean sphere radius at scale 1 is ``length_scale``: for checking a task before
    it runs."""
    lo = np.asarray(box_lower_xy, dtype=np.float64)
    hi = np.asarray(box_upper_xy, dtype=np.float64)
    _container(lo, hi, lateral, float(largest_radius), float(largest_extent), container, cylinder,
               substrate_positions, substrate_radii, 1e-9 * length_scale)


def _container(lo, hi, lateral, r_max, ext_max, container, cylinder, substrate_positions, substrate_radii, tol):
    """The substrate (centres, radii), the cylinder's polygon and sides (None, 0 for the box) and the
    lateral box, validated: a box of positive size, a periodic side wider than twice the largest
    extent and four times the largest sphere radius (minimum images unambiguous), walls that hold
    the largest sphere, a substrate inside the walls."""
    if lateral != LATERAL_NONE:
        if lo.shape != (2,) or hi.shape != (2,) or not np.all(np.isfinite(lo)) or not np.all(np.isfinite(hi)):
            raise ValueError("box_lower_xy and box_upper_xy must be finite pairs (x, y)")
        if np.any(hi <= lo):
            raise ValueError("box_upper_xy must exceed box_lower_xy in x and y")
    sub_pos, sub_rad = _substrate(substrate_positions, substrate_radii)
    r_contact = max(r_max, float(np.max(sub_rad)) if len(sub_rad) else 0.0)
    polygon, n_sides, lo, hi = _cylinder(container, cylinder, lateral, lo, hi, r_contact)
    if lateral == LATERAL_PERIODIC:
        side = np.min(hi - lo)
        need = max(2.0 * ext_max, 4.0 * r_contact)
        if side <= need:
            raise ValueError(
                f"periodic box side {side:g} must exceed twice the largest particle extent "
                f"(2 x {ext_max:g}) and four times the largest sphere radius (4 x {r_contact:g}), "
                f"i.e. {need:g}, so that minimum images are unambiguous")
    if lateral == LATERAL_WALLS:
        if np.any(hi - lo < 2.0 * r_max):
            raise ValueError("walled box narrower than the largest sphere")
        _check_substrate_inside(sub_pos, sub_rad, lo, hi, polygon, n_sides, tol)
    return sub_pos, sub_rad, polygon, n_sides, lo, hi


def _substrate(substrate_positions, substrate_radii):
    """The substrate's centres (m, 3) and radii (m,) (m = 0 when none is given), validated."""
    if substrate_positions is None and substrate_radii is None:
        return np.zeros((0, 3)), np.zeros(0)
    if substrate_positions is None or substrate_radii is None:
        raise ValueError("substrate_positions and substrate_radii must be given together")
    pos = np.ascontiguousarray(substrate_positions, dtype=np.float64)
    rad = np.ascontiguousarray(substrate_radii, dtype=np.float64)
    if pos.ndim != 2 or pos.shape[1] != 3 or rad.shape != (pos.shape[0],):
        raise ValueError(f"substrate_positions must have shape (m, 3) and substrate_radii (m,), "
                         f"got {pos.shape} and {rad.shape}")
    for j in range(len(rad)):
        if not (np.all(np.isfinite(pos[j])) and np.isfinite(rad[j]) and rad[j] > 0 and pos[j, 2] >= 0):
            raise ValueError(f"substrate sphere {j}: centre {tuple(pos[j])}, radius {rad[j]}: the centre "
                             f"must be finite with z >= 0 and the radius finite and > 0")
    return pos, rad


def _cylinder(container, cylinder, lateral, lo, hi, r_max):
    """The polygon of a cylindrical container (:func:`.polygon.polygon_geometry`), its number
    of sides and the box (the square about the cylinder), validated against the other
    arguments; ``(None, 0, lo, hi)`` for the box."""
    from parsim.core.sdbd.polygon import polygon_geometry

    if container not in (CONTAINER_BOX, CONTAINER_CYLINDER):
        raise ValueError(f"container must be CONTAINER_BOX (0) or CONTAINER_CYLINDER (1), got {container}")
    if container == CONTAINER_BOX:
        if cylinder is not None:
            raise ValueError("cylinder is given but container is CONTAINER_BOX")
        return None, 0, lo, hi
    if lateral != LATERAL_WALLS:
        raise ValueError(f"a cylindrical container needs lateral = LATERAL_WALLS (1), got {lateral}")
    if cylinder is None or len(cylinder) != 4:
        raise ValueError("CONTAINER_CYLINDER needs cylinder = (cx, cy, radius, n_sides)")
    cx, cy, radius, n_sides = cylinder
    cx, cy, radius = float(cx), float(cy), float(radius)
    if not (np.isfinite(cx) and np.isfinite(cy) and np.isfinite(radius)):
        raise ValueError(f"cylinder centre and radius must be finite, got {cylinder}")
    if int(n_sides) != n_sides or n_sides < MIN_CYLINDER_SIDES:
        raise ValueError(f"cylinder n_sides must be an integer >= {MIN_CYLINDER_SIDES}, got {n_sides}")
    if not radius > r_max:
        raise ValueError(f"cylinder radius {radius:g} must exceed the largest sphere radius {r_max:g}")
    square_lo = np.array([cx - radius, cy - radius])
    square_hi = np.array([cx + radius, cy + radius])
    tol = 1e-12 * (radius + abs(cx) + abs(cy))
    if np.any(np.abs(lo - square_lo) > tol) or np.any(np.abs(hi - square_hi) > tol):
        raise ValueError(f"with a cylinder the box must be the square [cx - radius, cx + radius] x "
                         f"[cy - radius, cy + radius] = {tuple(square_lo)} - {tuple(square_hi)}, "
                         f"got {tuple(lo)} - {tuple(hi)}")
    return polygon_geometry(cx, cy, radius, int(n_sides)), int(n_sides), square_lo, square_hi


#: particle spheres placed at once by the check that particles start inside the walls (bounds its memory)
FIT_CHECK_SPHERES = 1 << 18


def _first_outside_walls(offsets, radii, start, pshape, pscale, prot, pxy, lo, hi, polygon, n_sides, tol):
    """The first particle with a sphere outside the walls (the box or the cylinder's polygon) by more
    than ``tol`` at its drop point, or -1: the particles of each shape placed together, a batch at a time."""
    from parsim.core.structure import rotation_matrices

    first = len(pshape)
    for s in range(len(start) - 1):
        o, r = offsets[start[s]:start[s + 1]], radii[start[s]:start[s + 1]]
        particles = np.flatnonzero(pshape == s)
        batch = max(1, FIT_CHECK_SPHERES // len(r))
        for begin in range(0, len(particles), batch):  # none for a shape no particle has
            chosen = particles[begin:begin + batch]
            scale = pscale[chosen]
            # sphere k of particle p at pxy[p] + scale[p] (R(q_p) o_k)_xy, radius scale[p] r_k
            xy = pxy[chosen, None, :] + scale[:, None, None] * np.einsum("pij,kj->pki",
                                                                          rotation_matrices(prot[chosen])[:, :2], o)
            reach = scale[:, None] * r[None, :]
            if polygon is not None:
                out = _outside_polygon(xy.reshape(-1, 2), reach.ravel(), polygon, n_sides, tol).reshape(reach.shape)
            else:
                out = (xy - reach[..., None] < lo - tol) | (xy + reach[..., None] > hi + tol)
            bad = chosen[np.any(out.reshape(len(chosen), -1), axis=1)]
            if len(bad):
                first = min(first, int(bad[0]))
                break
    return first if first < len(pshape) else -1


def _outside_polygon(xy, r, polygon, n_sides, tol):
    """Which spheres (centres ``xy`` (k, 2), radii ``r``) cross a side of the polygon by more
    than ``tol``.  A point's farthest side is the one whose normal is nearest its direction
    from the axis; that side and its neighbours are tested."""
    table = polygon[3:].reshape(n_sides, 3)
    angle = np.arctan2(xy[:, 1] - polygon[1], xy[:, 0] - polygon[0])
    nearest = np.rint(angle * n_sides / (2.0 * np.pi)).astype(np.int64)
    outside = np.zeros(len(r), dtype=bool)
    for shift in (-1, 0, 1):
        ux, uy, d = table[(nearest + shift) % n_sides].T
        outside |= ux * xy[:, 0] + uy * xy[:, 1] + r - d > tol
    return outside


def _check_substrate_inside(pos, rad, lo, hi, polygon, n_sides, tol):
    """Every substrate sphere lies inside the walls (the box or the cylinder's polygon)."""
    if len(rad) == 0:
        return
    if polygon is not None:
        outside = _outside_polygon(pos[:, :2], rad, polygon, n_sides, tol)
    else:
        outside = np.any((pos[:, :2] - rad[:, None] < lo - tol) | (pos[:, :2] + rad[:, None] > hi + tol), axis=1)
    if np.any(outside):
        j = int(np.argmax(outside))
        raise ValueError(f"substrate sphere {j}: centre {tuple(pos[j])}, radius {rad[j]}: it does not lie "
                         f"inside the walls")
