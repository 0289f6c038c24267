"""The statistics of a finished sediment, as the deposition solver's dataset variables.

- Topić & Pöschel (2016): filling height 2 z_cm (section 4.1), bulk packing fraction and
  profile phi(z), coordination between particles, the events of the special situations,
  and the efficiency (section 5);
- mixtures: each species' packing profile phi_s(z) (the profiles add up to phi(z) of the
  deposited particles), its share and mean height, and a segregation index;
- structure of the bulk (:mod:`parsim.core.structure`, each function cites its definition):
  orientation order of the particles' long axes, radial distribution function g(r) of the
  centres of mass, distribution of contact numbers and the fabric tensor of the contact
  normals.

Heights count from the floor z = 0. The filling height h is 2 z_cm of the whole pile: the
deposited particles and, with a substrate, the union of its spheres, each weighted by its
volume of material. The substrate's share of it, z_b = h V_substrate / (V_substrate +
V_particles), is the height its material would fill at the pile's mean packing; the deposit
is z_b ... h. This stays meaningful for a sparse substrate (a few boulders the deposit fills
around), which has no level top.

The bulk is the middle of the deposit, z_b + ``BULK_SLAB`` (h - z_b), away from floor,
substrate and surface; in a walled box or a cylinder it also keeps ``BULK_WALL_DIAMETERS``
mean volume-equivalent particle diameters from the walls (:class:`Region`). A particle is in
the bulk when its centre of mass is.
"""

import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from parsim.core import sdbd
from parsim.core import structure
from parsim.core.sediment import (
    CONTACT_GAP_TOLERANCE,
    SlabCover,
    covered_volumes,
    exact_sum,
    points_per_cap,
    sphere_keys,
    sum_expansion,
    union_volume_and_height,
)
from parsim.parameters import Parameter
from parsim.solver import LENGTH_UNITS, Coordinate, Statistic, coded_coordinate
from parsim.deposition.inside import ConvexInside
from parsim.deposition.materials import mesh_approximation, mesh_volume

BULK_SLAB = (0.25, 0.75)  # the bulk: this slab of the deposit, z_b + BULK_SLAB (h - z_b), away from floor and surface
# With walls the bulk keeps this many mean volume-equivalent particle diameters from them: there
# benchmarks/wall_packing.py finds sphere packings within 0.002 of the periodic box's.
BULK_WALL_DIAMETERS = 4.0
PROFILE_TOP = 1.25  # the profile phi(z) covers 0 <= z <= PROFILE_TOP x filling height
RDF_REFERENCES = 2000  # g(r) from at most this many reference centres (noise ~ 1/sqrt of it per shell)
MAX_CONTACT_NUMBER = 24  # the distribution of contact numbers counts 0 ... this
AXES = ("x", "y", "z")

# Upper bounds: g(r)'s search grows as rdf_range^3 (at 25 diameters, 10^4 neighbours per reference centre),
# and a distribution of more than 10^4 bins resolves nothing a sediment has
MAX_RDF_RANGE = 25.0
MAX_BINS = 10_000

PARAMETERS = (
    Parameter("rdf_range", float, 4.0, "1", "g(r) covers 0 < r <= rdf_range mean volume-equivalent diameters",
              low=0.0, low_inclusive=False, high=MAX_RDF_RANGE, sweepable=False),
    Parameter("rdf_bins", int, 80, "1", "number of shells of g(r)", low=1, high=MAX_BINS, sweepable=False),
    Parameter("orientation_bins", int, 18, "1", "number of bins of the angle of the long axes to the vertical "
              "over [0, 90] degrees", low=1, high=MAX_BINS, sweepable=False),
)

