"""Debye's static structure factor S(q) of :mod:`parsim.core.scattering`, checked as a physicist would.

Against closed forms (two monomers, one monomer), the limits (S -> n as q -> 0 with Guinier's
curvature, S -> 1 at large q), an independent J0 (its integral representation), a brute-force
numpy sum, the histogram's error bound, freud's StaticStructureFactorDebye, and the fractal
regime S ~ q^-D_f of self-similar point sets of known dimension.
"""

import numpy as np
import pytest

from parsim.core import scattering
from parsim.core.scattering import J0_ABS_ERROR, bessel_j0, histogram_width, structure_factor
from parsim.core.statistics import radius_of_gyration
from tests.readers import require

# Nodes of the trapezoid rule for J0(x) = (1/pi) int_0^pi cos(x sin t) dt.  The integrand has
# period pi, so the rule over one period errs by 2 sum_k J_{2 k M}(x): below 1e-30 for x <= M/2.
J0_NODES = 256
LOG_PERIOD = np.log(3.0)  # the fractals below are self-similar under a scaling by 3


def j0_integral(x):
    """J0 of every element of ``x`` (0 <= x <= J0_NODES / 2) by the trapezoid rule, in numpy."""
    x = np.asarray(x, dtype=np.float64)
    assert x.max(initial=0.0) <= J0_NODES / 2
    t = np.pi * np.arange(J0_NODES) / J0_NODES
    return np.cos(x[..., None] * np.sin(t)).mean(axis=-1)


def brute_force(positions, q):
    """(1/n) sum_i sum_j f(q r_ij) over all n^2 ordered pairs, numpy broadcasting, f = sinc or J0."""
    r = np.linalg.norm(positions[:, None, :] - positions[None, :, :], axis=-1)
    if positions.shape[1] == 2:  # one q at a time: the integral's nodes make an n^2 x J0_NODES array
        return np.array([j0_integral(value * r).sum() for value in q]) / len(positions)
    x = q[:, None, None] * r[None]
    terms = np.sin(x) / np.where(x == 0.0, 1.0, x)
    terms[x == 0.0] = 1.0
    return terms.sum(axis=(1, 2)) / len(positions)


def pair_term(x, d):
    """f(x) of a pair, computed independently of parsim: sin(x) / x in 3-D, J0(x) in 2-D."""
    return np.sin(x) / x if d == 3 else j0_integral(x)


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("method", ["direct", "histogram"])
def test_two_monomers_and_one(d, method):
    """Two monomers at distance 1.7: S(q) = 1 + f(q 1.7); one monomer: S = 1 at every q.

    In 3-D the closed form holds to rounding; in 2-D to J0's error.  The histogram holds the one
    pair alone in its bin, whose mean distance is then the pair's: it is exact too (a bin centre
    instead of the mean would be up to half a bin off).
    """
    q = np.geomspace(1e-3, 50.0, 40)
    x = np.zeros((2, d))
    x[1] = 1.7 / np.sqrt(d)
    expected = 1.0 + pair_term(q * 1.7, d)
    tolerance = 1e-14 if d == 3 else J0_ABS_ERROR
    assert np.abs(structure_factor(x, q, method) - expected).max() <= tolerance
    assert np.array_equal(structure_factor(x[:1], q, method), np.ones_like(q))


@pytest.mark.parametrize("d, guinier", [(2, 2.0), (3, 3.0)])
def test_small_q_limit_and_guinier(d, guinier):
    """S -> n as q -> 0, then Guinier: S = n (1 - q^2 R_g^2 / c), c = 3 in 3-D and 2 in 2-D.

    sinc(x) and J0(x) lie within x^2/6 and x^2/4 of 1, so at q r_max = 1e-4, |S/n - 1| <= 3e-9.
    At q R_g = 1e-2 the next terms of the expansions are (q r)^2 / 20 (sinc) and (q r)^2 / 16 (J0)
    of the Guinier deficit, below 2e-4 of it for the pairs of this cluster (q r <= 0.05): the
    deficit is checked to 1e-3.
    """
    x = np.random.default_rng(11).normal(size=(100, d))
    r_max = np.linalg.norm(x[:, None] - x[None], axis=-1).max()
    s0 = structure_factor(x, np.array([1e-4 / r_max]), "direct")[0]
    assert abs(s0 / 100 - 1) <= 3e-9
    rg = radius_of_gyration(x)
    deficit = 1 - structure_factor(x, np.array([1e-2 / rg]), "direct")[0] / 100
    assert deficit == pytest.approx(1e-4 / guinier, rel=1e-3)


