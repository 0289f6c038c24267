"""Statistics of a sediment (Topić & Pöschel 2016, sections 4.1 and 5).

- :func:`filling_height`: twice the height of the centre of mass of the packing,
  2 z_cm (section 4.1, Fig. 8), each particle weighted by its volume;
- :func:`union_volume_and_height`: volume and centre-of-mass height of the union of spheres
  (a substrate's material, overlaps counted once);
- :func:`packing_fraction`, :func:`packing_fraction_profile`, :func:`packing_fractions`: the
  fraction of horizontal slabs of the box covered by the union of the spheres, for the bulk
  value (slab 0.25 h … 0.75 h) and the profile φ(z);

The packing fraction is the volume of the union of the spheres in a slab over the slab's
volume. The volume of each sphere in each slab is exact: the integral of π (r² − (z − z_c)²)
over the slab, spherical caps (a sphere counts with its whole horizontal extent; with periodic
sides its images wrap back in). From their sum the excess ∫ (1 − 1/c(x)) dx is subtracted,
c(x) the number of spheres covering x; it is non-zero only where spheres overlap, i.e. within
a multi-sphere particle. It is held in the caps of each sphere towards the spheres it
overlaps: a cap disjoint from the sphere's other caps holds exactly half the lens of the two
spheres (the lens volume in closed form), and is sampled only to split a lens cut by a slab
boundary (a ratio estimator); other caps (multiple overlaps) are sampled by quasi-Monte Carlo
(Halton points, shifted per cap), with the half lens as control variate when the lens lies in
one slab. Non-overlapping spheres are exact to round-off; rods of three spheres 1 radius apart
have errors of about 3·10⁻⁵ per slab with the default 2·10⁵ samples per slab.

Spheres are binned in cubic cells, so the cost per sphere does not grow with the height of the
pile. The horizontal box is periodic for all kernels (sediments of rigid walls lie inside the
box, so periodic wrapping changes nothing for them).
"""

import numpy as np

from parsim.core.growth import with_rows
from parsim.core.jit import jit
from parsim.core.shapes.union import centre_of_mass_of_union

# Two spheres of different particles are in contact when their gap is below this
# fraction of the mean radius: the solver closes contacts to ~1e-12, and the paper's
# cycling interruption leaves clearances of ~1e-8 (section 4.2).
CONTACT_GAP_TOLERANCE = 1e-6
DEFAULT_SAMPLES = 200_000
# Spheres closer than this fraction of the mean radius of touching overlap by round-off only; their
# lens (volume ~ R δ², δ <= 1e-9 R) is below any measurable fraction and is not sampled.
OVERLAP_TOLERANCE = 1e-9
# Points per sampled cap: ``samples`` per slab spread over the sampled caps, within these bounds
# (the floor keeps large packings' caps resolved; beyond the ceiling QMC error of a cap no longer
# matters next to the other caps).
MIN_POINTS_PER_CAP = 16
MAX_POINTS_PER_CAP = 1 << 16
# Per-cap shifts of the Halton points (Cranley–Patterson rotation) follow the R3 sequence
# (Roberts 2018): frac(n / g^k) with g the plastic number's 3D analogue, g^4 = g + 1.
_R3_0, _R3_1, _R3_2 = 1.0 / 1.2207440846057596 ** np.arange(1, 4)


def filling_height(particle_com_z, particle_volume):
    """2 z_cm, the filling height of section 4.1: z_cm = sum V_p z_p / sum V_p."""
    z = np.asarray(particle_com_z, dtype=np.float64)
    volume = np.asarray(particle_volume, dtype=np.float64)
    if z.shape != volume.shape or z.size == 0:
        raise ValueError("particle_com_z and particle_volume must be non-empty and of the same shape")
    return 2.0 * float(np.dot(volume, z) / volume.sum())


