"""simulate_ed: the checks of its arguments, the default skin, and the run's result."""

import math
from typing import NamedTuple

import numpy as np

from parsim.core.celllist import grid_size, worst_overlap
from parsim.core.ed.run import STOP_REASONS, simulate

#: Tolerance on initial overlaps and on spheres poking out of the box, relative to the
#: mean radius: input positions are typically computed to ~1e-15 relative precision.
OVERLAP_TOLERANCE = 1e-9
#: The default skin (neighbour-list margin) is chosen so that a sphere in a uniform gas
#: at the system's mean density would have this many spheres within 2 R_mean + skin.  A
#: larger skin means fewer re-bins but longer lists; measured on lattice + isotropic
#: initial conditions (N ~ 2.6e4, volume fractions 0.05-0.3, d = 2 and 3), 5-6 is
#: within ~10% of the best time everywhere (e.g. d = 2, V_f = 0.2: skin = 3 R).
DEFAULT_SKIN_NEIGHBOURS = 5.5
#: Bounds of the default skin, in mean radii.
DEFAULT_SKIN_RANGE = (0.25, 20.0)


class EDResult(NamedTuple):
    """Outcome of :func:`simulate_ed`."""

    positions: np.ndarray  #: (n, d) sphere centres at ``time``
    velocities: np.ndarray  #: (n, d) sphere velocities (each sphere carries its cluster's)
    cluster: np.ndarray  #: (n,) int64 cluster labels 0..n_clusters-1, by first appearance
    links: np.ndarray  #: (k, 2) int64 colliding pair (i < j) of every merge, in event order
    merge_times: np.ndarray  #: (k,) float64 time of every merge
    time: float  #: time reached
    n_events: int  #: physical events processed (collisions + wall reflections)
    n_collisions: int  #: merges (= k = n - n_clusters)
    n_wall_reflections: int  #: wall reflections of clusters
    stop_reason: str  #: "single_cluster", "max_time" or "max_events"
    merge_momentum_before: np.ndarray  #: (k, d) with record_merges, else (0, d)
    merge_momentum_after: np.ndarray  #: (k, d) with record_merges, else (0, d)
    n_rebins: int  #: re-bin (neighbour-list) events, bookkeeping only


