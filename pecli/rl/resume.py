"""What a resumed run keeps: its scenario, role, opponent and seed; which options may change when it continues.

``pecli train --resume`` and ``pecli selfplay --resume`` both call these, so the rules are written once: a run
keeps its own game (``--config`` may only name the same one), its seed and its opponent; of the training
settings only the budget may change (``--steps`` for one role, ``--rounds`` for self-play).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pecli.errors import PecliError
from pecli.rl.budget import MAX_CPU_HOURS
from pecli.scenario import Scenario, dotted, load_scenario
from pecli.text import article
from pecli.zoo import JOB_FILE, Run


def check_cpu_hours(hours: float | None) -> float | None:
    """A CPU budget in hours, or :class:`PecliError` in one line."""
    if hours is not None and not (math.isfinite(hours) and 0 < hours <= MAX_CPU_HOURS):
        raise PecliError(f"--cpu-hours must be a number of hours above 0 and at most {MAX_CPU_HOURS:,}, not {hours}")
    return hours


def resumed_scenario(run_scenario: Scenario, config: str | None, name: str) -> Scenario:
    """A resumed run's own scenario; :class:`PecliError` if ``config`` names another game."""
    if config is not None and load_scenario(config).fingerprint() != run_scenario.fingerprint():
        raise PecliError(
            f"run '{name}' plays scenario '{run_scenario.name}' ({run_scenario.fingerprint()}), another "
            "game than --config's; a resumed run keeps its own (drop --config)"
        )
    return run_scenario


def _open(zoo: Path, name: str | None) -> Run:
    if name is None:
        raise PecliError("--resume needs the --name of the run to continue")
    return Run.open(zoo, name)


def _refuse_changes(scenario: Scenario, settings: dict[str, Any], allowed: str) -> None:
    """:class:`PecliError` if ``settings`` (dotted training keys) change anything but the ``allowed`` key."""
    current = dotted(scenario.training.model_dump(mode="json"))
    changed = sorted(key for key, value in settings.items() if key != allowed and current.get(key, object()) != value)
    if changed:
        option = {"steps": "--steps", "selfplay.rounds": "--rounds"}[allowed]
        raise PecliError(f"only {option} can change when resuming (not {', '.join(changed)})")


@dataclass(frozen=True)
class ResumedTrain:
    """What ``pecli train --resume`` continues with."""

    scenario: Scenario
    opponent: str
    seed: int
    curriculum_steps: int
    cpu_minutes: float | None = None  # the run's CPU budget, if it has one


def resume_train(
    zoo: Path,
    name: str | None,
    role: str,
    config: str | None,
    opponent: str | None,
    seed: int | None,
    settings: dict[str, Any],
) -> ResumedTrain:
    """The run ``name`` of ``zoo`` as it continues; :class:`PecliError` if it is not a ``train`` run of ``role``,
    or an option changes what a resumed run keeps. The opponent its record names is resolved as data."""
    from pecli.policies.registry import recorded_policy

    run = _open(zoo, name)
    scenario = resumed_scenario(run.scenario(), config, run.name)
    kept = run.job()
    if kept is None or kept.get("command") != "train":
        what = "an older pecli's run (no run.json)" if kept is None else f"{article(str(kept.get('command')))} run"
        raise PecliError(f"run '{run.name}' is {what}: `pecli train --resume` cannot continue it")
    if any(kept.get(key) is None for key in ("role", "opponent", "seed")):
        raise PecliError(f"{run.path / JOB_FILE}: damaged (a train run records its role, opponent and seed)")
    if kept["role"] != role:
        raise PecliError(f"run '{run.name}' trains the {kept['role']}, not the {role}")
    for option, given, value in (("--opponent", opponent, kept["opponent"]), ("--seed", seed, kept["seed"])):
        if given is not None and given != value:
            raise PecliError(f"run '{run.name}' trains with {option} {value}; a resumed run keeps it")
    _refuse_changes(scenario, settings, "steps")
    if opponent is None:  # the record's, checked: a run folder from elsewhere names no code or path to follow
        opponent = recorded_policy(kept["opponent"], zoo, f"{run.path / JOB_FILE}")
    budget = kept.get("cpu_minutes")
    return ResumedTrain(scenario, opponent, kept["seed"], scenario.training.steps, budget)


def resume_selfplay(
    zoo: Path, name: str | None, config: str | None, seed: int | None, settings: dict[str, Any]
) -> tuple[Scenario, int]:
    """The self-play run ``name`` of ``zoo`` as it continues: its scenario and seed; :class:`PecliError` if an
    option changes what a resumed run keeps, or ``selfplay.rounds`` is below the rounds it has played."""
    from pecli.rl.state import read_state

    run = _open(zoo, name)
    scenario = resumed_scenario(run.scenario(), config, run.name)
    state = read_state(run)
    if seed is not None and seed != state.seed:
        raise PecliError(f"run '{run.name}' plays with --seed {state.seed}; a resumed run keeps it")
    _refuse_changes(scenario, settings, "selfplay.rounds")
    played = max((t.round for t in state.turns), default=0)
    rounds = settings.get("selfplay.rounds")  # a value of the wrong kind is refused when the settings are applied
    if isinstance(rounds, int) and not isinstance(rounds, bool) and rounds < played:
        raise PecliError(f"run '{run.name}' has played {played} rounds already: --rounds must be at least that")
    return scenario, state.seed
