"""Volumes of convex polytopes computed independently of parsim's sections, for the tests that check them."""

import numpy as np


def facet_volume(inside, low, high):
    """Volume of {inside, low <= z <= high} by the divergence theorem, V = sum over facets of A_f (-c_f) / 3 for
    planes N . x >= c: each facet is a large square in its plane clipped by every other half-space."""
    planes = [(n, c) for n, c in zip(inside.normals, inside.levels)]
    (x0, y0), (x1, y1) = inside.lower, inside.upper
    planes += [(np.array([1.0, 0, 0]), x0), (np.array([-1.0, 0, 0]), -x1), (np.array([0, 1.0, 0]), y0),
               (np.array([0, -1.0, 0]), -y1), (np.array([0, 0, 1.0]), max(low, 0.0)), (np.array([0, 0, -1.0]), -high)]
    size = 10.0 * (abs(x1 - x0) + abs(y1 - y0) + abs(high) + 1.0)
    volume = 0.0
    for f, (normal, level) in enumerate(planes):
        u = np.cross(normal, [0.0, 0.0, 1.0] if abs(normal[2]) < 0.9 else [1.0, 0.0, 0.0])
        u /= np.linalg.norm(u)
        v = np.cross(normal, u)
        centre = normal * level
        polygon = np.array([centre + size * (a * u + b * v) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
        for g, (other, other_level) in enumerate(planes):
            if g == f or not len(polygon):
                continue
            s = polygon @ other - other_level
            keep = s >= 0.0
            if keep.all():
                continue
            following, t = np.roll(polygon, -1, axis=0), np.roll(s, -1)
            with np.errstate(divide="ignore", invalid="ignore"):
                crossing = polygon + (following - polygon) * (s / (s - t))[:, None]
            points = np.stack([polygon, crossing], axis=1).reshape(-1, 3)
            polygon = points[np.stack([keep, keep != (t >= 0.0)], axis=1).ravel()]
        if len(polygon) >= 3:
            area = 0.5 * abs(float(np.dot(np.sum(np.cross(polygon, np.roll(polygon, -1, axis=0)), axis=0), normal)))
            volume += area * (-level) / 3.0  # the outward normal -N: x . (-N) = -c on the facet
    return volume
