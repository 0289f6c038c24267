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

import math
from dataclasses import dataclass

import numpy as np

from parsim.core import sdbd
from parsim.core import structure
from parsim.core.sediment import (
    CONTACT_GAP_TOLERANCE,
    filling_height,
    packing_fraction,
    packing_fractions,
    union_volume_and_height,
)
from parsim.parameters import Parameter
from parsim.solver import LENGTH_UNITS, Coordinate, Statistic, coded_coordinate
from parsim.solvers.deposition_materials import mesh_approximation, mesh_volume

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
    every point of the area is at least ``wall_distance`` from every side.
    """

    lower: np.ndarray
    upper: np.ndarray
    periodic: bool
    measured: bool
    inside_fraction: float = 1.0
    wall_distance: float = 0.0
    disc: tuple | None = None

    def bulk_area(self) -> float:
        """Area of the bulk's horizontal section (0 when the walls leave no room for it)."""
        if self.disc is not None:
            return math.pi * max(self.disc[2] - self.wall_distance, 0.0) ** 2
        return float(np.prod(np.maximum(self.upper - self.lower - 2.0 * self.wall_distance, 0.0)))

    def in_bulk_area(self, xy: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Which points ``xy`` (n, 2) lie in the bulk's area at least ``margin`` from its edges (a periodic
        box has none)."""
        if self.periodic:
            return np.ones(len(xy), dtype=bool)
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


def measure(params, result, species, drops, geometry, skip, substrate) -> dict:
    """Every statistic of a finished task (``result``: :class:`parsim.core.sdbd.DepositionResult`,
    ``geometry``: the container as the kernel took it, ``substrate``: (centres, radii), empty without one)."""
    volume = np.array([s.volume for s in species])[drops.species] * drops.scale**3
    diameter = float(np.mean(np.array([s.equivalent_diameter for s in species])[drops.species] * drops.scale))
    region = measuring_region(params, geometry, result, diameter)
    heights = pile_heights(result.center_of_mass[:, 2], volume, substrate)
    slab = heights.bulk_slab()
    com = result.center_of_mass
    in_area = region.in_bulk_area(com[:, :2])
    in_bulk = in_area & (com[:, 2] >= slab[0]) & (com[:, 2] < slab[1])
    if len(substrate[1]):
        positions = np.concatenate([substrate[0], result.positions])
        radii = np.concatenate([substrate[1], result.radii])
        # the substrate is one more particle, index n, never in the bulk
        particle = np.concatenate([np.full(len(substrate[1]), len(drops.scale)), result.particle])
    else:
        positions, radii, particle = result.positions, result.radii, result.particle
    # a substrate sphere is in the bulk's area when its centre is, a deposited one when its particle's centre is
    sphere_in_area = np.concatenate([region.in_bulk_area(substrate[0][:, :2]), in_area[result.particle]])
    # one search of the sphere pairs gives the contacts and the spheres that overlap, whose overlaps alone
    # the packing fraction has to measure
    network = structure.contact_network(positions, radii, particle, region.lower, region.upper, region.periodic)
    statistics = {
        "filling_height": heights.filling,
        "substrate_height": heights.substrate,
        "bulk_wall_distance": region.wall_distance,
        **_packing(params, result, region, heights, drops, len(species), positions, radii, sphere_in_area,
                   network.overlapping),
        **mixture(result, species, drops, volume, heights),
        **_orientations(params, result, species, drops, in_bulk),
        "radial_distribution": _radial_distribution(params, com, diameter, region, slab),
        **_contacts(positions, radii, particle, region, in_bulk, network),
        "n_spheres": len(result.radii),
        "events_per_particle": float(result.event_counts.sum(axis=1).mean()),
        "largest_steps_per_particle": int(result.steps.max()),
        "hanging_particles": int(np.isin(result.state, HANGING).sum()),
        "particles_on_floor": particles_on_floor(result, CONTACT_GAP_TOLERANCE * float(np.mean(radii))),
    }
    counted_spheres = int(np.sum(result.particle >= skip))
    statistics["spheres_per_second"] = (counted_spheres / result.clocked_seconds if result.clocked_seconds > 0
                                        else np.nan)
    for name, kind in EVENT_TOTALS.items():
        statistics[name] = int(result.event_counts[:, sdbd.EVENT_KINDS.index(kind)].sum())
    return statistics


def measuring_region(params, geometry, result, diameter) -> Region:
    """The horizontal box over which packing and contacts are measured, and the bulk's area: with walls
    ``BULK_WALL_DIAMETERS`` times the mean volume-equivalent particle ``diameter`` away from them."""
    wall_distance = BULK_WALL_DIAMETERS * diameter
    if geometry.cylinder is not None:
        x, y, radius, sides = geometry.cylinder
        polygon = 0.5 * sides * radius**2 * math.sin(2.0 * math.pi / sides)
        return Region(geometry.lower, geometry.upper, False, True, polygon / (2.0 * radius) ** 2, wall_distance,
                      (x, y, radius * math.cos(math.pi / sides)))
    if params["lateral"] == "walls":
        return Region(geometry.lower, geometry.upper, False, True, wall_distance=wall_distance)
    if params["lateral"] == "periodic":
        return Region(geometry.lower, geometry.upper, True, True)
    reach = 2.0 * result.radii.max()  # so that periodic wrapping of the measurement meets no sphere twice
    return Region(result.positions[:, :2].min(axis=0) - 2.0 * reach,
                  result.positions[:, :2].max(axis=0) + 2.0 * reach, False, False)


def pile_heights(com_z, volume, substrate) -> Heights:
    """h = 2 z_cm of the particles (centres of mass ``com_z``, volumes ``volume``) and of the union of
    the substrate's spheres (section 4.1), and z_b = h V_substrate / (V_substrate + V_particles)."""
    if not len(substrate[1]):
        return Heights(filling_height(com_z, volume))
    substrate_volume, substrate_z = union_volume_and_height(*substrate)
    height = filling_height(np.append(com_z, substrate_z), np.append(volume, substrate_volume))
    return Heights(height, height * substrate_volume / (substrate_volume + float(volume.sum())))


