"""Structure statistics of a finished sediment: orientational order, pair correlation, contacts.

- particle orientation: :func:`long_axis` of a particle template, :func:`rotation_matrices` and
  :func:`lab_axes` to carry it into the lab frame;
- orientational order of the long axes: :func:`nematic_order` (S and the director),
  :func:`vertical_order` (<P2(cos θ)> about z) and :func:`angle_distribution` (p(θ));
- positional order: :func:`radial_distribution`, g(r) of the particle centres in a slab, and
  :func:`region_radial_distribution` in a region of any shape;
- contact network: :func:`contact_pairs` (sphere–sphere contacts between particles and their normals),
  :func:`contacts_per_particle`, :func:`contact_number_distribution`, :func:`fabric_tensor` and
  :func:`fabric_anisotropy`.

All functions take plain numpy arrays. Boxes are periodic in x and y or not at all; z never is.
Pair searches use the cubic cell list of :mod:`parsim.core.sediment`, so they cost O(N) for a
sediment of N spheres.
"""

import numpy as np

from parsim.core.jit import jit
from parsim.core.sediment import CONTACT_GAP_TOLERANCE, _SphereGrid, _minimum_image, _neighbour_cells

# Two smallest principal moments of inertia equal within this relative tolerance: no long axis.
ISOTROPY_RTOL = 1e-6
# First guess of the number of contacts per sphere (the kissing number of equal spheres); the
# contact search runs again with the exact count when a packing has more.
CONTACTS_PER_SPHERE_GUESS = 12


def long_axis(offsets, radii):
    """Long axis of a particle template: (axis, anisotropy).

    The spheres (centres ``offsets`` (n, 3), ``radii`` (n,)) are solid spheres of one uniform
    density; overlapping volume is counted once per sphere (twice for two overlapping spheres),
    so sphere k has mass m_k ∝ R_k³. About the centre of mass c of these masses the inertia tensor
    is I = Σ_k m_k (2/5 R_k² 1 + |d_k|² 1 − d_k ⊗ d_k), d_k = offset_k − c (solid sphere plus the
    parallel-axis theorem; Goldstein, Poole & Safko, Classical Mechanics, 3rd ed. 2002, ch. 5).
    With its principal moments I_1 <= I_2 <= I_3, the long axis is the principal axis of I_1
    (the particle's mass lies closest to it), a unit vector whose component of largest magnitude
    is positive; ``anisotropy`` = 1 − I_1 / I_2, in [0, 1): 0 when the two smallest moments are
    equal, approaching 1 for a thin rod. When I_2 − I_1 <= 1e-6 I_2 (sphere, cube, spiky, a disc)
    no axis is singled out and ``axis`` is (NaN, NaN, NaN).
    """
    centres = _as_points(offsets)
    radii = np.asarray(radii, dtype=np.float64)
    if radii.shape != (len(centres),) or np.any(radii <= 0.0):
        raise ValueError("radii must be positive, one per offset")
    mass = radii**3
    d = centres - mass @ centres / mass.sum()
    inertia = (np.sum(mass * (0.4 * radii**2 + np.sum(d * d, axis=1))) * np.eye(3)
               - np.einsum("k,ki,kj->ij", mass, d, d))
    moments, axes = np.linalg.eigh(inertia)
    anisotropy = float(1.0 - moments[0] / moments[1])
    if anisotropy <= ISOTROPY_RTOL:
        return np.full(3, np.nan), anisotropy
    return _positive_sign(axes[:, 0]), anisotropy


def rotation_matrices(quaternions):
    """Rotation matrices R(q) (n, 3, 3) of quaternions q = (w, x, y, z) (n, 4), body → lab.

    q is normalised first; a body vector v maps to the lab vector R(q) v = q v q* (Hamilton
    product, v a pure quaternion; J. B. Kuipers, Quaternions and Rotation Sequences, 1999).
    """
    q = np.asarray(quaternions, dtype=np.float64).reshape(-1, 4)
    w, x, y, z = (q / np.linalg.norm(q, axis=1)[:, None]).T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=1)


