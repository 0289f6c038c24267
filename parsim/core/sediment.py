"""Statistics of a sediment (Topić & Pöschel 2016, sections 4.1 and 5).

- :func:`filling_height`: twice the height of the centre of mass of the packing,
  2 z_cm (section 4.1, Fig. 8), each particle weighted by its volume;
- :func:`packing_fraction`: the fraction of a horizontal slab of the box covered by
  the union of the spheres, and with it the bulk value (slab 0.25 h … 0.75 h) and the
  profile φ(z);
- :func:`coordination`: sphere–sphere contacts between different particles, per
  particle whose centre of mass lies in a slab.

The packing fraction is measured by quasi-Monte Carlo: the slab is sampled with a
Halton sequence (bases 2, 3, 5) and each point is tested against the spheres near it.
Unlike summing sphere volumes it counts the overlaps inside a multi-sphere particle
once, and it is deterministic. With n points the error is close to 1/n (not the
1/sqrt(n) of random sampling); the default 2·10^5 points per slab give about 10^-4.

Spheres are binned in cubic cells, so the cost per point or sphere does not grow with
the height of the pile. The horizontal box is periodic for both kernels (sediments of rigid walls lie inside
the box, so periodic wrapping changes nothing for them).
"""

import numpy as np

from parsim.core.jit import jit

# Two spheres of different particles are in contact when their gap is below this
# fraction of the mean radius: the solver closes contacts to ~1e-12, and the paper's
# cycling interruption leaves clearances of ~1e-8 (section 4.2).
CONTACT_GAP_TOLERANCE = 1e-6
DEFAULT_SAMPLES = 200_000


def filling_height(particle_com_z, particle_volume):
    """2 z_cm, the filling height of section 4.1: z_cm = sum V_p z_p / sum V_p."""
    z = np.asarray(particle_com_z, dtype=np.float64)
    volume = np.asarray(particle_volume, dtype=np.float64)
    if z.shape != volume.shape or z.size == 0:
        raise ValueError("particle_com_z and particle_volume must be non-empty and of the same shape")
    return 2.0 * float(np.dot(volume, z) / volume.sum())


def packing_fraction(positions, radii, box_lower_xy, box_upper_xy, z_low, z_high, samples=DEFAULT_SAMPLES):
    """Fraction of the slab box × [z_low, z_high) covered by the union of the spheres."""
    if not z_high > z_low:
        raise ValueError(f"need z_high > z_low, got {z_low}, {z_high}")
    grid = _SphereGrid(positions, radii, box_lower_xy, box_upper_xy)
    points = _halton_points(samples, grid.lower, grid.upper, z_low, z_high)
    return float(_covered_count(points, *grid.arrays()) / samples)


def packing_fraction_profile(positions, radii, box_lower_xy, box_upper_xy, z_edges, samples=DEFAULT_SAMPLES):
    """φ(z) in the slabs between consecutive ``z_edges``, each sampled with ``samples`` points."""
    grid = _SphereGrid(positions, radii, box_lower_xy, box_upper_xy)
    counts = np.empty(len(z_edges) - 1)
    for k in range(len(z_edges) - 1):
        points = _halton_points(samples, grid.lower, grid.upper, z_edges[k], z_edges[k + 1])
        counts[k] = _covered_count(points, *grid.arrays())
    return counts / samples


def coordination(positions, radii, particle, particle_com_z, box_lower_xy, box_upper_xy, z_low, z_high):
    """Mean number of sphere–sphere contacts with other particles, over particles with z_low <= z_cm < z_high.

    A contact is a pair of spheres of different particles whose gap |x_i − x_j| − R_i − R_j
    is below ``CONTACT_GAP_TOLERANCE`` times the mean radius.  Returns (mean, number of
    particles averaged over); the mean is NaN when the slab holds no particle.
    """
    grid = _SphereGrid(positions, radii, box_lower_xy, box_upper_xy)
    tolerance = CONTACT_GAP_TOLERANCE * float(np.mean(radii))
    per_particle = _contacts_per_particle(grid.positions, grid.radii, np.asarray(particle, dtype=np.int64),
                                          len(particle_com_z), tolerance, *grid.arrays()[2:])
    com_z = np.asarray(particle_com_z)
    selected = (com_z >= z_low) & (com_z < z_high)
    count = int(selected.sum())
    return (float(per_particle[selected].mean()) if count else float("nan")), count


