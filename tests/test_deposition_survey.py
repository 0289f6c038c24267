"""The survey kernels of a decomposed deposition (parsim.core.sdbd.survey) against the numpy passes
that state what they compute: the block of a drop point, a rank's particles with the spheres before
them, and the particles at which the grid's cell grows."""

import numpy as np
import pytest

from parsim.core.sdbd import survey


@pytest.mark.parametrize("periodic", [True, False])
@pytest.mark.parametrize("n_blocks", [1, 2, 3, 16])
def test_the_block_of_a_drop_point_is_numpys_search_of_the_edges(periodic, n_blocks):
    low, length = -1.7, 37.3
    edges = low + length * np.arange(n_blocks + 1) / n_blocks
    inner = np.ascontiguousarray(edges[1:-1])
    rng = np.random.default_rng(n_blocks)
    # points on and next to every edge, and far outside the box (wrapped when periodic)
    x = np.concatenate([rng.uniform(low - 3 * length, low + 4 * length, 20_000), edges,
                        np.nextafter(edges, np.inf), np.nextafter(edges, -np.inf)])
    if not periodic:
        x = np.concatenate([x, [np.inf, -np.inf]])
    wrapped = low + np.mod(x - low, length) if periodic else x
    expected = np.searchsorted(inner, wrapped, side="right")
    assert np.array_equal(survey.block_owners(x, low, length, inner, periodic), expected)


def test_a_ranks_particles_come_with_the_spheres_dropped_before_them():
    rng = np.random.default_rng(1)
    shape_start = np.array([0, 1, 4, 6])
    particle_shape = rng.integers(0, 3, 1000)
    drop_x = rng.uniform(0.0, 10.0, 1000)
    mine, spheres_before = survey.rows_of_block(drop_x, particle_shape, shape_start, 0.0, 10.0, np.array([5.0]),
                                                True, 1)
    counts = np.diff(shape_start)[particle_shape]
    assert np.array_equal(mine, np.flatnonzero(drop_x >= 5.0))
    assert np.array_equal(spheres_before, (np.cumsum(counts) - counts)[mine])


def test_the_cell_grows_at_each_particle_larger_than_all_before():
    rng = np.random.default_rng(2)
    particle_shape = rng.integers(0, 3, 1000)
    scale = rng.uniform(0.5, 2.0, 1000)
    largest_radius = np.array([0.5, 0.7, 0.3])
    at, cells = survey.cell_growth(particle_shape, scale, largest_radius, 1.0)
    running = np.maximum.accumulate(np.maximum(2.0 * scale * largest_radius[particle_shape], 1.0))
    grows = np.flatnonzero(np.diff(np.concatenate([[1.0], running])) > 0)
    assert len(grows) > 3
    assert np.array_equal(at, grows) and np.array_equal(cells, running[grows])
