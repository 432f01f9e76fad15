"""What a long job does with its own process: torch on one thread, and SIGTERM that stops like Ctrl-C; and
what a supervisor reads of other processes (their children and CPU time, from ``/proc``)."""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import NoReturn


def one_torch_thread() -> None:
    """Run torch on one thread if a learned policy loaded it: small batched networks gain nothing from
    more, and on a shared CPU extra threads make a forward pass 10-100x slower."""
    torch = sys.modules.get("torch")
    if torch is not None:
        torch.set_num_threads(1)


def interrupt(signum: int, frame: object) -> NoReturn:
    """A signal handler that stops the program like Ctrl-C does: by raising :class:`KeyboardInterrupt`."""
    raise KeyboardInterrupt


@contextmanager
def sigterm_stops() -> Iterator[None]:
    """Inside the block, SIGTERM (``kill``, a scheduler, a job's time limit) stops like Ctrl-C.

    Long commands catch :class:`KeyboardInterrupt` to save their finished work and say how to resume; this gives
    ``kill`` the same path. The handler that was there before comes back when the block ends.
    """
    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def live_parents() -> dict[int, int]:
    """PID -> parent PID of every live (not zombie) process, from ``/proc`` (Linux; empty elsewhere)."""
    found: dict[int, int] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):  # the process ended while being read
            continue
        if fields and fields[0] != "Z":
            found[int(stat.parent.name)] = int(fields[1])
    return found


def descendants(pid: int) -> set[int]:
    """The PIDs of every live process below ``pid``: its children, theirs, and so on (Linux)."""
    parents, found, frontier = live_parents(), set[int](), {pid}
    while frontier:
        frontier = {child for child, parent in parents.items() if parent in frontier} - found
        found |= frontier
    return found


def cpu_seconds(pid: int) -> float:
    """CPU time (user + system, s) a running process has used so far, from ``/proc`` (Linux)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
