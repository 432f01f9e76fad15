"""Small helpers for the text pecli prints: articles, amounts of CPU time, durations."""

from __future__ import annotations

import math
import re

VOWEL_SOUNDS = "aeiou"
CONTROL = re.compile(r"[\x00-\x08\x0a-\x1f\x7f-\x9f]")  # what drives a terminal or breaks a line; tabs stay


def article(word: str) -> str:
    """``word`` with its indefinite article: ``an evader``, ``a pursuer``, ``an exploiter``."""
    return f"{'an' if word[:1].lower() in VOWEL_SOUNDS else 'a'} {word}"


def plural(count: int, word: str) -> str:
    """``count`` and ``word``, with an ``s`` unless the count is one: ``1 episode``, ``3 episodes``."""
    return f"{count:,} {word}" if count == 1 else f"{count:,} {word}s"


def shortened(value: object, most: int = 40) -> str:
    """``repr(value)`` as a message quotes it: cut to ``most`` characters, ``...`` marking the cut."""
    text = repr(value)
    return text if len(text) <= most else f"{text[: most - 3]}..."


def printable(text: str) -> str:
    """``text`` with its control characters written as ``\\xNN``: a name or spec read from a stranger's file,
    quoted in a message, cannot move the cursor, clear the screen or retitle the terminal."""
    return CONTROL.sub(lambda found: f"\\x{ord(found.group()):02x}", text)


def cpu_time(seconds: float, budget: float | None = None) -> str:
    """CPU seconds in one unit, and out of ``budget`` (CPU seconds) when there is one: both in the unit the larger
    of the two calls for (CPU-s under a minute, CPU-min under an hour, CPU-h above) and with the same decimals,
    enough for two significant digits of the smaller.

    ``cpu_time(5, 7.2)`` is ``'5.0 of 7.2 CPU-s'``, ``cpu_time(90, 1800)`` ``'1.5 of 30.0 CPU-min'``,
    ``cpu_time(4500)`` ``'1.2 CPU-h'``.
    """
    values = [seconds] if budget is None else [seconds, budget]
    scale = max(values)
    unit, size = ("CPU-s", 1.0) if scale < 60 else ("CPU-min", 60.0) if scale < 3600 else ("CPU-h", 3600.0)
    digits = max(_decimals(value / size) for value in values)
    shown = [f"{value / size:.{digits}f}" for value in values]
    return f"{' of '.join(shown)} {unit}"


def _decimals(value: float) -> int:
    """Decimals that show ``value`` with two significant digits (none at 10 and above; at most 8)."""
    if value >= 10:
        return 0
    if value >= 1 or value <= 0 or not math.isfinite(value):
        return 1
    return min(8, 1 - math.floor(math.log10(value)))


def duration(seconds: float) -> str:
    """Seconds as a short duration for people: ``45 s``, ``2 min 30 s``, ``12 min``, ``3 h 20 min``, ``2 d 5 h``."""
    if not math.isfinite(seconds):
        return "?"
    seconds = max(0.0, seconds)
    if seconds < 59.5:
        return f"{seconds:.0f} s"
    if seconds < 599.5:  # under ten minutes, to the second
        minutes, rest = divmod(round(seconds), 60)
        return f"{minutes} min {rest} s" if rest else f"{minutes} min"
    minutes = round(seconds / 60)
    if minutes < 60:
        return f"{minutes} min"
    hours, minutes = divmod(minutes, 60)
    if hours < 24:
        return f"{hours} h {minutes} min" if minutes else f"{hours} h"
    days, hours = divmod(hours, 24)
    return f"{days} d {hours} h" if hours else f"{days} d"
