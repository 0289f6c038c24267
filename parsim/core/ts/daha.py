"""The damped Arrow–Hurwicz algorithm (DAHA) of Degond et al. 2024, section 3.2.

It looks for a configuration of the *moving* spheres that minimises the attraction
``W`` over the linked pairs (eq. 3.5; eq. 3.30 with the indicator ``H_W`` in the
almost-rigid form) under the smooth non-overlap constraints
``phi_ij = (R_i + R_j)^2 - |X_i - X_j|^2 <= 0`` (eq. 3.4) on the candidate pairs.
*Anchor* spheres (the outer rectangles of section 3.3) are read but never moved.

Signs.  The damped system (3.15)–(3.16) reads, with ``grad_i phi_ij = -2 (X_i - X_j)``,

    X_i'' = -alpha (grad_i W + sum_j lambda_ij grad_i phi_ij) - c_i X_i'
            - gamma sum_j phi_ij lambda_ij grad_i phi_ij,
    lambda_ij' = beta phi_ij   (held at 0 while lambda_ij = 0 and phi_ij < 0).

Its right-hand side is a force pulling linked spheres together and pushing
overlapping ones apart.  The printed discrete scheme (3.20)–(3.23) moves the
positions by ``-delta/2 V`` with ``V`` along that force, an *ascent*, and evaluates
the force at ``X^{r+1}`` before it is known.  We use the damped leapfrog that is a
consistent discretisation of (3.15) (drift, kick, damp, drift):

    X^{r+1/2} = X^r + (delta/2) U^r                                  (3.20)
    U^{r+1/2} = U^r + delta F(X^{r+1/2}, lambda^r)                   (3.21)
    U^{r+1}   = (1 - delta c_i) U^{r+1/2}, delta c_i clipped to [0, MAX_DAMPING] (3.22)
    X^{r+1}   = X^{r+1/2} + (delta/2) U^{r+1}                        (3.23)
    lambda^{r+1} = max(0, lambda^r + delta beta phi(X^{r+1}))         (3.24)

so ``alpha~ = delta alpha``, ``gamma~ = delta gamma``, ``beta~ = delta beta`` and
``c~ = delta c`` as in the paper.  Every moving sphere is updated from the previous
iterate (Jacobi): forces are gathered per sphere from its own link and pair lists,
and a multiplier depends only on the two positions of its pair, so splitting the
spheres among tiles or ranks changes nothing but the order of floating-point sums.

Stability.  Linearising (3.15)–(3.16) about a linked pair at contact (distance
``s = R_i + R_j``, multiplier ``lambda``) gives for the gap ``x``
``x''' + c x'' + 8 gamma lambda s^2 x' + 8 alpha beta s^2 x = 0``, stable (Routh–Hurwitz)
only if ``c gamma lambda > alpha beta``.  For a pair held by its own link
(``lambda = 1/2``) the values of eq. 4.1 (c = 1.3, gamma = 0.3, alpha = 0.3, beta = 3)
violate it (0.2 < 0.9): linked pairs then bounce about contact for ever, and DAHA does
not meet (3.27) on clumps of 20 discs or more.  Contacts that carry less load (smaller
``lambda``) need a larger ``c gamma``: with ``gamma = 10`` a few contacts of clumps of thousands
of discs kept bouncing with overlaps ``o_ij`` up to 0.2 (found by the deepest-overlap test
below, hidden by the mean of (3.28)).  Our defaults keep delta, alpha, eps_c and eps_s of
(4.1) and take ``c = 3``, ``gamma = 30`` and ``beta = 10``, constant, which converges on every
case we ran.

The multiplier rate.  ``phi_ij`` is quadratic in the overlap: a pair at ``o_ij = 0.05`` has
``phi_ij = 2.5e-3``, and with ``beta = 3`` its multiplier grows by ``delta beta phi_ij ~ 1e-3``
per iteration.  Shallow overlaps are then pushed out slowly, and their spheres, which do not
sleep while deeper than ``eps_c`` (below), stay awake: in the first minimisation of a large
step most moving spheres are still awake after 200 iterations.  The dynamic rate of (3.29)
multiplies ``beta_bar`` by ``sqrt(n) / phi_A``, over 10^3 in such a minimisation.  Our constant
rate is ``beta = 10``: such a minimisation then has about a quarter as many spheres awake at
iteration 200, needs about 40 % fewer sphere updates and ends at about half the mean overlap;
whole runs are shorter, and the TS-vs-ED statistics are unchanged within their spread.  A faster
rate gains little more and stops too early: at ``beta = 30`` two overlapping discs overshoot
contact, and the iteration stops at a turning point of their oscillation, where for a moment
every step is below ``eps_s``, with a gap of 0.005 (0.0006 at ``beta = 10``).  The Routh–Hurwitz bound asks
``lambda > alpha beta / (c gamma) = 0.033``.

Stiff spheres (ours).  The kick is explicit: it is stable only while ``delta^2 K_i`` stays
below a few, with ``K_i`` the stiffness of sphere ``i``, estimated as
``sum_j 2 lambda_ij (|alpha + gamma phi_ij| + 2 gamma |X_i - X_j|^2)`` over its active
constraints plus ``alpha`` per attracting link.  Multipliers grow in long minimisations of
jammed clumps, and a sphere with many links can then oscillate with growing amplitude until
one kick throws it a hundred radii away.  A sphere with ``delta^2 K_i > STIFFNESS_LIMIT``
therefore has its kick scaled by ``STIFFNESS_LIMIT / (delta^2 K_i)``, a diagonal preconditioning that
leaves the fixed points, and every sphere below the bound, unchanged.

Dynamic parameters (3.29), with ``dynamic = True``:
``c_i = c_bar (1 + |delta |U_i| - phi_i^A| / phi_A)`` and ``beta = beta_bar sqrt(n) / phi_A``
with ``n`` the number of moving spheres, ``phi_i^A`` the mean overlap of sphere ``i``
over its links and ``phi_A`` the mean overlap of the overlapping pairs.  Overlaps are
measured as in (3.28), ``o_ij = sqrt(max(0, phi_ij))`` (a length).  The printed law
``c_i = c_bar |...| / phi_A`` can freeze a sphere at rest or leave one undamped; the
``1 +`` keeps ``c_i >= c_bar``.  Each multiplier's rate is capped at ``STABILITY_MARGIN``
times the bound ``c gamma / (2 alpha)`` of its spheres.  The divisions are guarded:
``phi_A`` below ``OVERLAP_FLOOR eps_c`` counts as "no overlap".  The law still gives a sphere
deep in an overlap, once the mean overlap ``phi_A`` is small, ``delta c_i`` far above 1; clipped
at 1, (3.22) erased its velocity in every iteration and it never moved: every run at N >= 400
failed in its first steps, with a deep overlap left.  Clipped at
``MAX_DAMPING`` (0.9) it keeps a tenth of its velocity; clumps of 200 discs then converge and
those runs reach one cluster.  With constant parameters ``delta c`` is 0.45 and the clip does
nothing.  One caveat remains: the fast multipliers of (3.29) make two overlapping discs
overshoot contact, and the iteration stops at a turning point of their oscillation with a gap
of 0.009 (as with a constant ``beta = 30``, above); (3.27) looks at one iteration only.

Stopping (3.27)–(3.28): every moving sphere moved at most ``eps_s`` in the last
iteration and the mean overlap over the links, ``sum o_ij / #S``, is at most ``eps_c``.
We add that the deepest overlap, ``max o_ij`` over the candidate pairs, is at most
``eps_max``: the mean is diluted by the settled links of a large cluster, and in the
first iterations, which start at rest, every step is below ``eps_s``; without the
bound one deep overlap among a thousand settled links passes (3.28).

Stopping tile by tile (ours, after section 3.3).  Once the mean overlap (3.28) holds over
the whole minimisation, (3.27) and the deepest-overlap bound are applied to each inner
rectangle (tile) on its own.  A tile whose moving spheres all moved at most ``eps_s`` in the
last iteration and whose pairs overlap at most ``eps_max`` is *settled*: its spheres stop,
as anchors to their neighbours, and are skipped, with the multipliers of pairs that have no
moving end elsewhere.  Each check judges every tile again, so a settled tile whose
neighbours push into it reopens, and all reopen if the mean rises above ``eps_c``.  The
minimisation stops when every tile is settled (with one tile: the global tests).  Judged
as a whole, a large minimisation waits for the last of the spheres that creep around a
neighbour under a stretched link, somewhere among all its tiles; the more spheres, the
longer.  Judged tile by tile, a minimisation of 10^5 or 10^6 spheres stops after a few times
fewer iterations.  The mean overlap left is then close to ``eps_c`` (about 0.009, where the
test of the whole minimisation leaves about 0.002): the paper's tolerance; ``sqrt(phi) = 0.009``
is a penetration ``phi / (4 R)`` of 5e-4 R at R = 0.2.  Applying (3.28) tile by tile as well does
not work: a small tile jammed against its anchors can hold a mean above ``eps_c`` for ever.  The
tiles need not be the inner rectangles: the stepper stops on cells four diameters wide, or on the
inner rectangles where those are finer (:func:`parsim.core.ts.tiles.stopping_cells_per_side`).
The inner rectangles of a large first-step minimisation hold some hundreds of spheres each; on
the cells, settled regions rest sooner, with the same TS-vs-ED statistics.

Jammed tiles.  Settled neighbours can also jam a tile: a sphere pressed by settled spheres
(each pair at most ``eps_max``) into an anchor (deeper than ``eps_max``) has nowhere to go,
and its tile stays steady and too deep for ever: one such sphere can hold a minimisation of
most of 10^6 spheres open for thousands of iterations.  A tile found steady but too deep at
``JAMMED_CHECKS`` checks in a row is *jammed*, and a tile with a moving sphere that overlaps a
moving sphere of a jammed tile does not settle, so the spheres pressing on the jam can give way.
A tile that is still moving, or has been deep only for a moment, holds nothing open, so a
minimisation without a jam stops after the same iterations.  A sphere caged by anchors, which
never move, stays caged whatever the iterations: the stepper then gives up and solves the
minimisation again in one tile, without anchors (:mod:`parsim.core.ts.stepper`).

Initial multipliers.  Eq. 3.26 sets ``lambda_ij = lambda max(0, phi_ij)``.  A link that
took part in the previous minimisation ended it at a critical point of (3.8) with its
multiplier; restarting it from ``max(0, phi_ij) ~ 0`` releases every settled contact of
the interacting clusters, which must all relax again.  :func:`minimise` therefore takes
the multipliers to start from; the stepper passes each link's last value when
``carry_multipliers`` is set (the default), and pairs without one start from (3.26).
This needs about ten times fewer sphere updates.

Sleeping spheres (ours; ``sleep_tolerance = 0`` gives the plain Jacobi iteration above).
In a large minimisation most spheres settle within a few hundred iterations while a few
contacts elsewhere take a thousand more (most sphere updates of a large minimisation move
their sphere less than 1e-5).  Every ``FULL_SWEEP_EVERY`` iterations all spheres are updated
and the stopping conditions are tested; after such a sweep a sphere that moved at most
``sleep_tolerance`` and overlaps no partner by more than ``eps_c`` sleeps: it is put at rest
and skipped, and so are the multipliers of pairs of two sleeping spheres, until a partner
moves more than ``sleep_tolerance`` (it then wakes in the next iteration) or the next full
sweep.  Spheres in deeper overlaps never sleep: their multipliers are what drives (3.28)
down, and freezing them made a clump converge eight times slower.  A configuration where
nothing moves is a fixed point of both iterations, the stopping conditions are tested on full
sweeps only (but see polishing below), and every decision is local to a sphere and its
partners, so the iteration still splits among tiles and ranks.  While more than half the
moving spheres are awake (the first hundred or so iterations of a large minimisation, three
quarters of its sphere updates), the multipliers are updated and the wake-ups spread pair by
pair rather than sphere by sphere: the same pairs and spheres, in less time.

Polishing (ours, with sleeping spheres).  Once a full sweep finds (3.27) and (3.28) met, the
paper would stop; only our deepest-overlap bound may still fail.  From then on the full
sweeps stop: the checks (every ``FULL_SWEEP_EVERY`` iterations) put to sleep, by the rule
above, the spheres that are awake, but wake no sleeping one, and test the stopping conditions
on the current positions (the constraint values of sleeping pairs have not changed).  A
sleeping sphere wakes only when a partner moves.  The full sweeps kept waking the spheres
that creep at about 1e-4 per iteration under stretched links; they made new short-lived deep
overlaps elsewhere, with different pairs passing ``eps_max`` in turn, and a large minimisation
ran about twice as many iterations.  Letting the pairs deeper than ``eps_c`` sleep too would
stop sooner for the same CPU time, but leave several times more pairs above ``eps_c``.
Polishing ends, and the full sweeps resume, if the mean overlap rises above ``eps_c``.

Attraction range (3.30).  The indicator ``H_W(|X_i - X_j| <= Delta_W)`` is taken once per
minimisation, at the positions it starts from (``X^{n,q-1}`` of (3.1)); the links that
attract then attract until it ends.  Taken at every iterate, the pull of a link jumps between
``alpha Delta_W`` and 0 as its length crosses ``Delta_W``, and spheres on such links chatter
across it: in a large minimisation about a hundred of them, different ones at each check, move
more than ``eps_s`` per iteration, and it runs about three times as many iterations as with the
indicator fixed.  The paper's notation allows both readings: (3.30) writes the indicator at
``X^{n,q}``, as it writes the variable of (3.5).

Iterations in one call.  The iterations run in one jitted call, :func:`_iterations`, which
exchanges the ghost rows and reduces the drift from inside (:mod:`parsim.core.kernel_mpi`).  It
returns to Python only for what Python does (:class:`_Minimisation`): after a check iteration
(every ``FULL_SWEEP_EVERY``-th with sleeping spheres, every one without), for the stopping tests,
settled tiles and sleeping spheres; and before an iteration whose pairs must be searched again.
In between it does not leave numba, whose round trips at every iteration would take a large
share of a time step.  Each iteration sends each neighbour one message, after (3.23): the
position, velocity and damping of the awake spheres it holds as ghosts (:func:`_share_motion`),
the only rows that changed; the receiver marks those ghosts awake, the others asleep, and makes
the next half drift (3.20) of its ghosts itself, with their owners' velocities (a sphere at rest
on its owner has a zero velocity there too: :func:`_drift_ghosts`, :func:`_stop_ghosts`).  Checks
add the flags of settled tiles and sleeping spheres.

Candidate pairs.  The pairs that can touch are those with a gap of at most ``problem.reach``.
They are kept as a Verlet list refreshed sphere by sphere: once a sphere is ``REFRESH_DRIFT``
reach from where its pairs were last searched, the pairs of every sphere more than
``REFRESH_SET`` of that away are searched again
(:func:`parsim.core.ts.contacts.updated_candidate_pairs`).  A few fast spheres then no longer
cost a search over all pairs: the problem keeps its spheres binned in cells where their pairs
were last searched, and a refresh rebins and searches the moved spheres, then merges the
pair lists once, carrying each pair's multiplier and constraint value.  In the first hundred
iterations of a large minimisation it runs every second iteration for a few percent of the
spheres, at about half the cost of a sort of every sphere into cells.
"""

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from parsim.core import kernel_mpi
from parsim.core.jit import jit
from parsim.core.kernel_mpi import global_max, global_max_array, global_sum, share_changed_rows, share_flags
from parsim.core.ts.contacts import _distance_sq

