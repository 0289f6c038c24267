"""Freezing by infinite cycling (4.2): tests on the recent descents of the centre of mass.

The engine keeps two ring buffers: the last ``HISTORY`` positive decrements of the height
of the centre of mass (for criterion 34) and the descents of the last ``CREEP_STEPS``
steps (for the period-free backstop).  When either test holds, every obstacle within
``CYCLE_CLOSE_GAP`` of the particle is declared a closed contact.
"""

from parsim.core.jit import jit
from parsim.core.sdbd.constants import CYCLE_CLOSE_GAP

__all__ = ["HISTORY", "CREEP_STEPS", "period_detected", "creeping"]

#: Positive decrements kept for criterion (34) (enough for cycle_n <= 28 and period 4).
HISTORY = 32
#: Steps over which a particle that descends less than CYCLE_CLOSE_GAP is creeping.
CREEP_STEPS = 24


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
    ``CYCLE_CLOSE_GAP * ell`` over the steps in ``dz_recent``."""
    tot = 0.0
    for r in range(dz_recent.shape[0]):
        tot += dz_recent[r]
    return tot < CYCLE_CLOSE_GAP * ell
