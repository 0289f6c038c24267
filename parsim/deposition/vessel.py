"""Vessels read from surface mesh files (STL, OBJ, or another format trimesh reads).

A vessel is an open-topped container whose inside is convex: a hopper, a V-trough, a bowl, a
box, a prism, an inclined-plane wedge.  Its mesh is a surface closed everywhere except at its
opening, a single loop of boundary edges at the mesh's highest level (the rim).  The vessel
closed at its rim is a convex polytope, the intersection of the half-spaces behind its planar
faces; the kernel (:mod:`parsim.core.sdbd.faces`) takes it as the walled box of the bounding
box (walls at ``x = 0, Lx`` and ``y = 0, Ly``), the floor ``z = 0``, and the other faces as
planes ``N . x = c`` with inward unit normals ``N`` (``N_z >= 0``) and bounding boxes.

Physics assumption: as the inside is convex, a sphere inside meets a face only in the face's
interior, never at an edge or a vertex (those are valleys, reached only as contacts with two or
three faces at once).  Above the rim the vessel goes on as the planes of its faces, within the box's
walls, so that a pile that overflows the rim still lies in a convex container (a hopper's funnel
widens on; a prism's sides rise on).

:func:`read_vessel` reads a file: the mesh (duplicate vertices merged) is moved so that its
bounding box starts at (0, 0, 0), in the file's length units, and checked.  A refused file
raises :class:`parsim.errors.JobError` with one line starting with the job key, for: a missing
or unreadable file; triangles of zero area; a closed mesh (no opening); boundary edges below
the rim (a hole), edges shared by more than two triangles, or an opening of several loops; a
vessel that is not convex; an overhang (a face whose inward normal points down).

Coplanar triangles, adjacent or not, are merged into planar faces.  Each triangle's normal is
turned towards the centroid of the mesh's vertices: a weighted mean of all vertices of a convex
polytope with positive weights lies strictly inside it, whatever the winding of the file.  For
a mesh that is not convex that point may lie outside, but then some vertex lies outside some
face plane and the convexity check refuses it (a mesh passing it has every face plane
supporting all its vertices: it is convex).  A face lying in ``z = 0`` is the floor and one lying
in a side of the bounding box is that wall: both are dropped, the kernel has them; the others
are the kernel's faces, with ``N_z`` set to exactly 0 on vertical faces.

Tolerance: points and planes agree within ``tolerance``, 1e-9 of the bounding-box diagonal, or, when
larger, eight times the rounding of the file's numbers at its largest coordinate: half a float32
unit when all are float32 numbers (binary STL), else half a unit in the last digit of the longest
number (a text file written with 7 significant digits is rounded to 5e-7 of its numbers; numbers
with fewer digits are taken as rounded to 1e-6).
"""

from dataclasses import dataclass
from decimal import Decimal
from pathlib import Path

import numpy as np

from parsim.deposition.inside import ConvexInside
from parsim.errors import JobError

__all__ = ["Vessel", "read_vessel", "vessel_from_mesh", "hopper_mesh", "bowl_mesh", "v_trough_mesh", "box_mesh",
           "wedge_mesh", "prism_mesh"]

PLANE_RTOL = 1e-9  # planes agree within this times the bounding-box diagonal
FILE_ROUNDINGS = 8.0  # ... or within this many roundings of the file's largest coordinate
MAX_RELATIVE_ROUNDING = 1e-6  # the rounding assumed at most: 7 significant digits (float32: 6e-8)
ZERO_AREA_RTOL = 1e-12  # a triangle with less area than this times the diagonal squared is degenerate


