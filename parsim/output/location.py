"""Is a path somewhere a job can put its outputs?  Checked before anything is computed."""

import os
import tempfile
from pathlib import Path

from parsim.errors import JobError


JOB_OUTPUT_REMEDY = "give another output folder (key 'output' or option --output)"


def check_output_location(path: Path, role: str = "output", remedy: str = JOB_OUTPUT_REMEDY) -> None:
    """Raise a :class:`JobError` unless ``path`` is a folder, or can be made one, that this process can write in.

    The nearest existing ancestor of ``path`` (``path`` itself if it exists)
    must be a folder, and a file can be created in it: this catches a path
    that is a regular file or lies below one, a read-only file system and a
    folder without write permission.  Nothing is left behind: the probe file
    is removed and no folder is created.  The error starts with ``role`` and
    the path, and ends with ``remedy``.
    """
    path = Path(path)
    existing = _nearest_existing(path)
    if not os.path.isdir(existing):
        what = f"{path} is a file" if existing == path else f"{existing} is a file, so {path} cannot be a folder"
        raise JobError(f"{role} {path}: {what}; {remedy}")
    try:
        descriptor, probe = tempfile.mkstemp(prefix=".parsim-probe-", dir=existing)
    except OSError as error:
        raise JobError(f"{role} {path}: {existing} is not writable ({error.strerror}); {remedy}") from None
    os.close(descriptor)
    os.unlink(probe)


def _nearest_existing(path: Path) -> Path:
    """``path`` or its nearest ancestor that exists (the working directory for a relative path).

    ``os.path.exists`` rather than ``Path.exists``: a folder that cannot be searched counts as
    absent here (and its parent then as not writable) instead of raising.
    """
    candidate = path
    while not os.path.exists(candidate) and candidate.parent != candidate:
        candidate = candidate.parent
    return candidate if os.path.exists(candidate) else Path.cwd()
