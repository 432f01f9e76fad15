"""The records kept beside a run, typed: ``run.json`` (the command that made the run), ``selfplay.json`` (a
self-play run's turns, opponent pools and meta-game games), a learner's progress in its durable ``state.json``,
a tournament's ``results.json``, and an experiment's ``kept.json``, ``experiment.json`` and task markers.

A zoo may come from elsewhere, so every field is bounded and checked before pecli acts on it (a record that is
not one ends in one line naming the field). Torch-free: reading a record loads no network.
"""

from __future__ import annotations

from typing import Annotated, Literal, TypeVar

from pydantic import BaseModel, ConfigDict, Field, RootModel, ValidationError, model_validator

from pecli.errors import PecliError
from pecli.io import first_problem
from pecli.roles import Role

MAX_ROUNDS = 1_000_000
MAX_COUNT = 10**16  # transitions or games a record may count (a scenario's rounds x steps per round, at most)
MAX_CPU_SECONDS = 3.6e7  # 10 000 CPU-hours
MAX_ENTRIES = 100_000  # opponents in one pool, turns in one run
MAX_TEXT = 4096  # a name, a policy string, a run-relative path
MAX_SPEC = 1 << 20  # a player's policy string: a mixture (mix:) of up to 64 members' paths
MAX_ELO = 1e5  # a Bradley-Terry rating's distance from 1500 (its prior keeps it within a few thousand)
NO_NUL = r"^[^\x00]*$"  # a string that can name a file

Learner = Literal["main", "exploiter"]
# a checkpoint a record names: inside the run, in a learner's folder (no path out of it)
CHECKPOINT = r"^(exploiter-)?(pursuer|evader)/[A-Za-z0-9_.-]{1,200}\.zip$"


class _Record(BaseModel):
    model_config = ConfigDict(extra="ignore", strict=True, allow_inf_nan=False)


class JobRecord(_Record):
    """What ``run.json`` must hold to be read: the command, and for ``pecli train`` the role, opponent and seed."""

    model_config = ConfigDict(extra="allow", strict=True)

    command: str = Field(max_length=100)
    role: Role | None = None
    opponent: str | None = Field(default=None, max_length=MAX_TEXT)
    seed: int | None = Field(default=None, ge=0, le=2**32 - 1)
    cpu_minutes: float | None = Field(default=None, gt=0.0, le=MAX_CPU_SECONDS / 60)  # pecli train --cpu-minutes


class Turn(_Record):
    """One side's training in one round of self-play."""

    model_config = ConfigDict(extra="ignore", strict=True, allow_inf_nan=False, validate_assignment=True)

    round: int = Field(ge=1, le=MAX_ROUNDS)
    role: Role
    steps: int = Field(ge=0, le=MAX_COUNT)  # the learner's total transitions at the end of the turn
    episodes: int = Field(ge=0, le=MAX_COUNT)
    captures: int = Field(ge=0, le=MAX_COUNT)
    cpu_seconds: float = Field(ge=0.0, le=MAX_CPU_SECONDS)
    checkpoint: str = Field(pattern=CHECKPOINT)  # run-relative: <role>/<name>.zip or exploiter-<role>/<name>.zip
    opponents: int = Field(ge=0, le=MAX_ENTRIES)  # entries in the opponents' pool during the turn
    learner: Learner = "main"  # main, or exploiter (league)
    joined: bool = False  # an exploiter's checkpoint joined its side's pool
    joined_by: Literal["", "win", "timeout"] = ""  # why it joined ("" if it did not, or in an older record)
    join_rate: float | None = Field(default=None, ge=0.0, le=1.0)  # an exploiter's win rate in its join games

    @model_validator(mode="after")
    def _captures_within_episodes(self) -> Turn:
        if self.captures > self.episodes:
            raise ValueError(f"{self.captures} captures in {self.episodes} episodes")
        return self

    @property
    def capture_rate(self) -> float:
        return self.captures / self.episodes if self.episodes else float("nan")


class PoolEntryRecord(_Record):
    """One opponent of a pool as ``selfplay.json`` stores it."""

    name: str = Field(max_length=MAX_TEXT)
    spec: str = Field(min_length=1, max_length=MAX_TEXT)
    generation: int = Field(ge=0, le=MAX_ROUNDS)
    episodes: float = Field(default=0.0, ge=0.0, le=MAX_COUNT)
    wins: float = Field(default=0.0, ge=0.0, le=MAX_COUNT)


class PoolRecord(_Record):
    role: Role
    entries: list[PoolEntryRecord] = Field(max_length=MAX_ENTRIES)


class SelfPlayRecord(_Record):
    """What ``selfplay.json`` holds."""

    seed: int = Field(ge=0, le=2**32 - 1)
    curriculum_steps: int = Field(ge=0, le=MAX_COUNT)  # the span the curriculum is scheduled over
    pools: dict[Role, PoolRecord]
    turns: list[Turn] = Field(default_factory=list, max_length=MAX_ENTRIES)
    cpu_hours: float | None = Field(default=None, gt=0.0, le=10_000.0)  # absent in older records
    payoffs: dict[str, list[int]] = Field(default_factory=dict, max_length=MAX_ENTRIES)  # "pursuer|evader": games

    @model_validator(mode="after")
    def _payoffs_are_games(self) -> SelfPlayRecord:
        for key, value in self.payoffs.items():  # [captures, games] of one pairing
            if len(value) != 2 or not 0 <= value[0] <= value[1] or not 1 <= value[1] <= MAX_COUNT:
                raise ValueError(f"payoffs: {str(value)[:60]} is no [captures, games] ({key[:40]})")
            if len(key) > 2 * MAX_TEXT + 1:
                raise ValueError("payoffs: a pairing's name is too long")
        if set(self.pools) != {"pursuer", "evader"}:
            raise ValueError(f"pools: one for each role, not {sorted(self.pools)}")
        for role, pool in self.pools.items():
            if pool.role != role:
                raise ValueError(f"pools: the {role} pool says it is the {pool.role}'s")
        return self