def _as_array(name, value, shape):
    try:
        arr = np.array(value, dtype=np.float64, copy=True)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be an array of numbers: {exc}") from None
    if arr.ndim != len(shape) or any(s is not None and s != t for s, t in zip(shape, arr.shape)):
        want = "(" + ", ".join("?" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite")
    return np.ascontiguousarray(arr)


def _compact_labels(raw):
    """Relabel cluster ids to 0..k-1 in order of first appearance over the spheres."""
    _, first, inverse = np.unique(raw, return_index=True, return_inverse=True)
    rank = np.empty(first.size, dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(first.size, dtype=np.int64)
    return rank[inverse.reshape(-1)]


def default_skin(n, dimension, box_length, mean_radius):
    """Skin giving ``DEFAULT_SKIN_NEIGHBOURS`` neighbours per sphere at the mean density.

    Solves ``rho v_d (2 R + skin)^d = DEFAULT_SKIN_NEIGHBOURS`` with ``rho = n / L^d`` and
    ``v_d`` the volume of the unit d-ball, clamped to ``DEFAULT_SKIN_RANGE`` mean radii.
    """
    unit_ball = math.pi ** (dimension / 2.0) / math.gamma(dimension / 2.0 + 1.0)
    reach = (DEFAULT_SKIN_NEIGHBOURS * box_length**dimension / (n * unit_ball)) ** (1.0 / dimension)
    lo, hi = DEFAULT_SKIN_RANGE
    return min(max(reach - 2.0 * mean_radius, lo * mean_radius), hi * mean_radius)


def simulate_ed(positions, velocities, radii, masses, box_length, max_time=np.inf,
                max_events=None, skin=None, record_merges=False):
    """Run event-driven ballistic aggregation in the box ``[0, box_length]^d``.

    Parameters
    ----------
    positions, velocities : (n, d) arrays, d in 1..3
        Initial centres (every sphere inside the box, no overlaps) and velocities.
    radii, masses : (n,) arrays of positive numbers.
    box_length : float > 0.
    max_time : float >= 0, default inf
        Stop when the next event would come after this time (state returned at it).
    max_events : int >= 0 or None (no limit)
        Stop after this many physical events (collisions + wall reflections).
    skin : float > 0 or None
        Neighbour-list margin; default :func:`default_skin`.  Affects speed only, not
        the result (beyond round-off in the event times).
    record_merges : bool
        Also return the momentum of the two merging clusters before and of the merged
        cluster after each merge, summed over spheres (test hook).

    Returns
    -------
    EDResult
        ``stop_reason`` is "single_cluster", "max_time" or "max_events"; ``n_events``
        counts collisions and wall reflections (re-bin events are in ``n_rebins``).

    Raises
    ------
    ValueError
        Bad shapes or values; the message names the argument.
    """
    x = _as_array("positions", positions, (None, None))
    n, d = x.shape
    if n < 1:
        raise ValueError("positions must hold at least one sphere, got shape (0, d)")
    if not 1 <= d <= 3:
        raise ValueError(f"positions must have 1, 2 or 3 columns (the dimension), got {d}")
    v = _as_array("velocities", velocities, (n, d))
    r = _as_array("radii", radii, (n,))
    mass = _as_array("masses", masses, (n,))
    if np.any(r <= 0.0):
        raise ValueError(f"radii must be > 0, got min {r.min()!r}")
    if np.any(mass <= 0.0):
        raise ValueError(f"masses must be > 0, got min {mass.min()!r}")
    try:
        L = float(box_length)
    except (TypeError, ValueError):
        raise ValueError(f"box_length must be a number, got {box_length!r}") from None
    if not (math.isfinite(L) and L > 0.0):
        raise ValueError(f"box_length must be a finite number > 0, got {box_length!r}")
    try:
        max_time = float(max_time)
    except (TypeError, ValueError):
        raise ValueError(f"max_time must be a number, got {max_time!r}") from None
    if math.isnan(max_time) or max_time < 0.0:
        raise ValueError(f"max_time must be >= 0 (inf allowed), got {max_time!r}")
    if max_events is None:
        max_events = np.iinfo(np.int64).max
    elif isinstance(max_events, bool) or not isinstance(max_events, (int, np.integer)) or max_events < 0:
        raise ValueError(f"max_events must be an integer >= 0 or None, got {max_events!r}")
    r_mean = float(r.mean())
    if skin is None:
        skin = default_skin(n, d, L, r_mean)
    else:
        try:
            skin = float(skin)
        except (TypeError, ValueError):
            raise ValueError(f"skin must be a number, got {skin!r}") from None
        if not (math.isfinite(skin) and skin > 0.0):
            raise ValueError(f"skin must be a finite number > 0, got {skin!r}")

    tol = OVERLAP_TOLERANCE * r_mean
    below = x - r[:, None] < -tol
    above = x + r[:, None] > L + tol
    if np.any(below | above):
        i, a = np.argwhere(below | above)[0]
        raise ValueError(
            f"positions: sphere {i} (centre {x[i, a]!r} on axis {a}, radius {r[i]!r}) "
            f"is not inside the box [0, {L!r}]"
        )
    cutoff = 2.0 * float(r.max()) + skin
    k_side, side = grid_size(L, cutoff, d, n)
    if n > 1:
        i, j, gap = worst_overlap(x, r, side, k_side)
        if gap < -tol:
            raise ValueError(
                f"positions: spheres {i} and {j} overlap by {-gap!r} "
                f"(tolerance {tol!r} = {OVERLAP_TOLERANCE} x mean radius)"
            )

    out = simulate(x, v, r, mass, L, max_time, np.int64(max_events), skin, k_side, side,
                   np.bool_(record_merges))
    return EDResult(
        positions=out.positions,
        velocities=out.velocities,
        cluster=_compact_labels(out.cluster),
        links=out.links,
        merge_times=out.merge_times,
        time=float(out.time),
        n_events=int(out.n_events),
        n_collisions=int(out.n_collisions),
        n_wall_reflections=int(out.n_wall_reflections),
        stop_reason=STOP_REASONS[out.reason],
        merge_momentum_before=out.momentum_before,
        merge_momentum_after=out.momentum_after,
        n_rebins=int(out.n_rebins),
    )
