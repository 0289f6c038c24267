"""SDBD event solvers against brute-force rotation of the particle in small angle steps.

Every solver of :mod:`parsim.core.sdbd.events` is compared with the first angle at which
the event happens when the configuration is rotated (Rodrigues' formula written out here
with numpy) in steps of ``STEP`` radians, the crossing being refined by bisection.
"""

import math

import numpy as np
import pytest

from parsim.core.sdbd import events as ev
from parsim.core.sdbd import rotation as rot

STEP = 1e-5
TWO_PI = 2 * math.pi


# ----------------------------------------------------------------------------- helpers
def rotate(x, pivot, axis, phi):
    """Rotate points ``x`` (..., 3) by angles ``phi`` (m,) about ``axis`` through ``pivot``:
    returns (m, ..., 3)."""
    x = np.asarray(x, float)
    phi = np.atleast_1d(phi)
    r = x - pivot
    c = np.cos(phi).reshape((-1,) + (1,) * r.ndim)
    s = np.sin(phi).reshape((-1,) + (1,) * r.ndim)
    return pivot + c * r + s * np.cross(axis, r) + (1 - c) * (r @ axis)[..., None] * axis


def first_true(pred, phi_max=np.pi, step=STEP):
    """First angle in (0, phi_max] where ``pred(phi)`` (vectorised) becomes true, refined by
    bisection; ``inf`` if it never does on the grid."""
    grid = np.arange(1, int(phi_max / step) + 1) * step
    hit = pred(grid)
    k = np.argmax(hit)
    if not hit[k]:
        return np.inf
    lo = grid[k - 1] if k > 0 else 0.0
    hi = grid[k]
    if pred(np.array([lo]))[0]:
        return lo
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if pred(np.array([mid]))[0]:
            hi = mid
        else:
            lo = mid
    return 0.5 * (lo + hi)


def unit(v):
    return v / np.linalg.norm(v)


def random_unit(rng):
    return unit(rng.normal(size=3))


def steepest_axis(com, pivot):
    """Eq. 6: n = e_z x (r_cm - r_s) / |...|."""
    return unit(np.cross([0.0, 0.0, 1.0], com - pivot))


def single_contact_setup(rng):
    """A particle touching a sediment sphere: pivot s1, contact sphere a1, centre of mass."""
    rs = rng.uniform(0.5, 1.5)
    ra = rng.uniform(0.5, 1.5)
    s1 = rng.normal(size=3)
    d = random_unit(rng)
    d[2] = abs(d[2]) + 0.2  # above the sediment sphere
    a1 = s1 + (ra + rs) * unit(d)
    com = a1 + rng.normal(scale=1.5, size=3)
    return s1, a1, ra, rs, com


