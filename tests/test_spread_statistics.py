"""A deposition task spread over a group of ranks (``--ranks-per-task 2``) against the same task on one rank:
the sediment is the serial one, and so must be every statistic of the dataset, sampled ones included."""

import numpy as np
import pytest
import xarray as xr

from tests.datasets import reproducible_part, run_serial
from tests.mpi import parsim_command, run_mpi

# Rods of three spheres, 0.6 radii apart (three spheres overlap: the packing fraction's excess is partly sampled)
# and 1 radius apart (pairwise lenses, exact), of uniformly spread sizes, in a periodic box wide enough for two
# blocks: the sediment is split between the ranks and the kernels' frames are narrower than the box.
JOB = """
name = "spread_rods"
kind = "deposition"
seed = 17
realizations = 1
configurations = "none"
[parameters]
n_particles = 2400
box_length = 16.0
size_distribution = "uniform"
size_spread = 0.2
packing_samples = 20000
profile_bins = 30
rdf_range = 1.5
rdf_bins = 30
[[species]]
name = "tight"
shape = "rod"
shape_size = 3
shape_spacing = 0.6
share = 1.0
[[species]]
name = "loose"
shape = "rod"
shape_size = 3
shape_spacing = 1.0
share = 1.0
"""


MESH_JOB = """
name = "spread_hopper"
kind = "deposition"
seed = 23
realizations = 1
configurations = "none"
[parameters]
n_particles = 1200
container = "mesh"
container_file = "{vessel}"
floor = "roll"
profile_bins = 30
rdf_range = 1.5
rdf_bins = 30
[[species]]
name = "sphere"
shape = "sphere"
share = 1.0
[[species]]
name = "rod"
shape = "rod"
shape_size = 3
share = 1.0
"""


def _serial_and_spread(tmp_path, text, name):
    """The job ``text`` run on one rank and spread over two: the reproducible parts of both datasets, compared
    variable by variable (integers identical, the rest to 1e-12: sums in another order)."""
    job = tmp_path / "job.toml"
    job.write_text(text)
    spread = run_mpi(parsim_command("run", str(job), "--output", str(tmp_path / "spread"), "--quiet",
                                    "--ranks-per-task", "2"), ranks=2, timeout=300)
    assert spread.returncode == 0, spread.stderr
    one = run_serial("run", str(job), "--output", str(tmp_path / "one"), "--quiet")
    assert one.returncode == 0, one.stderr
    serial, split = (reproducible_part(tmp_path / folder / f"{name}.nc") for folder in ("one", "spread"))
    assert set(serial.data_vars) == set(split.data_vars) and "spheres_per_second" not in serial
    for variable_name, variable in serial.data_vars.items():
        if variable.dtype.kind in "iub":
            xr.testing.assert_identical(variable, split[variable_name])
        else:
            np.testing.assert_allclose(split[variable_name].values, variable.values, rtol=1e-12, atol=0,
                                       err_msg=variable_name)
    return serial


@pytest.mark.mpi
def test_a_spread_task_of_overlapping_spheres_is_the_serial_task_in_every_statistic(tmp_path):
    serial = _serial_and_spread(tmp_path, JOB, "spread_rods")
    # the comparison has something to compare: a bulk, g(r) and the overlaps measured
    assert serial.n_bulk_particles.values.item() > 100 and np.isfinite(serial.radial_distribution).all()
    assert serial.bulk_packing_fraction.values.item() > 0.3 and serial.nematic_order.values.item() > 0.0


@pytest.mark.mpi
def test_a_spread_task_in_a_hopper_is_the_serial_task_in_every_statistic(tmp_path):
    """The vessel's volumes and its bulk region (its inside shrunk from the faces) measured alike on one rank
    and spread over two."""
    from parsim.deposition.vessel import hopper_mesh
    from tests.mesh_files import write

    vessel = write(hopper_mesh(10.0, 6.0, 6.0, 8), tmp_path, "hopper.obj")
    serial = _serial_and_spread(tmp_path, MESH_JOB.format(vessel=vessel), "spread_hopper")
    assert serial.n_bulk_particles.values.item() > 20 and np.isfinite(serial.packing_profile).all()