@dataclass(frozen=True, eq=False)
class Vessel:
    """A checked vessel, translated so that its bounding box runs from (0, 0, 0) to ``upper``.

    ``normals`` (F, 3), ``levels`` (F,), ``boxes`` (F, 6) (``x0, x1, y0, y1, z0, z1``) are the
    kernel's faces (inward unit normals, the face in ``N . x = c``); ``opening`` (K, 2) is the rim
    polygon, counter-clockwise, at height ``upper[2]``; ``volume`` the volume closed at the rim;
    ``vertices`` the translated mesh vertices; ``tolerance`` the plane tolerance used; its inside,
    continued above the rim, is :meth:`convex_inside`."""

    path: str
    upper: np.ndarray
    normals: np.ndarray
    levels: np.ndarray
    boxes: np.ndarray
    opening: np.ndarray
    volume: float
    vertices: np.ndarray
    tolerance: float
    interior: ConvexInside = None  # the inside as a polytope, continued above the rim

    def faces(self):
        """The kernel's ``(normals, levels, boxes)`` as float64 arrays.  Above the rim the vessel goes
        on as its faces' planes within the box's walls, so each box bounds where its plane can be met:
        from the face's lowest point up without end, over the face's own footprint for a vertical face
        and over the whole box for an inclined one (its plane leans outwards above the rim)."""
        boxes = np.array(self.boxes, dtype=np.float64)
        boxes[:, 5] = np.inf
        inclined = self.normals[:, 2] != 0.0
        boxes[inclined, 0] = boxes[inclined, 2] = 0.0
        boxes[inclined, 1] = self.upper[0]
        boxes[inclined, 3] = self.upper[1]
        return np.array(self.normals, dtype=np.float64), np.array(self.levels, dtype=np.float64), boxes

    def area_at(self, z):
        """Area of the section of the vessel at height ``z`` (0 below the floor and above the rim)."""
        return self.interior.area_at(z) if z <= self.upper[2] else 0.0

    def volume_below(self, z):
        """Volume of the inside below height ``z`` (the whole ``volume`` from the rim up): exact,
        Simpson's rule between vertex heights, where the section area is quadratic."""
        return self.interior.volume_between(0.0, min(float(z), float(self.upper[2])))

    def inside(self, points, radii):
        """Whether each sphere (centres ``points`` (k, 3), ``radii`` (k,)) lies inside the vessel:
        behind every face by its radius, within the box's walls and above the floor."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        radii = np.broadcast_to(np.asarray(radii, dtype=np.float64), (len(points),))
        return self.interior.contains(points, radii) & (points[:, 2] >= radii)

    def opening_centroid(self) -> np.ndarray:
        """The centroid (x, y) of the opening's area (the rim polygon's)."""
        x, y = self.opening[:, 0], self.opening[:, 1]
        following_x, following_y = np.roll(x, -1), np.roll(y, -1)
        cross = x * following_y - following_x * y
        moments = np.array([np.sum((x + following_x) * cross), np.sum((y + following_y) * cross)])
        return moments / (3.0 * np.sum(cross))

    def convex_inside(self) -> ConvexInside:
        """The inside continued above the rim, as the kernel takes it: the box's walls, the floor and
        the faces' planes (:class:`parsim.deposition.inside.ConvexInside`)."""
        return self.interior

    def inside_opening(self, xy, margin=0.0):
        """Whether each point ``xy`` (k, 2) lies inside the opening shrunk by ``margin`` (scalar or
        (k,)): inside the rim polygon and at least ``margin`` from each of its edges."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        start, end = self.opening, np.roll(self.opening, -1, axis=0)
        x, y = xy[:, :1], xy[:, 1:]
        crosses = (start[:, 1] > y) != (end[:, 1] > y)  # even-odd rule, ray towards +x
        with np.errstate(divide="ignore", invalid="ignore"):
            at = start[:, 0] + (y - start[:, 1]) * (end[:, 0] - start[:, 0]) / (end[:, 1] - start[:, 1])
        within = np.count_nonzero(crosses & (x < at), axis=1) % 2 == 1
        return within & (_distance_to_edges(xy, start, end) >= margin)


def _distance_to_edges(xy, start, end):
    """Distance of each point (k, 2) to the nearest of the segments ``start -> end`` (K, 2)."""
    edge = end - start
    t = np.clip(np.einsum("kmj,mj->km", xy[:, None, :] - start, edge) / np.sum(edge**2, axis=1), 0.0, 1.0)
    foot = start + t[:, :, None] * edge
    return np.min(np.linalg.norm(xy[:, None, :] - foot, axis=2), axis=1)


class _Refusal(Exception):
    """What is wrong with a mesh (the message without the key), raised by the checks below."""


def read_vessel(path, key="container_file") -> Vessel:
    """The checked vessel in the mesh file ``path``; a refused file raises JobError naming ``key``."""
    import trimesh  # here, not at the top: only mesh vessels need it

    if not Path(path).is_file():
        raise JobError(f"{key}: file not found: {path} (give an STL or OBJ file of the vessel)")
    try:
        mesh = trimesh.load(path, force="mesh", process=True)
    except Exception as exc:  # trimesh's readers raise many exception types
        raise JobError(f"{key}: {path} cannot be read as a triangle mesh ({exc}); give an STL or OBJ file") from exc
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise JobError(f"{key}: no triangles found in {path}; give an STL or OBJ file of the vessel")
    return vessel_from_mesh(mesh, path, key)


def vessel_from_mesh(mesh, path="<mesh>", key="container_file") -> Vessel:
    """The checked vessel of a trimesh mesh (its vertices merged); ``path`` and ``key`` name it in errors."""
    original = np.asarray(mesh.vertices, dtype=np.float64)
    triangles = np.asarray(mesh.faces, dtype=np.int64)
    used = np.unique(triangles)
    vertices = original - original[used].min(axis=0)
    upper = vertices[used].max(axis=0)
    tol = _tolerance(original[used], float(np.linalg.norm(upper)))
    try:
        if np.any(upper <= tol):
            raise _Refusal(f"the mesh is flat (extents {upper.tolist()}); a vessel encloses a volume")
        _check_triangles(vertices, triangles, float(np.dot(upper, upper)))
        opening = _opening(vertices, triangles, upper[2], tol)
        faces = _planar_faces(vertices, triangles, tol)
        _check_convex(vertices, used, faces, tol)
    except _Refusal as refusal:
        raise JobError(f"{key}: {refusal} ({path})") from None
    kernel = [face for face in faces if not _in_box_side(vertices[face[2]], face[0], upper, tol)]
    normals = np.array([face[0] for face in kernel], dtype=np.float64).reshape(-1, 3)
    levels = np.array([face[1] for face in kernel], dtype=np.float64)
    boxes = np.array([_box(vertices[face[2]]) for face in kernel], dtype=np.float64).reshape(-1, 6)
    inside = ConvexInside(normals, levels, np.zeros(2), np.array(upper[:2], dtype=np.float64))
    return Vessel(str(path), upper, normals, levels, boxes, opening, inside.volume_between(0.0, upper[2]),
                  vertices[used], tol, inside)


def _tolerance(coordinates, diagonal):
    """Plane tolerance: PLANE_RTOL of the diagonal, or FILE_ROUNDINGS times the rounding of the file's
    coordinates when larger (:func:`_relative_rounding` of the largest coordinate)."""
    values = np.unique(np.abs(coordinates))
    return max(PLANE_RTOL * diagonal, FILE_ROUNDINGS * _relative_rounding(values) * float(values[-1]))


def _relative_rounding(values):
    """Relative rounding of the written numbers ``values`` (positive, sorted): half a float32 unit when they are
    all float32 numbers (binary STL), else half a unit in the last of the most significant digits any of
    them shows (a text file's precision), at most MAX_RELATIVE_ROUNDING (a file of short, exact numbers)."""
    values = values[values > 0.0]
    as32 = values.astype(np.float32).astype(np.float64)
    if np.all(np.abs(as32 - values) <= 4.0 * np.finfo(np.float64).eps * values):
        return 0.5 * float(np.finfo(np.float32).eps)
    digits = max(len(Decimal(repr(float(x))).normalize().as_tuple().digits) for x in values)
    return min(0.5 * 10.0 ** (1 - digits), MAX_RELATIVE_ROUNDING)


def _box(points):
    """Bounding box ``x0, x1, y0, y1, z0, z1`` of the points (m, 3)."""
    low, high = points.min(axis=0), points.max(axis=0)
    return np.column_stack([low, high]).ravel()


def _check_triangles(vertices, triangles, diagonal_squared):
    """Refuse triangles of zero area."""
    corners = vertices[triangles]
    areas = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    degenerate = np.flatnonzero(areas <= ZERO_AREA_RTOL * diagonal_squared)
    if len(degenerate):
        raise _Refusal(f"{len(degenerate)} triangles of zero area (the first is triangle {degenerate[0]}); "
                       "every triangle of the mesh must have an area")


def _opening(vertices, triangles, top, tol):
    """The rim polygon (K, 2), counter-clockwise; refuses a closed mesh, holes, non-manifold edges and several rims."""
    edges = np.sort(triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    if np.any(counts > 2):
        raise _Refusal(f"{np.count_nonzero(counts > 2)} edges are shared by more than two triangles; "
                       "a vessel's surface joins its triangles two by two along each edge")
    boundary = unique[counts == 1]
    if len(boundary) == 0:
        raise _Refusal("the mesh is closed (watertight): the vessel has no opening; "
                       "a vessel needs an open top (leave out the lid)")
    below = np.count_nonzero(np.any(vertices[boundary, 2] < top - tol, axis=1))
    if below:
        raise _Refusal(f"the mesh has {below} boundary edges below its rim (holes in the surface); "
                       "a vessel must be closed except for its opening at the top")
    loops = _loops(boundary)
    if len(loops) != 1:
        raise _Refusal(f"the opening is made of {len(loops)} separate loops of edges; a vessel has one opening")
    polygon = vertices[loops[0], :2]
    x, y = polygon[:, 0], polygon[:, 1]
    if np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)) < 0.0:
        polygon = polygon[::-1]
    return np.ascontiguousarray(polygon)