@pytest.mark.parametrize("d", [2, 3])
def test_large_q_limit(d):
    """S -> 1 at q far beyond the inverse of every pair distance, within the pairs' scatter.

    With phases q r_ij effectively random, S - 1 = (2/n) sum_{i<j} f(q r_ij) has mean ~0 and
    variance (4/n^2) sum_{i<j} <f^2>, with <f^2> = 1 / (2 (q r)^2) for sinc and 1 / (pi q r)
    for J0 (its envelope sqrt(2 / (pi x)) squared, halved).  Every q must be within 5 sigma.
    """
    n = 200
    x = np.random.default_rng(12).random((n, d))
    r = np.linalg.norm(x[:, None] - x[None], axis=-1)[np.triu_indices(n, 1)]
    q = np.geomspace(1e3, 1e4, 20) / r.min()
    mean_square = 1 / (2 * (q[:, None] * r) ** 2) if d == 3 else 1 / (np.pi * q[:, None] * r)
    sigma = 2 / n * np.sqrt(mean_square.sum(axis=1))
    deviation = structure_factor(x, q, "direct") - 1
    assert np.all(np.abs(deviation) <= 5 * sigma)
    assert sigma.max() < 0.05  # so that the check above says S is near 1


def test_j0_against_its_integral_representation():
    """The kernel's J0 (Abramowitz & Stegun 9.4.1/9.4.3) within J0_ABS_ERROR of the integral on [0, 100].

    The grid holds the approximation's switch at x = 3 and points on either side of it.
    """
    x = np.concatenate([np.linspace(0.0, 100.0, 20001), [3.0 - 1e-12, 3.0 + 1e-12]])
    kernel = np.array([bessel_j0(v) for v in x])
    assert np.abs(kernel - j0_integral(x)).max() <= J0_ABS_ERROR
    assert bessel_j0(-2.5) == bessel_j0(2.5)


@pytest.mark.parametrize("d", [2, 3])
def test_direct_against_brute_force(d):
    """"direct" against the n^2 terms summed by numpy, on random clusters of 40 monomers.

    3-D: relative 1e-12 (rounding of sums of 1600 terms).  2-D: parsim's J0 is an approximation,
    so S carries at most (n - 1) J0_ABS_ERROR; numpy's J0 is the integral, exact to rounding.
    """
    q = np.geomspace(0.05, 20.0, 30)
    for seed in range(3):
        x = np.random.default_rng(seed).normal(size=(40, d))
        direct, brute = structure_factor(x, q, "direct"), brute_force(x, q)
        if d == 3:
            np.testing.assert_allclose(direct, brute, rtol=1e-12, atol=0)
        else:
            assert np.abs(direct - brute).max() <= 39 * J0_ABS_ERROR


@pytest.mark.parametrize("d", [2, 3])
def test_histogram_against_direct(d):
    """"histogram" against "direct" on a random cluster of 300 monomers.

    The bound of the module docstring, (n - 1) C (q w)^2 with C = 1/6 (3-D) and 1/4 (2-D), holds
    at every q; it is the worst case.  The pairs' second-order errors have varied signs: their
    sum stays near (q w)^2 / 12 <= 8e-8 of S (measured: 2e-10 in 3-D, 3e-9 in 2-D), which is
    asserted to 1e-7.  Bin centres instead of mean distances would leave a first-order error,
    about 8e-6 of S here, and fail it.
    """
    n = 300
    x = np.random.default_rng(5).normal(size=(n, d)) * 5
    q = np.geomspace(0.01, 10.0, 60)
    direct, histogram = structure_factor(x, q, "direct"), structure_factor(x, q, "histogram")
    width = histogram_width(np.linalg.norm(x.max(axis=0) - x.min(axis=0)), q.max())
    bound = (n - 1) * (1 / 6 if d == 3 else 1 / 4) * (q * width) ** 2
    assert np.all(np.abs(histogram - direct) <= bound)
    np.testing.assert_allclose(histogram, direct, rtol=1e-7, atol=0)