# ----------------------------------------------------------------------------- rotation
def test_rotation_eq15_preserves_distances_and_composes():
    rng = np.random.default_rng(0)
    out = np.empty(3)
    out2 = np.empty(3)
    for _ in range(50):
        pivot = rng.normal(size=3)
        axis = random_unit(rng)
        x = rng.normal(size=(4, 3)) * 3
        a, b = rng.uniform(-np.pi, np.pi, 2)
        moved = np.array([(rot.rotate_point(xi, pivot, axis, np.cos(a), np.sin(a), out), out.copy())[1]
                          for xi in x])
        # distances to the pivot (and to the axis) and between points are preserved
        np.testing.assert_allclose(np.linalg.norm(moved - pivot, axis=1),
                                   np.linalg.norm(x - pivot, axis=1), rtol=1e-13)
        dx = np.linalg.norm(x[:, None] - x[None], axis=-1)
        dm = np.linalg.norm(moved[:, None] - moved[None], axis=-1)
        np.testing.assert_allclose(dm, dx, atol=1e-12)
        np.testing.assert_allclose((moved - pivot) @ axis, (x - pivot) @ axis, atol=1e-12)
        # agrees with an independent Rodrigues implementation
        np.testing.assert_allclose(moved, rotate(x, pivot, axis, a)[0], atol=1e-12)
        # composes: a then b == a + b
        rot.rotate_point(moved[0], pivot, axis, np.cos(b), np.sin(b), out2)
        np.testing.assert_allclose(out2, rotate(x[0], pivot, axis, a + b)[0], atol=1e-12)
        # eqs. 13-14 recover (cos, sin)
        c, s = rot.cos_sin_about(x[1], moved[1], pivot, axis)
        assert abs(c - np.cos(a)) < 1e-11 and abs(s - np.sin(a)) < 1e-11
        # the quaternion of (cos, sin) rotates like eq. 15 and composes like the rotations
        qa = np.empty(4)
        qb = np.empty(4)
        qab = np.empty(4)
        m = np.empty((3, 3))
        rot.quat_from_axis_cos_sin(axis, np.cos(a), np.sin(a), qa)
        rot.quat_to_matrix(qa, m)
        np.testing.assert_allclose(pivot + (x - pivot) @ m.T, moved, atol=1e-12)
        rot.quat_from_axis_cos_sin(axis, np.cos(b), np.sin(b), qb)
        rot.quat_mul(qb, qa, qab)
        rot.quat_to_matrix(qab, m)
        np.testing.assert_allclose(pivot + (x[0] - pivot) @ m.T, rotate(x[0], pivot, axis, a + b)[0],
                                   atol=1e-12)
        q2 = np.empty(4)
        rot.matrix_to_quat(m, q2)
        assert min(np.abs(q2 - qab).max(), np.abs(q2 + qab).max()) < 1e-12


def test_small_angle_quaternion_keeps_precision():
    axis = unit(np.array([0.3, -0.2, 0.9]))
    q = np.empty(4)
    for phi in (1e-12, 1e-8, 1e-4, 3.0):
        rot.quat_from_axis_cos_sin(axis, np.cos(phi), np.sin(phi), q)
        assert abs(q[0] - np.cos(phi / 2)) < 1e-15
        np.testing.assert_allclose(q[1:], np.sin(phi / 2) * axis, rtol=1e-13, atol=0)


# ----------------------------------------------------------------------------- 3.2.2 (a)
def check_sphere_contact(a, pivot, axis, s, D, phi_max=np.pi):
    phi, c, sn = ev.sphere_contact_angle(a, pivot, axis, s, D, 1.0, ev.POLICY_NEW)
    brute = first_true(lambda p: np.linalg.norm(rotate(a, pivot, axis, p) - s, axis=-1) < D,
                       phi_max)
    if phi > phi_max:
        phi = np.inf  # rotations never go beyond the hanging angle <= pi
    if np.isfinite(brute):
        assert abs(phi - brute) < 1e-8, (phi, brute)
    else:
        if np.isfinite(phi):
            # a contact the grid missed must be a graze (penetration below round-off scale)
            grid = phi + np.linspace(-2 * STEP, 2 * STEP, 4001)
            assert np.min(np.linalg.norm(rotate(a, pivot, axis, grid) - s, axis=-1)) > D - 1e-9
    if np.isfinite(phi):
        # (cos, sin) of eqs. 13-14 put the sphere exactly in contact
        out = np.empty(3)
        rot.rotate_point(a, pivot, axis, c, sn, out)
        assert abs(np.linalg.norm(out - s) - D) < 1e-12 * max(1.0, D)
        assert abs(np.arctan2(sn, c) % TWO_PI - phi) < 1e-12
    return phi, brute


def test_second_contact_circle_intersections_random():
    rng = np.random.default_rng(1)
    found = 0
    for _ in range(60):
        s1, a1, ra, rs, com = single_contact_setup(rng)
        n = steepest_axis(com, s1)
        # another sphere a2 of the particle and a sediment sphere s2 near its circle
        a2 = a1 + rng.normal(scale=1.5, size=3)
        r2 = rng.uniform(0.4, 1.2)
        rs2 = rng.uniform(0.4, 1.2)
        target = rotate(a2, s1, n, rng.uniform(0.1, 3.0))[0]
        s2 = target + (r2 + rs2) * rng.uniform(0.5, 1.5) * random_unit(rng)
        if np.linalg.norm(a2 - s2) <= r2 + rs2:
            continue
        phi, brute = check_sphere_contact(a2, s1, n, s2, r2 + rs2)
        found += np.isfinite(brute)
    assert found > 20


