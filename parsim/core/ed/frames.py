"""The clusters of an event-driven run in lazy frames, and the times of their next events.

Sphere ``i`` of cluster ``c = cl[i]`` is at ``X_i(t) = O_c + V_c (t - T0_c) + P_i``: a
cluster translates rigidly with one velocity (Degond et al. 2024, eq. 2.9), so a velocity
change moves the cluster's reference time and origin in O(1) and nothing per sphere.
"""

import math
from typing import NamedTuple

import numpy as np

from parsim.core.jit import jit


class Clusters(NamedTuple):
    """Spheres and the rigid clusters they form, each cluster in its own frame."""

    P: np.ndarray  #: (n, d) offset of each sphere from its cluster's origin
    R: np.ndarray  #: (n,) sphere radii
    m: np.ndarray  #: (n,) sphere masses
    cl: np.ndarray  #: (n,) cluster of each sphere
    O: np.ndarray  #: (n, d) origin of each cluster at its reference time
    V: np.ndarray  #: (n, d) velocity of each cluster
    T0: np.ndarray  #: (n,) reference time of each cluster
    D: np.ndarray  #: (n, d) displacement of each cluster since its spheres were binned
    M: np.ndarray  #: (n,) mass of each cluster
    count: np.ndarray  #: (n,) spheres in each cluster (0 once merged away)
    head: np.ndarray  #: (n,) first sphere of each cluster's list, -1 if none
    tail: np.ndarray  #: (n,) last sphere of each cluster's list
    nxt: np.ndarray  #: (n,) next sphere in its cluster's list, -1 at the end
    lo: np.ndarray  #: (n, d) lower corner of each cluster's bounding box, in its frame
    hi: np.ndarray  #: (n, d) upper corner of each cluster's bounding box, in its frame
    ver: np.ndarray  #: (n,) version stamp of each cluster; an event recorded with another is stale
    t_rebin: np.ndarray  #: (n,) time of each cluster's pending re-bin event
    stamp: np.ndarray  #: (1,) the next version stamp to hand out


@jit
def new_clusters(X0, V0, R, m, h):
    """Every sphere its own cluster at rest in its frame (``P = 0``, origin ``X0``) at t = 0."""
    n, d = X0.shape
    D = np.zeros((n, d))
    V = V0.copy()
    T0 = np.zeros(n)
    lo = np.empty((n, d))
    hi = np.empty((n, d))
    for i in range(n):
        for a in range(d):
            lo[i, a] = -R[i]
            hi[i, a] = R[i]
    t_rebin = np.empty(n)
    for i in range(n):
        t_rebin[i] = rebin_time(i, 0.0, D, V, T0, h)
    stamp = np.empty(1, dtype=np.int64)
    stamp[0] = n
    return Clusters(np.zeros((n, d)), R, m, np.arange(n), X0.copy(), V, T0, D, m.copy(),
                    np.ones(n, dtype=np.int64), np.arange(n), np.arange(n),
                    np.full(n, -1, dtype=np.int64), lo, hi, np.arange(n), t_rebin, stamp)


@jit(inline="always")
def restamp(clusters, c):
    """Give cluster ``c`` a new version: every event queued with its old one becomes stale."""
    clusters.ver[c] = clusters.stamp[0]
    clusters.stamp[0] += 1


@jit(inline="always")
def position(i, t, clusters, out):
    """Centre of sphere ``i`` at time ``t`` into ``out``."""
    P, cl, O, V, T0 = clusters.P, clusters.cl, clusters.O, clusters.V, clusters.T0
    c = cl[i]
    s = t - T0[c]
    for a in range(P.shape[1]):
        out[a] = (O[c, a] + V[c, a] * s) + P[i, a]


@jit(inline="always")
def rebase(c, t, clusters):
    """Move cluster ``c``'s reference time to ``t`` (origin and displacement since binning)."""
    O, D, V, T0 = clusters.O, clusters.D, clusters.V, clusters.T0
    s = t - T0[c]
    if s != 0.0:
        for a in range(O.shape[1]):
            O[c, a] += V[c, a] * s
            D[c, a] += V[c, a] * s
    T0[c] = t


@jit(inline="always")
def pair_time(i, j, t, clusters):
    """Absolute collision time of spheres ``i`` and ``j`` (eq. A.3), or inf."""
    P, R, cl, O, V, T0 = clusters.P, clusters.R, clusters.cl, clusters.O, clusters.V, clusters.T0
    ci = cl[i]
    cj = cl[j]
    si = t - T0[ci]
    sj = t - T0[cj]
    dxdv = 0.0
    dvdv = 0.0
    dxdx = 0.0
    for a in range(P.shape[1]):
        dx = ((O[ci, a] + V[ci, a] * si) + P[i, a]) - ((O[cj, a] + V[cj, a] * sj) + P[j, a])
        dv = V[ci, a] - V[cj, a]
        dxdv += dx * dv
        dvdv += dv * dv
        dxdx += dx * dx
    if dxdv >= 0.0:
        return np.inf
    rr = R[i] + R[j]
    sigma = dxdv * dxdv - dvdv * (dxdx - rr * rr)
    if sigma < 0.0:
        return np.inf
    dt = -(dxdv + math.sqrt(sigma)) / dvdv
    if dt < 0.0:  # already overlapping by round-off and approaching: collide now
        dt = 0.0
    return t + dt


@jit(inline="always")
def wall_time(c, t, clusters, L):
    """Next wall contact of cluster ``c``'s bounding box: ``(time, axis, side)``."""
    O, V, T0, lo, hi = clusters.O, clusters.V, clusters.T0, clusters.lo, clusters.hi
    best = np.inf
    axis = -1
    side = -1
    s = t - T0[c]
    for a in range(O.shape[1]):
        v = V[c, a]
        o = O[c, a] + v * s
        if v > 0.0:
            dt = (L - (o + hi[c, a])) / v
            sd = 1
        elif v < 0.0:
            dt = (0.0 - (o + lo[c, a])) / v
            sd = 0
        else:
            continue
        if dt < 0.0:
            dt = 0.0
        if dt < best:
            best = dt
            axis = a
            side = sd
    return t + best, axis, side


@jit(inline="always")
def rebin_time(c, t, D, V, T0, h):
    """Time at which ``|delta_c|`` reaches ``h``, or inf for a cluster at rest."""
    s = t - T0[c]
    vv = 0.0
    dv = 0.0
    dd = 0.0
    for a in range(D.shape[1]):
        x = D[c, a] + V[c, a] * s
        vv += V[c, a] * V[c, a]
        dv += x * V[c, a]
        dd += x * x
    if vv == 0.0:
        return np.inf
    q = dd - h * h
    if q >= 0.0:
        return t
    return t + (-dv + math.sqrt(dv * dv - vv * q)) / vv


@jit
def cluster_momentum(c, clusters, out):
    """Add ``sum_i m_i V_i`` over the spheres of cluster ``c`` to ``out``."""
    m, V, head, nxt = clusters.m, clusters.V, clusters.head, clusters.nxt
    k = head[c]
    while k >= 0:
        for a in range(V.shape[1]):
            out[a] += m[k] * V[c, a]
        k = nxt[k]
