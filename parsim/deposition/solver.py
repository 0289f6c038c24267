"""Sequential deposition of rigid multi-sphere particles (Topić & Pöschel 2016).

One task: ``n_particles`` particles of one shape or of a mixture of species
(:mod:`.materials`: each scaled by a factor from its size distribution, turned by
a uniformly random rotation, released at a random horizontal position above the sediment)
follow the steepest descent of their centre of mass with the event-driven algorithm of
sections 3 and 4, in a periodic or walled box, a cylinder or on an open floor, onto the
floor or a fixed substrate; then the sediment's statistics are measured
(:mod:`.statistics`).

With ``parsim run --ranks-per-task K > 1`` a task's sediment is spread over its group's K ranks
(:mod:`parsim.deposition.spread`), bitwise the serial sediment, and stays spread: its statistics
are reduced over the ranks (:mod:`parsim.deposition.spread_statistics`) and each rank writes its
particles to its own file, joined by the task file (:mod:`parsim.output.snapshot`).
"""

import copy
import math
import os
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from parsim.agglomerate_file import read_agglomerate
from parsim.core import sdbd
from parsim.core import shapes as shape_library
from parsim.core.sediment import MAX_POINTS_PER_CAP
from parsim.errors import JobError, NumericalError
from parsim.machine import check_memory
from parsim.parameters import LARGEST_QUANTITY, REQUIRED, Parameter
from parsim.phases import phase
from parsim.progress import settled_reporter
from parsim.solver import LENGTH_UNITS, Configuration, Solver, TableArray, TaskResult
from parsim.deposition import statistics
from parsim.deposition.vessel import Vessel, read_vessel
from parsim.deposition.materials import (
    SPECIES_KEYS,
    Drops,
    Species,
    check_species,
    ParticleDraws,
    species_of,
    species_parameters,
    species_shape,
)

SHAPES = ("sphere", "rod", "four_rods", "tripod", "spiky", "cube", "ellipsoid", "superellipsoid", "agglomerate",
          "mesh")
CONTAINERS = ("box", "cylinder", "mesh")
LATERAL = {"periodic": sdbd.LATERAL_PERIODIC, "walls": sdbd.LATERAL_WALLS, "none": sdbd.LATERAL_NONE}
FLOOR = {"stop": sdbd.FLOOR_STOP, "roll": sdbd.FLOOR_ROLL}
WALL_CONTACTS = {"frictionless": sdbd.WALL_FRICTIONLESS, "glued": sdbd.WALL_GLUED}
SIZE_DISTRIBUTIONS = ("monodisperse", "uniform", "lognormal", "sieve")
SMOOTH_SHAPES = ("ellipsoid", "superellipsoid")
SIZE_KEYS = {"rod": "shape_size", "four_rods": "shape_size", "tripod": "shape_size", "spiky": "shape_size",
             "cube": "shape_size", "ellipsoid": "shape_spheres", "superellipsoid": "shape_spheres",
             "agglomerate": "agglomerate_file", "mesh": "mesh_spheres"}  # sets how many spheres a particle has
BYTES_PER_PARTICLE = 512  # the terms of one task's memory estimate, see memory()
BYTES_PER_SEDIMENT_SPHERE = 128
BYTES_PER_SMOOTH_SHAPE_SPHERE = 3072
BYTES_PER_CAP_POINT = 48
MESH_BUILD_BYTES = 64 << 20  # building a mesh particle: samples, candidate balls, evaluation points
BYTES_PER_MESH_FILE_BYTE = 20  # ... and the triangles, per byte of the mesh file
BYTES_PER_GRID_COLUMN = 72  # a column of the sediment grid: its first 8 cells and its height
CYLINDER_FLATNESS = 0.01  # automatic container_sides: the polygon departs from the circle by at most this
# times the smallest sphere radius
PARTICLE_CHUNK = 1 << 20  # particles a rank of a spread task draws at a time (72 MB of inputs), keeping its own
WARM_UP_PARTICLES = 4  # particles of the warm-up run, which compiles the kernels before any task
WARM_UP_PACKING_SAMPLES = 1000  # the fewest allowed
# Upper bounds of keys beyond which a value means nothing and only costs time or memory:
MAX_SHAPE_SIZE = 1000  # a rod of 1000 spheres; a cube of L = 1000 has 6 million
MAX_SEMI_AXIS = 1000.0  # sphere radii: no set of shape_spheres spheres approximates a thinner body
MAX_SHAPE_SPHERES = 100_000  # a (super)ellipsoid of 10^5 spheres takes about 2 min to build
MAX_MESH_SPHERES = 10_000  # medial balls of a mesh: 10^4 take about 40 s (the cost grows as their square)
MAX_CONTAINER_SIDES = 100_000  # flat to 1e-9 of its radius; the automatic count stays far below
MAX_SIZE_SPREAD = 3.0  # lognormal: factors exp(+-6 x 3) span 15 decades of volume
MAX_PROFILE_BINS = 10_000
MAX_PACKING_SAMPLES = 10_000_000  # per slab: QMC error ~1e-6 already at 10^5-10^6
MAX_SHARE = 1e9  # shares are normalised; a species of one part in 10^9 is absent from any sediment
DROP_ATTEMPTS = 1000  # draws of a drop point in a vessel's opening before the particle is reported
MAX_HEAP_EXTENTS = 1e6  # drop_radius in particle extents: a heap wider than that is no heap

@dataclass(frozen=True)
class _ReadWhen:
    """A parameter is read by a task whose ``key`` takes one of ``values`` (e.g. a shape's size by
    the shapes that have one); picklable, unlike a lambda, so the job travels between ranks."""

    key: str
    values: tuple

    def __call__(self, params: dict) -> bool:
        return params[self.key] in self.values


@dataclass(frozen=True)
class _ReadWhenAll:
    """Read when every one of ``conditions`` holds."""

    conditions: tuple

    def __call__(self, params: dict) -> bool:
        return all(condition(params) for condition in self.conditions)


@dataclass(frozen=True)
class _ReadWhenAny:
    """Read when one of ``conditions`` holds."""

    conditions: tuple

    def __call__(self, params: dict) -> bool:
        return any(condition(params) for condition in self.conditions)


