"""Randomised search for deposition jobs whose sediment spread over K ranks is not the serial one.

The claim under test: a deposition split over K ranks (:func:`parsim.deposition.spread.deposit_streamed`)
gives the serial sediment (:func:`parsim.core.sdbd.deposit`) bit for bit, for every job a user can
write.  The search draws small random deposition jobs (TOML text that ``parsim run`` accepts) over
every key that changes a descent: each shape kind (sphere, rod, four_rods, tripod, spiky, cube,
ellipsoid, superellipsoid, an agglomerate file, a mesh: jobs/data/pebble.obj or a generated
octahedron), size distributions (monodisperse, uniform, lognormal, sieve curves of jobs/data or
generated), species mixtures by number or volume and their layers, the container (a periodic or
walled box, a heap on an open floor with its drop radius, a cylinder with its side count, a mesh
vessel: a hopper with or without a collar, a bowl, a V-trough, a prism or a wedge, poured over its
opening or through a drop disc), the
floor, the wall contact, a substrate, the trial angle, the cycling criterion and the event limit.
The container is sized from the particles so that most jobs split into K blocks (blocks wider
than the default halo); each job takes about a second once the kernels are compiled.

Each job's inputs are built as ``parsim run`` builds them (the task's random stream from the
job's seed, :func:`parsim.deposition.solver.deposition_inputs`); the serial sediment is deposited
once, then the job runs under ``mpiexec -n K`` with ``deposit_streamed(..., check=True)`` and the
gathered sediment is compared with the serial one field by field, bitwise (positions, radii,
particle, center_of_mass, rotation, contacts, state, event_counts, steps, stopped_at).  The serial
sediment is checked for overlaps between spheres of different particles (beyond 1e-9 of the mean
sphere radius), and so is a spread one that differs from it.

Every failure is recorded and the search goes on: a divergent sediment, an overlap, an exception
(a DecompositionError of the checks; ``deposit_streamed`` then ends every rank with MPI_Abort), a
crash, or a job still running after ``--timeout`` seconds (killed).  The jobs of one K run one
after the other in one ``mpiexec``; after a failure that ends it, a new one resumes at the next
job.  The summary lists per K the jobs run, split into blocks, and failed, and for each failure
the first divergent particle and the job's TOML to reproduce it; ``--report`` writes it as JSON.

    python benchmarks/spread_equivalence.py --jobs 200 --seed 1 --ranks 2 3 4 [--timeout 120]
                                            [--report report.json] [--work DIR] [--no-check]
    python benchmarks/spread_equivalence.py --one job.toml --ranks 2 3 4   # one job, to reproduce
    python benchmarks/spread_equivalence.py --one job.toml --ranks 2 --particles 40   # its first 40
    python benchmarks/spread_equivalence.py --one job.toml --ranks 2 --shrink [--found DIR] [--repeat 2]

``--no-check`` runs ``deposit_streamed`` without ``check=True`` (whether the sediment differs,
rather than whether a committed particle's read changed).  ``--particles N`` deposits only the
first N particles of each job, from the job's own random stream (a job with ``n_particles = N``
would draw other particles: the stream derives from the parameters).  ``--shrink`` bisects that
number for each failing job and writes the job, with its input files and the command that runs its
smallest failing number of particles, to ``--found`` (default benchmarks/found); ``--repeat R``
runs each smaller job up to R times before it counts as passing (some failures do not repeat).

Exits with 1 if a job failed (or the serial deposit refused one, or its sediment overlaps).  Input
files a job needs (agglomerates, substrates, sieve curves, meshes) are written into the work folder
(``--work``, default a temporary folder, kept when a job failed) and named by absolute path in its
TOML.
"""

import argparse
import json
import math
import re
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

REPOSITORY = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPOSITORY))  # tests.sediment_checks and tests.mpi from the source tree

from parsim.core import sdbd  # noqa: E402
from parsim.errors import JobError  # noqa: E402
from parsim.job import parse_job  # noqa: E402
from parsim.solvers import SOLVERS  # noqa: E402
from parsim.deposition.solver import deposition_inputs  # noqa: E402
from parsim.deposition.materials import species_of  # noqa: E402
from parsim.deposition.vessel import (bowl_mesh, hopper_mesh, prism_mesh, v_trough_mesh,  # noqa: E402
                                      vessel_from_mesh, wedge_mesh)
from tests.mpi import kill_session, mpiexec  # noqa: E402
from tests.sediment_checks import close_pairs  # noqa: E402

FIELDS = ("positions", "radii", "particle", "center_of_mass", "rotation", "contacts", "state", "event_counts",
          "steps", "stopped_at")
SPHERE_FIELDS = ("positions", "radii", "particle")  # one row per sphere; the others one per particle
OVERLAP_TOLERANCE = 1e-9  # of the mean sphere radius
SPHERE_BUDGET = 8000  # spheres of a job's sediment at most: about a second once compiled
PEBBLE = REPOSITORY / "jobs" / "data" / "pebble.obj"
SIEVE_CURVES = sorted((REPOSITORY / "jobs" / "data").glob("*.csv"))
CHAIN_SIZES = {"rod": (2, 6), "four_rods": (2, 3), "tripod": (2, 4), "spiky": (2, 4), "cube": (2, 3)}
DRAW_ATTEMPTS = 20
#: run by each worker before its first job, untimed: the kernels compile (or load from numba's cache) in it
WARM_UP = """name = "warm_up"
kind = "deposition"
seed = 1
realizations = 1

[parameters]
n_particles = 200
box_length = 24.0
floor = "roll"
"""
HALO_SCALE = 1.3  # the largest size factor of a job's particles, in typical ones (for the halo's estimate)
LARGEST = {"box_length": 60.0, "container_radius": 30.0, "drop_radius": 25.0,  # containers at most this wide
           "vessel_radius": 30.0}


