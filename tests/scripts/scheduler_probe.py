"""Run the scheduler on synthetic tasks; every rank appends 'task rank start end' lines to OUT.rank.

usage: scheduler_probe.py OUT COSTS_COMMA_SEPARATED [FAILING_TASK]
"""

import sys
import time

from mpi4py import MPI

from parsim.parallel.scheduler import run_tasks

out, costs = sys.argv[1], [float(c) for c in sys.argv[2].split(",")]
failing = int(sys.argv[3]) if len(sys.argv) > 3 else -1
comm = MPI.COMM_WORLD
records = []
finished_on_root = []


def work(k):
    start = time.perf_counter()
    if k == failing:
        raise ValueError(f"synthetic failure in task {k}")
    time.sleep(costs[k])
    records.append(f"{k} {comm.Get_rank()} {start} {time.perf_counter()}")


run_tasks(comm, len(costs), work, on_finished=lambda k, rank: finished_on_root.append((k, rank)))
with open(f"{out}.{comm.Get_rank()}", "w") as file:
    file.write("\n".join(records))
if comm.Get_rank() == 0:
    assert sorted(k for k, _ in finished_on_root) == list(range(len(costs))), finished_on_root
