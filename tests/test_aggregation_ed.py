"""Tests of the event-driven ballistic aggregation solver (parsim.core.ed)."""

import math

import numpy as np
import pytest

from parsim.core.ed import simulate_ed
from parsim.core.initial import (
    box_length_for_volume_fraction,
    isotropic_velocities,
    lattice_positions,
    lattice_spacing,
    uniform_cube_velocities,
)

#: Geometric tolerance relative to the radius: positions are exact up to round-off
#: (~1e-15 relative) accumulated over a few hundred events.
GEOM_TOL = 1e-9
#: Momentum tolerance relative to (cluster mass x max speed).
MOMENTUM_TOL = 1e-12


# ----------------------------------------------------------------------------- helpers


def a3_time(xi, xj, vi, vj, ri, rj):
    """Eq. A.3 of Degond et al. 2024, written out independently."""
    dx = np.subtract(xi, xj, dtype=float)
    dv = np.subtract(vi, vj, dtype=float)
    dxdv = dx @ dv
    sigma = dxdv**2 - (dv @ dv) * (dx @ dx - (ri + rj) ** 2)
    if dxdv >= 0 or sigma < 0:
        return math.inf
    return -(dxdv + math.sqrt(sigma)) / (dv @ dv)


def random_system(n, d, seed, polydisperse=True, volume_fraction=0.2):
    """Spheres on a lattice with jitter, radii in [0.1, 0.25], masses ~ R^d."""
    rng = np.random.default_rng(seed)
    r_max = 0.25
    radii = rng.uniform(0.1, r_max, n) if polydisperse else np.full(n, 0.2)
    L = box_length_for_volume_fraction(n, d, float(np.mean(radii)), volume_fraction)
    x = lattice_positions(n, d, L, rng)
    spacing = lattice_spacing(n, d, L)
    jitter = 0.5 * (spacing - 2 * r_max)
    assert jitter > 0
    x += rng.uniform(-jitter, jitter, x.shape)
    v = uniform_cube_velocities(n, d, rng)
    masses = radii**d
    return x, v, radii, masses, L


def pair_gaps(x, radii):
    """All pairwise |x_i - x_j| - (R_i + R_j) for i < j (brute force)."""
    diff = x[:, None, :] - x[None, :, :]
    dist = np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))
    iu = np.triu_indices(len(x), 1)
    return dist[iu] - (radii[:, None] + radii[None, :])[iu]


