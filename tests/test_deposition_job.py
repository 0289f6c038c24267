"""Deposition jobs end to end: identical sediments on 1 and 2 ranks and after a resume."""

import shutil

import numpy as np
import pytest
import xarray as xr

from parsim.errors import JobError
from parsim.job import load_job, parse_job
from parsim.output.dataset import decoded
from parsim.solvers import SOLVERS
from tests.datasets import reproducible_part, run_serial, snapshot_arrays, unfinish
from tests.mpi import parsim_command, run_mpi

JOB = """
name = "sediments"
kind = "deposition"
seed = 11
realizations = 2
[parameters]
n_particles = 150
box_length = 8.0
shape_size = 3
packing_samples = 20000
[sweep]
shape = ["sphere", "spiky", "cube"]
"""


@pytest.fixture(scope="module")
def two_ranks(tmp_path_factory):
    folder = tmp_path_factory.mktemp("deposition")
    job = folder / "job.toml"
    job.write_text(JOB)
    result = run_mpi(parsim_command("run", str(job), "--output", str(folder / "two"), "--quiet"))
    assert result.returncode == 0, result.stderr
    return job, folder / "two"


def tasks_of(folder):
    return sorted(path.name for path in (folder / "tasks").glob("*.h5"))


def assert_same_sediments(one, two):
    assert tasks_of(one) == tasks_of(two) and len(tasks_of(one)) == 6
    for name in tasks_of(one):
        a, b = snapshot_arrays(one / "tasks" / name), snapshot_arrays(two / "tasks" / name)
        assert a.keys() == b.keys()
        for key in a:
            np.testing.assert_array_equal(a[key], b[key], err_msg=f"{name}: {key}")  # bitwise


@pytest.mark.mpi
def test_identical_sediments_on_one_and_two_ranks(two_ranks, tmp_path):
    job, two = two_ranks
    result = run_serial("run", str(job), "--output", str(tmp_path), "--quiet")
    assert result.returncode == 0, result.stderr
    assert_same_sediments(tmp_path, two)
    xr.testing.assert_identical(reproducible_part(tmp_path / "sediments.nc"), reproducible_part(two / "sediments.nc"))


@pytest.mark.mpi
def test_resumed_job_recomputes_the_same_sediment(two_ranks, tmp_path):
    import shutil

    job, two = two_ranks
    shutil.copytree(two, tmp_path / "out")
    unfinish(tmp_path / "out", [(1, 1)])  # as if killed before this task finished
    (tmp_path / "out" / "sediments.nc").unlink()
    result = run_mpi(parsim_command("run", str(job), "--output", str(tmp_path / "out"), "--quiet"))
    assert result.returncode == 0, result.stderr
    assert_same_sediments(tmp_path / "out", two)
    xr.testing.assert_identical(reproducible_part(tmp_path / "out" / "sediments.nc"),
                                reproducible_part(two / "sediments.nc"))


@pytest.mark.mpi
def test_sediment_statistics_and_layout(two_ranks):
    _, two = two_ranks
    with xr.open_dataset(two / "sediments.nc") as ds:
        assert ds.packing_profile.dims == ("shape", "realization", "z_relative")
        named = decoded(ds, ["shape"])  # a swept string is coded as CF flags
        assert (named.n_spheres.sel(shape="spiky") == 150 * 7).all() and (named.n_spheres.sel(shape="cube") == 150 * 26).all()
        # every particle is accounted for: on the floor, hanging, or resting on three contacts
        assert (ds.particles_on_floor > 0).all() and (ds.filling_height > 0).all()
        assert (named.bulk_packing_fraction.sel(shape="sphere") > 0.5).all()
        # the parameters some task reads are scalar coordinates, those no task reads are not
        assert {"shape_size", "box_length", "sphere_radius", "trial_angle"} <= set(ds.coords)
        assert not {"shape_spacing", "semi_axis_x", "exponent_vertical", "shape_spheres", "agglomerate_file",
                    "wall_contact", "drop_radius", "size_spread"} & set(ds.coords)
    spiky = load_job(two / "job.toml", SOLVERS).tasks()[2]  # point 1 (shape = "spiky"), realisation 0
    arrays = snapshot_arrays(two / "tasks" / f"{spiky.label}.h5")
    particle = arrays["spheres/particle"]
    assert np.all(np.diff(particle) >= 0) and particle[-1] == 149  # deposition order, contiguous
    assert arrays["particles/rotation"].shape == (150, 4) and arrays["particles/event_counts"].shape == (150, 13)
    assert np.all(arrays["spheres/position"][:, 2] >= arrays["spheres/radius"] - 1e-9)  # nothing below the floor