STATISTICS = (
    Statistic("filling_height", LENGTH_UNITS, "filling height h = 2 z_cm of the pile above the floor z = 0: the "
              "deposited particles and the union of the substrate's spheres, each weighted by its volume "
              "(section 4.1)"),
    Statistic("substrate_height", LENGTH_UNITS, "the substrate's share z_b = h V_substrate / (V_substrate + "
              "V_particles) of the filling height: the height its material fills at the pile's mean packing; the "
              "deposit lies between z_b and h (0 without substrate)"),
    Statistic("bulk_wall_distance", LENGTH_UNITS, "distance the bulk keeps from the walls of a walled box or a "
              f"cylinder, {BULK_WALL_DIAMETERS:g} mean volume-equivalent particle diameters (0 in a periodic box "
              "and on an open floor)"),
    Statistic("bulk_packing_fraction", "1", "packing fraction of the bulk, the middle half z_b + [0.25, 0.75] "
              "(h - z_b) of the deposit, substrate spheres included; with walls the spheres of the particles whose "
              "centre of mass lies bulk_wall_distance or more from them, each with its volume in the slab, over "
              "the area so bounded (NaN without lateral boundaries or when the container is too narrow for a bulk)"),
    Statistic("packing_profile", "1", "packing fraction phi(z) of horizontal slabs of the container, substrate "
              "spheres included (NaN without lateral boundaries)", dims=("z_relative",)),
    Statistic("bulk_coordination", "1", "mean number of sphere-sphere contacts with other particles, per "
              "particle with its centre of mass in the bulk"),
    Statistic("n_bulk_particles", "1", "particles with their centre of mass in the bulk", dtype="int64"),
    Statistic("n_spheres", "1", "spheres in the sediment", dtype="int64"),
    Statistic("events_per_particle", "1", "mean number of events per particle"),
    Statistic("largest_steps_per_particle", "1", "the most decide-and-move steps one particle needed (bounded "
              "by max_events_per_particle)", dtype="int64"),
    Statistic("frustrated_steps", "1", "trial rotations of frustrated situations (section 4.1)", dtype="int64"),
    Statistic("cycling_interruptions", "1", "interruptions of infinite cycling (section 4.2)", dtype="int64"),
    Statistic("simultaneous_events", "1", "simultaneous events (section 4.3)", dtype="int64"),
    Statistic("hanging_particles", "1", "particles hanging on one or two contacts", dtype="int64"),
    Statistic("particles_on_floor", "1", "particles touching the floor: a sphere with z - r within the contact "
              "gap tolerance (1e-6 mean radii), whatever the state they rest in", dtype="int64"),
    Statistic("spheres_per_second", "s-1", "spheres deposited per wall-clock second, first "
              "timing_skip_fraction of the particles left out (section 5)", measured=True),
    # mixtures
    Statistic("species_particles", "1", "particles of each species", dims=("species",), dtype="int64"),
    Statistic("species_volume_share", "1", "each species' share of the deposited particles' volume",
              dims=("species",)),
    Statistic("species_packing_profile", "1", "packing fraction phi_s(z) of each species' particles in the "
              "slabs of packing_profile; over the species they add up to phi(z) of the deposited particles "
              "(NaN without lateral boundaries)", dims=("species", "z_relative")),
    Statistic("species_mean_height", "1", "mean height of each species' centres of mass, weighted by particle "
              "volume, in the deposit: (<z>_s - z_b) / (h - z_b), z_b = substrate_height (1/2 for the whole deposit "
              "without substrate)", dims=("species",)),
    Statistic("segregation_index", "1", "2 (max_s <z>_s - min_s <z>_s) / (h - z_b), <z>_s the volume-weighted "
              "mean height of species s: 0 when the species are mixed, 1 when two lie in separate layers (up to 2 "
              "for many layers; 0 for one species)"),
    Statistic("species_volume", f"{LENGTH_UNITS}3", "volume of the union of a species' spheres at size factor 1",
              dims=("species",)),
    Statistic("species_mesh_volume", f"{LENGTH_UNITS}3", "volume enclosed by a mesh species' surface at size "
              "factor 1 (NaN for other shapes)", dims=("species",)),
    Statistic("species_mesh_volume_error", "1", "relative volume error (V_spheres - V_mesh) / V_mesh of a mesh "
              "species' spheres (NaN for other shapes)", dims=("species",)),
    Statistic("species_mesh_surface_distance", "1", "largest distance between a mesh species' surface and "
              "the surface of its spheres, over its volume-equivalent radius (NaN for other shapes)",
              dims=("species",)),
    # structure of the bulk
    Statistic("nematic_order", "1", "nematic order parameter S of the long axes of the bulk particles: the "
              "largest eigenvalue of <3/2 u u - 1/2 I> (de Gennes & Prost 1993); NaN for shapes without a long "
              "axis"),
    Statistic("vertical_order", "1", "<P2(cos theta)> of the angle theta between the long axes and the vertical: "
              "1 upright, -1/2 flat, 0 isotropic; NaN for shapes without a long axis"),
    Statistic("orientation_density", "rad-1", "probability density of the angle theta between a bulk particle's "
              "long axis and the vertical (sin theta for isotropic orientations)", dims=("angle_to_vertical",)),
    Statistic("radial_distribution", "1", "radial distribution function g(r) of the bulk particles' centres of "
              "mass, normalised to 1 for an ideal gas of the same density (Allen & Tildesley 2017, 2.6)",
              dims=("r_relative",)),
    Statistic("contact_number_fraction", "1", "fraction of the bulk particles touching Z distinct other "
              f"particles (Aste et al. 2005), Z = 0 ... {MAX_CONTACT_NUMBER}", dims=("contact_number",)),
    Statistic("fabric_tensor", "1", "fabric tensor <n n> of the unit normals of the sphere contacts between "
              "particles with a bulk particle, each contact once (Satake 1982); I/3 when isotropic",
              dims=("fabric_row", "fabric_column")),
)

HANGING = (sdbd.HANGING_ONE, sdbd.HANGING_TWO)
EVENT_TOTALS = {"frustrated_steps": "frustrated_trial_rotation", "cycling_interruptions": "cycling_interruption",
                "simultaneous_events": "simultaneous"}


