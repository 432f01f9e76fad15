"""CPU budgets: the bounds of a ``--cpu-minutes`` (train, exploit, psro, tune, demo), and a self-play run's
budget read from its turns, one rule for ``pecli selfplay`` and ``pecli experiment``.

A run stops after the first round at which its recorded CPU time (every turn's, exploiters' included) reaches
its budget. Only whole rounds count, those with every turn recorded (both main learners' and the league
exploiters' scheduled in them), so a half-played round never ends a run. The functions read the turns as
``selfplay.json`` stores them (dicts), so the experiment's status needs no torch.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from pecli.rl.pool import EXPLOITER, LEAGUES, MAIN
from pecli.roles import ROLES, Role

if TYPE_CHECKING:
    from pecli.scenario import SelfPlay as SelfPlaySettings

MAX_CPU_HOURS = 10_000  # the largest budget a run takes (pecli selfplay --cpu-hours, an experiment's runs.cpu_hours)
MAX_CPU_MINUTES = 100_000.0  # the largest --cpu-minutes


def check_cpu_minutes(cpu_minutes: float) -> None:
    """:class:`PecliError` unless ``cpu_minutes`` is a finite budget in (0, :data:`MAX_CPU_MINUTES`]."""
    from pecli.errors import PecliError

    if not 0 < cpu_minutes <= MAX_CPU_MINUTES or not math.isfinite(cpu_minutes):
        raise PecliError(f"--cpu-minutes must be in (0, {MAX_CPU_MINUTES:g}], not {cpu_minutes}")


Turns = Sequence[Mapping[str, Any]]


def cpu_through(turns: Turns, round: float) -> float:
    """CPU seconds of the turns (exploiters' included) of rounds 1 to ``round`` (``math.inf``: all)."""
    return sum(float(t.get("cpu_seconds", 0.0)) for t in turns if int(t.get("round", 0)) <= round)


def scheduled_turns(settings: SelfPlaySettings, turns: Turns, round: int) -> list[tuple[str, Role]]:
    """The ``(learner, role)`` turns of ``round``: both main learners, then the sides of ``league_exploiter_roles``
    in every ``league_exploiter_every``-th round of a league (never if 0), once the rounds before it spent
    ``league_exploiter_after`` CPU-hours (a fact of the record: a resumed run decides alike)."""
    every = settings.league_exploiter_every if settings.opponents in LEAGUES else 0
    exploiters = (
        bool(every) and round % every == 0 and cpu_through(turns, round - 1) >= 3600.0 * settings.league_exploiter_after
    )
    return [(MAIN, role) for role in ROLES] + [
        (EXPLOITER, role) for role in ROLES if exploiters and role in settings.league_exploiter_roles
    ]


def whole_rounds(turns: Turns, settings: SelfPlaySettings) -> int:
    """How many rounds, from round 1 on, have all their scheduled turns recorded."""
    done = {(int(t.get("round", 0)), t.get("learner", MAIN), t.get("role")) for t in turns}
    rounds = 0
    while all((rounds + 1, *turn) in done for turn in scheduled_turns(settings, turns, rounds + 1)):
        rounds += 1
    return rounds


def budget_reached(turns: Turns, cpu_hours: float | None, settings: SelfPlaySettings) -> bool:
    """Whether a run of budget ``cpu_hours`` (``None``: none) is over it after its last whole round."""
    if cpu_hours is None:
        return False
    rounds = whole_rounds(turns, settings)
    return rounds > 0 and cpu_through(turns, rounds) >= cpu_hours * 3600
