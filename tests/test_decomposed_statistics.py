"""The statistics of a sediment spread over MPI ranks (parsim.parallel.deposition_statistics) against the
serial statistics of the gathered sediment.

``tests/scripts/decomposed_statistics_probe.py`` runs the deposition solver on 2 and 4 ranks for six
small sediments (spheres in a periodic box wide enough for the ranks' frames to be narrower than it,
rods and smaller spheres between walls, overlapping rods in a cylinder, a heap, spheres of several
sizes on a substrate, and spheres on a substrate that rank 0 settles alone) and compares every
statistic of ``measure_decomposed`` with ``measure`` of the gathered sediment. Counts must be equal,
floats equal to round-off; the packing fraction of particles whose spheres overlap is partly sampled
(quasi-Monte Carlo points that depend on how the spheres are grouped), so there it may differ by its
sampling error.
"""

import json
from pathlib import Path

import numpy as np
import pytest

from tests.mpi import run_mpi

REPOSITORY = Path(__file__).resolve().parent.parent
PROBE = str(REPOSITORY / "tests" / "scripts" / "decomposed_statistics_probe.py")

ROUND_OFF = 1e-12  # relative to the largest magnitude of a statistic's values
SAMPLED = ("bulk_packing_fraction", "packing_profile", "species_packing_profile")
OVERLAPPING = ("overlapping rods, cylinder",)  # spheres overlap within particles: SAMPLED keys are sampled
# measured (50 000 samples per slab): up to 6e-4 in a slab, 3.5e-5 in the bulk; one rod is 1e-2 of a slab
SAMPLING_TOLERANCE = {"bulk_packing_fraction": 3e-4, "packing_profile": 3e-3, "species_packing_profile": 3e-3}
ALONE = "substrate, rank 0 alone"  # the other ranks hold no particle
NEVER_MEASURED = ("species_mesh_volume", "species_mesh_volume_error", "species_mesh_surface_distance")  # no mesh


def mismatches(serial: dict, decomposed: dict, sampled: bool = False) -> list[str]:
    """The statistics of ``decomposed`` that differ from ``serial`` by more than the rules allow (both as the
    probe writes them: dtype, shape, values)."""
    found = []
    for key, expected in serial.items():
        got = decomposed.get(key)
        if got is None or got["dtype"] != expected["dtype"] or got["shape"] != expected["shape"]:
            found.append(f"{key}: {got and (got['dtype'], got['shape'])} != {expected['dtype'], expected['shape']}")
            continue
        a, b = np.array(expected["values"]), np.array(got["values"])
        if not np.array_equal(np.isnan(a), np.isnan(b)):
            found.append(f"{key}: NaN at other places")
            continue
        finite = ~np.isnan(a)
        error = float(np.max(np.abs(a[finite] - b[finite]), initial=0.0))
        if expected["dtype"] == "int":
            allowed = 0.0
        elif sampled and key in SAMPLED:
            allowed = SAMPLING_TOLERANCE[key]
        else:
            allowed = ROUND_OFF * float(np.max(np.abs(a[finite]), initial=0.0))
        if error > allowed:
            found.append(f"{key}: differs by {error:.3g} (allowed {allowed:.3g})")
    return found


@pytest.fixture(scope="module", params=[2, 4])
def report(request, tmp_path_factory):
    out = tmp_path_factory.mktemp(f"ranks{request.param}") / "report.json"
    done = run_mpi([PROBE, str(out)], ranks=request.param, timeout=900)
    assert done.returncode == 0, done.stdout + done.stderr
    return request.param, json.loads(out.read_text())


@pytest.mark.mpi
def test_every_statistic_is_the_serial_statistic(report):
    _, outcome = report
    assert len(outcome["cases"]) == 6
    for name, case in outcome["cases"].items():
        assert case["missing"] == [] and case["extra"] == [], (name, case["missing"], case["extra"])
        assert case["same_on_every_rank"], name
        assert mismatches(case["serial"], case["decomposed"], sampled=name in OVERLAPPING) == [], name


@pytest.mark.mpi
def test_the_reduction_and_the_halo_matter(report):
    """Every rank holds particles (but in the case that rank 0 settles alone), contacts join particles of
    different ranks (a rank alone would miss them), and every statistic is measured in some case (not NaN
    everywhere, so that its comparison counts)."""
    ranks, outcome = report
    cases = outcome["cases"]
    for name, case in cases.items():
        spread = case["particles_per_rank"]
        assert len(spread) == ranks, name
        if name == ALONE:
            assert spread[0] > 0 and not any(spread[1:]), spread
        else:
            assert min(spread) > 0 and case["cross_rank_contacts"] > 0, name
    for key in next(iter(cases.values()))["serial"]:
        if key not in NEVER_MEASURED:
            assert any(np.isfinite(case["serial"][key]["values"]).any() for case in cases.values()), key
    # the overlapping rods' packing is sampled differently, but not far off: still checked to its tolerance
    rods = cases[OVERLAPPING[0]]
    assert mismatches(rods["serial"], rods["decomposed"], sampled=False) != []


@pytest.mark.mpi
def test_the_ranks_choose_the_serial_reference_centres(report):
    _, outcome = report
    assert outcome["reference_selections"] and all(outcome["reference_selections"])


def test_the_comparison_finds_a_difference():
    """Each rule fails on a statistic changed by more than it allows."""
    serial = {"count": {"dtype": "int", "shape": [], "values": [12.0]},
              "mean": {"dtype": "float", "shape": [2], "values": [0.5, float("nan")]},
              "packing_profile": {"dtype": "float", "shape": [2], "values": [0.6, 0.3]}}
    assert mismatches(serial, serial) == [] and mismatches(serial, serial, sampled=True) == []

    def changed(key, values=None, **fields):
        return {**serial, key: {**serial[key], **fields, **({"values": values} if values is not None else {})}}

    assert mismatches(serial, changed("count", [13.0])) != []
    assert mismatches(serial, changed("count", dtype="float")) != []
    assert mismatches(serial, changed("mean", [0.5 * (1 + 1e-9), float("nan")])) != []
    assert mismatches(serial, changed("mean", [0.5, 0.0])) != []
    assert mismatches(serial, changed("packing_profile", [0.6 + 1e-4, 0.3])) != []
    assert mismatches(serial, changed("packing_profile", [0.6 + 1e-4, 0.3]), sampled=True) == []
    assert mismatches(serial, changed("packing_profile", [0.6 + 1e-2, 0.3]), sampled=True) != []
    assert mismatches(serial, {k: v for k, v in serial.items() if k != "mean"}) != []
