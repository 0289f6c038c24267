"""Structure statistics of a finished sediment: orientational order, pair correlation, contacts.

- particle orientation: :func:`long_axis` of a particle template, :func:`rotation_matrices` and
  :func:`lab_axes` to carry it into the lab frame;
- orientational order of the long axes: :func:`nematic_order` (S and the director),
  :func:`vertical_order` (<P2(cos θ)> about z) and :func:`angle_distribution` (p(θ));
- positional order: :func:`radial_distribution`, g(r) of the particle centres in a slab, and
  :func:`region_radial_distribution` in a region of any shape;
- contact network: :func:`contact_pairs` (sphere–sphere contacts between particles and their normals;
  :func:`contact_network` adds the spheres that overlap, from the same search),
  :func:`contacts_per_particle`, :func:`contact_number_distribution`, :func:`fabric_tensor` and
  :func:`fabric_anisotropy`.

All functions take plain numpy arrays. Boxes are periodic in x and y or not at all; z never is.
Pair searches use the cubic cell list of :mod:`parsim.core.sediment`, so they cost O(N) for a
sediment of N spheres.
"""

from typing import NamedTuple

import numpy as np

from parsim.core.growth import with_rows
from parsim.core.jit import jit
from parsim.core.sediment import (CONTACT_GAP_TOLERANCE, OVERLAP_TOLERANCE, _columns_around, _SphereGrid,
                                  _minimum_image)

# Two smallest principal moments of inertia equal within this relative tolerance: no long axis.
ISOTROPY_RTOL = 1e-6
# First guess of the number of contacts per sphere, each contact counted once: about 3 in a random
# packing of equal spheres (coordination 6); the contact search doubles its list when a packing has
# more (6 in a crystal of 12 neighbours).
CONTACTS_PER_SPHERE_GUESS = 4
# g(r)'s cell list has cells of r_max / RDF_CELLS_PER_RANGE or more, and a reference centre scans
# 2 RDF_CELLS_PER_RANGE + 1 cells along each axis: with 2 the scanned volume is 3.7 times the
# sphere of radius r_max (6.4 times with cells of r_max).
RDF_CELLS_PER_RANGE = 2


class ContactNetwork(NamedTuple):
    """The sphere contacts of a packing and the spheres that overlap others (:func:`contact_network`)."""

    pairs: np.ndarray  # (m, 2) sphere indices i < j of each contact between particles, sorted
    normals: np.ndarray  # (m, 3) unit vectors from sphere i to sphere j
    overlapping: np.ndarray  # (n,) bool: the sphere may overlap another by the packing's overlap tolerance


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
    values, vectors = np.linalg.eigh(order_tensor(u.T @ u, len(u)))
    return float(values[-1]), _positive_sign(vectors[:, -1])


def order_tensor(second_moment, count):
    """Q = 3/2 <u ⊗ u> − 1/2 1 of ``count`` unit axes from their second moment, the sum of u ⊗ u."""
    return 1.5 * np.asarray(second_moment, dtype=np.float64) / count - 0.5 * np.eye(3)


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
    edges, counts = angle_histogram(axes, bins)
    return edges, counts / np.diff(edges) / counts.sum()  # numpy's density, from the counts


