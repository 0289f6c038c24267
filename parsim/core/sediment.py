"""Statistics of a sediment (Topić & Pöschel 2016, sections 4.1 and 5).

- :func:`filling_height`: twice the height of the centre of mass of the packing,
  2 z_cm (section 4.1, Fig. 8), each particle weighted by its volume;
- :func:`union_volume_and_height`: volume and centre-of-mass height of the union of spheres
  (a substrate's material, overlaps counted once);
- :func:`packing_fraction`, :func:`packing_fraction_profile`, :func:`packing_fractions`: the
  fraction of horizontal slabs of the box covered by the union of the spheres, for the bulk
  value (slab 0.25 h … 0.75 h) and the profile φ(z); :func:`covered_volumes` and
  :class:`SlabCover` the union's volume in each slab, from which they are made;
- :func:`sum_expansion`, :func:`exact_sum`: sums of floats, exact and then correctly rounded, so
  that a sum over parts (the ranks of a spread sediment) is the sum over the whole to the bit.

The packing fraction is the volume of the union of the spheres in a slab over the slab's
volume. The volume of each sphere in each slab is exact: the integral of π (r² − (z − z_c)²)
over the slab, spherical caps (a sphere counts with its whole horizontal extent; with periodic
sides its images wrap back in). From their sum the excess ∫ (1 − 1/c(x)) dx is subtracted,
c(x) the number of spheres covering x; it is non-zero only where spheres overlap, i.e. within
a multi-sphere particle. It is held in the caps of each sphere towards the spheres it
overlaps (:func:`parsim.core.shapes.union.overlap_caps`): a cap disjoint from the sphere's
other caps holds exactly half the lens of the two spheres, whose volume below any height is
computed to 4·10⁻¹³ of the lens (:func:`_lens_below`: Gauss–Legendre quadrature of circular segments
along the lens's axis), so its share of every slab is exact. Other caps (multiple overlaps)
are sampled by quasi-Monte Carlo (Halton points, rotated per cap by a shift drawn from the
identities of its two spheres), with the exact half lens as control variate. The sample
points of a cap depend on nothing but the cap, its spheres' keys and the number of points per
cap, so a part of the spheres (a species, a rank's particles) gets the same estimate of each
cap as the whole. Non-overlapping spheres and pairwise overlaps (rods, four rods, tripods with
spacing of 1 radius or more) are exact to round-off; for sampled caps see docs/jobs.md.

Spheres are binned in cubic cells, so the cost per sphere does not grow with the height of the
pile. The horizontal box is periodic for all kernels (sediments of rigid walls lie inside the
box, so periodic wrapping changes nothing for them).
"""

import math
from typing import NamedTuple

import numpy as np

from parsim.core.growth import with_rows
from parsim.core.jit import jit
from parsim.core.shapes.union import cap_is_pairwise, centre_of_mass_of_union, lens_volume, overlap_caps

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
# Keys of spheres made from (particle, sphere of the particle): particle * SPHERES_PER_KEY + sphere
SPHERES_PER_KEY = 1 << 24
# Gauss–Legendre nodes per piece of a lens's volume below a plane (see _lens_below): 48 give the volume
# to 4e-13 of the lens (measured against 160 nodes for 3000 random lenses and planes, and against the
# integral over z of the area of the spheres' sections' intersection to its 1e-13).
LENS_NODES = 48
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(LENS_NODES)
# splitmix64 (Steele, Lea & Flood 2014): the shift of a cap's points from its spheres' keys
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX_1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX_2 = np.uint64(0x94D049BB133111EB)
# an expansion of a sum of doubles holds at most one partial per bit of the exponent range
_MOST_PARTIALS = 2100


