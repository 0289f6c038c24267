"""The damped Arrow–Hurwicz algorithm (DAHA) of Degond et al. 2024, section 3.2.

Modules: :mod:`~parsim.core.ts.daha.scheme` (the scheme, eqs. 3.20–3.28),
:mod:`~parsim.core.ts.daha.sleeping` (sleeping spheres), :mod:`~parsim.core.ts.daha.stopping`
(the stopping tests tile by tile, jammed tiles, polishing), :mod:`~parsim.core.ts.daha.ghosts`
(the ghost rows' messages and drift), :mod:`~parsim.core.ts.daha.pairs` (candidate pairs searched
again) and :mod:`~parsim.core.ts.daha.driver` (parameters, the jitted iterations, :func:`minimise`).

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

from parsim.core.ts.daha.driver import DahaParameters, Outcome, SerialExchange, minimise
from parsim.core.ts.daha.ghosts import motion_width
from parsim.core.ts.daha.scheme import attraction_energy

__all__ = ["DahaParameters", "Outcome", "SerialExchange", "minimise", "motion_width", "attraction_energy"]
