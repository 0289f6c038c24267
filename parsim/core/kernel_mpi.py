"""MPI called from inside jitted kernels: ghost rows and a global maximum without leaving numba.

An iterative solver that leaves its jitted loop at every iteration to exchange ghost rows from
Python pays the interpreter and mpi4py's object layer thousands of times per solve.  Here the
loop calls the MPI library itself: the functions are declared to numba by their C names
(:class:`numba.types.ExternalFunction`) and every handle (communicator, datatype, operation) is
an argument, so the compiled kernels hold no address of this process and stay in numba's
on-disk cache.  Handles are 64-bit integers (MPICH's are 32-bit ints, Open MPI's pointers:
either fits); requests, of the library's own size, lie back to back in 8-byte slots, so that a
kernel is compiled once for one process and for a decomposed run.

This module does not import mpi4py.  The names resolve to the MPI library that mpi4py mapped
into the process (:func:`bind_library`, which the parallel layer calls once it has imported
mpi4py); until then, and in a process without MPI, to stand-ins that fail (return -1), which the
kernels turn into an error.  A kernel first run in a process without the library keeps the
stand-ins for that process.

A *halo* (:class:`Halo`) describes one rank's ghost exchange: communicator, size, the neighbours' ranks,
which owned rows go to each (back to back, delimited by ``send_ptr``), how many ghost rows come
from each (``recv_ptr``, stored from the first ghost row on), buffers (room for every row with its
place in the list, and a count per neighbour), request slots (int64) and the bytes of one
request, statuses,
the handles of MPI_DOUBLE, MPI_MAX and MPI_SUM, and a tally of what was sent
(:func:`parsim.parallel.halo.HaloPlan.kernel_halo` builds it).  :func:`no_halo` is the
one-process halo: the kernels then make no MPI call at all.
"""

import ctypes
from typing import NamedTuple

import numpy as np
from llvmlite import binding as llvm
from numba import types

from parsim.core.jit import jit

#: Tag of the ghost rows exchanged from kernels.
ROWS_TAG = 31

#: Entries of a halo's tally: messages and bytes sent, seconds waiting on ghost rows and on
#: reductions, reductions made.
MESSAGES, BYTES, HALO_SECONDS, REDUCTION_SECONDS, REDUCTIONS = range(5)
N_TALLIES = 5
#: Room for one MPI_Status of any common library (MPICH: 20 bytes, Open MPI: 24), in int32.
STATUS_INTS = 8

_int, _handle, _pointer = ctypes.c_int, ctypes.c_int64, ctypes.c_void_p
#: name -> (ctypes prototype, numba signature) of the MPI functions the kernels call
_FUNCTIONS = {
    "MPI_Isend": (ctypes.CFUNCTYPE(_int, _pointer, _int, _handle, _int, _int, _handle, _pointer),
                  types.int32(types.voidptr, types.int32, types.int64, types.int32, types.int32, types.int64,
                              types.voidptr)),
    "MPI_Irecv": (ctypes.CFUNCTYPE(_int, _pointer, _int, _handle, _int, _int, _handle, _pointer),
                  types.int32(types.voidptr, types.int32, types.int64, types.int32, types.int32, types.int64,
                              types.voidptr)),
    "MPI_Waitall": (ctypes.CFUNCTYPE(_int, _int, _pointer, _pointer), types.int32(types.int32, types.voidptr,
                                                                                 types.voidptr)),
    "MPI_Allreduce": (ctypes.CFUNCTYPE(_int, _pointer, _pointer, _int, _handle, _handle, _handle),
                      types.int32(types.voidptr, types.voidptr, types.int32, types.int64, types.int64, types.int64)),
    "MPI_Wtime": (ctypes.CFUNCTYPE(ctypes.c_double), types.float64()),
    "MPI_Iprobe": (ctypes.CFUNCTYPE(_int, _int, _int, _handle, _pointer, _pointer),
                   types.int32(types.int32, types.int32, types.int64, types.voidptr, types.voidptr)),
    "MPI_Get_count": (ctypes.CFUNCTYPE(_int, _pointer, _handle, _pointer),
                      types.int32(types.voidptr, types.int64, types.voidptr)),
    "MPI_Recv": (ctypes.CFUNCTYPE(_int, _pointer, _int, _handle, _int, _int, _handle, _pointer),
                 types.int32(types.voidptr, types.int32, types.int64, types.int32, types.int32, types.int64,
                             types.voidptr)),
    "MPI_Test": (ctypes.CFUNCTYPE(_int, _pointer, _pointer, _pointer), types.int32(types.voidptr, types.voidptr,
                                                                                 types.voidptr)),
    "MPI_Iallreduce": (ctypes.CFUNCTYPE(_int, _pointer, _pointer, _int, _handle, _handle, _handle, _pointer),
                       types.int32(types.voidptr, types.voidptr, types.int32, types.int64, types.int64, types.int64,
                                   types.voidptr)),
}
_EXTERNAL = {name: types.ExternalFunction(name, signature) for name, (_, signature) in _FUNCTIONS.items()}
_isend, _irecv, _waitall, _allreduce, _wtime = (_EXTERNAL[name] for name in (
    "MPI_Isend", "MPI_Irecv", "MPI_Waitall", "MPI_Allreduce", "MPI_Wtime"))