def reference_ed(x, v, radii, masses, L, max_events=100000):
    """Brute-force O(N^2)-per-event ED loop in plain numpy (the paper's method, SM A)."""
    x = np.array(x, dtype=float)
    v = np.array(v, dtype=float)
    n, d = x.shape
    label = np.arange(n)
    t = 0.0
    links, times = [], []
    iu, ju = np.triu_indices(n, 1)
    rsum = radii[iu] + radii[ju]
    for _ in range(max_events):
        if np.unique(label).size == 1:
            break
        dx = x[iu] - x[ju]
        dv = v[iu] - v[ju]
        b = np.einsum("ij,ij->i", dx, dv)
        a = np.einsum("ij,ij->i", dv, dv)
        c = np.einsum("ij,ij->i", dx, dx) - rsum**2
        sigma = b * b - a * c
        ok = (b < 0) & (sigma >= 0) & (label[iu] != label[ju])
        with np.errstate(divide="ignore", invalid="ignore"):
            tp = np.where(ok, -(b + np.sqrt(np.where(ok, sigma, 0.0))) / np.where(ok, a, 1.0), np.inf)
        tp = np.maximum(tp, 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            t_hi = np.where(v > 0, (L - radii[:, None] - x) / v, np.inf)
            t_lo = np.where(v < 0, (radii[:, None] - x) / v, np.inf)
        tw = np.maximum(np.minimum(t_hi, t_lo), 0.0)
        kp = int(np.argmin(tp))
        kw = int(np.argmin(tw))
        dt = min(tp[kp], tw.flat[kw])
        assert np.isfinite(dt)
        x += v * dt
        t += dt
        if tp[kp] <= tw.flat[kw]:
            i, j = iu[kp], ju[kp]
            both = (label == label[i]) | (label == label[j])
            vnew = (masses[both, None] * v[both]).sum(axis=0) / masses[both].sum()
            v[both] = vnew
            label[label == label[j]] = label[i]
            links.append((i, j))
            times.append(t)
        else:
            i, axis = divmod(kw, d)
            v[label == label[i], axis] *= -1.0
    return x, v, np.array(links, dtype=np.int64).reshape(-1, 2), np.array(times)


def union_find_components(n, links):
    parent = list(range(n))

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    merged = 0
    for i, j in links:
        ri, rj = find(i), find(j)
        if ri != rj:
            parent[ri] = rj
            merged += 1
    return merged, len({find(a) for a in range(n)})


# ------------------------------------------------------------------ hand-computed cases


def test_head_on_merge_time_and_velocity():
    x = np.array([[2.0, 5.0], [8.0, 5.1]])
    v = np.array([[1.5, 0.0], [-0.5, 0.0]])
    r = np.array([0.5, 0.3])
    m = np.array([1.0, 3.0])
    res = simulate_ed(x, v, r, m, 10.0)
    # Same line up to 0.1 offset: eq. A.3 by hand.
    dx, dv = x[0] - x[1], v[0] - v[1]
    b = dx @ dv
    sigma = b**2 - (dv @ dv) * (dx @ dx - 0.8**2)
    t_hand = -(b + math.sqrt(sigma)) / (dv @ dv)
    assert res.stop_reason == "single_cluster"
    assert res.n_collisions == 1 and res.n_events == 1 and res.n_wall_reflections == 0
    assert res.links.tolist() == [[0, 1]]
    assert res.merge_times[0] == pytest.approx(t_hand, abs=1e-12)
    assert res.time == pytest.approx(t_hand, abs=1e-12)
    v_common = (1.0 * v[0] + 3.0 * v[1]) / 4.0  # eq. 2.9 with unequal masses
    np.testing.assert_allclose(res.velocities, [v_common, v_common], atol=1e-15)
    np.testing.assert_allclose(res.positions, x + v * t_hand, atol=1e-12)
    assert np.linalg.norm(res.positions[0] - res.positions[1]) == pytest.approx(0.8, abs=1e-12)
    np.testing.assert_array_equal(res.cluster, [0, 0])


def test_oblique_merge_time_and_velocity():
    x = np.array([[1.0, 1.0], [4.0, 1.55]])  # impact parameter 0.55 < R_i + R_j = 0.7
    v = np.array([[1.0, 0.2], [-1.0, 0.2]])
    r = np.array([0.4, 0.3])
    m = np.array([2.0, 0.5])
    t_hand = a3_time(x[0], x[1], v[0], v[1], 0.4, 0.3)
    assert 0 < t_hand < 1.5
    res = simulate_ed(x, v, r, m, 6.0)
    assert res.stop_reason == "single_cluster"
    assert res.merge_times[0] == pytest.approx(t_hand, abs=1e-12)
    v_common = (2.0 * v[0] + 0.5 * v[1]) / 2.5
    np.testing.assert_allclose(res.velocities, [v_common, v_common], atol=1e-15)
    np.testing.assert_allclose(res.positions, x + v * t_hand, atol=1e-12)


def test_missing_pair_never_merges_before_wall():
    # Impact parameter 0.75 > 0.7: they pass each other; only walls act before max_time.
    x = np.array([[1.0, 1.0], [4.0, 1.75]])
    v = np.array([[1.0, 0.0], [-1.0, 0.0]])
    res = simulate_ed(x, v, [0.4, 0.3], [1.0, 1.0], 6.0, max_time=2.5)
    assert res.stop_reason == "max_time" and res.n_collisions == 0 and res.time == 2.5
    np.testing.assert_allclose(res.positions, x + v * 2.5, atol=1e-12)


def test_disc_reflects_at_wall():
    L, R, x0, vx = 10.0, 0.3, 7.0, 0.7
    x = np.array([[x0, 5.0], [2.0, 2.0]])
    v = np.array([[vx, 0.0], [0.0, 0.0]])
    res = simulate_ed(x, v, [R, 0.2], [1.0, 1.0], L, max_events=1)
    t_hand = (L - R - x0) / vx
    assert res.stop_reason == "max_events"
    assert res.n_wall_reflections == 1 and res.n_collisions == 0 and res.n_events == 1
    assert res.time == pytest.approx(t_hand, abs=1e-12)
    np.testing.assert_allclose(res.velocities[0], [-vx, 0.0])
    assert res.positions[0, 0] == pytest.approx(L - R, abs=1e-12)
    # Reflection then free flight: at t_hand + 2 the disc is 1.4 back from the wall.
    res = simulate_ed(x, v, [R, 0.2], [1.0, 1.0], L, max_time=t_hand + 2.0)
    assert res.stop_reason == "max_time" and res.n_wall_reflections == 1
    assert res.positions[0, 0] == pytest.approx(L - R - 2.0 * vx, abs=1e-12)


def test_two_disc_cluster_reflects_as_a_whole():
    L = 10.0
    x = np.array([[5.0, 5.0], [6.0, 5.0], [1.0, 1.0]])
    v = np.array([[1.0, 1.5], [0.0, 1.5], [0.0, 0.0]])
    r = np.array([0.25, 0.25, 0.25])
    m = np.array([1.0, 1.0, 1.0])
    res = simulate_ed(x, v, r, m, L, max_events=2)
    t_merge = 0.5  # gap 0.5 closed at relative speed 1
    vc = np.array([0.5, 1.5])
    x_merge = x[:2] + v[:2] * t_merge
    # The cluster's top (y + R = 5.75 + 0.25 at t_merge) reaches y = L first.
    t_wall = t_merge + (L - (x_merge[0, 1] + 0.25)) / vc[1]
    assert (L - (x_merge[1, 0] + 0.25)) / vc[0] > t_wall - t_merge
    assert res.stop_reason == "max_events"
    assert res.n_collisions == 1 and res.n_wall_reflections == 1
    assert res.merge_times[0] == pytest.approx(t_merge, abs=1e-12)
    assert res.time == pytest.approx(t_wall, abs=1e-12)
    np.testing.assert_allclose(res.velocities[:2], [[0.5, -1.5], [0.5, -1.5]], atol=1e-15)
    np.testing.assert_allclose(res.positions[1] - res.positions[0], [0.5, 0.0], atol=1e-12)
    # Later: both spheres still rigidly attached and moving together.
    later = simulate_ed(x, v, r, m, L, max_time=t_wall + 1.0)
    np.testing.assert_allclose(later.positions[1] - later.positions[0], [0.5, 0.0], atol=1e-12)
    np.testing.assert_allclose(later.positions[0], res.positions[0] + [0.5, -1.5], atol=1e-12)


def test_merged_cluster_touching_wall_reflects_at_once():
    L = 4.0
    # Sphere 0 rests against the right wall; sphere 1 hits it from the left.
    x = np.array([[L - 0.5, 2.0], [1.0, 2.0], [0.5, 0.5]])
    v = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 0.0]])
    res = simulate_ed(x, v, [0.5, 0.5, 0.2], [1.0, 1.0, 1.0], L, max_events=2)
    assert res.n_collisions == 1 and res.n_wall_reflections == 1
    assert res.merge_times[0] == pytest.approx(1.5, abs=1e-12)
    assert res.time == res.merge_times[0]
    np.testing.assert_allclose(res.velocities[:2], [[-0.5, 0.0], [-0.5, 0.0]])


