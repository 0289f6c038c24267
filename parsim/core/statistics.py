"""Shape statistics of a configuration of spheres (discs in 2D).

The indicators are those of section 4.2 of Degond et al. (2024), "ballistic
aggregation ... time stepping" (``papers/ballistic-aggregation-time-stepping-degond-2024.txt``):

- :func:`gyration_tensor`, :func:`radius_of_gyration`: the gyration tensor G(Y) of
  section 4.2 and sqrt(trace G) of the centres; :func:`mass_radius_of_gyration`: the R_g of the
  monomers as bodies, mass-weighted with their own second moments, that of the aerosol fractal law
  N = k_f (R_g / a)^D_f;
- :func:`aspect_ratio_and_orientation`: aspect ratio A_r (eq. 4.4) and orientation D
  (eq. 4.5);
- :func:`relative_contact_number`: relative average number of contacts N_c (eq. 4.6), and
  :func:`contact_pairs` for unequal radii, a pair in contact when its centres are at most
  alpha_R (r_i + r_j) / 2 apart (alpha_R R for equal radii, as eq. 4.6);
- :func:`pair_distribution`, :func:`pair_distribution_grid`: cumulative pair
  distribution P(r) (eq. 4.7) and the paper's grid 2R < r <= 20R;
- :func:`box_counts`, :func:`fractal_dimension`: box counting N(eps_m), eps_m = L/2^m,
  and the least-squares fit of eq. 4.8, log N = log a - D_f log eps; :func:`fit_box_sizes`:
  how many box sizes the paper's fit range 3R <= eps <= L/2 holds (the fit needs two);
- :func:`cluster_statistics`: all of the above for one configuration.

All functions accept any configuration (positions of shape (n, d), d = 2 or 3), not only
solver output. Pair sums use a cell list, so they cost O(n * neighbours); box counting
sorts one Morton code per sphere, O(n log n), and never allocates the grid.
"""

import numpy as np

from parsim.core.celllist import block_cells, build_cells, grid_size, neighbour_offsets
from parsim.core.jit import jit

# Relative size below which the second gyration eigenvalue is rounding noise of eigh
# (errors there are a few ulp of lambda_1): the points lie on a line and A_r = +inf.
FLAT_RTOL = 1e-12
# Absolute tolerance on |component| when the sign rule of the orientation looks for
# the component of largest magnitude (components of a unit vector are O(1)).
SIGN_TIE_ATOL = 1e-12
# Relative tolerance on the bounds of the fit range of the fractal dimension
# (box sizes are L/2^m, computed exactly; bounds such as 3R or L/2 may carry rounding).
FIT_RANGE_RTOL = 1e-12
# The least-squares fit of the fractal dimension needs this many box sizes in its range.
MIN_FIT_BOX_SIZES = 2
# Cell lists are coarsened until they hold at most this many cells per sphere, so a
# sparse configuration spread over a huge extent never allocates a huge grid.
MAX_CELLS_PER_SPHERE = 4
# The cells of pair sums are max(r) / CELLS_PER_CUTOFF wide, and a pair's bin is looked up among
# SLOTS_PER_BIN slots of d^2 per bin (at 10^6 discs, 2.5x faster than cells max(r) wide and a
# binary search over the bins).
CELLS_PER_CUTOFF = 2
SLOTS_PER_BIN = 8
# Default N_max of eq. 4.6: kissing numbers of discs in 2D and spheres in 3D.
DEFAULT_N_MAX = {2: 6, 3: 12}
#: A monomer's second moment about its centre per unit mass, in units of r^2: a uniform disc (d = 2,
#: its mass spread over its area) has r^2 / 2, a uniform ball (d = 3) 3 r^2 / 5.
SELF_MOMENT = {2: 0.5, 3: 0.6}


