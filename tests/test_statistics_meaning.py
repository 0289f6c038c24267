"""The deposition's statistics mean what their names say, on substrates, between walls and on the floor.

Most sediments here are built by hand (spheres on lattices, particles placed where the answer is
known analytically) and measured by the solver's own statistics function; the others are small
depositions checked against what they must show.
"""

import math
from types import SimpleNamespace

import numpy as np
import pytest

import parsim
from parsim.core import sdbd
from parsim.core.sediment import CONTACT_GAP_TOLERANCE, filling_height, packing_fraction
from parsim.deposition import statistics as statistics
from parsim.deposition.materials import Drops, species_of

RADIUS = 0.5
SPHERE_VOLUME = 4.0 / 3.0 * math.pi * RADIUS**3
SIMPLE_CUBIC = math.pi / 6.0  # packing fraction of touching spheres on a simple cubic lattice
NO_SUBSTRATE = (np.zeros((0, 3)), np.zeros(0))


def point(species=None, **keys):
    """A deposition point's parameters: the job's defaults with ``keys`` (and ``[[species]]``)."""
    tables = {"species": species} if species else {}
    job = parsim.Job.from_dict({"name": "hand", "kind": "deposition", "seed": 1, "realizations": 1, **tables,
                                "parameters": {"n_particles": 1, "packing_samples": 1000, **keys}})
    return job.point_parameters(0)


def measure(params, com, kind=None, substrate=NO_SUBSTRATE, cylinder=None):
    """The statistics of particles placed by hand: centres of mass ``com`` (P, 3), species index ``kind``
    (P,), unrotated templates at size factor 1, in the container of ``params``."""
    species = species_of(params)
    com = np.asarray(com, dtype=float)
    kind = np.zeros(len(com), dtype=np.int64) if kind is None else np.asarray(kind, dtype=np.int64)
    positions = np.concatenate([c + species[k].offsets for c, k in zip(com, kind)])
    radii = np.concatenate([species[k].radii for k in kind])
    particle = np.repeat(np.arange(len(com)), [len(species[k].radii) for k in kind])
    n = len(com)
    result = sdbd.DepositionResult(positions, radii, particle, com, np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
                                   np.zeros(n, dtype=np.int8), np.full(n, sdbd.RESTING_THREE_CONTACTS, dtype=np.int8),
                                   np.zeros((n, len(sdbd.EVENT_KINDS)), dtype=np.int64), np.ones(n, dtype=np.int64),
                                   -1, np.nan)
    side = 2.0 * cylinder[2] if cylinder else params["box_length"]
    geometry = SimpleNamespace(lower=np.zeros(2), upper=np.full(2, side), cylinder=cylinder)
    return statistics.measure(params, result, species, Drops(kind, np.ones(n)), geometry, 0, substrate)


def lattice(sites_xy, layers_z):
    """Points of a lattice: every (x, y) of ``sites_xy`` at every height of ``layers_z``."""
    x, y, z = np.meshgrid(sites_xy, sites_xy, layers_z, indexing="ij")
    return np.column_stack([x.ravel(), y.ravel(), z.ravel()])


# --- substrates -------------------------------------------------------------------------------------------

LOWER_AND_UPPER = [{"name": "lower", "shape": "sphere"}, {"name": "upper", "shape": "sphere"}]


@pytest.fixture(scope="module")
def on_a_lattice_substrate():
    """A periodic box of 6 x 6 diameters: one layer of substrate spheres on the floor and eight layers
    of deposited spheres on it, all on one simple cubic lattice; the first four layers are species
    "lower", the next four "upper"."""
    params = point(LOWER_AND_UPPER, box_length=6.0, profile_bins=45)
    sites = np.arange(6) + 0.5
    substrate = lattice(sites, [0.5])
    com = lattice(sites, np.arange(1, 9) + 0.5)
    kind = (com[:, 2] > 5.0).astype(np.int64)
    return measure(params, com, kind, (substrate, np.full(len(substrate), RADIUS)))


def test_heights_count_from_the_floor_and_the_substrate_fills_its_share(on_a_lattice_substrate):
    stats = on_a_lattice_substrate
    # nine layers of one packing: the pile's 2 z_cm is its top, the substrate's share its one layer
    assert stats["filling_height"] == pytest.approx(9.0, rel=1e-12)
    assert stats["substrate_height"] == pytest.approx(1.0, rel=1e-12)


