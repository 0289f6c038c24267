"""Packings of spheres between walls against the periodic packing: the wall contact models.

Visscher-Bolsterli sediments (monodisperse spheres, floor stops particles, trial angle 1e-2) in
a square box of --box diameters, --spheres spheres, --realizations seeds per model:

* periodic: the reference (phi = 0.5813);
* frictionless walls (``wall_contact = "frictionless"``, the default): a wall is a sphere of infinite
  radius, the touching sphere slides along it;
* glued walls (``wall_contact = "glued"``): the wall holds the touching sphere's centre.

Per model: the packing fraction of the bulk (centres counted in the box --margin diameters away
from the walls, the floor and the filling height 2 z_cm; each centre carries one sphere volume),
of the layer next to the walls (centres within one diameter of a wall, same heights), and the
spheres propped on a wall: off the floor, touching a wall, and fewer than three contacts in all.

    python benchmarks/wall_packing.py [--box 30] [--spheres 30000] [--realizations 4] [--margin 4]
"""

import argparse
import time

import numpy as np

from parsim.core import sdbd

MODELS = {"periodic": (sdbd.LATERAL_PERIODIC, sdbd.WALL_FRICTIONLESS),
          "frictionless walls": (sdbd.LATERAL_WALLS, sdbd.WALL_FRICTIONLESS),
          "glued walls": (sdbd.LATERAL_WALLS, sdbd.WALL_GLUED)}
RADIUS = 0.5
CONTACT = 1e-7


def deposit(box, n, lateral, wall_contact, seed):
    rng = np.random.default_rng(seed)
    drop = RADIUS + rng.random((n, 2)) * (box - 2.0 * RADIUS)
    return sdbd.deposit(np.zeros((1, 3)), np.ones(1), np.array([0, 1]), np.zeros(n, dtype=np.int64),
                        np.full(n, RADIUS), np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), drop, (0.0, 0.0),
                        (box, box), lateral, sdbd.FLOOR_STOP, wall_contact=wall_contact)


def fraction(x, lo, hi):
    """Packing fraction from the centres inside the box [lo, hi] (3-vectors)."""
    inside = np.all((x > lo) & (x < hi), axis=1)
    return inside.sum() * 4.0 / 3.0 * np.pi * RADIUS ** 3 / np.prod(hi - lo)


def measure(res, box, margin):
    x = res.positions
    height = 2.0 * x[:, 2].mean()
    bulk = fraction(x, np.array([margin, margin, margin]), np.array([box - margin, box - margin, height - margin]))
    # the wall layer: the four slabs of one diameter along the walls (corners counted once)
    in_height = (x[:, 2] > margin) & (x[:, 2] < height - margin)
    near = np.minimum(np.minimum(x[:, 0], box - x[:, 0]), np.minimum(x[:, 1], box - x[:, 1])) < 2.0 * RADIUS
    layer_volume = (box ** 2 - (box - 4.0 * RADIUS) ** 2) * (height - 2.0 * margin)
    layer = np.count_nonzero(near & in_height) * 4.0 / 3.0 * np.pi * RADIUS ** 3 / layer_volume
    return bulk, layer, propped(x, box), height


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


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--box", type=float, default=30.0, help="box side, in diameters")
    parser.add_argument("--spheres", type=int, default=30_000)
    parser.add_argument("--realizations", type=int, default=4)
    parser.add_argument("--margin", type=float, default=4.0, help="bulk: diameters from every boundary")
    args = parser.parse_args()
    deposit(4.0, 10, sdbd.LATERAL_WALLS, sdbd.WALL_FRICTIONLESS, 0)  # compile first
    print(f"box {args.box:g} diameters, {args.spheres} spheres, {args.realizations} realisations, "
          f"bulk {args.margin:g} diameters from every boundary; mean +- standard error")
    print("| model | bulk phi | wall-layer phi | propped spheres | filling height | s per sediment |")
    print("|---|---:|---:|---:|---:|---:|")
    for name, (lateral, walls) in MODELS.items():
        rows = []
        start = time.perf_counter()
        for seed in range(args.realizations):
            rows.append(measure(deposit(args.box, args.spheres, lateral, walls, seed), args.box, args.margin))
        seconds = (time.perf_counter() - start) / args.realizations
        bulk, layer, n_propped, height = (np.array(column) for column in zip(*rows))
        error = bulk.std(ddof=1) / np.sqrt(len(bulk)) if len(bulk) > 1 else np.nan
        wall_layer = "–" if lateral == sdbd.LATERAL_PERIODIC else f"{layer.mean():.4f}"
        n_wall = "–" if lateral == sdbd.LATERAL_PERIODIC else f"{n_propped.mean():.1f}"
        print(f"| {name} | {bulk.mean():.4f} ± {error:.4f} | {wall_layer} | {n_wall} | {height.mean():.2f} | "
              f"{seconds:.1f} |", flush=True)


if __name__ == "__main__":
    main()