def _loops(edges):
    """The boundary edges chained into loops of vertex indices; refuses a vertex on more than two of them."""
    neighbours = {}
    for a, b in edges:
        neighbours.setdefault(int(a), []).append(int(b))
        neighbours.setdefault(int(b), []).append(int(a))
    if any(len(others) != 2 for others in neighbours.values()):
        raise _Refusal("the rim touches itself (a vertex on more than two boundary edges); "
                       "a vessel has one opening bounded by a simple loop")
    loops, seen = [], set()
    for start in neighbours:
        if start in seen:
            continue
        loop, previous, current = [start], None, start
        seen.add(start)
        while True:
            a, b = neighbours[current]
            following = b if a == previous else a
            if following == start:
                break
            loop.append(following)
            seen.add(following)
            previous, current = current, following
        loops.append(loop)
    return loops


def _planar_faces(vertices, triangles, tol):
    """Coplanar triangles merged into faces ``(inward unit normal, level, vertex indices)``.

    Each triangle's normal is turned towards the vertex centroid (inside a convex vessel); the
    largest unassigned triangle defines a plane and takes every triangle with all three corners
    within ``tol`` of it and a normal on the same side; the face's normal is then the
    area-weighted mean of its triangles', made vertical when that moves none of its vertices by
    more than ``tol``, and its level the mean of ``N . v`` over its vertices."""
    corners = vertices[triangles]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    units = cross / np.linalg.norm(cross, axis=1)[:, None]
    centre = vertices[np.unique(triangles)].mean(axis=0)
    side = np.einsum("tj,tj->t", units, centre - corners[:, 0])
    units = np.where(side[:, None] < 0.0, -units, units)
    unassigned = np.ones(len(triangles), dtype=bool)
    faces = []
    for seed in np.argsort(-np.linalg.norm(cross, axis=1)):
        if not unassigned[seed]:
            continue
        normal, level = units[seed], float(units[seed] @ corners[seed, 0])
        candidates = np.flatnonzero(unassigned)
        close = np.all(np.abs(corners[candidates] @ normal - level) <= tol, axis=1) & (units[candidates] @ normal > 0.0)
        members = np.zeros(len(triangles), dtype=bool)
        members[candidates[close]] = True
        members[seed] = True
        unassigned &= ~members
        faces.append(_fit_face(vertices, triangles[members], cross[members], units[members], tol))
    return faces