@jit
def sum_expansion(values):
    """The exact sum of ``values`` as a few doubles of increasing magnitude that do not overlap (Shewchuk
    1997, "Adaptive precision floating-point arithmetic", the grow-expansion of Python's ``math.fsum``).
    The expansions of parts of a set concatenated are an expansion of the whole's sum."""
    partials = np.empty(_MOST_PARTIALS)
    count = 0
    for value in values:
        x = value
        kept = 0
        for k in range(count):
            y = partials[k]
            if abs(x) < abs(y):
                x, y = y, x
            high = x + y
            low = y - (high - x)
            if low != 0.0:
                partials[kept] = low
                kept += 1
            x = high
        partials[kept] = x
        count = kept + 1
    return partials[:count].copy()


def exact_sum(*expansions) -> float:
    """The correctly rounded sum of the numbers whose exact sums the expansions (:func:`sum_expansion`)
    hold: the same bits however the numbers were split into parts."""
    return math.fsum(np.concatenate([np.asarray(e, dtype=np.float64).ravel() for e in expansions]))


def filling_height(particle_com_z, particle_volume):
    """2 z_cm, the filling height of section 4.1: z_cm = sum V_p z_p / sum V_p (sums exact, correctly rounded)."""
    z = np.asarray(particle_com_z, dtype=np.float64)
    volume = np.asarray(particle_volume, dtype=np.float64)
    if z.shape != volume.shape or z.size == 0:
        raise ValueError("particle_com_z and particle_volume must be non-empty and of the same shape")
    return 2.0 * exact_sum(sum_expansion(volume * z)) / exact_sum(sum_expansion(volume))


def union_volume_and_height(positions, radii):
    """Volume of the union of spheres (overlaps counted once) and the height of its centre of mass:
    :func:`parsim.core.shapes.union.centre_of_mass_of_union`, exact where no point lies in three spheres
    (inclusion and exclusion with the lenses in closed form), integrated on columns where more overlap."""
    centre, volume = centre_of_mass_of_union(positions, radii)
    return float(volume), float(centre[2])


def sphere_keys(particle, first_sphere):
    """Keys of spheres (:class:`SlabCover`): particle * SPHERES_PER_KEY + the sphere's place in its particle,
    from each sphere's ``particle`` and the index of its particle's first sphere ``first_sphere`` (both per
    sphere), so that a sphere has the same key in any part of a sediment it is measured in."""
    particle = np.asarray(particle, dtype=np.int64)
    place = np.arange(len(particle), dtype=np.int64) - np.asarray(first_sphere, dtype=np.int64)
    return particle * SPHERES_PER_KEY + place


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
                      overlapping=None, **options):
    """Covered fraction of each slab box × [z_low, z_high) of ``slabs`` (rows (z_low, z_high), may overlap):
    :func:`covered_volumes` over the slabs' volumes (``options``: its keys, points, mean_radius)."""
    slabs = _checked_slabs(slabs)
    area = float(np.prod(np.asarray(box_upper_xy, dtype=np.float64) - np.asarray(box_lower_xy, dtype=np.float64)))
    volumes = covered_volumes(positions, radii, box_lower_xy, box_upper_xy, slabs, samples, overlapping, **options)
    return volumes / (area * (slabs[:, 1] - slabs[:, 0]))


def covered_volumes(positions, radii, box_lower_xy, box_upper_xy, slabs, samples=DEFAULT_SAMPLES, overlapping=None,
                    keys=None, points=None, mean_radius=None):
    """Volume of the union of the spheres in each slab box × [z_low, z_high) of ``slabs`` (rows, may overlap).

    All slabs are measured in one pass over the spheres (:class:`SlabCover` on the slabs between their sorted
    edges). ``overlapping``, ``keys``, ``mean_radius``: see :class:`SlabCover`; ``points``: sample points per
    sampled cap, by default :func:`points_per_cap` of ``samples`` per slab over the caps sampled here.
    """
    slabs = _checked_slabs(slabs)
    edges = np.unique(slabs)
    cover = SlabCover(positions, radii, box_lower_xy, box_upper_xy, edges, overlapping, keys, mean_radius)
    return cover.covered(slabs, points_per_cap(samples, len(slabs), cover.sampled_caps) if points is None else points)


