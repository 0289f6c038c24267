"""The particles of a deposition task: its species, their shapes and sizes, and the order of the drops.

A task deposits a mixture of *species*.  A species is a particle shape (a template of
spheres about its centre of mass, built once) with its own size distribution and its
share of the mixture.  Without ``[[species]]`` the job's own keys make the only species;
with them, each ``[[species]]`` entry sets some of :data:`SPECIES_KEYS` and takes the job's
value of the others (a job-level key, swept or fixed, is the default of every species).

The drops come in *layers*: without ``[[layers]]`` one layer of ``n_particles`` particles
drawn from all species; with them, ``n`` particles of the species a layer names, then the
next layer, so that a stratified sediment is one task.  Within a layer every particle's
species is drawn independently with the probabilities of the species' shares (by number,
or by volume: ``share_basis``).

Random streams: the species of the particles come from one stream, the sizes of each
species from its own, so the first k particles of a task are those of the same task with k
particles (the sizes of a single species come from the size stream itself, as before
mixtures existed: a one-species job's sediment is unchanged).
"""

import functools
import math
import os
import re
import warnings
from dataclasses import dataclass

import numpy as np

from parsim.agglomerate_file import read_agglomerate
from parsim.core import shapes as shape_library
from parsim.deposition import sieve
from parsim.deposition.mesh_file import particle_from_mesh_file
from parsim.errors import JobError
from parsim.parameters import shown
from parsim.progress import preparing

SPECIES_KEYS = ("shape", "shape_size", "shape_spacing", "semi_axis_x", "semi_axis_y", "semi_axis_z",
                "exponent_vertical", "exponent_horizontal", "shape_spheres", "agglomerate_file", "mesh_file",
                "mesh_spheres", "sphere_radius", "size_distribution", "size_spread", "sieve_curve", "sieve_basis")
"""The keys a ``[[species]]`` entry may set besides ``name`` and ``share``."""
SPECIES_NAME = re.compile(r"[A-Za-z0-9_.+-]+")
MAX_SPECIES_NAME = 64
# Building a particle: about 1 ms per sphere of an ellipsoid (20 000 spheres: 17 s) and twice that of a
# superellipsoid; a mesh's greedy cover grows as the square of its balls (10 000: 38 s) and reading
# its triangles with the file (4 MiB, 82 000 triangles: 1.4 s)
SECONDS_PER_SMOOTH_SPHERE = {"ellipsoid": 1e-3, "superellipsoid": 2e-3}
SECONDS_PER_MESH_SPHERE_SQUARED = 4e-7
SECONDS_PER_MESH_FILE_BYTE = 3e-7
LOGNORMAL_TAIL = 6.0  # standard deviations: the largest and smallest lognormal factors the checks allow for


@dataclass(frozen=True)
class Species:
    """One species of a task: its parameters (the job's, with the entry's own keys) and its template."""

    name: str
    params: dict
    share: float
    offsets: np.ndarray  # (k, 3) sphere centres about the centre of mass, at scale 1
    radii: np.ndarray  # (k,)
    volume: float  # of the template at scale 1

    @property
    def equivalent_diameter(self) -> float:
        """Diameter of the sphere of the template's volume: the size a sieve curve gives."""
        return (6.0 * self.volume / math.pi) ** (1.0 / 3.0)

    @property
    def extent(self) -> float:
        """Distance from the centre of mass to the farthest sphere surface, at scale 1."""
        return float(shape_library.bounding_radius(self.offsets, self.radii))

    def largest_scale(self) -> float:
        """The largest size factor the distribution gives (box-fit checks)."""
        kind, spread = self.params["size_distribution"], self.params["size_spread"]
        if kind == "uniform":
            return 1.0 + spread
        if kind == "lognormal":
            return float(np.exp(LOGNORMAL_TAIL * spread))
        if kind == "sieve":
            return sieve.size_range(sieve_curve(self.params))[1] / self.equivalent_diameter
        return 1.0

    def smallest_scale(self) -> float:
        """The smallest size factor the distribution gives (the finest grid cell, the flattest cylinder)."""
        kind, spread = self.params["size_distribution"], self.params["size_spread"]
        if kind == "uniform":
            return 1.0 - spread
        if kind == "lognormal":
            return float(np.exp(-LOGNORMAL_TAIL * spread))
        if kind == "sieve":
            return sieve.size_range(sieve_curve(self.params))[0] / self.equivalent_diameter
        return 1.0

    def mean_scale_cubed(self) -> float:
        """E[s^3] of the size factor s: a particle's mean volume is this times the template's."""
        kind, spread = self.params["size_distribution"], self.params["size_spread"]
        if kind == "uniform" and spread > 0.0:
            return ((1.0 + spread) ** 4 - (1.0 - spread) ** 4) / (8.0 * spread)
        if kind == "lognormal":
            return float(np.exp(4.5 * spread**2))
        if kind == "sieve":
            curve = sieve_curve(self.params)
            return sieve.mean_cubed_size(curve, self.params["sieve_basis"]) / self.equivalent_diameter**3
        return 1.0

    def size_factors(self, count: int, rng: np.random.Generator) -> np.ndarray:
        """``count`` size factors, drawn in order (the first k do not depend on ``count``)."""
        kind, spread = self.params["size_distribution"], self.params["size_spread"]
        if kind == "uniform":
            return rng.uniform(1.0 - spread, 1.0 + spread, count)
        if kind == "lognormal":
            return np.exp(spread * rng.standard_normal(count))
        if kind == "sieve":
            sizes = sieve.sample_sizes(sieve_curve(self.params), self.params["sieve_basis"], count, rng)
            return sizes / self.equivalent_diameter
        return np.ones(count)


