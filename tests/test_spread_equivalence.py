"""A fixed sample of the randomised equivalence search (``benchmarks/spread_equivalence.py``).

The search draws small random deposition jobs over the keys that change a descent (every shape
kind, size distributions, mixtures and layers, boxes, heaps, cylinders and mesh vessels, floors, wall contacts,
substrates, trial angles) and runs each serially and spread over 2 and 3 ranks
(``deposit_streamed(..., check=True)``): every spread sediment must be the serial one bit for bit,
without overlaps, errors or hangs.
"""

import json
import subprocess
import sys
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parent.parent
SEARCH = REPOSITORY / "benchmarks" / "spread_equivalence.py"
JOBS = 12
SEED = 2027


def test_random_jobs_spread_over_ranks_give_the_serial_sediment(tmp_path):
    report_path = tmp_path / "report.json"
    done = subprocess.run([sys.executable, str(SEARCH), "--jobs", str(JOBS), "--seed", str(SEED), "--ranks", "2", "3",
                           "--timeout", "120", "--work", str(tmp_path / "work"), "--report", str(report_path)],
                          capture_output=True, text=True, timeout=1200)
    assert report_path.exists(), done.stdout + done.stderr
    report = json.loads(report_path.read_text())
    assert not report["serial_errors"], report["serial_errors"]
    for ranks, tally in report["ranks"].items():
        assert tally["run"] == JOBS, (ranks, tally["run"])
        assert tally["split"] >= JOBS // 2, (ranks, tally["split"])  # half of them or more run on several blocks
        assert tally["failed"] == 0, done.stdout
