"""Independent checks of a deposited sediment, from the final positions alone.

Nothing here uses the solver's bookkeeping (contacts, events, pivots): contacts are
re-derived from the sphere positions, and the rest condition is tested by moving each
particle a little along every candidate steepest-descent motion of the paper and
looking for overlaps.  Plain numpy.

:func:`check_sediment` returns a list of problems (empty when the sediment is valid):

* no two spheres of different particles overlap by more than ``overlap_tol * ell``;
* no sphere is below the floor (or through a wall) by more than that;
* every particle ``p`` is at rest at a local minimum with respect to the sediment it was
  deposited on (the substrate, the particles ``< p``, the floor and the walls): a vertical fall, the
  steepest-descent rotation about each contact, and the rotation about the axis through
  each pair of contacts (both senses) must each either not lower the centre of mass or
  be blocked, i.e. create an overlap larger than ``block_tol * ell`` for one of the trial
  sizes ``deltas`` (angles in rad, fall distances in ell).  Several sizes are needed: a
  contact that blocks at first order with a small rate reopens at second order after a
  large trial move, and one that blocks only at second order needs a large one.  Under FLOOR_STOP a particle touching the floor is exempt (the
  paper immobilises it);
* a particle with fewer than three contacts is reported hanging (or on the floor), and
  one reported resting on three contacts has at least three.

A sphere obstacle's pivot is its centre; the floor's (under FLOOR_ROLL) and a glued wall's
is the touching sphere's own centre.  A frictionless wall is a sphere of infinite radius:
its pivot lies at infinity behind the wall, so it adds no rotation of its own (rolling on it
alone is the fall), and with another pivot ``P`` it makes the rotation about the axis through
``P`` along the wall's normal.

A mesh vessel's faces ``(normals, levels)`` are planes of any inward normal, walls like the box's:
a glued face's pivot is the touching sphere's centre; a frictionless one adds the translations of
the slide, down the face's line of steepest descent and along the line of two frictionless planes
(faces or walls), and the rotation about the axis through another pivot along its normal.

A cylinder ``(cx, cy, R, n)`` is the regular polygon of ``n`` frictionless planar walls inscribed
in the circle of radius ``R`` about ``(cx, cy)``, side ``k`` facing the direction
``2 pi k / n`` (the engine's model); its spheres must also have their centres within ``R - r``
of the axis.  A substrate is a set of fixed spheres below the first particle: obstacles like
the deposited spheres, which may overlap each other and the floor.
"""

import numpy as np

# Only the boundary and state codes (plain constants of the public API) come from the
# package; nothing of the solver's computation is used.
from parsim.core.sdbd import FLOOR_STOP, HANGING_ONE, HANGING_TWO, RESTING_ON_FLOOR, RESTING_THREE_CONTACTS
from parsim.core.sdbd import LATERAL_NONE, LATERAL_PERIODIC, LATERAL_WALLS


def _min_image(d, lateral, box):
    if lateral == LATERAL_PERIODIC:
        d = d.copy()
        d[..., :2] -= box * np.round(d[..., :2] / box)
    return d


def _rotate(x, pivot, axis, phi):
    """Rotate points ``x`` (n, 3) by ``phi`` about the unit axis through ``pivot`` (Rodrigues)."""
    r = x - pivot
    c, s = np.cos(phi), np.sin(phi)
    return pivot + c * r + s * np.cross(axis, r) + (1 - c) * (r @ axis)[:, None] * axis


