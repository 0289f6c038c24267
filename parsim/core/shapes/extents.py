"""Sizes of a particle given by its offsets (relative to the centre of mass) and radii."""

import numpy as np

from parsim.core.shapes.checks import _check_centres_radii


def extent_below_com(offsets, radii):
    """Depth of the particle's lowest point below its centre of mass: ``max(r_i - z_i)``.

    With the centre of mass at height ``z_cm`` the particle's lowest point is at
    ``z_cm - extent_below_com``; a particle whose centre of mass is higher than that
    above the floor does not touch it.
    """
    c, r = _check_centres_radii(offsets, radii, allow_2d=False)
    return float(np.max(r - c[:, 2]))


def bounding_radius(offsets, radii):
    """Largest distance from the centre of mass (origin) to any sphere surface,
    ``max(|offset_i| + r_i)``: the particle lies inside this ball in any orientation."""
    c, r = _check_centres_radii(offsets, radii, allow_2d=False)
    return float(np.max(np.sqrt(np.sum(c * c, axis=1)) + r))

