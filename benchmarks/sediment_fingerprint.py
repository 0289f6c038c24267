"""Fingerprints of small deposition sediments: the check that a restructuring changes no result.

A restructuring of the deposition engine (parsim/core/sdbd/, run_deposition in engine.py) must
leave every sediment bitwise identical. Run on the old version, then on the new one:

    python benchmarks/sediment_fingerprint.py --write before.json     # old version
    python benchmarks/sediment_fingerprint.py --compare before.json   # new version: exit 1 names the jobs that differ

``--jobs SUBSTRING`` restricts the set to the jobs whose name contains it.

Each job below is a deposition task built with parsim.job.parse_job and solved in this process
exactly as ``parsim run`` solves it (same parameters, same seed sequence). Its fingerprint is a
SHA-256 over every array of the task's configuration (the task file's spheres/* and particles/*,
box bounds, periodicity; names sorted, each with dtype, shape and bytes), the configuration's
attributes, and every statistic except the timings (``measured=True``, spheres_per_second).
One line per job: name, particles, spheres, seconds and the first 16 hex digits of the hash.

The set (29 jobs, ROWS below) covers every shape, lateral mode (periodic, walls, none), floor mode
(stop, roll), size distribution (monodisperse, uniform, lognormal) and trial angle (1e-4, 1e-2),
each value in several jobs, not their Cartesian product: each shape with each lateral mode, floor,
size distribution and trial angle cycling; 150 to 2000 particles in boxes of 6 to 10 diameters or
heaps over a disc of radius 2. Walls are frictionless except in one job with glued walls
("walls-glued"). The agglomerate's CSV (five overlapping spheres) is written to a temporary folder
from fixed coordinates. Every job of the set finishes, the same particles as ``parsim run``
deposits (checked against its task files).

Run time: 55 to 90 s for the 29 jobs (AMD EPYC, 2 cores shared with other work, 2026-11-25),
kernels loaded from numba's cache; the first run after an edit of parsim/core compiles them first,
about a minute more. The hashes are equal between runs, and whether the kernels were just compiled
(fresh NUMBA_CACHE_DIR) or loaded from the cache.
"""

import argparse
import hashlib
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from parsim.errors import ParsimError
from parsim.job import parse_job
from parsim.solvers import SOLVERS

