"""What this machine offers a task: its physical memory, and the check of an estimate against it."""

import os
from typing import Callable

from parsim.errors import JobError

BINARY_UNITS = ("B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB", "ZiB", "YiB")


def physical_memory() -> int:
    """This machine's physical memory in bytes."""
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def in_binary_units(n_bytes: float) -> str:
    """``n_bytes`` to three digits in the largest binary unit it reaches, e.g. '23.4 GiB'; a float
    estimate that overflowed (an image of voxels too small to count) is 'inf YiB'."""
    exponent = 0
    while exponent < len(BINARY_UNITS) - 1 and n_bytes >= 1024 ** (exponent + 1):
        exponent += 1
    return f"{n_bytes / 1024**exponent:.3g} {BINARY_UNITS[exponent]}"


def check_memory(need: float, what: str, estimated_from: str, remedy: Callable[[int], str] | None = None) -> None:
    """Refuse ``what`` ("one task", "the dataset") if it needs more than this machine's memory:
    a one-line :class:`JobError` naming the estimate and the keys it grows with (``estimated_from``),
    then what would fit, ``remedy(memory)``, if that is given and says anything."""
    total = physical_memory()
    if need > total:
        advice = remedy(total) if remedy is not None else ""
        raise JobError(f"{what} needs about {in_binary_units(need)} of memory (estimated from {estimated_from}), "
                       f"more than this machine's {in_binary_units(total)}" + (f": {advice}" if advice else ""))
