"""The inside of a convex vessel as the kernel takes it: sections, volumes and membership, exact.

A mesh vessel's inside, continued above its rim (:mod:`parsim.deposition.vessel`), is the set of
points above the floor ``z >= 0`` within the rectangle ``lower <= (x, y) <= upper`` of its box's
walls and behind every face, ``N . x >= c`` with inward unit normals ``N`` (``N_z >= 0``): a convex
polytope, unbounded above.  Its section at height ``z`` is the rectangle clipped by the half-planes
``N_xy . p >= c - N_z z``, a convex polygon whose vertices move linearly with ``z`` along the
polytope's edges until they reach one of its vertices.  Between the heights of the polytope's
vertices the section's area is therefore a quadratic of ``z``, and Simpson's rule integrates it
exactly (:meth:`ConvexInside.volume_between`).  The vertices are found facet by facet: each plane's
facet is a large square in the plane clipped by the other half-spaces.  A section's area then comes
from the facets it cuts, by the divergence theorem in the plane: A(z) = 1/2 sum_f d_f(z) L_f(z), with
L_f the length of facet f's chord at height z and d_f the signed distance of its line from the origin.

A polygon is clipped by the half-planes it violates most first, and only by those: after at most a
few cuts per side every other half-plane holds at every vertex, so the cost grows with the sides of
the result rather than with the vessel's faces.

:meth:`ConvexInside.shrunk` gives the points at least a distance inside every face and wall (not the
floor): the same planes moved inwards, so the bulk of a sediment in a vessel is measured in a
convex inside of its own.
"""

from dataclasses import dataclass, field

import numpy as np

__all__ = ["ConvexInside"]

#: The polytope's vertices are found up to this height (then higher, if a volume above it is asked),
#: in units of the walls' rectangle's diagonal above the highest face's lowest point.
FIRST_CAP_DIAGONALS = 2.0
#: Vertex heights closer than this times the polytope's size are one height (the same vertex reached
#: from several facets differs by rounding; a height kept in vain would only cost a Simpson step).
DISTINCT_HEIGHTS_RTOL = 1e-12
#: A facet whose normal has a horizontal part below this is horizontal (the floor, the cut): it has no chord.
HORIZONTAL_RTOL = 1e-12
#: Halvings of the bracket when a height is solved for: 2^-60 of it, below a double's rounding.
BISECTIONS = 60