def close_pairs(pos, rad, lateral, box_lower, box_upper, extra):
    """All pairs ``i < j`` with ``|x_i - x_j| < r_i + r_j + extra`` (cell list in numpy)."""
    n = len(pos)
    if n < 2:
        return np.zeros((0, 2), dtype=np.int64), np.zeros(0)
    cell = 2 * rad.max() + extra
    lo = np.asarray(box_lower, float) if lateral != LATERAL_NONE else pos[:, :2].min(0)
    box = np.asarray(box_upper, float) - np.asarray(box_lower, float)
    idx = np.floor((pos - np.array([lo[0], lo[1], 0.0])) / cell).astype(np.int64)
    if lateral == LATERAL_PERIODIC:
        nc = np.maximum(np.floor(box / cell).astype(np.int64), 1)
        idx[:, :2] %= nc
    cells = {}
    for k, key in enumerate(map(tuple, idx)):
        cells.setdefault(key, []).append(k)
    cells = {k: np.array(v) for k, v in cells.items()}
    out_i, out_j, out_d = [], [], []
    offsets = [(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)]
    for key, members in cells.items():
        seen = set()
        for o in offsets:
            nb = (key[0] + o[0], key[1] + o[1], key[2] + o[2])
            if lateral == LATERAL_PERIODIC:
                nb = (nb[0] % nc[0], nb[1] % nc[1], nb[2])
            if nb in seen or nb not in cells:
                continue
            seen.add(nb)
            other = cells[nb]
            d = _min_image(pos[members][:, None, :] - pos[other][None, :, :], lateral, box)
            dist = np.sqrt((d ** 2).sum(-1))
            lim = rad[members][:, None] + rad[other][None, :] + extra
            a, b = np.nonzero((dist < lim) & (members[:, None] < other[None, :]))
            out_i.append(members[a])
            out_j.append(other[b])
            out_d.append(dist[a, b])
    if not out_i:
        return np.zeros((0, 2), dtype=np.int64), np.zeros(0)
    pairs = np.stack([np.concatenate(out_i), np.concatenate(out_j)], axis=1)
    return pairs, np.concatenate(out_d)


def lateral_walls(lateral, box_lower, box_upper, cylinder=None):
    """Inward unit normals ``N`` (k, 3) and levels ``c`` (k,) of the lateral walls: a sphere
    of radius ``r`` centred at ``x`` is inside when ``N . x - r >= c``.  The four box faces,
    or the sides of a cylinder's polygon, or none."""
    if lateral != LATERAL_WALLS:
        return np.zeros((0, 3)), np.zeros(0)
    if cylinder is None:
        normals = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])
        levels = np.array([box_lower[0], -box_upper[0], box_lower[1], -box_upper[1]])
        return normals, levels
    cx, cy, radius, n = cylinder
    theta = 2.0 * np.pi * np.arange(n) / n
    outward = np.stack([np.cos(theta), np.sin(theta), np.zeros(n)], axis=1)
    return -outward, -(outward[:, 0] * cx + outward[:, 1] * cy + radius * np.cos(np.pi / n))


def _plane_gaps(x, r, walls):
    """Gaps to the floor (column 0) and to the lateral walls (columns 1...)."""
    normals, levels = walls
    return np.concatenate([(x[:, 2] - r)[:, None], x @ normals.T - r[:, None] - levels[None, :]], axis=1)


