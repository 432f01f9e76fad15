"""Experiment files: one YAML file that says what to train, how to rank it, what plays the final
tournament and which of the paper's tables to report.

    name: table1-small
    scenario: paper                  # a built-in scenario or a YAML file (relative to this file)
    training: {checkpoint_every: 50} # overrides of the scenario's training section (as --set)
    runs:                            # the grid: kinds x seeds x schedules, one run each
      kinds: [none, ukf, image, bimdn, bimdn-mixed]
      seeds: [0, 1, 2]
      schedules: [selfplay]          # selfplay (the scenario's), alternating, simultaneous, league, pursuer, evader
      rounds: 6                      # self-play budget: rounds of steps_per_round per side
      steps_per_round: 30000
      # cpu_hours: 4                 # self-play: stop at the first round that reaches it (rounds: the ceiling)
    ranking: {sample: 32, episodes: 100, seeds: 1, keep: 1}
    tournament: {episodes: 500, seeds: 1, baselines: true, players: []}
    report: {table: I}

An experiment can start from another: ``extends: strength-small`` (a built-in name, or a YAML file relative to
this one) takes that experiment's keys, and the ones given here replace them; mappings merge key by key (so
``training: {selfplay: {league_exploiter_share: 0.25}}`` changes one setting), anything else (lists included) is
replaced whole. ``name`` must be given anew, and ``description`` is not inherited.

:func:`load_experiment` validates it into an :class:`Experiment`: unknown keys, wrong types, unknown
belief kinds and empty grids are refused in one line naming the file and the key.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from pecli.belief import BELIEF_KINDS
from pecli.errors import ConfigError, PecliError
from pecli.io import text_digest
from pecli.match import MAX_EPISODES
from pecli.rl.budget import MAX_CPU_HOURS
from pecli.roles import Role
from pecli.scenario import (
    Scenario,
    builtin_experiment_dir,
    builtin_experiments,
    dotted,
    load_scenario,
    read_yaml,
    validation_message,
)

BeliefKind = Literal["none", "bimdn", "bimdn-mixed", "ukf", "image"]
Schedule = Literal["selfplay", "alternating", "simultaneous", "league", "nash", "pursuer", "evader"]
SELFPLAY_SCHEDULES = ("selfplay", "alternating", "simultaneous", "league", "nash")
"""Schedules of a self-play run: ``selfplay`` as the scenario says (alternating unless it sets otherwise),
``alternating`` (one side at a time), ``simultaneous`` (both sides learn in the same games), ``league``
(alternating, with exploiters and the scripted players kept in the pools), ``nash`` (the league with opponents
drawn by the Nash mixture of the pools' meta-game, PSRO)."""
SELFPLAY_SETTINGS: dict[str, dict[str, object]] = {
    "selfplay": {},
    "alternating": {"selfplay.schedule": "alternating"},
    "simultaneous": {"selfplay.schedule": "simultaneous"},
    "league": {"selfplay.schedule": "alternating", "selfplay.opponents": "league"},
    "nash": {"selfplay.schedule": "alternating", "selfplay.opponents": "nash"},
}
assert set(BeliefKind.__args__) == set(BELIEF_KINDS)  # type: ignore[attr-defined]


MAX_EXTENDS = 8  # experiments one file may stack with ``extends``
MAX_SEED = 2**32 - 1  # what NumPy and SB3 take as a seed
MAX_SEEDS = 1000  # seeds of a ranking or tournament pairing


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)  # `true` is not a number, nor 1 a boolean


