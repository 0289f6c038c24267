"""Sequential deposition of rigid multi-sphere particles (Topić & Pöschel 2016).

One task: ``n_particles`` copies of one shape (each scaled by a factor from the size
distribution, turned by a uniformly random rotation, released at a random horizontal
position above the sediment) follow the steepest descent of their centre of mass with
the event-driven algorithm of sections 3 and 4, then the sediment's statistics are
measured: filling height 2 z_cm (section 4.1), bulk packing fraction and profile,
coordination between particles, and the events of the special situations.

The algorithm is sequential and not decomposable: with ``parsim run
--ranks-per-task K > 1`` a task runs on its group's rank 0 while the other ranks
of the group wait.
"""

import functools
from dataclasses import dataclass

import numpy as np

from parsim.agglomerate_file import read_agglomerate
from parsim.core import sdbd
from parsim.core import shapes as shape_library
from parsim.core.sediment import MAX_POINTS_PER_CAP, coordination, filling_height, packing_fractions
from parsim.errors import JobError, NumericalError
from parsim.parameters import REQUIRED, Parameter
from parsim.solver import LENGTH_UNITS, Configuration, Coordinate, Solver, Statistic, TaskResult

SHAPES = ("sphere", "rod", "four_rods", "tripod", "spiky", "cube", "ellipsoid", "superellipsoid", "agglomerate")
LATERAL = {"periodic": sdbd.LATERAL_PERIODIC, "walls": sdbd.LATERAL_WALLS, "none": sdbd.LATERAL_NONE}
FLOOR = {"stop": sdbd.FLOOR_STOP, "roll": sdbd.FLOOR_ROLL}
WALL_CONTACTS = {"frictionless": sdbd.WALL_FRICTIONLESS, "glued": sdbd.WALL_GLUED}
SIZE_DISTRIBUTIONS = ("monodisperse", "uniform", "lognormal")
SMOOTH_SHAPES = ("ellipsoid", "superellipsoid")
SIZE_KEYS = {"rod": "shape_size", "four_rods": "shape_size", "tripod": "shape_size", "spiky": "shape_size",
             "cube": "shape_size", "ellipsoid": "shape_spheres", "superellipsoid": "shape_spheres",
             "agglomerate": "agglomerate_file"}  # the parameter that sets how many spheres a particle has
BYTES_PER_PARTICLE = 512  # the terms of one task's memory estimate, see memory()
BYTES_PER_SEDIMENT_SPHERE = 128
BYTES_PER_SMOOTH_SHAPE_SPHERE = 3072
BYTES_PER_CAP_POINT = 48
BULK_SLAB = (0.25, 0.75)  # the bulk: this slab of the filling height, away from floor and surface
WARM_UP_PARTICLES = 4  # particles of the warm-up run, which compiles the kernels before any task
WARM_UP_PACKING_SAMPLES = 1000  # the fewest allowed
PROFILE_TOP = 1.25  # the profile phi(z) covers 0 <= z <= PROFILE_TOP x filling height

@dataclass(frozen=True)
class _ReadWhen:
    """A parameter is read by a task whose ``key`` takes one of ``values`` (e.g. a shape's size by
    the shapes that have one); picklable, unlike a lambda, so the job travels between ranks."""

    key: str
    values: tuple

    def __call__(self, params: dict) -> bool:
        return params[self.key] in self.values


_SIZED_SHAPES = _ReadWhen("shape", tuple(SIZE_KEYS))
_CHAINS = _ReadWhen("shape", ("rod", "four_rods", "tripod"))
_SMOOTH = _ReadWhen("shape", SMOOTH_SHAPES)
_SUPERELLIPSOID = _ReadWhen("shape", ("superellipsoid",))
_AGGLOMERATE = _ReadWhen("shape", ("agglomerate",))
_BOXED = _ReadWhen("lateral", ("periodic", "walls"))
_WALLED = _ReadWhen("lateral", ("walls",))
_HEAP = _ReadWhen("lateral", ("none",))
_SPREAD = _ReadWhen("size_distribution", ("uniform", "lognormal"))

