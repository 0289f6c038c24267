"""Aggregates of monomers of many sizes: lognormal radii for both methods, contacts at alpha_R (r_i + r_j) / 2,
the radius of gyration weighted by mass with each monomer's own second moment, and the fractal law
N = k_f (R_g / a)^D_f fitted on a dataset."""

import math

import numpy as np
import pytest
import xarray as xr

import parsim
from parsim.core.statistics import contact_pairs, mass_radius_of_gyration
from parsim.errors import JobError
from tests.method_agreement import assert_time_stepping_agrees


@pytest.mark.parametrize("method, dimension, n, fraction", [("ed", 2, 100, 0.1), ("ts", 2, 64, 0.1),
                                                            ("ed", 3, 64, 0.03), ("ts", 3, 27, 0.03)])
def test_lognormal_radii_of_unit_spread_are_the_monodisperse_run_bit_for_bit(method, dimension, n, fraction):
    common = dict(seed=11, method=method, dimension=dimension, volume_fraction=fraction)
    equal = parsim.aggregate(n, **common)
    lognormal = parsim.aggregate(n, radius_distribution="lognormal", radius_geometric_std=1.0, **common)
    for name, array in equal.configuration.arrays.items():
        assert np.array_equal(array, lognormal.configuration.arrays[name]), name
    for name in ("radius_of_gyration", "contact_number", "fractal_dimension", "pair_distribution"):
        assert np.array_equal(equal.statistics[name].values, lognormal.statistics[name].values), name


@pytest.mark.parametrize("method, dimension, n, fraction", [("ed", 2, 144, 0.1), ("ts", 2, 100, 0.1),
                                                            ("ed", 3, 64, 0.03), ("ts", 3, 64, 0.03)])
def test_a_lognormal_run_aggregates_its_monomers_at_their_own_contact_distances(method, dimension, n, fraction):
    """The final cluster holds every monomer, its radii are lognormal around the median with the masses of one
    density, no two monomers overlap deeper than the method allows, and every link touches at r_i + r_j."""
    run = parsim.aggregate(n, seed=5, method=method, dimension=dimension, volume_fraction=fraction,
                           radius_distribution="lognormal", radius_geometric_std=1.3)
    arrays = run.configuration.arrays
    x, r, m = arrays["spheres/position"], arrays["spheres/radius"], arrays["spheres/mass"]
    assert int(run.statistics.n_clusters) == 1
    assert len(np.unique(r)) == n and np.allclose(m, (r / 0.2) ** dimension)
    assert abs(np.log(r / 0.2).std() - math.log(1.3)) < 0.5 * math.log(1.3)
    gaps = np.linalg.norm(x[:, None] - x[None], axis=-1) - (r[:, None] + r[None])
    np.fill_diagonal(gaps, np.inf)
    tolerance = 1e-9 if method == "ed" else 0.02  # DAHA leaves overlaps of about eps_c (eq. 3.28)
    assert gaps.min() > -tolerance
    i, j = arrays["links"].T
    assert np.allclose(gaps[i, j], 0.0, atol=tolerance)


def test_contacts_of_unequal_monomers_count_at_the_mean_of_their_radii():
    """Radii 1 and 2 at distance 3.1: in contact for alpha_R = 2.1 (bound 3.15), not for alpha_R = 2.0 (3.0);
    eq. 4.6's self pairs add n."""
    x = np.array([[0.0, 0.0], [3.1, 0.0], [50.0, 0.0]])
    r = np.array([1.0, 2.0, 1.0])
    assert contact_pairs(x, r, 2.1) == 3 + 2
    assert contact_pairs(x, r, 2.0) == 3


def test_radius_of_gyration_of_monomers_weighted_by_mass_with_their_own_moments():
    """One ball: sqrt(3/5) r; one disc: r / sqrt(2); two balls of masses 1 and 3 at distance d: the parallel
    axis theorem, (1 * (3d/4)^2 + 3 * (d/4)^2) / 4 + 3/5 (1 r1^2 + 3 r2^2) / 4."""
    assert mass_radius_of_gyration([[1.0, 2.0, 3.0]], [0.5], [2.0]) == pytest.approx(math.sqrt(0.6) * 0.5, rel=1e-15)
    assert mass_radius_of_gyration([[1.0, 2.0]], [0.5], [2.0]) == pytest.approx(0.5 / math.sqrt(2.0), rel=1e-15)
    d, r1, r2 = 2.0, 0.3, 0.7
    expected = (1 * (0.75 * d) ** 2 + 3 * (0.25 * d) ** 2) / 4 + 0.6 * (r1**2 + 3 * r2**2) / 4
    value = mass_radius_of_gyration([[0.0, 0.0, 0.0], [d, 0.0, 0.0]], [r1, r2], [1.0, 3.0])
    assert value == pytest.approx(math.sqrt(expected), rel=1e-14)


def test_a_lognormal_lattice_that_cannot_hold_the_largest_monomer_is_refused():
    with pytest.raises(JobError, match="largest radius drawn.*radius_geometric_std"):
        parsim.aggregate(400, seed=1, dimension=3, volume_fraction=0.3, radius_distribution="lognormal",
                         radius_geometric_std=1.5)
    with pytest.raises(JobError, match="radius_geometric_std = 1.3 needs radius_distribution = 'lognormal'"):
        parsim.aggregate(100, seed=1, volume_fraction=0.1, radius_geometric_std=1.3)