def union_volume_and_height(positions, radii):
    """Volume of the union of spheres (overlaps counted once) and the height of its centre of mass.

    By inclusion and exclusion, exact where no point lies in three spheres: every sphere counts
    4/3 π r³ at its centre, and every lens of two overlapping spheres is taken off once, its volume
    and centroid in closed form (see :func:`_lens_volume_and_centroid`). Where three spheres or
    more overlap (a sphere whose caps towards its overlapping neighbours meet, see
    :func:`_classify_caps`), the union of those spheres is integrated on vertical columns by
    :func:`parsim.core.shapes.union.centre_of_mass_of_union`, the integration that gives every
    particle template its volume (errors below 2e-4), and only their lenses with the other spheres
    are taken off. Overlaps are found in the cubic cell grid: O(n). No periodic images: the
    spheres of one particle must lie together, as a sediment's do.
    """
    x = np.ascontiguousarray(positions, dtype=np.float64)
    r = np.ascontiguousarray(radii, dtype=np.float64)
    margin = 2.0 * r.max()  # the grid's periodic sides lie so far out that no sphere meets an image
    grid = _SphereGrid(x, r, x[:, :2].min(axis=0) - margin, x[:, :2].max(axis=0) + margin)
    centres, sorted_radii, _, start, lower, upper, _, _, cells = grid.arrays()
    first, neighbour, offset = _overlap_lists(centres, sorted_radii, OVERLAP_TOLERANCE * float(np.mean(r)), start,
                                              lower, upper, cells)
    axis, plane, distance = _caps(sorted_radii, first, neighbour, offset)
    everything = np.array([centres[:, 2].min() - margin, centres[:, 2].max() + margin])  # one slab holds every lens
    _, kind = _classify_caps(centres, sorted_radii, first, neighbour, offset, axis, plane, distance, everything)
    owner = np.repeat(np.arange(len(sorted_radii)), np.diff(first))
    multiple = np.zeros(len(sorted_radii), dtype=bool)
    multiple[owner[kind == 2]] = True
    single = ~multiple
    sphere = 4.0 / 3.0 * np.pi * sorted_radii[single] ** 3
    volume, moment = float(sphere.sum()), float(np.dot(sphere, centres[single, 2]))
    # each lens with a sphere outside the multiple overlaps appears in the rows of both its spheres: half in each
    rows = single[owner] | single[neighbour]
    lens, along = _lens_volume_and_centroid(sorted_radii[owner[rows]], sorted_radii[neighbour[rows]], distance[rows])
    volume -= 0.5 * float(lens.sum())
    moment -= 0.5 * float(np.dot(lens, centres[owner[rows], 2] + along * axis[rows, 2]))
    if multiple.any():
        centre, united = centre_of_mass_of_union(centres[multiple], sorted_radii[multiple])
        volume, moment = volume + united, moment + united * float(centre[2])
    return volume, moment / volume


def _lens_volume_and_centroid(r_i, r_j, d):
    """Volume of the lens S_i ∩ S_j of overlapping spheres of radii ``r_i``, ``r_j`` whose centres are ``d``
    apart, and the distance of its centroid from centre i towards centre j (arrays).

    The lens is a cap of each sphere cut by the plane of their meeting circle, t = (d² + r_i² − r_j²) / 2d
    from centre i; a cap of height a of a sphere of radius R has volume π a² (3R − a) / 3 and its
    centroid 3 (2R − a)² / (4 (3R − a)) from the sphere's centre. When one sphere holds the other, the
    plane lies beyond it and its cap is the whole sphere (a = 2R), the other cap empty.
    """
    d = np.maximum(d, np.finfo(np.float64).tiny)  # coincident centres: the plane at infinity, or at the centre
    with np.errstate(over="ignore"):
        t = (d * d + r_i * r_i - r_j * r_j) / (2.0 * d)
    a_i, a_j = np.clip(r_i - t, 0.0, 2.0 * r_i), np.clip(r_j - (d - t), 0.0, 2.0 * r_j)
    cap_i, cap_j = np.pi * a_i**2 * (3.0 * r_i - a_i) / 3.0, np.pi * a_j**2 * (3.0 * r_j - a_j) / 3.0
    centroid_i = 3.0 * (2.0 * r_i - a_i) ** 2 / (4.0 * (3.0 * r_i - a_i))
    centroid_j = d - 3.0 * (2.0 * r_j - a_j) ** 2 / (4.0 * (3.0 * r_j - a_j))
    volume = cap_i + cap_j
    return volume, (cap_i * centroid_i + cap_j * centroid_j) / volume


