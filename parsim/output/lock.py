"""One run per output folder at a time.

``parsim run`` takes the lock file ``<output>/parsim.lock`` before it touches
anything else in the folder, and removes it when it ends.  The file says who
holds it (host, process, start time) and the holder refreshes its modification
time every :data:`HEARTBEAT_SECONDS`.  A second run is refused at once, with
the holder named.  A run that was killed cannot remove its lock, so a lock is
taken over when its holder is known to be gone:

- on the same host, when no process with the holder's PID exists;
- on any host, when its heartbeat is older than :data:`STALE_SECONDS` (the
  only test possible for a holder on another node of a cluster).

The lock file is created with ``O_EXCL``, which is atomic on local and network
file systems alike.
"""

import datetime
import os
import socket
import sys
import threading
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

from parsim.errors import JobError, OutputError

LOCK_NAME = "parsim.lock"
HEARTBEAT_SECONDS = 15.0
STALE_SECONDS = 120.0  # eight missed heartbeats: the holder is gone, not merely busy
UNWRITTEN_SECONDS = 5.0  # a lock file still empty after this long was left by a process killed while taking it


@dataclass(frozen=True)
class Holder:
    """Who holds a lock, as its file says."""

    host: str
    pid: int
    started: str

    def describe(self) -> str:
        return f"process {self.pid} on host {self.host}, started {self.started}"


class FolderLock:
    """The lock of one output folder; :meth:`acquire` it before writing, :meth:`release` it at the end."""

    def __init__(self, root: Path):
        self.root = Path(root)
        self.path = self.root / LOCK_NAME
        self._me = Holder(socket.gethostname(), os.getpid(),
                          datetime.datetime.now().astimezone().isoformat(timespec="seconds"))
        self._stop = threading.Event()
        self._heartbeat: threading.Thread | None = None

    def acquire(self) -> None:
        """Take the lock, taking over a stale one; a live holder is a :class:`JobError` naming it."""
        for _ in range(3):  # a stale lock removed, then another run may still win the race to create it
            try:
                descriptor = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                self._take_over_if_stale()
                continue
            except OSError as error:
                raise OutputError.from_os_error(error, self.path) from None
            self._write_holder(descriptor)
            self._heartbeat = threading.Thread(target=self._beat, name="parsim-lock-heartbeat", daemon=True)
            self._heartbeat.start()
            return
        raise JobError(f"output folder {self.root}: could not take its lock {self.path}, another run keeps "
                       f"taking it; give another output folder")

    def release(self) -> None:
        """Stop the heartbeat and remove the lock file, if this process holds it."""
        if self._heartbeat is None:
            return
        self._stop.set()
        self._heartbeat = None
        if _read_holder(self.path) == self._me:
            self.path.unlink(missing_ok=True)

    def _write_holder(self, descriptor: int) -> None:
        text = f'host = "{self._me.host}"\npid = {self._me.pid}\nstarted = "{self._me.started}"\n' \
               f'command = {_toml_string(" ".join(sys.argv))}\n'
        try:
            with os.fdopen(descriptor, "w") as file:
                file.write(text)
        except OSError as error:
            self.path.unlink(missing_ok=True)
            raise OutputError.from_os_error(error, self.path) from None

    def _take_over_if_stale(self) -> None:
        holder = _read_holder(self.path)
        age = _age(self.path)
        if age is None:
            return  # released between our attempt and this look: try again
        if holder is None:
            if age < UNWRITTEN_SECONDS:
                time.sleep(UNWRITTEN_SECONDS - age)  # another run is writing it: look again
                return
        elif not self._is_gone(holder, age):
            raise JobError(f"output folder {self.root} is in use by another parsim run ({holder.describe()}); "
                           f"wait for it to finish or give another output folder; if that run is dead, "
                           f"remove {self.path}")
        _remove_if_unchanged(self.path, holder)

    def _is_gone(self, holder: Holder, age: float) -> bool:
        if age > STALE_SECONDS:
            return True
        return holder.host == self._me.host and not _process_exists(holder.pid)

    def _beat(self) -> None:
        while not self._stop.wait(HEARTBEAT_SECONDS):
            try:
                os.utime(self.path)
            except OSError:
                pass  # the folder went away; the run itself will report what it cannot write


def _read_holder(path: Path) -> Holder | None:
    """The holder a lock file names; None if it is missing, empty or not a lock file of parsim."""
    try:
        record = tomllib.loads(path.read_text())
        return Holder(str(record["host"]), int(record["pid"]), str(record["started"]))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, KeyError, ValueError):
        return None


def _age(path: Path) -> float | None:
    try:
        return time.time() - path.stat().st_mtime
    except FileNotFoundError:
        return None


def _remove_if_unchanged(path: Path, holder: Holder | None) -> None:
    """Remove a stale lock, unless another run replaced it since it was judged stale."""
    aside = path.with_name(f"{path.name}.stale.{os.getpid()}")
    try:
        os.rename(path, aside)
    except FileNotFoundError:
        return  # another run removed it first
    if _read_holder(aside) == holder:
        aside.unlink()
    else:  # a fresh lock of another run: put it back
        os.rename(aside, path)


def _process_exists(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # a process of another user
    return True


def _toml_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'
