"""Check the tile decomposition, migration and halo on the ranks of COMM_WORLD.

usage: decomposition_probe.py OUT.npz DIMENSION

Every rank builds the same global set of spheres from one seed (clusters of spheres and
isolated spheres) and keeps those it owns.  The rank blocks are balanced on the
spheres, then every cluster is moved into another rank's sub-box (every ordered pair of
ranks, hence every edge and corner of the rank grid), one to straddle the point where all
rank blocks meet and one to a corner outside the box, and the spheres are migrated.
Each result is checked against a serial computation on the global set.  Rank 0 writes the
migrated records that must not depend on the number of ranks (ids, masses, velocities;
the positions do, since clusters are moved into other ranks' sub-boxes) to OUT.npz and prints one line starting with "OK".
Any failure prints a traceback and aborts every rank.
"""

import itertools
import sys
import traceback

import numpy as np
from mpi4py import MPI

from parsim.core import kernel_mpi
from parsim.parallel.decomposition import Decomposition
from parsim.parallel.halo import HaloPlan
from parsim.parallel.migration import migrate

SEED = 20240611
BOX = 1.0
TILES = 8
N_CLUSTERS = 60
LARGEST_CLUSTER = 8
SPREAD = 0.03  # sphere offsets from their cluster centre, well below a tile side (0.125)
MOMENTUM_TOLERANCE = 1e-12  # relative to sum m|V|: round-off of sums in another order
HALO_STEPS = 3
STEP = 1e-3  # how far owned spheres move between halo exchanges


def make_world(dimension: int) -> dict:
    """The global set: clusters of spheres around random centres, with shuffled global ids."""
    rng = np.random.default_rng(SEED)
    sizes = rng.integers(1, LARGEST_CLUSTER + 1, N_CLUSTERS)
    sizes[[0, 5, 9]] = [2**dimension, 1, 1]  # cluster 0 gets one sphere per corner; two isolated spheres
    cluster = np.repeat(np.arange(N_CLUSTERS), sizes)
    n = cluster.shape[0]
    skewed = rng.uniform(size=(N_CLUSTERS, dimension)) ** 2  # crowded near the origin: uneven balanced splits
    centres = 2 * SPREAD + (BOX - 4 * SPREAD) * skewed
    offsets = rng.uniform(-SPREAD, SPREAD, (n, dimension))
    offsets[cluster == 0] = SPREAD * np.array(list(itertools.product((-1, 1), repeat=dimension)))
    return {
        "id": rng.choice(10**6, n, replace=False).astype(np.int64),
        "cluster": cluster,
        "position": centres[cluster] + offsets,
        "mass": rng.uniform(0.5, 2.0, n),
        "velocity": rng.normal(size=(n, dimension)),
    }


def rows_of(world: dict, ids: np.ndarray) -> np.ndarray:
    """Rows of the global set holding the spheres ``ids``."""
    sorter = np.argsort(world["id"])
    return sorter[np.searchsorted(world["id"], ids, sorter=sorter)]