class PairingRow(_Record):
    """One pairing of a tournament's ``results.json``: its games and captures."""

    pursuer: str = Field(max_length=MAX_TEXT)
    evader: str = Field(max_length=MAX_TEXT)
    episodes: int = Field(ge=1, le=MAX_COUNT)
    captures: int = Field(ge=0, le=MAX_COUNT)
    time_to_capture_mean: float = Field(ge=0.0, le=1.0)
    time_to_capture_std: float = Field(ge=0.0, le=1.0)

    @model_validator(mode="after")
    def _captures_are_games(self) -> PairingRow:
        if self.captures > self.episodes:
            raise ValueError(f"{self.captures} captures in {self.episodes} games")
        return self


class RatingRow(_Record):
    """One player's Bradley–Terry rating in ``results.json``."""

    name: str = Field(max_length=MAX_TEXT)
    role: Role
    spec: str = Field(max_length=MAX_SPEC, pattern=NO_NUL)
    elo: float = Field(ge=1500 - MAX_ELO, le=1500 + MAX_ELO)
    stderr: float = Field(ge=0.0, le=MAX_ELO)
    games: int | None = Field(default=None, ge=0, le=MAX_COUNT)  # absent from files of old versions


class TournamentRecord(_Record):
    """What a tournament's ``results.json`` must hold to be read: every pairing between two rated players."""

    scenario: str = Field(default="", max_length=MAX_TEXT)
    episodes_per_seed: int = Field(ge=1, le=MAX_COUNT)
    seeds: list[int] = Field(min_length=1, max_length=MAX_ENTRIES)
    pairings: list[PairingRow] = Field(max_length=MAX_ENTRIES)
    ratings: list[RatingRow] = Field(max_length=MAX_ENTRIES)

    @model_validator(mode="after")
    def _pairings_name_rated_players(self) -> TournamentRecord:
        rated = {(r.name, r.role) for r in self.ratings}  # a name may stand for a pursuer and for an evader
        if len(rated) != len(self.ratings):
            raise ValueError("ratings: a player is rated twice")
        for row in self.pairings:
            for role, name in (("pursuer", row.pursuer), ("evader", row.evader)):
                if (name, role) not in rated:
                    raise ValueError(f"pairings: {name[:60]} is no rated {role}")
        return self


class ProgressRecord(_Record):
    """What a learner's durable ``state.json`` says of its progress (the part a driver's status reads)."""

    steps: int = Field(ge=0, le=MAX_COUNT)
    cpu_seconds: float = Field(ge=0.0, le=MAX_CPU_SECONDS)


class _Open(_Record):
    model_config = ConfigDict(extra="allow", strict=True, allow_inf_nan=False)  # what it holds beside is kept


class DriverRecord(_Open):
    """The driver that last wrote ``experiment.json``."""

    pid: int | None = Field(default=None, ge=1, le=2**31 - 1)
    host: str | None = Field(default=None, max_length=MAX_TEXT)
    started: float | None = Field(default=None, ge=0.0)
    ended: str | None = Field(default=None, max_length=MAX_TEXT)


class RunRecord(_Open):
    """One run's status as the driver recorded it."""

    status: str = Field(default="pending", max_length=100)
    error: str = Field(default="", max_length=100_000)
    host: str = Field(default="", max_length=MAX_TEXT)


class StageRecord(_Open):
    """A tournament stage's progress."""

    pairings: int = Field(default=0, ge=0, le=MAX_COUNT)
    status: str = Field(default="", max_length=100)


class SessionRecord(_Open):
    """One ``pecli experiment run`` (what status reads of it)."""

    until_cpu_hours: float | None = Field(default=None, gt=0.0)


class StateRecord(_Open):
    """What ``experiment.json`` must hold to be read."""

    name: str | None = Field(default=None, max_length=MAX_TEXT)
    fingerprint: str | None = Field(default=None, max_length=MAX_TEXT)
    driver: DriverRecord | None = None
    runs: dict[str, RunRecord] = Field(default_factory=dict, max_length=MAX_ENTRIES)
    stages: dict[str, str | StageRecord] = Field(default_factory=dict, max_length=100)
    sessions: list[SessionRecord] = Field(default_factory=list, max_length=MAX_ENTRIES)


class TaskMarker(_Open):
    """Where and since when a run's task runs (``tasks/<run>.json``)."""

    started: float = Field(default=0.0, ge=0.0)
    host: str = Field(default="", max_length=MAX_TEXT)


RUN_NAME = r"^[A-Za-z0-9_-][A-Za-z0-9._-]{0,127}$"  # one folder name: a run stays inside its zoo (check_run_name)
_Paths = Annotated[list[Annotated[str, Field(max_length=MAX_TEXT)]], Field(max_length=MAX_ENTRIES)]
_RunName = Annotated[str, Field(pattern=RUN_NAME)]
# an experiment's kept.json: run -> role -> checkpoints
KeptRecord = RootModel[Annotated[dict[_RunName, dict[Role, _Paths]], Field(max_length=MAX_ENTRIES)]]

RecordT = TypeVar("RecordT", bound=BaseModel)


def validated(model: type[RecordT], data: object, path: object, what: str) -> RecordT:
    """``data`` as ``model``, or :class:`PecliError` in one line naming the first field that is wrong."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise PecliError(f"{path}: damaged {what} ({first_problem(exc, top='the record')})") from None