def packing_fraction(positions, radii, box_lower_xy, box_upper_xy, z_low, z_high, samples=DEFAULT_SAMPLES,
                     overlapping=None):
    """Fraction of the slab box × [z_low, z_high) covered by the union of the spheres (``overlapping``: see
    :func:`packing_fractions`)."""
    return float(packing_fractions(positions, radii, box_lower_xy, box_upper_xy, [(z_low, z_high)], samples,
                                   overlapping)[0])


def packing_fraction_profile(positions, radii, box_lower_xy, box_upper_xy, z_edges, samples=DEFAULT_SAMPLES):
    """φ(z) in the slabs between consecutive ``z_edges``."""
    edges = np.asarray(z_edges, dtype=np.float64)
    return packing_fractions(positions, radii, box_lower_xy, box_upper_xy, np.column_stack([edges[:-1], edges[1:]]),
                             samples)


def packing_fractions(positions, radii, box_lower_xy, box_upper_xy, slabs, samples=DEFAULT_SAMPLES,
                      overlapping=None):
    """Covered fraction of each slab box × [z_low, z_high) of ``slabs`` (rows (z_low, z_high), may overlap).

    All slabs are measured in one pass over the spheres, on the slabs between their sorted edges.
    ``overlapping`` (optional, one flag per sphere): True for every sphere that may overlap another
    by more than the overlap tolerance (minimum images across the box's sides); the others are known
    to overlap none, e.g. from :func:`parsim.core.structure.contact_network`, and skip the search for
    overlaps. The result is the same as without it, which searches every sphere.
    """
    slabs = np.asarray(slabs, dtype=np.float64).reshape(-1, 2)
    if len(slabs) == 0 or not np.all(slabs[:, 1] > slabs[:, 0]):
        raise ValueError(f"need z_high > z_low in every slab, got {slabs.tolist()}")
    edges = np.unique(slabs)
    covered = np.concatenate([[0.0], np.cumsum(_covered_volumes(positions, radii, box_lower_xy, box_upper_xy, edges,
                                                                samples * len(slabs), overlapping))])
    low, high = np.searchsorted(edges, slabs[:, 0]), np.searchsorted(edges, slabs[:, 1])
    area = float(np.prod(np.asarray(box_upper_xy, dtype=np.float64) - np.asarray(box_lower_xy, dtype=np.float64)))
    return (covered[high] - covered[low]) / (area * (slabs[:, 1] - slabs[:, 0]))


def _covered_volumes(positions, radii, box_lower_xy, box_upper_xy, edges, budget, overlapping=None):
    """Volume of the union of the spheres in each slab between consecutive ``edges``: exact sphere volumes
    minus the overlap excess, which is exact for pairwise caps and sampled with about ``budget`` points otherwise.

    Spheres are summed in the order of the cell grid. The overlaps are searched among the spheres
    flagged ``overlapping`` (all without flags), kept in that order on the same cells: the spheres
    left out have no overlap, so the overlap lists, their row numbers (which shift the sample points)
    and the sums over them are those of the search over all spheres.
    """
    grid = _SphereGrid(positions, radii, box_lower_xy, box_upper_xy)
    if len(grid.radii) == 0:
        return np.zeros(len(edges) - 1)
    volume = _sphere_slab_volumes(grid.positions, grid.radii, grid.order, edges)
    # the mean radius in the grid's order: the tolerance (and its last bit) of the search over every sphere
    tolerance = OVERLAP_TOLERANCE * float(np.mean(grid.radii[grid.order]))
    excess = np.zeros(len(edges) - 1)
    if overlapping is None:
        centres, radii, _, start, lower, upper, _, _, cells = grid.arrays()
    else:
        kept = np.asarray(overlapping, dtype=bool)
        if kept.shape != grid.radii.shape:
            raise ValueError("overlapping must hold one flag per sphere")
        kept_sorted = kept[grid.order]
        if not kept_sorted.any():
            return volume - excess
        chosen = grid.order[kept_sorted]
        centres, radii = grid.positions[chosen], grid.radii[chosen]
        # cell c holds the chosen spheres start[c]:start[c + 1] of the grid's order
        start = np.concatenate([[0], np.cumsum(kept_sorted)])[grid.start]
        lower, upper, cells = grid.lower, grid.upper, grid.cells
    first, neighbour, offset = _overlap_lists(centres, radii, tolerance, start, lower, upper, cells)
    if not len(neighbour):
        return volume - excess
    axis, plane, distance = _caps(radii, first, neighbour, offset)
    excess, kind = _classify_caps(centres, radii, first, neighbour, offset, axis, plane, distance, edges)
    sampled = int(np.count_nonzero(kind))
    if sampled:
        per_cap = int(min(max(MIN_POINTS_PER_CAP, np.ceil(budget / sampled)), MAX_POINTS_PER_CAP))
        unit = np.column_stack([_van_der_corput(per_cap, base) for base in (2, 3, 5)])
        excess += _sampled_excess(centres, radii, first, neighbour, offset, axis, plane, distance, kind,
                                  edges, unit)
    return volume - excess