def test_the_bulk_is_the_middle_half_of_the_deposit(on_a_lattice_substrate):
    stats = on_a_lattice_substrate
    # the deposit is 1 ... 9: the bulk slab 3 ... 7 holds the four layers at 3.5 ... 6.5, whole
    assert stats["n_bulk_particles"] == 4 * 36
    assert stats["bulk_packing_fraction"] == pytest.approx(SIMPLE_CUBIC, rel=1e-12)
    assert stats["bulk_coordination"] == 6.0
    assert stats["bulk_wall_distance"] == 0.0


def test_the_profile_runs_from_the_floor_over_the_corrected_height(on_a_lattice_substrate):
    profile = on_a_lattice_substrate["packing_profile"]
    # 45 slabs over 0 ... 1.25 h = 11.25: the first 36 cover the nine layers of the pile, substrate included
    assert profile[:36].mean() == pytest.approx(SIMPLE_CUBIC, rel=1e-12)
    assert np.all(profile[36:] == 0.0)


def test_species_heights_are_measured_in_the_deposit(on_a_lattice_substrate):
    stats = on_a_lattice_substrate
    # mean heights 3 and 7 in the deposit 1 ... 9: a quarter and three quarters of it, two separate layers
    np.testing.assert_allclose(stats["species_mean_height"], [0.25, 0.75], rtol=1e-12)
    assert stats["segregation_index"] == pytest.approx(1.0, rel=1e-12)


def test_without_substrate_the_filling_height_is_twice_the_centre_of_mass():
    params = point(box_length=6.0)
    com = lattice(np.arange(6) + 0.5, np.arange(8) + 0.5)
    stats = measure(params, com)
    assert stats["filling_height"] == filling_height(com[:, 2], np.full(len(com), SPHERE_VOLUME))  # as before
    assert stats["filling_height"] == pytest.approx(8.0, rel=1e-12)
    assert stats["n_bulk_particles"] == 4 * 36  # the slab 2 ... 6
    assert stats["species_mean_height"][0] == pytest.approx(0.5, rel=1e-12)
    assert stats["substrate_height"] == 0.0


def test_overlapping_substrate_spheres_count_once():
    """A substrate of rods lying on the floor: its material is the union of their spheres."""
    params = point(box_length=6.0)
    spacing = 0.5  # centre distance of the rods' spheres: each pair overlaps in a lens
    x = np.arange(0.5, 5.6, spacing)
    y = np.arange(6) + 0.5
    substrate = lattice(x, [0.5])
    substrate = substrate[np.isin(substrate[:, 1], y)]
    rods, per_rod = len(y), len(x)
    lens = math.pi * (4 * RADIUS + spacing) * (2 * RADIUS - spacing) ** 2 / 12.0  # of two equal spheres
    rod_volume = per_rod * SPHERE_VOLUME - (per_rod - 1) * lens
    com = lattice(np.arange(6) + 0.5, np.arange(1, 5) + 0.5)
    stats = measure(params, com, substrate=(substrate, np.full(len(substrate), RADIUS)))
    particles = len(com) * SPHERE_VOLUME
    height = 2.0 * (rods * rod_volume * 0.5 + particles * 3.0) / (rods * rod_volume + particles)
    assert stats["filling_height"] == pytest.approx(height, rel=1e-12)
    assert stats["substrate_height"] == pytest.approx(height * rods * rod_volume / (rods * rod_volume + particles),
                                                      rel=1e-12)


@pytest.fixture(scope="module")
def continued_pile(tmp_path_factory):
    """A sphere sediment continued on an earlier one: the earlier one's spheres are the substrate."""
    first = parsim.deposit(300, seed=2, box_length=5.0, packing_samples=1000)
    arrays = first.configuration.arrays
    csv = tmp_path_factory.mktemp("substrate") / "pile.csv"
    np.savetxt(csv, np.column_stack([arrays["spheres/position"], arrays["spheres/radius"]]), delimiter=",",
               header="x,y,z,r", comments="")
    return first, parsim.deposit(300, seed=9, box_length=5.0, packing_samples=1000, substrate=str(csv))


