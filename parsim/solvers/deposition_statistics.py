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

The bulk is the slab ``BULK_SLAB`` of the filling height, away from floor and surface.
"""

import math
from dataclasses import dataclass

import numpy as np

from parsim.core import sdbd
from parsim.core import structure
from parsim.core.sediment import filling_height, packing_fractions
from parsim.parameters import Parameter
from parsim.solver import LENGTH_UNITS, Coordinate, Statistic, coded_coordinate
from parsim.solvers.deposition_materials import mesh_approximation

BULK_SLAB = (0.25, 0.75)  # the bulk: this slab of the filling height, away from floor and surface
PROFILE_TOP = 1.25  # the profile phi(z) covers 0 <= z <= PROFILE_TOP x filling height
RDF_REFERENCES = 2000  # g(r) from at most this many reference centres (noise ~ 1/sqrt of it per shell)
MAX_CONTACT_NUMBER = 24  # the distribution of contact numbers counts 0 ... this
AXES = ("x", "y", "z")

PARAMETERS = (
    Parameter("rdf_range", float, 4.0, "1", "g(r) covers 0 < r <= rdf_range mean volume-equivalent diameters",
              low=0.0, low_inclusive=False, sweepable=False),
    Parameter("rdf_bins", int, 80, "1", "number of shells of g(r)", low=1, sweepable=False),
    Parameter("orientation_bins", int, 18, "1", "number of bins of the angle of the long axes to the vertical "
              "over [0, 90] degrees", low=1, sweepable=False),
)

STATISTICS = (
    Statistic("filling_height", LENGTH_UNITS, "filling height 2 z_cm, particles weighted by volume (section 4.1)"),
    Statistic("bulk_packing_fraction", "1", "packing fraction between 0.25 and 0.75 of the filling height "
              "(NaN without lateral boundaries)"),
    Statistic("packing_profile", "1", "packing fraction phi(z) of horizontal slabs (NaN without lateral "
              "boundaries)", dims=("z_relative",)),
    Statistic("bulk_coordination", "1", "mean number of sphere-sphere contacts with other particles, per "
              "particle with its centre of mass in the bulk slab"),
    Statistic("n_bulk_particles", "1", "particles in the bulk slab", dtype="int64"),
    Statistic("n_spheres", "1", "spheres in the sediment", dtype="int64"),
    Statistic("events_per_particle", "1", "mean number of events per particle"),
    Statistic("largest_steps_per_particle", "1", "the most decide-and-move steps one particle needed (bounded "
              "by max_events_per_particle)", dtype="int64"),
    Statistic("frustrated_steps", "1", "trial rotations of frustrated situations (section 4.1)", dtype="int64"),
    Statistic("cycling_interruptions", "1", "interruptions of infinite cycling (section 4.2)", dtype="int64"),
    Statistic("simultaneous_events", "1", "simultaneous events (section 4.3)", dtype="int64"),
    Statistic("hanging_particles", "1", "particles hanging on one or two contacts", dtype="int64"),
    Statistic("particles_on_floor", "1", "particles resting on the floor", dtype="int64"),
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
              "volume, over the filling height (1/2 for the whole sediment)", dims=("species",)),
    Statistic("segregation_index", "1", "2 (max_s <z>_s - min_s <z>_s) / h, <z>_s the volume-weighted mean "
              "height of species s: 0 when the species are mixed, 1 when two lie in separate layers (up to 2 for "
              "many layers; 0 for one species)"),
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

STATE_COUNTS = {"hanging_particles": (sdbd.HANGING_ONE, sdbd.HANGING_TWO), "particles_on_floor": (sdbd.RESTING_ON_FLOOR,)}
EVENT_TOTALS = {"frustrated_steps": "frustrated_trial_rotation", "cycling_interruptions": "cycling_interruption",
                "simultaneous_events": "simultaneous"}


@dataclass(frozen=True)
class Region:
    """Where the sediment is measured: the horizontal box (periodic or not) and the fraction of it
    inside the container (1 for a box, the polygon's area over the square's for a cylinder)."""

    lower: np.ndarray
    upper: np.ndarray
    periodic: bool
    measured: bool  # False for a heap: no packing fraction
    inside_fraction: float = 1.0


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
    ``geometry``: the container as the kernel took it)."""
    region = measuring_region(params, geometry, result)
    volume = np.array([s.volume for s in species])[drops.species] * drops.scale**3
    height = filling_height(result.center_of_mass[:, 2], volume)
    slab = (BULK_SLAB[0] * height, BULK_SLAB[1] * height)
    in_bulk = (result.center_of_mass[:, 2] >= slab[0]) & (result.center_of_mass[:, 2] < slab[1])
    positions = np.concatenate([substrate[0], result.positions])
    radii = np.concatenate([substrate[1], result.radii])
    # the substrate is one more particle, index n, never in the bulk
    particle = np.concatenate([np.full(len(substrate[1]), len(drops.scale)), result.particle])
    statistics = {
        "filling_height": height,
        **_packing(params, result, region, height, slab, drops, len(species), positions, radii),
        **_mixture(result, species, drops, volume, height),
        **_orientations(params, result, species, drops, in_bulk),
        "radial_distribution": _radial_distribution(params, result, species, drops, region, slab),
        **_contacts(positions, radii, particle, region, in_bulk),
        "n_spheres": len(result.radii),
        "events_per_particle": float(result.event_counts.sum(axis=1).mean()),
        "largest_steps_per_particle": int(result.steps.max()),
    }
    counted_spheres = int(np.sum(result.particle >= skip))
    statistics["spheres_per_second"] = (counted_spheres / result.clocked_seconds if result.clocked_seconds > 0
                                        else np.nan)
    for name, kind in EVENT_TOTALS.items():
        statistics[name] = int(result.event_counts[:, sdbd.EVENT_KINDS.index(kind)].sum())
    for name, states in STATE_COUNTS.items():
        statistics[name] = int(np.isin(result.state, states).sum())
    return statistics


