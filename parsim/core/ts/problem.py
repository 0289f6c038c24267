"""Assemble one DAHA minimisation (:class:`Problem`) from the spheres of one process.

On one process the problem holds the moving spheres and the anchors.  In a decomposed run
(:mod:`parsim.aggregation.tiled`) it also holds *ghost* rows: spheres owned by other ranks, read
like anchors, refreshed from their owners by the minimiser's exchange.  A ghost that moves on
its owner is a *moving ghost*; its pairs and links with this rank's moving spheres are
*cross* pairs and links, held by both ranks (each computes the same multiplier from the same
positions) and counted in the sums of (3.28) by the rank owning the lower global id.
"""

from dataclasses import dataclass

import numpy as np

from parsim.core.jit import jit
from parsim.core.ts.contacts import (BinnedRows, candidate_pairs, check_discs_or_spheres, incidence,
                                    updated_candidate_pairs)
from parsim.core.ts.links import link_index


@dataclass
class Ghosts:
    """Rows of spheres owned elsewhere: positions ``(g, d)``, radii, global ids, and whether
    each one moves on its owner."""

    positions: np.ndarray
    radii: np.ndarray
    global_id: np.ndarray
    moving: np.ndarray


@dataclass
class Problem:
    """One minimisation: local sphere ``k`` is global sphere ``members[k]``.

    The first ``n_moving`` members move; the rest are anchors, the ghost rows from
    ``first_ghost`` on (none on one process).  Links and candidate pairs are stored per
    moving sphere in CSR form (``*_ptr`` of length ``n_moving + 1``); ``pair_a < pair_b``
    are local indices, ``pair_of`` lists the pairs incident to each moving sphere and
    ``pair_partner`` their other ends, ``link_to`` its linked partners.  Candidate pairs are
    those with a gap of at most ``reach`` when their spheres' pairs were last searched (the
    minimiser refreshes them sphere by sphere, so that none that touches is missing);
    :meth:`refresh_pairs` recomputes them and the cross-pair bookkeeping: ``pair_counted``
    (the pairs this process counts in sums), ``cross_pairs``, and per moving ghost its local
    moving partners (``ghost_ptr``, ``ghost_partner``).
    """

    members: np.ndarray
    n_moving: int
    positions: np.ndarray  #: (n_members, d), updated in place for the moving spheres
    radii: np.ndarray
    link_ptr: np.ndarray
    link_to: np.ndarray
    n_links: int  #: distinct links with a moving end, the #S of (3.28), counted once over processes
    reach: float
    first_ghost: int
    moving_ghost: np.ndarray  #: per member, True for a ghost row that moves on its owner
    pair_a: np.ndarray = None
    pair_b: np.ndarray = None
    pair_ptr: np.ndarray = None
    pair_of: np.ndarray = None
    pair_partner: np.ndarray = None  #: the other end of the pair pair_of[e]
    pair_counted: np.ndarray = None
    cross_pairs: np.ndarray = None
    ghost_ptr: np.ndarray = None
    ghost_partner: np.ndarray = None
    cross_link_from: np.ndarray = None  #: the moving end of each link to a moving ghost ...
    cross_link_ghost: np.ndarray = None  #: ... and its ghost row
    binned: BinnedRows = None  #: the members where their pairs were last searched

    def refresh_pairs(self, moved=None):
        """Recompute the candidate pairs at the current positions, all of them or (``moved``, a
        flag per member) only those of the moved members (:func:`updated_candidate_pairs`).
        Returns the index of each pair among the pairs before (-1 for a new one), or ``None``
        after a search of all of them."""
        source = None
        if moved is None:
            self.pair_a, self.pair_b = candidate_pairs(self.positions, self.radii, self.n_moving, self.reach)
            self.binned = BinnedRows(self.positions, self.radii, self.reach)
        else:
            self.pair_a, self.pair_b, source = updated_candidate_pairs(self.positions, self.radii, self.n_moving,
                                                                       self.reach, self.pair_a, self.pair_b, moved,
                                                                       self.binned)
        self.pair_ptr, self.pair_of, self.pair_partner = incidence(self.pair_a, self.pair_b, self.n_moving)
        if self.moving_ghost[self.first_ghost:].any():
            self.cross_pairs, self.pair_counted = _cross_pairs(self.pair_a, self.pair_b, self.members,
                                                               self.moving_ghost)
        else:
            self.cross_pairs = np.empty(0, dtype=np.int64)
            self.pair_counted = np.ones(self.pair_a.size, dtype=np.bool_)
        if self.cross_link_from is None:  # links do not change during a minimisation
            from_row = np.repeat(np.arange(self.n_moving), np.diff(self.link_ptr))
            crossing_link = self.moving_ghost[self.link_to]
            self.cross_link_from, self.cross_link_ghost = from_row[crossing_link], self.link_to[crossing_link]
        self.ghost_ptr, self.ghost_partner = _ghost_partners(self.pair_a, self.pair_b, self.cross_pairs,
                                                             self.cross_link_from, self.cross_link_ghost,
                                                             self.moving_ghost.shape[0] - self.first_ghost,
                                                             self.first_ghost)
        return source

    def pair_links(self, links):
        """Index in ``links`` of each candidate pair, -1 for a pair that is not linked."""
        return _pair_links(self.members, self.pair_a, self.pair_b, links.head, links.next, links.to)