# ---------------------------------------------------------------- drawing jobs


class JobDraw:
    """One random job: its keys drawn from ``rng``; its input files go to ``folder`` as ``stem``_*."""

    def __init__(self, rng: np.random.Generator, folder: Path, stem: str):
        self.rng, self.folder, self.stem = rng, folder, stem
        self.files = 0
        self.seed = int(rng.integers(0, 2**31))  # the job's own seed
        self.opening_area = None  # a mesh vessel's, once drawn

    def text(self) -> str:
        """The job's TOML: particles first, then a container sized from them."""
        parameters, species, layered = self.particles()
        sizes = _particle_sizes(_toml(self.seed, {"n_particles": 1, **parameters, "box_length": 1000.0}, species))
        parameters.update(self.container(sizes))
        n = self.particle_count(sizes, parameters)
        layers = self.layers_of(n, species) if layered else []
        return _toml(self.seed, {"n_particles": n, **parameters}, species, layers)

    # the particles

    def particles(self):
        rng = self.rng
        parameters = {"sphere_radius": self.rounded(rng.uniform(0.3, 1.0))}
        if rng.random() < 0.3:  # a mixture
            species = [{"name": f"s{k}", "share": self.rounded(rng.uniform(0.2, 1.0)), **self.species_keys()}
                       for k in range(int(rng.integers(2, 4)))]
            if rng.random() < 0.5:
                parameters["share_basis"] = "volume"
            layers = rng.random() < 0.4
        else:
            species, layers = [], False
            parameters.update(self.species_keys())
        parameters.update(self.method_keys())
        return parameters, species, layers

    def species_keys(self) -> dict:
        """A shape with its keys and a size distribution."""
        rng = self.rng
        shape = str(rng.choice(("sphere", "rod", "four_rods", "tripod", "spiky", "cube", "ellipsoid",
                                "superellipsoid", "agglomerate", "mesh")))
        keys = {"shape": shape}
        if shape in CHAIN_SIZES:
            keys["shape_size"] = int(rng.integers(CHAIN_SIZES[shape][0], CHAIN_SIZES[shape][1] + 1))
        if shape in ("rod", "four_rods", "tripod") and rng.random() < 0.5:
            keys["shape_spacing"] = self.rounded(rng.uniform(0.6, 2.0))
        if shape in ("ellipsoid", "superellipsoid"):
            keys.update(semi_axis_x=self.rounded(rng.uniform(1.0, 2.5)),
                        semi_axis_y=self.rounded(rng.uniform(0.8, 2.0)),
                        semi_axis_z=self.rounded(rng.uniform(0.6, 1.6)), shape_spheres=int(rng.integers(5, 41)))
        if shape == "superellipsoid":
            keys.update(exponent_vertical=self.rounded(rng.uniform(1.3, 6.0)),
                        exponent_horizontal=self.rounded(rng.uniform(1.3, 6.0)))
        if shape == "agglomerate":
            keys["agglomerate_file"] = self.agglomerate_file()
        if shape == "mesh":
            keys["mesh_file"] = str(PEBBLE) if rng.random() < 0.5 else self.mesh_file()
            keys["mesh_spheres"] = int(rng.integers(4, 31))
        keys.update(self.size_keys())
        return keys

    def size_keys(self) -> dict:
        rng = self.rng
        kind = str(rng.choice(("monodisperse", "uniform", "lognormal", "sieve"), p=(0.35, 0.3, 0.2, 0.15)))
        if kind == "monodisperse":
            return {}
        if kind == "sieve":
            curve = str(rng.choice(SIEVE_CURVES)) if rng.random() < 0.3 else self.sieve_file()
            return {"size_distribution": "sieve", "sieve_curve": curve,
                    "sieve_basis": str(rng.choice(("mass", "number")))}
        high = 0.4 if kind == "uniform" else 0.25
        return {"size_distribution": kind, "size_spread": self.rounded(rng.uniform(0.0, high))}

    def method_keys(self) -> dict:
        """The keys of the descent itself, each now and then away from its default."""
        rng = self.rng
        keys = {"floor": str(rng.choice(("stop", "roll")))}
        if rng.random() < 0.25:
            keys["trial_angle"] = self.rounded(10.0 ** rng.uniform(-3.5, -0.5))
        if rng.random() < 0.15:
            keys["cycle_n"] = int(rng.integers(0, 8))
            keys["cycle_eps"] = self.rounded(10.0 ** rng.uniform(-5, -1))
        if rng.random() < 0.08:
            keys["max_events_per_particle"] = int(rng.integers(5, 200))
        return keys

    # the container

    def container(self, sizes: dict) -> dict:
        """A box (periodic, walls), a heap, a cylinder or a mesh vessel, mostly wide enough to split into 2-4
        blocks."""
        rng = self.rng
        halo, extent = sizes["halo"], sizes["largest_extent"]
        kind = str(rng.choice(("periodic", "walls", "heap", "cylinder", "vessel"), p=(0.25, 0.2, 0.15, 0.2, 0.2)))
        wide = rng.random() < 0.8
        if kind == "vessel":
            size = rng.uniform(*((1.0, 2.6) if wide else (0.6, 1.0))) * halo
            return self.vessel_keys(self.rounded(max(min(size, LARGEST["vessel_radius"]), 1.5 * extent)), extent)
        if kind == "cylinder":
            key, smallest, split, narrow = "container_radius", 1.05 * extent, (1.0, 2.6), (0.5, 1.0)
        elif kind == "heap":
            key, smallest, split, narrow = "drop_radius", 0.2 * extent, (0.5, 2.6), (0.05, 0.3)
        else:
            key, smallest, split, narrow = "box_length", 2.1 * extent, (2.0, 5.0), (0.5, 2.0)
        size = rng.uniform(*(split if wide else narrow)) * halo
        keys = {"container": "cylinder"} if kind == "cylinder" else {"lateral": "none" if kind == "heap" else kind}
        keys[key] = self.rounded(max(min(size, LARGEST[key]), smallest))
        if kind == "cylinder" and rng.random() < 0.4:
            keys["container_sides"] = int(rng.integers(sdbd.MIN_CYLINDER_SIDES, 49))
        if kind in ("cylinder", "walls") and rng.random() < 0.4:
            keys["wall_contact"] = "glued"
        if rng.random() < 0.15:
            keys["substrate"] = self.substrate_file(keys, sizes)
        return keys

    def vessel_keys(self, size: float, extent: float) -> dict:
        """A random convex vessel about ``size`` wide (a radius), written as OBJ: a hopper with or without a
        collar, a bowl, a V-trough, a prism or a wedge; frictionless or glued; poured over its opening or
        through a drop disc about its centroid."""
        rng = self.rng
        kind = str(rng.choice(("hopper", "bowl", "trough", "prism", "wedge")))
        if kind == "hopper":
            rim = rng.uniform(0.2, 0.6) * size if rng.random() < 0.5 else None
            mesh = hopper_mesh(size, rng.uniform(0.3, 0.8) * size, rng.uniform(0.5, 1.5) * size,
                               int(rng.integers(4, 13)), rim=rim)
        elif kind == "bowl":
            mesh = bowl_mesh(size, rng.uniform(0.5, 1.0) * size, int(rng.integers(6, 17)), int(rng.integers(2, 6)),
                             bottom=rng.uniform(0.2, 0.5))
        elif kind == "trough":
            mesh = v_trough_mesh(2.0 * size, 2.0 * size * rng.uniform(0.6, 1.0), size * rng.uniform(0.3, 1.0))
        elif kind == "prism":
            mesh = prism_mesh(size, size * rng.uniform(0.5, 1.5), int(rng.integers(3, 25)))
        else:
            lx, angle = 2.0 * size, rng.uniform(10.0, 40.0)
            start = rng.uniform(0.0, 0.3) * lx
            mesh = wedge_mesh(lx, 2.0 * size, (lx - start) * math.tan(math.radians(angle)) + size, angle, start)
        path = self.path(".obj")
        mesh.export(path, digits=17)
        vessel = vessel_from_mesh(mesh)
        self.opening_area = vessel.area_at(vessel.upper[2])
        keys = {"container": "mesh", "container_file": str(path)}
        if rng.random() < 0.4:
            keys["wall_contact"] = "glued"
        if rng.random() < 0.3:
            keys["drop_area_radius"] = self.rounded(max(rng.uniform(0.3, 1.0) * size, 1.5 * extent))
        return keys

    def particle_count(self, sizes: dict, parameters: dict) -> int:
        """About 1-4 layers of particles over the container's floor, 50-600, within SPHERE_BUDGET spheres."""
        if self.opening_area is not None:
            area = self.opening_area
        elif "box_length" in parameters:
            area = parameters["box_length"] ** 2
        elif "container_radius" in parameters:
            area = math.pi * parameters["container_radius"] ** 2
        else:
            area = math.pi * (parameters["drop_radius"] + 2.0 * sizes["extent"]) ** 2
        layer = area / (math.pi * sizes["extent"] ** 2)
        n = layer * self.rng.uniform(1.0, 4.0)
        return int(min(max(n, 50), 600, max(SPHERE_BUDGET // sizes["spheres"], 50)))

    def layers_of(self, n: int, species: list) -> list:
        """Two or three layers naming one species, several or all."""
        count = int(self.rng.integers(2, 4))
        cuts = np.sort(self.rng.choice(np.arange(1, n), count - 1, replace=False))
        sizes = np.diff([0, *cuts, n])
        names = [s["name"] for s in species]
        layers = []
        for size in sizes:
            chosen = self.rng.choice(names, int(self.rng.integers(1, len(names) + 1)), replace=False)
            layers.append({"n_particles": int(size), "species": ",".join(sorted(chosen)) if len(chosen) < len(names)
                           else ""})
        return layers

    # input files

    def path(self, suffix: str) -> Path:
        self.files += 1
        return self.folder / f"{self.stem}_{self.files}{suffix}"

    def agglomerate_file(self) -> str:
        """A chain of 3-10 overlapping or touching spheres, each next to one before it."""
        rng = self.rng
        count = int(rng.integers(3, 11))
        centres, radii = [np.zeros(3)], [1.0]
        for _ in range(count - 1):
            radius = rng.uniform(0.6, 1.0)
            base = int(rng.integers(0, len(centres)))
            direction = rng.standard_normal(3)
            direction /= np.linalg.norm(direction)
            centres.append(centres[base] + direction * (radii[base] + radius) * rng.uniform(0.5, 1.0))
            radii.append(radius)
        rows = [f"{x:.6f},{y:.6f},{z:.6f},{r:.6f}" for (x, y, z), r in zip(centres, radii)]
        return self.write(".csv", "x,y,z,r\n" + "\n".join(rows) + "\n")

    def mesh_file(self) -> str:
        """An octahedron stretched along its axes: a closed convex mesh of 8 triangles."""
        a, b, c = (self.rounded(value) for value in self.rng.uniform(0.5, 1.5, 3))
        vertices = [(a, 0, 0), (-a, 0, 0), (0, b, 0), (0, -b, 0), (0, 0, c), (0, 0, -c)]
        faces = [(1, 3, 5), (3, 2, 5), (2, 4, 5), (4, 1, 5), (3, 1, 6), (2, 3, 6), (4, 2, 6), (1, 4, 6)]
        lines = [f"v {x} {y} {z}" for x, y, z in vertices] + [f"f {i} {j} {k}" for i, j, k in faces]
        return self.write(".obj", "\n".join(lines) + "\n")

    def sieve_file(self) -> str:
        """Three sieves about a diameter of 0.5-2: 0 %, some, 100 % passing."""
        rng = self.rng
        middle = rng.uniform(0.5, 2.0)
        ratio = rng.uniform(1.1, 1.6)
        passing = rng.uniform(10, 90)
        return self.write(".csv", f"size,passing\n{middle / ratio:.5f},0\n{middle:.5f},{passing:.3f}\n"
                                  f"{middle * ratio:.5f},100\n")

    def substrate_file(self, container: dict, sizes: dict) -> str:
        """Spheres resting on (or sunk a little into) the floor, inside the container."""
        rng = self.rng
        radius = sizes["sphere"] * rng.uniform(0.4, 1.2)
        if "box_length" in container:
            length = container["box_length"]
            xy = radius + rng.random((1000, 2)) * (length - 2 * radius)
        else:
            if "container_radius" in container:
                centre, reach = container["container_radius"], 0.9 * container["container_radius"] - radius
            else:
                centre, reach = 0.0, container["drop_radius"] + 2.0 * sizes["extent"]
            distance, angle = reach * np.sqrt(rng.random(1000)), 2 * np.pi * rng.random(1000)
            xy = np.column_stack([centre + distance * np.cos(angle), centre + distance * np.sin(angle)])
        xy = xy[: int(rng.integers(10, 200))]
        z = radius * rng.uniform(0.5, 1.0, len(xy))
        rows = [f"{x:.6f},{y:.6f},{h:.6f},{radius:.6f}" for (x, y), h in zip(xy, z)]
        return self.write(".csv", "x,y,z,r\n" + "\n".join(rows) + "\n")

    def write(self, suffix: str, content: str) -> str:
        path = self.path(suffix)
        path.write_text(content)
        return str(path)

    @staticmethod
    def rounded(value: float) -> float:
        return float(f"{value:.4g}")


def _particle_sizes(text: str) -> dict:
    """What sizes a container for the job ``text``: the largest particle extent (what must fit), a typical
    one and a typical sphere radius (at the size factor of the mean volume), the spheres of the largest
    particle, and about the default halo of a spread run (4 grid cells and twice the extent, with the size
    factors a few hundred particles reach)."""
    species = species_of(parse_job(text, SOLVERS, source="<draft job>").point_parameters(0))
    typical = [min(s.largest_scale(), HALO_SCALE * s.mean_scale_cubed() ** (1 / 3)) for s in species]
    extent = max(s.extent * scale for s, scale in zip(species, typical))
    sphere = max(float(s.radii.max()) * scale for s, scale in zip(species, typical))
    return {"largest_extent": max(s.extent * s.largest_scale() for s in species), "extent": extent,
            "sphere": sphere, "spheres": max(len(s.radii) for s in species), "halo": 8.0 * sphere + 2.0 * extent}


def _toml(seed: int, parameters: dict, species: list, layers: list = ()) -> str:
    lines = ['name = "spread_equivalence"', 'kind = "deposition"', f"seed = {seed}", "realizations = 1", "",
             "[parameters]", *(_toml_line(key, value) for key, value in parameters.items())]
    for entry in species:
        lines += ["", "[[species]]", *(_toml_line(key, value) for key, value in entry.items())]
    for entry in layers:
        lines += ["", "[[layers]]", *(_toml_line(key, value) for key, value in entry.items())]
    return "\n".join(lines) + "\n"


def _toml_line(key: str, value) -> str:
    return f"{key} = {json.dumps(value) if isinstance(value, str) else repr(value)}"


def draw_jobs(count: int, seed: int, folder: Path) -> list[str]:
    """``count`` valid jobs (``parse_job`` accepts each), the same for the same seed."""
    streams = np.random.SeedSequence(seed).spawn(count)
    jobs = []
    for number, stream in enumerate(streams):
        rng = np.random.default_rng(stream)
        for attempt in range(DRAW_ATTEMPTS):
            try:
                text = JobDraw(rng, folder, f"job{number:05d}_{attempt}").text()
                parse_job(text, SOLVERS, source=f"job {number}")
            except JobError:
                continue
            jobs.append(text)
            break
        else:
            raise RuntimeError(f"job {number}: no valid job in {DRAW_ATTEMPTS} draws")
    return jobs


# ---------------------------------------------------------------- running a job


def task_inputs(text: str, spread: bool, particles: int | None = None):
    """The deposition inputs of the job's one task, as ``parsim run`` builds them; with ``particles``, of
    its first ``particles`` particles alone (from the task's random stream, which derives from the job's
    parameters: the job with ``n_particles = particles`` would draw other particles)."""
    job = parse_job(text, SOLVERS, source="<job>")
    task = job.tasks()[0]
    params = job.point_parameters(task.point)
    if particles is not None:
        params = {**params, "n_particles": min(particles, params["n_particles"])}
    return deposition_inputs(params, np.random.default_rng(job.seed_sequence(task)), spread)


def serial_sediment(text: str, particles: int | None = None):
    inputs = task_inputs(text, spread=False, particles=particles)
    drops, rotation, drop_xy = next(inputs.particles())
    return sdbd.deposit(*inputs.shapes, drops.species, drops.scale, rotation, drop_xy, *inputs.container,
                        **inputs.options)


def spread_sediment(comm, text: str, check: bool = True, particles: int | None = None, jitter: float = 0.0):
    """The gathered spread sediment on rank 0 (None on the others), the inputs and the blocks that held particles."""
    from parsim.deposition.spread import deposit_streamed

    inputs = task_inputs(text, spread=True, particles=particles)
    share = deposit_streamed(comm, *inputs.shapes, inputs.kernel_chunks, *inputs.container, **inputs.options,
                             check=check, jitter=jitter)
    blocks = sum(comm.allgather(int(share.tally["particles"] > 0)))
    return share.gather(comm), inputs, blocks


def first_divergence(serial: dict, spread) -> dict | None:
    """The first particle (drop index) at which ``spread`` differs from ``serial``, and the fields that differ."""
    fields = [f for f in FIELDS if not (np.shape(serial[f]) == np.shape(getattr(spread, f))
                                         and np.array_equal(serial[f], getattr(spread, f)))]
    if not fields:
        return None
    firsts = [_first_particle(f, serial, np.asarray(getattr(spread, f))) for f in fields]
    return {"fields": fields, "particle": min(firsts)}


def _first_particle(field: str, serial: dict, spread: np.ndarray) -> int:
    if field == "stopped_at":
        return int(min(s for s in (serial[field], spread) if s >= 0))
    ours = serial[field]
    rows = min(len(ours), len(spread))
    differ = np.flatnonzero(np.any((ours[:rows] != spread[:rows]).reshape(rows, -1), axis=1))
    row = int(differ[0]) if len(differ) else rows
    if field in SPHERE_FIELDS:
        particles = serial["particle"]
        return int(particles[row]) if row < len(particles) else int(particles[-1]) + 1 if len(particles) else 0
    return row


def first_overlap(result, inputs) -> dict | None:
    """The deepest overlap between spheres of different particles beyond the tolerance, if any."""
    lower, upper, lateral, _ = inputs.container
    if len(result.radii) < 2:
        return None
    pairs, distances = close_pairs(result.positions, result.radii, lateral, lower, upper, 0.0)
    i, j = pairs.T if len(pairs) else (np.zeros(0, dtype=int), np.zeros(0, dtype=int))
    depth = result.radii[i] + result.radii[j] - distances
    bad = (result.particle[i] != result.particle[j]) & (depth > OVERLAP_TOLERANCE * result.radii.mean())
    if not bad.any():
        return None
    worst = np.flatnonzero(bad)[np.argmax(depth[bad])]
    return {"particles": [int(result.particle[i[worst]]), int(result.particle[j[worst]])],
            "depth": float(depth[worst]), "pairs": int(bad.sum())}


# ---------------------------------------------------------------- worker: the jobs of one K in one process


def serial_worker(jobs: list[Path], runs: "Runs", log: Path) -> None:
    """Each job's serial sediment, saved as ``work/serial/NAME.npz``; one JSON line per job in ``log``."""
    work = runs.work
    (work / "serial").mkdir(exist_ok=True)
    serial_sediment(WARM_UP)
    for path in jobs:
        _log(log, {"job": path.stem, "event": "start"})
        start = time.perf_counter()
        try:
            result = serial_sediment(path.read_text(), runs.particles)
        except Exception as error:  # a job the serial kernel refuses is no test of the spread one
            _log(log, {"job": path.stem, "outcome": "serial error", "error": f"{type(error).__name__}: {error}"})
            continue
        np.savez(work / "serial" / f"{path.stem}.npz", **{f: getattr(result, f) for f in FIELDS})
        overlap = first_overlap(result, task_inputs(path.read_text(), spread=False, particles=runs.particles))
        _log(log, {"job": path.stem, "outcome": "serial overlap" if overlap else "done", "overlap": overlap,
                   "seconds": time.perf_counter() - start, "particles": len(result.state),
                   "spheres": len(result.radii), "stopped_at": result.stopped_at})


def spread_worker(jobs: list[Path], runs: "Runs", log: Path) -> None:
    """Each job under this ``mpiexec``: the spread sediment against the serial one (rank 0 logs)."""
    from mpi4py import MPI

    work = runs.work
    comm = MPI.COMM_WORLD
    spread_sediment(comm, WARM_UP)
    for path in jobs:
        serial_file = work / "serial" / f"{path.stem}.npz"
        if not serial_file.exists():
            continue  # the serial run failed: recorded there
        if comm.rank == 0:
            _log(log, {"job": path.stem, "event": "start"})
        start = time.perf_counter()
        whole, inputs, blocks = spread_sediment(comm, path.read_text(), runs.check, runs.particles, runs.jitter)
        if comm.rank == 0:
            with np.load(serial_file) as saved:
                serial = {f: saved[f] for f in FIELDS}
            divergence = first_divergence(serial, whole)  # an overlap of the serial sediment is the serial run's
            overlap = first_overlap(whole, inputs) if divergence else None
            outcome = "divergent" if divergence else "overlap" if overlap else "equal"
            particle = divergence["particle"] if divergence else min(overlap["particles"]) if overlap else None
            _log(log, {"job": path.stem, "outcome": outcome, "particle": particle, "divergence": divergence,
                       "overlap": overlap,
                       "blocks": blocks, "seconds": time.perf_counter() - start})
        comm.Barrier()


def _log(log: Path, entry: dict) -> None:
    with open(log, "a") as out:
        out.write(json.dumps(entry) + "\n")


# ---------------------------------------------------------------- driver


@dataclass(frozen=True)
class Runs:
    """How the jobs run: their folder, the seconds one may take, and ``deposit_streamed``'s ``check``."""

    work: Path
    timeout: float
    check: bool = True
    repeat: int = 1  # runs of a job while shrinking, before it counts as passing (a failure may not repeat)
    particles: int | None = None  # deposit only each job's first particles (see task_inputs)
    jitter: float = 0.0  # deposit_streamed's random delays (seconds): the sediment must not depend on the timing

    def options(self) -> list[str]:
        """The command line that gives a worker these settings."""
        return [*(() if self.check else ("--no-check",)), *(("--particles", str(self.particles)) if self.particles
                                                           else ()), *(("--jitter", str(self.jitter)) if self.jitter
                                                                       else ())]


def run_all(jobs: list[Path], ranks: int, runs: Runs) -> dict:
    """Outcome of each job on ``ranks`` ranks (1: the serial run); one process at a time runs the jobs
    left, and a job that ends it (an abort, a crash) or outlasts the timeout is recorded and skipped."""
    outcomes = {}
    left = list(jobs)
    work = runs.work
    log = work / f"log_{ranks}.jsonl"
    while left:
        listed = work / f"left_{ranks}.txt"
        listed.write_text("\n".join(str(p) for p in left) + "\n")
        command = [sys.executable, __file__, "--worker", str(ranks), str(listed), str(work), str(log),
                   "--timeout", str(runs.timeout), *runs.options()]
        if ranks > 1:
            command = [mpiexec(), "-n", str(ranks), *command]
        stderr, timed_out, current = _supervise(command, log, runs.timeout)
        for entry in _read_log(log):
            if "outcome" in entry:
                outcomes[entry["job"]] = entry
        if current is not None and current not in outcomes:
            outcomes[current] = _ended(current, stderr, timed_out)
        done = {p.stem for p in left if p.stem in outcomes or not _runs_on(p, ranks, work)}
        if not done and current is None:  # ended before any job: a failure of the worker itself
            raise RuntimeError(f"the worker on {ranks} ranks ended without running a job:\n{stderr}")
        left = [p for p in left if p.stem not in done]
    return outcomes


def _runs_on(path: Path, ranks: int, work: Path) -> bool:
    return ranks == 1 or (work / "serial" / f"{path.stem}.npz").exists()


def _supervise(command, log: Path, timeout: float):
    """Run ``command`` until it ends or its current job outlasts ``timeout``: (stderr, timed out, the job
    started last and not finished, or None)."""
    with tempfile.TemporaryFile("w+") as errors:
        process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=errors, start_new_session=True)
        timed_out = False
        try:
            while process.poll() is None:
                time.sleep(0.2)
                current, since = _current_job(log)
                if current is not None and time.time() - since > timeout:
                    kill_session(process)
                    timed_out = True
        finally:
            if process.poll() is None:  # interrupted: no rank outlives the search
                kill_session(process)
        errors.seek(0)
        stderr = errors.read()
    current, _ = _current_job(log)
    return stderr, timed_out, current


def _current_job(log: Path):
    """The job started last in ``log`` and not finished (None if none), and when it started."""
    entries = _read_log(log)
    if entries and entries[-1].get("event") == "start":
        return entries[-1]["job"], log.stat().st_mtime
    return None, 0.0


def _read_log(log: Path) -> list[dict]:
    if not log.exists():
        return []
    return [json.loads(line) for line in log.read_text().splitlines() if line.strip().endswith("}")]


def _ended(job: str, stderr: str, timed_out: bool) -> dict:
    """The outcome of a job that ended its worker: a timeout, an exception (its message names the particle
    a DecompositionError found) or a crash (a signal, no message)."""
    error = _error_lines(stderr)
    said = re.search(r"^(?:\w+\.)*(\w+Error): (?:particle (\d+))?", error, flags=re.MULTILINE)
    if timed_out:
        return {"job": job, "outcome": "timeout", "error": error}
    if said is None or "parsim: error" not in error:
        return {"job": job, "outcome": "crash", "error": error}
    return {"job": job, "outcome": said.group(1), "error": error,
            **({"particle": int(said.group(2))} if said.group(2) else {})}


def _error_lines(stderr: str) -> str:
    """What ``stderr`` says failed: from parsim's error line on (the failing rank's traceback), or its
    last 20 lines."""
    lines = [line for line in stderr.splitlines() if line.strip()]
    said = [k for k, line in enumerate(lines) if "parsim: error" in line]
    return "\n".join(lines[said[0]:said[0] + 40] if said else lines[-20:])


def failures(outcomes: dict) -> dict:
    return {job: entry for job, entry in outcomes.items() if entry["outcome"] not in ("equal", "done")}


def summary(jobs: list[Path], serial: dict, spread: dict[int, dict]) -> dict:
    texts = {p.stem: p.read_text() for p in jobs}
    report = {"jobs": len(jobs), "serial_errors": failures(serial), "ranks": {}}
    for ranks, outcomes in spread.items():
        failed = failures(outcomes)
        report["ranks"][ranks] = {
            "run": len(outcomes), "split": sum(1 for e in outcomes.values() if e.get("blocks", 0) > 1),
            "divergent": sum(1 for e in failed.values() if e["outcome"] == "divergent"),
            "failed": len(failed),
            "failures": [{**entry, "toml": texts[job]} for job, entry in sorted(failed.items())]}
    return report


def print_summary(report: dict) -> None:
    print(f"{report['jobs']} jobs drawn; {len(report['serial_errors'])} refused by the serial deposit or "
          f"overlapping in its sediment")
    for job, entry in report["serial_errors"].items():
        print(f"  {job}: {_failure_detail(entry)}")
    for ranks, tally in report["ranks"].items():
        print(f"K = {ranks}: {tally['run']} jobs run, {tally['split']} split into blocks, "
              f"{tally['divergent']} divergent, {tally['failed']} failed")
    for ranks, tally in report["ranks"].items():
        for entry in tally["failures"]:
            print(f"\n--- K = {ranks}, {entry['job']}: {entry['outcome']}: {_failure_detail(entry)}")
            print(entry["toml"], end="")


def _failure_detail(entry: dict) -> str:
    if entry.get("divergence"):
        divergence = entry["divergence"]
        return f"first divergent particle {divergence['particle']} ({', '.join(divergence['fields'])})"
    if entry.get("overlap"):
        overlap = entry["overlap"]
        return f"particles {overlap['particles']} overlap by {overlap['depth']:.3g} ({overlap['pairs']} pairs)"
    said = re.findall(r"^(?:\w+\.)*\w+Error: .*$", entry.get("error", ""), flags=re.MULTILINE)
    return said[-1] if said else (entry.get("error", "").splitlines() or [""])[-1]  # the report keeps the traceback


def first_failures(report: dict) -> dict:
    """Each failing job's failure on the fewest ranks."""
    first = {}
    for ranks, tally in sorted(report["ranks"].items()):
        for entry in tally["failures"]:
            first.setdefault(entry["job"], {**entry, "ranks": ranks})
    return first


def job_tag(text: str) -> str:
    """Shapes, container and floor of a job, for a file name: e.g. ``rod_cylinder_roll``."""
    document = tomllib.loads(text)
    parameters = document["parameters"]
    shapes = sorted({entry.get("shape", parameters.get("shape", "sphere"))
                     for entry in document.get("species", [{}])})
    container = "cylinder" if parameters.get("container") == "cylinder" else \
        {"none": "heap"}.get(parameters.get("lateral", "periodic"), parameters.get("lateral", "periodic"))
    return "_".join([*shapes, container, parameters.get("floor", "stop")])


def search(jobs: list[Path], ranks: list[int], runs: Runs) -> dict:
    serial = run_all(jobs, 1, runs)
    spread = {k: run_all(jobs, k, runs) for k in ranks}
    return summary(jobs, serial, spread)


# ---------------------------------------------------------------- shrinking a failure


def shrink(text: str, ranks: list[int], runs: Runs, tries: int = 8) -> tuple[int, dict]:
    """The fewest first particles of the job ``text`` found to fail still on one of ``ranks``, and their
    failure; ``tries`` runs at most.  The particles keep the job's random stream (``--particles``), so the
    first p of them are the same whatever their number: a divergence at particle p is first tried with
    p + 1 particles, then the count is bisected."""
    n = runs.particles or tomllib.loads(text)["parameters"]["n_particles"]
    failure = _failure_of(text, ranks, replace(runs, work=runs.work / "shrink_0", particles=n))
    if failure is None:
        raise RuntimeError("the job does not fail: nothing to shrink")
    passing = 0
    for attempt in range(1, tries + 1):
        first = failure.get("particle")
        candidate = first + 1 if first is not None and passing < first + 1 < n else (passing + n) // 2
        if candidate <= passing or candidate >= n:
            break
        found = _failure_of(text, ranks, replace(runs, work=runs.work / f"shrink_{attempt}", particles=candidate))
        if found is None:
            passing = candidate
        else:
            n, failure = candidate, found
    return n, failure


def _failure_of(text: str, ranks: list[int], runs: Runs) -> dict | None:
    """The first failure of ``text`` on ``ranks`` in up to ``runs.repeat`` runs, or None."""
    for attempt in range(runs.repeat):
        work = runs.work / f"run_{attempt}"
        work.mkdir(parents=True, exist_ok=True)
        report = search(write_jobs([text], work / "jobs"), ranks, replace(runs, work=work))
        first = first_failures(report)
        if first:
            return next(iter(first.values()))
    return None


def keep_reproducer(text: str, particles: int, failure: dict, folder: Path, name: str) -> Path:
    """Write ``text`` as ``folder/NAME.toml`` with its input files copied beside it (named in the job
    by absolute path), headed by a comment saying how its first ``particles`` particles fail and how to
    run them."""
    folder.mkdir(parents=True, exist_ok=True)
    for original in sorted(set(re.findall(r'^\w+ = "(/[^"]+)"$', text, flags=re.MULTILINE))):
        source = Path(original)
        if source.parent != REPOSITORY / "jobs" / "data":
            copy = folder / f"{name}_{source.name}"
            shutil.copyfile(source, copy)
            text = text.replace(f'"{original}"', f'"{copy.resolve()}"')
    path = folder / f"{name}.toml"
    run = (f"python benchmarks/spread_equivalence.py --one {path} --particles {particles} --ranks {failure['ranks']}"
           f"{'' if failure.get('check', True) else ' --no-check'}")
    path.write_text(f"# its first {particles} particles fail on {failure['ranks']} ranks: {failure['outcome']}: "
                    f"{_failure_detail(failure)}\n#   {run}\n" + text)
    return path


def write_jobs(texts: list[str], folder: Path) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for number, text in enumerate(texts):
        path = folder / f"job{number:05d}.toml"
        path.write_text(text)
        paths.append(path)
    return paths


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--jobs", type=int, default=20, help="random jobs to draw (default 20)")
    parser.add_argument("--seed", type=int, default=1, help="the search's seed: the same seed draws the same jobs")
    parser.add_argument("--ranks", type=int, nargs="+", default=[2, 3, 4], help="numbers of ranks (default 2 3 4)")
    parser.add_argument("--timeout", type=float, default=120.0, help="seconds a job may run on K ranks (default 120)")
    parser.add_argument("--report", type=Path, help="write the summary as JSON here")
    parser.add_argument("--work", type=Path, help="folder of the jobs, their input files and results (default: a "
                        "temporary folder, removed at the end)")
    parser.add_argument("--one", type=Path, nargs="+", help="run these job files instead of random ones (reproduce "
                        "a failure, run the regression cases)")
    parser.add_argument("--jitter", type=float, default=0.0, help="seconds of random delay injected before every "
                        "message of the spread runs and at every look at the messages (default 0: none)")
    parser.add_argument("--shrink", action="store_true", help="shrink each failing job to the fewest particles "
                        "found that still fail, and write it with its input files to --found")
    parser.add_argument("--found", type=Path, default=REPOSITORY / "benchmarks" / "found",
                        help="folder of the shrunk reproducers (default benchmarks/found)")
    parser.add_argument("--no-check", dest="check", action="store_false", help="run deposit_streamed without "
                        "check=True: whether a sediment differs, rather than whether a committed read changed")
    parser.add_argument("--repeat", type=int, default=1, help="with --shrink: runs of a smaller job before it "
                        "counts as passing (default 1; more for failures that do not always repeat)")
    parser.add_argument("--particles", type=int, help="deposit only the first PARTICLES particles of each job's "
                        "task, from its own random stream (a job with n_particles = PARTICLES would draw others)")
    parser.add_argument("--worker", nargs=4, metavar=("RANKS", "JOBS", "WORK", "LOG"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        ranks, listed, work, log = args.worker
        jobs = [Path(line) for line in Path(listed).read_text().split()]
        runs = Runs(Path(work), args.timeout, args.check, particles=args.particles, jitter=args.jitter)
        (serial_worker if int(ranks) == 1 else spread_worker)(jobs, runs, Path(log))
        return 0
    work = args.work or Path(tempfile.mkdtemp(prefix="spread_equivalence_"))
    work.mkdir(parents=True, exist_ok=True)
    if args.one:
        jobs = write_jobs([path.read_text() for path in args.one], work / "jobs")
    else:
        jobs = write_jobs(draw_jobs(args.jobs, args.seed, _inputs_folder(work)), work / "jobs")
    runs = Runs(work, args.timeout, args.check, max(1, args.repeat), args.particles, args.jitter)
    report = search(jobs, args.ranks, runs)
    print_summary(report)
    if args.report:
        args.report.write_text(json.dumps(report, indent=1))
    failed = bool(report["serial_errors"]) or any(tally["failed"] for tally in report["ranks"].values())
    if args.shrink:
        for job, failure in first_failures(report).items():
            shrinking = replace(runs, work=work / f"shrink_{job}")
            particles, smallest = shrink(failure["toml"], [failure["ranks"]], shrinking)
            name = f"{job}_{job_tag(failure['toml'])}" if not args.one else args.one[0].stem
            kept = keep_reproducer(failure["toml"], particles, {**smallest, "check": runs.check}, args.found, name)
            print(f"reproducer: {kept}")
    if args.work is None and not failed:
        shutil.rmtree(work, ignore_errors=True)
    elif args.work is None:
        print(f"\nthe jobs and their input files are kept in {work}")
    return 1 if failed else 0


def _inputs_folder(work: Path) -> Path:
    folder = work / "inputs"
    folder.mkdir(parents=True, exist_ok=True)
    return folder


if __name__ == "__main__":
    sys.exit(main())