def _packing(params, result, region, heights, drops, n_species, positions, radii, sphere_in_area,
             overlapping) -> dict:
    """Bulk packing fraction and the profiles phi(z), phi_s(z) of the container (substrate spheres count in
    the bulk and in phi(z)); ``sphere_in_area`` marks the spheres the bulk of a walled container counts,
    ``overlapping`` those that may overlap others (the others need no search for overlaps)."""
    bins = params["profile_bins"]
    if not region.measured:
        return {"bulk_packing_fraction": np.nan, "packing_profile": np.full(bins, np.nan),
                "species_packing_profile": np.full((n_species, bins), np.nan)}
    edges = np.linspace(0.0, PROFILE_TOP * heights.filling, bins + 1)
    slab = heights.bulk_slab()
    # in a periodic box the bulk is a slab of the whole box: measured in the same pass as the profile
    slabs = [slab, *zip(edges[:-1], edges[1:])] if region.periodic else list(zip(edges[:-1], edges[1:]))

    def profile(x, r, flags):
        return packing_fractions(x, r, region.lower, region.upper, slabs, samples=params["packing_samples"],
                                 overlapping=flags) / region.inside_fraction

    everything = profile(positions, radii, overlapping)
    bulk = (float(everything[0]) if region.periodic else
            _bulk_packing_fraction(positions[sphere_in_area], radii[sphere_in_area], region, slab,
                                   params["packing_samples"], overlapping[sphere_in_area]))
    if n_species == 1 and len(positions) == len(result.positions):  # one species, no substrate: phi_s = phi
        return {"bulk_packing_fraction": bulk, "packing_profile": everything[-bins:],
                "species_packing_profile": everything[None, -bins:]}
    sphere_species = drops.species[result.particle]
    deposited_overlapping = overlapping[len(positions) - len(result.positions):]  # after the substrate's spheres
    per_species = np.zeros((n_species, bins))
    for s in range(n_species):
        mine = sphere_species == s
        if mine.any():
            per_species[s] = profile(result.positions[mine], result.radii[mine], deposited_overlapping[mine])[-bins:]
    return {"bulk_packing_fraction": bulk, "packing_profile": everything[-bins:],
            "species_packing_profile": per_species}


def _bulk_packing_fraction(positions, radii, region, slab, samples, overlapping) -> float:
    """Packing fraction of the bulk of a walled container, box or cylinder (NaN when it has no room).

    The estimator: the spheres given (those of the particles whose centre of mass lies in the bulk's
    area, and the substrate spheres whose centre does), each with its exact volume in the slab (its
    whole horizontal extent; overlaps within a particle counted once), over the bulk's area times
    the slab's thickness. A sphere straddling the area's edge counts whole or not at all; for a
    packing that is statistically uniform across the area the estimate is unbiased (the selected
    centres are as dense as all centres: Campbell's theorem). The sum over the container's box, in
    which every sphere lies, so that the kernel's periodic sides never wrap a sphere. ``overlapping``
    flags the spheres that may overlap others."""
    area = region.bulk_area()
    if not area > 0.0:
        return np.nan
    if not len(radii):
        return 0.0
    box_area = float(np.prod(region.upper - region.lower))
    return (packing_fraction(positions, radii, region.lower, region.upper, *slab, samples, overlapping)
            * box_area / area)


def mixture(result, species, drops, volume, heights) -> dict:
    """Each species' count, volume share and mean height in the deposit, the segregation index, and the
    volumes of the species' particles and of the mesh fits."""
    count = np.bincount(drops.species, minlength=len(species))
    species_volume = np.bincount(drops.species, weights=volume, minlength=len(species))
    weighted_z = np.bincount(drops.species, weights=volume * result.center_of_mass[:, 2], minlength=len(species))
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_height = heights.in_deposit(weighted_z / species_volume)
    present = mean_height[count > 0]
    errors = [_mesh_error(s) for s in species]
    return {
        "species_particles": count,
        "species_volume_share": species_volume / species_volume.sum(),
        "species_mean_height": mean_height,
        "segregation_index": 2.0 * float(present.max() - present.min()) if len(present) > 1 else 0.0,
        "species_volume": np.array([s.volume for s in species]),
        "species_mesh_volume": np.array([mesh_volume(s.params) if s.params["shape"] == "mesh" else np.nan
                                         for s in species]),
        "species_mesh_volume_error": np.array([e[0] for e in errors]),
        "species_mesh_surface_distance": np.array([e[1] for e in errors]),
    }


