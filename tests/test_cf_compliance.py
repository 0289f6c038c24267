"""The datasets pass the CF checker (compliance-checker -t cf:1.10); their units, coordinates and provenance.

Two real jobs are run on one rank: the quick start made small (its own file, fewer and smaller
clusters) and a deposition job with a length unit of its own.  The checker's high-priority
failures ("Errors" in its report) and any exception a check raises fail the test, with the
checker's messages.
"""

import re
from pathlib import Path

import netCDF4
import numpy as np
import pytest
import xarray as xr

from tests.readers import require

require("cf_units", "compliance_checker.suite")

from cf_units import Unit  # noqa: E402
from compliance_checker.suite import CheckSuite  # noqa: E402

import parsim  # noqa: E402
from parsim.job import SI_PREFIXES, UNIT_KEYS, parse_job  # noqa: E402
from parsim.output.dataset import REFERENCES, all_statistics, build_dataset, row_layout  # noqa: E402
from parsim.output.snapshot import OUTPUT_SCHEMA  # noqa: E402
from parsim.solver import flag_value, resolve_units  # noqa: E402
from parsim.solvers import SOLVERS  # noqa: E402
from tests.datasets import run_serial, swept_mesh_files_dataset  # noqa: E402

CF = "cf:1.10"
QUICKSTART = Path(__file__).resolve().parent.parent / "jobs" / "quickstart.toml"
SMALLER = {"realizations": ("realizations = 4", "realizations = 2"),
           "n_spheres": ("n_spheres = [100, 400, 900]", "n_spheres = [16, 36]")}

DEPOSITION = """
name = "sediment"
kind = "deposition"
seed = 3
realizations = 2
length_unit = "mm"
[parameters]
n_particles = 40
box_length = 6.0
profile_bins = 5
packing_samples = 2000
[sweep]
trial_angle = [0.001, 0.01]
"""


STRING_SWEEP = """
name = "shapes"
kind = "deposition"
seed = 4
realizations = 1
[parameters]
n_particles = 20
box_length = 5.0
profile_bins = 4
packing_samples = 1000
[sweep]
shape = ["sphere", "rod"]
"""


def small_quickstart() -> str:
    """The quick start's job file with 16 and 36 discs and two realisations (12 tasks of a second)."""
    text = QUICKSTART.read_text()
    for key, (line, smaller) in SMALLER.items():
        assert line in text, f"jobs/quickstart.toml no longer has {line!r}; update SMALLER[{key!r}]"
        text = text.replace(line, smaller)
    return text


def run(folder: Path, job_text: str) -> Path:
    """Run ``job_text`` on one rank into ``folder``; the dataset's path."""
    job = folder / "job.toml"
    job.write_text(job_text)
    result = run_serial("run", str(job), "--output", str(folder / "out"), "--quiet")
    assert result.returncode == 0, result.stderr
    (dataset,) = (folder / "out").glob("*.nc")
    return dataset


@pytest.fixture(scope="module")
def quickstart(tmp_path_factory) -> Path:
    return run(tmp_path_factory.mktemp("quickstart"), small_quickstart())


@pytest.fixture(scope="module")
def deposition(tmp_path_factory) -> Path:
    return run(tmp_path_factory.mktemp("deposition"), DEPOSITION)


def cf_failures(path: Path) -> list[str]:
    """The checker's errors (high-priority failures) and the checks that raised, one message each."""
    suite = CheckSuite()
    suite.load_all_available_checkers()
    dataset = suite.load_dataset(str(path))
    try:
        results, raised = suite.run_all(dataset, [CF])[CF]
    finally:
        dataset.close()
    failures = [f"{result.name}: {message}" for result in results
                if result.weight == 3 and result.value[0] < result.value[1] for message in result.msgs]
    return failures + [f"the check {name} raised {error!r}" for name, (error, _) in raised.items()]


@pytest.fixture(scope="module")
def string_sweep(tmp_path_factory) -> Path:
    return run(tmp_path_factory.mktemp("string_sweep"), STRING_SWEEP)


@pytest.fixture(scope="module")
def colliding_paths(tmp_path_factory) -> Path:
    """A sweep of paths whose CF words would be one (``a/b.stl``, ``a_b.stl``; ``é.stl``, ``ü.stl``): the
    words that tell them apart are CF words too."""
    path = tmp_path_factory.mktemp("colliding_paths") / "meshes.nc"
    swept_mesh_files_dataset(["a/b.stl", "a_b.stl", "é.stl", "ü.stl"]).to_netcdf(path, engine="netcdf4")
    return path


@pytest.fixture(scope="module")
def partial(quickstart) -> Path:
    """The partial dataset of the small quick start (``parsim collect``): every statistic may have
    missing tasks there, its integer ones included."""
    collected = run_serial("collect", str(quickstart.parent))
    assert collected.returncode == 0, collected.stderr
    (path,) = quickstart.parent.glob("*.partial.nc")
    return path