def _fit_face(vertices, triangles, cross, units, tol):
    """``(normal, level, vertex indices)`` of the coplanar triangles (their inward unit normals ``units``)."""
    areas = np.linalg.norm(cross, axis=1)
    normal = np.sum(units * areas[:, None], axis=0)
    normal /= np.linalg.norm(normal)
    indices = np.unique(triangles)
    points = vertices[indices]
    if normal[2] != 0.0 and np.hypot(normal[0], normal[1]) > 0.0:
        flat = np.array([normal[0], normal[1], 0.0]) / np.hypot(normal[0], normal[1])
        projected = points @ flat
        if np.max(np.abs(projected - projected.mean())) <= tol:  # a vertical face: exactly vertical
            normal = flat
    return normal, float(np.mean(points @ normal)), indices


def _check_convex(vertices, used, faces, tol):
    """Refuse a vertex (of those ``used`` by triangles) outside a face's plane, then a face whose inward
    normal points down."""
    for k, (normal, level, _) in enumerate(faces):
        outside = level - vertices[used] @ normal
        worst = int(np.argmax(outside))
        if outside[worst] > tol:
            raise _Refusal(f"the vessel is not convex (vertex {used[worst]} lies {outside[worst]:.6g} outside "
                           f"the plane of face {k}, normal {np.round(normal, 6).tolist()}); parsim takes vessels whose "
                           "inside is convex")
    for k, (normal, _, _) in enumerate(faces):
        if normal[2] < -1e-12:
            raise _Refusal(f"face {k} overhangs (its inward normal {np.round(normal, 6).tolist()} points down); "
                           "a vessel's faces must look up or sideways (no part wider below than above)")


