"""This machine's MPI latency and bandwidth, for the benchmarks' models of larger runs."""

import time

import numpy as np


def ping_pong(comm, size, repeats=200):
    """Seconds for one message of ``size`` bytes between ranks 0 and 1 (half a round trip), as
    mpi4py sends it from Python."""
    data = np.zeros(max(size, 1), dtype=np.uint8)
    comm.Barrier()
    start = time.perf_counter()
    for _ in range(repeats):
        if comm.rank == 0:
            comm.Send(data, dest=1)
            comm.Recv(data, source=1)
        elif comm.rank == 1:
            comm.Recv(data, source=0)
            comm.Send(data, dest=0)
    return (time.perf_counter() - start) / (2 * repeats)


def latency_and_bandwidth(comm):
    """``(seconds per small message, bytes per second)`` between ranks 0 and 1."""
    return ping_pong(comm, 8), 4_000_000 / ping_pong(comm, 4_000_000, repeats=20)
