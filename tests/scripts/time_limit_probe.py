"""Run the scheduler under a time limit on tasks that turn 50 times slower half-way; rank 0 prints
the seconds until the last rank ended and the number of tasks finished.

usage: time_limit_probe.py LIMIT_SECONDS RESERVE_SECONDS
"""

import sys
import time

from mpi4py import MPI

from parsim.parallel.scheduler import TimeLimit, run_tasks

comm = MPI.COMM_WORLD
costs = [0.001] * 400 + [0.05] * 200  # the short tasks make chunks; the long ones must not ride in one
limit = TimeLimit(float(sys.argv[1]), float(sys.argv[2]))
start = time.monotonic()
finished = []
run_tasks(comm, len(costs), lambda k: time.sleep(costs[k]), time_limit=limit,
          on_finished=lambda k, rank: finished.append(k))
ended = comm.reduce(time.monotonic() - start, op=MPI.MAX)
if comm.Get_rank() == 0:
    print(f"{ended:.3f} {len(finished)}")