def as_positions(positions):
    """``positions`` as a contiguous (n, d) float64 array, d = 2 or 3, n >= 1, finite; else ValueError naming it."""
    x = np.ascontiguousarray(positions, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] not in (2, 3):
        raise ValueError(f"positions must have shape (n, 2) or (n, 3), got {x.shape}")
    if x.shape[0] < 1:
        raise ValueError("positions must hold at least one sphere (n >= 1), got n = 0")
    if not np.all(np.isfinite(x)):
        raise ValueError("positions must be finite, got NaN or infinite values")
    return x


def gyration_tensor(positions):
    """Gyration tensor G = (1/n) sum_i y_i y_i^T with y = x - mean(x), shape (d, d)."""
    x = as_positions(positions)
    y = x - x.mean(axis=0)
    return y.T @ y / x.shape[0]


def radius_of_gyration(positions):
    """Radius of gyration sqrt(trace G) of the sphere centres."""
    return float(np.sqrt(np.trace(gyration_tensor(positions))))


def mass_radius_of_gyration(positions, radii, masses):
    """Radius of gyration of the monomers as bodies:
    ``R_g^2 = sum_i m_i (|x_i - x_cm|^2 + c_d r_i^2) / sum_i m_i``, ``x_cm`` the centre of mass and
    ``c_d r_i^2`` monomer i's own second moment (:data:`SELF_MOMENT`; overlaps of touching monomers are
    not subtracted).  The R_g of the fractal law ``N = k_f (R_g / a)^D_f`` of the aerosol literature
    (FracVAL, MCAC), which weights monomers of unequal sizes by their masses."""
    x = as_positions(positions)
    r = np.asarray(radii, dtype=np.float64)
    m = np.asarray(masses, dtype=np.float64)
    if r.shape != (x.shape[0],) or m.shape != (x.shape[0],):
        raise ValueError(f"radii and masses must have shape ({x.shape[0]},), got {r.shape} and {m.shape}")
    if not (np.all(r > 0.0) and np.all(m > 0.0)):
        raise ValueError("radii and masses must be > 0")
    total = m.sum()
    centre = (m[:, None] * x).sum(axis=0) / total
    spread = ((x - centre) ** 2).sum(axis=1)
    return float(np.sqrt((m * (spread + SELF_MOMENT[x.shape[1]] * r * r)).sum() / total))


def aspect_ratio_and_orientation(positions):
    """Aspect ratio A_r = lambda_1 / lambda_2 (eq. 4.4) and orientation D = v_1/|v_1| (eq. 4.5).

    lambda_1 >= lambda_2 are the two largest eigenvalues of the gyration tensor (also in
    3D) and v_1 is the eigenvector of lambda_1.

    - If lambda_2 <= FLAT_RTOL * lambda_1 (all centres on a line, up to rounding) A_r is
      ``inf``; D is still the direction of the line.
    - Sign rule for D (an eigenvector is defined up to sign): the component of largest
      absolute value is made positive; if several components tie in absolute value to
      within SIGN_TIE_ATOL = 1e-12, the first of them is made positive.

    Raises ValueError for fewer than two spheres, or when all centres coincide (no
    direction exists).
    """
    x = as_positions(positions)
    if x.shape[0] < 2:
        raise ValueError("need at least two spheres")
    eigenvalues, eigenvectors = np.linalg.eigh(gyration_tensor(x))  # ascending order
    lambda_1, lambda_2 = eigenvalues[-1], eigenvalues[-2]
    if lambda_1 <= 0.0:
        raise ValueError("all sphere centres coincide: orientation is undefined")
    aspect_ratio = np.inf if lambda_2 <= FLAT_RTOL * lambda_1 else float(lambda_1 / lambda_2)
    direction = eigenvectors[:, -1] / np.linalg.norm(eigenvectors[:, -1])
    magnitude = np.abs(direction)
    first_largest = np.flatnonzero(magnitude >= magnitude.max() - SIGN_TIE_ATOL)[0]
    if direction[first_largest] < 0.0:
        direction = -direction
    return aspect_ratio, direction


