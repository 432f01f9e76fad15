"""Progress lines for logs (with a fake clock) and the wording helpers of printed text."""

from __future__ import annotations

import io

import pytest
from rich.console import Console

from pecli.progress import PeriodicLines, WorkProgress
from pecli.text import article, cpu_time, duration, plural


class FakeClock:
    """Seconds that pass only when a test says so."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


@pytest.mark.parametrize(
    ("word", "expected"),
    [("evader", "an evader"), ("pursuer", "a pursuer"), ("exploiter", "an exploiter"), ("int", "an int")],
)
def test_article(word: str, expected: str) -> None:
    assert article(word) == expected


def test_plural() -> None:
    assert plural(1, "episode") == "1 episode"
    assert plural(0, "episode") == "0 episodes"
    assert plural(1200, "episode") == "1,200 episodes"


@pytest.mark.parametrize(
    ("seconds", "budget", "expected"),
    [
        (0.0036, 7.2, "0.0036 of 7.2000 CPU-s"),  # 0.000001 of 0.002 CPU-h: both readable, not 0.00 of 0.002
        (5.0, 7.2, "5.0 of 7.2 CPU-s"),
        (90.0, 1800.0, "1.5 of 30.0 CPU-min"),  # under an hour: CPU-minutes
        (1800.0, 7200.0, "0.50 of 2.00 CPU-h"),  # two significant digits of the smaller
        (36000.0, 72000.0, "10 of 20 CPU-h"),
        (4500.0, None, "1.2 CPU-h"),
        (0.0, 3600.0, "0.0 of 1.0 CPU-h"),
    ],
)
def test_cpu_time_puts_both_in_one_unit_with_the_same_decimals(
    seconds: float, budget: float | None, expected: str
) -> None:
    assert cpu_time(seconds, budget) == expected


def test_duration() -> None:
    assert [duration(s) for s in (12, 59.7, 150, 600, 3600 * 3 + 1200, 3600 * 26, float("inf"))] == [
        "12 s",
        "1 min",
        "2 min 30 s",
        "10 min",
        "3 h 20 min",
        "1 d 2 h",
        "?",
    ]


def test_periodic_lines_come_every_interval_with_an_eta() -> None:
    clock, lines = FakeClock(), []
    progress = PeriodicLines("train", 1000, lines.append, unit="steps", every=30, clock=clock, details=lambda: "cpu")
    clock.now += 10
    assert not progress.update(100) and lines == []  # not yet 30 s
    clock.now += 20
    assert progress.update(250)
    assert lines == ["train: 250/1,000 steps (25%), cpu, 30 s elapsed, about 1 min 30 s left"]  # 750 at 250 per 30 s
    clock.now += 5
    progress.update(300)
    assert len(lines) == 1  # 5 s after the last line
    clock.now += 30
    progress.update(1000)
    assert lines[-1] == "train: 1,000/1,000 steps (100%), cpu, 1 min 5 s elapsed"  # done: no time left to tell


def test_periodic_lines_leave_resumed_and_cached_work_out_of_the_rate() -> None:
    clock, lines = FakeClock(), []
    progress = PeriodicLines("pairings", 100, lines.append, every=30, clock=clock, start=40)
    progress.skip(10)  # 10 pairings found in the cache
    clock.now += 60
    progress.update(60)  # 10 played in 60 s: 40 left take 4 min
    assert lines == ["pairings: 60/100 (60%), 1 min elapsed, about 4 min left"]


def test_work_progress_prints_plain_lines_without_a_terminal() -> None:
    clock, out = FakeClock(), io.StringIO()
    console = Console(file=out, width=120, force_terminal=False)
    with WorkProgress("solving", 40, console, unit="steps", every=30, clock=clock) as progress:
        for done in range(1, 41):
            clock.now += 3
            progress.update(done, note=f"step {done}")
    shown = out.getvalue().splitlines()
    assert len(shown) == 4  # one line every 30 s of the 120 s
    assert shown[0] == "solving: 10/40 steps (25%), 30 s elapsed, about 1 min 30 s left"
    quiet = io.StringIO()
    with WorkProgress("solving", 40, Console(file=quiet), enabled=False, clock=clock) as progress:
        clock.now += 100
        progress.update(20)
    assert quiet.getvalue() == ""
