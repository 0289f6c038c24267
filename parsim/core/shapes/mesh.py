"""Particles from closed triangle surface meshes (STL, OBJ) as unions of medial balls.

:func:`mesh_particle` takes a closed, consistently oriented triangle mesh (a
:class:`ClosedMesh`, read from STL or OBJ by :mod:`parsim.deposition.mesh_file`), possibly
non-convex, and approximates the solid it bounds by overlapping polydisperse spheres,
each a *medial ball*: a ball inside the solid tangent to its surface.

1. Cover samples: points on the surface, area-weighted and deterministic (the stratified
   sequence (i + 1/2) / m shared out to the faces by area, spread inside each face by
   the golden-ratio sequence), each with the inward unit normal of its face.
2. Candidates: the medial ball at every cover sample s with inward normal n, the largest
   ball B(s + rho n, rho) whose interior holds no surface point (it then lies inside the
   solid), found by the shrinking-ball method of Ma, Bae, Choi, Hu & Prasad ("3D medial
   axis point approximation using nearest neighbors and the normal field", The Visual
   Computer 28, 2012) with exact point-to-triangle distances (Ericson, "Real-Time
   Collision Detection", 2005, section 5.1.5) in place of nearest sample points: a
   trial ball whose centre is closer than rho to some surface point q is shrunk to the
   ball tangent at s through q.  A ball may protrude from the surface by at most
   ``INSIDE_RTOL`` times the diagonal of the mesh's bounding box.
3. Greedy cover: a sample s is covered when its inward normal line s + t n (t >= 0)
   enters the union of the chosen balls at a depth t <= delta.  This depth bounds the
   distance from s to the union from above, and it also sees the creases between balls
   below the surface (a union point u at distance d from the surface lies on the normal
   line of its nearest surface point, at depth d), which the distance to the union does
   not.  Repeatedly add the candidate covering the most uncovered samples (ties: the
   largest ball) until every sample is covered; then halve delta and go on.  delta
   starts at ``COARSEST_COVER`` r_eq (coarser for fewer than 20 balls), so the first
   balls are the big ones that cover large parts of the surface, the later ones fill
   the cusps between them (as the cusp depths drive the cover of
   :func:`parsim.core.shapes.superellipsoid`).

Error measures (:class:`MeshFit`), with r_eq the radius of the sphere of the mesh's
volume (the *volume-equivalent radius*):

- ``volume_error``: (V_union - V_mesh) / V_mesh, V_union from
  :func:`centre_of_mass_of_union` (its measured accuracy there).  The balls lie inside
  the mesh, so it is negative up to that accuracy.
- ``mesh_to_union``: the largest distance to the union from the mesh's vertices and
  ``EVALUATION_FACTOR`` times as many area samples as there are cover samples (another
  sequence than theirs).
- ``union_to_mesh``: the largest distance to the mesh surface (exact, over all
  triangles) of samples of the union's surface: ``UNION_POINTS_PER_BALL`` Fibonacci
  points on each ball's sphere and ``POINTS_PER_CREASE`` points on each circle where
  two spheres meet, those that lie in no other ball.  The creases matter: there the
  union's surface is farthest from the mesh (sphere points alone measured up to 25 %
  less on the ellipsoid of the tests).
- ``surface_distance``: the larger of the two, a sampled two-sided Hausdorff distance
  between the surfaces (between the samples it can be slightly larger);
  ``relative_surface_distance = surface_distance / r_eq``.

Stopping.  ``n_spheres``: after that many balls (fewer if every sample is covered at
delta = ``FINEST_COVER`` r_eq).  ``tolerance``: the cover runs down to delta =
tolerance r_eq (a proxy: every cover sample within that depth of the union); then, while
the measured ``surface_distance`` exceeds tolerance r_eq, the failing points are added
and the cover goes on at that delta (at most ``MAX_REFINEMENTS`` rounds).  A failing
mesh point becomes a cover sample; a failing mesh vertex becomes a sample to cover
(with the mean normal of its faces), with candidates on its faces close to it (balls
shrink to nothing at a convex vertex); a point u of the union's surface at distance d
from the mesh brings the medial ball at its nearest surface point q with normal
(u - q) / d, which is added to the union: it contains u, its radius being at least d
(B(u, d) is inside and tangent at q).  :class:`MeshFit` reports the measured values,
so a caller can check the tolerance.

Cost: distances are brute force over the triangles (skipping those whose bounding
sphere is farther than the best so far), and the coverage lists brute force over the
samples in an x-slab: fine for meshes of a few thousand faces and a few thousand spheres.
"""

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from parsim.core.jit import jit
from parsim.core.shapes.checks import _check_int, _check_positive
from parsim.core.shapes.medial_balls import _heap_pop, _heap_push
from parsim.core.shapes.smooth import _fibonacci_sphere
from parsim.core.shapes.union import centre_of_mass_of_union