def lab_axes(quaternions, body_axis):
    """Lab-frame unit vectors R(q) a (n, 3) of the body axis ``a`` of particles rotated by ``quaternions``."""
    axis = np.asarray(body_axis, dtype=np.float64)
    if axis.shape != (3,) or not np.all(np.isfinite(axis)) or not np.any(axis):
        raise ValueError(f"body_axis must be a finite non-zero 3-vector, got {axis}")
    return rotation_matrices(quaternions) @ (axis / np.linalg.norm(axis))


def nematic_order(axes):
    """Nematic order parameter S and director of unsigned axes ``axes`` (n, 3): (S, director).

    Q = <3/2 u ⊗ u − 1/2 1> over the unit axes u (the tensor order parameter of de Gennes & Prost,
    The Physics of Liquid Crystals, 2nd ed. 1993, ch. 2); S is its largest eigenvalue and the
    director its eigenvector (component of largest magnitude positive). S = 1 when all axes are
    parallel, 1/4 for axes isotropic in a plane and 0 for isotropic axes; a finite isotropic sample
    of n axes has S ~ 1/sqrt(n).
    """
    u = _as_unit_vectors(axes)
    q = 1.5 * (u.T @ u) / len(u) - 0.5 * np.eye(3)
    values, vectors = np.linalg.eigh(q)
    return float(values[-1]), _positive_sign(vectors[:, -1])


def vertical_order(axes):
    """<P2(cos θ)> = <3/2 cos² θ − 1/2>, θ the angle of each axis to the vertical z.

    The scalar order parameter about a fixed axis, here z (de Gennes & Prost 1993, ch. 2): 1 when
    all axes are vertical, −1/2 when all are horizontal, 0 for isotropic axes.
    """
    u = _as_unit_vectors(axes)
    return float(np.mean(1.5 * u[:, 2] ** 2 - 0.5))


def angle_distribution(axes, bins):
    """Probability density p(θ) of the angle θ ∈ [0, π/2] between the unsigned axes and z: (edges, density).

    θ = arccos |u_z|; ``bins`` bins uniform in θ, ``density`` (bins,) integrates to 1 over θ.
    Isotropic axes cover the unit sphere uniformly, whose area element is sin θ dθ dφ, so they give
    p(θ) = sin θ.
    """
    u = _as_unit_vectors(axes)
    theta = np.arccos(np.minimum(np.abs(u[:, 2]), 1.0))
    density, edges = np.histogram(theta, bins=bins, range=(0.0, 0.5 * np.pi), density=True)
    return edges, density


def radial_distribution(centres, box_lower_xy, box_upper_xy, periodic, z_low, z_high, r_max, bins,
                        max_references=None):
    """Radial distribution function g(r) of the particle centres in a slab: (r, g, number of references).

    The region V is the box (lateral extent ``box_lower_xy`` … ``box_upper_xy``) × [z_low, z_high),
    holding N_V centres, density ρ = N_V / |V|. Reference centres lie in V at least ``r_max`` from its
    faces: z_low + r_max <= z < z_high − r_max and, unless the box is ``periodic`` in x and y, at
    least r_max from each lateral wall. Every reference's sphere of radius r_max thus lies in V, so
    the density of its neighbours is sampled where ρ is measured. Neighbours are all other centres
    (the minimum image in x and y when periodic, which needs r_max <= half the box width).
    In ``bins`` shells r_1 <= r < r_2 uniform on [0, r_max),
        g = n(r_1, r_2) / (N_ref ρ 4/3 π (r_2³ − r_1³)),
    n the number of (reference, neighbour) pairs at those distances: the histogram estimator of
    Allen & Tildesley, Computer Simulation of Liquids, 2nd ed. 2017, sec. 2.6 and 8.2, which gives
    g = 1 − 1/N_V for N_V uniform random points. ``r`` are the bin centres; g is NaN without references.
    With ``max_references``, at most that many references are used, evenly spread over the
    candidates in index order (the estimator is unchanged, its noise grows as 1/sqrt(N_ref)).
    """
    x = _as_points(centres)
    lower, upper = np.asarray(box_lower_xy, dtype=np.float64), np.asarray(box_upper_xy, dtype=np.float64)
    if not z_high > z_low:
        raise ValueError(f"need z_high > z_low, got {z_low}, {z_high}")
    in_region = _in_box(x, lower, upper, periodic, z_low, z_high, 0.0)
    reference = np.flatnonzero(_in_box(x, lower, upper, periodic, z_low, z_high, r_max))
    return region_radial_distribution(x, in_region, np.prod(upper - lower) * (z_high - z_low), reference, r_max,
                                      bins, lower, upper, periodic, max_references)


