"""Aggregation points that cannot give every statistic are refused before anything is computed."""

import math
import re

import pytest
import xarray as xr

from parsim.errors import JobError
from parsim.job import parse_job
from parsim.solvers import SOLVERS
from parsim.aggregation.solver import box_length, check, warm_up_parameters
from tests.datasets import run_serial

JOB = """
name = "fit"
kind = "aggregation"
seed = 3
realizations = 1
[parameters]
{parameters}
"""

#: Too small for the box-counting fit: L/4 < 3R, only eps = L/2 lies in 3R <= eps <= L/2.
TOO_SMALL = {"2d": {"n_spheres": 9, "volume_fraction": 0.3},
             "3d": {"dimension": 3, "n_spheres": 64, "volume_fraction": 0.2}}
#: The fewest spheres at the same volume fractions with L/4 >= 3R (L >= 12R).
JUST_BIG_ENOUGH = {"2d": {"n_spheres": 14, "volume_fraction": 0.3},
                   "3d": {"dimension": 3, "n_spheres": 83, "volume_fraction": 0.2}}


def job_text(parameters):
    return JOB.format(parameters="\n".join(f"{key} = {value}" for key, value in parameters.items()))


def write_job(tmp_path, parameters):
    path = tmp_path / "job.toml"
    path.write_text(job_text(parameters))
    return str(path)


def point(parameters):
    return parse_job(job_text(parameters), SOLVERS).point_parameters(0)


@pytest.mark.parametrize("case", TOO_SMALL, ids=str)
def test_validate_refuses_a_box_too_small_for_the_box_counting_fit(tmp_path, case):
    parameters = TOO_SMALL[case]
    defaults = {"dimension": 2, "radius": 0.2, "initial_condition": "lattice_isotropic"}
    length = box_length({**defaults, **parameters})
    message = (f"the box-counting fit of D_f needs at least two box sizes eps = L/2^m with 3R <= eps <= L/2; "
               f"this point has L = {length:.6g}, R = 0.2")
    with pytest.raises(JobError, match=re.escape(message)):
        parse_job(job_text(parameters), SOLVERS)
    result = run_serial("validate", write_job(tmp_path, parameters))
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert message in result.stderr and "raise n_spheres or lower volume_fraction" in result.stderr


@pytest.mark.parametrize("case", JUST_BIG_ENOUGH, ids=str)
def test_a_point_just_big_enough_for_the_fit_runs(tmp_path, case):
    parameters = JUST_BIG_ENOUGH[case]
    smaller = {**parameters, "n_spheres": parameters["n_spheres"] - 1}
    with pytest.raises(JobError, match="the box-counting fit of D_f"):
        parse_job(job_text(smaller), SOLVERS)
    result = run_serial("run", write_job(tmp_path, parameters), "--output", str(tmp_path / "out"), "--quiet")
    assert result.returncode == 0, result.stderr
    with xr.open_dataset(tmp_path / "out" / "fit.nc") as dataset:
        assert math.isfinite(float(dataset.fractal_dimension.squeeze()))


@pytest.mark.parametrize("parameters", [
    {"dimension": 3, "method": '"ts"', "n_spheres": 343, "volume_fraction": 0.1},
    {"dimension": 3, "n_spheres": 1000, "volume_fraction": 0.3},
    {"n_spheres": 400, "volume_fraction": 0.3},
    {"n_spheres": 14, "volume_fraction": 0.3},
    {"n_spheres": 100, "initial_condition": '"unit_lattice_uniform"'},
], ids=str)
def test_the_warm_up_point_passes_the_checks(parameters):
    """The runner solves the warm-up point of every point before the tasks: it must give every statistic."""
    params = point(parameters)
    small = warm_up_parameters(params)
    check(small)
    assert small["n_spheres"] <= params["n_spheres"]
