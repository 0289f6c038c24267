"""Freezing by infinite cycling (4.2): tests on the recent descents of the centre of mass.

A :class:`DescentHistory` keeps two ring buffers of the moving particle: the last
``HISTORY`` positive decrements of the height of its centre of mass (for criterion 34) and
the descents of its last ``CREEP_STEPS`` steps (for the period-free backstop).  When either
test holds after a move (:func:`after_move`), every obstacle within ``CYCLE_CLOSE_GAP`` of
the particle is declared a closed contact (:func:`close_near_obstacles`) and the steepest
descent goes on with them.
"""

import numpy as np

from parsim.core.jit import jit
from parsim.core.sdbd.borrowed import borrowed, carve
from parsim.core.sdbd.bundles import bundle
from parsim.core.sdbd.constants import CREEP_DESCENT, FLOOR_STOP, K_CYCLING
from parsim.core.sdbd.contacts import near_contacts

__all__ = [
    "HISTORY",
    "CREEP_STEPS",
    "DescentHistory",
    "new_descent_history",
    "forget_descents",
    "period_detected",
    "creeping",
    "close_near_obstacles",
    "after_move",
]

#: Positive decrements kept for criterion (34) (enough for cycle_n <= 28 and period 4).
HISTORY = 32
#: Steps over which a particle that descends less than CREEP_DESCENT is creeping.
CREEP_STEPS = 24

#: ``decrements`` (HISTORY,) the positive decrements of the height of the centre of mass,
#: ``recent`` (CREEP_STEPS,) the descents of the last steps (0 for a rise), both ring
#: buffers; ``counts`` (2,) how many of each were recorded since the last reset; ``memory``
#: what they borrow from (:mod:`.borrowed`).
DescentHistory = bundle("DescentHistory", ["decrements", "recent", "counts", "memory"], module=__name__)
_DECREMENTS = 0
_RECENT = 1


@jit
def new_descent_history():
    """An empty history."""
    floats = np.zeros(HISTORY + CREEP_STEPS)
    counts = np.zeros(2, dtype=np.int64)
    decrements, f = carve(floats, 0, HISTORY)
    recent, f = carve(floats, f, CREEP_STEPS)
    return DescentHistory(decrements, recent, borrowed(counts), (floats, counts))


@jit(inline="always")
def forget_descents(history):
    """Start the history of a new particle."""
    history.counts[_DECREMENTS] = 0
    history.counts[_RECENT] = 0


@jit
def period_detected(dz_hist, n_hist, cycle_n, cycle_eps):
    """Criterion (34) on the ring buffer ``dz_hist`` of the last of ``n_hist`` decrements.

    For the paper's period 3, and for periods 2 and 4: the decrements decay
    (``dz(k) < dz(k - per)``) and ``|Q - 1| < cycle_eps`` for the last ``cycle_n`` steps,
    ``Q = dz(k) dz(k - per - 1) / (dz(k - 1) dz(k - per))``.  ``cycle_n = 0``: never.
    """
    hist = dz_hist.shape[0]
    for per in (3, 2, 4):
        need = cycle_n + per + 1
        if cycle_n <= 0 or n_hist < need or need > hist:
            continue
        last = n_hist - 1
        if dz_hist[last % hist] >= dz_hist[(last - per) % hist]:
            continue  # not decaying
        ok = True
        for jj in range(cycle_n):
            kk = last - jj
            num = dz_hist[kk % hist] * dz_hist[(kk - per - 1) % hist]
            den = dz_hist[(kk - 1) % hist] * dz_hist[(kk - per) % hist]
            if not (den > 0.0) or abs(num / den - 1.0) >= cycle_eps:
                ok = False
                break
        if ok:
            return True
    return False


@jit
def creeping(dz_recent, ell):
    """4.2 without a period: the centre of mass went down by less than
    ``CREEP_DESCENT * ell`` over the steps in ``dz_recent``."""
    tot = 0.0
    for r in range(dz_recent.shape[0]):
        tot += dz_recent[r]
    return tot < CREEP_DESCENT * ell


@jit(inline="always")
def close_near_obstacles(n, particle, n_c, contacts, sediment, grid, settings, buf, nrm, event_counts):
    """4.2: declare closed every obstacle within ``CYCLE_CLOSE_GAP`` (:func:`near_contacts`),
    counted as a cycling interruption when that adds a contact.  Returns
    ``(n_c, closed, stop, buf)``: ``stop`` when a floor contact immobilises the particle
    (FLOOR_STOP)."""
    n_c, added, floor_added, buf = near_contacts(n, particle, n_c, contacts, sediment, grid,
                                                 settings.walls, settings.ell, buf, nrm)
    if added > 0:
        event_counts[K_CYCLING] += 1
    return n_c, added > 0, floor_added and settings.floor_mode == FLOOR_STOP, buf


@jit(inline="always")
def after_move(descent, history, n, particle, n_c, contacts, sediment, grid, settings, buf, nrm,
               event_counts):
    """The cycling tests after a move that lowered the centre of mass by ``descent``.

    Criterion (34) on the decrements; then the backstop: the centre of mass went down by
    less than ``CREEP_DESCENT`` in the last ``CREEP_STEPS`` steps, so the particle zigzags
    among obstacles at clearances of the order of the tolerances.  Either one closes the
    obstacles near the particle.  Returns ``(n_c, stop, buf)``, ``stop`` when that made a
    floor contact that immobilises the particle.
    """
    decrements = history.decrements
    recent = history.recent
    counts = history.counts
    if descent > 0.0:
        decrements[counts[_DECREMENTS] % HISTORY] = descent
        counts[_DECREMENTS] += 1
        if period_detected(decrements, counts[_DECREMENTS], settings.cycle_n, settings.cycle_eps):
            n_c, closed, stop, buf = close_near_obstacles(n, particle, n_c, contacts, sediment, grid,
                                                          settings, buf, nrm, event_counts)
            if closed:
                forget_descents(history)
            if stop:
                return n_c, True, buf
    recent[counts[_RECENT] % CREEP_STEPS] = max(descent, 0.0)
    counts[_RECENT] += 1
    if counts[_RECENT] >= CREEP_STEPS and creeping(recent, settings.ell):
        n_c, closed, stop, buf = close_near_obstacles(n, particle, n_c, contacts, sediment, grid,
                                                      settings, buf, nrm, event_counts)
        counts[_RECENT] = 0
        if closed:
            counts[_DECREMENTS] = 0
        if stop:
            return n_c, True, buf
    return n_c, False, buf