@dataclass(frozen=True)
class _ReadBySpecies:
    """A species key given for the job is read when a species takes it (its entry does not set
    ``key``) and reads it (``condition`` of the species' own parameters; None: always)."""

    key: str
    condition: object = None

    def __call__(self, params: dict) -> bool:
        entries = params.get("species") or ({},)
        return any(self.key not in entry and (self.condition is None or self.condition({**params, **entry}))
                   for entry in entries)


@dataclass(frozen=True)
class _HasTable:
    """Read when the job holds the array of tables ``name``."""

    name: str

    def __call__(self, params: dict) -> bool:
        return bool(params.get(self.name))


_SIZED_SHAPES = _ReadWhen("shape", tuple(SIZE_KEYS))
_CHAINS = _ReadWhen("shape", ("rod", "four_rods", "tripod"))
_SMOOTH = _ReadWhen("shape", SMOOTH_SHAPES)
_SUPERELLIPSOID = _ReadWhen("shape", ("superellipsoid",))
_AGGLOMERATE = _ReadWhen("shape", ("agglomerate",))
_MESH = _ReadWhen("shape", ("mesh",))
_IN_BOX = _ReadWhen("container", ("box",))
_CYLINDER = _ReadWhen("container", ("cylinder",))
_VESSEL = _ReadWhen("container", ("mesh",))
_BOXED = _ReadWhenAll((_IN_BOX, _ReadWhen("lateral", ("periodic", "walls"))))
_WALLED = _ReadWhenAny((_CYLINDER, _VESSEL, _ReadWhenAll((_IN_BOX, _ReadWhen("lateral", ("walls",))))))
_HEAP = _ReadWhenAll((_IN_BOX, _ReadWhen("lateral", ("none",))))
_SPREAD = _ReadWhen("size_distribution", ("uniform", "lognormal"))
_SIEVE = _ReadWhen("size_distribution", ("sieve",))