PARAMETERS = (
    Parameter("n_particles", int, REQUIRED, "1", "number of particles deposited", low=1),
    Parameter("shape", str, "sphere", "1",
              "particle shape: sphere; rod (shape_size spheres on a line, Fig. 1a); four_rods (four rods of "
              "shape_size spheres sharing the centre one, Fig. 1b); tripod (three legs of shape_size spheres); "
              "spiky (3L-2 spheres on three perpendicular axes, section 5); cube (6L^2-12L+8 spheres on the "
              "surface of an LxLxL cube, section 5); ellipsoid, superellipsoid (shape_spheres overlapping "
              "polydisperse spheres, Fig. 1d-f); agglomerate (the spheres of agglomerate_file)",
              choices=SHAPES),
    Parameter("shape_size", int, 5, "1", "L of spiky and cube; spheres of a rod, of each arm of four_rods, "
              "of each leg of a tripod", low=1, read_when=_SIZED_SHAPES),
    Parameter("shape_spacing", float, 1.0, "1", "centre distance of neighbouring spheres in rod, four_rods "
              "and tripod, in sphere radii (< 2: overlapping; 1 gives Fig. 1a)", low=0.0, high=2.0,
              low_inclusive=False, read_when=_CHAINS),
    Parameter("semi_axis_x", float, 4.0, "1", "ellipsoid/superellipsoid semi-axis along x, in sphere_radius units",
              low=0.0, low_inclusive=False, read_when=_SMOOTH),
    Parameter("semi_axis_y", float, 3.0, "1", "semi-axis along y, in sphere_radius units", low=0.0,
              low_inclusive=False, read_when=_SMOOTH),
    Parameter("semi_axis_z", float, 2.0, "1", "semi-axis along z, in sphere_radius units", low=0.0,
              low_inclusive=False, read_when=_SMOOTH),
    Parameter("exponent_vertical", float, 2.0, "1", "superellipsoid exponent e1 (north-south; 2: ellipsoid)",
              low=1.0, high=20.0, low_inclusive=False, read_when=_SUPERELLIPSOID),
    Parameter("exponent_horizontal", float, 2.0, "1", "superellipsoid exponent e2 (east-west; 2: ellipsoid)",
              low=1.0, high=20.0, low_inclusive=False, read_when=_SUPERELLIPSOID),
    Parameter("shape_spheres", int, 1785, "1", "number of spheres approximating an ellipsoid or superellipsoid "
              "(Fig. 1d: 1785)", low=1, read_when=_SMOOTH),
    Parameter("agglomerate_file", str, "", "1", "CSV (x, y, z, r) or HDF5 (spheres/position, spheres/radius, e.g. "
              "an aggregation task file) holding the agglomerate; it is rescaled to mean radius sphere_radius",
              is_file=True, read_when=_AGGLOMERATE),
    Parameter("sphere_radius", float, 0.5, LENGTH_UNITS, "radius of the particles' spheres (the default 0.5 "
              "makes lengths count sphere diameters); shape lengths are in units of it",
              low=0.0, low_inclusive=False),
    Parameter("box_length", float, 50.0, LENGTH_UNITS, "side of the square bottom [0, box_length]^2 "
              "(periodic or walled)", low=0.0, low_inclusive=False, read_when=_BOXED),
    Parameter("lateral", str, "periodic", "1", "lateral boundaries: periodic, walls (four rigid vertical walls, "
              "see wall_contact), none (a heap on an unbounded floor)", choices=tuple(LATERAL)),
    Parameter("wall_contact", str, "frictionless", "1", "wall contact model of lateral = walls: frictionless "
              "(a sphere of infinite radius: the wall pushes only along its normal and a touching sphere slides "
              "along it) or glued (the wall holds the touching sphere's centre: it pivots about it, no sliding)",
              choices=tuple(WALL_CONTACTS), affects_seed=False, read_when=_WALLED),
    Parameter("floor", str, "stop", "1", "floor z = 0: stop (the paper: a particle touching it is immobilised) "
              "or roll (the floor contact acts as a pivot and the particle keeps rolling)", choices=tuple(FLOOR)),
    Parameter("drop_radius", float, 5.0, LENGTH_UNITS, "with lateral = none: particles are released uniformly "
              "over the disc of this radius around the origin", low=0.0, low_inclusive=False, read_when=_HEAP),
    Parameter("size_distribution", str, "monodisperse", "1", "particle size factor: monodisperse (1), uniform "
              "(in [1 - size_spread, 1 + size_spread]) or lognormal (exp(size_spread Z), Z standard normal)",
              choices=SIZE_DISTRIBUTIONS),
    Parameter("size_spread", float, 0.1, "1", "width of the size distribution", low=0.0, read_when=_SPREAD),
    Parameter("trial_angle", float, 1e-2, "rad", "trial rotation Delta phi of frustrated situations (section 4.1)",
              low=0.0, high=np.pi, low_inclusive=False, high_inclusive=False),
    Parameter("cycle_n", int, 4, "1", "n of the cycling criterion (34), section 4.2 (0: off)", low=0, high=28),
    Parameter("cycle_eps", float, 1e-3, "1", "epsilon of the cycling criterion (34)", low=0.0, low_inclusive=False),
    Parameter("max_events_per_particle", int, 100_000, "1", "a particle needing more events stops the task "
              "with an error naming it", low=1),
    Parameter("profile_bins", int, 50, "1", "number of slabs of the packing profile over 0 <= z <= 1.25 h",
              low=1, sweepable=False),
    Parameter("packing_samples", int, 200_000, "1", "quasi-Monte Carlo points per slab for the overlaps of "
              "spheres within a particle (sphere volumes are exact; measured error below 1e-4)", low=1000),
    Parameter("timing_skip_fraction", float, 0.5, "1", "fraction of the particles, deposited first, left out "
              "of spheres_per_second (section 5: the first half)", low=0.0, high=1.0, high_inclusive=False),
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
)

