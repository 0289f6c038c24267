"""Initial conditions for ballistic aggregation (Degond et al. 2024, section 4.1 and SM A).

Positions: spheres sit on the sites of a cubic (square for d = 2) lattice filling the
box ``[0, L]^d``.  Velocities: either isotropic with a fixed speed (eq. 4.3) or uniform in
the cube ``[-1/2, 1/2]^d`` (the supplementary initial condition of section A).

Every function that draws random numbers takes a :class:`numpy.random.Generator` and uses
nothing else, so the result is a deterministic function of the generator's state.

Non-overlap.  Spheres of radius ``R`` placed by :func:`lattice_positions` do not overlap
(and do not leave the box) when the lattice spacing is at least ``2R``, i.e. when
``L >= 2 R ceil(n^(1/d))``.  For ``n = k^d`` this is the paper's condition (4.2),
``L^2 > 4 R^2 N`` for d = 2; for other ``n`` the lattice is finer than ``L / n^(1/d)`` and
(4.2) alone is not sufficient.
"""

import math

import numpy as np

__all__ = [
    "lattice_sites_per_side",
    "lattice_spacing",
    "lattice_positions",
    "isotropic_velocities",
    "uniform_cube_velocities",
    "box_length_for_volume_fraction",
]


def _check_count(n, dimension):
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
        raise ValueError(f"n must be an integer >= 0, got {n!r}")
    if isinstance(dimension, bool) or not isinstance(dimension, (int, np.integer)) or not 1 <= dimension <= 3:
        raise ValueError(f"dimension must be 1, 2 or 3, got {dimension!r}")
    return int(n), int(dimension)


def _check_positive(name, value):
    value = float(value)
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return value


def _check_rng(rng):
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")


def lattice_sites_per_side(n, dimension):
    """The smallest ``k`` with ``k**dimension >= n`` (``ceil(n^(1/d))``, computed exactly)."""
    n, dimension = _check_count(n, dimension)
    if n == 0:
        return 0
    k = max(1, int(round(n ** (1.0 / dimension))))
    while k**dimension < n:
        k += 1
    while k > 1 and (k - 1) ** dimension >= n:
        k -= 1
    return k


def lattice_spacing(n, dimension, box_length):
    """Spacing ``box_length / k`` of the lattice used by :func:`lattice_positions`.

    ``k = ceil(n^(1/d))`` sites per side; for ``n = 0`` the spacing is ``box_length``.
    """
    k = lattice_sites_per_side(n, dimension)
    box_length = _check_positive("box_length", box_length)
    return box_length / max(k, 1)


def lattice_positions(n, dimension, box_length, rng):
    """Centres of ``n`` spheres on a cubic lattice in ``[0, box_length]^dimension``.

    The lattice has ``k = ceil(n^(1/d))`` sites per side with spacing
    ``a = box_length / k``; site ``(i_0, ..., i_{d-1})`` (``0 <= i_a < k``) is at
    ``((i_0 + 0.5) a, ..., (i_{d-1} + 0.5) a)``, the centre of its lattice cell.
    Sites are numbered in lattice order: lexicographic in ``(i_0, ..., i_{d-1})``, the
    last index varying fastest.

    If ``n == k^d`` every site is used, in lattice order, and ``rng`` is not used.
    Otherwise ``n`` distinct sites are drawn uniformly at random without replacement
    with ``rng`` (:meth:`numpy.random.Generator.choice`) and returned in lattice order.

    Returns a float64 array of shape ``(n, dimension)``.
    """
    n, dimension = _check_count(n, dimension)
    box_length = _check_positive("box_length", box_length)
    _check_rng(rng)
    if n == 0:
        return np.zeros((0, dimension), dtype=np.float64)
    k = lattice_sites_per_side(n, dimension)
    n_sites = k**dimension
    if n == n_sites:
        sites = np.arange(n_sites, dtype=np.int64)
    else:
        sites = np.sort(rng.choice(n_sites, size=n, replace=False)).astype(np.int64)
    index = np.stack(np.unravel_index(sites, (k,) * dimension), axis=1)
    spacing = box_length / k
    return (index.astype(np.float64) + 0.5) * spacing


def isotropic_velocities(n, dimension, speed, rng):
    """Velocities of magnitude ``speed`` with uniformly distributed directions (eq. 4.3).

    d = 2: ``V = speed (cos theta, sin theta)`` with ``theta ~ U[0, 2 pi)``.
    d = 3 (and d = 1): ``V = speed g / |g|`` with ``g`` a standard Gaussian vector, which is
    uniform on the sphere (for d = 1: a random sign).

    Returns a float64 array of shape ``(n, dimension)``.
    """
    n, dimension = _check_count(n, dimension)
    speed = float(speed)
    if not (math.isfinite(speed) and speed >= 0.0):
        raise ValueError(f"speed must be a finite number >= 0, got {speed!r}")
    _check_rng(rng)
    if dimension == 2:
        theta = rng.uniform(0.0, 2.0 * np.pi, size=n)
        return speed * np.stack([np.cos(theta), np.sin(theta)], axis=1)
    g = rng.standard_normal((n, dimension))
    norm = np.linalg.norm(g, axis=1)
    # A zero Gaussian vector has probability zero; redraw it (deterministically) if it occurs.
    for i in np.flatnonzero(norm == 0.0):
        while norm[i] == 0.0:
            g[i] = rng.standard_normal(dimension)
            norm[i] = np.linalg.norm(g[i])
    return speed * g / norm[:, None]


def uniform_cube_velocities(n, dimension, rng):
    """Velocities ``V = z - 1/2`` with ``z ~ U([0, 1]^d)`` (supplementary material A).

    Returns a float64 array of shape ``(n, dimension)``.
    """
    n, dimension = _check_count(n, dimension)
    _check_rng(rng)
    return rng.random((n, dimension)) - 0.5


def box_length_for_volume_fraction(n, dimension, radius, volume_fraction):
    """Box side ``L`` at which ``n`` spheres of radius ``radius`` fill ``volume_fraction``.

    d = 2: ``L = sqrt(n pi / V_f) R`` (Table 1); in general
    ``L = (n v_d / V_f)^(1/d) R`` with ``v_d`` the volume of the unit d-ball.
    """
    n, dimension = _check_count(n, dimension)
    radius = _check_positive("radius", radius)
    volume_fraction = _check_positive("volume_fraction", volume_fraction)
    if volume_fraction >= 1.0:
        raise ValueError(f"volume_fraction must be < 1, got {volume_fraction!r}")
    unit_ball = math.pi ** (dimension / 2.0) / math.gamma(dimension / 2.0 + 1.0)
    return (n * unit_ball / volume_fraction) ** (1.0 / dimension) * radius