def _mesh_error(s) -> tuple[float, float]:
    if s.params["shape"] != "mesh":
        return np.nan, np.nan
    error = mesh_approximation(s.params)
    return float(error.volume_error), float(error.relative_surface_distance)


def _orientations(params, result, species, drops, in_bulk) -> dict:
    """Orientation order and the distribution of the angle to the vertical of the bulk particles' long axes."""
    axes = long_axes(result, species, drops)[in_bulk]
    axes = axes[np.all(np.isfinite(axes), axis=1)]
    bins = params["orientation_bins"]
    if not len(axes):
        return {"nematic_order": np.nan, "vertical_order": np.nan, "orientation_density": np.full(bins, np.nan)}
    return {"nematic_order": structure.nematic_order(axes)[0], "vertical_order": structure.vertical_order(axes),
            "orientation_density": structure.angle_distribution(axes, bins)[1]}


def rdf_shells(params, diameter, region):
    """g(r)'s usable shells and range r_max (shells beyond half a periodic box's width are left out); None
    when none is left or the container has no room for a bulk."""
    bins = params["rdf_bins"]
    width = params["rdf_range"] * diameter / bins
    usable = bins
    if region.periodic:
        usable = min(bins, int(0.5 * float(np.min(region.upper - region.lower)) / width))
    return (usable, usable * width) if usable > 0 and region.bulk_area() > 0.0 else None


def _radial_distribution(params, centres, diameter, region, slab) -> np.ndarray:
    """g(r) of the bulk's centres of mass on the job's shells (r over the mean volume-equivalent
    ``diameter``); references lie at least r_max inside the bulk. Shells beyond half a periodic box's
    width (minimum images) are NaN, and all are when the container has no room for a bulk."""
    g = np.full(params["rdf_bins"], np.nan)
    shells = rdf_shells(params, diameter, region)
    if shells is not None:
        usable, r_max = shells
        z = centres[:, 2]
        in_bulk = (z >= slab[0]) & (z < slab[1]) & region.in_bulk_area(centres[:, :2])
        reference = np.flatnonzero((z >= slab[0] + r_max) & (z < slab[1] - r_max)
                                   & region.in_bulk_area(centres[:, :2], r_max))
        g[:usable] = structure.region_radial_distribution(centres, in_bulk, region.bulk_area() * (slab[1] - slab[0]),
                                                          reference, r_max, usable, region.lower, region.upper,
                                                          region.periodic, max_references=RDF_REFERENCES)[1]
    return g


def _contacts(positions, radii, particle, region, in_bulk, network=None) -> dict:
    """Coordination, contact numbers and fabric of the bulk particles, from one search of the
    sphere contacts between particles (periodic only across the sides of a periodic box): ``network``,
    the search :func:`measure` made, or a new one. ``particle`` numbers the substrate's spheres
    ``len(in_bulk)``."""
    if network is None:
        network = structure.contact_network(positions, radii, particle, region.lower, region.upper, region.periodic)
    pairs, normals = network.pairs, network.normals
    n = len(in_bulk)
    sphere_contacts = structure.sphere_contacts_per_particle(pairs, particle, n + 1)[:n]
    touched = structure.contacts_per_particle(pairs, particle, n + 1)[:n]
    bulk = np.append(in_bulk, False)  # the substrate is never in the bulk
    with_bulk = bulk[particle[pairs[:, 0]]] | bulk[particle[pairs[:, 1]]]
    count = int(in_bulk.sum())
    return {"bulk_coordination": float(sphere_contacts[in_bulk].mean()) if count else np.nan,
            "n_bulk_particles": count,
            "contact_number_fraction": structure.contact_number_distribution(touched, in_bulk, MAX_CONTACT_NUMBER),
            "fabric_tensor": structure.fabric_tensor(normals[with_bulk])}


def particles_on_floor(result, tolerance) -> int:
    """Particles with a sphere touching the floor, z - r <= ``tolerance``, whatever state they rest in (with
    floor = "roll" a particle on the floor rests on three contacts, the floor one of them)."""
    touching = result.positions[:, 2] - result.radii <= tolerance
    return int(np.unique(result.particle[touching]).size)


def long_axes(result, species, drops) -> np.ndarray:
    """Unit long axis of every particle in the lab frame (NaN rows for shapes without one)."""
    axes = np.full((len(drops.species), 3), np.nan)
    for index, s in enumerate(species):
        body_axis = structure.long_axis(s.offsets, s.radii)[0]
        mine = drops.species == index
        if np.all(np.isfinite(body_axis)) and mine.any():
            axes[mine] = structure.lab_axes(result.rotation[mine], body_axis)
    return axes


def _centres(edges: np.ndarray) -> np.ndarray:
    return 0.5 * (edges[1:] + edges[:-1])