class _SphereGrid:
    """Spheres binned in cubic cells (side >= the largest diameter), periodic in x and y.

    Cells are 3D, so a query costs the same at any depth of the pile. Cell (i, j, k) (x, y, z) is
    numbered (i cells[1] + j) cells[2] + k, the cells of a column consecutive; with ``layers_first``
    (k cells[0] + i) cells[1] + j, the cells of a horizontal layer consecutive, so that a pass in cell
    order meets the spheres of a sediment about in the order they were deposited.
    """

    def __init__(self, positions, radii, box_lower_xy, box_upper_xy, layers_first=False):
        self.positions = np.ascontiguousarray(positions, dtype=np.float64)
        self.radii = np.ascontiguousarray(radii, dtype=np.float64)
        if self.positions.ndim != 2 or self.positions.shape[1] != 3 or self.radii.shape != (len(self.positions),):
            raise ValueError("positions must be (n, 3) and radii (n,)")
        self.lower = np.asarray(box_lower_xy, dtype=np.float64)
        self.upper = np.asarray(box_upper_xy, dtype=np.float64)
        width = self.upper - self.lower
        reach = 2.0 * self.radii.max() if len(self.radii) else 1.0
        z = self.positions[:, 2] if len(self.radii) else np.zeros(1)
        self.z_lower = float(z.min())
        self.cells = np.array([*np.maximum(np.floor(width / reach), 1), np.floor((z.max() - self.z_lower) / reach) + 1],
                              dtype=np.int64)
        self.cell_height = reach
        # order: the spheres by cell, in index order within a cell; start: cell c holds order[start[c]:start[c + 1]]
        self.order, self.start = _bin_by_cell(self.positions, self.lower, width, self.z_lower, reach, self.cells,
                                              layers_first)

    def arrays(self):
        return (self.positions[self.order], self.radii[self.order], self.order, self.start,
                self.lower, self.upper, self.z_lower, self.cell_height, self.cells)


@jit
def _cell_of(x, y, z, lower, width, z_lower, cell_height, cells, layers_first):
    """Cell (i, j, k) of the point as one index (see :class:`_SphereGrid`): periodic in x and y, heights
    below and above the grid in its bottom and top layers."""
    i = int(np.floor((x - lower[0]) / width[0] * cells[0])) % cells[0]
    j = int(np.floor((y - lower[1]) / width[1] * cells[1])) % cells[1]
    k = min(max(int(np.floor((z - z_lower) / cell_height)), 0), cells[2] - 1)
    if layers_first:
        return (k * cells[0] + i) * cells[1] + j
    return (i * cells[1] + j) * cells[2] + k