def angle_histogram(axes, bins):
    """The counts of :func:`angle_distribution`'s bins: (edges, counts), so that the counts of parts of a
    set of axes add up to the whole set's."""
    u = _as_unit_vectors(axes)
    theta = np.arccos(np.minimum(np.abs(u[:, 2]), 1.0))
    counts, edges = np.histogram(theta, bins=bins, range=(0.0, 0.5 * np.pi))
    return edges, counts


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
    out the cell list and, when ``periodic`` in x and y, gives the minimum images: the pairs of
    :func:`shell_counts`, normalised by :func:`shell_density`.
    """
    if not region_volume > 0.0:
        raise ValueError(f"need a region of positive volume, got {region_volume}")
    reference = np.asarray(reference, dtype=np.int64)
    if max_references is not None and len(reference) > max_references:
        reference = reference[evenly_spaced(len(reference), max_references)]
    counts = shell_counts(centres, reference, r_max, bins, box_lower_xy, box_upper_xy, periodic)
    edges = np.linspace(0.0, r_max, bins + 1)
    return (0.5 * (edges[1:] + edges[:-1]), shell_density(counts, len(reference), np.count_nonzero(in_region),
                                                          region_volume, r_max), len(reference))


def shell_density(counts, references, n_region, region_volume, r_max):
    """g(r) of pair ``counts`` in shells uniform on [0, ``r_max``) about ``references`` centres, in a region of
    ``n_region`` centres and volume ``region_volume``: n / (N_ref ρ 4/3 π (r_2³ − r_1³)), ρ = N_V / V
    (Allen & Tildesley 2017, sec. 2.6); NaN without references."""
    counts = np.asarray(counts)
    if references == 0:
        return np.full(len(counts), np.nan)
    edges = np.linspace(0.0, r_max, len(counts) + 1)
    shell = 4.0 / 3.0 * np.pi * (edges[1:] ** 3 - edges[:-1] ** 3)
    return counts / (references * (n_region / region_volume) * shell)


def shell_counts(centres, reference, r_max, bins, box_lower_xy, box_upper_xy, periodic, period=None):
    """Histogram (bins,) of the distances r < ``r_max`` from the ``reference`` centres (indices) to all other
    ``centres``, in ``bins`` shells uniform on [0, r_max).

    The box (``box_lower_xy`` … ``box_upper_xy``) lays out the cell list. ``periodic``: distances are minimum
    images in x and y, over the box's widths or, when the box is a window of a wider periodic domain, over
    ``period`` (its widths; centres outside the window by whole periods are wrapped into it for the cell list,
    every reference's neighbours within r_max must lie in the window). A distance is computed from the
    centres as given, x_j − x_i then its minimum image, so that the same pair gives the same bits in any
    window (a pair at a shell's edge, as touching spheres are at 1 diameter, counts in the same shell).
    """
    x = _as_points(centres)
    lower, upper = np.asarray(box_lower_xy, dtype=np.float64), np.asarray(box_upper_xy, dtype=np.float64)
    if not (r_max > 0.0 and bins >= 1):
        raise ValueError(f"need r_max > 0 and bins >= 1, got {r_max}, {bins}")
    width = upper - lower if period is None else np.asarray(period, dtype=np.float64)
    if periodic and r_max > 0.5 * np.min(np.minimum(width, upper - lower)):
        raise ValueError(f"r_max = {r_max} exceeds half the periodic box width {upper - lower}")
    reference = np.asarray(reference, dtype=np.int64)
    if len(reference) == 0:
        return np.zeros(bins, dtype=np.int64)
    placed = x
    if periodic and period is not None:
        placed = x.copy()
        for axis in range(2):
            out = (x[:, axis] < lower[axis]) | (x[:, axis] >= upper[axis])
            placed[out, axis] = lower[axis] + np.mod(x[out, axis] - lower[axis], width[axis])
    # Only centres within r_max of a reference's height can be counted: the cell list holds those (with a
    # margin, so that round-off cannot leave one out), sorted by cell, so that a reference scans contiguous runs
    z = x[:, 2]
    reach = 1.001 * r_max
    nearby = np.flatnonzero((z >= z[reference].min() - reach) & (z <= z[reference].max() + reach))
    grid = _SphereGrid(placed[nearby], np.full(len(nearby), 0.5 * r_max / RDF_CELLS_PER_RANGE), lower, upper)
    sorted_index = np.full(len(x), -1, dtype=np.int64)  # a centre's place in the cell list
    sorted_index[nearby[grid.order]] = np.arange(len(grid.order))
    return _shell_counts(grid.positions[grid.order], np.ascontiguousarray(x[nearby[grid.order]]),
                         sorted_index[reference], r_max, bins, bool(periodic), width, grid.cell_list(),
                         RDF_CELLS_PER_RANGE)


def evenly_spaced(n, most):
    """The places of ``most`` entries spread evenly over a list of ``n`` (first and last included): the
    reference centres g(r) keeps of more than it needs."""
    return np.linspace(0, n - 1, most).astype(np.int64)


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
    network = contact_network(positions, radii, particle, box_lower_xy, box_upper_xy, periodic)
    return network.pairs, network.normals


def contact_network(positions, radii, particle, box_lower_xy, box_upper_xy, periodic, mean_radius=None):
    """The contacts of :func:`contact_pairs` and, from the same search, the spheres that overlap:
    :class:`ContactNetwork` (pairs, normals, overlapping).  The contact tolerance is
    CONTACT_GAP_TOLERANCE times ``mean_radius`` (default: the mean of ``radii``; a part of a sediment
    passes the whole sediment's).

    ``overlapping`` flags each sphere that overlaps another, of any particle, by more than half the
    overlap tolerance of :mod:`parsim.core.sediment` times the smallest radius,
    |x_j − x_i| < R_i + R_j − OVERLAP_TOLERANCE min R / 2, with minimum images in x and y whether
    or not the contacts are ``periodic`` (the packing kernels take the box as periodic). The
    packing fraction searches overlaps beyond OVERLAP_TOLERANCE times a mean radius, so the
    spheres not flagged overlap nothing it counts (``overlapping`` of
    :func:`parsim.core.sediment.packing_fractions`), for these spheres or any subset of them.
    """
    x = _as_points(positions)
    radii = np.ascontiguousarray(radii, dtype=np.float64)
    particle = np.ascontiguousarray(particle, dtype=np.int64)
    if radii.shape != (len(x),) or particle.shape != (len(x),):
        raise ValueError("radii and particle must hold one entry per sphere")
    width = np.asarray(box_upper_xy, dtype=np.float64) - np.asarray(box_lower_xy, dtype=np.float64)
    if periodic and np.any(width < 4.0 * radii.max()):
        raise ValueError(f"periodic box widths {width} must exceed twice the largest diameter")
    tolerance = CONTACT_GAP_TOLERANCE * float(np.mean(radii) if mean_radius is None else mean_radius)
    overlap_cut = 0.5 * OVERLAP_TOLERANCE * float(radii.min())
    # cells span R_i + R_j + tolerance; layer by layer, the order in which a sediment was deposited, about
    grid = _SphereGrid(x, radii + 0.5 * tolerance, box_lower_xy, box_upper_xy, layers_first=True)
    order, lower, upper = grid.order, grid.lower, grid.upper
    overlapping = np.zeros(len(x), dtype=bool)
    x_sorted = _gather(x, order)
    row_start, partner, contacts = _touching_in_cells(x_sorted, _gather(radii, order), _gather(particle, order), order,
                                                      tolerance, overlap_cut, bool(periodic), grid.cell_list(),
                                                      CONTACTS_PER_SPHERE_GUESS * len(x) + 16, overlapping)
    pairs, normals = _sorted_contacts(x_sorted, order, row_start, partner, contacts, bool(periodic), upper - lower)
    return ContactNetwork(pairs, normals, overlapping)


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
    pairs = np.ascontiguousarray(pairs, dtype=np.int64).reshape(-1, 2)
    particle = np.ascontiguousarray(particle, dtype=np.int64)
    if len(pairs) and not (0 <= pairs.min() and pairs.max() < len(particle)):
        raise ValueError("pairs must be sphere indices of particle")
    if len(particle) and not (0 <= particle.min() and particle.max() < n_particles):
        raise ValueError(f"particle must number particles 0 ... {n_particles - 1}")
    return _distinct_partners(pairs, particle, int(n_particles))


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
def _shell_counts(sorted_centres, sorted_given, reference, r_max, bins, periodic, period, grid, reach):
    """Histogram of the distances r < r_max from the reference centres to all other centres, in ``bins`` shells
    uniform on [0, r_max).

    ``sorted_centres``: the centres of the :class:`~parsim.core.sediment.CellList` ``grid`` in its order
    (wrapped into the box), cell c holding start[c]:start[c + 1]; ``sorted_given``: the same centres as given,
    from which distances are computed (minimum images over ``period`` when ``periodic``); ``reference``: the
    references' places in the list. Cells are r_max / ``reach`` or more wide, so a reference scans ``reach``
    cells on each side; the cells of one column are consecutive, so each column is one run of the list.
    """
    start, lower, cells = grid.start, grid.lower, grid.cells
    width = grid.upper - lower
    counts = np.zeros(bins, dtype=np.int64)
    columns = np.empty((2 * reach + 1) ** 2, dtype=np.int64)
    for i in reference:
        ci = int(np.floor((sorted_centres[i, 0] - lower[0]) / width[0] * cells[0])) % cells[0]
        cj = int(np.floor((sorted_centres[i, 1] - lower[1]) / width[1] * cells[1])) % cells[1]
        ck = int(np.floor((sorted_centres[i, 2] - grid.z_lower) / grid.cell_height))
        xi, yi, zi = sorted_given[i, 0], sorted_given[i, 1], sorted_given[i, 2]
        bottom, top = max(ck - reach, 0), min(ck + reach + 1, cells[2])
        if bottom >= top:
            continue
        n_columns = _columns_around(ci, cj, reach, cells, columns)
        for c in range(n_columns):
            for j in range(start[columns[c] * cells[2] + bottom], start[columns[c] * cells[2] + top]):
                if j == i:
                    continue
                dx = sorted_given[j, 0] - xi
                dy = sorted_given[j, 1] - yi
                if periodic:
                    dx, dy = _minimum_image(dx, period[0]), _minimum_image(dy, period[1])
                dz = sorted_given[j, 2] - zi
                distance_squared = dx * dx + dy * dy + dz * dz
                if distance_squared < r_max * r_max:
                    counts[min(int(np.sqrt(distance_squared) / r_max * bins), bins - 1)] += 1
    return counts


@jit
def _touching_in_cells(x, radii, particle, order, tolerance, overlap_cut, periodic, grid, capacity, overlapping):
    """Every pair of spheres of the cell list closer than the contact criterion, found once: (row_start,
    partner, contacts), sphere m of the list (in its order) touching the spheres partner[row_start[m]:
    row_start[m + 1]] that come after it, and contacts[i + 1] the number of contacts of sphere i (its own
    number) with spheres of higher numbers; flags in ``overlapping`` (indexed by the spheres' own
    numbers) the spheres that overlap another by more than ``overlap_cut`` (minimum images in x and y,
    see :func:`contact_network`).

    ``x``, ``radii``, ``particle``: the spheres of the :class:`~parsim.core.sediment.CellList` ``grid``,
    sorted layer by layer (``layers_first`` of the cell grid), ``order`` their own numbers; ``capacity``: the
    contacts the list of partners has room for at first (it doubles when full). The cells are visited in
    order and each sphere meets the later spheres of its 27 cells, read as runs of the list
    (:func:`_runs_around`), so the search reads the list nearly sequentially; and as a sediment is deposited
    about layer by layer, the contacts it finds one after the other belong to spheres of nearby numbers,
    which keeps the counts here and the sorting of :func:`_sorted_contacts` within a small part of memory.
    A pair farther apart than R_i + R_j + tolerance (minimum images, the shortest separation) is passed
    over at once; for the others the gap test is the one of :func:`contact_pairs`, on x_j − x_i with
    i < j the spheres' own numbers.
    """
    start, cells = grid.start, grid.cells
    width = grid.upper - grid.lower
    n = x.shape[0]
    partner = np.empty(capacity, dtype=np.int64)
    row_start = np.zeros(n + 1, dtype=np.int64)
    contacts = np.zeros(n + 1, dtype=np.int64)
    runs = np.empty((27, 2), dtype=np.int64)
    count = 0
    for ck in range(cells[2]):
        for ci in range(cells[0]):
            for cj in range(cells[1]):
                cell = (ck * cells[0] + ci) * cells[1] + cj
                if start[cell] == start[cell + 1]:
                    continue
                n_runs = _runs_around(ci, cj, ck, cells, start, runs)
                for m in range(start[cell], start[cell + 1]):
                    row_start[m] = count
                    xm, ym, zm, rm = x[m, 0], x[m, 1], x[m, 2], radii[m]
                    for run in range(n_runs):
                        for other in range(max(runs[run, 0], m + 1), runs[run, 1]):
                            image_x = _minimum_image(x[other, 0] - xm, width[0])
                            image_y = _minimum_image(x[other, 1] - ym, width[1])
                            dz = x[other, 2] - zm
                            reach = rm + radii[other] + tolerance
                            if image_x * image_x + image_y * image_y + dz * dz > reach * reach * (1.0 + 1e-12):
                                continue  # the gap exceeds the tolerance by far: neither contact nor overlap
                            first, second = (m, other) if order[m] < order[other] else (other, m)
                            dx = x[second, 0] - x[first, 0]
                            dy = x[second, 1] - x[first, 1]
                            dz = x[second, 2] - x[first, 2]
                            image_x, image_y = _minimum_image(dx, width[0]), _minimum_image(dy, width[1])
                            overlap = radii[first] + radii[second] - overlap_cut
                            if image_x * image_x + image_y * image_y + dz * dz < overlap * overlap and overlap > 0.0:
                                overlapping[order[m]] = True
                                overlapping[order[other]] = True
                            if particle[m] == particle[other]:
                                continue
                            if periodic:
                                dx, dy = image_x, image_y
                            if np.sqrt(dx * dx + dy * dy + dz * dz) - radii[first] - radii[second] < tolerance:
                                if count == len(partner):
                                    partner = with_rows(partner, 2 * len(partner), count)
                                partner[count] = other
                                contacts[order[first] + 1] += 1
                                count += 1
    row_start[n] = count
    return row_start, partner[:count], contacts


@jit
def _runs_around(ci, cj, ck, cells, start, runs):
    """The spheres of the 27 cells around cell (ci, cj, ck) (periodic in x and y, each cell once) of a list
    sorted layer by layer (cell (k cells[0] + i) cells[1] + j): fill ``runs`` with the runs (first, end) of
    the list, one per row of three cells (j - 1 ... j + 1) when they are consecutive; return how many."""
    count = 0
    wide_i, wide_j = cells[0] >= 3, cells[1] >= 3
    for k in range(max(ck - 1, 0), min(ck + 2, cells[2])):
        for a in range(3 if wide_i else cells[0]):
            row = (k * cells[0] + ((ci - 1 + a) % cells[0] if wide_i else a)) * cells[1]
            if not wide_j:  # every cell of the row
                runs[count, 0], runs[count, 1] = start[row], start[row + cells[1]]
                count += 1
            elif 1 <= cj <= cells[1] - 2:
                runs[count, 0], runs[count, 1] = start[row + cj - 1], start[row + cj + 2]
                count += 1
            else:  # the row wraps around the periodic side
                for b in range(3):
                    j = (cj - 1 + b) % cells[1]
                    runs[count, 0], runs[count, 1] = start[row + j], start[row + j + 1]
                    count += 1
    return count


@jit
def _sorted_contacts(x, order, row_start, partner, contacts, periodic, width):
    """The contacts of :func:`_touching_in_cells` as sphere pairs i < j (their own numbers), sorted by i
    then j, and the unit normals (x_j − x_i) / |x_j − x_i| (minimum images when ``periodic``).

    ``x``: the spheres in the cell list's order; ``contacts`` is turned into the first contact of each
    sphere (i: contacts[i]:contacts[i + 1]). The normals are computed where the contacts were found, from
    the list's nearby spheres, and move with their pairs."""
    m = len(partner)
    for i in range(len(contacts) - 1):
        contacts[i + 1] += contacts[i]
    pairs = np.empty((m, 2), dtype=np.int64)
    normals = np.empty((m, 3))
    filled = contacts[:-1].copy()
    for mm in range(len(row_start) - 1):
        for k in range(row_start[mm], row_start[mm + 1]):
            first, second = (mm, partner[k]) if order[mm] < order[partner[k]] else (partner[k], mm)
            dx = x[second, 0] - x[first, 0]
            dy = x[second, 1] - x[first, 1]
            if periodic:
                dx, dy = _minimum_image(dx, width[0]), _minimum_image(dy, width[1])
            dz = x[second, 2] - x[first, 2]
            distance = np.sqrt(dx * dx + dy * dy + dz * dz)
            slot = filled[order[first]]
            filled[order[first]] += 1
            pairs[slot, 0], pairs[slot, 1] = order[first], order[second]
            normals[slot, 0], normals[slot, 1], normals[slot, 2] = dx / distance, dy / distance, dz / distance
    for i in range(len(contacts) - 1):
        # a sphere has a few contacts: insertion sort of its partners
        for k in range(contacts[i] + 1, contacts[i + 1]):
            j, nx, ny, nz = pairs[k, 1], normals[k, 0], normals[k, 1], normals[k, 2]
            slot = k
            while slot > contacts[i] and pairs[slot - 1, 1] > j:
                pairs[slot, 1] = pairs[slot - 1, 1]
                normals[slot, 0], normals[slot, 1], normals[slot, 2] = (normals[slot - 1, 0], normals[slot - 1, 1],
                                                                        normals[slot - 1, 2])
                slot -= 1
            pairs[slot, 1] = j
            normals[slot, 0], normals[slot, 1], normals[slot, 2] = nx, ny, nz
    return pairs, normals


@jit
def _gather(values, order):
    """values[order] (rows of a 2D array), in one pass."""
    out = np.empty((len(order),) + values.shape[1:], dtype=values.dtype)
    for m in range(len(order)):
        out[m] = values[order[m]]
    return out


@jit
def _distinct_partners(pairs, particle, n_particles):
    """Number of distinct particles each particle touches through the sphere ``pairs`` (a pair within one
    particle counts it twice, as a contact with itself from both sides)."""
    m = pairs.shape[0]
    first = np.zeros(n_particles + 1, dtype=np.int64)  # the pairs whose lower particle is p: first[p]:first[p + 1]
    for k in range(m):
        first[min(particle[pairs[k, 0]], particle[pairs[k, 1]]) + 1] += 1
    for p in range(n_particles):
        first[p + 1] += first[p]
    higher = np.empty(m, dtype=np.int64)
    filled = first[:-1].copy()
    for k in range(m):
        a, b = particle[pairs[k, 0]], particle[pairs[k, 1]]
        low, high = (a, b) if a <= b else (b, a)
        higher[filled[low]] = high
        filled[low] += 1
    touched = np.zeros(n_particles, dtype=np.int64)
    seen = np.full(n_particles, -1, dtype=np.int64)  # seen[q] == p: q already counted as a partner of p
    for p in range(n_particles):
        for k in range(first[p], first[p + 1]):
            q = higher[k]
            if seen[q] != p:
                seen[q] = p
                touched[p] += 1
                touched[q] += 1
    return touched
