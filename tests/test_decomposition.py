"""The tile decomposition of the TS solver: ownership, migration and halo across ranks.

Single-rank tests use ``COMM_SELF``; the MPI tests run ``tests/scripts/decomposition_probe.py``
on 2 and 4 ranks (2 x 1 and 2 x 2 rank grids, and 2 x 2 x 1 in 3-D), where it checks itself
against a serial computation on the global set, and compare what it writes with a one-rank
run of the same script.
"""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from parsim.core.celllist import block_owners, cell_index
from parsim.parallel.decomposition import Decomposition, balanced_boundaries, even_boundaries
from parsim.parallel.halo import HaloPlan
from parsim.parallel.migration import migrate
from tests.mpi import run_mpi, run_mpi_bounded

REPOSITORY = Path(__file__).resolve().parent.parent
PROBE = str(REPOSITORY / "tests" / "scripts" / "decomposition_probe.py")
MIGRATION_PROBE = str(REPOSITORY / "tests" / "scripts" / "migration_probe.py")


def one_rank(dimension=2, tiles=4, box_length=1.0):
    return Decomposition(MPI.COMM_SELF, box_length, dimension, tiles)


# ownership ----------------------------------------------------------------------------


def test_one_rank_owns_the_whole_box():
    decomposition = one_rank(dimension=3, tiles=5, box_length=2.0)
    assert decomposition.dims == (1, 1, 1) and decomposition.coords == (0, 0, 0)
    assert decomposition.tile_start.tolist() == [0, 0, 0] and decomposition.tile_stop.tolist() == [5, 5, 5]
    assert decomposition.lower.tolist() == [0.0] * 3 and decomposition.upper.tolist() == [2.0] * 3
    assert decomposition.neighbours.shape == (0,) and decomposition.neighbour_offsets.shape == (0, 3)
    assert decomposition.owner_of(np.array([[-1.0, 0.5, 3.0], [1.0, 1.0, 1.0]])).tolist() == [0, 0]


def test_tiles_at_boundaries_and_outside_the_box():
    decomposition = one_rank(dimension=2, tiles=4)
    points = np.array([[0.25, 0.5], [0.25 - 1e-12, 0.0], [1.0, 1.0], [-0.3, 1.7], [0.0, -0.0]])
    assert decomposition.tile_indices(points).tolist() == [[1, 2], [0, 0], [3, 3], [0, 3], [0, 0]]


def test_tiles_follow_the_cell_rule_of_the_solver():
    decomposition = one_rank(dimension=3, tiles=7, box_length=3.0)
    points = np.random.default_rng(1).uniform(-0.5, 3.5, (500, 3))
    points[:7, 0] = np.arange(7) * 3.0 / 7  # exactly on tile edges
    tiles = decomposition.tile_indices(points)
    linear = tiles @ (7 ** np.arange(3))
    assert linear.tolist() == [cell_index(points, i, 3.0 / 7, 7) for i in range(len(points))]


def test_a_boundary_tile_belongs_to_the_upper_block():
    boundaries = np.array([[0, 3, 8]])
    points = (np.array([0, 2, 3, 7]) + 0.5)[:, None]  # in tiles 0, 2, 3 and 7 of side 1
    assert block_owners(points, 1.0, 8, boundaries, np.array([2]), np.array([5, 9])).tolist() == [5, 5, 9, 9]


