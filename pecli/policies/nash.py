"""``nash:FOLDER``: the Nash mixture of a zoo as one player.

``pecli tournament ... --nash --out FOLDER`` writes ``FOLDER/nash.json``: the equilibrium of the zoo's meta-game
(:mod:`pecli.metagame`), each side's members with their weights. The policy string ``nash:FOLDER`` (or
``nash:FOLDER/nash.json``) plays one side of it: every game draws one member by its weight when it starts
(:class:`~pecli.policies.mixed.MixedPolicy`), so over many games it plays the mixture that no player of the zoo
exploits.

The file is read as data: its members are built-in names or policy files (a relative path is read from the
folder); a ``module:Class`` member is imported only with ``--trust``, and a mixture never nests another.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from pecli.errors import PolicyError
from pecli.metagame import MetaGame, MetaSolver
from pecli.policies.base import Policy
from pecli.roles import Role
from pecli.scenario import Scenario

NASH_FILE = "nash.json"
MAX_MEMBERS = 10_000
Rate = Annotated[float, Field(ge=0.0, le=1.0)]


class _Record(BaseModel):
    model_config = ConfigDict(extra="ignore", frozen=True, strict=True, allow_inf_nan=False)


class Member(_Record):
    """One player of a mixture and its weight."""

    name: str = Field(max_length=1000)
    spec: str = Field(min_length=1, max_length=4096)
    weight: float = Field(ge=0.0, le=1.0)


class NashRecord(_Record):
    """What ``nash.json`` holds."""

    kind: Literal["nash"] = "nash"
    scenario: str = Field(max_length=1000)
    scenario_hash: str = Field(max_length=200)
    value: float = Field(ge=0.0, le=1.0)
    pursuer: list[Member] = Field(min_length=1, max_length=MAX_MEMBERS)
    evader: list[Member] = Field(min_length=1, max_length=MAX_MEMBERS)
    exploitability: dict[str, float] = Field(default_factory=dict, max_length=2 * MAX_MEMBERS)
    held_to: dict[Role, Rate] = Field(default_factory=dict)  # each mixture against the zoo's strongest reply
    solvers: dict[Role, MetaSolver] = Field(default_factory=lambda: {"pursuer": "nash", "evader": "nash"})
    slack: float | None = Field(default=None, gt=0.0, le=1.0)  # a maxent mixture's, below the value

    @model_validator(mode="after")
    def _slack_with_maxent(self) -> NashRecord:
        if (self.slack is not None) != ("maxent" in self.solvers.values()):
            raise ValueError("a slack goes with a maxent mixture, and only with one")
        return self


def mixture_record(scenario: Scenario, game: MetaGame, specs: Mapping[str, str]) -> dict:
    """What ``nash.json`` holds: each side's mixture of ``game`` (the equilibrium's, or a meta-solver's: ``solvers``)
    with its members' policy strings (``specs``, by player name) and weights, the game's value and every player's
    exploitability within it."""

    def members(role: str) -> list[dict]:
        return [{"name": name, "spec": specs[name], "weight": weight} for name, weight in game.support(role).items()]

    return {
        "kind": "nash",
        "scenario": scenario.name,
        "scenario_hash": scenario.fingerprint(),
        "value": game.value,
        "pursuer": members("pursuer"),
        "evader": members("evader"),
        "exploitability": game.exploitability(),
        "held_to": {"pursuer": game.pursuer_held_to, "evader": game.evader_caught_at_most},
        "solvers": {"pursuer": game.pursuer_solver, "evader": game.evader_solver},
        "slack": game.slack,
    }


def nash_path(options: str) -> Path:
    """The file a ``nash:`` string names: ``FOLDER/nash.json`` or the ``.json`` file itself."""
    path = Path(options.strip())
    return path if path.suffix == ".json" else path / NASH_FILE


def read_nash(path: Path) -> NashRecord:
    """The mixture record at ``path``, validated; :class:`PolicyError` in one line if it is not one."""
    from pecli.errors import PecliError
    from pecli.io import first_problem, read_json

    try:
        data = read_json(path, "Nash mixture (pecli tournament --nash)")
        return NashRecord.model_validate(data)
    except PecliError as exc:
        raise PolicyError(str(exc)) from None
    except ValidationError as exc:
        raise PolicyError(f"{path}: not a Nash mixture ({first_problem(exc)})") from None


def load_nash_policy(options: str, role: Role, scenario: Scenario, member: Callable[[str, Path], Policy]) -> Policy:
    """The ``nash:`` family: ``role``'s side of the mixture in ``options`` (a folder or its ``nash.json``).

    ``member(spec, folder)`` plays one member's policy string, a relative file read from ``folder``.
    """
    from pecli.policies.mixed import MixedPolicy

    if not options.strip():
        raise PolicyError("nash: needs the folder of a tournament run with --nash, e.g. nash:runs/tournament")
    path = nash_path(options)
    record = read_nash(path)
    if record.scenario_hash != scenario.fingerprint():
        raise PolicyError(
            f"{path}: its players play scenario '{record.scenario}', not '{scenario.name}': "
            "pass the config they were trained with"
        )
    members = [m for m in (record.pursuer if role == "pursuer" else record.evader) if m.weight > 0]
    if not members:
        raise PolicyError(f"{path}: its {role} mixture has no member of positive weight")
    from pecli.io import file_digest

    policies = [member(m.spec, path.parent) for m in members]
    mixture = MixedPolicy(role, policies, [m.name for m in members], [m.weight for m in members])
    mixture.identity = f"nash:{file_digest(path)}"  # what a tournament's cache knows it by: the mixture's content
    return mixture
