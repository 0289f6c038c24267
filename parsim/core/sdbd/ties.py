"""The potential events of one move that can still be the earliest (4.3).

Every potential event of a move (the drop of a fall, or the angle of a rotation) is
offered to :func:`push_event`, which keeps those within ``tol`` of the smallest so far: at
the end the window holds the earliest event and every event simultaneous with it.

The window is a set of arrays of ``MAX_TIES`` rows, row ``r`` one event: ``t_phi`` (drop or
angle), ``t_c, t_s`` (cos and sin of the angle), ``t_ev`` (``EV_*``) and the contact it
makes, ``t_i, t_ob, t_j`` and the image shift ``t_sh`` (2,) (see :mod:`.contacts`).
"""

from parsim.core.jit import jit

__all__ = ["push_event"]


@jit
def push_event(n_t, best, tol, phi, c, s, ev, i, ob, j, sh0, sh1,
               t_phi, t_c, t_s, t_ev, t_i, t_ob, t_j, t_sh):
    """Add a potential event if it can still be among the earliest; returns ``(n_t, best)``
    (``best`` the smallest ``phi`` so far)."""
    if phi > best + tol:
        return n_t, best
    if phi < best:
        best = phi
        # drop entries that fell out of the window
        w = 0
        for r in range(n_t):
            if t_phi[r] <= best + tol:
                if w != r:
                    t_phi[w] = t_phi[r]
                    t_c[w] = t_c[r]
                    t_s[w] = t_s[r]
                    t_ev[w] = t_ev[r]
                    t_i[w] = t_i[r]
                    t_ob[w] = t_ob[r]
                    t_j[w] = t_j[r]
                    t_sh[w, 0] = t_sh[r, 0]
                    t_sh[w, 1] = t_sh[r, 1]
                w += 1
        n_t = w
    if n_t >= t_phi.shape[0]:
        return n_t, best
    t_phi[n_t] = phi
    t_c[n_t] = c
    t_s[n_t] = s
    t_ev[n_t] = ev
    t_i[n_t] = i
    t_ob[n_t] = ob
    t_j[n_t] = j
    t_sh[n_t, 0] = sh0
    t_sh[n_t, 1] = sh1
    return n_t + 1, best