@dataclass(frozen=True)
class Region:
    """Where the sediment is measured.

    ``lower``, ``upper``: the horizontal box of the measuring kernels, periodic or not (the
    container's box; a cylinder's bounding square; a heap's extent with a margin);
    ``inside_fraction``: the container's share of the box (the polygon's area over the square's for
    a cylinder); ``measured``: False for a heap, which has no packing fraction.

    The bulk's horizontal area: the whole periodic box (or a heap's box); with walls the box
    shrunk by ``wall_distance``; in a cylinder the disc of radius r_in - ``wall_distance`` about
    its axis, ``disc`` = (x, y, r_in) with r_in the inscribed radius of the wall's polygon, so that
    every point of the area is at least ``wall_distance`` from every side.  In a mesh vessel, whose
    section changes with height, the volumes are the vessel's own: ``inside`` is its inside and
    :attr:`bulk_inside` the points at least ``wall_distance`` from every face and wall
    (:class:`parsim.deposition.inside.ConvexInside`), both exact.
    """

    lower: np.ndarray
    upper: np.ndarray
    periodic: bool
    measured: bool
    inside_fraction: float = 1.0
    wall_distance: float = 0.0
    disc: tuple | None = None
    inside: ConvexInside | None = None

    @functools.cached_property
    def bulk_inside(self) -> ConvexInside | None:
        """A vessel's inside at least ``wall_distance`` from every face and wall (None for other containers)."""
        return None if self.inside is None else self.inside.shrunk(self.wall_distance)

    def has_bulk(self) -> bool:
        """Whether the walls leave room for a bulk (a vessel's inside widens upwards: room at some height is
        room between its two highest vertex heights)."""
        if self.bulk_inside is not None:
            heights = self.bulk_inside.vertex_heights(0.0)
            return len(heights) > 1 and self.bulk_inside.area_at(0.5 * float(heights[-2] + heights[-1])) > 0.0
        return self.bulk_area() > 0.0

    def bulk_area(self) -> float:
        """Area of the bulk's horizontal section (0 when the walls leave no room for it)."""
        if self.disc is not None:
            return math.pi * max(self.disc[2] - self.wall_distance, 0.0) ** 2
        return float(np.prod(np.maximum(self.upper - self.lower - 2.0 * self.wall_distance, 0.0)))

    def bulk_volume(self, low: float, high: float) -> float:
        """Volume of the bulk's region between heights ``low`` and ``high``."""
        if self.bulk_inside is not None:
            return self.bulk_inside.volume_between(low, high)
        return self.bulk_area() * (high - low)

    def layer_volumes(self, slabs: np.ndarray) -> np.ndarray:
        """Volume of the container in each slab (n, 2) of heights: the box's share ``inside_fraction``, or
        the vessel's inside."""
        if self.inside is not None:
            return np.array([self.inside.volume_between(low, high) for low, high in slabs])
        return float(np.prod(self.upper - self.lower)) * (slabs[:, 1] - slabs[:, 0]) * self.inside_fraction

    def in_bulk_area(self, points: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Which points (n, 3) lie over the bulk's area (in a vessel: in its bulk's region) at least
        ``margin`` from its edges (a periodic box has none)."""
        if self.periodic:
            return np.ones(len(points), dtype=bool)
        if self.bulk_inside is not None:
            return self.bulk_inside.contains(points, margin)
        xy = points[:, :2]
        reach = self.wall_distance + margin
        if self.disc is not None:
            x, y, radius = self.disc
            return np.hypot(xy[:, 0] - x, xy[:, 1] - y) <= radius - reach
        return np.all((xy >= self.lower + reach) & (xy <= self.upper - reach), axis=1)


@dataclass(frozen=True)
class Heights:
    """Heights of the pile above the floor z = 0: the filling height h and the substrate's share z_b of it."""

    filling: float
    substrate: float = 0.0

    def bulk_slab(self) -> tuple[float, float]:
        """The middle of the deposit, z_b + BULK_SLAB (h - z_b)."""
        thickness = self.filling - self.substrate
        return self.substrate + BULK_SLAB[0] * thickness, self.substrate + BULK_SLAB[1] * thickness

    def in_deposit(self, z):
        """Heights ``z`` over the deposit's thickness, (z - z_b) / (h - z_b): 0 at z_b, 1 at h."""
        return (z - self.substrate) / (self.filling - self.substrate)


def coordinates(constants: dict) -> dict[str, Coordinate]:
    """The observable coordinates, from what every point shares (fixed parameters, [[species]])."""
    bins = constants["profile_bins"]
    edges = np.linspace(0.0, PROFILE_TOP, bins + 1)
    r_edges = np.linspace(0.0, constants["rdf_range"], constants["rdf_bins"] + 1)
    angle_edges = np.linspace(0.0, 0.5 * np.pi, constants["orientation_bins"] + 1)
    return {
        "z_relative": Coordinate(_centres(edges), "1", "height of the slab centre over the filling height, z / h"),
        "species": coded_coordinate("species of the mixture", tuple(species_names(constants))),
        "r_relative": Coordinate(_centres(r_edges), "1", "centre distance over the mean volume-equivalent "
                                 "particle diameter, at the shell's middle"),
        "angle_to_vertical": Coordinate(_centres(angle_edges), "rad", "angle between a long axis and the vertical"),
        "contact_number": Coordinate(np.arange(MAX_CONTACT_NUMBER + 1), "1", "number of particles touched"),
        "fabric_row": coded_coordinate("row of the fabric tensor", AXES),
        "fabric_column": coded_coordinate("column of the fabric tensor", AXES),
    }


def species_names(constants: dict) -> list[str]:
    """The species coordinate: the [[species]] names; without them, the job's shape (or "particles"
    when the shape is swept)."""
    entries = constants.get("species")
    if entries:
        return [entry["name"] for entry in entries]
    return [constants.get("shape", "particles")]