def test_paper_frame_eq10_12_gives_the_same_intersections():
    """The circle intersection in the paper's frame (eqs. 10-12) yields the two roots."""
    rng = np.random.default_rng(2)
    for _ in range(50):
        pivot = rng.normal(size=3)
        n = random_unit(rng)
        a2 = pivot + rng.normal(scale=2, size=3)
        s2 = rotate(a2, pivot, n, 1.0)[0] + 0.5 * random_unit(rng)
        D = 1.3
        O = pivot + n * ((a2 - pivot) @ n)                        # eq. 10
        w = s2 - O - n * ((s2 - O) @ n)
        if np.linalg.norm(w) < 1e-9:
            continue
        ex = unit(w)                                               # eq. 11
        ey = np.cross(n, ex)
        d = np.linalg.norm(w)
        rc1 = np.linalg.norm(a2 - O)
        arg = D ** 2 - ((s2 - O) @ n) ** 2                         # eq. 12
        if arg <= 0:
            continue
        rc2 = np.sqrt(arg)
        xi = (rc1 ** 2 - rc2 ** 2 + d ** 2) / (2 * d)
        if rc1 ** 2 - xi ** 2 <= 0:
            continue
        eta = np.sqrt(rc1 ** 2 - xi ** 2)
        roots = []
        for sg in (1, -1):
            p = O + xi * ex + sg * eta * ey
            c, s = rot.cos_sin_about(a2, p, O, n)                  # eqs. 13-14
            roots.append(np.arctan2(s, c) % TWO_PI)
        phi, _, _ = ev.sphere_contact_angle(a2, pivot, n, s2, D, 1.0, ev.POLICY_NEW)
        if np.linalg.norm(a2 - s2) > D:
            assert np.isfinite(phi)
            assert min(abs(phi - r) for r in roots) < 1e-9


# ----------------------------------------------------------------------------- 3.2.3 (b)
def test_loss_of_contact_eq17_random():
    rng = np.random.default_rng(3)
    tested = 0
    for _ in range(40):
        s1, a1, ra, rs, com = single_contact_setup(rng)
        n = steepest_axis(com, s1)
        nz = np.array([0.0, 0.0, 1.0])
        phi, c, s = ev.plane_contact_angle(a1, s1, n, nz, s1[2], 1.0, ev.POLICY_TRUSTED)
        brute = first_true(lambda p: rotate(a1, s1, n, p)[..., 2] < s1[2])
        assert abs(phi - brute) < 1e-8
        # eq. 17 gives the same position when the rotation reaches it going down
        target = np.empty(3)
        ev.loss_position_eq17(a1, s1, n, target)
        moved = rotate(a1, s1, n, phi)[0]
        np.testing.assert_allclose(moved, target, atol=1e-9)
        assert abs(target[2] - s1[2]) < 1e-12
        tested += 1
    assert tested == 40


# ----------------------------------------------------------------------------- 3.2.4 (c)
def test_hanging_on_one_contact_eq18_random():
    rng = np.random.default_rng(4)
    for _ in range(60):
        s1, a1, ra, rs, com = single_contact_setup(rng)
        n = steepest_axis(com, s1)
        phi, c, s = ev.hang_cos_sin(com, s1, n)
        grid = np.arange(0, np.pi + STEP, STEP)
        z = rotate(com, s1, n, grid)[..., 2]
        k = np.argmin(z)
        assert abs(phi - grid[k]) < 2 * STEP
        lowest = np.empty(3)
        ev.hanging_com_one(com, s1, lowest)                        # eq. 18
        np.testing.assert_allclose(rotate(com, s1, n, phi)[0], lowest, atol=1e-12)
        # eq. 16: same side of the vertical plane through the axis exactly before the hang
        out = np.empty(3)
        for f in (0.3, 0.9, 1.1, 1.5):
            rot.rotate_point(com, s1, n, np.cos(f * phi), np.sin(f * phi), out)
            assert ev.same_side_eq16(com, out, s1, n) == (f < 1.0)