def move_clusters(world: dict, decomposition: Decomposition, rng) -> np.ndarray:
    """New positions: each cluster into another rank's sub-box (cycling over the others).

    Cluster 0 goes to the point where all rank blocks meet (it then spans every rank),
    cluster 1 to just outside the lower corner of the box.
    """
    owner = decomposition.owner_of(world["position"])
    centre_owner = np.array([owner[world["cluster"] == c][0] for c in range(N_CLUSTERS)])
    moved_so_far = np.zeros(decomposition.size, dtype=np.int64)
    shift = np.zeros((N_CLUSTERS, decomposition.dimension))
    for c in range(N_CLUSTERS):
        source = centre_owner[c]
        target = (source + 1 + moved_so_far[source] % max(decomposition.size - 1, 1)) % decomposition.size
        moved_so_far[source] += 1
        lower, upper = decomposition.bounds_of(int(target))
        shift[c] = rng.uniform(lower + SPREAD, upper - SPREAD) - world["position"][world["cluster"] == c][0]
    middle = [split[len(split) // 2] if len(split) > 2 else TILES // 2 for split in decomposition.tile_splits]
    junction = np.array(middle) * decomposition.tile_side
    members = world["cluster"] == 0
    shift[0] = junction - world["position"][members].mean(axis=0)
    shift[1] = -SPREAD / 2 - world["position"][world["cluster"] == 1][0]
    return world["position"] + shift[world["cluster"]]


def check_ownership_rule(decomposition: Decomposition) -> None:
    """Points on a rank boundary belong to the upper block; points outside the box to the edge blocks."""
    side, d = decomposition.tile_side, decomposition.dimension
    for axis in range(d):
        for block, boundary in enumerate(decomposition.tile_splits[axis][1:-1], start=1):
            on = np.full(d, side / 2)
            on[axis] = boundary * side
            below = on.copy()
            below[axis] -= 1e-9
            coords = np.zeros(d, dtype=int)
            coords[axis] = block
            expected_on = decomposition.comm.Get_cart_rank(list(coords))
            coords[axis] = block - 1
            expected_below = decomposition.comm.Get_cart_rank(list(coords))
            assert decomposition.owner_of(np.array([on, below])).tolist() == [expected_on, expected_below]
    far_corner = [dim - 1 for dim in decomposition.dims]
    outside = np.array([np.full(d, -1.0), np.full(d, 2 * BOX), np.full(d, BOX)])
    expected = [0, decomposition.comm.Get_cart_rank(far_corner), decomposition.comm.Get_cart_rank(far_corner)]
    assert decomposition.owner_of(outside).tolist() == expected, decomposition.owner_of(outside)


def check_too_few_tiles(comm: MPI.Comm, dimension: int) -> None:
    """A rank grid with more ranks along an axis than tiles is refused with a clear message."""
    if comm.Get_size() == 1:
        return
    try:
        Decomposition(comm, BOX, dimension, 1)
    except ValueError as error:
        assert "tiles_per_side" in str(error) and "rank grid" in str(error), error
    else:
        raise AssertionError("tiles_per_side = 1 on several ranks was accepted")


def owned_records(world: dict, positions: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, dict]:
    """The records of the spheres in ``mask``, with float64, int64, float32 and bool columns."""
    return world["id"][mask], {"position": positions[mask], "mass": world["mass"][mask],
                               "velocity": world["velocity"][mask], "cluster": world["cluster"][mask],
                               "mass32": world["mass"][mask].astype(np.float32), "even": world["id"][mask] % 2 == 0}


def check_migration(decomposition, world, before, after, ids, records) -> int:
    """Conservation, ownership and the exact global id -> position map after migration; returns spheres moved."""
    comm, rank = decomposition.comm, decomposition.rank
    assert np.all(np.diff(ids) > 0), "records are not sorted by global id"
    assert np.all(decomposition.owner_of(records["position"]) == rank), "a sphere is not on its owner"
    total = comm.allreduce(ids.shape[0])
    assert total == world["id"].shape[0], (total, world["id"].shape[0])
    mass = comm.allreduce(records["mass"].sum())
    assert abs(mass - world["mass"].sum()) <= MOMENTUM_TOLERANCE * world["mass"].sum()
    momentum = np.empty(decomposition.dimension)
    comm.Allreduce((records["mass"][:, None] * records["velocity"]).sum(axis=0), momentum)
    scale = (world["mass"] * np.linalg.norm(world["velocity"], axis=1)).sum()
    expected_momentum = (world["mass"][:, None] * world["velocity"]).sum(axis=0)
    assert np.all(np.abs(momentum - expected_momentum) <= MOMENTUM_TOLERANCE * scale), momentum - expected_momentum
    gathered = comm.gather((ids, records["position"], records["velocity"], records["cluster"]), root=0)
    if rank == 0:
        all_ids, positions, velocities, clusters = (np.concatenate(part) for part in zip(*gathered))
        order, serial_order = np.argsort(all_ids), np.argsort(world["id"])
        assert np.array_equal(all_ids[order], world["id"][serial_order])
        assert np.array_equal(positions[order], after[serial_order])
        assert np.array_equal(velocities[order], world["velocity"][serial_order])
        assert np.array_equal(clusters[order], world["cluster"][serial_order]) and clusters.dtype == np.int64
    assert records["mass32"].dtype == np.float32 and np.array_equal(records["mass32"], records["mass"].astype(np.float32))
    assert records["even"].dtype == bool and np.array_equal(records["even"], ids % 2 == 0)
    source, target = decomposition.owner_of(before), decomposition.owner_of(after)
    pairs = {(int(s), int(t)) for s, t in zip(source, target) if s != t}
    size = decomposition.size
    assert pairs == {(s, t) for s in range(size) for t in range(size) if s != t}, sorted(pairs)
    return int(np.count_nonzero(source != target))


def check_halo(decomposition, world, positions, ids, records, width) -> int:
    """Ghosts equal a brute-force search of the global set, also after the owners move; returns n_ghost."""
    plan = HaloPlan(decomposition, records["position"], width, ids)
    global_positions = positions.copy()
    owner = decomposition.owner_of(global_positions)
    inside = np.clip(global_positions, 0.0, BOX)
    near = np.all((inside > decomposition.lower - width) & (inside < decomposition.upper + width), axis=1)
    expected = np.flatnonzero(near & (owner != decomposition.rank))
    expected = expected[np.lexsort((world["id"][expected], owner[expected]))]
    assert np.array_equal(plan.ghost_global_id, world["id"][expected]), (plan.ghost_global_id, world["id"][expected])
    assert np.array_equal(plan.ghost_source, owner[expected])
    corners = [rank for rank, offset in zip(decomposition.neighbours, decomposition.neighbour_offsets)
               if np.count_nonzero(offset) >= 2]
    assert all(np.any(plan.ghost_source == rank) for rank in corners), "no ghost from a corner neighbour"
    owned_positions = records["position"].copy()
    first = plan.exchange(owned_positions)
    assert np.array_equal(first, global_positions[expected])
    for _ in range(HALO_STEPS):
        owned_positions += STEP * records["velocity"]
        global_positions += STEP * world["velocity"]
        ghosts = plan.exchange(owned_positions)
        assert ghosts is first, "exchange allocated a new buffer"
        assert np.array_equal(ghosts, global_positions[expected])
    assert np.array_equal(plan.exchange(records["mass"]), world["mass"][expected])
    check_kernel_halo(decomposition, plan, owned_positions, ids, global_positions[expected], world["id"][expected])
    return plan.n_ghost


def check_kernel_halo(decomposition, plan, owned_positions, owned_ids, ghost_positions, ghost_ids):
    """The jitted exchange (parsim.core.kernel_mpi) fills the ghost rows as the brute-force search
    expects, the rows that changed alone when so asked, flags included, and its global maximum is
    the ranks' maximum."""
    n_owned, dimension = owned_positions.shape
    halo = plan.kernel_halo(dimension)
    rows = np.vstack([owned_positions, np.full((plan.n_ghost, dimension), np.nan)])
    arrived = np.empty(plan.n_ghost, dtype=np.int64)
    n = kernel_mpi.share_changed_rows(rows, n_owned, np.ones(n_owned, dtype=bool), arrived, halo)
    assert np.array_equal(rows[:n_owned], owned_positions) and np.array_equal(rows[n_owned:], ghost_positions)
    assert np.array_equal(np.sort(arrived[:n]), np.arange(plan.n_ghost))
    rows[:n_owned] += 1.0  # every owned row moves, a third of them is sent
    n = kernel_mpi.share_changed_rows(rows, n_owned, owned_ids % 3 == 0, arrived, halo)
    sent = ghost_ids % 3 == 0
    assert np.array_equal(np.sort(arrived[:n]), np.flatnonzero(sent))
    assert np.array_equal(rows[n_owned:][sent], ghost_positions[sent] + 1.0)
    assert np.array_equal(rows[n_owned:][~sent], ghost_positions[~sent])
    flags = np.concatenate([owned_ids % 3 == 0, np.zeros(plan.n_ghost, dtype=bool)])
    kernel_mpi.share_flags(flags, n_owned, halo)
    assert np.array_equal(flags[n_owned:], ghost_ids % 3 == 0)
    size = decomposition.comm.Get_size()
    assert kernel_mpi.global_max(float(decomposition.rank), halo) == size - 1
    assert kernel_mpi.global_sum(float(decomposition.rank + 1), halo) == size * (size + 1) / 2
    spread = kernel_mpi.global_max_array(np.array([decomposition.rank, -decomposition.rank], dtype=float), halo)
    assert np.array_equal(spread, [size - 1, 0.0])
    sending = sum(len(rows) > 0 for rows in plan.send_indices) if size > 1 else 0
    assert halo[-1][kernel_mpi.MESSAGES] == 3 * sending, (halo[-1], sending)


def main(out: str, dimension: int) -> None:
    comm = MPI.COMM_WORLD
    check_too_few_tiles(comm, dimension)
    world = make_world(dimension)
    decomposition = Decomposition(comm, BOX, dimension, TILES)
    rank = decomposition.rank
    ids, records = owned_records(world, world["position"], decomposition.owner_of(world["position"]) == rank)
    decomposition.set_tile_splits(decomposition.balanced_splits(decomposition.tile_counts(records["position"])))
    ids, records = migrate(decomposition, ids, records)
    assert np.all(decomposition.owner_of(records["position"]) == rank), "rebalanced records not on their owner"
    check_ownership_rule(decomposition)
    even = [split.tolist() == [(j * TILES) // (len(split) - 1) for j in range(len(split))]
            for split in decomposition.tile_splits]
    assert comm.Get_size() == 1 or not all(even), "balanced splits are even: nothing is rebalanced"

    moved = move_clusters(world, decomposition, np.random.default_rng(SEED + 1))
    assert np.any(moved < 0.0), "no sphere left the box"
    records["position"] = moved[rows_of(world, ids)]
    ids, records = migrate(decomposition, ids, records)
    n_moved = check_migration(decomposition, world, world["position"], moved, ids, records)

    ghosts = [check_halo(decomposition, world, moved, ids, records, width)
              for width in (decomposition.tile_side, decomposition.tile_side / 2)]

    counts = comm.allgather(ids.shape[0])
    imbalance = decomposition.imbalance(ids.shape[0])
    assert abs(imbalance - max(counts) / np.mean(counts)) < 1e-12, (imbalance, counts)
    gathered = comm.gather((ids, records["mass"], records["velocity"]), root=0)
    if rank == 0:
        merged = [np.concatenate(part) for part in zip(*gathered)]
        order = np.argsort(merged[0])
        np.savez(out, **{name: array[order] for name, array in zip(("id", "mass", "velocity"), merged)})
        grid = "x".join(map(str, decomposition.dims))
        print(f"OK ranks={comm.Get_size()} grid={grid} spheres={world['id'].shape[0]} moved={n_moved} "
              f"ghosts={ghosts} splits={[s.tolist() for s in decomposition.tile_splits]} imbalance={imbalance:.3f}", flush=True)
    decomposition.free()


if __name__ == "__main__":
    try:
        main(sys.argv[1], int(sys.argv[2]))
    except Exception:  # noqa: BLE001 - one failing rank must end every rank, with its traceback
        traceback.print_exc()
        sys.stderr.flush()
        MPI.COMM_WORLD.Abort(1)