def _in_box_side(points, normal, upper, tol):
    """Is the face with these vertices the floor (in z = 0) or a wall of the box (in x = 0, Lx, y = 0, Ly)?"""
    if normal[2] > 0.0 and np.all(np.abs(points[:, 2]) <= tol):
        return True
    for axis in (0, 1):
        if normal[axis] > 0.0 and np.all(np.abs(points[:, axis]) <= tol):
            return True
        if normal[axis] < 0.0 and np.all(np.abs(points[:, axis] - upper[axis]) <= tol):
            return True
    return False


# Builders of vessel meshes, for tests and job files.  Each returns an open-topped trimesh.Trimesh
# wound with outward normals (away from the inside).

def _mesh_of_polygons(polygons):
    """The mesh of convex planar polygons (lists of 3-D points), fan-triangulated, points merged."""
    import trimesh

    points, triangles = [], []
    for polygon in polygons:
        ring = [p for i, p in enumerate(polygon) if not np.array_equal(p, polygon[i - 1])]
        base = len(points)
        points.extend(ring)
        triangles.extend([base, base + i, base + i + 1] for i in range(1, len(ring) - 1))
    mesh = trimesh.Trimesh(np.array(points, dtype=np.float64), np.array(triangles), process=True)
    faces = np.array(mesh.faces)
    corners = mesh.vertices[faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    inward = np.einsum("tj,tj->t", normals, mesh.vertices.mean(axis=0) - corners[:, 0]) > 0.0
    faces[inward] = faces[inward][:, ::-1]
    return trimesh.Trimesh(mesh.vertices, faces, process=False)


def _ring(radius, sides, z, centre):
    """Vertices of the regular polygon whose side k faces the direction 2 pi k / n (vertices at 2 pi (k + 1/2) / n)."""
    angles = 2.0 * np.pi * (np.arange(sides) + 0.5) / sides
    return [np.array([centre + radius * np.cos(a), centre + radius * np.sin(a), z]) for a in angles]


def hopper_mesh(top_radius, bottom_radius, height, sides, rim=None):
    """An open-topped frustum of a regular ``sides``-gon (radii to the vertices; ``bottom_radius`` 0 is a
    pyramid's apex), flat bottom at z = 0, top at ``height``, with a vertical collar of height ``rim``
    above it when given.  Side k faces the direction 2 pi k / sides; the axis is at x = y = the larger radius."""
    if sides < 3 or height <= 0.0 or top_radius <= 0.0 or bottom_radius < 0.0 or (rim is not None and rim < 0.0):
        raise ValueError("hopper_mesh: sides >= 3, height > 0, top_radius > 0, bottom_radius >= 0, rim >= 0")
    radii, heights = [bottom_radius, top_radius], [0.0, height]
    if rim:
        radii, heights = radii + [top_radius], heights + [height + rim]
    return _rings_mesh(radii, heights, sides)


def bowl_mesh(radius, depth, sides, rings, bottom=0.1):
    """A polyhedral spherical bowl: the cap of depth ``depth`` <= ``radius`` of the sphere of ``radius``, its
    ``rings`` + 1 regular ``sides``-gons inscribed at polar angles from that of a flat bottom of radius
    ``bottom`` x ``radius`` up to the rim, so that it is convex with no overhang."""
    if sides < 3 or rings < 1 or not 0.0 < depth <= radius or not 0.0 < bottom < 1.0:
        raise ValueError("bowl_mesh: sides >= 3, rings >= 1, 0 < depth <= radius, 0 < bottom < 1")
    first, last = np.arcsin(bottom), np.arccos(1.0 - depth / radius)
    if last <= first:
        raise ValueError("bowl_mesh: the bottom must be narrower than the rim")
    angles = np.linspace(first, last, rings + 1)
    heights = radius * (np.cos(first) - np.cos(angles))
    return _rings_mesh(list(radius * np.sin(angles)), list(heights), sides)


def _rings_mesh(radii, heights, sides):
    """Regular ``sides``-gons of ``radii`` at ``heights`` (the first at 0: the bottom, or an apex for radius 0)
    joined by their sides; the axis at x = y = the largest radius."""
    centre = max(radii)
    rings = [_ring(r, sides, z, centre) if r > 0.0 else [np.array([centre, centre, z])] * sides
             for r, z in zip(radii, heights)]
    polygons = [rings[0]] if radii[0] > 0.0 else []
    for low, high in zip(rings[:-1], rings[1:]):
        polygons += [[low[k], low[k - 1], high[k - 1], high[k]] for k in range(sides)]
    return _mesh_of_polygons(polygons)


def prism_mesh(radius, height, sides):
    """An open-topped regular ``sides``-gon prism with a flat bottom, like parsim's cylinder polygon: side k has
    outward normal (cos 2 pi k / n, sin 2 pi k / n), vertices at radius ``radius``, axis at x = y = radius."""
    return hopper_mesh(radius, radius, height, sides)


def v_trough_mesh(length, width, depth):
    """A V-shaped trough along y: its two slopes meet in the line x = width / 2, z = 0 and rise to x = 0 and
    x = width at z = depth; vertical triangular ends at y = 0 and y = length; open top."""
    bottom = [np.array([width / 2.0, y, 0.0]) for y in (0.0, length)]
    left = [np.array([0.0, y, depth]) for y in (0.0, length)]
    right = [np.array([width, y, depth]) for y in (0.0, length)]
    return _mesh_of_polygons([[bottom[0], bottom[1], left[1], left[0]], [bottom[0], bottom[1], right[1], right[0]],
                              [left[0], bottom[0], right[0]], [left[1], bottom[1], right[1]]])


def box_mesh(lx, ly, lz):
    """An open-topped box [0, lx] x [0, ly] x [0, lz]: its bottom and four sides."""
    corners = [np.array([x, y, z]) for z in (0.0, lz) for y in (0.0, ly) for x in (0.0, lx)]
    low, high = [corners[i] for i in (0, 1, 3, 2)], [corners[i] for i in (4, 5, 7, 6)]
    return _mesh_of_polygons([low] + [[low[k - 1], low[k], high[k], high[k - 1]] for k in range(4)])


def wedge_mesh(lx, ly, lz, angle, start=0.0):
    """An inclined plane in an open-topped box [0, lx] x [0, ly] x [0, lz]: the floor z = 0 up to x = ``start``,
    then a plane rising along x at ``angle`` degrees to (lx - start) tan(angle) < lz at x = lx."""
    rise = (lx - start) * np.tan(np.radians(angle))
    if not (0.0 < angle < 90.0 and 0.0 <= start < lx and rise < lz):
        raise ValueError("wedge_mesh: 0 < angle < 90, 0 <= start < lx, and the slope must end below lz")
    profile = [(0.0, 0.0), (start, 0.0), (lx, rise), (lx, lz), (0.0, lz)]  # (x, z) of the side at y = 0
    near = [np.array([x, 0.0, z]) for x, z in profile]
    far = [np.array([x, ly, z]) for x, z in profile]
    polygons = [near, far[::-1]] + [[near[k], near[k + 1], far[k + 1], far[k]] for k in range(3)]
    polygons.append([near[4], near[0], far[0], far[4]])
    return _mesh_of_polygons(polygons)