def test_a_continued_pile_is_as_high_as_its_top(continued_pile):
    first, second = continued_pile
    stats = second.statistics
    arrays = second.configuration.arrays
    top = float(np.max(arrays["spheres/position"][:, 2] + arrays["spheres/radius"]))
    height = float(stats["filling_height"])
    assert top - 2 * RADIUS < height < top
    # the substrate is the first pile, packed as the second: its share is the first pile's own height
    assert float(stats["substrate_height"]) == pytest.approx(float(first.statistics["filling_height"]), abs=RADIUS)


def test_bulk_packing_of_a_continued_pile_is_that_of_its_profile(continued_pile):
    _, second = continued_pile
    stats = second.statistics
    # the substrate holds as many spheres as the deposit, half the material: z_b = h / 2, and the bulk slab
    # h/2 + [1/4, 3/4] h/2 = [0.625, 0.875] h is made of the profile's slabs 25 ... 34 (of h/40)
    profile = stats["packing_profile"].values
    assert len(profile) == 50
    assert float(stats["bulk_packing_fraction"]) == pytest.approx(profile[25:35].mean(), rel=1e-9)
    assert profile[25:35].mean() > 0.55
    assert float(stats["substrate_height"]) == pytest.approx(0.5 * float(stats["filling_height"]), rel=1e-12)
    assert float(stats["species_mean_height"].squeeze()) == pytest.approx(0.5, abs=0.05)


# --- walls --------------------------------------------------------------------------------------------------

WALL_GAP = 1.0  # between the walls and the lattice's outer spheres: a loose wall layer


def walled_lattice(shift):
    """A walled box of 12 diameters holding eight layers of a simple cubic lattice, 10 x 10 sites
    per layer, 1 diameter from the walls, shifted by ``shift`` along x and y."""
    params = point(box_length=12.0, lateral="walls", rdf_range=1.5, rdf_bins=30)
    com = lattice(np.arange(10) + WALL_GAP + RADIUS + shift, np.arange(8) + RADIUS)
    return params, com


@pytest.mark.parametrize("shift", [0.0, 0.3, 0.8])
def test_the_bulk_between_walls_keeps_four_diameters_from_them(shift):
    params, com = walled_lattice(shift)
    stats = measure(params, com)
    # h = 8, the slab 2 ... 6; the bulk's area 4 ... 8 holds 4 x 4 centres per layer however the lattice lies,
    # the spheres straddling its edges counted whole when their centre is inside
    assert stats["bulk_packing_fraction"] == pytest.approx(SIMPLE_CUBIC, rel=1e-12)
    assert stats["n_bulk_particles"] == 4 * 4 * 4
    assert stats["bulk_coordination"] == 6.0
    assert stats["bulk_wall_distance"] == 4.0
    # the whole box's packing fraction counts the loose wall layer
    whole_box = packing_fraction(com, np.full(len(com), RADIUS), (0.0, 0.0), (12.0, 12.0), 2.0, 6.0)
    assert whole_box == pytest.approx(SIMPLE_CUBIC * 100 / 144, rel=1e-12)


def test_g_of_r_between_walls_has_the_bulk_density():
    params, com = walled_lattice(0.0)
    stats = measure(params, com)
    edges = np.linspace(0.0, 1.5, 31)
    neighbours = np.nansum(stats["radial_distribution"] * 1.0 * 4.0 / 3.0 * np.pi * np.diff(edges**3))
    assert neighbours == pytest.approx(6 + 12, rel=1e-12)  # at distances 1 and sqrt 2, density 1


ROD_OF_TWO = dict(shape="rod", shape_size=2, shape_spacing=1.0)  # centres 0.5 apart, along x


@pytest.mark.parametrize("inside", [True, False])
def test_a_particle_counts_whole_where_its_centre_of_mass_is(inside):
    params = point(box_length=12.0, lateral="walls", **ROD_OF_TWO)
    spacing = 0.5
    lens = math.pi * (4 * RADIUS + spacing) * (2 * RADIUS - spacing) ** 2 / 12.0
    volume = 2 * SPHERE_VOLUME - lens
    distance = 4.0 * species_of(params)[0].equivalent_diameter  # of the template's volume, integrated to 2e-4
    assert distance == pytest.approx(4.0 * (6.0 * volume / math.pi) ** (1.0 / 3.0), rel=1e-4)
    x = distance + (0.2 if inside else -0.2)  # one sphere on each side of the bulk's edge
    stats = measure(params, [(x, 6.0, 2.0)])
    area = (12.0 - 2.0 * distance) ** 2
    expected = volume / (area * 2.0) if inside else 0.0  # h = 4: the slab 1 ... 3 holds the rod whole
    assert stats["bulk_packing_fraction"] == pytest.approx(expected, rel=1e-12, abs=1e-15)
    assert stats["n_bulk_particles"] == int(inside)
    assert stats["bulk_wall_distance"] == distance