# ----------------------------------------------------------------------------- 3.2.5 (d)
def test_ground_contact_random():
    rng = np.random.default_rng(5)
    found = 0
    for _ in range(60):
        s1, a1, ra, rs, com = single_contact_setup(rng)
        s1 = s1 + [0, 0, 3.0]
        a1 = a1 + [0, 0, 3.0]
        com = com + [0, 0, 3.0]
        n = steepest_axis(com, s1)
        a2 = a1 + rng.normal(scale=2.0, size=3)
        r2 = rng.uniform(0.3, 1.0)
        if a2[2] <= r2:
            continue
        nz = np.array([0.0, 0.0, 1.0])
        phi, c, s = ev.plane_contact_angle(a2, s1, n, nz, r2, 1.0, ev.POLICY_NEW)
        brute = first_true(lambda p: rotate(a2, s1, n, p)[..., 2] < r2)
        phi = phi if phi <= np.pi else np.inf
        if np.isfinite(brute):
            found += 1
            assert abs(phi - brute) < 1e-8
            out = np.empty(3)
            rot.rotate_point(a2, s1, n, c, s, out)
            assert abs(out[2] - r2) < 1e-12
        else:
            assert not np.isfinite(phi) or rotate(a2, s1, n, phi)[0, 2] > r2 - 1e-9
    assert found > 15


def test_wall_contact_random():
    """A vertical wall x = 0 (3.2.5 for a lateral wall): same solver with normal e_x."""
    rng = np.random.default_rng(6)
    found = 0
    for _ in range(100):
        s1, a1, ra, rs, com = single_contact_setup(rng)
        shift = np.array([2.5, 0, 0])
        s1, a1, com = s1 + shift, a1 + shift, com + shift
        n = steepest_axis(com, s1)
        a2 = a1 + rng.normal(scale=2.0, size=3)
        r2 = 0.5
        if a2[0] <= r2:
            continue
        ex = np.array([1.0, 0.0, 0.0])
        phi, c, s = ev.plane_contact_angle(a2, s1, n, ex, r2, 1.0, ev.POLICY_NEW)
        brute = first_true(lambda p: rotate(a2, s1, n, p)[..., 0] < r2)
        phi = phi if phi <= np.pi else np.inf
        if np.isfinite(brute):
            found += 1
            assert abs(phi - brute) < 1e-8
        else:
            assert not np.isfinite(phi)
    assert found > 5


# ----------------------------------------------------------------------------- 3.3
def two_contact_setup(rng):
    """Particle touching two sediment spheres s1, s2 with spheres a1, a2."""
    while True:
        s1 = np.zeros(3)
        s2 = np.array([rng.uniform(1.5, 3.5), rng.uniform(-1, 1), rng.uniform(-0.8, 0.8)])
        u = unit(s2 - s1)
        # choose a1, a2 touching s1, s2 and a rigid particle containing them
        d1 = random_unit(rng)
        d1[2] = abs(d1[2]) + 0.1
        d2 = random_unit(rng)
        d2[2] = abs(d2[2]) + 0.1
        a1 = s1 + 2.0 * unit(d1)
        a2 = s2 + 2.0 * unit(d2)
        if np.linalg.norm(a1 - s2) < 2.05 or np.linalg.norm(a2 - s1) < 2.05:
            continue
        com = 0.5 * (a1 + a2) + rng.normal(scale=1.0, size=3)
        w = np.cross(u, com - s1)
        if abs(w[2]) < 1e-3:
            continue
        axis = -np.sign(w[2]) * u                       # eq. 24, the descending sense
        return s1, s2, a1, a2, com, axis