STATE_COUNTS = {"hanging_particles": (sdbd.HANGING_ONE, sdbd.HANGING_TWO), "particles_on_floor": (sdbd.RESTING_ON_FLOOR,)}
EVENT_TOTALS = {"frustrated_steps": "frustrated_trial_rotation", "cycling_interruptions": "cycling_interruption",
                "simultaneous_events": "simultaneous"}


def check(params: dict) -> None:
    if params["shape"] == "agglomerate":
        particle_shape(params)  # reads and checks the file
    if params["size_distribution"] == "uniform" and not params["size_spread"] < 1.0:
        raise JobError(f"size_spread = {params['size_spread']} with size_distribution = 'uniform': allowed: "
                       "0 <= size_spread < 1 (factors must stay positive)")
    if params["lateral"] != "none":
        offsets, radii, _ = particle_shape(params)
        extent = shape_library.bounding_radius(offsets, radii) * _largest_size_factor(params)
        if not params["box_length"] > 2.0 * extent:
            raise JobError(f"box_length = {params['box_length']} must exceed twice the particle extent "
                           f"(2 x {extent:.6g}), so that a particle fits in the box; allowed: box_length > "
                           f"{2 * extent:.6g}")


def coordinates(fixed: dict) -> dict[str, Coordinate]:
    bins = fixed["profile_bins"]
    edges = np.linspace(0.0, PROFILE_TOP, bins + 1)
    return {"z_relative": Coordinate(0.5 * (edges[1:] + edges[:-1]), "1", "height of the slab centre over the "
                                     "filling height, z / h")}


