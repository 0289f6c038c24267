"""The inputs of a deposition checked and put in the kernels' types (:func:`prepare_deposition` ->
:class:`PreparedDeposition`), and the container they describe: the box, the cylinder's polygon
(:mod:`.polygon`) and the substrate, with the checks that every particle and substrate sphere fits in it."""

from typing import NamedTuple

import numpy as np

from parsim.core.sdbd.constants import (
    CONTAINER_BOX,
    CONTAINER_CYLINDER,
    CONTAINER_MESH,
    FLOOR_ROLL,
    FLOOR_STOP,
    LATERAL_NONE,
    LATERAL_PERIODIC,
    LATERAL_WALLS,
    MAX_EVENT_LIMIT,
    MIN_CYLINDER_SIDES,
    WALL_FRICTIONLESS,
    WALL_GLUED,
)
from parsim.core.shapes.rotations import DrawnRotations


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
                       substrate_positions=None, substrate_radii=None, first_particle=0, keep_drawn_rotations=False,
                       faces=None):
    """The arguments of :func:`deposit` validated (a ValueError names the first bad one) as a
    :class:`PreparedDeposition`; ``first_particle`` is the first particle's place in the drop order
    when these are a chunk of a longer run (the errors name particles by it).  With
    ``keep_drawn_rotations``, ``particle_rotation`` given as :class:`~parsim.core.shapes.rotations.DrawnRotations`
    (unit quaternions by construction) stays one, its rows computed only when taken.

    Why so many parameters: it takes :func:`.api.deposit`'s arguments, which it checks.
    """

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

    _check_shapes(offsets, radii, start)
    n_shapes = start.shape[0] - 1
    P = pshape.shape[0]
    _check_particles(pshape, pscale, prot, pxy, n_shapes, drawn)
    _check_modes(lateral, floor, wall_contact, trial_angle, cycle_n, cycle_eps, max_events_per_particle)

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

    sub_pos, sub_rad, polygon, n_sides, lo, hi = _container(lo, hi, lateral, r_max, ext_max, (container, cylinder, faces),
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


def _check_shapes(offsets, radii, start):
    """A ValueError naming the first bad array of the shapes' spheres."""
    if offsets.ndim != 2 or offsets.shape[1] != 3:
        raise ValueError(f"shape_offsets must have shape (k, 3), got {offsets.shape}")
    if radii.shape != (offsets.shape[0],):
        raise ValueError(f"shape_radii must have shape ({offsets.shape[0]},), got {radii.shape}")
    if not (np.all(np.isfinite(offsets)) and np.all(np.isfinite(radii)) and np.all(radii > 0)):
        raise ValueError("shape_offsets must be finite and shape_radii finite and > 0")
    if start.ndim != 1 or start.shape[0] < 2 or start[0] != 0 or start[-1] != offsets.shape[0] \
            or np.any(np.diff(start) <= 0):
        raise ValueError("shape_start must increase strictly from 0 to len(shape_radii)")


def _check_particles(pshape, pscale, prot, pxy, n_shapes, drawn):
    """A ValueError naming the first bad array of the particles (``drawn``: rotations drawn as unit quaternions)."""
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


def _check_modes(lateral, floor, wall_contact, trial_angle, cycle_n, cycle_eps, max_events_per_particle):
    """A ValueError naming the first bad mode or setting of the run."""
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


def check_container(box_lower_xy, box_upper_xy, lateral, largest_radius, largest_extent, length_scale,
                    container=CONTAINER_BOX, cylinder=None, substrate_positions=None, substrate_radii=None, faces=None):
    """Raise the ValueError :func:`deposit` would raise for this container and substrate, for particles
    whose spheres have radii up to ``largest_radius`` and reach ``largest_extent`` from their centre
    of mass, and whose mean sphere radius at scale 1 is ``length_scale``: for checking a task before
    it runs."""
    lo = np.asarray(box_lower_xy, dtype=np.float64)
    hi = np.asarray(box_upper_xy, dtype=np.float64)
    _container(lo, hi, lateral, float(largest_radius), float(largest_extent), (container, cylinder, faces),
               substrate_positions, substrate_radii, 1e-9 * length_scale)


def _container(lo, hi, lateral, r_max, ext_max, walls, substrate_positions, substrate_radii, tol):
    """The substrate (centres, radii), the container's geometry after the grid's (the cylinder's
    polygon or the mesh vessel's faces; None for the box), the polygon's sides (0 but for the
    cylinder) and the lateral box, validated for ``walls = (container, cylinder, faces)``: a box of positive size, a periodic side wider than twice the largest
    extent and four times the largest sphere radius (minimum images unambiguous), walls that hold
    the largest sphere, a substrate inside the walls."""
    if lateral != LATERAL_NONE:
        if lo.shape != (2,) or hi.shape != (2,) or not np.all(np.isfinite(lo)) or not np.all(np.isfinite(hi)):
            raise ValueError("box_lower_xy and box_upper_xy must be finite pairs (x, y)")
        if np.any(hi <= lo):
            raise ValueError("box_upper_xy must exceed box_lower_xy in x and y")
    sub_pos, sub_rad = _substrate(substrate_positions, substrate_radii)
    r_contact = max(r_max, float(np.max(sub_rad)) if len(sub_rad) else 0.0)
    container, cylinder, faces = walls
    if container == CONTAINER_MESH or faces is not None:
        polygon, n_sides = _mesh_faces(container, faces, lateral, cylinder), 0
    else:
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


def _mesh_faces(container, faces, lateral, cylinder):
    """The faces of a mesh vessel as the grid's container geometry (:func:`.faces.face_geometry`),
    validated."""
    from parsim.core.sdbd.faces import face_geometry

    if container != CONTAINER_MESH:
        raise ValueError("faces are given but container is not CONTAINER_MESH")
    if cylinder is not None:
        raise ValueError("cylinder is given but container is CONTAINER_MESH")
    if lateral != LATERAL_WALLS:
        raise ValueError(f"a mesh vessel needs lateral = LATERAL_WALLS (1), got {lateral}")
    if faces is None or len(faces) != 3:
        raise ValueError("CONTAINER_MESH needs faces = (normals, levels, boxes)")
    normals, levels, boxes = (np.asarray(a, dtype=np.float64) for a in faces)
    n = len(levels)
    if normals.shape != (n, 3) or levels.shape != (n,) or boxes.shape != (n, 6):
        raise ValueError(f"faces must be normals (F, 3), levels (F,) and boxes (F, 6), got {normals.shape}, "
                         f"{levels.shape} and {boxes.shape}")
    if not (np.all(np.isfinite(normals)) and np.all(np.isfinite(levels)) and not np.any(np.isnan(boxes))):
        raise ValueError("face normals and levels must be finite and boxes not NaN")
    if np.any(np.abs(np.linalg.norm(normals, axis=1) - 1.0) > 1e-12) or np.any(normals[:, 2] < 0.0):
        raise ValueError("face normals must be unit vectors with N_z >= 0 (the vessel has no overhang)")
    if np.any(boxes[:, 1::2] < boxes[:, 0::2]):
        raise ValueError("face boxes must be x0 <= x1, y0 <= y1, z0 <= z1")
    return face_geometry(normals, levels, boxes)


def _cylinder(container, cylinder, lateral, lo, hi, r_max):
    """The polygon of a cylindrical container (:func:`.polygon.polygon_geometry`), its number
    of sides and the box (the square about the cylinder), validated against the other
    arguments; ``(None, 0, lo, hi)`` for the box."""
    from parsim.core.sdbd.polygon import polygon_geometry

    if container not in (CONTAINER_BOX, CONTAINER_CYLINDER):
        raise ValueError(f"container must be CONTAINER_BOX (0), CONTAINER_CYLINDER (1) or CONTAINER_MESH (2), "
                         f"got {container}")
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
            if n_sides > 0:
                out = _outside_polygon(xy.reshape(-1, 2), reach.ravel(), polygon, n_sides, tol).reshape(reach.shape)
            else:
                out = (xy - reach[..., None] < lo - tol) | (xy + reach[..., None] > hi + tol)
                if polygon is not None:
                    out = np.any(out, axis=-1) | _outside_vertical_faces(xy, reach, polygon, tol)
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


def _outside_vertical_faces(xy, r, faces, tol):
    """Which spheres (centres ``xy`` (..., 2), radii ``r`` (...)) cross a vertical face of a mesh
    vessel (:mod:`.faces`) by more than ``tol``."""
    from parsim.core.sdbd.faces import FACE_WIDTH

    table = faces.reshape(-1, FACE_WIDTH)
    vertical = table[table[:, 2] == 0.0]
    gap = xy[..., None, 0] * vertical[:, 0] + xy[..., None, 1] * vertical[:, 1] - vertical[:, 3] - r[..., None]
    return np.any(gap < -tol, axis=-1)


def _outside_faces(pos, r, faces, tol):
    """Which spheres (centres ``pos`` (k, 3), radii ``r``) cross a face of a mesh vessel by more than
    ``tol``."""
    from parsim.core.sdbd.faces import FACE_WIDTH

    table = faces.reshape(-1, FACE_WIDTH)
    return np.any(pos @ table[:, :3].T - table[:, 3] - r[:, None] < -tol, axis=1)


def _check_substrate_inside(pos, rad, lo, hi, polygon, n_sides, tol):
    """Every substrate sphere lies inside the walls (the box or the cylinder's polygon, and a mesh
    vessel's faces)."""
    if len(rad) == 0:
        return
    if n_sides > 0:
        outside = _outside_polygon(pos[:, :2], rad, polygon, n_sides, tol)
    else:
        outside = np.any((pos[:, :2] - rad[:, None] < lo - tol) | (pos[:, :2] + rad[:, None] > hi + tol), axis=1)
        if polygon is not None:
            outside |= _outside_faces(pos, rad, polygon, tol)
    if np.any(outside):
        j = int(np.argmax(outside))
        raise ValueError(f"substrate sphere {j}: centre {tuple(pos[j])}, radius {rad[j]}: it does not lie "
                         f"inside the walls")