@pytest.mark.parametrize("dimension", [2, 3])
def test_block_owners_follow_the_tile_and_block_rules(dimension):
    """Random rank grids, tile splits and points (inside, on tile edges, outside the box): the
    owner is the rank table's entry at the blocks ``searchsorted`` finds for the points' tiles
    (:meth:`Decomposition.tile_indices`).  300 random cases."""
    rng = np.random.default_rng(dimension)
    for _ in range(150):
        k = int(rng.integers(1, 12))
        dims = rng.integers(1, min(k, 4) + 1, size=dimension)
        splits = [np.concatenate([[0], np.sort(rng.choice(np.arange(1, k), parts - 1, replace=False)), [k]])
                  for parts in dims]
        boundaries = np.zeros((dimension, dims.max() + 1), dtype=np.int64)
        for axis, split in enumerate(splits):
            boundaries[axis, :split.size] = split
        table = rng.permutation(int(np.prod(dims))).reshape(dims)
        length = float(rng.uniform(0.5, 5.0))
        points = rng.uniform(-0.5 * length, 1.5 * length, (64, dimension))
        points[:8] = rng.integers(0, k + 1, (8, dimension)) * (length / k)  # on tile edges
        tiles = one_rank(dimension, tiles=k, box_length=length).tile_indices(points)
        blocks = tuple(np.searchsorted(splits[a], tiles[:, a], side="right") - 1 for a in range(dimension))
        owners = block_owners(points, length / k, k, boundaries, dims.astype(np.int64), table.ravel())
        assert owners.tolist() == table[blocks].tolist()


def test_even_boundaries_differ_by_at_most_one_tile():
    sizes = np.diff(even_boundaries(10, 4))
    assert sizes.sum() == 10 and sizes.max() - sizes.min() <= 1 and sizes.min() >= 1


def test_bad_arguments_name_the_argument():
    with pytest.raises(ValueError, match="dimension"):
        Decomposition(MPI.COMM_SELF, 1.0, 4, 2)
    with pytest.raises(ValueError, match="tiles_per_side"):
        Decomposition(MPI.COMM_SELF, 1.0, 2, 0)
    with pytest.raises(ValueError, match="box_length"):
        Decomposition(MPI.COMM_SELF, -1.0, 2, 2)
    with pytest.raises(ValueError, match=r"boundaries\[1\]"):
        one_rank(tiles=4).set_tile_splits([[0, 4], [0, 3]])
    with pytest.raises(ValueError, match="positions"):
        one_rank().owner_of(np.zeros((2, 3)))


# load balance -------------------------------------------------------------------------


def test_balanced_boundaries_split_where_the_weight_halves():
    # A skewed map: the first two columns carry half of the weight.
    weights = np.full((8, 8), 10.0 / 8)
    weights[:2] = 30.0 / 8
    along_x = weights.sum(axis=1)  # [30, 30, 10, 10, 10, 10, 10, 10]
    assert balanced_boundaries(along_x, 2).tolist() == [0, 2, 8]
    assert balanced_boundaries(along_x, 4).tolist() == [0, 1, 2, 5, 8]


def test_balanced_boundaries_keep_a_tile_per_block():
    all_in_the_last_tile = np.zeros(8)
    all_in_the_last_tile[-1] = 1.0
    assert balanced_boundaries(all_in_the_last_tile, 4).tolist() == [0, 1, 2, 3, 8]
    assert balanced_boundaries(np.zeros(8), 4).tolist() == even_boundaries(8, 4).tolist()
    with pytest.raises(ValueError, match="parts"):
        balanced_boundaries(np.ones(3), 4)


def test_balanced_splits_and_imbalance_on_one_rank():
    decomposition = one_rank(tiles=4)
    counts = decomposition.tile_counts(np.array([[0.1, 0.1], [0.1, 0.2], [0.9, 0.9]]))
    assert counts[0, 0] == 2 and counts[3, 3] == 1 and counts.sum() == 3
    assert [s.tolist() for s in decomposition.balanced_splits(counts)] == [[0, 4], [0, 4]]
    assert decomposition.imbalance(7.0) == 1.0
    with pytest.raises(ValueError, match="tile_weights"):
        decomposition.balanced_splits(np.ones((3, 3)))


# migration ----------------------------------------------------------------------------