@pytest.mark.parametrize("dataset", ["quickstart", "deposition", "string_sweep", "colliding_paths", "partial"])
def test_the_checker_reports_no_error(dataset, request):
    failures = cf_failures(request.getfixturevalue(dataset))
    assert not failures, f"{CF} reports for the {dataset} dataset:\n" + "\n".join(failures)


def test_the_checker_finds_what_was_wrong_before(quickstart, tmp_path):
    """What parsim 0.1 wrote fails: job-named units, a coordinate with a _FillValue, a string coordinate."""
    with xr.open_dataset(quickstart) as dataset:
        dataset = dataset.load()
    dataset.radius.attrs["units"] = "job_length_unit"
    dataset["r"].encoding["_FillValue"] = np.nan
    broken = dataset.assign_coords(component=("component", np.array(["x", "y"]), {"long_name": "component"}))
    broken.to_netcdf(tmp_path / "broken.nc")
    failures = "\n".join(cf_failures(tmp_path / "broken.nc"))
    assert 'units for radius, "job_length_unit" are not recognized by UDUNITS' in failures
    assert "The coordinate variable 'r' must not have the _FillValue attribute" in failures
    assert "check_coordinate_variables_strict_monotonicity raised" in failures


def test_no_coordinate_has_a_fill_value(quickstart, deposition):
    for path in (quickstart, deposition):
        with netCDF4.Dataset(path) as dataset:
            coordinates = set(dataset.dimensions) | {name for variable in dataset.variables.values()
                                                     for name in getattr(variable, "coordinates", "").split()}
            filled = [name for name in coordinates if "_FillValue" in dataset.variables[name].ncattrs()]
            assert not filled, f"{path.name}: coordinates with a _FillValue: {filled}"


def test_component_is_coded_by_flags(quickstart):
    with xr.open_dataset(quickstart) as dataset:
        component = dataset.component
        assert np.issubdtype(component.dtype, np.integer)
        assert component.attrs["flag_meanings"] == "x y"
        np.testing.assert_array_equal(component.attrs["flag_values"], component.values)
        x = dataset.orientation.sel(component=flag_value(component.attrs, "x"))
        y = dataset.orientation.sel(component=flag_value(component.attrs, "y"))
        np.testing.assert_allclose(x**2 + y**2, 1.0, rtol=1e-12)  # D is a unit vector


def test_units_follow_the_job(quickstart, deposition):
    with xr.open_dataset(quickstart) as dataset:
        units = {name: variable.attrs["units"] for name, variable in {**dataset.coords, **dataset.data_vars}.items()}
        assert dataset.attrs["length_unit"] == "m" and dataset.attrs["mass_unit"] == "kg"
    assert (units["radius"], units["box_length"], units["radius_of_gyration"]) == ("m", "m", "m")
    assert (units["final_time"], units["max_time"], units["speed"], units["mass"]) == ("s", "s", "m s-1", "kg")
    with xr.open_dataset(deposition) as dataset:
        assert dataset.sphere_radius.attrs["units"] == "mm" and dataset.filling_height.attrs["units"] == "mm"
        assert dataset.wall_time.attrs["units"] == "s"  # wall-clock seconds, whatever the job's time unit


SI_EXPONENTS = {"": 0, "Y": 24, "Z": 21, "E": 18, "P": 15, "T": 12, "G": 9, "M": 6, "k": 3, "h": 2, "da": 1,
                "d": -1, "c": -2, "m": -3, "u": -6, "n": -9, "p": -12, "f": -15, "a": -18, "z": -21, "y": -24}


def test_every_unit_a_job_may_name_is_udunits_of_its_quantity():
    """The job's small check accepts only what UDUNITS reads as a unit of the quantity, with the prefix's factor."""
    assert set(SI_EXPONENTS) == {"", *SI_PREFIXES}
    for unit in UNIT_KEYS:
        base = Unit(unit.base)
        for prefix, exponent in SI_EXPONENTS.items():
            assert unit.accepts(prefix + unit.base)
            assert Unit(prefix + unit.base).convert(1.0, base) == pytest.approx(10.0**exponent, rel=1e-12), prefix
        for other in unit.others:
            assert unit.accepts(other) and Unit(other).is_convertible(base)
        assert Unit(unit.default).is_convertible(base) and unit.accepts(unit.default)
        assert not unit.accepts(unit.quantity) and not unit.accepts("1") and not unit.accepts(1)


def test_every_declared_unit_is_udunits_of_its_quantity():
    """Every unit of every solver's declarations, in the defaults and in other units, parses and has its dimension."""
    dimension_of = {"{length}": "m", "{time}": "s", "{mass}": "kg", "{length} {time}-1": "m s-1", "{length}3": "m3"}
    job_units = [{"length": "m", "time": "s", "mass": "kg"}, {"length": "um", "time": "h", "mass": "mg"}]
    for solver in SOLVERS.values():
        declared = [(p.name, p.units) for p in solver.parameters] + [(s.name, s.units) for s in all_statistics(solver)]
        for name, template in declared:
            for units in job_units:
                text = resolve_units(template, units)
                unit = Unit(text)  # raises on a string UDUNITS does not accept
                assert unit.is_convertible(Unit(dimension_of.get(template, template))), (solver.kind, name, text)


