"""A self-play run's CPU budget, read from its turns: one rule for ``pecli selfplay`` and ``pecli experiment``.

A run stops after the first round at which its recorded CPU time (every turn's, exploiters' included) reaches
its budget. Only whole rounds count, those both main learners finished, so a half-played round never ends a run.
The functions read the turns as ``selfplay.json`` stores them (dicts), so the experiment's status needs no torch.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

MAIN = "main"  # pecli.rl.pool.MAIN
MAIN_ROLES = ("pursuer", "evader")
MAX_CPU_HOURS = 10_000  # the largest budget a run takes (pecli selfplay --cpu-hours, an experiment's runs.cpu_hours)

Turns = Sequence[Mapping[str, Any]]


def whole_rounds(turns: Turns) -> int:
    """How many rounds, from round 1 on, both main learners have finished."""
    done = {(int(t.get("round", 0)), t.get("role")) for t in turns if t.get("learner", MAIN) == MAIN}
    rounds = 0
    while all((rounds + 1, role) in done for role in MAIN_ROLES):
        rounds += 1
    return rounds


def cpu_through(turns: Turns, round: int) -> float:
    """CPU seconds of the turns (exploiters' included) of rounds 1 to ``round``."""
    return sum(float(t.get("cpu_seconds", 0.0)) for t in turns if int(t.get("round", 0)) <= round)


def budget_reached(turns: Turns, cpu_hours: float | None) -> bool:
    """Whether a run of budget ``cpu_hours`` (``None``: none) is over it after its last whole round."""
    if cpu_hours is None:
        return False
    rounds = whole_rounds(turns)
    return rounds > 0 and cpu_through(turns, rounds) >= cpu_hours * 3600
