"""One sediment spread over MPI ranks (parsim.deposition.spread) against the serial deposition.

``tests/scripts/decomposed_deposition_probe.py`` deposits seven small sediments (every shape kind,
periodic and walled boxes, a cylinder, a heap, both floors, glued walls, a species mixture whose
larger particles arrive later, a substrate, a run stopped at the event limit) with
``deposit_decomposed(..., check=True)`` on every rank, and compares each, gathered on rank 0, with
``deposit`` of the same inputs.  Their halos are small, so that particles conflict across blocks
and roll out of their owner's region: the run must settle again and fetch, and still give the
serial sediment bit for bit.  ``check=True`` asserts the invariant that makes it exact on every
committed particle: the sediment its descent read is the one it was settled on.
"""

import json
from pathlib import Path

import pytest

from tests.mpi import error_lines, run_mpi, run_mpi_bounded

REPOSITORY = Path(__file__).resolve().parent.parent
PROBE = str(REPOSITORY / "tests" / "scripts" / "decomposed_deposition_probe.py")


def probe_report(tmp_path, ranks):
    out = tmp_path / f"report{ranks}.json"
    done = run_mpi([PROBE, str(out)], ranks=ranks, timeout=900)
    assert done.returncode == 0, done.stdout + done.stderr
    return json.loads(out.read_text())


@pytest.mark.parametrize("ranks", [2, 4])
def test_the_decomposed_sediment_is_the_serial_sediment_bitwise(tmp_path, ranks):
    report = probe_report(tmp_path, ranks)
    assert len(report) == 7
    for name, case in report.items():
        assert all(case["equal"].values()), (name, case["equal"])
    tally = {key: sum(case["tally"][key] for case in report.values()) for key in ("conflicts", "fetches")}
    assert tally["conflicts"] > 50 and tally["fetches"] > 50, tally  # the hard paths ran
    assert report["event limit"]["stopped_at"] > 0
    split = [case["blocks_with_particles"] for case in report.values()]
    assert max(split) == ranks
    if ranks == 4:  # the heap's drop area is narrower than four halos: it runs whole, on rank 0
        assert report["heap"]["blocks_with_particles"] == 1


def test_a_failure_on_one_rank_ends_every_rank_with_one_line(tmp_path):
    script = tmp_path / "one_rank_fails.py"
    script.write_text(
        "import numpy as np\n"
        "from mpi4py import MPI\n"
        "from parsim.core import sdbd\n"
        "from parsim.deposition.spread import deposit_decomposed\n"
        "comm = MPI.COMM_WORLD\n"
        "n = 50\n"
        "rng = np.random.default_rng(1)\n"
        "deposit_decomposed(comm, np.zeros((1, 3)), np.array([0.5]), np.array([0, 1]), np.zeros(n, dtype=int),\n"
        "                   np.ones(n), np.tile([1.0, 0, 0, 0], (n, 1)), rng.random((n, 2)) * 10, (0, 0), (10, 10),\n"
        "                   sdbd.LATERAL_PERIODIC, sdbd.FLOOR_ROLL, halo=-1.0 if comm.rank == 1 else 2.0)\n")
    done, seconds = run_mpi_bounded([str(script)], bound=120)
    assert done.returncode != 0
    lines = [line for line in error_lines(done.stderr) if "parsim: error" in line]
    assert len(lines) == 1 and "halo must be a finite length > 0" in lines[0] and "rank 1" in lines[0], done.stderr