def test_third_contact_random():
    rng = np.random.default_rng(7)
    found = 0
    for _ in range(60):
        s1, s2, a1, a2, com, axis = two_contact_setup(rng)
        a3 = com + rng.normal(scale=1.5, size=3)
        target = rotate(a3, s1, axis, rng.uniform(0.1, 2.5))[0]
        s3 = target + rng.uniform(1.0, 2.5) * random_unit(rng)
        D = 1.8
        if np.linalg.norm(a3 - s3) <= D:
            continue
        phi, brute = check_sphere_contact(a3, s1, axis, s3, D)
        found += np.isfinite(brute)
    assert found > 15


def release_function(com, px, py, ay, ny_fixed, axis, phis):
    """Eq. 25 evaluated by brute force: t_{x,y} . N_y along the pair rotation, with the
    steepest single-contact axis n_x = e_z x (r_cm - P_x) (unnormalised: same sign)."""
    c = rotate(com, px, axis, phis)
    a = rotate(ay, px, axis, phis)
    nx = np.cross([0.0, 0.0, 1.0], c - px)
    t = np.cross(nx, a - px)
    if ny_fixed is None:
        N = a - py
    else:
        N = np.broadcast_to(ny_fixed, a.shape)
    return np.sum(t * N, axis=-1)


def release_angle(com, px, py, ay, is_sphere, ny, axis, sliding_wall=False):
    """The release angle from the plane of eq. 30 (of a frictionless wall if ``sliding_wall``)."""
    nrm = np.empty(3)
    if sliding_wall:
        ok, use_com, c0, gap = ev.sliding_wall_release_plane(com, px, ay, ny, nrm)
    else:
        ok, use_com, c0, gap = ev.release_plane(com, px, py, ay, is_sphere,
                                                ny if ny is not None else np.zeros(3), nrm)
    if not ok:
        return np.inf
    point = com if use_com else ay
    phi, c, s = ev.plane_contact_angle(point, px, axis, nrm, c0, 1.0, ev.POLICY_TRUSTED)
    return phi if phi <= np.pi else np.inf


def agrees(phi, brute):
    """Assert that the release angle equals the brute-force one (or both are absent); 1 if there
    was one."""
    if np.isfinite(brute):
        assert abs(phi - brute) < 1e-7, (phi, brute)
        return 1
    assert not np.isfinite(phi)
    return 0


def test_loss_of_one_contact_eq25_30_random():
    rng = np.random.default_rng(8)
    found = 0
    for _ in range(50):
        s1, s2, a1, a2, com, axis = two_contact_setup(rng)
        for px, py, ay in ((s2, s1, a1), (s1, s2, a2)):
            f0 = release_function(com, px, py, ay, None, axis, np.array([0.0]))[0]
            if f0 >= -1e-6:
                continue  # rolling on x is not blocked by y now
            brute = first_true(lambda p: release_function(com, px, py, ay, None, axis, p) > 0)
            found += agrees(release_angle(com, px, py, ay, True, None, axis), brute)
    assert found > 15


def test_loss_of_one_contact_with_a_wall_random():
    """Eq. 25 when the released contact is a wall (its pivot is its own sphere centre)."""
    rng = np.random.default_rng(9)
    found = 0
    N = np.array([1.0, 0.0, 0.0])  # wall x = const, normal into the box
    for _ in range(60):
        s1, s2, a1, a2, com, axis = two_contact_setup(rng)
        py = a2  # the wall contact of sphere a2: pivot is a2 itself, fixed on the axis
        axis = unit(py - s1)
        w = np.cross(axis, com - s1)
        if abs(w[2]) < 1e-3:
            continue
        axis = -np.sign(w[2]) * axis
        f0 = release_function(com, s1, py, a2, N, axis, np.array([0.0]))[0]
        if f0 >= -1e-6:
            continue
        brute = first_true(lambda p: release_function(com, s1, py, a2, N, axis, p) > 0)
        found += agrees(release_angle(com, s1, py, a2, False, N, axis), brute)
    assert found > 8


