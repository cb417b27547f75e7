"""One run per file: an exclusive lock on a run file's path, taken before anything else and held to the end.

The lock is an fcntl lock on a file beside the run file, `RUN.h5.lock`, not on the run file itself: the
writer replaces the run file (os.replace) when it grows, resumes and closes, and a lock on the run file would
stay with the replaced inode. The kernel drops the lock when its process ends, however it ends; a lock file
left behind by a killed process is simply taken over by the next run on that file, and one left before its run
file existed (nothing will run on it again) is removed by the next run in its directory (`remove_stale_locks`). The holder removes the lock file when
it is done, and a run that locked a lock file just removed (its inode no longer at the path) tries again.
"""

from __future__ import annotations

import fcntl
import os
import re
from pathlib import Path
from types import TracebackType

from benchlab.errors import InputError


#: The lock files remove_stale_locks looks at: a run file's (RUN.h5.lock), holding the process id of its run.
STALE_LOCK_GLOB = "*.h5.lock"
LOCK_TEXT = re.compile(rb"[0-9]{1,10}\n")


def remove_stale_locks(directory: Path) -> list[Path]:
    """Remove the run-file locks in `directory` that no process holds and whose run file does not exist (a run
    killed by SIGKILL before it made its file leaves one: the kernel dropped its lock, nothing removed the file).
    A lock file that a run holds, or that is not benchlab's (other text), is left. Returns what was removed."""
    removed = []
    for lock_path in directory.glob(STALE_LOCK_GLOB):
        if lock_path.with_name(lock_path.name[:-len(".lock")]).exists():
            continue  # its run file is there: the next run on it takes the lock over and removes it
        try:
            fd = os.open(lock_path, os.O_RDWR)
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            if LOCK_TEXT.fullmatch(os.read(fd, 32)) and os.path.samestat(os.fstat(fd), os.stat(lock_path)):
                lock_path.unlink()  # under its lock: a run that opens it now finds it gone and tries again
                removed.append(lock_path)
        except OSError:  # held by a running run, or gone meanwhile
            pass
        finally:
            os.close(fd)
    return removed


class RunFileLock:
    """`with RunFileLock(path, field):` holds the lock; another holder means bad input (InputError on `field`)."""

    def __init__(self, path: "str | os.PathLike[str]", field: str = "--out") -> None:
        self.path = Path(path)
        self.field = field
        self.lock_path = self.path.with_name(self.path.name + ".lock")
        self._fd: int | None = None

    def acquire(self) -> None:
        """Take the lock now, or raise InputError naming the process that holds it."""
        while self._fd is None:
            try:
                fd = os.open(self.lock_path, os.O_RDWR | os.O_CREAT, 0o644)
            except FileNotFoundError:
                raise InputError(self.path, self.field,
                                 f"a file in an existing directory ({self.path.parent} not found)") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = os.read(fd, 32).decode(errors="replace").strip() or "?"
                os.close(fd)
                raise InputError(self.path, self.field, f"a run file no other run is using (process {holder} "
                                                        f"holds {self.lock_path.name})") from None
            if self._still_at_path(fd):
                os.ftruncate(fd, 0)
                os.write(fd, f"{os.getpid()}\n".encode())
                self._fd = fd
            else:
                os.close(fd)
        remove_stale_locks(self.path.parent)

    def release(self) -> None:
        """Remove the lock file, then drop the lock (in that order: see the module docstring)."""
        if self._fd is None:
            return
        try:
            self.lock_path.unlink()
        except FileNotFoundError:
            pass
        os.close(self._fd)
        self._fd = None

    def _still_at_path(self, fd: int) -> bool:
        try:
            return os.path.samestat(os.fstat(fd), os.stat(self.lock_path))
        except FileNotFoundError:
            return False

    def __enter__(self) -> "RunFileLock":
        self.acquire()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.release()
