"""What a long job does with its own process: torch on one thread, and SIGTERM that stops like Ctrl-C; and
what a supervisor reads of other processes (their children and CPU time, from ``/proc``)."""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from contextlib import contextmanager
from multiprocessing import get_context
from pathlib import Path
from typing import Any, NoReturn


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


def die_with(driver: int) -> None:
    """Make this process end with ``driver`` (PID), whatever signal ends the driver.

    On Linux the kernel sends this process SIGKILL when its parent dies (``PR_SET_PDEATHSIG``); elsewhere a thread
    polls the parent. Ends at once if the driver died before the watch was set.
    """
    if sys.platform.startswith("linux"):
        import ctypes

        PR_SET_PDEATHSIG = 1
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    else:
        threading.Thread(target=_watch_parent, args=(driver,), daemon=True).start()
    if os.getppid() != driver:
        os._exit(1)


def _watch_parent(driver: int) -> None:
    while os.getppid() == driver:
        time.sleep(0.5)
    os._exit(1)


_worker_stopped = False  # in a worker of stoppable_pool: the driver has stopped it


def _stop_worker(signum: int, frame: object) -> NoReturn:
    """A worker's SIGTERM: interrupt its task like Ctrl-C, and start none of those queued behind it."""
    global _worker_stopped
    _worker_stopped = True
    raise KeyboardInterrupt


def _stoppable_worker_init(driver: int) -> None:
    """A worker of :func:`stoppable_pool`: the driver alone decides when it stops (SIGINT ignored, so a Ctrl-C
    reaches the driver only) and stops it with SIGTERM, which interrupts like Ctrl-C."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _stop_worker)
    die_with(driver)


def _unless_stopped(task: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """Run ``task`` in a worker, unless the driver has stopped the worker: a task already handed to a worker when
    the pool stops (the pool queues one beyond those running) is refused like a stopped one, not started."""
    if _worker_stopped:
        raise KeyboardInterrupt
    return task(*args, **kwargs)


class _StoppablePool(ProcessPoolExecutor):
    """A process pool whose tasks do not start in a worker the driver has stopped."""

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future:
        return super().submit(_unless_stopped, fn, *args, **kwargs)


@contextmanager
def stoppable_pool(workers: int, grace: float = 120.0) -> Iterator[ProcessPoolExecutor]:
    """A pool of ``workers`` spawned processes for long tasks that keep their state when stopped (training runs).

    The workers never outlive this process (:func:`die_with`). An exception in the ``with`` block (Ctrl-C, SIGTERM
    turned into ``KeyboardInterrupt``, an error) cancels the tasks not started, stops the running ones like
    Ctrl-C (SIGTERM: a training run commits its state and ends) and waits up to ``grace`` seconds for them before
    killing what is left; a normal exit waits for every task.
    """
    pool = _StoppablePool(
        max_workers=workers,
        mp_context=get_context("spawn"),
        initializer=_stoppable_worker_init,
        initargs=(os.getpid(),),
    )
    try:
        yield pool
    except BaseException:
        processes = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for process in processes:
            if process.is_alive() and process.pid is not None:
                os.kill(process.pid, signal.SIGTERM)
        deadline = time.monotonic() + grace
        for process in processes:
            process.join(max(0.0, deadline - time.monotonic()))
            if process.is_alive():
                process.kill()
        pool.shutdown(wait=True)
        raise
    pool.shutdown(wait=True)