@dataclass(frozen=True)
class Drops:
    """The particles of a task in deposition order: species index and size factor of each."""

    species: np.ndarray  # (n,) int64
    scale: np.ndarray  # (n,)


def species_of(params: dict) -> tuple[Species, ...]:
    """The task's species, in the order of ``[[species]]`` (one, named after its shape, without it)."""
    entries = params.get("species") or ({},)
    found = []
    for i, entry in enumerate(entries):
        own = species_parameters(params, entry)
        offsets, radii, volume = species_shape(own, entry)
        name = entry.get("name", own["shape"] if len(entries) == 1 else f"species_{i}")
        found.append(Species(name, own, entry.get("share", 1.0), offsets, radii, volume))
    return tuple(found)


def species_parameters(params: dict, entry: dict) -> dict:
    """The parameters of the species of a ``[[species]]`` entry: its own keys, the job's for the rest."""
    return {**params, **{key: value for key, value in entry.items() if key in SPECIES_KEYS}}


def species_shape(own: dict, entry: dict) -> tuple[np.ndarray, np.ndarray, float]:
    """:func:`particle_shape` of a species' parameters ``own``; an error names the ``[[species]]`` entry."""
    try:
        return particle_shape(own)
    except JobError as error:
        raise (JobError(f"[[species]] name = {entry['name']!r}: {error}") if entry else error) from None


def check_species(params: dict) -> None:
    """The checks across entries: distinct names, layers that name species and add up to ``n_particles``."""
    species = species_of(params)
    names = [s.name for s in species]
    for name in names:
        if not SPECIES_NAME.fullmatch(name) or len(name) > MAX_SPECIES_NAME:
            raise JobError(f"[[species]] name = {shown(name)}: allowed: at most {MAX_SPECIES_NAME} letters, digits "
                           "and _ . + - (no blanks; the dataset's species flag_meanings)")
        if names.count(name) > 1:
            raise JobError(f"[[species]] name = {name!r} is given twice; allowed: distinct names")
    for s in species:
        _check_size_distribution(s)
    layers = params.get("layers") or ()
    for i, layer in enumerate(layers):
        for name in _layer_species_names(layer):
            if name not in names:
                raise JobError(f"[[layers]] entry {i + 1}: species = {layer['species']!r} names no species; "
                               f"allowed: names of [[species]] ({', '.join(repr(n) for n in names)}), "
                               "separated by commas, or \"\" for all")
    if layers and sum(layer["n_particles"] for layer in layers) != params["n_particles"]:
        total = sum(layer["n_particles"] for layer in layers)
        raise JobError(f"n_particles = {params['n_particles']} but the [[layers]] hold {total} particles; "
                       f"allowed: n_particles = {total}")