SOLVER = SOLVERS["deposition"]
# Every job: one task, few samples and slabs for the packing statistics (they are hashed too).
COMMON = {"packing_samples": 1000, "profile_bins": 10}
# shape: (its parameters, box_length: above twice the extent of the largest lognormal particle)
SHAPES = {
    "sphere": ({}, 6.0),
    "rod": ({"shape_size": 5}, 8.0),
    "four_rods": ({"shape_size": 3}, 8.0),
    "tripod": ({"shape_size": 3}, 8.0),
    "spiky": ({"shape_size": 3}, 8.0),
    "cube": ({"shape_size": 3}, 10.0),
    "ellipsoid": ({"shape_spheres": 40}, 10.0),
    "superellipsoid": ({"shape_spheres": 40, "exponent_vertical": 4.0, "exponent_horizontal": 4.0}, 10.0),
    "agglomerate": ({}, 8.0),
}
SPREAD = {"monodisperse": 0.0, "uniform": 0.2, "lognormal": 0.1}
DROP_RADIUS = 2.0  # lateral = "none": a heap
# (shape, lateral, floor, size_distribution, trial_angle, n_particles, seed); the job's name joins the first five.
ROWS = (
    ("sphere", "periodic", "stop", "monodisperse", 1e-2, 2000, 1),
    ("sphere", "walls", "roll", "lognormal", 1e-4, 2000, 2),
    ("sphere", "walls-glued", "stop", "uniform", 1e-2, 2000, 4),
    ("sphere", "none", "stop", "uniform", 1e-2, 2000, 3),
    ("rod", "periodic", "roll", "uniform", 1e-2, 600, 11),
    ("rod", "walls", "stop", "monodisperse", 1e-4, 500, 12),
    ("rod", "none", "roll", "lognormal", 1e-2, 600, 13),
    ("rod", "walls", "roll", "uniform", 1e-4, 500, 14),
    ("four_rods", "periodic", "stop", "lognormal", 1e-4, 400, 21),
    ("four_rods", "walls", "roll", "uniform", 1e-2, 400, 22),
    ("four_rods", "none", "stop", "monodisperse", 1e-4, 400, 23),
    ("tripod", "periodic", "roll", "monodisperse", 1e-4, 400, 31),
    ("tripod", "walls", "stop", "lognormal", 1e-2, 400, 32),
    ("tripod", "none", "roll", "uniform", 1e-4, 400, 33),
    ("spiky", "periodic", "stop", "uniform", 1e-2, 400, 41),
    ("spiky", "walls", "roll", "monodisperse", 1e-4, 400, 42),
    ("spiky", "none", "stop", "lognormal", 1e-2, 400, 43),
    ("cube", "periodic", "roll", "lognormal", 1e-2, 250, 51),
    ("cube", "walls", "stop", "uniform", 1e-4, 250, 52),
    ("cube", "none", "roll", "monodisperse", 1e-2, 250, 53),
    ("ellipsoid", "periodic", "stop", "monodisperse", 1e-4, 150, 61),
    ("ellipsoid", "walls", "roll", "lognormal", 1e-2, 150, 62),
    ("ellipsoid", "none", "stop", "uniform", 1e-4, 150, 63),
    ("superellipsoid", "periodic", "roll", "uniform", 1e-4, 150, 71),
    ("superellipsoid", "walls", "stop", "monodisperse", 1e-2, 150, 72),
    ("superellipsoid", "none", "roll", "lognormal", 1e-4, 150, 73),
    ("agglomerate", "periodic", "stop", "lognormal", 1e-2, 600, 81),
    ("agglomerate", "walls", "roll", "uniform", 1e-4, 600, 82),
    ("agglomerate", "none", "stop", "monodisperse", 1e-2, 600, 83),
)


def job_parameters(shape, lateral, floor, size_distribution, trial_angle, n_particles) -> dict:
    """The task's parameters; ``lateral`` "walls-glued" is ``lateral = "walls"``, ``wall_contact = "glued"``."""
    shape_parameters, box_length = SHAPES[shape]
    lateral, _, walls = lateral.partition("-")
    if walls:
        shape_parameters = {**shape_parameters, "wall_contact": walls}
    params = {**COMMON, **shape_parameters, "shape": shape, "n_particles": n_particles, "lateral": lateral,
              "floor": floor, "size_distribution": size_distribution, "size_spread": SPREAD[size_distribution],
              "trial_angle": trial_angle}
    params.update({"drop_radius": DROP_RADIUS} if lateral == "none" else {"box_length": box_length})
    return params


# name: (seed, parameters)
JOBS = {f"{shape}_{lateral}_{floor}_{size[:4]}_{angle:.0e}":
        (seed, job_parameters(shape, lateral, floor, size, angle, n)) for shape, lateral, floor, size, angle, n, seed in ROWS}
# The agglomerate: five overlapping spheres of unequal radii, not coplanar (x, y, z, r).
AGGLOMERATE = ((0.0, 0.0, 0.0, 1.0), (1.5, 0.0, 0.0, 0.8), (0.5, 1.3, 0.0, 0.9), (0.4, 0.5, 1.4, 0.7),
               (-1.2, -0.6, 0.3, 0.6))


def write_agglomerate(folder: Path) -> Path:
    path = folder / "agglomerate.csv"
    path.write_text("x,y,z,r\n" + "".join(",".join(repr(v) for v in row) + "\n" for row in AGGLOMERATE))
    return path


def job_text(name: str, seed: int, params: dict, agglomerate: Path) -> str:
    if params["shape"] == "agglomerate":
        params = {**params, "agglomerate_file": str(agglomerate)}
    lines = [f'name = "{name}"', 'kind = "deposition"', f"seed = {seed}", "realizations = 1", "[parameters]"]
    lines += [f"{key} = {json.dumps(value)}" for key, value in params.items()]
    return "\n".join(lines) + "\n"


