"""Sediments of mixtures, layers, substrates, sieve curves and cylinders, through the job layer.

Each sediment is checked by the independent checker (no overlap, nothing outside the
container, every particle at rest), and its statistics against what a mixture must show.
"""

import numpy as np
import pytest
from mpi4py import MPI

import parsim
from parsim.errors import JobError
from parsim.job import parse_job
from parsim.solvers import SOLVERS
from tests.sediment_checks import check_sediment

from parsim.core.sdbd import FLOOR_STOP, LATERAL_PERIODIC, LATERAL_WALLS

SMALL_AND_LARGE = [{"name": "large", "shape": "sphere", "sphere_radius": 0.5, "share": 1.0},
                   {"name": "small", "shape": "sphere", "sphere_radius": 0.25, "share": 1.0}]
COMMON = {"box_length": 6.0, "packing_samples": 1000, "share_basis": "volume"}


def sediment_problems(outcome, lateral=LATERAL_PERIODIC, **options):
    arrays = outcome.configuration.arrays
    box = outcome.configuration
    return check_sediment(arrays["spheres/position"], arrays["spheres/radius"], arrays["spheres/particle"],
                          arrays["particles/center_of_mass"], arrays["particles/state"], box.box_lower[:2],
                          box.box_upper[:2], lateral, FLOOR_STOP, **options)


@pytest.fixture(scope="module")
def mixed():
    return parsim.deposit(600, seed=5, species=SMALL_AND_LARGE, **COMMON)


@pytest.fixture(scope="module")
def layered():
    return parsim.deposit(600, seed=5, species=SMALL_AND_LARGE, **COMMON,
                          layers=[{"n_particles": 120, "species": "large"}, {"n_particles": 480, "species": "small"}])


def test_species_profiles_add_up_to_the_packing_profile(mixed):
    stats = mixed.statistics
    assert stats["species"].attrs["flag_meanings"] == "large small"
    # spheres of different particles never overlap: the union's volume is the sum of the species'
    np.testing.assert_allclose(stats["species_packing_profile"].sum("species"), stats["packing_profile"],
                               rtol=1e-12, atol=1e-15)
    assert float(stats["species_volume_share"].sum()) == pytest.approx(1.0)


def test_mixed_shares_and_no_segregation(mixed):
    stats = mixed.statistics
    count = stats["species_particles"].values
    assert count.sum() == 600
    # equal volume shares of radii 0.5 and 0.25: eight small spheres per large one
    p_large = 1.0 / 9.0
    assert abs(count[0] / 600 - p_large) < 4.0 * np.sqrt(p_large * (1 - p_large) / 600)
    # drawn in random order the species mix; the large spheres sit a little higher, as their centres
    # stay a radius above the floor (0.25 more than the small ones': 2 x 0.25 / h = 0.14 of the index)
    height = stats["species_mean_height"].values
    assert height[0] > height[1]
    assert float(stats["segregation_index"]) < 0.3
    assert not sediment_problems(mixed)


def test_layers_lie_on_top_of_each_other(layered, mixed):
    stats = layered.statistics
    assert list(stats["species_particles"].values) == [120, 480]
    arrays = layered.configuration.arrays
    assert np.all(arrays["particles/shape"][:120] == 0) and np.all(arrays["particles/shape"][120:] == 1)
    height = stats["species_mean_height"].values
    assert height[1] > height[0]
    # the small spheres fill the top layer's voids only: the layers separate almost fully
    assert float(stats["segregation_index"]) > 0.6
    assert float(stats["segregation_index"]) > 2.5 * float(mixed.statistics["segregation_index"])
    assert not sediment_problems(layered)


def test_a_layer_is_the_beginning_of_the_stratified_task(layered):
    """Prefix independence: from the same random stream, the first layer alone is the stratified task's
    first 120 particles (a job's layers are part of its points' values, hence of their streams)."""
    first = parsim.Job.from_dict({"name": "first", "kind": "deposition", "seed": 5, "realizations": 1,
                                  "species": SMALL_AND_LARGE, "layers": [{"n_particles": 120, "species": "large"}],
                                  "parameters": {"n_particles": 120, **COMMON}})
    stream = np.random.default_rng(layered.job.seed_sequence(layered.job.tasks()[0]))
    alone = SOLVERS["deposition"].solve(first.point_parameters(0), stream, MPI.COMM_SELF)
    a, b = alone.configuration.arrays, layered.configuration.arrays
    n = len(a["spheres/radius"])
    np.testing.assert_array_equal(a["spheres/position"], b["spheres/position"][:n])


def test_templates_are_stored_once_per_species(mixed):
    arrays = mixed.configuration.arrays
    start = arrays["shapes/start"]
    assert list(start) == [0, 1, 2]
    np.testing.assert_allclose(arrays["shapes/radius"], [0.5, 0.25])
    assert mixed.configuration.attrs["shape_names"] == ["large", "small"]