class ParticleDraws:
    """The species and the size factors of a task's particles in deposition order, drawn chunk after
    chunk: successive :meth:`draw` calls give the particles one run after the other, the same as one
    call for all (each stream is read in order, and a draw's first k values do not depend on its
    length), so that a rank can keep the particles it owns without holding all."""

    def __init__(self, params: dict, species: tuple[Species, ...], species_rng, size_rng):
        self.species = species
        self.species_rng = species_rng
        self.size_streams = [size_rng] if len(species) == 1 else size_rng.spawn(len(species))
        self.layers = []  # (first particle, end, normalised cumulative probabilities of the species)
        first = 0
        for count, probabilities in _layer_plan(params, species):
            cumulative = np.cumsum(probabilities)
            cumulative /= cumulative[-1]
            self.layers.append((first, first + count, cumulative))
            first += count
        self.drawn = 0

    def draw(self, count: int) -> Drops:
        """The next ``count`` particles."""
        first, end = self.drawn, self.drawn + count
        uniform = self.species_rng.random(count) if len(self.species) > 1 else np.zeros(count)
        index = np.empty(count, dtype=np.int64)
        for layer_first, layer_end, cumulative in self.layers:
            a, b = max(first, layer_first), min(end, layer_end)
            if a < b:
                index[a - first:b - first] = np.searchsorted(cumulative, uniform[a - first:b - first], side="right")
        index = np.minimum(index, len(self.species) - 1)  # round-off at the top of the cumulative
        scale = np.empty(count)
        for s, stream in enumerate(self.size_streams):
            mine = index == s
            scale[mine] = self.species[s].size_factors(int(mine.sum()), stream)
        self.drawn = end
        return Drops(index, scale)


def number_probabilities(params: dict, species: tuple[Species, ...]) -> np.ndarray:
    """Probability that a particle is of each species: the shares by number, or by volume
    divided by each species' mean particle volume."""
    shares = np.array([s.share for s in species], dtype=float)
    if params["share_basis"] == "volume":
        shares = shares / np.array([s.volume * s.mean_scale_cubed() for s in species])
    return shares / shares.sum()


def _layer_plan(params, species):
    """(count, probabilities over all species) of each layer in deposition order."""
    probabilities = number_probabilities(params, species)
    layers = params.get("layers") or ({"n_particles": params["n_particles"], "species": ""},)
    names = [s.name for s in species]
    plan = []
    for layer in layers:
        chosen = _layer_species_names(layer) or names
        mask = np.array([name in chosen for name in names])
        plan.append((layer["n_particles"], np.where(mask, probabilities, 0.0)))
    return plan


def _layer_species_names(layer: dict) -> list[str]:
    return [name.strip() for name in layer.get("species", "").split(",") if name.strip()]


def _check_size_distribution(s: Species) -> None:
    where = f"species {s.name!r}: " if s.params.get("species") else ""
    if s.params["size_distribution"] == "uniform" and not s.params["size_spread"] < 1.0:
        raise JobError(f"{where}size_spread = {s.params['size_spread']} with size_distribution = 'uniform': "
                       "allowed: 0 <= size_spread < 1 (factors must stay positive)")
    if s.params["size_distribution"] == "sieve":
        if not s.params["sieve_curve"]:
            raise JobError(f"{where}size_distribution = 'sieve' needs sieve_curve (a CSV file of sieve size, "
                           "cumulative percent passing)")
        sieve_curve(s.params)  # reads and checks the file


def sieve_curve(params: dict) -> "sieve.SieveCurve":
    return _read_sieve_curve(params["sieve_curve"])


@functools.lru_cache(maxsize=16)
def _read_sieve_curve(path: str) -> "sieve.SieveCurve":
    return sieve.read_sieve_curve(path)


def particle_shape(params: dict) -> tuple[np.ndarray, np.ndarray, float]:
    """Offsets and radii of the particle (in length units, about its centre of mass) and its volume."""
    if params["shape"] == "agglomerate" and not params["agglomerate_file"]:
        raise JobError("shape = 'agglomerate' needs agglomerate_file (a CSV or HDF5 file of spheres)")
    if params["shape"] == "mesh" and not params["mesh_file"]:
        raise JobError("shape = 'mesh' needs mesh_file (a closed triangle mesh, STL or OBJ)")
    return _built_shape(params["shape"], params["shape_size"], params["shape_spacing"],
                        (params["semi_axis_x"], params["semi_axis_y"], params["semi_axis_z"]),
                        (params["exponent_vertical"], params["exponent_horizontal"]), params["shape_spheres"],
                        params["agglomerate_file"], params["mesh_file"], params["mesh_spheres"],
                        params["sphere_radius"])