@jit
def _bin_by_cell(positions, lower, width, z_lower, cell_height, cells, layers_first):
    """Counting sort of the points by cell: (order, start), cell c holding order[start[c]:start[c + 1]] in
    index order (what a stable sort by cell gives, in O(n) rather than O(n log n))."""
    n = positions.shape[0]
    cell = np.empty(n, dtype=np.int64)
    start = np.zeros(cells[0] * cells[1] * cells[2] + 1, dtype=np.int64)
    for m in range(n):
        cell[m] = _cell_of(positions[m, 0], positions[m, 1], positions[m, 2], lower, width, z_lower, cell_height,
                           cells, layers_first)
        start[cell[m] + 1] += 1
    for c in range(len(start) - 1):
        start[c + 1] += start[c]
    order = np.empty(n, dtype=np.int64)
    filled = start[:-1].copy()
    for m in range(n):
        order[filled[cell[m]]] = m
        filled[cell[m]] += 1
    return order, start


def _van_der_corput(n, base):
    """The first n points (from index 1) of the radical-inverse sequence in ``base``."""
    index = np.arange(1, n + 1, dtype=np.int64)
    value = np.zeros(n)
    scale = 1.0 / base
    while np.any(index > 0):
        value += (index % base) * scale
        index //= base
        scale /= base
    return value


@jit
def _columns_around(ci, cj, reach, cells, out):
    """Fill ``out`` with the distinct columns i cells[1] + j within ``reach`` columns of (ci, cj), periodic in
    x and y (every column of an axis with fewer than 2 reach + 1), x outer and y inner; return how many.

    The cells of a column are consecutive in a cell-sorted list (cell (i cells[1] + j) cells[2] + k), so
    the cells around a point are read as one run of the list per column."""
    count = 0
    wide_i, wide_j = cells[0] >= 2 * reach + 1, cells[1] >= 2 * reach + 1
    for a in range(2 * reach + 1 if wide_i else cells[0]):
        i = (ci - reach + a) % cells[0] if wide_i else a
        for b in range(2 * reach + 1 if wide_j else cells[1]):
            j = (cj - reach + b) % cells[1] if wide_j else b
            out[count] = i * cells[1] + j
            count += 1
    return count


@jit
def _volume_below(centre_z, radius, z):
    """Volume of a sphere below the plane z: the integral of π (r² − s²) over −r <= s <= z − z_c."""
    s = min(max(z - centre_z, -radius), radius)
    return np.pi * (radius * radius * (s + radius) - (s * s * s + radius * radius * radius) / 3.0)


@jit
def _sphere_slab_volumes(positions, radii, order, edges):
    """Sum over spheres, in the given ``order``, of their volume in each slab [edges[k], edges[k+1]]
    (spherical caps, exact).

    A sphere counts with its whole horizontal extent: laterally it lies in the box or, with
    periodic sides, its images wrap the parts outside back in.
    """
    volume = np.zeros(len(edges) - 1)
    for i in order:
        zc, r = positions[i, 2], radii[i]
        k = max(np.searchsorted(edges, zc - r, side="right") - 1, 0)
        below = _volume_below(zc, r, edges[k])
        while k < len(edges) - 1 and edges[k] < zc + r:
            above = _volume_below(zc, r, edges[k + 1])
            volume[k] += above - below
            below = above
            k += 1
    return volume


@jit
def _overlap_lists(centres, radii, tolerance, start, lower, upper, cells):
    """The spheres overlapping each sphere by more than ``tolerance`` and their minimum-image offsets c_j − c_i.

    Works on the cell-sorted spheres (``centres``, ``radii``, cell c holding start[c]:start[c+1]),
    cell by cell for locality; returns the CSR rows ``first`` (sphere i: first[i]:first[i+1]),
    ``neighbour`` and ``offset``.
    """
    width = upper - lower
    n = centres.shape[0]
    capacity = 4 * n + 16
    neighbour = np.empty(capacity, dtype=np.int64)
    offset = np.empty((capacity, 3))
    first = np.zeros(n + 1, dtype=np.int64)
    columns = np.empty(9, dtype=np.int64)
    rows = 0
    for ci in range(cells[0]):
        for cj in range(cells[1]):
            n_columns = _columns_around(ci, cj, 1, cells, columns)
            for ck in range(cells[2]):
                cell = (ci * cells[1] + cj) * cells[2] + ck
                if start[cell] == start[cell + 1]:
                    continue
                bottom, top = max(ck - 1, 0), min(ck + 2, cells[2])  # the cells ck - 1 ... ck + 1 of a column
                for m in range(start[cell], start[cell + 1]):
                    first[m] = rows
                    for c in range(n_columns):
                        for other in range(start[columns[c] * cells[2] + bottom], start[columns[c] * cells[2] + top]):
                            if other == m:
                                continue
                            dx = _minimum_image(centres[other, 0] - centres[m, 0], width[0])
                            dy = _minimum_image(centres[other, 1] - centres[m, 1], width[1])
                            dz = centres[other, 2] - centres[m, 2]
                            reach = radii[m] + radii[other] - tolerance
                            if dx * dx + dy * dy + dz * dz < reach * reach and reach > 0.0:
                                if rows == capacity:
                                    capacity *= 2
                                    neighbour = with_rows(neighbour, capacity, rows)
                                    offset = with_rows(offset, capacity, rows)
                                neighbour[rows] = other
                                offset[rows, 0], offset[rows, 1], offset[rows, 2] = dx, dy, dz
                                rows += 1
    first[n] = rows
    return first, neighbour[:rows], offset[:rows]