def points_per_cap(samples, slabs, sampled_caps) -> int:
    """Sample points per sampled cap: ``samples`` per slab for ``slabs`` slabs spread over ``sampled_caps``
    caps, within MIN_POINTS_PER_CAP … MAX_POINTS_PER_CAP."""
    if sampled_caps <= 0:
        return MIN_POINTS_PER_CAP
    return int(min(max(MIN_POINTS_PER_CAP, math.ceil(samples * slabs / sampled_caps)), MAX_POINTS_PER_CAP))


def _checked_slabs(slabs):
    slabs = np.asarray(slabs, dtype=np.float64).reshape(-1, 2)
    if len(slabs) == 0 or not np.all(slabs[:, 1] > slabs[:, 0]):
        raise ValueError(f"need z_high > z_low in every slab, got {slabs.tolist()}")
    return slabs


class CellList(NamedTuple):
    """Spheres binned in the cubic cells of :class:`_SphereGrid`, as its kernels read them: cell c holds the
    places start[c]:start[c + 1] of the grid's order; the box ``lower`` … ``upper`` is cut into cells[0] ×
    cells[1] columns in x and y, the heights from ``z_lower`` up into cells[2] layers of ``cell_height``."""

    start: np.ndarray  # (cells[0] cells[1] cells[2] + 1,) the first place of each cell in the grid's order
    lower: np.ndarray  # (2,) the box's lower corner in x and y
    upper: np.ndarray  # (2,) its upper corner
    z_lower: float  # the bottom of the lowest layer
    cell_height: float  # the layers' height: the largest diameter of the binned spheres
    cells: np.ndarray  # (3,) cells along x, y and z


class OverlapCaps(NamedTuple):
    """The caps of the spheres towards the spheres they overlap (:func:`_overlap_lists`,
    :func:`parsim.core.shapes.union.overlap_caps`), one row per cap, sphere i's caps in the rows
    first[i]:first[i + 1]; the cap of sphere i towards j is the part of S_i with (x − c_i)·u >= s."""

    centres: np.ndarray  # (n, 3) the spheres' centres c_i
    radii: np.ndarray  # (n,) their radii r_i
    keys: np.ndarray  # (n,) what each sphere is, whatever the others measured with it (:func:`sphere_keys`)
    first: np.ndarray  # (n + 1,) each sphere's first row
    neighbour: np.ndarray  # (rows,) the sphere j that sphere i overlaps
    offset: np.ndarray  # (rows, 3) c_j − c_i, the minimum image in x and y
    axis: np.ndarray  # (rows, 3) u, the unit vector from c_i towards c_j
    plane: np.ndarray  # (rows,) s = max(d − r_j, −r_i)
    distance: np.ndarray  # (rows,) d = |c_j − c_i|