# ---------------------------------------------------------------------------- pair sums


def _half_stencil(d, reach):
    """Cell offsets in {-reach, ..., reach}^d whose first non-zero component is positive.

    Exactly one of o and -o is in the set for every o != 0, so each pair of cells at most
    ``reach`` cells apart along every axis is visited once.
    """
    steps = list(range(-reach, reach + 1))
    grid = np.array(np.meshgrid(*([steps] * d), indexing="ij")).reshape(d, -1).T
    keep = [o for o in grid if np.any(o != 0) and o[np.flatnonzero(o)[0]] > 0]
    return np.array(keep, dtype=np.int64)


@jit
def _pair_histogram(positions, lower, side, shape, stencil, r_squared, first_bin, slot_scale):
    """Unordered pairs i < j binned by distance: bin k holds r_{k-1}^2 < d^2 <= r_k^2.

    The stencil reaches every cell within max(r) of a cell; pairs farther apart than max(r)
    are not counted.  A pair's bin is found from its slot of d^2 (``slot_scale`` slots per unit
    of d^2): ``first_bin`` of the slot is at or below the bin, and a step or two up finds it,
    where a binary search over the bins took 7 unpredictable branches.
    """
    n, d = positions.shape
    strides = np.ones(d, dtype=np.int64)
    for k in range(d - 2, -1, -1):
        strides[k] = strides[k + 1] * shape[k + 1]
    n_cells = strides[0] * shape[0]

    # Counting sort of the centres by cell; sorted copy for memory locality.
    cell = np.empty(n, dtype=np.int64)
    for i in range(n):
        c = 0
        for k in range(d):
            index = int((positions[i, k] - lower[k]) / side)
            index = min(max(index, 0), shape[k] - 1)
            c += index * strides[k]
        cell[i] = c
    start = np.zeros(n_cells + 1, dtype=np.int64)
    for i in range(n):
        start[cell[i] + 1] += 1
    for c in range(n_cells):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    x = np.zeros((n, 3))  # a third coordinate of 0 in 2D: one loop for both, the same sums
    for i in range(n):
        for k in range(d):
            x[fill[cell[i]], k] = positions[i, k]
        fill[cell[i]] += 1

    n_bins, n_slots = r_squared.shape[0], first_bin.shape[0]
    r_max_squared = r_squared[n_bins - 1]
    histogram = np.zeros(n_bins, dtype=np.int64)
    home = np.empty(d, dtype=np.int64)
    for c in range(n_cells):
        a0, a1 = start[c], start[c + 1]
        if a0 == a1:
            continue
        rest = c
        for k in range(d):
            home[k] = rest // strides[k]
            rest -= home[k] * strides[k]
        for s in range(-1, stencil.shape[0]):  # s = -1: the cell itself
            if s < 0:
                other = c
            else:
                other = 0
                for k in range(d):
                    index = home[k] + stencil[s, k]
                    if index < 0 or index >= shape[k]:
                        other = -1
                        break
                    other += index * strides[k]
                if other < 0:
                    continue
            b0, b1 = start[other], start[other + 1]
            for a in range(a0, a1):
                xa, ya, za = x[a, 0], x[a, 1], x[a, 2]
                for b in range(a + 1 if s < 0 else b0, b1):
                    distance_squared = (xa - x[b, 0]) ** 2 + (ya - x[b, 1]) ** 2 + (za - x[b, 2]) ** 2
                    if distance_squared > r_max_squared:
                        continue
                    k = first_bin[min(int(distance_squared * slot_scale), n_slots - 1)]
                    while r_squared[k] < distance_squared:
                        k += 1
                    histogram[k] += 1
    return histogram