def cost(params: dict) -> float:
    return float(params["n_particles"]) * len(particle_shape(params)[1])


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
      (about 3 MiB).

    Measured peaks: 0.37 KiB per particle of one sphere, 95 B per sediment sphere of cubes
    (L = 3), 2.4 KiB per sphere of an ellipsoid of 8000 spheres, 48 B per cap point (rods of
    five overlapping spheres, tracemalloc).
    """
    spheres = _spheres_per_particle(params)
    build = BYTES_PER_SMOOTH_SHAPE_SPHERE * spheres if params["shape"] in SMOOTH_SHAPES else 0
    sediment = params["n_particles"] * (BYTES_PER_PARTICLE + BYTES_PER_SEDIMENT_SPHERE * spheres)
    cap_points = min(MAX_POINTS_PER_CAP, params["packing_samples"] * (params["profile_bins"] + 1))
    return build + sediment + BYTES_PER_CAP_POINT * cap_points


def memory_keys(params: dict) -> tuple[str, ...]:
    size = SIZE_KEYS.get(params["shape"])
    return ("n_particles", "shape", size) if size else ("n_particles", "shape")


def warm_up_parameters(params: dict) -> dict:
    """The point with a few particles and the fewest packing samples: the same kernels in milliseconds."""
    return {**params, "n_particles": min(params["n_particles"], WARM_UP_PARTICLES),
            "packing_samples": WARM_UP_PACKING_SAMPLES}


def _spheres_per_particle(params: dict) -> int:
    """Spheres of one particle, counted without building it (an agglomerate's file is read)."""
    shape, size = params["shape"], params["shape_size"]
    if shape == "agglomerate":
        return len(particle_shape(params)[1])
    if shape in SMOOTH_SHAPES:
        return params["shape_spheres"]  # at most: medial balls that add nothing are dropped
    return {"sphere": 1, "rod": size, "four_rods": 4 * size - 3, "tripod": 3 * size - 2, "spiky": 3 * size - 2,
            "cube": size**3 - max(size - 2, 0) ** 3}[shape]


def solve(params: dict, rng: np.random.Generator, comm) -> TaskResult:
    """One task; serial, so ``comm`` (a group of one, see :class:`parsim.solver.Solver`) is not used."""
    offsets, radii, volume = particle_shape(params)
    n = params["n_particles"]
    # sizes, orientations and drop points each from their own stream: the first k particles of a
    # task are those of the same task with n_particles = k, and so is their sediment
    size_rng, rotation_rng, drop_rng = rng.spawn(3)
    scale = _size_factors(params, size_rng)
    rotation = shape_library.random_rotations(n, rotation_rng)
    drop_xy = _drop_positions(params, offsets, radii, scale, drop_rng)
    lower, upper = np.zeros(2), np.full(2, params["box_length"])  # unused with lateral = none
    skip = int(params["timing_skip_fraction"] * n)
    result = sdbd.deposit(offsets, radii, np.array([0, len(radii)]), np.zeros(n, dtype=np.int64), scale, rotation,
                          drop_xy, lower, upper, LATERAL[params["lateral"]], FLOOR[params["floor"]],
                          wall_contact=WALL_CONTACTS[params["wall_contact"]], trial_angle=params["trial_angle"],
                          cycle_n=params["cycle_n"], cycle_eps=params["cycle_eps"],
                          max_events_per_particle=params["max_events_per_particle"],
                          clock_from_particle=skip if skip < n else -1)
    if result.stopped_at >= 0:
        raise NumericalError(f"particle {result.stopped_at} (of {n}) needed more than max_events_per_particle = "
                             f"{params['max_events_per_particle']} events; raise the limit or check the shape")
    if not np.all(np.isfinite(result.positions)):
        raise NumericalError("non-finite sphere positions in the sediment")
    return TaskResult(_statistics(params, result, volume * scale**3, skip), _configuration(params, result, scale))


def _statistics(params, result, particle_volume, skip) -> dict:
    height = filling_height(result.center_of_mass[:, 2], particle_volume)
    slab = (BULK_SLAB[0] * height, BULK_SLAB[1] * height)
    lower, upper = _measuring_box(params, result)
    bins = params["profile_bins"]
    if params["lateral"] == "none":
        bulk_phi, profile = np.nan, np.full(bins, np.nan)
    else:
        edges = np.linspace(0.0, PROFILE_TOP * height, bins + 1)
        # the bulk slab and the profile's slabs in one pass over the spheres
        fractions = packing_fractions(result.positions, result.radii, lower, upper,
                                      [slab, *zip(edges[:-1], edges[1:])], samples=params["packing_samples"])
        bulk_phi, profile = float(fractions[0]), fractions[1:]
    bulk_z, n_bulk = coordination(result.positions, result.radii, result.particle, result.center_of_mass[:, 2],
                                  lower, upper, *slab)
    counted_spheres = int(np.sum(result.particle >= skip))
    statistics = {
        "filling_height": height,
        "bulk_packing_fraction": bulk_phi,
        "packing_profile": profile,
        "bulk_coordination": bulk_z,
        "n_bulk_particles": n_bulk,
        "n_spheres": len(result.radii),
        "events_per_particle": float(result.event_counts.sum(axis=1).mean()),
        "largest_steps_per_particle": int(result.steps.max()),
        "spheres_per_second": counted_spheres / result.clocked_seconds if result.clocked_seconds > 0 else np.nan,
    }
    for name, kind in EVENT_TOTALS.items():
        statistics[name] = int(result.event_counts[:, sdbd.EVENT_KINDS.index(kind)].sum())
    for name, states in STATE_COUNTS.items():
        statistics[name] = int(np.isin(result.state, states).sum())
    return statistics


def _configuration(params, result, scale) -> Configuration:
    top = float(np.max(result.positions[:, 2] + result.radii))
    periodic = params["lateral"] == "periodic"
    if params["lateral"] == "none":  # the heap's extent
        lower = (result.positions[:, :2] - result.radii[:, None]).min(axis=0)
        upper = (result.positions[:, :2] + result.radii[:, None]).max(axis=0)
    else:
        lower, upper = np.zeros(2), np.full(2, params["box_length"])
    return Configuration(
        arrays={"spheres/position": result.positions, "spheres/radius": result.radii,
                "spheres/particle": result.particle,
                "particles/center_of_mass": result.center_of_mass, "particles/rotation": result.rotation,
                "particles/shape": np.zeros(len(scale), dtype=np.int64), "particles/scale": scale,
                "particles/state": result.state, "particles/contacts": result.contacts,
                "particles/event_counts": result.event_counts, "particles/steps": result.steps},
        box_lower=np.array([lower[0], lower[1], 0.0]), box_upper=np.array([upper[0], upper[1], top]),
        periodic=np.array([periodic, periodic, False]),
        attrs={"floor_z": 0.0, "event_kinds": list(sdbd.EVENT_KINDS), "state_names": list(sdbd.STATE_NAMES),
               "shape_names": [params["shape"]]})


def particle_shape(params: dict) -> tuple[np.ndarray, np.ndarray, float]:
    """Offsets and radii of the particle (in length units, about its centre of mass) and its volume."""
    if params["shape"] == "agglomerate" and not params["agglomerate_file"]:
        raise JobError("shape = 'agglomerate' needs agglomerate_file (a CSV or HDF5 file of spheres)")
    return _built_shape(params["shape"], params["shape_size"], params["shape_spacing"],
                        (params["semi_axis_x"], params["semi_axis_y"], params["semi_axis_z"]),
                        (params["exponent_vertical"], params["exponent_horizontal"]), params["shape_spheres"],
                        params["agglomerate_file"], params["sphere_radius"])


@functools.lru_cache(maxsize=8)
def _built_shape(shape, size, spacing, semi_axes, exponents, n_spheres, agglomerate_file, sphere_radius):
    """Build once per process: the smooth bodies take seconds for thousands of spheres."""
    if shape == "sphere":
        offsets, radii = shape_library.sphere()
    elif shape == "rod":
        offsets, radii = shape_library.rod(size, spacing=spacing)
    elif shape == "four_rods":
        offsets, radii = shape_library.four_rods(size, spacing=spacing)
    elif shape == "tripod":
        offsets, radii = shape_library.tripod(size, spacing=spacing)
    elif shape == "spiky":
        offsets, radii = shape_library.spiky(size)
    elif shape == "cube":
        offsets, radii = shape_library.cube(size)
    elif shape == "ellipsoid":
        offsets, radii = shape_library.ellipsoid(semi_axes, n_spheres)
    elif shape == "superellipsoid":
        offsets, radii = shape_library.superellipsoid(semi_axes, exponents, n_spheres)
    else:
        centres, file_radii = read_agglomerate(agglomerate_file)
        offsets, radii = shape_library.agglomerate(centres / file_radii.mean(), file_radii / file_radii.mean())
    offsets, radii = offsets * sphere_radius, radii * sphere_radius
    _, volume = shape_library.centre_of_mass_of_union(offsets, radii)
    offsets.setflags(write=False)
    radii.setflags(write=False)
    return offsets, radii, float(volume)


def _size_factors(params, rng) -> np.ndarray:
    n, spread = params["n_particles"], params["size_spread"]
    if params["size_distribution"] == "uniform":
        return rng.uniform(1.0 - spread, 1.0 + spread, n)
    if params["size_distribution"] == "lognormal":
        return np.exp(spread * rng.standard_normal(n))
    return np.ones(n)


def _largest_size_factor(params) -> float:
    if params["size_distribution"] == "uniform":
        return 1.0 + params["size_spread"]
    if params["size_distribution"] == "lognormal":
        return float(np.exp(6.0 * params["size_spread"]))  # 6 standard deviations: never reached in practice
    return 1.0


def _drop_positions(params, offsets, radii, scale, rng):
    """Horizontal release positions of the centres of mass."""
    n, length = params["n_particles"], params["box_length"]
    if params["lateral"] == "none":
        u = rng.random((n, 2))  # one row per particle
        radius = params["drop_radius"] * np.sqrt(u[:, 0])  # uniform over the disc
        angle = 2.0 * np.pi * u[:, 1]
        return np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
    if params["lateral"] == "walls":  # the whole particle starts inside, whatever its orientation
        margin = shape_library.bounding_radius(offsets, radii) * scale[:, None]
        if np.any(2.0 * margin >= length):
            raise NumericalError(f"a particle of size factor {scale.max():.4g} does not fit between the walls")
        return margin + rng.random((n, 2)) * (length - 2.0 * margin)
    return rng.random((n, 2)) * length


def _measuring_box(params, result):
    """The horizontal box over which packing and contacts are measured."""
    if params["lateral"] != "none":
        return np.zeros(2), np.full(2, params["box_length"])
    reach = 2.0 * result.radii.max()  # so that periodic wrapping of the measurement meets no sphere twice
    return (result.positions[:, :2].min(axis=0) - 2.0 * reach, result.positions[:, :2].max(axis=0) + 2.0 * reach)


SOLVER = Solver(kind="deposition", description="steepest descent ballistic deposition of multi-sphere particles "
                "(Topic & Poeschel 2016)", parameters=PARAMETERS, statistics=STATISTICS,
                coordinates=coordinates, check=check, cost=cost, memory=memory, memory_keys=memory_keys,
                warm_up_parameters=warm_up_parameters, solve=solve)