@jit
def _caps(radii, first, neighbour, offset):
    """Per overlapping pair (i, j): the axis u (unit, from sphere i towards j), the plane height s and distance d
    of the cap of sphere i that holds S_i ∩ S_j.

    S_i ∩ S_j lies in {x : (x − c_i)·u >= d − r_j}; the cap is cut at s = max(d − r_j, −r_i).
    """
    axis = np.empty((len(neighbour), 3))
    plane = np.empty(len(neighbour))
    distance = np.empty(len(neighbour))
    for i in range(len(first) - 1):
        for row in range(first[i], first[i + 1]):
            d = np.sqrt(offset[row, 0] ** 2 + offset[row, 1] ** 2 + offset[row, 2] ** 2)
            if d > 1e-12 * radii[i]:
                for x in range(3):
                    axis[row, x] = offset[row, x] / d
            else:  # coincident centres: the cap is the whole sphere, any axis will do
                axis[row, 0], axis[row, 1], axis[row, 2] = 0.0, 0.0, 1.0
            plane[row] = max(d - radii[neighbour[row]], -radii[i])
            distance[row] = d
    return axis, plane, distance


@jit
def _lens_volume(r_i, r_j, d):
    """Volume of S_i ∩ S_j for centre distance d (the lens of two spheres, e.g. Weisstein, MathWorld "Sphere-Sphere
    Intersection": π (R + r − d)² (d² + 2dr − 3r² + 2dR + 6rR − 3R²) / 12d)."""
    if d >= r_i + r_j:
        return 0.0
    if d <= abs(r_i - r_j):
        small = min(r_i, r_j)
        return 4.0 / 3.0 * np.pi * small * small * small
    depth = r_i + r_j - d
    return (np.pi * depth * depth * (d * d + 2 * d * r_j - 3 * r_j * r_j + 2 * d * r_i + 6 * r_i * r_j
                                     - 3 * r_i * r_i) / (12.0 * d))


@jit
def _slab_of(edges, z):
    """Index of the slab [edges[k], edges[k+1]) holding z, or −1 outside the edges."""
    if z < edges[0] or z >= edges[-1]:
        return -1
    return np.searchsorted(edges, z, side="right") - 1


@jit
def _lens_z_range(offset, r_i, r_j, d, u):
    """Lowest and highest z of S_i ∩ S_j relative to the centre of sphere i.

    The lens is bounded by the part of each sphere inside the other; the extreme z of such a
    part is the sphere's pole if the pole lies inside the other sphere, otherwise a point of the
    circle where the spheres meet (centre t u, t = (d² + r_i² − r_j²) / 2d, in the plane ⊥ u).
    """
    if d <= abs(r_i - r_j):  # one sphere inside the other: the lens is the smaller one
        if r_i <= r_j:
            return -r_i, r_i
        return offset[2] - r_j, offset[2] + r_j
    t = (d * d + r_i * r_i - r_j * r_j) / (2.0 * d)
    spread = np.sqrt(max(r_i * r_i - t * t, 0.0)) * np.sqrt(max(1.0 - u[2] * u[2], 0.0))
    low, high = t * u[2] - spread, t * u[2] + spread
    horizontal = offset[0] * offset[0] + offset[1] * offset[1]
    for sign in (-1.0, 1.0):
        if horizontal + (sign * r_i - offset[2]) ** 2 <= r_j * r_j:  # pole of sphere i inside sphere j
            low, high = min(low, sign * r_i), max(high, sign * r_i)
        if horizontal + (offset[2] + sign * r_j) ** 2 <= r_i * r_i:  # pole of sphere j inside sphere i
            low, high = min(low, offset[2] + sign * r_j), max(high, offset[2] + sign * r_j)
    return low, high


