"""The part of the sediment a particle's descent reads, recorded when asked for.

``deposit_with_diagnostics(..., record_reads=True)`` hands the kernel a row of four numbers
per particle; without it the rows are empty and every note is one untaken branch.  A row is the
lateral rectangle ``[x_low, x_high] x [y_low, y_high]`` (the particle's own coordinates: in a
periodic box not wrapped) that contains every query box of the particle's descent: the drop
height's (:func:`.grid.top_near`), the falls' and the closing of near obstacles' (the squares
about its spheres at every step) and the contact searches of its rotations.  Every sediment
sphere the descent read has its centre in a grid cell that meets the rectangle, at any height
(a fall reads its columns down to the floor).  So a particle settled on the sediment spheres
whose cells meet its rectangle, and on no other, settles bit for bit as on the whole sediment:
what a decomposed deposition checks before it commits a particle settled ahead of its turn.
"""

import math

from parsim.core.jit import jit

X_LOW, X_HIGH, Y_LOW, Y_HIGH = 0, 1, 2, 3
N_READS = 4


@jit(inline="always")
def forget(reads):
    """Start an empty rectangle (when recording)."""
    if reads.shape[0] != 0:
        reads[X_LOW] = math.inf
        reads[X_HIGH] = -math.inf
        reads[Y_LOW] = math.inf
        reads[Y_HIGH] = -math.inf


@jit(inline="always")
def note(reads, x_low, x_high, y_low, y_high):
    """Grow the rectangle over a query box (when recording)."""
    if reads.shape[0] != 0:
        reads[X_LOW] = min(reads[X_LOW], x_low)
        reads[X_HIGH] = max(reads[X_HIGH], x_high)
        reads[Y_LOW] = min(reads[Y_LOW], y_low)
        reads[Y_HIGH] = max(reads[Y_HIGH], y_high)


@jit(inline="always")
def note_spheres(reads, n, particle, margin):
    """Grow the rectangle over the squares of half side ``radius + margin`` about the particle's
    ``n`` spheres (when recording)."""
    if reads.shape[0] != 0:
        for i in range(n):
            reach = particle.radius[i] + margin
            x = particle.centre[i, 0]
            y = particle.centre[i, 1]
            note(reads, x - reach, x + reach, y - reach, y + reach)
