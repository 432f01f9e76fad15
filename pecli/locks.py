"""Folder locks: one writer at a time for a run folder or a tournament's output folder.

A writer holds an OS file lock (``fcntl.flock``) on ``<folder>/.pecli.lock``. The operating system
drops it when the process ends, however it ends (Ctrl-C, SIGKILL, the OOM killer), so a lock is never
stale. A second writer is refused in one line that names the folder and the PID written in the
lock file. Within one process the lock is re-entrant: taking it again counts, and it is released
when every taker has released it.

    with locked(Path("zoo/run"), "run 'run'"):
        ...                                   # another process taking it raises FolderLocked

Where ``fcntl`` is missing (Windows) locking is skipped. Network file systems may not honour
``flock``: share a zoo for reading, write it from one machine.
"""

from __future__ import annotations

import errno
import os
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from pecli.errors import PecliError

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]

LOCK_FILE = ".pecli.lock"

_held: dict[Path, list[int]] = {}  # folder (resolved) -> [file descriptor, takers]


class FolderLocked(PecliError):
    """Another process is writing the folder."""


def process_alive(pid: int) -> bool:
    """Whether process ``pid`` of this machine runs (someone else's counts: it cannot be signalled, but it is there)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def holder(folder: Path) -> int | None:
    """The PID recorded by the process that holds (or last held) ``folder``'s lock, if readable."""
    path = folder / LOCK_FILE
    try:
        if path.is_symlink() or path.stat().st_size > 64:
            return None
        return int(path.read_text().strip())
    except (OSError, ValueError):
        return None


def acquire(folder: str | Path, what: str) -> None:
    """Take ``folder``'s lock (the folder must exist); :class:`FolderLocked` if another process holds it.

    ``what`` names the folder in the refusal, e.g. ``"run 'k5'"`` or ``"tournament output"``.
    """
    key = Path(folder).resolve()
    if key in _held:
        _held[key][1] += 1
        return
    if fcntl is None:
        _held[key] = [-1, 1]
        return
    try:  # never through a link: a lock file linked elsewhere would empty that file
        fd = os.open(key / LOCK_FILE, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK, 0o644)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise PecliError(
                f"{key / LOCK_FILE} is a symbolic link: pecli writes no lock through a link (delete it)"
            ) from None
        raise
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise PecliError(f"{key / LOCK_FILE} is not a regular file: delete it")
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        pid = holder(key)
        by = f"process {pid}" if pid is not None else "another process"
        raise FolderLocked(
            f"{what} ({folder}) is being written by {by}: wait for it to end, or stop it (one writer at a time)"
        ) from None
    except OSError:
        os.close(fd)
        raise
    os.ftruncate(fd, 0)
    os.write(fd, f"{os.getpid()}\n".encode())
    _held[key] = [fd, 1]


def release(folder: str | Path) -> None:
    """Give back one take of ``folder``'s lock; the last one unlocks it. Releasing a lock not held does nothing."""
    key = Path(folder).resolve()
    entry = _held.get(key)
    if entry is None:
        return
    entry[1] -= 1
    if entry[1] > 0:
        return
    del _held[key]
    if entry[0] >= 0:
        os.close(entry[0])  # closing the descriptor drops the flock


@contextmanager
def locked(folder: str | Path, what: str) -> Iterator[None]:
    """Hold ``folder``'s lock for the ``with`` block (see :func:`acquire`)."""
    acquire(folder, what)
    try:
        yield
    finally:
        release(folder)