def test_auto_chooses_by_cost():
    """"auto": direct up to 2e7 pair-q evaluations, or while the histogram has as many bins as pairs."""
    assert scattering._auto_method(10**6, 20, 10**4) == "direct"
    assert scattering._auto_method(10**6, 21, 10**4) == "histogram"
    assert scattering._auto_method(10**6, 21, 10**6) == "direct"
    x = np.random.default_rng(3).random((1500, 3)) * 10  # 1 124 250 pairs, 20 q: histogram
    q = np.geomspace(0.1, 10.0, 20)
    assert np.array_equal(structure_factor(x, q), structure_factor(x, q, "histogram"))
    assert np.array_equal(structure_factor(x[:100], q), structure_factor(x[:100], q, "direct"))


@pytest.mark.parametrize("d, rtol", [(3, 1e-4), (2, 5e-4)])
def test_against_freud(d, rtol):
    """parsim's S(q) against freud's StaticStructureFactorDebye on a random cluster of 200 points.

    freud's convention is parsim's: S(k) = (1/N) sum_i sum_j sinc(k r_ij), self terms included, so
    S(0) = N; J0 instead of sinc when the box is 2-D; k in freud is q here.  Its k grid is
    linspace(k_min, k_max, num_k_values) in float32 (its first value, k_min = 0, comes out as
    -7e-9): parsim is evaluated at those k, less the first.  The box is 100 times the cluster, so
    no periodic image is the nearest.  freud works in single precision: the phases k r_ij (up to
    350 here) and its running sums of 19 900 pair terms in float32 (eps = 6e-8) leave relative
    errors of order 1e-5 in 3-D and 1e-4 in 2-D (measured 2e-5 and 1.4e-4), hence the tolerances.
    """
    require("freud")
    import freud

    x = np.random.default_rng(7).uniform(-5.0, 5.0, (200, d))
    points = np.zeros((200, 3))
    points[:, :d] = x
    box = freud.box.Box.cube(1000.0) if d == 3 else freud.box.Box.square(1000.0)
    debye = freud.diffraction.StaticStructureFactorDebye(num_k_values=100, k_max=20.0, k_min=0.0)
    debye.compute((box, points))
    assert debye.S_k[0] == pytest.approx(200.0, rel=1e-6)  # k = 0: freud keeps the n self terms
    k = debye.k_values[1:].astype(np.float64)
    np.testing.assert_allclose(structure_factor(x, k), debye.S_k[1:], rtol=rtol, atol=0)


def digit_fractal(offsets, generations):
    """The points sum_{k < g} 3^k o_k, each o_k in ``offsets``: len(offsets) copies of generation
    g - 1 placed at 3^(g-1) o, a self-similar set of len(offsets)^g points on the unit lattice
    (spacing a = 1) of dimension log(len(offsets)) / log 3."""
    offsets = np.asarray(offsets, dtype=np.float64)
    x = np.zeros((1, offsets.shape[1]))
    for k in range(generations):
        x = (x[None] + offsets[:, None] * 3**k).reshape(-1, offsets.shape[1])
    return x


def fractal_slope(x, per_period=12):
    """The log-log slope of S(q) over whole log-periods from q R_g = 3 up to q a = 1/2.

    The window: S leaves Guinier's regime by q R_g ~ 3, and the power law of point monomers on a
    lattice of spacing a ends near q a ~ 1, where S has fallen to ~1; a narrower window such as
    [10/R_g, 0.1/a] is empty at the sizes a test can afford (10/R_g = 0.13 for the Vicsek fractal
    below).  The slope is the least-squares line through the means of ln S over each log-period
    (a factor 3 in q, sampled evenly in ln q): S = q^-D_f P(ln q) with P of period ln 3 puts those
    means on a line of slope -D_f, while a line fitted to ln S itself tilts with P's phase (by up
    to 0.4 over two periods, measured).
    """
    q0 = 3.0 / radius_of_gyration(x)
    periods = int(np.log(0.5 / q0) / LOG_PERIOD)
    assert periods >= 2
    q = q0 * np.exp(LOG_PERIOD * np.arange(periods * per_period) / per_period)
    means = np.log(structure_factor(x, q)).reshape(periods, per_period).mean(axis=1)
    return np.polyfit(LOG_PERIOD * np.arange(periods), means, 1)[0]


