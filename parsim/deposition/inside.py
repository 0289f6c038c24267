"""The inside of a convex vessel as the kernel takes it: sections, volumes and membership, exact.

A mesh vessel's inside, continued above its rim (:mod:`parsim.deposition.vessel`), is the set of
points above the floor ``z >= 0`` within the rectangle ``lower <= (x, y) <= upper`` of its box's
walls and behind every face, ``N . x >= c`` with inward unit normals ``N`` (``N_z >= 0``).  Its
section at height ``z`` is the rectangle clipped by the half-planes ``N_xy . p >= c - N_z z``: a
convex polygon whose sides move linearly with ``z``.  So is every vertex of the polygon, until three
of its lines (faces' or walls') meet in a point of it, or two opposite lines meet; between such
heights the section's area is a quadratic of ``z`` and Simpson's rule integrates it exactly.
:meth:`ConvexInside.volume_between` integrates over the heights where that can happen, found once
for the whole inside; a height found that changes nothing costs one more Simpson step.

:meth:`ConvexInside.shrunk` gives the points at least a distance inside every face and wall (not the
floor): the same planes moved inwards, so the bulk of a sediment in a vessel is measured in a
convex inside of its own.
"""

from dataclasses import dataclass, field

import numpy as np

__all__ = ["ConvexInside", "clip_polygon"]

#: A height where lines meet is kept when the point lies within this many units of the inside's
#: size from every other line: generous, since a height kept in vain changes no volume.
MEETING_RTOL = 1e-7
#: Triples of lines examined at a time (their feasibility test holds triples x lines floats).
TRIPLES_PER_CHUNK = 20_000


def clip_polygon(polygon, a, b):
    """The convex polygon (m, 2) clipped to the half-plane ``a . p >= b`` (Sutherland-Hodgman)."""
    s = polygon @ a - b
    keep = s >= 0.0
    if keep.all() or not keep.any():
        return polygon if keep.all() else polygon[:0]
    following, t = np.roll(polygon, -1, axis=0), np.roll(s, -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        crossing = polygon + (following - polygon) * (s / (s - t))[:, None]
    points = np.stack([polygon, crossing], axis=1).reshape(-1, 2)  # each vertex, then its edge's crossing
    return points[np.stack([keep, keep != (t >= 0.0)], axis=1).ravel()]


def polygon_area(polygon) -> float:
    """Shoelace area of a polygon (m, 2); 0 for fewer than three vertices."""
    if len(polygon) < 3:
        return 0.0
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


@dataclass(frozen=True, eq=False)
class ConvexInside:
    """Points ``z >= 0``, ``lower <= (x, y) <= upper`` with ``normals . x >= levels`` for every face.

    ``normals`` (F, 3) inward unit normals, ``levels`` (F,), ``lower``, ``upper`` the walls' rectangle."""

    normals: np.ndarray
    levels: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    _breaks: list = field(default_factory=list, repr=False)  # the heights of :meth:`breaks`, once found

    def shrunk(self, distance: float) -> "ConvexInside":
        """The points at least ``distance`` from every face and wall (the floor stays where it is)."""
        return ConvexInside(self.normals, self.levels + distance, self.lower + distance, self.upper - distance)

    def contains(self, points, margin=0.0) -> np.ndarray:
        """Whether each point (k, 3) lies inside, at least ``margin`` from every face and wall."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        inside = np.all(points @ self.normals.T >= self.levels + margin, axis=1)
        inside &= np.all((points[:, :2] >= self.lower + margin) & (points[:, :2] <= self.upper - margin), axis=1)
        return inside & (points[:, 2] >= 0.0)

    def section(self, z: float) -> np.ndarray:
        """The section at height ``z``: the walls' rectangle clipped by every face, a polygon (m, 2)."""
        (x0, y0), (x1, y1) = self.lower, self.upper
        if z < 0.0 or x1 <= x0 or y1 <= y0:
            return np.zeros((0, 2))
        polygon = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=np.float64)
        for normal, level in zip(self.normals, self.levels):
            polygon = clip_polygon(polygon, normal[:2], level - normal[2] * z)
            if not len(polygon):
                break
        return polygon

    def area_at(self, z: float) -> float:
        """Area of the section at height ``z``."""
        return polygon_area(self.section(float(z)))

    def volume_between(self, low: float, high: float) -> float:
        """Volume of the inside between heights ``low`` and ``high``: Simpson's rule between the
        heights where the section's area may stop being one quadratic, exact but for rounding."""
        low, high = max(float(low), 0.0), float(high)
        if high <= low:
            return 0.0
        inner = [b for b in self.breaks() if low < b < high]
        edges = np.concatenate([[low], inner, [high]])
        return float(sum((b - a) / 6.0 * (self.area_at(a) + 4.0 * self.area_at(0.5 * (a + b)) + self.area_at(b))
                         for a, b in zip(edges[:-1], edges[1:])))

    def breaks(self) -> np.ndarray:
        """Heights above the floor where three of the section's lines meet in a point of it, or two
        opposite lines meet: the only heights where its area stops being one quadratic of z."""
        if not self._breaks:
            self._breaks.append(_meeting_heights(*self._lines(), self._size()))
        return self._breaks[0]

    def _lines(self):
        """The section's lines ``a . p >= b - m z``: the faces', then the four walls'."""
        walls = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
        a = np.concatenate([self.normals[:, :2], walls])
        b = np.concatenate([self.levels, [self.lower[0], -self.upper[0], self.lower[1], -self.upper[1]]])
        m = np.concatenate([self.normals[:, 2], np.zeros(4)])
        return a, b, m

    def _size(self) -> float:
        return float(np.hypot(*(self.upper - self.lower)))