PARAMETERS = (
    Parameter("n_particles", int, REQUIRED, "1", "number of particles deposited", low=1),
    Parameter("shape", str, "sphere", "1",
              "particle shape: sphere; rod (shape_size spheres on a line, Fig. 1a); four_rods (four rods of "
              "shape_size spheres sharing the centre one, Fig. 1b); tripod (three legs of shape_size spheres); "
              "spiky (3L-2 spheres on three perpendicular axes, section 5); cube (6L^2-12L+8 spheres on the "
              "surface of an LxLxL cube, section 5); ellipsoid, superellipsoid (shape_spheres overlapping "
              "polydisperse spheres, Fig. 1d-f); agglomerate (the spheres of agglomerate_file); mesh (mesh_spheres "
              "medial balls of the closed surface mesh mesh_file)", choices=SHAPES),
    Parameter("shape_size", int, 5, "1", "L of spiky and cube; spheres of a rod, of each arm of four_rods, "
              "of each leg of a tripod", low=1, high=MAX_SHAPE_SIZE, read_when=_SIZED_SHAPES),
    Parameter("shape_spacing", float, 1.0, "1", "centre distance of neighbouring spheres in rod, four_rods "
              "and tripod, in sphere radii (< 2: overlapping; 1 gives Fig. 1a)", low=0.0, high=2.0,
              low_inclusive=False, read_when=_CHAINS),
    Parameter("semi_axis_x", float, 4.0, "1", "ellipsoid/superellipsoid semi-axis along x, in sphere_radius units",
              low=0.0, low_inclusive=False, high=MAX_SEMI_AXIS, read_when=_SMOOTH),
    Parameter("semi_axis_y", float, 3.0, "1", "semi-axis along y, in sphere_radius units", low=0.0,
              low_inclusive=False, high=MAX_SEMI_AXIS, read_when=_SMOOTH),
    Parameter("semi_axis_z", float, 2.0, "1", "semi-axis along z, in sphere_radius units", low=0.0,
              low_inclusive=False, high=MAX_SEMI_AXIS, read_when=_SMOOTH),
    Parameter("exponent_vertical", float, 2.0, "1", "superellipsoid exponent e1 (north-south; 2: ellipsoid)",
              low=1.0, high=20.0, low_inclusive=False, read_when=_SUPERELLIPSOID),
    Parameter("exponent_horizontal", float, 2.0, "1", "superellipsoid exponent e2 (east-west; 2: ellipsoid)",
              low=1.0, high=20.0, low_inclusive=False, read_when=_SUPERELLIPSOID),
    Parameter("shape_spheres", int, 1785, "1", "number of spheres approximating an ellipsoid or superellipsoid "
              "(Fig. 1d: 1785)", low=1, high=MAX_SHAPE_SPHERES, read_when=_SMOOTH),
    Parameter("agglomerate_file", str, "", "1", "CSV (x, y, z, r) or HDF5 (spheres/position, spheres/radius, e.g. "
              "an aggregation task file) holding the agglomerate; it is rescaled to mean radius sphere_radius",
              is_file=True, read_when=_AGGLOMERATE),
    Parameter("mesh_file", str, "", "1", "closed triangle mesh (STL or OBJ) of the particle: approximated by "
              "mesh_spheres overlapping medial balls and scaled to the volume of a sphere of radius sphere_radius",
              is_file=True, read_when=_MESH),
    Parameter("mesh_spheres", int, 100, "1", "number of medial balls approximating mesh_file (the approximation's "
              "volume error and surface distance are recorded per species)", low=1, high=MAX_MESH_SPHERES,
              read_when=_MESH),
    Parameter("sphere_radius", float, 0.5, LENGTH_UNITS, "radius of the particles' spheres (the default 0.5 "
              "makes lengths count sphere diameters); shape lengths are in units of it",
              low=0.0, low_inclusive=False, high=LARGEST_QUANTITY),
    Parameter("container", str, "box", "1", "box (lateral boundaries set by lateral) or cylinder (a vertical "
              "cylinder of container_radius about (container_radius, container_radius), its wall frictionless or "
              "glued as wall_contact says) or mesh (the vessel of container_file: an open-topped surface mesh whose "
              "inside is convex, its faces walls as wall_contact says)", choices=CONTAINERS),
    Parameter("container_file", str, "", "1", "surface mesh (STL or OBJ) of the vessel: closed but for its opening at "
              "the top, its inside convex, no face overhanging; moved so that its bounding box starts at the origin, "
              "in the job's length units; particles are dropped inside its opening", is_file=True,
              read_when=_VESSEL),
    Parameter("drop_area_radius", float, None, LENGTH_UNITS, "with container = mesh: particles are released "
              "uniformly over the part of the disc of this radius about (drop_area_x, drop_area_y) that lies in the "
              "vessel's opening, each whole particle inside it; unset: over the whole opening", low=0.0,
              low_inclusive=False, high=LARGEST_QUANTITY, read_when=_VESSEL),
    Parameter("drop_area_x", float, None, LENGTH_UNITS, "x of the drop disc's centre, in the vessel's coordinates "
              "(its bounding box from the origin); unset: the centroid of the opening", low=-LARGEST_QUANTITY,
              high=LARGEST_QUANTITY, read_when=_VESSEL),
    Parameter("drop_area_y", float, None, LENGTH_UNITS, "y of the drop disc's centre (see drop_area_x)",
              low=-LARGEST_QUANTITY, high=LARGEST_QUANTITY, read_when=_VESSEL),
    Parameter("box_length", float, 50.0, LENGTH_UNITS, "side of the square bottom [0, box_length]^2 "
              "(periodic or walled)", low=0.0, low_inclusive=False, high=LARGEST_QUANTITY, read_when=_BOXED),
    Parameter("lateral", str, "periodic", "1", "lateral boundaries of the box: periodic, walls (four rigid vertical "
              "walls, see wall_contact), none (a heap on an unbounded floor)", choices=tuple(LATERAL),
              read_when=_IN_BOX),
    Parameter("container_radius", float, 10.0, LENGTH_UNITS, "radius of the cylinder", low=0.0,
              low_inclusive=False, high=LARGEST_QUANTITY, read_when=_CYLINDER),
    Parameter("container_sides", int, 0, "1", "the cylinder's wall is the regular polygon of this many flat sides "
              "inscribed in its circle (the exact motions of the method exist for flat walls only); 0: the fewest "
              "sides with which it departs from the circle by at most 1 % of the smallest sphere radius",
              low=0, high=MAX_CONTAINER_SIDES, read_when=_CYLINDER),
    Parameter("substrate", str, "", "1", "fixed spheres the particles are deposited onto: CSV (x, y, z, r) or HDF5 "
              "(spheres/position, spheres/radius, e.g. a deposition task file, whose own substrate is included); "
              "\"\": the bare floor", is_file=True),
    Parameter("wall_contact", str, "frictionless", "1", "wall contact model of the walls, the cylinder and a "
              "vessel's faces: "
              "frictionless "
              "(a sphere of infinite radius: the wall pushes only along its normal and a touching sphere slides "
              "along it) or glued (the wall holds the touching sphere's centre: it pivots about it, no sliding)",
              choices=tuple(WALL_CONTACTS), affects_seed=False, read_when=_WALLED),
    Parameter("floor", str, "stop", "1", "floor z = 0: stop (the paper: a particle touching it is immobilised) "
              "or roll (the floor contact acts as a pivot and the particle keeps rolling)", choices=tuple(FLOOR)),
    Parameter("drop_radius", float, 5.0, LENGTH_UNITS, "with lateral = none: particles are released uniformly "
              "over the disc of this radius around the origin", low=0.0, low_inclusive=False, high=LARGEST_QUANTITY,
              read_when=_HEAP),
    Parameter("size_distribution", str, "monodisperse", "1", "particle size factor: monodisperse (1), uniform "
              "(in [1 - size_spread, 1 + size_spread]), lognormal (exp(size_spread Z), Z standard normal) or sieve "
              "(the volume-equivalent diameter drawn from the sieve curve sieve_curve)", choices=SIZE_DISTRIBUTIONS),
    Parameter("size_spread", float, 0.1, "1", "width of the size distribution", low=0.0, high=MAX_SIZE_SPREAD,
              read_when=_SPREAD),
    Parameter("sieve_curve", str, "", "1", "CSV file of the sieve curve: sieve size (a length), cumulative percent "
              "passing; interpolated linearly in log size", is_file=True, read_when=_SIEVE),
    Parameter("sieve_basis", str, "mass", "1", "what the sieve curve's percentages count: mass (a grading curve) "
              "or number", choices=("mass", "number"), read_when=_SIEVE),
    Parameter("share_basis", str, "number", "1", "what the species' share values count: number of particles or "
              "volume of material", choices=("number", "volume"), read_when=_HasTable("species")),
    Parameter("trial_angle", float, 1e-2, "rad", "trial rotation Delta phi of frustrated situations (section 4.1)",
              low=0.0, high=np.pi, low_inclusive=False, high_inclusive=False),
    Parameter("cycle_n", int, 4, "1", "n of the cycling criterion (34), section 4.2 (0: off)", low=0, high=28),
    Parameter("cycle_eps", float, 1e-3, "1", "epsilon of the cycling criterion (34)", low=0.0, low_inclusive=False,
              high=1.0),
    Parameter("max_events_per_particle", int, 100_000, "1", "a particle needing more events stops the task "
              "with an error naming it", low=1, high=sdbd.MAX_EVENT_LIMIT),
    Parameter("profile_bins", int, 50, "1", "number of slabs of the packing profile over 0 <= z <= 1.25 h",
              low=1, high=MAX_PROFILE_BINS, sweepable=False),
    Parameter("packing_samples", int, 200_000, "1", "quasi-Monte Carlo points per slab for the multiple "
              "overlaps of spheres within a particle (sphere volumes and pairwise lenses are exact; spread over the "
              "sediment's sampled overlap caps, 16 to 65 536 per cap; measured error in docs/jobs.md)", low=1000,
              high=MAX_PACKING_SAMPLES),
    Parameter("timing_skip_fraction", float, 0.5, "1", "fraction of the particles, deposited first, left out "
              "of spheres_per_second (section 5: the first half)", low=0.0, high=1.0, high_inclusive=False),
    *statistics.PARAMETERS,
)
# a key a species may set is read for the job when some species takes the job's value
PARAMETERS = tuple(Parameter(**{**vars(p), "read_when": _ReadBySpecies(p.name, p.read_when)})
                   if p.name in SPECIES_KEYS else p for p in PARAMETERS)