class SlabCover:
    """The union of spheres in the slabs between consecutive ``edges``, prepared: the spheres' exact volumes in
    the slabs, their overlaps, and which overlap caps must be sampled (``sampled_caps`` of them).
    :meth:`volumes` gives the union's volume in each slab for a number of points per sampled cap.

    ``overlapping`` (optional, one flag per sphere): True for every sphere that may overlap another
    by more than the overlap tolerance (minimum images across the box's sides); the others are known
    to overlap none, e.g. from :func:`parsim.core.structure.contact_network`, and skip the search for
    overlaps. The result is the same as without it, which searches every sphere.
    ``keys`` (optional, int64 per sphere, default the index): what a sphere is, whatever the other
    spheres measured with it (:func:`sphere_keys`); a sampled cap's points are rotated by a shift drawn
    from its two spheres' keys. ``mean_radius``: the radius of the overlap tolerance, OVERLAP_TOLERANCE
    times it (default: the mean of ``radii``; a part of a sediment passes the whole's).
    """

    def __init__(self, positions, radii, box_lower_xy, box_upper_xy, edges, overlapping=None, keys=None,
                 mean_radius=None):
        grid = _SphereGrid(positions, radii, box_lower_xy, box_upper_xy)
        self.edges = np.ascontiguousarray(edges, dtype=np.float64)
        self.sampled_caps = 0
        self._caps = None
        if len(grid.radii) == 0:
            self._volume = np.zeros(len(self.edges) - 1)
            return
        self._volume = _sphere_slab_volumes(grid.positions, grid.radii, grid.order, self.edges)
        keys = np.arange(len(grid.radii), dtype=np.int64) if keys is None else np.asarray(keys, dtype=np.int64)
        if keys.shape != grid.radii.shape:
            raise ValueError("keys must hold one key per sphere")
        radius = float(np.mean(grid.radii[grid.order]) if mean_radius is None else mean_radius)
        if overlapping is None:
            order, cells = grid.order, grid.cell_list()
        else:
            kept = np.asarray(overlapping, dtype=bool)
            if kept.shape != grid.radii.shape:
                raise ValueError("overlapping must hold one flag per sphere")
            kept_sorted = kept[grid.order]
            if not kept_sorted.any():
                return
            order = grid.order[kept_sorted]
            # cell c holds the chosen spheres start[c]:start[c + 1] of the grid's order
            cells = grid.cell_list(np.concatenate([[0], np.cumsum(kept_sorted)])[grid.start])
        centres, radii = grid.positions[order], grid.radii[order]
        first, neighbour, offset = _overlap_lists(centres, radii, OVERLAP_TOLERANCE * radius, cells)
        if not len(neighbour):
            return
        axis, plane, distance = overlap_caps(radii, first, neighbour, offset)
        caps = OverlapCaps(centres, radii, np.ascontiguousarray(keys[order]), first, neighbour, offset, axis, plane,
                           distance)
        exact, kind = _exact_excess(caps, self.edges, _NODES, _WEIGHTS)
        self._volume = self._volume - exact
        self.sampled_caps = int(np.count_nonzero(kind))
        self._caps = (caps, kind)

    def covered(self, slabs, points):
        """The union's volume in each slab box × [z_low, z_high) of ``slabs`` (rows whose heights are among the
        edges; they may overlap): the sum of :meth:`volumes` between its edges (not a difference of cumulative
        sums, whose round-off would be that of the whole pile's volume in a nearly empty slab)."""
        slabs = _checked_slabs(slabs)
        volumes = self.volumes(points)
        low, high = np.searchsorted(self.edges, slabs[:, 0]), np.searchsorted(self.edges, slabs[:, 1])
        return np.array([volumes[a:b].sum() for a, b in zip(low, high)])

    def volumes(self, points):
        """The union's volume in each slab, the sampled caps with ``points`` points each."""
        if not self.sampled_caps:
            return self._volume.copy()
        unit = np.column_stack([_van_der_corput(int(points), base) for base in (2, 3, 5)])
        return self._volume - _sampled_excess(*self._caps, self.edges, unit, _NODES, _WEIGHTS)


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

    def cell_list(self, start=None):
        """The grid's :class:`CellList`; ``start``: the cells' first places in a part of the grid's order
        (by default the whole order's)."""
        return CellList(self.start if start is None else start, self.lower, self.upper, self.z_lower,
                        self.cell_height, self.cells)


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
def _overlap_lists(centres, radii, tolerance, grid):
    """The spheres overlapping each sphere by more than ``tolerance`` and their minimum-image offsets c_j − c_i.

    Works on the cell-sorted spheres (``centres``, ``radii``, cell c of the :class:`CellList` ``grid``
    holding start[c]:start[c+1]), cell by cell for locality; returns the CSR rows ``first`` (sphere i:
    first[i]:first[i+1]), ``neighbour`` and ``offset``.
    """
    start, cells = grid.start, grid.cells
    width = grid.upper - grid.lower
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
def _segment_below(rho, delta):
    """Area of the part of a disc of radius ``rho`` below a chord ``delta`` from its centre (signed, along the
    disc's steepest ascent): ρ² (π − arccos(δ/ρ)) + δ √(ρ² − δ²)."""
    if delta >= rho:
        return np.pi * rho * rho
    if delta <= -rho:
        return 0.0
    return rho * rho * (np.pi - np.arccos(delta / rho)) + delta * np.sqrt(rho * rho - delta * delta)


