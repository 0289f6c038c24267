"""The tiles of the almost-rigid formulation shared out among MPI ranks (section 3.3).

Section 3.3 cuts the box ``[0, L]^d`` into ``k^d`` equal tiles (the inner rectangles of
Fig. 3; see :mod:`parsim.core.ts.tiles`).  ``k`` is set by the physics, never by the number
of ranks.  To run one aggregation on several ranks, the ranks form a Cartesian grid
(``MPI.Compute_dims``, not periodic) and each rank owns a box-shaped group of whole tiles:
along every axis the ``k`` tiles are cut into contiguous blocks, one per rank of that axis.
The cut points (the *tile splits*) start even and can be moved to balance the work.

A sphere belongs to the rank owning the tile that holds its centre.  Centres outside the box
count in the nearest edge tile, as in :mod:`parsim.core.celllist`, so every sphere has
exactly one owner.

With one rank (``COMM_WORLD`` of size 1, with or without ``mpiexec``, or ``COMM_SELF``) the
rank owns every tile and has no neighbours; the same code runs.
"""

import itertools
import math
import numbers

import numpy as np
from mpi4py import MPI

from parsim.core.celllist import block_owners

SUPPORTED_DIMENSIONS = (2, 3)


class Decomposition:
    """The Cartesian rank grid over the tiles of ``[0, box_length]^dimension``.

    One object per configuration of the tiles; it owns the Cartesian communicator and
    answers "what is mine, who owns that, who are my neighbours".  Collective: every rank
    of ``comm`` builds it with the same arguments.

    Attributes
    ----------
    comm : the Cartesian communicator (same ranks as ``comm``: no reordering).
    rank, size : this rank and the number of ranks.
    dims, coords : the rank grid shape and this rank's position in it (tuples of ``d`` ints).
    tile_side : ``box_length / tiles_per_side``.
    tile_splits : per axis, the ``dims[a] + 1`` tile indices where rank blocks start and end.
    tile_start, tile_stop : this rank's tiles, ``[tile_start[a], tile_stop[a])`` along axis ``a``.
    lower, upper : the corners of this rank's sub-box.
    neighbours : the ranks of the up to ``3^d - 1`` adjacent sub-boxes (edges and corners),
        ascending; ``neighbour_offsets[i]`` is the grid offset in ``{-1, 0, 1}^d`` of ``neighbours[i]``.
    """

    def __init__(self, comm: MPI.Comm, box_length: float, dimension: int, tiles_per_side: int):
        _check_geometry(box_length, dimension, tiles_per_side)
        dims = MPI.Compute_dims(comm.Get_size(), dimension)
        _check_tiles_cover_rank_grid(tiles_per_side, dims)
        self.comm = comm.Create_cart(dims, periods=[False] * dimension, reorder=False)
        self.rank = self.comm.Get_rank()
        self.size = self.comm.Get_size()
        self.dims = tuple(dims)
        self.coords = tuple(self.comm.Get_coords(self.rank))
        self.box_length = float(box_length)
        self.dimension = dimension
        self.tiles_per_side = tiles_per_side
        self.tile_side = self.box_length / tiles_per_side
        self._rank_at = self._rank_table()
        self._dims = np.array(self.dims, dtype=np.int64)  # the rank grid and its table as block_owners takes them
        self._rank_of_block = self._rank_at.ravel()
        self.neighbours, self.neighbour_offsets = self._find_neighbours()
        self.set_tile_splits([even_boundaries(tiles_per_side, parts) for parts in self.dims])

    def free(self) -> None:
        """Release the Cartesian communicator (collective)."""
        self.comm.Free()

    # ownership ------------------------------------------------------------------------

    def set_tile_splits(self, boundaries) -> None:
        """Use new rank blocks: ``boundaries[a]`` are the ``dims[a] + 1`` tile indices cutting axis ``a``.

        Each must run from 0 to ``tiles_per_side``, strictly increasing (every rank keeps at
        least one tile), and be the same on every rank.  Halo plans built before are stale.
        """
        if len(boundaries) != self.dimension:
            raise ValueError(f"boundaries: need one array per axis ({self.dimension}), got {len(boundaries)}")
        splits = tuple(np.asarray(b, dtype=np.int64) for b in boundaries)
        for axis, split in enumerate(splits):
            _check_boundaries(split, self.dims[axis], self.tiles_per_side, axis)
        self.tile_splits = splits
        self._boundaries = np.zeros((self.dimension, max(self.dims) + 1), dtype=np.int64)
        for axis, split in enumerate(splits):
            self._boundaries[axis, :split.size] = split
        self.tile_start = np.array([splits[a][c] for a, c in enumerate(self.coords)], dtype=np.int64)
        self.tile_stop = np.array([splits[a][c + 1] for a, c in enumerate(self.coords)], dtype=np.int64)
        self.lower, self.upper = self.bounds_of(self.rank)

    def bounds_of(self, rank: int) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper corners of the sub-box of ``rank``."""
        coords = self.comm.Get_coords(rank)
        start = np.array([self.tile_splits[a][c] for a, c in enumerate(coords)])
        stop = np.array([self.tile_splits[a][c + 1] for a, c in enumerate(coords)])
        return self._tile_edge(start), self._tile_edge(stop)

    def tile_indices(self, positions) -> np.ndarray:
        """Per-axis tile index ``(n, d)`` of each position, clamped into ``0 .. k-1``.

        Same rule as :func:`parsim.core.celllist.cell_index` with ``side = L / k`` (the
        rule of :mod:`parsim.core.ts.tiles`), so ownership and the solver's tiles agree.
        """
        positions = checked_positions(positions, self.dimension)
        tiles = np.floor(positions / self.tile_side)
        tiles[positions <= 0.0] = 0.0
        return np.minimum(tiles, self.tiles_per_side - 1).astype(np.int64)

    def owner_of(self, positions) -> np.ndarray:
        """The rank owning each position (int64, shape ``(n,)``); outside the box: the nearest edge tile."""
        positions = np.asarray(positions, dtype=np.float64)
        if positions.ndim != 2 or positions.shape[1] != self.dimension:
            raise ValueError(f"positions: need shape (n, {self.dimension}), got {positions.shape}")
        return block_owners(positions, self.tile_side, self.tiles_per_side, self._boundaries, self._dims,
                            self._rank_of_block)

    # load balance ---------------------------------------------------------------------

    def tile_counts(self, positions, weights=None) -> np.ndarray:
        """Sum of ``weights`` (default 1) of the given positions in each tile, shape ``(k,) * d``."""
        tiles = self.tile_indices(positions)
        counts = np.zeros((self.tiles_per_side,) * self.dimension)
        np.add.at(counts, tuple(tiles.T), 1.0 if weights is None else np.asarray(weights, dtype=np.float64))
        return counts

    def balanced_splits(self, tile_weights) -> tuple[np.ndarray, ...]:
        """Tile splits that give every rank slab about the same weight (collective).

        ``tile_weights`` (shape ``(k,) * d``) is this rank's contribution (for example
        :meth:`tile_counts` of its own spheres); the contributions of all ranks are summed.
        Each axis is split on its own, on the weights projected onto it (summed over the
        other axes), by :func:`balanced_boundaries`: simple and deterministic.  Pass the
        result to :meth:`set_tile_splits`.
        """
        weights = np.asarray(tile_weights, dtype=np.float64)
        expected = (self.tiles_per_side,) * self.dimension
        if weights.shape != expected or not np.all(np.isfinite(weights)) or np.any(weights < 0):
            raise ValueError(f"tile_weights: need finite non-negative weights of shape {expected}, "
                             f"got shape {weights.shape}")
        projections = np.stack([_project_on_axis(weights, a) for a in range(self.dimension)])
        total = np.empty_like(projections)
        self.comm.Allreduce(projections, total, op=MPI.SUM)
        return tuple(balanced_boundaries(total[a], self.dims[a]) for a in range(self.dimension))

    def imbalance(self, local_work: float) -> float:
        """``max / mean`` over the ranks of ``local_work`` (collective); 1 is perfect balance."""
        largest = self.comm.allreduce(float(local_work), op=MPI.MAX)
        mean = self.comm.allreduce(float(local_work), op=MPI.SUM) / self.size
        return largest / mean if mean > 0.0 else 1.0

    # collective helpers on rows of arrays ----------------------------------------------

    def alltoallv_rows(self, rows: np.ndarray, send_counts, receive_counts=None) -> tuple[np.ndarray, np.ndarray]:
        """Send ``send_counts[r]`` consecutive rows of ``rows`` to each rank ``r`` (collective).

        ``rows`` is a 2-D float64 or int64 array with the same number of columns on every
        rank.  Returns the rows received, ordered by source rank then in the sender's order,
        and how many came from each rank; pass those ``receive_counts`` back when sending
        more rows with the same counts, to skip the ``Alltoall`` of the counts.
        """
        rows = np.ascontiguousarray(rows)
        columns = rows.shape[1]
        if receive_counts is None:
            receive_counts = np.empty(self.size, dtype=np.int64)
            self.comm.Alltoall(np.asarray(send_counts, dtype=np.int64), receive_counts)
        received = np.empty((int(receive_counts.sum()), columns), dtype=rows.dtype)
        if columns:
            self.comm.Alltoallv([rows, _counts_and_displacements(send_counts, columns)],
                                [received, _counts_and_displacements(receive_counts, columns)])
        return received, receive_counts

    def allgatherv_rows(self, rows: np.ndarray) -> np.ndarray:
        """The rows of every rank, concatenated in rank order, on every rank."""
        rows = np.ascontiguousarray(rows)
        columns = rows.shape[1]
        counts = np.empty(self.size, dtype=np.int64)
        self.comm.Allgather(np.array([rows.shape[0]], dtype=np.int64), counts)
        gathered = np.empty((int(counts.sum()), columns), dtype=rows.dtype)
        if columns:
            self.comm.Allgatherv(rows, [gathered, _counts_and_displacements(counts, columns)])
        return gathered

    # internals ------------------------------------------------------------------------

    def _tile_edge(self, tile: np.ndarray) -> np.ndarray:
        """Coordinate of the lower edge of tile ``tile`` (``tile = k`` gives exactly ``L``)."""
        return self.box_length * np.asarray(tile, dtype=np.float64) / self.tiles_per_side

    def _rank_table(self) -> np.ndarray:
        """``table[coords] = rank`` for every position of the rank grid."""
        table = np.empty(self.dims, dtype=np.int64)
        for rank in range(self.size):
            table[tuple(self.comm.Get_coords(rank))] = rank
        return table

    def _find_neighbours(self) -> tuple[np.ndarray, np.ndarray]:
        """Ranks of the existing adjacent grid positions (corners included) and their offsets, by rank."""
        found = []
        for offset in itertools.product((-1, 0, 1), repeat=self.dimension):
            place = np.add(self.coords, offset)
            if any(offset) and np.all(place >= 0) and np.all(place < self.dims):
                found.append((int(self._rank_at[tuple(place)]), offset))
        found.sort()
        ranks = np.array([rank for rank, _ in found], dtype=np.int64)
        offsets = np.array([offset for _, offset in found], dtype=np.int64).reshape(-1, self.dimension)
        return ranks, offsets


def checked_positions(positions, dimension: int) -> np.ndarray:
    """``positions`` as a float64 ``(n, dimension)`` array of finite values; raises ValueError otherwise."""
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim != 2 or positions.shape[1] != dimension:
        raise ValueError(f"positions: need shape (n, {dimension}), got {positions.shape}")
    if not np.all(np.isfinite(positions)):
        raise ValueError("positions: every coordinate must be finite")
    return positions


def even_boundaries(tiles: int, parts: int) -> np.ndarray:
    """Cut ``tiles`` tiles into ``parts`` contiguous blocks as even as possible (sizes differ by at most 1)."""
    return np.array([(j * tiles) // parts for j in range(parts + 1)], dtype=np.int64)


def balanced_boundaries(weights, parts: int) -> np.ndarray:
    """Cut the tiles of one axis into ``parts`` blocks of about equal summed ``weights``.

    Boundary ``j`` is the tile index whose cumulative weight is closest to ``j / parts`` of
    the total (the smaller index on a tie), kept so that every block has at least one tile.
    Without any weight the cut is even.
    """
    weights = np.asarray(weights, dtype=np.float64)
    tiles = weights.shape[0]
    if not 1 <= parts <= tiles:
        raise ValueError(f"parts: need 1 <= parts <= {tiles} (the tiles of the axis), got {parts}")
    cumulative = np.concatenate([[0.0], np.cumsum(weights)])
    total = cumulative[-1]
    if total <= 0.0:
        return even_boundaries(tiles, parts)
    boundaries = [0]
    for j in range(1, parts):
        first, last = boundaries[-1] + 1, tiles - (parts - j)
        candidates = cumulative[first:last + 1]
        boundaries.append(first + int(np.argmin(np.abs(candidates - total * j / parts))))
    boundaries.append(tiles)
    return np.array(boundaries, dtype=np.int64)


def _project_on_axis(weights: np.ndarray, axis: int) -> np.ndarray:
    """Sum of ``weights`` over every axis but ``axis``."""
    others = tuple(a for a in range(weights.ndim) if a != axis)
    return weights.sum(axis=others)


def _counts_and_displacements(row_counts, columns: int) -> tuple[np.ndarray, np.ndarray]:
    """Element counts and offsets of consecutive blocks of ``row_counts`` rows of ``columns`` values."""
    counts = np.asarray(row_counts, dtype=np.int64) * columns
    return counts, np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)


def _check_geometry(box_length, dimension, tiles_per_side) -> None:
    if dimension not in SUPPORTED_DIMENSIONS:
        raise ValueError(f"dimension: must be one of {SUPPORTED_DIMENSIONS}, got {dimension!r}")
    if not (isinstance(box_length, numbers.Real) and math.isfinite(box_length) and box_length > 0):
        raise ValueError(f"box_length: must be a finite number > 0, got {box_length!r}")
    if not (isinstance(tiles_per_side, numbers.Integral) and tiles_per_side >= 1):
        raise ValueError(f"tiles_per_side: must be an integer >= 1, got {tiles_per_side!r}")


def _check_tiles_cover_rank_grid(tiles_per_side: int, dims) -> None:
    """Every rank needs at least one tile along every axis."""
    if tiles_per_side < max(dims):
        grid = " x ".join(map(str, dims))
        raise ValueError(f"tiles_per_side = {tiles_per_side} is smaller than the rank grid {grid}: every rank "
                         f"needs at least one tile along each axis; use tiles_per_side >= {max(dims)} "
                         f"or fewer ranks")


def _check_boundaries(split: np.ndarray, parts: int, tiles: int, axis: int) -> None:
    if (split.shape != (parts + 1,) or split[0] != 0 or split[-1] != tiles
            or np.any(np.diff(split) < 1)):
        raise ValueError(f"boundaries[{axis}]: need {parts + 1} strictly increasing tile indices from 0 "
                         f"to {tiles} (one block of at least one tile per rank of the axis), got {split.tolist()}")