@jit
def _classify_caps(positions, radii, first, neighbour, offset, axis, plane, distance, edges):
    """Exact part of the overlap excess, and which caps must be sampled.

    The cap of sphere i towards j is *pairwise* when it is disjoint from every other cap of i:
    then no point of it lies in a third sphere, and the excess it holds is exactly half the lens
    S_i ∩ S_j (the other half is in the cap of j towards i). Two caps of one sphere are
    disjoint when the angle between their axes is at least the sum of their angular radii
    arccos(s / r_i) (their solids meet only if their surface caps do). A pairwise cap whose
    lens lies within one slab (or outside all) is added exactly; every other cap is sampled.
    Returns (excess per slab, per cap: 0 exact, 1 pairwise and sampled, 2 sampled in full).
    """
    excess = np.zeros(len(edges) - 1)
    kind = np.zeros(len(neighbour), dtype=np.int64)
    for i in range(positions.shape[0]):
        r_i, zc = radii[i], positions[i, 2]
        for row in range(first[i], first[i + 1]):
            if zc + r_i <= edges[0] or zc - r_i >= edges[-1]:
                continue
            j = neighbour[row]
            angle = np.arccos(min(max(plane[row] / r_i, -1.0), 1.0))
            pairwise = True
            for other in range(first[i], first[i + 1]):
                if other != row:
                    cosine = (axis[row, 0] * axis[other, 0] + axis[row, 1] * axis[other, 1]
                              + axis[row, 2] * axis[other, 2])
                    separation = np.arccos(min(max(cosine, -1.0), 1.0))
                    if separation < angle + np.arccos(min(max(plane[other] / r_i, -1.0), 1.0)) - 1e-9:
                        pairwise = False
                        break
            low, high = _lens_z_range(offset[row], r_i, radii[j], distance[row], axis[row])
            bottom, top = _slab_of(edges, zc + low), _slab_of(edges, zc + high)
            if zc + high < edges[0] or zc + low >= edges[-1]:
                kind[row] = 0 if pairwise else 2
            elif bottom == top and bottom >= 0:
                if pairwise:
                    excess[bottom] += 0.5 * _lens_volume(r_i, radii[j], distance[row])
                else:
                    kind[row] = 2
            else:
                kind[row] = 1 if pairwise else 2
    return excess, kind