SPECIES_TABLE = TableArray(
    "species", "the species of a mixture: each entry a shape with its own parameters and size distribution "
    "(any of " + ", ".join(SPECIES_KEYS) + "; the others are the job's) and its share",
    (Parameter("name", str, REQUIRED, "1", "the species' name (the dataset's species coordinate)"),
     Parameter("share", float, 1.0, "1", "share of the mixture, by share_basis; shares are normalised", low=0.0,
               low_inclusive=False, high=MAX_SHARE),
     *(p for p in PARAMETERS if p.name in SPECIES_KEYS)),
    required=("name",))
LAYERS_TABLE = TableArray(
    "layers", "layers deposited one after the other in one task: n_particles of the species named",
    (Parameter("n_particles", int, REQUIRED, "1", "particles of the layer", low=1),
     Parameter("species", str, "", "1", "the species of the layer: names of [[species]] separated by commas, "
               "drawn by their shares; \"\": all species")),
    required=("n_particles",))

def check(params: dict) -> None:
    """The checks across keys of one point: species, layers, sieve curves, that a particle fits in
    the container, the substrate, and the memory of the sediment grid (which needs the particles)."""
    check_species(params)
    species = species_of(params)
    sizes = _Sizes.of(species)
    if params["container"] == "cylinder":
        _check_cylinder(params, species, sizes)
    elif params["container"] == "box" and params["lateral"] != "none":
        _check_box(params, sizes)
    elif params["container"] == "box":
        _check_heap(params, sizes)
    geometry = _container(params, species)  # reads a vessel's mesh once for the checks below
    if geometry.vessel is not None:
        _check_vessel(params, geometry.vessel, sizes)
    substrate = substrate_spheres(params)
    _check_container(params, geometry, sizes, substrate)
    _check_grid_memory(params, species, substrate, geometry)


@dataclass(frozen=True)
class _Sizes:
    """The sizes of a point's particles that the container must hold, over every species and size factor."""

    extent: float  # the farthest sphere surface from a centre of mass, at the largest size factor
    largest_radius: float  # the largest sphere, at the largest size factor
    length_scale: float  # the mean sphere radius of the templates at scale 1: the kernel's tolerances
    widest: str  # "2 x extent", and the size distribution that makes it, as a message shows it

    @classmethod
    def of(cls, species: tuple[Species, ...]) -> "_Sizes":
        widest = max(species, key=lambda s: s.extent * s.largest_scale())
        scale = widest.largest_scale()
        named = f"species {widest.name!r}: " if len(species) > 1 else ""
        spread = (f"; {named}size_distribution = {widest.params['size_distribution']!r} gives size factors up to "
                  f"{scale:.4g}" if scale != 1.0 else "")
        return cls(extent=widest.extent * scale,
                   largest_radius=max(float(s.radii.max()) * s.largest_scale() for s in species),
                   length_scale=float(np.concatenate([s.radii for s in species]).mean()),
                   widest=f"2 x {widest.extent * scale:.6g}{spread}")


def _check_box(params: dict, sizes: _Sizes) -> None:
    if not params["box_length"] > 2.0 * sizes.extent:
        raise JobError(f"box_length = {params['box_length']} must exceed twice the particle extent "
                       f"({sizes.widest}), so that a particle fits in the box; allowed: box_length > "
                       f"{2 * sizes.extent:.6g}")


def _check_cylinder(params: dict, species: tuple[Species, ...], sizes: _Sizes) -> None:
    if 0 < params["container_sides"] < sdbd.MIN_CYLINDER_SIDES:
        raise JobError(f"container_sides = {params['container_sides']}: allowed: 0 (automatic) or at least "
                       f"{sdbd.MIN_CYLINDER_SIDES}")
    radius = params["container_radius"]
    sides = container_sides(params, species)
    if sides > MAX_CONTAINER_SIDES:
        raise JobError(f"container_radius = {radius}: the automatic container_sides would be {sides} (the polygon "
                       f"departs from the circle by at most {CYLINDER_FLATNESS} of the smallest sphere radius "
                       f"{smallest_sphere_radius(species):.4g}); allowed: at most {MAX_CONTAINER_SIDES} sides: "
                       "a smaller container_radius, or container_sides")
    inscribed = radius * math.cos(math.pi / sides)
    if not inscribed > sizes.extent:
        raise JobError(f"container_radius = {radius} must exceed the largest particle extent {sizes.extent:.6g} "
                       f"(and the polygon's inscribed radius {inscribed:.6g} too), so that a particle fits in "
                       f"the cylinder; allowed: container_radius > {sizes.extent / inscribed * radius:.6g}")


def _check_vessel(params: dict, vessel, sizes: _Sizes) -> None:
    """The largest particle fits through the vessel's opening (some point of it lies an extent from its rim),
    and through the drop disc's part of it."""
    grid = np.stack(np.meshgrid(*(np.linspace(0.0, u, 201) for u in vessel.upper[:2])), axis=-1).reshape(-1, 2)
    usable = vessel.inside_opening(grid, sizes.extent)
    if not np.any(usable):
        raise JobError(f"container_file = {params['container_file']!r}: the vessel's opening is too narrow for the "
                       f"particles ({sizes.widest}); allowed: an opening wider than twice the particle extent")
    for key in ("drop_area_x", "drop_area_y"):
        if params[key] is not None and params["drop_area_radius"] is None:
            raise JobError(f"{key} = {params[key]!r}: the centre of the drop disc needs its radius: set "
                           "drop_area_radius too, or leave both unset to drop over the whole opening")
    area = drop_area(params, vessel)
    if area is None:
        return
    centre, radius = area
    disc = _on_disc(np.stack(np.meshgrid(np.linspace(0.0, 1.0, 101), np.linspace(0.0, 1.0, 101)),
                             axis=-1).reshape(-1, 2), radius, centre)
    if not np.any(vessel.inside_opening(disc, sizes.extent)):
        raise JobError(f"drop_area_radius = {radius!r}: the drop disc about ({centre[0]:.6g}, {centre[1]:.6g}) holds "
                       f"no place in the vessel's opening at least the particle extent {sizes.extent:.6g} from its "
                       "rim; allowed: a disc that reaches that far into the opening (the vessel's bounding box runs "
                       f"from (0, 0) to ({vessel.upper[0]:.6g}, {vessel.upper[1]:.6g}))")