#: With dynamic parameters, phi_A below OVERLAP_FLOOR x eps_c counts as no overlap at all.
OVERLAP_FLOOR = 1e-9
#: The multiplier rate is kept below this fraction of the linear stability bound c gamma / (2 alpha).
STABILITY_MARGIN = 0.5
#: A sphere's kick is scaled down when delta^2 times its stiffness exceeds this (module docstring).
STIFFNESS_LIMIT = 2.0
#: The damping of one iteration, delta c_i, is clipped here: at 1 a sphere's velocity would be
#: erased in every iteration (module docstring, "Dynamic parameters").
MAX_DAMPING = 0.9
#: Once a moving sphere is this fraction of the candidate reach away from where its pairs were
#: last searched, its pairs are searched again (contacts.updated_candidate_pairs needs <= 1/3) ...
REFRESH_DRIFT = 1.0 / 3.0
#: ... and so are those of every sphere more than this fraction of that distance away.
REFRESH_SET = 0.5
#: With sleeping spheres, every sphere is updated (and the stopping conditions tested) once
#: in this many iterations.
FULL_SWEEP_EVERY = 16
#: A tile steady but deeper than eps_max at this many checks in a row is jammed (module docstring).
JAMMED_CHECKS = 4


@dataclass(frozen=True)
class DahaParameters:
    """The numerical parameters of DAHA: eq. 4.1 except ``damping`` and ``penalty``
    (see the module docstring: the printed pair is linearly unstable).

    ``initial_multiplier`` is the constant ``lambda`` of eq. 3.26 (the paper gives no
    value); ``max_iterations`` bounds one minimisation, beyond which it is reported as
    not converged.  ``max_overlap_tolerance``, ``carry_multipliers`` and ``sleep_tolerance`` are ours
    (module docstring).
    """

    damping: float = 3.0  #: c (c_bar of (3.29) when dynamic); eq. 4.1 has 1.3
    step: float = 0.15  #: delta, the artificial time step
    attraction: float = 0.3  #: alpha
    penalty: float = 30.0  #: gamma; eq. 4.1 has 0.3
    multiplier_rate: float = 10.0  #: beta (beta_bar of (3.29) when dynamic); eq. 4.1 has 3
    overlap_tolerance: float = 1e-2  #: eps_c of (3.28), a length
    steadiness_tolerance: float = 1e-3  #: eps_s of (3.27), a length
    max_overlap_tolerance: float = 0.1  #: eps_max, bound on the deepest overlap max o_ij, a length
    initial_multiplier: float = 1.0  #: lambda of (3.26)
    dynamic: bool = False  #: c and beta from (3.29); False: the constants c_bar, beta_bar of (3.15)-(3.16)
    max_iterations: int = 100_000
    carry_multipliers: bool = True  #: links start from their last multiplier, not from (3.26)
    sleep_tolerance: float = 1e-4  #: a length; 0: every sphere is updated in every iteration