def _pair_counts(x, r_values):
    """For each r: number of ordered pairs (i, j), i = j included, with |X_i - X_j| <= r.

    The self pairs (i, i) are counted as the sums of eqs. 4.6 and 4.7 are printed: they
    add n for every r >= 0.  Cells are max(r) / CELLS_PER_CUTOFF wide (narrower cells leave
    fewer pairs beyond max(r) to reject), and d^2 is cut into SLOTS_PER_BIN slots per bin.
    """
    n, d = x.shape
    cutoff = r_values[-1]
    self_pairs = np.where(r_values >= 0.0, float(n), 0.0)
    if n < 2 or cutoff < 0.0:
        return self_pairs
    lower = x.min(axis=0)
    extent = x.max(axis=0) - lower
    side = cutoff / CELLS_PER_CUTOFF if cutoff > 0.0 else (extent.max() / n if extent.max() > 0.0 else 1.0)
    while np.prod(np.floor(extent / side) + 1.0) > MAX_CELLS_PER_SPHERE * n:
        side *= 2.0
    shape = (np.floor(extent / side) + 1.0).astype(np.int64)
    r_squared = np.where(r_values >= 0.0, r_values * r_values, -1.0)  # r < 0 counts nothing
    n_slots = SLOTS_PER_BIN * r_values.size
    slot_scale = n_slots / r_squared[-1] if r_squared[-1] > 0.0 else 0.0
    # Slot j holds j <= d^2 * slot_scale < j + 1; its first bin is taken at the slot below, so that the
    # rounding of d^2 * slot_scale never starts a search above the pair's bin.
    edges = np.maximum(np.arange(n_slots) - 1.0, 0.0) / slot_scale if slot_scale > 0.0 else np.zeros(n_slots)
    first_bin = np.searchsorted(r_squared, edges, side="left").astype(np.int64)
    histogram = _pair_histogram(x, lower, side, shape, _half_stencil(d, CELLS_PER_CUTOFF), r_squared, first_bin,
                                slot_scale)
    return self_pairs + 2.0 * np.cumsum(histogram).astype(np.float64)


def relative_contact_number(positions, radius, contact_factor=2.1, n_max=None):
    """Relative average number of contacts per sphere N_c (eq. 4.6).

    N_c = (1/(n N_max)) sum_{i, j} 1{|X_i - X_j| <= contact_factor * radius}, the sum over
    all ordered pairs *including i = j*, exactly as eq. 4.6 is printed. So N_c =
    (1 + mean contacts per sphere) / N_max: an isolated sphere gives 1/6 in 2D, the lower
    bound the paper states, and the tree-like clusters of the event-driven method (two
    contacts per sphere) give (1 + 2)/6 = 0.5, the value the paper reports for both methods
    (section 4.2.1); the mean number of contacts is N_max N_c - 1. A chain of n discs gives
    exactly (1 + 2(n-1)/n)/6.

    ``radius`` is the scalar R (pass the mean radius for polydisperse spheres).
    ``n_max`` defaults to 6 in 2D and 12 in 3D.
    """
    x = as_positions(positions)
    contacts = _pair_counts(x, np.array([_contact_distance(radius, contact_factor)]))
    return _relative(contacts[0], x, n_max)


def contact_pairs(positions, radii, contact_factor=2.1):
    """The ordered pairs (i, j), i = j included as eq. 4.6 prints it, whose centres are at most
    ``contact_factor (r_i + r_j) / 2`` apart: the contacts of eq. 4.6 for monomers of unequal radii (for
    equal radii R the bound is eq. 4.6's alpha_R R).  N_c is this count over n N_max."""
    x = as_positions(positions)
    r = np.ascontiguousarray(radii, dtype=np.float64)
    if r.shape != (x.shape[0],) or not np.all(r > 0.0) or not contact_factor > 0.0:
        raise ValueError(f"radii must have shape ({x.shape[0]},) and be > 0, contact_factor > 0")
    lower = x.min(axis=0)
    shifted = np.ascontiguousarray(x - lower)
    cutoff = contact_factor * float(r.max())
    k, side = grid_size(max(float((shifted.max(axis=0)).max()), cutoff), cutoff, x.shape[1], x.shape[0])
    return x.shape[0] + 2 * _touching_pairs(shifted, r, 0.5 * contact_factor, side, k)