def test_rods_lie_flatter_than_random_orientations():
    rods = parsim.deposit(400, seed=3, shape="rod", shape_size=4, box_length=8.0, floor="roll", packing_samples=1000)
    stats = rods.statistics
    # isotropic axes have <P2> = 0 with a standard error sqrt(1/5 / N): the bulk rods lie flatter
    n_bulk = int(stats["n_bulk_particles"])
    assert float(stats["vertical_order"]) < -3.0 * np.sqrt(0.2 / n_bulk)
    density = stats["orientation_density"].values
    width = float(np.diff(stats["angle_to_vertical"].values)[0])
    assert float(np.sum(density) * width) == pytest.approx(1.0)
    # the lying half of the angles, 45-90 degrees, holds more than isotropic axes' share, cos(pi/4)
    assert float(np.sum(density[len(density) // 2:]) * width) > np.cos(np.pi / 4) + 0.05
    spheres = parsim.deposit(20, seed=3, box_length=6.0, packing_samples=1000).statistics
    assert np.isnan(float(spheres["nematic_order"]))  # a sphere has no long axis


def test_sieve_curve_sizes(tmp_path):
    curve = tmp_path / "sand.csv"
    curve.write_text("size,passing\n0.6,0\n0.8,40\n1.0,100\n")
    outcome = parsim.deposit(200, seed=1, size_distribution="sieve", sieve_curve=str(curve), sieve_basis="number",
                             box_length=8.0, packing_samples=1000)
    diameters = 2.0 * outcome.configuration.arrays["spheres/radius"]
    assert diameters.min() >= 0.6 - 1e-12 and diameters.max() <= 1.0 + 1e-12
    passing = np.mean(diameters <= 0.8)
    assert abs(passing - 0.4) < 4.0 * np.sqrt(0.4 * 0.6 / 200)
    assert not sediment_problems(outcome)


def test_substrate_from_an_earlier_task(tmp_path):
    first = parsim.deposit(60, seed=2, box_length=5.0, packing_samples=1000)
    previous = tmp_path / "previous.csv"
    arrays = first.configuration.arrays
    rows = np.column_stack([arrays["spheres/position"], arrays["spheres/radius"]])
    np.savetxt(previous, rows, delimiter=",", header="x,y,z,r", comments="")
    second = parsim.deposit(60, seed=9, box_length=5.0, packing_samples=1000, substrate=str(previous))
    sub = second.configuration.arrays
    np.testing.assert_array_equal(sub["substrate/position"], arrays["spheres/position"])
    assert not sediment_problems(second, substrate=(sub["substrate/position"], sub["substrate/radius"]))
    # every new particle lies on the old pile: no particle of the second deposit is lower than its surface allows
    assert sub["particles/center_of_mass"][:, 2].mean() > arrays["particles/center_of_mass"][:, 2].mean()
    assert second.job.input_hashes  # the substrate's content is part of the job's identity


def test_cylinder_holds_every_sphere():
    radius = 6.0  # room for a bulk 4 particle diameters from the wall
    outcome = parsim.deposit(600, seed=4, container="cylinder", container_radius=radius,
                             size_distribution="uniform", size_spread=0.3, packing_samples=1000)
    arrays = outcome.configuration.arrays
    distance = np.hypot(arrays["spheres/position"][:, 0] - radius, arrays["spheres/position"][:, 1] - radius)
    assert np.all(distance <= radius - arrays["spheres/radius"] + 1e-9 * radius)
    cylinder = tuple(outcome.configuration.attrs["cylinder"])
    assert not sediment_problems(outcome, lateral=LATERAL_WALLS, cylinder=cylinder)
    assert 0.45 < float(outcome.statistics["bulk_packing_fraction"]) < 0.62


@pytest.mark.parametrize("container", [{"lateral": "walls", "box_length": 6.0},
                                       {"container": "cylinder", "container_radius": 3.0}], ids=["box", "cylinder"])
def test_a_species_without_particles_fits_the_walls(container):
    """A rare species (1 % of 200 particles) may draw no particle, as it does in the 4-particle warm-up:
    the check that every particle starts inside the walls passes over its shape."""
    species = [{"name": "common", "shape": "sphere", "share": 0.99},
               {"name": "rare", "shape": "rod", "shape_size": 2, "sphere_radius": 0.25, "share": 0.01}]
    outcome = parsim.deposit(200, seed=3, species=species, packing_samples=1000, **container)
    count = outcome.statistics["species_particles"].values
    assert count.sum() == 200 and count[1] <= 10
    cylinder = outcome.configuration.attrs.get("cylinder")
    assert not sediment_problems(outcome, lateral=LATERAL_WALLS,
                                 **({} if cylinder is None else {"cylinder": tuple(cylinder)}))


@pytest.mark.parametrize("table, message", [
    ('[[species]]\nshape = "rod"\n', "missing key 'name'"),
    ('[[species]]\nname = "a"\ncolour = 1\n', "unknown key 'colour'"),
    ('[[species]]\nname = "a"\n[[species]]\nname = "a"\n', "name = 'a' is given twice"),
    ('[[species]]\nname = "a"\nshare = -1.0\n', "share = -1.0 is out of range"),
    ('[[species]]\nname = "a"\n[[layers]]\nn_particles = 5\nspecies = "b"\n', "names no species"),
    ('[[species]]\nname = "a"\n[[layers]]\nn_particles = 5\n', "the [[layers]] hold 5 particles"),
])
def test_bad_tables_are_refused_naming_the_key(table, message):
    text = ('name = "m"\nkind = "deposition"\nseed = 1\nrealizations = 1\n'
            '[parameters]\nn_particles = 10\n' + table)
    with pytest.raises(JobError, match=message.replace("[", r"\[").replace("]", r"\]")):
        parse_job(text, SOLVERS)


def test_mesh_particles_rest_in_a_walled_box():
    outcome = parsim.deposit(60, seed=8, shape="mesh", mesh_file="jobs/data/pebble.obj", mesh_spheres=30,
                             sphere_radius=0.5, lateral="walls", box_length=6.0, floor="roll", packing_samples=1000)
    stats = outcome.statistics
    volume_error = float(stats["species_mesh_volume_error"].squeeze())
    assert -0.2 < volume_error < 0.0  # medial balls lie inside the mesh
    assert 0.0 < float(stats["species_mesh_surface_distance"].squeeze()) < 0.3
    # scaled to the volume of a sphere of radius sphere_radius
    arrays = outcome.configuration.arrays
    assert arrays["shapes/radius"].max() < 0.5
    assert not sediment_problems(outcome, lateral=LATERAL_WALLS)


def test_no_contact_across_opposite_walls():
    """Two spheres touching opposite walls of a walled box do not touch each other; in a periodic
    box of the same side they do, through the side."""
    from parsim.core.structure import contact_network
    from parsim.deposition.statistics import contact_part

    length = 6.0
    positions = np.array([[0.5, 3.0, 0.5], [length - 0.5, 3.0, 0.5]])
    for periodic, expected in ((False, 0), (True, 1)):
        network = contact_network(positions, np.full(2, 0.5), np.arange(2), np.zeros(2), np.full(2, length), periodic)
        contacts = contact_part(network.pairs, network.normals, np.arange(2), np.ones(2, dtype=bool),
                                np.ones(2, dtype=bool))
        assert contacts["sphere_contacts"] == 2 * expected and contacts["bulk"] == 2
        assert contacts["contact_numbers"][expected] == 2


CHUNKED_JOB = """
name = "chunked"
kind = "deposition"
seed = 4
realizations = 1
[parameters]
n_particles = 1000
box_length = 30.0
lateral = "{lateral}"
[[species]]
name = "rods"
shape = "rod"
shape_size = 3
size_distribution = "lognormal"
size_spread = 0.2
[[species]]
name = "grains"
shape = "sphere"
size_distribution = "uniform"
size_spread = 0.3
[[layers]]
n_particles = 400
species = "rods"
[[layers]]
n_particles = 600
species = ""
"""


@pytest.mark.parametrize("lateral", ["periodic", "walls", "none"])
def test_particles_drawn_in_chunks_are_those_drawn_at_once(lateral):
    """A rank of a task spread over ranks draws the particles a chunk at a time, keeping its own: every
    chunk, across layers and species, continues the streams exactly where the one draw would."""
    from parsim.deposition.solver import _container, _particle_chunks
    from parsim.deposition.materials import species_of

    params = parse_job(CHUNKED_JOB.format(lateral=lateral), SOLVERS).point_parameters(0)
    species = species_of(params)
    geometry = _container(params, species)
    (drops, rotation, drop_xy), = _particle_chunks(params, species, geometry, np.random.default_rng(5), 1000)()
    chunks = _particle_chunks(params, species, geometry, np.random.default_rng(5), 37)
    for parts in (list(chunks()), list(chunks())):  # every call starts again from the first particle
        assert len(parts) == 28
        np.testing.assert_array_equal(drops.species, np.concatenate([part[0].species for part in parts]))
        np.testing.assert_array_equal(drops.scale, np.concatenate([part[0].scale for part in parts]))
        np.testing.assert_array_equal(rotation, np.concatenate([part[1] for part in parts]))
        np.testing.assert_array_equal(drop_xy, np.concatenate([part[2] for part in parts]))
    assert (drops.species[:400] == 0).all() and 0 < drops.species[400:].sum() < 600