def drop_area(params: dict, vessel) -> tuple | None:
    """The drop disc of a mesh vessel's job, ((x, y), radius), its centre the opening's centroid unless given;
    None when the job drops over the whole opening."""
    radius = params["drop_area_radius"]
    if radius is None:
        return None
    centroid = vessel.opening_centroid()
    given = (params["drop_area_x"], params["drop_area_y"])
    centre = [centroid[k] if given[k] is None else given[k] for k in range(2)]
    return (float(centre[0]), float(centre[1])), float(radius)


def _check_heap(params: dict, sizes: _Sizes) -> None:
    if params["drop_radius"] > MAX_HEAP_EXTENTS * sizes.extent:
        raise JobError(f"drop_radius = {params['drop_radius']!r}: allowed: at most {MAX_HEAP_EXTENTS:g} particle "
                       f"extents ({MAX_HEAP_EXTENTS * sizes.extent:.6g}); particles dropped farther apart form no heap")


def _check_container(params: dict, geometry: "_Geometry", sizes: _Sizes, substrate) -> None:
    """What the deposition kernel would refuse: a periodic box narrower than four sphere radii, walls
    narrower than a sphere, a substrate sphere below the floor or through a wall."""
    try:
        sdbd.check_container(geometry.lower, geometry.upper, geometry.lateral, sizes.largest_radius, sizes.extent,
                             sizes.length_scale, container=geometry.container, cylinder=geometry.cylinder,
                             substrate_positions=substrate[0], substrate_radii=substrate[1], faces=geometry.faces())
    except ValueError as error:
        if "substrate sphere" in str(error):
            raise JobError(f"substrate = {params['substrate']!r}: {error} (spheres count from 0, in the order of "
                           "the file)") from None
        raise JobError(f"{_container_size_key(params)} = {params[_container_size_key(params)]!r}: {error}") from None


def _check_grid_memory(params: dict, species: tuple[Species, ...], substrate, geometry: "_Geometry") -> None:
    """Refuse a container whose sediment grid, with the rest of the task, needs more than this machine's memory.

    The grid has a column per cell of the box, the cell being the first particle's largest sphere
    diameter (or the substrate's largest); the smallest that can be is taken.  A heap's columns
    are made where particles land."""
    if params["container"] == "box" and params["lateral"] == "none":
        return
    size = _container_size_key(params)
    width = float(np.max(geometry.upper - geometry.lower))
    cell = 2.0 * max(min(float(s.radii.max()) * s.smallest_scale() for s in species),
                     float(substrate[1].max(initial=0.0)))
    columns = math.floor(width / cell) ** 2
    need = memory(params) + BYTES_PER_GRID_COLUMN * columns + BYTES_PER_SEDIMENT_SPHERE * len(substrate[1])
    keys = ", ".join(f"{key}={params[key]!r}" for key in (size, *memory_keys(params)))
    check_memory(need, "one task", f"{keys}, and a grid cell of {cell:.4g}, the smallest the first particle's "
                 "largest sphere diameter can be")


def _container_size_key(params: dict) -> str:
    return {"cylinder": "container_radius", "mesh": "container_file"}.get(params["container"], "box_length")


def container_sides(params: dict, species: tuple[Species, ...]) -> int:
    """Sides of the cylinder's polygon: ``container_sides``, or the fewest with which the polygon departs
    from the circle, R (1 - cos(pi / n)), by at most CYLINDER_FLATNESS of the smallest sphere radius
    any particle can have (:func:`smallest_sphere_radius`)."""
    if params["container_sides"]:
        return params["container_sides"]
    depth = CYLINDER_FLATNESS * smallest_sphere_radius(species) / params["container_radius"]
    return max(sdbd.MIN_CYLINDER_SIDES, math.ceil(math.pi / math.acos(1.0 - min(depth, 1.0))))


def smallest_sphere_radius(species: tuple[Species, ...]) -> float:
    """The smallest sphere radius of any particle: a species' smallest sphere at its smallest size factor."""
    return min(float(s.radii.min()) * s.smallest_scale() for s in species)


def substrate_spheres(params: dict) -> tuple[np.ndarray, np.ndarray]:
    """Centres (m, 3) and radii (m,) of the substrate (empty without one)."""
    if not params["substrate"]:
        return np.zeros((0, 3)), np.zeros(0)
    centres, radii = read_agglomerate(params["substrate"], key="substrate", with_substrate=True)
    if centres.shape[1] != 3:
        raise JobError(f"substrate = {params['substrate']!r}: spheres in a plane (x, y, r); allowed: x, y, z, r")
    return centres, radii


def cost(params: dict) -> float:
    return float(params["n_particles"]) * _spheres_per_particle(params)


def memory(params: dict) -> int:
    """Peak memory of one task in bytes, from the number of particles and the spheres of one particle.

    - ``BYTES_PER_PARTICLE`` per particle: its size factor, rotation, drop position, centre of
      mass, state, contacts and 13 event counters, with their input copies;
    - ``BYTES_PER_SEDIMENT_SPHERE`` per sphere of the sediment: position, radius, particle index,
      link of the sediment grid, and the sorted copies and cell indices of the packing and
      contact statistics;
    - ``BYTES_PER_SMOOTH_SHAPE_SPHERE`` per sphere of a (super)ellipsoid, once: building it scans
      16 surface samples per sphere (points, normals, chords, cells, a heap);
    - ``BYTES_PER_CAP_POINT`` per quasi-Monte Carlo point of the overlap caps of the packing
      fraction: one cap's points are held at a time, at most ``MAX_POINTS_PER_CAP`` of them
      (about 3 MiB);
    - a mesh particle, while it is built: ``MESH_BUILD_BYTES`` and ``BYTES_PER_MESH_FILE_BYTE`` per
      byte of its file (the triangles and their samples);
    - the profiles and distributions of the statistics, 8 bytes per bin of each.

    A mixture counts its largest species, a mesh particle ``mesh_spheres`` spheres (at most that many
    balls are kept); nothing is built here.  The sediment grid, which needs the built particles, is
    checked with them (:func:`check`).  Measured peaks: 0.37 KiB per particle of one sphere, 95 B per
    sediment sphere of cubes (L = 3), 2.4 KiB per sphere of an ellipsoid of 8000 spheres, 48 B per
    cap point (rods of five overlapping spheres), 55 MiB for a mesh of 20 480 triangles in a binary
    STL of 1 MiB and 66 MiB for 81 920 triangles in 4 MiB (tracemalloc).
    """
    spheres = _spheres_per_particle(params)
    build = BYTES_PER_SMOOTH_SHAPE_SPHERE * spheres if _shapes(params) & set(SMOOTH_SHAPES) else 0
    sediment = params["n_particles"] * (BYTES_PER_PARTICLE + BYTES_PER_SEDIMENT_SPHERE * spheres)
    cap_points = min(MAX_POINTS_PER_CAP, params["packing_samples"] * (params["profile_bins"] + 1))
    species = len(params.get("species") or ((),))
    bins = (species + 1) * params["profile_bins"] + params["rdf_bins"] + params["orientation_bins"]
    return build + _mesh_build_bytes(params) + sediment + BYTES_PER_CAP_POINT * cap_points + 8 * bins


