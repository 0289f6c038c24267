"""Run one fixed-seed TS aggregation decomposed over every rank and write what it ended with.

    mpiexec -n K python tests/scripts/tiled_ts_probe.py OUT.npz N VOLUME_FRACTION [SEED [DIMENSION [HALO_MARGIN
                                                        [TILED_ITERATIONS]]]]

HALO_MARGIN (in radii) replaces the stepper's halo margins (the least and the first): a small one
makes minimisations leave their halo and run again with a wider one.  TILED_ITERATIONS replaces
the iterations after which a minimisation in several tiles gives up (0: every one does).

Rank 0 writes the final positions, velocities, cluster labels, links (sorted) and counters
to OUT.npz, and how many times DAHA was started (``attempts``: a minimisation run again with a
wider halo counts twice); tests/test_tiled_ts.py compares the files of 1, 2 and 4 ranks.
"""

import sys
import traceback

import numpy as np
from mpi4py import MPI

from parsim.core.initial import box_length_for_volume_fraction, isotropic_velocities, lattice_positions
from parsim.core.ts import simulate_ts, stepper
from parsim.aggregation.tiled import DecomposedDomain

RADIUS = 0.2
TIME_STEP_FACTOR = 0.01


def initial_condition(n, volume_fraction, seed=3, dimension=2):
    """Lattice positions and isotropic unit speeds (eq. 4.3): ``(x, v, radii, masses, L)``."""
    rng = np.random.default_rng(seed)
    L = box_length_for_volume_fraction(n, dimension, RADIUS, volume_fraction)
    x = lattice_positions(n, dimension, L, rng)
    v = isotropic_velocities(n, dimension, 1.0, rng)
    return x, v, np.full(n, RADIUS), np.ones(n), L


def counting_attempts():
    """Count the stepper's calls of DAHA; returns the count, a one-element list."""
    attempts = [0]
    minimise = stepper.minimise

    def counted(*args, **kwargs):
        attempts[0] += 1
        return minimise(*args, **kwargs)

    stepper.minimise = counted
    return attempts


def main(out, n, volume_fraction, seed=3, dimension=2):
    x, v, r, m, L = initial_condition(n, volume_fraction, seed, dimension)
    comm = MPI.COMM_WORLD
    attempts = counting_attempts()
    result = simulate_ts(x, v, r, m, L, time_step_factor=TIME_STEP_FACTOR,
                         domain=DecomposedDomain(comm, L, dimension))
    iterations_per_rank = comm.gather(result.n_iterations, root=0)  # one convergence schedule for all
    if comm.Get_rank() == 0:
        order = np.lexsort((result.links[:, 1], result.links[:, 0]))
        np.savez(out, positions=result.positions, velocities=result.velocities, cluster=result.cluster,
                 links=result.links[order], link_steps=result.link_steps[order], time=result.time,
                 counters=np.array([result.n_steps, result.n_collisions, result.n_wall_reflections,
                                    result.n_minimisations, result.n_iterations]),
                 cluster_history=result.cluster_history, imbalance=result.imbalance, radius=RADIUS,
                 iterations_per_rank=np.array(iterations_per_rank), attempts=attempts[0])


if __name__ == "__main__":
    try:
        if len(sys.argv) > 6:
            stepper.HALO_MARGIN = stepper.FIRST_MARGIN = float(sys.argv[6])
        if len(sys.argv) > 7:
            stepper.TILED_ITERATIONS = int(sys.argv[7])
        main(sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), *map(int, sys.argv[4:6]))
    except Exception:  # noqa: BLE001 - one failing rank must end every rank, with its traceback
        traceback.print_exc()
        sys.stderr.flush()
        MPI.COMM_WORLD.Abort(1)