def test_the_bulk_of_a_cylinder_is_a_disc_four_diameters_inside_its_wall():
    radius, sides = 8.0, 64
    params = point(container="cylinder", container_radius=radius, container_sides=sides)
    bulk_radius = radius * math.cos(math.pi / sides) - 4.0
    angle = np.arange(12) * np.pi / 6
    inner = np.column_stack([radius + 3.9 * np.cos(angle), radius + 3.9 * np.sin(angle), np.full(12, 2.0)])
    outer = np.column_stack([radius + 4.1 * np.cos(angle + np.pi / 12), radius + 4.1 * np.sin(angle + np.pi / 12),
                             np.full(12, 2.0)])
    stats = measure(params, np.concatenate([inner, outer]), cylinder=(radius, radius, radius, sides))
    assert stats["n_bulk_particles"] == 12
    assert stats["bulk_packing_fraction"] == pytest.approx(12 * SPHERE_VOLUME / (np.pi * bulk_radius**2 * 2.0),
                                                           rel=1e-12)


def test_a_box_too_narrow_for_a_bulk_has_no_bulk_statistics():
    params = point(box_length=7.0, lateral="walls")  # 4 diameters from each wall leave nothing
    stats = measure(params, lattice(np.arange(7) + RADIUS, np.arange(6) + RADIUS))
    assert stats["n_bulk_particles"] == 0
    for name in ("bulk_packing_fraction", "bulk_coordination", "radial_distribution", "contact_number_fraction",
                 "fabric_tensor"):
        assert np.all(np.isnan(stats[name])), name
    assert np.all(np.isfinite(stats["packing_profile"]))


# --- the floor ----------------------------------------------------------------------------------------------

def floor_touching_particles(outcome):
    """Particles with a sphere within the contact gap tolerance of the floor, from the configuration."""
    arrays = outcome.configuration.arrays
    radii = arrays["spheres/radius"]
    gap = arrays["spheres/position"][:, 2] - radii
    return np.unique(arrays["spheres/particle"][gap <= CONTACT_GAP_TOLERANCE * radii.mean()]).size


def test_rolling_rods_on_the_floor_are_counted():
    rods = parsim.deposit(60, seed=4, shape="rod", shape_size=3, box_length=5.0, floor="roll",
                          packing_samples=1000)
    touching = floor_touching_particles(rods)
    assert touching > 5
    assert int(rods.statistics["particles_on_floor"]) == touching


def test_stopped_particles_on_the_floor_are_those_in_the_floor_state():
    rods = parsim.deposit(60, seed=4, shape="rod", shape_size=3, box_length=5.0, packing_samples=1000)
    on_floor = np.count_nonzero(rods.configuration.arrays["particles/state"] == sdbd.RESTING_ON_FLOOR)
    assert int(rods.statistics["particles_on_floor"]) == floor_touching_particles(rods) == on_floor


# --- species' volumes ---------------------------------------------------------------------------------------

def test_species_volumes_of_a_mesh_and_a_sphere():
    species = [{"name": "pebble", "shape": "mesh", "mesh_file": "jobs/data/pebble.obj", "mesh_spheres": 30},
               {"name": "grain", "shape": "sphere", "sphere_radius": 0.3}]
    outcome = parsim.deposit(8, seed=1, species=species, box_length=5.0, packing_samples=1000, length_unit="mm")
    stats = outcome.statistics
    volume, mesh = stats["species_volume"].values, stats["species_mesh_volume"].values
    assert stats["species_volume"].attrs["units"] == stats["species_mesh_volume"].attrs["units"] == "mm3"
    # the mesh is scaled to the volume of a sphere of sphere_radius; its balls, inside it, fill less
    assert mesh[0] == pytest.approx(SPHERE_VOLUME, rel=1e-12) and np.isnan(mesh[1])
    error = float(stats["species_mesh_volume_error"].values[0])
    assert volume[0] / mesh[0] - 1.0 == pytest.approx(error, abs=1e-3)
    assert volume[1] == pytest.approx(4.0 / 3.0 * math.pi * 0.3**3, rel=1e-12)
