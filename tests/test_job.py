"""Job files: what is accepted, and the message for what is not."""

import subprocess
import sys

import pytest

from parsim.errors import JobError
from parsim.job import load_job, parse_job
from parsim.solvers import SOLVERS

BASE = """
name = "t"
kind = "aggregation"
seed = 7
realizations = 2
output = "out"
[parameters]
radius = 0.2
[sweep]
n_spheres = [100, 400]
volume_fraction = [0.1, 0.2, 0.3]
"""


def parse(text):
    return parse_job(text, SOLVERS, source="job.toml")


def test_quickstart_is_valid():
    job = load_job("jobs/quickstart.toml", SOLVERS)
    assert job.kind == "aggregation"
    assert job.n_points * job.realizations == len(job.tasks())


def test_grid_order_and_defaults():
    job = parse(BASE)
    assert job.sweep_shape == (2, 3)
    assert job.point_parameters(0)["n_spheres"] == 100 and job.point_parameters(0)["volume_fraction"] == 0.1
    assert job.point_parameters(4)["n_spheres"] == 400 and job.point_parameters(4)["volume_fraction"] == 0.2
    assert job.fixed["mass"] == 1.0 and job.fixed["contact_factor"] == 2.1  # paper defaults


def test_seed_depends_on_task_indices_only_and_not_on_the_method():
    job = parse(BASE.replace("[sweep]", '[sweep]\nmethod = ["ed"]'))
    solver = SOLVERS["aggregation"]
    keys = {task: job.seed_sequence(task, solver).spawn_key for task in job.tasks()}
    assert len(set(keys.values())) == len(keys)  # distinct streams
    # method is the first (slowest) sweep axis but does not count in the seed's point index
    assert keys[job.tasks()[-1]] == (5, 1)


@pytest.mark.parametrize("change, message", [
    (("seed = 7", "seed = 7\ncolour = 1"), "unknown key 'colour'; allowed top-level keys"),
    (("radius = 0.2", "radius = 0.2\nradiuss = 1"), r"\[parameters\] unknown key 'radiuss'; allowed keys"),
    (("radius = 0.2", 'radius = "big"'), "radius = 'big': must be a number"),
    (("radius = 0.2", "radius = -1"), r"radius = -1.0 is out of range; allowed: a number, 0 < radius"),
    (("[0.1, 0.2, 0.3]", "[0.1, 1.5]"), r"volume_fraction\[1\] = 1.5 is out of range; allowed: a number, 0 < volume_fraction < 1"),
    (("[0.1, 0.2, 0.3]", "[0.1, 0.1]"), "values must be distinct"),
    (("realizations = 2", "realizations = 0"), "realizations = 0: allowed: an integer >= 1"),
    (("radius = 0.2", 'radius = 0.2\nmethod = "magic"'), "method = 'magic': allowed: one of 'ed'"),
    (("radius = 0.2", "radius = 0.2\nbox_levels = 8\n[sweep.x]"), "unknown key 'x'"),
    (("n_spheres = [100, 400]", "box_levels = [8, 9]\nn_spheres = [100, 400]"), "'box_levels' cannot be swept"),
    (("n_spheres = [100, 400]", "n_spheres = [100, 400]\nradius = [0.2]"), "'radius' is both in"),
    (("n_spheres = [100, 400]", ""), "parameter 'n_spheres' is required"),
    (("[0.1, 0.2, 0.3]", "[0.1, 0.8]"), r"volume_fraction=0.8: the initial lattice does not fit .*condition 4\.2"),
])
def test_invalid_jobs_name_the_field_and_the_allowed_values(change, message):
    with pytest.raises(JobError, match=message):
        parse(BASE.replace(*change))


def test_supplementary_initial_condition_needs_no_volume_fraction():
    text = BASE.replace("volume_fraction = [0.1, 0.2, 0.3]", "").replace(
        "radius = 0.2", 'radius = 0.2\ninitial_condition = "unit_lattice_uniform"')
    assert parse(text).n_points == 2
    with pytest.raises(JobError, match="volume_fraction must not be given"):
        parse(text.replace("n_spheres = [100, 400]", "n_spheres = [100, 400]\nvolume_fraction = [0.2]"))


def test_cli_rejects_an_invalid_job_without_traceback_and_computes_nothing(tmp_path):
    job = tmp_path / "bad.toml"
    job.write_text(BASE.replace('output = "out"', f'output = "{tmp_path / "out"}"').replace("[0.1, 0.2, 0.3]", "[2.0]"))
    for command in ("validate", "run"):
        result = subprocess.run([sys.executable, "-m", "parsim.cli", command, str(job)], capture_output=True, text=True)
        assert result.returncode == 2
        assert "volume_fraction[0] = 2.0 is out of range" in result.stderr
        assert "Traceback" not in result.stderr
    assert not (tmp_path / "out").exists()


def test_every_parameter_is_in_the_job_reference():
    reference = open("docs/jobs.md").read()
    for solver in SOLVERS.values():
        for parameter in solver.parameters:
            assert f"| `{parameter.name}` |" in reference, parameter.name
        for statistic in solver.statistics:
            assert f"`{statistic.name}`" in reference, statistic.name
