"""Frustrated situations (4.1): the trial rotation.

The motion is decided from the contacts' state at the start of a rotation.  In a frustrated
situation (for instance a rate of the order of the tolerances) the decision taken a little
later differs although no event of 3.2-3.3 lies in between.  As in 4.1 of the paper, the
decision is taken again after a trial rotation by the small angle ``trial_angle``, with the
pivots as the only contacts; if it differs, that angle is an event of the rotation, and the
particle decides anew there.
"""

import math

from parsim.core.jit import jit
from parsim.core.sdbd.bundles import geometry_arrays
from parsim.core.sdbd.constants import OB_SPHERE
from parsim.core.sdbd.decision import decide
from parsim.core.sdbd.rotation import rotate_point

__all__ = ["decision_changes"]


@jit(inline="always")
def decision_changes(motion, n_pivots, k, m, geometry, com, axis, pivot, trial_angle, work, settings):
    """Does the decision change after the rotation by ``trial_angle`` about ``axis`` through
    ``pivot``, the ``n_pivots`` pivots (contacts ``k`` and ``m`` of ``geometry``) being the
    only contacts?  The same motion on the same pivots is no change."""
    scratch = work.scratch
    point = scratch.point
    ca, cP, cN, cD, cc0, ckind = geometry_arrays(geometry)
    ta, tP, tN, tD, tc0, tkind = geometry_arrays(work.trial)
    ct = math.cos(trial_angle)
    st = math.sin(trial_angle)
    rotate_point(com, pivot, axis, ct, st, scratch.trial_com)
    for t in range(n_pivots):
        l = k if t == 0 else m
        rotate_point(ca[l], pivot, axis, ct, st, point)
        tkind[t] = ckind[l]
        tD[t] = cD[l]
        tc0[t] = cc0[l]
        for q in range(3):
            ta[t, q] = point[q]
        if ckind[l] == OB_SPHERE:
            # the sediment sphere stays, the normal follows the moving sphere
            for q in range(3):
                tP[t, q] = cP[l, q]
            nn = math.sqrt((point[0] - cP[l, 0]) ** 2 + (point[1] - cP[l, 1]) ** 2 + (point[2] - cP[l, 2]) ** 2)
            for q in range(3):
                tN[t, q] = (point[q] - cP[l, q]) / nn
        else:
            # a plane holds the moving sphere's centre, its normal does not turn
            for q in range(3):
                tP[t, q] = point[q]
                tN[t, q] = cN[l, q]
    motion_after, k_after, m_after, _ = decide(scratch.trial_com, n_pivots, work.trial, settings.ell,
                                               settings.sliding_walls, scratch.trial_decision)
    return not (motion_after == motion and k_after == 0 and (n_pivots == 1 or m_after == 1))