def region_radial_distribution(centres, in_region, region_volume, reference, r_max, bins, box_lower_xy,
                               box_upper_xy, periodic, max_references=None):
    """g(r) of the centres in a region of any shape: (r, g, number of references).

    The estimator of :func:`radial_distribution` for a region given by the mask ``in_region`` of
    the N_V centres it holds and its volume ``region_volume`` (ρ = N_V / volume), and the indices
    ``reference`` of the reference centres, which the caller chooses at least ``r_max`` inside the
    region (e.g. within a disc shrunk by r_max). The box (``box_lower_xy`` … ``box_upper_xy``) lays
    out the cell list and, when ``periodic`` in x and y, gives the minimum images.
    """
    x = _as_points(centres)
    lower, upper = np.asarray(box_lower_xy, dtype=np.float64), np.asarray(box_upper_xy, dtype=np.float64)
    if not (r_max > 0.0 and bins >= 1 and region_volume > 0.0):
        raise ValueError(f"need r_max > 0, bins >= 1 and a region of positive volume, got {r_max}, {bins}, "
                         f"{region_volume}")
    if periodic and r_max > 0.5 * np.min(upper - lower):
        raise ValueError(f"r_max = {r_max} exceeds half the periodic box width {upper - lower}")
    reference = np.asarray(reference, dtype=np.int64)
    if max_references is not None and len(reference) > max_references:
        reference = reference[np.linspace(0, len(reference) - 1, max_references).astype(np.int64)]
    edges = np.linspace(0.0, r_max, bins + 1)
    r = 0.5 * (edges[1:] + edges[:-1])
    if len(reference) == 0:
        return r, np.full(bins, np.nan), 0
    grid = _SphereGrid(x, np.full(len(x), 0.5 * r_max), lower, upper)  # cells at least r_max wide
    _, _, order, start, _, _, z_lower, cell_height, cells = grid.arrays()
    counts = _shell_counts(x, reference, r_max, bins, bool(periodic), order, start, lower, upper, z_lower,
                           cell_height, cells)
    density = np.count_nonzero(in_region) / region_volume
    shell = 4.0 / 3.0 * np.pi * (edges[1:] ** 3 - edges[:-1] ** 3)
    return r, counts / (len(reference) * density * shell), len(reference)


def contact_pairs(positions, radii, particle, box_lower_xy, box_upper_xy, periodic):
    """Sphere–sphere contacts between different particles: (pairs, normals).

    Spheres i and j (centres ``positions`` (n, 3), ``radii`` (n,), owned by ``particle`` (n,)) touch
    when particle[i] != particle[j] and their gap |x_j − x_i| − R_i − R_j is below
    ``CONTACT_GAP_TOLERANCE`` times the mean radius (the criterion of
    :func:`coordination`). ``pairs`` (m, 2) holds each contact once as sphere
    indices i < j, sorted; ``normals`` (m, 3) the unit vectors from sphere i to sphere j. With
    ``periodic`` sides x_j − x_i is the minimum image in x and y (box widths must exceed twice the
    largest diameter); without, the box bounds only lay out the cell list and may be the extent of
    the spheres (lateral walls, a heap).
    """
    x = _as_points(positions)
    radii = np.ascontiguousarray(radii, dtype=np.float64)
    particle = np.ascontiguousarray(particle, dtype=np.int64)
    if radii.shape != (len(x),) or particle.shape != (len(x),):
        raise ValueError("radii and particle must hold one entry per sphere")
    width = np.asarray(box_upper_xy, dtype=np.float64) - np.asarray(box_lower_xy, dtype=np.float64)
    if periodic and np.any(width < 4.0 * radii.max()):
        raise ValueError(f"periodic box widths {width} must exceed twice the largest diameter")
    tolerance = CONTACT_GAP_TOLERANCE * float(np.mean(radii))
    grid = _SphereGrid(x, radii + 0.5 * tolerance, box_lower_xy, box_upper_xy)  # cells span R_i + R_j + tolerance
    _, _, order, start, lower, upper, z_lower, cell_height, cells = grid.arrays()
    capacity = CONTACTS_PER_SPHERE_GUESS * len(x)
    while True:
        pairs, normals = np.empty((capacity, 2), dtype=np.int64), np.empty((capacity, 3))
        count = _contacts(x, radii, particle, tolerance, bool(periodic), pairs, normals, order, start, lower,
                          upper, z_lower, cell_height, cells)
        if count <= capacity:
            break
        capacity = count
    ranked = np.lexsort((pairs[:count, 1], pairs[:count, 0]))
    return pairs[ranked], normals[ranked]