def test_single_sphere_and_trivial_cases():
    res = simulate_ed([[1.0, 1.0]], [[1.0, 0.0]], [0.5], [1.0], 2.0)
    assert res.stop_reason == "single_cluster" and res.time == 0.0 and res.n_events == 0
    assert res.links.shape == (0, 2) and res.merge_times.shape == (0,)
    # Two spheres at rest never meet: nothing is left to happen.
    res = simulate_ed([[1.0, 1.0], [3.0, 3.0]], [[0.0, 0.0]] * 2, [0.5, 0.5], [1.0, 1.0], 4.0)
    assert res.stop_reason == "max_time" and res.n_events == 0
    res = simulate_ed([[1.0, 1.0], [3.0, 3.0]], [[0.0, 0.0]] * 2, [0.5, 0.5], [1.0, 1.0], 4.0, max_time=7.0)
    assert res.stop_reason == "max_time" and res.time == 7.0


# ------------------------------------------------------------------ physics invariants


@pytest.fixture(scope="module")
def run_300():
    x, v, r, m, L = random_system(300, 2, seed=7)
    res = simulate_ed(x, v, r, m, L, record_merges=True)
    return x, v, r, m, L, res


def test_momentum_conserved_at_every_merge(run_300):
    x, v, r, m, L, res = run_300
    assert res.stop_reason == "single_cluster"
    k = res.n_collisions
    assert res.merge_momentum_before.shape == (k, 2) == res.merge_momentum_after.shape
    # Mass of the merged cluster at each merge, from the links in order.
    parent = np.arange(len(m))
    mass = m.copy()

    def find(a):
        while parent[a] != a:
            a = parent[a]
        return a

    v_max = np.max(np.linalg.norm(v, axis=1))  # merges average, walls preserve speed
    for q, (i, j) in enumerate(res.links):
        ri, rj = find(i), find(j)
        assert ri != rj
        parent[ri] = rj
        mass[rj] += mass[ri]
        scale = mass[rj] * v_max
        err = np.abs(res.merge_momentum_after[q] - res.merge_momentum_before[q]).max()
        assert err <= MOMENTUM_TOL * scale
    # Without the flag the fields are empty.
    plain = simulate_ed(x, v, r, m, L, max_events=50)
    assert plain.merge_momentum_before.shape == (0, 2)
    assert plain.merge_momentum_after.shape == (0, 2)