def clip_polygon(polygon, a, b):
    """The convex polygon (m, d) clipped to the half-space ``a . p >= b`` (Sutherland-Hodgman, any d)."""
    s = polygon @ a - b
    keep = s >= 0.0
    if keep.all() or not keep.any():
        return polygon if keep.all() else polygon[:0]
    following, t = np.roll(polygon, -1, axis=0), np.roll(s, -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        crossing = polygon + (following - polygon) * (s / (s - t))[:, None]
    points = np.stack([polygon, crossing], axis=1).reshape(-1, polygon.shape[1])  # each vertex, then its crossing
    return points[np.stack([keep, keep != (t >= 0.0)], axis=1).ravel()]


def clip_to_all(polygon, normals, levels):
    """The convex polygon (m, d) clipped to every half-space ``normals[k] . p >= levels[k]``: by the most
    violated one first, each at most once, until every half-space holds at every vertex."""
    used = np.zeros(len(levels), dtype=bool)
    while len(polygon) and not used.all():
        slack = np.min(polygon @ normals.T - levels, axis=0)
        slack[used] = np.inf
        worst = int(np.argmin(slack))
        if slack[worst] >= 0.0:
            break
        polygon = clip_polygon(polygon, normals[worst], levels[worst])
        used[worst] = True
    return polygon


@dataclass(frozen=True, eq=False)
class ConvexInside:
    """Points ``z >= 0``, ``lower <= (x, y) <= upper`` with ``normals . x >= levels`` for every face.

    ``normals`` (F, 3) inward unit normals, ``levels`` (F,), ``lower``, ``upper`` the walls' rectangle."""

    normals: np.ndarray
    levels: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    _vertices: dict = field(default_factory=dict, repr=False)  # "cap", "heights": the vertex heights found

    def shrunk(self, distance: float) -> "ConvexInside":
        """The points at least ``distance`` from every face and wall (the floor stays where it is)."""
        return ConvexInside(self.normals, self.levels + distance, self.lower + distance, self.upper - distance)

    def contains(self, points, margin=0.0) -> np.ndarray:
        """Whether each point (k, 3) lies inside, at least ``margin`` (a number, or one per point) from every
        face and wall."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        margin = np.broadcast_to(np.asarray(margin, dtype=np.float64), (len(points),))[:, None]
        inside = np.all(points @ self.normals.T >= self.levels + margin, axis=1)
        inside &= np.all((points[:, :2] >= self.lower + margin) & (points[:, :2] <= self.upper - margin), axis=1)
        return inside & (points[:, 2] >= 0.0)

    def area_at(self, z: float) -> float:
        """Area of the section at height ``z`` (0 below the floor), from the chords of the facets."""
        z = float(z)
        if z < 0.0:
            return 0.0
        self.vertex_heights(z)
        return self._vertices["chords"].area(z)

    def volume_between(self, low: float, high: float) -> float:
        """Volume of the inside between heights ``low`` and ``high``: Simpson's rule between the heights
        of the polytope's vertices, where the section's area is one quadratic; exact but for rounding."""
        low, high = max(float(low), 0.0), float(high)
        if high <= low:
            return 0.0
        heights = self.vertex_heights(high)
        edges = np.concatenate([[low], heights[(heights > low) & (heights < high)], [high]])
        return float(sum((b - a) / 6.0 * (self.area_at(a) + 4.0 * self.area_at(0.5 * (a + b)) + self.area_at(b))
                         for a, b in zip(edges[:-1], edges[1:])))

    def moment_between(self, low: float, high: float) -> float:
        """The first moment of the inside's volume about the floor between heights ``low`` and ``high``,
        the integral of z A(z): a cubic between vertex heights, which Simpson's rule integrates exactly."""
        low, high = max(float(low), 0.0), float(high)
        if high <= low:
            return 0.0
        heights = self.vertex_heights(high)
        edges = np.concatenate([[low], heights[(heights > low) & (heights < high)], [high]])
        return float(sum((b - a) / 6.0 * (a * self.area_at(a) + 2.0 * (a + b) * self.area_at(0.5 * (a + b))
                                          + b * self.area_at(b)) for a, b in zip(edges[:-1], edges[1:])))

    def filled_height(self, centre: float) -> float:
        """The height H to which the inside, filled uniformly from the floor, has its centre of mass at
        height ``centre`` (H = 2 centre in a constant section).  Its sections widen upwards, so the
        centroid lies between H / 2 and H: H is found by bisection in [centre, 2 centre]."""
        low, high = float(centre), 2.0 * float(centre)
        for _ in range(BISECTIONS):
            middle = 0.5 * (low + high)
            volume = self.volume_between(0.0, middle)
            if volume > 0.0 and self.moment_between(0.0, middle) / volume > centre:
                high = middle
            else:
                low = middle
        return 0.5 * (low + high)

    def height_holding(self, volume: float, top: float) -> float:
        """The height below which the inside holds ``volume``, by bisection in [0, ``top``]."""
        low, high = 0.0, float(top)
        for _ in range(BISECTIONS):
            middle = 0.5 * (low + high)
            if self.volume_between(0.0, middle) > volume:
                high = middle
            else:
                low = middle
        return 0.5 * (low + high)

    def vertex_heights(self, up_to: float) -> np.ndarray:
        """The distinct heights of the polytope's vertices up to ``up_to`` at least (it is cut above that,
        and the cut's own vertices are among them)."""
        if self._vertices.get("cap", -np.inf) < up_to:
            diagonal = float(np.hypot(*(self.upper - self.lower)))
            lowest = np.max(self.levels, initial=0.0)
            cap = max(2.0 * float(up_to), lowest + FIRST_CAP_DIAGONALS * diagonal, 2.0 * self._vertices.get("cap", 0.0))
            facets = _facets(*self._planes(cap))
            tolerance = DISTINCT_HEIGHTS_RTOL * max(cap, diagonal)
            heights = np.unique(np.concatenate([facet[:, 2] for _, facet in facets] + [np.zeros(0)]))
            heights = heights[np.concatenate([[True], np.diff(heights) > tolerance])] if len(heights) else heights
            heights[np.abs(heights) <= tolerance] = 0.0  # the floor's vertices, as computed, within rounding of 0
            self._vertices.update(cap=cap, heights=heights,
                                  chords=_Chords.of(facets, *self._planes(cap), tolerance))
        return self._vertices["heights"]

    def surface(self, height: float) -> list:
        """The vessel's walls up to ``height``: the polygons (k, 3) of the polytope cut there, but for the
        cut itself (the opening), floor and walls included; each polygon's vertices in order."""
        normals, levels = self._planes(height)
        return [polygon for f, polygon in _facets(normals, levels) if f != len(levels) - 1]

    def _planes(self, cap: float):
        """The polytope cut at height ``cap`` as half-spaces ``n . x >= c``: faces, walls, floor, cap."""
        bounds = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0], [0, 0, 1.0], [0, 0, -1.0]])
        levels = [self.lower[0], -self.upper[0], self.lower[1], -self.upper[1], 0.0, -cap]
        return np.concatenate([self.normals, bounds]), np.concatenate([self.levels, levels])