@dataclass(frozen=True)
class Particles:
    """Particles as one rank holds them, or all of a serial task: global indices (ascending), centres of mass,
    sphere counts, and the spheres' centres and radii, particle after particle."""

    index: np.ndarray
    com: np.ndarray
    count: np.ndarray
    positions: np.ndarray
    radii: np.ndarray

    @classmethod
    def of_result(cls, result, index=None, count=None) -> "Particles":
        """The particles of a :class:`parsim.core.sdbd.DepositionResult`: a serial task's all, or a rank's share
        of a spread one, whose particles' drop ``index`` and sphere ``count`` it gives."""
        n = len(result.center_of_mass)
        if index is None:
            index, count = np.arange(n, dtype=np.int64), np.bincount(result.particle, minlength=n)
        return cls(np.asarray(index, dtype=np.int64), np.asarray(result.center_of_mass, dtype=np.float64).reshape(-1, 3),
                   np.asarray(count, dtype=np.int64), np.asarray(result.positions, dtype=np.float64).reshape(-1, 3),
                   np.asarray(result.radii, dtype=np.float64))

    def subset(self, chosen) -> "Particles":
        spheres = np.repeat(chosen, self.count)
        return Particles(self.index[chosen], self.com[chosen], self.count[chosen], self.positions[spheres],
                         self.radii[spheres])

    def row_of_sphere(self) -> np.ndarray:
        return np.repeat(np.arange(len(self.index)), self.count)

    def sphere_keys(self) -> np.ndarray:
        """The keys of the spheres (:func:`parsim.core.sediment.sphere_keys`): particle index and place in it."""
        first = np.repeat(np.cumsum(self.count) - self.count, self.count)
        return sphere_keys(np.repeat(self.index, self.count), first)


def local_sums(own: Particles, species, drops) -> dict:
    """What ``own`` particles (``drops``: their species and size factors) add to the sizes that steer the
    measurement and to the species' totals: counts, extremes, and exact sums (expansions,
    :func:`parsim.core.sediment.sum_expansion`) of the sphere radii, the volume-equivalent diameters, and
    each species' volume V and V z of the centres of mass."""
    diameters = np.array([s.equivalent_diameter for s in species])[drops.species] * drops.scale
    extents = np.array([s.extent for s in species])[drops.species] * drops.scale
    volume = np.array([s.volume for s in species])[drops.species] * drops.scale**3
    xy = own.positions[:, :2]
    by_species = [drops.species == k for k in range(len(species))]
    return {"particles": len(own.index), "spheres": len(own.radii), "radius": sum_expansion(own.radii),
            "diameter": sum_expansion(diameters), "largest_radius": float(own.radii.max(initial=0.0)),
            "span": 2.0 * float(extents.max(initial=0.0)),
            "low": xy.min(axis=0) if len(xy) else np.full(2, np.inf),
            "high": xy.max(axis=0) if len(xy) else np.full(2, -np.inf),
            "n_index": int(own.index.max(initial=-1)) + 1,
            "species_count": np.bincount(drops.species, minlength=len(species)).astype(np.int64),
            "species_volume": [sum_expansion(volume[mine]) for mine in by_species],
            "species_moment": [sum_expansion(volume[mine] * own.com[mine, 2]) for mine in by_species]}


@dataclass(frozen=True)
class Whole:
    """What the measurement needs of the whole sediment, the same on every rank that holds a part of it: from
    the parts' :func:`local_sums` (one part for a serial task), and then the number of bulk particles and
    of sampled overlap caps (:meth:`counted`). Sums of floats are exact and correctly rounded, so that they
    have the same bits however the sediment is split, and so the bulk, the slabs and g(r)'s shells."""

    params: dict
    species: tuple
    substrate: tuple
    region: Region
    heights: Heights
    n_particles: int
    n_index: int  # the largest particle index + 1
    mean_radius: float  # of every sphere, the substrate's included (the contact and floor tolerances)
    diameter: float  # mean volume-equivalent particle diameter
    largest_radius: float  # of the particles' spheres
    span: float  # the farthest two points of one particle (sphere centres, centre of mass) can be apart
    species_count: np.ndarray
    species_volume: np.ndarray  # sum of V per species
    species_moment: np.ndarray  # sum of V z_cm per species
    n_bulk: int = 0
    points: int = 0  # sample points per sampled overlap cap

    @classmethod
    def of(cls, params, species, geometry, substrate, parts) -> "Whole":
        column = {key: [part[key] for part in parts] for key in parts[0]}
        n_particles, n_spheres = sum(column["particles"]), sum(column["spheres"])
        substrate_radii = np.ascontiguousarray(substrate[1], dtype=np.float64)
        mean_radius = exact_sum(sum_expansion(substrate_radii), *column["radius"]) / (len(substrate_radii) + n_spheres)
        diameter = exact_sum(*column["diameter"]) / n_particles
        largest = max(column["largest_radius"])
        n_species = len(species)
        volume = np.array([exact_sum(*(part[k] for part in column["species_volume"])) for k in range(n_species)])
        moment = np.array([exact_sum(*(part[k] for part in column["species_moment"])) for k in range(n_species)])
        volume_total = exact_sum(*(e for part in column["species_volume"] for e in part))
        moment_total = exact_sum(*(e for part in column["species_moment"] for e in part))
        region = measuring_region(params, geometry, np.min(column["low"], axis=0), np.max(column["high"], axis=0),
                                  largest, diameter)
        heights = pile_heights(volume_total, moment_total, substrate, region.inside)
        return cls(params, tuple(species), substrate, region, heights, n_particles, max(column["n_index"]), mean_radius,
                   diameter, largest, max(column["span"]), np.sum(column["species_count"], axis=0), volume, moment)

    def counted(self, n_bulk, sampled_caps) -> "Whole":
        """With the number of bulk particles and of sampled overlap caps of every part."""
        slabs = len(self.measured_slabs())
        return replace(self, n_bulk=int(n_bulk),
                       points=points_per_cap(self.params["packing_samples"], slabs, int(sampled_caps)))

    def in_bulk(self, com) -> np.ndarray:
        """Which centres of mass ``com`` lie in the bulk (its area and slab)."""
        slab = self.heights.bulk_slab()
        return self.region.in_bulk_area(com) & (com[:, 2] >= slab[0]) & (com[:, 2] < slab[1])

    def contact_tolerance(self) -> float:
        return CONTACT_GAP_TOLERANCE * self.mean_radius

    def shells(self):
        """g(r)'s usable shells and range r_max, None when it has none."""
        return rdf_shells(self.params, self.diameter, self.region)

    def profile_slabs(self) -> np.ndarray:
        edges = np.linspace(0.0, PROFILE_TOP * self.heights.filling, self.params["profile_bins"] + 1)
        return np.column_stack([edges[:-1], edges[1:]])

    def measured_slabs(self) -> np.ndarray:
        """The slabs measured in one pass: in a periodic box the bulk's first, then the profile's."""
        profile = self.profile_slabs()
        return np.concatenate([[self.heights.bulk_slab()], profile]) if self.region.periodic else profile

    def rdf_candidates(self, com) -> np.ndarray:
        """Which centres of mass may be g(r)'s references: at least r_max inside the bulk."""
        shells = self.shells()
        if shells is None:
            return np.zeros(len(com), dtype=bool)
        r_max, slab = shells[1], self.heights.bulk_slab()
        return ((com[:, 2] >= slab[0] + r_max) & (com[:, 2] < slab[1] - r_max)
                & self.region.in_bulk_area(com, r_max))