def test_fractal_regime_of_the_vicsek_fractal():
    """S ~ q^-D_f for 1/R_g << q << 1/a: the 3-D Vicsek fractal, D_f = log 7 / log 3 = 1.771.

    Five generations (16 807 monomers, R_g = 79.5): the window 3/R_g <= q <= 1/2 holds two whole
    log-periods, q in [0.038, 0.34].  Measured slope: -1.82 (-1.77 to -1.83 for windows starting
    anywhere in q R_g = 2 to 4).
    """
    centre_and_faces = np.vstack([np.zeros(3), np.eye(3), -np.eye(3)])
    slope = fractal_slope(digit_fractal(centre_and_faces, 5))
    assert slope == pytest.approx(-np.log(7) / np.log(3), abs=0.1)


def test_fractal_regime_of_the_cantor_dust():
    """S ~ q^-D_f in 2-D (the J0 form): the Cantor dust, 4 corner copies at scale 1/3, D_f = log 4 / log 3 = 1.262.

    Seven generations (16 384 monomers, R_g = 1093): four log-periods, q in [0.0027, 0.22].
    Measured slope: -1.29 (-1.28 to -1.33 for windows starting anywhere in q R_g = 2.5 to 4).
    The 2-D Vicsek fractal (D_f = 1.465) is not used: where the pair-distance density of a
    cluster of size R is cut off, J0 ~ (q r)^-1/2 leaves a term oscillating in q R whose size
    relative to q^-D_f goes as (q R)^(D_f - 3/2), here (q R)^-0.035, which never dies out: its
    slopes between successive log-periods scatter from -1.47 to -1.66, and this window gives
    -1.64 (measured, six generations).  The dust's term goes as (q R)^-0.24, the Vicsek fractal's
    in 3-D, with sinc ~ (q r)^-1, as (q R)^(D_f - 2) = (q R)^-0.23.
    """
    corners = [(a, b) for a in (-1.0, 1.0) for b in (-1.0, 1.0)]
    slope = fractal_slope(digit_fractal(corners, 7))
    assert slope == pytest.approx(-np.log(4) / np.log(3), abs=0.1)


@pytest.mark.parametrize("positions, q, method, argument", [
    (np.zeros((3, 4)), [1.0], "auto", "positions"),
    (np.zeros(3), [1.0], "auto", "positions"),
    (np.zeros((0, 3)), [1.0], "auto", "positions"),
    (np.array([[0.0, np.nan]]), [1.0], "auto", "positions"),
    (np.zeros((2, 3)), [[1.0]], "auto", "q"),
    (np.zeros((2, 3)), [], "auto", "q"),
    (np.zeros((2, 3)), [1.0, 0.0], "auto", "q"),
    (np.zeros((2, 3)), [1.0, -2.0], "direct", "q"),
    (np.zeros((2, 3)), [np.inf], "histogram", "q"),
    (np.zeros((2, 3)), [np.nan], "auto", "q"),
    (np.zeros((2, 3)), [1.0], "exact", "method"),
])
def test_bad_inputs_name_the_argument(positions, q, method, argument):
    with pytest.raises(ValueError, match=f"^{argument} must"):
        structure_factor(positions, q, method)


@pytest.mark.parametrize("dimension, fraction", [(2, 0.1), (3, 0.05)])
def test_an_aggregation_task_reports_the_structure_factor_of_its_final_cluster(dimension, fraction):
    """The dataset's S(q) on its q grid (in units of 1/R) is the brute-force sum over the final configuration;
    without ``compute_structure_factor = true`` it is NaN."""
    import parsim

    common = dict(seed=4, dimension=dimension, volume_fraction=fraction, structure_factor_points=6)
    asked = parsim.aggregate(64, compute_structure_factor=True, **common)
    q = asked.statistics.q.values / 0.2
    assert np.allclose(q * 0.2, np.geomspace(0.01, 2.0, 6), rtol=1e-15)
    expected = brute_force(asked.configuration.arrays["spheres/position"], q)
    np.testing.assert_allclose(asked.statistics.structure_factor.values, expected, rtol=1e-6)
    rg = radius_of_gyration(asked.configuration.arrays["spheres/position"])  # Guinier at the smallest q
    assert asked.statistics.structure_factor.values[0] == pytest.approx(64 * (1 - (q[0] * rg) ** 2 / dimension),
                                                                       rel=1e-3)
    assert np.isnan(parsim.aggregate(64, **common).statistics.structure_factor.values).all()
