"""Voxel images of a sediment (parsim export --format voxels, TaskOutcome.voxelize) read by porespy.

A sediment of 200 hard spheres of diameter 1 in a periodic box of 5 x 5: its exact porosity up to
the image's top is 1 - (sum of the spheres' volumes) / (box area x image height), since the spheres
do not overlap and all lie below the top.  porespy's porosity of the image must approach it as
the voxels shrink.
"""

import json

import numpy as np
import pytest

from tests.readers import require

require("porespy")

import porespy  # noqa: E402

import parsim  # noqa: E402
from parsim.errors import JobError  # noqa: E402
from parsim.output.export import TaskSpheres, export_output  # noqa: E402
from parsim.output.voxels import voxelize  # noqa: E402
from tests.datasets import run_serial  # noqa: E402


@pytest.fixture(scope="module")
def sediment():
    return parsim.deposit(n_particles=200, seed=1, shape="sphere", box_length=5.0)


def exact_porosity(outcome, image) -> float:
    configuration = outcome.configuration
    radius = configuration.arrays["spheres/radius"]
    area = np.prod(configuration.box_upper[:2] - configuration.box_lower[:2])
    height = image.void.shape[2] * image.spacing[2]
    return 1.0 - (4.0 / 3.0 * np.pi * radius**3).sum() / (area * height)


def test_porespy_porosity_converges_on_the_exact_one(sediment):
    errors = []
    for size in (0.2, 0.05):
        image = sediment.voxelize(size)
        assert image.void.dtype == bool and image.void.shape[:2] == (round(5.0 / size),) * 2
        errors.append(abs(porespy.metrics.porosity(image.void) - exact_porosity(sediment, image)))
    assert errors[0] < 5e-3 and errors[1] < 1e-3 and errors[1] < errors[0], errors


def one_sphere(x, periodic):
    """A TaskSpheres of one sphere of radius 1 centred at (x, 2, 2) in a box of 4 x 4 x 4."""
    return TaskSpheres(label="one", kind="deposition", dimension=3, position=np.array([[x, 2.0, 2.0]]),
                       radius=np.ones(1), body=np.zeros(1, dtype=np.int64), body_name="particle",
                       box_lower=np.zeros(3), box_upper=np.full(3, 4.0), periodic=np.array([periodic, True, False]),
                       arrays={}, attrs={})


def test_a_sphere_across_a_periodic_side_wraps_and_a_walled_one_is_cut():
    centred = voxelize(one_sphere(2.0, True), 0.1, height=4.0).void
    across = voxelize(one_sphere(0.0, True), 0.1, height=4.0).void
    cut = voxelize(one_sphere(0.0, False), 0.1, height=4.0).void
    solid = (~centred).sum()
    assert (~across).sum() == solid and np.array_equal(np.roll(~centred, -20, axis=0), ~across)
    assert (~cut).sum() == solid // 2
    assert abs(solid * 0.1**3 - 4.0 / 3.0 * np.pi) < 0.01 * 4.0 / 3.0 * np.pi


def test_the_export_writes_the_image_numpy_and_raw_bytes_alike(tmp_path):
    job = tmp_path / "job.toml"
    job.write_text('name = "v"\nkind = "deposition"\nseed = 2\nrealizations = 1\n'
                   '[parameters]\nn_particles = 40\nshape = "sphere"\nbox_length = 4.0\n')
    assert run_serial("run", str(job), "--output", str(tmp_path / "out"), "--quiet").returncode == 0
    written = export_output(tmp_path / "out", "voxels", out=tmp_path / "images/", voxel_size=0.25)
    npy, raw, header = (next(path for path in written if path.suffix == suffix) for suffix in (".npy", ".raw", ".json"))
    void = np.load(npy)
    layout = json.loads(header.read_text())
    assert layout["shape"] == list(void.shape) and layout["spacing"][2] == 0.25 and layout["void"] == 1
    assert np.array_equal(np.fromfile(raw, dtype=np.uint8).reshape(layout["shape"]).astype(bool), void)
    with pytest.raises(JobError, match="needs --voxel-size"):
        export_output(tmp_path / "out", "voxels", out=tmp_path / "images/")
    with pytest.raises(JobError, match="options of format 'voxels'"):
        export_output(tmp_path / "out", "csv", out=tmp_path / "images/", voxel_size=0.25)


def test_voxels_outside_a_cylinder_are_solid():
    """An empty cylinder of radius 2 in its 4 x 4 box: the pore space is its disc, pi r^2 of 16."""
    empty = TaskSpheres(label="empty", kind="deposition", dimension=3, position=np.zeros((0, 3)), radius=np.zeros(0),
                        body=np.zeros(0, dtype=np.int64), body_name="particle", box_lower=np.zeros(3),
                        box_upper=np.full(3, 4.0), periodic=np.zeros(3, dtype=bool), arrays={},
                        attrs={"container": "cylinder", "container_radius": 2.0})
    image = voxelize(empty, 0.02, height=0.1)
    assert abs(porespy.metrics.porosity(image.void) - np.pi * 4.0 / 16.0) < 1e-3