# A ball may protrude from the mesh surface by at most this times the bounding-box
# diagonal (the inside test of the shrinking ball): far above the round-off of the
# distances (a few ulp of the diagonal), far below any effect on the particle.
INSIDE_RTOL = 1e-10
# The shrinking-ball search stops when the bracket of the medial radius is narrower than
# this times the bounding-box diagonal.
MEDIAL_RTOL = 1e-7
# Coverage depth delta of the greedy cover, in units of r_eq: the first level (in
# n_spheres mode max(COARSEST_COVER, 1 / n_spheres): measured on an ellipsoid, a box and a
# torus, a coarser start gives more volume to 5 or 10 balls, a finer one to 20 and more),
# and the last one in n_spheres mode.
COARSEST_COVER = 0.05
FINEST_COVER = 1e-5
# Default number of cover samples: per requested sphere with a floor (n_spheres mode), or
# fixed (tolerance mode, where the refinement adds samples where they are needed).
SAMPLES_PER_SPHERE = 8
MIN_SAMPLES = 2048
TOLERANCE_SAMPLES = 4096
# Evaluation of the surface distance: mesh samples per cover sample, points per ball.
EVALUATION_FACTOR = 4
UNION_POINTS_PER_BALL = 128
POINTS_PER_CREASE = 32
MAX_REFINEMENTS = 6
# Faces with area below this times the squared diagonal are left out of the distance
# computations (in a closed mesh their points lie on the edges of other faces).
DEGENERATE_AREA_RTOL = 1e-14
GOLDEN_FRACTION = (math.sqrt(5.0) - 1.0) / 2.0


@dataclass(frozen=True)
class MeshFit:
    """How well the union of the balls approximates the mesh (definitions in the module
    docstring); lengths in the mesh's units, ``equivalent_radius`` = r_eq.
    ``centre_of_mass``: the union's, in the mesh's frame (the balls' centres there are
    the offsets plus it)."""

    n_spheres: int
    volume_error: float
    surface_distance: float
    relative_surface_distance: float
    mesh_to_union: float
    union_to_mesh: float
    mesh_volume: float
    union_volume: float
    equivalent_radius: float
    centre_of_mass: tuple


# ---------------------------------------------------------------- the closed surface


class ClosedMesh(NamedTuple):
    """A closed, consistently wound triangle mesh with outward normals, as a reader checked it
    (:func:`parsim.deposition.mesh_file.read_closed_mesh`): ``vertices`` (v, 3) float64, ``faces``
    (f, 3) int64, the enclosed ``volume`` (> 0) and the ``diagonal`` of its bounding box."""

    vertices: np.ndarray
    faces: np.ndarray
    volume: float
    diagonal: float


def equivalent_radius(volume):
    """The radius of the sphere of ``volume``: (3 V / 4 pi)^(1/3)."""
    return (3.0 * volume / (4.0 * math.pi)) ** (1.0 / 3.0)


# ---------------------------------------------------------------- triangles and samples


class _Triangles:
    """The non-degenerate faces for the kernels: vertex indices ``faces``, first corner
    ``a``, edges ``ab`` and ``ac`` (outward normal along ab x ac), unit ``outward``
    normals, ``areas`` and bounding spheres (``centroid``, ``reach``)."""

    def __init__(self, vertices, faces, diagonal):
        corners = vertices[faces]
        cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        double_area = np.linalg.norm(cross, axis=1)
        keep = double_area > 2.0 * DEGENERATE_AREA_RTOL * diagonal**2
        corners = corners[keep]
        self.faces = faces[keep]
        self.areas = 0.5 * double_area[keep]
        self.outward = cross[keep] / double_area[keep, None]
        self.a = np.ascontiguousarray(corners[:, 0])
        self.ab = np.ascontiguousarray(corners[:, 1] - corners[:, 0])
        self.ac = np.ascontiguousarray(corners[:, 2] - corners[:, 0])
        self.centroid = np.ascontiguousarray(corners.mean(axis=1))
        self.reach = np.linalg.norm(corners - self.centroid[:, None, :], axis=2).max(axis=1)

    def arrays(self):
        return self.a, self.ab, self.ac, self.centroid, self.reach