_iprobe, _get_count, _recv, _test, _iallreduce = (_EXTERNAL[name] for name in (
    "MPI_Iprobe", "MPI_Get_count", "MPI_Recv", "MPI_Test", "MPI_Iallreduce"))


def _stand_in(prototype):
    return prototype(lambda *args: -1 if prototype._restype_ is _int else 0.0)


_STAND_INS = {name: _stand_in(prototype) for name, (prototype, _) in _FUNCTIONS.items()}


def _mapped_library():
    """The path of the MPI library mapped into this process, or None."""
    try:
        with open("/proc/self/maps") as maps:
            for line in maps:
                path = line.split()[-1]
                if "/libmpi" in path and ".so" in path:
                    return path
    except OSError:
        return None
    return None


def bind_library() -> bool:
    """Point the kernels' MPI names at the library mapped into this process (mpi4py's, once it is
    imported); returns whether one was found.  Without one, the names keep their stand-ins."""
    path = _mapped_library()
    if path is None:
        for name, stand_in in _STAND_INS.items():
            llvm.add_symbol(name, ctypes.cast(stand_in, ctypes.c_void_p).value)
        return False
    library = ctypes.CDLL(path)
    for name in _FUNCTIONS:
        llvm.add_symbol(name, ctypes.cast(getattr(library, name), ctypes.c_void_p).value)
    return True


bind_library()


class Halo(NamedTuple):
    """One rank's ghost exchange, as the jitted loops take it (module docstring): the communicator's
    handle and size, the neighbours' ranks, the owned ``rows`` each gets (delimited by ``send_ptr``),
    the ghost rows from each (``recv_ptr``), the ``send`` and ``receive`` buffers, the request slots and
    the bytes of one request, statuses, the handles of MPI_DOUBLE, MPI_MAX and MPI_SUM, and the tally."""

    comm: int
    size: int
    neighbours: np.ndarray
    rows: np.ndarray
    send_ptr: np.ndarray
    recv_ptr: np.ndarray
    send: np.ndarray
    receive: np.ndarray
    request_slots: np.ndarray
    request_bytes: int
    statuses: np.ndarray
    double: int
    maximum: int
    total: int
    tally: np.ndarray


def no_halo():
    """The halo of a problem held whole by one process: no neighbour, no reduction."""
    empty = np.zeros(0, dtype=np.int64)
    return Halo(np.int64(0), np.int64(1), np.zeros(0, dtype=np.int32), empty, np.zeros(1, dtype=np.int64),
                np.zeros(1, dtype=np.int64), np.zeros(0), np.zeros(0), np.zeros(1, dtype=np.int64), np.int64(8),
                np.zeros(STATUS_INTS, dtype=np.int32), np.int64(0), np.int64(0), np.int64(0), np.zeros(N_TALLIES))


@jit(inline="always")
def _address(array, start):
    """The address of ``array[start]``, for the library."""
    return array[start:].ctypes