@dataclass(frozen=True)
class MeasuredSpheres:
    """The spheres whose union a part measures: its particles' and, on one part, the substrate's (first), with
    their keys, the species of their particle (-1 for the substrate) and whether the bulk of a walled
    container counts them (a substrate sphere when its centre lies in the bulk's area, a particle's when its
    centre of mass does)."""

    positions: np.ndarray
    radii: np.ndarray
    keys: np.ndarray
    species: np.ndarray
    in_area: np.ndarray

    @classmethod
    def of(cls, whole, own, drops, with_substrate) -> "MeasuredSpheres":
        substrate = whole.substrate if with_substrate else (np.zeros((0, 3)), np.zeros(0))
        n_substrate = len(substrate[1])
        row = own.row_of_sphere()
        region = whole.region
        return cls(np.concatenate([substrate[0], own.positions]), np.concatenate([substrate[1], own.radii]),
                   np.concatenate([sphere_keys(np.full(n_substrate, whole.n_particles), np.zeros(n_substrate)),
                                   own.sphere_keys()]),
                   np.concatenate([np.full(n_substrate, -1), drops.species[row]]),
                   np.concatenate([region.in_bulk_area(substrate[0]), region.in_bulk_area(own.com[row])]))


def measure(params, result, species, drops, geometry, skip, substrate) -> dict:
    """Every statistic of a finished task (``result``: :class:`parsim.core.sdbd.DepositionResult`,
    ``geometry``: the container as the kernel took it, ``substrate``: (centres, radii), empty without one):
    :func:`combine` of the one part that is the whole sediment, the reduction a spread task makes over its
    ranks (:mod:`parsim.deposition.spread_statistics`)."""
    own = Particles.of_result(result)
    whole = Whole.of(params, species, geometry, substrate, [local_sums(own, species, drops)])
    region = whole.region
    in_bulk = whole.in_bulk(own.com)
    spheres = MeasuredSpheres.of(whole, own, drops, True)
    n = len(own.index)
    # the substrate is one more particle, row n, never in the bulk
    particle_row = np.concatenate([np.full(len(substrate[1]), n), own.row_of_sphere()])
    # one search of the sphere pairs gives the contacts and the spheres that overlap, whose overlaps alone
    # the packing fraction has to measure
    network = structure.contact_network(spheres.positions, spheres.radii, particle_row, region.lower, region.upper,
                                        region.periodic, mean_radius=whole.mean_radius)
    cover = packing_cover(whole, spheres, network.overlapping, region.lower, region.upper)
    whole = whole.counted(int(in_bulk.sum()), cover.sampled_caps if cover is not None else 0)
    candidates = np.flatnonzero(whole.rdf_candidates(own.com))
    references = candidates[structure.evenly_spaced(len(candidates), RDF_REFERENCES)] \
        if len(candidates) > RDF_REFERENCES else candidates
    part = {**contact_part(network.pairs, network.normals, particle_row, np.ones(n, dtype=bool), in_bulk),
            **rdf_part(whole, own.com, references, region.lower, region.upper),
            "packing": packing_part(whole, spheres, network.overlapping, cover, region.lower, region.upper),
            **axis_part(whole, result.rotation, drops, in_bulk),
            **count_part(whole, own, result, skip)}
    return combine(whole, [part])