@jit
def _pair_links(members, pair_a, pair_b, head, nxt, to):
    index = np.empty(pair_a.shape[0], dtype=np.int64)
    for p in range(pair_a.shape[0]):
        index[p] = link_index(head, nxt, to, members[pair_a[p]], members[pair_b[p]])
    return index


@jit
def _cross_pairs(pair_a, pair_b, members, moving_ghost):
    """The pairs with a moving ghost end (``pair_a < n_moving <= pair_b`` for these), and whether
    each pair is counted here: all but the cross pairs whose ghost has the lower global id.  Two
    loops over the pairs, in about a third of the time of five numpy passes over them."""
    counted = np.empty(pair_a.shape[0], dtype=np.bool_)
    n_cross = 0
    for p in range(pair_a.shape[0]):
        crossing = moving_ghost[pair_b[p]]
        counted[p] = not (crossing and members[pair_b[p]] < members[pair_a[p]])
        n_cross += crossing
    cross = np.empty(n_cross, dtype=np.int64)
    n_cross = 0
    for p in range(pair_a.shape[0] if cross.shape[0] else 0):
        if moving_ghost[pair_b[p]]:
            cross[n_cross] = p
            n_cross += 1
    return cross, counted


@jit
def _ghost_partners(pair_a, pair_b, cross_pairs, link_from, link_ghost, n_ghost, first_ghost):
    """CSR over the ghost rows of the local moving partners (cross pairs, then the cross links
    ``link_from[e]`` -- ``link_ghost[e]``) of each moving ghost: who must wake when that ghost
    moves."""
    ptr = np.zeros(n_ghost + 1, dtype=np.int64)
    for p in cross_pairs:
        ptr[pair_b[p] - first_ghost + 1] += 1
    for e in range(link_ghost.shape[0]):
        ptr[link_ghost[e] - first_ghost + 1] += 1
    for g in range(n_ghost):
        ptr[g + 1] += ptr[g]
    fill = ptr[:-1].copy()
    partner = np.empty(ptr[n_ghost], dtype=np.int64)
    for p in cross_pairs:
        g = pair_b[p] - first_ghost
        partner[fill[g]] = pair_a[p]
        fill[g] += 1
    for e in range(link_ghost.shape[0]):
        g = link_ghost[e] - first_ghost
        partner[fill[g]] = link_from[e]
        fill[g] += 1
    return ptr, partner


@jit
def _local_links(members, n_moving, local_of, head, nxt, to, moving_ghost):
    """CSR of the linked partners (local indices) of each moving sphere, and #S (a link to a
    moving ghost is counted by the process holding its lower global id)."""
    ptr = np.zeros(n_moving + 1, dtype=np.int64)
    for i in range(n_moving):
        slot = head[members[i]]
        while slot >= 0:
            if local_of[to[slot]] >= 0:
                ptr[i + 1] += 1
            slot = nxt[slot]
    for i in range(n_moving):
        ptr[i + 1] += ptr[i]
    partners = np.empty(ptr[n_moving], dtype=np.int64)
    distinct = 0
    for i in range(n_moving):
        e = ptr[i]
        slot = head[members[i]]
        while slot >= 0:
            j = local_of[to[slot]]
            if j >= 0:
                partners[e] = j
                e += 1
                # a moving-moving link is listed at both ends, a moving-anchor link once
                if j > i and not (moving_ghost[j] and members[j] < members[i]):
                    distinct += 1
            slot = nxt[slot]
    return ptr, partners, distinct


def build_problem(X, R, moving, anchors, links, reach, local_of, global_id=None, ghosts=None):
    """The minimisation of the rows ``moving`` of ``X`` with the rows ``anchors`` (and the
    ``ghosts``, if any) fixed.

    ``global_id`` names the rows of ``X`` and ``R`` (default: row ``i`` is sphere ``i``);
    ``links`` are between global ids.  ``reach`` is the largest gap of a constraint
    candidate pair; ``local_of`` is scratch over the global ids filled with -1, returned so.
    """
    check_discs_or_spheres(X)
    own = np.concatenate([moving, anchors])
    rows = [X[own]]
    radii = [R[own]]
    members = [own if global_id is None else global_id[own]]
    if ghosts is not None:
        rows.append(ghosts.positions)
        radii.append(ghosts.radii)
        members.append(ghosts.global_id)
    members = np.concatenate(members)
    moving_ghost = np.zeros(members.size, dtype=np.bool_)
    if ghosts is not None:
        moving_ghost[own.size:] = ghosts.moving
    local_of[members] = np.arange(members.size)
    try:
        link_ptr, link_to, n_links = _local_links(members, moving.size, local_of, links.head, links.next, links.to,
                                                  moving_ghost)
    finally:
        local_of[members] = -1
    problem = Problem(members=members, n_moving=int(moving.size), positions=np.concatenate(rows),
                      radii=np.concatenate(radii), link_ptr=link_ptr, link_to=link_to, n_links=int(n_links),
                      reach=float(reach), first_ghost=int(own.size), moving_ghost=moving_ghost)
    problem.refresh_pairs()
    return problem