def coordination(positions, radii, particle, particle_com_z, box_lower_xy, box_upper_xy, z_low, z_high,
                 periodic=True):
    """Mean number of sphere–sphere contacts with other particles, over particles with z_low <= z_cm < z_high.

    The contacts of :func:`contact_pairs` (periodic in x and y unless ``periodic`` is False).
    Returns (mean, number of particles averaged over); the mean is NaN when the slab holds no particle.
    """
    pairs, _ = contact_pairs(positions, radii, particle, box_lower_xy, box_upper_xy, periodic)
    per_particle = sphere_contacts_per_particle(pairs, particle, len(particle_com_z))
    com_z = np.asarray(particle_com_z)
    selected = (com_z >= z_low) & (com_z < z_high)
    count = int(selected.sum())
    return (float(per_particle[selected].mean()) if count else float("nan")), count


def sphere_contacts_per_particle(pairs, particle, n_particles):
    """Sphere–sphere contacts of each particle (n_particles,) with other particles: a contact of
    :func:`contact_pairs` counts once for each of its two particles."""
    owners = np.asarray(particle, dtype=np.int64)[np.asarray(pairs, dtype=np.int64).reshape(-1, 2)]
    return np.bincount(owners.ravel(), minlength=n_particles)


def contacts_per_particle(pairs, particle, n_particles):
    """Contact number Z of each particle (n_particles,): the number of distinct particles it touches.

    Several sphere contacts between the same two particles (a rod lying across two spheres of
    another) count once, as one touching neighbour; :func:`sphere_contacts_per_particle`
    counts every sphere–sphere contact. ``pairs`` are sphere index pairs of
    :func:`contact_pairs`, ``particle`` maps spheres to particles 0 … n_particles − 1.
    """
    owners = np.sort(np.asarray(particle, dtype=np.int64)[np.asarray(pairs, dtype=np.int64).reshape(-1, 2)], axis=1)
    touching = np.unique(owners[:, 0] * n_particles + owners[:, 1])  # each pair of particles once
    return np.bincount(touching // n_particles, minlength=n_particles) + np.bincount(touching % n_particles,
                                                                                      minlength=n_particles)


def contact_number_distribution(counts, selected, max_count):
    """P(Z), the fraction of the ``selected`` particles with contact number Z = 0 … max_count (max_count + 1,).

    ``counts`` from :func:`contacts_per_particle`, ``selected`` a boolean mask or index array of
    particles (e.g. those whose centre lies in the bulk). Particles with Z > max_count are in no
    entry, so the fractions then sum to less than 1. NaN when no particle is selected. The contact
    number distribution of Aste, Saadatfar & Senden, Phys. Rev. E 71, 061302 (2005), sec. V.
    """
    chosen = np.asarray(counts, dtype=np.int64)[selected]
    if chosen.size == 0:
        return np.full(max_count + 1, np.nan)
    return np.bincount(chosen, minlength=max_count + 1)[:max_count + 1] / chosen.size


def fabric_tensor(normals):
    """Fabric tensor F = <n ⊗ n> (3, 3) of the contact normals ``normals`` (m, 3); NaN without contacts.

    The second-order fabric tensor of Satake (1982), "Fabric tensor in granular materials",
    IUTAM Symp. Deformation and Failure of Granular Materials, pp. 63–68, and Oda (1982), "Fabric
    tensor for discontinuous geometric materials", Soils and Foundations 22(4), 96–108. The normals
    are made unit vectors; their sign does not matter. trace F = 1, and isotropic normals give
    F = 1/3 (see :func:`fabric_anisotropy`). To describe the contacts of a set of particles, pass
    the normals of their contacts, once per contact and particle of the set.
    """
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    if len(n) == 0:
        return np.full((3, 3), np.nan)
    n = n / np.linalg.norm(n, axis=1)[:, None]
    return n.T @ n / len(n)