def _mesh_build_bytes(params: dict) -> int:
    """Memory of building the largest mesh particle of the point (0 without one)."""
    files = [own["mesh_file"] for own in (species_parameters(params, entry) for entry in params.get("species") or ({},))
             if own["shape"] == "mesh" and own["mesh_file"]]
    return max((MESH_BUILD_BYTES + BYTES_PER_MESH_FILE_BYTE * os.path.getsize(path) for path in files), default=0)


def memory_keys(params: dict) -> tuple[str, ...]:
    size = SIZE_KEYS.get(params["shape"])
    mesh = ("mesh_file",) if params["shape"] == "mesh" else ()
    return ("n_particles", "shape", size, *mesh) if size else ("n_particles", "shape")


def warm_up_parameters(params: dict) -> dict:
    """The point with a few particles and the fewest packing samples: the same kernels in milliseconds."""
    few = min(params["n_particles"], WARM_UP_PARTICLES)
    layers = params.get("layers")
    return {**params, "n_particles": few, "packing_samples": WARM_UP_PACKING_SAMPLES,
            **({"layers": ({"n_particles": few},)} if layers else {})}


def _shapes(params: dict) -> set[str]:
    return {entry.get("shape", params["shape"]) for entry in params.get("species") or ({},)}


def _spheres_per_particle(params: dict) -> int:
    """Spheres of the largest particle of the mixture, counted without building it where possible."""
    return max(_spheres_of(species_parameters(params, entry), entry) for entry in params.get("species") or ({},))


def _spheres_of(params: dict, entry: dict) -> int:
    shape, size = params["shape"], params["shape_size"]
    if shape == "agglomerate":
        return len(species_shape(params, entry)[1])
    if shape == "mesh":
        return params["mesh_spheres"]  # at most: the cover stops early when every sample is covered
    if shape in SMOOTH_SHAPES:
        return params["shape_spheres"]  # at most: medial balls that add nothing are dropped
    return {"sphere": 1, "rod": size, "four_rods": 4 * size - 3, "tripod": 3 * size - 2, "spiky": 3 * size - 2,
            "cube": size**3 - max(size - 2, 0) ** 3}[shape]


def solve(params: dict, rng: np.random.Generator, comm) -> TaskResult:
    """One task on the ranks of ``comm`` (:func:`parsim.deposition.spread.deposit_streamed` on
    several); every rank returns the statistics and its share of the configuration."""
    spread = comm is not None and comm.Get_size() > 1
    with phase("initial_condition"):
        inputs = deposition_inputs(params, rng, spread)
    if spread:
        return _solve_spread(comm, params, inputs)
    n = params["n_particles"]
    with phase("initial_condition"):
        drops, rotation, drop_xy = next(inputs.particles())
    with phase("steps"):
        result = sdbd.deposit(*inputs.shapes, drops.species, drops.scale, rotation, drop_xy, *inputs.container,
                              **inputs.options, progress=settled_reporter(n))
    _check_sediment(params, result.stopped_at, np.all(np.isfinite(result.positions)))
    with phase("statistics"):
        measured = statistics.measure(params, result, inputs.species, drops, inputs.geometry, inputs.skip,
                                      inputs.substrate)
    return TaskResult(measured, _configuration(params, inputs.geometry, result, inputs.species, drops,
                                               inputs.substrate))


@dataclass(frozen=True)
class DepositionInputs:
    """A task's deposition as the kernels take it: the arguments of :func:`parsim.core.sdbd.deposit`
    and of :func:`parsim.deposition.spread.deposit_streamed` (``shapes``, the particles, ``container``,
    ``options``), and what the statistics and the configuration need besides."""

    shapes: tuple  # (shape_offsets, shape_radii, shape_start) of every species
    container: tuple  # (box_lower_xy, box_upper_xy, lateral, floor)
    options: dict  # the keyword arguments of both kernels
    particles: Callable  # particles(): yields (drops, rotation, drop_xy) a chunk at a time, from the first particle
    species: tuple
    geometry: "_Geometry"
    substrate: tuple  # (centres, radii)
    skip: int  # particles left out of the timing

    def kernel_chunks(self):
        """``deposit_streamed``'s ``particle_chunks()``: (particle_shape, particle_scale, particle_rotation,
        particle_drop_xy) a chunk at a time."""
        return ((drops.species, drops.scale, rotation, drop_xy) for drops, rotation, drop_xy in self.particles())