def test_agglomerates_from_an_aggregation_task(tmp_path):
    aggregation = tmp_path / "aggregation.toml"
    aggregation.write_text('name = "clusters"\nkind = "aggregation"\nseed = 1\nrealizations = 1\n'
                           '[parameters]\nn_spheres = 25\nvolume_fraction = 0.2\n')
    assert run_serial("run", str(aggregation), "--output", str(tmp_path / "clusters"), "--quiet").returncode == 0
    (cluster,) = (tmp_path / "clusters" / "tasks").glob("*.h5")
    deposition = tmp_path / "deposition.toml"
    deposition.write_text(f'name = "flakes"\nkind = "deposition"\nseed = 2\nrealizations = 1\n[parameters]\n'
                          f'n_particles = 30\nshape = "agglomerate"\nagglomerate_file = "{cluster}"\n'
                          f'box_length = 40.0\npacking_samples = 5000\n')
    result = run_serial("run", str(deposition), "--output", str(tmp_path / "flakes"), "--quiet")
    assert result.returncode == 0, result.stderr
    with xr.open_dataset(tmp_path / "flakes" / "flakes.nc") as ds:
        assert int(ds.n_spheres.squeeze()) == 30 * 25

    # Another cluster at the same path: resuming would mix two particles in one dataset, so it is refused.
    aggregation.write_text(aggregation.read_text().replace("seed = 1", "seed = 2"))
    assert run_serial("run", str(aggregation), "--output", str(tmp_path / "other"), "--quiet").returncode == 0
    (other,) = (tmp_path / "other" / "tasks").glob("*.h5")
    assert other.name == cluster.name  # one point, hence one label: the seed is not part of it
    shutil.copy(other, cluster)
    resumed = run_serial("run", str(deposition), "--output", str(tmp_path / "flakes"), "--quiet")
    assert resumed.returncode == 2, resumed.stderr
    assert "holds results of a different job, which differs in: [parameters] agglomerate_file " \
           f"('{cluster}' (sha256" in resumed.stderr


@pytest.mark.parametrize("change, message", [
    (("box_length = 8.0", "box_length = 3.0"), "box_length = 3.0 must exceed twice the particle extent"),
    (('shape = ["sphere", "spiky", "cube"]', 'shape = ["agglomerate"]'), "needs agglomerate_file"),
    (('shape_size = 3', 'shape_size = 3\nshape = "agglomerate"\nagglomerate_file = "nowhere.h5"'),
     "agglomerate_file = 'nowhere.h5': no such file"),
    (('shape_size = 3', 'shape_size = 3\nsize_distribution = "uniform"\nsize_spread = 1.5'), "size_spread = 1.5"),
    (('shape_size = 3', 'shape_size = 3\nlateral = "sideways"'), "lateral = 'sideways': allowed: one of 'periodic', 'walls', 'none'"),
])
def test_invalid_deposition_jobs(change, message):
    text = JOB.replace(*change)
    if "nowhere" in change[1]:
        text = text.replace('shape = ["sphere", "spiky", "cube"]', "")
    with pytest.raises(JobError, match=message):
        parse_job(text, SOLVERS)


@pytest.mark.parametrize("lateral", ["periodic", "walls", "none"])
def test_the_first_particles_of_a_task_are_the_task_with_fewer_of_them(lateral):
    solver = SOLVERS["deposition"]
    params = {p.name: p.default for p in solver.parameters}
    params.update(shape="rod", shape_size=5, box_length=12.0, lateral=lateral, floor="roll",
                  size_distribution="lognormal", size_spread=0.2, packing_samples=5000)
    results = {}
    for n in (90, 35):
        params["n_particles"] = n
        results[n] = solver.solve(dict(params), np.random.default_rng(5), None).configuration.arrays
    many, few = results[90], results[35]
    for key, value in few.items():
        np.testing.assert_array_equal(many[key][:len(value)], value, err_msg=key)  # bitwise