def fabric_anisotropy(fabric):
    """Largest eigenvalue of the deviator F − (trace F / 3) 1 of a fabric tensor F.

    0 for isotropic normals (F = 1/3), 2/3 when all normals are parallel, 1/6 when they are
    isotropic in a plane. F − 1/3 = 2/3 Q of the normals, Q as in :func:`nematic_order`.
    """
    f = np.asarray(fabric, dtype=np.float64)
    return float(np.linalg.eigvalsh(f - np.trace(f) / 3.0 * np.eye(3))[-1])


def _as_points(points):
    x = np.ascontiguousarray(points, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != 3 or len(x) == 0:
        raise ValueError(f"need a non-empty array of shape (n, 3), got shape {x.shape}")
    return x


def _as_unit_vectors(vectors):
    u = _as_points(vectors)
    length = np.linalg.norm(u, axis=1)
    if not np.all(np.isfinite(length) & (length > 0.0)):
        raise ValueError("axes must be finite and non-zero")
    return u / length[:, None]


def _positive_sign(vector):
    """``vector`` or −``vector``, whichever has its component of largest magnitude positive."""
    return vector if vector[np.argmax(np.abs(vector))] > 0.0 else -vector


def _in_box(x, lower, upper, periodic, z_low, z_high, margin):
    """Points at least ``margin`` inside the slab [z_low, z_high) and, unless ``periodic``, inside the lateral box."""
    inside = (x[:, 2] >= z_low + margin) & (x[:, 2] < z_high - margin)
    if not periodic:
        inside &= np.all((x[:, :2] >= lower + margin) & (x[:, :2] <= upper - margin), axis=1)
    return inside


@jit
def _separation(positions, i, j, width, periodic):
    """x_j − x_i, the minimum image in x and y when ``periodic``."""
    dx = positions[j, 0] - positions[i, 0]
    dy = positions[j, 1] - positions[i, 1]
    if periodic:
        dx, dy = _minimum_image(dx, width[0]), _minimum_image(dy, width[1])
    return dx, dy, positions[j, 2] - positions[i, 2]


@jit
def _shell_counts(centres, reference, r_max, bins, periodic, order, start, lower, upper, z_lower, cell_height,
                  cells):
    """Histogram of the distances r < r_max from the ``reference`` centres to all other centres."""
    width = upper - lower
    around = np.empty(27, dtype=np.int64)
    counts = np.zeros(bins, dtype=np.int64)
    for i in reference:
        n_cells = _neighbour_cells(centres[i, 0], centres[i, 1], centres[i, 2], lower, width, z_lower, cell_height,
                                   cells, around)
        for c in range(n_cells):
            for k in range(start[around[c]], start[around[c] + 1]):
                j = order[k]
                if j == i:
                    continue
                dx, dy, dz = _separation(centres, i, j, width, periodic)
                distance_squared = dx * dx + dy * dy + dz * dz
                if distance_squared < r_max * r_max:
                    counts[min(int(np.sqrt(distance_squared) / r_max * bins), bins - 1)] += 1
    return counts


@jit
def _contacts(positions, radii, particle, tolerance, periodic, pairs, normals, order, start, lower, upper, z_lower,
              cell_height, cells):
    """Fill ``pairs`` and ``normals`` with the contacts i < j (as far as they hold); return how many there are."""
    width = upper - lower
    around = np.empty(27, dtype=np.int64)
    count = 0
    for i in range(positions.shape[0]):
        n_cells = _neighbour_cells(positions[i, 0], positions[i, 1], positions[i, 2], lower, width, z_lower,
                                   cell_height, cells, around)
        for c in range(n_cells):
            for k in range(start[around[c]], start[around[c] + 1]):
                j = order[k]
                if j <= i or particle[j] == particle[i]:
                    continue
                dx, dy, dz = _separation(positions, i, j, width, periodic)
                distance = np.sqrt(dx * dx + dy * dy + dz * dz)
                if distance - radii[i] - radii[j] < tolerance:
                    if count < len(pairs):
                        pairs[count, 0], pairs[count, 1] = i, j
                        normals[count, 0], normals[count, 1], normals[count, 2] = (dx / distance, dy / distance,
                                                                                   dz / distance)
                    count += 1
    return count