@jit
def _sampled_excess(positions, radii, first, neighbour, offset, axis, plane, distance, kind, edges, unit):
    """Per slab, the excess ∫ (1 − 1/c(x)) dx held by the sampled caps (c(x): spheres covering x).

    Sum of sphere volumes − excess = volume of the union. Points covered twice or more lie in
    the caps of sphere i towards its overlapping spheres (see _caps). A cap is sampled with the
    quasi-random ``unit`` points (Halton, shifted per cap) in its bounding square prism along
    the cap's axis; a point of S_i in m caps of i has weight (1 − 1/c)/m, so the caps of i
    together give ∫_{S_i} (1 − 1/c) without double counting.
    - pairwise caps (kind 1): the weight is 1/2 on the lens S_i ∩ S_j; the cap's total is set to
      the exact half lens and the points only distribute it over the slabs (ratio estimator);
    - other caps (kind 2) whose lens lies in one slab: the exact half lens g = 1/2 on the lens is
      a control variate, so only (weight − g) is sampled; otherwise the weights themselves.
    """
    n_points = unit.shape[0]
    excess = np.zeros(len(edges) - 1)
    weight = np.empty(n_points)
    slab = np.empty(n_points, dtype=np.int64)
    inside = np.empty(n_points, dtype=np.bool_)
    e1 = np.empty(3)
    e2 = np.empty(3)
    p = np.empty(3)
    for i in range(positions.shape[0]):
        r_i, zc = radii[i], positions[i, 2]
        for row in range(first[i], first[i + 1]):
            if kind[row] == 0:
                continue
            j = neighbour[row]
            u, s, d = axis[row], plane[row], distance[row]
            height = r_i - s
            half_width = r_i if s <= 0.0 else np.sqrt(r_i * r_i - s * s)
            # e1, e2: an orthonormal pair perpendicular to u
            if abs(u[0]) < 0.9:
                e1[0], e1[1], e1[2] = 0.0, u[2], -u[1]
            else:
                e1[0], e1[1], e1[2] = -u[2], 0.0, u[0]
            e1 /= np.sqrt(e1[0] ** 2 + e1[1] ** 2 + e1[2] ** 2)
            e2[0] = u[1] * e1[2] - u[2] * e1[1]
            e2[1] = u[2] * e1[0] - u[0] * e1[2]
            e2[2] = u[0] * e1[1] - u[1] * e1[0]
            shift = row + 1.0
            shift_a, shift_b, shift_c = (shift * _R3_0) % 1.0, (shift * _R3_1) % 1.0, (shift * _R3_2) % 1.0
            in_lens = 0
            for q in range(n_points):
                weight[q] = 0.0
                slab[q] = -1
                inside[q] = False
                a, b, c = unit[q, 0] + shift_a, unit[q, 1] + shift_b, unit[q, 2] + shift_c
                a = a - 1.0 if a >= 1.0 else a
                b = 2.0 * (b - 1.0 if b >= 1.0 else b) - 1.0
                c = 2.0 * (c - 1.0 if c >= 1.0 else c) - 1.0
                t = s + height * a
                for x in range(3):
                    p[x] = t * u[x] + half_width * (b * e1[x] + c * e2[x])
                if p[0] * p[0] + p[1] * p[1] + p[2] * p[2] >= r_i * r_i:
                    continue
                covering = 1
                caps = 0
                own = False
                for other in range(first[i], first[i + 1]):
                    k = neighbour[other]
                    dx, dy, dz = p[0] - offset[other, 0], p[1] - offset[other, 1], p[2] - offset[other, 2]
                    if dx * dx + dy * dy + dz * dz < radii[k] * radii[k]:
                        covering += 1
                        own = own or other == row
                    if other == row or (p[0] * axis[other, 0] + p[1] * axis[other, 1] + p[2] * axis[other, 2]
                                        >= plane[other]):
                        caps += 1
                if covering >= 2:
                    weight[q] = (1.0 - 1.0 / covering) / caps
                if own:
                    in_lens += 1
                inside[q] = own
                slab[q] = _slab_of(edges, zc + p[2])
            lens_half = 0.5 * _lens_volume(r_i, radii[j], d)
            low, high = _lens_z_range(offset[row], r_i, radii[j], d, u)
            middle = _slab_of(edges, zc + 0.5 * (low + high))
            if kind[row] == 1:
                if in_lens == 0:  # a lens too thin to be hit: its volume goes to the slab of its middle
                    if middle >= 0:
                        excess[middle] += lens_half
                    continue
                for q in range(n_points):
                    if slab[q] >= 0 and weight[q] > 0.0:
                        excess[slab[q]] += lens_half / in_lens
                continue
            volume = 4.0 * half_width * half_width * height / n_points
            control = _slab_of(edges, zc + low) == _slab_of(edges, zc + high) and middle >= 0
            if control:
                excess[middle] += lens_half
            for q in range(n_points):
                if slab[q] >= 0:
                    excess[slab[q]] += (weight[q] - (0.5 if control and inside[q] else 0.0)) * volume
    return excess


@jit
def _minimum_image(delta, width):
    """The image of ``delta`` in [-width / 2, width / 2]; within a quarter width it is ``delta`` itself, which
    the formula would return too, so the division is skipped there (most pairs of a large box)."""
    if abs(delta) < 0.25 * width:
        return delta
    return delta - width * np.floor(delta / width + 0.5)
