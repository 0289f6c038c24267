"""The set of links (adhesive contacts) of a time-stepping aggregation, ``S`` in section 3.

Links are stored in the order they were made (``first``, ``second``, the time step
that made them and the DAHA multiplier they ended their last minimisation with, NaN
before the first) and as a per-sphere adjacency list (linked lists in flat arrays), so
that "are i and j linked" costs the degree of ``i``.  Capacities double as needed.
"""

import numpy as np

from parsim.core.jit import jit


@jit
def _append(first, second, made_in, head, nxt, to, count, i_new, j_new, step):
    """Append links ``(i_new[k], j_new[k])`` not present yet; returns the new count."""
    for k in range(i_new.shape[0]):
        i, j = i_new[k], j_new[k]
        if i > j:
            i, j = j, i
        if are_linked(head, nxt, to, i, j):
            continue
        first[count] = i
        second[count] = j
        made_in[count] = step
        _push(head, nxt, to, i, j, 2 * count)
        _push(head, nxt, to, j, i, 2 * count + 1)
        count += 1
    return count


@jit
def _push(head, nxt, to, end, other, slot):
    to[slot] = other
    nxt[slot] = head[end]
    head[end] = slot


@jit
def are_linked(head, nxt, to, i, j):
    return link_index(head, nxt, to, i, j) >= 0


@jit
def link_index(head, nxt, to, i, j):
    """Index (in order made) of the link ``i``-``j``, or -1 if they are not linked."""
    slot = head[i]
    while slot >= 0:
        if to[slot] == j:
            return slot // 2
        slot = nxt[slot]
    return -1


class LinkSet:
    """Links between ``n`` spheres; ``pairs()`` returns them as an ``(m, 2)`` array."""

    def __init__(self, n, capacity=None):
        capacity = max(16, capacity if capacity is not None else n)
        self.count = 0
        self.first = np.empty(capacity, dtype=np.int64)
        self.second = np.empty(capacity, dtype=np.int64)
        self.made_in = np.empty(capacity, dtype=np.int64)
        self.multiplier = np.empty(capacity)
        self.head = np.full(n, -1, dtype=np.int64)
        self.next = np.empty(2 * capacity, dtype=np.int64)
        self.to = np.empty(2 * capacity, dtype=np.int64)

    def add(self, i, j, step):
        """Add the links ``(i[k], j[k])`` made in time step ``step``; returns how many were new."""
        i = np.ascontiguousarray(i, dtype=np.int64)
        j = np.ascontiguousarray(j, dtype=np.int64)
        need = self.count + i.shape[0]
        if need > self.first.shape[0]:
            self._grow(max(need, 2 * self.first.shape[0]))
        before = self.count
        self.count = int(_append(self.first, self.second, self.made_in, self.head, self.next, self.to,
                                 self.count, i, j, step))
        self.multiplier[before:self.count] = np.nan
        return self.count - before

    def _grow(self, capacity):
        for name in ("first", "second", "made_in", "multiplier"):
            old = getattr(self, name)
            new = np.empty(capacity, dtype=old.dtype)
            new[: self.count] = old[: self.count]
            setattr(self, name, new)
        for name in ("next", "to"):
            old = getattr(self, name)
            new = np.empty(2 * capacity, dtype=np.int64)
            new[: 2 * self.count] = old[: 2 * self.count]
            setattr(self, name, new)

    def linked(self, i, j):
        return bool(are_linked(self.head, self.next, self.to, i, j))

    def pairs(self):
        return np.stack([self.first[: self.count], self.second[: self.count]], axis=1)

    def steps(self):
        """The time step that made each link (same order as :meth:`pairs`)."""
        return self.made_in[: self.count].copy()