def _area_samples(tris, m, shift):
    """m points on the surface, area-weighted and deterministic, and their faces.

    The stratified points (i + 1/2) / m of [0, 1) are shared out to the faces by
    cumulative area: the position inside a face's share is one coordinate of the point in
    the face, the golden-ratio sequence (offset ``shift``) the other; the unit square is
    folded onto the triangle.
    """
    cdf = np.cumsum(tris.areas) / tris.areas.sum()
    u = (np.arange(m) + 0.5) / m
    face = np.minimum(np.searchsorted(cdf, u, side="right"), len(cdf) - 1)
    share_start = np.concatenate([[0.0], cdf[:-1]])[face]
    s = np.clip((u - share_start) / (cdf[face] - share_start), 0.0, 1.0)
    t = (np.arange(m) * GOLDEN_FRACTION + shift) % 1.0
    fold = s + t > 1.0
    s[fold], t[fold] = 1.0 - s[fold], 1.0 - t[fold]
    points = tris.a[face] + s[:, None] * tris.ab[face] + t[:, None] * tris.ac[face]
    return np.ascontiguousarray(points), face


# ---------------------------------------------------------------- kernels: distances


@jit
def _closest_on_triangle(px, py, pz, a, ab, ac, f):
    """Weights (v, w) of the point a + v ab + w ac of triangle f closest to p (Ericson,
    Real-Time Collision Detection, section 5.1.5: the Voronoi regions of the three
    vertices, then of the three edges, else the face)."""
    apx = px - a[f, 0]
    apy = py - a[f, 1]
    apz = pz - a[f, 2]
    abx, aby, abz = ab[f, 0], ab[f, 1], ab[f, 2]
    acx, acy, acz = ac[f, 0], ac[f, 1], ac[f, 2]
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return 0.0, 0.0
    abac = abx * acx + aby * acy + abz * acz
    d3 = d1 - (abx * abx + aby * aby + abz * abz)  # ab.(p - b)
    d4 = d2 - abac  # ac.(p - b)
    if d3 >= 0.0 and d4 <= d3:
        return 1.0, 0.0
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        return d1 / (d1 - d3), 0.0
    d5 = d1 - abac  # ab.(p - c)
    d6 = d2 - (acx * acx + acy * acy + acz * acz)  # ac.(p - c)
    if d6 >= 0.0 and d5 <= d6:
        return 0.0, 1.0
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        return 0.0, d2 / (d2 - d6)
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return 1.0 - w, w
    denom = 1.0 / (va + vb + vc)
    return vb * denom, vc * denom


