"""One run per output folder at a time.

``parsim run`` takes the lock file ``<output>/parsim.lock`` before it touches
anything else in the folder, and removes it when it ends.  The file says who
holds it (host, process, the process's start time, the run's start) and the
holder refreshes its modification time every :data:`HEARTBEAT_SECONDS`.  A
second run is refused at once, with the holder named.  A run that was killed
cannot remove its lock, so a lock is taken over when its holder is known to be
gone:

- on the same host, when no process with the holder's PID exists, or one
  exists that started at another time (the PID was reused);
- on another host, when its heartbeat is older than :data:`STALE_SECONDS`
  (the only test possible for a holder on another node of a cluster).

The lock is written complete to a file of its own and then hard-linked to
``parsim.lock``: the link is atomic on local and network file systems alike,
and a lock file is never seen half-written.  A stale lock is moved aside and
removed only if it is still the very file (device and inode) judged stale.
"""

import datetime
import json
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


@dataclass(frozen=True)
class Holder:
    """Who holds a lock, as its file says; ``process_start`` is 0 where the system does not tell it."""

    host: str
    pid: int
    process_start: int
    started: str

    def describe(self) -> str:
        return f"process {self.pid} on host {self.host}, started {self.started}"


class FolderLock:
    """The lock of one output folder; :meth:`acquire` it before writing, :meth:`release` it at the end."""

    def __init__(self, root: Path):
        self.root = Path(root)
        self.path = self.root / LOCK_NAME
        self._me = Holder(socket.gethostname(), os.getpid(), _process_start(os.getpid()),
                          datetime.datetime.now().astimezone().isoformat(timespec="seconds"))
        self._stop = threading.Event()
        self._heartbeat: threading.Thread | None = None
        self._identity: tuple[int, int] | None = None  # (device, inode) of the lock file while held

    def acquire(self) -> None:
        """Take the lock, taking over a stale one; a live holder is a :class:`JobError` naming it."""
        mine = self.path.with_name(f"{LOCK_NAME}.{self._me.host}.{self._me.pid}")
        _write_holder(mine, self._me)
        try:
            for _ in range(3):  # a stale lock moved aside, another run may still win the race to link
                try:
                    os.link(mine, self.path)
                except FileExistsError:
                    self._take_over_if_stale()
                    continue
                except OSError as error:
                    raise OutputError.from_os_error(error, self.path) from None
                self._identity = _identity(self.path)
                self._heartbeat = threading.Thread(target=self._beat, name="parsim-lock-heartbeat", daemon=True)
                self._heartbeat.start()
                return
        finally:
            mine.unlink(missing_ok=True)
        raise JobError(f"output folder {self.root}: could not take its lock {self.path}, another run keeps "
                       f"taking it; give another output folder")

    def release(self) -> None:
        """Stop the heartbeat and remove the lock file, if this process still holds it."""
        if self._heartbeat is None:
            return
        self._stop.set()
        self._heartbeat = None
        if _identity(self.path) == self._identity:
            self.path.unlink(missing_ok=True)

    def _take_over_if_stale(self) -> None:
        identity, holder, age = _identity(self.path), read_holder(self.path), _age(self.path)
        if identity is None or age is None:
            return  # released between our attempt and this look: try again
        if holder is not None and not self._is_gone(holder, age):
            raise JobError(f"output folder {self.root} is in use by another parsim run ({holder.describe()}); "
                           f"wait for it to finish or give another output folder{self._when_taken_over(holder)}")
        _remove_if_same(self.path, identity)

    def _when_taken_over(self, holder: Holder) -> str:
        """How a dead holder's lock goes, for the refusal: on this host the holder is known to live; on
        another, only its heartbeat tells, so a run that died there still holds the lock for a while."""
        if holder.host == self._me.host:
            return ""
        return (f" (if that run is dead, the next run takes its lock over {STALE_SECONDS:.0f} s after its last "
                "refresh)")

    def _is_gone(self, holder: Holder, age: float) -> bool:
        if holder.host != self._me.host:
            return age > STALE_SECONDS
        if not _process_exists(holder.pid):
            return True
        return holder.process_start != 0 and _process_start(holder.pid) not in (0, holder.process_start)

    def _beat(self) -> None:
        while not self._stop.wait(HEARTBEAT_SECONDS):
            if _identity(self.path) != self._identity:
                return  # the lock was removed by hand: nothing of ours to refresh
            try:
                os.utime(self.path)
            except OSError:
                pass  # the folder went away; the run itself will report what it cannot write


def _write_holder(path: Path, holder: Holder) -> None:
    text = (f"host = {json.dumps(holder.host)}\npid = {holder.pid}\nprocess_start = {holder.process_start}\n"
            f"started = {json.dumps(holder.started)}\ncommand = {json.dumps(' '.join(sys.argv))}\n")
    try:
        path.write_text(text)
    except OSError as error:
        path.unlink(missing_ok=True)
        raise OutputError.from_os_error(error, path.with_name(LOCK_NAME)) from None


def read_holder(path: Path) -> Holder | None:
    """The holder a lock file names; None if it is missing or not a lock file of parsim."""
    try:
        record = tomllib.loads(path.read_text())
        return Holder(str(record["host"]), int(record["pid"]), int(record.get("process_start", 0)),
                      str(record["started"]))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, KeyError, ValueError):
        return None


def _identity(path: Path) -> tuple[int, int] | None:
    try:
        status = path.stat()
    except FileNotFoundError:
        return None
    return status.st_dev, status.st_ino


def _age(path: Path) -> float | None:
    try:
        return time.time() - path.stat().st_mtime
    except FileNotFoundError:
        return None


def _remove_if_same(path: Path, identity: tuple[int, int]) -> None:
    """Remove the stale lock ``path``, unless another run replaced it since it was judged stale."""
    aside = path.with_name(f"{path.name}.stale.{socket.gethostname()}.{os.getpid()}")
    try:
        os.rename(path, aside)
    except FileNotFoundError:
        return  # another run removed it first
    if _identity(aside) != identity:  # a fresh lock of another run: put it back, unless a third one is there
        try:
            os.link(aside, path)
        except FileExistsError:
            pass
    aside.unlink(missing_ok=True)


def _process_exists(pid: int) -> bool:
    """Whether process ``pid`` runs; a zombie (killed, not yet reaped by its parent) does not."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass  # a process of another user
    return _proc_stat(pid)[:1] != ["Z"]


def _process_start(pid: int) -> int:
    """When process ``pid`` started, in clock ticks since boot (Linux); 0 where the system does not say."""
    fields = _proc_stat(pid)
    return int(fields[19]) if len(fields) > 19 else 0  # field 22 of /proc/PID/stat


def _proc_stat(pid: int) -> list[str]:
    """The fields of /proc/PID/stat from the third (the state) on; empty where there is no such file."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return []
