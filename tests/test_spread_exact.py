"""One sediment spread over ranks is the serial one on the jobs where it once was not, whatever the
timing of the messages.

Each file of ``tests/spread_cases`` is a job on which the spread deposition once differed from the
serial one, overlapped at a block border, crashed, or failed its own check; its header says how.
``benchmarks/spread_equivalence.py`` runs each serially and spread over 2 and 3 ranks (3 on two
cores: oversubscribed) with ``deposit_streamed(..., check=True)`` and random delays before every
message and at every look at the messages, and compares every field bitwise with the serial
sediment; a second run with other delays must give it again.  The kernels' messages themselves
are checked with arrays large enough for MPI's rendezvous protocol.
"""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.mpi import run_mpi

REPOSITORY = Path(__file__).resolve().parent.parent
SEARCH = REPOSITORY / "benchmarks" / "spread_equivalence.py"
CASES = sorted((REPOSITORY / "tests" / "spread_cases").glob("*.toml"))
SEND_PROBE = str(REPOSITORY / "tests" / "scripts" / "kernel_send_probe.py")


def run_cases(tmp_path, ranks, jitter):
    report_path = tmp_path / "report.json"
    done = subprocess.run([sys.executable, str(SEARCH), "--one", *map(str, CASES), "--ranks", *map(str, ranks),
                           "--jitter", str(jitter), "--timeout", "300", "--work", str(tmp_path / "work"),
                           "--report", str(report_path)], capture_output=True, text=True, timeout=1800,
                          cwd=REPOSITORY)
    assert report_path.exists(), done.stdout + done.stderr
    return json.loads(report_path.read_text()), done.stdout


def assert_serial_everywhere(report, output, ranks):
    assert not report["serial_errors"], report["serial_errors"]
    for k in ranks:
        tally = report["ranks"][str(k)]
        assert tally["run"] == len(CASES), (k, tally)
        assert tally["failed"] == 0, output
    assert report["ranks"]["2"]["split"] == len(CASES)  # every case really ran on two blocks


def test_the_regression_cases_give_the_serial_sediment_with_random_delays(tmp_path):
    assert len(CASES) >= 8
    report, output = run_cases(tmp_path, [2, 3], jitter=2e-5)
    assert_serial_everywhere(report, output, [2, 3])


def test_another_run_with_other_delays_gives_the_same_sediment_again(tmp_path):
    report, output = run_cases(tmp_path, [2], jitter=1e-4)
    assert_serial_everywhere(report, output, [2])


@pytest.mark.parametrize("ranks", [2, 3])
def test_large_messages_sent_from_a_kernel_arrive_intact(tmp_path, ranks):
    out = tmp_path / "sends.json"
    done = run_mpi([SEND_PROBE, str(out)], ranks=ranks, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    report = json.loads(out.read_text())
    assert report["values"] >= 1 << 20
    assert report["wrong"] == [[0, 0, 0, 0]] * ranks