@jit
def share_changed_rows(values, first_ghost, changed, arrived, halo):
    """Overwrite the ghost rows of ``values`` (2-d, float64, from row ``first_ghost`` on) whose
    owners flagged them ``changed`` (a flag per owned row): each neighbour gets one message, the
    number of its rows that changed, then each of those after its place in the neighbour's list.
    Writes into ``arrived`` the ghost rows (counted from ``first_ghost``) that came; returns how
    many.  Collective among neighbours."""
    _, size, neighbours, rows, send_ptr, recv_ptr, send, receive, _, _, _, _, _, _, _ = halo
    if size == 1 or neighbours.shape[0] == 0:
        return 0
    width = values.shape[1] + 1  # the place, then the row
    for q in range(neighbours.shape[0]):
        start = send_ptr[q] * width + q
        count = 0
        for j in range(send_ptr[q], send_ptr[q + 1]):
            if changed[rows[j]]:
                at = start + 1 + count * width
                send[at] = j - send_ptr[q]
                for k in range(width - 1):
                    send[at + 1 + k] = values[rows[j], k]
                count += 1
        send[start] = count
    _swap(halo, width, True)
    n = 0
    for q in range(neighbours.shape[0]):
        start = recv_ptr[q] * width + q
        if recv_ptr[q + 1] == recv_ptr[q]:
            continue
        for c in range(int(receive[start])):
            at = start + 1 + c * width
            g = recv_ptr[q] + int(receive[at])
            for k in range(width - 1):
                values[first_ghost + g, k] = receive[at + 1 + k]
            arrived[n] = g
            n += 1
    return n


@jit
def share_flags(flags, first_ghost, halo):
    """Overwrite the ghost rows of ``flags`` (a flag per row, from row ``first_ghost`` on) with
    their owners' flags: one message each way per neighbour.  Collective among neighbours."""
    _, size, neighbours, rows, _, recv_ptr, send, receive, _, _, _, _, _, _, _ = halo
    if size == 1 or neighbours.shape[0] == 0:
        return
    for j in range(rows.shape[0]):
        send[j] = 1.0 if flags[rows[j]] else 0.0
    _swap(halo, 1, False)
    for j in range(recv_ptr[-1]):
        flags[first_ghost + j] = receive[j] > 0.5


@jit
def _swap(halo, width, counted):
    """Send each neighbour its part of the packed send buffer and receive its ghost rows (rows of
    ``width`` floats, all of them, or with ``counted`` as many as the part's first float says, the
    parts one float apart); returns when both are done."""
    comm, _, neighbours, _, send_ptr, recv_ptr, send, receive, slots, request_bytes, statuses, double, _, _, \
        tally = halo
    requests = slots.view(np.uint8)  # the library's requests back to back, whatever their size
    started = _wtime()
    n = 0
    failed = 0
    slot = 1 if counted else 0  # the count before each part
    for q in range(neighbours.shape[0]):  # every receive and send posted, then all awaited
        first, last = recv_ptr[q] * width + q * slot, recv_ptr[q + 1] * width + q * slot
        if last > first:
            failed |= _irecv(_address(receive, first), last - first + slot, double, neighbours[q], ROWS_TAG, comm,
                             _address(requests, n * request_bytes))
            n += 1
        first, last = send_ptr[q] * width + q * slot, send_ptr[q + 1] * width + q * slot
        if last > first:
            last = first + 1 + int(send[first]) * width if counted else last
            failed |= _isend(_address(send, first), last - first, double, neighbours[q], ROWS_TAG, comm,
                             _address(requests, n * request_bytes))
            n += 1
            tally[MESSAGES] += 1.0
            tally[BYTES] += 8.0 * (last - first)
    failed |= _waitall(n, requests.ctypes, statuses.ctypes)
    if failed != 0:
        raise RuntimeError("a ghost-row exchange from a jitted kernel failed (is the MPI library bound? "
                           "parsim.core.kernel_mpi.bind_library)")
    tally[HALO_SECONDS] += _wtime() - started


@jit
def global_max(value, halo):
    """The largest ``value`` over the ranks of the halo's communicator.  Collective."""
    if halo.size == 1:  # one process: nothing to allocate in the iteration loop
        return value
    return _reduced(np.full(1, value), halo, False)[0]


@jit
def global_sum(value, halo):
    """The sum of ``value`` over the ranks of the halo's communicator.  Collective."""
    if halo.size == 1:
        return value
    return _reduced(np.full(1, value), halo, True)[0]


@jit
def global_max_array(values, halo):
    """``values`` (float64) maximised element by element over the ranks.  Collective."""
    return _reduced(values, halo, False)


@jit
def _reduced(values, halo, add):
    """``values`` summed (``add``) or maximised element by element over the ranks of the halo."""
    comm, size, _, _, _, _, _, _, _, _, _, double, maximum, total, tally = halo
    if size == 1:
        return values
    started = _wtime()
    mine = np.ascontiguousarray(values).copy()
    result = np.empty_like(mine)
    if _allreduce(mine.ctypes, result.ctypes, mine.shape[0], double, total if add else maximum, comm) != 0:
        raise RuntimeError("a reduction from a jitted kernel failed (is the MPI library bound? "
                           "parsim.core.kernel_mpi.bind_library)")
    tally[REDUCTIONS] += 1.0
    tally[REDUCTION_SECONDS] += _wtime() - started
    return result


