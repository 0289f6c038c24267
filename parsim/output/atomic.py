"""Write a file so that it either exists complete or not at all."""

import os
from contextlib import contextmanager
from pathlib import Path

from parsim.errors import OutputError

TEMPORARY_SUFFIX = ".tmp"


@contextmanager
def written_atomically(path: Path):
    """Yield a temporary path beside ``path``; rename it to ``path`` only if the block succeeds.

    A kill at any moment leaves either the previous state or the complete new
    file, never a half-written ``path``; the resume logic can trust every file
    it finds.  Leftover temporaries end in :data:`TEMPORARY_SUFFIX`.  An
    ``OSError`` of the block or of the rename (a full disk, a missing folder)
    becomes an :class:`OutputError` naming ``path``.
    """
    path = Path(path)
    temporary = path.with_name(f"{path.name}.{os.getpid()}{TEMPORARY_SUFFIX}")
    try:
        yield temporary
        os.replace(temporary, path)
    except OSError as error:
        raise OutputError.from_os_error(error, path) from None
    finally:
        try:
            temporary.unlink(missing_ok=True)
        except OSError:
            pass  # the folder itself is gone or unreadable: the error above says so


@contextmanager
def opened_atomically(path: Path):
    """Yield a binary file open for writing that becomes ``path`` only if the block succeeds, as
    :func:`written_atomically`; it is on the disk (flushed, fsynced) before it is renamed."""
    with written_atomically(path) as temporary:
        with open(temporary, "wb") as file:
            yield file
            file.flush()
            os.fsync(file.fileno())


def write_bytes_atomically(path: Path, data: bytes | memoryview) -> None:
    """Write ``data`` to ``path`` atomically, as :func:`written_atomically`.

    Files made by a library in memory (HDF5, netCDF) are written to disk by
    this function, so that a full disk is reported by the operating system's
    own error, never half-way through the library's writes.
    """
    with opened_atomically(path) as file:
        file.write(data)
