"""Packings of spheres between walls against the periodic packing: the wall contact models.

Visscher-Bolsterli sediments (monodisperse spheres of diameter 1, floor stops particles, trial
angle 1e-2) in a square box of --box diameters, --spheres spheres, --realizations seeds per model,
each one task of a deposition job (``parsim.deposit``):

* periodic: the reference;
* frictionless walls (``wall_contact = "frictionless"``, the default): a wall is a sphere of infinite
  radius, the touching sphere slides along it;
* glued walls (``wall_contact = "glued"``): the wall holds the touching sphere's centre.

Per model: the dataset's ``bulk_packing_fraction`` (the slab 0.25 h ... 0.75 h of the filling
height h = 2 z_cm; with walls the spheres whose centre lies ``bulk_wall_distance`` = 4 diameters
or more from them, each with its exact volume in the slab, over that area), the packing fraction
of the layer next to the walls by the same estimator (centres within one diameter of a wall, the
same slab), the spheres propped on a wall (off the floor, touching a wall, fewer than three
contacts in all) and ``filling_height``.

    python benchmarks/wall_packing.py [--box 30] [--spheres 30000] [--realizations 4]
"""

import argparse
import time

import numpy as np

import parsim
from parsim.core.sediment import packing_fraction

MODELS = {"periodic": {"lateral": "periodic"},
          "frictionless walls": {"lateral": "walls", "wall_contact": "frictionless"},
          "glued walls": {"lateral": "walls", "wall_contact": "glued"}}
RADIUS = 0.5
CONTACT = 1e-7
WARM_UP_SPHERES = 10


def wall_layer_fraction(x, box, height):
    """Packing fraction of the layer of one diameter along the walls, in the bulk slab: the spheres whose
    centre lies in it, each with its exact volume in the slab, over the layer's area times the slab's height."""
    near = np.minimum(np.minimum(x[:, 0], box - x[:, 0]), np.minimum(x[:, 1], box - x[:, 1])) < 2.0 * RADIUS
    layer_area = box**2 - (box - 4.0 * RADIUS) ** 2
    whole_box = packing_fraction(x[near], np.full(np.count_nonzero(near), RADIUS), (0.0, 0.0), (box, box),
                                 0.25 * height, 0.75 * height)
    return whole_box * box**2 / layer_area


def propped(x, box):
    """Spheres off the floor that touch a wall and have fewer than three contacts in all."""
    walls = ((x[:, 0] - RADIUS < CONTACT).astype(int) + (box - x[:, 0] - RADIUS < CONTACT)
             + (x[:, 1] - RADIUS < CONTACT) + (box - x[:, 1] - RADIUS < CONTACT))
    candidates = np.nonzero((walls > 0) & (x[:, 2] - RADIUS > CONTACT))[0]
    count = 0
    for i in candidates:
        d = np.linalg.norm(x[:i] - x[i], axis=1) - 2.0 * RADIUS
        if walls[i] + np.count_nonzero(d < CONTACT) < 3:
            count += 1
    return count


def measure(outcome, box):
    """(bulk phi, wall-layer phi, propped spheres, filling height, bulk wall distance) of one sediment."""
    stats = outcome.statistics
    x = outcome.configuration.arrays["spheres/position"]
    height = float(stats["filling_height"])
    return (float(stats["bulk_packing_fraction"]), wall_layer_fraction(x, box, height), propped(x, box), height,
            float(stats["bulk_wall_distance"]))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--box", type=float, default=30.0, help="box side, in diameters")
    parser.add_argument("--spheres", type=int, default=30_000)
    parser.add_argument("--realizations", type=int, default=4)
    args = parser.parse_args()
    print(f"box {args.box:g} diameters, {args.spheres} spheres, {args.realizations} realisations; "
          "mean +- standard error")
    print("| model | bulk phi | wall-layer phi | propped spheres | filling height | bulk wall distance "
          "| s per sediment |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for name, container in MODELS.items():
        parsim.deposit(WARM_UP_SPHERES, seed=0, box_length=args.box, sphere_radius=RADIUS, **container)  # kernels ready
        rows = []
        start = time.perf_counter()
        for seed in range(args.realizations):
            outcome = parsim.deposit(args.spheres, seed=seed, box_length=args.box, sphere_radius=RADIUS,
                                     **container)
            rows.append(measure(outcome, args.box))
        seconds = (time.perf_counter() - start) / args.realizations
        bulk, layer, n_propped, height, distance = (np.array(column) for column in zip(*rows))
        error = bulk.std(ddof=1) / np.sqrt(len(bulk)) if len(bulk) > 1 else np.nan
        walled = container["lateral"] == "walls"
        wall_layer = f"{layer.mean():.4f}" if walled else "–"
        n_wall = f"{n_propped.mean():.1f}" if walled else "–"
        print(f"| {name} | {bulk.mean():.4f} ± {error:.4f} | {wall_layer} | {n_wall} | {height.mean():.2f} | "
              f"{distance.mean():g} | {seconds:.1f} |", flush=True)


if __name__ == "__main__":
    main()