def _update(digest, name: str, value) -> None:
    array = np.ascontiguousarray(value)
    digest.update(f"{name}|{array.dtype.str}|{array.shape}|".encode())
    digest.update(array.tobytes())


def fingerprint(result) -> str:
    """SHA-256 of the configuration's arrays and attributes and of the non-timing statistics."""
    measured = {s.name for s in SOLVER.statistics if s.measured} | {"spheres_per_second", "wall_time"}
    configuration = result.configuration
    digest = hashlib.sha256()
    for name in sorted(configuration.arrays):
        _update(digest, "arrays/" + name, configuration.arrays[name])
    for name in ("box_lower", "box_upper", "periodic"):
        _update(digest, name, getattr(configuration, name))
    digest.update(json.dumps(configuration.attrs, sort_keys=True, default=repr).encode())
    for name in sorted(set(result.statistics) - measured):
        _update(digest, "statistics/" + name, result.statistics[name])
    return digest.hexdigest()


def run_job(text: str, folder: Path):
    """The job's one task, solved as the runner solves it: its result."""
    job = parse_job(text, SOLVERS, output=folder)
    (task,) = job.tasks()
    params = job.point_parameters(task.point)
    return SOLVER.solve(params, np.random.default_rng(job.seed_sequence(task)), MPI.COMM_SELF)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--jobs", default="", help="run only the jobs whose name contains this substring")
    output = parser.add_mutually_exclusive_group()
    output.add_argument("--write", metavar="FILE", help="write the full hashes as JSON")
    output.add_argument("--compare", metavar="FILE", help="compare with hashes written before; exit 1 if any differ")
    args = parser.parse_args()

    names = [name for name in JOBS if args.jobs in name]
    if not names:
        parser.error(f"--jobs {args.jobs!r} matches no job; jobs: {', '.join(JOBS)}")
    expected = json.loads(Path(args.compare).read_text()) if args.compare else None

    hashes, differing = {}, []
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        agglomerate = write_agglomerate(folder)
        start = time.perf_counter()
        first_seed, first = JOBS[names[0]]
        run_job(job_text("warm_up", first_seed, SOLVER.warm_up_parameters(first),
                         agglomerate), folder)  # compiles, or loads from the cache, the kernels
        print(f"kernels ready in {time.perf_counter() - start:.1f} s")
        print(f"{'job':<38} {'particles':>9} {'spheres':>8} {'time [s]':>8}  {'sha256[:16]':<16}")
        total = time.perf_counter()
        for name in names:
            seed, params = JOBS[name]
            started = time.perf_counter()
            try:
                result = run_job(job_text(name, seed, params, agglomerate), folder)
                hashes[name] = fingerprint(result)
                spheres = len(result.configuration.arrays["spheres/radius"])
            except ParsimError as error:
                hashes[name] = f"error: {error}"
                spheres = -1
            mark = ""
            if expected is not None and expected.get(name) != hashes[name]:
                differing.append(name)
                mark = "  DIFFERS" if name in expected else "  (not in the file)"
            shown = hashes[name][:16] if spheres >= 0 else hashes[name]
            print(f"{name:<38} {params['n_particles']:>9} {spheres:>8} {time.perf_counter() - started:>8.2f}  "
                  f"{shown}{mark}", flush=True)
        print(f"{len(names)} jobs in {time.perf_counter() - total:.1f} s")

    if args.write:
        Path(args.write).write_text(json.dumps(hashes, indent=1) + "\n")
        print(f"hashes written to {args.write}")
    if expected is not None:
        if differing:
            print(f"{len(differing)} of {len(names)} jobs differ from {args.compare}: {', '.join(differing)}")
            return 1
        print(f"all {len(names)} jobs equal to {args.compare}")
    return 1 if any(h.startswith("error") for h in hashes.values()) and not args.compare else 0


if __name__ == "__main__":
    sys.exit(main())