def measuring_region(params, geometry, lowest_xy, highest_xy, largest_radius, diameter) -> Region:
    """The horizontal box over which packing and contacts are measured, and the bulk's area: with walls
    ``BULK_WALL_DIAMETERS`` times the mean volume-equivalent particle ``diameter`` away from them (a heap's box:
    around the sediment's spheres, whose centres' extremes are ``lowest_xy``, ``highest_xy``)."""
    wall_distance = BULK_WALL_DIAMETERS * diameter
    if geometry.cylinder is not None:
        x, y, radius, sides = geometry.cylinder
        polygon = 0.5 * sides * radius**2 * math.sin(2.0 * math.pi / sides)
        return Region(geometry.lower, geometry.upper, False, True, polygon / (2.0 * radius) ** 2, wall_distance,
                      (x, y, radius * math.cos(math.pi / sides)))
    if params["container"] == "mesh":
        inside = geometry.vessel.convex_inside()
        return Region(geometry.lower, geometry.upper, False, True, wall_distance=wall_distance, inside=inside)
    if params["lateral"] == "walls":
        return Region(geometry.lower, geometry.upper, False, True, wall_distance=wall_distance)
    if params["lateral"] == "periodic":
        return Region(geometry.lower, geometry.upper, True, True)
    reach = 2.0 * largest_radius  # so that periodic wrapping of the measurement meets no sphere twice
    return Region(lowest_xy - 2.0 * reach, highest_xy + 2.0 * reach, False, False)


def pile_heights(volume, moment, substrate, inside=None) -> Heights:
    """h = 2 z_cm of the particles (their total volume ``volume`` and first moment ``moment`` = sum V z_cm) and
    of the union of the substrate's spheres (section 4.1), and z_b = h V_substrate / (V_substrate +
    V_particles); the sums exact, correctly rounded.  In a vessel whose section changes with height
    (``inside``, a :class:`parsim.deposition.inside.ConvexInside`), h is the height to which the vessel filled
    uniformly has its centre of mass at z_cm, and z_b the height below which it holds the substrate's share
    of that filling: both 2 z_cm and h V_substrate / V in a constant section."""
    if not len(substrate[1]):
        substrate_volume, total, centre = 0.0, volume, moment / volume
    else:
        substrate_volume, substrate_z = union_volume_and_height(*substrate)
        total = exact_sum([volume, substrate_volume])
        centre = exact_sum([moment, substrate_volume * substrate_z]) / total
    if inside is None:
        return Heights(2.0 * centre, 2.0 * centre * substrate_volume / total)
    height = inside.filled_height(centre)
    if not substrate_volume:
        return Heights(height)
    return Heights(height, inside.height_holding(inside.volume_between(0.0, height) * substrate_volume / total,
                                                 height))


def packing_cover(whole, spheres, overlapping, lower, upper):
    """The :class:`parsim.core.sediment.SlabCover` of ``spheres`` (:class:`MeasuredSpheres`, ``overlapping``:
    their flags) on the measured slabs, laid over the box ``lower`` ... ``upper``; None when the container has
    no packing fraction or the part no sphere."""
    if not whole.region.measured or not len(spheres.radii):
        return None
    return SlabCover(spheres.positions, spheres.radii, lower, upper, np.unique(whole.measured_slabs()), overlapping,
                     spheres.keys, whole.mean_radius)


def packing_part(whole, spheres, overlapping, cover, lower, upper):
    """A part's volumes of the union of its ``spheres`` (``cover``: their :func:`packing_cover`): in the bulk slab
    (with walls, of the spheres in the bulk's area), in the profile's slabs, and in the profile's slabs of each
    species' spheres, one after the other; every sampled cap with the points per cap of the whole. None when
    the container has no packing fraction."""
    if not whole.region.measured:
        return None
    profile, measured = whole.profile_slabs(), whole.measured_slabs()
    n_species, bins = len(whole.species), len(profile)
    volumes = np.zeros(1 + (1 + n_species) * bins)
    if cover is None:
        return volumes
    region = whole.region

    def covered(chosen, slabs):
        if not chosen.any():
            return np.zeros(len(slabs))
        return covered_volumes(spheres.positions[chosen], spheres.radii[chosen], lower, upper, slabs,
                               overlapping=overlapping[chosen], keys=spheres.keys[chosen], points=whole.points,
                               mean_radius=whole.mean_radius)

    everything = cover.covered(measured, whole.points)
    bulk = np.array([whole.heights.bulk_slab()])
    volumes[0] = everything[0] if region.periodic else covered(spheres.in_area, bulk)[0]
    volumes[1:1 + bins] = everything[-bins:]
    deposited_only = not len(whole.substrate[1])
    for s in range(n_species):
        part = everything if n_species == 1 and deposited_only else covered(spheres.species == s, measured)
        volumes[(1 + s) * bins + 1:(2 + s) * bins + 1] = part[-bins:]
    return volumes


def contact_part(pairs, normals, particle_row, own, in_bulk) -> dict:
    """A part's share of the contact statistics, from the sphere contacts ``pairs`` (and ``normals``) of the
    spheres it searched, ``particle_row`` of each (the substrate's: the number of particles), ``own``: the
    particles whose contact numbers it counts (it must have searched every sphere near them), ``in_bulk``:
    which particles lie in the bulk. Its own bulk particles' number, sphere contacts and histogram of
    contact numbers; and the exact sums of n n over the contacts with a bulk particle whose lower particle
    row is its own (each contact once over the parts)."""
    cap = MAX_CONTACT_NUMBER
    n = len(in_bulk)
    mine = own & in_bulk
    owners = particle_row[pairs].reshape(-1, 2)
    bulk = np.append(in_bulk, False)  # the substrate is never in the bulk
    counted = np.append(own, False)[owners.min(axis=1)] & (bulk[owners[:, 0]] | bulk[owners[:, 1]])
    touched = structure.contacts_per_particle(pairs, particle_row, n + 1)[:n]
    unit = normals[counted] / np.linalg.norm(normals[counted], axis=1)[:, None] if counted.any() else np.zeros((0, 3))
    return {"bulk": int(mine.sum()),
            "sphere_contacts": int(structure.sphere_contacts_per_particle(pairs, particle_row, n + 1)[:n][mine].sum()),
            "contact_numbers": np.bincount(touched[mine], minlength=cap + 1)[:cap + 1].astype(np.int64),
            "fabric": [sum_expansion(unit[:, a] * unit[:, b]) for a in range(3) for b in range(3)],
            "fabric_contacts": int(counted.sum())}


