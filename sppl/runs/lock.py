"""One writer per output folder: a lock file that a second process meets with a clear error.

``sppl sample`` (new, ``--resume`` or ``--force``) and ``sppl simulate`` hold their ``--out``
folder's lock for as long as they write in it. The lock is ``fcntl.flock`` on ``.sppl-lock``
in the folder, holding the writer's pid for the message another process gets. The system
releases an flock when its process ends, however it ends, so a lock left by a killed process
is no lock: the next writer takes it over (and the pid in the file is only ever shown while
its process holds the lock, so a pid reused since does not matter). Locks are per folder and
per process: holding a folder again in the process that holds it is a no-op.
"""

from __future__ import annotations

import contextlib
import fcntl
import logging
import os
from collections.abc import Iterator
from pathlib import Path

from ..errors import UsageError

LOCK_FILE = ".sppl-lock"

log = logging.getLogger(__name__)

# The folders this process holds: resolved path -> [lock, depth of nested holds].
_HELD: dict[Path, list] = {}


class FolderInUse(UsageError):
    """Another live process holds the folder's lock."""


class FolderLock:
    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder)
        self.path = self.folder / LOCK_FILE
        self._fd: int | None = None

    def acquire(self) -> FolderLock:
        """Take the lock, or raise ``FolderInUse`` naming the holder's pid. OSError if the
        lock file cannot be made (the caller says why in its own words)."""
        while True:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = _read_pid(fd)
                os.close(fd)
                who = f"pid {holder}" if holder else "a process that has not yet written its pid"
                raise FolderInUse(
                    f"another sppl process ({who}) is writing this folder", path=self.folder,
                    hint="wait for it to finish or stop it, or choose another --out",
                ) from None
            # The holder we waited for may have removed the file as it released it: then this
            # flock is on a file no one else will open, so make and lock the file anew.
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(self.path))
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        stale = _read_pid(fd)
        if stale and stale != os.getpid():
            log.info("%s: the sppl process %s that wrote here has ended; taking the folder over",
                     self.folder, stale)
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self._fd = fd
        return self

    def release(self) -> None:
        if self._fd is None:
            return
        with contextlib.suppress(OSError):
            if os.path.samestat(os.fstat(self._fd), os.stat(self.path)):
                os.unlink(self.path)  # still holding it: no one can have taken it over
        fcntl.flock(self._fd, fcntl.LOCK_UN)
        os.close(self._fd)
        self._fd = None


def _read_pid(fd: int) -> int | None:
    try:
        text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def holder(folder: str | Path) -> int | None:
    """The pid of the live process holding ``folder``'s lock, or None."""
    path = Path(folder) / LOCK_FILE
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return _read_pid(fd) or -1
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)


@contextlib.contextmanager
def hold(folder: str | Path) -> Iterator[None]:
    """Hold ``folder``'s lock (which must exist as a folder) for the block; a no-op where this
    process holds it already."""
    key = Path(folder).resolve()
    if key in _HELD:
        _HELD[key][1] += 1
        try:
            yield
        finally:
            _HELD[key][1] -= 1
        return
    lock = FolderLock(folder).acquire()
    _HELD[key] = [lock, 1]
    try:
        yield
    finally:
        del _HELD[key]
        lock.release()


def held(folder: str | Path) -> bool:
    return Path(folder).resolve() in _HELD