def test_release_from_a_frictionless_wall_random():
    """Eq. 25 when the released contact is a frictionless wall: the pair rotation is about the
    axis through the sphere pivot along the wall's normal, and rolling on the sphere pivot alone
    becomes possible where it first moves the wall's sphere away from the wall."""
    rng = np.random.default_rng(12)
    found = 0
    for _ in range(80):
        N = np.array([*unit(rng.normal(size=2)), 0.0])  # a vertical wall, normal into the box
        px = rng.normal(size=3)
        ay = px + rng.uniform(1.0, 2.0) * random_unit(rng)  # the sphere touching the wall
        com = 0.5 * (px + ay) + rng.normal(scale=0.7, size=3)
        w = np.cross(N, com - px)
        if abs(w[2]) < 1e-3:
            continue
        axis = -np.sign(w[2]) * N  # the sense that lowers the centre of mass
        f0 = release_function(com, px, None, ay, N, axis, np.array([0.0]))[0]
        if f0 >= -1e-6:
            continue
        brute = first_true(lambda p: release_function(com, px, None, ay, N, axis, p) > 0)
        found += agrees(release_angle(com, px, None, ay, False, N, axis, sliding_wall=True), brute)
    assert found > 15


def test_loss_of_two_contacts_random():
    """3.3.4: both moving spheres at or below their sediment spheres: the first angle where
    one comes level while the other is below."""
    rng = np.random.default_rng(10)
    found = 0
    nz = np.array([0.0, 0.0, 1.0])
    for _ in range(80):
        s1, s2, a1, a2, com, axis = two_contact_setup(rng)

        def both_level(p):
            return (rotate(a1, s1, axis, p)[..., 2] <= s1[2]) & (rotate(a2, s1, axis, p)[..., 2] <= s2[2])

        brute = first_true(both_level, np.pi)
        best = np.inf
        for ak, sk, am, sm in ((a1, s1, a2, s2), (a2, s2, a1, s1)):
            phi, c, s = ev.plane_contact_angle(ak, s1, axis, nz, sk[2], 1.0, ev.POLICY_TRUSTED)
            if np.isfinite(phi) and phi <= np.pi and rotate(am, s1, axis, phi)[0, 2] <= sm[2] + 1e-12:
                best = min(best, phi)
        if np.isfinite(brute):
            found += 1
            assert abs(best - brute) < 1e-8
        else:
            assert not np.isfinite(best)
    assert found > 5


def test_hanging_on_two_contacts_eq32_random():
    rng = np.random.default_rng(11)
    for _ in range(60):
        s1, s2, a1, a2, com, axis = two_contact_setup(rng)
        phi, c, s = ev.hang_cos_sin(com, s1, axis)
        grid = np.arange(0, np.pi + STEP, STEP)
        z = rotate(com, s1, axis, grid)[..., 2]
        assert abs(phi - grid[np.argmin(z)]) < 2 * STEP
        lowest = np.empty(3)
        assert ev.hanging_com_two(com, s1, axis, lowest)          # eq. 32
        np.testing.assert_allclose(rotate(com, s1, axis, phi)[0], lowest, atol=1e-12)
        assert lowest[2] <= z.min() + 1e-12
        # eq. 16 with a tilted axis: same side exactly before the hang
        out = np.empty(3)
        for f in (0.5, 0.95, 1.05):
            rot.rotate_point(com, s1, axis, np.cos(f * phi), np.sin(f * phi), out)
            assert ev.same_side_eq16(com, out, s1, axis) == (f < 1.0)


# ----------------------------------------------------------------------------- 3.1
def test_fall_eq1_2_random():
    rng = np.random.default_rng(12)
    found = 0
    for _ in range(200):
        a = rng.normal(size=3) + [0, 0, 5.0]
        s = rng.normal(size=3)
        ra, rs = rng.uniform(0.5, 1.5, 2)
        if np.linalg.norm(a - s) < ra + rs:
            continue
        dz = ev.fall_drop(*a, ra, *s, rs)

        def inside(h):
            return np.linalg.norm((a - [0, 0, 1.0] * h[:, None]) - s, axis=-1) < ra + rs

        brute = first_true(inside, 12.0, 1e-4)
        if np.isfinite(brute):
            found += 1
            assert abs(dz - brute) < 1e-9
        else:
            assert not np.isfinite(dz) or dz < 0