def _facets(normals, levels) -> list:
    """The facets of the bounded polytope ``normals . x >= levels``, (plane index, polygon (k, 3)) for each
    plane that bounds it: a square in the plane larger than the polytope clipped by the other half-spaces."""
    reach = 4.0 * (float(np.max(np.abs(levels))) + 1.0)  # every vertex lies within |x| <= max |level|
    facets = []
    for f, (normal, level) in enumerate(zip(normals, levels)):
        u = np.cross(normal, [0.0, 0.0, 1.0] if abs(normal[2]) < 0.9 else [1.0, 0.0, 0.0])
        u /= np.linalg.norm(u)
        v = np.cross(normal, u)
        corners = [normal * level + reach * (a * u + b * v) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
        others = np.arange(len(levels)) != f
        facet = clip_to_all(np.array(corners), normals[others], levels[others])
        if len(facet) >= 3:
            facets.append((f, facet))
    return facets


@dataclass(frozen=True)
class _Chords:
    """The edges of the polytope's non-horizontal facets, to cut at a height: ``start``, ``end`` (E, 3) and
    the facet of each (E,); per facet, its highest point ``top`` (G,), its line's unit direction ``along``
    (G, 2) (the inside on its left)
    and ``distance``, ``rate``: the signed distance of its line from the origin, d_f(z) = distance - rate z."""

    start: np.ndarray
    end: np.ndarray
    facet: np.ndarray
    top: np.ndarray
    along: np.ndarray
    distance: np.ndarray
    rate: np.ndarray
    tolerance: float

    @classmethod
    def of(cls, facets, normals, levels, tolerance) -> "_Chords":
        slanted = [(f, polygon) for f, polygon in facets if np.hypot(*normals[f, :2]) > HORIZONTAL_RTOL]
        starts, ends, owner = [np.zeros((0, 3))], [np.zeros((0, 3))], [np.zeros(0, dtype=np.int64)]
        for g, (_, polygon) in enumerate(slanted):
            starts.append(polygon)
            ends.append(np.roll(polygon, -1, axis=0))
            owner.append(np.full(len(polygon), g))
        index = np.array([f for f, _ in slanted], dtype=np.int64)
        horizontal = np.hypot(normals[index, 0], normals[index, 1])
        # the line n_xy . p = c - n_z z at distance (c - n_z z) / |n_xy| along n_xy; walked with the inside
        # (where n_xy points) on the left, its contribution to 1/2 sum of p x q is minus that distance
        top = np.array([polygon[:, 2].max() for _, polygon in slanted])
        return cls(np.concatenate(starts), np.concatenate(ends), np.concatenate(owner), top,
                   np.column_stack([normals[index, 1], -normals[index, 0]]) / horizontal[:, None],
                   -levels[index] / horizontal, -normals[index, 2] / horizontal, tolerance)

    def area(self, z: float) -> float:
        """A(z) = 1/2 sum_f d_f(z) L_f(z) over the facets whose chord at height z has a length, the limit from
        above: at a horizontal edge the facet below it, whose chord is the same edge, is left out (the area
        is continuous above the floor, and at the floor this is the floor's polygon)."""
        below, above = self.start[:, 2] - z, self.end[:, 2] - z
        rising = self.top[self.facet] > z + self.tolerance  # edges of facets that go on above z
        on = (np.abs(below) <= self.tolerance) & rising  # every vertex starts one edge of each of its facets
        crossing = (((below < -self.tolerance) & (above > self.tolerance))
                    | ((below > self.tolerance) & (above < -self.tolerance))) & rising
        if not (on.any() or crossing.any()):
            return 0.0
        start, end = self.start[crossing], self.end[crossing]
        w = (z - start[:, 2]) / (end[:, 2] - start[:, 2])
        point = np.concatenate([self.start[on, :2], start[:, :2] + w[:, None] * (end[:, :2] - start[:, :2])])
        facet = np.concatenate([self.facet[on], self.facet[crossing]])
        position = np.sum(point * self.along[facet], axis=1)
        first = np.full(len(self.along), np.inf)
        last = np.full(len(self.along), -np.inf)
        np.minimum.at(first, facet, position)
        np.maximum.at(last, facet, position)
        length = np.where(last > first, last - first, 0.0)
        return max(float(0.5 * np.sum((self.distance - self.rate * z) * length)), 0.0)  # a point's rounding: 0
