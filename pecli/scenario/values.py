"""Numbers and angles as a scenario file writes them, and the bounds every size and quantity must keep."""

from __future__ import annotations

import math
import re
from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict
from pydantic.functional_validators import BeforeValidator

TWO_PI = 2.0 * math.pi


_ANGLE = re.compile(r"^\s*(?:(?P<k>[0-9]*\.?[0-9]+)\s*\*?\s*)?pi\s*(?:/\s*(?P<d>[0-9]*\.?[0-9]+))?\s*$")


_DEGREES = re.compile(r"^\s*(?P<v>-?[0-9]*\.?[0-9]+)\s*deg\s*$")


_NUMBER = re.compile(r"^\s*[-+]?(?:[0-9][0-9_]*\.?[0-9_]*|\.[0-9_]+)(?:[eE][-+]?[0-9]+)?\s*$")


def parse_number(value: Any) -> Any:
    """A string that spells a number, as YAML 1.1 leaves ``1e-4`` or ``1.0e6``, as that float; anything else
    unchanged (``nan``, ``inf`` and ``true`` stay what they are, and strict validation refuses them)."""
    if isinstance(value, str) and _NUMBER.match(value):
        return float(value.replace("_", ""))
    return value


def parse_angle(value: Any) -> Any:
    """Turn ``"2pi/3"``, ``"pi"``, ``"1.5*pi"`` or ``"120deg"`` into radians; pass numbers through."""
    value = parse_number(value)
    if isinstance(value, str):
        if m := _ANGLE.match(value):
            k = float(m["k"]) if m["k"] else 1.0
            d = float(m["d"]) if m["d"] else 1.0
            if d == 0.0:
                raise ValueError(f"cannot read {value!r} as an angle (it divides by zero)")
            return k * math.pi / d
        if m := _DEGREES.match(value):
            return math.radians(float(m["v"]))
        raise ValueError(f"cannot read {value!r} as an angle (write radians, 'k*pi/m' or 'Ndeg')")
    return value


Angle = Annotated[float, BeforeValidator(parse_angle)]


Real = Annotated[float, BeforeValidator(parse_number)]
"""A real setting: a finite number (``1e-4`` as YAML leaves it, a string, is read too); ``true`` is refused."""


def _whole(value: Any) -> Any:
    """A number that is whole (``1.0e6``, or YAML's string ``1e6``) as that integer; anything else unchanged."""
    value = parse_number(value)
    if isinstance(value, float) and value.is_integer():
        return int(value)
    return value


Count = Annotated[int, BeforeValidator(_whole)]
"""An integer setting; ``true`` is refused, a whole float such as ``1.0e6`` accepted."""


# Plausible bounds: beyond them a setting is a typo (an extra zero, a unit mix-up), refused before
# anything is allocated. What they allocate together is bounded by MEMORY_LIMIT (memory_estimate).
MAX_STEPS = 10**10  # learner transitions of one run (the paper: 10^6)


MAX_GAMES = 65_536  # training.n_envs: games stepped together in one process (the paper: 8)


MAX_HORIZON = 100_000  # game steps of one episode (the paper: 400)


MAX_HISTORY = 10_000  # game steps of the belief window (the paper: 200)


MAX_BUFFER = 10**8  # transitions or pairs kept (the paper: 10^5)


MAX_BATCH = 65_536


MAX_WIDTH = 65_536  # units of one hidden layer or LSTM


MAX_METRES = 1e6  # any length: arena, sensor range, car, capture radius (the paper's arena: 16 m)


MAX_RATE = 1e5  # any speed, acceleration or steering rate, SI (the paper's car: 2.5 m/s, 2 m/s^2)


MAX_DT = 10.0  # the game's time step, s (the paper: 0.1)


MAX_DEPTH = 32  # hidden layers


MAX_COUNT = 10**9  # any other count (episodes, intervals, threads, ...)


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False)


def dotted(data: Any, prefix: str = "") -> dict[str, Any]:
    """A nested mapping as ``{"dotted.key": leaf}`` (an empty mapping, or anything else, is a leaf):
    ``{"arena": {"width": 8.0}}`` -> ``{"arena.width": 8.0}``."""
    if not isinstance(data, dict) or not data:
        return {prefix.rstrip("."): data}
    return {k: v for key, value in data.items() for k, v in dotted(value, f"{prefix}{key}.").items()}
