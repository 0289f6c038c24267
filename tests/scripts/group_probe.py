"""Run the group scheduler on synthetic tasks; each rank writes "task rank group_rank group_size" lines to OUT.rank.

usage: group_probe.py OUT RANKS_PER_TASK N_TASKS [FAILING_TASK FAILING_GROUP_RANK]
"""

import sys
import time

from mpi4py import MPI

from parsim.parallel.scheduler import run_group_tasks

out, ranks_per_task, n_tasks = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
failing = (int(sys.argv[4]), int(sys.argv[5])) if len(sys.argv) > 4 else None
comm = MPI.COMM_WORLD
records = []


def work(k, group):
    if (k, group.Get_rank()) == failing:
        raise ValueError(f"synthetic failure in task {k}")
    group.Barrier()  # every rank of the group is in the task together, as a decomposed solver would be
    records.append(f"{k} {comm.Get_rank()} {group.Get_rank()} {group.Get_size()}")
    if failing is not None:
        time.sleep(30.0)  # the failing task must end the job, not wait for this one


run_group_tasks(comm, ranks_per_task, n_tasks, work)
with open(f"{out}.{comm.Get_rank()}", "w") as file:
    file.write("\n".join(records))