def rdf_part(whole, centres, references, lower, upper, period=None) -> dict:
    """A part's share of g(r): its number of ``references`` (indices into ``centres``, every centre within r_max
    of them among ``centres``) and their pairs in g(r)'s shells (:func:`parsim.core.structure.shell_counts`
    over the box ``lower`` ... ``upper``, a window of the periodic box of ``period`` when given)."""
    shells = whole.shells()
    if shells is None or not len(references):
        return {"references": 0, "shell_counts": np.zeros(shells[0] if shells else 0, dtype=np.int64)}
    bins, r_max = shells
    counts = structure.shell_counts(centres, references, r_max, bins, lower, upper, whole.region.periodic, period)
    return {"references": len(references), "shell_counts": counts}


def axis_part(whole, rotation, drops, in_bulk) -> dict:
    """A part's share of the orientation statistics: of its bulk particles' long axes u their number, the exact
    sums of u u and of P2(u_z), and the histogram of the angle to the vertical."""
    bins = whole.params["orientation_bins"]
    axes = long_axes(rotation, whole.species, drops)[in_bulk]
    axes = axes[np.all(np.isfinite(axes), axis=1)]
    unit = axes / np.linalg.norm(axes, axis=1)[:, None] if len(axes) else np.zeros((0, 3))
    return {"axes": len(axes), "moment": [sum_expansion(unit[:, a] * unit[:, b]) for a in range(3) for b in range(3)],
            "p2": sum_expansion(1.5 * unit[:, 2] ** 2 - 0.5),
            "angles": (structure.angle_histogram(axes, bins)[1].astype(np.int64) if len(axes)
                       else np.zeros(bins, dtype=np.int64))}


def count_part(whole, own, settled, skip) -> dict:
    """A part's counts: spheres, events, the most steps, hanging particles, particles on the floor, the spheres
    timed (the particles from ``skip`` on) and the clock (``settled``: the particles' state, event counts and
    steps, and the clocked seconds)."""
    events = np.asarray(settled.event_counts, dtype=np.int64).reshape(-1, len(sdbd.EVENT_KINDS))
    floor = particles_on_floor(own.positions, own.radii, own.row_of_sphere(), whole.contact_tolerance())
    return {"spheres": len(own.radii), "events": events.sum(axis=0), "steps": int(np.max(settled.steps, initial=0)),
            "hanging": int(np.isin(settled.state, HANGING).sum()), "on_floor": floor,
            "timed_spheres": int(np.sum(np.repeat(own.index, own.count) >= skip)),
            "clocked_seconds": settled.clocked_seconds}


def combine(whole, parts) -> dict:
    """The statistics of the whole sediment from the parts' sums (in the parts' order: the same on every rank;
    integers are summed exactly, floats that steer or need it as exact sums)."""

    def total(key):
        return np.sum(np.stack([np.asarray(part[key]) for part in parts]), axis=0)

    def exact(key):
        return np.array([exact_sum(*(part[key][k] for part in parts)) for k in range(len(parts[0][key]))])

    n = whole.n_particles
    events = total("events")
    clocked = parts[0]["clocked_seconds"]  # a spread sediment's clock is its first rank's
    statistics = {
        "filling_height": whole.heights.filling,
        "substrate_height": whole.heights.substrate,
        "bulk_wall_distance": whole.region.wall_distance,
        **_packing(whole, parts),
        **mixture(whole),
        **_orientations(parts, total, exact),
        "radial_distribution": _radial_distribution(whole, total),
        **_contacts(total, exact),
        "n_spheres": int(total("spheres")),
        "events_per_particle": int(events.sum()) / n,
        "largest_steps_per_particle": int(max(part["steps"] for part in parts)),
        "hanging_particles": int(total("hanging")),
        "particles_on_floor": int(total("on_floor")),
        "spheres_per_second": int(total("timed_spheres")) / clocked if clocked > 0 else np.nan,
    }
    for name, kind in EVENT_TOTALS.items():
        statistics[name] = int(events[sdbd.EVENT_KINDS.index(kind)])
    return statistics


def _packing(whole, parts) -> dict:
    """Bulk packing fraction and the profiles phi(z), phi_s(z) from the parts' covered volumes."""
    region = whole.region
    bins, n_species = whole.params["profile_bins"], len(whole.species)
    if not region.measured:
        return {"bulk_packing_fraction": np.nan, "packing_profile": np.full(bins, np.nan),
                "species_packing_profile": np.full((n_species, bins), np.nan)}
    volumes = np.sum(np.stack([part["packing"] for part in parts]), axis=0)
    profile = whole.profile_slabs()
    slab = whole.heights.bulk_slab()
    layers = region.layer_volumes(profile)
    if region.periodic:
        fraction = volumes[0] / region.layer_volumes(np.array([slab]))[0]
    else:
        # the spheres of the particles in the bulk's area, each with its whole horizontal extent, over that
        # area: unbiased for a packing statistically uniform across it (the selected centres are as dense as
        # all centres: Campbell's theorem); in a vessel, whose bulk's section changes with height, unbiased
        # where that section's area is linear in z over a particle's height (quadratic terms leave a bias
        # of order (particle height / vessel width)^2)
        bulk = region.bulk_volume(*slab)
        fraction = volumes[0] / bulk if bulk > 0.0 else np.nan
    return {"bulk_packing_fraction": float(fraction), "packing_profile": volumes[1:bins + 1] / layers,
            "species_packing_profile": volumes[bins + 1:].reshape(n_species, bins) / layers}


