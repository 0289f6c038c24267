"""Tests of size distributions given as sieve curves (parsim.deposition.sieve)."""

import math
import re

import numpy as np
import pytest

from parsim.deposition.sieve import (
    SieveCurve,
    fraction_passing,
    mean_cubed_size,
    read_sieve_curve,
    sample_sizes,
    size_range,
)
from parsim.errors import JobError

N = 20_000
#: Tolerance in standard errors of the sampling: a correct sampler exceeds it with probability < 1e-6.
SIGMAS = 5.0
#: Kolmogorov's critical value of sqrt(n) * KS statistic at the 0.1 % level.
KOLMOGOROV_0_001 = 1.95

# fines (5 % below the smallest sieve) and an empty interval (1.25 to 1.6)
GRADING = "1.0,5\n1.25,20\n1.6,20\n2.0,55\n2.5,90\n3.15,100\n"
GRADING_CURVE = SieveCurve((1.0, 1.25, 1.6, 2.0, 2.5, 3.15), (0.05, 0.2, 0.2, 0.55, 0.9, 1.0))
#: The grading curve's sieves and the one step below the smallest that ends its fines.
GRADING_SIEVES = np.array([0.8, *GRADING_CURVE.sizes])
GRADING_PASSING = np.array([0.0, *GRADING_CURVE.passing])


def two_sieves(smallest, largest):
    return SieveCurve((smallest, largest), (0.0, 1.0))


def log_uniform_cdf(a, b):
    return lambda d: np.log(d / a) / np.log(b / a)


def ks_statistic(samples, cdf):
    """The largest distance between the samples' empirical cumulative and ``cdf``."""
    values = cdf(np.sort(samples))
    n = len(samples)
    return max(np.max(np.arange(1, n + 1) / n - values), np.max(values - np.arange(n) / n))


def write(tmp_path, text, name="curve.csv", encoding="utf-8"):
    path = tmp_path / name
    path.write_text(text, encoding=encoding, newline="")
    return path


# reading

def test_reads_the_curve_as_fractions(tmp_path):
    assert read_sieve_curve(write(tmp_path, GRADING)) == GRADING_CURVE


def test_header_semicolons_whitespace_and_order_parse_identically(tmp_path):
    variants = [
        "sieve size (mm),passing (%)\n" + GRADING,
        "\ufeffsieve size (mm); passing (%)\r\n1,0;5\r\n1,25;20\r\n1,6;20\r\n2,0;55\r\n2,5;90\r\n3,15;100\r\n",
        "# grading of a sand\n\n3.15 100\n1.6\t20\n1.0   5  # pan below\n2.5 90\n\n2.0 55\n1.25 20\n",
        "2.0;55\n1.0;5\n3.15;100\n1.25;20\n2.5;90\n1.6;20\n",
    ]
    for number, text in enumerate(variants):
        assert read_sieve_curve(write(tmp_path, text, f"curve{number}.csv")) == GRADING_CURVE, text


MALFORMED = {
    "one sieve": ("size,passing\n1.0,100\n", "line 2", "at least 2"),
    "zero size": ("1,0\n0,50\n2,100\n", "line 2", "a size from 1e-30 to 1e+30"),
    "negative size": ("1,0\n-1,50\n2,100\n", "line 2", "a size from 1e-30 to 1e+30"),
    "infinite size": ("1,0\ninf,100\n", "line 2", "a size from 1e-30 to 1e+30"),
    "size whose cube is below double precision": ("1e-200,10\n1e-199,100\n", "line 1", "a size from 1e-30"),
    "size whose cube overflows": ("1e200,10\n1e201,100\n", "line 1", "to 1e+30"),
    "duplicate size": ("1,0\n2,100\n1.0,50\n", "lines 1 and 3", "each size once"),
    "passing above 100": ("1,0\n1.5,101\n2,100\n", "line 2", "0 to 100"),
    "passing below 0": ("1,-1\n2,100\n", "line 1", "0 to 100"),
    "passing not a number": ("1,0\n1.5,nan\n2,100\n", "line 2", "0 to 100"),
    "passing decreasing": ("1,0\n1.5,60\n1.2,70\n2,100\n", "line 2", "never decreases"),
    "largest below 100": ("1,0\n2,99.5\n", "line 2", "100 %"),
    "text among numbers": ("1,0\nabc,50\n2,100\n", "line 2", "two numbers"),
    "three columns": ("# sizes in mm\n1,0,3\n2,100\n", "line 2", "two numbers"),
}


@pytest.mark.parametrize("text, line, allowed", MALFORMED.values(), ids=MALFORMED.keys())
def test_malformed_file_names_file_line_and_what_is_allowed(tmp_path, text, line, allowed):
    path = write(tmp_path, text, "bad_grading.csv")
    with pytest.raises(JobError) as error:
        read_sieve_curve(path)
    message = str(error.value)
    assert str(path) in message and re.search(rf"\b{line}(?!\d)", message)
    assert "allowed" in message and allowed in message


def test_empty_or_missing_file_is_refused(tmp_path):
    with pytest.raises(JobError, match="found 0 sieve.*at least 2"):
        read_sieve_curve(write(tmp_path, "size,passing\n# nothing measured\n"))
    with pytest.raises(JobError, match="no such file"):
        read_sieve_curve(tmp_path / "absent.csv")


# the curve between sieves

