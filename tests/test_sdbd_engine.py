"""SDBD deposition engine: analytic cases, packings of spheres, sediments of complex particles.

Shapes are built here by small helpers (the shape library is elsewhere); the sediments are
checked by :mod:`tests.sediment_checks`, which works from the final positions alone.
"""

import math
from pathlib import Path

import numpy as np
import pytest

from parsim.core import sdbd
from parsim.core import shapes as shape_library
from parsim.core.sdbd.constants import OVERLAP_LIMIT
from parsim.core.sdbd import (
    EVENT_KINDS,
    EVENT_LIMIT,
    FLOOR_ROLL,
    FLOOR_STOP,
    HANGING_ONE,
    LATERAL_NONE,
    LATERAL_PERIODIC,
    LATERAL_WALLS,
    RESTING_ON_FLOOR,
    RESTING_THREE_CONTACTS,
)

from . import sediment_checks as sc

KIND = {k: i for i, k in enumerate(EVENT_KINDS)}
IDENTITY = [1.0, 0.0, 0.0, 0.0]


# ----------------------------------------------------------------------------- shapes
def sphere_shape(R=1.0):
    return np.zeros((1, 3)), np.array([R])


def spiky(L, R=1.0):
    """3L - 2 spheres along three perpendicular axes, spacing 2R (a 3-d cross)."""
    t = (np.arange(L) - (L - 1) // 2) * 2 * R
    pts = {(0.0, 0.0, 0.0)}
    for ax in range(3):
        for v in t:
            p = [0.0, 0.0, 0.0]
            p[ax] = float(v)
            pts.add(tuple(p))
    o = np.array(sorted(pts))
    return o - o.mean(0), np.full(len(o), R)


def cube(L, R=1.0):
    """6L^2 - 12L + 8 spheres on the surface of an L x L x L cube, spacing 2R."""
    if L == 1:
        return np.zeros((1, 3)), np.array([R])
    o = np.array([(x, y, z) for x in range(L) for y in range(L) for z in range(L)
                  if min(x, y, z) == 0 or max(x, y, z) == L - 1], float) * 2 * R
    return o - o.mean(0), np.full(len(o), R)


def rod(L, R=1.0, spacing=1.0):
    """L overlapping spheres on a line (spacing < 2R)."""
    o = np.zeros((L, 3))
    o[:, 0] = np.arange(L) * spacing * R
    return o - o.mean(0), np.full(L, R)


def shapes(*items):
    """Concatenate (offsets, radii) pairs into shape_offsets, shape_radii, shape_start."""
    offs = np.concatenate([o for o, r in items])
    rads = np.concatenate([r for o, r in items])
    start = np.concatenate([[0], np.cumsum([len(r) for o, r in items])])
    return offs, rads, start


def random_quats(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1)[:, None]


def quat_matrix(q):
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def run(items, pshape, xy, lateral=LATERAL_NONE, floor=FLOOR_STOP, lo=(0, 0), hi=(0, 0), rot=None,
        scale=None, **kw):
    offs, rads, start = shapes(*items)
    P = len(pshape)
    rot = np.tile(IDENTITY, (P, 1)) if rot is None else rot
    scale = np.ones(P) if scale is None else scale
    res, diag = sdbd.deposit_with_diagnostics(offs, rads, start, np.asarray(pshape), scale, rot,
                                              np.asarray(xy, float), lo, hi, lateral, floor,
                                              check_overlaps=True, **kw)
    # no move left an overlap beyond the named tolerance (measured after every move)
    assert diag["max_overlap"] <= OVERLAP_LIMIT * diag["length_scale"]
    return res


# ----------------------------------------------------------------------------- analytic cases
def triangle(R=1.0):
    """Three touching spheres in a horizontal equilateral triangle, as one rigid particle."""
    rho = 2 * R / math.sqrt(3)
    o = np.array([[rho * math.cos(a), rho * math.sin(a), 0.0]
                  for a in (math.pi / 2, math.pi / 2 + 2 * math.pi / 3, math.pi / 2 + 4 * math.pi / 3)])
    return o - o.mean(0), np.full(3, R)


@pytest.mark.parametrize("drop, r4", [((0.0, 0.0), 1.0), ((0.3, 0.1), 1.0), ((-0.2, 0.25), 0.7)])
def test_sphere_on_three_touching_spheres(drop, r4):
    res = run([triangle(), sphere_shape(r4)], [0, 1], [(0.0, 0.0), drop])
    assert res.state[0] == RESTING_ON_FLOOR
    np.testing.assert_allclose(res.positions[:3, 2], 1.0, atol=1e-12)
    # centre above the centroid at height R + sqrt((R + r4)^2 - (2R/sqrt3)^2)
    z = 1.0 + math.sqrt((1.0 + r4) ** 2 - 4.0 / 3.0)
    np.testing.assert_allclose(res.center_of_mass[1], [0.0, 0.0, z], atol=1e-9)
    assert res.state[1] == RESTING_THREE_CONTACTS and res.contacts[1] == 3
    if drop == (0.0, 0.0):
        # the three contacts are made at the same fall height (4.3)
        assert res.event_counts[1, KIND["fall_contact"]] == 3
        assert res.event_counts[1, KIND["simultaneous"]] == 2
    else:
        assert res.event_counts[1, KIND["second_contact"]] >= 1
        assert res.event_counts[1, KIND["third_contact"]] >= 1


@pytest.mark.parametrize("floor", [FLOOR_STOP, FLOOR_ROLL])
def test_sphere_onto_the_floor(floor):
    res = run([sphere_shape(1.5)], [0], [(3.0, -2.0)], floor=floor)
    np.testing.assert_allclose(res.positions[0], [3.0, -2.0, 1.5], atol=1e-12)
    assert res.state[0] == RESTING_ON_FLOOR and res.contacts[0] == 1
    assert res.event_counts[0, KIND["floor_contact"]] == 1


@pytest.mark.parametrize("floor", [FLOOR_STOP, FLOOR_ROLL])
def test_dimer_rolls_off_a_single_sphere(floor):
    dimer = (np.array([[-1.0, 0, 0], [1.0, 0, 0]]), np.ones(2))
    # the dimer lands off-centre on the sphere (its centre of mass is not above the pivot)
    res = run([sphere_shape(), dimer], [0, 1], [(0.0, 0.0), (0.7, 0.2)], floor=floor)
    com = res.center_of_mass[1]
    a = res.positions[1:]
    # it did not stay on the sphere: it reached the floor on the side of its centre of mass
    assert res.event_counts[1, KIND["floor_contact"]] >= 1
    assert a[:, 2].min() == pytest.approx(1.0, abs=1e-9)
    assert com[0] > 0.7
    if floor == FLOOR_STOP:
        assert res.state[1] == RESTING_ON_FLOOR
    else:
        # under FLOOR_ROLL it keeps rolling until it lies flat on the floor
        np.testing.assert_allclose(a[:, 2], 1.0, atol=1e-9)
        assert com[2] == pytest.approx(1.0, abs=1e-9)
    probs = sc.check_sediment(res.positions, res.radii, res.particle, res.center_of_mass, res.state,
                              (0, 0), (0, 0), LATERAL_NONE, floor)
    assert probs == []


def test_hook_hangs_on_one_contact():
    """An asymmetric inverted-U particle over a vertical post swings until its centre of mass
    is straight below the pivot, with its contact sphere above the post's top sphere."""
    post = np.zeros((8, 3))
    post[:, 2] = np.arange(8) * 2.0
    post -= post.mean(0)
    bar = [(0.0, y, 0.0) for y in range(-6, 7, 2)]
    left = [(0.0, -6.0, -2.0 * k) for k in range(1, 6)]
    right = [(0.0, 6.0, -2.0 * k) for k in range(1, 5)]
    hook = np.array(bar + left + right)
    com0 = hook.mean(0)
    hook -= com0
    contact = np.argmin(np.linalg.norm(hook - (np.array([0.0, 0.0, 0.0]) - com0), axis=1))
    drop = -hook[contact, :2]  # the hook's middle bar sphere straight above the post
    res = run([(post, np.ones(8)), (hook, np.ones(len(hook)))], [0, 1], [(0.0, 0.0), drop])
    assert res.state[0] == RESTING_ON_FLOOR
    top = res.positions[7]
    assert top[2] == pytest.approx(15.0, abs=1e-12)
    assert res.state[1] == HANGING_ONE and res.contacts[1] == 1
    assert res.event_counts[1, KIND["hanging_one"]] == 1
    com = res.center_of_mass[1]
    np.testing.assert_allclose(com[:2], top[:2], atol=1e-9)   # eq. 18
    assert com[2] < top[2]
    a = res.positions[res.particle == 1]
    d = np.linalg.norm(a - top, axis=1)
    k = np.argmin(d)
    assert d[k] == pytest.approx(2.0, abs=1e-9) and a[k, 2] > top[2]
    probs = sc.check_sediment(res.positions, res.radii, res.particle, res.center_of_mass, res.state,
                              (0, 0), (0, 0), LATERAL_NONE, FLOOR_STOP)
    assert probs == []


def test_orientation_and_positions_are_consistent():
    rng = np.random.default_rng(3)
    items = [spiky(3, 0.8), cube(2, 1.1), sphere_shape(0.6), rod(4)]
    offs, rads, start = shapes(*items)
    P = 40
    pshape = rng.integers(0, 4, P)
    scale = rng.uniform(0.8, 1.2, P)
    q = random_quats(rng, P)
    L = 24.0
    res = run(items, pshape, rng.uniform(0, L, (P, 2)), LATERAL_PERIODIC, FLOOR_ROLL, (0, 0), (L, L),
              rot=q, scale=scale)
    assert res.stopped_at == -1
    np.testing.assert_allclose(np.linalg.norm(res.rotation, axis=1), 1.0, atol=1e-12)
    for p in range(P):
        s = pshape[p]
        body = scale[p] * offs[start[s]:start[s + 1]]
        expect = res.center_of_mass[p] + body @ quat_matrix(res.rotation[p]).T
        np.testing.assert_allclose(res.positions[res.particle == p], expect, atol=1e-9)
        np.testing.assert_allclose(res.radii[res.particle == p], scale[p] * rads[start[s]:start[s + 1]])
    assert np.all((res.center_of_mass[:, :2] >= 0) & (res.center_of_mass[:, :2] < L))
    assert np.all(np.diff(res.particle) >= 0)
    probs = sc.check_sediment(res.positions, res.radii, res.particle, res.center_of_mass, res.state,
                              (0, 0), (L, L), LATERAL_PERIODIC, FLOOR_ROLL)
    assert probs == []


def test_deterministic():
    rng = np.random.default_rng(5)
    P = 60
    args = ([spiky(3)], np.zeros(P, int), rng.uniform(0, 20, (P, 2)), LATERAL_PERIODIC, FLOOR_STOP,
            (0, 0), (20, 20))
    q = random_quats(rng, P)
    a = run(*args, rot=q)
    b = run(*args, rot=q)
    for name in a._fields:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_event_limit_reports_the_particle():
    rng = np.random.default_rng(6)
    P = 300
    xy = rng.uniform(0, 12, (P, 2))
    full = run([sphere_shape()], np.zeros(P, int), xy, LATERAL_PERIODIC, FLOOR_STOP, (0, 0), (12, 12))
    # decide-and-move steps of each sphere: one per executed move (simultaneous events share
    # a move: the extra ones are counted in their kind and in "simultaneous"), plus the final
    # decision "rest" unless the floor stopped it
    ec = full.event_counts
    moves = (ec.sum(1) - 2 * ec[:, KIND["simultaneous"]] - ec[:, KIND["cycling_interruption"]])
    steps = moves + (full.state != RESTING_ON_FLOOR)
    res = run([sphere_shape()], np.zeros(P, int), xy, LATERAL_PERIODIC, FLOOR_STOP, (0, 0), (12, 12),
              max_events_per_particle=2)
    p = res.stopped_at
    assert p == np.argmax(steps > 2) and 0 < p < P
    # the result holds exactly the particles before it, deposited as without the limit
    assert len(res.state) == p and len(res.center_of_mass) == p and len(res.radii) == p
    assert EVENT_LIMIT not in res.state
    np.testing.assert_array_equal(res.positions, full.positions[:p])
    np.testing.assert_array_equal(res.event_counts, full.event_counts[:p])


# ----------------------------------------------------------------------------- errors
def test_bad_arguments_raise_value_error():
    o, r = sphere_shape()
    ok = dict(shape_offsets=o, shape_radii=r, shape_start=[0, 1], particle_shape=[0],
              particle_scale=[1.0], particle_rotation=[IDENTITY], particle_drop_xy=[(1.0, 1.0)],
              box_lower_xy=(0, 0), box_upper_xy=(10, 10), lateral=LATERAL_PERIODIC, floor=FLOOR_STOP)
    sdbd.deposit(**ok)
    for change in (dict(box_upper_xy=(3.9, 10)),            # periodic box < 4 sphere radii
                   dict(lateral=7), dict(floor=3), dict(shape_radii=[-1.0]),
                   dict(shape_start=[0, 2]), dict(particle_shape=[1]), dict(particle_scale=[0.0]),
                   dict(particle_rotation=[[0, 0, 0, 0]]), dict(trial_angle=-1.0),
                   dict(max_events_per_particle=0),
                   dict(lateral=LATERAL_WALLS, particle_drop_xy=[(0.5, 5.0)])):  # outside the walls
        with pytest.raises(ValueError):
            sdbd.deposit(**{**ok, **change})


# ----------------------------------------------------------------------------- packings
def slab_statistics(pos, rad, L):
    """Packing fraction and mean sphere-sphere coordination number in the slab between 0.25
    and 0.75 of the filling height (twice the mean height of the sphere centres)."""
    H = 2 * pos[:, 2].mean()
    z0, z1 = 0.25 * H, 0.75 * H
    a = np.clip(z0, pos[:, 2] - rad, pos[:, 2] + rad) - pos[:, 2]
    b = np.clip(z1, pos[:, 2] - rad, pos[:, 2] + rad) - pos[:, 2]
    vol = np.sum(np.pi * (rad ** 2 * (b - a) - (b ** 3 - a ** 3) / 3))
    phi = vol / (L * L * (z1 - z0))
    sel = np.nonzero((pos[:, 2] > z0) & (pos[:, 2] < z1))[0]
    d = pos[sel][:, None, :] - pos[None, :, :]
    d[..., :2] -= L * np.round(d[..., :2] / L)
    dist = np.sqrt((d ** 2).sum(-1))
    contact = (np.abs(dist - rad[sel][:, None] - rad[None, :]) < 1e-9) & (dist > 0)
    return phi, contact.sum(1).mean()


def test_monodisperse_spheres_visscher_bolsterli():
    L = 32.0  # 16 x 16 diameters
    P = 4000
    rng = np.random.default_rng(7)
    res = run([sphere_shape()], np.zeros(P, int), rng.uniform(0, L, (P, 2)), LATERAL_PERIODIC,
              FLOOR_STOP, (0, 0), (L, L))
    assert res.stopped_at == -1
    assert set(np.unique(res.state)) <= {RESTING_THREE_CONTACTS, RESTING_ON_FLOOR}
    # spheres never hang; a sphere not on the floor rests on three (a fourth contact needs a
    # coincidence within the contact tolerances)
    c = res.contacts[res.state == RESTING_THREE_CONTACTS]
    assert np.all(c >= 3) and np.mean(c == 3) > 0.99
    phi, z = slab_statistics(res.positions, res.radii, L)
    assert abs(phi - 0.582) < 0.006, phi
    assert abs(z - 6.00) < 0.02, z
    # the first few hundred are checked independently (the checker is O(N^2) in numpy)
    m = 600
    probs = sc.check_sediment(res.positions[:m], res.radii[:m], res.particle[:m],
                              res.center_of_mass[:m], res.state[:m], (0, 0), (L, L),
                              LATERAL_PERIODIC, FLOOR_STOP)
    assert probs == []


@pytest.mark.parametrize("name, shape, P, L, lateral, floor", [
    ("spiky5", spiky(5), 120, 30.0, LATERAL_PERIODIC, FLOOR_STOP),
    ("spiky3-walls", spiky(3), 150, 24.0, LATERAL_WALLS, FLOOR_ROLL),
    ("cube3", cube(3), 100, 24.0, LATERAL_PERIODIC, FLOOR_STOP),
    ("cube3-heap", cube(3), 100, 24.0, LATERAL_NONE, FLOOR_ROLL),
    ("rod5", rod(5), 150, 24.0, LATERAL_PERIODIC, FLOOR_ROLL),
    ("rod5-walls", rod(5), 150, 24.0, LATERAL_WALLS, FLOOR_STOP),
])
def test_complex_particle_sediments(name, shape, P, L, lateral, floor):
    rng = np.random.default_rng(11)
    o, r = shape
    ext = np.max(np.linalg.norm(o, axis=1) + r)
    if lateral == LATERAL_WALLS:
        xy = rng.uniform(ext, L - ext, (P, 2))
    elif lateral == LATERAL_NONE:
        xy = rng.normal(0.0, L / 6, (P, 2)) - 500.0  # far from the origin: hashed columns
    else:
        xy = rng.uniform(0, L, (P, 2))
    res = run([shape], np.zeros(P, int), xy, lateral, floor, (0, 0), (L, L), rot=random_quats(rng, P))
    assert res.stopped_at == -1
    assert np.all(res.positions[:, 2] - res.radii >= -1e-9)
    probs = sc.check_sediment(res.positions, res.radii, res.particle, res.center_of_mass, res.state,
                              (0, 0), (L, L), lateral, floor)
    assert probs == [], probs[:5]
    counts = res.event_counts.sum(0)
    # rolling on one and two contacts happened (3.2, 3.3)
    assert counts[KIND["second_contact"]] > 0 and counts[KIND["third_contact"]] > 0
    if lateral == LATERAL_WALLS:
        assert counts[KIND["wall_contact"]] > 0


# ----------------------------------------------------------------------------- regressions
def test_frustrated_creep_at_a_small_trial_angle_terminates():
    """Regression: a cube (L = 5) creeping through a frustrated situation (4.1) in steps of
    the trial angle 1e-4 - roll on two contacts until one releases (eq. 25), virtual
    rotation, roll on one until the released contact closes again - reaches the end of the
    frustration, where the released contact opens at a rate ~5e-8 and closes again after
    ~1e-6 rad.  The re-entry was computed from the roots of (*) with the measured gap; a
    round-off overlap of 1.5e-14 made them vanish, the cube rolled 0.11 rad through the
    sediment sphere (overlap 6e-4) and then looped at zero angle until the event limit.
    The sediment particle is the cube of the reproducer (particle 94 of a 97-cube run) in
    its final orientation, dropped onto the floor; the second cube is the stuck one."""
    o, r = shape_library.cube(5)
    rot = np.array([[0.6134563110245619, -0.5092537849187883, -0.5571093099590351, -0.23229540194974224],
                    [-0.12551875755272898, 0.12151751581195024, -0.5524460452225007, 0.8150349084372585]])
    xy = np.array([[19.96644421551475, 11.355398053948711],
                   [18.087311214452285, 11.55776516992458]])
    res = run([(o, r)], [0, 0], xy, LATERAL_PERIODIC, FLOOR_STOP, (0, 0), (20, 20), rot=rot,
              scale=np.full(2, 0.5), trial_angle=1e-4, max_events_per_particle=20_000)
    assert res.stopped_at == -1
    assert list(res.state) == [RESTING_ON_FLOOR, RESTING_ON_FLOOR]
    ec = res.event_counts[1]
    # it did creep (about 350 rounds of second contact / release / trial rotation) ...
    assert ec[KIND["second_contact"]] > 300 and ec[KIND["loss_of_one_contact"]] > 300
    assert ec[KIND["frustrated_trial_rotation"]] > 300
    # ... and got through: a few more events after the creep
    assert ec.sum() < 3000


def test_a_spiky_particle_does_not_roll_into_a_sphere_its_circle_osculates():
    """Regression: a spiky particle (L = 5, trial angle 1e-3) of the Fig. 8 job (particle 424 of
    realisation 3) touching two spheres of a sediment particle with one of its spheres.  Rolling on
    the first, its sphere's circle about the axis meets the second tangentially (rate -7e-15) and
    curves into it slowly (second derivative of the gap -4e-4); a probe rotation by 1e-4 saw a drop
    of 2e-12, below its tolerance, so the decision released the contact, the roll ran 0.43 rad into
    the sphere (overlap 3.8e-5) and the particle then looped at zero angle until the event limit.
    The fixture holds the particle and the sediment within 4 of its path, cut from its task."""
    fixture = np.load(Path(__file__).parent / "data" / "spiky_on_an_osculating_sphere.npz")
    res = run([(fixture["shape_offsets"], fixture["shape_radii"])], [0], fixture["particle_drop_xy"],
              LATERAL_PERIODIC, FLOOR_STOP, (0.0, 0.0), fixture["box_upper_xy"], rot=fixture["particle_rotation"],
              scale=fixture["particle_scale"], trial_angle=float(fixture["trial_angle"]),
              max_events_per_particle=20_000, substrate_positions=fixture["substrate_positions"],
              substrate_radii=fixture["substrate_radii"])
    assert res.stopped_at == -1
    assert res.state[0] in (RESTING_THREE_CONTACTS, RESTING_ON_FLOOR)
