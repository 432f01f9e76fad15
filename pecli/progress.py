"""Progress of long work: a Rich bar with an ETA on a terminal, a plain line every ``every`` seconds elsewhere.

    with WorkProgress("pairings", total=len(pairings), console=err_console) as progress:
        for done, pairing in enumerate(pairings, start=1):
            ...
            progress.update(done, note=f"{pursuer} vs {evader}")

Output that goes to a log file or CI (no terminal) gets lines such as
``pairings: 12/40 (30%), 2 min elapsed, about 5 min left``; :class:`PeriodicLines` makes them and is what
training callbacks use directly.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from types import TracebackType

from rich.console import Console
from rich.markup import escape
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from pecli.text import duration

LOG_EVERY = 30.0
"""Seconds between two plain progress lines where no terminal shows a bar."""


class PeriodicLines:
    """Plain progress lines, at most one every ``every`` seconds of ``clock``: done of total, share, time elapsed,
    an ETA from the rate since the start, and ``details()`` (e.g. the CPU time spent).

    Args:
        label: what is being done, the start of each line.
        total: the amount of work (steps, pairings, iterations).
        report: where a line goes (``print``, a console's ``print``).
        unit: the work's unit, after the counts (``steps``); empty for none.
        every: seconds between two lines.
        clock: seconds (wall time by default); tests give a fake one.
        details: more text for each line, e.g. ``lambda: cpu_time(spent, budget)``.
        start: work already done before this process started (a resumed run): not counted in the rate.
    """

    def __init__(
        self,
        label: str,
        total: float,
        report: Callable[[str], None],
        unit: str = "",
        every: float = LOG_EVERY,
        clock: Callable[[], float] = time.monotonic,
        details: Callable[[], str] | None = None,
        start: float = 0.0,
    ) -> None:
        self.label, self.total, self.report, self.unit = label, total, report, unit
        self.every, self.clock, self.details = every, clock, details
        self.start = start
        self.started = self.last = clock()

    def skip(self, amount: float) -> None:
        """Count ``amount`` of work as done without time (pairings found in a cache): the ETA leaves it out."""
        self.start += amount

    def update(self, done: float) -> bool:
        """Note that ``done`` of the work is done; reports a line if ``every`` seconds passed since the last one
        (returns whether it did)."""
        now = self.clock()
        if now - self.last < self.every:
            return False
        self.last = now
        self.report(self.line(done, now))
        return True

    def line(self, done: float, now: float | None = None) -> str:
        """The progress line for ``done`` of the work at time ``now`` (the clock's by default)."""
        now = self.clock() if now is None else now
        elapsed = now - self.started
        unit = f" {self.unit}" if self.unit else ""
        share = f" ({100 * done / self.total:.0f}%)" if self.total > 0 else ""
        parts = [f"{done:,.0f}/{self.total:,.0f}{unit}{share}"]
        if self.details is not None and (text := self.details()):
            parts.append(text)
        parts.append(f"{duration(elapsed)} elapsed")
        rate = (done - self.start) / elapsed if elapsed > 0 else 0.0
        if 0 < rate and done < self.total:
            parts.append(f"about {duration((self.total - done) / rate)} left")
        return f"{self.label}: " + ", ".join(parts)


class WorkProgress:
    """A context manager showing the progress of ``total`` units of work on ``console``: a Rich bar (done/total,
    the last ``note``, time elapsed and left) on a terminal, else :class:`PeriodicLines`; nothing if not
    ``enabled`` (``--json``, ``--quiet``)."""

    def __init__(
        self,
        label: str,
        total: float,
        console: Console,
        unit: str = "",
        enabled: bool = True,
        every: float = LOG_EVERY,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.label, self.total, self.console, self.unit = label, total, console, unit
        self.bar: Progress | None = None
        self.lines: PeriodicLines | None = None
        if enabled and console.is_terminal:
            self.bar = Progress(
                TextColumn(f"[bold]{escape(label)}"),
                BarColumn(),
                MofNCompleteColumn(),
                TextColumn(escape(unit)),
                TextColumn("{task.fields[note]}"),
                TimeElapsedColumn(),
                TimeRemainingColumn(),
                console=console,
                transient=True,
            )
            self.task = self.bar.add_task(label, total=total, note="")
        elif enabled:
            self.lines = PeriodicLines(label, total, self._print, unit=unit, every=every, clock=clock)

    def _print(self, line: str) -> None:
        self.console.print(line, highlight=False, markup=False)

    def __enter__(self) -> WorkProgress:
        if self.bar is not None:
            self.bar.start()
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        if self.bar is not None:
            self.bar.stop()

    def update(self, done: float, note: str = "", skipped: float = 0.0) -> None:
        """``done`` units of the work are done, ``skipped`` of them just now without work (a cache's); ``note``:
        what finished last (plain text)."""
        if self.bar is not None:
            self.bar.update(self.task, completed=done, note=escape(note))
        elif self.lines is not None:
            if skipped:
                self.lines.skip(skipped)
            self.lines.update(done)
