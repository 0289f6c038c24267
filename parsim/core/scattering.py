"""Static structure factor S(q) of a cluster of point-like monomers, by Debye's formula.

:func:`structure_factor` computes the isotropically averaged static structure factor of n
identical point scatterers at positions r_i (Debye 1915, "Zerstreuung von Röntgenstrahlen",
Ann. Phys. 351, 809; its use for fractal aggregates: Sorensen 2001, "Light scattering by fractal
aggregates: a review", Aerosol Sci. Technol. 35, 648):

- 3-D, averaged over all directions of q:   S(q) = (1/n) sum_i sum_j sin(q r_ij) / (q r_ij);
- 2-D (discs in a plane, q averaged over the directions of that plane, where
  (1/2 pi) int_0^{2 pi} exp(i q r cos phi) dphi = J0(q r)):   S(q) = (1/n) sum_i sum_j J0(q r_ij),

r_ij = |r_i - r_j|.  The n terms i = j are 1, so S(q) = 1 + (2/n) sum_{i<j} f(q r_ij) with
f = sinc (sin x / x, not sin(pi x)/(pi x)) or J0: S -> n as q -> 0 (Guinier:
S = n (1 - q^2 R_g^2 / 3) in 3-D, n (1 - q^2 R_g^2 / 2) in 2-D), S -> 1 at large q, and in between
S ~ (q R_g)^-D_f for a fractal of dimension D_f.

Two methods, equal up to the bound below:

- ``"direct"``: the double sum over the n (n - 1) / 2 pairs at every q, costing n^2/2 * n_q
  evaluations of f (about 15 ns each for sinc, 20 ns for J0 on one core), exact to rounding
  (and to the error of J0 in 2-D);
- ``"histogram"``: one pass over the pairs (n^2 / 2 distances, no f) builds a histogram of r_ij
  in bins of width w, keeping in each bin b its count c_b and the sum of its distances, so that
  r_b is the bin's mean distance; then S(q) = 1 + (2/n) sum_b c_b f(q r_b), costing n_q
  evaluations of f per non-empty bin.  Because r_b is the mean, the first-order terms
  f'(q r_b) q (r - r_b) of the pairs of a bin cancel exactly and each pair's error is the
  second-order remainder, at most (1/2) max|f''| (q w)^2, with max|sinc''| = 1/3 and
  max|J0''| = 1/2 (from sinc(x) = int_0^1 cos(x t) dt and J0(x) = (1/pi) int_0^pi cos(x sin t) dt).
  Hence, for every q (in 2-D for the exact J0, to within the error of its approximation below),

      |S_histogram(q) - S_direct(q)| <= (n - 1) C (q w)^2,  C = 1/6 (3-D), 1/4 (2-D),

  a worst case in which every pair's error has the same sign; the errors of the pairs have
  varied signs and add up to some (q w)^2 / 12 of S or less.  The width is
  w = HISTOGRAM_PHASE / q_max, so that q w <= 1e-3 at every q, unless that would take more than
  MAX_BINS bins (q_max r_max > 4194, r_max the diagonal of the positions' bounding box); the
  bins are then r_max / (MAX_BINS - 1) wide.

In 2-D, J0 is Abramowitz & Stegun (1964), Handbook of Mathematical Functions, 9.4.1 (x <= 3) and
9.4.3 (x > 3), polynomial and modulus-phase approximations with absolute error below
J0_ABS_ERROR; S(q) then carries an error of at most (n - 1) J0_ABS_ERROR.
"""

import math

import numpy as np

from parsim.core.jit import jit
from parsim.core.statistics import as_positions

METHODS = ("auto", "direct", "histogram")
#: q_max times the histogram's bin width: each pair's error is at most C (q w)^2 <= 2.5e-7.
HISTOGRAM_PHASE = 1e-3
#: At most this many histogram bins (a count and a sum each: 64 MiB).
MAX_BINS = 2**22
#: "auto" sums directly up to this many evaluations of f (pairs times q values), 0.3 s for sinc
#: and 0.4 s for J0 on one core: the histogram could save at most that much time, and would add
#: its error.  Above it, the histogram's pass over the pairs costs about what one q of the direct
#: sum costs (a distance per pair and no f), and it evaluates f only once per non-empty bin and q.
DIRECT_MAX_EVALUATIONS = 2e7
#: The bound on |J0(x) - J0 of this module| of Abramowitz & Stegun 9.4.1 (5e-8) and 9.4.3
#: (x^-1/2 (1.6e-8 + 0.8 * 7e-8) <= 4.2e-8 for x >= 3).
J0_ABS_ERROR = 5e-8