def _law_dataset(rng, sizes, realisations, fractions, dimension, prefactor, noise):
    """A dataset of R_g = a (N / k_f)^(1/D_f) exp(noise), as fractal_law reads it."""
    shape = (len(sizes), len(fractions), realisations)
    n = np.array(sizes, dtype=float)[:, None, None]
    rg = 0.2 * (n / prefactor) ** (1.0 / dimension[None, :, None]) * np.exp(noise * rng.standard_normal(shape))
    dims = ("n_spheres", "volume_fraction", "realization")
    return xr.Dataset({"radius_of_gyration": (dims, rg), "n_clusters": (dims, np.ones(shape, dtype=np.int64))},
                      coords={"n_spheres": sizes, "volume_fraction": fractions, "realization": range(realisations),
                              "radius": 0.2})


def test_fractal_law_recovers_an_exact_law_and_agrees_with_numpy_least_squares():
    rng = np.random.default_rng(3)
    dimension = np.array([1.5, 1.8])
    exact = parsim.fractal_law(_law_dataset(rng, [50, 100, 200, 400], 5, [0.1, 0.2], dimension, 1.3, 0.0))
    assert np.allclose(exact.fractal_dimension, dimension, rtol=1e-12)
    assert np.allclose(exact.fractal_prefactor, 1.3, rtol=1e-12)
    assert np.all(exact.fractal_dimension_error < 1e-10) and np.all(exact.tasks == 20)
    noisy_data = _law_dataset(rng, [50, 100, 200, 400], 5, [0.1, 0.2], dimension, 1.3, 0.05)
    noisy = parsim.fractal_law(noisy_data)
    for k, fraction in enumerate([0.1, 0.2]):
        point = noisy_data.sel(volume_fraction=fraction)
        x = np.log(point.radius_of_gyration.values / 0.2).ravel()
        y = np.log(np.broadcast_to(point.n_spheres.values[:, None], point.radius_of_gyration.shape)).ravel()
        (slope, intercept), cov = np.polyfit(x, y, 1, cov=True)
        assert noisy.fractal_dimension[k] == pytest.approx(slope, rel=1e-10)
        assert noisy.fractal_prefactor[k] == pytest.approx(math.exp(intercept), rel=1e-10)
        assert noisy.fractal_dimension_error[k] == pytest.approx(math.sqrt(cov[0, 0]), rel=1e-8)
        assert noisy.fractal_prefactor_error[k] == pytest.approx(math.exp(intercept) * math.sqrt(cov[1, 1]), rel=1e-8)
        assert abs(slope - dimension[k]) < 4 * math.sqrt(cov[0, 0])


def test_fractal_law_leaves_out_tasks_that_did_not_end_as_one_cluster():
    rng = np.random.default_rng(4)
    data = _law_dataset(rng, [50, 100, 200], 4, [0.1], np.array([1.6]), 1.1, 0.05)
    spoiled = data.copy(deep=True)
    spoiled.n_clusters[0, 0, 0] = 3
    spoiled.radius_of_gyration[0, 0, 0] = 100.0
    kept = data.where(spoiled.n_clusters == 1)
    assert float(parsim.fractal_law(spoiled).fractal_dimension[0]) == pytest.approx(
        float(parsim.fractal_law(kept.assign(n_clusters=spoiled.n_clusters)).fractal_dimension[0]), rel=1e-12)
    assert int(parsim.fractal_law(spoiled).tasks[0]) == 11


def test_fractal_law_of_a_job_and_its_errors(tmp_path):
    job = {"name": "law", "kind": "aggregation", "seed": 2, "realizations": 3,
           "parameters": {"method": "ed", "dimension": 2, "volume_fraction": 0.1, "radius_distribution": "lognormal",
                          "radius_geometric_std": 1.2},
           "sweep": {"n_spheres": [36, 72, 144]}}
    dataset = parsim.run(job, output=tmp_path / "law", progress=False)
    law = parsim.fractal_law(dataset)
    assert int(law.tasks) == 9 and 1.0 < float(law.fractal_dimension) < 2.5
    assert 0.0 < float(law.fractal_dimension_error) < 0.5
    with pytest.raises(ValueError, match=r"needs n_spheres swept over two values or more; this dataset has n_spheres"):
        parsim.fractal_law(dataset.isel(n_spheres=[0]).squeeze("n_spheres"))
    with pytest.raises(ValueError, match="needs 'radius_of_gyration'"):
        parsim.fractal_law(dataset.drop_vars("radius_of_gyration"))


def test_time_stepping_agrees_with_event_driven_on_lognormal_monomers(tmp_path):
    """sigma_g = 1.3, both methods from the same initial conditions: the test of docs/ts-vs-ed.md, D_f within
    5 % at every point and 3 % on average (Fig. 11's bounds), N_c of tree-like clusters for both (Fig. 7), and
    A_r within two standard errors of the difference."""
    job = {"name": "poly", "kind": "aggregation", "seed": 7, "realizations": 10,
           "parameters": {"dimension": 2, "radius_distribution": "lognormal", "radius_geometric_std": 1.3},
           "sweep": {"method": ["ed", "ts"], "n_spheres": [100, 400], "volume_fraction": [0.05, 0.1]}}
    dataset = parsim.run(job, output=tmp_path / "poly", progress=False)
    assert_time_stepping_agrees(dataset, contacts_ed=(0.45, 0.6), contacts_ts=(0.45, 0.65))