def measuring_region(params, geometry, result) -> Region:
    """The horizontal box over which packing and contacts are measured."""
    if geometry.cylinder is not None:
        _, _, radius, sides = geometry.cylinder
        polygon = 0.5 * sides * radius**2 * math.sin(2.0 * math.pi / sides)
        return Region(geometry.lower, geometry.upper, False, True, polygon / (2.0 * radius) ** 2)
    if params["lateral"] != "none":
        return Region(geometry.lower, geometry.upper, params["lateral"] == "periodic", True)
    reach = 2.0 * result.radii.max()  # so that periodic wrapping of the measurement meets no sphere twice
    return Region(result.positions[:, :2].min(axis=0) - 2.0 * reach,
                             result.positions[:, :2].max(axis=0) + 2.0 * reach, False, False)


def _packing(params, result, region, height, slab, drops, n_species, positions, radii) -> dict:
    """Bulk packing fraction and the profiles phi(z), phi_s(z) (substrate spheres count in phi(z))."""
    bins = params["profile_bins"]
    if not region.measured:
        return {"bulk_packing_fraction": np.nan, "packing_profile": np.full(bins, np.nan),
                "species_packing_profile": np.full((n_species, bins), np.nan)}
    edges = np.linspace(0.0, PROFILE_TOP * height, bins + 1)
    slabs = [slab, *zip(edges[:-1], edges[1:])]

    def fractions(x, r):
        return packing_fractions(x, r, region.lower, region.upper, slabs,
                                 samples=params["packing_samples"]) / region.inside_fraction

    everything = fractions(positions, radii)
    if n_species == 1 and len(positions) == len(result.positions):  # one species, no substrate: phi_s = phi
        return {"bulk_packing_fraction": float(everything[0]), "packing_profile": everything[1:],
                "species_packing_profile": everything[None, 1:]}
    sphere_species = drops.species[result.particle]
    per_species = np.zeros((n_species, bins))
    for s in range(n_species):
        mine = sphere_species == s
        if mine.any():
            per_species[s] = fractions(result.positions[mine], result.radii[mine])[1:]
    return {"bulk_packing_fraction": float(everything[0]), "packing_profile": everything[1:],
            "species_packing_profile": per_species}


def _mixture(result, species, drops, volume, height) -> dict:
    count = np.bincount(drops.species, minlength=len(species))
    species_volume = np.bincount(drops.species, weights=volume, minlength=len(species))
    weighted_z = np.bincount(drops.species, weights=volume * result.center_of_mass[:, 2], minlength=len(species))
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_height = weighted_z / species_volume / height
    present = mean_height[count > 0]
    errors = [_mesh_error(s) for s in species]
    return {
        "species_particles": count,
        "species_volume_share": species_volume / species_volume.sum(),
        "species_mean_height": mean_height,
        "segregation_index": 2.0 * float(present.max() - present.min()) if len(present) > 1 else 0.0,
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
    axes = _long_axes(result, species, drops)[in_bulk]
    axes = axes[np.all(np.isfinite(axes), axis=1)]
    bins = params["orientation_bins"]
    if not len(axes):
        return {"nematic_order": np.nan, "vertical_order": np.nan, "orientation_density": np.full(bins, np.nan)}
    return {"nematic_order": structure.nematic_order(axes)[0], "vertical_order": structure.vertical_order(axes),
            "orientation_density": structure.angle_distribution(axes, bins)[1]}


def _radial_distribution(params, result, species, drops, region, slab) -> np.ndarray:
    """g(r) on the job's shells (r over the mean volume-equivalent diameter); shells beyond half a
    periodic box's width (minimum images) are NaN."""
    diameters = np.array([s.equivalent_diameter for s in species])[drops.species] * drops.scale
    bins = params["rdf_bins"]
    width = params["rdf_range"] * float(diameters.mean()) / bins
    usable = bins
    if region.periodic:
        usable = min(bins, int(0.5 * float(np.min(region.upper - region.lower)) / width))
    g = np.full(bins, np.nan)
    if usable > 0:
        g[:usable] = structure.radial_distribution(result.center_of_mass, region.lower, region.upper,
                                                   region.periodic, *slab, usable * width, usable,
                                                   max_references=RDF_REFERENCES)[1]
    return g


def _contacts(positions, radii, particle, region, in_bulk) -> dict:
    """Coordination, contact numbers and fabric of the bulk particles, from one search of the
    sphere contacts between particles (periodic only across the sides of a periodic box).
    ``particle`` numbers the substrate's spheres ``len(in_bulk)``."""
    pairs, normals = structure.contact_pairs(positions, radii, particle, region.lower, region.upper,
                                             region.periodic)
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


def _long_axes(result, species, drops) -> np.ndarray:
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