def mixture(whole) -> dict:
    """Each species' count, volume share and mean height in the deposit, the segregation index, and the
    volumes of the species' particles and of the mesh fits (from the whole's exact species sums)."""
    count, volume, moment = whole.species_count, whole.species_volume, whole.species_moment
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_height = whole.heights.in_deposit(moment / volume)
    present = mean_height[count > 0]
    errors = [_mesh_error(s) for s in whole.species]
    return {
        "species_particles": count.astype(np.int64),
        "species_volume_share": volume / exact_sum(volume),
        "species_mean_height": mean_height,
        "segregation_index": 2.0 * float(present.max() - present.min()) if len(present) > 1 else 0.0,
        "species_volume": np.array([s.volume for s in whole.species]),
        "species_mesh_volume": np.array([mesh_volume(s.params) if s.params["shape"] == "mesh" else np.nan
                                         for s in whole.species]),
        "species_mesh_volume_error": np.array([e[0] for e in errors]),
        "species_mesh_surface_distance": np.array([e[1] for e in errors]),
    }


def _mesh_error(s) -> tuple[float, float]:
    if s.params["shape"] != "mesh":
        return np.nan, np.nan
    error = mesh_approximation(s.params)
    return float(error.volume_error), float(error.relative_surface_distance)


def _orientations(parts, total, exact) -> dict:
    """Nematic order, <P2> and the density of the angle to the vertical of the bulk particles' long axes (the
    density from the summed histogram as numpy's histogram makes it)."""
    n = int(total("axes"))
    angles = total("angles")
    if not n:
        return {"nematic_order": np.nan, "vertical_order": np.nan, "orientation_density": np.full(len(angles), np.nan)}
    order = np.linalg.eigh(structure.order_tensor(exact("moment").reshape(3, 3), n))[0][-1]
    width = np.diff(np.linspace(0.0, 0.5 * np.pi, len(angles) + 1))
    return {"nematic_order": float(order), "vertical_order": exact_sum(*(part["p2"] for part in parts)) / n,
            "orientation_density": angles / width / n}


def rdf_shells(params, diameter, region):
    """g(r)'s usable shells and range r_max (shells beyond half a periodic box's width are left out); None
    when none is left or the container has no room for a bulk."""
    bins = params["rdf_bins"]
    width = params["rdf_range"] * diameter / bins
    usable = bins
    if region.periodic:
        usable = min(bins, int(0.5 * float(np.min(region.upper - region.lower)) / width))
    return (usable, usable * width) if usable > 0 and region.has_bulk() else None


def _radial_distribution(whole, total) -> np.ndarray:
    """g(r) on the job's shells from the parts' pair counts about their references, with the bulk's density
    (:func:`parsim.core.structure.shell_density`); NaN beyond the usable shells and without references."""
    g = np.full(whole.params["rdf_bins"], np.nan)
    shells = whole.shells()
    references = int(total("references"))
    if shells is not None and references:
        slab = whole.heights.bulk_slab()
        g[:shells[0]] = structure.shell_density(total("shell_counts"), references, whole.n_bulk,
                                                whole.region.bulk_volume(*slab), shells[1])
    return g


def _contacts(total, exact) -> dict:
    """Coordination, contact numbers and fabric of the bulk particles from the parts' sums."""
    bulk, contacts = int(total("bulk")), int(total("fabric_contacts"))
    cap = MAX_CONTACT_NUMBER
    return {"bulk_coordination": int(total("sphere_contacts")) / bulk if bulk else np.nan,
            "n_bulk_particles": bulk,
            "contact_number_fraction": total("contact_numbers") / bulk if bulk else np.full(cap + 1, np.nan),
            "fabric_tensor": exact("fabric").reshape(3, 3) / contacts if contacts else np.full((3, 3), np.nan)}


def particles_on_floor(positions, radii, particle, tolerance) -> int:
    """Particles with a sphere touching the floor, z - r <= ``tolerance``, whatever state they rest in (with
    floor = "roll" a particle on the floor rests on three contacts, the floor one of them); ``particle``: the
    particle of each sphere."""
    touching = positions[:, 2] - radii <= tolerance
    return int(np.unique(particle[touching]).size)


def long_axes(rotation, species, drops) -> np.ndarray:
    """Unit long axis of every particle in the lab frame, turned by its ``rotation`` quaternion (NaN rows for
    shapes without one)."""
    axes = np.full((len(drops.species), 3), np.nan)
    for index, s in enumerate(species):
        body_axis = structure.long_axis(s.offsets, s.radii)[0]
        mine = drops.species == index
        if np.all(np.isfinite(body_axis)) and mine.any():
            axes[mine] = structure.lab_axes(rotation[mine], body_axis)
    return axes


def _centres(edges: np.ndarray) -> np.ndarray:
    return 0.5 * (edges[1:] + edges[:-1])
