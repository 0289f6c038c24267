"""Ctrl-C and a batch system's SIGTERM end a run at once, with one line instead of tracebacks.

Python runs its signal handlers in the main thread between two bytecodes, so a
Ctrl-C would wait for a jitted kernel that runs for minutes.  Instead, the
signal's number is written to a socket (``signal.set_wakeup_fd``) that a
watcher thread reads: it reacts within milliseconds, whatever the main thread
is doing, calls the run's ``on_signal`` (release the lock, say how many tasks
are kept) and ends the process with the shell's status for that signal,
128 + signal number.  Task files are written atomically, so whatever a killed
write left behind is a temporary that the next run removes.

Under ``mpiexec``, Ctrl-C reaches every rank: rank 0 prints the line and exits,
and the launcher ends the other ranks.  MPICH's ``mpiexec`` forwards SIGINT and
SIGTERM but not SIGHUP: it ends at once and its proxies kill the ranks, each in a
session of its own and so never signalled, with nothing a rank can catch; the next
run takes over the lock its rank 0 left (:mod:`parsim.output.lock`: the holder is gone).
"""

import os
import signal
import socket
import threading
from contextlib import contextmanager
from typing import Callable

SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


@contextmanager
def ending_on_signals(on_signal: Callable[[signal.Signals], None]):
    """While the block runs, SIGINT, SIGTERM and SIGHUP call ``on_signal(signal)`` and end the process.

    A signal that the process ignores when the block starts is left ignored.

    Outside the main thread (where Python allows no signal handlers) the block
    runs without this protection.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    receiver, sender = socket.socketpair()
    sender.setblocking(False)
    previous_fd = signal.set_wakeup_fd(sender.fileno(), warn_on_full_buffer=False)
    # A signal ignored on purpose stays ignored: SIGHUP under nohup, SIGINT in a background job of a script.
    watched = [number for number in SIGNALS if signal.getsignal(number) is not signal.SIG_IGN]
    previous_handlers = {number: signal.signal(number, _ignore) for number in watched}
    watcher = threading.Thread(target=_watch, args=(receiver, on_signal), name="parsim-signals", daemon=True)
    watcher.start()
    try:
        yield
    finally:
        for number, handler in previous_handlers.items():
            signal.signal(number, handler)
        signal.set_wakeup_fd(previous_fd)
        sender.close()  # the watcher reads the end of the stream and returns
        watcher.join()
        receiver.close()


def _watch(receiver: socket.socket, on_signal: Callable[[signal.Signals], None]) -> None:
    while True:
        received = receiver.recv(1)
        if not received:
            return  # the run ended normally
        if received[0] in SIGNALS:
            break  # other signals with a Python handler also write their number: not ours to act on
    number = signal.Signals(received[0])
    try:
        on_signal(number)
    finally:
        os._exit(128 + number)


def _ignore(number, frame) -> None:
    """The Python-level handler: nothing to do, the watcher thread has acted already."""