class RunGrid(_Model):
    """Every combination of belief kind, seed and schedule is one run."""

    kinds: list[BeliefKind] = Field(min_length=1, description="belief kinds, each trained as its own run")
    seeds: list[Annotated[int, Field(ge=0, le=MAX_SEED)]] = Field(
        min_length=1, max_length=MAX_SEEDS, description="training seeds"
    )
    schedules: list[Schedule] = Field(
        default=["selfplay"],
        min_length=1,
        description="selfplay: both sides by the scenario's self-play (alternating by "
        "default); alternating; simultaneous; league; pursuer/evader: one role against a "
        "frozen opponent",
    )
    opponent: str | None = Field(
        default=None, description="frozen opponent of pursuer/evader runs (default: greedy, pure-pursuit)"
    )
    rounds: int | None = Field(default=None, ge=1, description="self-play rounds (default: the scenario's)")
    steps_per_round: int | None = Field(default=None, ge=1, description="self-play transitions per side per round")
    steps: int | None = Field(default=None, ge=1, description="budget of pursuer/evader runs (default: the scenario's)")
    cpu_hours: float | None = Field(
        default=None,
        gt=0,
        le=MAX_CPU_HOURS,
        allow_inf_nan=False,
        description="self-play runs: stop after the first round at which the run's CPU time "
        "(every turn's, exploiters' included) reaches this; rounds is then a ceiling",
    )

    @model_validator(mode="after")
    def _distinct(self) -> RunGrid:
        for key in ("kinds", "seeds", "schedules"):
            values = getattr(self, key)
            if len(set(values)) != len(values):
                raise ValueError(f"{key} repeats a value ({values})")
        one_role = set(self.schedules) - set(SELFPLAY_SCHEDULES)
        if not set(self.schedules) & set(SELFPLAY_SCHEDULES) and len(one_role) < 2:
            raise ValueError(
                f"schedules {self.schedules} train only {one_role.pop()}s: the ranking and the tournament "
                "need both sides (add a self-play schedule, or the other role)"
            )
        return self


class Ranking(_Model):
    """The paper's checkpoint ranking: each checkpoint against ``sample`` random checkpoints of the other
    side; the best ``keep`` of each run and role by mean capture rate go to the tournament. With
    ``players: handed-over`` no games are played: each self-play run's ``<role>/average.zip`` (the mean of its
    last rounds, what ``pecli selfplay`` hands over) goes to the tournament."""

    players: Literal["ranked", "handed-over"] = Field(
        default="ranked", description="ranked: the paper's ranking; handed-over: each run's average.zip"
    )
    sample: int = Field(default=32, ge=1, le=100_000)
    episodes: int = Field(default=100, ge=1, le=MAX_EPISODES, description="episodes per seed and pairing")
    seeds: int = Field(default=1, ge=1, le=MAX_SEEDS)
    keep: int = Field(default=1, ge=1, description="checkpoints kept per run and role")


class TournamentSettings(_Model):
    """The final tournament: kept pursuers x kept evaders, plus the heuristics and ``players``."""

    episodes: int = Field(default=500, ge=1, le=MAX_EPISODES, description="episodes per seed and pairing")
    seeds: int = Field(default=1, ge=1, le=MAX_SEEDS)
    baselines: bool = Field(default=True, description="add the heuristics: pure pursuit; random walk, greedy, rash")
    players: list[str] = Field(default=[], description="more players, as policy strings (e.g. hj)")


class ReportSettings(_Model):
    table: Literal["I", "II", "none"] = Field(default="I", description="the paper's table to lay the results out as")


class Experiment(_Model):
    """A validated experiment file."""

    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
    description: str = ""
    scenario: str = Field(min_length=1, description="built-in scenario name or YAML file")
    training: dict[str, object] = Field(default={}, description="overrides of the scenario's training settings")
    runs: RunGrid
    ranking: Ranking = Ranking()
    tournament: TournamentSettings = TournamentSettings()
    report: ReportSettings = ReportSettings()

    @model_validator(mode="after")
    def _handed_over(self) -> Experiment:
        single = sorted(set(self.runs.schedules) - set(SELFPLAY_SCHEDULES))
        if self.ranking.players == "handed-over" and single:
            raise ValueError(
                f"ranking.players: handed-over takes each self-play run's average.zip, and schedules {single} "
                "train one role without one (use ranking.players: ranked)"
            )
        return self

    def fingerprint(self) -> str:
        """A hash of everything that decides what the experiment computes (not its name or description;
        settings left at their defaults do not count, so a setting added to pecli later keeps old hashes)."""
        text = json.dumps(
            self.model_dump(mode="json", exclude={"name", "description"}, exclude_defaults=True), sort_keys=True
        )
        return text_digest(text)


class RunSpec(BaseModel):
    """One run of the grid, with its resolved scenario (belief and budget applied)."""

    model_config = ConfigDict(frozen=True)

    name: str
    kind: str
    seed: int
    schedule: Schedule
    opponent: str | None
    scenario: Scenario
    cpu_hours: float | None = None  # self-play runs: the CPU budget, checked after each round

    @property
    def selfplay(self) -> bool:
        return self.schedule in SELFPLAY_SCHEDULES

    @property
    def roles(self) -> tuple[Role, ...]:
        return ("pursuer", "evader") if self.selfplay else (self.schedule,)  # type: ignore[return-value]


