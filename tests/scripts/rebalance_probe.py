"""Spheres crowded into one side of the box: DecomposedDomain.redistribute must move the tile
blocks so that every rank owns about as many spheres, and lose or change none.

    mpiexec -n K python tests/scripts/rebalance_probe.py

Prints one line starting with "OK"; any failed check aborts every rank with its traceback.
"""

import sys
import traceback

import numpy as np
from mpi4py import MPI

from parsim.aggregation.tiled import REBALANCE_ABOVE, DecomposedDomain

BOX = 40.0
N = 2000
HALO = 1.0


def main():
    comm = MPI.COMM_WORLD
    rng = np.random.default_rng(7)
    X = rng.uniform(0.0, BOX, (N, 2)) * np.array([0.3, 1.0])  # every centre in the left 30 % of the box
    V = rng.normal(size=(N, 2))
    domain = DecomposedDomain(comm, BOX, 2)
    ids, mine_X, mine_V = domain.distribute(X, V, HALO)
    before = domain.imbalance(ids.size)
    ids, mine_X, mine_V = domain.redistribute(ids, mine_X, mine_V)
    after = domain.imbalance(ids.size)
    every = np.sort(np.concatenate(comm.allgather(ids)))
    assert np.array_equal(every, np.arange(N)), "spheres lost or duplicated"
    assert np.array_equal(mine_X, X[ids]) and np.array_equal(mine_V, V[ids]), "records changed on the way"
    assert np.all(domain.decomposition.owner_of(mine_X) == comm.Get_rank()), "a sphere is not on its owner"
    assert comm.Get_size() == 1 or before > REBALANCE_ABOVE, f"the set-up is not imbalanced ({before:.2f})"
    assert after < REBALANCE_ABOVE, f"still imbalanced after redistribute: {before:.2f} -> {after:.2f}"
    domain.close()
    if comm.Get_rank() == 0:
        print(f"OK ranks={comm.Get_size()} imbalance {before:.2f} -> {after:.2f}", flush=True)


if __name__ == "__main__":
    try:
        main()
    except Exception:  # noqa: BLE001 - one failing rank must end every rank, with its traceback
        traceback.print_exc()
        sys.stderr.flush()
        MPI.COMM_WORLD.Abort(1)
