"""What a self-play run hands over: each main learner's ``average.zip``, the mean of its newest rounds.

The average spans the learner's newest ``selfplay.average_last`` rounds played wholly on the real game, after
the curriculum (the newest round alone while the curriculum runs). These functions read the turns as
``selfplay.json`` stores them (dicts) and checkpoints' metadata, so the experiment's driver tells a stale
average without torch; :func:`pecli.rl.selfplay.write_averages` writes them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pecli.rl.pool import MAIN
from pecli.roles import ROLES, Role
from pecli.zoo import AVERAGE_FILE, SELFPLAY_FILE, ZooError, read_metadata

if TYPE_CHECKING:
    from pecli.scenario import Scenario

STATE_FILE = SELFPLAY_FILE  # a self-play run's state: its turns, pools and records

Turns = Sequence[Mapping[str, Any]]


def averaged_rounds(turns: Turns, curriculum_steps: int, scenario: Scenario) -> dict[Role, list[str]]:
    """The run-relative checkpoints each main learner's average is the mean of (none with ``average_last`` 0 or
    before its first round); ``curriculum_steps`` is the span ``selfplay.json`` fixed for the curriculum."""
    last = scenario.training.selfplay.average_last
    curriculum = scenario.training.curriculum
    eased = curriculum.span(curriculum_steps) if curriculum.enabled else 0  # transitions per learner
    rounds: dict[Role, list[str]] = {}
    for role in ROLES if last else ():
        mine = sorted(
            (t for t in turns if t.get("role") == role and t.get("learner", MAIN) == MAIN),
            key=lambda t: int(t["round"]),
        )
        started = [0, *(int(t["steps"]) for t in mine)]  # the learner's transitions when each turn began
        real = [t for t, steps in zip(mine, started) if steps >= eased] or mine[-1:]
        if real:
            rounds[role] = [str(t["checkpoint"]) for t in real[-last:]]
    return rounds


def averaged_from(checkpoint: Path) -> list[str] | None:
    """The checkpoints ``checkpoint`` is the mean of, as its metadata names them; ``None`` where it is missing
    or its metadata does not read."""
    if not checkpoint.is_file():
        return None
    try:
        return read_metadata(checkpoint).averaged
    except ZooError:
        return None


def stale_averages(folder: Path, turns: Turns, curriculum_steps: int, scenario: Scenario) -> dict[Role, list[Path]]:
    """The averages the self-play run in ``folder`` (its ``turns``) lacks or holds of other rounds, each with the
    checkpoints it should be the mean of: a stop between a round's record and its averages leaves one behind."""
    wanted = averaged_rounds(turns, curriculum_steps, scenario)
    paths = {role: [folder / checkpoint for checkpoint in checkpoints] for role, checkpoints in wanted.items()}
    return {
        role: inputs
        for role, inputs in paths.items()
        if [Path(path).resolve() for path in averaged_from(folder / role / AVERAGE_FILE) or []]
        != [path.resolve() for path in inputs]
    }  # resolved: a driver's relative --out, a Ray task's absolute one