@jit
def _slices_below(h, u_z, slope, centre, radius, low, high, nodes, weights):
    """∫ over t in [low, high] of the area below the plane z = h of the slice at t of a sphere whose centre lies
    at t = ``centre`` on an axis with vertical component ``u_z`` (``slope`` = √(1 − u_z²)): the disc of radius
    ρ(t) = √(R² − (t − c)²) perpendicular to the axis, centred at height t u_z.

    The slice's area below the plane is the segment of :func:`_segment_below` at the chord δ = (h − t u_z) /
    slope (all or nothing when the axis is vertical). It is analytic in t but where the plane touches a slice,
    (h − t u_z)² = slope² ρ(t)², at t = h u_z + slope² c ± slope √(R² − (h − c u_z)²) (the slice
    through the plane when the axis is vertical), and at the ends of a sphere, where it behaves as powers
    of the square root of the distance. The interval is split at the roots inside it and each piece
    integrated by Gauss–Legendre quadrature in φ of t = a + (b − a)(1 − cos φ)/2, φ ∈ [0, π], which makes
    such square roots smooth (LENS_NODES nodes: see there for the measured accuracy).
    """
    cuts = np.empty(4)
    cuts[0] = low
    count = 1
    b = h * u_z + slope * slope * centre
    # the discriminant b² − (h² − slope² (R² − c²)) over slope²
    inner = radius * radius - (h - centre * u_z) ** 2
    if inner >= 0.0:
        root = slope * np.sqrt(inner)
        for t in (b - root, b + root):
            if low < t < high:
                cuts[count] = t
                count += 1
    cuts[count] = high
    count += 1
    total = 0.0
    for piece in range(count - 1):
        a, e = cuts[piece], cuts[piece + 1]
        if e <= a:
            continue
        half = 0.5 * (e - a)
        piece_sum = 0.0
        for q in range(len(nodes)):
            phi = 0.5 * np.pi * (nodes[q] + 1.0)
            t = a + half * (1.0 - np.cos(phi))
            rho = np.sqrt(max(radius * radius - (t - centre) ** 2, 0.0))
            rise = h - t * u_z
            if slope > 0.0:
                area = _segment_below(rho, rise / slope)
            else:
                area = np.pi * rho * rho if rise > 0.0 else 0.0
            piece_sum += weights[q] * area * np.sin(phi)
        total += 0.5 * np.pi * half * piece_sum
    return total


@jit
def _lens_below(h, r_i, r_j, d, u_z, nodes, weights):
    """Volume of the lens S_i ∩ S_j below the plane at height ``h`` above centre i (centres ``d`` apart, the
    axis from i to j of vertical component ``u_z``).

    Along the axis, t from centre i, the lens is bounded by sphere j for d − r_j <= t <= t0 and by sphere i
    for t0 <= t <= r_i, t0 = (d² + r_i² − r_j²) / 2d the plane of the spheres' meeting circle; each part is
    integrated by :func:`_slices_below`. When one sphere holds the other, the lens is the smaller sphere, and
    its volume below the plane the spherical cap.
    """
    if d <= abs(r_i - r_j):
        if r_i <= r_j:
            return _volume_below(0.0, r_i, h)
        return _volume_below(d * u_z, r_j, h)
    slope = np.sqrt(max(1.0 - u_z * u_z, 0.0))
    t0 = (d * d + r_i * r_i - r_j * r_j) / (2.0 * d)
    return (_slices_below(h, u_z, slope, d, r_j, d - r_j, t0, nodes, weights)
            + _slices_below(h, u_z, slope, 0.0, r_i, t0, r_i, nodes, weights))


