"""The ghost rows during the iterations: each iteration's one message per neighbour, and the ghosts' own drift.

After (3.23) a rank sends each neighbour the position, velocity and damping of the awake spheres
that neighbour holds as ghosts; the receiver drifts its ghosts (3.20) with their owners'
velocities, so a ghost at rest on its owner stays at rest.
"""

from typing import NamedTuple

import numpy as np

from parsim.core.jit import jit
from parsim.core.kernel_mpi import share_changed_rows


def motion_width(dimension):
    """Floats per row that the iterations send a neighbour: a moving sphere's position, velocity
    and damping (:func:`_share_motion`)."""
    return 2 * dimension + 1


@jit
def _drift_ghosts(P, ghost_U, previous_ghost, first_ghost, h):
    """(3.20) for the ghost rows, as their owners do it: ``ghost_U`` is each one's velocity on its
    owner, zero for a sphere at rest there (asleep, settled, an anchor), which the owner does not
    move; the rows that move keep their start in ``previous_ghost``."""
    d = P.shape[1]
    for g in range(ghost_U.shape[0]):
        if _is_moving(ghost_U, g):
            for k in range(d):
                previous_ghost[g, k] = P[first_ghost + g, k]
                P[first_ghost + g, k] += h * ghost_U[g, k]


@jit
def _is_moving(U, i):
    """Whether row ``i`` of the velocities ``U`` is not zero."""
    for k in range(U.shape[1]):
        if U[i, k] != 0.0:
            return True
    return False


@jit
def _share_motion(P, U, damping_of, previous_ghost, is_awake, awake, ghost_motion, halo):
    """After (3.23): each neighbour gets, in one message, the position, velocity and damping of the
    ``awake`` spheres it holds as ghosts (the rows that changed); the ghost rows that come are
    ``arrived[:n]`` (returns ``n``), awake (``is_awake``) as on their owners, the others asleep.
    Their start stays in ``previous_ghost``."""
    ghost_U, motion, changed, sends, arrived = ghost_motion
    first_ghost, d = P.shape[0] - ghost_U.shape[0], P.shape[1]
    if halo.neighbours.shape[0] == 0:  # no neighbour
        return 0
    for i in awake:
        if sends[i]:
            changed[i] = True
            for k in range(d):
                motion[i, k] = P[i, k]
                motion[i, d + k] = U[i, k]
            motion[i, 2 * d] = damping_of[i]
    n = share_changed_rows(motion, first_ghost, changed, arrived, halo)
    for i in awake:
        changed[i] = False
    is_awake[first_ghost:] = False
    for g in arrived[:n]:
        row = first_ghost + g
        if not _is_moving(ghost_U, g):  # not drifted: still at its start
            for k in range(d):
                previous_ghost[g, k] = P[row, k]
        for k in range(d):
            P[row, k] = motion[row, k]
            ghost_U[g, k] = motion[row, d + k]
        damping_of[row] = motion[row, 2 * d]
        is_awake[row] = True
    return n


@jit
def _stop_ghosts(ghost_U, flags, first_ghost, stop_flagged):
    """Zero the velocity of the ghost rows whose flag (per row) is ``stop_flagged``, as their
    owners zero it (settled tiles, sleeping spheres: :func:`_check`)."""
    for g in range(ghost_U.shape[0]):
        if flags[first_ghost + g] == stop_flagged:
            for k in range(ghost_U.shape[1]):
                ghost_U[g, k] = 0.0


class GhostMotion(NamedTuple):
    """The ghosts' velocities as on their owners, the rows sent and received, the flags of the changed
    rows, which owned rows some neighbour holds as ghosts, and the ghost rows that arrived."""

    ghost_U: np.ndarray
    motion: np.ndarray
    changed: np.ndarray
    sends: np.ndarray
    arrived: np.ndarray