@jit
def _touching_pairs(x, radii, half_factor, side, k):
    """Unordered pairs i < j with ``|x_i - x_j| <= half_factor (r_i + r_j)``, from a cell list whose cells are
    at least the largest such distance wide."""
    n, d = x.shape
    head, nxt, _, cell_of, _ = build_cells(x, side, k)
    offsets = neighbour_offsets(d)
    coords = np.empty(d, dtype=np.int64)
    block = np.empty(offsets.shape[0], dtype=np.int64)
    found = 0
    for i in range(n):
        for b in range(block_cells(cell_of[i], k, offsets, coords, block)):
            j = head[block[b]]
            while j >= 0:
                if j > i:
                    s = 0.0
                    for a in range(d):
                        s += (x[i, a] - x[j, a]) ** 2
                    reach = half_factor * (radii[i] + radii[j])
                    if s <= reach * reach:
                        found += 1
                j = nxt[j]
    return found


def _contact_distance(radius, contact_factor):
    if not (radius > 0.0 and contact_factor > 0.0):
        raise ValueError(f"radius and contact_factor must be > 0, got {radius}, {contact_factor}")
    return float(contact_factor * radius)


def _relative(contacts, x, n_max):
    """N_c of eq. 4.6 from the count of ordered pairs in contact."""
    return float(contacts / (x.shape[0] * (DEFAULT_N_MAX[x.shape[1]] if n_max is None else n_max)))


def pair_distribution(positions, r_values):
    """Cumulative pair distribution P(r) = (1/n) sum_{i, j} 1{|X_i - X_j| <= r} (eq. 4.7).

    The sum includes i = j as printed (as in eq. 4.6), so P(r) = 1 + the mean number of
    other spheres within r, for r >= 0. Evaluated at every r of the non-decreasing array
    ``r_values``; returns an array of the same length. Each unordered pair i != j is found
    once with a cell list and counted twice.
    """
    x = as_positions(positions)
    r = _checked_r_values(r_values)
    return _pair_counts(x, r) / x.shape[0] if r.size else np.zeros(0)


def _checked_r_values(r_values):
    r = np.ascontiguousarray(r_values, dtype=np.float64)
    if r.ndim != 1:
        raise ValueError(f"r_values must be one-dimensional, got shape {r.shape}")
    if not np.all(np.isfinite(r)) or np.any(np.diff(r) < 0.0):
        raise ValueError("r_values must be finite and non-decreasing")
    return r


def _contacts_and_pair_distribution(x, contact_distance, r):
    """The count of ordered pairs within ``contact_distance`` (eq. 4.6) and P at ``r`` (eq. 4.7), from one
    pass over the pairs: ``contact_distance`` is one more r of the same cumulative counts."""
    merged = np.append(r, contact_distance)
    order = np.argsort(merged, kind="stable")
    counts = np.empty_like(merged)
    counts[order] = _pair_counts(x, merged[order])
    return counts[-1], counts[:-1] / x.shape[0]


def pair_distribution_grid(radius, points=72):
    """The paper's r grid 2R < r <= 20R: r_k = R (2 + 18 k / points), k = 1..points.

    ``points`` is the number of values returned; the default 72 gives steps of R/4:
    2.25R, 2.5R, ..., 20R (the last value is exactly 20R).
    """
    if not radius > 0.0:
        raise ValueError(f"radius must be > 0, got {radius}")
    if points < 1:
        raise ValueError(f"points must be >= 1, got {points}")
    return radius * (2.0 + 18.0 * np.arange(1, points + 1) / points)


# ----------------------------------------------------------------------- box counting