def deposition_inputs(params: dict, rng: np.random.Generator, spread: bool = False) -> DepositionInputs:
    """The deposition of the task ``params`` whose random stream is ``rng`` (the task's: the same stream
    gives the same particles), as :func:`solve` runs it: every particle in one chunk, or with ``spread``
    (on several ranks) ``PARTICLE_CHUNK`` at a time.  Draws from ``rng``: call once per stream."""
    species = species_of(params)
    n = params["n_particles"]
    geometry = _container(params, species)
    substrate = substrate_spheres(params)
    skip = int(params["timing_skip_fraction"] * n)
    shapes = (np.concatenate([s.offsets for s in species]), np.concatenate([s.radii for s in species]),
              np.cumsum([0, *(len(s.radii) for s in species)]))
    container = (geometry.lower, geometry.upper, geometry.lateral, FLOOR[params["floor"]])
    options = dict(wall_contact=WALL_CONTACTS[params["wall_contact"]], trial_angle=params["trial_angle"],
                   cycle_n=params["cycle_n"], cycle_eps=params["cycle_eps"],
                   max_events_per_particle=params["max_events_per_particle"],
                   clock_from_particle=skip if skip < n else -1, container=geometry.container,
                   cylinder=geometry.cylinder, substrate_positions=substrate[0] if len(substrate[1]) else None,
                   substrate_radii=substrate[1] if len(substrate[1]) else None, faces=geometry.faces())
    particles = _particle_chunks(params, species, geometry, rng, PARTICLE_CHUNK if spread else max(n, 1))
    return DepositionInputs(shapes, container, options, particles, species, geometry, substrate, skip)


def _particle_chunks(params, species, geometry, rng, chunk):
    """The task's particles, ``chunk`` at a time: a function whose every call yields ``(drops, rotation,
    drop_xy)`` of consecutive particles from the first on (each call reads copies of the streams)."""
    # sizes, orientations and drop points each from their own stream, the species from a fourth:
    # the first k particles of a task are those of the same task with n_particles = k, and so is
    # their sediment
    size_rng, rotation_rng, drop_rng = rng.spawn(3)
    species_rng = rng.spawn(1)[0]
    n = params["n_particles"]

    def chunks():
        species_stream, size_stream, rotation_stream, drop_stream = copy.deepcopy(
            (species_rng, size_rng, rotation_rng, drop_rng))
        draws = ParticleDraws(params, species, species_stream, size_stream)
        for first in range(0, n, chunk):
            drops = draws.draw(min(chunk, n - first))
            yield (drops, shape_library.DrawnRotations.draw(len(drops.scale), rotation_stream),
                   _drop_positions(params, geometry, species, drops, drop_stream))

    return chunks


def rehearse_spread(params: dict) -> None:
    """Solve the small point ``params`` on this process alone as a task spread over several ranks is solved,
    compiling or loading every kernel such a task calls (those of several blocks and of fetches included):
    the warm-up of ``--ranks-per-task``.  A process of one rank compiles them for any number of ranks."""
    from mpi4py import MPI

    _solve_spread(MPI.COMM_SELF, params, deposition_inputs(params, np.random.default_rng(0), spread=True),
                  rehearsal=True)


def _solve_spread(comm, params, inputs: DepositionInputs, rehearsal: bool = False) -> TaskResult:
    """The task on the ranks of ``comm``: the sediment, bitwise the serial one, stays spread over them
    and no rank holds every particle; each rank returns the statistics, reduced over the ranks, and
    its share of the configuration.  ``rehearsal``: see :func:`rehearse_spread`."""
    from mpi4py import MPI

    from parsim.deposition.spread import deposit_streamed
    from parsim.deposition.spread_statistics import measure_decomposed

    with phase("steps"):  # the survey of the particles' inputs is a phase of its own
        share = deposit_streamed(comm, *inputs.shapes, inputs.kernel_chunks, *inputs.container, **inputs.options,
                                 rehearsal=rehearsal)
    _check_sediment(params, share.result.stopped_at,
                    comm.allreduce(bool(np.all(np.isfinite(share.result.positions))), op=MPI.LAND))
    own = Drops(share.particle_shape, share.particle_scale)
    with phase("statistics"):
        measured = measure_decomposed(comm, params, share, inputs.species, own, inputs.geometry, inputs.skip,
                                      inputs.substrate)
    return TaskResult(measured, _configuration(params, inputs.geometry, share.result, inputs.species, own,
                                               inputs.substrate, comm, share.index))


def _check_sediment(params, stopped_at, finite) -> None:
    if stopped_at >= 0:
        raise NumericalError(f"particle {stopped_at} (of {params['n_particles']}) needed more than "
                             f"max_events_per_particle = {params['max_events_per_particle']} events; raise the "
                             "limit or check the shape")
    if not finite:
        raise NumericalError("non-finite sphere positions in the sediment")


@dataclass(frozen=True)
class _Geometry:
    """The container as the kernel takes it."""

    container: int
    lateral: int
    lower: np.ndarray  # the lateral box (the cylinder's bounding square)
    upper: np.ndarray
    cylinder: tuple | None = None  # (cx, cy, R, sides)
    vessel: Vessel | None = None  # a mesh vessel, in the box of its bounding box

    def faces(self):
        """The kernel's ``faces`` of a mesh vessel (None for other containers)."""
        return None if self.vessel is None else self.vessel.faces()


def _container(params, species) -> _Geometry:
    if params["container"] == "mesh":
        vessel = read_vessel(params["container_file"])
        return _Geometry(sdbd.CONTAINER_MESH, sdbd.LATERAL_WALLS, np.zeros(2), np.array(vessel.upper[:2]),
                         vessel=vessel)
    if params["container"] == "cylinder":
        radius = params["container_radius"]
        return _Geometry(sdbd.CONTAINER_CYLINDER, sdbd.LATERAL_WALLS, np.zeros(2), np.full(2, 2.0 * radius),
                         (radius, radius, radius, container_sides(params, species)))
    return _Geometry(sdbd.CONTAINER_BOX, LATERAL[params["lateral"]], np.zeros(2), np.full(2, params["box_length"]))


def _drop_positions(params, geometry, species, drops, rng):
    """Horizontal release positions of the centres of mass of ``drops``."""
    n = len(drops.scale)
    extents = np.array([s.extent for s in species])
    if geometry.cylinder is not None:  # the whole particle starts inside the polygon, whatever its orientation
        cx, cy, radius, sides = geometry.cylinder
        reach = radius * math.cos(math.pi / sides) - extents[drops.species] * drops.scale
        if np.any(reach <= 0.0):
            raise NumericalError(f"a particle of size factor {drops.scale.max():.4g} does not fit in the cylinder")
        return _on_disc(rng.random((n, 2)), reach, (cx, cy))
    if geometry.vessel is not None:
        margins = extents[drops.species] * drops.scale
        return _in_opening(geometry.vessel, margins, rng, drop_area(params, geometry.vessel))
    if params["lateral"] == "none":
        return _on_disc(rng.random((n, 2)), params["drop_radius"], (0.0, 0.0))
    length = params["box_length"]
    if params["lateral"] == "walls":  # the whole particle starts inside, whatever its orientation
        margin = (extents[drops.species] * drops.scale)[:, None]
        if np.any(2.0 * margin >= length):
            raise NumericalError(f"a particle of size factor {drops.scale.max():.4g} does not fit between the walls")
        return margin + rng.random((n, 2)) * (length - 2.0 * margin)
    return rng.random((n, 2)) * length