def test_single_cluster_is_spanning_tree_of_contacts(run_300):
    x, v, r, m, L, res = run_300
    n = len(r)
    assert res.stop_reason == "single_cluster"
    assert res.links.shape == (n - 1, 2) and res.n_collisions == n - 1
    assert np.all(res.links[:, 0] < res.links[:, 1])
    assert np.all(np.diff(res.merge_times) >= 0)
    merged, components = union_find_components(n, res.links)
    assert merged == n - 1 and components == 1
    np.testing.assert_array_equal(res.cluster, np.zeros(n, dtype=np.int64))
    i, j = res.links.T
    dist = np.linalg.norm(res.positions[i] - res.positions[j], axis=1)
    np.testing.assert_allclose(dist, r[i] + r[j], rtol=0, atol=GEOM_TOL * r.mean())
    # One rigid cluster: every sphere carries the cluster velocity.
    assert np.all(res.velocities == res.velocities[0])


def test_no_overlap_in_final_and_intermediate_states():
    x, v, r, m, L = random_system(120, 2, seed=3)
    full = simulate_ed(x, v, r, m, L)
    tol = GEOM_TOL * r.mean()
    n_ev = full.n_events
    checkpoints = sorted({1, 2, 5, 10, 30, n_ev // 4, n_ev // 2, (3 * n_ev) // 4, n_ev - 1, n_ev})
    for k in checkpoints:
        part = simulate_ed(x, v, r, m, L, max_events=k)
        assert part.n_events == k
        assert part.stop_reason == ("single_cluster" if k == n_ev else "max_events")
        assert pair_gaps(part.positions, r).min() >= -tol
        assert np.all(part.positions - r[:, None] >= -tol)
        assert np.all(part.positions + r[:, None] <= L + tol)
        # The truncated run follows the full one.
        np.testing.assert_array_equal(part.links, full.links[: part.n_collisions])
    # States between events (free flight), via max_time.
    for tmax in np.linspace(0.0, full.time, 9)[1:-1]:
        part = simulate_ed(x, v, r, m, L, max_time=tmax)
        assert part.stop_reason == "max_time" and part.time == tmax
        assert pair_gaps(part.positions, r).min() >= -tol


@pytest.mark.parametrize("d, n, seed", [(2, 30, 11), (2, 50, 12), (3, 27, 13), (3, 40, 14)])
def test_agrees_with_brute_force_reference(d, n, seed):
    x, v, r, m, L = random_system(n, d, seed=seed, volume_fraction=0.2 if d == 2 else 0.1)
    xr, vr, links_ref, times_ref = reference_ed(x, v, r, m, L)
    res = simulate_ed(x, v, r, m, L)
    assert res.stop_reason == "single_cluster"
    np.testing.assert_array_equal(res.links, np.sort(links_ref, axis=1))
    np.testing.assert_allclose(res.merge_times, times_ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(res.positions, xr, rtol=0, atol=1e-9)
    np.testing.assert_allclose(res.velocities, vr, rtol=0, atol=1e-12)


def test_result_independent_of_skin():
    # The neighbour lists are an acceleration only: tiny and large skins agree.
    x, v, r, m, L = random_system(400, 2, seed=5)
    a = simulate_ed(x, v, r, m, L, skin=0.02)
    b = simulate_ed(x, v, r, m, L, skin=2.0)
    np.testing.assert_array_equal(a.links, b.links)
    np.testing.assert_allclose(a.merge_times, b.merge_times, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.positions, b.positions, rtol=0, atol=1e-9)
    assert a.n_wall_reflections == b.n_wall_reflections
    assert a.n_rebins > b.n_rebins


def test_lattice_isotropic_paper_setup_runs_to_single_cluster():
    rng = np.random.default_rng(2024)
    n, R = 400, 0.2
    L = box_length_for_volume_fraction(n, 2, R, 0.2)
    x = lattice_positions(n, 2, L, rng)
    v = isotropic_velocities(n, 2, 1.0, rng)
    res = simulate_ed(x, v, np.full(n, R), np.ones(n), L)
    assert res.stop_reason == "single_cluster" and res.n_collisions == n - 1
    assert pair_gaps(res.positions, np.full(n, R)).min() >= -GEOM_TOL * R


# ------------------------------------------------------------------ determinism, limits


def test_deterministic_bitwise():
    x, v, r, m, L = random_system(200, 2, seed=9)
    a = simulate_ed(x, v, r, m, L, record_merges=True)
    b = simulate_ed(x.copy(), v.copy(), r.copy(), m.copy(), L, record_merges=True)
    for name, va, vb in zip(a._fields, a, b):
        if isinstance(va, np.ndarray):
            assert va.dtype == vb.dtype, name
            assert va.tobytes() == vb.tobytes(), name
        else:
            assert va == vb, name


def test_inputs_not_modified_and_types():
    x, v, r, m, L = random_system(50, 2, seed=4)
    copies = [a.copy() for a in (x, v, r, m)]
    res = simulate_ed(x, v, r, m, L)
    for a, c in zip((x, v, r, m), copies):
        np.testing.assert_array_equal(a, c)
    assert res.cluster.dtype == np.int64 and res.links.dtype == np.int64
    assert res.merge_times.dtype == np.float64 and res.positions.dtype == np.float64
    assert isinstance(res.time, float) and isinstance(res.n_events, int)
    assert res.n_events == res.n_collisions + res.n_wall_reflections


def test_limits_and_stop_reasons():
    x, v, r, m, L = random_system(100, 2, seed=8)
    full = simulate_ed(x, v, r, m, L)
    assert full.stop_reason == "single_cluster"
    res = simulate_ed(x, v, r, m, L, max_events=17)
    assert res.stop_reason == "max_events" and res.n_events == 17
    res = simulate_ed(x, v, r, m, L, max_events=0)
    assert res.stop_reason == "max_events" and res.n_events == 0 and res.time == 0.0
    np.testing.assert_array_equal(res.positions, x)
    t_half = 0.5 * full.time
    res = simulate_ed(x, v, r, m, L, max_time=t_half)
    assert res.stop_reason == "max_time" and res.time == t_half
    assert np.all(res.merge_times <= t_half)
    n_before = int(np.sum(full.merge_times <= t_half))
    assert res.n_collisions == n_before
    # Cluster labels: compact, in order of first appearance.
    labels = res.cluster
    first = [labels[0]]
    for c in labels:
        if c not in first:
            first.append(c)
    assert first == list(range(labels.max() + 1))
    assert labels.max() + 1 == len(r) - res.n_collisions
    res = simulate_ed(x, v, r, m, L, max_time=2 * full.time)
    assert res.stop_reason == "single_cluster" and res.time == full.time


@pytest.mark.parametrize(
    "kwargs, word",
    [
        (dict(positions=np.zeros((2, 4))), "positions"),
        (dict(velocities=np.zeros((3, 2))), "velocities"),
        (dict(radii=[0.5, -0.1]), "radii"),
        (dict(masses=[1.0, 0.0]), "masses"),
        (dict(box_length=-1.0), "box_length"),
        (dict(positions=[[0.2, 1.0], [3.0, 3.0]]), "positions"),  # pokes out of the box
        (dict(positions=[[1.0, 1.0], [1.5, 1.0]]), "positions"),  # overlap
        (dict(max_time=-1.0), "max_time"),
        (dict(max_events=-3), "max_events"),
        (dict(skin=0.0), "skin"),
        (dict(velocities=[[np.nan, 0.0], [0.0, 0.0]]), "velocities"),
    ],
)
def test_bad_arguments_raise_value_error(kwargs, word):
    args = dict(positions=[[1.0, 1.0], [3.0, 3.0]], velocities=[[1.0, 0.0], [0.0, 0.0]],
                radii=[0.5, 0.5], masses=[1.0, 1.0], box_length=4.0)
    args.update(kwargs)
    with pytest.raises(ValueError, match=word):
        simulate_ed(**args)


def test_initial_overlap_within_tolerance_is_accepted():
    # Touching up to round-off and approaching: they collide at once (t = 0).
    res = simulate_ed([[1.0, 1.0], [2.0 - 1e-12, 1.0]], [[1.0, 0.0], [0.0, 0.0]],
                      [0.5, 0.5], [1.0, 1.0], 4.0)
    assert res.n_collisions == 1 and res.merge_times[0] == 0.0
    # Touching and separating: they never collide.
    res = simulate_ed([[1.0, 1.0], [2.0 - 1e-12, 1.0]], [[-1.0, 0.0], [0.0, 0.0]],
                      [0.5, 0.5], [1.0, 1.0], 4.0, max_events=1)
    assert res.n_collisions == 0 and res.n_wall_reflections == 1


def test_cluster_spanning_the_box_stops_along_that_axis():
    # Two touching discs fill the box width exactly and merge at t = 0 moving left: the
    # merged cluster touches both x walls, so it cannot reflect back and forth; its x
    # velocity is set to 0 (documented exception) and it keeps moving along y.
    L = 2.0
    x = np.array([[0.5, 0.5], [1.5, 0.5], [1.0, 1.8]])
    v = np.array([[0.0, 1.0], [-1.0, 0.0], [0.0, 0.0]])
    res = simulate_ed(x, v, [0.5, 0.5, 0.1], [1.0, 1.0, 1.0], L, max_time=0.5)
    assert res.stop_reason == "max_time"
    assert res.n_collisions == 1 and res.merge_times[0] == 0.0
    assert res.n_wall_reflections == 1
    np.testing.assert_allclose(res.velocities[:2], [[0.0, 0.5], [0.0, 0.5]])
    np.testing.assert_allclose(res.positions[:2], [[0.5, 0.75], [1.5, 0.75]], atol=1e-12)