def mesh_approximation(params: dict):
    """The error measures of a mesh particle's spheres (:func:`parsim.core.shapes.mesh.mesh_particle`)."""
    return _mesh_spheres(params["mesh_file"], params["mesh_spheres"])[2]


def mesh_volume(params: dict) -> float:
    """Volume enclosed by a mesh species' surface at size factor 1: the mesh is scaled to the volume of
    a sphere of radius ``sphere_radius`` (its spheres, inside it, hold ``1 + volume_error`` of that)."""
    return 4.0 / 3.0 * math.pi * params["sphere_radius"] ** 3


@functools.lru_cache(maxsize=8)
def _mesh_spheres(path: str, n_spheres: int):
    """:func:`particle_from_mesh_file` of ``path``; a mesh it refuses is a one-line JobError.

    The RuntimeWarnings of trimesh and numpy computing with the file's coordinates are held back (they
    print two lines each, before parsim's): where the mesh is then refused, the first of them says why
    in its line (trimesh merges vertices by rounding coordinates times 1e8 to 64-bit integers, which
    overflows beyond about 1e11 and makes the mesh look open); a mesh built despite them passed every
    check of its own.  Other warnings are shown as usual."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        try:
            return particle_from_mesh_file(path, n_spheres=n_spheres)
        except ValueError as error:
            raise JobError(f"mesh_file = {path!r}: {error}{_arithmetic_cause(caught)}") from None
        finally:
            for warning in caught:
                if not issubclass(warning.category, RuntimeWarning):
                    warnings.showwarning(warning.message, warning.category, warning.filename, warning.lineno)


def _arithmetic_cause(caught: list) -> str:
    """What the first RuntimeWarning of ``caught`` tells of a refused mesh, as the end of its line."""
    first = next((warning for warning in caught if issubclass(warning.category, RuntimeWarning)), None)
    if first is None:
        return ""
    return (f"; trimesh could not compute with its coordinates ({first.message}): give finite coordinates "
            "below 1e10 in size (the particle is scaled to sphere_radius whatever the mesh's size)")


@functools.lru_cache(maxsize=16)
def _built_shape(shape, size, spacing, semi_axes, exponents, n_spheres, agglomerate_file, mesh_file, mesh_spheres,
                 sphere_radius):
    """Build once per process: the smooth bodies and meshes take seconds for thousands of spheres, and say
    so while they are built (:func:`parsim.progress.preparing`)."""
    spheres = {"ellipsoid": n_spheres, "superellipsoid": n_spheres, "mesh": mesh_spheres}.get(shape)
    with preparing(f"building the {shape} particle of {spheres} spheres", _build_seconds(shape, spheres, mesh_file)):
        return _shape_of(shape, size, spacing, semi_axes, exponents, n_spheres, agglomerate_file, mesh_file,
                         mesh_spheres, sphere_radius)


def _build_seconds(shape: str, spheres: int | None, mesh_file: str) -> float:
    """Estimated time to build a particle on one core (the constants above)."""
    if shape in SECONDS_PER_SMOOTH_SPHERE:
        return SECONDS_PER_SMOOTH_SPHERE[shape] * spheres
    if shape == "mesh":
        return SECONDS_PER_MESH_SPHERE_SQUARED * spheres**2 + SECONDS_PER_MESH_FILE_BYTE * os.path.getsize(mesh_file)
    return 0.0


def _shape_of(shape, size, spacing, semi_axes, exponents, n_spheres, agglomerate_file, mesh_file, mesh_spheres,
              sphere_radius):
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
    elif shape == "mesh":  # the mesh (not the union of its balls) scaled to volume-equivalent radius 1
        offsets, radii, fit = _mesh_spheres(mesh_file, mesh_spheres)
        offsets, radii = offsets / fit.equivalent_radius, radii / fit.equivalent_radius
    else:
        centres, file_radii = read_agglomerate(agglomerate_file)
        offsets, radii = shape_library.agglomerate(centres / file_radii.mean(), file_radii / file_radii.mean())
    offsets, radii = offsets * sphere_radius, radii * sphere_radius
    _, volume = shape_library.centre_of_mass_of_union(offsets, radii)
    offsets.setflags(write=False)
    radii.setflags(write=False)
    return offsets, radii, float(volume)