class _SphereGrid:
    """Spheres binned in cubic cells (side >= the largest diameter), periodic in x and y.

    Cells are 3D, so a query costs the same at any depth of the pile.
    """

    def __init__(self, positions, radii, box_lower_xy, box_upper_xy):
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
        cell = _cell_index(self.positions, self.lower, width, self.z_lower, reach, self.cells)
        self.order = np.argsort(cell, kind="stable")
        self.start = np.searchsorted(cell[self.order], np.arange(np.prod(self.cells) + 1))

    def arrays(self):
        return (self.positions[self.order], self.radii[self.order], self.order, self.start,
                self.lower, self.upper, self.z_lower, self.cell_height, self.cells)


def _cell_index(positions, lower, width, z_lower, cell_height, cells):
    ij = np.floor((positions[:, :2] - lower) / width * cells[:2]).astype(np.int64) % cells[:2]
    k = np.clip(np.floor((positions[:, 2] - z_lower) / cell_height).astype(np.int64), 0, cells[2] - 1)
    return (ij[:, 0] * cells[1] + ij[:, 1]) * cells[2] + k


def _halton_points(n, lower_xy, upper_xy, z_low, z_high):
    unit = np.column_stack([_van_der_corput(n, base) for base in (2, 3, 5)])
    lower = np.array([lower_xy[0], lower_xy[1], z_low])
    upper = np.array([upper_xy[0], upper_xy[1], z_high])
    return lower + unit * (upper - lower)


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
def _neighbour_cells(x, y, z, lower, width, z_lower, cell_height, cells, out):
    """Fill ``out`` with the distinct cells around the point (periodic in x, y); return how many."""
    ci = int(np.floor((x - lower[0]) / width[0] * cells[0])) % cells[0]
    cj = int(np.floor((y - lower[1]) / width[1] * cells[1])) % cells[1]
    ck = int(np.floor((z - z_lower) / cell_height))
    count = 0
    for a in range(min(3, cells[0])):
        i = (ci - 1 + a) % cells[0] if cells[0] >= 3 else a
        for b in range(min(3, cells[1])):
            j = (cj - 1 + b) % cells[1] if cells[1] >= 3 else b
            for k in range(max(ck - 1, 0), min(ck + 2, cells[2])):
                out[count] = (i * cells[1] + j) * cells[2] + k
                count += 1
    return count


@jit
def _covered_count(points, centres, radii, order, start, lower, upper, z_lower, cell_height, cells):
    width = upper - lower
    neighbours = np.empty(27, dtype=np.int64)
    covered = 0
    for p in range(points.shape[0]):
        x, y, z = points[p, 0], points[p, 1], points[p, 2]
        n_cells = _neighbour_cells(x, y, z, lower, width, z_lower, cell_height, cells, neighbours)
        found = False
        for c in range(n_cells):
            for k in range(start[neighbours[c]], start[neighbours[c] + 1]):
                dx = _minimum_image(x - centres[k, 0], width[0])
                dy = _minimum_image(y - centres[k, 1], width[1])
                dz = z - centres[k, 2]
                if dx * dx + dy * dy + dz * dz < radii[k] * radii[k]:
                    found = True
                    break
            if found:
                break
        if found:
            covered += 1
    return covered


@jit
def _contacts_per_particle(positions, radii, particle, n_particles, tolerance, order, start, lower, upper,
                           z_lower, cell_height, cells):
    width = upper - lower
    neighbours = np.empty(27, dtype=np.int64)
    contacts = np.zeros(n_particles)
    for i in range(positions.shape[0]):
        n_cells = _neighbour_cells(positions[i, 0], positions[i, 1], positions[i, 2], lower, width, z_lower,
                                   cell_height, cells, neighbours)
        for c in range(n_cells):
            for k in range(start[neighbours[c]], start[neighbours[c] + 1]):
                j = order[k]
                if particle[j] == particle[i]:
                    continue
                dx = _minimum_image(positions[i, 0] - positions[j, 0], width[0])
                dy = _minimum_image(positions[i, 1] - positions[j, 1], width[1])
                dz = positions[i, 2] - positions[j, 2]
                if np.sqrt(dx * dx + dy * dy + dz * dz) - radii[i] - radii[j] < tolerance:
                    contacts[particle[i]] += 1.0
    return contacts


@jit
def _minimum_image(delta, width):
    return delta - width * np.floor(delta / width + 0.5)