def structure_factor(positions, q, method="auto"):
    """Debye's static structure factor S(q) of point monomers at ``positions``, shape (len(q),).

    ``positions`` is (n, d), d = 2 (the J0 form) or 3 (the sinc form), n >= 1; ``q`` a 1-D array
    of finite wave numbers q > 0, in inverse units of the positions.  ``method`` is ``"direct"``
    (exact pair sum), ``"histogram"`` (pair distances binned, error bound in the module
    docstring) or ``"auto"``: direct while n (n - 1) / 2 * len(q) <= DIRECT_MAX_EVALUATIONS or
    while the histogram would have as many bins as there are pairs (it would then save nothing);
    histogram otherwise.
    """
    x, q = _checked(positions, q, method)
    n, planar = x.shape[0], x.shape[1] == 2
    pairs = n * (n - 1) // 2
    r_bound = float(np.linalg.norm(x.max(axis=0) - x.min(axis=0)))  # >= every r_ij
    width = histogram_width(r_bound, float(q.max()))
    n_bins = int(r_bound / width) + 1
    if method == "auto":
        method = _auto_method(pairs, q.size, n_bins)
    if method == "direct":
        sums = _direct_sums(x, q, planar)
    else:
        counts, distances = _distance_histogram(x, width, n_bins)
        full = counts > 0
        sums = _binned_sums(distances[full] / counts[full], counts[full].astype(np.float64), q, planar)
    return 1.0 + 2.0 * sums / n


def _auto_method(pairs, n_q, n_bins):
    """The method of ``"auto"`` for ``pairs`` pairs, ``n_q`` values of q and a histogram of ``n_bins`` bins.

    The histogram evaluates f n_q times per non-empty bin, of which there are at most
    min(n_bins, pairs): with as many bins as pairs it saves nothing on the direct sum.
    """
    if pairs * n_q <= DIRECT_MAX_EVALUATIONS or n_bins >= pairs:
        return "direct"
    return "histogram"


def histogram_width(r_bound, q_max):
    """The histogram's bin width: HISTOGRAM_PHASE / q_max, or wider if that needs over MAX_BINS bins."""
    return max(HISTOGRAM_PHASE / q_max, r_bound / (MAX_BINS - 1))


def _checked(positions, q, method):
    """``positions`` and ``q`` as contiguous float64 arrays, or ValueError naming the bad argument."""
    x = as_positions(positions)
    q = np.ascontiguousarray(q, dtype=np.float64)
    if q.ndim != 1 or q.size < 1:
        raise ValueError(f"q must be a non-empty 1-D array, got shape {q.shape}")
    if not np.all(np.isfinite(q) & (q > 0)):
        raise ValueError("q must hold finite values q > 0")
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    return x, q


@jit(inline="always")
def bessel_j0(x):
    """J0(x), the Bessel function of the first kind of order 0, with |error| < J0_ABS_ERROR.

    Abramowitz & Stegun 9.4.1 for |x| <= 3: a polynomial in (x/3)^2; 9.4.3 for |x| > 3:
    J0 = x^-1/2 f0 cos(theta0), f0 and theta0 - x polynomials in 3/x.  J0 is even.
    """
    x = abs(x)
    if x <= 3.0:
        y = (x / 3.0) ** 2
        return 1.0 + y * (-2.2499997 + y * (1.2656208 + y * (-0.3163866 + y * (0.0444479 + y * (
            -0.0039444 + y * 0.0002100)))))
    y = 3.0 / x
    f0 = 0.79788456 + y * (-0.00000077 + y * (-0.00552740 + y * (-0.00009512 + y * (0.00137237 + y * (
        -0.00072805 + y * 0.00014476)))))
    theta0 = x - 0.78539816 + y * (-0.04166397 + y * (-0.00003954 + y * (0.00262573 + y * (-0.00054125 + y * (
        -0.00029333 + y * 0.00013558)))))
    return f0 * math.cos(theta0) / math.sqrt(x)


@jit(inline="always")
def _pair_term(x, planar):
    """A pair's term f(q r_ij) of Debye's sum at x = q r_ij: J0(x) in 2-D, sin(x) / x in 3-D."""
    if planar:
        return bessel_j0(x)
    if x == 0.0:  # coincident monomers; elsewhere sin(x) / x is accurate down to the smallest x
        return 1.0
    return math.sin(x) / x


@jit(inline="always")
def _distance(x, i, j):
    """|x_i - x_j|."""
    s = 0.0
    for k in range(x.shape[1]):
        s += (x[i, k] - x[j, k]) ** 2
    return math.sqrt(s)


@jit
def _direct_sums(x, q, planar):
    """sum_{i<j} f(q r_ij) at every q, f = J0 if ``planar`` else sinc."""
    sums = np.zeros(q.size)
    for i in range(x.shape[0] - 1):
        for j in range(i + 1, x.shape[0]):
            r = _distance(x, i, j)
            for k in range(q.size):
                sums[k] += _pair_term(q[k] * r, planar)
    return sums


@jit
def _distance_histogram(x, width, n_bins):
    """Count and sum of the pair distances r_ij (i < j) in bins [b w, (b + 1) w), b < n_bins.

    A distance that rounding puts past the last bin (n_bins w exceeds every r_ij) goes to it.
    """
    counts = np.zeros(n_bins, dtype=np.int64)
    distances = np.zeros(n_bins)
    for i in range(x.shape[0] - 1):
        for j in range(i + 1, x.shape[0]):
            r = _distance(x, i, j)
            b = min(int(r / width), n_bins - 1)
            counts[b] += 1
            distances[b] += r
    return counts, distances


@jit
def _binned_sums(radii, weights, q, planar):
    """sum_b weights_b f(q radii_b) at every q, f = J0 if ``planar`` else sinc."""
    sums = np.zeros(q.size)
    for b in range(radii.size):
        for k in range(q.size):
            sums[k] += weights[b] * _pair_term(q[k] * radii[b], planar)
    return sums