# ---------------------------------------------------------------------------------------- messages
# A *link* tuple lets a jitted loop send messages of any length to other ranks, find out whether one
# has arrived and start a reduction, without waiting: communicator, size, the handles of MPI_DOUBLE
# and MPI_MIN, request slots (int64, see above) and the bytes of one request, statuses, a flag, the
# reduction's input and output, and a tally (LINK_* entries).  The parallel layer builds it
# (:func:`parsim.parallel.halo.kernel_link`).

#: Entries of a link's tally: messages and bytes sent, seconds waiting for messages and reductions.
LINK_MESSAGES, LINK_BYTES, LINK_WAIT_SECONDS = range(3)
N_LINK_TALLIES = 3


@jit
def _checked(code):
    if code != 0:
        raise RuntimeError("an MPI call from a jitted kernel failed (is the MPI library bound? "
                           "parsim.core.kernel_mpi.bind_library)")


@jit
def post_send(values, count, destination, tag, link, slot):
    """Start sending ``values[:count]`` (float64) to rank ``destination``; its request takes slot
    ``slot`` of the link, and lives until :func:`wait_slots`, which is given the array ``values``
    views, to keep it alive until then."""
    comm, _, double, _, slots, request_bytes, _, _, _, tally = link
    requests = slots.view(np.uint8)
    _checked(_isend(values.ctypes, count, double, destination, tag, comm,
                    _address(requests, slot * request_bytes)))
    tally[LINK_MESSAGES] += 1.0
    tally[LINK_BYTES] += 8.0 * count


@jit
def arrived_count(source, tag, link):
    """The number of float64 in the next message from ``source`` with ``tag``, or -1 if none has
    arrived yet."""
    comm, _, double, _, _, _, statuses, flag, _, _ = link
    flag[0] = 0
    _checked(_iprobe(source, tag, comm, flag.ctypes, statuses.ctypes))
    if flag[0] == 0:
        return -1
    _checked(_get_count(statuses.ctypes, double, flag.ctypes))
    return np.int64(flag[0])


@jit
def receive_arrived(source, tag, count, link):
    """The message that :func:`arrived_count` found (``count`` float64), as a new array."""
    comm, _, double, _, _, _, statuses, _, _, _ = link
    values = np.empty(max(count, 1))
    _checked(_recv(values.ctypes, count, double, source, tag, comm, statuses.ctypes))
    return values[:count]


@jit
def post_minimum(value, link, slot):
    """Start the minimum of ``value`` over the link's ranks (slot ``slot``); read it with
    :func:`reduced` once :func:`is_done`."""
    comm, _, double, minimum, slots, request_bytes, _, _, reduction, _ = link
    reduction[0] = value
    requests = slots.view(np.uint8)
    _checked(_iallreduce(reduction[0:].ctypes, reduction[1:].ctypes, 1, double, minimum, comm,
                         _address(requests, slot * request_bytes)))


@jit
def reduced(link):
    """The result of the last :func:`post_minimum`."""
    return link[8][1]


@jit
def is_done(link, slot):
    """Whether the request in slot ``slot`` has completed (it is then freed)."""
    _, _, _, _, slots, request_bytes, statuses, flag, _, _ = link
    requests = slots.view(np.uint8)
    flag[0] = 0
    _checked(_test(_address(requests, slot * request_bytes), flag.ctypes, statuses.ctypes))
    return flag[0] != 0


@jit
def wait_slots(link, first, count, sent):
    """Wait for the requests in slots ``first .. first + count - 1``.  ``sent`` is the array their
    sends read: numba frees a local array after its last use in a function, and a send still in
    flight (MPI's rendezvous protocol reads a large message only once the receive is posted) would
    read freed memory; passing it here keeps it alive until they are done."""
    _, _, _, _, slots, request_bytes, statuses, _, _, _ = link
    if count > 0:
        requests = slots.view(np.uint8)
        _checked(_waitall(count, _address(requests, first * request_bytes), statuses.ctypes))


@jit
def now():
    """MPI_Wtime: seconds from an arbitrary origin."""
    return _wtime()