@jit
def _morton_codes(positions, lower, box_length, levels):
    """Interleaved bits of the per-dimension cell indices at the finest level.

    Index k of a centre is floor((x_k - lower_k) / box_length * 2^levels), clipped to
    [0, 2^levels - 1]. The cell of level m is then the code shifted right by
    d (levels - m) bits: floor(floor(t 2^L) / 2^(L-m)) = floor(t 2^m), and scaling by a
    power of two is exact in floating point, so every level sees the same index as a
    direct floor((x_k - lower_k) / eps_m).
    """
    n, d = positions.shape
    scale = 2.0**levels
    codes = np.zeros(n, dtype=np.int64)
    index = np.empty(d, dtype=np.int64)
    for i in range(n):
        for k in range(d):
            t = np.floor((positions[i, k] - lower[k]) / box_length * scale)
            index[k] = int(min(max(t, 0.0), scale - 1.0))
        code = 0
        for bit in range(levels - 1, -1, -1):
            for k in range(d):
                code = (code << 1) | ((index[k] >> bit) & 1)
        codes[i] = code
    return codes


@jit
def _distinct_cells_per_level(sorted_codes, d, levels):
    counts = np.zeros(levels)
    n = sorted_codes.shape[0]
    for m in range(1, levels + 1):
        shift = d * (levels - m)
        distinct = 1
        previous = sorted_codes[0] >> shift
        for i in range(1, n):
            current = sorted_codes[i] >> shift
            if current != previous:
                distinct += 1
                previous = current
        counts[m - 1] = distinct
    return counts


def box_counts(positions, box_lower, box_length, levels):
    """Box counting of section 4.2 (text after eq. 4.8).

    For m = 1..levels, eps_m = box_length / 2^m and N(eps_m) is the number of cells of the
    Cartesian grid of side eps_m, anchored at ``box_lower`` (the same cubic grid of side
    ``box_length`` in every dimension), that contain at least one sphere centre. Cell
    indices are clipped to [0, 2^m - 1]: centres on the upper face, or outside the cube,
    count in the nearest boundary cell. levels * d must be at most 63 (levels <= 31 in
    2D, <= 21 in 3D); the grid is never allocated.

    Returns (eps, counts), both float64 arrays of length ``levels``.
    """
    x = as_positions(positions)
    d = x.shape[1]
    lower = np.ascontiguousarray(box_lower, dtype=np.float64)
    if lower.shape != (d,):
        raise ValueError(f"box_lower must have shape ({d},), got {lower.shape}")
    if not box_length > 0.0:
        raise ValueError(f"box_length must be > 0, got {box_length}")
    if not 1 <= levels <= 63 // d:
        raise ValueError(f"levels must be in [1, {63 // d}] in {d}D, got {levels}")
    codes = np.sort(_morton_codes(x, lower, float(box_length), int(levels)))
    return box_sizes(box_length, levels), _distinct_cells_per_level(codes, d, int(levels))


def box_sizes(box_length, levels):
    """The box sizes eps_m = box_length / 2^m, m = 1..levels."""
    return box_length / 2.0 ** np.arange(1, levels + 1)


def fit_range(radius, box_length):
    """The paper's fit range of D_f (text after eq. 4.8): 3R <= eps <= L/2, as (eps_min, eps_max)."""
    return 3.0 * radius, box_length / 2.0


def _in_fit_range(eps, eps_min, eps_max):
    """Which ``eps`` lie in [eps_min, eps_max], the bounds widened by FIT_RANGE_RTOL."""
    return (eps >= eps_min * (1.0 - FIT_RANGE_RTOL)) & (eps <= eps_max * (1.0 + FIT_RANGE_RTOL))


def fit_box_sizes(box_length, radius, levels):
    """How many box sizes eps_m = L/2^m (m = 1..levels) :func:`cluster_statistics` fits D_f on,
    those in 3R <= eps <= L/2; the fit needs at least MIN_FIT_BOX_SIZES."""
    return int(np.count_nonzero(_in_fit_range(box_sizes(box_length, levels), *fit_range(radius, box_length))))


