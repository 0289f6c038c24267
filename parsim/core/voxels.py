"""Spheres rasterised on a regular grid of voxels: the solid/void image of a sediment or cluster."""

import math

from parsim.core.jit import jit


@jit
def carve_spheres(void, centres, radii, lower, spacing, periodic):
    """Set ``void[i, j, k]`` to False for every voxel whose centre, ``lower + (index + 1/2)
    spacing``, lies in a sphere (``centres``, ``radii``).  Along a ``periodic`` axis the grid spans
    one period exactly and a sphere's voxels wrap around it; along the others, voxels outside the
    grid are left out."""
    shape = void.shape
    first = [0, 0, 0]
    last = [0, 0, 0]
    for s in range(radii.shape[0]):
        r = radii[s]
        for a in range(3):
            first[a] = math.floor((centres[s, a] - r - lower[a]) / spacing[a] - 0.5)
            last[a] = math.ceil((centres[s, a] + r - lower[a]) / spacing[a] - 0.5)
            if periodic[a]:
                last[a] = min(last[a], first[a] + shape[a] - 1)
            else:
                first[a], last[a] = max(first[a], 0), min(last[a], shape[a] - 1)
        for i in range(first[0], last[0] + 1):
            dx = lower[0] + (i + 0.5) * spacing[0] - centres[s, 0]
            for j in range(first[1], last[1] + 1):
                dy = lower[1] + (j + 0.5) * spacing[1] - centres[s, 1]
                for k in range(first[2], last[2] + 1):
                    dz = lower[2] + (k + 0.5) * spacing[2] - centres[s, 2]
                    if dx * dx + dy * dy + dz * dz <= r * r:
                        void[i % shape[0], j % shape[1], k % shape[2]] = False
