"""What a long job does with its own process: torch on one thread, and SIGTERM that stops like Ctrl-C."""

from __future__ import annotations

import signal
import sys
from collections.abc import Iterator
from contextlib import contextmanager
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