@jit
def _add_lens(excess, edges, factor, zc, r_i, r_j, d, offset, u, nodes, weights):
    """Add ``factor`` times the volume of the lens of spheres i (centre height ``zc``) and j in each slab between
    ``edges`` (the parts outside the edges left out): the lens's volume below each edge inside its height range
    (:func:`_lens_below`), the whole lens (closed form) above the last."""
    low, high = _lens_z_range(offset, r_i, r_j, d, u)
    if zc + high <= edges[0] or zc + low >= edges[-1]:
        return
    k = max(np.searchsorted(edges, zc + low, side="right") - 1, 0)
    below = 0.0 if edges[k] <= zc + low else _lens_below(edges[k] - zc, r_i, r_j, d, u[2], nodes, weights)
    whole = lens_volume(r_i, r_j, d)
    while k < len(edges) - 1 and edges[k] < zc + high:
        if edges[k + 1] >= zc + high:
            above = whole
        else:
            above = _lens_below(edges[k + 1] - zc, r_i, r_j, d, u[2], nodes, weights)
        excess[k] += factor * (above - below)
        below = above
        k += 1


@jit
def _exact_excess(caps, edges, nodes, weights):
    """The exact part of the overlap excess in each slab, and which caps must be sampled.

    Every cap of sphere i towards j holds half the lens S_i ∩ S_j in the slabs it lies in (:func:`_add_lens`;
    the pair's whole lens is added once, on the side of the sphere of the lower key). For a cap disjoint from
    the sphere's other caps (:func:`parsim.core.shapes.union.cap_is_pairwise`) that is its excess: no point
    of it lies in a third sphere. For the other caps it is the control variate of :func:`_sampled_excess`,
    which samples the rest. ``caps``: :class:`OverlapCaps`; ``nodes``, ``weights``: the Gauss–Legendre rule
    of :func:`_lens_below`. Returns (excess per slab, per cap: 1 when sampled).
    """
    radii, keys, first, neighbour = caps.radii, caps.keys, caps.first, caps.neighbour
    excess = np.zeros(len(edges) - 1)
    kind = np.zeros(len(neighbour), dtype=np.int64)
    for i in range(caps.centres.shape[0]):
        r_i, zc = radii[i], caps.centres[i, 2]
        if zc + r_i <= edges[0] or zc - r_i >= edges[-1]:
            continue
        for row in range(first[i], first[i + 1]):
            j = neighbour[row]
            if keys[i] < keys[j] or (keys[i] == keys[j] and i < j):
                _add_lens(excess, edges, 1.0, zc, r_i, radii[j], caps.distance[row], caps.offset[row], caps.axis[row],
                          nodes, weights)
            if not cap_is_pairwise(row, first[i], first[i + 1], caps.axis, caps.plane, r_i):
                kind[row] = 1
    return excess, kind


@jit
def _mix(x):
    """The splitmix64 finaliser of a uint64 (Steele, Lea & Flood 2014)."""
    x = (x ^ (x >> np.uint64(30))) * _MIX_1
    x = (x ^ (x >> np.uint64(27))) * _MIX_2
    return x ^ (x >> np.uint64(31))