def check_sediment(positions, radii, particle, center_of_mass, state, box_lower_xy,
                   box_upper_xy, lateral, floor, wall_contact="frictionless", overlap_tol=1e-9, contact_tol=1e-7,
                   deltas=(1e-7, 1e-6, 1e-5, 1e-4), block_tol=1e-12, max_report=20, cylinder=None,
                   substrate=None, faces=None):
    """Problems found in a sediment (see the module docs); an empty list means valid.
    ``wall_contact`` is the wall contact model, "frictionless" or "glued"; ``cylinder``
    ``(cx, cy, R, n_sides)`` replaces the box walls by the cylinder's polygon (LATERAL_WALLS);
    ``substrate`` ``(positions, radii)`` are fixed spheres below the first particle; ``faces``
    ``(normals, levels)`` a mesh vessel's planes ``N . x - r >= c`` besides the box's walls."""
    if wall_contact not in ("frictionless", "glued"):
        raise ValueError(f"wall_contact must be 'frictionless' or 'glued', got {wall_contact!r}")
    if cylinder is not None and lateral != LATERAL_WALLS:
        raise ValueError("a cylinder needs lateral = LATERAL_WALLS")
    pos = np.asarray(positions, float)
    rad = np.asarray(radii, float)
    part = np.asarray(particle, np.int64)
    com_all = np.asarray(center_of_mass, float)
    lo = np.asarray(box_lower_xy, float)
    hi = np.asarray(box_upper_xy, float)
    box = hi - lo
    ell = rad.mean()
    walls = lateral_walls(lateral, lo, hi, cylinder)
    if faces is not None:
        walls = (np.concatenate([walls[0], np.asarray(faces[0], float).reshape(-1, 3)]),
                 np.concatenate([walls[1], np.asarray(faces[1], float)]))
    sub_pos, sub_rad = (np.zeros((0, 3)), np.zeros(0)) if substrate is None else \
        (np.asarray(substrate[0], float).reshape(-1, 3), np.asarray(substrate[1], float))
    n_sub = len(sub_rad)
    problems = []

    # 1. overlaps between particles (the substrate is particle -1), floor, walls
    all_pos = np.concatenate([sub_pos, pos])
    all_rad = np.concatenate([sub_rad, rad])
    all_part = np.concatenate([np.full(n_sub, -1), part])
    pairs, dist = close_pairs(all_pos, all_rad, lateral, lo, hi, 0.0)
    if len(pairs):
        diff = all_part[pairs[:, 0]] != all_part[pairs[:, 1]]
        ov = all_rad[pairs[:, 0]] + all_rad[pairs[:, 1]] - dist
        bad = diff & (ov > overlap_tol * ell)
        for (i, j), o in list(zip(pairs[bad] - n_sub, ov[bad]))[:max_report]:
            problems.append(f"spheres {i} (particle {all_part[i + n_sub]}) and {j} (particle "
                            f"{all_part[j + n_sub]}) overlap by {o / ell:.3g} ell (negative: substrate)")
    pg = _plane_gaps(pos, rad, walls)
    for i in np.nonzero(pg.min(1) < -overlap_tol * ell)[0][:max_report]:
        problems.append(f"sphere {i} (particle {part[i]}) crosses the floor or a wall by "
                        f"{-pg[i].min() / ell:.3g} ell")
    if cylinder is not None:
        cx, cy, radius, _ = cylinder
        beyond = np.hypot(pos[:, 0] - cx, pos[:, 1] - cy) - (radius - rad)
        for i in np.nonzero(beyond > overlap_tol * ell)[0][:max_report]:
            problems.append(f"sphere {i} (particle {part[i]}) has its centre {beyond[i] / ell:.3g} ell "
                            f"beyond R - r from the cylinder's axis")

    # 2. rest at a local minimum, particle by particle, on the sediment below it
    starts = np.searchsorted(part, np.arange(len(com_all) + 1))
    ext = np.array([np.max(np.linalg.norm(pos[starts[p]:starts[p + 1]] - com_all[p], axis=1)
                           + rad[starts[p]:starts[p + 1]]) for p in range(len(com_all))])
    rmax = all_rad.max()
    n_reported = 0
    for p in range(len(com_all)):
        a = pos[starts[p]:starts[p + 1]]
        ra = rad[starts[p]:starts[p + 1]]
        com = com_all[p]
        # sediment of earlier particles and substrate near this one, as minimum images about its com
        sed = all_pos[:n_sub + starts[p]]
        rs = all_rad[:n_sub + starts[p]]
        d = _min_image(sed - com, lateral, box)
        near = np.linalg.norm(d, axis=1) < ext[p] + rmax + 1e-3 * ell
        s_pos = com + d[near]
        s_rad = rs[near]

        def gaps(x):
            """(pair gaps (na, ns), plane gaps (na, k))"""
            if len(s_pos):
                dd = np.sqrt(((x[:, None, :] - s_pos[None, :, :]) ** 2).sum(-1))
                gp = dd - ra[:, None] - s_rad[None, :]
            else:
                gp = np.zeros((len(x), 0))
            return gp, _plane_gaps(x, ra, walls)

        g0, pg0 = gaps(a)
        # contacts from positions: (pivot, kind)
        pivots = []
        ci, cj = np.nonzero(g0 < contact_tol * ell)
        for i, j in zip(ci, cj):
            pivots.append(s_pos[j])
        pi, pk = np.nonzero(pg0 < contact_tol * ell)
        on_floor = bool(np.any(pk == 0))
        sliding = []  # normals of frictionless wall contacts (pivots at infinity)
        for i, k in zip(pi, pk):
            if k > 0 and wall_contact == "frictionless":
                sliding.append(walls[0][k - 1])
            else:
                pivots.append(a[i].copy())
        n_contacts = len(pivots) + len(sliding)
        if floor == FLOOR_STOP and on_floor:
            continue

        def blocked(x):
            g, pgl = gaps(x)
            bad = (g < -block_tol * ell) & (g < g0 - 1e-13 * ell)
            badp = (pgl < -block_tol * ell) & (pgl < pg0 - 1e-13 * ell)
            return bool(bad.any() or badp.any())

        motions = []  # (name, pivot or None, axis): a rotation, or with no pivot a translation along axis
        motions.append(("fall", None, np.array([0.0, 0.0, -1.0])))
        for k, normal in enumerate(sliding):
            down = np.array([0.0, 0.0, -1.0]) + normal[2] * normal  # gravity's part along the plane
            if np.linalg.norm(down) > 1e-9:
                motions.append((f"slide down plane {k}", None, down / np.linalg.norm(down)))
            for m in range(k + 1, len(sliding)):
                line = np.cross(normal, sliding[m])
                if np.linalg.norm(line) > 1e-9 and abs(line[2]) > 1e-12:
                    motions.append((f"slide along planes {k},{m}", None, -np.sign(line[2]) * line
                                    / np.linalg.norm(line)))
        for k, P in enumerate(pivots):
            dv = com - P
            dh = np.hypot(dv[0], dv[1])
            if dh <= 1e-9 * np.linalg.norm(dv):
                continue
            motions.append((f"roll on contact {k}", P, np.array([-dv[1], dv[0], 0.0]) / dh))
        for k in range(len(pivots)):
            for normal in sliding:
                for sg in (1.0, -1.0):
                    motions.append((f"roll on contact {k} along a wall", pivots[k], sg * normal))
            for m in range(k + 1, len(pivots)):
                u = pivots[m] - pivots[k]
                if np.linalg.norm(u) < 1e-9 * ell:
                    continue
                u = u / np.linalg.norm(u)
                for sg in (1.0, -1.0):
                    motions.append((f"roll on contacts {k},{m}", pivots[k], sg * u))
        for name, P, axis in motions:
            free = True
            for dl in deltas:
                if P is None:
                    x = a + dl * ell * axis
                    zc = com[2] + dl * ell * axis[2]
                else:
                    x = _rotate(a, P, axis, dl)
                    zc = _rotate(com[None], P, axis, dl)[0, 2]
                lowering = (zc - com[2]) / dl
                if lowering >= -1e-8 * ell or blocked(x):
                    free = False
                    break
            if free:
                if n_reported < max_report:
                    problems.append(f"particle {p} (state {state[p]}, {n_contacts} contacts) is not at "
                                    f"rest: {name} lowers its centre of mass by "
                                    f"{-lowering / ell:.3g} ell/rad unblocked")
                n_reported += 1
                break
        if n_contacts < 3 and not (state[p] in (HANGING_ONE, HANGING_TWO) or
                                   (state[p] == RESTING_ON_FLOOR and on_floor)):
            problems.append(f"particle {p} has {n_contacts} contacts but state {state[p]}")
        if state[p] == RESTING_THREE_CONTACTS and n_contacts < 3:
            problems.append(f"particle {p} is reported resting on three contacts but has {n_contacts}")
    return problems
