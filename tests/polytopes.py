"""Volumes of convex polytopes computed independently of parsim's sections, for the tests that check them."""

import numpy as np


def facets(inside, low, high):
    """The facets of {inside, low <= z <= high}, (inward normal, level, polygon) for planes N . x >= c: each a
    large square in its plane clipped by every other half-space, in turn."""
    planes = [(n, c) for n, c in zip(inside.normals, inside.levels)]
    (x0, y0), (x1, y1) = inside.lower, inside.upper
    planes += [(np.array([1.0, 0, 0]), x0), (np.array([-1.0, 0, 0]), -x1), (np.array([0, 1.0, 0]), y0),
               (np.array([0, -1.0, 0]), -y1), (np.array([0, 0, 1.0]), max(low, 0.0)), (np.array([0, 0, -1.0]), -high)]
    size = 10.0 * (abs(x1 - x0) + abs(y1 - y0) + abs(high) + 1.0)
    found = []
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
            found.append((normal, level, polygon))
    return found


def facet_volume(inside, low, high):
    """Volume of {inside, low <= z <= high} by the divergence theorem, V = sum over facets of A_f (-c_f) / 3."""
    volume = 0.0
    for normal, level, polygon in facets(inside, low, high):
        area = 0.5 * abs(float(np.dot(np.sum(np.cross(polygon, np.roll(polygon, -1, axis=0)), axis=0), normal)))
        volume += area * (-level) / 3.0  # the outward normal -N: x . (-N) = -c on the facet
    return volume


def centroid_height(inside, low, high):
    """The height of the centroid of {inside, low <= z <= high}: the tetrahedra from an inner point to the
    facets' fan triangles, each weighted by its volume."""
    parts = facets(inside, low, high)
    inner = np.mean(np.concatenate([polygon for _, _, polygon in parts]), axis=0)  # inside a convex polytope
    volume = moment = 0.0
    for _, _, polygon in parts:
        for b, c in zip(polygon[1:-1], polygon[2:]):
            tetrahedron = abs(np.linalg.det(np.array([polygon[0] - inner, b - inner, c - inner]))) / 6.0
            volume += tetrahedron
            moment += tetrahedron * (inner[2] + polygon[0][2] + b[2] + c[2]) / 4.0
    return moment / volume
