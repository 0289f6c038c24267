"""Messages sent from a jitted function out of an array it allocated itself, large enough for MPI's
rendezvous protocol (the library reads the buffer only once the receive is posted), arrive intact
on every rank of ``mpiexec -n K``: the array must live until the send is done.  Writes a JSON
report (rank 0) to ``argv[1]``."""

import json
import sys

import numpy as np
from mpi4py import MPI

from parsim.core import kernel_mpi
from parsim.core.jit import jit
from parsim.parallel.halo import kernel_link

TAG = 7
VALUES = 1 << 20  # 8 MB: far above any eager threshold


@jit
def _pattern(rank, round_, n):
    values = np.empty(n)
    for i in range(n):
        values[i] = rank * 1e7 + round_ * 1e6 + i
    return values


@jit
def exchange_round(rank, round_, n, destination, source, link):
    """Send a fresh array to ``destination``, receive one from ``source`` while other arrays are made
    and dropped (reusing freed memory), then wait; returns how many received values are wrong."""
    send = _pattern(rank, round_, n)
    kernel_mpi.post_send(send, n, destination, TAG, link, 0)
    count = -1
    while count < 0:
        scratch = np.full(n, -1.0)  # the allocator hands out freed memory first
        scratch[0] = 0.0
        count = kernel_mpi.arrived_count(source, TAG, link)
    received = kernel_mpi.receive_arrived(source, TAG, count, link)
    kernel_mpi.wait_slots(link, 0, 1, send)
    wrong = 0 if count == n else n
    expected = _pattern(source, round_, n)
    for i in range(min(count, n)):
        wrong += received[i] != expected[i]
    return wrong


def main(report_path):
    comm = MPI.COMM_WORLD
    rank, size = comm.Get_rank(), comm.Get_size()
    link = kernel_link(comm, 1)
    wrong = [int(exchange_round(rank, r, VALUES, (rank + 1) % size, (rank - 1) % size, link)) for r in range(4)]
    everyone = comm.gather(wrong, root=0)
    if rank == 0:
        with open(report_path, "w") as out:
            json.dump({"wrong": everyone, "values": VALUES}, out)


if __name__ == "__main__":
    main(sys.argv[1])
