"""The damped Arrow–Hurwicz scheme (Degond et al. 2024, eqs. 3.20–3.28), as :mod:`parsim.core.ts.daha` derives it.

The constraint (3.4), the drift–kick–damp–drift step (3.20)–(3.23) with its stiffness limit, the
multiplier update (3.24) on all pairs or on the pairs of awake spheres, the initial multipliers
(3.26), the attraction range of (3.30), and the measures of (3.27)–(3.28).
"""

import math

import numpy as np

from parsim.core.jit import jit
from parsim.core.kernel_mpi import global_sum
from parsim.core.ts.contacts import _distance_sq


@jit
def _phi(P, R, a, b):
    """Smooth constraint (3.4): ``(R_a + R_b)^2 - |X_a - X_b|^2``."""
    contact = R[a] + R[b]
    return contact * contact - _distance_sq(P, a, P, b)


@jit
def _drift(P, U, awake, h):
    for i in awake:
        for k in range(P.shape[1]):
            P[i, k] += h * U[i, k]


@jit
def _kick_damp_drift(state, adjacency, coefficients, awake, mean_overlap, dynamic):
    """Forces at the half step, eqs. (3.21)–(3.23); new positions of the awake spheres go to ``state.new``.
    ``state`` is the driver's ``MinimiserState``, ``adjacency`` its ``Adjacency``, ``coefficients`` its
    ``Coefficients`` (delta, alpha, gamma, c_bar and the two limits); ``mean_overlap`` is phi_A of (3.29),
    floored, read when ``dynamic``.
    A sphere whose stiffness ``K`` exceeds ``stiffness_limit / delta^2`` gets its kick scaled
    by ``stiffness_limit / (delta^2 K)`` (package docstring, "Stiff spheres").

    Written for d = 2 and 3 with the components in local variables, and the partner of each
    listed pair read from ``pair_partner``: the same sums in the same order as loops over the
    components with the force in an array and the partner found from the pair's two ends, in
    a little over half their time per sphere update."""
    P, U, R, lam, sphere_overlap = state.P, state.U, state.R, state.lam, state.sphere_overlap
    attracts, out, damping_of = state.attracts, state.new, state.damping_of
    link_ptr, link_to = adjacency.link_ptr, adjacency.link_to
    pair_ptr, pair_of, pair_partner = adjacency.pair_ptr, adjacency.pair_of, adjacency.pair_partner
    delta, alpha, gamma, c_bar = coefficients.step, coefficients.attraction, coefficients.penalty, coefficients.damping
    stiffness_limit, max_damping = coefficients.stiffness_limit, coefficients.max_damping
    three = P.shape[1] == 3
    for i in awake:
        xi, yi = P[i, 0], P[i, 1]
        zi = P[i, 2] if three else 0.0
        fx = fy = fz = 0.0
        stiffness = 0.0
        for e in range(link_ptr[i], link_ptr[i + 1]):  # attraction -alpha grad W (3.5 / 3.30)
            if attracts[e]:
                j = link_to[e]
                stiffness += alpha
                fx -= alpha * (xi - P[j, 0])
                fy -= alpha * (yi - P[j, 1])
                if three:
                    fz -= alpha * (zi - P[j, 2])
        for e in range(pair_ptr[i], pair_ptr[i + 1]):  # constraints, grad_i phi = -2 (X_i - X_j)
            multiplier = lam[pair_of[e]]
            if multiplier == 0.0:
                continue
            j = pair_partner[e]
            dx, dy = xi - P[j, 0], yi - P[j, 1]
            dz = zi - P[j, 2] if three else 0.0
            distance_sq = dx * dx + dy * dy + dz * dz if three else dx * dx + dy * dy
            contact = R[i] + R[j]
            strength = alpha + gamma * (contact * contact - distance_sq)
            stiffness += 2.0 * multiplier * (abs(strength) + 2.0 * gamma * distance_sq)
            coefficient = 2.0 * multiplier * strength
            fx += coefficient * dx
            fy += coefficient * dy
            fz += coefficient * dz
        step = delta * min(1.0, stiffness_limit / (delta * delta * stiffness)) if stiffness > 0.0 else delta
        ux, uy = U[i, 0] + step * fx, U[i, 1] + step * fy
        uz = U[i, 2] + step * fz if three else 0.0
        speed = ux * ux + uy * uy + uz * uz if three else ux * ux + uy * uy
        if dynamic:  # eq. 3.29; mean_overlap > 0 (floored)
            c = c_bar * (1.0 + abs(delta * math.sqrt(speed) - sphere_overlap[i]) / mean_overlap)
        else:
            c = c_bar
        damping_of[i] = c
        kept = 1.0 - min(delta * c, max_damping)
        U[i, 0], U[i, 1] = ux * kept, uy * kept
        out[i, 0], out[i, 1] = xi + 0.5 * delta * U[i, 0], yi + 0.5 * delta * U[i, 1]
        if three:
            U[i, 2] = uz * kept
            out[i, 2] = zi + 0.5 * delta * U[i, 2]


@jit
def _attracting_links(P, link_ptr, link_to, range_sq):
    """``H_W`` of eq. 3.30 for each link (in ``link_to`` order) at the positions ``P`` the
    minimisation starts from (package docstring, "Attraction range")."""
    attracts = np.empty(link_to.shape[0], dtype=np.bool_)
    for i in range(link_ptr.shape[0] - 1):
        for e in range(link_ptr[i], link_ptr[i + 1]):
            attracts[e] = _distance_sq(P, i, P, link_to[e]) <= range_sq
    return attracts


