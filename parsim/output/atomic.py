"""Write a file so that it either exists complete or not at all."""

import os
from contextlib import contextmanager
from pathlib import Path

TEMPORARY_SUFFIX = ".tmp"


@contextmanager
def written_atomically(path: Path):
    """Yield a temporary path beside ``path``; rename it to ``path`` only if the block succeeds.

    A kill at any moment leaves either the previous state or the complete new
    file, never a half-written ``path``; the resume logic can trust every file
    it finds.  Leftover temporaries end in :data:`TEMPORARY_SUFFIX`.
    """
    path = Path(path)
    temporary = path.with_name(f"{path.name}.{os.getpid()}{TEMPORARY_SUFFIX}")
    try:
        yield temporary
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)
