"""A self-play run's state: its turns, its opponent pools and its meta-game games, as ``selfplay.json`` holds them.

Torch-free: reading a run's state loads no network. The record is validated (:class:`pecli.records.SelfPlayRecord`)
before anything acts on it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pecli.errors import PecliError
from pecli.io import path_inside, read_json
from pecli.policies.registry import builtin_names
from pecli.records import SelfPlayRecord, Turn, validated
from pecli.rl import budget
from pecli.rl.handover import STATE_FILE, averaged_rounds, stale_averages
from pecli.rl.pool import LEAGUES, MAIN, OpponentPool
from pecli.roles import ROLES, Role
from pecli.scenario import Scenario
from pecli.zoo import Run

__all__ = ["SelfPlayState", "Turn", "checkpoint_name", "initial_state", "read_state", "read_state_file", "round_of"]


@dataclass
class SelfPlayState:
    """What ``selfplay.json`` holds."""

    seed: int
    curriculum_steps: int  # the span the curriculum is scheduled over (fixed when the run starts)
    pools: dict[Role, OpponentPool]
    turns: list[Turn] = field(default_factory=list)
    cpu_hours: float | None = None  # the CPU budget: the run stops after the first round that reaches it
    payoffs: dict[str, list[int]] = field(default_factory=dict)  # opponents nash: "pursuer|evader" -> [captures, games]

    def done(self, round: int, role: Role, learner: str = MAIN) -> bool:
        return any(t.round == round and t.role == role and t.learner == learner for t in self.turns)

    def latest(self, role: Role, learner: str = MAIN) -> Turn | None:
        mine = [t for t in self.turns if t.role == role and t.learner == learner]
        return mine[-1] if mine else None

    def cpu_seconds(self, through: int | None = None) -> float:
        """CPU seconds of the finished turns (exploiters' included), of rounds 1 to ``through`` if given."""
        return budget.cpu_through(self.records(), math.inf if through is None else through)

    def records(self) -> list[dict[str, Any]]:
        """The turns as ``selfplay.json`` stores them (what :mod:`pecli.rl.budget` reads)."""
        return [t.model_dump() for t in self.turns]

    def to_dict(self) -> dict[str, Any]:
        return {
            "seed": self.seed,
            "curriculum_steps": self.curriculum_steps,
            "pools": {role: pool.to_dict() for role, pool in self.pools.items()},
            "turns": self.records(),
            "cpu_hours": self.cpu_hours,
            "payoffs": self.payoffs,
        }

    @classmethod
    def from_record(cls, record: SelfPlayRecord) -> SelfPlayState:
        return cls(
            seed=record.seed,
            curriculum_steps=record.curriculum_steps,
            pools={role: OpponentPool.from_dict(pool.model_dump()) for role, pool in record.pools.items()},
            turns=list(record.turns),
            cpu_hours=record.cpu_hours,
            payoffs={key: list(value) for key, value in record.payoffs.items()},
        )


def read_state(run: Run) -> SelfPlayState:
    """The state of a self-play run; :class:`PecliError` if it has none or it is damaged."""
    path = run.path / STATE_FILE
    if not path.is_file():
        raise PecliError(f"run '{run.name}' is not a self-play run (no {STATE_FILE}): resume it with `pecli train`")
    return read_state_file(path)


def read_state_file(path: Path) -> SelfPlayState:
    """The state in a ``selfplay.json`` at ``path``, validated; :class:`PecliError` if it is unreadable or damaged."""
    record = validated(SelfPlayRecord, read_json(path, "self-play state"), path, "self-play state")
    return SelfPlayState.from_record(record)


def handed_over_rounds(run: Run, role: Role) -> tuple[list[Path], bool]:
    """The round checkpoints of ``role`` that the self-play ``run`` hands over the mean of (``average.zip``), as
    its ``selfplay.json`` and ``config.yaml`` say, and whether its ``average.zip`` lags them (a stop came between a
    round's record and its average). :class:`PecliError` in one line where the run has none, or its record names
    a checkpoint that is missing or lies outside the run (through a link)."""
    state = read_state(run)
    scenario = run.scenario()
    if not scenario.training.selfplay.average_last:
        raise PecliError(f"run '{run.name}' hands over no average (its selfplay.average_last is 0)")
    rounds = averaged_rounds(state.records(), state.curriculum_steps, scenario).get(role)
    if not rounds:
        raise PecliError(f"run '{run.name}' has trained no {role} round yet")
    paths = [run.path / checkpoint for checkpoint in rounds]  # run-relative: <role>/<name>.zip
    for path in paths:
        if not path.is_file():
            raise PecliError(f"run '{run.name}' lacks its round checkpoint {path}")
        if not path_inside(path, run.path):
            raise PecliError(f"run '{run.name}': {path} leads out of the run; pecli follows no such link")
    stale = role in stale_averages(run.path, state.records(), state.curriculum_steps, scenario)
    return paths, stale


def checkpoint_name(round: int) -> str:
    """The name of a learner's checkpoint after ``round``: ``round-003``."""
    return f"round-{round:03d}"


def round_of(checkpoint: Path) -> int | None:
    """The round whose checkpoint ``checkpoint`` is (``round-003.zip`` → 3); ``None`` for any other name."""
    number = checkpoint.stem.removeprefix("round-")
    return int(number) if checkpoint.stem != number and number.isascii() and number.isdigit() else None


def initial_state(scenario: Scenario, seed: int) -> SelfPlayState:
    """Pools holding the baselines of each role: generation 0."""
    sp = scenario.training.selfplay
    pools = {role: OpponentPool(role) for role in ROLES}
    for role in ROLES:
        for name in builtin_names(role, paper_only=sp.opponents not in LEAGUES):  # a league keeps pecli's adversaries
            pools[role].add(name, name, generation=0)
    return SelfPlayState(seed=seed, curriculum_steps=sp.rounds * sp.steps_per_round, pools=pools)