def fractal_dimension(eps, counts, eps_min, eps_max):
    """Least-squares fit of log N = log a - D_f log eps (eq. 4.8); returns (D_f, a).

    Only box sizes with eps_min <= eps <= eps_max enter the fit (bounds inclusive with a
    relative tolerance FIT_RANGE_RTOL). The paper's range is :func:`fit_range`. Raises
    ValueError when fewer than MIN_FIT_BOX_SIZES box sizes fall in the range.
    """
    eps = np.asarray(eps, dtype=np.float64)
    counts = np.asarray(counts, dtype=np.float64)
    if eps.shape != counts.shape or eps.ndim != 1:
        raise ValueError(f"eps and counts must be 1-D of equal length, got {eps.shape}, {counts.shape}")
    selected = _in_fit_range(eps, eps_min, eps_max)
    if np.count_nonzero(selected) < MIN_FIT_BOX_SIZES:
        raise ValueError(
            f"fewer than two box sizes in the fit range {eps_min} <= eps <= {eps_max}"
        )
    if np.any(counts[selected] <= 0.0):
        raise ValueError("box counts in the fit range must be positive")
    log_eps = np.log(eps[selected])
    log_counts = np.log(counts[selected])
    dx = log_eps - log_eps.mean()
    slope = np.dot(dx, log_counts - log_counts.mean()) / np.dot(dx, dx)
    prefactor = np.exp(log_counts.mean() - slope * log_eps.mean())
    return float(-slope), float(prefactor)


def cluster_statistics(positions, radii, box_lower, box_upper, *, contact_factor=2.1,
                       r_values, box_levels, masses=None):
    """All shape indicators of section 4.2 for one configuration.

    R = mean(radii) is the radius of the fit range; a pair is in contact (eq. 4.6) within
    contact_factor (r_i + r_j) / 2, alpha_R R for equal radii; L = max(box_upper - box_lower) is the
    side of the box-counting grid, anchored at box_lower; D_f is fitted over 3R <= eps <= L/2.  The
    radius of gyration is :func:`mass_radius_of_gyration`, with ``masses`` (default: proportional to
    r^d, one density).
    Returns a dict with keys "aspect_ratio", "orientation", "contact_number",
    "pair_distribution" (at ``r_values``), "box_size" (eps_m), "box_count" (N(eps_m)),
    "fractal_dimension", "fractal_prefactor" and "radius_of_gyration".
    """
    x = as_positions(positions)
    radii = np.asarray(radii, dtype=np.float64)
    if radii.shape != (x.shape[0],):
        raise ValueError(f"radii must have shape ({x.shape[0]},), got {radii.shape}")
    lower = np.asarray(box_lower, dtype=np.float64)
    upper = np.asarray(box_upper, dtype=np.float64)
    radius = float(radii.mean())
    box_length = float(np.max(upper - lower))
    aspect_ratio, orientation = aspect_ratio_and_orientation(x)
    eps, counts = box_counts(x, lower, box_length, box_levels)
    d_f, prefactor = fractal_dimension(eps, counts, *fit_range(radius, box_length))
    contacts, pairs = _contacts_and_pair_distribution(x, _contact_distance(radius, contact_factor),
                                                      _checked_r_values(r_values))
    if np.any(radii != radii[0]):  # eq. 4.6's bound pair by pair
        contacts = contact_pairs(x, radii, contact_factor)
    masses = radii ** x.shape[1] if masses is None else masses
    return {
        "aspect_ratio": aspect_ratio,
        "orientation": orientation,
        "contact_number": _relative(contacts, x, None),
        "pair_distribution": pairs,
        "box_size": eps,
        "box_count": counts,
        "fractal_dimension": d_f,
        "fractal_prefactor": prefactor,
        "radius_of_gyration": mass_radius_of_gyration(x, radii, masses),
    }
