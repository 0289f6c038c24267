"""Migrate records over the ranks of COMM_WORLD in random rounds and check every round.

usage: migration_probe.py ROUNDS SEED

Every rank knows the same global set of records (ids, positions, a float and an integer
payload) from one seed.  In each round a random share of the records, from none to all and
often those of a few ranks only, jumps to random places in the box; each rank migrates what
it holds, and the records it then holds must be exactly those whose new position it owns,
sorted by id, payloads intact.  Rounds where nothing moves, where some ranks neither send nor
receive while others exchange, and where every record moves all occur.  Prints "OK ROUNDS";
any failure prints a traceback and aborts every rank.
"""

import sys
import traceback

import numpy as np
from mpi4py import MPI

from parsim.parallel.decomposition import Decomposition
from parsim.parallel.migration import migrate

N_RECORDS = 400


def main(rounds: int, seed: int) -> None:
    comm = MPI.COMM_WORLD
    rng = np.random.default_rng(seed)  # the same stream on every rank
    decomposition = Decomposition(comm, 1.0, 2, 6)
    ids = rng.permutation(N_RECORDS).astype(np.int64)
    position = rng.random((N_RECORDS, 2))
    payload = rng.random(N_RECORDS)
    tag = rng.integers(0, 2**40, N_RECORDS)
    mine = np.flatnonzero(decomposition.owner_of(position) == decomposition.rank)
    held_id, held = migrate(decomposition, ids[mine], {"position": position[mine], "payload": payload[mine],
                                                         "tag": tag[mine]})
    for _ in range(rounds):
        movers = rng.random(N_RECORDS) < rng.choice([0.0, 0.01, 0.2, 1.0])
        if rng.random() < 0.5:  # only records now on a few ranks move
            owners = decomposition.owner_of(position)
            movers &= np.isin(owners, rng.choice(decomposition.size, rng.integers(1, decomposition.size + 1)))
        position[movers] = rng.random((int(movers.sum()), 2))
        by_id = np.argsort(ids)
        held["position"] = position[by_id][held_id]  # the records held here, moved
        held_id, held = migrate(decomposition, held_id, held)
        expected = np.sort(ids[decomposition.owner_of(position) == decomposition.rank])
        assert np.array_equal(held_id, expected), "the records held are not those owned"
        assert np.array_equal(held["payload"], payload[by_id][held_id]) and held["tag"].dtype == tag.dtype
        assert np.array_equal(held["tag"], tag[by_id][held_id])
    comm.Barrier()
    if comm.rank == 0:
        print(f"OK {rounds}")


if __name__ == "__main__":
    try:
        main(int(sys.argv[1]), int(sys.argv[2]))
    except Exception:  # noqa: BLE001 - one failing rank must end every rank, with its traceback
        traceback.print_exc()
        sys.stderr.flush()
        MPI.COMM_WORLD.Abort(1)