def dataset_of(body: str) -> xr.Dataset:
    """The dataset of an aggregation job from zeros, without running it: its coordinates and attributes."""
    job = parse_job(f'name = "a"\nkind = "aggregation"\nseed = 1\nrealizations = 1\n{body}', SOLVERS)
    solver = SOLVERS["aggregation"]
    observable = solver.coordinates(job.fixed)
    zeros = {s.name: np.zeros([len(observable[d].values) for d in s.dims]) for s in all_statistics(solver)}
    return build_dataset(job, solver, row_layout(job, solver).rows([(task, zeros) for task in job.tasks()]),
                         mpi_size=1, ranks_per_task=1)


def test_ts_keys_are_coordinates_only_of_jobs_with_ts_tasks():
    """The keys of the time-stepping method, the speed the supplementary initial condition does not read, and
    the spread of lognormal radii."""
    ts_only = {p.name for p in SOLVERS["aggregation"].parameters if p.read_when is not None} - {"speed",
                                                                                                 "radius_geometric_std"}
    assert {"daha_damping", "time_step_factor", "formulation"} <= ts_only
    ed = dataset_of("[parameters]\nn_spheres = 16\nvolume_fraction = 0.2\n")
    assert not ts_only & set(ed.coords) and "speed" in ed.coords and "method" in ed.coords
    both = dataset_of('[parameters]\nn_spheres = 16\nvolume_fraction = 0.2\n[sweep]\nmethod = ["ed", "ts"]\n')
    assert ts_only <= set(both.coords)
    supplementary = dataset_of('[parameters]\nn_spheres = 16\ninitial_condition = "unit_lattice_uniform"\n')
    assert "speed" not in supplementary.coords and "volume_fraction" not in supplementary.coords
    assert "radius_geometric_std" not in ed.coords
    lognormal = dataset_of('[parameters]\nn_spheres = 16\nvolume_fraction = 0.1\nradius_distribution = "lognormal"\n')
    assert "radius_geometric_std" in lognormal.coords


def test_the_units_a_job_names_reach_every_variable_of_their_quantity():
    dataset = dataset_of('length_unit = "um"\ntime_unit = "ms"\nmass_unit = "mg"\n'
                         '[parameters]\nn_spheres = 16\nvolume_fraction = 0.2\n')
    units = {name: variable.attrs["units"] for name, variable in {**dataset.coords, **dataset.data_vars}.items()}
    assert (units["radius"], units["box_length"], units["radius_of_gyration"]) == ("um", "um", "um")
    assert (units["final_time"], units["max_time"], units["speed"], units["mass"]) == ("ms", "ms", "um ms-1", "mg")
    assert units["wall_time"] == "s" and "eps in um" in dataset.fractal_prefactor.attrs["long_name"]
    assert not [name for name, unit in units.items() if "{" in unit], "a placeholder left unresolved"


def test_provenance_and_references(quickstart):
    with xr.open_dataset(quickstart) as dataset:
        attrs = dataset.attrs
    assert attrs["Conventions"] == "CF-1.10"
    assert attrs["parsim_version"] == parsim.__version__ and attrs["parsim_output_schema"] == OUTPUT_SCHEMA
    assert attrs["references"] == REFERENCES
    assert "Topić, N. & Pöschel, T. (2016)" in REFERENCES and "J. Comput. Phys. 308" in REFERENCES
    assert "Degond, P., Dimarco, G., Ferreira, M. A. & Hecht, S. (2024)" in REFERENCES


def test_the_unit_keys_are_documented():
    reference = (Path(__file__).resolve().parent.parent / "docs" / "jobs.md").read_text()
    for unit in UNIT_KEYS:
        assert re.search(rf"\| `{unit.key}` \| string \| `\"{unit.default}\"` \|", reference), unit.key


def test_a_swept_string_is_coded_by_flags_and_selected_by_name(string_sweep):
    """A string sweep is an int8 coordinate whose flag_meanings name its values in the job's order;
    parsim.decoded gives it back by name, for ``sel``."""
    with xr.open_dataset(string_sweep) as dataset:
        shape = dataset["shape"]
        assert shape.dtype == np.int8 and shape.values.tolist() == [0, 1]
        assert shape.attrs["flag_meanings"] == "sphere rod" and flag_value(shape.attrs, "rod") == 1
        named = parsim.decoded(dataset)
        assert named["shape"].values.tolist() == ["sphere", "rod"]
        rods = named.sel(shape="rod")
        assert np.array_equal(rods.bulk_packing_fraction.values, dataset.bulk_packing_fraction.isel(shape=1).values)


def test_a_partial_dataset_keeps_integer_statistics_integer(partial, quickstart):
    """Missing tasks of an integer statistic are its _FillValue, not NaN in a float copy: its
    flag_values keep the variable's type (CF 3.5)."""
    with xr.open_dataset(quickstart) as whole, netCDF4.Dataset(partial) as collected:
        reason = collected["stop_reason"]
        assert reason.dtype == np.int8 and reason.flag_values.dtype == np.int8
        assert np.array_equal(reason[:], whole.stop_reason.values)