@jit
def _cap_shift(key_i, key_j, component):
    """A uniform number in [0, 1) drawn from the keys of a cap's two spheres (its ``component`` of three): a
    counter-based stream, splitmix64 of the keys, the same wherever the cap is measured."""
    state = _mix(_mix(np.uint64(key_i) + _GOLDEN) ^ np.uint64(key_j))
    return float(_mix(state + np.uint64(component + 1) * _GOLDEN) >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@jit
def _sampled_excess(caps, kind, edges, unit, nodes, weights):
    """Per slab, the part of the excess ∫ (1 − 1/c(x)) dx of the sampled caps (of :class:`OverlapCaps` ``caps``,
    those of ``kind`` 1) that the exact half lenses of :func:`_exact_excess` leave (c(x): spheres covering x).

    Sum of sphere volumes − excess = volume of the union. Points covered twice or more lie in
    the caps of sphere i towards its overlapping spheres. A cap is sampled with the quasi-random
    ``unit`` points (Halton) in its bounding square prism along the cap's axis, rotated modulo 1
    (Cranley–Patterson) by a shift drawn from the keys of its spheres (:func:`_cap_shift`); a point of
    S_i in m caps of i has weight w = (1 − 1/c)/m, so the caps of i together give ∫_{S_i} (1 − 1/c)
    without double counting. The exact half lens g = 1/2 on S_i ∩ S_j is the control variate: the points
    sample w − g, whose integral adds to the half lens already counted.
    """
    radii, first, neighbour = caps.radii, caps.first, caps.neighbour
    offset, axis, plane = caps.offset, caps.axis, caps.plane
    n_points = unit.shape[0]
    excess = np.zeros(len(edges) - 1)
    e1 = np.empty(3)
    e2 = np.empty(3)
    p = np.empty(3)
    for i in range(caps.centres.shape[0]):
        r_i, zc = radii[i], caps.centres[i, 2]
        for row in range(first[i], first[i + 1]):
            if kind[row] == 0:
                continue
            u, s = axis[row], plane[row]
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
            key_i, key_j = caps.keys[i], caps.keys[neighbour[row]]
            shift_a, shift_b, shift_c = _cap_shift(key_i, key_j, 0), _cap_shift(key_i, key_j, 1), _cap_shift(
                key_i, key_j, 2)
            volume = 4.0 * half_width * half_width * height / n_points
            for q in range(n_points):
                a, b, c = unit[q, 0] + shift_a, unit[q, 1] + shift_b, unit[q, 2] + shift_c
                a = a - 1.0 if a >= 1.0 else a
                b = 2.0 * (b - 1.0 if b >= 1.0 else b) - 1.0
                c = 2.0 * (c - 1.0 if c >= 1.0 else c) - 1.0
                t = s + height * a
                for x in range(3):
                    p[x] = t * u[x] + half_width * (b * e1[x] + c * e2[x])
                if p[0] * p[0] + p[1] * p[1] + p[2] * p[2] >= r_i * r_i:
                    continue
                slab = _slab_of(edges, zc + p[2])
                if slab < 0:
                    continue
                covering = 1
                in_caps = 0
                own = False
                for other in range(first[i], first[i + 1]):
                    k = neighbour[other]
                    dx, dy, dz = p[0] - offset[other, 0], p[1] - offset[other, 1], p[2] - offset[other, 2]
                    if dx * dx + dy * dy + dz * dz < radii[k] * radii[k]:
                        covering += 1
                        own = own or other == row
                    if other == row or (p[0] * axis[other, 0] + p[1] * axis[other, 1] + p[2] * axis[other, 2]
                                        >= plane[other]):
                        in_caps += 1
                weight = (1.0 - 1.0 / covering) / in_caps if covering >= 2 else 0.0
                if own:
                    weight -= 0.5
                if weight != 0.0:
                    excess[slab] += weight * volume
    return excess


@jit
def _minimum_image(delta, width):
    """The image of ``delta`` in [-width / 2, width / 2]; within a quarter width it is ``delta`` itself, which
    the formula would return too, so the division is skipped there (most pairs of a large box)."""
    if abs(delta) < 0.25 * width:
        return delta
    return delta - width * np.floor(delta / width + 0.5)
