"""The potential events of one move that can still be the earliest (4.3).

Every potential event of a move (the drop of a fall, or the angle of a rotation) is
offered to :func:`push_event`, which keeps those within ``tol`` of the smallest so far: at
the end the window (an :class:`.bundles.EventWindow` of ``MAX_TIES`` rows) holds the
earliest event and every event simultaneous with it.
"""

from parsim.core.jit import jit
from parsim.core.sdbd.bundles import window_arrays

__all__ = ["NO_CONTACT", "push_event", "earliest_event"]


#: The contact of an event that makes none (a trial angle, a chunk's end, hanging, ...).
NO_CONTACT = (-1, -1, -1, 0.0, 0.0)


@jit(inline="always")
def push_event(n_t, best, tol, crossing, ev, contact, window):
    """Add a potential event if it can still be among the earliest; returns ``(n_t, best)``
    (``best`` the smallest ``phi`` so far).  The event has drop or angle ``phi`` with
    cosine and sine ``c, s`` (``crossing = (phi, c, s)``), kind ``ev`` and makes the contact
    ``contact = (i, ob, j, sh0, sh1)``: moving sphere ``i`` with obstacle ``ob``, sediment sphere
    ``j`` seen through the periodic shift ``(sh0, sh1)`` (:data:`NO_CONTACT` for an event that
    makes none).

    Inlined at each of its dozen call sites, it holds only the test most candidates fail and
    the append; the compaction of the window after a new earliest event is a call
    (:func:`_keep_within`): inlined as well, it makes the first deposition's compilation about
    4 s longer, for no measurable speed."""
    phi, c, s = crossing
    if phi > best + tol:
        return n_t, best
    if phi < best:
        best = phi
        n_t = _keep_within(n_t, best + tol, window)
    angle, cos, sin, kind, sphere, obstacle, sediment, shift = window_arrays(window)
    if n_t >= angle.shape[0]:
        return n_t, best
    i, ob, j, sh0, sh1 = contact
    angle[n_t] = phi
    cos[n_t] = c
    sin[n_t] = s
    kind[n_t] = ev
    sphere[n_t] = i
    obstacle[n_t] = ob
    sediment[n_t] = j
    shift[n_t, 0] = sh0
    shift[n_t, 1] = sh1
    return n_t + 1, best


@jit
def _keep_within(n_t, latest, window):
    """Drop the first ``n_t`` entries of the window later than ``latest``, keeping the others in order;
    returns how many are left."""
    angle, cos, sin, kind, sphere, obstacle, sediment, shift = window_arrays(window)
    w = 0
    for r in range(n_t):
        if angle[r] <= latest:
            if w != r:
                angle[w] = angle[r]
                cos[w] = cos[r]
                sin[w] = sin[r]
                kind[w] = kind[r]
                sphere[w] = sphere[r]
                obstacle[w] = obstacle[r]
                sediment[w] = sediment[r]
                shift[w, 0] = shift[r, 0]
                shift[w, 1] = shift[r, 1]
            w += 1
    return w


@jit(inline="always")
def earliest_event(n_t, window):
    """Row of the smallest angle among the first ``n_t`` rows (the first of equals)."""
    angle = window.angle
    r_best = 0
    for r in range(n_t):
        if angle[r] < angle[r_best]:
            r_best = r
    return r_best