def _meeting_heights(a, b, m, size) -> np.ndarray:
    """The heights z >= 0 where lines ``a . p = b - m z`` (L, 2), (L,), (L,) meet, three in a point of
    the section or two opposite ones; only triples with a line that moves (m != 0) can meet at one
    height alone (three fixed lines meet at every height or at none)."""
    tolerance = MEETING_RTOL * size
    heights = [_opposite_meetings(a, b, m)]
    moving = m != 0.0
    for i in range(len(b) - 2):
        j, k = np.triu_indices(len(b) - i - 1, 1)
        j, k = j + i + 1, k + i + 1
        triples = np.column_stack([np.full(len(j), i), j, k])[moving[i] | moving[j] | moving[k]]
        for start in range(0, len(triples), TRIPLES_PER_CHUNK):
            heights.append(_concurrent_heights(a, b, m, triples[start:start + TRIPLES_PER_CHUNK], tolerance))
    found = np.concatenate(heights)
    return np.unique(found[found >= 0.0])


def _opposite_meetings(a, b, m) -> np.ndarray:
    """Heights where two lines of opposite normals coincide (a V's two faces at its bottom line)."""
    i, j = np.triu_indices(len(b), 1)
    cross = a[i, 0] * a[j, 1] - a[i, 1] * a[j, 0]
    opposite = (np.abs(cross) <= 1e-12) & (np.sum(a[i] * a[j], axis=1) < 0.0)
    i, j = i[opposite], j[opposite]
    # a_j = -k a_i: the lines coincide where b_j - m_j z = -k (b_i - m_i z)
    k = np.linalg.norm(a[j], axis=1) / np.maximum(np.linalg.norm(a[i], axis=1), 1e-300)
    rate = m[j] + k * m[i]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (b[j] + k * b[i]) / rate
    return z[np.isfinite(z) & (rate != 0.0)]


def _concurrent_heights(a, b, m, triples, tolerance) -> np.ndarray:
    """For each triple of lines, the height where they pass through one point, kept when that point lies
    within ``tolerance`` of the section (behind every other line)."""
    if not len(triples):
        return np.zeros(0)
    ta, tb, tm = a[triples], b[triples], m[triples]  # (T, 3, 2), (T, 3), (T, 3)
    # det [a | b - m z] = det[a | b] - z det[a | m], linear in z
    minors = np.stack([ta[:, 1, 0] * ta[:, 2, 1] - ta[:, 1, 1] * ta[:, 2, 0],
                       ta[:, 2, 0] * ta[:, 0, 1] - ta[:, 2, 1] * ta[:, 0, 0],
                       ta[:, 0, 0] * ta[:, 1, 1] - ta[:, 0, 1] * ta[:, 1, 0]], axis=1)
    d_b, d_m = np.sum(minors * tb, axis=1), np.sum(minors * tm, axis=1)
    usable = np.abs(d_m) > 1e-12 * np.maximum(np.abs(d_b), 1.0)
    z = np.where(usable, d_b / np.where(usable, d_m, 1.0), -1.0)
    # the point: the two of the three lines whose normals are furthest from parallel
    best = np.argmax(np.abs(minors), axis=1)  # minor r excludes line r
    rows = np.arange(len(triples))
    first, second = (best + 1) % 3, (best + 2) % 3
    a1, a2 = ta[rows, first], ta[rows, second]
    c1 = tb[rows, first] - tm[rows, first] * z
    c2 = tb[rows, second] - tm[rows, second] * z
    det = minors[rows, best]
    with np.errstate(divide="ignore", invalid="ignore"):
        point = np.stack([(c1 * a2[:, 1] - c2 * a1[:, 1]) / det, (a1[:, 0] * c2 - a2[:, 0] * c1) / det], axis=1)
    usable &= np.isfinite(point).all(axis=1) & (z >= 0.0)
    z, point = z[usable], point[usable]
    if not len(z):
        return z
    slack = point @ a.T - (b[None, :] - z[:, None] * m[None, :])
    return z[np.all(slack >= -tolerance, axis=1)]