class LoadedExperiment:
    """An :class:`Experiment` with its base scenario and its runs resolved."""

    def __init__(self, spec: Experiment, scenario: Scenario, source: str) -> None:
        self.spec = spec
        self.scenario = scenario  # the scenario with the experiment's training overrides
        self.source = source

    @property
    def name(self) -> str:
        return self.spec.name

    def runs(self) -> list[RunSpec]:
        """The grid in the order the runs start: schedule, then seed, then kind. A cluster smaller than the grid
        thus finishes the first schedule's runs of every kind, seed by seed, before it starts the next schedule:
        an experiment stopped half-way can already compare the kinds."""
        from pecli.rl.train import with_overrides

        grid, out = self.spec.runs, []
        for schedule in grid.schedules:
            for seed in grid.seeds:
                for kind in grid.kinds:
                    settings: dict[str, object] = {"belief": kind}
                    if schedule in SELFPLAY_SCHEDULES:
                        settings.update(SELFPLAY_SETTINGS[schedule])
                        if grid.rounds is not None:
                            settings["selfplay.rounds"] = grid.rounds
                        if grid.steps_per_round is not None:
                            settings["selfplay.steps_per_round"] = grid.steps_per_round
                    elif grid.steps is not None:
                        settings["steps"] = grid.steps
                    name = f"{kind}-s{seed}" if schedule == "selfplay" else f"{kind}-{schedule}-s{seed}"
                    scenario = with_overrides(self.scenario, settings, source=self.source)
                    out.append(
                        RunSpec(
                            name=name,
                            kind=kind,
                            seed=seed,
                            schedule=schedule,
                            opponent=grid.opponent,
                            scenario=scenario,
                            cpu_hours=grid.cpu_hours if schedule in SELFPLAY_SCHEDULES else None,
                        )
                    )
        return out

    def grid_order(self, runs: list[RunSpec]) -> list[RunSpec]:
        """``runs`` in the grid's own order, kind, then seed, then schedule: the order the paper's ranking draws
        its random pairings in (runs started in that order before :meth:`runs` changed it, and a ranking
        resumed or repeated must draw the same pairings)."""
        grid = self.spec.runs
        return sorted(
            runs,
            key=lambda run: (
                grid.kinds.index(run.kind),
                grid.seeds.index(run.seed),
                grid.schedules.index(run.schedule),
            ),
        )


def experiment_from_dict(data: object, source: str, base: Path | None = None) -> LoadedExperiment:
    """Validate ``data`` (a parsed experiment file); ``base`` is the folder a relative scenario path is read from."""
    from pecli.rl.train import with_overrides

    if not isinstance(data, dict):
        raise ConfigError(f"{source}: an experiment must be a mapping of keys to values, not {type(data).__name__}")
    try:
        spec = Experiment.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(validation_message(exc, source)) from None
    scenario_path = Path(spec.scenario)
    if base is not None and not scenario_path.is_absolute() and (base / scenario_path).is_file():
        scenario_path = base / scenario_path
    try:
        scenario = load_scenario(scenario_path if scenario_path.suffix in (".yaml", ".yml") else spec.scenario)
    except PecliError as exc:
        raise ConfigError(f"{source}: scenario: {exc}") from None
    if scenario_path.is_file():  # a scenario file: recorded by its absolute path, read from wherever --out is
        spec = spec.model_copy(update={"scenario": str(scenario_path.resolve())})
    flat = {
        key: value for key, value in dotted(dict(spec.training)).items() if value != {}
    }  # an empty section: nothing
    scenario = with_overrides(scenario, flat, source=source)
    _check_players(spec, scenario, source)
    return LoadedExperiment(spec, scenario, source)


