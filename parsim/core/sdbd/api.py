"""The entry points of a deposition: :func:`deposit` and :func:`deposit_with_diagnostics`, which
validate their inputs (:mod:`.inputs`), run the kernel (:func:`.engine.run_deposition`) and return a
:class:`DepositionResult`."""

import contextlib
from typing import NamedTuple

import numpy as np

from parsim.core.sdbd.constants import CONTAINER_BOX, N_EVENT_KINDS, WALL_FRICTIONLESS
from parsim.core.sdbd.inputs import prepare_deposition
from parsim.core.ticker import ticking


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
            substrate_positions=None, substrate_radii=None, progress=None, faces=None):
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
        CONTAINER_CYLINDER (a vertical cylinder, ``cylinder``) or CONTAINER_MESH (the box with the
        inclined and vertical ``faces`` of a convex mesh vessel).
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
    faces : (normals, levels, boxes)
        With CONTAINER_MESH (and only then): the faces of a vessel whose inside is convex, other
        than those in the box's sides and in the floor ``z = 0`` (:mod:`.faces`): inward unit
        ``normals`` (F, 3) with ``N_z >= 0``, ``levels`` (F,) (the face lies in ``N . x = c``) and
        the bounding ``boxes`` (F, 6) ``x0, x1, y0, y1, z0, z1`` of the faces.  ``lateral`` must be
        LATERAL_WALLS; every particle must start inside the faces that are vertical (it is dropped
        above the others).
    progress : callable, optional
        Called as ``progress(settled)`` with the particles settled so far, from another thread,
        every ``PROGRESS_SECONDS`` while the run goes on (the kernel releases the GIL), and once
        at its end.

    Why so many parameters: they are the deposition's inputs in the paper's terms, each with its
    default, named by the caller; the kernels take them in named groups (:class:`.engine.Drops`, ...).
    """
    return deposit_with_diagnostics(
        shape_offsets, shape_radii, shape_start, particle_shape, particle_scale,
        particle_rotation, particle_drop_xy, box_lower_xy, box_upper_xy, lateral, floor,
        trial_angle, cycle_n, cycle_eps, max_events_per_particle,
        clock_from_particle=clock_from_particle, wall_contact=wall_contact, container=container,
        cylinder=cylinder, substrate_positions=substrate_positions, substrate_radii=substrate_radii,
        progress=progress, faces=faces)[0]


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
                             progress=None, faces=None):
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

    Why so many parameters: they are the deposition's inputs in the paper's terms and what a test asks
    to see, each with its default, named by the caller; the kernels take them in named groups
    (:class:`.engine.Drops`, ...).
    """
    from parsim.core.sdbd import counters, engine, grid, reads

    prep = prepare_deposition(shape_offsets, shape_radii, shape_start, particle_shape, particle_scale,
                              particle_rotation, particle_drop_xy, box_lower_xy, box_upper_xy, lateral, floor,
                              trial_angle, cycle_n, cycle_eps, max_events_per_particle, wall_contact, container,
                              cylinder, substrate_positions, substrate_radii, faces=faces)
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
