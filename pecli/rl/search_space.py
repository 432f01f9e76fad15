"""The search space of ``pecli tune``: one YAML file a user can edit, validated into typed objects.

    fixed:                      # training settings every trial uses
      steps: 300000
    parameters:                 # training settings Optuna chooses, in this order
      algo: {type: categorical, choices: [td3, sac, tqc, crossq]}
      learning_rate: {type: float, low: 1.0e-4, high: 3.0e-3, log: true}
      action_noise: {type: float, low: 0.05, high: 0.5, algos: [td3, ddpg]}
      net_width: {type: categorical, choices: [64, 128, 256]}

A parameter's name is a key of the config's ``training`` section (nested keys with dots, as ``--set``
takes them), or ``net_width`` / ``net_depth``, which together make ``net_arch = [net_width] * net_depth``.
``algos`` limits a parameter to trials of those algorithms (``algo`` is drawn first).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from pecli.errors import PecliError
from pecli.scenario import ALGOS, Scenario, StrictLoader, Training
from pecli.text import article

DEFAULT_SPACE = Path(__file__).with_name("search_space.yaml")
DERIVED = ("net_width", "net_depth")  # make net_arch


class Parameter(BaseModel):
    """One setting Optuna chooses: a float or int range (``log`` for a log-uniform one), or a list of choices."""

    model_config = ConfigDict(extra="forbid")

    type: Literal["float", "int", "categorical"]
    low: float | None = None
    high: float | None = None
    log: bool = False
    choices: list[str | int | float | bool] | None = None
    algos: list[Literal[ALGOS]] | None = Field(  # type: ignore[valid-type]
        default=None, description="chosen only in trials of these algorithms"
    )

    @field_validator("low", "high", mode="before")
    @classmethod
    def _a_number(cls, value: Any) -> Any:
        if isinstance(value, bool):
            raise ValueError("a bound is a number, not true or false")
        return value

    @model_validator(mode="after")
    def _consistent(self) -> Parameter:
        if self.type == "categorical":
            if not self.choices:
                raise ValueError("a categorical parameter needs a non-empty list of choices")
            if self.low is not None or self.high is not None or self.log:
                raise ValueError("a categorical parameter takes choices, not low/high/log")
            return self
        if self.choices is not None:
            raise ValueError(f"{article(self.type)} parameter takes low and high, not choices")
        if self.low is None or self.high is None or not self.low < self.high:
            raise ValueError(f"{article(self.type)} parameter needs low < high")
        if self.log and self.low <= 0:
            raise ValueError("a log-scaled parameter needs low > 0")
        if self.type == "int" and not (float(self.low).is_integer() and float(self.high).is_integer()):
            raise ValueError("an int parameter needs whole low and high")
        return self

    def values(self) -> list[Any]:
        """The values to check against the scenario: the choices, or both ends of the range."""
        if self.type == "categorical":
            return list(self.choices or [])
        cast = int if self.type == "int" else float
        return [cast(self.low), cast(self.high)]


class SearchSpace(BaseModel):
    """What ``pecli tune`` searches: fixed settings and the parameters Optuna chooses."""

    model_config = ConfigDict(extra="forbid")

    fixed: dict[str, Any] = Field(default_factory=dict)
    parameters: dict[str, Parameter] = Field(min_length=1)

    def check(self, scenario: Scenario, source: str) -> None:
        """:class:`PecliError` (one line) unless every name is a training setting and every value, alone
        with the fixed settings, makes a valid ``scenario``."""
        from pecli.rl.train import with_overrides

        for name in [*self.fixed, *self.parameters]:
            if name not in DERIVED and not _is_setting(name):
                raise PecliError(f"{source}: '{name}' is not a training setting (see `pecli config show`)")
        base = with_overrides(scenario, self.fixed, source=f"{source}: fixed")
        for name, parameter in self.parameters.items():
            for value in parameter.values():
                overrides = _resolve({name: value}, base.training)
                with_overrides(base, overrides, source=f"{source}: parameters.{name} = {value!r}")
        for name, parameter in self.parameters.items():
            if (
                parameter.algos
                and "algo" in self.parameters
                and not set(parameter.algos) & set(self.parameters["algo"].choices or [])
            ):
                raise PecliError(
                    f"{source}: parameters.{name} is for {', '.join(parameter.algos)}, which 'algo' never chooses"
                )


def load_space(path: str | Path | None, scenario: Scenario) -> tuple[SearchSpace, str]:
    """The search space in ``path`` (the default one if ``None``), checked against ``scenario``; with its text."""
    path = Path(path) if path is not None else DEFAULT_SPACE
    try:
        text = path.read_text()
        data = yaml.load(text, Loader=StrictLoader)  # noqa: S506 (a SafeLoader that refuses duplicate keys)
    except OSError as exc:
        raise PecliError(f"cannot read the search space {path}: {exc.strerror or exc}") from None
    except yaml.YAMLError as exc:
        raise PecliError(f"{path}: not valid YAML ({' '.join(str(exc).split())})") from None
    except RecursionError:
        raise PecliError(f"{path}: nested too deeply to be read") from None
    space = parse_space(data, str(path))
    space.check(scenario, str(path))
    return space, text


def parse_space(data: Any, source: str) -> SearchSpace:
    """Validate a loaded YAML document; :class:`PecliError` naming the first problem."""
    if not isinstance(data, dict):
        raise PecliError(f"{source}: a search space is a mapping with 'parameters' (and optionally 'fixed')")
    try:
        return SearchSpace.model_validate(data)
    except ValidationError as exc:
        error = exc.errors()[0]
        where = ".".join(str(part) for part in error["loc"])
        raise PecliError(f"{source}: {where}: {error['msg']}") from None


def suggest(trial: Any, space: SearchSpace, training: Training) -> dict[str, Any]:
    """The trial's training overrides (``--set`` keys): the fixed settings and Optuna's choices.

    ``algo`` is drawn first, so that a parameter limited to some algorithms is drawn only when it counts;
    ``training`` (the scenario's, with the fixed settings) gives the algorithm when ``algo`` is not searched.
    """
    chosen: dict[str, Any] = {}
    algo = training.algo
    names = sorted(space.parameters, key=lambda name: name != "algo")
    for name in names:
        parameter = space.parameters[name]
        if parameter.algos is not None and algo not in parameter.algos:
            continue
        if parameter.type == "categorical":
            chosen[name] = trial.suggest_categorical(name, parameter.choices)
        elif parameter.type == "int":
            chosen[name] = trial.suggest_int(name, int(parameter.low), int(parameter.high), log=parameter.log)
        else:
            chosen[name] = trial.suggest_float(name, parameter.low, parameter.high, log=parameter.log)
        if name == "algo":
            algo = chosen[name]
    return {**space.fixed, **_resolve(chosen, training)}


def config_point(space: SearchSpace, training: Training) -> dict[str, Any]:
    """The parameters' values in ``training`` (the config's own settings), those the space can express:
    a choice it lists or a value inside its range, for the config's algorithm."""
    values = training.model_dump(mode="json")
    widths = set(training.net_arch)
    point: dict[str, Any] = {}
    for name, parameter in space.parameters.items():
        if parameter.algos is not None and training.algo not in parameter.algos:
            continue
        if name == "net_width":
            value: Any = training.net_arch[0] if len(widths) == 1 else None
        elif name == "net_depth":
            value = len(training.net_arch)
        else:
            value = values
            for part in name.split("."):
                value = value[part]
        if parameter.type == "categorical":
            if value in (parameter.choices or []):
                point[name] = value
        elif value is not None and parameter.low <= value <= parameter.high:  # type: ignore[operator]
            point[name] = int(value) if parameter.type == "int" else float(value)
    return point


def _resolve(chosen: dict[str, Any], training: Training) -> dict[str, Any]:
    """``net_width`` and ``net_depth`` become ``net_arch`` (the other from ``training``'s own)."""
    overrides = {k: v for k, v in chosen.items() if k not in DERIVED}
    if any(name in chosen for name in DERIVED):
        width = int(chosen.get("net_width", training.net_arch[0]))
        depth = int(chosen.get("net_depth", len(training.net_arch)))
        overrides["net_arch"] = [width] * depth
    return overrides


def _is_setting(key: str) -> bool:
    """Whether ``key`` (dots for nested sections) names a field of :class:`Training`."""
    model: Any = Training
    for part in key.split("."):
        fields = getattr(model, "model_fields", None)
        if not fields or part not in fields:
            return False
        model = fields[part].annotation
    return True
