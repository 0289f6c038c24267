"""Assemble one DAHA minimisation (:class:`parsim.core.ts.daha.Problem`) from the global state."""

from dataclasses import dataclass

import numpy as np

from parsim.core.jit import jit
from parsim.core.ts.contacts import candidate_pairs, incidence
from parsim.core.ts.links import link_index


@dataclass
class Problem:
    """One minimisation: local sphere ``k`` is global sphere ``members[k]``.

    The first ``n_moving`` members move; the rest are anchors.  Links and candidate
    pairs are stored per moving sphere in CSR form (``*_ptr`` of length
    ``n_moving + 1``); ``pair_a < pair_b`` are local indices, ``pair_of`` lists the
    pairs incident to each moving sphere, ``link_to`` its linked partners.  Candidate
    pairs are those with a gap of at most ``reach``; :meth:`refresh_pairs` recomputes them.
    """

    members: np.ndarray
    n_moving: int
    positions: np.ndarray  #: (n_members, d), updated in place for the moving spheres
    radii: np.ndarray
    link_ptr: np.ndarray
    link_to: np.ndarray
    n_links: int  #: distinct links with a moving end, the #S of (3.28)
    reach: float
    pair_a: np.ndarray = None
    pair_b: np.ndarray = None
    pair_ptr: np.ndarray = None
    pair_of: np.ndarray = None

    def refresh_pairs(self, multipliers=None):
        """Recompute the candidate pairs at the current positions; returns their multipliers
        (those of pairs that stay candidates are kept, new pairs start at 0)."""
        old_keys = None if self.pair_a is None else self.pair_a * self.positions.shape[0] + self.pair_b
        self.pair_a, self.pair_b = candidate_pairs(self.positions, self.radii, self.n_moving, self.reach)
        self.pair_ptr, self.pair_of = incidence(self.pair_a, self.pair_b, self.n_moving)
        kept = np.zeros(self.pair_a.size)
        if multipliers is not None and old_keys.size:
            keys = self.pair_a * self.positions.shape[0] + self.pair_b
            where = np.minimum(np.searchsorted(old_keys, keys), old_keys.size - 1)
            found = old_keys[where] == keys
            kept[found] = multipliers[where[found]]
        return kept

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
def _local_links(members, n_moving, local_of, head, nxt, to):
    """CSR of the linked partners (local indices) of each moving sphere, and #S."""
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
                if j > i:  # a moving-moving link is listed twice, a moving-anchor link once
                    distinct += 1
            slot = nxt[slot]
    return ptr, partners, distinct


def build_problem(X, R, moving, anchors, links, reach, local_of):
    """The minimisation of the ``moving`` spheres with ``anchors`` fixed.

    ``reach`` is the largest gap of a constraint candidate pair; ``local_of``
    is scratch of length ``n`` filled with -1, returned filled with -1.
    """
    members = np.concatenate([moving, anchors])
    local_of[members] = np.arange(members.size)
    try:
        link_ptr, link_to, n_links = _local_links(members, moving.size, local_of, links.head, links.next, links.to)
    finally:
        local_of[members] = -1
    problem = Problem(members=members, n_moving=int(moving.size), positions=X[members].copy(),
                      radii=R[members].copy(), link_ptr=link_ptr, link_to=link_to, n_links=int(n_links),
                      reach=float(reach))
    problem.refresh_pairs()
    return problem