def test_cumulative_is_linear_in_log_size_with_fines_one_step_below():
    at_sieves = fraction_passing(GRADING_CURVE, GRADING_SIEVES)
    np.testing.assert_allclose(at_sieves, GRADING_PASSING, atol=1e-15)
    middles = np.sqrt(GRADING_SIEVES[:-1] * GRADING_SIEVES[1:])
    np.testing.assert_allclose(fraction_passing(GRADING_CURVE, middles),
                               (GRADING_PASSING[:-1] + GRADING_PASSING[1:]) / 2, atol=1e-15)
    np.testing.assert_array_equal(fraction_passing(GRADING_CURVE, [0.5, 0.79, 3.2, 10.0]), [0, 0, 1, 1])


def test_size_range_is_where_material_is():
    assert size_range(GRADING_CURVE) == pytest.approx((0.8, 3.15))
    assert size_range(SieveCurve((0.5, 1.0, 2.0, 4.0, 8.0), (0.0, 0.0, 0.5, 1.0, 1.0))) == (1.0, 4.0)


# sampling

def test_mass_basis_reproduces_the_mass_fraction_passing_each_sieve():
    sizes = sample_sizes(GRADING_CURVE, "mass", N, np.random.default_rng(1))
    assert sizes.dtype == np.float64 and sizes.shape == (N,)
    volume = sizes**3
    for sieve, target in zip(GRADING_SIEVES, GRADING_PASSING):
        passing = sizes <= sieve
        realised = volume[passing].sum() / volume.sum()
        # standard error of a ratio estimator (delta method); 0 where the target is 0 or 1
        error = math.sqrt(np.sum((volume * (passing - target)) ** 2)) / volume.sum()
        assert abs(realised - target) <= SIGMAS * error, (sieve, realised, target, error)


def test_number_basis_reproduces_the_number_fraction_passing_each_sieve():
    sizes = sample_sizes(GRADING_CURVE, "number", N, np.random.default_rng(2))
    for sieve, target in zip(GRADING_SIEVES, GRADING_PASSING):
        realised = np.mean(sizes <= sieve)
        error = math.sqrt(target * (1.0 - target) / N)  # binomial
        assert abs(realised - target) <= SIGMAS * error, (sieve, realised, target, error)


def test_sizes_stay_within_the_size_range():
    for basis in ("mass", "number"):
        sizes = sample_sizes(GRADING_CURVE, basis, N, np.random.default_rng(3))
        smallest, largest = size_range(GRADING_CURVE)
        assert smallest <= sizes.min() and sizes.max() <= largest
        assert not np.any((sizes > 1.25) & (sizes < 1.6))  # the empty interval


def test_two_sieves_by_number_are_log_uniform():
    a, b = 0.5, 2.0
    sizes = sample_sizes(two_sieves(a, b), "number", N, np.random.default_rng(4))
    assert ks_statistic(sizes, log_uniform_cdf(a, b)) <= KOLMOGOROV_0_001 / math.sqrt(N)
    assert mean_cubed_size(two_sieves(a, b), "number") == pytest.approx((b**3 - a**3) / (3 * math.log(b / a)))


def test_two_sieves_by_mass_have_number_density_d_to_the_minus_4():
    # mass uniform in ln d: f_m(d) ~ 1/d per unit d, so f_n(d) ~ f_m(d) / d^3 ~ d^-4 on [a, b]
    a, b = 0.5, 2.0
    sizes = sample_sizes(two_sieves(a, b), "mass", N, np.random.default_rng(5))
    assert ks_statistic(sizes, lambda d: (a**-3 - d**-3) / (a**-3 - b**-3)) <= KOLMOGOROV_0_001 / math.sqrt(N)
    assert ks_statistic(sizes, log_uniform_cdf(a, b)) > 10 * KOLMOGOROV_0_001 / math.sqrt(N)  # tells them apart
    # E_n[d^3] = integral of d^-1 / integral of d^-4
    assert mean_cubed_size(two_sieves(a, b), "mass") == pytest.approx(math.log(b / a) / ((a**-3 - b**-3) / 3))


def test_mean_cubed_size_is_the_mean_volume_of_the_drawn_sizes():
    for seed, basis in enumerate(("mass", "number")):
        cubes = sample_sizes(GRADING_CURVE, basis, N, np.random.default_rng(10 + seed)) ** 3
        error = cubes.std() / math.sqrt(N)
        assert abs(cubes.mean() - mean_cubed_size(GRADING_CURVE, basis)) <= SIGMAS * error, basis


def test_same_seed_same_sizes():
    for basis in ("mass", "number"):
        first = sample_sizes(GRADING_CURVE, basis, 1000, np.random.default_rng(7))
        np.testing.assert_array_equal(first, sample_sizes(GRADING_CURVE, basis, 1000, np.random.default_rng(7)))
        assert not np.array_equal(first, sample_sizes(GRADING_CURVE, basis, 1000, np.random.default_rng(8)))


def test_unknown_basis_names_the_allowed_ones():
    with pytest.raises(JobError, match="'volume'.*allowed: 'mass', 'number'"):
        sample_sizes(GRADING_CURVE, "volume", 10, np.random.default_rng(0))
    with pytest.raises(JobError, match="allowed: 'mass', 'number'"):
        mean_cubed_size(GRADING_CURVE, "count")