@jit
def _nearest_on_mesh(px, py, pz, a, ab, ac, centroid, reach, stop_below, hint, q):
    """Distance from p to the mesh surface and the index of the nearest triangle; the
    nearest point goes to q.

    The search starts at triangle ``hint`` (a good guess makes the bounding-sphere test
    skip most others) and ends early, returning a distance below ``stop_below``, as soon
    as it finds one (pass a negative value for the exact distance).
    """
    n = a.shape[0]
    best = np.inf
    nearest = hint
    for t in range(n):
        f = hint + t
        if f >= n:
            f -= n
        sx = px - centroid[f, 0]
        sy = py - centroid[f, 1]
        sz = pz - centroid[f, 2]
        bound = best + reach[f]
        if sx * sx + sy * sy + sz * sz >= bound * bound:
            continue
        v, w = _closest_on_triangle(px, py, pz, a, ab, ac, f)
        qx = a[f, 0] + v * ab[f, 0] + w * ac[f, 0]
        qy = a[f, 1] + v * ab[f, 1] + w * ac[f, 1]
        qz = a[f, 2] + v * ab[f, 2] + w * ac[f, 2]
        d = np.sqrt((px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2)
        if d < best:
            best = d
            nearest = f
            q[0] = qx
            q[1] = qy
            q[2] = qz
            if best < stop_below:
                break
    return best, nearest


@jit
def _medial_radius(p, n, a, ab, ac, centroid, reach, rho_max, atol, width, hint):
    """Radius of the largest ball B(p + rho n, rho) with no surface point inside, for p on
    the surface and n the inward unit normal there (shrinking ball, Ma et al. 2012).

    A trial ball is accepted when its centre is at least rho - atol from the surface.
    Otherwise the search finds a surface point q inside it (Ma et al. take the nearest;
    any one will do, and stopping at the first one found saves most of the distance
    computations), and no ball tangent at p with a radius above that of the one through
    q, |q - p|^2 / (2 n.(q - p)), is empty: an upper bound that shrinks the bracket
    [lo, hi].  The next trial is hi backed off by ``width * 4^j / 2`` after j
    consecutive failures, never below the bracket's midpoint, until the bracket is
    narrower than ``width``.  Returns lo, a radius tested empty.
    """
    q = np.empty(3)
    lo = 0.0
    hi = rho_max
    trial = rho_max
    fails = 0
    for _ in range(200):
        cx = p[0] + trial * n[0]
        cy = p[1] + trial * n[1]
        cz = p[2] + trial * n[2]
        d, hint = _nearest_on_mesh(cx, cy, cz, a, ab, ac, centroid, reach, trial - atol, hint, q)
        if d >= trial - atol:
            lo = trial
            fails = 0
        else:
            vx = q[0] - p[0]
            vy = q[1] - p[1]
            vz = q[2] - p[2]
            # q inside the trial ball implies n.(q - p) > |q - p|^2 / (2 trial) > 0
            along = vx * n[0] + vy * n[1] + vz * n[2]
            bound = (vx * vx + vy * vy + vz * vz) / (2.0 * along)
            hi = max(min(trial, bound), lo)
            fails += 1
        if hi - lo <= width:
            break
        trial = max(hi - 0.5 * width * 4.0**fails, 0.5 * (lo + hi))
    return lo


@jit
def _medial_radii(points, normals, faces, a, ab, ac, centroid, reach, rho_max, atol, width):
    """:func:`_medial_radius` of every point, its search starting at its face."""
    radii = np.empty(points.shape[0])
    for k in range(points.shape[0]):
        radii[k] = _medial_radius(points[k], normals[k], a, ab, ac, centroid, reach, rho_max, atol, width,
                                  faces[k])
    return radii


@jit
def _distances_to_mesh(points, a, ab, ac, centroid, reach, floor, running):
    """Distance of each point to the mesh surface: exact for the points farther than
    ``floor``, below ``floor`` for the others (their search stops there).  With
    ``running``, the floor rises to the largest distance found so far, so that only the
    maximum is exact (a one-sided Hausdorff distance at a fraction of the cost)."""
    q = np.empty(3)
    out = np.empty(points.shape[0])
    hint = 0
    for k in range(points.shape[0]):
        d, hint = _nearest_on_mesh(points[k, 0], points[k, 1], points[k, 2], a, ab, ac, centroid, reach,
                                   floor, hint, q)
        out[k] = d
        if running and d > floor:
            floor = d
    return out


@jit
def _distances_to_union(points, centres, radii, floor, running):
    """Distance of each point to the union of the balls (0 inside), with ``floor`` and
    ``running`` as in :func:`_distances_to_mesh`."""
    n = radii.shape[0]
    out = np.empty(points.shape[0])
    nearest = 0
    for k in range(points.shape[0]):
        best = np.inf
        start = nearest  # the previous point's nearest ball: a good first guess
        for t in range(n):
            b = start + t
            if b >= n:
                b -= n
            dx = points[k, 0] - centres[b, 0]
            dy = points[k, 1] - centres[b, 1]
            dz = points[k, 2] - centres[b, 2]
            gap = np.sqrt(dx * dx + dy * dy + dz * dz) - radii[b]
            if gap < best:
                best = gap
                nearest = b
                if best < floor:
                    break
        out[k] = max(best, 0.0)
        if running and out[k] > floor:
            floor = out[k]
    return out


@jit
def _container(x, y, z, centres, radii, neighbours, n_neighbours, skip, first_guess):
    """A ball of neighbours[:n_neighbours], not ``skip``, that contains the point (the
    ball ``first_guess`` is tried first), or -1."""
    if first_guess >= 0 and first_guess != skip:
        dx = x - centres[first_guess, 0]
        dy = y - centres[first_guess, 1]
        dz = z - centres[first_guess, 2]
        if dx * dx + dy * dy + dz * dz < radii[first_guess] * radii[first_guess]:
            return first_guess
    for t in range(n_neighbours):
        j = neighbours[t]
        dx = x - centres[j, 0]
        dy = y - centres[j, 1]
        dz = z - centres[j, 2]
        if j != skip and dx * dx + dy * dy + dz * dz < radii[j] * radii[j]:
            return j
    return -1


@jit
def _holds_circle(x, y, z, rho, centres, radii, neighbours, n_neighbours, skip):
    """Whether a ball of neighbours[:n_neighbours], not ``skip``, contains all of the
    circle of radius rho centred at (x, y, z)."""
    for t in range(n_neighbours):
        j = neighbours[t]
        dx = x - centres[j, 0]
        dy = y - centres[j, 1]
        dz = z - centres[j, 2]
        if j != skip and radii[j] > rho and dx * dx + dy * dy + dz * dz < (radii[j] - rho) ** 2:
            return True
    return False


@jit
def _keep(out, count, x, y, z):
    """Append a point to the buffer ``out`` (grown when full); returns it."""
    if count == out.shape[0]:
        grown = np.empty((2 * count, 3))
        for i in range(count):  # loops, not a slice assignment: much faster to compile
            for k in range(3):
                grown[i, k] = out[i, k]
        out = grown
    out[count, 0] = x
    out[count, 1] = y
    out[count, 2] = z
    return out


@jit
def _union_surface_points(centres, radii, directions, n_crease):
    """Samples of the surface of the union of the balls: the points c_b + r_b u (u in
    ``directions``) of every ball b and ``n_crease`` equally spaced points on the circle
    where two overlapping balls' spheres meet (the creases, where the union's surface is
    farthest from a surface it approximates), each kept if it lies in no other ball.
    Consecutive points are often in the same ball, which is therefore tested first."""
    n = radii.shape[0]
    out = np.empty((n * directions.shape[0] + 1, 3))
    count = 0
    neighbours = np.empty(n, dtype=np.int64)
    for b in range(n):
        container = -1
        n_neighbours = 0
        for j in range(n):
            dx = centres[b, 0] - centres[j, 0]
            dy = centres[b, 1] - centres[j, 1]
            dz = centres[b, 2] - centres[j, 2]
            s = radii[b] + radii[j]
            if j != b and dx * dx + dy * dy + dz * dz < s * s:
                neighbours[n_neighbours] = j
                n_neighbours += 1
        for u in range(directions.shape[0]):
            x = centres[b, 0] + radii[b] * directions[u, 0]
            y = centres[b, 1] + radii[b] * directions[u, 1]
            z = centres[b, 2] + radii[b] * directions[u, 2]
            container = _container(x, y, z, centres, radii, neighbours, n_neighbours, b, container)
            if container < 0:
                out = _keep(out, count, x, y, z)
                count += 1
        for t in range(n_neighbours):
            j = neighbours[t]
            ex = centres[j, 0] - centres[b, 0]
            ey = centres[j, 1] - centres[b, 1]
            ez = centres[j, 2] - centres[b, 2]
            d = np.sqrt(ex * ex + ey * ey + ez * ez)
            if j < b or d <= abs(radii[b] - radii[j]):  # each pair once; nested spheres do not meet
                continue
            ex /= d
            ey /= d
            ez /= d
            along = (d * d + radii[b] * radii[b] - radii[j] * radii[j]) / (2.0 * d)
            rho = np.sqrt(max(radii[b] * radii[b] - along * along, 0.0))
            # unit vectors u, v normal to e: u = e x (the axis least along e), v = e x u
            if abs(ex) <= abs(ey) and abs(ex) <= abs(ez):
                ux, uy, uz = 0.0, ez, -ey
            elif abs(ey) <= abs(ez):
                ux, uy, uz = -ez, 0.0, ex
            else:
                ux, uy, uz = ey, -ex, 0.0
            norm = np.sqrt(ux * ux + uy * uy + uz * uz)
            ux /= norm
            uy /= norm
            uz /= norm
            vx = ey * uz - ez * uy
            vy = ez * ux - ex * uz
            vz = ex * uy - ey * ux
            # the circle's centre, and whether a third ball holds all of the circle
            ox = centres[b, 0] + along * ex
            oy = centres[b, 1] + along * ey
            oz = centres[b, 2] + along * ez
            if _holds_circle(ox, oy, oz, rho, centres, radii, neighbours, n_neighbours, j):
                continue
            for k in range(n_crease):
                c = np.cos(2.0 * np.pi * k / n_crease)
                s = np.sin(2.0 * np.pi * k / n_crease)
                x = ox + rho * (c * ux + s * vx)
                y = oy + rho * (c * uy + s * vy)
                z = oz + rho * (c * uz + s * vz)
                container = _container(x, y, z, centres, radii, neighbours, n_neighbours, j, container)
                if container < 0:
                    out = _keep(out, count, x, y, z)
                    count += 1
    return out[:count].copy()


# ---------------------------------------------------------------- kernels: greedy cover


@jit
def _grown(member, depth):
    """The two arrays with twice the length, same leading values."""
    member2 = np.empty(2 * member.shape[0], dtype=np.int64)
    depth2 = np.empty(2 * member.shape[0])
    for e in range(member.shape[0]):
        member2[e] = member[e]
        depth2[e] = depth[e]
    return member2, depth2


@jit
def _cover_lists(points, normals, centres, radii, first, last, reach):
    """For every candidate ball i, the samples j whose inward normal line s_j + t n_j
    (t >= 0) enters the ball at a depth t <= reach: candidate i owns entries
    ptr[i]:ptr[i + 1] of (member, depth).  The samples are sorted by x; only those in
    first[i]:last[i] (the ball's x-slab) are tested."""
    n = radii.shape[0]
    ptr = np.zeros(n + 1, dtype=np.int64)
    member = np.empty(16 * points.shape[0], dtype=np.int64)
    depth = np.empty(member.shape[0])
    nnz = 0
    for i in range(n):
        for j in range(first[i], last[i]):
            vx = points[j, 0] - centres[i, 0]
            vy = points[j, 1] - centres[i, 1]
            vz = points[j, 2] - centres[i, 2]
            along = vx * normals[j, 0] + vy * normals[j, 1] + vz * normals[j, 2]
            disc = along * along - (vx * vx + vy * vy + vz * vz - radii[i] * radii[i])
            if disc < 0.0 or np.sqrt(disc) - along < 0.0:  # the line misses the ball
                continue
            entry = max(-along - np.sqrt(disc), 0.0)
            if entry > reach:
                continue
            if nnz == member.shape[0]:
                member, depth = _grown(member, depth)
            member[nnz] = j
            depth[nnz] = entry
            nnz += 1
        ptr[i + 1] = nnz
    return ptr, member[:nnz].copy(), depth[:nnz].copy()


@jit
def _gain(ptr, member, depth, union_depth, i, delta):
    """Number of samples that candidate i covers at delta and the union does not
    (``union_depth``: the depth at which a sample's normal line enters the union)."""
    g = 0
    for e in range(ptr[i], ptr[i + 1]):
        if depth[e] <= delta and union_depth[member[e]] > delta:
            g += 1
    return g


@jit
def _add_to_union(ptr, member, depth, i, union_depth):
    """Lower the samples' depths of entry into the union to candidate i's."""
    for e in range(ptr[i], ptr[i + 1]):
        j = member[e]
        if depth[e] < union_depth[j]:
            union_depth[j] = depth[e]


@jit
def _greedy_cover(ptr, member, depth, tie, chosen, n_chosen, deltas, n_target):
    """Greedy cover of the samples by the candidate balls (see the module docstring).

    ``chosen[:n_chosen]`` are already in the union; candidates are appended, for each
    delta of ``deltas`` (decreasing) in turn, until every sample is covered at that delta
    or ``n_target`` are chosen.  The priority of a candidate is its gain plus its
    ``tie`` value in [0, 1): among equal gains the larger ball wins.  Lazy greedy: gains
    only decrease as the union grows, so a popped candidate whose recomputed priority
    equals its key is the best one.  Returns the new n_chosen.
    """
    m = ptr.shape[0] - 1
    union_depth = np.full(m, np.inf)
    for b in range(n_chosen):
        _add_to_union(ptr, member, depth, chosen[b], union_depth)
    key = np.empty(m + 1)
    index = np.empty(m + 1, dtype=np.int64)
    for delta in deltas:
        size = 0
        for i in range(m):
            g = _gain(ptr, member, depth, union_depth, i, delta)
            if g > 0:
                size = _heap_push(key, index, size, g + tie[i], i)
        while size > 0 and n_chosen < n_target:
            top = key[0]
            i = index[0]
            size = _heap_pop(key, index, size)
            g = _gain(ptr, member, depth, union_depth, i, delta)
            if g + tie[i] < top:
                if g > 0:
                    size = _heap_push(key, index, size, g + tie[i], i)
                continue
            chosen[n_chosen] = i
            n_chosen += 1
            _add_to_union(ptr, member, depth, i, union_depth)
    return n_chosen


# ---------------------------------------------------------------- the construction


class _Cover:
    """Cover samples (with inward unit normals), their candidate balls and the chosen ones."""

    def __init__(self, tris, diagonal, reach):
        self.tris = tris
        self.diagonal = diagonal
        self.reach = reach
        self.points = np.empty((0, 3))
        self.normals = np.empty((0, 3))
        self.centres = np.empty((0, 3))
        self.radii = np.empty(0)
        self.chosen = np.empty(0, dtype=np.int64)

    def medial_radii(self, points, normals, faces):
        """Radii of the medial balls at the points (``faces``: where to start the searches)."""
        return _medial_radii(np.ascontiguousarray(points, dtype=np.float64),
                             np.ascontiguousarray(normals, dtype=np.float64),
                             np.asarray(faces, dtype=np.int64), *self.tris.arrays(),
                             self.diagonal, INSIDE_RTOL * self.diagonal, MEDIAL_RTOL * self.diagonal)

    def add_samples(self, points, normals, radii):
        """Add cover samples and their candidates, the balls tangent there with ``radii``
        (zero: no candidate, a point to cover only); returns their indices."""
        first = len(self.radii)
        self.points = np.vstack([self.points, points])
        self.normals = np.vstack([self.normals, normals])
        self.centres = np.vstack([self.centres, points + radii[:, None] * normals])
        self.radii = np.concatenate([self.radii, radii])
        return np.arange(first, len(self.radii))

    def cover(self, deltas, n_target, forced=()):
        """Add the ``forced`` candidates, then run the greedy cover at ``deltas``."""
        by_x = np.argsort(self.points[:, 0], kind="stable")
        points = np.ascontiguousarray(self.points[by_x])
        first = np.searchsorted(points[:, 0], self.centres[:, 0] - self.radii - self.reach)
        last = np.searchsorted(points[:, 0], self.centres[:, 0] + self.radii + self.reach, side="right")
        last[self.radii <= 0.0] = first[self.radii <= 0.0]  # a point, not a ball
        ptr, member, depth = _cover_lists(points, np.ascontiguousarray(self.normals[by_x]), self.centres,
                                          self.radii, first, last, self.reach)
        member = by_x[member]
        chosen = np.empty(len(self.radii), dtype=np.int64)
        already = np.concatenate([self.chosen, np.asarray(forced, dtype=np.int64)])
        chosen[: len(already)] = already
        tie = 0.5 * self.radii / self.radii.max()
        n_chosen = _greedy_cover(ptr, member, depth, tie, chosen, len(already),
                                 np.asarray(deltas, dtype=np.float64), min(n_target, len(chosen)))
        self.chosen = chosen[:n_chosen]

    def balls(self):
        return np.ascontiguousarray(self.centres[self.chosen]), np.ascontiguousarray(self.radii[self.chosen])


class _Evaluation:
    """Two-sided sampled distance between the mesh surface and the union's surface."""

    def __init__(self, tris, vertices, m):
        samples, faces = _area_samples(tris, m, 0.5)
        self.tris = tris
        self.n_vertices = len(vertices)
        self.mesh_points = np.ascontiguousarray(np.vstack([vertices, samples]))
        self.faces = faces
        self.vertex_steps = {}

    def distances(self, centres, radii, floor, running):
        """Distances of the mesh points to the union, the union's surface points and
        their distances to the mesh (floor and running as in :func:`_distances_to_mesh`)."""
        to_union = _distances_to_union(self.mesh_points, centres, radii, floor, running)
        directions = _fibonacci_sphere(UNION_POINTS_PER_BALL)
        union_points = _union_surface_points(centres, radii, directions, POINTS_PER_CREASE)
        to_mesh = _distances_to_mesh(union_points, *self.tris.arrays(), floor, running)
        return to_union, union_points, to_mesh

    def refine(self, cover, centres, radii, limit):
        """Add the points farther than ``limit`` to ``cover`` (see the module docstring);
        returns the candidates to force, or None if no point fails."""
        to_union, union_points, to_mesh = self.distances(centres, radii, limit, False)
        failing = np.flatnonzero(to_union > limit)
        inner = failing[failing >= self.n_vertices]
        points = self.mesh_points[inner]
        faces = self.faces[inner - self.n_vertices]
        normals = -self.tris.outward[faces]
        cover.add_samples(points, normals, cover.medial_radii(points, normals, faces))
        for v in failing[failing < self.n_vertices]:
            self._add_near_vertex(cover, v, limit)
        forced = self._add_forced(cover, union_points[to_mesh > limit], to_mesh[to_mesh > limit])
        return forced if len(failing) + len(forced) else None

    def _add_near_vertex(self, cover, v, limit):
        """Cover samples for a failing vertex v: v itself, to be covered, with the mean
        inward normal of its faces, and candidates on its faces, towards their centroids,
        at a distance that starts at limit / 2 and halves each time v fails again
        (medial balls shrink to nothing at a convex vertex: only small ones near it bring
        it within the limit)."""
        self.vertex_steps[v] = 0.5 * self.vertex_steps.get(v, limit)
        faces = np.flatnonzero((self.tris.faces == v).any(axis=1))
        vertex = self.mesh_points[v]
        towards = self.tris.centroid[faces] - vertex
        step = np.minimum(0.5, self.vertex_steps[v] / np.linalg.norm(towards, axis=1))
        points = vertex + step[:, None] * towards
        normals = -self.tris.outward[faces]
        mean_normal = normals.sum(axis=0) / np.linalg.norm(normals.sum(axis=0))
        cover.add_samples(vertex[None, :], mean_normal[None, :], np.zeros(1))
        cover.add_samples(points, normals, cover.medial_radii(points, normals, faces))

    def _add_forced(self, cover, union_points, to_mesh):
        """Candidates to force for union points u farther than the limit from the mesh:
        the medial ball at u's nearest surface point q, with normal (u - q) / |u - q|,
        which contains u; worst point first, skipping the points in a ball already
        taken.  Returns their indices in ``cover``."""
        q = np.empty(3)
        taken_points, taken_normals, taken_radii = [], [], []
        for k in np.argsort(-to_mesh, kind="stable"):
            u = union_points[k]
            taken = zip(taken_points, taken_normals, taken_radii)
            if any(np.linalg.norm(u - (p + r * n)) < r for p, n, r in taken):
                continue
            d, face = _nearest_on_mesh(u[0], u[1], u[2], *self.tris.arrays(), -1.0, 0, q)
            normal = (u - q) / d
            radius = cover.medial_radii(q[None, :], normal[None, :], [face])[0]
            if radius > 0.0:  # at least d but for round-off
                taken_points.append(q.copy())
                taken_normals.append(normal)
                taken_radii.append(radius)
        if not taken_points:
            return np.empty(0, dtype=np.int64)
        return cover.add_samples(np.array(taken_points), np.array(taken_normals), np.array(taken_radii))


def _cover_levels(start, stop):
    """The coverage depths start, start / 2, ... down to the last one >= stop."""
    count = int(math.floor(math.log2(start / stop))) + 1
    return start * 0.5 ** np.arange(count)


def mesh_particle(mesh, n_spheres=None, tolerance=None, samples=None):
    """A particle template from the :class:`ClosedMesh` ``mesh``.

    The solid bounded by the mesh (possibly non-convex) is approximated by the union of
    medial balls chosen by a greedy cover of surface samples; the module docstring
    describes the construction and the error measures.  Give exactly one of:

    - ``n_spheres``: stop after that many balls (fewer when every sample is covered to
      ``FINEST_COVER`` r_eq);
    - ``tolerance``: add balls until the sampled two-sided surface distance is at most
      ``tolerance`` r_eq, r_eq = (3 V / 4 pi)^(1/3) the volume-equivalent radius, or the
      refinement rounds run out (the returned fit tells).

    ``samples``: number of cover samples (default ``max(8 n_spheres, 2048)``, or 4096 in
    tolerance mode).  Deterministic: the same mesh gives the same template.

    Returns ``(offsets, radii, fit)``: ``offsets`` (k, 3) float64, the sphere centres
    relative to the centre of mass of the union of the spheres, in the mesh's frame and
    length units; ``radii`` (k,) float64; ``fit`` a :class:`MeshFit`.
    """
    if (n_spheres is None) == (tolerance is None):
        raise ValueError("give exactly one of n_spheres and tolerance")
    if n_spheres is not None:
        n_spheres = _check_int("n_spheres", n_spheres, 1)
        default_samples = max(SAMPLES_PER_SPHERE * n_spheres, MIN_SAMPLES)
    else:
        tolerance = _check_positive("tolerance", tolerance)
        default_samples = TOLERANCE_SAMPLES
    samples = _check_int("samples", default_samples if samples is None else samples, 16)

    vertices, volume, diagonal = mesh.vertices, mesh.volume, mesh.diagonal
    r_eq = equivalent_radius(volume)
    tris = _Triangles(vertices, mesh.faces, diagonal)
    evaluation = _Evaluation(tris, vertices, EVALUATION_FACTOR * samples)

    if n_spheres is not None:
        levels = _cover_levels(max(COARSEST_COVER, 1.0 / n_spheres) * r_eq, FINEST_COVER * r_eq)
    else:
        limit = tolerance * r_eq
        levels = _cover_levels(max(COARSEST_COVER * r_eq, limit), limit)
        levels *= limit / levels[-1]
    cover = _Cover(tris, diagonal, levels[0])
    points, faces = _area_samples(tris, samples, 0.0)
    normals = -tris.outward[faces]
    cover.add_samples(points, normals, cover.medial_radii(points, normals, faces))
    if n_spheres is not None:
        cover.cover(levels, n_spheres)
    else:
        cover.cover(levels, len(cover.radii))
        for _ in range(MAX_REFINEMENTS):
            forced = evaluation.refine(cover, *cover.balls(), limit)
            if forced is None:
                break
            cover.cover([limit], len(cover.radii), forced)

    centres, radii = cover.balls()
    com, union_volume = centre_of_mass_of_union(centres, radii)
    to_union, _, to_mesh = evaluation.distances(centres, radii, 0.0, True)
    distance = float(max(to_union.max(), to_mesh.max()))
    fit = MeshFit(
        n_spheres=len(radii),
        volume_error=(union_volume - volume) / volume,
        surface_distance=distance,
        relative_surface_distance=distance / r_eq,
        mesh_to_union=float(to_union.max()),
        union_to_mesh=float(to_mesh.max()),
        mesh_volume=volume,
        union_volume=float(union_volume),
        equivalent_radius=r_eq,
        centre_of_mass=tuple(float(x) for x in com),
    )
    return np.ascontiguousarray(centres - com), radii, fit