@dataclass
class Outcome:
    """What one minimisation did."""

    converged: bool
    iterations: int
    mean_overlap: float  #: mean overlap over the links at the end (3.28)
    max_overlap: float  #: the deepest overlap max o_ij at the end
    max_step: float  #: largest displacement of the last iteration (3.27)
    finite: bool
    multipliers: np.ndarray  #: lambda of each candidate pair of the problem at the end
    left_halo: bool = False  #: a sphere moved farther than the exchange's ``margin`` (decomposed runs)


class SerialExchange:
    """The halo interface of the minimiser on one process: every call is a no-op.

    A decomposed run passes an object with the same members: ``sum`` and ``max`` reduce a float
    over all parts of the problem;
    ``margin`` is how far a sphere may move from where the ghosts were chosen; ``kernel_halo``
    is the same exchange for the jitted iterations (:mod:`parsim.core.kernel_mpi`).
    """

    margin = math.inf

    @property
    def kernel_halo(self):
        """The halo of :mod:`parsim.core.kernel_mpi` for the jitted iterations: none."""
        return kernel_mpi.no_halo()

    def sum(self, value):
        return value

    def max(self, value):
        return value


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
def _kick_damp_drift(P, U, R, awake, link_ptr, link_to, pair_ptr, pair_of, pair_partner, lam,
                     sphere_overlap, mean_overlap, dynamic, delta, alpha, gamma, c_bar, attracts, out,
                     damping_of, stiffness_limit, max_damping):
    """Forces at the half step, eqs. (3.21)–(3.23); new positions of the awake spheres go to ``out``.
    A sphere whose stiffness ``K`` exceeds ``stiffness_limit / delta^2`` gets its kick scaled
    by ``stiffness_limit / (delta^2 K)`` (module docstring, "Stiff spheres").

    Written for d = 2 and 3 with the components in local variables, and the partner of each
    listed pair read from ``pair_partner``: the same sums in the same order as loops over the
    components with the force in an array and the partner found from the pair's two ends, in
    a little over half their time per sphere update."""
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
    minimisation starts from (module docstring, "Attraction range")."""
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
def _carried(source, lam, phi, P, R, pair_a, pair_b):
    """Multiplier and constraint value of each pair after a refresh of the candidate pairs:
    those of the same pair before (``source``; ``phi`` is kept current by the multiplier
    updates), and 0 and (3.4) for a new pair."""
    new_lam = np.zeros(source.shape[0])
    new_phi = np.empty(source.shape[0])
    for p in range(source.shape[0]):
        if source[p] >= 0:
            new_lam[p] = lam[source[p]]
            new_phi[p] = phi[source[p]]
        else:
            new_phi[p] = _phi(P, R, pair_a[p], pair_b[p])
    return new_lam, new_phi


@jit
def _wake_partners(i, n_moving, is_awake, link_ptr, link_to, pair_ptr, pair_partner, woken, count):
    """Wake the moving partners (links and candidate pairs) of sphere ``i``; returns the new count."""
    for e in range(link_ptr[i], link_ptr[i + 1]):
        j = link_to[e]
        if j < n_moving and not is_awake[j]:
            is_awake[j] = True
            woken[count] = j
            count += 1
    for e in range(pair_ptr[i], pair_ptr[i + 1]):
        j = pair_partner[e]
        if j < n_moving and not is_awake[j]:
            is_awake[j] = True
            woken[count] = j
            count += 1
    return count


@jit
def _wake_ghost_partners(g, first_ghost, is_awake, ghost_ptr, ghost_partner, woken, count):
    """Wake the local moving partners of ghost row ``first_ghost + g``; returns the new count."""
    for e in range(ghost_ptr[g], ghost_ptr[g + 1]):
        j = ghost_partner[e]
        if not is_awake[j]:
            is_awake[j] = True
            woken[count] = j
            count += 1
    return count


@jit
def _spread(P, previous, previous_ghost, arrived, awake, is_awake, n_moving, first_ghost, link_ptr, link_to, pair_ptr,
            pair_partner, ghost_ptr, ghost_partner, tolerance):
    """The awake spheres after a partial iteration: those awake, and the partners of those
    (moving ghosts included: the ghost rows that ``arrived`` from their owners) that moved more
    than ``tolerance`` (a disturbance travels one contact per iteration)."""
    woken = np.empty(n_moving, dtype=np.int64)
    count = 0
    for i in awake:
        if _distance_sq(P, i, previous, i) > tolerance * tolerance:
            count = _wake_partners(i, n_moving, is_awake, link_ptr, link_to, pair_ptr, pair_partner, woken, count)
    for g in arrived:
        if ghost_ptr[g + 1] > ghost_ptr[g] and _distance_sq(P, first_ghost + g, previous_ghost, g) > tolerance**2:
            count = _wake_ghost_partners(g, first_ghost, is_awake, ghost_ptr, ghost_partner, woken, count)
    if count == 0:
        return awake
    return _merged(awake, np.sort(woken[:count]))


@jit
def _spread_dense(P, previous, previous_ghost, arrived, awake, is_awake, n_moving, first_ghost, link_ptr, link_to,
                  pair_a, pair_b, tolerance):
    """:func:`_spread` pair by pair and link by link, the same awake spheres: cheaper when most
    spheres are awake (it visits each pair once, in memory order, not from both ends)."""
    moved = np.zeros(P.shape[0], dtype=np.bool_)
    for i in awake:
        moved[i] = _distance_sq(P, i, previous, i) > tolerance * tolerance
    for g in arrived:
        moved[first_ghost + g] = _distance_sq(P, first_ghost + g, previous_ghost, g) > tolerance * tolerance
    woken = np.empty(n_moving, dtype=np.int64)
    count = 0
    for p in range(pair_a.shape[0]):  # pair_a < n_moving
        a, b = pair_a[p], pair_b[p]
        if moved[a] and b < n_moving and not is_awake[b]:
            is_awake[b] = True
            woken[count] = b
            count += 1
        if moved[b] and not is_awake[a]:
            is_awake[a] = True
            woken[count] = a
            count += 1
    for i in range(n_moving):  # a link is listed at each moving end
        if not is_awake[i]:
            for e in range(link_ptr[i], link_ptr[i + 1]):
                if moved[link_to[e]]:
                    is_awake[i] = True
                    woken[count] = i
                    count += 1
                    break
    if count == 0:
        return awake
    return _merged(awake, np.sort(woken[:count]))


@jit
def _merged(a, b):
    """The sorted union of the sorted, disjoint arrays ``a`` and ``b`` (cheaper than sorting
    their concatenation when ``b`` is short)."""
    out = np.empty(a.shape[0] + b.shape[0], dtype=a.dtype)
    i = j = 0
    for k in range(out.shape[0]):
        if j == b.shape[0] or (i < a.shape[0] and a[i] < b[j]):
            out[k] = a[i]
            i += 1
        else:
            out[k] = b[j]
            j += 1
    return out


@jit
def _restless(P, previous, phi, pair_ptr, pair_of, tolerance, restless_phi, settled, restless):
    """After a full sweep: a moving sphere outside the ``settled`` tiles is restless if it moved
    more than ``tolerance`` or overlaps a partner by more than ``sqrt(restless_phi)`` (a settled
    sphere's deep partners are restless themselves, so they wake what it would wake)."""
    for i in range(previous.shape[0]):
        if settled[i]:
            restless[i] = False
            continue
        moved = _distance_sq(P, i, previous, i) > tolerance * tolerance
        for e in range(pair_ptr[i], pair_ptr[i + 1]):
            moved = moved or phi[pair_of[e]] > restless_phi
        restless[i] = moved


@jit
def _settle(restless, U, is_awake, first_ghost, link_ptr, link_to, pair_ptr, pair_partner, ghost_ptr, ghost_partner):
    """The restless spheres (ghost rows: restless on their owner) and their partners stay
    awake; the others sleep, at rest, with their pairs' multipliers, until a partner moves.
    Returns the awake moving spheres, in order: read off the flags in the pass that stops the
    others, not sorted as they woke (a sort that would about double the checks' time here)."""
    n_moving = U.shape[0]
    for i in range(is_awake.shape[0]):
        is_awake[i] = False
    woken = np.empty(n_moving, dtype=np.int64)
    count = 0
    for i in range(n_moving):
        if restless[i]:
            if not is_awake[i]:
                is_awake[i] = True
                woken[count] = i
                count += 1
            count = _wake_partners(i, n_moving, is_awake, link_ptr, link_to, pair_ptr, pair_partner, woken, count)
    for g in range(ghost_ptr.shape[0] - 1):
        if restless[first_ghost + g]:
            count = _wake_ghost_partners(g, first_ghost, is_awake, ghost_ptr, ghost_partner, woken, count)
    count = 0
    for i in range(n_moving):
        if is_awake[i]:
            woken[count] = i
            count += 1
        else:
            for k in range(U.shape[1]):
                U[i, k] = 0.0
    return woken[:count]


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
def _rebase(P, built_at, n_moving, first_ghost, far, moved):
    """Flag in ``moved`` the moving spheres (rows below ``n_moving``) and the ghost rows (from
    ``first_ghost`` on) more than ``far`` from ``built_at``, where their pairs are to be searched
    again, and move their ``built_at`` to ``P``; returns how far the other moving spheres are
    from theirs at most.  A ghost row holds its owner's positions, from the same start, and is
    rebased at the same iterations: it is flagged as its owner flags it, with no exchange."""
    largest = 0.0
    for i in range(n_moving):
        distance_sq = _distance_sq(P, i, built_at, i)
        if not _flag_moved(P, built_at, i, distance_sq > far * far, moved):
            largest = max(largest, distance_sq)
    for i in range(first_ghost, P.shape[0]):
        _flag_moved(P, built_at, i, _distance_sq(P, i, built_at, i) > far * far, moved)
    return math.sqrt(largest)


@jit
def _flag_moved(P, built_at, i, far_off, moved):
    """``moved[i] = far_off``, and a row far off is rebased at ``P``; returns ``far_off``."""
    moved[i] = far_off
    if far_off:
        for k in range(P.shape[1]):
            built_at[i, k] = P[i, k]
    return far_off


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
def _update_multipliers_near(P, R, phi, awake, is_awake, n_moving, pair_ptr, pair_of, pair_partner, lam, rate,
                             damping_of, stable):
    """``phi`` and eq. 3.24 on the pairs with an awake end, each once; the pairs of two sleeping
    spheres did not move and sleep too."""
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
def _tile_measures(P, previous, phi, pair_a, pair_b, n_moving, tile_of, n_tiles):
    """Per tile of this process (rows of a ``(2, n_tiles)`` array): the largest step of its
    moving spheres (3.27) and its deepest overlap over the pairs with an end in it."""
    measures = np.zeros((2, n_tiles))
    largest, deepest = measures[0], measures[1]
    for i in range(n_moving):
        largest[tile_of[i]] = max(largest[tile_of[i]], math.sqrt(_distance_sq(P, i, previous, i)))
    for p in range(phi.shape[0]):
        if phi[p] > 0.0:
            overlap = math.sqrt(phi[p])
            deepest[tile_of[pair_a[p]]] = max(deepest[tile_of[pair_a[p]]], overlap)
            if pair_b[p] < n_moving:
                deepest[tile_of[pair_b[p]]] = max(deepest[tile_of[pair_b[p]]], overlap)
    return measures


@jit
def _over_all_tiles(tiles, shared_tiles, halo):
    """Maximise each row of ``tiles`` (measures, >= 0, of this process's tiles) over the processes
    at the tiles several of them hold (``shared_tiles``: the local index of each, -1 where this
    process holds none of it), in place, in one reduction with the largest of each row; returns
    those (numpy's max: a NaN stays)."""
    rows, n_shared = tiles.shape[0], shared_tiles.shape[0]
    packed = np.zeros(rows * (n_shared + 1))
    for r in range(rows):
        packed[r] = tiles[r].max() if tiles.shape[1] > 0 else 0.0
        for s in range(n_shared):
            if shared_tiles[s] >= 0:
                packed[rows + r * n_shared + s] = tiles[r, shared_tiles[s]]
    packed = global_max_array(packed, halo)
    for r in range(rows):
        for s in range(n_shared):
            if shared_tiles[s] >= 0:
                tiles[r, shared_tiles[s]] = packed[rows + r * n_shared + s]
    return packed[:rows]


@jit
def _any_over_all_tiles(a, b, c, halo):
    """Whether any tile of any process is flagged in ``a``, in ``b``, in ``c``: one reduction."""
    flags = np.array([1.0 if a.any() else 0.0, 1.0 if b.any() else 0.0, 1.0 if c.any() else 0.0])
    flags = global_max_array(flags, halo)
    return flags[0] > 0.0, flags[1] > 0.0, flags[2] > 0.0


@jit
def _pressed_tiles(phi, pair_a, pair_b, n_moving, tile_of, n_tiles, in_jammed_tile):
    """Per tile (one row), 1.0 if one of its moving spheres overlaps a moving sphere of a jammed
    tile (``in_jammed_tile``, per row; module docstring, "Jammed tiles"), else 0.0."""
    pressed_tiles = np.zeros((1, n_tiles))
    pressed = pressed_tiles[0]
    for p in range(phi.shape[0]):
        if phi[p] > 0.0:
            a, b = pair_a[p], pair_b[p]
            if in_jammed_tile[b]:
                pressed[tile_of[a]] = 1.0
            if in_jammed_tile[a] and b < n_moving:
                pressed[tile_of[b]] = 1.0
    return pressed_tiles


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
def _drop_settled(awake, settled, is_awake):
    """The ``awake`` spheres outside settled tiles (the others are marked asleep)."""
    kept = np.empty_like(awake)
    count = 0
    for i in awake:
        if settled[i]:
            is_awake[i] = False
        else:
            kept[count] = i
            count += 1
    return kept[:count]


def motion_width(dimension):
    """Floats per row that the iterations send a neighbour: a moving sphere's position, velocity
    and damping (:func:`_share_motion`)."""
    return 2 * dimension + 1


@jit
def _drift_ghosts(P, ghost_U, previous_ghost, first_ghost, h):
    """(3.20) for the ghost rows, as their owners do it: ``ghost_U`` is each one's velocity on its
    owner, zero for a sphere at rest there (asleep, settled, an anchor), which the owner does not
    move; the rows that move keep their start in ``previous_ghost``."""
    d = P.shape[1]
    for g in range(ghost_U.shape[0]):
        if _is_moving(ghost_U, g):
            for k in range(d):
                previous_ghost[g, k] = P[first_ghost + g, k]
                P[first_ghost + g, k] += h * ghost_U[g, k]


@jit
def _is_moving(U, i):
    """Whether row ``i`` of the velocities ``U`` is not zero."""
    for k in range(U.shape[1]):
        if U[i, k] != 0.0:
            return True
    return False


@jit
def _share_motion(P, U, damping_of, previous_ghost, is_awake, awake, ghost_motion, halo):
    """After (3.23): each neighbour gets, in one message, the position, velocity and damping of the
    ``awake`` spheres it holds as ghosts (the rows that changed); the ghost rows that come are
    ``arrived[:n]`` (returns ``n``), awake (``is_awake``) as on their owners, the others asleep.
    Their start stays in ``previous_ghost``."""
    ghost_U, motion, changed, sends, arrived = ghost_motion
    first_ghost, d = P.shape[0] - ghost_U.shape[0], P.shape[1]
    if halo.neighbours.shape[0] == 0:  # no neighbour
        return 0
    for i in awake:
        if sends[i]:
            changed[i] = True
            for k in range(d):
                motion[i, k] = P[i, k]
                motion[i, d + k] = U[i, k]
            motion[i, 2 * d] = damping_of[i]
    n = share_changed_rows(motion, first_ghost, changed, arrived, halo)
    for i in awake:
        changed[i] = False
    is_awake[first_ghost:] = False
    for g in arrived[:n]:
        row = first_ghost + g
        if not _is_moving(ghost_U, g):  # not drifted: still at its start
            for k in range(d):
                previous_ghost[g, k] = P[row, k]
        for k in range(d):
            P[row, k] = motion[row, k]
            ghost_U[g, k] = motion[row, d + k]
        damping_of[row] = motion[row, 2 * d]
        is_awake[row] = True
    return n


@jit
def _stop_ghosts(ghost_U, flags, first_ghost, stop_flagged):
    """Zero the velocity of the ghost rows whose flag (per row) is ``stop_flagged``, as their
    owners zero it (settled tiles, sleeping spheres: :func:`_check`)."""
    for g in range(ghost_U.shape[0]):
        if flags[first_ghost + g] == stop_flagged:
            for k in range(ghost_U.shape[1]):
                ghost_U[g, k] = 0.0


#: Why :func:`_iterations` returned: it reached the iteration it was asked to stop at, the pairs
#: must be searched again before the next iteration moves anything, the stopping tests hold, or a
#: position or the mean overlap is not finite.
REACHED_LAST, REFRESH_DUE, CONVERGED, NOT_FINITE = 0, 1, 2, 3
_GO_ON = -1


@jit
def _iterations(iteration, last, state, awake, stepped, drift, refresh_at, flags, measures, adjacency, pairs,
                coefficients, checks, dynamic, ghost_motion, halo):
    """DAHA iterations from ``iteration`` on, in one call, with the ghost rows and the reductions
    exchanged from here (:mod:`parsim.core.kernel_mpi`), until ``last``, the stopping tests, a
    non-finite value, or an iteration whose pairs must be searched again (the global ``drift``
    above ``refresh_at``; it returns before moving anything).  Returns ``(iteration, awake,
    stepped, drift, why, flags, measures)``, ``flags`` = ``(polishing, any_settled)`` and
    ``measures`` = ``(mean_overlap, typical_overlap, largest, deepest)``.

    Each iteration: the drift test; on a full sweep every sphere outside settled tiles awake;
    (3.20)-(3.23) for the awake spheres; (3.24) for their pairs; then, between checks, the
    spheres that a moving partner wakes (module docstring, "Sleeping spheres"), and on a check
    the tests of :func:`_check`.

    Why so many parameters: besides the named bundles (``state`` a :class:`MinimiserState`,
    ``adjacency``, ``pairs``, ``coefficients``, ``checks``, ``ghost_motion``, ``halo``), a call takes the
    progress the previous one returned (iteration, awake and stepped rows, drift, flags, measures)."""
    P, R, U, new, previous, previous_ghost, built_at, lam, phi, sphere_overlap, attracts, damping_of, is_awake, \
        settled, is_anchor = state
    link_ptr, link_to, pair_ptr, pair_of, pair_partner, ghost_ptr, ghost_partner = adjacency
    pair_a, pair_b, cross_pairs = pairs
    delta, alpha, gamma, c_bar, stable, sleep, stiffness_limit, max_damping, multiplier_rate, floor, n_spheres = \
        coefficients
    polishing, any_settled = flags
    n_moving = U.shape[0]
    first_ghost = P.shape[0] - previous_ghost.shape[0]
    ghost_U, arrived = ghost_motion.ghost_U, ghost_motion.arrived
    while iteration < last:
        guarded = max(measures[1], floor)
        rate = delta * multiplier_rate * (math.sqrt(n_spheres) / guarded if dynamic else 1.0)
        check = sleep == 0.0 or iteration % FULL_SWEEP_EVERY == 0
        _copy_rows(previous, P, stepped)
        drift = max(drift, _largest_step(P, built_at, stepped))
        if global_max(drift, halo) > refresh_at:  # a pair may come within reach
            return iteration, awake, stepped, drift, REFRESH_DUE, (polishing, any_settled), measures
        full = check and not polishing
        if full:
            awake = _drop_settled(np.arange(n_moving), settled, is_awake) if any_settled else np.arange(n_moving)
        stepped = awake
        _drift(P, U, awake, 0.5 * delta)
        _drift_ghosts(P, ghost_U, previous_ghost, first_ghost, 0.5 * delta)
        _kick_damp_drift(P, U, R, awake, link_ptr, link_to, pair_ptr, pair_of, pair_partner, lam, sphere_overlap,
                         guarded, dynamic, delta, alpha, gamma, c_bar, attracts, new, damping_of, stiffness_limit,
                         max_damping)
        _copy_rows(P, new, awake)  # accept the new positions
        n_arrived = _share_motion(P, U, damping_of, previous_ghost, is_awake, awake, ghost_motion, halo)
        mostly_awake = 2 * awake.shape[0] > n_moving  # then pair by pair beats sphere by sphere
        if full:
            _update_multipliers(P, R, phi, pair_a, pair_b, lam, rate, damping_of, stable, settled | is_anchor)
        elif mostly_awake:
            _update_multipliers(P, R, phi, pair_a, pair_b, lam, rate, damping_of, stable, ~is_awake)
        else:
            _update_multipliers_near(P, R, phi, awake, is_awake, n_moving, pair_ptr, pair_of, pair_partner, lam,
                                     rate, damping_of, stable)
            _update_cross_pairs_near(P, R, cross_pairs, pair_a, pair_b, is_awake, phi, lam, rate, damping_of, stable)
        iteration += 1
        if check:
            why, awake, polishing, any_settled, measures = _check(state, awake, polishing, adjacency, pairs, checks,
                                                                  sleep, ghost_U, halo)
            if why != _GO_ON:
                return iteration, awake, stepped, drift, why, (polishing, any_settled), measures
            continue
        if mostly_awake:
            awake = _spread_dense(P, previous, previous_ghost, arrived[:n_arrived], awake, is_awake, n_moving,
                                  first_ghost, link_ptr, link_to, pair_a, pair_b, sleep)
        else:
            awake = _spread(P, previous, previous_ghost, arrived[:n_arrived], awake, is_awake, n_moving, first_ghost,
                            link_ptr, link_to, pair_ptr, pair_partner, ghost_ptr, ghost_partner, sleep)
        if any_settled:
            awake = _drop_settled(awake, settled, is_awake)
    return iteration, awake, stepped, drift, REACHED_LAST, (polishing, any_settled), measures


@jit
def _check(state, awake, polishing, adjacency, pairs, checks, sleep, ghost_U, halo):
    """The tests after a check iteration (module docstring, "Stopping tile by tile", "Jammed
    tiles", "Polishing"): ``(why, awake, polishing, any_settled, measures)``, ``why`` CONVERGED,
    NOT_FINITE or ``_GO_ON``; settles tiles and puts spheres to sleep when it goes on."""
    P, R, U, new, previous, previous_ghost, built_at, lam, phi, sphere_overlap, attracts, damping_of, is_awake, \
        settled, is_anchor = state
    link_ptr, link_to, pair_ptr, pair_of, pair_partner, ghost_ptr, ghost_partner = adjacency
    pair_a, pair_b, cross_pairs = pairs
    tile_of, shared_tiles, jammed_checks, in_jammed_tile, restless, pair_counted, tolerances, n_links, \
        jammed_limit = checks
    steadiness, max_overlap, overlap = tolerances
    n_moving, n_tiles = U.shape[0], jammed_checks.shape[0]
    first_ghost = P.shape[0] - previous_ghost.shape[0]
    mean_overlap, typical_overlap = _overlaps(phi, pair_counted, link_ptr, pair_ptr, pair_of, sphere_overlap, n_links,
                                              halo)
    tiles = _tile_measures(P, previous, phi, pair_a, pair_b, n_moving, tile_of, n_tiles)
    maxima = _over_all_tiles(tiles, shared_tiles, halo)
    largest, deepest = maxima[0], maxima[1]
    measures = (mean_overlap, typical_overlap, largest, deepest)
    if not (math.isfinite(largest) and math.isfinite(mean_overlap)):
        return NOT_FINITE, awake, polishing, False, measures
    steady = tiles[0] <= steadiness
    too_deep = tiles[1] > max_overlap
    done = steady & ~too_deep & (mean_overlap <= overlap)
    for t in range(n_tiles):
        jammed_checks[t] = jammed_checks[t] + 1 if steady[t] and too_deep[t] else 0
    jammed = jammed_checks >= jammed_limit
    not_all_done, any_done, any_jammed = _any_over_all_tiles(~done, done, jammed, halo)
    if not not_all_done:
        return CONVERGED, awake, polishing, False, measures
    if any_jammed and any_done:  # a jammed tile holds open the tiles pressing on it
        in_jammed_tile[:n_moving] = jammed[tile_of]
        share_flags(in_jammed_tile, first_ghost, halo)
        pressed = _pressed_tiles(phi, pair_a, pair_b, n_moving, tile_of, n_tiles, in_jammed_tile)
        _over_all_tiles(pressed, shared_tiles, halo)
        done &= pressed[0] == 0.0
    any_settled = done.any()
    settled[:n_moving] = done[tile_of]
    share_flags(settled, first_ghost, halo)
    for i in range(n_moving):
        if settled[i]:
            U[i, :] = 0.0
    _stop_ghosts(ghost_U, settled, first_ghost, True)
    if sleep > 0.0:
        polishing = (polishing or largest <= steadiness) and mean_overlap <= overlap
        _restless(P, previous, phi, pair_ptr, pair_of, sleep, overlap**2, settled, restless)
        share_flags(restless, first_ghost, halo)
        awake = _settle(restless, U, is_awake, first_ghost, link_ptr, link_to, pair_ptr, pair_partner, ghost_ptr,
                        ghost_partner)
        if any_settled:
            awake = _drop_settled(awake, settled, is_awake)
        share_flags(is_awake, first_ghost, halo)
        _stop_ghosts(ghost_U, is_awake, first_ghost, False)
    return _GO_ON, awake, polishing, any_settled, measures


@jit
def _overlaps(phi, counted, link_ptr, pair_ptr, pair_of, sphere_overlap, n_links, halo):
    """The mean overlap over the links (3.28) and over the overlapping pairs, over all ranks."""
    total, overlapping = _measure(phi, counted, link_ptr, pair_ptr, pair_of, sphere_overlap)
    total = global_sum(total, halo)
    return total / max(n_links, 1.0), total / max(global_sum(float(overlapping), halo), 1.0)


def minimise(problem, params, attraction_range=math.inf, exchange=None, on_iteration=None, multipliers=None,
             tile_of=None, n_tiles=1, shared_tiles=None):
    """Run DAHA on ``problem`` until (3.27), (3.28) and the deepest-overlap bound hold in
    every tile, or ``max_iterations``.

    ``tile_of`` gives the tile (``0 .. n_tiles - 1``, numbered on each process) of each moving
    sphere, the regions that stop one by one; ``None`` is one tile, the whole problem.  The
    tiles that several processes hold are ``shared_tiles``, in one order on every process: the
    local number of each, -1 where this process holds none of it (``None``: none).

    ``multipliers`` (one per candidate pair, NaN where unknown) replace the initial
    multipliers of (3.26) where given.  ``attraction_range`` is ``Delta_W`` of eq. 3.30 (``inf``: eq. 3.5).  ``exchange``
    is the halo interface (:class:`SerialExchange` by default).  ``on_iteration(r,
    problem)``, if given, is called after every iteration (a test hook).  Moving
    positions are updated in ``problem.positions``.  Stops early, with
    ``finite=False``, at the first full sweep after a position becomes non-finite, and with
    ``left_halo=True`` when a sphere moved farther than ``exchange.margin``.
    """
    run = _Minimisation(problem, params, attraction_range, exchange or SerialExchange(), multipliers,
                        np.zeros(problem.n_moving, dtype=np.int64) if tile_of is None else tile_of, n_tiles,
                        np.zeros(0, dtype=np.int64) if shared_tiles is None else shared_tiles)
    while run.iteration < params.max_iterations:
        why = run.iterate(params.max_iterations if on_iteration is None else run.iteration + 1)
        if why == REFRESH_DUE:
            if run.left_halo():
                return run.outcome(False, left_halo=True)
            run.refresh_pairs()
            continue
        if on_iteration is not None:
            on_iteration(run.iteration, problem)
        if why != REACHED_LAST:
            return run.outcome(why == CONVERGED, finite=why != NOT_FINITE)
    return run.outcome(False)


class MinimiserState(NamedTuple):
    """What the iterations read and change: positions ``P`` (moving rows, then anchors and ghosts) and
    ``R``, velocities ``U``, the trial ``new`` rows, ``previous`` positions (and the ghosts'), where the
    pairs were searched (``built_at``), multipliers ``lam`` and constraint values ``phi`` per pair, each
    sphere's overlap, which links attract, each row's damping, and the awake, settled and anchor flags."""

    P: np.ndarray
    R: np.ndarray
    U: np.ndarray
    new: np.ndarray
    previous: np.ndarray
    previous_ghost: np.ndarray
    built_at: np.ndarray
    lam: np.ndarray
    phi: np.ndarray
    sphere_overlap: np.ndarray
    attracts: np.ndarray
    damping_of: np.ndarray
    is_awake: np.ndarray
    settled: np.ndarray
    is_anchor: np.ndarray


class Adjacency(NamedTuple):
    """Each moving sphere's links (``link_ptr``, ``link_to``) and pairs (``pair_ptr``, ``pair_of``,
    ``pair_partner``), and each ghost's pairs (``ghost_ptr``, ``ghost_partner``), in CSR form."""

    link_ptr: np.ndarray
    link_to: np.ndarray
    pair_ptr: np.ndarray
    pair_of: np.ndarray
    pair_partner: np.ndarray
    ghost_ptr: np.ndarray
    ghost_partner: np.ndarray


class PairLists(NamedTuple):
    """The pairs' two rows, and the pairs across the rank's border."""

    pair_a: np.ndarray
    pair_b: np.ndarray
    cross_pairs: np.ndarray


class Coefficients(NamedTuple):
    """The scheme's coefficients: delta, alpha, gamma, c_bar of (3.20)-(3.24), the damping where
    (3.26) is stable, the sleep tolerance, the stiffness and damping limits, beta, the overlap floor
    of the dynamic rate (3.29) and the number of moving spheres over all ranks."""

    step: float
    attraction: float
    penalty: float
    damping: float
    stable: float
    sleep: float
    stiffness_limit: float
    max_damping: float
    multiplier_rate: float
    floor: float
    n_spheres: float


class Checks(NamedTuple):
    """What the stopping tests read: each row's tile, the tiles shared with neighbours, each tile's
    jammed count and flag, the restless rows, which pairs are counted, the tolerances
    (eps_s, eps_max, eps_c), the number of links and the jammed limit."""

    tile_of: np.ndarray
    shared_tiles: np.ndarray
    jammed_checks: np.ndarray
    in_jammed_tile: np.ndarray
    restless: np.ndarray
    pair_counted: np.ndarray
    tolerances: tuple
    n_links: float
    jammed_limit: int


class GhostMotion(NamedTuple):
    """The ghosts' velocities as on their owners, the rows sent and received, the flags of the changed
    rows, which owned rows some neighbour holds as ghosts, and the ghost rows that arrived."""

    ghost_U: np.ndarray
    motion: np.ndarray
    changed: np.ndarray
    sends: np.ndarray
    arrived: np.ndarray


class _Minimisation:
    """The state of one :func:`minimise` between calls of :func:`_iterations`, and the pair searches
    it returns for."""

    def __init__(self, problem, params, attraction_range, exchange, multipliers, tile_of, n_tiles, shared_tiles):
        self.problem, self.params, self.exchange = problem, params, exchange
        self.tile_of, self.shared_tiles = tile_of, shared_tiles
        P, R = problem.positions, problem.radii
        n_moving, d = problem.n_moving, P.shape[1]
        self.start = P[:n_moving].copy()
        self.built_at = P.copy()  # where the pairs of each row were last searched (anchors: never again)
        self.U = np.zeros((n_moving, d))
        self.lam = _initial_multipliers(P, R, problem.pair_a, problem.pair_b, params.initial_multiplier)
        if multipliers is not None:
            known = np.isfinite(multipliers)
            self.lam[known] = multipliers[known]
        self.sphere_overlap = np.zeros(n_moving if params.dynamic else 0)  # phi_i^A of (3.29), dynamic damping
        self.previous = self.start.copy()
        self.previous_ghost = P[problem.first_ghost:].copy()
        self.phi = np.empty(problem.pair_a.size)
        _constraint_values(P, R, problem.pair_a, problem.pair_b, self.phi)
        self.n_links = exchange.sum(float(problem.n_links))
        self.n_spheres = exchange.sum(float(n_moving))
        self.halo = exchange.kernel_halo
        n_rows, n_ghost = P.shape[0], P.shape[0] - problem.first_ghost
        sends = np.zeros(n_rows, dtype=np.bool_)
        sends[self.halo.rows] = True  # the owned rows some neighbour holds as ghosts
        # ghost velocities as on their owners, rows sent and received, flags of the changed rows, ghost rows arrived
        self.ghost_motion = GhostMotion(np.zeros((n_ghost, d)), np.zeros((n_rows, motion_width(d))),
                                        np.zeros(n_rows, dtype=np.bool_), sends, np.empty(n_ghost, dtype=np.int64))
        mean_overlap, typical_overlap = _overlaps(self.phi, problem.pair_counted, problem.link_ptr, problem.pair_ptr,
                                                  problem.pair_of, self.sphere_overlap, self.n_links, self.halo)
        self.measures = (mean_overlap, typical_overlap, math.inf, math.inf)  # and the largest step, deepest overlap
        range_sq = attraction_range**2 if math.isfinite(attraction_range) else math.inf
        self.attracts = _attracting_links(P, problem.link_ptr, problem.link_to, range_sq)
        self.new = np.empty((n_moving, d))
        self.damping_of = np.where(problem.moving_ghost, params.damping, math.inf)  # anchors never limit a rate
        self.damping_of[:n_moving] = params.damping
        self.is_anchor = self.damping_of == math.inf
        self.stable = params.step * STABILITY_MARGIN * params.penalty / (2.0 * params.attraction)
        self.everyone = np.arange(n_moving)
        self.awake = self.everyone
        self.is_awake = np.zeros(P.shape[0], dtype=np.bool_)  # moving rows, then ghost rows as on their owner
        self.restless = np.zeros(P.shape[0], dtype=np.bool_)
        self.moved = np.zeros(P.shape[0], dtype=np.bool_)  # whose candidate pairs are searched again
        self.settled = np.zeros(P.shape[0], dtype=np.bool_)  # moving rows in settled tiles, ghosts as on owner
        self.jammed_checks = np.zeros(n_tiles, dtype=np.int64)
        self.in_jammed_tile = np.zeros(P.shape[0], dtype=np.bool_)  # moving rows, then ghosts as on their owner
        self.flags = (False, False)  # polishing, any tile settled
        self.iteration = 0
        # Only the spheres stepped in an iteration move, so the bookkeeping between iterations
        # goes over those alone: ``previous`` equals ``P`` on every other moving row, and
        # ``drift`` bounds from above how far any moving sphere is from ``built_at``.
        self.stepped = self.everyone[:0]
        self.drift = 0.0

    def outcome(self, converged, finite=True, left_halo=False):
        mean_overlap, _, largest, deepest = self.measures
        return Outcome(converged, self.iteration, mean_overlap, deepest, largest, finite, self.lam,
                       left_halo=left_halo)

    def iterate(self, last):
        """Iterations up to ``last`` at most (:func:`_iterations`); returns why it stopped."""
        problem, params = self.problem, self.params
        state = MinimiserState(problem.positions, problem.radii, self.U, self.new, self.previous,
                               self.previous_ghost, self.built_at, self.lam, self.phi, self.sphere_overlap,
                               self.attracts, self.damping_of, self.is_awake, self.settled, self.is_anchor)
        adjacency = Adjacency(problem.link_ptr, problem.link_to, problem.pair_ptr, problem.pair_of,
                              problem.pair_partner, problem.ghost_ptr, problem.ghost_partner)
        coefficients = Coefficients(params.step, params.attraction, params.penalty, params.damping, self.stable,
                                    params.sleep_tolerance, STIFFNESS_LIMIT, MAX_DAMPING, params.multiplier_rate,
                                    OVERLAP_FLOOR * params.overlap_tolerance, self.n_spheres)
        tolerances = (params.steadiness_tolerance, params.max_overlap_tolerance, params.overlap_tolerance)
        checks = Checks(self.tile_of, self.shared_tiles, self.jammed_checks, self.in_jammed_tile, self.restless,
                        problem.pair_counted, tolerances, self.n_links, JAMMED_CHECKS)
        self.iteration, self.awake, self.stepped, self.drift, why, self.flags, self.measures = _iterations(
            self.iteration, last, state, self.awake, self.stepped, self.drift, REFRESH_DRIFT * problem.reach,
            self.flags, self.measures, adjacency, PairLists(problem.pair_a, problem.pair_b, problem.cross_pairs),
            coefficients, checks, params.dynamic, self.ghost_motion, self.halo)
        return why

    def left_halo(self):
        """Whether a sphere may now reach beyond the ghosts chosen for this minimisation."""
        problem, exchange = self.problem, self.exchange
        reach = REFRESH_DRIFT * problem.reach
        return exchange.max(_largest_step(problem.positions, self.start, self.everyone)) + reach > exchange.margin

    def refresh_pairs(self):
        """Search again the pairs of the spheres that drifted (module docstring, "Candidate pairs")."""
        problem = self.problem
        P, R = problem.positions, problem.radii
        self.drift = _rebase(P, self.built_at, problem.n_moving, problem.first_ghost,
                             REFRESH_SET * REFRESH_DRIFT * problem.reach, self.moved)
        self.lam, self.phi = _carried(problem.refresh_pairs(self.moved), self.lam, self.phi, P, R, problem.pair_a,
                                      problem.pair_b)
