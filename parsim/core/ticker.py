"""A function called at regular intervals from a thread while a block of code runs (a jitted kernel
releases the GIL, so the thread runs beside it)."""

import contextlib
import threading


@contextlib.contextmanager
def ticking(seconds: float, tick, name: str = "parsim-ticker"):
    """Within the block, call ``tick()`` every ``seconds`` from a thread; it stops with the block."""
    done = threading.Event()

    def run():
        while not done.wait(seconds):
            tick()

    thread = threading.Thread(target=run, name=name, daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join()
