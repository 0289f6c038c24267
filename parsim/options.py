"""The command line's value types: each turns one option's text into its value or refuses it.

argparse calls them while it reads the command line, so a refusal is its one-line usage error
naming the option (``parsim: error: argument --out: ...``), before any file is read, any folder
made or any rank started on work.  Paths are refused here only for what no file system takes (an
empty path, a name longer than :data:`NAME_MAX`); where a path leads is checked by the command.
"""

import argparse
import os
import re
from pathlib import Path

#: The longest file name, in bytes, of the file systems parsim runs on (ext4, XFS, Lustre, GPFS, APFS, NTFS).
NAME_MAX = 255
#: The most ranks ``--ranks-per-task`` can name: MPI counts ranks in a C int.
MAX_RANKS = 2**31 - 1
DURATION = re.compile(r"(?:(?P<days>\d+)-)?(?P<hours>\d+):(?P<minutes>\d\d):(?P<seconds>\d\d)")


def path(text: str) -> Path:
    """A path: not empty (which would mean the working folder) and no part longer than NAME_MAX bytes."""
    if not text:
        raise argparse.ArgumentTypeError("an empty path: allowed: a file or folder name")
    longest = max(len(os.fsencode(part)) for part in Path(text).parts)
    if longest > NAME_MAX:
        raise argparse.ArgumentTypeError(f"{_shown(text)}: a name of {longest} bytes; allowed: names of at most "
                                         f"{NAME_MAX} bytes")
    return Path(text)


def target(text: str) -> str:
    """A path a command writes to, kept as typed: a final '/' says it is a folder."""
    path(text)
    return text


def name(text: str) -> str:
    """A name looked up among a folder's files, e.g. a task label: a path's rules, without folders."""
    if "/" in text or os.sep in text:
        raise argparse.ArgumentTypeError(f"{_shown(text)}: allowed: a name without '/'")
    return str(path(text))


def file_to_write(text: str) -> Path:
    """A file a command writes when it ends, checked before it starts: a path, not a folder, in a
    folder that exists and takes files (so that nothing computed is lost for want of it)."""
    given = path(text)
    folder = given.parent
    if given.is_dir() or not folder.is_dir() or not os.access(folder, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(f"{text!r}: allowed: a file in a folder that exists and can be written")
    return given


def ranks(text: str) -> int:
    """A number of ranks without a run to divide (``compile --ranks-per-task``): 1 to MAX_RANKS."""
    if not text.isdigit() or not 1 <= int(text) <= MAX_RANKS:
        raise argparse.ArgumentTypeError(f"{_shown(text)}: allowed: a whole number from 1 to {MAX_RANKS}, e.g. 2")
    return int(text)


def duration(text: str) -> float:
    """Seconds of a batch-system time, [D-]HH:MM:SS (Slurm's form), for --time-limit."""
    match = DURATION.fullmatch(text)
    if match is None or int(match["minutes"]) >= 60 or int(match["seconds"]) >= 60:
        raise argparse.ArgumentTypeError(f"{_shown(text)}: allowed: HH:MM:SS or D-HH:MM:SS, e.g. 23:50:00")
    days, hours, minutes, seconds = (int(match[part] or 0) for part in ("days", "hours", "minutes", "seconds"))
    return ((days * 24 + hours) * 60 + minutes) * 60.0 + seconds


def _shown(text: str) -> str:
    """``text`` quoted for an error line, its middle left out when it is long."""
    return repr(text) if len(text) <= 60 else f"{text[:28]!r}...{text[-28:]!r} ({len(text)} characters)"