def _check_players(spec: Experiment, scenario: Scenario, source: str) -> None:
    """Refuse, before any training, an opponent or tournament player that could not play: a name that is
    no policy, a role it cannot take, an ``hj`` player in a game that is not point mass vs point mass."""
    from pecli.policies.registry import BUILTINS, builtin_names, family_of
    from pecli.tournament import check_saved_players

    one_role = [s for s in spec.runs.schedules if s not in SELFPLAY_SCHEDULES]
    if spec.runs.opponent is not None and one_role:
        if len(one_role) > 1:
            raise ConfigError(
                f"{source}: runs.opponent: one opponent cannot train both pursuers and evaders "
                "(put the pursuer and the evader runs in two experiments)"
            )
        role = "evader" if one_role[0] == "pursuer" else "pursuer"
        name = spec.runs.opponent
        if name in BUILTINS and role not in BUILTINS[name].roles:
            raise ConfigError(
                f"{source}: runs.opponent: '{name}' cannot play {role} (for {role}: {', '.join(builtin_names(role))})"
            )
    for i, player in enumerate(spec.tournament.players):
        family = family_of(player)
        if family == "hj" and not (scenario.pursuer.kind == scenario.evader.kind == "point_mass"):
            raise ConfigError(
                f"{source}: tournament.players.{i}: hj plays point mass vs point mass only, not the "
                f"game of scenario '{scenario.name}'"
            )
        if family is None and player not in BUILTINS and ":" not in player and not Path(player).exists():
            raise ConfigError(
                f"{source}: tournament.players.{i}: unknown player '{player}' (a built-in policy such "
                f"as {', '.join(builtin_names()[:4])}, a family such as hj, a file or module:Class)"
            )
        try:
            check_saved_players(player, scenario)  # a checkpoint of another game, or a folder of none
        except PecliError as exc:
            raise ConfigError(f"{source}: tournament.players.{i}: {exc}") from None


def experiment_path(name_or_path: str | Path) -> Path:
    """The YAML file of an experiment given as a file or a built-in name (:func:`builtin_experiments`)."""
    path = Path(name_or_path)
    if (
        not path.is_file()
        and path.suffix not in (".yaml", ".yml")
        and len(path.parts) == 1
        and str(name_or_path) in builtin_experiments()
    ):
        path = builtin_experiment_dir() / f"{name_or_path}.yaml"
    if not path.is_file():
        known = ", ".join(builtin_experiments())
        raise ConfigError(f"experiment not found: {name_or_path} (give a YAML file or one of: {known})")
    return path


def read_experiment(path: Path, _chain: tuple[Path, ...] = ()) -> object:
    """The experiment file at ``path`` as read (a mapping, unless the file is no experiment), with the experiment it
    ``extends`` (if any) merged under it."""
    data = read_yaml(path)
    if not isinstance(data, dict) or "extends" not in data:
        return data
    data = dict(data)
    ref = data.pop("extends")
    if not isinstance(ref, str) or not ref.strip():
        raise ConfigError(f"{path}: extends: give the experiment it starts from (a built-in name or a YAML file)")
    if "name" not in data:
        raise ConfigError(f"{path}: an experiment that extends another needs a name of its own")
    chain = (*_chain, path.resolve())
    if len(chain) > MAX_EXTENDS:
        raise ConfigError(f"{path}: extends: more than {MAX_EXTENDS} experiments stacked")
    relative = path.parent / ref
    try:
        base_path = relative if relative.is_file() else experiment_path(ref)
    except ConfigError as exc:
        raise ConfigError(f"{path}: extends: {exc}") from None
    if base_path.resolve() in chain:
        raise ConfigError(f"{path}: extends: {ref} extends this file in turn (a loop)")
    base = read_experiment(base_path, chain)
    if not isinstance(base, dict):
        raise ConfigError(f"{base_path}: an experiment must be a mapping of keys to values")
    base.pop("description", None)
    scenario = base.get("scenario")
    if isinstance(scenario, str) and (base_path.parent / scenario).is_file():  # a scenario file of the base's own
        base["scenario"] = str((base_path.parent / scenario).resolve())
    return _merged(base, data)


def _merged(base: dict, top: dict) -> dict:
    """``base`` with ``top``'s keys: mappings merged key by key, anything else replaced."""
    out = dict(base)
    for key, value in top.items():
        out[key] = _merged(out[key], value) if isinstance(value, dict) and isinstance(out.get(key), dict) else value
    return out


def load_experiment(name_or_path: str | Path) -> LoadedExperiment:
    """Read and validate an experiment from a YAML file or a built-in name (:func:`builtin_experiments`)."""
    path = experiment_path(name_or_path)
    return experiment_from_dict(read_experiment(path), str(path), base=path.parent)