# ----------------------------------------------------------------------------- touching rules
def test_touching_obstacle_policies():
    """An obstacle touched at phi = 0: an entry now if the motion goes into it, otherwise
    its next entry; a released contact (trusted) never gives an event at 0."""
    pivot = np.zeros(3)
    axis = np.array([0.0, 1.0, 0.0])
    a = np.array([2.0, 0.0, 0.0])       # moves towards -z for positive angles about +y
    s_below = np.array([2.0, 0.0, -2.0])
    s_above = np.array([2.0, 0.0, 2.0])
    phi, _, _ = ev.sphere_contact_angle(a, pivot, axis, s_below, 2.0, 1.0, ev.POLICY_NEW)
    assert phi == 0.0
    phi, _, _ = ev.sphere_contact_angle(a, pivot, axis, s_below, 2.0, 1.0, ev.POLICY_TRUSTED)
    assert phi != 0.0
    phi, _, _ = ev.sphere_contact_angle(a, pivot, axis, s_above, 2.0, 1.0, ev.POLICY_NEW)
    brute = first_true(lambda p: np.linalg.norm(rotate(a, pivot, axis, p) - s_above, axis=-1)
                       < 2.0 - 1e-12, TWO_PI)
    assert phi > 1.0 and abs(phi - brute) < 1e-6


def test_released_contact_grazing_back_in_with_a_round_off_overlap():
    """A touching contact that opens slowly and curves back in: its re-entry must be found
    whatever the sign of the round-off gap.  The circle of ``a`` (radius 1 about the z axis)
    lies inside the sphere of radius ``D`` about ``s`` except on the arc ``(0, 2 w)``; with
    the gap -1e-14 the roots of (*) near 0 vanish (``w < sqrt(|gap| / curvature)``), and a
    re-entry computed from them is lost (the cube L = 5 of the 97-particle reproducer rolled
    0.11 rad through a sediment sphere and then looped forever at zero angle)."""
    pivot = np.zeros(3)
    axis = np.array([0.0, 0.0, 1.0])
    a = np.array([1.0, 0.0, 0.0])
    d = 0.2
    for w in (1e-7, 3e-7, 1e-5):
        psi = w - math.pi
        s = d * np.array([math.cos(psi), math.sin(psi), 0.0])
        for gap in (-1e-14, 0.0, 1e-14):
            D = np.linalg.norm(a - s) - gap
            for policy in (ev.POLICY_TRUSTED, ev.POLICY_NEW):
                phi, c, sn = ev.sphere_contact_angle(a, pivot, axis, s, D, 1.0, policy)
                assert abs(phi - 2 * w) < 1e-3 * w, (w, gap, policy, phi)
                assert abs(c - math.cos(phi)) < 1e-15 and abs(sn - math.sin(phi)) < 1e-15
                # the contact closes there (within the touching tolerance) ...
                x = rotate(a, pivot, axis, phi)[0]
                assert abs(np.linalg.norm(x - s) - D) < 1e-12
                # ... and not before: open at half the angle (c w^2 above round-off)
                if w >= 1e-5:
                    x = rotate(a, pivot, axis, 0.5 * phi)[0]
                    assert np.linalg.norm(x - s) - D > gap + 1e-12


