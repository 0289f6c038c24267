"""The survey of a deposition spread over ranks, one chunk of particles at a time: which block of
columns each particle is dropped in, the particles a rank keeps, and where the grid's cell grows.

Every rank reads every particle's inputs (the drop order defines the sediment), so these passes
over all N particles are the part of a decomposed deposition that does not shrink with the ranks;
they run here in one loop each, not as a chain of numpy passes that would each read all N again.
"""

import math

import numpy as np

from parsim.core.jit import jit


@jit(inline="always")
def _block_of(x, low, length, inner_edges, periodic):
    """The block of a drop abscissa: how many inner edges lie at or below it (numpy's
    ``searchsorted(inner_edges, x, side="right")``), ``x`` first taken onto ``[low, low + length)``
    in a periodic box as numpy's ``low + mod(x - low, length)`` does."""
    if periodic:
        rest = x - low
        if not 0.0 <= rest < length:  # inside, fmod would return rest itself
            rest = np.fmod(rest, length)
            if rest == 0.0:
                rest = math.copysign(0.0, length)
            elif (rest < 0.0) != (length < 0.0):
                rest += length
        x = low + rest
    n = inner_edges.shape[0]
    k = 0
    if length > 0.0 and math.isfinite(x):  # start from the equal blocks' guess, then correct it
        k = min(max(int((x - low) / length * (n + 1)), 0), n)
    while k < n and inner_edges[k] <= x:
        k += 1
    while k > 0 and not inner_edges[k - 1] <= x:
        k -= 1
    return k


@jit
def block_owners(x, low, length, inner_edges, periodic):
    """The block of each drop abscissa of ``x`` (see :func:`_block_of`)."""
    out = np.empty(x.shape[0], dtype=np.int64)
    for i in range(x.shape[0]):
        out[i] = _block_of(x[i], low, length, inner_edges, periodic)
    return out


@jit
def rows_of_block(drop_x, particle_shape, shape_start, low, length, inner_edges, periodic, block):
    """The particles of a chunk dropped in ``block`` (their indices in the chunk), and the number of
    spheres of the chunk's particles before each of them."""
    mine = np.empty(drop_x.shape[0], dtype=np.int64)
    spheres_before = np.empty(drop_x.shape[0], dtype=np.int64)
    count = spheres = 0
    for i in range(drop_x.shape[0]):
        if _block_of(drop_x[i], low, length, inner_edges, periodic) == block:
            mine[count] = i
            spheres_before[count] = spheres
            count += 1
        s = particle_shape[i]
        spheres += shape_start[s + 1] - shape_start[s]
    return mine[:count].copy(), spheres_before[:count].copy()


@jit
def cell_growth(particle_shape, particle_scale, shape_largest_radius, cell):
    """The particles of a chunk larger than every one before (their indices in the chunk) and the
    grid's cell after each, starting from ``cell``: the largest sphere diameter so far."""
    at = np.empty(particle_shape.shape[0], dtype=np.int64)
    cells = np.empty(particle_shape.shape[0])
    count = 0
    for i in range(particle_shape.shape[0]):
        diameter = 2.0 * particle_scale[i] * shape_largest_radius[particle_shape[i]]
        if diameter > cell:
            cell = diameter
            at[count] = i
            cells[count] = cell
            count += 1
    return at[:count].copy(), cells[:count].copy()
