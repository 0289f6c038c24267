"""The statistics of a sediment spread over MPI ranks (parsim.deposition.spread_statistics) against the
serial statistics of the gathered sediment.

``tests/scripts/decomposed_statistics_probe.py`` runs the deposition solver on 2 and 4 ranks for six
small sediments (spheres in a periodic box wide enough for the ranks' frames to be narrower than it,
rods and smaller spheres between walls, overlapping rods in a cylinder, a heap, spheres of several
sizes on a substrate, and spheres on a substrate that rank 0 settles alone), and lays out a lattice of
touching spheres over the ranks by hand; it compares every statistic of ``measure_decomposed`` with
``measure`` of the gathered sediment. Counts must be equal, floats equal to round-off, also the packing
fraction of particles whose spheres overlap, whose sampled part is drawn from the same points on any
number of ranks.
"""

import json
from pathlib import Path

import numpy as np
import pytest

from tests.mpi import run_mpi

REPOSITORY = Path(__file__).resolve().parent.parent
PROBE = str(REPOSITORY / "tests" / "scripts" / "decomposed_statistics_probe.py")

ROUND_OFF = 1e-12  # relative to the largest magnitude of a statistic's values
LATTICE = "touching lattice, periodic"  # contacts at 1 diameter, an edge of g(r)'s shells
ALONE = "substrate, rank 0 alone"  # the other ranks hold no particle
NEVER_MEASURED = ("species_mesh_volume", "species_mesh_volume_error", "species_mesh_surface_distance")  # no mesh


def mismatches(serial: dict, decomposed: dict) -> list[str]:
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
    assert len(outcome["cases"]) == 7
    for name, case in outcome["cases"].items():
        assert case["missing"] == [] and case["extra"] == [], (name, case["missing"], case["extra"])
        assert case["same_on_every_rank"], name
        assert mismatches(case["serial"], case["decomposed"]) == [], name


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


@pytest.mark.mpi
def test_g_at_the_contact_distance_is_the_serial_g_to_the_bit(report):
    """The lattice's contacts lie at 1 diameter, the edge between two shells: a distance computed from a copy
    moved by the box's period would round to the other side of it. Every shell is the serial one, bit for bit,
    and the two shells about the contact distance hold the contacts."""
    _, outcome = report
    serial, decomposed = (outcome["cases"][LATTICE][side]["radial_distribution"]["values"]
                          for side in ("serial", "decomposed"))
    assert serial == decomposed
    assert serial[19] + serial[20] > 1.0  # 30 shells of 0.05 diameters: 19 ends, 20 starts at 1 diameter


@pytest.mark.mpi
def test_the_ranks_choose_the_serial_reference_centres(report):
    _, outcome = report
    assert outcome["reference_selections"] and all(outcome["reference_selections"])


def test_the_comparison_finds_a_difference():
    """Each rule fails on a statistic changed by more than it allows."""
    serial = {"count": {"dtype": "int", "shape": [], "values": [12.0]},
              "mean": {"dtype": "float", "shape": [2], "values": [0.5, float("nan")]},
              "packing_profile": {"dtype": "float", "shape": [2], "values": [0.6, 0.3]}}
    assert mismatches(serial, serial) == []

    def changed(key, values=None, **fields):
        return {**serial, key: {**serial[key], **fields, **({"values": values} if values is not None else {})}}

    assert mismatches(serial, changed("count", [13.0])) != []
    assert mismatches(serial, changed("count", dtype="float")) != []
    assert mismatches(serial, changed("mean", [0.5 * (1 + 1e-9), float("nan")])) != []
    assert mismatches(serial, changed("mean", [0.5, 0.0])) != []
    assert mismatches(serial, changed("packing_profile", [0.6 * (1 + 1e-11), 0.3])) != []
    assert mismatches(serial, {k: v for k, v in serial.items() if k != "mean"}) != []