@jit
def _constraint_values(P, R, pair_a, pair_b, phi):
    """``phi`` of every candidate pair at ``P`` (eq. 3.4)."""
    for p in range(pair_a.shape[0]):
        phi[p] = _phi(P, R, pair_a[p], pair_b[p])


@jit
def _measure(phi, counted, link_ptr, pair_ptr, pair_of, sphere_overlap):
    """Overlap sum and count over the ``counted`` pairs (3.28), and the mean overlap per
    moving sphere (``sphere_overlap``, filled in; empty when not wanted)."""
    total = 0.0
    overlapping = 0
    for p in range(phi.shape[0]):
        if phi[p] > 0.0 and counted[p]:
            total += math.sqrt(phi[p])
            overlapping += 1
    for i in range(sphere_overlap.shape[0]):
        s = 0.0
        for e in range(pair_ptr[i], pair_ptr[i + 1]):
            p = pair_of[e]
            if phi[p] > 0.0:
                s += math.sqrt(phi[p])
        degree = link_ptr[i + 1] - link_ptr[i]
        sphere_overlap[i] = s / max(degree, 1)
    return total, overlapping


@jit
def _largest_step(P, previous, rows):
    """``max |P_i - previous_i|`` over the moving spheres ``rows``."""
    largest = 0.0
    for i in rows:
        largest = max(largest, _distance_sq(P, i, previous, i))
    return math.sqrt(largest)


@jit
def _copy_rows(target, source, rows):
    """``target[i] = source[i]`` for ``i`` in ``rows``."""
    for i in rows:
        for k in range(target.shape[1]):
            target[i, k] = source[i, k]


@jit
def _update_multipliers(P, R, phi, pair_a, pair_b, lam, rate, damping_of, stable, still):
    """``phi`` (3.4) at ``P`` and eq. 3.24 (3.31 in the almost-rigid form: the pairs are the
    tile's), the rate kept below ``stable`` times the smaller damping of the pair's moving
    spheres (``damping_of`` is infinite on anchors); pairs whose two ends are ``still`` (per
    row: settled or anchors on a full sweep, asleep otherwise) are skipped.  The step is
    written out here and in the two kernels below: a shared jitted helper made a large
    minimisation 1.5x slower."""
    for p in range(pair_a.shape[0]):
        if still[pair_a[p]] and still[pair_b[p]]:
            continue
        phi[p] = _phi(P, R, pair_a[p], pair_b[p])
        c = min(damping_of[pair_a[p]], damping_of[pair_b[p]])
        value = lam[p] + min(rate, stable * c) * phi[p]
        lam[p] = value if value > 0.0 else 0.0


@jit
def _update_multipliers_near(state, adjacency, awake, rate, stable):
    """``phi`` and eq. 3.24 on the pairs with an awake end, each once; the pairs of two sleeping
    spheres did not move and sleep too."""
    P, R, phi, lam, damping_of, is_awake = state.P, state.R, state.phi, state.lam, state.damping_of, state.is_awake
    pair_ptr, pair_of, pair_partner = adjacency.pair_ptr, adjacency.pair_of, adjacency.pair_partner
    n_moving = state.U.shape[0]
    for i in awake:
        for e in range(pair_ptr[i], pair_ptr[i + 1]):
            p = pair_of[e]
            j = pair_partner[e]
            if j < n_moving and is_awake[j] and j < i:
                continue  # updated from its other end, j
            phi[p] = _phi(P, R, i, j)  # (3.4) is symmetric: the same value as from (pair_a, pair_b)
            c = min(damping_of[i], damping_of[j])
            value = lam[p] + min(rate, stable * c) * phi[p]
            lam[p] = value if value > 0.0 else 0.0


@jit
def _update_cross_pairs_near(P, R, cross_pairs, pair_a, pair_b, is_awake, phi, lam, rate, damping_of, stable):
    """``phi`` and eq. 3.24 on the cross pairs whose local end sleeps and whose ghost end is
    awake on its owner (the pairs with an awake local end were updated from it)."""
    for p in cross_pairs:
        a, g = pair_a[p], pair_b[p]
        if is_awake[g] and not is_awake[a]:
            phi[p] = _phi(P, R, a, g)
            c = min(damping_of[a], damping_of[g])
            value = lam[p] + min(rate, stable * c) * phi[p]
            lam[p] = value if value > 0.0 else 0.0


@jit
def _initial_multipliers(P, R, pair_a, pair_b, initial):
    """Eq. 3.26: ``lambda_ij = lambda max(0, phi_ij)``."""
    lam = np.zeros(pair_a.shape[0])
    for p in range(pair_a.shape[0]):
        phi = _phi(P, R, pair_a[p], pair_b[p])
        if phi > 0.0:
            lam[p] = initial * phi
    return lam


def attraction_energy(problem):
    """``W`` of eq. 3.5 over the problem's links."""
    P = problem.positions
    energy = 0.0
    for i in range(problem.n_moving):
        for e in range(problem.link_ptr[i], problem.link_ptr[i + 1]):
            j = problem.link_to[e]
            # a link between two moving spheres is listed at both ends
            energy += 0.5 * float(np.sum((P[i] - P[j]) ** 2)) * (0.5 if j < problem.n_moving else 1.0)
    return energy


@jit
def _overlaps(phi, counted, link_ptr, pair_ptr, pair_of, sphere_overlap, n_links, halo):
    """The mean overlap over the links (3.28) and over the overlapping pairs, over all ranks."""
    total, overlapping = _measure(phi, counted, link_ptr, pair_ptr, pair_of, sphere_overlap)
    total = global_sum(total, halo)
    return total / max(n_links, 1.0), total / max(global_sum(float(overlapping), halo), 1.0)