@pytest.mark.parametrize("excess", [1e-3, 1e-4, 1e-6, 1e-8, -1e-8, -1e-4])
def test_a_tangent_contact_opens_as_its_gap_does(excess):
    """A contact the rotation moves along (no first-order rate) opens or closes as its gap's second
    derivative says, however small; the decision and the event solver agree.  The circle of ``a``
    (radius 1 about the z axis) touches the sphere of radius ``D = 1 + excess`` about ``(1 - D, 0,
    0)``: the gap goes as ``(1 / D - 1) phi^2 / 2``, closing for ``D > 1``.  (A spiky particle of
    the Fig. 8 job, whose circle met a sphere so, with a curvature of 4e-4, was let roll 0.43 rad
    into it; it stayed 3.8e-5 inside and looped at zero angle until the event limit.)"""
    from parsim.core.sdbd.constants import OB_SPHERE
    from parsim.core.sdbd.decision import contact_opens

    pivot, axis, a = np.zeros(3), np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    D = 1.0 + excess
    s = np.array([1.0 - D, 0.0, 0.0])
    normal = (a - s) / D
    opens = contact_opens(0, tuple(pivot), tuple(axis), a[None], normal[None], np.array([OB_SPHERE], dtype=np.int8),
                          np.array([D]), 1.0)
    gap_later = np.linalg.norm(rotate(a, pivot, axis, 0.1)[0] - s) - D
    assert opens == (gap_later > 0.0), (excess, gap_later)
    phi, _, _ = ev.sphere_contact_angle(a, pivot, axis, s, D, 1.0, ev.POLICY_NEW)
    assert (phi == 0.0) == (not opens)


def _arc_range_by_arctangent(rho, e1k, e2k, phi_lim):
    """The arc's extent by the arctangents of its extreme directions (the reference)."""
    f0 = rho * e1k
    f1 = rho * (e1k * math.cos(phi_lim) + e2k * math.sin(phi_lim))
    lo, hi = min(f0, f1), max(f0, f1)
    m = rho * math.sqrt(e1k * e1k + e2k * e2k)
    th = math.atan2(e2k, e1k)
    if th < 0.0:
        th += 2.0 * math.pi
    if th <= phi_lim:
        hi = m
    th += math.pi
    if th >= 2.0 * math.pi:
        th -= 2.0 * math.pi
    if th <= phi_lim:
        lo = -m
    return lo, hi


def test_arc_range_without_arctangents_is_bitwise_that_with_them():
    from parsim.core.sdbd.events import arc_range

    rng = np.random.default_rng(11)
    specials = [0.0, -0.0, 1e-300, -1e-300, 1e-12, -1e-12, 1.0, -1.0]
    for _ in range(20000):
        e1k, e2k = rng.normal(size=2) * rng.choice([1.0, 1e-6, 1e-11])
        if rng.random() < 0.2:
            e2k = rng.choice(specials)
        if rng.random() < 0.1:
            e1k = rng.choice(specials)
        phi_lim = rng.choice([rng.random() * math.pi, math.pi, math.pi - 1e-7, 1e-9,
                              math.atan2(e2k, e1k) % (2.0 * math.pi)])
        rho = rng.random() * 3.0
        got = arc_range(rho, e1k, e2k, phi_lim, math.cos(phi_lim), math.sin(phi_lim))
        assert got == _arc_range_by_arctangent(rho, e1k, e2k, phi_lim), (rho, e1k, e2k, phi_lim)


def test_an_entry_beyond_the_limit_is_skipped_and_every_other_is_unchanged():
    from parsim.core.sdbd.events import POLICY_NEW, POLICY_TRUSTED, first_entry

    rng = np.random.default_rng(12)
    skipped = 0
    for _ in range(50000):
        A, B = rng.normal(size=2)
        K = rng.normal() * rng.choice([1.0, 1e-3])
        gap = rng.choice([rng.random(), 0.0, 1e-12, -1e-12])
        policy = POLICY_NEW if rng.random() < 0.5 else POLICY_TRUSTED
        limit = rng.choice([rng.random() * math.pi, math.pi, 1e-9])
        full = first_entry(A, B, K, gap, 1.0, 1.0, policy)
        limited = first_entry(A, B, K, gap, 1.0, 1.0, policy, limit, math.cos(limit))
        if limited[0] == np.inf and full[0] != np.inf:
            assert full[0] > limit  # skipped: the caller would have discarded it
            skipped += 1
        else:
            assert limited == full
    assert skipped > 5000  # the shortcut does skip