def test_migrate_on_one_rank_sorts_and_keeps_dtypes():
    ids = np.array([5, 2, 9])
    arrays = {
        "position": np.array([[0.1, 0.2], [0.3, 0.4], [1.5, -0.1]]),
        "radius": np.array([1.0, 2.0, 3.0], dtype=np.float32),
        "stuck": np.array([True, False, True]),
        "frame": np.arange(12).reshape(3, 2, 2),
    }
    new_ids, new = migrate(one_rank(), ids, arrays)
    assert new_ids.tolist() == [2, 5, 9]
    for key, value in arrays.items():
        assert new[key].dtype == value.dtype and np.array_equal(new[key], value[[1, 0, 2]])


def test_migrate_rejects_records_that_do_not_line_up():
    with pytest.raises(ValueError, match="position"):
        migrate(one_rank(), np.arange(2), {"mass": np.ones(2)})
    with pytest.raises(ValueError, match=r"arrays\['mass'\]"):
        migrate(one_rank(), np.arange(2), {"position": np.zeros((2, 2)), "mass": np.ones(3)})


# halo ---------------------------------------------------------------------------------


def test_halo_on_one_rank_has_no_ghosts_and_reuses_its_buffer():
    positions = np.random.default_rng(2).uniform(0, 1, (20, 2))
    plan = HaloPlan(one_rank(), positions, 0.3, np.arange(20))
    assert plan.n_ghost == 0 and plan.ghost_global_id.shape == (0,)
    first = plan.exchange(positions)
    assert first.shape == (0, 2) and plan.exchange(positions + 1.0) is first
    assert plan.exchange(np.ones(20)).shape == (0,)
    with pytest.raises(ValueError, match="values"):
        plan.exchange(np.ones(19))
    with pytest.raises(ValueError, match="width"):
        HaloPlan(one_rank(), positions, 0.0, np.arange(20))


# clusters -----------------------------------------------------------------------------


# several ranks ------------------------------------------------------------------------


def run_probe(out: Path, ranks: int, dimension: int) -> dict:
    """Run the probe on ``ranks`` ranks (one rank: without mpiexec); it must say OK; returns what it wrote."""
    arguments = [PROBE, str(out), str(dimension)]
    if ranks == 1:
        result = subprocess.run([sys.executable, *arguments], capture_output=True, text=True, timeout=120,
                                cwd=REPOSITORY)
    else:
        result = run_mpi(arguments, ranks=ranks, timeout=120, cwd=REPOSITORY)
    assert result.returncode == 0, result.stdout + result.stderr
    assert any(line.startswith("OK ") for line in result.stdout.splitlines()), result.stdout
    with np.load(out) as written:
        return dict(written)


@pytest.fixture(scope="module")
def one_rank_probe(tmp_path_factory):
    """What the probe writes on one rank, per dimension (computed on first use)."""
    folder, runs = tmp_path_factory.mktemp("probe"), {}

    def get(dimension):
        if dimension not in runs:
            runs[dimension] = run_probe(folder / f"one_rank_{dimension}d.npz", 1, dimension)
        return runs[dimension]

    return get


@pytest.mark.mpi
@pytest.mark.parametrize("ranks, dimension", [(2, 2), (4, 2), (4, 3)])
def test_several_ranks_match_one_rank(ranks, dimension, one_rank_probe, tmp_path):
    decomposed = run_probe(tmp_path / "decomposed.npz", ranks, dimension)
    serial = one_rank_probe(dimension)
    for name in ("id", "mass", "velocity"):
        assert np.array_equal(decomposed[name], serial[name]), name


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [3, 4])
def test_random_migrations_keep_every_record_with_its_owner(ranks):
    """200 random rounds per rank count: none, a few, most or all records move, often from a few
    ranks only, so that some ranks exchange while others neither send nor receive.  Every rank
    must end each round with exactly the records it owns, sorted, payloads intact, and no round
    may leave the ranks at different collectives (a hang, bounded here)."""
    done, _ = run_mpi_bounded([MIGRATION_PROBE, "200", str(ranks)], bound=120, ranks=ranks, cwd=REPOSITORY)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "OK 200" in done.stdout