def _in_opening(vessel, margins, rng, area=None):
    """Points uniform over a vessel's opening, each at least its ``margin`` from the rim (the whole particle
    starts inside, whatever its orientation): drawn as between walls, in the bounding box shrunk by the
    margin, and redrawn where they miss the opening (an opening that is the box's square misses nothing).
    With a drop ``area`` ((x, y), radius), drawn on its disc and redrawn where they miss the opening."""
    if np.any(2.0 * margins >= np.min(vessel.upper[:2])):
        raise NumericalError(f"a particle of extent {margins.max():.4g} does not fit in the vessel")
    points = np.zeros((len(margins), 2))
    missing = np.arange(len(margins))
    for _ in range(DROP_ATTEMPTS):
        if not len(missing):
            return points
        if area is None:
            margin = margins[missing, None]
            points[missing] = margin + rng.random((len(missing), 2)) * (vessel.upper[:2] - 2.0 * margin)
        else:
            points[missing] = _on_disc(rng.random((len(missing), 2)), area[1], area[0])
        missing = missing[~vessel.inside_opening(points[missing], margins[missing])]
    where = "the vessel's opening" if area is None else "the drop disc's part of the vessel's opening"
    raise NumericalError(f"a particle of extent {margins.max():.4g} found no place in {where} in {DROP_ATTEMPTS} "
                         "draws")


def _on_disc(uniform, radius, centre):
    """Points uniform over discs of ``radius`` about ``centre`` from uniform pairs (one row per point)."""
    distance = radius * np.sqrt(uniform[:, 0])
    angle = 2.0 * np.pi * uniform[:, 1]
    return np.column_stack([centre[0] + distance * np.cos(angle), centre[1] + distance * np.sin(angle)])


def _configuration(params, geometry, result, species, drops, substrate, comm=None, index=None) -> Configuration:
    """The task file's configuration of the sediment ``result`` (a :class:`parsim.core.sdbd.DepositionResult`);
    with ``comm``, the result of this rank's share (:class:`parsim.deposition.spread.DecomposedDeposition`,
    ``drops`` its particles', ``index`` their drop indices) of a sediment spread over the ranks of ``comm``
    (collective)."""
    top = float(np.max(result.positions[:, 2] + result.radii, initial=-np.inf))
    in_box = params["container"] == "box"
    periodic = in_box and params["lateral"] == "periodic"
    if in_box and params["lateral"] == "none":  # the heap's extent
        lower = (result.positions[:, :2] - result.radii[:, None]).min(axis=0, initial=np.inf)
        upper = (result.positions[:, :2] + result.radii[:, None]).max(axis=0, initial=-np.inf)
    else:
        lower, upper = geometry.lower, geometry.upper
    arrays = {"spheres/position": result.positions, "spheres/radius": result.radii, "spheres/particle": result.particle,
              "particles/center_of_mass": result.center_of_mass, "particles/rotation": result.rotation,
              "particles/shape": drops.species, "particles/scale": drops.scale, "particles/state": result.state,
              "particles/contacts": result.contacts, "particles/event_counts": result.event_counts,
              "particles/steps": result.steps}
    rank_rows = ()
    if comm is not None:
        from mpi4py import MPI

        # over the ranks' particles (numpy arrays reduced through buffers: elementwise)
        bounds = np.array([top, -lower[0], -lower[1], upper[0], upper[1]], dtype=np.float64)
        comm.Allreduce(MPI.IN_PLACE, bounds, op=MPI.MAX)
        top, lower, upper = bounds[0], -bounds[1:3], bounds[3:5]
        arrays["particles/index"] = index
        rank_rows = tuple(arrays)
    attrs = {"floor_z": 0.0, "event_kinds": list(sdbd.EVENT_KINDS), "state_names": list(sdbd.STATE_NAMES),
             "shape_names": [s.name for s in species], "container": params["container"]}
    if geometry.cylinder is not None:
        attrs["cylinder"] = list(geometry.cylinder)  # centre x, y, radius, sides of the polygon
    if geometry.vessel is not None:
        attrs["vessel_volume"] = float(geometry.vessel.volume)  # closed at its rim, exact from the mesh
        attrs["vessel_upper"] = np.asarray(geometry.vessel.upper, dtype=np.float64).tolist()  # the rim at z
        # the faces besides the box's walls and floor, as rows (N_x, N_y, N_z, c): inside is N . x >= c
        attrs["vessel_planes"] = np.column_stack([geometry.vessel.normals, geometry.vessel.levels]).ravel().tolist()
    return Configuration(
        arrays={**arrays, "shapes/offsets": np.concatenate([s.offsets for s in species]),
                "shapes/radius": np.concatenate([s.radii for s in species]),
                "shapes/start": np.cumsum([0, *(len(s.radii) for s in species)]),
                "substrate/position": substrate[0], "substrate/radius": substrate[1]},
        box_lower=np.array([lower[0], lower[1], 0.0]), box_upper=np.array([upper[0], upper[1], top]),
        periodic=np.array([periodic, periodic, False]), attrs=attrs, rank_rows=rank_rows)


SOLVER = Solver(kind="deposition", description="steepest descent ballistic deposition of multi-sphere particles "
                "(Topic & Poeschel 2016)", parameters=PARAMETERS, statistics=statistics.STATISTICS,
                coordinates=statistics.coordinates, check=check, cost=cost, memory=memory, memory_keys=memory_keys,
                warm_up_parameters=warm_up_parameters, solve=solve, decomposable=True,
                tables=(SPECIES_TABLE, LAYERS_TABLE), rehearse_spread=rehearse_spread)
